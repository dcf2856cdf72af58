"""The coupler's constraint coupling of immersed bodies to the background (DESIGN.md, "The constraint
solve"), one module per job:

* ``grid``      -- the background grid as a descriptor (zone, node and face ids; no whole-grid arrays);
* ``geometry``  -- the interface geometry: body surfaces clipped against the zones (pieces with their
  quadrature), exact blocked volume fractions and face coverages;
* ``operators`` -- the coupling operators B^b, B^f built on the pieces;
* ``solve``     -- the stabilised multiplier solve ``H lambda = B v*`` and the impulses;
* ``variants``  -- the coupling methods by name (multiplier, penalty, Nitsche);
* ``embedded``  -- the coupler's share of a coupled step (exchange, load, solve, geometry);
* ``conditioning`` -- the condition number sweep of H (tests and the coupling bench).
"""
