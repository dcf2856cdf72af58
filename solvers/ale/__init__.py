"""ALE background solver: staggered-grid Lagrange step plus remap (Eulerian) hydrodynamics."""
