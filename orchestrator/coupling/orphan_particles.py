"""Particles the reconstructed surface leaves out, coupled to the background point by point.

The embedded SPH coupling (particle_operators.py) constrains a particle body where the iso-surface
of its Shepard indicator cuts the grid.  A sheet or a fragment thinner than the reconstruction
resolves (about a zone: the indicator stays below the iso value at every node) has no surface, so
no multiplier holds it: it crosses background material as if it were not there.  The 3-D Tate
penetrator measured it (cases/penetrator_tate): of 4160 rod particles 166 / 870 / 1754 sat in zones
full of aluminium at 4 / 16 / 32 us, eroded rod material flying on through the target.

A particle whose zone the bodies do not block at all (an *orphan*) is tied here to the background
velocity at its position, interpolated from the zone's corner nodes (the multilinear shape functions
N_pa), in the same tied sense as the surface multipliers but with one constraint per particle:

    u_p + J_p / m_p = sum_a N_pa (u_a - sum_q N_qa J_q / m_a)        for every orphan p,

i.e. H J = N u_b - u_p with H = M_p^-1 + N M_b^-1 N^T (SPD, one sparse solve for all orphans and
components: orphans sharing nodes share their inertia, so nothing overshoots).  The particle gets
+J_p, the nodes -N^T J: equal and opposite, momentum is conserved to round-off; the kinetic energy
the inelastic match removes, 1/2 J . (N u_b - u_p), is reported as the coupling's dissipation.

Only orphans in background material at least ``DENSITY_RATIO`` times as dense as the particle are
tied: a water droplet in air (ratio 1/800) flies on as before -- tying it would drag the air along
at the droplet's speed, an infinite drag coefficient -- and void (trace mass) is never given a
fragment's velocity.  A fragment in a metal target (steel in aluminium: 0.34) is.  The orphans'
volume is not blocked from the background: below the grid's resolution the two overlap.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from orchestrator.coupling.grid import corner_weights
from orchestrator.coupling.particle_operators import _constants

DENSITY_RATIO = 0.1
"""Tie an orphan only where the background near it is at least this fraction of the particle's
density (module docstring): below it the background barely slows a fragment anyway."""


MAX_COMPRESSION = 10.0
"""A bound on how much denser than anything the case starts with (regions, inflow) the background
gets (a gas compresses 6-fold in the strongest single shock at gamma = 1.4): a background that even
so stays below ``DENSITY_RATIO`` of the particles can never tie one, and the lookup is skipped
(the embedded dam break: water in air, 49 us a step of a ~1 ms surface reconstruction)."""


def may_tie(ale: dict, particle_density: float) -> bool:
    """Whether the background of the normalised ``[ale]`` table can ever be dense enough to tie
    particles of ``particle_density`` (MAX_COMPRESSION times its densest initial or inflow state)."""
    dens = [float(r["density"]) for r in ale.get("regions", []) if "density" in r]
    dens += [float(f["inflow"]["density"]) for f in ale.get("boundaries", {}).values()
             if isinstance(f, dict) and "inflow" in f]
    return MAX_COMPRESSION * max(dens, default=0.0) >= DENSITY_RATIO * particle_density


@dataclass
class Orphans:
    """The orphan particles of one geometry: ``index`` (no,) into the particles, ``nodes`` (no, 2^dim)
    global ids of their zones' corners, ``weights`` (no, 2^dim) the multilinear N_pa (rows sum to 1)."""

    index: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray

    @property
    def size(self) -> int:
        return int(self.index.size)


@njit(cache=True)
def _outside_kernel(x, lower, upper, h, cells, zones, total, run_start, run_length, mark):
    """(n,) True for each particle inside the grid whose zone has no blocked fraction: the zones with
    one (``zones`` with ``total`` > 0, and the runs covered whole) are marked in ``mark`` (zeros,
    one per zone; left zeroed again), then each particle looks its zone up."""
    n, dim = x.shape
    for k in range(zones.size):
        if total[k] > 0.0:
            mark[zones[k]] = 1
    for r in range(run_start.size):
        for z in range(run_start[r], run_start[r] + run_length[r]):
            mark[z] = 1
    out = np.zeros(n, np.bool_)
    for p in range(n):
        zone, stride, inside = 0, 1, True
        for d in range(dim):
            if not (x[p, d] >= lower[d] and x[p, d] <= upper[d]):
                inside = False
                break
            i = min(int((x[p, d] - lower[d]) / h[d]), cells[d] - 1)
            zone += i * stride
            stride *= cells[d]
        out[p] = inside and mark[zone] == 0
    for k in range(zones.size):
        mark[zones[k]] = 0
    for r in range(run_start.size):
        for z in range(run_start[r], run_start[r] + run_length[r]):
            mark[z] = 0
    return out


