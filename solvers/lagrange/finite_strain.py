"""Finite-strain (total-Lagrangian) statics of the compressible neo-Hookean model: the internal force
vector, its consistent tangent and the Cauchy stresses at the Gauss points, for full-integration
bilinear quads (plane strain, F_33 = 1) and trilinear hexahedra (2 x 2 and 2 x 2 x 2 Gauss, the
elements of small_strain.py). Used by the quasi-static mode's Newton iteration (quasi_static.py).

The model is materials.neo_hookean_stress's: the stored energy per reference volume

    W(C) = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,     I1 = tr C,  J = det F,  C = F^T F,

(Bonet & Wood, Nonlinear Continuum Mechanics for FEA, 2nd ed., eq. 6.27-6.28), whose second
Piola-Kirchhoff stress is S = 2 dW/dC = mu (I - C^-1) + lambda ln J C^-1 and Cauchy stress
sigma = J^-1 F S F^T = mu/J (b - I) + lambda ln J / J I. The material elasticity tensor is

    C_IJKL = 4 d^2W / dC_IJ dC_KL = lambda C^-1_IJ C^-1_KL + 2 (mu - lambda ln J) I_{C^-1},
    I_{C^-1,IJKL} = (C^-1_IK C^-1_JL + C^-1_IL C^-1_JK) / 2     (Bonet & Wood eq. 6.29).

Total-Lagrangian weak form (Bonet & Wood ch. 8; Holzapfel ch. 8): f_int,ai = integral over the
reference of P_iJ dN_a/dX_J with the first Piola-Kirchhoff P = F S, and its derivative with respect
to u_bk, the tangent

    K_aibk = integral dN_a/dX_J A_iJkL dN_b/dX_L,   A_iJkL = F_iI C_IJKL F_kK + S_JL delta_ik,

material part plus geometric (initial-stress) part. With H = F^-T (F C^-1 = F^-T and
F C^-1 F^T = I) the material part is lambda H_iJ H_kL + (mu - lambda ln J)(delta_ik C^-1_JL +
H_iL H_kJ), which is what is evaluated. In plane strain F, C are block diagonal with F_33 = 1, so
the in-plane 2 x 2 blocks of all of this are exact and sigma_zz = lambda ln J / J.

At F = I the tangent is Hooke's lambda delta_iJ delta_kL + mu (delta_ik delta_JL + delta_iL delta_kJ):
K_T(0) is small_strain.py's stiffness with the same E, nu.

Vectorised numpy over elements and Gauss points; scipy.sparse assembly; dofs interleaved
(x0, y0, [z0,] x1, ...) as in small_strain.py.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["lame", "kinematics", "internal_force", "tangent", "cauchy_stresses"]

_G = 1.0 / np.sqrt(3.0)
_QUAD = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)            # mesh.py order
_HEX = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                 [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)


def lame(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(mu, lambda) of E, nu (materials.material_params' G and K - 2 G / 3)."""
    e, nu = float(youngs_modulus), float(poisson_ratio)
    mu = e / (2.0 * (1.0 + nu))
    return mu, e / (3.0 * (1.0 - 2.0 * nu)) - 2.0 * mu / 3.0


def _reference_gradients(points: np.ndarray, cells: np.ndarray):
    """dN_a/dX (ne, g, a, d) at the Gauss points of the reference configuration and the weights
    det(dX/dxi) (ne, g) (all Gauss weights are 1)."""
    corners = _QUAD if cells.shape[1] == 4 else _HEX
    xi = _G * corners                                                   # Gauss points (g, d)
    f = 1.0 + xi[:, None, :] * corners[None, :, :]                      # (g, a, d)
    d = corners.shape[1]
    # dN_a/dxi_n = c_an prod_{m != n} (1 + xi_m c_am) / 2^d
    dn = np.stack([corners[None, :, n] * np.prod(np.delete(f, n, axis=2), axis=2) for n in range(d)],
                  axis=2) / 2 ** d
    x = points[cells]
    jac = np.einsum("gan,ead->egnd", dn, x)                             # dX_d / dxi_n
    det = np.linalg.det(jac)
    if np.any(det <= 0.0):
        raise ValueError("an element has a non-positive Jacobian at a Gauss point")
    return np.einsum("gan,egdn->egad", dn, np.linalg.inv(jac)), det


def _dofs(cells: np.ndarray, d: int) -> np.ndarray:
    return (d * cells[:, :, None] + np.arange(d)).reshape(len(cells), -1)


