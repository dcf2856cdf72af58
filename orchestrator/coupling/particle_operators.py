"""The coupling geometry and operators of a particle (SPH) body in the background grid (Tsuji, Puso,
Spangler, Owen et al., "Embedded smoothed particle hydrodynamics", CMAME 366 (2020); the seed's
"Couple particles to background").

A particle body has no mesh: its interface Gamma is the iso-surface c = 1/2 of the particles'
colour function at the background nodes (particle_surface.py: marching squares / tetrahedra per
zone, closed and outward-oriented), rebuilt from the particle positions at every step.  That
surface is clipped by the zones exactly as a Lagrangian body's (geometry.clip_surface), so the
blocked fractions and face coverages of the restricted advection, the areas, normals and B^b are
the mesh body's.  Only B^f changes: the foreground velocity on Gamma is the particles'
Shepard-normalised kernel interpolation, so

    B^f_ei = ∫_{Γ_e} W_i / Σ_j W_j dΓ   (W_i = V_i W(|x - x_i|, h), Lucy kernel, support h),

integrated with the pieces' quadrature points (geometry.py: degree 3 in 2-D, 4 in 3-D).  Its
columns are particles.  The Shepard weights of a point sum to 1 (a point beyond every kernel, where
the surface runs straight across a zone coarser than h, takes its nearest particle's velocity), so
every row of B^f sums to the cut area A_e, as every row of B^b does: the impulses on particles and
background are equal and opposite.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from orchestrator.coupling.geometry import clip_surface
from orchestrator.coupling.operators import Operators
from orchestrator.coupling.particle_surface import as_coupling_facets, colour_at_nodes, reconstruct, shepard_weights


@dataclasses.dataclass
class ParticleInterface:
    points: np.ndarray   # (nv, dim) vertices of the reconstructed surface
    facets: np.ndarray   # (nf, 2 | 4) segments / quads (a, b, c, c) of the coupling geometry
    pieces: object       # geometry.Pieces of the whole surface (fractions, coverages)
    inner: object        # the pieces facing gas (operators)
    ops: Operators       # B^f over particles


def particle_rows(ops: Operators, inner, x: np.ndarray, volume: np.ndarray, h: float) -> sp.csr_matrix:
    """B^f (n_zones x n_particles): the quadrature of the Shepard weights over each zone's pieces."""
    qzone = np.asarray(inner.zone, dtype=np.int64)[np.asarray(inner.qpiece, dtype=np.int64)]
    if ops.zones.size == 0:
        return sp.csr_matrix((0, len(x)))
    # the row of each point's zone; points of zones without a multiplier (zero area) are dropped
    row = np.minimum(np.searchsorted(ops.zones, qzone), ops.zones.size - 1)
    q = np.flatnonzero(ops.zones[row] == qzone)
    Z = sp.csr_matrix((np.asarray(inner.qw, float)[q], (row[q], q)), shape=(ops.zones.size, qzone.size))
    S = shepard_weights(np.asarray(inner.qp, float), x, volume, h)
    lone = np.flatnonzero(np.diff(S.indptr) == 0)
    if lone.size:
        # a quadrature point beyond every particle's kernel (the surface runs straight between its
        # vertices on grid edges, which can lie up to a zone from the particles): its weight goes
        # to the nearest particle, so every row still sums to the cut area (momentum balance)
        from scipy.spatial import cKDTree

        _, near = cKDTree(x).query(np.asarray(inner.qp, float)[lone])
        S = (S + sp.csr_matrix((np.ones(lone.size), (lone, near)), shape=S.shape)).tocsr()
    Bf = (Z @ S).tocsr()
    Bf.sort_indices()
    return Bf


def boundary_images(grid, x: np.ndarray, volume: np.ndarray, h: float):
    """The particles with their images across the grid's boundary planes (within h of a plane:
    mirrored across it, or shifted by the period on a periodic axis), for the colour function only:
    a body that reaches the boundary keeps c ~ 1 up to it instead of the half kernel's ~ 1/2, so its
    reconstructed surface meets the boundary where the body does."""
    xs, vs = [x], [volume]
    periodic = np.asarray(grid.periodic, dtype=bool)
    for d in range(grid.dim):   # (per axis; corners get no double image: c stays above 1/2 there)
        lo, hi = float(grid.lower[d]), float(grid.upper[d])
        for near, image in ((x[:, d] < lo + h, hi - lo if periodic[d] else 2.0 * lo),
                            (x[:, d] > hi - h, lo - hi if periodic[d] else 2.0 * hi)):
            xi = x[near].copy()
            xi[:, d] = xi[:, d] + image if periodic[d] else image - xi[:, d]
            xs.append(xi)
            vs.append(volume[near])
    return np.concatenate(xs), np.concatenate(vs)


def particle_interface(grid, x: np.ndarray, volume: np.ndarray, h: float, iso: float = 0.5) -> ParticleInterface:
    """The reconstructed interface of the particles ``x`` (n, dim) with volumes ``volume`` (n,) and
    kernel support ``h`` in ``grid`` (geometry.Grid), and its operators (columns of B^f: particles).
    The surface closes on the grid's boundary planes where the body reaches them (those facets
    count for the fractions and get no multiplier: embedded.facing_the_grid)."""
    from orchestrator.coupling.embedded import facing_the_grid

    xg, vg = boundary_images(grid, x, volume, h)
    c = colour_at_nodes(grid.lower, grid.h, grid.cells, xg, vg, h)
    points, tri = reconstruct(grid.lower, grid.h, grid.cells, c, iso, close_on_boundary=True)
    if len(tri) == 0:
        from orchestrator.coupling.geometry import GeometryError

        raise GeometryError(f"the SPH particles form no surface on the background grid (their colour "
                            f"function stays below {iso:g} at every node: the body has come apart into "
                            "particles further apart than the smoothing length)")
    facets = as_coupling_facets(tri)
    pieces = clip_surface(grid, points, facets, np.zeros(len(facets), np.int64))
    inner = facing_the_grid(grid, pieces)
    ops = Operators.build(grid, inner, facets, len(points))
    ops = dataclasses.replace(ops, Bf=particle_rows(ops, inner, x, volume, h))
    return ParticleInterface(points, facets, pieces, inner, ops)
