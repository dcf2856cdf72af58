"""The clipping kernels of the interface geometry (geometry.py's "Pieces" and "Quadrature"): each
facet (2-D segment, 3-D triangle) cut slab by slab at the grid planes inside its range, with
the quadrature points of every piece; 2-D segments by their own scalar kernel."""
from __future__ import annotations

import numpy as np
from numba import njit

from orchestrator.coupling.pieces import _grow1, _grow2

# 2-point Gauss on [0, 1]: exact to degree 3.
_GAUSS2_T = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
# 6-point degree-4 triangle rule (two orbits (a, a, 1-2a)); weights normalised to sum 1.  Digits from
# solving the moment equations of degree <= 4 in 50-digit arithmetic (test_geometry checks the moments).
_W1, _A1 = 0.22338158967801146569, 0.44594849091596488631
_W2, _A2 = 0.10995174365532186763, 0.09157621350977074345
_TRI_BARY = np.array([[_A1, _A1, 1 - 2 * _A1], [_A1, 1 - 2 * _A1, _A1], [1 - 2 * _A1, _A1, _A1],
                      [_A2, _A2, 1 - 2 * _A2], [_A2, 1 - 2 * _A2, _A2], [1 - 2 * _A2, _A2, _A2]])
_TRI_W = np.array([_W1, _W1, _W1, _W2, _W2, _W2])



@njit(cache=True)
def _locate(X, v):
    """Index i of the slab with X[i] <= v < X[i+1] (n if v >= X[n], 0 if v < X[0])."""
    n = X.size - 1
    i = int(np.floor((v - X[0]) / (X[n] - X[0]) * n))
    if i < 0:
        i = 0
    if i > n:
        i = n
    while i > 0 and X[i] > v:
        i -= 1
    while i < n and X[i + 1] <= v:
        i += 1
    return i


@njit(cache=True)
def _axis_range(poly, nv, d, X, nd):
    """Zones [i0, i1] along d that a polygon covers with positive extent.  A polygon at constant
    coordinate (perpendicular to d) lies in one zone: on a grid plane the one on its outward side
    (normal component nd), at the grid boundary the inner one."""
    mn = poly[0, d]
    mx = mn
    for v in range(1, nv):
        if poly[v, d] < mn:
            mn = poly[v, d]
        if poly[v, d] > mx:
            mx = poly[v, d]
    return _extent_range(mn, mx, X, nd)


@njit(cache=True, inline="always")
def _extent_range(mn, mx, X, nd):
    """Zones [i0, i1] along an axis with planes X that the extent [mn, mx] covers with positive
    length; a zero extent lies in one zone: on a grid plane the one on the outward side (normal
    component nd), at the grid boundary the inner one."""
    n = X.size - 1
    if mn == mx:
        z = _locate(X, mn)
        if X[z] == mn and nd < 0.0:
            z = z - 1
        z = min(max(z, 0), n - 1)
        return z, z
    i0 = min(_locate(X, mn), n - 1)
    i1 = _locate(X, mx)
    if i1 > 0 and X[i1] >= mx:
        i1 -= 1
    return i0, min(max(i1, i0), n - 1)


@njit(cache=True)
def _cut_polygon(src, ns, d, X, lo, hi):
    """Sutherland-Hodgman against the plane x_d = X, both sides at once; cut vertices get x_d = X
    exactly (so the next slab's range starts on the plane) and interpolate every other column."""
    nlo = 0
    nhi = 0
    na = src.shape[1]
    for e in range(ns):
        f = e + 1 if e + 1 < ns else 0
        sp = src[e, d] - X
        sq = src[f, d] - X
        if sp <= 0.0:
            lo[nlo, :] = src[e, :]
            nlo += 1
        if sp >= 0.0:
            hi[nhi, :] = src[e, :]
            nhi += 1
        if (sp < 0.0 and sq > 0.0) or (sp > 0.0 and sq < 0.0):
            t = sp / (sp - sq)
            for a in range(na):
                r = src[e, a] + t * (src[f, a] - src[e, a])
                lo[nlo, a] = r
                hi[nhi, a] = r
            lo[nlo, d] = X
            hi[nhi, d] = X
            nlo += 1
            nhi += 1
        if nlo > lo.shape[0] - 2 or nhi > hi.shape[0] - 2:
            raise ValueError("clipped polygon exceeds its buffer")
    return nlo, nhi


