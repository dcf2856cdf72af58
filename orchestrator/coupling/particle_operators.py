"""The coupling geometry and operators of a particle (SPH) body in the background grid (Tsuji, Puso,
Spangler, Owen et al., "Embedded smoothed particle hydrodynamics", CMAME 366 (2020); the seed's
"Couple particles to background").

A particle body has no mesh: its interface Gamma is the iso-surface c = 1/2 of the particles'
colour function at the background nodes (particle_surface.py: marching squares / tetrahedra per
zone, closed and outward-oriented), rebuilt from the particle positions at every step.  That
surface is clipped by the zones exactly as a Lagrangian body's (geometry.clip_surface), so the
blocked fractions and face coverages of the restricted advection, the areas, normals and B^b are
the mesh body's.  Only B^f changes: the foreground velocity on Gamma is the particles'
Shepard-normalised kernel interpolation, so

    B^f_ei = ∫_{Γ_e} W_i / Σ_j W_j dΓ   (W_i = V_i W(|x - x_i|, h), Lucy kernel, support h),

integrated with the pieces' quadrature points (geometry.py: degree 3 in 2-D, 4 in 3-D).  Its
columns are particles.  The Shepard weights of a point sum to 1 (a point beyond every kernel, where
the surface runs straight across a zone coarser than h, takes its nearest particle's velocity), so
every row of B^f sums to the cut area A_e, as every row of B^b does: the impulses on particles and
background are equal and opposite.

Cost.  This runs every coupled step on the coupler's rank, between the correction and the next
step, and counts in the coupler's share of the step (summary.json coupling_share; the issue's
target: coupler + reconstruction <= 20 % of the coupled step, `immerse bench sph`).  The surface of
a particle body is small (tens to hundreds of cut zones) and its particles many, so the
array-by-array form (boundary images, colour, ~25 numpy calls of marching, clipping, the pieces
facing gas, Operators.build, coverage, Shepard weights, Z @ S and three more scipy matrices: ~1.2
ms a step on the 4k-particle dam break, mostly call overhead) is done by two numba kernels,
``_surface_kernel`` (colour with the images, marching, snapping) and ``_interface_kernel``
(clipping, coverage, operators, B^f), which call geometry.py's and operator_rows.py's kernels
directly and give the same arrays bit for bit (tests compare them with ``reference_interface``,
the array form kept for that): ~0.4 ms a step, about half of it the two passes over all particles
(colour, Shepard neighbours).
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np
import scipy.sparse as sp
from numba import njit

from orchestrator.coupling import clipping as CL
from orchestrator.coupling import coverage as CV
from orchestrator.coupling import geometry as G
from orchestrator.coupling import pieces as P
from orchestrator.coupling.grid import SNAP_ULPS
from orchestrator.coupling.operator_rows import on_grid_boundary, operator_arrays
from orchestrator.coupling.operators import MIN_AREA_FRACTION, NORMAL_FALLBACK_RATIO, Operators
from orchestrator.coupling.particle_surface import (_SQ_COUNT, _SQ_TABLE, _TET_COUNT, _TET_TABLE, _TETS,
                                                    _colour_kernel, _grid, _lucy, _lucy_norm, _march, _particles,
                                                    as_coupling_facets, colour_at_nodes, colour_planes,
                                                    march_planes, reconstruct, shepard_weights)


class ParticleInterface:
    """The reconstructed surface and its geometry: points (nv, dim) its vertices; facets (nf, 2 | 4)
    segments / quads (a, b, c, c) of the coupling geometry; pieces (geometry.Pieces) of the whole
    surface (fractions, coverages); inner, the pieces facing gas (the operators'); ops (Operators,
    B^f over particles); coverage (geometry.Coverage of the pieces, one body; None: not computed).
    ``inner`` may be given as a function that builds it: it is then built on first use (the
    coupled step does not need it as Pieces, only the operators built from it)."""

    def __init__(self, points, facets, pieces, inner, ops, coverage=None):
        self.points, self.facets, self.pieces, self._inner, self.ops, self.coverage = (
            points, facets, pieces, inner, ops, coverage)

    @property
    def inner(self):
        if callable(self._inner):
            self._inner = self._inner()
        return self._inner


# ------------------------------------------------------------------------ the array form (reference)
def particle_rows(ops: Operators, inner, x: np.ndarray, volume: np.ndarray, h: float) -> sp.csr_matrix:
    """B^f (n_zones x n_particles): the quadrature of the Shepard weights over each zone's pieces."""
    qzone = np.asarray(inner.zone, dtype=np.int64)[np.asarray(inner.qpiece, dtype=np.int64)]
    if ops.zones.size == 0:
        return sp.csr_matrix((0, len(x)))
    # the row of each point's zone; points of zones without a multiplier (zero area) are dropped
    row = np.minimum(np.searchsorted(ops.zones, qzone), ops.zones.size - 1)
    q = np.flatnonzero(ops.zones[row] == qzone)
    Z = sp.csr_matrix((np.asarray(inner.qw, float)[q], (row[q], q)), shape=(ops.zones.size, qzone.size))
    S = shepard_weights(np.asarray(inner.qp, float), x, volume, h)
    lone = np.flatnonzero(np.diff(S.indptr) == 0)
    if lone.size:
        # a quadrature point beyond every particle's kernel (the surface runs straight between its
        # vertices on grid edges, which can lie up to a zone from the particles): its weight goes
        # to the nearest particle, so every row still sums to the cut area (momentum balance)
        from scipy.spatial import cKDTree

        _, near = cKDTree(x).query(np.asarray(inner.qp, float)[lone])
        S = (S + sp.csr_matrix((np.ones(lone.size), (lone, near)), shape=S.shape)).tocsr()
    Bf = (Z @ S).tocsr()
    Bf.sort_indices()
    return Bf


