"""Exact 1-D profiles keyed by check kind: every registered kind is a check kind, each profile is
its solver.ale.exact solution along the case's axis, and a piston on the upper face is the mirror
image of one on the lower face."""
import numpy as np
import pytest

from orchestrator import checks
from orchestrator.exact_profiles import PROFILES, exact_profile
from solvers.ale.exact import piston
from solvers.ale.exact.reflected_shock import ReflectedShock
from solvers.ale.exact.riemann import RiemannSolution


def test_registry_is_keyed_by_check_kinds():
    assert set(PROFILES) == {"riemann", "piston", "reflected_shock", "bar_wave", "riemann_wall"}
    assert set(PROFILES) <= set(checks.CHECKS)
    assert exact_profile({"check": {"kind": "taylor_bar"}}, 1.0) is None
    assert exact_profile({"check": None}, 1.0) is None


def test_riemann_wall_profile_is_riemann_then_the_reflected_state_and_nothing_beyond_the_wall():
    """Sod into a wall at x = 0.9, t = 0.27: Riemann's solution up to the reflected shock (0.8579),
    the Rankine-Hugoniot state behind it (rho 0.509395, p 0.780387), no gas beyond the wall."""
    params = {"axis": "x", "x0": 0.5, "x_wall": 0.9, "left": [1.0, 0.0, 1.0], "right": [0.125, 0.0, 0.1],
              "gamma_left": 1.4}
    prof = exact_profile({"check": {"kind": "riemann_wall", "params": params}}, 0.27)
    x = np.array([0.1, 0.6, 0.8, 0.85, 0.87, 0.89, 0.95])
    got = prof.sample(x)
    rho, u, p, _ = RiemannSolution((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.4).sample(x, 0.27, 0.5)
    np.testing.assert_array_equal(got["density"][:4], rho[:4])
    np.testing.assert_allclose(got["density"][4:6], 0.509395, rtol=2e-6)
    np.testing.assert_allclose(got["pressure"][4:6], 0.780387, rtol=2e-6)
    assert np.all(got["velocity"][4:6] == 0.0) and np.isnan(got["density"][6])


def test_riemann_profile_along_y():
    params = {"axis": "y", "x0": 0.3, "left": [1.0, 0.0, 1.0], "right": [0.125, 0.0, 0.1], "gamma_left": 1.4}
    prof = exact_profile({"check": {"kind": "riemann", "params": params}}, 0.15)
    assert prof.axis == 1
    y = np.linspace(0.0, 1.0, 11)
    got = prof.sample(y)
    rho, u, p, e = RiemannSolution((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.4).sample(y, 0.15, 0.3)
    for name, ref in (("density", rho), ("velocity", u), ("pressure", p), ("specific_internal_energy", e)):
        np.testing.assert_array_equal(got[name], ref)


def test_riemann_profile_of_eos_tables_is_the_general_solution():
    """`eos_left` / `eos_right` (copper against aluminium, Mie-Grueneisen): the profile is the general-EOS
    solution, e from each side's own EOS."""
    from solvers.ale import eos
    from solvers.ale.exact.riemann_eos import EosRiemannSolution

    cu = {"eos": "mie_gruneisen", "rho0": 8930.0, "c0": 3940.0, "s": 1.49, "gamma0": 2.0}
    al = {"eos": "mie_gruneisen", "rho0": 2700.0, "c0": 5350.0, "s": 1.34, "gamma0": 2.0}
    params = {"axis": "x", "x0": 0.05, "left": [8930.0, 500.0, 0.0], "right": [2700.0, 0.0, 0.0],
              "eos_left": cu, "eos_right": al}
    prof = exact_profile({"check": {"kind": "riemann", "params": params}}, 5e-6)
    x = np.linspace(0.0, 0.1, 21)
    got = prof.sample(x)
    rho, u, p, e = EosRiemannSolution((8930.0, 500.0, 0.0), (2700.0, 0.0, 0.0), cu, al).sample(x, 5e-6, 0.05)
    for name, ref in (("density", rho), ("velocity", u), ("pressure", p), ("specific_internal_energy", e)):
        np.testing.assert_array_equal(got[name], ref)
    k = np.argmax(x > 0.0518)                   # in the shocked aluminium, right of the contact
    assert p[k] > 5e9 and e[k] == eos.energy_from_pressure(*eos.eos_params("mie_gruneisen", al), rho[k], p[k])


def _piston_case(face: str, length=1.0):
    return {
        "ale": {
            "boundaries": {face: {"piston": {"velocity": 50.0}}, "x_upper" if face == "x_lower" else "x_lower": "wall"},
            "grid": {"lower": [0.0, 0.0], "upper": [length, 0.01], "cells": [100, 1]},
            "materials": {"water": {"eos": "tait", "rho0": 1000.0, "bulk_modulus": 2.19e9, "exponent": 7.15,
                                    "p0": 1e5}},
            "regions": [{"material": "water", "density": 1000.0, "pressure": 1e5}],
        },
        "check": {"kind": "piston", "params": {}},
    }


def test_piston_on_either_face():
    t = 2e-4
    ex = piston.tait(50.0, 1000.0, 2.19e9, 7.15, 1e5, rho0=1000.0)
    lower = exact_profile(_piston_case("x_lower"), t)
    upper = exact_profile(_piston_case("x_upper"), t)
    assert lower.axis == upper.axis == 0
    x = np.linspace(0.02, 0.98, 97)
    a, b = lower.sample(x), upper.sample(1.0 - x)
    np.testing.assert_array_equal(a["density"], b["density"])
    np.testing.assert_array_equal(a["pressure"], b["pressure"])
    np.testing.assert_array_equal(a["velocity"], -b["velocity"])  # the upper piston drives along -x
    # the plateau behind the shock (at D t from the face) moves with the piston at 50 m/s
    behind = x < ex.D * t
    assert behind.any() and (~behind).any()
    np.testing.assert_allclose(a["velocity"][behind], 50.0)
    np.testing.assert_allclose(a["pressure"][behind], ex.p1)
    np.testing.assert_allclose(a["density"][~behind], 1000.0)


def test_reflected_shock_profile():
    params = {"mach": 2.0, "ahead": [1.0, 1.0], "gamma": 1.4, "x_shock0": 0.5, "x_wall": 0.75}
    prof = exact_profile({"check": {"kind": "reflected_shock", "params": params}}, 0.25)
    x = np.linspace(0.0, 0.8, 81)
    got = prof.sample(x)
    rho, u, p = ReflectedShock((1.0, 1.0), 1.4, mach=2.0).sample(x, 0.25, 0.5, 0.75)
    np.testing.assert_array_equal(got["density"], rho)
    np.testing.assert_array_equal(got["pressure"], p)
    assert np.isnan(got["density"][x > 0.75]).all()  # beyond the wall: nothing


def test_bad_params_raise():
    with pytest.raises(KeyError):
        exact_profile({"check": {"kind": "riemann", "params": {}}}, 0.1)


def test_bar_wave_profile():
    """c = sqrt(E / rho) = 5000 m/s; behind the front sigma_xx = -4e7 Pa and v = sigma / (rho c) = 1 m/s."""
    case = {"lagrange": {"bodies": [{"material": "steel"}]},
            "materials": {"steel": {"density": 8000.0, "youngs_modulus": 200e9}},
            "check": {"kind": "bar_wave", "params": {"expected_amplitude": 4.0e7}}}
    prof = exact_profile(case, 10e-6)
    got = prof.sample(np.array([0.0, 0.049, 0.051, 0.1]))
    np.testing.assert_array_equal(got["stress"], [-4e7, -4e7, 0.0, 0.0])
    np.testing.assert_allclose(got["velocity"], [1.0, 1.0, 0.0, 0.0], rtol=1e-15)