@njit(cache=True)
def _cut_segment(src, d, X, lo, hi):
    """Split a segment (2 rows) at the plane x_d = X strictly inside its range, keeping its direction."""
    sp = src[0, d] - X
    sq = src[1, d] - X
    t = sp / (sp - sq)
    first_below = sp < 0.0
    # lo: (p, r) if p is below the plane else (r, q); hi: the other half
    r_lo = 1 if first_below else 0
    r_hi = 0 if first_below else 1
    for a in range(src.shape[1]):
        r = src[0, a] + t * (src[1, a] - src[0, a])
        lo[r_lo, a] = r
        hi[r_hi, a] = r
        lo[1 - r_lo, a] = src[1 - r_lo, a]
        hi[1 - r_hi, a] = src[1 - r_hi, a]
    lo[r_lo, d] = X
    hi[r_hi, d] = X
    return 2, 2


@njit(cache=True)
def _grow_pieces(pz, pe, pa, pc, pq0, pqn, n):
    """The per-piece arrays of the clippers (zone, element, area, centroid, first quadrature point,
    point count) grown to n rows."""
    return _grow1(pz, n), _grow1(pe, n), _grow1(pa, n), _grow2(pc, n), _grow1(pq0, n), _grow1(pqn, n)


@njit(cache=True)
def _clip_kernel(xs, elems, planes, cells, gauss_t, tri_bary, tri_w):
    """Clip every element (2-D segment / 3-D triangle) against the zones.

    Returns per piece (in element order): zone id, element, area, centroid (np, D), first point and
    number of points; per point: position (nq, D), weight, foreground barycentrics (nq, 3); per
    element: unit normal (ne, D).
    """
    D = xs.shape[1]
    ne = elems.shape[0]
    nvert = D                      # vertices of an element
    ncol = D + (3 if D == 3 else 1)  # position + foreground coordinates carried through the cuts
    minv = 3 if D == 3 else 2
    MAXV = 32
    buf = np.empty((3, 3, MAXV, ncol))   # per level: remainder, piece, scratch
    icur = np.zeros(3, np.int64)
    iend = np.zeros(3, np.int64)
    idx = np.zeros(3, np.int64)
    nrem = np.zeros(3, np.int64)
    npc = np.zeros(3, np.int64)

    cap = 4 * ne + 16
    qcap = (24 if D == 3 else 2) * cap
    pz = np.empty(cap, np.int64)
    pe = np.empty(cap, np.int64)
    pa = np.empty(cap)
    pc = np.empty((cap, D))
    pq0 = np.empty(cap, np.int64)
    pqn = np.empty(cap, np.int64)
    qx = np.empty((qcap, D))
    qw = np.empty(qcap)
    ql = np.empty((qcap, 3))
    normals = np.zeros((ne, D))
    npieces = 0
    nq = 0
    nrm = np.zeros(D)
    cen = np.zeros(D)

    for el in range(ne):
        # unit normal of the element (right-handed, outward)
        if D == 3:
            a = xs[elems[el, 0]]
            b = xs[elems[el, 1]]
            c = xs[elems[el, 2]]
            e1x, e1y, e1z = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            e2x, e2y, e2z = c[0] - a[0], c[1] - a[1], c[2] - a[2]
            nrm[0] = e1y * e2z - e1z * e2y
            nrm[1] = e1z * e2x - e1x * e2z
            nrm[2] = e1x * e2y - e1y * e2x
        else:
            a = xs[elems[el, 0]]
            b = xs[elems[el, 1]]
            nrm[0] = b[1] - a[1]
            nrm[1] = -(b[0] - a[0])
        nn = 0.0
        for k in range(D):
            nn += nrm[k] * nrm[k]
        nn = np.sqrt(nn)
        if nn == 0.0:
            continue                  # degenerate element: no area
        for k in range(D):
            nrm[k] /= nn
            normals[el, k] = nrm[k]
        # level 0 remainder: the element with its foreground coordinates
        for v in range(nvert):
            for k in range(D):
                buf[0, 0, v, k] = xs[elems[el, v], k]
            for k in range(D, ncol):
                buf[0, 0, v, k] = 0.0
            if D == 3:
                buf[0, 0, v, D + v] = 1.0
            else:
                buf[0, 0, v, D] = float(v)      # segment parameter t
        nrem[0] = nvert
        i0, i1 = _axis_range(buf[0, 0], nvert, 0, planes[0, : cells[0] + 1], nrm[0])
        icur[0] = i0
        iend[0] = i1
        lvl = 0
        while lvl >= 0:
            if icur[lvl] > iend[lvl]:
                lvl -= 1
                continue
            i = icur[lvl]
            icur[lvl] += 1
            idx[lvl] = i
            X = planes[lvl, : cells[lvl] + 1]
            if i < iend[lvl]:
                # split off the slab below plane i+1; the rest stays the remainder
                if D == 3:
                    nlo, nhi = _cut_polygon(buf[lvl, 0], nrem[lvl], lvl, X[i + 1], buf[lvl, 1], buf[lvl, 2])
                else:
                    nlo, nhi = _cut_segment(buf[lvl, 0], lvl, X[i + 1], buf[lvl, 1], buf[lvl, 2])
                buf[lvl, 0, :nhi, :] = buf[lvl, 2, :nhi, :]
                nrem[lvl] = nhi
                npc[lvl] = nlo
            else:
                buf[lvl, 1, : nrem[lvl], :] = buf[lvl, 0, : nrem[lvl], :]
                npc[lvl] = nrem[lvl]
            if npc[lvl] < minv:
                continue
            if lvl < D - 1:
                nxt = lvl + 1
                buf[nxt, 0, : npc[lvl], :] = buf[lvl, 1, : npc[lvl], :]
                nrem[nxt] = npc[lvl]
                j0, j1 = _axis_range(buf[nxt, 0], nrem[nxt], nxt, planes[nxt, : cells[nxt] + 1], nrm[nxt])
                icur[nxt] = j0
                iend[nxt] = j1
                lvl = nxt
                continue
            # a piece: buf[lvl, 1, :npc] in zone idx
            P = buf[lvl, 1]
            m = npc[lvl]
            if npieces == pz.size:
                pz, pe, pa, pc, pq0, pqn = _grow_pieces(pz, pe, pa, pc, pq0, pqn, 2 * pz.size)
            need = nq + (6 * (m - 2) if D == 3 else 2)
            if need > qw.size:
                qcap2 = max(2 * qw.size, need)
                qx = _grow2(qx, qcap2)
                qw = _grow1(qw, qcap2)
                ql = _grow2(ql, qcap2)
            q0 = nq
            area = 0.0
            for k in range(D):
                cen[k] = 0.0
            if D == 3:
                # fan from vertex 0; each positive triangle gets the degree-4 rule.  Points are
                # P0 + b1 e1 + b2 e2, so a coordinate constant on the piece is reproduced exactly.
                for f in range(1, m - 1):
                    e1x = P[f, 0] - P[0, 0]
                    e1y = P[f, 1] - P[0, 1]
                    e1z = P[f, 2] - P[0, 2]
                    e2x = P[f + 1, 0] - P[0, 0]
                    e2y = P[f + 1, 1] - P[0, 1]
                    e2z = P[f + 1, 2] - P[0, 2]
                    at = 0.5 * (nrm[0] * (e1y * e2z - e1z * e2y) + nrm[1] * (e1z * e2x - e1x * e2z)
                                + nrm[2] * (e1x * e2y - e1y * e2x))
                    if not at > 0.0:
                        continue        # round-off sliver of a (numerically) non-convex polygon
                    area += at
                    cen[0] += at * (e1x + e2x) / 3.0
                    cen[1] += at * (e1y + e2y) / 3.0
                    cen[2] += at * (e1z + e2z) / 3.0
                    for g in range(tri_w.size):
                        b1 = tri_bary[g, 1]
                        b2 = tri_bary[g, 2]
                        b0 = tri_bary[g, 0]
                        qx[nq, 0] = P[0, 0] + b1 * e1x + b2 * e2x
                        qx[nq, 1] = P[0, 1] + b1 * e1y + b2 * e2y
                        qx[nq, 2] = P[0, 2] + b1 * e1z + b2 * e2z
                        for k in range(3):
                            ql[nq, k] = b0 * P[0, 3 + k] + b1 * P[f, 3 + k] + b2 * P[f + 1, 3 + k]
                        qw[nq] = tri_w[g] * at
                        nq += 1
                if not area > 0.0:
                    nq = q0
                    continue
                for k in range(3):
                    cen[k] = P[0, k] + cen[k] / area
            else:
                dx = P[1, 0] - P[0, 0]
                dy = P[1, 1] - P[0, 1]
                area = np.sqrt(dx * dx + dy * dy)
                if not area > 0.0:
                    continue
                cen[0] = P[0, 0] + 0.5 * dx
                cen[1] = P[0, 1] + 0.5 * dy
                for g in range(gauss_t.size):
                    s = gauss_t[g]
                    qx[nq, 0] = P[0, 0] + s * dx
                    qx[nq, 1] = P[0, 1] + s * dy
                    t = P[0, 2] + s * (P[1, 2] - P[0, 2])
                    ql[nq, 0] = 1.0 - t
                    ql[nq, 1] = t
                    ql[nq, 2] = 0.0
                    qw[nq] = 0.5 * area
                    nq += 1
            zid = idx[D - 1]
            for k in range(D - 2, -1, -1):
                zid = zid * cells[k] + idx[k]
            pz[npieces] = zid
            pe[npieces] = el
            pa[npieces] = area
            for k in range(D):
                pc[npieces, k] = cen[k]
            pq0[npieces] = q0
            pqn[npieces] = nq - q0
            npieces += 1
    return (pz[:npieces], pe[:npieces], pa[:npieces], pc[:npieces], pq0[:npieces], pqn[:npieces],
            qx[:nq], qw[:nq], ql[:nq], normals)


