"""Stand-ins for `coupling.grid.Grid` and `coupling.geometry.Pieces` (same fields), with analytic
cuts of straight polylines (2-D) and a tilted plane (3-D) through a uniform grid, for the operator,
solve and variant tests.  Test helpers: plain loops over facets are fine here (tiny meshes)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GAUSS2 = (np.array([-1.0, 1.0]) / np.sqrt(3.0) + 1.0) / 2.0  # 2-point Gauss on [0, 1], weights 1/2


@dataclass(frozen=True)
class Grid:
    lower: np.ndarray
    upper: np.ndarray
    cells: np.ndarray

    @classmethod
    def make(cls, lower, upper, cells) -> "Grid":
        return cls(np.asarray(lower, float), np.asarray(upper, float), np.asarray(cells, np.int64))

    @property
    def dim(self) -> int:
        return int(self.cells.size)

    @property
    def h(self) -> np.ndarray:
        return (self.upper - self.lower) / self.cells

    @property
    def zone_volume(self) -> float:
        return float(np.prod(self.h))

    def zone_index(self, zone_ids):
        z = np.asarray(zone_ids, np.int64)
        out = []
        for c in self.cells:
            out.append(z % c)
            z = z // c
        return np.stack(out, axis=-1)

    def zone_id(self, index):
        index = np.asarray(index, np.int64)
        zid = np.zeros(index.shape[:-1], np.int64)
        for a in reversed(range(self.dim)):
            zid = zid * self.cells[a] + index[..., a]
        return zid

    def node_id(self, index):
        index = np.asarray(index, np.int64)
        nid = np.zeros(index.shape[:-1], np.int64)
        for a in reversed(range(self.dim)):
            nid = nid * (self.cells[a] + 1) + index[..., a]
        return nid

    def corner_offsets(self) -> np.ndarray:
        c = np.arange(2**self.dim)
        return np.stack([(c >> a) & 1 for a in range(self.dim)], axis=1)

    def zone_nodes(self, zone_ids):
        idx = self.zone_index(zone_ids)
        return self.node_id(idx[:, None, :] + self.corner_offsets()[None, :, :])

    def n_nodes(self) -> int:
        return int(np.prod(self.cells + 1))

    def node_coords(self, node_ids):
        n = np.asarray(node_ids, np.int64)
        out = []
        for c in self.cells + 1:
            out.append(n % c)
            n = n // c
        return self.lower + np.stack(out, axis=-1) * self.h


@dataclass
class Pieces:
    zone: np.ndarray
    body: np.ndarray
    facet: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    qp: np.ndarray
    qw: np.ndarray
    qpiece: np.ndarray
    qf: np.ndarray
    qb: np.ndarray


def background_shape(grid: Grid, zone: int, x: np.ndarray) -> np.ndarray:
    """Multilinear shape functions of the zone's corners (zone_nodes order) at points x (n, dim)."""
    idx = grid.zone_index([zone])[0]
    xi = (x - (grid.lower + idx * grid.h)) / grid.h  # local coordinates in [0, 1]
    off = grid.corner_offsets()
    return np.prod(np.where(off[None, :, :] == 1, xi[:, None, :], 1.0 - xi[:, None, :]), axis=2)


def _assemble(grid, rows) -> Pieces:
    """rows: list of (zone, body, facet, area, normal, centroid, qp, qw, qf) per piece -> Pieces
    sorted by (zone, body, facet, first quadrature point)."""
    rows = sorted(rows, key=lambda r: (r[0], r[1], r[2], tuple(r[6][0])))
    qp = np.concatenate([r[6] for r in rows])
    nq = [len(r[7]) for r in rows]
    qpiece = np.repeat(np.arange(len(rows)), nq)
    qb = np.concatenate([background_shape(grid, r[0], r[6]) for r in rows])
    return Pieces(zone=np.array([r[0] for r in rows], np.int64), body=np.array([r[1] for r in rows], np.int64),
                  facet=np.array([r[2] for r in rows], np.int64), area=np.array([r[3] for r in rows]),
                  normal=np.array([r[4] for r in rows]), centroid=np.array([r[5] for r in rows]), qp=qp,
                  qw=np.concatenate([r[7] for r in rows]), qpiece=qpiece,
                  qf=np.concatenate([r[8] for r in rows]), qb=qb)