def boundary_images(grid, x: np.ndarray, volume: np.ndarray, h: float):
    """The particles with their images across the grid's boundary planes (within h of a plane:
    mirrored across it, or shifted by the period on a periodic axis), for the colour function only:
    a body that reaches the boundary keeps c ~ 1 up to it instead of the half kernel's ~ 1/2, so its
    reconstructed surface meets the boundary where the body does.  (The kernels add the images
    without building this array: particle_surface._colour_kernel.)"""
    xs, vs = [x], [volume]
    periodic = np.asarray(grid.periodic, dtype=bool)
    for d in range(grid.dim):   # (per axis; corners get no double image: c stays above 1/2 there)
        lo, hi = float(grid.lower[d]), float(grid.upper[d])
        for near, image in ((x[:, d] < lo + h, hi - lo if periodic[d] else 2.0 * lo),
                            (x[:, d] > hi - h, lo - hi if periodic[d] else 2.0 * hi)):
            xi = x[near].copy()
            xi[:, d] = xi[:, d] + image if periodic[d] else image - xi[:, d]
            xs.append(xi)
            vs.append(volume[near])
    return np.concatenate(xs), np.concatenate(vs)


def _no_surface(iso: float):
    return P.GeometryError(f"the SPH particles form no surface on the background grid (their colour "
                           f"function stays below {iso:g} at every node: the body has come apart into "
                           "particles further apart than the smoothing length)")


def reference_interface(grid, x: np.ndarray, volume: np.ndarray, h: float, iso: float = 0.5) -> ParticleInterface:
    """``particle_interface`` array by array (boundary images, colour, marching, clip_surface,
    facing_the_grid, Operators.build, Z @ S): what the kernels must reproduce, and the readable form
    of what they do."""
    from orchestrator.coupling.operator_rows import facing_the_grid

    xg, vg = boundary_images(grid, x, volume, h)
    c = colour_at_nodes(grid.lower, grid.h, grid.cells, xg, vg, h)
    points, tri = reconstruct(grid.lower, grid.h, grid.cells, c, iso, close_on_boundary=True)
    if len(tri) == 0:
        raise _no_surface(iso)
    facets = as_coupling_facets(tri)
    pieces = G.clip_surface(grid, points, facets, np.zeros(len(facets), np.int64))
    inner = facing_the_grid(grid, pieces)
    ops = Operators.build(grid, inner, facets, len(points))
    ops = dataclasses.replace(ops, Bf=particle_rows(ops, inner, x, volume, h))
    return ParticleInterface(points, facets, pieces, inner, ops, CV.coverage(grid, pieces, 1))


