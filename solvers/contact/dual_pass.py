"""The stabilized dual-pass mortar operators of 2-D and 3-D contact between two surfaces, or a surface
and itself (Puso & Solberg, "A dual pass mortar approach for unbiased constraints and self contact",
CMAME 367 (2020); seed slides "Stabilized two pass mortar approach" and "implementation").

Each side is the non-mortar side of one pass and carries its own nodal multipliers (normal contact
pressures p >= 0 at the nodes with contact area). With the mortar integrals D and M of a pass
(mortar_segments.py for 2-D segments, mortar_facets.py for 3-D quadrilateral facets) and the unit
nodal normal n_A of its non-mortar side (length- or area-weighted average of the outward normals of
the facets at A that have contact area in the pass):

    weighted gap   g_A = n_A . (sum_C M_AC x_C - sum_B D_AB x_B)      (> 0: apart)
                   g = G x, G row A = n_A (x) (M_A - D_A)

which is the seed's g_A = n_A . integral of phi_A (x^1 - x^2) with n_A pointing into side 1. The
constraint form is the average of the two passes,

    b(mu, u) = 1/2 (mu^a . G^ab u + mu^b . G^ba u),     B = G / 2,

so no side is preferred (the bias of single-pass mortar) and the nodal forces of pressures p are
f = B^T p (pushing the sides apart). Each pass's rows balance (sum_C M_AC = sum_B D_AB), so the
forces sum to zero to round-off. The two passes together have twice the multipliers the interface
can resolve; the stabilization penalises the jump between the two sides' tractions (lambda = p n:
lambda^a + lambda^b ~ (p^a - p^b) n^a on facing sides). Per pass a -> b it is the full jump form on
that pass's own overlap,

    j_ab(mu, lambda) = (gamma h / 2) integral over Gamma^ab of
                       (mu^a n^a phi^a + mu^b n^b phi^b) . (lambda^a n^a phi^a + lambda^b n^b phi^b),
    gamma = alpha / E,

with side a's multipliers (this pass's) interpolated by a's shape functions and side b's (those of
the other pass, at the mortar nodes C) by b's at the projected points; the dual pass averages its
passes, J = (j_ab + j_ba) / 2, as B = G / 2 does. In matrix form pass a -> b contributes

    (gamma h / 4) [[D_AB n_A.n_B,  M_AC n_A.n_C ],
                   [M_AC n_C.n_A,  E_CC' n_C.n_C']],   E_CC' = integral over Gamma^ab of phi^b_C phi^b_C'

(E from the same kernels as D and M). A node C with no multiplier in the other pass (no contact
area of its own) drops its rows and columns: its pressure is taken as 0 there. Each block is
sum over quadrature points w_q v_q v_q^T with v_q the functions phi n of both sides at that point (a
Gram matrix on the pass's own quadrature), so J is symmetric positive semidefinite by construction,
whatever the meshes: the explicit step's multiplier system dt^2 B M^-1 B^T + J stays positive
(semi)definite and the active set (kkt.py) cannot cycle on an indefinite J. (The earlier form,
rows of a's multipliers only, integral of mu^a . (lambda^a + lambda^b) per pass, was not symmetric
on non-matching or curved meshes and its symmetric part could be indefinite: in the crushed ring's
self contact its smallest eigenvalue was -7e-3 of its largest.) Equal pressures on facing flat sides
still give lambda^a + lambda^b = 0 pointwise, so J p = 0: the patch test is unchanged.

Self contact is one pass of a surface against itself, its own neighbours excluded: every facing pair
then appears once in each direction, which is the dual pass. Its J is the same formula with one
multiplier set (C's multiplier is of the same pass): the pass's Gram matrix over all its pairs, each
direction once, times gamma h / 4, which is what two separate bodies give.

The dimension follows the facets: (n, 2) segments in 2-D, (n, 4) quadrilaterals in 3-D (points
(n, 3)); every operator above is the same in both, with dim unknowns per node (columns
dim * node + k). Only the tangent operator of the friction is 2-D (one tangent per node).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from solvers.contact.mortar_facets import facet_pair_integrals
from solvers.contact.mortar_segments import segment_pair_integrals
from solvers.contact.search import candidate_pairs, facet_boxes

__all__ = ["MortarPass", "mortar_pass", "DualPassContact", "nodal_normals"]


def nodal_normals(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Unit normal at every node of ``points`` (zero at nodes no facet has): the sum of the outward
    facet normals times length (2-D segments: (dy, -dx)) or times area (3-D quadrilaterals
    (a, b, c, d): (c - a) x (d - b) / 2, the integral of the normal over the bilinear facet,
    lagrange.surface.facet_area_vectors) of the facets at the node, normalised."""
    x = np.asarray(points, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.int64)
    if segments.shape[1] == 2:
        d = x[segments[:, 1]] - x[segments[:, 0]]
        nl = np.stack([d[:, 1], -d[:, 0]], axis=1)
    else:
        f = x[segments]
        nl = 0.5 * np.cross(f[:, 2] - f[:, 0], f[:, 3] - f[:, 1])
    n = np.zeros_like(x)
    for k in range(segments.shape[1]):  # the facet's 2 or 4 corners
        np.add.at(n, segments[:, k], nl)
    norm = np.linalg.norm(n, axis=1)
    return np.divide(n, norm[:, None], out=np.zeros_like(n), where=norm[:, None] > 0)