def cut_polyline(grid: Grid, nodes, closed: bool, body: int = 0):
    """Clip the segments of a 2-D polyline (nodes (n, 2), counter-clockwise if closed) by the grid.
    Returns (pieces, facets (nf, 2), n_surface_nodes).  Outward normal of a CCW polygon: (t_y, -t_x)."""
    nodes = np.asarray(nodes, float)
    n = len(nodes)
    facets = np.array([[i, (i + 1) % n] for i in range(n if closed else n - 1)], np.int64)
    rows = []
    for f, (a, b) in enumerate(facets):
        pa, pb = nodes[a], nodes[b]
        d = pb - pa
        length = float(np.hypot(*d))
        t = d / length
        normal = np.array([t[1], -t[0]])
        cuts = [0.0, 1.0]
        for ax in range(2):
            if d[ax] != 0.0:
                lines = grid.lower[ax] + grid.h[ax] * np.arange(grid.cells[ax] + 1)
                s = (lines - pa[ax]) / d[ax]
                cuts.extend(s[(s > 0.0) & (s < 1.0)])
        cuts = np.unique(cuts)
        for s0, s1 in zip(cuts[:-1], cuts[1:]):
            if s1 - s0 <= 0.0:
                continue
            mid = pa + 0.5 * (s0 + s1) * d
            idx = np.floor((mid - grid.lower) / grid.h).astype(np.int64)
            if np.any(idx < 0) or np.any(idx >= grid.cells):
                continue  # outside the grid
            zone = int(grid.zone_id(idx))
            sq = s0 + (s1 - s0) * GAUSS2
            qp = pa[None, :] + sq[:, None] * d[None, :]
            qw = np.full(2, 0.5 * (s1 - s0) * length)
            qf = np.stack([1.0 - sq, sq], axis=1)
            rows.append((zone, body, f, (s1 - s0) * length, normal, mid, qp, qw, qf))
    return _assemble(grid, rows), facets, n


def line_nodes(grid: Grid, point, angle: float, spacing: float):
    """Nodes of a straight open polyline through `point` at `angle`, clipped to the grid's box,
    at about `spacing` apart (the last facet ends on the box)."""
    point = np.asarray(point, float)
    t = np.array([np.cos(angle), np.sin(angle)])
    lo, hi = -np.inf, np.inf
    for ax in range(2):
        if t[ax] != 0.0:
            s = np.sort([(grid.lower[ax] - point[ax]) / t[ax], (grid.upper[ax] - point[ax]) / t[ax]])
            lo, hi = max(lo, s[0]), min(hi, s[1])
    m = max(int(np.ceil((hi - lo) / spacing)), 1)
    s = np.linspace(lo, hi, m + 1)
    return point[None, :] + s[:, None] * t[None, :]


def circle_nodes(center, radius, n):
    a = 2.0 * np.pi * np.arange(n) / n
    return np.asarray(center, float)[None, :] + radius * np.stack([np.cos(a), np.sin(a)], axis=1)


