"""The contact operators of the solvers that hold the whole mesh on every rank (quasi_static.py,
implicit_dynamic.py): each ``[contact]`` pair's facets on the global exterior surface, and the
stacked constraint operator B and stabilization J of every pair at given positions.

B is the pair's method's constraint operator (dual_pass.py for the default: G / 2), J its
stabilization with Puso & Solberg's gamma = alpha / E (the softer side's modulus: the stabilization
is weighed against the compliance that sets the pressures) and the median element edge h. Each
multiplier row has a key, its node offset by its pair (node + pair index x n_nodes: a body may be in
two pairs), which stays the same from one configuration to the next for the rows that exist in both.

The implicit dynamic step weighs J with its own system instead (dynamic_operators): alpha times the
median of diag(B A^-1 B^T) (A^-1 taken as the inverse diagonal of the step's matrix A = 2 M / dt^2 +
K) over the median of J_1's diagonal, J_1 the stabilization with gamma h = 1 (the explicit contact's
weighting, solvers/contact/explicit.py, with A for M / dt^2). With the static alpha / E the redundant
rows of the dual pass were held too loosely against A: the pressures of a steel bar impact scattered
by 30 % from one Newton iterate to the next and the active set cycled.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.lagrange.surface import exterior_facets
from solvers.sorted_ids import find_sorted

__all__ = ["GatheredContact"]


class GatheredContact:
    def __init__(self, cfg: dict, case: dict, points: np.ndarray, cells: np.ndarray, cell_type: str,
                 body_of_cell: np.ndarray, body_names: list):
        facets, facet_cell = exterior_facets(cells, cell_type, len(points), points)
        fbody = body_of_cell[facet_cell]
        bodies = case["lagrange"]["bodies"]
        self.method = cfg.get("method", "dual_pass_mortar")
        self.pairs = []   # (facets of a, facets of b (None: self contact), body a, the softer E)
        for a, b in cfg["pairs"]:
            ia, ib = body_names.index(a), body_names.index(b)
            e = min(case["materials"][bodies[k]["material"]]["youngs_modulus"] for k in (ia, ib))
            self.pairs.append((facets[fbody == ia], None if ia == ib else facets[fbody == ib], ia, e))
        edge = np.linalg.norm(points[cells[:, 1]] - points[cells[:, 0]], axis=1)
        self.h = float(np.median(edge))
        self.capture = float(cfg.get("capture", self.h))
        self.alpha = float(cfg.get("alpha", 1.0))

    def operators(self, x: np.ndarray):
        """(B (nm, n d), J (nm, nm), keys (nm,)) of every pair at positions x (n, d)."""
        return self._stacked(x, lambda c, b, e: c.stabilization(self.alpha / e, self.h))

    def dynamic_operators(self, x: np.ndarray, inv_stiffness: np.ndarray):
        """(B, J, keys) at positions x with J weighed against the dofs' inverse stiffness (n d,)
        (module docstring), each pair on its own rows."""
        def weighed(c, b, e):
            j1 = c.stabilization(1.0, 1.0)
            w = np.asarray(b.multiply(b) @ inv_stiffness).ravel()
            d = j1.diagonal()
            scale = (self.alpha * float(np.median(w[w > 0])) / float(np.median(d[d > 0]))
                     if np.any(w > 0) and np.any(d > 0) else 0.0)
            return scale * j1

        return self._stacked(x, weighed)

    def rows_at(self, x: np.ndarray, keys: np.ndarray, fallback) -> sp.csr_matrix:
        """B's rows of the given keys rebuilt at positions x (n, d), in the keys' order; a key the
        operator no longer has there (its node outside the capture, or projecting off the other side)
        keeps its row of ``fallback`` (same rows as keys). The implicit contact update's velocity
        changes at x_{n+1} take their rows from here: a row is torque-free about the positions it is
        built at, and only those (implicit_dynamic.py _contact_update)."""
        keys = np.asarray(keys, dtype=np.int64)
        if not len(keys):
            return sp.csr_matrix(fallback)
        B, _, k = self._stacked(x, lambda c, b, e: sp.csr_matrix((b.shape[0], b.shape[0])))
        if len(np.unique(k)) < len(k):   # (keys not a row's name here: keep the rows as they were)
            return sp.csr_matrix(fallback)
        order = np.argsort(k, kind="stable")
        at, found = find_sorted(k[order], keys)
        rows = sp.vstack([B[order[at[found]]], sp.csr_matrix(fallback)[~found]], format="csr")
        place = np.empty(len(keys), dtype=np.int64)   # each key's row in the stack
        place[found] = np.arange(int(found.sum()))
        place[~found] = int(found.sum()) + np.arange(int((~found).sum()))
        return rows[place]

    def _stacked(self, x: np.ndarray, stabilization):
        """Every pair's (B, stabilization(contact, B, E), keys) at positions x, stacked."""
        from solvers.contact import methods

        bs, js, keys = [], [], []
        for k, (seg_a, seg_b, _, e) in enumerate(self.pairs):
            c = methods.build(self.method, x, seg_a, seg_b, self.capture, self.capture)
            b = c.constraint_operator()
            bs.append(b)
            js.append(stabilization(c, b, e))
            ids = np.concatenate([q.nodes for q in c.passes]) if hasattr(c, "passes") else c.nodes
            keys.append(ids + k * len(x))
        return (sp.vstack(bs, format="csr"), sp.block_diag(js, format="csr"),
                np.concatenate(keys).astype(np.int64))
