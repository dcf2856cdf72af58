"""Mortar integrals of 3-D contact: bilinear quadrilateral facets of a non-mortar side a against those
of a mortar side b (the 3-D analogue of mortar_segments.py; Puso & Solberg, CMAME 367 (2020), the
integrals of one pass, with the 3-D segmentation, the overlaps found in a projection plane, of Puso
& Laursen, "A mortar segment-to-segment contact method for large deformation solid mechanics", CMAME
193 (2004)).

For one pass a -> b and the bilinear shape functions phi of the 4-node facets on both sides:

    D_AB = integral over Gamma^ab of phi^a_A phi^a_B          (A, B nodes of facet a)
    M_AC = integral over Gamma^ab of phi^a_A phi^b_C          (C nodes of facet b)
    E_CC' = integral over Gamma^ab of phi^b_C phi^b_C'       (the mortar side's mass on the overlap;
                                                               only the dual pass's stabilization uses it)

Gamma^ab, the mortar segment of the pair, is found in a plane (as in Puso & Laursen 2004):

1. the plane of facet a through its centre c_a (the mean of its corners), normal to its unit normal
   n_a at the centre (the direction of (x_2 - x_0) x (x_3 - x_1), which is dx/dxi x dx/deta at
   xi = eta = 0), with an orthonormal basis e1, e2 (e1 x e2 = n_a);
2. both facets' corners projected onto that plane along n_a (the plane coordinates of a point y are
   ((y - c_a) . e1, (y - c_a) . e2); the dropped component (y - c_a) . n_a is its separation);
3. the projection of b clipped against the projection of a (Sutherland-Hodgman: b's polygon cut by
   the half-plane left of every edge of a's, both counter-clockwise about n_a; b's corners run
   clockwise about n_a when the facets face each other, so its polygon is taken in reverse);
4. the clipped polygon triangulated from its vertex centroid, and on each triangle the 7-point
   degree-5 rule (Strang & Fix; Dunavant 1985), at whose points the local coordinates (xi, eta) of
   both facets are found by inverting their projected bilinear maps (Newton, from the centre).

Assumed: both projected quadrilaterals are convex (corner angles below 180 degrees in a's plane, as
for any valid hexahedral face that is not folded). A warped facet (corners not coplanar) enters only
through its projection: the integrals are over the projected overlap in a's plane, so for a warped a
its area there differs from the curved surface's by the second-order warp (Puso & Laursen's
approximation). Convexity makes the clipped polygon convex, so the fan from its vertex centroid
covers it with positively oriented triangles.

Exactness: where both projected facets are parallelograms (any flat rectangular, sheared or rotated
grid), the bilinear maps are affine, the phi are polynomials of degree 2 in the plane coordinates,
phi^a phi^b has degree 4 and the degree-5 rule integrates it exactly: D, M and E are exact to round-off
for flat parallel facets of such meshes. A general flat quadrilateral (non-parallel opposite sides)
has rational phi in the plane; the rule is then accurate, not exact (tests measure it). Wherever the
inversion converges, the mortar shape functions sum to one at every quadrature point, so
sum_C M_AC = sum_B D_AB row by row to round-off (the forces of a pass balance: linear momentum), and
a field linear in the plane coordinates is reproduced pointwise (isoparametric facets): the weighted
gaps of a linear motion are consistent on any flat mesh. The nodal forces of a uniform pressure are
as exact as the integrals (the 3-D patch test: round-off on rectangular grids, 1.7e-7 in the
displacements with a grid turned 25 degrees, tests/solvers/contact/test_patch_3d.py).

Filters, as in 2-D: only facing facets pair (unit centre normals with n_a . n_b < -FACING_COS of
mortar_segments.py), and only where b's separation from a along n_a lies within [-penetration,
capture] somewhere on the overlap (checked at the clipped polygon's vertices; exact for flat facets,
where the separation is affine in the plane).

Numba kernel, one pass over the candidate pairs (no Python loop over facets or pairs): measured
0.65 us per candidate pair, 2.7 us per overlapping one (60 x 60 facets against 47 x 47, one core).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from solvers.contact.mortar_segments import FACING_COS

__all__ = ["facet_pair_integrals", "TRIANGLE_RULE"]

# 7-point rule of degree 5 on a triangle (Strang & Fix 1973, Dunavant 1985): barycentric coordinates
# of the points (rows, (l1, l2, l3)) and the weights, which sum to one (times the triangle's area).
_S15 = np.sqrt(15.0)
_A1, _B1 = (6.0 - _S15) / 21.0, (9.0 + 2.0 * _S15) / 21.0
_A2, _B2 = (6.0 + _S15) / 21.0, (9.0 - 2.0 * _S15) / 21.0
_W1, _W2 = (155.0 - _S15) / 1200.0, (155.0 + _S15) / 1200.0
TRIANGLE_RULE = (
    np.array([[1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
              [_A1, _A1, _B1], [_A1, _B1, _A1], [_B1, _A1, _A1],
              [_A2, _A2, _B2], [_A2, _B2, _A2], [_B2, _A2, _A2]]),
    np.array([9.0 / 40.0, _W1, _W1, _W1, _W2, _W2, _W2]),
)
"""(points (7, 3) barycentric, weights (7,)): exact for polynomials of degree <= 5."""

_MAX_VERTICES = 64  # a clip edge at most doubles the vertices (inside ones + crossings): 4 * 2^4
                    # (at most 8 when both polygons are convex)
_MIN_AREA = 1e-12   # overlaps below this fraction of a's projected area are dropped (shared edges)
_NEWTON_STEPS = 12
_NEWTON_TOL = 1e-14  # on a step in the reference coordinates (range [-1, 1]): quadratic, so one more
                     # step than needed is taken; an affine map converges in the first


@njit(cache=True)
def _invert_bilinear(c, qx, qy):
    """(xi, eta) of the point (qx, qy) on the projected bilinear facet with corner coefficients c
    (4, 2): x(xi, eta) = c0 + c1 xi + c2 eta + c3 xi eta. Newton from the centre."""
    xi = 0.0
    eta = 0.0
    for _ in range(_NEWTON_STEPS):
        rx = c[0, 0] + c[1, 0] * xi + c[2, 0] * eta + c[3, 0] * xi * eta - qx
        ry = c[0, 1] + c[1, 1] * xi + c[2, 1] * eta + c[3, 1] * xi * eta - qy
        j00 = c[1, 0] + c[3, 0] * eta   # dx/dxi
        j10 = c[1, 1] + c[3, 1] * eta   # dy/dxi
        j01 = c[2, 0] + c[3, 0] * xi    # dx/deta
        j11 = c[2, 1] + c[3, 1] * xi    # dy/deta
        det = j00 * j11 - j01 * j10
        if det == 0.0:
            break
        dxi = (j11 * rx - j01 * ry) / det
        deta = (-j10 * rx + j00 * ry) / det
        xi -= dxi
        eta -= deta
        if abs(dxi) + abs(deta) < _NEWTON_TOL:
            break
    return xi, eta


@njit(cache=True)
def _shape(xi, eta, out):
    """Bilinear shape functions at (xi, eta) of corners (-1,-1), (1,-1), (1,1), (-1,1) (facet order)."""
    out[0] = 0.25 * (1.0 - xi) * (1.0 - eta)
    out[1] = 0.25 * (1.0 + xi) * (1.0 - eta)
    out[2] = 0.25 * (1.0 + xi) * (1.0 + eta)
    out[3] = 0.25 * (1.0 - xi) * (1.0 + eta)


@njit(cache=True)
def _coefficients(p, c):
    """c (4, 2) of x(xi, eta) = c0 + c1 xi + c2 eta + c3 xi eta from the projected corners p (4, 2)."""
    for k in range(2):
        c[0, k] = 0.25 * (p[0, k] + p[1, k] + p[2, k] + p[3, k])
        c[1, k] = 0.25 * (-p[0, k] + p[1, k] + p[2, k] - p[3, k])
        c[2, k] = 0.25 * (-p[0, k] - p[1, k] + p[2, k] + p[3, k])
        c[3, k] = 0.25 * (p[0, k] - p[1, k] + p[2, k] - p[3, k])


@njit(cache=True)
def _centre_normal(x, f, n):
    """n = (x_2 - x_0) x (x_3 - x_1) of the facet f (4,): 8 dx/dxi x dx/deta at its centre, whose
    length is twice the area of a flat facet."""
    u0 = x[f[2], 0] - x[f[0], 0]
    u1 = x[f[2], 1] - x[f[0], 1]
    u2 = x[f[2], 2] - x[f[0], 2]
    v0 = x[f[3], 0] - x[f[1], 0]
    v1 = x[f[3], 1] - x[f[1], 1]
    v2 = x[f[3], 2] - x[f[1], 2]
    n[0] = u1 * v2 - u2 * v1
    n[1] = u2 * v0 - u0 * v2
    n[2] = u0 * v1 - u1 * v0


@njit(cache=True)
def _facet_pair_integrals(x, fac_a, fac_b, pairs, bary, wts, capture, penetration, facing_cos,
                          d_out, m_out, e_out, overlap):
    pa = np.empty((4, 2))
    pb = np.empty((4, 2))
    ca = np.empty((4, 2))
    cb = np.empty((4, 2))
    sa = np.empty(4)
    sb = np.empty(4)
    na = np.empty(3)
    nb = np.empty(3)
    e1 = np.empty(3)
    e2 = np.empty(3)
    cen = np.empty(3)
    phia = np.empty(4)
    phib = np.empty(4)
    poly = np.empty((_MAX_VERTICES, 2))
    tmp = np.empty((_MAX_VERTICES, 2))
    nq = wts.shape[0]
    for p in range(pairs.shape[0]):
        fa = fac_a[pairs[p, 0]]
        fb = fac_b[pairs[p, 1]]
        # centre normals: (x2 - x0) x (x3 - x1) is 8 dx/dxi x dx/deta at the centre
        _centre_normal(x, fa, na)
        _centre_normal(x, fb, nb)
        la = np.sqrt(na[0] * na[0] + na[1] * na[1] + na[2] * na[2])
        lb = np.sqrt(nb[0] * nb[0] + nb[1] * nb[1] + nb[2] * nb[2])
        if la <= 0.0 or lb <= 0.0:
            continue
        for k in range(3):
            na[k] /= la
            nb[k] /= lb
        # facing only (a face at a right angle would pair over a round-off sliver)
        if na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2] >= -facing_cos:
            continue
        # a's plane: centre, e1 along a's xi direction at the centre with n_a taken out, e2 = n_a x e1
        for k in range(3):
            cen[k] = 0.25 * (x[fa[0], k] + x[fa[1], k] + x[fa[2], k] + x[fa[3], k])
            e1[k] = x[fa[1], k] + x[fa[2], k] - x[fa[0], k] - x[fa[3], k]
        tn = e1[0] * na[0] + e1[1] * na[1] + e1[2] * na[2]
        for k in range(3):
            e1[k] -= tn * na[k]
        le = np.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
        if le <= 0.0:
            continue
        for k in range(3):
            e1[k] /= le
        e2[0] = na[1] * e1[2] - na[2] * e1[1]
        e2[1] = na[2] * e1[0] - na[0] * e1[2]
        e2[2] = na[0] * e1[1] - na[1] * e1[0]
        # corners projected along n_a: plane coordinates and separations (step 2 of the docstring)
        for i in range(4):
            ra0 = x[fa[i], 0] - cen[0]
            ra1 = x[fa[i], 1] - cen[1]
            ra2 = x[fa[i], 2] - cen[2]
            pa[i, 0] = ra0 * e1[0] + ra1 * e1[1] + ra2 * e1[2]
            pa[i, 1] = ra0 * e2[0] + ra1 * e2[1] + ra2 * e2[2]
            sa[i] = ra0 * na[0] + ra1 * na[1] + ra2 * na[2]
            rb0 = x[fb[i], 0] - cen[0]
            rb1 = x[fb[i], 1] - cen[1]
            rb2 = x[fb[i], 2] - cen[2]
            pb[i, 0] = rb0 * e1[0] + rb1 * e1[1] + rb2 * e1[2]
            pb[i, 1] = rb0 * e2[0] + rb1 * e2[1] + rb2 * e2[2]
            sb[i] = rb0 * na[0] + rb1 * na[1] + rb2 * na[2]
        # the separation below (phi_b . s_b - phi_a . s_a, the shape functions convex weights inside
        # the facets) lies within [min s_b - max s_a, max s_b - min s_a]: a pair out of reach on the
        # whole of it is dropped before the clipping (the same pairs kept; most candidates of two
        # plates approaching each other are out of reach). The slack covers the round-off of the
        # overlap's vertices on a facet's edge (shape functions of -1e-16).
        slack = 1e-9 * max(abs(sa[0]), abs(sa[1]), abs(sa[2]), abs(sa[3]),
                           abs(sb[0]), abs(sb[1]), abs(sb[2]), abs(sb[3]))
        if (min(sb[0], sb[1], sb[2], sb[3]) - max(sa[0], sa[1], sa[2], sa[3]) > capture + slack
                or max(sb[0], sb[1], sb[2], sb[3]) - min(sa[0], sa[1], sa[2], sa[3]) < -penetration - slack):
            continue
        _coefficients(pa, ca)
        _coefficients(pb, cb)
        # a's projected area: half the cross product of its diagonals
        area_a = 0.5 * ((pa[2, 0] - pa[0, 0]) * (pa[3, 1] - pa[1, 1])
                        - (pa[2, 1] - pa[0, 1]) * (pa[3, 0] - pa[1, 0]))
        # Sutherland-Hodgman: b's polygon (reversed: counter-clockwise about n_a) cut by the inner
        # half-plane of each of a's edges in turn (the left side: a runs counter-clockwise)
        nv = 4
        for i in range(4):
            poly[i, 0] = pb[3 - i, 0]
            poly[i, 1] = pb[3 - i, 1]
        for e in range(4):
            ex = pa[e, 0]
            ey = pa[e, 1]
            dx = pa[(e + 1) % 4, 0] - ex
            dy = pa[(e + 1) % 4, 1] - ey
            nout = 0
            for i in range(nv):
                j = i + 1 if i + 1 < nv else 0
                dc = dx * (poly[i, 1] - ey) - dy * (poly[i, 0] - ex)   # > 0: left of the edge, inside
                dn = dx * (poly[j, 1] - ey) - dy * (poly[j, 0] - ex)
                if dc >= 0.0:
                    tmp[nout, 0] = poly[i, 0]
                    tmp[nout, 1] = poly[i, 1]
                    nout += 1
                if (dc >= 0.0) != (dn >= 0.0):   # the edge i -> j crosses the line: keep the crossing
                    t = dc / (dc - dn)
                    tmp[nout, 0] = poly[i, 0] + t * (poly[j, 0] - poly[i, 0])
                    tmp[nout, 1] = poly[i, 1] + t * (poly[j, 1] - poly[i, 1])
                    nout += 1
            nv = nout
            for i in range(nv):
                poly[i, 0] = tmp[i, 0]
                poly[i, 1] = tmp[i, 1]
            if nv < 3:
                break
        if nv < 3:
            continue
        # vertex centroid (inside a convex polygon) and the area of the fan around it
        gx = 0.0
        gy = 0.0
        for i in range(nv):
            gx += poly[i, 0]
            gy += poly[i, 1]
        gx /= nv
        gy /= nv
        area = 0.0
        for i in range(nv):
            j = i + 1 if i + 1 < nv else 0
            area += 0.5 * ((poly[i, 0] - gx) * (poly[j, 1] - gy) - (poly[i, 1] - gy) * (poly[j, 0] - gx))
        if area <= _MIN_AREA * abs(area_a):   # touching along an edge or a corner only
            continue
        # separation of b from a along n_a at the overlap's vertices: within [-penetration, capture]
        # somewhere (else out of reach, or behind a: a thin body's far side)
        gmin = np.inf
        gmax = -np.inf
        for i in range(nv):
            xi, eta = _invert_bilinear(ca, poly[i, 0], poly[i, 1])
            _shape(xi, eta, phia)
            xi, eta = _invert_bilinear(cb, poly[i, 0], poly[i, 1])
            _shape(xi, eta, phib)
            g = 0.0
            for k in range(4):
                g += phib[k] * sb[k] - phia[k] * sa[k]
            gmin = min(gmin, g)
            gmax = max(gmax, g)
        if gmax < -penetration or gmin > capture:
            continue
        overlap[p] = area
        # the fan's triangles (centroid, v_i, v_i+1), each with the degree-5 rule
        for i in range(nv):
            j = i + 1 if i + 1 < nv else 0
            ux = poly[i, 0] - gx
            uy = poly[i, 1] - gy
            vx = poly[j, 0] - gx
            vy = poly[j, 1] - gy
            tri = 0.5 * (ux * vy - uy * vx)
            if tri == 0.0:
                continue
            for q in range(nq):
                qx = gx + bary[q, 1] * ux + bary[q, 2] * vx
                qy = gy + bary[q, 1] * uy + bary[q, 2] * vy
                xi, eta = _invert_bilinear(ca, qx, qy)
                _shape(xi, eta, phia)
                xi, eta = _invert_bilinear(cb, qx, qy)
                _shape(xi, eta, phib)
                w = tri * wts[q]
                for r in range(4):
                    wr = w * phia[r]
                    for s in range(4):
                        d_out[p, r, s] += wr * phia[s]
                        m_out[p, r, s] += wr * phib[s]
                    wr = w * phib[r]
                    for s in range(4):
                        e_out[p, r, s] += wr * phib[s]


def facet_pair_integrals(points: np.ndarray, fac_a: np.ndarray, fac_b: np.ndarray, pairs: np.ndarray,
                         capture: float = np.inf, penetration: float = np.inf, mortar_mass: bool = False):
    """D and M (and E) of every candidate pair of one pass a -> b of quadrilateral facets (module docstring).

    A pair counts where the facets face each other and the mortar facet's separation from the
    non-mortar one, along the latter's centre normal, lies within [-penetration, capture] somewhere
    on their overlap.

    points (n, 3); fac_a (na, 4), fac_b (nb, 4) node ids, outward by the right-hand rule
    (lagrange.surface.exterior_facets); pairs (np, 2) indices into fac_a and fac_b
    (search.candidate_pairs). Returns d (np, 4, 4) with d[p, i, j] the integral of the non-mortar
    facet's shape functions i and j over the overlap, m (np, 4, 4) with m[p, i, k] that of its shape
    function i and the mortar facet's k, and the overlap area in a's plane (np,) (0 for pairs that do
    not face each other, do not overlap or are out of reach). mortar_mass: also e (np, 4, 4),
    e[p, k, l] the integral of the mortar facet's shape functions k and l over the overlap, returned
    last.
    """
    x = np.ascontiguousarray(points, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"facet_pair_integrals: points must have shape (n, 3), got {x.shape}")
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    d = np.zeros((len(pairs), 4, 4))
    m = np.zeros((len(pairs), 4, 4))
    e = np.zeros((len(pairs), 4, 4))
    overlap = np.zeros(len(pairs))
    bary, wts = TRIANGLE_RULE
    _facet_pair_integrals(x, np.ascontiguousarray(fac_a, dtype=np.int64).reshape(-1, 4),
                          np.ascontiguousarray(fac_b, dtype=np.int64).reshape(-1, 4), pairs, bary, wts,
                          float(capture), float(penetration), FACING_COS, d, m, e, overlap)
    return (d, m, overlap, e) if mortar_mass else (d, m, overlap)
