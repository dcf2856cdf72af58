"""Tests of the semi-analytic Sedov-Taylor solution (solvers/ale/exact/sedov.py).

References and tolerances
-------------------------
* Independent reference: the similarity ODEs (mass, momentum, entropy for
  rho = rho0 G(lam), u = D F(lam), p = rho0 D^2 P(lam), lam = r/r2) integrated inward from
  the strong-shock state with scipy's DOP853 at rtol 1e-12, together with the energy
  integral alpha = sigma_j (2/(j+2))^2 Int (G F^2/2 + P/(gamma-1)) lam^(j-1) dlam.  It shares
  no code or formula with the closed-form parametric solution: alpha to 1e-9 relative,
  the similarity functions to 1e-9 absolute (they are O(1)).
* Kamm & Timmes (2007), standard cases for gamma = 1.4, rho0 = 1, t = 1: spherical
  E0 = 0.851072 puts the shock at r = 1 (asserted to 5e-7 on alpha, half a unit of the
  last published digit); cylindrical E0 = 0.311357 at r = 0.75 and planar E0 = 0.0673185
  (half-space energy) at r = 0.5.  Our alpha reproduces the cylindrical and planar numbers
  only to 3.4e-5 and 3.6e-4 relative (shock radius 8.5e-6 and 1.2e-4); the ODE
  integration agrees with our alpha to 1e-12 in all three geometries, so those two
  published E0 values carry fewer correct digits than printed.  Asserted at 1.5e-5 and
  1.5e-4 on the shock radius.
* Strong-shock Rankine-Hugoniot state behind the shock: rho2 = rho0 (g+1)/(g-1),
  u2 = 2 D/(g+1), p2 = 2 rho0 D^2/(g+1), D = 2 r2/((j+2) t): 1e-12 relative.
* Total energy: Gauss-Legendre quadrature in r of (rho u^2/2 + p/(g-1)) sigma_j r^(j-1)
  of the sampled profiles recovers E0 to 1e-11 (observed <= 1.1e-13).
* Euler equations: centred finite differences (h = 1e-5 r2 in r and 1e-5 t in t) of the
  sampled profiles satisfy mass, momentum and entropy conservation to 1e-7 of the
  largest term for 0.3 <= r/r2 <= 0.97 (observed <= 1.5e-8: truncation ~ (h/L)^2 plus
  round-off ~ 1e-14/h; a wrong exponent gives residuals of order 1e-2).
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from solvers.ale.exact import SedovSolution

SIGMA = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


# ----------------------------------------------------------------------------- independent ODE reference

def ode_reference(gamma, j, lam_end=None):
    """Integrate the similarity ODEs from lam = 1 to lam_end in s = ln lam; returns (alpha, dense solution).

    The energy integrand behaves like lam^(j-1) at the centre, so stopping at lam_end drops
    O(lam_end^j) of alpha: 1e-12 (j = 1), 1e-9 (j = 2), 1e-6 (j = 3) keep that below 1e-12
    (deeper, the ODE's centre singularity stalls the integrator for j = 3)."""
    if lam_end is None:
        lam_end = {1: 1e-12, 2: 1e-9, 3: 1e-6}[j]
    g = gamma
    d = 2.0 / (j + 2.0)
    k = (d - 1.0) / d

    def rhs(s, y):
        lam = math.exp(s)
        F, G, P, _ = y
        w = F - lam
        # mass: w G' + G F' = -(j-1) G F/lam; momentum: w F' + P'/G = -k F;
        # entropy (P G^-g conserved along particle paths): w (P' - g P G'/G) = -2 k P
        A = np.array([[G, w, 0.0], [w, 0.0, 1.0 / G], [0.0, -g * P * w / G, w]])
        b = np.array([-(j - 1) * G * F / lam, -k * F, -2.0 * k * P])
        dF, dG, dP = np.linalg.solve(A, b)
        dI = -(0.5 * G * F * F + P / (g - 1.0)) * lam ** (j - 1)
        return [lam * dF, lam * dG, lam * dP, lam * dI]

    y0 = [2.0 / (g + 1.0), (g + 1.0) / (g - 1.0), 2.0 / (g + 1.0), 0.0]
    sol = solve_ivp(rhs, [0.0, math.log(lam_end)], y0, method="DOP853", rtol=1e-12, atol=1e-14,
                    dense_output=True)
    assert sol.status == 0
    return SIGMA[j] * d * d * sol.y[3, -1], sol


@pytest.mark.parametrize("j", [1, 2, 3])
@pytest.mark.parametrize("gamma", [1.4, 5.0 / 3.0, 2.0, 3.0])
def test_against_independent_ode_integration(gamma, j):
    s = SedovSolution(1.0, 1.0, gamma, j)
    alpha, sol = ode_reference(gamma, j)
    assert s.alpha == pytest.approx(alpha, rel=1e-9)
    lam = np.array([1.0, 0.97, 0.9, 0.7, 0.5, 0.3, 0.1, 0.02])
    F, G, P = sol.sol(np.log(lam))[:3]
    f, g, h = s.similarity(lam)
    np.testing.assert_allclose(2.0 / (gamma + 1.0) * f, F, rtol=0, atol=1e-9)
    np.testing.assert_allclose((gamma + 1.0) / (gamma - 1.0) * g, G, rtol=0, atol=1e-9)
    np.testing.assert_allclose(2.0 / (gamma + 1.0) * h, P, rtol=0, atol=1e-9)


def test_vacuum_family_against_ode():
    """j = 3, gamma = 10: evacuated centre; the ODE is integrated down to just outside the hole."""
    s = SedovSolution(1.0, 1.0, 10.0, 3)
    assert s.family == "vacuum" and 0.2 < s.hole_radius_fraction < 0.25
    lv = s.hole_radius_fraction
    _, sol = ode_reference(10.0, 3, lam_end=1.05 * lv)
    lam = np.linspace(1.06 * lv, 1.0, 9)
    F, G, P = sol.sol(np.log(lam))[:3]
    f, g, h = s.similarity(lam)
    np.testing.assert_allclose(2.0 / 11.0 * f, F, atol=1e-9)
    np.testing.assert_allclose(11.0 / 9.0 * g, G, atol=1e-9)
    np.testing.assert_allclose(2.0 / 11.0 * h, P, atol=1e-9)
    rho, u, p = s.profiles(np.array([0.0, 0.5 * lv, 0.999 * lv]) * s.shock_radius(1.0), 1.0)
    assert np.all(rho == 0.0) and np.all(u == 0.0) and np.all(p == 0.0)
    # inner edge moves with the flow: u(r_v) = dr_v/dt = 2 r_v/(5 t)  ->  f(lam_v) = (g+1) lam_v / 2
    f_v, g_v, h_v = s.similarity(np.array([lv]))
    assert f_v[0] == pytest.approx(5.5 * lv, rel=1e-9) and g_v[0] == 0.0 and h_v[0] == 0.0


# ----------------------------------------------------------------------------- published values

def test_kamm_timmes_standard_cases():
    sph = SedovSolution(0.851072, 1.0, 1.4, 3)
    assert sph.alpha == pytest.approx(0.851072, abs=5e-7)
    assert sph.shock_radius(1.0) == pytest.approx(1.0, rel=2e-7)
    cyl = SedovSolution(0.311357, 1.0, 1.4, "cylindrical")
    assert cyl.shock_radius(1.0) == pytest.approx(0.75, rel=1.5e-5)
    pla = SedovSolution(2 * 0.0673185, 1.0, 1.4, "planar")         # K&T quote the half-space energy
    assert pla.shock_radius(1.0) == pytest.approx(0.5, rel=1.5e-4)
    # rough classical values (brief / Sedov 1959)
    assert SedovSolution(1, 1, 1.4, 2).alpha == pytest.approx(0.984, abs=5e-4)
    assert SedovSolution(1, 1, 1.4, 1).alpha == pytest.approx(1.077, abs=5e-4)


def test_post_shock_state_is_strong_shock_rankine_hugoniot():
    for j in (1, 2, 3):
        for gamma in (1.4, 5.0 / 3.0, 2.0, 7.0, 10.0):
            E0, rho0, t = 2.5e6, 1.2, 3e-3
            s = SedovSolution(E0, rho0, gamma, j)
            r2 = s.shock_radius(t)
            assert r2 == pytest.approx((E0 * t * t / (s.alpha * rho0)) ** (1.0 / (j + 2)), rel=1e-15)
            D = 2.0 * r2 / ((j + 2.0) * t)
            rho, u, p = s.profiles(np.array([r2, r2 * (1 + 1e-12)]), t)
            assert rho[0] == pytest.approx(rho0 * (gamma + 1) / (gamma - 1), rel=1e-12)
            assert u[0] == pytest.approx(2 * D / (gamma + 1), rel=1e-12)
            assert p[0] == pytest.approx(2 * rho0 * D * D / (gamma + 1), rel=1e-12)
            assert (rho[1], u[1], p[1]) == (rho0, 0.0, 0.0)                 # ambient just outside
    s = SedovSolution(0.851072, 1.0, 1.4, 3)                                # standard spherical case at t = 1
    rho2, u2, p2 = s.post_shock(1.0)
    assert rho2 == pytest.approx(6.0, rel=1e-14)
    assert u2 == pytest.approx(1.0 / 3.0, rel=1e-6) and p2 == pytest.approx(2.0 / 15.0, rel=1e-6)


# ----------------------------------------------------------------------------- conservation

def energy_by_quadrature(s, t, panels=120, order=20):
    """sigma_j Int (rho u^2/2 + p/(g-1)) r^(j-1) dr of the sampled profiles (graded Gauss-Legendre)."""
    r2 = s.shock_radius(t)
    lv = s.hole_radius_fraction
    edges = r2 * (lv + (1.0 - lv) * np.linspace(0.0, 1.0, panels + 1) ** 3)
    x, w = np.polynomial.legendre.leggauss(order)
    r = (0.5 * (edges[:-1] + edges[1:])[:, None] + 0.5 * np.diff(edges)[:, None] * x).ravel()
    wr = (0.5 * np.diff(edges)[:, None] * w).ravel()
    rho, u, p = s.profiles(r, t)
    return SIGMA[s.j] * np.sum(wr * (0.5 * rho * u * u + p / (s.gamma - 1.0)) * r ** (s.j - 1))


@pytest.mark.parametrize("j", [1, 2, 3])
@pytest.mark.parametrize("gamma", [1.2, 1.4, 5.0 / 3.0, 2.0, 3.0, 7.0, 10.0])
def test_profiles_integrate_to_blast_energy(gamma, j):
    E0, rho0, t = 1.0e5, 1.2, 2e-3
    s = SedovSolution(E0, rho0, gamma, j)
    assert energy_by_quadrature(s, t) == pytest.approx(E0, rel=1e-11)


def test_mass_conservation_spherical():
    """Swept mass: Int rho 4 pi r^2 dr over the blast = rho0 4/3 pi r2^3."""
    s = SedovSolution(1.0, 1.0, 1.4, 3)
    r2 = s.shock_radius(1.0)
    x, w = np.polynomial.legendre.leggauss(20)
    edges = r2 * np.linspace(0, 1, 121) ** 0.5
    r = (0.5 * (edges[:-1] + edges[1:])[:, None] + 0.5 * np.diff(edges)[:, None] * x).ravel()
    wr = (0.5 * np.diff(edges)[:, None] * w).ravel()
    rho, _, _ = s.profiles(r, 1.0)
    assert np.sum(wr * rho * 4 * np.pi * r * r) == pytest.approx(4.0 / 3.0 * np.pi * r2 ** 3, rel=1e-9)


def _euler_residuals(s, r, t, h):
    g = s.gamma
    rho, u, p = s.profiles(r, t)
    rp, up, pp = s.profiles(r + h * s.shock_radius(t), t)
    rm, um, pm = s.profiles(r - h * s.shock_radius(t), t)
    rtp, utp, ptp = s.profiles(r, t * (1 + h))
    rtm, utm, ptm = s.profiles(r, t * (1 - h))
    dr, dt = 2 * h * s.shock_radius(t), 2 * h * t
    rho_r, u_r, p_r = (rp - rm) / dr, (up - um) / dr, (pp - pm) / dr
    rho_t, u_t = (rtp - rtm) / dt, (utp - utm) / dt
    S, Sr = np.log(p) - g * np.log(rho), ((np.log(pp) - g * np.log(rp)) - (np.log(pm) - g * np.log(rm))) / dr
    St = ((np.log(ptp) - g * np.log(rtp)) - (np.log(ptm) - g * np.log(rtm))) / dt
    mass = [rho_t, u * rho_r, rho * u_r, (s.j - 1) * rho * u / r]
    mom = [u_t, u * u_r, p_r / rho]
    ent = [St, u * Sr]
    return [(abs(sum(terms)) / np.max(np.abs(terms), axis=0)) for terms in (mass, mom, ent)]


@pytest.mark.parametrize("j", [1, 2, 3])
@pytest.mark.parametrize("gamma", [1.4, 5.0 / 3.0, 2.0, 2.0 + 1e-9, 3.0, 10.0])
def test_profiles_satisfy_euler_equations(gamma, j):
    s = SedovSolution(1.0, 1.0, gamma, j)
    # (towards the centre rho -> 0 and p_r/rho amplifies the round-off of the differences; the
    # residual found there is round-off, ~1e-7 at lam = 0.2; at lam >= 0.3 it is <= 2e-8)
    lam0 = max(0.3, 1.1 * s.hole_radius_fraction)
    r = np.linspace(lam0, 0.97, 12) * s.shock_radius(1.0)
    for k, res in enumerate(_euler_residuals(s, r, 1.0, 1e-5)):
        assert np.all(res < 1e-7), (k, res.max())


# ----------------------------------------------------------------------------- structure and special cases

@pytest.mark.parametrize("j", [1, 2, 3])
def test_monotone_profiles_and_empty_centre(j):
    s = SedovSolution(1.0, 1.0, 1.4, j)
    r2 = s.shock_radius(1.0)
    r = np.linspace(0.0, 1.0, 2001) * r2
    rho, u, p = s.profiles(r, 1.0)
    rho2, u2, p2 = s.post_shock(1.0)
    # (the central pressure plateau is flat to round-off)
    assert np.all(np.diff(rho) >= 0) and np.all(np.diff(u) > 0) and np.all(np.diff(p) >= -1e-15 * p2)
    assert rho[0] == 0.0 and u[0] == 0.0 and 0.3 * p2 < p[0] < 0.4 * p2          # finite central pressure
    assert rho[np.searchsorted(r, 1e-3 * r2)] < 1e-6 * rho2
    if j == 3:
        # central density -> 0: rho ~ lam^(a3/-a2) = lam^(3/(g-1)) = lam^7.5
        lam = np.array([1e-2, 1e-4, 1e-8, 1e-30, 1e-200])
        g = s.similarity(lam)[1]
        assert np.all(np.diff(g) < 0) and g[-2] < 1e-200 and g[-1] == 0.0
        ratio = np.log(s.similarity(np.array([1e-6]))[1][0] / s.similarity(np.array([1e-5]))[1][0]) / np.log(0.1)
        assert ratio == pytest.approx(3.0 / 0.4, rel=1e-9)


def test_self_similarity_in_time():
    s = SedovSolution(1.0e6, 1.2, 1.4, 3)
    lam = np.linspace(0.05, 1.0, 50)
    t1, t2 = 1e-3, 7e-3
    a = s.profiles(lam * s.shock_radius(t1), t1)
    b = s.profiles(lam * s.shock_radius(t2), t2)
    D1, D2 = s.shock_velocity(t1), s.shock_velocity(t2)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-12)
    np.testing.assert_allclose(a[1] / D1, b[1] / D2, rtol=1e-12)
    np.testing.assert_allclose(a[2] / D1 ** 2, b[2] / D2 ** 2, rtol=1e-12)
    assert s.shock_radius(t2) / s.shock_radius(t1) == pytest.approx(7.0 ** 0.4, rel=1e-14)


