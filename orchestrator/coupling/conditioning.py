"""The conditioning study of the multiplier system: cond(H) over grid refinement for random straight
cuts, with and without the stabilisation (the talk's claim: s_con = λ_max(H)/λ_min(H) is a constant
independent of h when stabilised).  Used by the tests and the benchmark chart.

The interfaces are manufactured analytically (a straight line through the unit square, a plane
z = z0 + a x through the unit cube, each meshed by segments/quads of about the zone width at a random
spacing and offset), so the study measures the solve, not the general clipper; the uniform lattice
below follows the contract of `grid.Grid` (zone id i + nx (j + ny k), node id i + (nx+1)(j + (ny+1)k),
corner c at offset (c&1, c>>1&1, c>>2&1)).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from orchestrator.coupling.grid import corner_weights
from orchestrator.coupling.operators import Operators
from orchestrator.coupling.solve import ALPHA, BETA, assemble, condition_number

HS = (1 / 8, 1 / 16, 1 / 32, 1 / 64)
GAUSS2 = (np.array([-1.0, 1.0]) / np.sqrt(3.0) + 1.0) / 2.0  # 2-point Gauss on [0, 1], weights 1/2


@dataclass(frozen=True)
class Lattice:
    """Uniform grid on [0, 1]^dim with n zones per direction (the `grid.Grid` contract's subset)."""

    dim: int
    n: int

    @property
    def cells(self) -> np.ndarray:
        return np.full(self.dim, self.n, dtype=np.int64)

    @property
    def h(self) -> np.ndarray:
        return np.full(self.dim, 1.0 / self.n)

    @property
    def zone_volume(self) -> float:
        return (1.0 / self.n) ** self.dim

    def zone_nodes(self, zone_ids) -> np.ndarray:
        z = np.asarray(zone_ids, dtype=np.int64)
        idx = np.stack([(z // self.n**a) % self.n for a in range(self.dim)], axis=1)
        c = np.arange(2**self.dim)
        off = np.stack([(c >> a) & 1 for a in range(self.dim)], axis=1)
        corner = idx[:, None, :] + off[None, :, :]
        return sum(corner[:, :, a] * (self.n + 1) ** a for a in range(self.dim))


def _zone_id(idx: np.ndarray, n: int) -> np.ndarray:
    return sum(idx[:, a] * n**a for a in range(idx.shape[1]))


def _pieces(lat: Lattice, zone, facet, area, normal, qp, qw, qf, nq_per_piece):
    """Pieces sorted by (zone, facet, position) with the background shape functions at the points."""
    order = np.lexsort((np.arange(zone.size), facet, zone))
    zone, facet, area = zone[order], facet[order], area[order]
    q = (order[:, None] * nq_per_piece + np.arange(nq_per_piece)[None, :]).ravel()
    qp, qw, qf = qp[q], qw[q], qf[q]
    qpiece = np.repeat(np.arange(zone.size), nq_per_piece)
    idx = np.stack([(zone // lat.n**a) % lat.n for a in range(lat.dim)], axis=1)
    xi = qp * lat.n - idx[qpiece]
    centroid = np.stack([np.bincount(qpiece, weights=qw * qp[:, a]) for a in range(lat.dim)], axis=1) / area[:, None]
    return SimpleNamespace(zone=zone, body=np.zeros(zone.size, np.int64), facet=facet, area=area,
                           normal=np.repeat(normal[None, :], zone.size, axis=0), centroid=centroid, qp=qp,
                           qw=qw, qpiece=qpiece, qf=qf, qb=corner_weights(np.clip(xi, 0.0, 1.0)))


def straight_cut(dim: int, h: float, rng: np.random.Generator):
    """A random straight interface through [0, 1]^dim: (lattice, pieces, facets, nodes (ns, dim)).

    2-D: a line through a point of [0.3, 0.7]^2 at a random angle, facets of about h (x U(0.7, 1.3)).
    3-D: the plane z = z0 + a x (a = tan of an angle in U(-50°, 50°)), quads of about h x h at a
    random offset.  Clipping is exact (straight pieces); 2-point Gauss per direction integrates the
    products of linear foreground and multilinear background shape functions exactly."""
    n = int(round(1.0 / h))
    lat = Lattice(dim, n)
    grid_lines = np.arange(n + 1) / n
    if dim == 2:
        angle = rng.uniform(0.0, np.pi)
        point = rng.uniform(0.3, 0.7, 2)
        t = np.array([np.cos(angle), np.sin(angle)])
        with np.errstate(divide="ignore"):
            ends = np.sort(np.stack([(0.0 - point) / t, (1.0 - point) / t]), axis=0)
        lo, hi = np.max(ends[0]), np.min(ends[1])
        m = max(int(np.ceil((hi - lo) / (h * rng.uniform(0.7, 1.3)))), 1)
        s_nodes = np.linspace(lo, hi, m + 1)
        breaks = [s_nodes]
        for a in range(2):
            if t[a] != 0.0:
                breaks.append((grid_lines - point[a]) / t[a])
        b = np.unique(np.concatenate(breaks))
        b = b[(b >= lo) & (b <= hi)]
        s0, s1 = b[:-1], b[1:]
        mid = 0.5 * (s0 + s1)
        xm = point[None, :] + mid[:, None] * t[None, :]
        idx = np.clip(np.floor(xm * n).astype(np.int64), 0, n - 1)
        zone = _zone_id(idx, n)
        facet = np.clip(np.searchsorted(s_nodes, mid, side="right") - 1, 0, m - 1)
        sq = (s0[:, None] + (s1 - s0)[:, None] * GAUSS2[None, :]).ravel()
        qp = point[None, :] + sq[:, None] * t[None, :]
        qw = np.repeat(0.5 * (s1 - s0), 2)
        fq = np.repeat(facet, 2)
        xi = (sq - s_nodes[fq]) / (s_nodes[fq + 1] - s_nodes[fq])
        qf = np.stack([1.0 - xi, xi], axis=1)
        facets = np.stack([np.arange(m), np.arange(1, m + 1)], axis=1)
        pieces = _pieces(lat, zone, facet, s1 - s0, np.array([t[1], -t[0]]), qp, qw, qf, 2)
        return lat, pieces, facets, point[None, :] + s_nodes[:, None] * t[None, :]
    if dim == 3:
        slope = np.tan(np.radians(rng.uniform(-50.0, 50.0)))
        z0 = rng.uniform(0.3, 0.7) - 0.5 * slope
        scale = np.sqrt(1.0 + slope**2)
        fx = _facet_lines(h * rng.uniform(0.7, 1.3), rng.uniform(0.0, h))
        fy = _facet_lines(h * rng.uniform(0.7, 1.3), rng.uniform(0.0, h))
        xz = (grid_lines - z0) / slope if slope != 0.0 else np.zeros(0)
        bx = np.unique(np.concatenate([fx, grid_lines, xz[(xz > 0.0) & (xz < 1.0)]]))
        by = np.unique(np.concatenate([fy, grid_lines]))
        X0, Y0 = np.meshgrid(bx[:-1], by[:-1], indexing="ij")
        X1, Y1 = np.meshgrid(bx[1:], by[1:], indexing="ij")
        X0, Y0, X1, Y1 = X0.ravel(), Y0.ravel(), X1.ravel(), Y1.ravel()
        zm = z0 + slope * 0.5 * (X0 + X1)
        inside = (zm > 0.0) & (zm < 1.0)
        X0, Y0, X1, Y1, zm = X0[inside], Y0[inside], X1[inside], Y1[inside], zm[inside]
        xm = np.stack([0.5 * (X0 + X1), 0.5 * (Y0 + Y1), zm], axis=1)
        zone = _zone_id(np.clip(np.floor(xm * n).astype(np.int64), 0, n - 1), n)
        nfx = fx.size - 1
        ix = np.clip(np.searchsorted(fx, xm[:, 0], side="right") - 1, 0, nfx - 1)
        iy = np.clip(np.searchsorted(fy, xm[:, 1], side="right") - 1, 0, fy.size - 2)
        facet = iy * nfx + ix
        gx = (X0[:, None] + (X1 - X0)[:, None] * np.repeat(GAUSS2, 2)[None, :]).ravel()
        gy = (Y0[:, None] + (Y1 - Y0)[:, None] * np.tile(GAUSS2, 2)[None, :]).ravel()
        qp = np.stack([gx, gy, z0 + slope * gx], axis=1)
        qw = np.repeat(0.25 * (X1 - X0) * (Y1 - Y0) * scale, 4)
        fq_x, fq_y = np.repeat(ix, 4), np.repeat(iy, 4)
        xi = (gx - fx[fq_x]) / (fx[fq_x + 1] - fx[fq_x])
        eta = (gy - fy[fq_y]) / (fy[fq_y + 1] - fy[fq_y])
        qf = np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), xi * eta, (1 - xi) * eta], axis=1)
        nx_nodes = fx.size
        jj, ii = np.divmod(np.arange(nfx * (fy.size - 1)), nfx)
        facets = np.stack([jj * nx_nodes + ii, jj * nx_nodes + ii + 1, (jj + 1) * nx_nodes + ii + 1,
                           (jj + 1) * nx_nodes + ii], axis=1)
        normal = np.array([-slope, 0.0, 1.0]) / scale
        pieces = _pieces(lat, zone, facet, (X1 - X0) * (Y1 - Y0) * scale, normal, qp, qw, qf, 4)
        NX, NY = np.meshgrid(fx, fy, indexing="xy")
        nodes = np.stack([NX.ravel(), NY.ravel(), z0 + slope * NX.ravel()], axis=1)
        return lat, pieces, facets, nodes
    raise ValueError(f"dim = {dim!r}: must be 2 or 3")


def _facet_lines(spacing: float, offset: float) -> np.ndarray:
    """Facet boundaries on [0, 1]: 0, offset + k spacing inside, 1 (first/last facets clipped)."""
    inner = offset + spacing * np.arange(int(np.ceil(1.0 / spacing)) + 1)
    return np.unique(np.concatenate([[0.0], inner[(inner > 0.0) & (inner < 1.0)], [1.0]]))


def conditioning_sweep(dim: int = 2, hs=HS, seeds=range(12), alpha: float = ALPHA, beta: float = BETA,
                       condition: str = "tied", cut=straight_cut) -> dict:
    """cond(H) for random straight cuts over grid widths h, stabilised (alpha, beta) and not
    (1/α = 0, β = 0), with Δt = 0.5 h (a CFL-like step, unit wave speed) and unit density
    (nodal masses h^dim).  Returns {"h": [...], "stabilised": {"max": [...], "median": [...],
    "all": [[...] per h]}, "unstabilised": {...}, "zones": [mean cut zones per h], "alpha", "beta"}."""
    out = {"dim": dim, "h": [float(h) for h in hs], "alpha": float(alpha), "beta": float(beta),
           "condition": condition, "zones": []}
    runs = {"stabilised": (alpha, beta), "unstabilised": (np.inf, 0.0)}
    conds = {k: [] for k in runs}
    for h in hs:
        per = {k: [] for k in runs}
        zones = []
        for seed in seeds:
            grid, pieces, facets, nodes = cut(dim, h, np.random.default_rng(seed))
            ns = len(nodes)
            ops = Operators.build(grid, pieces, facets, ns)
            zones.append(ops.n_zones)
            m_b = np.full(ops.bnodes.size, h**dim)
            m_f = np.full(ns, h**dim)
            for key, (a, b) in runs.items():
                per[key].append(condition_number(assemble(ops, m_b, m_f, 0.5 * h, condition, a, b).H))
        for key in runs:
            conds[key].append(per[key])
        out["zones"].append(float(np.mean(zones)))
    for key in runs:
        out[key] = {"all": conds[key], "max": [float(max(c)) for c in conds[key]],
                    "median": [float(np.median(c)) for c in conds[key]]}
    return out
