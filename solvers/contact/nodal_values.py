"""Per-node values of contact multipliers, shared by the explicit step (explicit.py) and the
quasi-static mode (solvers/lagrange/quasi_static.py): a row's weighted gap as a distance, and the
mean of the rows a node carries."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["constraint_weights", "nodal_mean"]


def constraint_weights(B: sp.spmatrix, dim: int) -> np.ndarray:
    """(nm,) what turns a row's weighted gap B x into a distance: half the sum over the row's nodes of
    |its coefficient| (each node's block is coefficient x normal). A mortar row A has -D on its own
    side and +M on the other, each summing to its area (B = G/2 of the dual pass: area / 2, single
    pass: the area); a node-to-surface row has +1 on the node and -1 shared by the segment: 1."""
    B = sp.csr_matrix(B)
    per_dof = B.multiply(B).tocsc()
    n_nodes = B.shape[1] // dim
    gather = sp.csr_matrix((np.ones(B.shape[1]), (np.arange(B.shape[1]), np.repeat(np.arange(n_nodes), dim))),
                           shape=(B.shape[1], n_nodes))
    node = (per_dof @ gather).tocsr()
    node.data = np.sqrt(node.data)
    w = 0.5 * np.asarray(node.sum(axis=1)).ravel()
    return np.where(w > 0, w, 1.0)


def nodal_mean(nodes: np.ndarray, values: np.ndarray, n: int, empty: float) -> np.ndarray:
    """(n,) the mean of ``values`` over the entries of each node in ``nodes``, ``empty`` where none."""
    total, count = np.zeros(n), np.zeros(n)
    np.add.at(total, nodes, values)
    np.add.at(count, nodes, 1.0)
    return np.divide(total, count, out=np.full(n, float(empty)), where=count > 0)
