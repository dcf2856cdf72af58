"""The per-zone sums of `operators.Operators.build` in one numba kernel (kept apart from operators.py
so that validating a case, which imports the coupling variants' schemas, imports no numba)."""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit


@njit(cache=True)
def zone_rows(pzone, parea, pnormal, qpiece, qw, qb, qf, pfacet, facets):
    """The per-zone sums of ``Operators.build`` over pieces sorted by zone: zone ids, area, area
    vector, B^b weights (nz, 2^dim) = Σ_points qw φ^b, and B^f rows (CSR: sorted surface node ids, their
    Σ qw φ^f; duplicates summed in point order); and each piece's zone row."""
    npc = pzone.size
    dim = pnormal.shape[1]
    nc = qb.shape[1]
    nv = qf.shape[1]
    nz = 0
    for p in range(npc):
        if p == 0 or pzone[p] != pzone[p - 1]:
            nz += 1
    zones = np.empty(nz, np.int64)
    area = np.zeros(nz)
    avec = np.zeros((nz, dim))
    bw = np.zeros((nz, nc))
    prow = np.empty(npc, np.int64)
    # point ranges of the pieces (points grouped by piece, in piece order)
    q0 = np.zeros(npc + 1, np.int64)
    for q in range(qpiece.size):
        q0[qpiece[q] + 1] += 1
    for p in range(npc):
        q0[p + 1] += q0[p]
    fptr = np.zeros(nz + 1, np.int64)
    fcol = np.empty(qpiece.size * nv, np.int64)
    fval = np.empty(qpiece.size * nv)
    nodes = np.empty(qpiece.size * nv, np.int64)
    vals = np.empty(qpiece.size * nv)
    r = -1
    p = 0
    nf = 0
    while p < npc:
        r += 1
        zones[r] = pzone[p]
        p1 = p
        while p1 < npc and pzone[p1] == pzone[p]:
            p1 += 1
        m = 0
        for a in range(p, p1):
            prow[a] = r
            area[r] += parea[a]
            for d in range(dim):
                avec[r, d] += parea[a] * pnormal[a, d]
            for q in range(q0[a], q0[a + 1]):
                for c in range(nc):
                    bw[r, c] += qw[q] * qb[q, c]
                for j in range(nv):
                    nodes[m] = facets[pfacet[a], j]
                    vals[m] = qw[q] * qf[q, j]
                    m += 1
        # the row's surface nodes sorted (stable: duplicates summed in point order)
        order = np.argsort(nodes[:m], kind="mergesort")
        for t in range(m):
            k = order[t]
            if t > 0 and nodes[k] == fcol[nf - 1]:
                fval[nf - 1] += vals[k]
            else:
                fcol[nf] = nodes[k]
                fval[nf] = vals[k]
                nf += 1
        fptr[r + 1] = nf
        p = p1
    return zones, area, avec, bw, fptr, fcol[:nf], fval[:nf], prow


