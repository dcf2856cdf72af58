"""Linear small-strain statics of plane-strain quadrilaterals and of hexahedra: the stiffness matrix and
the stresses at the Gauss points (2 x 2 and 2 x 2 x 2 full integration, the bilinear and trilinear
elements that pass the patch test).

The first piece of the implicit quasi-static mode (issue 11): contact patch tests are linear
small-strain problems (Crisfield's two blocks: E = 1e6, nu = 0, 1 % strain, sigma_y = E eps
exactly). The explicit solver's one-point quadrature with hourglass control has no stiffness of its
hourglass modes that a static solve can use, hence full integration here.

Everything is vectorised numpy over elements and Gauss points; the matrix is scipy.sparse.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["plane_strain_elasticity", "quad_stiffness", "quad_stresses", "elasticity_3d", "hex_stiffness",
           "hex_stresses"]

_G = 1.0 / np.sqrt(3.0)
_XI = np.array([[-_G, -_G], [_G, -_G], [_G, _G], [-_G, _G]])          # 2 x 2 Gauss points, weight 1
_CORNERS = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)  # mesh.py node order


def plane_strain_elasticity(youngs_modulus: float, poisson_ratio: float) -> np.ndarray:
    """D (3, 3) mapping (eps_xx, eps_yy, gamma_xy) to (sigma_xx, sigma_yy, tau_xy), plane strain."""
    e, nu = float(youngs_modulus), float(poisson_ratio)
    c = e / ((1 + nu) * (1 - 2 * nu))
    return c * np.array([[1 - nu, nu, 0.0], [nu, 1 - nu, 0.0], [0.0, 0.0, (1 - 2 * nu) / 2]])


def _strain_displacement(points: np.ndarray, cells: np.ndarray):
    """B (ne, 4, 3, 8) at the Gauss points and the weights det(J) (ne, 4)."""
    # dN/dxi (4 gauss, 4 nodes, 2): N_a = (1 + xi xi_a)(1 + eta eta_a) / 4
    xi, eta = _XI[:, 0, None], _XI[:, 1, None]
    dn = np.stack([_CORNERS[:, 0] * (1 + eta * _CORNERS[:, 1]), _CORNERS[:, 1] * (1 + xi * _CORNERS[:, 0])], axis=2) / 4
    x = points[cells]                                   # (ne, 4, 2)
    jac = np.einsum("gan,ead->egnd", dn, x)             # (ne, g, 2 ref, 2 phys): dx_d / dxi_n
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    if np.any(det <= 0.0):
        raise ValueError("an element has a non-positive Jacobian at a Gauss point")
    inv = np.stack([np.stack([jac[..., 1, 1], -jac[..., 0, 1]], -1),
                    np.stack([-jac[..., 1, 0], jac[..., 0, 0]], -1)], -2) / det[..., None, None]
    dndx = np.einsum("gan,egdn->egad", dn, inv)         # (ne, g, 4 nodes, 2): dN_a / dx_d = J^-1 dN_a / dxi
    b = np.zeros(dndx.shape[:2] + (3, 8))
    b[..., 0, 0::2] = dndx[..., 0]
    b[..., 1, 1::2] = dndx[..., 1]
    b[..., 2, 0::2] = dndx[..., 1]
    b[..., 2, 1::2] = dndx[..., 0]
    return b, det


def _dofs(cells: np.ndarray) -> np.ndarray:
    return np.stack([2 * cells, 2 * cells + 1], axis=2).reshape(len(cells), 8)


def quad_stiffness(points: np.ndarray, cells: np.ndarray, d: np.ndarray) -> sp.csr_matrix:
    """K (2 n, 2 n) of plane-strain quads (dofs x0, y0, x1, y1, ...), d from plane_strain_elasticity;
    per unit thickness."""
    points = np.asarray(points, dtype=np.float64)
    b, det = _strain_displacement(points, cells)
    return _assemble(b, det, d, _dofs(cells), 2 * len(points))


def _assemble(b: np.ndarray, det: np.ndarray, d: np.ndarray, dof: np.ndarray, n: int) -> sp.csr_matrix:
    """K (n, n) = sum over elements and Gauss points of B^T D B det(J) (unit weights), scattered by
    each element's dofs (ne, k)."""
    ke = np.einsum("egip,ij,egjq,eg->epq", b, d, b, det)
    k = dof.shape[1]
    rows = np.repeat(dof, k, axis=1).ravel()
    cols = np.tile(dof, (1, k)).ravel()
    return sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n, n))


