"""Tests of the Lagrangian element kernel against analytic references.

References are computed independently in numpy: exact trilinear/bilinear volumes
by 2x2(x2) Gauss quadrature of det J (exact for these polynomials), their
derivatives dV/dx_I by complex-step differentiation, and closed-form stress
updates for affine velocity fields.
"""
import numpy as np
import pytest

from solvers.elements import HEX_HG, QUAD_HG
from solvers.lagrange.kernels import element_forces, reference_gradients
from solvers.lagrange.materials import material_params
# the independent geometry references (the element geometry itself: tests/solvers/test_elements.py)
from tests.solvers.test_elements import (HEX_XI, QUAD_XI, complex_step_b, distorted_element,
                                         gauss_volume)

RHO, E, NU = 7800.0, 200e9, 0.3
G = E / (2 * (1 + NU))
K = E / (3 * (1 - 2 * NU))
LAM = K - 2 * G / 3


# ----------------------------------------------------------------------------- helpers

def box_mesh(n, dim, amp=0.0, seed=0, h=1.0):
    """Structured n^dim mesh of side n*h, nodes perturbed by +-amp*h."""
    ax = np.arange(n + 1) * h
    grids = np.meshgrid(*([ax] * dim), indexing="ij")
    pts = np.stack(grids, -1).reshape(-1, dim).astype(float)
    idx = np.arange((n + 1) ** dim).reshape((n + 1,) * dim)
    c = np.meshgrid(*([np.arange(n)] * dim), indexing="ij")
    c = [a.ravel() for a in c]
    if dim == 3:
        i, j, k = c
        conn = np.stack([idx[i, j, k], idx[i + 1, j, k], idx[i + 1, j + 1, k], idx[i, j + 1, k],
                         idx[i, j, k + 1], idx[i + 1, j, k + 1], idx[i + 1, j + 1, k + 1],
                         idx[i, j + 1, k + 1]], 1)
    else:
        i, j = c
        conn = np.stack([idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]], 1)
    rng = np.random.default_rng(seed)
    pts = pts + rng.uniform(-amp, amp, pts.shape) * h
    interior = np.all((pts > 0.5 * h) & (pts < (n - 0.5) * h), axis=1)
    return pts, conn.astype(np.int64), interior


def run(x, v, dt, conn, model="linear_elastic", X0=None, sig=None, temp=None, hg=0.1,
        ql=0.0, qq=0.0, rho=RHO, props=None):
    """One kernel call on a single-material mesh; returns the state dict."""
    p = dict(density=rho, youngs_modulus=E, poisson_ratio=NU)
    if props:
        p.update(props)
    code, par = material_params(model, p)
    ne = conn.shape[0]
    X0 = x if X0 is None else X0
    grad0, vol0 = reference_gradients(X0, conn)
    st = dict(
        sig=np.zeros((ne, 6)) if sig is None else np.array(sig, dtype=float).copy(),
        eps_p=np.zeros(ne),
        temp=np.full(ne, 293.0) if temp is None else temp.copy(),
        e_int=np.zeros(ne), q=np.zeros(ne), f=np.zeros_like(x),
    )
    mass = rho * vol0
    dtm, bad = element_forces(x, v, float(dt), conn, np.zeros(ne, np.int64),
                              np.array([code], np.int64), par[None, :].copy(), grad0, vol0,
                              mass, st["sig"], st["eps_p"], st["temp"], st["e_int"], st["q"],
                              float(hg), float(ql), float(qq), st["f"])
    st.update(dt=dtm, bad=bad, mass=mass, vol0=vol0)
    return st


def voigt(s):
    return np.array([[s[0], s[3], s[5]], [s[3], s[1], s[4]], [s[5], s[4], s[2]]])


def to_voigt(m):
    return np.array([m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[1, 2], m[2, 0]])


def expand3(m2):
    """Embed a 2x2 (plane) tensor in 3x3; 3x3 input is returned as a copy."""
    m = np.zeros((3, 3))
    k = m2.shape[0]
    m[:k, :k] = m2
    return m


def single(dim):
    return np.arange(2 ** dim, dtype=np.int64)[None, :]


# ----------------------------------------------------------------------------- geometry

def test_reference_gradients_mesh():
    X, conn, _ = box_mesh(2, 3, amp=0.15, seed=3)
    grad, vol0 = reference_gradients(X, conn)
    for e in range(conn.shape[0]):
        xe = X[conn[e]]
        assert vol0[e] == pytest.approx(gauss_volume(xe), rel=1e-12)
        assert np.abs(xe.T @ grad[e] - np.eye(3)).max() <= 1e-12


