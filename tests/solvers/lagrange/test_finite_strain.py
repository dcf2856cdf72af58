"""Total-Lagrangian neo-Hookean quads and hexahedra (solvers/lagrange/finite_strain.py): the tangent
is the derivative of the internal force; at F = I they are small_strain.py's; the stress is
materials.neo_hookean_stress's; a homogeneous uniaxial stretch on a distorted mesh is reproduced."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla
from scipy.optimize import brentq

from solvers.lagrange import finite_strain as fs
from solvers.lagrange import small_strain
from solvers.lagrange.materials import neo_hookean_stress

E, NU = 3.0e6, 0.35


def _quad_mesh():
    """3 x 3 quads on the unit square, interior nodes moved (a distorted mesh)."""
    g = np.linspace(0.0, 1.0, 4)
    x, y = np.meshgrid(g, g, indexing="xy")
    p = np.stack([x.ravel(), y.ravel()], axis=1)
    inner = (p[:, 0] > 0) & (p[:, 0] < 1) & (p[:, 1] > 0) & (p[:, 1] < 1)
    p[inner] += np.array([[0.07, -0.05], [-0.06, 0.04], [0.05, 0.06], [-0.04, -0.07]])
    cells = np.array([[j * 4 + i, j * 4 + i + 1, (j + 1) * 4 + i + 1, (j + 1) * 4 + i]
                      for j in range(3) for i in range(3)])
    return p, cells


def _hex_mesh():
    """2 x 2 x 2 hexahedra on the unit cube, the centre node moved."""
    g = np.linspace(0.0, 1.0, 3)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    p[13] += [0.08, -0.06, 0.05]
    idx = lambda i, j, k: k * 9 + j * 3 + i  # noqa: E731
    cells = np.array([[idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j + 1, k), idx(i, j + 1, k),
                       idx(i, j, k + 1), idx(i + 1, j, k + 1), idx(i + 1, j + 1, k + 1), idx(i, j + 1, k + 1)]
                      for k in range(2) for j in range(2) for i in range(2)])
    return p, cells


MESHES = {"quad": _quad_mesh, "hex": _hex_mesh}


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_tangent_is_the_derivative_of_the_internal_force(kind):
    """Central differences of f_int (h = 1e-6) at a random large deformation (strains 10 - 25 %):
    relative 1e-9 of the largest entry (measured 1.8e-11 quad, 1.7e-11 hex)."""
    p, cells = MESHES[kind]()
    mu, lam = fs.lame(E, NU)
    rng = np.random.default_rng(7)
    u = 0.04 * rng.standard_normal(p.shape) + p @ np.diag([0.2, -0.25, 0.1][: p.shape[1]])
    k, f0 = fs.tangent(p, cells, u, mu, lam)
    assert np.allclose(f0, fs.internal_force(p, cells, u, mu, lam), rtol=0, atol=1e-9 * np.abs(f0).max())
    h = 1e-6
    kd = np.zeros(k.shape)
    for i in range(u.size):
        du = np.zeros(u.size)
        du[i] = h
        kd[:, i] = (fs.internal_force(p, cells, u.ravel() + du, mu, lam)
                    - fs.internal_force(p, cells, u.ravel() - du, mu, lam)) / (2 * h)
    err = np.abs(k.toarray() - kd).max() / np.abs(kd).max()
    assert err < 1e-9, err


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_small_strain_limit(kind):
    """K_T(0) is the small-strain stiffness to 1e-12 (measured 1.9e-16 quad, 1.5e-16 hex); at a
    1e-7 displacement f_int is K u to 1e-5 relative (the neglected terms are quadratic in u)."""
    p, cells = MESHES[kind]()
    mu, lam = fs.lame(E, NU)
    if kind == "quad":
        k_lin = small_strain.quad_stiffness(p, cells, small_strain.plane_strain_elasticity(E, NU))
    else:
        k_lin = small_strain.hex_stiffness(p, cells, small_strain.elasticity_3d(E, NU))
    k0, f0 = fs.tangent(p, cells, np.zeros_like(p), mu, lam)
    assert np.abs(f0).max() == 0.0
    err = abs(k0 - k_lin).max() / abs(k_lin).max()
    assert err < 1e-12, err
    u = 1e-7 * np.random.default_rng(3).standard_normal(p.size)
    f = fs.internal_force(p, cells, u, mu, lam)
    lin = k_lin @ u
    assert np.abs(f - lin).max() / np.abs(lin).max() < 1e-5


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_stress_of_a_homogeneous_deformation_is_the_materials_model(kind):
    """F uniform (a general one, J != 1): every Gauss point's Cauchy stress is
    materials.neo_hookean_stress's to round-off (measured 2.8e-15 quad, 1.2e-15 hex, of its largest)."""
    p, cells = MESHES[kind]()
    d = p.shape[1]
    mu, lam = fs.lame(E, NU)
    f = np.array([[1.2, 0.3, -0.1], [-0.15, 0.8, 0.2], [0.05, 0.1, 1.1]])[:d, :d]
    u = p @ (f - np.eye(d)).T
    sig = fs.cauchy_stresses(p, cells, u, mu, lam)
    f3 = np.eye(3)
    f3[:d, :d] = f
    ref = np.array(neo_hookean_stress(*f3.ravel(), mu, lam)[1:])
    err = np.abs(sig - ref).max() / np.abs(ref).max()
    assert err < 1e-14, err


