"""Node-to-surface contact constraints, single and double pass: the classic methods the dual-pass
mortar is compared with (seed slide "Contact Problems": single pass fails the patch test, double
pass locks).

Single pass: every node A of the slave side a with a facing segment of the master side b below it
gets one constraint, its gap along the segment's outward unit normal n:

    g_A = n . (x_A - y(xi)),   y(xi) = (1 - xi) y0 + xi y1   the closest point of the segment,

so row A of G is +n on A, -(1 - xi) n on y0 and -xi n on y1 (linearised at the current positions)
and its multiplier is a nodal force, not a pressure. Double pass adds the same with the sides
swapped. Nothing weights a row by an area, so the forces a uniform pressure needs on non-matching
meshes are not representable: the patch test fails.

Vectorised numpy: candidate node-segment pairs from the binned search, the closest facing segment
of each node by a sort.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.contact.mortar_segments import FACING_COS
from solvers.contact.search import candidate_pairs, facet_boxes

__all__ = ["NodeToSurface"]

_XI_TOL = 1e-12  # a node above a master node projects onto both its segments: either will do


def _node_rows(x: np.ndarray, slave: np.ndarray, master: np.ndarray, capture: float, penetration: float):
    """(nodes, segment, xi, normal) of the slave nodes that have a facing master segment within
    [-penetration, capture] along its normal; the nearest one per node."""
    nodes = np.unique(slave)
    # the slave's nodal normals (sum of its segments' (dy, -dx)) to test facing
    d = x[slave[:, 1]] - x[slave[:, 0]]
    ns = np.zeros_like(x)
    np.add.at(ns, slave[:, 0], np.stack([d[:, 1], -d[:, 0]], 1))
    np.add.at(ns, slave[:, 1], np.stack([d[:, 1], -d[:, 0]], 1))
    box = np.stack([x[nodes] - capture, x[nodes] + capture], axis=1)
    pairs = candidate_pairs(box, facet_boxes(x, master, capture))
    a, s = nodes[pairs[:, 0]], pairs[:, 1]
    y0, y1 = x[master[s, 0]], x[master[s, 1]]
    t = y1 - y0
    length2 = np.einsum("ij,ij->i", t, t)
    xi = np.einsum("ij,ij->i", x[a] - y0, t) / length2
    n = np.stack([t[:, 1], -t[:, 0]], axis=1) / np.sqrt(length2)[:, None]
    dist = np.einsum("ij,ij->i", x[a] - y0, n)
    na = ns[a] / np.maximum(np.linalg.norm(ns[a], axis=1), 1e-300)[:, None]
    ok = ((xi >= -_XI_TOL) & (xi <= 1 + _XI_TOL) & (dist <= capture) & (dist >= -penetration)
          & (np.einsum("ij,ij->i", na, n) < -FACING_COS))
    a, s, xi, n, dist = a[ok], s[ok], np.clip(xi[ok], 0.0, 1.0), n[ok], dist[ok]
    order = np.lexsort((np.abs(dist), a))
    first = order[np.r_[True, a[order][1:] != a[order][:-1]]] if len(order) else order
    return a[first], s[first], xi[first], n[first]


class NodeToSurface:
    """Node-to-surface constraints of side a's nodes on side b (and b's on a with passes=2): the same
    interface as dual_pass.DualPassContact (constraint_operator, stabilization, forces, gaps)."""

    def __init__(self, points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, capture: float,
                 penetration: float | None = None, passes: int = 1):
        self.points = np.asarray(points, dtype=np.float64)
        pen = capture if penetration is None else penetration
        sides = [(seg_a, seg_b)] + ([(seg_b, seg_a)] if passes == 2 else [])
        self.rows = [_node_rows(self.points, np.asarray(s, np.int64), np.asarray(m, np.int64), capture, pen)
                     for s, m in sides]
        self.masters = [np.asarray(m, np.int64) for _, m in sides]
        self.nodes = np.concatenate([r[0] for r in self.rows])

    @property
    def n_multipliers(self) -> int:
        return len(self.nodes)

    def constraint_operator(self) -> sp.csr_matrix:
        """G (n_multipliers, 2 n): nodal gaps g = G x.ravel()."""
        rows, cols, vals = [], [], []
        off = 0
        for (a, s, xi, n), master in zip(self.rows, self.masters):
            k = off + np.arange(len(a))
            for node, w in ((a, np.ones(len(a))), (master[s, 0], -(1 - xi)), (master[s, 1], -xi)):
                for c in range(2):
                    rows.append(k)
                    cols.append(2 * node + c)
                    vals.append(w * n[:, c])
            off += len(a)
        shape = (off, 2 * len(self.points))
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)

    def stabilization(self, gamma: float, h: float) -> sp.csr_matrix:
        """None: the classic method has no stabilization (J = 0)."""
        return sp.csr_matrix((self.n_multipliers, self.n_multipliers))

    def gaps(self, x: np.ndarray | None = None) -> np.ndarray:
        x = self.points if x is None else np.asarray(x, dtype=np.float64)
        return self.constraint_operator() @ x.ravel()

    def forces(self, multipliers: np.ndarray) -> np.ndarray:
        return (self.constraint_operator().T @ np.asarray(multipliers, dtype=np.float64)).reshape(-1, 2)