# ----------------------------------------------------------------------------- patch test

def _affine_case(dim, seed):
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(dim, dim)) * 50.0          # 1/s, general (stretch + spin)
    a = rng.normal(size=dim)
    s0 = rng.normal(size=6) * 1e8
    if dim == 2:
        s0[4] = s0[5] = 0.0
    return L, a, s0


@pytest.mark.parametrize("dim", [2, 3])
def test_patch_uniform_strain(dim):
    n = 3
    X, conn, interior = box_mesh(n, dim, amp=0.2, seed=11, h=0.01)
    L, a, s0 = _affine_case(dim, 7)
    dt = 2e-6
    x = X + (X @ (np.eye(dim) * 0.01).T)             # some current configuration
    v = x @ L.T + a
    sig0 = np.tile(s0, (conn.shape[0], 1))
    st = run(x, v, dt, conn, X0=X, sig=sig0, hg=0.1, ql=0.0, qq=0.0)
    assert st["bad"] == -1
    # analytic: L_mid = (I - dt/2 L)^-1 L, explicit Jaumann + isotropic elasticity
    Lm = np.linalg.solve(np.eye(dim) - 0.5 * dt * L, L)
    D = expand3(0.5 * (Lm + Lm.T))
    W = expand3(0.5 * (Lm - Lm.T))
    S0 = voigt(s0)
    S = S0 + dt * (W @ S0 - S0 @ W) + dt * (LAM * np.trace(D) * np.eye(3) + 2 * G * D)
    ref = to_voigt(S)
    scale = np.abs(ref).max()
    assert np.abs(st["sig"] - ref).max() <= 1e-10 * scale
    # internal energy: 1/2 (s0 + s) : D  V_mid dt, V_mid = det(I - dt/2 L) V^n (affine map)
    detm = np.linalg.det(np.eye(dim) - 0.5 * dt * L)
    vn = np.array([gauss_volume(x[c]) for c in conn])
    e_ref = 0.5 * np.sum((S0 + S) * D) * detm * vn * dt
    assert np.abs(st["e_int"] - e_ref).max() <= 1e-10 * np.abs(e_ref).max()
    # zero net force on interior nodes
    fscale = np.abs(st["f"]).max()
    assert fscale > 0
    assert interior.sum() > 0
    assert np.abs(st["f"][interior]).max() <= 1e-10 * fscale


# ----------------------------------------------------------------------------- rigid motion

def _rotation(dim, angle):
    c, s = np.cos(angle), np.sin(angle)
    if dim == 2:
        return np.array([[c, -s], [s, c]])
    ax = np.array([1.0, 2.0, 2.0]) / 3.0
    Kx = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    return np.eye(3) + s * Kx + (1 - c) * Kx @ Kx


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_rotation_zero_stress_and_hourglass(dim):
    X, conn, _ = box_mesh(2, dim, amp=0.2, seed=5)
    omega, dt = 1000.0, 1e-5
    R = _rotation(dim, omega * dt)
    center = np.full(dim, 0.7)
    x_old = X + 0.3
    x = (x_old - center) @ R.T + center
    v = (x - x_old) / dt
    st = run(x, v, dt, conn, X0=X, hg=0.2, ql=0.06, qq=1.5)
    assert st["bad"] == -1
    assert np.abs(st["sig"]).max() <= 1e-12 * E * omega * dt
    # with zero stress the only forces are hourglass + bulk viscosity: must vanish
    rho_c = RHO * np.sqrt((K + 4 * G / 3) / RHO)
    fscale = rho_c * np.abs(v).max()           # rho c V^(2/3) |v| with V = 1
    assert np.abs(st["f"]).max() <= 1e-12 * fscale
    assert np.abs(st["q"]).max() <= 1e-12 * rho_c * np.abs(v).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_translation(dim):
    X, conn, _ = box_mesh(2, dim, amp=0.2, seed=6)
    rng = np.random.default_rng(1)
    s0 = rng.normal(size=6) * 1e8
    if dim == 2:
        s0[4:] = 0.0
    sig0 = np.tile(s0, (conn.shape[0], 1))
    v = np.tile(rng.normal(size=dim) * 100.0, (X.shape[0], 1))
    st = run(X, v, 1e-6, conn, sig=sig0, hg=0.3)
    assert np.abs(st["sig"] - sig0).max() <= 1e-12 * np.abs(s0).max()
    # forces equal the pure stress divergence (no hourglass, no viscosity)
    st0 = run(X, np.zeros_like(v), 0.0, conn, sig=sig0, hg=0.0)
    assert np.abs(st["f"] - st0["f"]).max() <= 1e-12 * np.abs(st0["f"]).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_rotation_objectivity_second_order(dim):
    """Prestressed element under rigid rotation: sigma^n = R sigma R^T + O((omega dt)^2)."""
    X = distorted_element(dim, 4)
    conn = single(dim)
    s0 = np.array([3e8, -1e8, 2e8, 1.5e8, 0.5e8, -0.7e8])
    if dim == 2:
        s0[4:] = 0.0
    errs = []
    omega = 2000.0
    for dt in (1e-5, 5e-6):
        R = _rotation(dim, omega * dt)
        x = X @ R.T
        v = (x - X) / dt
        st = run(x, v, dt, conn, sig=s0[None, :])
        R3 = expand3(R)
        R3[2, 2] = R[2, 2] if dim == 3 else 1.0
        ref = to_voigt(R3 @ voigt(s0) @ R3.T)
        err = np.abs(st["sig"][0] - ref).max() / np.abs(s0).max()
        assert err <= 2 * (omega * dt) ** 2
        errs.append(err)
        # invariants preserved to second order as well
        assert abs(np.trace(voigt(st["sig"][0])) - np.trace(voigt(s0))) <= 1e-9 * np.abs(s0).max()
    ratio = errs[0] / errs[1]
    assert 3.5 < ratio < 4.5