def test_gamma_two_removable_singularity():
    """j (2 - gamma) = 0: the closed-form exponents a4, a5 diverge; the solution is continuous through it."""
    for j in (1, 2, 3):
        ref = SedovSolution(1.0, 1.0, 2.0, j)
        lam = np.linspace(0.01, 1.0, 30)
        fr, gr, hr = ref.similarity(lam)
        for d in (1e-12, 1e-9, 1e-6):
            for gam in (2.0 - d, 2.0 + d):
                s = SedovSolution(1.0, 1.0, gam, j)
                assert s.alpha == pytest.approx(ref.alpha, rel=10 * d)
                f, g, h = s.similarity(lam)
                for a, b in ((f, fr), (g, gr), (h, hr)):
                    np.testing.assert_allclose(a, b, rtol=0, atol=10 * d)


def test_singular_family_gamma_7_spherical():
    s = SedovSolution(1.0, 1.0, 7.0, 3)
    assert s.family == "singular"
    # Kamm & Timmes' closed form: f = lam, g = lam, h = lam^3, alpha = sigma 8/(25 (g^2-1)) / 3
    assert s.alpha == pytest.approx(4 * math.pi * 8 / (25 * 48) / 3, rel=1e-15)
    lam = np.linspace(0, 1, 11)
    f, g, h = s.similarity(lam)
    np.testing.assert_allclose(f, lam, rtol=1e-15)
    np.testing.assert_allclose(g, lam, rtol=1e-15)
    np.testing.assert_allclose(h, lam ** 3, rtol=1e-15)
    assert energy_by_quadrature(s, 1.0) == pytest.approx(1.0, rel=1e-12)
    # the standard (gamma < 7) and vacuum (gamma > 7) families approach it continuously
    for gam in (7.0 - 1e-6, 7.0 + 1e-6):
        n = SedovSolution(1.0, 1.0, gam, 3)
        assert n.family == ("standard" if gam < 7 else "vacuum")
        assert n.alpha == pytest.approx(s.alpha, rel=1e-5)
        fn, gn, hn = n.similarity(np.linspace(0.1, 1, 10))
        np.testing.assert_allclose(gn, np.linspace(0.1, 1, 10), atol=1e-4)
    assert SedovSolution(1.0, 1.0, 7.0 + 1e-6, 3).hole_radius_fraction < 1e-3


def test_planar_symmetry_and_input_checks():
    s = SedovSolution(1.0, 1.0, 1.4, "planar")
    y = np.linspace(0.0, 1.2, 21) * s.shock_radius(0.5)
    x = np.concatenate([-y[::-1], y[1:]])
    rho, u, p = s.profiles(x, 0.5)
    np.testing.assert_array_equal(rho, rho[::-1])
    np.testing.assert_array_equal(p, p[::-1])
    np.testing.assert_array_equal(u, -u[::-1])
    with pytest.raises(ValueError):
        SedovSolution(1.0, 1.0, 1.4, "conical")
    with pytest.raises(ValueError):
        SedovSolution(1.0, 1.0, 1.0, 3)
    with pytest.raises(ValueError):
        SedovSolution(-1.0, 1.0, 1.4, 3)
    with pytest.raises(ValueError):
        SedovSolution(1.0, 1.0, 1.4, 3).profiles(np.array([-0.1]), 1.0)
    with pytest.raises(ValueError):
        SedovSolution(1.0, 1.0, 1.4, 3).profiles(np.array([0.1]), 0.0)
