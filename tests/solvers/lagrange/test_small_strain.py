"""solvers/lagrange/small_strain.py: the plane-strain quad stiffness reproduces linear displacement
fields exactly (the element patch test) and has exactly the rigid-body modes as its null space."""
import numpy as np
import pytest

from solvers.lagrange.mesh import box_mesh
from solvers.lagrange.small_strain import plane_strain_elasticity, quad_stiffness, quad_stresses


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
