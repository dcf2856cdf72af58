"""The energy-momentum internal force of compressible neo-Hookean bodies for the midpoint step (issue
12, item 1): Gonzalez's discrete gradient of the stored energy (O. Gonzalez, "Exact energy and
momentum conserving algorithms for general models in nonlinear elasticity", CMAME 190 (2000)
1763-1783), on the elements of finite_strain.py.

W(C) = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 (finite_strain.py's model; I1 = tr C, J^2 =
det C; plane strain: C's in-plane 2 x 2 block, C_33 = 1). Over a step with C_n, C_{n+1} at a Gauss
point, C_m = (C_n + C_{n+1}) / 2, dC = C_{n+1} - C_n, the algorithmic stress

    S_alg = 2 dW/dC(C_m) + 2 [W(C_{n+1}) - W(C_n) - dW/dC(C_m) : dC] dC / (dC : dC)

(the second term vanishes as dC -> 0, where S_alg is the midpoint stress; below a relative |dC| of
1e-7 it is left out: its quotient is round-off there), and f_int,ai = integral of (F_{n+1/2} S_alg)_iJ
dN_a/dX_J. Since dC = 2 sym(F_{n+1/2}^T dF), (u_{n+1} - u_n) . f_int = integral S_alg : dC / 2 =
U_{n+1} - U_n exactly: the midpoint scheme conserves the energy to the Newton tolerance, whatever
the step, and the momenta (F_{n+1/2} S_alg F_{n+1/2}^T is symmetric) as with St. Venant-Kirchhoff
(midpoint_svk.py).

Newton's matrix: the derivative of the midpoint force with S taken as 2 dW/dC(C_m) (A_iJkL = 1/2
S_JL delta_ik + 1/2 F_{n+1/2},iI CC_IJKL(C_m) F_{n+1},kK / 2 ... in midpoint_svk.py's form with the
neo-Hookean elasticity tensor CC at C_m, finite_strain.py's), without the discrete gradient's
correction: exact as dC -> 0, so Newton converges fast for the steps the scheme is used at; the
residual, and so the conservation, is exact.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.lagrange.finite_strain import _assemble_matrix, _assemble_vector, kinematics

__all__ = ["nh_energy", "element_energies", "cauchy_stresses", "dg_force", "dg_elements", "dg_tangent"]


def _cauchy_green(f: np.ndarray) -> np.ndarray:
    return np.einsum("...kI,...kJ->...IJ", f, f)


def _w(c: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """W(C) per Gauss point (plane strain: I1 = tr C + 1)."""
    d = c.shape[-1]
    i1 = np.trace(c, axis1=-2, axis2=-1) + (1.0 if d == 2 else 0.0)
    lnj = 0.5 * np.log(np.linalg.det(c))
    return 0.5 * mu * (i1 - 3.0) - mu * lnj + 0.5 * lam * lnj ** 2


def _s(c: np.ndarray, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(2 dW/dC = mu (I - C^-1) + lambda ln J C^-1, C^-1, ln J) at C."""
    cinv = np.linalg.inv(c)
    lnj = 0.5 * np.log(np.linalg.det(c))
    return mu * (np.eye(c.shape[-1]) - cinv) + (lam * lnj)[..., None, None] * cinv, cinv, lnj