# ----------------------------------------------------------------------------- hourglass

def _gamma_ref(xe):
    """Independent FB gamma vectors from the complex-step B."""
    b = complex_step_b(xe)
    vol = gauss_volume(xe)
    Gam = HEX_HG if xe.shape[1] == 3 else QUAD_HG[None, :]
    return Gam - (Gam @ xe) @ (b / vol).T, vol


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_hourglass_force(dim, seed):
    xe = distorted_element(dim, seed, amp=0.15)
    conn = single(dim)
    hg = 0.1
    gam, vol = _gamma_ref(xe)
    c = np.sqrt((K + 4 * G / 3) / RHO)
    ah = hg * RHO * c * (vol ** (2 / 3) if dim == 3 else np.sqrt(vol)) / 4
    Gam = HEX_HG if dim == 3 else QUAD_HG[None, :]
    rng = np.random.default_rng(seed)
    for mode in range(Gam.shape[0]):
        u = rng.normal(size=dim)
        v = np.outer(Gam[mode], u)                  # hourglass velocity pattern
        st = run(xe, v, 0.0, conn, hg=hg)
        f = st["f"]
        ref = -ah * gam.T @ (gam @ v)
        assert np.abs(f - ref).max() <= 1e-10 * np.abs(ref).max()
        assert np.sum(f * v) < 0                    # dissipative, opposes the mode
    # zero response to any linear velocity field
    v = xe @ rng.normal(size=(dim, dim)).T * 10 + rng.normal(size=dim)
    st = run(xe, v, 0.0, conn, hg=hg)
    assert np.abs(st["f"]).max() <= 1e-12 * ah * np.abs(v).max()


def test_hourglass_cube_opposes_mode():
    xe = 0.5 * (HEX_XI + 1)
    for mode in range(4):
        v = np.outer(HEX_HG[mode], [1.0, -2.0, 0.5])
        f = run(xe, v, 0.0, single(3), hg=0.1)["f"]
        # cube: gamma = Gamma, f_I = -a_h * 8 * v_I
        ah = 0.1 * RHO * np.sqrt((K + 4 * G / 3) / RHO) / 4
        assert np.abs(f + 8 * ah * v).max() <= 1e-12 * np.abs(8 * ah * v).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_momentum_conservation(dim):
    X, conn, _ = box_mesh(2, dim, amp=0.2, seed=2)
    rng = np.random.default_rng(3)
    x = X + rng.uniform(-0.05, 0.05, X.shape)
    v = rng.normal(size=X.shape) * 50.0 - 30.0 * (x - 1.0)   # random + compression
    s = rng.normal(size=(conn.shape[0], 6)) * 1e8
    if dim == 2:
        s[:, 4:] = 0.0
    st = run(x, v, 1e-6, conn, X0=X, sig=s, hg=0.1, ql=0.06, qq=1.5)
    assert st["bad"] == -1
    assert st["q"].max() > 0
    f = st["f"]
    scale = np.abs(f).sum() * np.abs(x).max()
    assert np.abs(f.sum(0)).max() <= 1e-12 * np.abs(f).sum()
    if dim == 3:
        mom = np.cross(x, f).sum(0)
    else:
        mom = np.array([np.sum(x[:, 0] * f[:, 1] - x[:, 1] * f[:, 0])])
    assert np.abs(mom).max() <= 1e-12 * scale


