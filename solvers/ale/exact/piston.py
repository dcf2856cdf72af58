"""Piston-driven shock: a piston moving at constant speed ``u_p`` (> 0) into a fluid at rest
(``rho0``, ``p0``) drives a steady shock of speed ``D`` ahead of it; between the piston and the shock
the fluid moves with the piston at the uniform state ``(rho1, p1)``.

Rankine-Hugoniot conditions in the lab frame (fluid ahead at rest)::

    mass      rho0 D = rho1 (D - u_p)
    momentum  p1 - p0 = rho0 D u_p
    energy    e1 - e0 = (p1 + p0) / 2 (1/rho0 - 1/rho1)           (stiffened gas)

Eliminating D from mass and momentum: ``u_p^2 = (p1 - p0)(1/rho0 - 1/rho1)``.  The post-shock
state is the root of that equation (``scipy.optimize.brentq``):

* stiffened gas (``p = (gamma - 1) rho e - gamma p_inf``): the Hugoniot (energy condition) gives
  ``rho1/rho0 = ((g+1) P1 + (g-1) P0) / ((g-1) P1 + (g+1) P0)`` with ``P = p + p_inf``; unknown p1;
* Tait (barotropic, ``p(rho) = p_ref + K0/n ((rho/rho_ref)^n - 1)``, the form of solvers/ale/eos.py,
  ``c^2 = K0/rho_ref (rho/rho_ref)^(n-1)``): only mass and momentum with ``p1 = p(rho1)``; unknown
  rho1 (the energy jump is not imposed: a barotropic shock dissipates the difference);
* Mie-Grueneisen from its reference state at rest: the linear us-up Hugoniot, D = c0 + s u_p.

Then ``D = rho1 u_p / (rho1 - rho0)``.  Positions (piston starting at ``x0`` and moving along +x):
piston ``x0 + u_p t``, shock ``x0 + D t``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq


@dataclass(frozen=True)
class PistonShock:
    """Post-shock state and shock speed; ``c0`` is the sound speed ahead."""

    u_p: float
    rho0: float
    p0: float
    rho1: float
    p1: float
    D: float
    c0: float

    def shock_position(self, t: float, x0: float = 0.0) -> float:
        return x0 + self.D * t

    def piston_position(self, t: float, x0: float = 0.0) -> float:
        return x0 + self.u_p * t

    def sample(self, x, t: float, x0: float = 0.0):
        """(rho, u, p) at the points x (piston at x0 + u_p t, shock at x0 + D t; NaN behind the
        piston)."""
        x = np.asarray(x, dtype=np.float64)
        behind = x < self.shock_position(t, x0)
        rho = np.where(behind, self.rho1, self.rho0)
        u = np.where(behind, self.u_p, 0.0)
        p = np.where(behind, self.p1, self.p0)
        out = x < self.piston_position(t, x0)
        return (np.where(out, np.nan, rho), np.where(out, np.nan, u), np.where(out, np.nan, p))


def _check_speed(u_p: float) -> float:
    u_p = float(u_p)
    if not u_p > 0.0:
        raise ValueError(f"piston speed u_p = {u_p!r}: must be > 0 (into the fluid)")
    return u_p


def stiffened_gas(u_p: float, rho0: float, p0: float, gamma: float, p_inf: float = 0.0) -> PistonShock:
    """Piston shock in a stiffened gas (ideal gas: p_inf = 0) at rest at (rho0, p0)."""
    u_p, rho0, p0, g, pinf = _check_speed(u_p), float(rho0), float(p0), float(gamma), float(p_inf)
    P0 = p0 + pinf
    if not (rho0 > 0 and P0 > 0 and g > 1):
        raise ValueError("stiffened gas piston: needs rho0 > 0, p0 + p_inf > 0 and gamma > 1")

    def rho1_of(p1):
        P1 = p1 + pinf
        return rho0 * ((g + 1) * P1 + (g - 1) * P0) / ((g - 1) * P1 + (g + 1) * P0)

    def f(p1):
        return (p1 - p0) * (1.0 / rho0 - 1.0 / rho1_of(p1)) - u_p * u_p

    c0 = math.sqrt(g * P0 / rho0)
    hi = p0 + rho0 * u_p * (c0 + (g + 1) * u_p)  # an upper bracket (doubled until f > 0)
    while f(hi) < 0:
        hi = p0 + 2.0 * (hi - p0)
    p1 = brentq(f, p0, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
    rho1 = rho1_of(p1)
    D = rho1 * u_p / (rho1 - rho0)
    return PistonShock(u_p, rho0, p0, rho1, p1, D, c0)


def tait(u_p: float, rho_ref: float, bulk_modulus: float, exponent: float, p_ref: float = 0.0,
         rho0: float | None = None) -> PistonShock:
    """Piston shock in a Tait liquid (parameters as in solvers/ale/eos.py) at rest at density rho0
    (default rho_ref; the pressure ahead is p(rho0))."""
    u_p = _check_speed(u_p)
    rr, K0, n, pr = float(rho_ref), float(bulk_modulus), float(exponent), float(p_ref)
    rho0 = rr if rho0 is None else float(rho0)
    if not (rr > 0 and K0 > 0 and n >= 1 and rho0 > 0):
        raise ValueError("Tait piston: needs rho_ref > 0, bulk_modulus > 0, exponent >= 1, rho0 > 0")

    def p(rho):
        return pr + K0 / n * ((rho / rr) ** n - 1.0)

    p0 = p(rho0)

    def f(rho1):
        return (p(rho1) - p0) * (1.0 / rho0 - 1.0 / rho1) - u_p * u_p

    hi = rho0 * 1.01
    while f(hi) < 0:
        hi = rho0 + 2.0 * (hi - rho0)
    rho1 = brentq(f, rho0, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
    D = rho1 * u_p / (rho1 - rho0)
    c0 = math.sqrt(K0 / rr * (rho0 / rr) ** (n - 1.0))
    return PistonShock(u_p, rho0, p0, rho1, p(rho1), D, c0)


def mie_gruneisen(u_p: float, rho0: float, c0: float, s: float) -> PistonShock:
    """Mie-Grueneisen material at rest at its reference state (p = e = 0, the EOS of
    solvers/ale/eos.py): its reference curve is the Hugoniot from that state, so the shock follows
    the linear us-up relation exactly: D = c0 + s u_p, p1 = rho0 D u_p, rho1 = rho0 D / (D - u_p)
    (mass and momentum; the energy jump e1 = u_p^2 / 2 lies on the reference curve)."""
    u_p = _check_speed(u_p)
    D = c0 + s * u_p
    return PistonShock(u_p, rho0, 0.0, rho0 * D / (D - u_p), rho0 * D * u_p, D, c0)
