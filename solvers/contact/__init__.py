"""Contact between Lagrangian bodies: a library the Lagrangian solver calls inside its own group (as
LLNL's codes call Tribol), independent of the orchestrator.

Order of use at one configuration:

1. search.py          broad phase: facet bounding boxes (grown by a capture distance) binned, the
                      candidate facet pairs (cost linear in the surface size);
2. mortar_segments.py the mortar integrals D and M of one pass on the candidate pairs (2-D);
   mortar_facets.py   the same for quadrilateral facets (3-D: projection onto the non-mortar facet's
                      plane, polygon clipping, triangle quadrature on the overlaps);
3. dual_pass.py       both passes assembled: weighted gaps g = G x, the constraint operator B = G/2,
                      nodal forces B^T p and the stabilization J of Puso & Solberg (2020);
                      methods.py gives it and the comparisons (single-pass mortar, node-to-surface
                      single and double pass) by name, behind the same interface;
4. kkt.py             a static solve: K u - B^T p = F with p >= 0, B (X + u) + J p >= 0,
                      complementary (primal-dual active set).
"""
