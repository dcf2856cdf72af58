"""The midpoint St. Venant-Kirchhoff internal force (solvers/lagrange/midpoint_svk.py, issue 12): over
any step its work equals the change of stored energy to round-off, it conserves linear and angular
momentum, its tangent is its derivative, and a rigid rotation stores nothing."""
import numpy as np
import pytest

from solvers.lagrange import finite_strain as fs
from solvers.lagrange import midpoint_svk as mp
from tests.solvers.lagrange.test_finite_strain import MESHES

E, NU = 3.0e6, 0.35


def _rotation(d, angle):
    c, s = np.cos(angle), np.sin(angle)
    r = np.array([[c, -s], [s, c]]) if d == 2 else np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if d == 3:  # and a turn about x, so that no axis is left alone
        a = 0.7 * angle
        r = r @ np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    return r


def _step(p, rng):
    """Two large deformations: a 40 degree turn apart, stretched 10-30 %, randomly perturbed."""
    d = p.shape[1]
    x0 = p @ (_rotation(d, 0.3) @ np.diag([1.1, 0.85, 1.2][:d])).T + 0.03 * rng.standard_normal(p.shape)
    x1 = p @ (_rotation(d, 1.0) @ np.diag([1.3, 0.9, 0.95][:d])).T + 0.03 * rng.standard_normal(p.shape)
    return x0 - p, x1 - p


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_midpoint_work_is_the_energy_change_and_momenta_are_conserved(kind):
    """(u1 - u0) . f^{n+1/2} = U(u1) - U(u0): measured 4.0e-16 (quad) and 2.9e-16 (hex) relative to U;
    the forces sum to zero (translation) and x_{n+1/2} x f to zero (rotation), relative to |f| |x|."""
    p, cells = MESHES[kind]()
    mu, lam = fs.lame(E, NU)
    rng = np.random.default_rng(11)
    for _ in range(3):
        u0, u1 = _step(p, rng)
        f = mp.midpoint_force(p, cells, u0, u1, mu, lam)
        work = float((u1 - u0).ravel() @ f)
        du = mp.svk_energy(p, cells, u1, mu, lam) - mp.svk_energy(p, cells, u0, mu, lam)
        scale = max(mp.svk_energy(p, cells, u1, mu, lam), mp.svk_energy(p, cells, u0, mu, lam))
        assert abs(work - du) <= 2e-15 * scale, (work, du)
        fn = f.reshape(p.shape)
        assert np.abs(fn.sum(axis=0)).max() <= 1e-12 * np.abs(fn).max()
        xm = p + 0.5 * (u0 + u1)
        torque = (xm[:, 0] * fn[:, 1] - xm[:, 1] * fn[:, 0]).sum() if p.shape[1] == 2 else np.cross(xm, fn).sum(axis=0)
        assert np.abs(torque).max() <= 1e-12 * np.abs(fn).max() * np.abs(xm).max(), torque


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_midpoint_tangent_is_the_derivative_in_the_end_state(kind):
    """Central differences of f^{n+1/2} in u1 (h = 1e-6): relative 2e-10 of the largest entry (measured
    3.3e-11 quad, 2.4e-11 hex)."""
    p, cells = MESHES[kind]()
    mu, lam = fs.lame(E, NU)
    u0, u1 = _step(p, np.random.default_rng(5))
    k, f = mp.midpoint_tangent(p, cells, u0, u1, mu, lam)
    assert np.array_equal(f, mp.midpoint_force(p, cells, u0, u1, mu, lam))
    h = 1e-6
    kd = np.zeros(k.shape)
    for i in range(u1.size):
        du = np.zeros(u1.size)
        du[i] = h
        kd[:, i] = (mp.midpoint_force(p, cells, u0, u1.ravel() + du, mu, lam)
                    - mp.midpoint_force(p, cells, u0, u1.ravel() - du, mu, lam)) / (2 * h)
    err = np.abs(k.toarray() - kd).max() / np.abs(kd).max()
    assert err < 2e-10, err


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_rigid_rotation_stores_nothing_and_small_steps_are_hookes(kind):
    """A rigid turn by 70 degrees: E = 0, no force (relative 1e-15 of E |X|^2); at small strain the
    static midpoint force (u0 = u1) is small_strain's K u to second order in u."""
    from solvers.lagrange import small_strain

    p, cells = MESHES[kind]()
    d = p.shape[1]
    mu, lam = fs.lame(E, NU)
    u = p @ _rotation(d, 1.2).T - p
    assert np.abs(mp.midpoint_force(p, cells, np.zeros_like(p), u, mu, lam)).max() <= 1e-15 * E
    assert abs(mp.svk_energy(p, cells, u, mu, lam)) <= 1e-25 * E
    k_lin = (small_strain.quad_stiffness(p, cells, small_strain.plane_strain_elasticity(E, NU)) if d == 2
             else small_strain.hex_stiffness(p, cells, small_strain.elasticity_3d(E, NU)))
    v = np.random.default_rng(3).standard_normal(p.size)
    rel = []
    for eps in (1e-4, 1e-5):
        f = mp.midpoint_force(p, cells, eps * v, eps * v, mu, lam)
        rel.append(np.abs(f - k_lin @ (eps * v)).max() / np.abs(k_lin @ (eps * v)).max())
    # first order in the displacement (the quadratic part of E): measured 1.25e-3 (quad), 0.93e-3 (hex)
    # at eps = 1e-4, 10x less at 10x less displacement
    assert rel[0] < 3e-3 and rel[1] / rel[0] == pytest.approx(0.1, rel=0.05), rel


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_the_numba_kernel_is_the_numpy_formulas(kind):
    """midpoint_elements (the numba kernel) against numpy_elements (the formulas in numpy) on large
    deformations: element matrices and forces equal to 4e-15 of their largest entry (measured 1.9e-16 /
    3.4e-16 quad, 4.0e-16 / 5.4e-16 hex)."""
    p, cells = MESHES[kind]()
    mu, lam = fs.lame(E, NU)
    u0, u1 = _step(p, np.random.default_rng(3))
    ke, fe = mp.midpoint_elements(p, cells, u0, u1, mu, lam)
    kr, fr = mp.numpy_elements(p, cells, u0, u1, mu, lam)
    assert np.abs(ke - kr).max() <= 4e-15 * np.abs(kr).max()
    assert np.abs(fe - fr).max() <= 4e-15 * np.abs(fr).max()
