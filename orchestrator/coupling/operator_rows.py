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
