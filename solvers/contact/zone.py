"""Which surface nodes may take part in a step's contact: gather what is near, not the whole surface.

A body split over ranks has its surface spread over them too. Every rank solves the same contact
problem (explicit.py), so every rank needs the positions of the nodes whose facets may touch, and
only those. Each rank reduces its own surface nodes to one box per body (the nodes it owns); the
boxes of all ranks are gathered (P x bodies boxes: a few numbers per rank); a node of body a is
near when it lies within ``margin`` of a box of a body it is paired with (any rank's), every node
of a body in self contact is. Only the near nodes' states are then gathered and the operators built
on the facets all of whose nodes are near.

Why that loses no contact: two facets f (body a) and g (body b) are paired by the search when their
boxes grown by the capture distance c overlap (search.py), so along every axis a node of f lies
within c + e_f + c + e_g of a node of g (e: a facet's extent along the axis). With margin =
2 (c + e_max), e_max the largest facet extent, every node of f lies within margin of the box of
the rank owning that node of g: f's nodes are all near.

Cost per step and rank: O(its own surface nodes) for the boxes and the test, one gather of P x
bodies boxes, and the gather and the solve of the near nodes only (O(the contact zone), not
O(the surface)). A body against itself keeps its whole surface (the boxes cannot tell which of its
parts face each other).

Vectorised numpy: no loop over nodes or facets.
"""
from __future__ import annotations

import numpy as np

__all__ = ["body_boxes", "near_nodes", "facet_extent"]


def body_boxes(x: np.ndarray, node_body: np.ndarray, n_bodies: int) -> np.ndarray:
    """(n_bodies, 2, dim) [lo, hi] of the points x (n, dim) of each body (node_body (n,)); a body
    with no point here: lo = +inf, hi = -inf (contains nothing)."""
    x = np.asarray(x, dtype=np.float64)
    dim = x.shape[1] if x.ndim == 2 else 0
    lo = np.full((n_bodies, dim), np.inf)
    hi = np.full((n_bodies, dim), -np.inf)
    if len(x):
        np.minimum.at(lo, node_body, x)
        np.maximum.at(hi, node_body, x)
    return np.stack([lo, hi], axis=1)


def facet_extent(x: np.ndarray, facets: np.ndarray) -> float:
    """The largest extent of a facet (rows of indices into x) along any axis; 0 without facets."""
    if len(facets) == 0:
        return 0.0
    p = np.asarray(x, dtype=np.float64)[np.asarray(facets)]
    return float((p.max(axis=1) - p.min(axis=1)).max())


def near_nodes(x: np.ndarray, node_body: np.ndarray, pairs, boxes: np.ndarray, margin: float) -> np.ndarray:
    """(n,) bool: the points x (n, dim) of bodies node_body (n,) within ``margin`` (along every axis)
    of a box of a body they are paired with; boxes (n_boxes, n_bodies, 2, dim): every rank's
    body_boxes; pairs [(a, b), ...] body indices (a == b: self contact, all of a's points)."""
    x = np.asarray(x, dtype=np.float64)
    near = np.zeros(len(x), dtype=bool)
    for a, b in pairs:
        for me, other in ((a, b), (b, a)):
            mine = node_body == me
            if me == other:
                near |= mine
                continue
            lo = boxes[:, other, 0] - margin       # (n_boxes, dim)
            hi = boxes[:, other, 1] + margin
            ok = np.all(lo <= hi, axis=1)          # (a rank without any of the other body: no box)
            if not ok.any() or not mine.any():
                continue
            p = x[mine]
            inside = np.all((p[:, None, :] >= lo[None, ok]) & (p[:, None, :] <= hi[None, ok]), axis=2).any(axis=1)
            near[np.flatnonzero(mine)[inside]] = True
    return near