# ------------------------------------------------------------------------------------ the kernels
@functools.lru_cache(maxsize=16)
def _constants(grid):
    """Per grid (grid.Grid hashes by identity): the writable float/int copies the kernels take (one
    specialisation whatever the caller's arrays' flags), computed once."""
    lower, spacing, cells = _grid(grid.lower, grid.h, grid.cells)
    p3, n3 = colour_planes(lower, spacing, cells)
    return dict(
        lower=np.array(grid.lower, dtype=np.float64), upper=np.array(grid.upper, dtype=np.float64),
        zone_h=np.array(grid.h, dtype=np.float64), cells=np.array(grid.cells, dtype=np.int64),
        periodic=np.asarray(grid.periodic, dtype=np.uint8),
        cplanes=p3, cnodes=n3, mplanes=march_planes(lower, spacing, cells, True),
        planes=np.array(P._planes(grid), dtype=np.float64),
        snap_tol=SNAP_ULPS * np.finfo(np.float64).eps * np.maximum(np.abs(grid.lower), np.abs(grid.upper)),
        full_area=float(grid.zone_volume) ** ((grid.dim - 1) / grid.dim),
        width=float(grid.zone_volume) ** (1.0 / grid.dim))


@njit(cache=True)
def _surface_kernel(x, vol, h, norm, iso, cplanes, cnodes, lower, upper, periodic, mplanes, cells,
                    sq_table, sq_count, tets, tet_table, tet_count, planes, snap_tol):
    """Colour at the nodes with the boundary images, the marching, and the vertices snapped as
    ``Grid.snap`` snaps a surface's nodes: (points, facets, snapped points, any vertex beyond the
    grid's box)."""
    c = np.zeros(cnodes[0] * cnodes[1] * cnodes[2])
    _colour_kernel(x, vol, h, norm, cplanes, cnodes, lower, upper, periodic, True, c)
    points, tri = _march(c, cells, iso, mplanes, sq_table, sq_count, tets, tet_table, tet_count)
    nv, dim = points.shape
    xs = points.copy()
    beyond = False
    for v in range(nv):
        for d in range(dim):
            n = cells[d]
            k = np.rint((xs[v, d] - lower[d]) / (upper[d] - lower[d]) * n)
            k = min(max(k, 0.0), float(n))
            X = planes[d, int(k)]
            if abs(xs[v, d] - X) <= snap_tol[d]:
                xs[v, d] = X
            if xs[v, d] < lower[d] or xs[v, d] > upper[d]:
                beyond = True
    return points, tri, xs, beyond


