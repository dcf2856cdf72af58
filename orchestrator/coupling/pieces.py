"""The clipped pieces of the interface geometry (geometry.py): their type, the error of the
geometry, the grid planes' table and the growable arrays the compiled clippers and scans share."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from orchestrator.coupling.grid import Grid


class GeometryError(ValueError):
    pass


_SNAP = 64 * np.finfo(np.float64).eps


@dataclass
class Pieces:
    """The body surfaces clipped against the zones; piece arrays sorted by (zone, body, facet, part)
    (part: the triangle of a 3-D quad, 0 = (0,1,2), 1 = (0,2,3)); quadrature points grouped by piece
    in piece order."""

    zone: np.ndarray      # (np,) int64 global zone id
    body: np.ndarray      # (np,) int64 body of the parent facet
    facet: np.ndarray     # (np,) int64 parent facet (row of the facets array given)
    area: np.ndarray      # (np,) length (2-D) / area (3-D)
    normal: np.ndarray    # (np, dim) unit outward normal of the body (into the fluid)
    centroid: np.ndarray  # (np, dim)
    qp: np.ndarray        # (nq, dim) quadrature points
    qw: np.ndarray        # (nq,) weights; a piece's weights sum to its area
    qpiece: np.ndarray    # (nq,) int64 piece of each point (non-decreasing)
    qf: np.ndarray        # (nq, nv) foreground P1 shape functions of the parent facet's nodes
    qb: np.ndarray        # (nq, 2**dim) background shape functions of the piece's zone corners

    @property
    def dim(self) -> int:
        return int(self.normal.shape[1])

    @property
    def qstart(self) -> np.ndarray:
        """(np + 1,) offsets: the points of piece p are ``qstart[p]:qstart[p+1]``."""
        return np.searchsorted(self.qpiece, np.arange(self.zone.size + 1)).astype(np.int64)




def _planes(grid: Grid) -> np.ndarray:
    """(dim, max n + 1) the grid planes of every axis (padded with zeros): grid.Grid's table, or built
    for a grid-like object without one."""
    table = getattr(grid, "plane_table", None)
    if table is not None:
        return table
    out = np.zeros((grid.dim, int(grid.cells.max()) + 1))
    for e in range(grid.dim):
        out[e, : grid.cells[e] + 1] = grid.planes(e)
    return out



@njit(cache=True)
def _grow1(a, n):
    out = np.empty(n, a.dtype)
    out[: a.size] = a
    return out


@njit(cache=True)
def _grow2(a, n):
    out = np.empty((n, a.shape[1]), a.dtype)
    out[: a.shape[0], :] = a
    return out