def cut_tilted_plane(grid: Grid, z0: float, slope: float, spacing, offset=(0.0, 0.0), body: int = 0):
    """The plane z = z0 + slope x over the grid's x-y extent, meshed by quads that are rectangles
    of `spacing` (sx, sy) in the x-y projection (shifted by `offset`), clipped by the zones.
    Node order of a quad: (x0,y0), (x1,y0), (x1,y1), (x0,y1); outward normal (-slope, 0, 1)/norm.
    Returns (pieces, facets (nf, 4), n_surface_nodes)."""
    sx, sy = spacing
    scale = np.sqrt(1.0 + slope**2)
    normal = np.array([-slope, 0.0, 1.0]) / scale
    xs = np.unique(np.clip(np.concatenate(([grid.lower[0]], grid.lower[0] + offset[0] + sx * np.arange(
        int(np.ceil((grid.upper[0] - grid.lower[0]) / sx)) + 2), [grid.upper[0]])), grid.lower[0], grid.upper[0]))
    ys = np.unique(np.clip(np.concatenate(([grid.lower[1]], grid.lower[1] + offset[1] + sy * np.arange(
        int(np.ceil((grid.upper[1] - grid.lower[1]) / sy)) + 2), [grid.upper[1]])), grid.lower[1], grid.upper[1]))
    nx = len(xs)
    node_xy = np.array([(x, y) for y in ys for x in xs])
    facets = np.array([[j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
                       for j in range(len(ys) - 1) for i in range(nx - 1)], np.int64)
    gx = grid.lower[0] + grid.h[0] * np.arange(grid.cells[0] + 1)
    gy = grid.lower[1] + grid.h[1] * np.arange(grid.cells[1] + 1)
    gz = grid.lower[2] + grid.h[2] * np.arange(grid.cells[2] + 1)
    xz = (gz - z0) / slope if slope != 0.0 else np.array([])
    rows = []
    for f, quad in enumerate(facets):
        x0, y0 = node_xy[quad[0]]
        x1, y1 = node_xy[quad[2]]
        cx = np.unique(np.concatenate(([x0, x1], gx[(gx > x0) & (gx < x1)], xz[(xz > x0) & (xz < x1)])))
        cy = np.unique(np.concatenate(([y0, y1], gy[(gy > y0) & (gy < y1)])))
        for a0, a1 in zip(cx[:-1], cx[1:]):
            for b0, b1 in zip(cy[:-1], cy[1:]):
                mid = np.array([(a0 + a1) / 2, (b0 + b1) / 2, z0 + slope * (a0 + a1) / 2])
                idx = np.floor((mid - grid.lower) / grid.h).astype(np.int64)
                if np.any(idx < 0) or np.any(idx >= grid.cells):
                    continue
                qx = a0 + (a1 - a0) * GAUSS2
                qy = b0 + (b1 - b0) * GAUSS2
                X, Y = np.meshgrid(qx, qy, indexing="ij")
                X, Y = X.ravel(), Y.ravel()
                qp = np.stack([X, Y, z0 + slope * X], axis=1)
                qw = np.full(4, 0.25 * (a1 - a0) * (b1 - b0) * scale)
                xi, eta = (X - x0) / (x1 - x0), (Y - y0) / (y1 - y0)
                qf = np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), xi * eta, (1 - xi) * eta], axis=1)
                rows.append((int(grid.zone_id(idx)), body, f, (a1 - a0) * (b1 - b0) * scale, normal, mid,
                             qp, qw, qf))
    return _assemble(grid, rows), facets, len(node_xy)


def two_masses(M1: float, M2: float):
    """One unit zone cut through its middle by one facet spanning it: B^b = 1/4 on each corner,
    B^f = 1/2 on each facet node.  Masses M1/4 per corner and M2/2 per facet node make every node
    of a side receive the same Δv: two point masses M1, M2 tied by one zone of area 1.
    Returns (ops, m_b, m_f)."""
    from orchestrator.coupling.operators import Operators

    g = Grid.make([0.0, 0.0], [1.0, 1.0], [1, 1])
    ops = Operators.build(g, *cut_polyline(g, np.array([[0.0, 0.5], [1.0, 0.5]]), closed=False))
    assert np.allclose(ops.Bb.toarray(), 0.25) and np.allclose(ops.Bf.toarray(), 0.5)
    return ops, np.full(4, M1 / 4), np.full(2, M2 / 2)