@njit(cache=True)
def _interface_kernel(x, vol, h, norm, xs, tri, cells, planes, lower, upper, zone_h, periodic, gauss_t,
                      tri_bary, tri_w, key_limit, cov_snap, min_area, fallback_ratio):
    """clip_surface, coverage (one body), facing_the_grid, Operators.build's arrays and B^f in one
    dispatch, from the snapped surface ``xs``/``tri`` of ``_surface_kernel``."""
    dim = cells.size
    nf = tri.shape[0]
    # the coupling facets (as_coupling_facets: 3-D triangles as quads (a, b, c, c)) and the elements
    # clip_surface cuts (3-D: each quad's triangles (0, 1, 2) and (0, 2, 3))
    nv = 2 if dim == 2 else 4
    facets = np.empty((nf, nv), np.int64)
    for f in range(nf):
        for k in range(nv):
            facets[f, k] = tri[f, min(k, dim - 1)]
    ne = nf if dim == 2 else 2 * nf
    elems = np.empty((ne, dim), np.int64)
    e_facet = np.empty(ne, np.int64)
    e_part = np.zeros(ne, np.int64)
    for f in range(nf):
        if dim == 2:
            elems[f, 0] = facets[f, 0]
            elems[f, 1] = facets[f, 1]
            e_facet[f] = f
        else:
            for k in range(3):
                elems[f, k] = facets[f, k]
            elems[nf + f, 0] = facets[f, 0]
            elems[nf + f, 1] = facets[f, 2]
            elems[nf + f, 2] = facets[f, 3]
            e_facet[f] = f
            e_facet[nf + f] = f
            e_part[nf + f] = 1
    if dim == 2:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = CL._clip_segments_2d(
            xs, elems, planes[0, : cells[0] + 1].copy(), planes[1, : cells[1] + 1].copy(), gauss_t)
    else:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = CL._clip_kernel(xs, elems, planes, cells, gauss_t,
                                                                       tri_bary, tri_w)
    body = np.zeros(nf, np.int64)
    zone, pbody, facet, area, normal, centroid, qp, qw, qpiece, qf, qb = G._sorted_pieces(
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal, e_facet, e_part, body, cells, planes, nv, key_limit)
    cov = CV._coverage_kernel(zone, pbody, normal, centroid, area, cells, planes, cov_snap, 1)
    # the pieces facing gas (operator_rows.facing_the_grid): those on the grid's boundary planes dropped
    on, count = on_grid_boundary(centroid, normal, lower, upper, zone_h)
    if count == 0:
        izone, iarea, inormal, ifacet = zone, area, normal, facet
        iqp, iqw, iqpiece, iqf, iqb = qp, qw, qpiece, qf, qb
    else:
        remap = np.full(zone.size, -1, np.int64)
        m = 0
        for p in range(zone.size):
            if not on[p]:
                remap[p] = m
                m += 1
        izone = np.empty(m, np.int64)
        iarea = np.empty(m)
        inormal = np.empty((m, dim))
        ifacet = np.empty(m, np.int64)
        for p in range(zone.size):
            r = remap[p]
            if r >= 0:
                izone[r] = zone[p]
                iarea[r] = area[p]
                ifacet[r] = facet[p]
                for d in range(dim):
                    inormal[r, d] = normal[p, d]
        mq = 0
        for q in range(qpiece.size):
            if remap[qpiece[q]] >= 0:
                mq += 1
        iqp = np.empty((mq, dim))
        iqw = np.empty(mq)
        iqpiece = np.empty(mq, np.int64)
        iqf = np.empty((mq, qf.shape[1]))
        iqb = np.empty((mq, qb.shape[1]))
        t = 0
        for q in range(qpiece.size):
            r = remap[qpiece[q]]
            if r >= 0:
                iqp[t, :] = qp[q, :]
                iqw[t] = qw[q]
                iqpiece[t] = r
                iqf[t, :] = qf[q, :]
                iqb[t, :] = qb[q, :]
                t += 1
    ops = operator_arrays(izone, iarea, inormal, iqpiece, iqw, iqb, iqf, ifacet, facets, min_area, fallback_ratio,
                          cells, periodic)
    zones, prow = ops[0], ops[9]
    # B^f over particles: the Shepard weights at the points of the kept rows, their quadrature
    qrow = np.empty(iqpiece.size, np.int64)
    for q in range(iqpiece.size):
        qrow[q] = prow[iqpiece[q]]
    sptr, sidx, sval, lone = _shepard_at(iqp, qrow, zones, x, vol, h, norm, planes, cells)
    fptr, fcol, fval = _particle_rows(zones.size, qrow, iqw, sptr, sidx, sval, np.full(qrow.size, -1, np.int64))
    return (facets, zone, pbody, facet, area, normal, centroid, qp, qw, qpiece, qf, qb, cov, on, count, ops,
            qrow, iqw, sptr, sidx, sval, lone, fptr, fcol, fval)


@njit(cache=True, inline="always")
def _zone_span(v, h, X, n, x0, iw):
    """The zones i of an axis with planes X (n zones) whose closed slab [X_i, X_i+1] comes closer
    than h to the coordinate v: X_i < v + h and X_i+1 > v - h, from the estimate by the inverse
    width, corrected on the exact planes (so a point on a slab's face is found from either side).
    Returns (lo, hi); lo > hi when none."""
    lo = int(min(max(np.floor((v - h - x0) * iw), 0.0), n - 1.0))
    while lo > 0 and X[lo] > v - h:
        lo -= 1
    while lo < n and X[lo + 1] <= v - h:
        lo += 1
    hi = int(min(max(np.floor((v + h - x0) * iw), 0.0), n - 1.0))
    while hi < n - 1 and X[hi + 1] < v + h:
        hi += 1
    while hi >= 0 and X[hi] >= v + h:
        hi -= 1
    return lo, hi


@njit(cache=True, inline="always")
def _dist2(a, i, b, j, dim):
    """|a_i - b_j|^2, summed over the axes in order (the one rounding the count and the weights share)."""
    r2 = 0.0
    for d in range(dim):
        r2 += (a[i, d] - b[j, d]) ** 2
    return r2


