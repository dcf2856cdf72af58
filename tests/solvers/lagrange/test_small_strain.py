"""solvers/lagrange/small_strain.py: the plane-strain quad and the hexahedron stiffness reproduce linear
displacement fields exactly (the element patch test) and have exactly the rigid-body modes as their
null space."""
import numpy as np
import pytest

from solvers.lagrange.mesh import box_mesh
from solvers.lagrange.small_strain import (elasticity_3d, hex_stiffness, hex_stresses, plane_strain_elasticity,
                                           quad_stiffness, quad_stresses)


def _distorted_mesh():
    m = box_mesh([0.0, 0.0], [2.0, 1.0], [4, 3])
    rng = np.random.default_rng(0)
    inner = (m.points[:, 0] > 0) & (m.points[:, 0] < 2) & (m.points[:, 1] > 0) & (m.points[:, 1] < 1)
    m.points[inner] += rng.uniform(-0.12, 0.12, (inner.sum(), 2))  # distorted interior, straight sides
    return m


def test_linear_displacement_gives_its_exact_uniform_stress_on_a_distorted_mesh():
    m = _distorted_mesh()
    e, nu = 2.0e5, 0.3
    d = plane_strain_elasticity(e, nu)
    grad = np.array([[1e-3, 4e-4], [-2e-4, -5e-4]])  # du_i / dx_j
    u = m.points @ grad.T
    s = quad_stresses(m.points, m.cells, d, u)
    eps = np.array([grad[0, 0], grad[1, 1], grad[0, 1] + grad[1, 0]])
    np.testing.assert_allclose(s, np.broadcast_to(d @ eps, s.shape), rtol=0, atol=1e-14 * np.abs(d @ eps).max())  # measured 1.3e-15
    # interior nodes are in equilibrium: K u has forces on the boundary only
    K = quad_stiffness(m.points, m.cells, d)
    f = (K @ u.ravel()).reshape(-1, 2)
    inner = (m.points[:, 0] > 0) & (m.points[:, 0] < 2) & (m.points[:, 1] > 0) & (m.points[:, 1] < 1)
    assert np.abs(f[inner]).max() <= 1e-14 * np.abs(f).max()  # measured 2.9e-15


def test_null_space_is_the_three_rigid_modes():
    m = _distorted_mesh()
    K = quad_stiffness(m.points, m.cells, plane_strain_elasticity(1.0, 0.25)).toarray()
    w = np.linalg.eigvalsh(K)
    assert np.all(np.abs(w[:3]) < 1e-15 * w[-1]) and w[3] > 1e-3 * w[-1]  # measured 1.0e-16 and 1.1e-2
    x, y = m.points.T
    for mode in (np.stack([np.ones_like(x), 0 * x], 1), np.stack([0 * x, np.ones_like(x)], 1), np.stack([-y, x], 1)):
        assert np.abs(K @ mode.ravel()).max() < 1e-13 * np.abs(K).max()


def test_an_inverted_element_is_refused():
    m = box_mesh([0.0, 0.0], [1.0, 1.0], [1, 1])
    with pytest.raises(ValueError, match="non-positive Jacobian"):
        quad_stiffness(m.points, m.cells[:, ::-1], plane_strain_elasticity(1.0, 0.0))


# ----------------------------------------------------------------------------- hexahedra
def _distorted_hex_mesh():
    m = box_mesh([0.0, 0.0, 0.0], [2.0, 1.0, 1.5], [3, 2, 3])
    rng = np.random.default_rng(1)
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    inner = np.all((m.points > lo) & (m.points < hi), axis=1)
    m.points[inner] += rng.uniform(-0.12, 0.12, (inner.sum(), 3))  # distorted interior, flat sides
    return m, inner


def test_hex_linear_displacement_gives_its_exact_uniform_stress_on_a_distorted_mesh():
    m, inner = _distorted_hex_mesh()
    d = elasticity_3d(2.0e5, 0.3)
    grad = np.array([[1e-3, 4e-4, -3e-4], [-2e-4, -5e-4, 6e-4], [7e-4, 1e-4, 2e-4]])  # du_i / dx_j
    u = m.points @ grad.T
    s = hex_stresses(m.points, m.cells, d, u)
    eps = np.array([grad[0, 0], grad[1, 1], grad[2, 2], grad[0, 1] + grad[1, 0], grad[1, 2] + grad[2, 1],
                    grad[2, 0] + grad[0, 2]])
    want = d @ eps
    np.testing.assert_allclose(s, np.broadcast_to(want, s.shape), rtol=0, atol=1e-13 * np.abs(want).max())  # measured 1.2e-15
    # interior nodes are in equilibrium: K u has forces on the boundary only
    f = (hex_stiffness(m.points, m.cells, d) @ u.ravel()).reshape(-1, 3)
    assert np.abs(f[inner]).max() <= 1e-13 * np.abs(f).max()  # measured 2.0e-15


def test_hex_elasticity_is_isotropic_hooke():
    e, nu = 3.0, 0.25
    d = elasticity_3d(e, nu)
    # uniaxial stress: eps_xx = 1/E, the others -nu/E: sigma = (1, 0, ...)
    np.testing.assert_allclose(d @ np.array([1, -nu, -nu, 0, 0, 0]) / e, [1, 0, 0, 0, 0, 0], atol=1e-15)
    # simple shear gamma_yz: tau_yz = G gamma
    np.testing.assert_allclose(d @ np.array([0, 0, 0, 0, 1.0, 0]), [0, 0, 0, 0, e / (2 * (1 + nu)), 0], atol=1e-15)


def test_hex_null_space_is_the_six_rigid_modes():
    m, _ = _distorted_hex_mesh()
    K = hex_stiffness(m.points, m.cells, elasticity_3d(1.0, 0.25)).toarray()
    w = np.linalg.eigvalsh(K)
    assert np.all(np.abs(w[:6]) < 1e-14 * w[-1]) and w[6] > 1e-3 * w[-1]  # measured 1.2e-16 and 9.2e-3
    x, y, z = m.points.T
    one, zero = np.ones_like(x), np.zeros_like(x)
    modes = [np.stack(v, 1) for v in ((one, zero, zero), (zero, one, zero), (zero, zero, one),
                                      (-y, x, zero), (zero, -z, y), (z, zero, -x))]
    for mode in modes:
        assert np.abs(K @ mode.ravel()).max() < 1e-13 * np.abs(K).max()  # measured 3.3e-16


def test_an_inverted_hex_is_refused():
    m = box_mesh([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1, 1, 1])
    with pytest.raises(ValueError, match="non-positive Jacobian"):
        hex_stiffness(m.points, m.cells[:, [4, 5, 6, 7, 0, 1, 2, 3]], elasticity_3d(1.0, 0.0))