@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_uniaxial_stretch_patch_on_a_distorted_mesh(kind):
    """The face x = 1 pulled to 1.4, x = 0 held in x (rolling), the other faces free: Newton finds
    the homogeneous state (lateral stretch from sigma_yy (= sigma_zz) = 0) at every node to 1e-12
    (measured 3.6e-16 quad, 6.9e-17 hex), converging quadratically (residuals 1.5e6, 3.9e5, 5.8e4,
    2.4e3, 4.9, 2e-5, ... in 2-D; 1.0e6, 1.8e5, 1.1e4, 66, 3.3e-3, 1.6e-10 in 3-D)."""
    p, cells = MESHES[kind]()
    d = p.shape[1]
    mu, lam = fs.lame(E, NU)
    stretch = 1.4
    if d == 2:   # plane strain: sigma_yy = mu/J (l^2 - 1) + lam ln J / J = 0, J = stretch l
        lat = brentq(lambda l: mu * (l * l - 1) + lam * np.log(stretch * l), 0.3, 1.0)
    else:        # uniaxial: J = stretch l^2
        lat = brentq(lambda l: mu * (l * l - 1) + lam * np.log(stretch * l * l), 0.3, 1.0)
    fixed = np.zeros(p.shape, bool)
    ud = np.zeros(p.shape)
    fixed[p[:, 0] < 1e-12, 0] = True
    fixed[p[:, 0] > 1 - 1e-12, 0] = True
    ud[p[:, 0] > 1 - 1e-12, 0] = stretch - 1
    for c in range(1, d):                         # symmetry planes y = 0 (z = 0): no rigid motion
        fixed[p[:, c] < 1e-12, c] = True
    fixed, ud = fixed.ravel(), ud.ravel()
    free = np.flatnonzero(~fixed)
    u = ud.copy()
    history = []
    for _ in range(20):
        k, f = fs.tangent(p, cells, u, mu, lam)
        r = -f[free]
        history.append(np.linalg.norm(r))
        if history[-1] < 1e-12 * np.abs(f).max():
            break
        u[free] += spla.spsolve(k[free][:, free].tocsc(), r)
    exact = p * np.array([stretch - 1] + [lat - 1] * (d - 1))
    err = np.abs(u.reshape(p.shape) - exact).max()
    assert err < 1e-12, (err, history)
    assert len(history) <= 8, history
    # quadratic: r_5 ~ r_4^2 / r_1 (measured ratio 1.26 quad, 0.77 hex; linear convergence's would be ~ 50)
    assert history[4] < 3.0 * history[3] ** 2 / history[0], history