def _tangent(n: np.ndarray) -> np.ndarray:
    """The tangent t = (n_y, -n_x) of unit normals n (n, 2)."""
    return np.stack([n[:, 1], -n[:, 0]], axis=1)


def _tangents_3d(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents t1, t2 of unit normals n (n, 3), (t1, t2, n) right-handed: t1 = e x n / |e x n|
    with e the coordinate axis least aligned with n (|e x n| >= sqrt(2/3): never near 0), t2 = n x t1.
    Any orthonormal pair serves: the Coulomb cone is isotropic (friction.py)."""
    e = np.zeros_like(n)
    e[np.arange(len(n)), np.argmin(np.abs(n), axis=1)] = 1.0
    t1 = np.cross(e, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def _summed(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n_cols: int) -> tuple:
    """The triplets with the duplicates of each (row, column) summed, in (row, column) order: every
    entry of D, M and E is then one number, whichever order the pairs came in (the two passes of a
    dual pass give equal operators with the sides swapped, bit for bit)."""
    if len(rows) == 0:
        return rows, cols, vals
    key = rows * n_cols + cols
    order = np.argsort(key, kind="stable")
    key = key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    return rows[order][start], cols[order][start], np.add.reduceat(vals[order], start)


def _csr(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
    """One csr matrix from triplets (duplicates summed)."""
    return sp.csr_matrix((vals, (rows, cols)), shape=shape)


@dataclass
class MortarPass:
    """One pass with side a as the non-mortar side: its multiplier nodes and integrals.

    nodes (nm,) sorted node ids of side a with contact area; normals (nm, dim) unit nodal normals of
    side a's facets with contact area, at ``nodes``; area (nm,) = row sums of D = integral of phi_A
    over the contact area; n_points: the number of nodes the ids count.
    d, m: (row, column, value) triplets of D_AB and M_AC (module docstring), rows the multiplier index
    (into ``nodes``), columns global node ids, each (row, column) once; e: E_CC' of the mortar nodes,
    rows and columns global node ids. The operators are assembled from the triplets once (each
    scipy.sparse construction costs ~50 us of overhead, more than a small contact's arithmetic: the
    explicit step of a block on an incline spent 3/4 of its time building matrices); D, M and E as csr
    matrices on demand.
    """
    nodes: np.ndarray
    normals: np.ndarray
    area: np.ndarray
    n_points: int
    d: tuple
    m: tuple
    e: tuple

    @property
    def D(self) -> sp.csr_matrix:
        """(nm, n_points) csr."""
        return _csr(*self.d, (len(self.nodes), self.n_points))

    @property
    def M(self) -> sp.csr_matrix:
        """(nm, n_points) csr."""
        return _csr(*self.m, (len(self.nodes), self.n_points))

    @property
    def E(self) -> sp.csr_matrix:
        """(n_points, n_points) csr."""
        return _csr(*self.e, (self.n_points, self.n_points))

    def index_of(self, node_ids: np.ndarray) -> np.ndarray:
        """Multiplier index of each node id (-1 where the node has no contact area in this pass)."""
        node_ids = np.asarray(node_ids)
        if len(self.nodes) == 0:
            return np.full(node_ids.shape, -1, dtype=np.int64)
        k = np.searchsorted(self.nodes, node_ids).clip(max=len(self.nodes) - 1)
        return np.where(self.nodes[k] == node_ids, k, -1)


def mortar_pass(points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, capture: float,
                penetration: float | None = None, self_contact: bool = False,
                pairs: np.ndarray | None = None) -> MortarPass:
    """The pass a -> b: candidate pairs within ``capture`` (search.py), their integrals, assembled.

    seg_a, seg_b: (n, 2) segments with points (n, 2), or (n, 4) quadrilateral facets with points
    (n, 3) (mortar_segments.py or mortar_facets.py integrates them). A facet of b pairs with one of a
    where it lies in front of it within ``capture`` or behind it by at most ``penetration`` (default:
    capture), somewhere on their overlap.

    self_contact: seg_b is seg_a; pairs of a facet with itself or a neighbour (a shared node) are
    left out.

    pairs: the candidate pairs when known (the other pass's, swapped: DualPassContact), else searched.
    """
    x = np.asarray(points, dtype=np.float64)
    n = len(x)
    seg_a = np.asarray(seg_a, dtype=np.int64)
    seg_b = np.asarray(seg_b, dtype=np.int64)
    k = seg_a.shape[1]  # nodes per facet: 2 (segments, 2-D) or 4 (quadrilaterals, 3-D)
    if seg_b.shape[1] != k or (k, x.shape[1]) not in ((2, 2), (4, 3)):
        raise ValueError(f"mortar_pass: facets of {k} and {seg_b.shape[1]} nodes with {x.shape[1]}-D points "
                         "(2-D: segments of 2 nodes; 3-D: quadrilaterals of 4)")
    if pairs is None:
        pairs = candidate_pairs(facet_boxes(x, seg_a, capture), facet_boxes(x, seg_b, capture))
    if self_contact and len(pairs):
        a, b = seg_a[pairs[:, 0]], seg_b[pairs[:, 1]]
        shared = (a[:, :, None] == b[:, None, :]).any(axis=(1, 2))
        pairs = pairs[~shared]
    integrals = segment_pair_integrals if k == 2 else facet_pair_integrals
    d, m, overlap, e = integrals(x, seg_a, seg_b, pairs, capture, capture if penetration is None else penetration,
                                 mortar_mass=True)
    keep = overlap > 0.0
    pairs, d, m, e = pairs[keep], d[keep], m[keep], e[keep]
    rows = np.repeat(seg_a[pairs[:, 0]], k, axis=1).ravel()           # A of [A, B] for B in seg_a
    d_cols = np.tile(seg_a[pairs[:, 0]], (1, k)).ravel()
    m_cols = np.tile(seg_b[pairs[:, 1]], (1, k)).ravel()
    d, m = d.ravel(), m.ravel()
    area = np.bincount(rows, weights=d, minlength=n)
    nodes = np.flatnonzero(area > 0.0)
    on = area[rows] > 0.0                                              # the rows of nodes with contact area
    local = np.searchsorted(nodes, rows[on])
    e_trip = _summed(np.repeat(seg_b[pairs[:, 1]], k, axis=1).ravel(), m_cols, e.ravel(), n)
    # the normals of the contact surface: from the segments with contact area only (a block's corner
    # would otherwise lean towards its side face and push sideways: the patch test fails)
    normals = nodal_normals(x, seg_a[np.unique(pairs[:, 0])])
    return MortarPass(nodes=nodes, normals=normals[nodes], area=area[nodes], n_points=n,
                      d=_summed(local, d_cols[on], d[on], n), m=_summed(local, m_cols[on], m[on], n), e=e_trip)


class DualPassContact:
    """The dual-pass operators of two surfaces (or one against itself) at one configuration.

    points (n, dim) of all bodies; seg_a, seg_b outward facets of the two sides, (n_s, 2) segments in
    2-D or (n_s, 4) quadrilaterals in 3-D (seg_b None: self contact of seg_a); capture: the search
    distance (a gap larger than it is not paired);
    penetration: the deepest overlap still paired (default: capture; keep it below the bodies'
    thickness, or a thin body's far side pairs).
    Multipliers are numbered pass by pass: pass a -> b's nodes, then pass b -> a's.
    """

    def __init__(self, points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray | None, capture: float,
                 penetration: float | None = None):
        self.points = np.asarray(points, dtype=np.float64)
        if seg_b is None:
            self.passes = (mortar_pass(self.points, seg_a, seg_a, capture, penetration, self_contact=True),)
        else:
            # one search for both passes: box overlap is symmetric, so pass b -> a's candidates are
            # pass a -> b's swapped, put in candidate_pairs' order (by the first index, then the
            # second): the same array its own search returns, so the same sums in the same order
            ab = candidate_pairs(facet_boxes(self.points, seg_a, capture), facet_boxes(self.points, seg_b, capture))
            ba = ab[np.lexsort((ab[:, 0], ab[:, 1]))][:, ::-1]
            self.passes = (mortar_pass(self.points, seg_a, seg_b, capture, penetration, pairs=ab),
                           mortar_pass(self.points, seg_b, seg_a, capture, penetration, pairs=np.ascontiguousarray(ba)))
        self.offsets = np.cumsum([0] + [len(p.nodes) for p in self.passes])

    @property
    def n_multipliers(self) -> int:
        return int(self.offsets[-1])

    def gap_operator(self) -> sp.csr_matrix:
        """G (n_multipliers, dim n): weighted gaps g = G x.ravel() (x (n, dim) positions)."""
        return self._directed_operator(lambda n: n)

    def _differences(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per pass the triplets of M - D (rows: multiplier index in the pass; columns: node ids),
        gathered once for every directed operator of this configuration."""
        if getattr(self, "_diff", None) is None:
            self._diff = [(np.concatenate([p.m[0], p.d[0]]), np.concatenate([p.m[1], p.d[1]]),
                           np.concatenate([p.m[2], -p.d[2]])) for p in self.passes]
        return self._diff

    def _directed_operator(self, *directions, factor: float = 1.0) -> sp.csr_matrix:
        """Rows d_A (x) (M_A - D_A) with d_A = direction(normals) of each pass: column dim * C + k
        holds (M_AC - D_AC) d_A[k]. With several directions, each multiplier's rows follow one
        another (row len(directions) A + j along directions[j]). ``factor``: a power of two the
        entries are scaled by (exactly, before their sums: the same as scaling the matrix)."""
        dim, nd = self.points.shape[1], len(directions)
        rows, cols, vals = [], [], []
        for off, p, (r, c, v) in zip(self.offsets, self.passes, self._differences()):
            v = v * factor if factor != 1.0 else v
            for j, direction in enumerate(directions):
                nrm = direction(p.normals)[r]
                for k in range(dim):
                    rows.append(nd * (r + off) + j)
                    cols.append(dim * c + k)
                    vals.append(v * nrm[:, k])
        if not rows:
            return sp.csr_matrix((nd * self.n_multipliers, dim * len(self.points)))
        return _csr(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals),
                    (nd * self.n_multipliers, dim * len(self.points)))

    def constraint_operator(self) -> sp.csr_matrix:
        """B = G / 2, the dual pass's b(mu, u) = mu . B u (both passes averaged)."""
        return self._directed_operator(lambda n: n, factor=0.5)

    def _tangential(self, factor: float = 1.0) -> sp.csr_matrix:
        """G with tangents in place of the normals: in 2-D one row per multiplier along t_A = (n_y,
        -n_x); in 3-D two, along t1_A and t2_A, interleaved (friction.py's blocks)."""
        if self.points.shape[1] == 2:
            return self._directed_operator(_tangent, factor=factor)
        tangents = {}   # (both tangents of a pass's normals from one call)

        def tangent(k):
            return lambda n: tangents.setdefault(id(n), _tangents_3d(n))[k]

        return self._directed_operator(tangent(0), tangent(1), factor=factor)

    def tangent_operator(self) -> sp.csr_matrix:
        """T: the constraint operator with each multiplier's tangent(s) in place of its normal (the
        weighted tangential slip of the friction, friction.py): (n_multipliers (dim - 1), dim n)."""
        return self._tangential(factor=0.5)

    def gaps(self, x: np.ndarray | None = None) -> np.ndarray:
        """Weighted gaps g_A of every multiplier at positions x (default: the operators' own)."""
        x = self.points if x is None else np.asarray(x, dtype=np.float64)
        return self.gap_operator() @ x.ravel()

    def forces(self, pressures: np.ndarray) -> np.ndarray:
        """Nodal forces (n, dim) of multiplier pressures: B^T p."""
        dim = self.points.shape[1]
        return (self.constraint_operator().T @ np.asarray(pressures, dtype=np.float64)).reshape(-1, dim)

    def stabilization(self, gamma: float, h: float) -> sp.csr_matrix:
        """J (n_multipliers, n_multipliers): j(mu, lambda) = mu . J lambda, symmetric positive
        semidefinite (module docstring): per pass the Gram blocks D n.n, M n.n (and its transpose),
        E n.n, times gamma h / 4 (the passes averaged; self contact's one pass holds both directions)."""
        other = (0,) if len(self.passes) == 1 else (1, 0)
        rows, cols, vals = [], [], []

        def add(trip, p_row, off_row, p_col, off_col, row_ids, transpose=False):
            """The entries of triplets trip (row ids: local if not row_ids else global node ids; cols
            global) times the nodal normals' dot product, where both nodes carry a multiplier of their
            pass."""
            row, col, data = trip
            i = p_row.index_of(row) if row_ids else row
            j = p_col.index_of(col)
            ok = (i >= 0) & (j >= 0)
            i, j = i[ok], j[ok]
            v = data[ok] * np.einsum("ij,ij->i", p_row.normals[i], p_col.normals[j])
            r, s = i + off_row, j + off_col
            rows.append(s if transpose else r)
            cols.append(r if transpose else s)
            vals.append(v)

        for k, p in enumerate(self.passes):
            q, op, oq = self.passes[other[k]], self.offsets[k], self.offsets[other[k]]
            add(p.d, p, op, p, op, row_ids=False)                   # a-a: D_AB n_A.n_B
            add(p.m, p, op, q, oq, row_ids=False)                   # a-b: M_AC n_A.n_C
            add(p.m, p, op, q, oq, row_ids=False, transpose=True)   # b-a: its transpose
            add(p.e, q, oq, q, oq, row_ids=True)                    # b-b: E_CC' n_C.n_C'
        n = self.n_multipliers
        J = sp.csr_matrix((0.25 * gamma * h * np.concatenate(vals),
                           (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        # symmetric in exact arithmetic; the duplicates' sums in csr order can differ by an ulp
        return (0.5 * (J + J.T)).tocsr()


class SinglePassMortar(DualPassContact):
    """Standard (biased) mortar: side a is the non-mortar side of the only pass, b = G^ab, no
    stabilization. Kept as the comparison: swapping the sides changes the answer."""

    def __init__(self, points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, capture: float,
                 penetration: float | None = None):
        self.points = np.asarray(points, dtype=np.float64)
        self.passes = (mortar_pass(self.points, seg_a, seg_b, capture, penetration),)
        self.offsets = np.cumsum([0, len(self.passes[0].nodes)])

    def constraint_operator(self) -> sp.csr_matrix:
        return self.gap_operator()

    def tangent_operator(self) -> sp.csr_matrix:
        return self._tangential()

    def stabilization(self, gamma: float, h: float) -> sp.csr_matrix:
        return sp.csr_matrix((self.n_multipliers, self.n_multipliers))
