"""The fixed uniform Cartesian background grid of the ALE solver, as a descriptor.

The coupler never holds whole-grid arrays (its cost must grow with the interface, not the volume:
DESIGN.md, "The constraint solve"); it names zones, nodes and faces by global ids computed from
their integer coordinates:

* zone ``(i, j, k)``, ``0 <= i < nx`` ...:      id ``i + nx*(j + ny*k)`` (x fastest: the ALE output order);
* node ``(i, j, k)``, ``0 <= i <= nx`` ...:     id ``i + (nx+1)*(j + (ny+1)*k)``; node ``(i, j, k)`` is
  the lower corner of zone ``(i, j, k)``;
* corner ``c`` of a zone (``0 <= c < 2**dim``): offset ``(c & 1, c >> 1 & 1, c >> 2 & 1)`` from its lower
  node (bit d of c = offset along axis d, the tensor-product order of the bilinear/trilinear shape
  functions, not the VTK order);
* face normal to axis d: the lattice with ``n_d + 1`` planes along d and the zone counts across,
  ``(i, j, k)`` the face on plane ``i`` (d = 0) below zone ``(i, j, k)``;
  id ``i + (n0 + [d == 0])*(j + (n1 + [d == 1])*k)``.

Plane coordinates are computed one canonical way, ``X_k = lower + (upper - lower) * k / n``, by every
kernel that compares a position with a grid plane (geometry.py): with ``lower = 0`` the plane is the
correctly rounded ``k L / n``, so a body face typed at ``0.3`` on a ``[0, 1]`` grid of 10 zones lies
exactly on plane 3 (``0 + 3 * 0.1`` would not), and the end planes are ``lower`` and ``upper`` exactly.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


def corner_weights(xi: np.ndarray) -> np.ndarray:
    """(n, 2**dim) the bilinear / trilinear shape functions of a zone's corners (the corner order
    above) at local coordinates ``xi`` (n, dim) in [0, 1]."""
    dim = xi.shape[1]
    c = np.arange(2 ** dim)
    off = (c[:, None] >> np.arange(dim)[None, :]) & 1          # (2**dim, dim)
    return np.prod(np.where(off[None] == 1, xi[:, None, :], 1.0 - xi[:, None, :]), axis=2)


SNAP_ULPS = 8
"""Node coordinates within this many ulps (of the grid's coordinate scale) of a grid plane lie on it
(``Grid.snap``): a body face typed at a plane's value in other digits is still on the plane."""


class GridError(ValueError):
    pass


@dataclass(frozen=True, eq=False)
class Grid:
    """``cells`` zones per axis on the box ``[lower, upper]`` (2-D or 3-D)."""

    lower: np.ndarray   # (dim,) float64
    upper: np.ndarray   # (dim,) float64
    cells: np.ndarray   # (dim,) int64
    periodic: tuple = ()  # axes whose upper node plane is the lower one (node ids wrap there)

    def __post_init__(self):
        lower = np.array(self.lower, dtype=np.float64).reshape(-1)
        upper = np.array(self.upper, dtype=np.float64).reshape(-1)
        cells = np.array(self.cells, dtype=np.int64).reshape(-1)
        if lower.size not in (2, 3) or upper.size != lower.size or cells.size != lower.size:
            raise GridError(f"grid lower/upper/cells must all have 2 or 3 entries, got "
                            f"{lower.size}/{upper.size}/{cells.size}")
        if np.any(cells < 1) or not np.all(upper > lower) or not np.all(np.isfinite(lower + upper)):
            raise GridError(f"grid needs cells >= 1 and finite lower < upper, got lower={lower.tolist()}, "
                            f"upper={upper.tolist()}, cells={cells.tolist()}")
        periodic = np.zeros(lower.size, dtype=bool)
        periodic[np.asarray(self.periodic, dtype=np.int64)] = True
        for name, v in (("lower", lower), ("upper", upper), ("cells", cells), ("periodic", periodic)):
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    @classmethod
    def from_ale(cls, ale_cfg: dict) -> "Grid":
        """The grid of a normalised ``[ale]`` case table (``ale_cfg["grid"] = {lower, upper, cells}``;
        an axis whose ``boundaries`` are ``periodic`` wraps its node ids)."""
        g = ale_cfg["grid"]
        faces = ale_cfg.get("boundaries", {})
        axes = tuple(d for d, a in enumerate("xyz"[: len(g["cells"])]) if faces.get(f"{a}_lower") == "periodic")
        return cls(g["lower"], g["upper"], g["cells"], axes)

    # --- sizes ---------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return int(self.lower.size)

    @property
    def h(self) -> np.ndarray:
        """(dim,) zone widths."""
        return (self.upper - self.lower) / self.cells

    @property
    def zone_volume(self) -> float:
        return float(np.prod(self.h))

    @property
    def n_zones(self) -> int:
        return int(np.prod(self.cells))

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.cells + 1))

    def planes(self, d: int) -> np.ndarray:
        """(n_d + 1,) canonical coordinates of the grid planes normal to axis d (module docstring)."""
        k = np.arange(self.cells[d] + 1, dtype=np.float64)
        x = self.lower[d] + (self.upper[d] - self.lower[d]) * k / float(self.cells[d])
        x[-1] = self.upper[d]   # lower + (upper - lower) may round away from upper
        return x

    @functools.cached_property
    def plane_table(self) -> np.ndarray:
        """(dim, max n + 1) read-only: row d holds ``planes(d)``, padded with zeros (the form the
        geometry kernels take; computed once, the coupler asks every step)."""
        out = np.zeros((self.dim, int(self.cells.max()) + 1))
        for d in range(self.dim):
            out[d, : self.cells[d] + 1] = self.planes(d)
        out.setflags(write=False)
        return out

    def snap(self, x) -> np.ndarray:
        """Copy of node positions x (nn, dim) with coordinates within ``SNAP_ULPS`` ulps (of the
        grid's coordinate scale) of a canonical grid plane moved onto it."""
        xs = np.array(x, dtype=np.float64)
        if xs.ndim != 2 or xs.shape[1] != self.dim:   # (every axis at once below, ~3x cheaper per step)
            raise GridError(f"node positions must have shape (nn, {self.dim}), got {xs.shape}")
        eps = np.finfo(np.float64).eps
        n = self.cells
        k = np.clip(np.rint((xs - self.lower) / (self.upper - self.lower) * n), 0, n).astype(np.int64)
        X = self.plane_table[np.arange(self.dim), k]
        tol = SNAP_ULPS * eps * np.maximum(np.abs(self.lower), np.abs(self.upper))
        near = np.abs(xs - X) <= tol
        xs[near] = X[near]
        return xs

    def beyond(self, xs) -> np.ndarray:
        """(nn, dim) mask of the snapped node positions xs (``snap``) beyond the grid's box along each
        axis: the rule the coupler's geometry applies to a body's surface nodes and the case check to
        a body's mesh."""
        return (xs < self.lower) | (xs > self.upper)

    # --- ids -------------------------------------------------------------------------------------
    @staticmethod
    def _ids(ijk, shape) -> np.ndarray:
        ijk = np.asarray(ijk, dtype=np.int64)
        ids = np.zeros(ijk.shape[:-1], dtype=np.int64)
        for d in range(len(shape) - 1, -1, -1):
            ids = ids * shape[d] + ijk[..., d]
        return ids

    @staticmethod
    def _ijk(ids, shape) -> np.ndarray:
        ids = np.asarray(ids, dtype=np.int64)
        out = np.empty(ids.shape + (len(shape),), dtype=np.int64)
        rest = ids
        for d in range(len(shape)):
            out[..., d] = rest % shape[d]
            rest = rest // shape[d]
        return out

    def zone_ids(self, ijk) -> np.ndarray:
        """Global zone ids of integer zone coordinates ``ijk`` (..., dim)."""
        return self._ids(ijk, self.cells)

    def zone_ijk(self, ids) -> np.ndarray:
        """(..., dim) integer coordinates of global zone ids."""
        return self._ijk(ids, self.cells)

    def node_ids(self, ijk) -> np.ndarray:
        return self._ids(ijk, self.cells + 1)

    def node_ijk(self, ids) -> np.ndarray:
        return self._ijk(ids, self.cells + 1)

    def face_shape(self, d: int) -> np.ndarray:
        """(dim,) lattice of the faces normal to axis d: ``n_d + 1`` planes along d, zones across."""
        return self.cells + (np.arange(self.dim) == d)

    def face_ids(self, d: int, ijk) -> np.ndarray:
        """Global ids of the faces normal to axis d at lattice coordinates ``ijk`` (..., dim)."""
        return self._ids(ijk, self.face_shape(d))

    def face_ijk(self, d: int, ids) -> np.ndarray:
        return self._ijk(ids, self.face_shape(d))

    def zone_nodes(self, zone_ids) -> np.ndarray:
        """(n, 2**dim) node ids of the zones' corners; corner c has offset (c&1, c>>1&1, c>>2&1).
        Along a periodic axis the upper plane's nodes are the lower plane's (one node, one mass, one
        velocity in the ALE solver: the upper plane is its image), so a zone of the last layer names
        the nodes of plane 0 and the multipliers' impulses land on the node the solver owns."""
        ijk = self.zone_ijk(np.asarray(zone_ids, dtype=np.int64).reshape(-1))
        c = np.arange(2 ** self.dim)
        offsets = (c[:, None] >> np.arange(self.dim)[None, :]) & 1          # (2**dim, dim)
        nijk = ijk[:, None, :] + offsets[None, :, :]
        if self.periodic.any():
            nijk = np.where(self.periodic & (nijk == self.cells), 0, nijk)
        return self.node_ids(nijk)

    def neighbours(self, zone_ids):
        """Face-adjacent pairs among a set of zones: ``(pairs (m, 2), axis (m,))``, ``pairs[:, 0]`` the
        lower zone along ``axis``, sorted by (lower zone, axis); duplicates in ``zone_ids`` are ignored."""
        z = np.unique(np.asarray(zone_ids, dtype=np.int64))
        ijk = self.zone_ijk(z)
        lo, hi, ax = [], [], []
        stride = 1
        for d in range(self.dim):
            cand = z + stride
            pos = np.searchsorted(z, cand)
            found = (ijk[:, d] < self.cells[d] - 1) & (pos < z.size)
            found[found] = z[pos[found]] == cand[found]
            lo.append(z[found])
            hi.append(cand[found])
            ax.append(np.full(int(found.sum()), d, dtype=np.int64))
            stride *= int(self.cells[d])
        lo, hi, ax = np.concatenate(lo), np.concatenate(hi), np.concatenate(ax)
        order = np.lexsort((ax, lo))
        return np.stack([lo[order], hi[order]], axis=1), ax[order]