def element_energies(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """(ne,) each element's integral of W (J; per unit thickness in 2-D)."""
    f, _, w = kinematics(points, cells, u, cache=True)
    if np.any(np.linalg.det(f) <= 0.0):
        raise ValueError("an element is inverted (J <= 0 at a Gauss point)")
    return np.sum(w * _w(_cauchy_green(f), mu, lam), axis=1)


def nh_energy(points, cells, u, mu: float, lam: float) -> float:
    return float(element_energies(points, cells, u, mu, lam).sum())


def cauchy_stresses(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """(ne, 6) Voigt xx yy zz xy yz zx, the mean over each element's Gauss points."""
    from solvers.lagrange.finite_strain import cauchy_stresses as cs

    return cs(points, cells, np.asarray(u, float).reshape(len(points), -1), mu, lam).mean(axis=1)


def _algorithmic_state(points, cells, u0, u1, mu, lam):
    f0, dndx, w = kinematics(points, cells, u0, cache=True)
    f1 = kinematics(points, cells, u1, cache=True)[0]
    if np.any(np.linalg.det(f1) <= 0.0):
        raise ValueError("an element is inverted (J <= 0 at a Gauss point)")
    c0, c1 = _cauchy_green(f0), _cauchy_green(f1)
    cm, dc = 0.5 * (c0 + c1), c1 - c0
    s_m, cinv, lnj = _s(cm, mu, lam)
    dd = np.einsum("...IJ,...IJ->...", dc, dc)
    size = np.einsum("...IJ,...IJ->...", cm, cm)
    jump = _w(c1, mu, lam) - _w(c0, mu, lam) - 0.5 * np.einsum("...IJ,...IJ->...", s_m, dc)
    use = dd > 1e-14 * size
    corr = np.where(use, 2.0 * jump / np.where(use, dd, 1.0), 0.0)
    s = s_m + corr[..., None, None] * dc
    return f1, 0.5 * (f0 + f1), s, s_m, cinv, lnj, dndx, w


def dg_force(points, cells, u0, u1, mu: float, lam: float) -> np.ndarray:
    """f_int (n d,) of the step from u0 to u1 (each (n, d) or (n d,))."""
    cells = np.asarray(cells, dtype=np.int64)
    _, fm, s, *_, dndx, w = _algorithmic_state(points, cells, u0, u1, mu, lam)
    p = np.einsum("egiI,egIJ->egiJ", fm, s)
    fe = np.einsum("egiJ,egaJ,eg->eai", p, dndx, w)
    return _assemble_vector(cells, fm.shape[-1], fe, len(points))


def dg_tangent(points, cells, u0, u1, mu: float, lam: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """(Newton's matrix (n d, n d), f_int (n d,)) (module docstring)."""
    cells = np.asarray(cells, dtype=np.int64)
    ke, fe = dg_elements(points, cells, u0, u1, mu, lam)
    d = fe.shape[-1]
    return _assemble_matrix(cells, d, ke, len(points)), _assemble_vector(cells, d, fe, len(points))


def dg_elements(points, cells, u0, u1, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Each element's (Newton's matrix (ne, a d, a d), f_int (ne, a, d)) (module docstring)."""
    cells = np.asarray(cells, dtype=np.int64)
    f1, fm, s, s_m, cinv, lnj, dndx, w = _algorithmic_state(points, cells, u0, u1, mu, lam)
    d = fm.shape[-1]
    eye = np.eye(d)
    m = (mu - lam * lnj)[..., None, None, None, None]
    # CC_IJKL(C_m) = lambda C^-1_IJ C^-1_KL + (mu - lambda ln J)(C^-1_IK C^-1_JL + C^-1_IL C^-1_JK)
    cc = (lam * np.einsum("egIJ,egKL->egIJKL", cinv, cinv)
          + m * (np.einsum("egIK,egJL->egIJKL", cinv, cinv) + np.einsum("egIL,egJK->egIJKL", cinv, cinv)))
    # d S_m / d u1 = CC : dC_m/du1 = CC : sym(F1^T dF1) / 2 ... with dF_m = dF1 / 2:
    # A_iJkL = 1/2 S_JL delta_ik + 1/2 F_m,iI CC_IJKL F1,kK
    a = 0.5 * (np.einsum("ik,egJL->egiJkL", eye, s) + np.einsum("egiI,egIJKL,egkK->egiJkL", fm, cc, f1))
    ke = np.einsum("egaJ,egiJkL,egbL,eg->eaibk", dndx, a, dndx, w, optimize=True)
    nd = cells.shape[1] * d
    p = np.einsum("egiI,egIJ->egiJ", fm, s)
    return ke.reshape(len(cells), nd, nd), np.einsum("egiJ,egaJ,eg->eai", p, dndx, w)
