"""Blocked fractions and face coverages of the clipped bodies (geometry.py clips them).

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

from dataclasses import dataclass

import numpy as np
from numba import njit

from orchestrator.coupling.grid import Grid
from orchestrator.coupling.pieces import _SNAP, GeometryError, Pieces, _grow1, _grow2, _planes


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
