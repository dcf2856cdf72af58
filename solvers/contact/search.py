"""Broad phase of the contact search: which facets of one surface may touch which of another.

Every facet is reduced to its axis-aligned bounding box, grown by the capture distance on every side
(a gap the step may close). The boxes of side b are registered in a uniform grid of bins no smaller
than the largest box, so that a box touches at most two bins along each axis (at most 4 in 2-D, 8
in 3-D); each box of side a looks in the bins it touches. The candidate pairs are the registered
ones whose boxes overlap, each counted in one bin only: the first bin both boxes touch (the
componentwise larger of their lowest bins), so no pair is found twice. Sorting the bin keys makes
the cost O(n log n) in the number of facets (linear in practice, the sort being a small share) plus
the number of candidates, against the O(n_a n_b) of testing all pairs; `immerse bench contact`
charts it.

Numba kernels: every explicit contact step searches (both passes of every pair), and on surfaces of
a few hundred facets the vectorised numpy version spent its time in the array calls' overhead (4.1
ms a search of 64 against 198 boxes in 3-D, 1,833 pairs; 20 % of cases/block_on_incline_3d's step).
Below ALL_PAIRS_MAX box pairs, testing every pair in one contiguous sweep is cheaper than binning
(32 us there; 0.6 ms at ALL_PAIRS_MAX): the same pairs, in the same order. Both kernels count their pairs, then fill them
(an output array grown inside the loop cost 0.25 us a pair in reference counting).
"""
from __future__ import annotations

import numpy as np

from numba import njit

__all__ = ["facet_boxes", "candidate_pairs"]


def facet_boxes(points: np.ndarray, facets: np.ndarray, capture: float = 0.0) -> np.ndarray:
    """Bounding boxes of facets, grown by ``capture`` on every side: shape (nf, 2, dim), [lo, hi]."""
    x = np.asarray(points, dtype=np.float64)[np.asarray(facets)]
    return np.stack([x.min(axis=1) - capture, x.max(axis=1) + capture], axis=1)


ALL_PAIRS_MAX = 1 << 18
"""Up to this many box pairs (n_a n_b) every pair is tested; beyond, the binned search."""