_REFERENCE: list = []
"""The last few (points, cells, gradients, weights): an implicit step evaluates the same mesh's
reference gradients at every Newton iterate (a fifth of the L-block's step before). Keyed by the
arrays' identity; the cache holds them, so an id cannot be reused for other data while cached, and
they are compared unchanged (a caller that edits its points in place gets fresh gradients)."""


def _reference_gradients_cached(points: np.ndarray, cells: np.ndarray):
    for entry in _REFERENCE:
        p, c, pc, cc, grads = entry
        if p is points and c is cells and np.array_equal(pc, points) and np.array_equal(cc, cells):
            return grads
    grads = _reference_gradients(points, cells)
    _REFERENCE.insert(0, (points, cells, points.copy(), cells.copy(), grads))
    del _REFERENCE[4:]
    return grads


def kinematics(points: np.ndarray, cells: np.ndarray, u: np.ndarray, cache: bool = False):
    """(F (ne, g, d, d), dN/dX (ne, g, a, d), weights (ne, g)) of displacements u (n, d); cache: the
    reference gradients kept for the next call with these very arrays (the implicit step's meshes,
    which hold them for the run; the cache holds 4: its memory is the meshes' gradients)."""
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    dndx, w = _reference_gradients_cached(points, cells) if cache else _reference_gradients(points, cells)
    ue = np.asarray(u, dtype=np.float64).reshape(len(points), -1)[cells]      # (ne, a, d)
    f = np.eye(points.shape[1]) + np.einsum("eai,egaJ->egiJ", ue, dndx)      # F_iJ = delta + u_ai dN_a/dX_J
    return f, dndx, w


def _stress_state(f: np.ndarray, mu: float, lam: float):
    """J, ln J, C^-1, H = F^-T and S = mu (I - C^-1) + lambda ln J C^-1 (in-plane in 2-D)."""
    j = np.linalg.det(f)
    if np.any(j <= 0.0):
        raise ValueError("an element is inverted (J <= 0 at a Gauss point)")
    lnj = np.log(j)
    finv = np.linalg.inv(f)
    cinv = np.einsum("...Ii,...Ji->...IJ", finv, finv)                # C^-1 = F^-1 F^-T
    eye = np.eye(f.shape[-1])
    s = mu * (eye - cinv) + (lam * lnj)[..., None, None] * cinv
    return j, lnj, cinv, np.swapaxes(finv, -1, -2), s


def _assemble_matrix(cells, d, ke, n):
    """The global (n d, n d) CSR matrix of element blocks ke (ne, a d, a d) (duplicates summed)."""
    nd = ke.shape[1]
    dof = _dofs(cells, d)
    rows = np.repeat(dof, nd, axis=1).ravel()
    cols = np.tile(dof, (1, nd)).ravel()
    return sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n * d, n * d))


class AssemblyPattern:
    """The CSR pattern of the element blocks of several meshes (the bodies) over one set of nodes,
    with each element entry's slot in it: matrix(values) sums the entries (ke of every mesh, raveled
    and concatenated in order) into their slots in entry order, duplicates included."""

    def __init__(self, cells_list, d: int, n_points: int):
        nd = n_points * d
        rows, cols = [], []
        for cells in cells_list:
            dof = _dofs(np.asarray(cells, dtype=np.int64), d)
            k = dof.shape[1]
            rows.append(np.repeat(dof, k, axis=1).ravel())
            cols.append(np.tile(dof, (1, k)).ravel())
        key = np.concatenate(rows) * nd + np.concatenate(cols) if rows else np.zeros(0, np.int64)
        unique, self.slot = np.unique(key, return_inverse=True)
        self.indices = (unique % nd).astype(np.int32)
        self.indptr = np.searchsorted(unique // nd, np.arange(nd + 1)).astype(np.int32)
        self.shape = (nd, nd)
        diag = np.arange(nd, dtype=np.int64) * (nd + 1)
        at = np.minimum(np.searchsorted(unique, diag), max(len(unique) - 1, 0))
        # each dof's diagonal slot (None if a dof belongs to no element: then a sparse sum)
        self.diag_slot = at if len(unique) and np.array_equal(unique[at], diag) else None

    def matrix(self, values: np.ndarray, diagonal: np.ndarray | None = None) -> sp.csr_matrix:
        """The matrix of the entries ``values``; plus diag(``diagonal``) (added to the summed
        entries: the same as sp.diags(diagonal) + K)."""
        data = np.bincount(self.slot, weights=values, minlength=len(self.indices))
        if diagonal is not None and self.diag_slot is not None:
            data[self.diag_slot] = np.asarray(diagonal, dtype=np.float64) + data[self.diag_slot]
            diagonal = None
        k = sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape)
        return k if diagonal is None else sp.diags(diagonal) + k