@njit(cache=True)
def face_pair_rows(zones, cells, periodic):
    """``operators.face_pairs`` in one pass: the face-adjacent pairs among the sorted zone ids as
    (i, j) row indices, i < j, sorted; along a periodic axis (``periodic``, uint8 per axis) with more
    than two layers the last layer's neighbour is the first."""
    nz = zones.size
    dim = cells.size
    stride = np.ones(dim, np.int64)
    for d in range(1, dim):
        stride[d] = stride[d - 1] * cells[d - 1]
    out = np.empty((nz * dim, 2), np.int64)
    m = 0
    for r in range(nz):
        z = zones[r]
        for d in range(dim):
            idx = (z // stride[d]) % cells[d]
            if idx < cells[d] - 1:
                cand = z + stride[d]
            elif periodic[d] != 0 and cells[d] > 2:
                cand = z - (cells[d] - 1) * stride[d]
            else:
                continue
            q = np.searchsorted(zones, cand)
            if q < nz and zones[q] == cand:
                out[m, 0] = min(r, q)
                out[m, 1] = max(r, q)
                m += 1
    key = np.empty(m, np.int64)
    for a in range(m):
        key[a] = out[a, 0] * nz + out[a, 1]
    o = np.argsort(key, kind="mergesort")
    res = np.empty((m, 2), np.int64)
    for a in range(m):
        res[a, 0] = out[o[a], 0]
        res[a, 1] = out[o[a], 1]
    return res


@njit(cache=True)
def corner_columns(zones, cells, periodic):
    """B^b's columns: the sorted distinct corner nodes of the sorted zone ids (``bnodes``) and, per
    zone and corner c (offset (c & 1, c >> 1 & 1, c >> 2 & 1)), the column of its node (nz, 2^dim);
    node ids as ``grid.Grid.zone_nodes`` (wrapped on periodic axes).

    Without a wrap each corner's list over the sorted zones is itself sorted (node id = the zone's
    lower node + a fixed offset), so a 2^dim-way merge gives the distinct nodes and the columns in
    one pass (``np.unique`` + ``searchsorted`` over the corners cost ~0.25 ms per thousand zones, every
    step); a wrapped corner list takes a sort."""
    nz = zones.size
    dim = cells.size
    nc = 1 << dim
    node = np.empty((nz, nc), np.int64)
    ijk = np.empty(dim, np.int64)
    for r in range(nz):
        rest = zones[r]
        for d in range(dim):
            ijk[d] = rest % cells[d]
            rest //= cells[d]
        for c in range(nc):
            v = 0
            for d in range(dim - 1, -1, -1):
                k = ijk[d] + ((c >> d) & 1)
                if periodic[d] != 0 and k == cells[d]:
                    k = 0
                v = v * (cells[d] + 1) + k
            node[r, c] = v
    col = np.empty((nz, nc), np.int64)
    merged = True
    for c in range(nc):
        for r in range(1, nz):
            if node[r, c] < node[r - 1, c]:
                merged = False
    if merged:
        out = np.empty(nz * nc, np.int64)
        head = np.zeros(nc, np.int64)
        m = 0
        while True:
            best = -1
            for c in range(nc):
                if head[c] < nz and (best < 0 or node[head[c], c] < node[head[best], best]):
                    best = c
            if best < 0:
                break
            v = node[head[best], best]
            if m == 0 or out[m - 1] != v:
                out[m] = v
                m += 1
            col[head[best], best] = m - 1
            head[best] += 1
        return out[:m].copy(), col
    flat = node.ravel()
    o = np.argsort(flat)
    out = np.empty(flat.size, np.int64)
    m = 0
    for t in range(flat.size):
        v = flat[o[t]]
        if m == 0 or out[m - 1] != v:
            out[m] = v
            m += 1
        col[o[t] // nc, o[t] % nc] = m - 1
    return out[:m].copy(), col


@njit(cache=True)
def kept_rows(zones, zarea, zavec, bw, fptr, fcol, fval, prow, min_area, fallback_ratio):
    """``zone_rows``'s rows of area above ``min_area`` (the others get no multiplier): their zone ids,
    areas, area vectors, B^b weights, B^f CSR and each piece's row (-1 if dropped); and the unit
    normal ``avec / |avec|`` with the zones where ``|avec| < fallback_ratio A_e`` flagged (their normal is
    left 0 for ``operators._fallback_normals`` to set).  One pass instead of ~20 numpy calls, every step."""
    nall, dim = zavec.shape
    nc = bw.shape[1]
    row_of = np.full(nall, -1, np.int64)
    nz = 0
    nnz = 0
    for r in range(nall):
        if zarea[r] > min_area:
            row_of[r] = nz
            nz += 1
            nnz += fptr[r + 1] - fptr[r]
    kz = np.empty(nz, np.int64)
    area = np.empty(nz)
    avec = np.empty((nz, dim))
    w = np.empty((nz, nc))
    normal = np.zeros((nz, dim))
    fallback = np.zeros(nz, np.bool_)
    kptr = np.zeros(nz + 1, np.int64)
    kcol = np.empty(nnz, np.int64)
    kval = np.empty(nnz)
    t = 0
    for r in range(nall):
        e = row_of[r]
        if e < 0:
            continue
        kz[e] = zones[r]
        area[e] = zarea[r]
        length = 0.0
        for d in range(dim):
            avec[e, d] = zavec[r, d]
            length += zavec[r, d] * zavec[r, d]
        length = np.sqrt(length)
        if length < fallback_ratio * zarea[r]:
            fallback[e] = True
        else:
            for d in range(dim):
                normal[e, d] = zavec[r, d] / length
        for c in range(nc):
            w[e, c] = bw[r, c]
        for k in range(fptr[r], fptr[r + 1]):
            kcol[t] = fcol[k]
            kval[t] = fval[k]
            t += 1
        kptr[e + 1] = t
    krow = np.empty(prow.size, np.int64)
    for p in range(prow.size):
        krow[p] = row_of[prow[p]]
    return kz, area, avec, w, normal, fallback, kptr, kcol, kval, krow


@njit(cache=True)
def transpose_product(indptr, indices, data, x, ncols):
    """``B.T @ x`` for a CSR ``B`` (indptr, indices, data) with ``ncols`` columns and a dense x
    (nrows, k): rows in order, each entry added to its column's row of the result -- scipy's order
    for ``csr.T @ x`` (its CSC product), without building the transpose (~15 us per call)."""
    out = np.zeros((ncols, x.shape[1]))
    for e in range(indptr.size - 1):
        for q in range(indptr[e], indptr[e + 1]):
            j = indices[q]
            for a in range(x.shape[1]):
                out[j, a] += data[q] * x[e, a]
    return out


@njit(cache=True)
def operator_arrays(pzone, parea, pnormal, qpiece, qw, qb, qf, pfacet, facets, min_area, fallback_ratio, cells,
                    periodic):
    """``Operators.build``'s arrays in one dispatch: ``zone_rows``, ``kept_rows``, ``corner_columns`` and
    ``face_pair_rows`` in turn (each a numba call of ~5-15 us from Python, every step)."""
    all_zones, zarea, zavec, bw, fptr, fcol, fval, prow_all = zone_rows(pzone, parea, pnormal, qpiece, qw, qb, qf,
                                                                        pfacet, facets)
    zones, area, avec, w, normal, fallback, kptr, kcol, kval, prow = kept_rows(
        all_zones, zarea, zavec, bw, fptr, fcol, fval, prow_all, min_area, fallback_ratio)
    bnodes, columns = corner_columns(zones, cells, periodic)
    pairs = face_pair_rows(zones, cells, periodic)
    return zones, area, avec, w, normal, fallback, kptr, kcol, kval, prow, bnodes, columns, pairs


@njit(cache=True)
def row_means(indptr, indices, data, v, area):
    """(B @ v) / A_e per row of a CSR ``B`` (rows = cut zones; a row of zero area divides by 1): the
    surface's mean of v over each Γ_e -- scipy's order for ``csr @ v`` (entries of a row in turn),
    without its ~10 us of dispatch, called three times per step."""
    nz = indptr.size - 1
    out = np.zeros((nz, v.shape[1]))
    for e in range(nz):
        for q in range(indptr[e], indptr[e + 1]):
            j = indices[q]
            for a in range(v.shape[1]):
                out[e, a] += data[q] * v[j, a]
        a_e = area[e] if area[e] > 0.0 else 1.0
        for a in range(v.shape[1]):
            out[e, a] /= a_e
    return out


@njit(cache=True)
def on_grid_boundary(centroid, normal, lower, upper, h):
    """``embedded.facing_the_grid``'s test per piece: its centroid on a boundary plane of the grid
    (within 1e-9 of a zone width) and its normal pointing out of the grid there (component beyond
    0.5).  Returns (mask, count)."""
    n, dim = centroid.shape
    on = np.zeros(n, np.bool_)
    count = 0
    for p in range(n):
        for d in range(dim):
            tol = 1e-9 * h[d]
            c = centroid[p, d]
            if (abs(c - lower[d]) <= tol and normal[p, d] < -0.5) or (abs(c - upper[d]) <= tol and normal[p, d] > 0.5):
                on[p] = True
        if on[p]:
            count += 1
    return on, count


# ---- the coupled step's per-node arithmetic (embedded.EmbeddedCoupling.solve / background_correction)
# A particle body's surface nodes are all its particles (thousands), so the step's few numpy
# expressions over (ns, dim) arrays (temporaries, strided axis-0 sums: ~60 us for 4k particles,
# every step) are single passes here, with numpy's summation orders so the results are the same.
@njit(cache=True)
def surface_load(indptr, indices, data, R, area, ns, dt_avg, vstar, free, mass):
    """The fluid's load on the surface nodes and their loaded predictor velocities (embedded.solve):
    ``load = dt_avg * -(B^fT (R / A_e))`` (a zone of zero area divides by 1) and ``v_f = vstar + load
    free / m`` (free: 1 per component a boundary condition leaves free)."""
    dim = R.shape[1]
    x = np.empty(R.shape)
    for e in range(R.shape[0]):
        a_e = area[e] if area[e] > 0.0 else 1.0
        for a in range(dim):
            x[e, a] = R[e, a] / a_e
    F = transpose_product(indptr, indices, data, x, ns)
    load = np.empty((ns, dim))
    v_f = np.empty((ns, dim))
    for j in range(ns):
        for a in range(dim):
            load[j, a] = dt_avg * -F[j, a]
            v_f[j, a] = vstar[j, a] + load[j, a] * free[j, a] / mass[j]
    return load, v_f


@njit(cache=True)
def impulse_sums(load, impulse_f):
    """``load + impulse_f`` and its column sums (numpy's axis-0 sum: the rows in order)."""
    n, dim = load.shape
    imp = np.empty((n, dim))
    total = np.zeros(dim)
    for j in range(n):
        for a in range(dim):
            imp[j, a] = load[j, a] + impulse_f[j, a]
            total[a] += imp[j, a]
    return imp, total


@njit(cache=True)
def _pairwise_block(a, s, n):
    """numpy's pairwise_sum leaf (n <= 128): below 8 in turn, else 8 interleaved partial sums."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[s + i]
        return res
    r0, r1, r2, r3 = a[s], a[s + 1], a[s + 2], a[s + 3]
    r4, r5, r6, r7 = a[s + 4], a[s + 5], a[s + 6], a[s + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[s + i]
        r1 += a[s + i + 1]
        r2 += a[s + i + 2]
        r3 += a[s + i + 3]
        r4 += a[s + i + 4]
        r5 += a[s + i + 5]
        r6 += a[s + i + 6]
        r7 += a[s + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[s + i]
        i += 1
    return res


@njit(cache=True)
def pairwise_sum(a, s, n):
    """numpy's pairwise summation of a[s:s+n] (float64 ``add.reduce`` of a contiguous array: blocks of
    at most 128 summed by ``_pairwise_block``, larger ranges split in two halves, the first a multiple
    of 8, and the halves' sums added), so a sum done here is numpy's bit for bit.  The recursion is
    walked with an explicit stack (a recursive njit function loaded from numba's cache into a caller
    crashes)."""
    if n <= 128:
        return _pairwise_block(a, s, n)
    cap = 256
    ss = np.empty(cap, np.int64)
    sn = np.empty(cap, np.int64)
    st = np.zeros(cap, np.int64)
    vals = np.empty(cap)
    nv = 0
    ss[0], sn[0], st[0] = s, n, 0
    top = 1
    while top > 0:
        top -= 1
        cs, cn, state = ss[top], sn[top], st[top]
        if cn <= 128:
            vals[nv] = _pairwise_block(a, cs, cn)
            nv += 1
        elif state == 0:   # expand: combine after the first half, then the second, are done
            n2 = cn // 2
            n2 -= n2 % 8
            ss[top], sn[top], st[top] = cs, cn, 1
            ss[top + 1], sn[top + 1], st[top + 1] = cs + n2, cn - n2, 0
            ss[top + 2], sn[top + 2], st[top + 2] = cs, n2, 0
            top += 3
        else:
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
    return vals[0]


@njit(cache=True)
def correction_means(indptr, indices, data, area, v_old, v_new, imp_f):
    """embedded.background_correction's arithmetic: the mean velocity ``(v_old + v_new) / 2``, the
    zone means of v_new and of it (``row_means``), and the impulses' work ``sum(imp_f * vbar)``."""
    n, dim = v_new.shape
    vbar = np.empty((n, dim))
    prod = np.empty(n * dim)
    for j in range(n):
        for a in range(dim):
            vbar[j, a] = 0.5 * (v_old[j, a] + v_new[j, a])
            prod[j * dim + a] = imp_f[j, a] * vbar[j, a]
    work = 0.0 + pairwise_sum(prod, 0, prod.size)
    return row_means(indptr, indices, data, v_new, area), row_means(indptr, indices, data, vbar, area), work


@njit(cache=True)
def oscillation(lam, pairs, normal):
    """embedded.multiplier_oscillation on arrays: lam (nz, k), pairs (np, 2) rows, normal (nz, dim)
    (np.linalg.norm's row norms and np.mean's pairwise sums)."""
    dim = normal.shape[1]
    k = lam.shape[1]
    keep = np.empty(pairs.shape[0], np.int64)
    m = 0
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        dot = 0.0
        for d in range(dim):
            dot += normal[i, d] * normal[j, d]
        if dot > 0.5:
            keep[m] = p
            m += 1
    if m == 0:
        return 0.0
    norms = np.empty(lam.shape[0])
    for e in range(lam.shape[0]):
        s = 0.0
        for c in range(k):
            s += lam[e, c] * lam[e, c]
        norms[e] = np.sqrt(s)
    scale = pairwise_sum(norms, 0, norms.size) / norms.size
    if not scale > 0.0:
        return 0.0
    diffs = np.empty(m)
    for t in range(m):
        i, j = pairs[keep[t], 0], pairs[keep[t], 1]
        s = 0.0
        for c in range(k):
            d = lam[i, c] - lam[j, c]
            s += d * d
        diffs[t] = np.sqrt(s)
    return (pairwise_sum(diffs, 0, m) / m) / scale


def facing_the_grid(grid, pieces):
    """The pieces that face gas: a body face lying on the grid's boundary and facing out of it (a
    plate's base on the floor, an end on a periodic or open face) borders no gas -- it counts for the
    fractions, but a multiplier there would tie the gas nodes at its edge to the body."""
    on, count = on_grid_boundary(np.ascontiguousarray(pieces.centroid), np.ascontiguousarray(pieces.normal),
                                 grid.lower, grid.upper, grid.h)
    if count == 0:
        return pieces
    keep = np.flatnonzero(~on)
    qkeep = np.isin(pieces.qpiece, keep)
    remap = np.full(pieces.zone.size, -1, np.int64)
    remap[keep] = np.arange(keep.size)
    return dataclasses.replace(
        pieces, zone=pieces.zone[keep], body=pieces.body[keep], facet=pieces.facet[keep],
        area=pieces.area[keep], normal=pieces.normal[keep], centroid=pieces.centroid[keep],
        qp=pieces.qp[qkeep], qw=pieces.qw[qkeep], qpiece=remap[pieces.qpiece[qkeep]],
        qf=pieces.qf[qkeep], qb=pieces.qb[qkeep])