@njit(cache=True)
def _row_particles(rows, box, zlo, zn, x, h, planes, cells):
    """The particles that may lie within h of a point of each kept row, as CSR over the rows
    (``rptr``, ``rj``), each row's in ascending particle order: every particle j is listed under the
    rows of the zones whose slabs come within h of it (``_zone_span`` per axis, in the table of the
    cut zones' bounding box)."""
    dim = cells.size
    iw = np.ones(3)
    for d in range(dim):
        iw[d] = 1.0 / ((planes[d, cells[d]] - planes[d, 0]) / cells[d])
    # the zones within a radius a little above h: a point on a slab's face exactly h away (in exact
    # arithmetic) may still pass the rounded distance test of _shepard_at
    reach = h * (1.0 + 1e-9)
    lo = np.zeros(3, np.int64)
    hi = np.zeros(3, np.int64)
    rptr = np.zeros(rows + 1, np.int64)
    rj = np.empty(0, np.int64)
    for fill in range(2):   # count, then list (the same scan)
        if fill == 1:
            for r in range(rows):
                rptr[r + 1] += rptr[r]
            rj = np.empty(rptr[rows], np.int64)
            at = rptr[:-1].copy()
        for j in range(x.shape[0] if rows > 0 else 0):
            empty = False
            for d in range(dim):
                a, b = _zone_span(x[j, d], reach, planes[d], cells[d], planes[d, 0], iw[d])
                a = max(a, zlo[d]) - zlo[d]
                b = min(b, zlo[d] + zn[d] - 1) - zlo[d]
                if a > b:
                    empty = True
                    break
                lo[d] = a
                hi[d] = b
            if empty:
                continue
            for k in range(lo[2], hi[2] + 1):
                for jj in range(lo[1], hi[1] + 1):
                    for i in range(lo[0], hi[0] + 1):
                        r = box[(k * zn[1] + jj) * zn[0] + i]
                        if r < 0:
                            continue
                        if fill == 0:
                            rptr[r + 1] += 1
                        else:
                            rj[at[r]] = j
                            at[r] += 1
    return rptr, rj


