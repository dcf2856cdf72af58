"""Mortar integrals of 2-D contact: segments of a non-mortar side a against segments of a mortar
side b (Puso & Solberg, CMAME 367 (2020), the integrals of one pass; the seed's "Surface to surface
formulation").

For one pass a -> b and piecewise-linear shape functions phi on both sides:

    D_AB = integral over Gamma^ab of phi^a_A phi^a_B          (A, B nodes of side a)
    M_AC = integral over Gamma^ab of phi^a_A phi^b_C          (C nodes of side b)
    E_CC' = integral over Gamma^ab of phi^b_C phi^b_C'       (the mortar side's mass on the overlap)

E enters only the dual pass's stabilization (dual_pass.py: with D and M it makes each pass's
stabilization a Gram matrix, on the same quadrature points).

Gamma^ab is the part of side a onto which side b projects. The projection is along the normal of
the non-mortar segment: a point y of a mortar segment lands at xi = (y - x0) . t / L on the segment
x0 -> x1 (t its unit tangent, L its length). Orthogonal projection onto a line is affine, so on the
overlap [max(0, min(xi0, xi1)), min(1, max(xi0, xi1))] the mortar coordinate eta is affine in xi,
phi^a phi^b (and phi^b phi^b) is a quadratic in xi, and the 2-point Gauss rule integrates it exactly. A flat interface
is therefore integrated exactly for any two meshes (the patch test's geometry).

Only facing segments pair: outward normals with n_a . n_b < -FACING_COS (a surface's own next segments in self
contact are not its partners), with the mortar segment in front of the non-mortar one within the
capture distance or behind it by at most the allowed penetration (a thin body's far side, facing
the other way at a thickness behind, is not). Within an overlap the
mortar shape functions sum to one, so sum_C M_AC = sum_B D_AB row by row: the forces of a pass
balance to round-off (linear momentum exact).

Numba kernel, one pass over the candidate pairs (no Python loop).
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["segment_pair_integrals"]

_GAUSS_X = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])  # on [0, 1]
FACING_COS = 0.1
"""Segments pair when their outward normals are more than ~84 degrees apart (n_a . n_b < -0.1):
surfaces in contact are near antiparallel (Hertz: 6 degrees at the contact's edge)."""


@njit(cache=True)
def _pair_integrals(x, seg_a, seg_b, pairs, gx, capture, penetration, facing_cos, d_out, m_out, e_out, overlap):
    for p in range(pairs.shape[0]):
        sa = seg_a[pairs[p, 0]]
        sb = seg_b[pairs[p, 1]]
        x0 = x[sa[0]]
        x1 = x[sa[1]]
        tx = x1[0] - x0[0]
        ty = x1[1] - x0[1]
        ll = tx * tx + ty * ty
        y0 = x[sb[0]]
        y1 = x[sb[1]]
        ux = y1[0] - y0[0]
        uy = y1[1] - y0[1]
        # outward normals (dy, -dx): facing when their dot product is negative, by more than
        # FACING_COS of the lengths (a face at a right angle, e.g. a symmetry plane's last segment at
        # the contact, would pair over a round-off sliver and tilt its node's normal)
        if ty * uy + tx * ux >= -facing_cos * np.sqrt(ll * (ux * ux + uy * uy)) or ll <= 0.0:
            continue
        s0 = ((y0[0] - x0[0]) * tx + (y0[1] - x0[1]) * ty) / ll
        s1 = ((y1[0] - x0[0]) * tx + (y1[1] - x0[1]) * ty) / ll
        if s0 == s1:
            continue
        lo = max(0.0, min(s0, s1))
        hi = min(1.0, max(s0, s1))
        if hi <= lo:
            continue
        # separation along a's unit normal (ty, -tx)/L of b's points over the overlap's ends: b must
        # lie within [-penetration, capture] somewhere on it (else it is out of reach, or behind a:
        # a thin body's far side)
        el = np.sqrt(ll)
        dist0 = ((y0[0] - x0[0]) * ty - (y0[1] - x0[1]) * tx) / el
        dist1 = ((y1[0] - x0[0]) * ty - (y1[1] - x0[1]) * tx) / el
        e_lo = (lo - s0) / (s1 - s0)
        e_hi = (hi - s0) / (s1 - s0)
        g_lo = dist0 + e_lo * (dist1 - dist0)
        g_hi = dist0 + e_hi * (dist1 - dist0)
        if max(g_lo, g_hi) < -penetration or min(g_lo, g_hi) > capture:
            continue
        w = 0.5 * (hi - lo) * el
        overlap[p] = 2.0 * w
        for g in range(2):
            xi = lo + (hi - lo) * gx[g]
            eta = (xi - s0) / (s1 - s0)
            pa0 = 1.0 - xi
            pa1 = xi
            pb0 = 1.0 - eta
            pb1 = eta
            d_out[p, 0, 0] += w * pa0 * pa0
            d_out[p, 0, 1] += w * pa0 * pa1
            d_out[p, 1, 0] += w * pa1 * pa0
            d_out[p, 1, 1] += w * pa1 * pa1
            m_out[p, 0, 0] += w * pa0 * pb0
            m_out[p, 0, 1] += w * pa0 * pb1
            m_out[p, 1, 0] += w * pa1 * pb0
            m_out[p, 1, 1] += w * pa1 * pb1
            e_out[p, 0, 0] += w * pb0 * pb0
            e_out[p, 0, 1] += w * pb0 * pb1
            e_out[p, 1, 0] += w * pb1 * pb0
            e_out[p, 1, 1] += w * pb1 * pb1


def segment_pair_integrals(points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, pairs: np.ndarray,
                           capture: float = np.inf, penetration: float = np.inf, mortar_mass: bool = False):
    """D and M (and E) of every candidate pair of one pass a -> b (module docstring).

    A pair counts where the mortar segment's separation from the non-mortar one, along the latter's
    normal, lies within [-penetration, capture] somewhere on their overlap.

    points (n, 2); seg_a (na, 2), seg_b (nb, 2) node ids, outward by the right-hand rule
    (lagrange.surface.exterior_facets); pairs (np, 2) indices into seg_a and seg_b
    (search.candidate_pairs). Returns d (np, 2, 2) with d[p, i, j] the integral of the non-mortar
    segment's shape functions i and j over the overlap, m (np, 2, 2) with m[p, i, k] that of its
    shape function i and the mortar segment's k, and the overlap length (np,) (0 for pairs that do
    not face each other or do not overlap). mortar_mass: also e (np, 2, 2), e[p, k, l] the integral
    of the mortar segment's shape functions k and l over the overlap, returned last.
    """
    x = np.ascontiguousarray(points, dtype=np.float64)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    d = np.zeros((len(pairs), 2, 2))
    m = np.zeros((len(pairs), 2, 2))
    e = np.zeros((len(pairs), 2, 2))
    overlap = np.zeros(len(pairs))
    _pair_integrals(x, np.ascontiguousarray(seg_a, dtype=np.int64), np.ascontiguousarray(seg_b, dtype=np.int64),
                    pairs, _GAUSS_X, float(capture), float(penetration), FACING_COS, d, m, e, overlap)
    return (d, m, overlap, e) if mortar_mass else (d, m, overlap)
