"""Interface geometry of the embedded-mesh coupling: Lagrangian body surfaces clipped against the
zones of the fixed Cartesian background grid (DESIGN.md, "The constraint solve").

Surfaces
--------
A body is a closed surface of facets: 2-D segments ``(a, b)`` oriented so that the outward normal is
``(yb - ya, -(xb - xa)) / L`` (the body's counter-clockwise boundary), 3-D quads ``(a, b, c, d)`` with
outward normal along ``(b - a) x (d - a)``.  A quad is split along its diagonal 0-2 into the triangles
``(0, 1, 2)`` and ``(0, 2, 3)`` (its *parts*); that triangulated surface is what is clipped, integrated
and enclosed, so a warped quad is treated consistently everywhere (the volumes of the references
are those of the triangulated surface).

Pieces
------
A *piece* is the part of one segment / triangle inside one zone: a sub-segment or a convex polygon,
planar, so it has one normal (a quad gives up to two pieces per zone, one per part, both carrying
the quad's facet index).  Each element is split slab by slab (along x, then each slab piece along
y, then along z) at the grid planes strictly inside its range, so it only visits the zones its
bounding box covers and the work is linear in the number of facets for facets of bounded size;
every piece has a positive extent across each plane it was cut at (no zero-area slivers from a
facet that merely touches a plane).

*Facets on grid planes.*  A facet whose vertices all lie on a grid plane normal to d belongs to the
zone on its outward side (normal component > 0: the zone above the plane), at the grid boundary to
the inner zone.  Why this rule keeps everything exact: it is the limit of the body dilated outward
by epsilon -> 0, whose surface lies strictly inside the outward zone, and the volume fractions and
face coverages of the dilated body tend to those of the body.  Positions are compared with the
canonical grid planes of grid.py; node coordinates within ``SNAP_ULPS`` ulps (of the grid's
coordinate scale) of a plane are first moved onto it (``Grid.snap``), so a body face meshed at
``x = 0.3`` lies on the plane whichever way the mesh generator rounded it (the volume changes by
O(eps)).

Quadrature (degrees of exactness)
---------------------------------
Restricted to a planar piece, the background bilinear (2-D) / trilinear (3-D) shape functions are
polynomials of degree 2 / 3 in the piece's coordinates, the foreground P1 functions of degree 1.
2-D: 2-point Gauss on each sub-segment, exact to degree 3 (background x foreground products).
3-D: each clipped polygon is fan-triangulated from its first vertex and each triangle gets the
6-point degree-4 rule (Strang & Fix / Dunavant, all weights positive, points inside), exact for
background x foreground products (degree 4); background x background products (degree 6 in 3-D,
4 in 2-D) are NOT integrated exactly.

Volume fractions and face coverages (exact, from the closed clipped surface)
---------------------------------------------------------------------------
For a zone Z = [x_lo, x_hi] x Y and a body Omega, the divergence theorem applied to the field
``(x - x_lo) e_x`` (divergence 1) on Omega ∩ Z gives

    V(Omega ∩ Z) = ∫_{Γ∩Z} (x - x_lo) n_x dΓ + h_x A_{hi}                               (1)

(the part of ∂(Omega ∩ Z) on the zone's boundary contributes only through its upper x face, where
``x - x_lo = h_x`` and ``n_x = 1``; on the lower face ``x - x_lo = 0``, on the others ``n_x = 0``),
``A_hi`` the area of the upper x face covered by Omega.  The field ``e_x`` (divergence 0) on the part
of Omega in the column beyond that face gives

    A_{hi} = Σ_{zones Z' of the row beyond Z} ∫_{Γ∩Z'} n_x dΓ                              (2)

(the column is bounded by planes parallel to x, and the body lies inside the grid), a suffix sum
along the row.  Both integrals are exact on planar pieces: ``∫ n_x = n_x a`` and
``∫ (x - x_lo) n_x = (c_x - x_lo) n_x a`` with the piece's area a and centroid c.  Zones of a row
between two cut zones are not cut, so they are entirely inside or outside: fraction 1 where the
coverage of their upper face (2) is the full face, else 0.  The same suffix sum along axis d gives
the coverage of every face normal to d (``face_coverage``).  A facet lying on the grid boundary
plane (assigned to the inner zone) counts as lying just outside the grid in these sums (position
-1 or n along d), which makes the coverage of the boundary faces exact too; it contributes nothing
to (1) either way (``x - x_lo = 0`` or it moves ``h_x a`` from the integral to ``A_hi``).
Summation order: the pieces of a zone are summed in the order of their terms' values (not of the
facet numbering), so fractions and coverages are bitwise independent of the order of the facets.
Fractions within ``_SNAP`` (64 eps) of 0 or 1 are set to 0 or 1 (round-off of the sums, which are
exact in exact arithmetic); only positive fractions are returned.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from orchestrator.coupling.grid import Grid


class GeometryError(ValueError):
    pass


_SNAP = 64 * np.finfo(np.float64).eps

# 2-point Gauss on [0, 1]: exact to degree 3.
_GAUSS2_T = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
# 6-point degree-4 triangle rule (two orbits (a, a, 1-2a)); weights normalised to sum 1.  Digits from
# solving the moment equations of degree <= 4 in 50-digit arithmetic (test_geometry checks the moments).
_W1, _A1 = 0.22338158967801146569, 0.44594849091596488631
_W2, _A2 = 0.10995174365532186763, 0.09157621350977074345
_TRI_BARY = np.array([[_A1, _A1, 1 - 2 * _A1], [_A1, 1 - 2 * _A1, _A1], [1 - 2 * _A1, _A1, _A1],
                      [_A2, _A2, 1 - 2 * _A2], [_A2, 1 - 2 * _A2, _A2], [1 - 2 * _A2, _A2, _A2]])
_TRI_W = np.array([_W1, _W1, _W1, _W2, _W2, _W2])

# Exterior faces of positively oriented cells, right-handed outward (the meshio/VTK node order).
_QUAD_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
_HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]],
                      dtype=np.int64)
_QUAD_FLIP = np.array([0, 3, 2, 1], dtype=np.int64)
_HEX_FLIP = np.array([0, 3, 2, 1, 4, 7, 6, 5], dtype=np.int64)


@dataclass
class Pieces:
    """The body surfaces clipped against the zones; piece arrays sorted by (zone, body, facet, part)
    (part: the triangle of a 3-D quad, 0 = (0,1,2), 1 = (0,2,3)); quadrature points grouped by piece
    in piece order."""

    zone: np.ndarray      # (np,) int64 global zone id
    body: np.ndarray      # (np,) int64 body of the parent facet
    facet: np.ndarray     # (np,) int64 parent facet (row of the facets array given)
    area: np.ndarray      # (np,) length (2-D) / area (3-D)
    normal: np.ndarray    # (np, dim) unit outward normal of the body (into the fluid)
    centroid: np.ndarray  # (np, dim)
    qp: np.ndarray        # (nq, dim) quadrature points
    qw: np.ndarray        # (nq,) weights; a piece's weights sum to its area
    qpiece: np.ndarray    # (nq,) int64 piece of each point (non-decreasing)
    qf: np.ndarray        # (nq, nv) foreground P1 shape functions of the parent facet's nodes
    qb: np.ndarray        # (nq, 2**dim) background shape functions of the piece's zone corners

    @property
    def dim(self) -> int:
        return int(self.normal.shape[1])

    @property
    def qstart(self) -> np.ndarray:
        """(np + 1,) offsets: the points of piece p are ``qstart[p]:qstart[p+1]``."""
        return np.searchsorted(self.qpiece, np.arange(self.zone.size + 1)).astype(np.int64)


# ----------------------------------------------------------------------------------- kernels
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
def _grow1(a, n):
    out = np.empty(n, a.dtype)
    out[: a.size] = a
    return out


@njit(cache=True)
def _grow2(a, n):
    out = np.empty((n, a.shape[1]), a.dtype)
    out[: a.shape[0], :] = a
    return out


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


@njit(cache=True)
def _same_row(oth, a, b):
    for j in range(oth.shape[1]):
        if oth[a, j] != oth[b, j]:
            return False
    return True


@njit(cache=True)
def _scan_rows(body, oth, pos, s, m, F, X, snap):
    """Suffix sums (2) along the rows of one axis and the fractions (1) / face coverages they give.

    Input sorted by (body, row coordinates ``oth``, position along the axis); ``s = n_d a``,
    ``m = (c_d - X[pos]) n_d a`` per piece, F the row's face area.  Returns the zone rows of the cut
    positions (body, oth, index, fraction), the face rows next to them (body, oth, plane index,
    covered fraction), only positive values, and the *runs* of uncut zones inside a body (body, oth,
    first index, end index): every zone of a run is covered whole, and so is every face between two
    zones of a run -- neither is listed one by one (their number grows with the body's volume, the
    rest with its surface).
    """
    n = X.size - 1
    npc = body.size
    no = oth.shape[1]
    cap = 4 * npc + 16
    zb = np.empty(cap, np.int64)
    zo = np.empty((cap, no), np.int64)
    zi = np.empty(cap, np.int64)
    zv = np.empty(cap)
    fb = np.empty(cap, np.int64)
    fo = np.empty((cap, no), np.int64)
    fk = np.empty(cap, np.int64)
    fv = np.empty(cap)
    rb = np.empty(cap, np.int64)
    ro = np.empty((cap, no), np.int64)
    r_0 = np.empty(cap, np.int64)
    r_1 = np.empty(cap, np.int64)
    nz = 0
    nf = 0
    nr = 0
    gp = np.empty(npc, np.int64)
    gs = np.empty(npc)
    gm = np.empty(npc)
    r0 = 0
    while r0 < npc:
        r1 = r0 + 1
        while r1 < npc and body[r1] == body[r0] and _same_row(oth, r0, r1):
            r1 += 1
        ng = 0
        for p in range(r0, r1):
            if ng > 0 and gp[ng - 1] == pos[p]:
                gs[ng - 1] += s[p]
                gm[ng - 1] += m[p]
            else:
                gp[ng] = pos[p]
                gs[ng] = s[p]
                gm[ng] = m[p]
                ng += 1
        Fr = F[r0]
        # worst case output of this row: two zones and two faces per position, one run between two
        extra = 2 * ng + 4
        if nz + extra > zv.size or nf + extra > fv.size or nr + extra > rb.size:
            c2 = 2 * zv.size + extra
            rb = _grow1(rb, c2)
            ro = _grow2(ro, c2)
            r_0 = _grow1(r_0, c2)
            r_1 = _grow1(r_1, c2)
            zb = _grow1(zb, c2)
            zo = _grow2(zo, c2)
            zi = _grow1(zi, c2)
            zv = _grow1(zv, c2)
            fb = _grow1(fb, c2)
            fo = _grow2(fo, c2)
            fk = _grow1(fk, c2)
            fv = _grow1(fv, c2)
        R = 0.0            # covered area of the face above the current position (2)
        for g in range(ng - 1, -1, -1):
            p = gp[g]
            if (g == ng - 1 or gp[g + 1] > p + 1) and p + 1 <= n:
                v = R / Fr
                v = 0.0 if v < snap else (1.0 if v > 1.0 - snap else v)
                if v > 0.0:
                    fb[nf] = body[r0]
                    fo[nf] = oth[r0]
                    fk[nf] = p + 1
                    fv[nf] = v
                    nf += 1
            if 0 <= p < n:
                w = X[p + 1] - X[p]
                v = (gm[g] + w * R) / (w * Fr)          # (1)
                v = 0.0 if v < snap else (1.0 if v > 1.0 - snap else v)
                if v > 0.0:
                    zb[nz] = body[r0]
                    zo[nz] = oth[r0]
                    zi[nz] = p
                    zv[nz] = v
                    nz += 1
            R += gs[g]
            if p >= 0:
                v = R / Fr
                v = 0.0 if v < snap else (1.0 if v > 1.0 - snap else v)
                if v > 0.0:
                    fb[nf] = body[r0]
                    fo[nf] = oth[r0]
                    fk[nf] = p
                    fv[nf] = v
                    nf += 1
            # zones strictly between the previous position and this one are not cut: inside or out
            if g > 0 and R > 0.5 * Fr and p > gp[g - 1] + 1:
                rb[nr] = body[r0]
                ro[nr] = oth[r0]
                r_0[nr] = gp[g - 1] + 1
                r_1[nr] = p
                nr += 1
        r0 = r1
    return (zb[:nz], zo[:nz], zi[:nz], zv[:nz], fb[:nf], fo[:nf], fk[:nf], fv[:nf],
            rb[:nr], ro[:nr], r_0[:nr], r_1[:nr])


@njit(cache=True)
def _is_sorted(key, o):
    for t in range(1, o.size):
        if key[o[t]] < key[o[t - 1]]:
            return False
    return True


@njit(cache=True)
def _stable_order(key, body, n_rows, n_pos):
    """The stable ascending order of key = (body n_rows + row) n_pos + position, as
    np.argsort(kind="mergesort") gives it, cheaply for the pieces clip_surface gives (sorted by zone
    id): along x the keys are already in order; along another axis a stable counting sort by
    (body, row) is, because within a row the zone id grows with the position.  Any other input (or
    too many rows to count) takes the merge sort."""
    npc = key.size
    o = np.arange(npc)
    if _is_sorted(key, o):
        return o
    nb = 0
    for p in range(npc):
        nb = max(nb, body[p] + 1)
    nbuckets = nb * n_rows
    if nbuckets <= 4 * npc + 4096:
        start = np.zeros(nbuckets + 1, np.int64)
        for p in range(npc):
            start[key[p] // n_pos + 1] += 1
        for b in range(nbuckets):
            start[b + 1] += start[b]
        for p in range(npc):
            b = key[p] // n_pos
            o[start[b]] = p
            start[b] += 1
        if _is_sorted(key, o):
            return o
    return np.argsort(key, kind="mergesort")


@njit(cache=True)
def _axis_coverage(zone, body, nd, cd, area, cells, planes, d, snap):
    """``_row_coverage``'s work for axis d in one kernel: the pieces' positions along d (a facet on
    the grid's boundary plane counts as just outside it), their terms s = n_d a and
    m = (c_d - X[pos]) n_d a, the canonical order (body, row, position, then s, m: three stable
    sorts, as np.lexsort), the row scan and the ids of what it gives."""
    dim = cells.size
    n = cells[d]
    npc = zone.size
    others = np.empty(dim - 1, np.int64)
    j = 0
    for e in range(dim):
        if e != d:
            others[j] = e
            j += 1
    ijk = np.empty((npc, dim), np.int64)
    pos = np.empty(npc, np.int64)
    s = np.empty(npc)
    m = np.zeros(npc)
    F = np.ones(npc)
    key = np.empty(npc, np.int64)
    n_rows = 1
    for e in range(dim - 1):
        n_rows *= cells[others[e]]
    for p in range(npc):
        rest = zone[p]
        for e in range(dim):
            ijk[p, e] = rest % cells[e]
            rest //= cells[e]
        q = ijk[p, d]
        if q == 0 and nd[p] < 0.0 and cd[p] == planes[d, 0]:
            q = -1
        elif q == n - 1 and nd[p] > 0.0 and cd[p] == planes[d, n]:
            q = n
        pos[p] = q
        s[p] = nd[p] * area[p]
        if 0 <= q < n:
            m[p] = (cd[p] - planes[d, q]) * s[p]
        row = 0
        for jj in range(dim - 2, -1, -1):
            e = others[jj]
            row = row * cells[e] + ijk[p, e]
        for jj in range(dim - 1):
            e = others[jj]
            F[p] *= planes[e, ijk[p, e] + 1] - planes[e, ijk[p, e]]
        key[p] = (body[p] * n_rows + row) * (n + 2) + (q + 1)
    # (key, then s, then m, then piece order: one stable sort by key, then insertion sorts of the
    # short runs of equal keys -- a zone row's pieces at one position -- by (s, m))
    o = _stable_order(key, body, n_rows, n + 2)
    t0 = 0
    while t0 < npc:
        t1 = t0 + 1
        while t1 < npc and key[o[t1]] == key[o[t0]]:
            t1 += 1
        for a in range(t0 + 1, t1):
            x = o[a]
            b = a - 1
            while b >= t0 and (s[o[b]] > s[x] or (s[o[b]] == s[x] and m[o[b]] > m[x])):
                o[b + 1] = o[b]
                b -= 1
            o[b + 1] = x
        t0 = t1
    oth = np.empty((npc, dim - 1), np.int64)
    for t in range(npc):
        for jj in range(dim - 1):
            oth[t, jj] = ijk[o[t], others[jj]]
    zb, zo, zi, zv, fb, fo, fk, fv, rb, ro, r0, r1 = _scan_rows(
        body[o], oth, pos[o], s[o], m[o], F[o], planes[d, : n + 1].copy(), snap)
    # ids (x fastest): zones on the grid's lattice, faces on the one with n_d + 1 planes along d
    zid = np.empty(zi.size, np.int64)
    for t in range(zi.size):
        v = 0
        for e in range(dim - 1, -1, -1):
            c = zi[t] if e == d else zo[t, _slot(others, e)]
            v = v * cells[e] + c
        zid[t] = v
    fid = np.empty(fk.size, np.int64)
    for t in range(fk.size):
        v = 0
        for e in range(dim - 1, -1, -1):
            c = fk[t] if e == d else fo[t, _slot(others, e)]
            v = v * (cells[e] + (1 if e == d else 0)) + c
        fid[t] = v
    first = np.empty((rb.size, dim), np.int64)
    for t in range(rb.size):
        for e in range(dim):
            first[t, e] = r0[t] if e == d else ro[t, _slot(others, e)]
    return zid, zb, zv, fid, fb, fv, rb, first, r1 - r0


@njit(cache=True, inline="always")
def _slot(others, e):
    for jj in range(others.size):
        if others[jj] == e:
            return jj
    return -1


@njit(cache=True)
def _gather_points(order, pq0, pqn, qx, qw, ql, part, zijk, planes, nv):
    """The quadrature points in sorted piece order, with the foreground shape functions of the
    parent facet's nv nodes (3-D: part 0 holds nodes (0, 1, 2), part 1 nodes (0, 2, 3)) and the
    background ones: tensor products of the 1-D hats of the zone's local coordinates
    ``xi_d = (x_d - X_i) / (X_{i+1} - X_i)`` (clipped against round-off); corner c has offset
    (c & 1, c >> 1 & 1, c >> 2 & 1)."""
    D = qx.shape[1]
    nq = 0
    for p in range(order.size):
        nq += pqn[order[p]]
    out_x = np.empty((nq, D))
    out_w = np.empty(nq)
    out_p = np.empty(nq, np.int64)
    out_f = np.zeros((nq, nv))
    nc = 1 << D
    out_b = np.empty((nq, nc))
    xi = np.empty(D)
    k = 0
    for p in range(order.size):
        o = order[p]
        for j in range(pq0[o], pq0[o] + pqn[o]):
            for d in range(D):
                out_x[k, d] = qx[j, d]
                i = zijk[p, d]
                t = (qx[j, d] - planes[d, i]) / (planes[d, i + 1] - planes[d, i])
                xi[d] = min(max(t, 0.0), 1.0)
            out_w[k] = qw[j]
            out_p[k] = p
            if D == 3:
                out_f[k, 0] = ql[j, 0]
                if part[o] == 0:
                    out_f[k, 1] = ql[j, 1]
                    out_f[k, 2] = ql[j, 2]
                else:
                    out_f[k, 2] = ql[j, 1]
                    out_f[k, 3] = ql[j, 2]
            else:
                out_f[k, 0] = ql[j, 0]
                out_f[k, 1] = ql[j, 1]
            for c in range(nc):
                v = 1.0
                for d in range(D):
                    v *= xi[d] if (c >> d) & 1 else 1.0 - xi[d]
                out_b[k, c] = v
            k += 1
    return out_x, out_w, out_p, out_f, out_b


# ------------------------------------------------------------------------------ public API
_SORT_KEY_LIMIT = 2.0**62
"""_sorted_pieces sorts by one int64 key below this bound, by four stable sorts above it."""


def _check_inputs(grid: Grid, x, facets, body):
    dim = grid.dim
    x = np.asarray(x, dtype=np.float64)
    facets = np.asarray(facets, dtype=np.int64)
    nv = 2 if dim == 2 else 4
    if x.ndim != 2 or x.shape[1] != dim:
        raise GeometryError(f"node positions must have shape (nn, {dim}) for a {dim}-D grid, got {x.shape}")
    if facets.ndim != 2 or facets.shape[1] != nv:
        raise GeometryError(f"facets must have shape (nf, {nv}) in {dim}-D, got {facets.shape}")
    if facets.size and (facets.min() < 0 or facets.max() >= x.shape[0]):
        raise GeometryError(f"facet node indices must lie in [0, {x.shape[0]}), got "
                            f"[{facets.min()}, {facets.max()}]")
    if body is None:
        body = np.zeros(facets.shape[0], dtype=np.int64)
    body = np.asarray(body, dtype=np.int64).reshape(-1)
    if body.size != facets.shape[0] or (body.size and body.min() < 0):
        raise GeometryError(f"body must give a non-negative body index per facet ({facets.shape[0]}), "
                            f"got {body.size} values")
    if not np.all(np.isfinite(x[facets])):
        raise GeometryError("facet node positions must be finite")
    return x, facets, body


def clip_surface(grid: Grid, x, facets, body=None) -> Pieces:
    """The body surfaces (facets into node positions x; body index per facet, default 0) clipped
    against the zones of the grid; see the module docstring for the rules and the quadrature."""
    dim = grid.dim
    x, facets, body = _check_inputs(grid, x, facets, body)
    xs = grid.snap(x)
    beyond = grid.beyond(xs)
    outside = None
    if beyond.any():   # (only then: which of those nodes a facet uses)
        used = np.zeros(x.shape[0], dtype=bool)
        used[facets.reshape(-1)] = True
        outside = used & beyond.any(axis=1)
    if outside is not None and outside.any():
        bad = np.any(outside[facets], axis=1)
        b = int(body[bad].min())
        nodes = facets[bad & (body == b)].reshape(-1)
        node = int(nodes[outside[nodes]].min())
        past = float(np.max(np.maximum(grid.lower - x[node], x[node] - grid.upper) / grid.h))
        hint = ("" if past > 1e-3 else
                f" ({past:.2g} of a zone past the face: a body on a face of the grid must be held on it, by a "
                f"[[boundaries]] symmetry (axis, at) or a fixed or velocity boundary there; the gas presses on "
                f"its other sides only)")
        raise GeometryError(f"body {b} is not inside the grid box [{grid.lower.tolist()}, "
                            f"{grid.upper.tolist()}]: node {node} at {x[node].tolist()}{hint}")
    if dim == 3:   # the quads' two triangles along the diagonal 0-2
        elems = np.concatenate([facets[:, [0, 1, 2]], facets[:, [0, 2, 3]]])
        e_facet = np.concatenate([np.arange(facets.shape[0])] * 2)
        e_part = np.repeat(np.arange(2), facets.shape[0])
    else:
        elems, e_facet, e_part = facets, np.arange(facets.shape[0]), np.zeros(facets.shape[0], np.int64)
    planes = _planes(grid)
    if dim == 2:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = _clip_segments_2d(
            np.ascontiguousarray(xs), np.ascontiguousarray(elems), planes[0, : grid.cells[0] + 1],
            planes[1, : grid.cells[1] + 1], _GAUSS2_T)
    else:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = _clip_kernel(
            np.ascontiguousarray(xs), np.ascontiguousarray(elems), planes, grid.cells.astype(np.int64),
            _GAUSS2_T, _TRI_BARY, _TRI_W)
    zone, pbody, facet, area, normal, centroid, qp, qw, qpiece, qf, qb = _sorted_pieces(
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal, e_facet.astype(np.int64), e_part.astype(np.int64), body,
        grid.cells.astype(np.int64), planes, facets.shape[1], _SORT_KEY_LIMIT)
    return Pieces(zone=zone, body=pbody, facet=facet, area=area, normal=normal, centroid=centroid, qp=qp, qw=qw,
                  qpiece=qpiece, qf=qf, qb=qb)


@njit(cache=True)
def _sorted_pieces(pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal, e_facet, e_part, body, cells, planes, nv,
                   key_limit):
    """The clipped pieces in the canonical order (zone, body, facet, part: np.lexsort's), with their
    quadrature points (``_gather_points``), in one kernel.  A piece is one (zone, facet, part): a
    convex polygon clipped by a box is one polygon, so the order is that of the unique key
    ((zone nb + body) nf + facet) 2 + part; a key that could overflow takes four stable sorts."""
    n = pz.size
    dim = cells.size
    nb = 1
    nf = 1
    for p in range(n):
        f = e_facet[pe[p]]
        nb = max(nb, body[f] + 1)
        nf = max(nf, f + 1)
    nzones = 1
    for d in range(dim):
        nzones *= cells[d]
    if float(nzones) * nb * nf * 2.0 < key_limit:
        key = np.empty(n, np.int64)
        for p in range(n):
            f = e_facet[pe[p]]
            key[p] = ((pz[p] * nb + body[f]) * nf + f) * 2 + e_part[pe[p]]
        order = np.argsort(key)
    else:
        order = np.arange(n)
        col = np.empty(n, np.int64)
        for c in range(4):   # least significant first, each stable
            for t in range(n):
                p = order[t]
                f = e_facet[pe[p]]
                col[t] = e_part[pe[p]] if c == 0 else (f if c == 1 else (body[f] if c == 2 else pz[p]))
            order = order[np.argsort(col, kind="mergesort")]
    zone = np.empty(n, np.int64)
    pbody = np.empty(n, np.int64)
    facet = np.empty(n, np.int64)
    area = np.empty(n)
    normal = np.empty((n, enormal.shape[1]))
    centroid = np.empty((n, pc.shape[1]))
    zijk = np.empty((n, dim), np.int64)
    part = np.empty(n, np.int64)
    for p in range(pe.size):
        part[p] = e_part[pe[p]]
    for t in range(n):
        p = order[t]
        zone[t] = pz[p]
        f = e_facet[pe[p]]
        facet[t] = f
        pbody[t] = body[f]
        area[t] = pa[p]
        for d in range(dim):
            normal[t, d] = enormal[pe[p], d]
            centroid[t, d] = pc[p, d]
        rest = pz[p]
        for d in range(dim):
            zijk[t, d] = rest % cells[d]
            rest //= cells[d]
    qp, qw2, qpiece, qf, qb = _gather_points(order, pq0, pqn, qx, qw, ql, part, zijk, planes, nv)
    return zone, pbody, facet, area, normal, centroid, qp, qw2, qpiece, qf, qb


def _row_coverage(grid: Grid, pieces: Pieces, n_bodies: int, d: int):
    """Run the suffix sums along axis d (``_axis_coverage``): the zone rows, face rows and runs of
    ``_scan_rows``, as (ids, body, value) for zones and faces and (body, ijk of the first zone,
    length) for runs."""
    if pieces.body.size and pieces.body.max() >= n_bodies:
        raise GeometryError(f"pieces name body {int(pieces.body.max())} but n_bodies = {n_bodies}")
    zid, zb, zv, fid, fb, fv, rb, first, length = _axis_coverage(
        np.ascontiguousarray(pieces.zone, dtype=np.int64), np.ascontiguousarray(pieces.body, dtype=np.int64),
        np.ascontiguousarray(pieces.normal[:, d]), np.ascontiguousarray(pieces.centroid[:, d]),
        np.ascontiguousarray(pieces.area, dtype=np.float64), grid.cells.astype(np.int64), _planes(grid), int(d),
        _SNAP)
    return (zid, zb, zv), (fid, fb, fv), (rb, first, length)


def _planes(grid: Grid) -> np.ndarray:
    """(dim, max n + 1) the grid planes of every axis (padded with zeros): grid.Grid's table, or built
    for a grid-like object without one."""
    table = getattr(grid, "plane_table", None)
    if table is not None:
        return table
    out = np.zeros((grid.dim, int(grid.cells.max()) + 1))
    for e in range(grid.dim):
        out[e, : grid.cells[e] + 1] = grid.planes(e)
    return out


def _by_id(ids, bodies, values, n_bodies):
    """(sorted distinct ids, (n, n_bodies) their values per body)."""
    return _by_id_kernel(np.ascontiguousarray(ids, dtype=np.int64), np.ascontiguousarray(bodies, dtype=np.int64),
                         np.ascontiguousarray(values, dtype=np.float64), int(n_bodies))


@njit(cache=True)
def _by_id_kernel(ids, bodies, values, n_bodies):
    """_by_id in one pass when the ids come sorted (the zones and x-faces of one body do), after a sort
    otherwise (np.unique with return_inverse costs ~0.1 ms per thousand ids)."""
    o = np.arange(ids.size)
    if not _is_sorted(ids, o):
        o = np.argsort(ids, kind="mergesort")
    nu = 0
    for t in range(ids.size):
        if t == 0 or ids[o[t]] != ids[o[t - 1]]:
            nu += 1
    u = np.empty(nu, np.int64)
    out = np.zeros((nu, n_bodies))
    k = -1
    for t in range(ids.size):
        p = o[t]
        if t == 0 or ids[p] != ids[o[t - 1]]:
            k += 1
            u[k] = ids[p]
        out[k, bodies[p]] = values[p]
    return u, out


def _expand_runs(first, length, d):
    """ijk (n, dim) of every zone of the runs (first zone ijk, length along axis d)."""
    total = int(length.sum())
    which = np.repeat(np.arange(length.size), length)
    step = np.arange(total) - np.repeat(np.cumsum(length) - length, length)
    ijk = first[which].copy()
    ijk[:, d] += step
    return which, ijk


@dataclass
class Coverage:
    """The bodies in the grid (``coverage``), listed by what the surface touches: the exact blocked
    fraction of every zone a surface piece lies in (sorted ids, (nz, n_bodies)); the zones covered
    whole between them as runs along x, each a range of consecutive zone ids
    ``[run_start, run_start + run_length)`` of body ``run_body`` (ids x fastest); per axis d the exact
    covered fraction of the faces next to a cut zone (sorted ids, (nf, n_bodies)) -- every other face
    a body covers lies between two zones of runs and is covered whole."""

    zones: np.ndarray
    fractions: np.ndarray
    run_start: np.ndarray
    run_length: np.ndarray
    run_body: np.ndarray
    faces: tuple
    total: np.ndarray | None = None       # (nz,) min(Σ_bodies fractions, 1)
    face_totals: tuple | None = None      # per axis (nf,) min(Σ_bodies covered, 1)


def coverage(grid: Grid, pieces: Pieces, n_bodies: int) -> Coverage:
    """Blocked fractions and face coverages of the clipped bodies (1), (2) with the interior as runs:
    one scan of the pieces per axis, work linear in the number of pieces."""
    dim = grid.dim
    if pieces.body.size and pieces.body.max() >= n_bodies:
        raise GeometryError(f"pieces name body {int(pieces.body.max())} but n_bodies = {n_bodies}")
    zones, frac, start, length, rb, fid, fval, foff = _coverage_kernel(
        np.ascontiguousarray(pieces.zone, dtype=np.int64), np.ascontiguousarray(pieces.body, dtype=np.int64),
        np.ascontiguousarray(pieces.normal, dtype=np.float64), np.ascontiguousarray(pieces.centroid, dtype=np.float64),
        np.ascontiguousarray(pieces.area, dtype=np.float64), grid.cells.astype(np.int64), _planes(grid), _SNAP,
        int(n_bodies))
    faces = tuple((fid[foff[d]:foff[d + 1]], fval[foff[d]:foff[d + 1]]) for d in range(dim))
    return Coverage(zones, frac, start, length, rb, faces, _capped_sums(frac),
                    tuple(_capped_sums(v) for _, v in faces))


@njit(cache=True)
def _capped_sums(values):
    """min(sum over the bodies, 1) per row of (n, n_bodies) (bodies do not overlap: sums of disjoint
    parts, capped against round-off)."""
    out = np.empty(values.shape[0])
    for i in range(values.shape[0]):
        s = 0.0
        for b in range(values.shape[1]):
            s += values[i, b]
        out[i] = min(s, 1.0)
    return out


@njit(cache=True)
def _coverage_kernel(zone, body, normal, centroid, area, cells, planes, snap, n_bodies):
    """``coverage`` in one call (one kernel dispatch instead of a dozen calls per step): per axis the
    scan of ``_axis_coverage`` and the faces by id; the zones by id and the runs (as zone ids, sorted
    stably) from the x scan.  Face lists concatenated over the axes, ``foff`` their offsets."""
    dim = cells.size
    fids = []
    fvals = []
    zones = np.zeros(0, np.int64)
    frac = np.zeros((0, n_bodies))
    start = np.zeros(0, np.int64)
    length = np.zeros(0, np.int64)
    rbody = np.zeros(0, np.int64)
    for d in range(dim):
        zid, zb, zv, fid, fb, fv, rb, first, ln = _axis_coverage(
            zone, body, np.ascontiguousarray(normal[:, d]), np.ascontiguousarray(centroid[:, d]), area, cells,
            planes, d, snap)
        fu, fo = _by_id_kernel(fid, fb, fv, n_bodies)
        fids.append(fu)
        fvals.append(fo)
        if d == 0:
            zones, frac = _by_id_kernel(zid, zb, zv, n_bodies)
            ids = np.empty(ln.size, np.int64)
            for t in range(ln.size):
                v = 0
                for e in range(dim - 1, -1, -1):
                    v = v * cells[e] + first[t, e]
                ids[t] = v
            o = np.argsort(ids, kind="mergesort")
            start = ids[o]
            length = ln[o]
            rbody = rb[o]
    foff = np.zeros(dim + 1, np.int64)
    for d in range(dim):
        foff[d + 1] = foff[d] + fids[d].size
    fid_all = np.empty(foff[dim], np.int64)
    fval_all = np.empty((foff[dim], n_bodies))
    for d in range(dim):
        fid_all[foff[d]:foff[d + 1]] = fids[d]
        fval_all[foff[d]:foff[d + 1], :] = fvals[d]
    return zones, frac, start, length, rbody, fid_all, fval_all, foff


def blocked_fractions(grid: Grid, pieces: Pieces, n_bodies: int):
    """``(zone_ids (nz,), fractions (nz, n_bodies))``: the exact volume fraction of every zone covered
    by each body (1) -- cut zones and fully covered ones, only zones with a positive fraction,
    sorted by zone id (every zone listed: for tests and tools; the coupled step uses ``coverage``)."""
    (ids, b, v), _, (rb, first, length) = _row_coverage(grid, pieces, n_bodies, 0)
    which, ijk = _expand_runs(first, length, 0)
    return _by_id(np.concatenate([ids, grid.zone_ids(ijk).reshape(-1)]), np.concatenate([b, rb[which]]),
                  np.concatenate([v, np.ones(which.size)]), n_bodies)


def face_coverage(grid: Grid, pieces: Pieces, n_bodies: int, d: int):
    """``(face_ids (nf,), covered (nf, n_bodies))``: the exact covered fraction of every face normal to
    axis d (grid.face_ids) that a body covers at least partly (2), sorted by face id (every face
    listed, the runs' inner faces too)."""
    if not 0 <= d < grid.dim:
        raise GeometryError(f"axis d must be in [0, {grid.dim}), got {d}")
    _, (ids, b, v), (rb, first, length) = _row_coverage(grid, pieces, n_bodies, d)
    inner = np.maximum(length - 1, 0)  # faces k of the run with k - 1 and k both in it
    first = first.copy()
    first[:, d] += 1
    which, ijk = _expand_runs(first, inner, d)
    return _by_id(np.concatenate([ids, grid.face_ids(d, ijk).reshape(-1)]), np.concatenate([b, rb[which]]),
                  np.concatenate([v, np.ones(which.size)]), n_bodies)


def closed_surface_from_cells(points, cells, cell_type: str) -> np.ndarray:
    """Exterior facets of a quad (2-D: segments (nf, 2)) or hexahedron (3-D: quads (nf, 4)) mesh,
    oriented with the outward normal of clip_surface's convention; inverted cells are mirrored
    first.  Facets in the order of their cells and local faces."""
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    if cell_type == "quad":
        local, flip = _QUAD_EDGES, _QUAD_FLIP
        x = points[cells]
        signed = 0.5 * np.sum(x[:, :, 0] * np.roll(x[:, :, 1], -1, axis=1)
                              - np.roll(x[:, :, 0], -1, axis=1) * x[:, :, 1], axis=1)   # shoelace
    elif cell_type == "hexahedron":
        local, flip = _HEX_FACES, _HEX_FLIP
        f = points[cells[:, local]]                                   # (ne, 6, 4, 3)
        s = 0.5 * np.cross(f[:, :, 2] - f[:, :, 0], f[:, :, 3] - f[:, :, 1])
        signed = np.sum(np.einsum("efk,efk->ef", f.mean(axis=2), s), axis=1) / 3.0   # div theorem
    else:
        raise GeometryError(f"cell_type must be 'quad' or 'hexahedron', got {cell_type!r}")
    if cells.ndim != 2 or cells.shape[1] != flip.size:
        raise GeometryError(f"{cell_type} cells must have shape (ne, {flip.size}), got {cells.shape}")
    cells = np.where((signed < 0)[:, None], cells[:, flip], cells)
    faces = cells[:, local].reshape(-1, local.shape[1])
    _, inv, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inv.reshape(-1)] == 1]


# ------------------------------------------------------------------------------- cost probe
def cube_sphere_surface(n: int, radius: float = 1.0, centre=(0.0, 0.0, 0.0)):
    """A closed sphere-like quad surface: the 6 n^2 boundary quads of an n^3 hex cube projected
    radially onto the sphere (outward).  Returns (points (nn, 3), quads (6 n^2, 4))."""
    t = np.linspace(-1.0, 1.0, n + 1)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    ids = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    c = ids[:-1, :-1, :-1].reshape(-1)
    sx, sy, sz = (n + 1) ** 2, n + 1, 1
    cells = np.stack([c, c + sx, c + sx + sy, c + sy, c + sz, c + sx + sz, c + sx + sy + sz, c + sy + sz], 1)
    quads = closed_surface_from_cells(g, cells, "hexahedron")
    used = np.unique(quads)
    remap = np.full(g.shape[0], -1, np.int64)
    remap[used] = np.arange(used.size)
    p = g[used]
    p = np.asarray(centre, dtype=np.float64) + radius * p / np.linalg.norm(p, axis=1)[:, None]
    return p, remap[quads]


def warm_kernels() -> None:
    """Compile (or load from the cache) every kernel of this module: one tiny 2-D and 3-D body (for
    an install-time warm-up such as orchestrator/warmup.py)."""
    for dim, (x, f) in ((2, (np.array([[0.2, 0.2], [0.8, 0.3], [0.5, 0.7]]), np.array([[0, 1], [1, 2], [2, 0]]))),
                        (3, cube_sphere_surface(1, 0.5))):
        grid = Grid([-1.0] * dim, [1.0] * dim, [3] * dim)
        pieces = clip_surface(grid, x, f)
        blocked_fractions(grid, pieces, 1)
        face_coverage(grid, pieces, 1, 1)


def geometry_cost(n_facets: int) -> dict:
    """Wall times of the interface geometry for a sphere-like closed surface of about ``n_facets``
    quads on a grid whose zones are about the facets' size (for ``immerse bench coupling``; the
    kernels are compiled by a small warm-up call first, not timed)."""
    m = max(1, int(round(np.sqrt(n_facets / 6.0))))
    x, quads = cube_sphere_surface(m, radius=1.0)
    cells = max(2, int(round(1.5 * m)))          # zone width ~ the facets' arc length (pi/2 / m)
    grid = Grid([-1.25] * 3, [1.25] * 3, [cells] * 3)
    warm_kernels()
    t0 = time.perf_counter()
    pieces = clip_surface(grid, x, quads)
    t1 = time.perf_counter()
    zones, _ = blocked_fractions(grid, pieces, 1)
    t2 = time.perf_counter()
    for d in range(3):
        face_coverage(grid, pieces, 1, d)
    t3 = time.perf_counter()
    return {"n_facets": int(quads.shape[0]), "cells": [cells] * 3, "n_pieces": int(pieces.zone.size),
            "n_points": int(pieces.qw.size), "n_blocked_zones": int(zones.size),
            "clip_s": t1 - t0, "fractions_s": t2 - t1, "faces_s": t3 - t2}
