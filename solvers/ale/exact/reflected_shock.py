"""Exact solution of a planar shock reflecting from a rigid wall (ideal or stiffened gas).

A shock of Mach number ``M`` runs in +x into gas at rest (state 1: rho_1, p_1), leaving state 2
(rho_2, u_2 > 0, p_2) behind it, and hits a rigid wall at rest at ``x_wall``.  The reflected
shock runs back into state 2 and brings the gas to rest: state 5 (rho_5, 0, p_5) between the
reflected shock and the wall.

Relations (stiffened gas p = (gamma - 1) rho e - gamma p_inf; ideal gas p_inf = 0; written in the
shifted pressure pbar = p + p_inf, in which the Hugoniot is the ideal-gas one, see riemann.py)::

    incident:   pbar_2 / pbar_1 = 1 + 2 gamma / (gamma + 1) (M^2 - 1)
                rho_2 / rho_1   = (gamma + 1) M^2 / ((gamma - 1) M^2 + 2)
                W_i = M c_1,  c_1^2 = gamma pbar_1 / rho_1,  u_2 = W_i (1 - rho_1 / rho_2)
    reflected:  the velocity jump across a shock into state 2 equals u_2 (wall at rest):
                (p_5 - p_2) sqrt(A / (pbar_5 + B)) = u_2,
                A = 2 / ((gamma + 1) rho_2),  B = (gamma - 1) / (gamma + 1) pbar_2      (root in p_5)
                rho_5 = rho_2 (r + mu) / (mu r + 1),  r = pbar_5 / pbar_2,  mu = (gamma - 1)/(gamma + 1)
                W_r = rho_2 u_2 / (rho_2 - rho_5)  (< 0: lab-frame speed, mass balance with u_5 = 0)

(Rankine-Hugoniot; e.g. Anderson, "Modern Compressible Flow", 3rd ed., section 7.7, whose closed
forms for the ideal gas -- the reflected Mach number and p_5/p_2 = ((3 gamma - 1) M^2 - 2 (gamma - 1))
/ ((gamma - 1) M^2 + 2) -- the tests compare with).  The p_5 root is found by bisection-safeguarded
Newton iteration to 1e-15 relative.

Public API: :class:`ReflectedShock`.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["ReflectedShock"]


class ReflectedShock:
    """Incident shock of Mach ``mach`` into ``ahead`` = (rho_1, p_1) at rest, reflected by a wall.

    Attributes: rho1, p1, rho2, u2, p2, rho5, p5 (u5 = 0), incident_speed W_i (> 0),
    reflected_speed W_r (< 0, lab frame), reflected_mach (relative to state 2).
    Alternatively give ``behind_pressure`` = p_2 instead of ``mach``.
    """

    def __init__(self, ahead, gamma, mach=None, behind_pressure=None, p_inf=0.0):
        rho1, p1 = (float(v) for v in ahead)
        g = float(gamma)
        pinf = float(p_inf)
        if not (g > 1.0):
            raise ValueError(f"gamma must be > 1, got {g}")
        if not (rho1 > 0.0) or not (p1 + pinf > 0.0):
            raise ValueError(f"state ahead needs rho > 0 and p + p_inf > 0, got rho={rho1}, p={p1}")
        if (mach is None) == (behind_pressure is None):
            raise ValueError("give exactly one of mach, behind_pressure")
        pb1 = p1 + pinf
        if mach is None:
            ratio = (float(behind_pressure) + pinf) / pb1
            if not (ratio > 1.0):
                raise ValueError(f"behind_pressure must exceed the pressure ahead ({p1})")
            mach = math.sqrt(1.0 + (ratio - 1.0) * (g + 1.0) / (2.0 * g))
        M = float(mach)
        if not (M > 1.0):
            raise ValueError(f"shock Mach number must be > 1, got {M}")
        self.gamma, self.p_inf, self.mach = g, pinf, M
        self.rho1, self.p1 = rho1, p1
        c1 = math.sqrt(g * pb1 / rho1)
        pb2 = pb1 * (1.0 + 2.0 * g / (g + 1.0) * (M * M - 1.0))
        self.rho2 = rho1 * (g + 1.0) * M * M / ((g - 1.0) * M * M + 2.0)
        self.p2 = pb2 - pinf
        self.incident_speed = M * c1
        self.u2 = self.incident_speed * (1.0 - rho1 / self.rho2)
        # reflected shock: f(p5) = u2
        A = 2.0 / ((g + 1.0) * self.rho2)
        B = (g - 1.0) / (g + 1.0) * pb2

        def f(p):
            return (p - self.p2) * math.sqrt(A / (p + pinf + B))

        def df(p):
            s = math.sqrt(A / (p + pinf + B))
            return s * (1.0 - 0.5 * (p - self.p2) / (p + pinf + B))

        lo, hi = self.p2, self.p2 + pb2
        while f(hi) < self.u2:
            lo, hi = hi, hi + 2.0 * (hi + pinf)
        p = 0.5 * (lo + hi)
        for _ in range(200):
            r = f(p) - self.u2
            if r > 0.0:
                hi = p
            else:
                lo = p
            step = r / df(p)
            pn = p - step
            if not (lo < pn < hi):
                pn = 0.5 * (lo + hi)
            if abs(pn - p) <= 1e-15 * (abs(pn) + pinf):
                p = pn
                break
            p = pn
        self.p5 = p
        mu = (g - 1.0) / (g + 1.0)
        r = (p + pinf) / pb2
        self.rho5 = self.rho2 * (r + mu) / (mu * r + 1.0)
        self.reflected_speed = self.rho2 * self.u2 / (self.rho2 - self.rho5)
        c2 = math.sqrt(g * pb2 / self.rho2)
        self.reflected_mach = (self.u2 - self.reflected_speed) / c2

    # ------------------------------------------------------------------------------------------
    def reflection_time(self, x_shock0: float, x_wall: float) -> float:
        """Time at which the incident shock, at ``x_shock0`` at t = 0, reaches the wall."""
        return (float(x_wall) - float(x_shock0)) / self.incident_speed

    def shock_position(self, t: float, x_shock0: float, x_wall: float) -> tuple[str, float]:
        """("incident" | "reflected", position) of the shock at time t."""
        tr = self.reflection_time(x_shock0, x_wall)
        if t <= tr:
            return "incident", float(x_shock0) + self.incident_speed * t
        return "reflected", float(x_wall) + self.reflected_speed * (t - tr)

    def sample(self, x, t: float, x_shock0: float, x_wall: float):
        """(rho, u, p) at the points x <= x_wall at time t (x > x_wall: NaN)."""
        x = np.asarray(x, dtype=np.float64)
        kind, xs = self.shock_position(t, x_shock0, x_wall)
        rho = np.full(x.shape, self.rho2)
        u = np.full(x.shape, self.u2)
        p = np.full(x.shape, self.p2)
        beyond = x > xs
        if kind == "incident":
            rho[beyond], u[beyond], p[beyond] = self.rho1, 0.0, self.p1
        else:
            rho[beyond], u[beyond], p[beyond] = self.rho5, 0.0, self.p5
        out = x > float(x_wall)
        for a in (rho, u, p):
            a[out] = np.nan
        return rho, u, p

    def __repr__(self):
        return (f"ReflectedShock(M={self.mach:.6g}, state2=({self.rho2:.6g}, {self.u2:.6g}, {self.p2:.6g}), "
                f"state5=({self.rho5:.6g}, 0, {self.p5:.6g}), W_i={self.incident_speed:.6g}, "
                f"W_r={self.reflected_speed:.6g})")
