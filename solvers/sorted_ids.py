"""Sorted distinct values of an integer id array, by a sort: numpy 2's ``np.unique`` without
``return_inverse`` hashes instead, 3-4x slower on the few thousand ids per step of the coupled step's
lists (0.29 against 0.08 ms for 4000 ids here), and these run every step."""
from __future__ import annotations

import numpy as np


def sorted_unique(ids) -> np.ndarray:
    """The distinct values of ``ids`` (any shape), ascending (``np.unique(ids)``)."""
    s = np.sort(np.asarray(ids).ravel())
    if s.size == 0:
        return s
    keep = np.empty(s.size, dtype=bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]