@njit(cache=True, inline="always")
def _split_at(pd, po, pt, qd, qo, qt, X):
    """A segment p -> q strictly across the plane x_d = X (ends given as their coordinate along d,
    the other coordinate and the segment parameter t): (the part below the plane, the part above),
    each (d, o, t) of its two ends in the segment's direction; the cut vertex gets x_d = X exactly and
    interpolates the rest (``_cut_segment``)."""
    sp = pd - X
    sq = qd - X
    t = sp / (sp - sq)
    ro = po + t * (qo - po)
    rt = pt + t * (qt - pt)
    if sp < 0.0:
        return (pd, po, pt, X, ro, rt), (X, ro, rt, qd, qo, qt)
    return (X, ro, rt, qd, qo, qt), (pd, po, pt, X, ro, rt)


@njit(cache=True)
def _clip_segments_2d(xs, elems, X0, X1, gauss_t):
    """_clip_kernel for 2-D segments, the same operations on scalars: the generic kernel's level
    buffers and loops over columns cost ~250 ns per piece, this ~4x less (the coupler's geometry runs
    every step).  Same cuts (``_cut_segment``: the cut vertex gets the plane's coordinate, the other
    columns interpolate), same order, same results bit for bit."""
    ne = elems.shape[0]
    nx = X0.size - 1
    cap = 3 * ne + 16
    pz = np.empty(cap, np.int64)
    pe = np.empty(cap, np.int64)
    pa = np.empty(cap)
    pc = np.empty((cap, 2))
    pq0 = np.empty(cap, np.int64)
    pqn = np.empty(cap, np.int64)
    qx = np.empty((2 * cap, 2))
    qw = np.empty(2 * cap)
    ql = np.empty((2 * cap, 3))
    normals = np.zeros((ne, 2))
    ng = gauss_t.size
    npieces = 0
    for el in range(ne):
        px = xs[elems[el, 0], 0]
        py = xs[elems[el, 0], 1]
        qx_ = xs[elems[el, 1], 0]
        qy_ = xs[elems[el, 1], 1]
        n0 = qy_ - py
        n1 = -(qx_ - px)
        nn = np.sqrt(n0 * n0 + n1 * n1)
        if nn == 0.0:
            continue
        n0 /= nn
        n1 /= nn
        normals[el, 0] = n0
        normals[el, 1] = n1
        # the remainder along x: (ax, ay, at) -> (bx, by, bt); t the segment parameter
        ax, ay, at, bx, by, bt = px, py, 0.0, qx_, qy_, 1.0
        i0, i1 = _extent_range(min(ax, bx), max(ax, bx), X0, n0)
        for i in range(i0, i1 + 1):
            if i < i1:   # split off the part below plane i+1; the rest stays the remainder
                (sx0, sy0, st0, sx1, sy1, st1), (ax, ay, at, bx, by, bt) = _split_at(
                    ax, ay, at, bx, by, bt, X0[i + 1])
            else:
                sx0, sy0, st0, sx1, sy1, st1 = ax, ay, at, bx, by, bt
            j0, j1 = _extent_range(min(sy0, sy1), max(sy0, sy1), X1, n1)
            for j in range(j0, j1 + 1):
                if j < j1:   # along y (the helper's first coordinate is the cut axis)
                    (cy0, cx0, ct0, cy1, cx1, ct1), (sy0, sx0, st0, sy1, sx1, st1) = _split_at(
                        sy0, sx0, st0, sy1, sx1, st1, X1[j + 1])
                else:
                    cx0, cy0, ct0, cx1, cy1, ct1 = sx0, sy0, st0, sx1, sy1, st1
                dx = cx1 - cx0
                dy = cy1 - cy0
                area = np.sqrt(dx * dx + dy * dy)
                if not area > 0.0:
                    continue
                if npieces == pz.size:
                    c2 = 2 * pz.size
                    pz, pe, pa, pc, pq0, pqn = _grow_pieces(pz, pe, pa, pc, pq0, pqn, c2)
                    qx = _grow2(qx, ng * c2)
                    qw = _grow1(qw, ng * c2)
                    ql = _grow2(ql, ng * c2)
                nq = ng * npieces
                for g in range(ng):
                    s = gauss_t[g]
                    qx[nq + g, 0] = cx0 + s * dx
                    qx[nq + g, 1] = cy0 + s * dy
                    t = ct0 + s * (ct1 - ct0)
                    ql[nq + g, 0] = 1.0 - t
                    ql[nq + g, 1] = t
                    ql[nq + g, 2] = 0.0
                    qw[nq + g] = 0.5 * area
                pz[npieces] = i + nx * j
                pe[npieces] = el
                pa[npieces] = area
                pc[npieces, 0] = cx0 + 0.5 * dx
                pc[npieces, 1] = cy0 + 0.5 * dy
                pq0[npieces] = nq
                pqn[npieces] = ng
                npieces += 1
    nq = ng * npieces
    return (pz[:npieces], pe[:npieces], pa[:npieces], pc[:npieces], pq0[:npieces], pqn[:npieces],
            qx[:nq], qw[:nq], ql[:nq], normals)