def quad_stresses(points: np.ndarray, cells: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(sigma_xx, sigma_yy, tau_xy) at every Gauss point, (ne, 4, 3), of displacements u (n, 2)."""
    b, _ = _strain_displacement(np.asarray(points, dtype=np.float64), cells)
    ue = np.asarray(u, dtype=np.float64).reshape(-1)[_dofs(cells)]
    return np.einsum("ij,egjq,eq->egi", d, b, ue)


# ----------------------------------------------------------------------------- hexahedra (3-D)
_HEX_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                         [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)  # mesh.py order
_HEX_XI = _G * _HEX_CORNERS                                             # 2 x 2 x 2 Gauss points, weight 1


def elasticity_3d(youngs_modulus: float, poisson_ratio: float) -> np.ndarray:
    """D (6, 6) of isotropic linear elasticity in Voigt order (xx, yy, zz, xy, yz, zx), engineering
    shear strains (gamma_xy = 2 eps_xy): sigma = D eps."""
    e, nu = float(youngs_modulus), float(poisson_ratio)
    lam = e * nu / ((1 + nu) * (1 - 2 * nu))
    mu = e / (2 * (1 + nu))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[[0, 1, 2], [0, 1, 2]] += 2 * mu
    d[[3, 4, 5], [3, 4, 5]] = mu
    return d


def _hex_strain_displacement(points: np.ndarray, cells: np.ndarray):
    """B (ne, 8, 6, 24) at the Gauss points and the weights det(J) (ne, 8)."""
    # dN_a/dxi_k (8 gauss, 8 nodes, 3): N_a = (1 + xi xi_a)(1 + eta eta_a)(1 + zeta zeta_a) / 8
    f = 1.0 + _HEX_XI[:, None, :] * _HEX_CORNERS[None, :, :]          # (g, a, 3)
    dn = np.stack([_HEX_CORNERS[None, :, 0] * f[..., 1] * f[..., 2],
                   _HEX_CORNERS[None, :, 1] * f[..., 0] * f[..., 2],
                   _HEX_CORNERS[None, :, 2] * f[..., 0] * f[..., 1]], axis=2) / 8
    x = points[cells]                                   # (ne, 8, 3)
    jac = np.einsum("gan,ead->egnd", dn, x)             # (ne, g, 3 ref, 3 phys): dx_d / dxi_n
    det = np.linalg.det(jac)
    if np.any(det <= 0.0):
        raise ValueError("an element has a non-positive Jacobian at a Gauss point")
    dndx = np.einsum("gan,egdn->egad", dn, np.linalg.inv(jac))   # dN_a / dx_d = (J^-1)_dn dN_a / dxi_n
    b = np.zeros(dndx.shape[:2] + (6, 24))
    for k in range(3):                                  # normal strains eps_kk
        b[..., k, k::3] = dndx[..., k]
    for row, (i, j) in zip((3, 4, 5), ((0, 1), (1, 2), (2, 0))):   # gamma_ij = du_i/dx_j + du_j/dx_i
        b[..., row, i::3] = dndx[..., j]
        b[..., row, j::3] = dndx[..., i]
    return b, det


def _hex_dofs(cells: np.ndarray) -> np.ndarray:
    return np.stack([3 * cells, 3 * cells + 1, 3 * cells + 2], axis=2).reshape(len(cells), 24)


def hex_stiffness(points: np.ndarray, cells: np.ndarray, d: np.ndarray) -> sp.csr_matrix:
    """K (3 n, 3 n) of 8-node trilinear hexahedra (dofs x0, y0, z0, x1, ...; cells in mesh.py's node
    order), d (6, 6) from elasticity_3d; 2 x 2 x 2 Gauss (exact for a parallelepiped)."""
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    b, det = _hex_strain_displacement(points, cells)
    return _assemble(b, det, d, _hex_dofs(cells), 3 * len(points))


def hex_stresses(points: np.ndarray, cells: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Stresses (xx, yy, zz, xy, yz, zx) at every Gauss point, (ne, 8, 6), of displacements u (n, 3)."""
    cells = np.asarray(cells, dtype=np.int64)
    b, _ = _hex_strain_displacement(np.asarray(points, dtype=np.float64), cells)
    ue = np.asarray(u, dtype=np.float64).reshape(-1)[_hex_dofs(cells)]
    return np.einsum("ij,egjq,eq->egi", d, b, ue)