@njit(cache=True)
def _shepard_at(qp, qrow, zones, x, vol, h, norm, planes, cells):
    """The Shepard weights ``S_qj = V_j W(|p_q - x_j|) / sum_k V_k W(|p_q - x_k|)`` at the points of
    the kept rows (``qrow >= 0``) as CSR over the points (columns ascending), and the points with no
    particle within h (``lone``).

    The points lie in the cut zones: each particle is listed under the kept rows whose zones' slabs
    come within h of it (``_row_particles``: 1-2 zones per axis at h = w/2), and each point is tested
    against its row's list only -- no cell lists of all the particles (``shepard_weights`` builds
    those: ~4 passes and a sort).  A row's list is in particle order, so each point's columns come
    out ascending and its normalisation sums them in that order, as ``shepard_weights`` does.
    (Listing per row instead of scanning pairs per particle and sorting them by point: the same
    weights bit for bit, in a third of the time of the 3-D penetrator's interface.)"""
    dim = cells.size
    nq = qp.shape[0]
    nz = zones.size
    # the kept rows' points are contiguous (pieces sorted by zone); the zone box of the rows
    rq0 = np.zeros(nz, np.int64)
    rq1 = np.zeros(nz, np.int64)
    for q in range(nq - 1, -1, -1):
        r = qrow[q]
        if r >= 0:
            if rq1[r] == 0:
                rq1[r] = q + 1
            rq0[r] = q
    zlo = np.zeros(3, np.int64)
    zn = np.ones(3, np.int64)
    if nz > 0:
        stride = 1
        for d in range(dim):
            lo = cells[d]
            hi = 0
            for r in range(nz):
                i = (zones[r] // stride) % cells[d]
                lo = min(lo, i)
                hi = max(hi, i)
            zlo[d] = lo
            zn[d] = hi - lo + 1
            stride *= cells[d]
    box = np.full(zn[0] * zn[1] * zn[2], -1, np.int64)   # zone of the box (x fastest) -> row
    for r in range(nz):
        rest = zones[r]
        b = 0
        bs = 1
        for d in range(dim):
            b += ((rest % cells[d]) - zlo[d]) * bs
            rest //= cells[d]
            bs *= zn[d]
        box[b] = r
    # every point of a kept row against the particles listed for its row, in particle order: each
    # row's columns come out ascending and its normalisation sums them in that order, as
    # ``shepard_weights`` does (counted first, then written in place: no pair list to sort)
    rptr, rj = _row_particles(nz, box, zlo, zn, x, h, planes, cells)
    h2 = h * h
    sptr = np.zeros(nq + 1, np.int64)
    for r in range(nz):
        for q in range(rq0[r], rq1[r]):
            c = 0
            for t in range(rptr[r], rptr[r + 1]):
                if _dist2(qp, q, x, rj[t], dim) < h2:
                    c += 1
            sptr[q + 1] = c
    for q in range(nq):
        sptr[q + 1] += sptr[q]
    sidx = np.empty(sptr[nq], np.int64)
    sval = np.empty(sptr[nq])
    for r in range(nz):
        for q in range(rq0[r], rq1[r]):
            w = sptr[q]
            for t in range(rptr[r], rptr[r + 1]):
                j = rj[t]
                r2 = _dist2(qp, q, x, j, dim)
                if r2 < h2:
                    sidx[w] = j
                    sval[w] = vol[j] * _lucy(r2, h, norm)
                    w += 1
    nlone = 0
    for q in range(nq):
        if qrow[q] >= 0 and sptr[q + 1] == sptr[q]:
            nlone += 1
    lone = np.empty(nlone, np.int64)
    nlone = 0
    for q in range(nq):
        s = 0.0
        for t in range(sptr[q], sptr[q + 1]):
            s += sval[t]
        for t in range(sptr[q], sptr[q + 1]):
            sval[t] = sval[t] / s
        if qrow[q] >= 0 and sptr[q + 1] == sptr[q]:
            lone[nlone] = q
            nlone += 1
    return sptr, sidx, sval, lone


@njit(cache=True)
def _particle_rows(nrows, qrow, qw, sptr, sidx, sval, near):
    """B^f's CSR: row r = sum over its points q (in order) of qw_q S_q (a lone point, ``near[q] >= 0``:
    weight 1 on that particle) -- scipy's ``Z @ S`` (csr_matmat) term for term: each column's sum
    accumulated over the points in order, columns sorted, exact zero sums dropped.  (The sums in a
    dense accumulator over the particles, added in that same order: the same bits as sorting every
    row's terms, which took ~25 % of the 3-D interface kernel.)"""
    nq = qrow.size
    cap = 0
    ncol = 0
    for q in range(nq):
        if qrow[q] >= 0:
            cap += max(sptr[q + 1] - sptr[q], 1)
        ncol = max(ncol, near[q] + 1)
    for t in range(sidx.size):
        ncol = max(ncol, sidx[t] + 1)
    fptr = np.zeros(nrows + 1, np.int64)
    fcol = np.empty(cap, np.int64)
    fval = np.empty(cap)
    acc = np.zeros(ncol)
    seen = np.zeros(ncol, np.uint8)
    touched = np.empty(min(cap, ncol), np.int64)
    nf = 0
    q = 0
    for r in range(nrows):
        while q < nq and qrow[q] != r:
            q += 1
        m = 0
        while q < nq and qrow[q] == r:
            if sptr[q + 1] > sptr[q]:
                for t in range(sptr[q], sptr[q + 1]):
                    c = sidx[t]
                    if seen[c] == 0:
                        seen[c] = 1
                        touched[m] = c
                        m += 1
                    acc[c] += qw[q] * sval[t]
            elif near[q] >= 0:
                c = near[q]
                if seen[c] == 0:
                    seen[c] = 1
                    touched[m] = c
                    m += 1
                acc[c] += qw[q] * 1.0
            q += 1
        cols = np.sort(touched[:m])
        for t in range(m):
            c = cols[t]
            if acc[c] != 0.0:
                fcol[nf] = c
                fval[nf] = acc[c]
                nf += 1
            acc[c] = 0.0
            seen[c] = 0
        fptr[r + 1] = nf
    return fptr, fcol[:nf], fval[:nf]


# ------------------------------------------------------------------------------------- the interface
def particle_interface(grid, x: np.ndarray, volume: np.ndarray, h: float, iso: float = 0.5) -> ParticleInterface:
    """The reconstructed interface of the particles ``x`` (n, dim) with volumes ``volume`` (n,) and
    kernel support ``h`` in ``grid`` (geometry.Grid), and its operators (columns of B^f: particles).
    The surface closes on the grid's boundary planes where the body reaches them (those facets
    count for the fractions and get no multiplier: embedded.facing_the_grid)."""
    k = _constants(grid)
    dim = grid.dim
    x, volume, h = _particles(x, volume, h, dim)
    norm = _lucy_norm(dim, h)
    points, tri, xs, beyond = _surface_kernel(
        x, volume, h, norm, float(iso), k["cplanes"], k["cnodes"], k["lower"], k["upper"], k["periodic"],
        k["mplanes"], k["cells"], _SQ_TABLE, _SQ_COUNT, _TETS, _TET_TABLE, _TET_COUNT, k["planes"], k["snap_tol"])
    if len(tri) == 0:
        raise _no_surface(iso)
    if beyond:   # (not expected: the surface closes on the boundary planes) clip_surface's own error
        G.clip_surface(grid, points, as_coupling_facets(tri))
    (facets, zone, pbody, facet, area, normal, centroid, qp, qw, qpiece, qf, qb, cov, on, count, ops, qrow, iqw,
     sptr, sidx, sval, lone, fptr, fcol, fval) = _interface_kernel(
        x, volume, h, norm, xs, tri, k["cells"], k["planes"], k["lower"], k["upper"], k["zone_h"], k["periodic"],
        CL._GAUSS2_T, CL._TRI_BARY, CL._TRI_W, G._SORT_KEY_LIMIT, P._SNAP, MIN_AREA_FRACTION, NORMAL_FALLBACK_RATIO)
    pieces = P.Pieces(zone=zone, body=pbody, facet=facet, area=area, normal=normal, centroid=centroid, qp=qp, qw=qw,
                      qpiece=qpiece, qf=qf, qb=qb)
    if count:
        from orchestrator.coupling.operator_rows import facing_the_grid

        inner = functools.partial(facing_the_grid, grid, pieces)   # (built only if asked for)
    else:
        inner = pieces
    czones, frac, start, length, rb, fid, fval_c, foff = cov
    faces = tuple((fid[foff[d]:foff[d + 1]], fval_c[foff[d]:foff[d + 1]]) for d in range(dim))
    coverage = CV.Coverage(czones, frac, start, length, rb, faces, CV._capped_sums(frac),
                          tuple(CV._capped_sums(v) for _, v in faces))
    out = ParticleInterface(points, facets, pieces, inner, None, coverage)
    zones, area_e, avec, bw, normal_e, fallback, _, _, _, prow, bnodes, columns, pairs = ops
    if lone.size:
        # a quadrature point beyond every particle's kernel (the surface runs straight between its
        # vertices on grid edges, which can lie up to a zone from the particles): its weight goes
        # to the nearest particle, so every row still sums to the cut area (momentum balance)
        from scipy.spatial import cKDTree

        near = np.full(qrow.size, -1, np.int64)
        near[lone] = cKDTree(x).query(out.inner.qp[lone])[1]
        fptr, fcol, fval = _particle_rows(zones.size, qrow, iqw, sptr, sidx, sval, near)
    if fallback.any():
        from orchestrator.coupling.operators import _fallback_normals

        live = prow >= 0
        _fallback_normals(normal_e, fallback, avec, prow[live], out.inner.area[live], out.inner.normal[live])
    nz = zones.size
    Bb = sp.csr_matrix((bw.ravel(), columns.ravel(), np.arange(nz + 1, dtype=np.int64) * 2**dim),
                       shape=(nz, bnodes.size))
    Bf = sp.csr_matrix((fval, fcol, fptr), shape=(nz, len(x)))
    out.ops = Operators(zones=zones, bnodes=bnodes, Bb=Bb, Bf=Bf, area=area_e, avec=avec, normal=normal_e,
                        fallback=fallback, pairs=pairs, full_area=k["full_area"], width=k["width"])
    return out


def _flush_stale_cache() -> None:
    """particle_surface.py's colour and marching kernels, the interface geometry's clipping, sorting and
    coverage (clipping.py, geometry.py, coverage.py, pieces.py) and operator_rows.py's operator sums are
    compiled into these kernels (see solvers.numba_cache): drop their cache when one of those files
    changed."""
    from orchestrator.coupling import operator_rows as _rows
    from orchestrator.coupling import particle_surface as _surface
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([_surface_kernel, _interface_kernel, _zone_span, _dist2, _row_particles, _shepard_at, _particle_rows],
                      [G.__file__, CL.__file__, CV.__file__, P.__file__, _rows.__file__, _surface.__file__],
                      "particle_operators.deps.sha256")


_flush_stale_cache()