@functools.lru_cache(maxsize=16)
def _zone_marks(grid):
    """Per grid (grid.Grid hashes by identity): the kernel's zone marks, zeros between calls."""
    return np.zeros(grid.n_zones, np.uint8)


def find_orphans(grid, x: np.ndarray, coverage) -> Orphans:
    """The particles at ``x`` (n, dim) inside the grid whose zone no body blocks (``coverage``:
    geometry.Coverage of the reconstructed surface), with their zones' corner nodes and weights.
    (One kernel pass: the numpy form of the lookup cost half the surface reconstruction's time on
    the 2-D dam break's 4k particles.)"""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, grid.dim)
    zones = np.ascontiguousarray(coverage.zones, dtype=np.int64)
    total = coverage.total if coverage.total is not None else coverage.fractions
    total = np.asarray(total, dtype=np.float64)
    if total.ndim != 1:   # (per body: any of them)
        total = total.reshape(zones.size, -1).max(axis=1, initial=0.0)
    k = _constants(grid)   # (the grid's arrays as the particle kernels take them, made once)
    lower, h, cells = k["lower"], k["zone_h"], k["cells"]
    idx = np.flatnonzero(_outside_kernel(x, lower, k["upper"], h, cells, zones, np.ascontiguousarray(total),
                                         np.ascontiguousarray(coverage.run_start, dtype=np.int64),
                                         np.ascontiguousarray(coverage.run_length, dtype=np.int64),
                                         _zone_marks(grid)))
    nc = 2 ** grid.dim
    if idx.size == 0:
        return Orphans(idx, np.zeros((0, nc), np.int64), np.zeros((0, nc)))
    s = (x[idx] - lower) / h
    ijk = np.minimum(np.floor(s).astype(np.int64), cells - 1)
    return Orphans(idx, grid.zone_nodes(grid.zone_ids(ijk)).reshape(idx.size, nc), corner_weights(s - ijk))


def tie(orphans: Orphans, cols: np.ndarray, u_p: np.ndarray, m_p: np.ndarray, rho_p: np.ndarray,
        u_b: np.ndarray, m_b: np.ndarray, zone_volume: float):
    """The impulses that tie the orphans to the background (module docstring).

    ``cols`` (no, 2^dim): the orphans' corner nodes as rows of ``u_b`` (nb, dim) / ``m_b`` (nb,), the
    nodes' velocities and masses; ``u_p`` (no, dim), ``m_p``, ``rho_p`` (no,): the orphans' velocities,
    masses and densities.  Returns (J (no, dim) on the orphans -- zero rows for those not tied --,
    node impulses (nb, dim), tied count, kinetic energy removed)."""
    no, dim = u_p.shape
    nb = u_b.shape[0]
    J = np.zeros((no, dim))
    imp_b = np.zeros((nb, dim))
    if no == 0:
        return J, imp_b, 0, 0.0
    N = orphans.weights
    rho_b = np.einsum("pc,pc->p", N, m_b[cols]) / zone_volume
    tied = np.flatnonzero((rho_b >= DENSITY_RATIO * rho_p) & np.all(m_b[cols] > 0.0, axis=1))
    if tied.size == 0:
        return J, imp_b, 0, 0.0
    k = 2 ** dim
    rows = np.repeat(np.arange(tied.size), k)
    Nm = sp.csr_matrix((N[tied].ravel(), (rows, cols[tied].ravel())), shape=(tied.size, nb))
    H = (sp.diags(1.0 / m_p[tied]) + Nm @ sp.diags(1.0 / m_b) @ Nm.T).tocsc()
    gap = Nm @ u_b - u_p[tied]                                     # (nt, dim) N u_b - u_p
    Jt = spla.splu(H).solve(np.ascontiguousarray(gap))
    J[tied] = Jt
    imp_b = -(Nm.T @ Jt)
    return J, np.asarray(imp_b), int(tied.size), 0.5 * float(np.sum(Jt * gap))
