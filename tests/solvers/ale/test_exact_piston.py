"""Piston-driven shock (solvers.ale.exact.piston) against the acoustic limit, an independent check
of the jump conditions and the closed form of the stiffened-gas piston shock."""
from __future__ import annotations

import math

import pytest

from solvers.ale.exact import piston

WATER_TAIT = dict(rho_ref=1000.0, bulk_modulus=2.19e9, exponent=7.15, p_ref=1.0e5)
WATER_SG = dict(rho0=1000.0, p0=1.0e5, gamma=4.4, p_inf=6.0e8)


def _tait_p(rho, rho_ref, bulk_modulus, exponent, p_ref):
    return p_ref + bulk_modulus / exponent * ((rho / rho_ref) ** exponent - 1.0)


@pytest.mark.parametrize("u_p", [1.0e-3, 1.0e-2])
def test_acoustic_limit(u_p):
    """Weak shock: p1 - p0 -> rho0 c0 u_p and D -> c0, relative deviation D/c0 - 1 = G/2 u_p/c0 + ...
    (fundamental derivative G = (n+1)/2 Tait, (gamma+1)/2 stiffened gas): tolerance 3 u_p/c0
    (<= 2e-5); the first-order slope (D/c0 - 1)/(u_p/c0) -> G/2 to 1e-3."""
    for ex, G in ((piston.tait(u_p, **WATER_TAIT), (7.15 + 1) / 2),
                  (piston.stiffened_gas(u_p, **WATER_SG), (4.4 + 1) / 2)):
        tol = 3 * u_p / ex.c0
        assert (ex.p1 - ex.p0) / (ex.rho0 * ex.c0 * u_p) == pytest.approx(1.0, rel=tol)
        assert ex.D / ex.c0 == pytest.approx(1.0, rel=tol)
        assert (ex.D / ex.c0 - 1) / (u_p / ex.c0) == pytest.approx(G / 2, rel=1e-3)


def test_tait_sound_speed():
    """c0^2 = K0/rho_ref at rho_ref (the EOS module's form)."""
    ex = piston.tait(50.0, **WATER_TAIT)
    assert ex.c0 == pytest.approx(math.sqrt(2.19e9 / 1000.0), rel=1e-15)
    assert ex.p0 == 1.0e5


@pytest.mark.parametrize("u_p", [50.0, 500.0, 3000.0])
def test_tait_jump_conditions(u_p):
    """Mass and momentum fluxes through the shock (shock frame) and p1 = p(rho1), to 1e-10."""
    ex = piston.tait(u_p, **WATER_TAIT)
    w0, w1 = ex.D, ex.D - u_p
    assert ex.rho1 > ex.rho0 and ex.D > ex.c0
    assert ex.rho1 * w1 == pytest.approx(ex.rho0 * w0, rel=1e-10)
    assert ex.p1 + ex.rho1 * w1 ** 2 == pytest.approx(ex.p0 + ex.rho0 * w0 ** 2, rel=1e-10)
    assert ex.p1 == pytest.approx(_tait_p(ex.rho1, **WATER_TAIT), rel=1e-10)


@pytest.mark.parametrize("u_p", [50.0, 500.0, 3000.0])
def test_stiffened_gas_jump_conditions(u_p):
    """Mass, momentum and total-enthalpy fluxes (shock frame) with e from the EOS, to 1e-10."""
    ex = piston.stiffened_gas(u_p, **WATER_SG)
    g, pinf = WATER_SG["gamma"], WATER_SG["p_inf"]

    def h(rho, p):  # e + p/rho, e = (p + gamma p_inf) / ((gamma - 1) rho)
        return (p + g * pinf) / ((g - 1) * rho) + p / rho

    w0, w1 = ex.D, ex.D - u_p
    assert ex.rho1 * w1 == pytest.approx(ex.rho0 * w0, rel=1e-10)
    assert ex.p1 + ex.rho1 * w1 ** 2 == pytest.approx(ex.p0 + ex.rho0 * w0 ** 2, rel=1e-10)
    assert h(ex.rho1, ex.p1) + 0.5 * w1 ** 2 == pytest.approx(h(ex.rho0, ex.p0) + 0.5 * w0 ** 2, rel=1e-10)


@pytest.mark.parametrize("u_p", [50.0, 3000.0])
def test_stiffened_gas_closed_form(u_p):
    """Closed form of the piston shock (P = p + p_inf): D = (g+1)/4 u + sqrt(((g+1)/4 u)^2 + c0^2)."""
    ex = piston.stiffened_gas(u_p, **WATER_SG)
    g = WATER_SG["gamma"]
    c0 = math.sqrt(g * (WATER_SG["p0"] + WATER_SG["p_inf"]) / WATER_SG["rho0"])
    a = 0.25 * (g + 1) * u_p
    D = a + math.sqrt(a * a + c0 * c0)
    assert ex.c0 == pytest.approx(c0, rel=1e-15)
    assert ex.D == pytest.approx(D, rel=1e-10)
    assert ex.p1 - ex.p0 == pytest.approx(WATER_SG["rho0"] * D * u_p, rel=1e-10)


def test_positions_and_sample():
    ex = piston.tait(50.0, **WATER_TAIT)
    t = 1e-4
    rho, u, p = ex.sample([0.001, 0.01, 0.5], t)
    assert math.isnan(rho[0])  # behind the piston (at 0.005)
    assert (rho[1], u[1], p[1]) == (ex.rho1, 50.0, ex.p1)
    assert (rho[2], u[2], p[2]) == (ex.rho0, 0.0, ex.p0)
    assert ex.shock_position(t, 0.2) == pytest.approx(0.2 + ex.D * t, rel=1e-15)


def test_rejects_bad_speed():
    with pytest.raises(ValueError, match="u_p"):
        piston.tait(0.0, **WATER_TAIT)