# ----------------------------------------------------------------------------- elasticity

@pytest.mark.parametrize("dim", [2, 3])
def test_uniaxial_strain_elastic(dim):
    h = 0.02
    X = 0.5 * h * ((HEX_XI if dim == 3 else QUAD_XI) + 1)
    rate, dt = 300.0, 1e-6
    # velocity linear in x^{n-1/2} with gradient diag(rate, 0, 0)
    v = np.zeros_like(X)
    v[:, 0] = rate * X[:, 0] / (1 + 0.5 * rate * dt)
    st = run(X, v, dt, single(dim))
    eps = rate * dt
    ref = np.array([(LAM + 2 * G) * eps, LAM * eps, LAM * eps, 0, 0, 0])
    assert np.abs(st["sig"][0] - ref).max() <= 1e-10 * ref[0]
    vmid = h ** dim * (1 - 0.5 * rate * dt / (1 + 0.5 * rate * dt))
    assert st["e_int"][0] == pytest.approx(0.5 * ref[0] * eps * vmid, rel=1e-10)
    # forces: -sigma b on the x-faces, total zero
    assert st["f"][:, 0].sum() == pytest.approx(0.0, abs=1e-12 * np.abs(st["f"]).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_first_call_no_stress_update(dim):
    X = distorted_element(dim, 2)
    s0 = np.array([1e8, 2e8, 3e8, 4e7, 5e7, 6e7])
    if dim == 2:
        s0[4:] = 0
    v = np.random.default_rng(0).normal(size=X.shape)
    st = run(X, v, 0.0, single(dim), sig=s0[None], hg=0.0)
    assert np.array_equal(st["sig"][0], s0)
    assert st["e_int"][0] == 0.0
    b = complex_step_b(X)
    ref = -(voigt(s0)[:dim, :dim] @ b.T).T
    assert np.abs(st["f"] - ref).max() <= 1e-12 * np.abs(ref).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_neo_hookean_uniaxial_stretch(dim):
    X = 0.01 * distorted_element(dim, 8, amp=0.15)
    for s in (1.3, 0.7):
        F = np.eye(dim)
        F[0, 0] = s
        x = X @ F.T
        st = run(x, np.zeros_like(x), 1e-7, single(dim), model="neo_hookean", X0=X)
        ref = np.array([G / s * (s * s - 1) + LAM * np.log(s) / s,
                        LAM * np.log(s) / s, LAM * np.log(s) / s, 0, 0, 0])
        assert np.abs(st["sig"][0] - ref).max() <= 1e-10 * np.abs(ref).max()


def test_neo_hookean_general_deformation():
    X = 0.01 * distorted_element(3, 9, amp=0.15)
    F = np.array([[1.2, 0.3, -0.1], [0.05, 0.9, 0.2], [0.1, -0.2, 1.1]])
    x = X @ F.T + 0.003
    st = run(x, np.zeros_like(x), 1e-7, single(3), model="neo_hookean", X0=X)
    J = np.linalg.det(F)
    ref = G / J * (F @ F.T - np.eye(3)) + LAM * np.log(J) / J * np.eye(3)
    assert np.abs(st["sig"][0] - to_voigt(ref)).max() <= 1e-10 * np.abs(ref).max()


# ----------------------------------------------------------------------------- time step

def cube_step_length(h, lam, mu):
    """The hexahedron's effective length for a cube of side h: 2 c / omega_max with the free cube's
    highest frequency omega^2 = (3 lambda + 2 mu) / (rho (h/2)^2) (its uniform dilatation), so
    h sqrt((lambda + 2 mu) / (3 lambda + 2 mu)) (LS-DYNA's V / A_max alone is h)."""
    return h * np.sqrt((lam + 2 * mu) / (3 * lam + 2 * mu))


def test_stable_dt_cube():
    h = 0.004
    X, conn, _ = box_mesh(2, 3, h=h)
    st = run(X, np.zeros_like(X), 0.0, conn, ql=0.06, qq=1.5)
    c = np.sqrt((K + 4 * G / 3) / RHO)
    assert st["dt"] == pytest.approx(cube_step_length(h, LAM, G) / c, rel=1e-13)
    assert np.all(st["q"] == 0.0)


def test_stable_dt_square():
    h = 0.004
    X, conn, _ = box_mesh(2, 2, h=h)
    st = run(X, np.zeros_like(X), 0.0, conn)
    c = np.sqrt((K + 4 * G / 3) / RHO)
    assert st["dt"] == pytest.approx(h / np.sqrt(2) / c, rel=1e-13)


@pytest.mark.parametrize("dim", [2, 3])
def test_bulk_viscosity_and_dt_under_compression(dim):
    h = 0.01
    X = 0.5 * h * ((HEX_XI if dim == 3 else QUAD_XI) + 1)
    rate, dt = -2000.0, 1e-7
    v = rate * X / (1 + 0.5 * rate * dt)        # grad v = rate I at mid-step
    ql, qq = 0.06, 1.5
    st = run(X, v, dt, single(dim), ql=ql, qq=qq)
    divv = dim * rate
    c = np.sqrt((K + 4 * G / 3) / RHO)
    lc = h if dim == 3 else h / np.sqrt(2)
    q = RHO * lc * (qq * lc * divv ** 2 - ql * c * divv)
    assert st["q"][0] == pytest.approx(q, rel=1e-10)
    Q = ql * c + qq * lc * abs(divv)
    lce = cube_step_length(lc, LAM, G) if dim == 3 else lc
    assert st["dt"] == pytest.approx(lce / (Q + np.sqrt(Q * Q + c * c)), rel=1e-10)
    # q acts as a pressure: f_I = -(sigma - q I) b_I
    b = complex_step_b(X)
    S = voigt(st["sig"][0])[:dim, :dim] - q * np.eye(dim)
    assert np.abs(st["f"] + b @ S).max() <= 1e-10 * np.abs(b @ S).max()
    # expansion: no viscosity
    st = run(X, -v, dt, single(dim), ql=ql, qq=qq)
    assert st["q"][0] == 0.0


# ----------------------------------------------------------------------------- failures

@pytest.mark.parametrize("dim", [2, 3])
def test_inverted_element_flagged(dim):
    X, conn, _ = box_mesh(2, dim)
    x = X.copy()
    e = 2
    node = conn[e, 0]
    # push node 0 of element 2 through the opposite corner of element 2
    x[node] = X[conn[e, 6 if dim == 3 else 2]] + 0.5
    st = run(x, np.zeros_like(x), 0.0, conn, X0=X)
    vols = np.array([gauss_volume(x[c]) for c in conn])
    assert (vols <= 0).any()
    assert st["bad"] == int(np.argmax(vols <= 0))


def test_nonfinite_stress_flagged():
    X, conn, _ = box_mesh(2, 3)
    sig = np.zeros((conn.shape[0], 6))
    sig[3, 2] = np.nan
    st = run(X, np.zeros_like(X), 1e-6, conn, sig=sig)
    assert st["bad"] == 3


def test_material_indexing():
    """Two materials on one mesh: every element uses the row mat_code/mat_par[mat_id[e]]."""
    X, conn, _ = box_mesh(2, 3, h=0.01)
    ne = conn.shape[0]
    c0, p0 = material_params("linear_elastic", dict(density=RHO, youngs_modulus=E, poisson_ratio=NU))
    c1, p1 = material_params("linear_elastic", dict(density=2700.0, youngs_modulus=70e9,
                                                    poisson_ratio=0.33))
    mat_id = np.array([0, 1] * (ne // 2), dtype=np.int64)
    grad0, vol0 = reference_gradients(X, conn)
    mass = np.where(mat_id == 0, RHO, 2700.0) * vol0
    rate, dt = 100.0, 1e-6
    v = np.zeros_like(X)
    v[:, 0] = rate * X[:, 0] / (1 + 0.5 * rate * dt)
    sig = np.zeros((ne, 6))
    z = np.zeros(ne)
    f = np.zeros_like(X)
    dtm, bad = element_forces(X, v, dt, conn, mat_id, np.array([c0, c1], np.int64),
                              np.stack([p0, p1]), grad0, vol0, mass, sig, z.copy(),
                              np.full(ne, 293.0), z.copy(), z.copy(), 0.1, 0.0, 0.0, f)
    assert bad == -1
    for e in range(ne):
        p = (p0, p1)[mat_id[e]]
        assert sig[e, 0] == pytest.approx((p[5] + 2 * p[3]) * rate * dt, rel=1e-10)
        assert sig[e, 1] == pytest.approx(p[5] * rate * dt, rel=1e-10)
    c_al = np.sqrt((p1[4] + 4 * p1[3] / 3) / 2700.0)
    c_st = np.sqrt((K + 4 * G / 3) / RHO)
    dt_al = cube_step_length(0.01, p1[5], p1[3]) / c_al
    dt_st = cube_step_length(0.01, LAM, G) / c_st
    assert dtm == pytest.approx(min(dt_al, dt_st), rel=1e-12)
