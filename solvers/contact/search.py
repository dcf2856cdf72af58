"""Broad phase of the contact search: which facets of one surface may touch which of another.

Every facet is reduced to its axis-aligned bounding box, grown by the capture distance on every side
(a gap the step may close). The boxes of side b are registered in a uniform grid of bins no smaller
than the largest box, so that a box touches at most two bins along each axis (at most 4 in 2-D, 8
in 3-D); each box of side a looks in the bins it touches. The candidate pairs are the registered
ones whose boxes overlap. Sorting the bin keys makes the cost O(n log n) in the number of facets
(linear in practice, the sort being a small share) plus the number of candidates, against the
O(n_a n_b) of testing all pairs; `immerse bench contact` charts it.

Everything is vectorised numpy: no loop over facets.
"""
from __future__ import annotations

import numpy as np

__all__ = ["facet_boxes", "candidate_pairs"]


def facet_boxes(points: np.ndarray, facets: np.ndarray, capture: float = 0.0) -> np.ndarray:
    """Bounding boxes of facets, grown by ``capture`` on every side: shape (nf, 2, dim), [lo, hi]."""
    x = np.asarray(points, dtype=np.float64)[np.asarray(facets)]
    return np.stack([x.min(axis=1) - capture, x.max(axis=1) + capture], axis=1)


def _bin_range(boxes: np.ndarray, origin: np.ndarray, size: float):
    lo = np.floor((boxes[:, 0] - origin) / size).astype(np.int64)
    hi = np.floor((boxes[:, 1] - origin) / size).astype(np.int64)
    return lo, hi


def _touched_bins(lo: np.ndarray, hi: np.ndarray, shape: np.ndarray):
    """(box index, flat bin key) for every bin a box touches (at most 2 per axis)."""
    n, dim = lo.shape
    keys = []
    owners = []
    for corner in range(1 << dim):  # the 2^dim corners of a box's bin range (dim <= 3)
        off = np.array([(corner >> k) & 1 for k in range(dim)], dtype=np.int64)
        b = lo + off
        ok = np.all(b <= hi, axis=1)
        flat = np.ravel_multi_index(tuple(b[ok].T), tuple(shape))
        keys.append(flat)
        owners.append(np.flatnonzero(ok))
    return np.concatenate(owners), np.concatenate(keys)


def candidate_pairs(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Pairs (i, j) of boxes a[i], b[j] that overlap (closed boxes: touching counts), shape (np, 2),
    sorted by i then j, each pair once.

    boxes: (n, 2, dim) arrays of [lo, hi] (facet_boxes). The bin size is the largest extent of any
    box along any axis, so no box spans more than two bins along an axis.
    """
    boxes_a = np.asarray(boxes_a, dtype=np.float64)
    boxes_b = np.asarray(boxes_b, dtype=np.float64)
    if len(boxes_a) == 0 or len(boxes_b) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    dim = boxes_a.shape[2]
    both = np.concatenate([boxes_a, boxes_b])
    origin = both[:, 0].min(axis=0)
    size = float((both[:, 1] - both[:, 0]).max())
    span = float((both[:, 1] - origin).max())
    if size <= 0.0:  # all boxes are points: any positive size works
        size = max(span, 1.0)
    # never more bins than boxes along an axis: sparse surfaces in a large box stay O(n) in memory
    size = max(size, span / max(len(both), 1))
    shape = np.floor((both[:, 1] - origin).max(axis=0) / size).astype(np.int64) + 1
    lo_b, hi_b = _bin_range(boxes_b, origin, size)
    own_b, key_b = _touched_bins(lo_b, hi_b, shape)
    order = np.argsort(key_b, kind="stable")
    own_b, key_b = own_b[order], key_b[order]
    lo_a, hi_a = _bin_range(boxes_a, origin, size)
    own_a, key_a = _touched_bins(lo_a, hi_a, shape)
    start = np.searchsorted(key_b, key_a, side="left")
    stop = np.searchsorted(key_b, key_a, side="right")
    count = stop - start
    i = np.repeat(own_a, count)
    # the positions start..stop-1 of every query, flattened
    first = np.repeat(start - np.cumsum(count) + count, count)
    j = own_b[first + np.arange(count.sum())]
    a, b = boxes_a[i], boxes_b[j]
    hit = np.all((a[:, 0] <= b[:, 1]) & (b[:, 0] <= a[:, 1]), axis=1)
    # two shared bins give a pair twice: one flat key per pair, sorted (by i, then j) and deduplicated
    key = np.sort(i[hit] * len(boxes_b) + j[hit])
    key = key[np.r_[True, key[1:] != key[:-1]]] if len(key) else key
    return np.stack([key // len(boxes_b), key % len(boxes_b)], axis=1)
