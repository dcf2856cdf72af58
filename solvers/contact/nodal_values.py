"""Per-node values of contact multipliers, shared by the explicit step (explicit.py) and the
quasi-static mode (solvers/lagrange/quasi_static.py): a row's weighted gap as a distance, and the
mean of the rows a node carries."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["constraint_weights", "nodal_mean", "row_sums", "scale_columns"]


def constraint_weights(B: sp.spmatrix, dim: int) -> np.ndarray:
    """(nm,) what turns a row's weighted gap B x into a distance: half the sum over the row's nodes of
    |its coefficient| (each node's block is coefficient x normal). A mortar row A has -D on its own
    side and +M on the other, each summing to its area (B = G/2 of the dual pass: area / 2, single
    pass: the area); a node-to-surface row has +1 on the node and -1 shared by the segment: 1."""
    B = sp.csr_matrix(B, copy=True)
    B.sum_duplicates()                       # (canonical: a row's columns sorted, each once)
    if B.nnz == 0:
        return np.ones(B.shape[0])
    row = np.repeat(np.arange(B.shape[0]), np.diff(B.indptr))
    node = B.indices // dim
    # a row's entries of one node are adjacent (columns dim * node + k, sorted): one run per (row, node)
    start = np.flatnonzero(np.r_[True, (row[1:] != row[:-1]) | (node[1:] != node[:-1])])
    size = np.sqrt(np.add.reduceat(B.data * B.data, start))
    w = 0.5 * np.bincount(row[start], weights=size, minlength=B.shape[0])
    return np.where(w > 0, w, 1.0)


def row_sums(A: sp.csr_matrix, values: np.ndarray) -> np.ndarray:
    """(rows,) the sums over each row of ``values``, one per stored entry of the csr matrix A."""
    return np.bincount(np.repeat(np.arange(A.shape[0]), np.diff(A.indptr)), weights=values, minlength=A.shape[0])


def scale_columns(A: sp.csr_matrix, s: np.ndarray) -> sp.csr_matrix:
    """A diag(s) for a csr A, without building diag(s) (a product of scipy matrices costs ~50 us of
    overhead more than this)."""
    out = A.copy()
    out.data = out.data * s[out.indices]
    return out


def nodal_mean(nodes: np.ndarray, values: np.ndarray, n: int, empty: float) -> np.ndarray:
    """(n,) the mean of ``values`` over the entries of each node in ``nodes``, ``empty`` where none."""
    total, count = np.zeros(n), np.zeros(n)
    np.add.at(total, nodes, values)
    np.add.at(count, nodes, 1.0)
    return np.divide(total, count, out=np.full(n, float(empty)), where=count > 0)
