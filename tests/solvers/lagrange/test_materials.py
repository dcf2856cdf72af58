"""Tests of the constitutive models (parameter layout, Johnson-Cook return mapping).

The Johnson-Cook references are computed independently with full 3x3 tensors and
scipy.optimize.brentq on the consistency condition
    q_tr - 3 G dg - sigma_y(eps_p + dg, dg/dt, T) = 0.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from solvers.lagrange import materials as m
from solvers.lagrange.kernels import element_forces, reference_gradients

JC = dict(density=7850.0, youngs_modulus=200e9, poisson_ratio=0.29, yield_stress=792e6,
          hardening_modulus=510e6, hardening_exponent=0.26, strain_rate_coefficient=0.014,
          reference_strain_rate=1.0, thermal_exponent=1.03, melt_temperature=1793.0,
          room_temperature=293.0, specific_heat=477.0, taylor_quinney=0.9)


def jc_sigma_y(p, eps, rate, T):
    ts = min(max((T - p["room_temperature"]) / (p["melt_temperature"] - p["room_temperature"]), 0), 1)
    r = max(rate / p["reference_strain_rate"], 1.0)
    return ((p["yield_stress"] + p["hardening_modulus"] * eps ** p["hardening_exponent"])
            * (1 + p["strain_rate_coefficient"] * math.log(r)) * (1 - ts ** p["thermal_exponent"]))


def jc_reference_dg(p, q_tr, eps, T, dt):
    G = p["youngs_modulus"] / (2 * (1 + p["poisson_ratio"]))
    def fun(dg):
        return q_tr - 3 * G * dg - jc_sigma_y(p, eps + dg, dg / dt, T)
    if fun(0.0) <= 0:
        return 0.0
    return brentq(fun, 0.0, q_tr / (3 * G), xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)


# ----------------------------------------------------------------------------- parameters

def test_material_params_layout():
    code, par = m.material_params("johnson_cook", dict(JC, model="johnson_cook"))
    assert code == m.JOHNSON_COOK == 2
    assert par.shape == (m.NPAR,) == (16,)
    E, nu = JC["youngs_modulus"], JC["poisson_ratio"]
    assert par[m.P_G] == pytest.approx(E / (2 * (1 + nu)), rel=1e-15)
    assert par[m.P_K] == pytest.approx(E / (3 * (1 - 2 * nu)), rel=1e-15)
    assert par[m.P_LAM] == pytest.approx(E * nu / ((1 + nu) * (1 - 2 * nu)), rel=1e-14)
    for key, idx in [("density", m.P_RHO), ("yield_stress", m.P_A), ("hardening_modulus", m.P_B),
                     ("hardening_exponent", m.P_N), ("strain_rate_coefficient", m.P_C),
                     ("reference_strain_rate", m.P_EPS0), ("thermal_exponent", m.P_M),
                     ("melt_temperature", m.P_TMELT), ("room_temperature", m.P_TROOM),
                     ("specific_heat", m.P_CP), ("taylor_quinney", m.P_CHI)]:
        assert par[idx] == JC[key]
    code, par = m.material_params("linear_elastic", dict(density=1.0, youngs_modulus=3.0,
                                                         poisson_ratio=0.25))
    assert code == m.LINEAR_ELASTIC == 0 and par[m.P_A:].sum() == 0.0
    assert m.material_params("neo_hookean", JC)[0] == m.NEO_HOOKEAN == 1


def test_material_params_errors():
    with pytest.raises(ValueError, match="unknown material model"):
        m.material_params("plastic", JC)
    with pytest.raises(ValueError, match="misses keys"):
        m.material_params("johnson_cook", dict(density=1.0, youngs_modulus=1.0, poisson_ratio=0.3))
    with pytest.raises(ValueError):
        m.material_params("linear_elastic", dict(density=1.0, youngs_modulus=1.0, poisson_ratio=0.5))


# ----------------------------------------------------------------------------- JC return

@pytest.mark.parametrize("q_tr,eps,T,dt", [
    (1.2e9, 0.0, 293.0, 1e-7),      # first yield, n < 1 (infinite initial slope)
    (0.8e9, 0.0, 293.0, 1e-8),      # barely plastic
    (1.5e9, 0.05, 400.0, 1e-6),
    (1.4e9, 0.3, 900.0, 1e-9),      # strong rate term
    (1.3e9, 0.2, 293.0, 1e3),       # rate below eps0 (no rate term)
])
def test_jc_return_against_brentq(q_tr, eps, T, dt):
    _, par = m.material_params("johnson_cook", JC)
    dg, sy = m.jc_return_increment(q_tr, eps, T, dt, par)
    ref = jc_reference_dg(JC, q_tr, eps, T, dt)
    assert ref > 0
    assert dg == pytest.approx(ref, rel=1e-10)
    assert sy == pytest.approx(jc_sigma_y(JC, eps + ref, ref / dt, T), rel=1e-10)
    # consistency: q_tr - 3 G dg == sigma_y
    assert q_tr - 3 * par[m.P_G] * dg == pytest.approx(sy, rel=1e-10)


def test_jc_elastic_and_melt():
    _, par = m.material_params("johnson_cook", JC)
    dg, sy = m.jc_return_increment(700e6, 0.0, 293.0, 1e-7, par)
    assert dg == 0.0 and sy == pytest.approx(792e6, rel=1e-15)
    dg, sy = m.jc_return_increment(700e6, 0.1, 2000.0, 1e-7, par)   # above melt
    assert sy == 0.0 and dg == pytest.approx(700e6 / (3 * par[m.P_G]), rel=1e-15)


# ----------------------------------------------------------------------------- JC in the kernel

def _jc_reference_history(p, rate, dt, nsteps, h, T0, dim):
    """Uniaxial strain D = diag(rate, 0, 0), explicit JC with 3x3 tensors."""
    E, nu = p["youngs_modulus"], p["poisson_ratio"]
    G = E / (2 * (1 + nu))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    D = np.diag([rate, 0.0, 0.0])
    S = np.zeros((3, 3))
    eps, T = 0.0, T0
    mass = p["density"] * h ** dim
    length = h
    out = []
    for _ in range(nsteps):
        length *= (1 + 0.5 * rate * dt) / (1 - 0.5 * rate * dt)
        rho = mass / (length * h ** (dim - 1))
        St = S + dt * (lam * np.trace(D) * np.eye(3) + 2 * G * D)
        pr = np.trace(St) / 3
        dev = St - pr * np.eye(3)
        q_tr = math.sqrt(1.5 * np.sum(dev * dev))
        dg = jc_reference_dg(p, q_tr, eps, T, dt)
        if dg > 0:
            sy = jc_sigma_y(p, eps + dg, dg / dt, T)
            S = pr * np.eye(3) + dev * sy / q_tr
            dT = p["taylor_quinney"] * sy * dg / (rho * p["specific_heat"])
        else:
            S, sy, dT = St, 0.0, 0.0
        eps += dg
        T += dT
        out.append((S.copy(), eps, T, dg, sy, rho, dT))
    return out


@pytest.mark.parametrize("dim", [2, 3])
def test_jc_uniaxial_strain_history(dim):
    p = dict(JC, melt_temperature=700.0)       # strong thermal softening
    code, par = m.material_params("johnson_cook", p)
    h = 0.01
    xi = (np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], float) if dim == 3
          else np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float))
    X = 0.5 * h * (xi + 1)
    conn = np.arange(len(xi), dtype=np.int64)[None, :]
    grad0, vol0 = reference_gradients(X, conn)
    mass = p["density"] * vol0
    rate, dt, nsteps = 2e4, 5e-7, 12                  # 1 % strain per step
    sig, ep = np.zeros((1, 6)), np.zeros(1)
    T0 = 300.0
    temp, e_int, q = np.full(1, T0), np.zeros(1), np.zeros(1)
    ref = _jc_reference_history(p, rate, dt, nsteps, h, T0, dim)
    x = X.copy()
    fac = (1 + 0.5 * rate * dt) / (1 - 0.5 * rate * dt)
    nplastic = 0
    for n in range(nsteps):
        x_old = x.copy()
        x[:, 0] *= fac                                 # D = rate exactly at mid-step
        v = (x - x_old) / dt
        T_before = temp[0]
        f = np.zeros_like(x)
        dtm, bad = element_forces(x, v, dt, conn, np.zeros(1, np.int64), np.array([code]),
                                  par[None, :].copy(), grad0, vol0, mass, sig, ep, temp, e_int,
                                  q, 0.0, 0.0, 0.0, f)
        assert bad == -1
        S, eps, T, dg, sy, rho, dT = ref[n]
        assert np.abs(sig[0] - [S[0, 0], S[1, 1], S[2, 2], S[0, 1], S[1, 2], S[2, 0]]).max() \
            <= 1e-8 * np.abs(S).max()
        assert ep[0] == pytest.approx(eps, rel=1e-8)
        assert temp[0] == pytest.approx(T, rel=1e-8)
        if dg > 0:
            nplastic += 1
            # temperature rise = Taylor-Quinney fraction of the plastic work
            assert (temp[0] - T_before) * rho * p["specific_heat"] == pytest.approx(
                p["taylor_quinney"] * sy * dg, rel=1e-8)
    assert nplastic >= nsteps - 1
    assert temp[0] > T0 + 10.0                      # heating (and softening) is significant


def test_jc_return_random_states():
    """200 random states (first yield, high rate, near melt): Newton result == brentq root."""
    _, par = m.material_params("johnson_cook", JC)
    G = par[m.P_G]
    rng = np.random.default_rng(42)
    for _ in range(200):
        eps = 0.0 if rng.random() < 0.2 else 10 ** rng.uniform(-6, 0)
        T = rng.uniform(293.0, 1780.0)
        dt = 10 ** rng.uniform(-10, -4)
        sy0 = jc_sigma_y(JC, eps, 0.0, T)
        q_tr = sy0 * (1 + 10 ** rng.uniform(-6, 0.5))
        dg, sy = m.jc_return_increment(q_tr, eps, T, dt, par)
        ref = jc_reference_dg(JC, q_tr, eps, T, dt)
        assert abs(dg - ref) <= 1e-9 * ref + 1e-15
        assert abs(q_tr - 3 * G * dg - sy) <= 1e-10 * q_tr
        assert abs(sy - jc_sigma_y(JC, eps + dg, dg / dt, T)) <= 1e-10 * q_tr
