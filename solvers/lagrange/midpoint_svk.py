"""The energy-momentum midpoint internal force of St. Venant-Kirchhoff bodies (issue 12's implicit
step; seed slide "Structure preserving time integration w/ contact"), for the elements of
finite_strain.py (full-integration bilinear quads in plane strain, trilinear hexahedra).

St. Venant-Kirchhoff: the stored energy per reference volume W(E) = lambda/2 (tr E)^2 + mu E:E of
the Green strain E = (F^T F - I)/2, so S = lambda tr(E) I + 2 mu E (S = C E, C constant). Over a
step n -> n+1 the midpoint scheme takes

    f_int,ai^{n+1/2} = integral over the reference of (F_{n+1/2} S_{n+1/2})_iJ dN_a/dX_J,
    F_{n+1/2} = (F_n + F_{n+1}) / 2,   S_{n+1/2} = C (E_n + E_{n+1}) / 2

(Simo & Tarnow, ZAMP 43 (1992)). Because E_{n+1} - E_n = sym(F_{n+1/2}^T (F_{n+1} - F_n)) exactly,

    (u_{n+1} - u_n) . f_int^{n+1/2} = integral (E_{n+1} - E_n) : C (E_n + E_{n+1}) / 2 = U_{n+1} - U_n

to round-off, whatever the step: with M (v_{n+1} - v_n)/dt + f_int^{n+1/2} = f_ext and
x_{n+1} - x_n = dt (v_n + v_{n+1}) / 2 the discrete energy is conserved. The force sums to zero
(translation) and x_{n+1/2} x f sums to zero (F S F^T symmetric): the momenta are conserved too.

Newton on u_{n+1} needs d f_int^{n+1/2} / d u_{n+1}: with dF_{n+1/2} = dF_{n+1} / 2 and
dE_{n+1} = sym(F_{n+1}^T dF_{n+1}),

    K_aibk = integral dN_a/dX_J A_iJkL dN_b/dX_L,
    A_iJkL = 1/2 S_JL delta_ik + 1/2 F_{n+1/2},iI C_IJKL F_{n+1},kK
           = 1/2 S_JL delta_ik + 1/2 [lambda F_{n+1/2},iJ F_{n+1},kL
                                      + mu ((F_{n+1/2} F_{n+1}^T)_ik delta_JL + F_{n+1/2},iL F_{n+1},kJ)],

not symmetric (F_{n+1/2} against F_{n+1}); at u_n = u_{n+1} it is half the static tangent.

Vectorised numpy over elements and Gauss points (the step's element matrices and forces: the numba
kernel of midpoint_svk_kernel.py); dofs interleaved as in finite_strain.py.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.lagrange.finite_strain import _assemble_matrix, _assemble_vector, _reference_gradients_cached, kinematics
from solvers.lagrange.midpoint_svk_kernel import svk_midpoint_elements

__all__ = ["svk_energy", "element_energies", "cauchy_stresses", "midpoint_force", "midpoint_elements", "midpoint_tangent"]


def _green(f: np.ndarray) -> np.ndarray:
    return 0.5 * (np.einsum("...kI,...kJ->...IJ", f, f) - np.eye(f.shape[-1]))


def _svk_stress(e: np.ndarray, mu: float, lam: float) -> np.ndarray:
    tr = np.trace(e, axis1=-2, axis2=-1)
    return lam * tr[..., None, None] * np.eye(e.shape[-1]) + 2.0 * mu * e


def element_energies(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """(ne,) each element's integral of lambda/2 (tr E)^2 + mu E:E (J; per unit thickness in 2-D)."""
    f, _, w = kinematics(points, cells, u, cache=True)
    e = _green(f)
    tr = np.trace(e, axis1=-2, axis2=-1)
    return np.sum(w * (0.5 * lam * tr ** 2 + mu * np.einsum("...IJ,...IJ->...", e, e)), axis=1)


def svk_energy(points, cells, u, mu: float, lam: float) -> float:
    """U = integral over the reference of lambda/2 (tr E)^2 + mu E:E (per unit thickness in 2-D)."""
    return float(element_energies(points, cells, u, mu, lam).sum())


