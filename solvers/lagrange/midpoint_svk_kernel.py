"""The energy-momentum midpoint step's element matrices and forces of St. Venant-Kirchhoff bodies as a
numba kernel (midpoint_svk.py's module docstring has the equations; its numpy form,
midpoint_svk.numpy_elements, is what the tests compare this with). One pass over the elements and
their Gauss points with small per-point arrays, instead of numpy's (ne, g, ...) temporaries: the
implicit step's element evaluation was 7 us per quad in numpy (`immerse bench implicit`).

Per Gauss point, with F_n, F_{n+1} from the element's displacements, F_m = (F_n + F_{n+1}) / 2,
S = C (E_n + E_{n+1}) / 2, g_a = F_m dN_a, h_a = F_{n+1} dN_a, G = F_m F_{n+1}^T,
s_ab = dN_a . S dN_b and n_ab = dN_a . dN_b:

    f_ai  += w (F_m S)_iJ dN_aJ,
    K_aibk += w / 2 [s_ab delta_ik + lambda g_ai h_bk + mu (G_ik n_ab + g_bi h_ak)].
"""
from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["svk_midpoint_elements"]


@nb.njit(cache=True)
def svk_midpoint_elements(ue0, ue1, dndx, w, mu, lam):
    """(ke (ne, a d, a d), fe (ne, a, d)) from the elements' nodal displacements at t_n and t_{n+1}
    ue0, ue1 (ne, a, d), the reference gradients dndx (ne, g, a, d) and weights w (ne, g)."""
    ne, ng, na, d = dndx.shape
    nd = na * d
    ke = np.zeros((ne, nd, nd))
    fe = np.zeros((ne, na, d))
    f0 = np.empty((d, d))
    f1 = np.empty((d, d))
    fm = np.empty((d, d))
    s = np.empty((d, d))
    big_g = np.empty((d, d))
    p = np.empty((d, d))
    g = np.empty((na, d))
    h = np.empty((na, d))
    sdn = np.empty((na, d))
    for e in range(ne):
        for q in range(ng):
            # F = I + u_a dN_a (both ends), the midpoint F
            for i in range(d):
                for jj in range(d):
                    a0 = 1.0 if i == jj else 0.0
                    a1 = a0
                    for a in range(na):
                        a0 += ue0[e, a, i] * dndx[e, q, a, jj]
                        a1 += ue1[e, a, i] * dndx[e, q, a, jj]
                    f0[i, jj] = a0
                    f1[i, jj] = a1
                    fm[i, jj] = 0.5 * (a0 + a1)
            # S = lambda tr(E) I + 2 mu E, E = (E_n + E_{n+1}) / 2 = (C_n + C_{n+1}) / 4 - I / 2
            tr = 0.0
            for ii in range(d):
                for jj in range(d):
                    c = 0.0
                    for k in range(d):
                        c += f0[k, ii] * f0[k, jj] + f1[k, ii] * f1[k, jj]
                    s[ii, jj] = 0.25 * c - (0.5 if ii == jj else 0.0)
                tr += s[ii, ii]
            for ii in range(d):
                for jj in range(d):
                    s[ii, jj] *= 2.0 * mu
                s[ii, ii] += lam * tr
            # P = F_m S, G = F_m F_{n+1}^T
            for i in range(d):
                for jj in range(d):
                    a0 = 0.0
                    a1 = 0.0
                    for k in range(d):
                        a0 += fm[i, k] * s[k, jj]
                        a1 += fm[i, k] * f1[jj, k]
                    p[i, jj] = a0
                    big_g[i, jj] = a1
            wq = w[e, q]
            hw = 0.5 * wq
            for a in range(na):
                for i in range(d):
                    ga = 0.0
                    ha = 0.0
                    fa = 0.0
                    sa = 0.0
                    for jj in range(d):
                        ga += fm[i, jj] * dndx[e, q, a, jj]
                        ha += f1[i, jj] * dndx[e, q, a, jj]
                        fa += p[i, jj] * dndx[e, q, a, jj]
                        sa += s[i, jj] * dndx[e, q, a, jj]
                    g[a, i] = ga
                    h[a, i] = ha
                    sdn[a, i] = sa
                    fe[e, a, i] += wq * fa
            for a in range(na):
                for b in range(na):
                    sab = 0.0
                    nab = 0.0
                    for jj in range(d):
                        sab += dndx[e, q, a, jj] * sdn[b, jj]
                        nab += dndx[e, q, a, jj] * dndx[e, q, b, jj]
                    for i in range(d):
                        r = a * d + i
                        ke[e, r, b * d + i] += hw * sab
                        for k in range(d):
                            ke[e, r, b * d + k] += hw * (lam * g[a, i] * h[b, k]
                                                        + mu * (big_g[i, k] * nab + g[b, i] * h[a, k]))
    return ke, fe