def candidate_pairs(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Pairs (i, j) of boxes a[i], b[j] that overlap (closed boxes: touching counts), shape (np, 2),
    sorted by i then j, each pair once.

    boxes: (n, 2, dim) arrays of [lo, hi] (facet_boxes). The bin size is the largest extent of any
    box along any axis, so no box spans more than two bins along an axis (three where round-off
    puts its ends just past two bin faces: the numpy version of this search, which assumed two,
    missed such pairs).
    """
    boxes_a = np.ascontiguousarray(boxes_a, dtype=np.float64)
    boxes_b = np.ascontiguousarray(boxes_b, dtype=np.float64)
    if len(boxes_a) == 0 or len(boxes_b) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if len(boxes_a) * len(boxes_b) <= ALL_PAIRS_MAX:
        return _all_pairs(boxes_a, boxes_b)
    return _binned_pairs(boxes_a, boxes_b)


@njit(cache=True)
def _all_pairs(boxes_a, boxes_b):
    """Every pair tested: the axes' bounds of b contiguous, one sweep over b per box of a."""
    na, nb, dim = boxes_a.shape[0], boxes_b.shape[0], boxes_a.shape[2]
    lo_b = np.empty((dim, nb))
    hi_b = np.empty((dim, nb))
    for j in range(nb):
        for k in range(dim):
            lo_b[k, j] = boxes_b[j, 0, k]
            hi_b[k, j] = boxes_b[j, 1, k]
    hit = np.ones((na, nb), np.bool_)
    for i in range(na):
        for k in range(dim):
            lo, hi = boxes_a[i, 0, k], boxes_a[i, 1, k]
            for j in range(nb):
                hit[i, j] &= (lo <= hi_b[k, j]) & (lo_b[k, j] <= hi)
    pairs = np.empty((hit.sum(), 2), np.int64)
    n = 0
    for i in range(na):
        for j in range(nb):
            if hit[i, j]:
                pairs[n, 0] = i
                pairs[n, 1] = j
                n += 1
    return pairs


@njit(cache=True)
def _bins(boxes, origin, size, shape, dim):
    """Each box's lowest bin and its bin count along each axis (unused axes: bin 0, count 1)."""
    n = boxes.shape[0]
    lo = np.zeros((n, 3), np.int64)
    span = np.ones((n, 3), np.int64)
    for i in range(n):
        for k in range(dim):
            lo[i, k] = min(int(np.floor((boxes[i, 0, k] - origin[k]) / size)), shape[k] - 1)
            hi = min(int(np.floor((boxes[i, 1, k] - origin[k]) / size)), shape[k] - 1)
            span[i, k] = hi - lo[i, k] + 1
    return lo, span


@njit(cache=True)
def _binned_pairs(boxes_a, boxes_b):
    na, nb, dim = boxes_a.shape[0], boxes_b.shape[0], boxes_a.shape[2]
    origin = np.empty(dim)
    top = np.empty(dim)
    size = 0.0
    for k in range(dim):
        origin[k] = min(boxes_a[:, 0, k].min(), boxes_b[:, 0, k].min())
        top[k] = max(boxes_a[:, 1, k].max(), boxes_b[:, 1, k].max())
        size = max(size, (boxes_a[:, 1, k] - boxes_a[:, 0, k]).max(), (boxes_b[:, 1, k] - boxes_b[:, 0, k]).max())
    span_all = 0.0
    for k in range(dim):
        span_all = max(span_all, top[k] - origin[k])
    if size <= 0.0:  # all boxes are points: any positive size works
        size = max(span_all, 1.0)
    # never more bins than boxes along an axis: sparse surfaces in a large box stay O(n) in memory
    size = max(size, span_all / (na + nb))
    shape = np.ones(3, np.int64)
    for k in range(dim):
        shape[k] = int(np.floor((top[k] - origin[k]) / size)) + 1
    lo_b, span_b = _bins(boxes_b, origin, size, shape, dim)
    lo_a, span_a = _bins(boxes_a, origin, size, shape, dim)
    # every bin a box of b touches, as (flat key, box), sorted by key
    count = 0
    for j in range(nb):
        count += span_b[j, 0] * span_b[j, 1] * span_b[j, 2]
    key_b = np.empty(count, np.int64)
    own_b = np.empty(count, np.int64)
    c = 0
    for j in range(nb):
        for d0 in range(span_b[j, 0]):
            for d1 in range(span_b[j, 1]):
                for d2 in range(span_b[j, 2]):
                    key_b[c] = ((lo_b[j, 0] + d0) * shape[1] + lo_b[j, 1] + d1) * shape[2] + lo_b[j, 2] + d2
                    own_b[c] = j
                    c += 1
    order = np.argsort(key_b, kind="mergesort")
    key_b = key_b[order]
    own_b = own_b[order]
    # two sweeps: count each box's pairs, then fill them in place
    per_a = np.zeros(na + 1, np.int64)
    pairs = np.empty((0, 2), np.int64)
    for sweep in range(2):
        for i in range(na):
            n = per_a[i]
            for d0 in range(span_a[i, 0]):
                for d1 in range(span_a[i, 1]):
                    for d2 in range(span_a[i, 2]):
                        c0, c1, c2 = lo_a[i, 0] + d0, lo_a[i, 1] + d1, lo_a[i, 2] + d2
                        key = (c0 * shape[1] + c1) * shape[2] + c2
                        p = np.searchsorted(key_b, key)
                        while p < count and key_b[p] == key:
                            j = own_b[p]
                            p += 1
                            # counted in the first bin both boxes touch only
                            if (c0 != max(lo_a[i, 0], lo_b[j, 0]) or c1 != max(lo_a[i, 1], lo_b[j, 1])
                                    or c2 != max(lo_a[i, 2], lo_b[j, 2])):
                                continue
                            hit = True
                            for k in range(dim):
                                if boxes_a[i, 0, k] > boxes_b[j, 1, k] or boxes_b[j, 0, k] > boxes_a[i, 1, k]:
                                    hit = False
                            if hit:
                                if sweep == 1:
                                    pairs[n, 0] = i
                                    pairs[n, 1] = j
                                n += 1
            if sweep == 0:
                per_a[i] = n
            else:
                pairs[per_a[i]:n, 1] = np.sort(pairs[per_a[i]:n, 1])  # by i (the sweep), then j
        if sweep == 0:
            total = 0
            for i in range(na):
                m = per_a[i]
                per_a[i] = total
                total += m
            per_a[na] = total
            pairs = np.empty((total, 2), np.int64)
    return pairs
