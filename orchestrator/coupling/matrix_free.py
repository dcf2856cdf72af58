"""The stabilised multiplier solve of one coupled step in one numba kernel (the step's hot path).

Same system as `solve.assemble` / `solve.solve_system` (read that module for the equations):

    H λ = g*,   H = Δt (B^b M_b^-1 B^bT + Bf M_f^-1 BfT) [∘ n·n for slip] + diag(s/α) + J,

but H is assembled here by a kernel (`_assemble`: per zone, the zones sharing a node with it, once
per step) instead of through scipy.  Why: the product's work is small (each zone couples to its few
neighbours) but scipy's sparse products and constructions cost ~20 interpreter round trips per
step, several milliseconds for any interface size -- most of the coupler's time on a 1000-facet
surface before this module.  An earlier form applied B M^-1 B^T inside every CG iteration without
forming H; assembling once and then multiplying by H's few entries per row is ~2.5x faster at the
10-25 iterations a step takes.  The whole solve is one kernel: material columns, the diagonal (for
the stabilisation scale s_e), H, the Galilean relative velocity, Jacobi-PCG with the warm start and
the impulses, in a fixed loop order (equal inputs give bitwise-equal outputs).

The operators arrive as CSR arrays (rows = cut zones); the material restriction of
`solve.material_operators` is applied on the fly: void background nodes (m_b = 0) drop out and each
row's remaining weights are rescaled to sum to A_e again.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from orchestrator.coupling.solve import MAX_ITER, RTOL, MultiplierSolveError, Solution, check_masses


@njit(cache=True)
def _material(indptr, indices, data, m_b, area):
    """Bb restricted to the material nodes, rows rescaled to sum to A_e: (weights like data, active
    row mask, reference column per row: the first material column, -1 if none)."""
    nz = indptr.size - 1
    w = np.zeros(data.size)
    active = np.zeros(nz, np.bool_)
    ref = np.full(nz, -1, np.int64)
    for e in range(nz):
        s = 0.0
        for k in range(indptr[e], indptr[e + 1]):
            if m_b[indices[k]] > 0.0:
                s += data[k]
                if ref[e] < 0:
                    ref[e] = indices[k]
        if s > 0.0:
            active[e] = True
            f = area[e] / s
            for k in range(indptr[e], indptr[e + 1]):
                if m_b[indices[k]] > 0.0:
                    w[k] = data[k] * f
    return w, active, ref


@njit(cache=True)
def _transpose(active, ptr, idx, w, n):
    """Column lists of the active rows of a CSR (ptr, idx, w): for each of the n columns the rows
    and weights, in row order."""
    cnt = np.zeros(n + 1, np.int64)
    for e in range(ptr.size - 1):
        if active[e]:
            for q in range(ptr[e], ptr[e + 1]):
                cnt[idx[q] + 1] += 1
    for a in range(n):
        cnt[a + 1] += cnt[a]
    rows = np.empty(cnt[n], np.int64)
    vals = np.empty(cnt[n])
    fill = cnt[:-1].copy()
    for e in range(ptr.size - 1):
        if active[e]:
            for q in range(ptr[e], ptr[e + 1]):
                a = idx[q]
                rows[fill[a]] = e
                vals[fill[a]] = w[q]
                fill[a] += 1
    return cnt, rows, vals


@njit(cache=True)
def _row_terms(e, ptr, idx, w, inv_m, tptr, trows, tvals, scale, mark, start, pos, Hi, Hv):
    """Add scale Σ_A w_eA w_e'A / m_A over the nodes A of row e to row e's entries (mark: the
    position of zone e' in the row being built, >= start when present)."""
    for q in range(ptr[e], ptr[e + 1]):
        a = idx[q]
        f = scale * w[q] * inv_m[a]
        if f == 0.0:
            continue
        for t in range(tptr[a], tptr[a + 1]):
            pos = _add_entry(trows[t], f * tvals[t], mark, start, pos, Hi, Hv)
    return pos


@njit(cache=True, inline="always")
def _add_entry(e2, val, mark, start, pos, Hi, Hv):
    """Add val to entry e2 of the row being built (it starts at `start`; mark[e2] >= start: the
    entry's position, else a new entry at pos).  Returns the row's end."""
    if mark[e2] >= start:
        Hv[mark[e2]] += val
        return pos
    mark[e2] = pos
    Hi[pos] = e2
    Hv[pos] = val
    return pos + 1


@njit(cache=True)
def _assemble(active, slip, normal, bp, bi, bw, inv_mb, fp, fi, fw, inv_mf, dt, pi, pj, pw, diag_c):
    """H as a CSR over the zones (rows of inactive zones empty): dt (B^b M_b^-1 B^bT + Bf M_f^-1 BfT)
    [∘ n·n for slip] + diag(s/α) + J.  Work: Σ over the nodes of (zones sharing it)^2, once per
    step; every CG iteration is then one product over H's few entries per row."""
    nz = active.size
    tb_ptr, tb_rows, tb_vals = _transpose(active, bp, bi, bw, inv_mb.size)
    tf_ptr, tf_rows, tf_vals = _transpose(active, fp, fi, fw, inv_mf.size)
    # the face pairs of each zone (a pair is a row with its two zones as columns: transposed, each
    # zone's pairs in pair order); the other zone of pair u is pi[u] + pj[u] - e
    npair = pi.size
    pptr = np.arange(0, 2 * npair + 1, 2).astype(np.int64)
    pidx = np.empty(2 * npair, np.int64)
    pidx[0::2] = pi
    pidx[1::2] = pj
    pc, prow, pweight = _transpose(np.ones(npair, np.bool_), pptr, pidx, np.repeat(pw, 2), nz)
    cap = 16 * nz + 16
    Hp = np.zeros(nz + 1, np.int64)
    Hi = np.empty(cap, np.int64)
    Hv = np.empty(cap)
    mark = np.full(nz, -1, np.int64)
    pos = 0
    for e in range(nz):
        start = pos
        if active[e]:
            # (worst case of this row: every zone sharing one of its nodes, and its pairs)
            need = pos + nz
            if need > Hi.size:
                c2 = max(2 * Hi.size, need)
                Hi2 = np.empty(c2, np.int64)
                Hv2 = np.empty(c2)
                Hi2[:pos] = Hi[:pos]
                Hv2[:pos] = Hv[:pos]
                Hi, Hv = Hi2, Hv2
            pos = _row_terms(e, bp, bi, bw, inv_mb, tb_ptr, tb_rows, tb_vals, dt, mark, start, pos, Hi, Hv)
            pos = _row_terms(e, fp, fi, fw, inv_mf, tf_ptr, tf_rows, tf_vals, dt, mark, start, pos, Hi, Hv)
            if slip:
                for q in range(start, pos):
                    e2 = Hi[q]
                    d = 0.0
                    for c in range(normal.shape[1]):
                        d += normal[e, c] * normal[e2, c]
                    Hv[q] *= d
            # C^-1 = diag(s/α) + J
            for t in range(-1, pc[e + 1] - pc[e]):
                if t < 0:
                    e2 = e
                    val = diag_c[e]
                    for u in range(pc[e], pc[e + 1]):
                        val += pweight[u]
                else:
                    u = prow[pc[e] + t]
                    e2 = pi[u] + pj[u] - e
                    val = -pweight[pc[e] + t]
                pos = _add_entry(e2, val, mark, start, pos, Hi, Hv)
        Hp[e + 1] = pos
    return Hp, Hi[:pos], Hv[:pos]


@njit(cache=True)
def _spmv(Hp, Hi, Hv, x, out):
    for e in range(Hp.size - 1):
        for c in range(x.shape[1]):
            s = 0.0
            for q in range(Hp[e], Hp[e + 1]):
                s += Hv[q] * x[Hi[q], c]
            out[e, c] = s


@njit(cache=True)
def _dot(a, b):
    s = 0.0
    for e in range(a.shape[0]):
        for c in range(a.shape[1]):
            s += a[e, c] * b[e, c]
    return s


@njit(cache=True)
def _solve_kernel(bp, bi, bd, m_b, fp, fi, fw, m_f, area, full_area, normal, slip, pairs, alpha, beta, dt,
                  v_b, v_f, x0, rtol, max_iter):
    nz = area.size
    dim = v_b.shape[1]
    nb = m_b.size
    ns = m_f.size
    k = 1 if slip else dim
    bw, active, ref = _material(bp, bi, bd, m_b, area)
    inv_mb = np.zeros(nb)
    for a in range(nb):
        if m_b[a] > 0.0:
            inv_mb[a] = 1.0 / m_b[a]
    inv_mf = np.zeros(ns)
    for e in range(nz):
        for q in range(fp[e], fp[e + 1]):
            inv_mf[fi[q]] = 1.0 / m_f[fi[q]]
    # the unstabilised diagonal, the scale s_e of a full cut and C^-1's diagonal s_e / alpha
    du = np.zeros(nz)
    for e in range(nz):
        if not active[e]:
            continue
        s = 0.0
        for q in range(bp[e], bp[e + 1]):
            s += bw[q] * bw[q] * inv_mb[bi[q]]
        for q in range(fp[e], fp[e + 1]):
            s += fw[q] * fw[q] * inv_mf[fi[q]]
        du[e] = dt * s
    scale = np.zeros(nz)
    diag_c = np.zeros(nz)
    for e in range(nz):
        if active[e]:
            r = full_area / area[e]
            scale[e] = r * r * du[e]
            diag_c[e] = scale[e] / alpha
    # the jump term over the face pairs of active zones
    npair = 0
    for q in range(pairs.shape[0]):
        if active[pairs[q, 0]] and active[pairs[q, 1]]:
            npair += 1
    pi = np.empty(npair, np.int64)
    pj = np.empty(npair, np.int64)
    pw = np.empty(npair)
    n = 0
    for q in range(pairs.shape[0]):
        i, j = pairs[q, 0], pairs[q, 1]
        if active[i] and active[j]:
            pi[n] = i
            pj[n] = j
            pw[n] = beta * np.sqrt(scale[i] * scale[j])
            n += 1
    Hp, Hi, Hv = _assemble(active, slip, normal, bp, bi, bw, inv_mb, fp, fi, fw, inv_mf, dt, pi, pj, pw, diag_c)
    dinv = np.zeros(nz)
    for e in range(nz):
        for q in range(Hp[e], Hp[e + 1]):
            if Hi[q] == e:
                dinv[e] = 1.0 / Hv[q]
    # g* = B^b v_b - Bf v_f, Galilean form (solve.relative_velocity), slip: its normal part
    g = np.zeros((nz, k))
    for e in range(nz):
        if not active[e]:
            continue
        r0 = ref[e]
        for c in range(dim):
            vr = v_b[r0, c]
            s = 0.0
            for q in range(bp[e], bp[e + 1]):
                s += bw[q] * (v_b[bi[q], c] - vr)
            for q in range(fp[e], fp[e + 1]):
                s -= fw[q] * (v_f[fi[q], c] - vr)
            if slip:
                g[e, 0] += s * normal[e, c]
            else:
                g[e, c] = s
    # Jacobi-PCG (solve.pcg: why Jacobi, the stopping rule over all columns together)
    x = np.zeros((nz, k))
    for e in range(nz):
        if active[e]:
            for c in range(k):
                x[e, c] = x0[e, c]
    bnorm = np.sqrt(_dot(g, g))
    it = 0
    Hx = np.zeros((nz, k))
    if bnorm == 0.0:
        x[:] = 0.0
        rel = 0.0
    else:
        _spmv(Hp, Hi, Hv, x, Hx)
        r = g - Hx
        z = np.empty_like(r)
        for e in range(nz):
            for c in range(k):
                z[e, c] = dinv[e] * r[e, c]
        p = z.copy()
        rz = np.zeros(k)
        for e in range(nz):
            for c in range(k):
                rz[c] += r[e, c] * z[e, c]
        rnorm = np.sqrt(_dot(r, r))
        HP = np.zeros((nz, k))
        while rnorm > rtol * bnorm:
            if it >= max_iter:
                return x, it, rnorm / bnorm, active, bw, inv_mb, diag_c, pi, pj, pw, True
            _spmv(Hp, Hi, Hv, p, HP)
            pHp = np.zeros(k)
            for e in range(nz):
                for c in range(k):
                    pHp[c] += p[e, c] * HP[e, c]
            for c in range(k):
                a = rz[c] / pHp[c] if pHp[c] > 0.0 else 0.0
                for e in range(nz):
                    x[e, c] += a * p[e, c]
                    r[e, c] -= a * HP[e, c]
            rzn = np.zeros(k)
            for e in range(nz):
                for c in range(k):
                    z[e, c] = dinv[e] * r[e, c]
                    rzn[c] += r[e, c] * z[e, c]
            for c in range(k):
                gam = rzn[c] / rz[c] if rz[c] > 0.0 else 0.0
                for e in range(nz):
                    p[e, c] = z[e, c] + gam * p[e, c]
                rz[c] = rzn[c]
            rnorm = np.sqrt(_dot(r, r))
            it += 1
        _spmv(Hp, Hi, Hv, x, Hx)
        rel = np.sqrt(_dot(g - Hx, g - Hx)) / bnorm
    return x, it, rel, active, bw, inv_mb, diag_c, pi, pj, pw, False


@njit(cache=True)
def _impulses(x, active, slip, normal, bp, bi, bw, fp, fi, fw, dt, nb, ns, diag_c, pi, pj, pw):
    """-dt B^bT λ, +dt BfT λ (λ_e = μ_e n_e for slip) and the stabilisation's dissipation dt λ·C^-1 λ."""
    nz = x.shape[0]
    dim = normal.shape[1]
    ib = np.zeros((nb, dim))
    jf = np.zeros((ns, dim))
    for e in range(nz):
        if not active[e]:
            continue
        for c in range(dim):
            v = x[e, 0] * normal[e, c] if slip else x[e, c]
            for q in range(bp[e], bp[e + 1]):
                ib[bi[q], c] += bw[q] * v
            for q in range(fp[e], fp[e + 1]):
                jf[fi[q], c] += fw[q] * v
    # (B^T λ first, then the step: the impulses of both sides scaled alike)
    for a in range(nb):
        for c in range(dim):
            ib[a, c] *= -dt
    for a in range(ns):
        for c in range(dim):
            jf[a, c] *= dt
    diss = 0.0
    for e in range(nz):
        for c in range(x.shape[1]):
            diss += diag_c[e] * x[e, c] * x[e, c]
    for q in range(pi.size):
        for c in range(x.shape[1]):
            d = x[pi[q], c] - x[pj[q], c]
            diss += pw[q] * d * d
    return ib, jf, dt * diss


def solve(ops, m_b, m_f, v_b, v_f, dt: float, condition: str, alpha: float, beta: float, warm=None,
          rtol: float = RTOL, max_iter: int = MAX_ITER) -> Solution:
    """`solve.solve` without the assembled H (same arguments and result, equal to round-off)."""
    dim = ops.dim
    slip = condition == "slip"
    k = 1 if slip else dim
    m_b = np.ascontiguousarray(m_b, dtype=np.float64)
    m_f = np.ascontiguousarray(m_f, dtype=np.float64)
    v_b = np.ascontiguousarray(np.asarray(v_b, dtype=np.float64).reshape(-1, dim))
    v_f = np.ascontiguousarray(np.asarray(v_f, dtype=np.float64).reshape(-1, dim))
    x0 = np.zeros((ops.n_zones, k))
    if warm is not None and np.size(warm[0]):
        wz, wl = np.asarray(warm[0], np.int64), np.asarray(warm[1], dtype=float)
        wl = wl.reshape(wz.size, -1)
        if wl.shape[1] == k:
            pos = np.minimum(np.searchsorted(wz, ops.zones), wz.size - 1)
            hit = wz[pos] == ops.zones
            x0[hit] = wl[pos[hit]]
    Bb, Bf = ops.Bb, ops.Bf
    check_masses(ops, m_b, m_f)
    # (scipy keeps int32 indices; the kernels take int64: converted once for both calls)
    bp, bi = Bb.indptr.astype(np.int64), Bb.indices.astype(np.int64)
    fp, fi = Bf.indptr.astype(np.int64), Bf.indices.astype(np.int64)
    normal = np.ascontiguousarray(ops.normal)
    x, it, rel, active, bw, inv_mb, diag_c, pi, pj, pw, failed = _solve_kernel(
        bp, bi, Bb.data, m_b, fp, fi, Bf.data, m_f, np.ascontiguousarray(ops.area), float(ops.full_area),
        normal, slip, np.ascontiguousarray(ops.pairs, dtype=np.int64).reshape(-1, 2),
        float(alpha), float(beta), float(dt), v_b, v_f, x0, float(rtol), int(max_iter))
    if failed:
        raise MultiplierSolveError(
            f"multiplier solve: no convergence in {max_iter} CG iterations (relative residual "
            f"{rel:.3e} > tolerance {rtol:.1e}) on {int(active.sum())} cut zones; H is too ill "
            f"conditioned: raise coupling.beta or lower coupling.alpha")
    ib, jf, diss = _impulses(x, active, slip, normal, bp, bi, bw, fp, fi, Bf.data, float(dt), m_b.size, m_f.size,
                             diag_c, pi, pj, pw)
    return Solution(zones=ops.zones, lam=x[:, 0] if slip else x, impulse_b=ib, impulse_f=jf, iterations=int(it),
                    residual=float(rel), dissipation=float(diss))
