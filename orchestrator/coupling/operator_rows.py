"""The per-zone sums of `operators.Operators.build` in one numba kernel (kept apart from operators.py
so that validating a case, which imports the coupling variants' schemas, imports no numba)."""
from __future__ import annotations

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