_PATTERNS: list = []
"""The last few (cells arrays, their copies, d, n, pattern), as _REFERENCE: keyed by the arrays'
identity and compared unchanged."""


def assembly_pattern(cells_list, d: int, n_points: int) -> AssemblyPattern:
    """The AssemblyPattern of these meshes, from the cache when the very arrays were seen before."""
    for entry in _PATTERNS:
        cl, copies, dd, nn, pattern = entry
        if (dd == d and nn == n_points and len(cl) == len(cells_list)
                and all(a is b and np.array_equal(a, c) for a, b, c in zip(cl, cells_list, copies))):
            return pattern
    pattern = AssemblyPattern(cells_list, d, n_points)
    _PATTERNS.insert(0, (list(cells_list), [np.array(c, copy=True) for c in cells_list], d, n_points, pattern))
    del _PATTERNS[4:]
    return pattern


def _assemble_vector(cells, d, fe, n):
    out = np.zeros(n * d)
    np.add.at(out, _dofs(cells, d).ravel(), fe.ravel())
    return out


def internal_force(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """f_int (n d,): integral over the reference of P_iJ dN_a/dX_J, P = F S (per unit thickness in 2-D)."""
    cells = np.asarray(cells, dtype=np.int64)
    f, dndx, w = kinematics(points, cells, u)
    s = _stress_state(f, mu, lam)[4]
    p = np.einsum("egiI,egIJ->egiJ", f, s)
    fe = np.einsum("egiJ,egaJ,eg->eai", p, dndx, w)
    return _assemble_vector(cells, f.shape[-1], fe, len(points))


def tangent(points, cells, u, mu: float, lam: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """(K_T (n d, n d), f_int (n d,)) at displacements u: the consistent tangent of internal_force
    (module docstring: material + geometric part)."""
    cells = np.asarray(cells, dtype=np.int64)
    f, dndx, w = kinematics(points, cells, u)
    d = f.shape[-1]
    j, lnj, cinv, h, s = _stress_state(f, mu, lam)
    eye = np.eye(d)
    m = (mu - lam * lnj)[..., None, None, None, None]
    # A_iJkL: material part lambda H_iJ H_kL + (mu - lambda ln J)(delta_ik C^-1_JL + H_iL H_kJ),
    # geometric part S_JL delta_ik
    a = (lam * np.einsum("egiJ,egkL->egiJkL", h, h)
         + m * (np.einsum("ik,egJL->egiJkL", eye, cinv) + np.einsum("egiL,egkJ->egiJkL", h, h))
         + np.einsum("ik,egJL->egiJkL", eye, s))
    ke = np.einsum("egaJ,egiJkL,egbL,eg->eaibk", dndx, a, dndx, w)
    na = cells.shape[1]
    ke = ke.reshape(len(cells), na * d, na * d)
    p = np.einsum("egiI,egIJ->egiJ", f, s)
    fe = np.einsum("egiJ,egaJ,eg->eai", p, dndx, w)
    return _assemble_matrix(cells, d, ke, len(points)), _assemble_vector(cells, d, fe, len(points))


def cauchy_stresses(points, cells, u, mu: float, lam: float) -> np.ndarray:
    """Cauchy stress sigma = mu/J (b - I) + lambda ln J / J I at every Gauss point, (ne, g, 6) Voigt
    xx yy zz xy yz zx (plane strain: b_zz = 1, so sigma_zz = lambda ln J / J, yz = zx = 0)."""
    f = kinematics(points, cells, u)[0]
    j = np.linalg.det(f)
    if np.any(j <= 0.0):
        raise ValueError("an element is inverted (J <= 0 at a Gauss point)")
    b = np.einsum("...iK,...jK->...ij", f, f)
    d = f.shape[-1]
    sig = (mu / j)[..., None, None] * (b - np.eye(d)) + (lam * np.log(j) / j)[..., None, None] * np.eye(d)
    out = np.zeros(f.shape[:2] + (6,))
    if d == 2:
        out[..., 0], out[..., 1], out[..., 3] = sig[..., 0, 0], sig[..., 1, 1], sig[..., 0, 1]
        out[..., 2] = lam * np.log(j) / j
    else:
        out[..., 0], out[..., 1], out[..., 2] = sig[..., 0, 0], sig[..., 1, 1], sig[..., 2, 2]
        out[..., 3], out[..., 4], out[..., 5] = sig[..., 0, 1], sig[..., 1, 2], sig[..., 2, 0]
    return out