def cauchy_stresses(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """(ne, 6) Voigt xx yy zz xy yz zx: sigma = F S F^T / J, the mean over each element's Gauss points
    (plane strain: E_33 = 0, so sigma_zz = lambda tr E / J)."""
    f, _, _ = kinematics(points, cells, u, cache=True)
    e = _green(f)
    s = _svk_stress(e, mu, lam)
    j = np.linalg.det(f)
    sig = np.einsum("...iI,...IJ,...jJ->...ij", f, s, f) / j[..., None, None]
    out = np.zeros(f.shape[:2] + (6,))
    if f.shape[-1] == 2:
        out[..., 0], out[..., 1], out[..., 3] = sig[..., 0, 0], sig[..., 1, 1], sig[..., 0, 1]
        out[..., 2] = lam * np.trace(e, axis1=-2, axis2=-1) / j
    else:
        out[..., 0], out[..., 1], out[..., 2] = sig[..., 0, 0], sig[..., 1, 1], sig[..., 2, 2]
        out[..., 3], out[..., 4], out[..., 5] = sig[..., 0, 1], sig[..., 1, 2], sig[..., 2, 0]
    return out.mean(axis=1)


def _midpoint_state(points, cells, u0, u1, mu, lam):
    f0, dndx, w = kinematics(points, cells, u0, cache=True)
    f1 = kinematics(points, cells, u1, cache=True)[0]
    s = _svk_stress(0.5 * (_green(f0) + _green(f1)), mu, lam)
    return f1, 0.5 * (f0 + f1), s, dndx, w


def midpoint_force(points, cells, u0, u1, mu: float, lam: float) -> np.ndarray:
    """f_int^{n+1/2} (n d,) of the step from displacements u0 to u1 (each (n, d) or (n d,)): the
    step's own (midpoint_elements')."""
    cells = np.asarray(cells, dtype=np.int64)
    fe = midpoint_elements(points, cells, u0, u1, mu, lam)[1]
    return _assemble_vector(cells, fe.shape[-1], fe, len(points))


def numpy_elements(points, cells, u0, u1, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """midpoint_elements in vectorised numpy (the module docstring's formulas as they read): the
    reference the numba kernel is tested against."""
    cells = np.asarray(cells, dtype=np.int64)
    f1, fm, s, dndx, w = _midpoint_state(points, cells, u0, u1, mu, lam)
    p = np.einsum("egiI,egIJ->egiJ", fm, s)
    return _element_tangents(f1, fm, s, dndx, w, mu, lam), np.einsum("egiJ,egaJ,eg->eai", p, dndx, w)


def _element_tangents(f1, fm, s, dndx, w, mu: float, lam: float) -> np.ndarray:
    """(ne, a d, a d) element blocks of the module docstring's K: with g_a = F_{n+1/2} dN_a,
    h_a = F_{n+1} dN_a, G = F_{n+1/2} F_{n+1}^T, s_ab = dN_a . S dN_b and n_ab = dN_a . dN_b,

        K_aibk = sum_gauss w / 2 [s_ab delta_ik + lambda g_ai h_bk + mu (G_ik n_ab + g_bi h_ak)]

    (A contracted with the gradients term by term: batched products over the Gauss points instead of
    the 6-index A, 4x faster on the L-block's 117 hexahedra)."""
    ne, ng, na, d = dndx.shape
    hw = 0.5 * w[..., None, None]
    g = np.einsum("egiJ,egaJ->egai", fm, dndx)
    h = np.einsum("egiJ,egaJ->egai", f1, dndx)
    big_g = np.einsum("egiK,egkK->egik", fm, f1)
    sdn = np.einsum("egJL,egbL->egJb", s, dndx)
    s_ab = (hw * np.matmul(dndx, sdn)).sum(axis=1)                             # (e, a, b)
    n_ab = hw * np.matmul(dndx, np.swapaxes(dndx, -1, -2))                      # (e, g, a, b)
    gw = (hw * g).reshape(ne, ng, na * d)
    ke = lam * np.matmul(np.swapaxes(gw, 1, 2), h.reshape(ne, ng, na * d)).reshape(ne, na, d, na, d)
    ke += mu * np.matmul(np.swapaxes(n_ab.reshape(ne, ng, na * na), 1, 2),
                         big_g.reshape(ne, ng, d * d)).reshape(ne, na, na, d, d).transpose(0, 1, 3, 2, 4)
    ke += mu * np.matmul(np.swapaxes(h.reshape(ne, ng, na * d), 1, 2), gw).reshape(ne, na, d, na, d).transpose(0, 1, 4, 3, 2)
    ke += s_ab[:, :, None, :, None] * np.eye(d)[None, None, :, None, :]
    return ke.reshape(ne, na * d, na * d)


def midpoint_elements(points, cells, u0, u1, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Each element's (d f_int^{n+1/2} / d u1 (ne, a d, a d), f_int^{n+1/2} (ne, a, d)), by the numba
    kernel of midpoint_svk_kernel.py (the same as numpy_elements to 8e-16):
    an element's values depend on its own nodes only, so any split of the cells gives them bit for
    bit."""
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    dndx, w = _reference_gradients_cached(points, cells)
    n = len(points)
    ue0 = np.asarray(u0, dtype=np.float64).reshape(n, -1)[cells]
    ue1 = np.asarray(u1, dtype=np.float64).reshape(n, -1)[cells]
    return svk_midpoint_elements(ue0, ue1, np.ascontiguousarray(dndx), np.ascontiguousarray(w), float(mu), float(lam))


def midpoint_tangent(points, cells, u0, u1, mu: float, lam: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """(d f_int^{n+1/2} / d u1 (n d, n d), f_int^{n+1/2}) (module docstring's A)."""
    cells = np.asarray(cells, dtype=np.int64)
    ke, fe = midpoint_elements(points, cells, u0, u1, mu, lam)
    d = fe.shape[-1]
    return _assemble_matrix(cells, d, ke, len(points)), _assemble_vector(cells, d, fe, len(points))
