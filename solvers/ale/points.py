"""Where the ALE solver evaluates the case's expressions (region and obstacle strings in x, y[, z]).

One code path for the solver and the orchestrator's check (``immerse check`` evaluates every
expression on exactly these points before anything launches):

* one material per zone: regions at the zone centres ``lower + (i + 1/2) h`` (grid.Block);
* several materials (or void) per zone: regions at ``k^dim`` points per zone, the centres of its
  ``k^dim`` equal sub-cells, ``k = fraction_samples`` (mixed.Materials.sample);
* obstacles: their region at ``k^dim`` sub-cell centres per zone, ``k = subsamples`` (blocked.py).

numpy only (the check imports this without the numba kernels).
"""
from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

DEFAULT_FRACTION_SAMPLES = {2: 8, 3: 4}
"""Sub-cells per axis of a zone for the volume fractions of several materials (64 points a zone)."""


def spacing(lower, upper, cells) -> np.ndarray:
    """Zone widths per axis, (upper - lower) / cells in float64."""
    return (np.asarray(upper, dtype=np.float64) - np.asarray(lower, dtype=np.float64)) \
        / np.asarray(cells, dtype=np.int64)


def axis_centres(lower_d: float, h_d: float, gi) -> np.ndarray:
    """Centre coordinates along one axis of the zones with global indices ``gi``."""
    return lower_d + (gi + 0.5) * h_d


def subcell_offsets(k: int, h) -> np.ndarray:
    """(k^dim, dim) offsets of the ``k^dim`` sub-cell centres of a zone from its centre (last axis
    fastest; k = 1: the centre itself)."""
    h = np.asarray(h, dtype=np.float64)
    dim = h.size
    off1 = ((np.arange(k) + 0.5) / k - 0.5)
    return np.stack(np.meshgrid(*([off1] * dim), indexing="ij"), axis=-1).reshape(-1, dim) * h


def several_materials(config: dict) -> bool:
    """Whether the regions put several materials (or a void one) in the grid: then fractions are
    sampled per zone and region expressions are evaluated at the sub-cell points."""
    used = list(dict.fromkeys(r["material"] for r in config["regions"]))
    return len(used) > 1 or config["materials"][used[0]]["eos"] == "void"


def fraction_samples(config: dict, dim: int) -> int:
    """Sub-cells per axis for the volume fractions of several materials."""
    return int(config.get("fraction_samples") or DEFAULT_FRACTION_SAMPLES[int(dim)])


def grid_points(lower, upper, cells, k: int | None = None, zones_per_chunk: int = 1 << 12,
                stride: int = 1) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The points of the grid, ``zones_per_chunk`` zones at a time: ``(ijk, points)`` with the global
    (i, j[, k]) of the chunk's zones, (nz, dim), and their points, (nz * k^dim, dim), zone by zone;
    ``k = None``: the zone centres (one point a zone), else the k^dim sub-cell centres.  ``stride``
    visits every stride-th zone only (in flat x-slowest order).  Memory stays bounded by the chunk
    whatever the grid."""
    cells = [int(c) for c in cells]
    total = math.prod(cells)
    step = max(1, int(zones_per_chunk)) * stride
    for start in range(0, total, step):
        ids = np.arange(start, min(start + step, total), stride, dtype=np.int64)
        ijk = np.stack(np.unravel_index(ids, cells), axis=1)
        yield ijk, _zone_points(lower, upper, cells, k, ijk)


def box_points(lower, upper, cells, box, k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(ijk, points)`` of the zones in the index box ((i0, i1), (j0, j1)[, (k0, k1)]) of the grid:
    grid_points' arithmetic, so the same values."""
    ijk = np.stack([g.ravel() for g in np.meshgrid(*(np.arange(a, b) for a, b in box), indexing="ij")], axis=1)
    return ijk, _zone_points(lower, upper, [int(c) for c in cells], k, ijk)


def _zone_points(lower, upper, cells, k, ijk) -> np.ndarray:
    """The points of the zones ``ijk`` (zone centres, or their k^dim sub-cell centres, zone by zone)."""
    dim = len(cells)
    lo = np.asarray(lower, dtype=np.float64)
    h = spacing(lower, upper, cells)
    centres = np.empty((len(ijk), dim))
    for d in range(dim):
        centres[:, d] = axis_centres(lo[d], h[d], ijk[:, d])
    if k is None:
        return centres
    offs = subcell_offsets(k, h)
    return (centres[:, None, :] + offs[None, :, :]).reshape(-1, dim)
