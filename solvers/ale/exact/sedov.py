"""Semi-analytic Sedov-Taylor point-blast solution (uniform ambient density).

Follows J. R. Kamm and F. X. Timmes, "On efficient generation of numerically
robust Sedov solutions", LA-UR-07-2849 (2007), and J. R. Kamm, "Evaluation of the
Sedov-von Neumann-Taylor blast wave solution", LA-UR-00-6055 (2000), for a
polytropic gas (p = (gamma - 1) rho e), zero ambient pressure, uniform ambient
density rho0 (omega = 0) and geometry j = 1 (planar), 2 (cylindrical),
3 (spherical).

Energy E0 is the total energy of the full-space problem: per unit area for j = 1
(the blast on the plane x = 0 drives two shocks, at x = +-r2), per unit length for
j = 2, total for j = 3.  The shock radius is

    r2(t) = (E0 t^2 / (alpha rho0))^(1/(j+2)),      D = dr2/dt = 2 r2 / ((j+2) t),

and behind the strong shock rho2 = rho0 (g+1)/(g-1), u2 = 2 D/(g+1),
p2 = 2 rho0 D^2/(g+1).  Inside, rho = rho2 g(lam), u = u2 f(lam), p = p2 h(lam)
with lam = r/r2, given parametrically by the similarity variable V (Kamm 2000,
eqs. 29-47 with omega = 0):

    x1 = a V, x2 = b (c V - 1), x3 = d (1 - e V), x4 = b (1 - c V / g)
    lam = x1^-a0 x2^-a2 x3^-a1,  f = x1 lam,
    g = x2^a3 x3^a4 x4^a5,       h = x1^(a0 j) x3^(a4 - 2 a1) x4^(1 + a5).

Numerical robustness (the point of Kamm & Timmes):
  * V is never used directly.  Since x1..x4 are all 1 at the shock (V = V2) and
    affine in V, they are written in terms of s = x2 and 1 - s:
    x1 = 1 - (g-1)(1-s)/(2g), x3 = 1 + kappa3 (1-s), x4 = 1 + (1-s)/g,
    kappa3 = 2 e (g-1)/(g Dn), Dn = 3j - 2 + g(2-j) = (j+2)(g+1) - 2(2 + j(g-1)).
    The standard family (V0 <= V <= V2, i.e. 0 <= s <= 1) is parametrised by
    tau = ln s in (-inf, 0] with 1 - s = -expm1(tau): lam ~ s^(-a2) -> 0 at the
    centre, and a parametrisation by V would lose all resolution for
    lam < (machine eps)^(-a2) (about 0.02 for g = 1.4, j = 3).  For
    tau < -40, 1 - s == 1 in double precision and the solution is an exact
    power law in lam, inverted and integrated in closed form.
  * The "omega3" singularity j(2 - g) = 0, i.e. g = 2 for any j, where a4 and a5
    diverge and Kamm & Timmes switch to an exponential form, is removed
    analytically: a4 ln x3 + a5 ln x4 = (a4 + a5) ln x4 - a1 (j+2) y phi((g-2) y)
    with a4 + a5 = (j-2) Dn / ((2 + j(g-1)) (2(g-1) + j)),
    y = j (g+1)(1-s)/(g Dn x4), phi(u) = log1p(u)/u, which is smooth through g = 2
    and reduces there to Kamm & Timmes' exp form.  Used for |g - 2| < 1/2.
  * Dn = 0 (j = 3, g = 7) is Kamm's "singular" family with the closed form
    f = lam, g = lam^(j-2), h = lam^j; Dn < 0 (j = 3, g > 7) is the "vacuum"
    family: V2 <= V <= Vv, the centre is evacuated for lam < lam_v = lam(x4 = 0),
    parametrised by p = 1 - x4 in [0, 1].  Near g = 7 the standard and vacuum
    profiles live in a shock layer 1 - s ~ 1/kappa3 (kappa3 -> inf); the 1 - s
    (expm1) and p parametrisations resolve it and the quadrature gets
    breakpoints at decades of that width, so both families join the singular one
    continuously (alpha changes by 2.5e-7 between g = 7 and 7 -+ 1e-6, its
    linear variation).
  * The energy integral is evaluated by scipy.integrate.quad in the
    parameter (tau or p) with the exact power-law tail below tau = -40:

        E0 = alpha rho0 r2^(j+2) / t^2,
        alpha = sigma_j 8 / ((j+2)^2 (g^2 - 1)) Int_0^1 (g f^2 + h) lam^(j-1) dlam,

    sigma_j = 2, 2 pi, 4 pi (for j = 1 this alpha is twice Kamm & Timmes' alpha,
    which refers to the half space x > 0).

Public API: :class:`SedovSolution`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad

__all__ = ["SedovSolution"]

_GEOMETRIES = {"planar": 1, "cylindrical": 2, "spherical": 3}
_TAU_ASYM = -40.0            # below: exp(tau) < eps/2, so 1 - s == 1.0 exactly
_DECADES = tuple(10.0 ** k for k in range(-3, 20))   # quadrature breakpoints, in units of the shock-layer width
_SIGMA = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


def _log1p_over(u):
    """phi(u) = log1p(u)/u, with phi(0) = 1 (vectorised, u > -1)."""
    u = np.asarray(u, dtype=float)
    small = np.abs(u) < 1e-5
    us = np.where(small, 1.0, u)
    return np.where(small, 1.0 - u / 2.0 + u * u / 3.0 - u ** 3 / 4.0, np.log1p(us) / us)


def _quad_pieces(fun, edges, rtol=1e-13):
    """Sum of adaptive quadratures over consecutive intervals of edges.

    Pieces are integrated to relative accuracy rtol; a piece whose contribution is
    negligible may not reach it, so the check is on the summed error estimate."""
    total, err = 0.0, 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        val, e, *_ = quad(fun, a, b, epsabs=0.0, epsrel=rtol, limit=500, full_output=1)
        total += val
        err += e
    if not (math.isfinite(total) and err <= 1e3 * rtol * abs(total)):
        raise RuntimeError(f"Sedov energy integral inaccurate: {total} +- {err}")
    return total


class SedovSolution:
    """Sedov-Taylor blast wave in a uniform polytropic gas (zero ambient pressure).

    Parameters
    ----------
    E0 : float
        Blast energy (J; J/m for cylindrical, J/m^2 for planar, full space).
    rho0 : float
        Ambient density (kg/m^3).
    gamma : float
        Ratio of specific heats, > 1.
    geometry : int or str
        1 / "planar", 2 / "cylindrical", 3 / "spherical".

    Attributes
    ----------
    j : int
        Geometry index.
    alpha : float
        Energy integral constant, E0 = alpha rho0 r2^(j+2) / t^2.
    family : str
        ``"standard"``, ``"singular"`` (j=3, gamma=7) or ``"vacuum"`` (j=3, gamma>7).
    hole_radius_fraction : float
        lam_v = r_v / r2 of the evacuated centre (0 unless family == "vacuum").
    """

    def __init__(self, E0, rho0, gamma, geometry):
        if isinstance(geometry, str):
            if geometry not in _GEOMETRIES:
                raise ValueError(f"geometry must be one of {sorted(_GEOMETRIES)} or 1, 2, 3; got {geometry!r}")
            geometry = _GEOMETRIES[geometry]
        if geometry not in (1, 2, 3):
            raise ValueError(f"geometry must be 1, 2 or 3, got {geometry!r}")
        E0, rho0, gamma = float(E0), float(rho0), float(gamma)
        if not (E0 > 0.0 and math.isfinite(E0)):
            raise ValueError(f"E0 must be > 0, got {E0}")
        if not (rho0 > 0.0 and math.isfinite(rho0)):
            raise ValueError(f"rho0 must be > 0, got {rho0}")
        if not (gamma > 1.0 and math.isfinite(gamma)):
            raise ValueError(f"gamma must be > 1, got {gamma}")
        self.E0, self.rho0, self.gamma, self.j = E0, rho0, gamma, int(geometry)
        self._setup_constants()
        self.alpha = _SIGMA[self.j] * 8.0 / ((self.j + 2.0) ** 2 * (gamma * gamma - 1.0)) * self._energy_integral()

    # ------------------------------------------------------------------ constants
    def _setup_constants(self):
        g, j = self.gamma, float(self.j)
        self.a0 = 2.0 / (j + 2.0)
        self._B = 2.0 * (g - 1.0) + j                    # Kamm's denom2 (omega = 0), > 0
        self._A = 2.0 + j * (g - 1.0)                    # 2 e
        self.a2 = -(g - 1.0) / self._B
        self.a1 = (j + 2.0) * g / self._A * (2.0 * j * (2.0 - g) / (g * (j + 2.0) ** 2) - self.a2)
        self.a3 = j / self._B
        self._Dn = 3.0 * j - 2.0 + g * (2.0 - j)          # (j+2)(g+1) - 2(2 + j(g-1))
        self._near2 = abs(g - 2.0) < 0.5
        if not self._near2:
            self.a4 = self.a1 * (j + 2.0) / (2.0 - g)     # a1 (j+2) j / (j (2-g))
            self.a5 = 2.0 / (g - 2.0)                    # -2 j / (j (2-g))
        self._a45 = (j - 2.0) * self._Dn / (self._A * self._B)   # a4 + a5, finite at g = 2
        self.hole_radius_fraction = 0.0
        if self._Dn > 0.0:
            self.family = "standard"
        elif self._Dn == 0.0:
            self.family = "singular"
            return
        else:
            self.family = "vacuum"
        self._kappa3 = 2.0 * (0.5 * self._A) * (g - 1.0) / (g * self._Dn)
        if self.family == "standard":
            # centre asymptote: ln lam = C - a2 tau for tau < _TAU_ASYM (1 - s == 1)
            x1c = 1.0 - (g - 1.0) / (2.0 * g)
            x3c = 1.0 + self._kappa3
            self._C = -self.a0 * math.log(x1c) - self.a1 * math.log(x3c)
        else:
            self.hole_radius_fraction = float(np.exp(self._eval_p(np.array([1.0]))[0][0]))

    # ------------------------------------------------------------------ similarity functions
    def _core(self, oms, ln_x2, doms, dlnx2, x4=None):
        """ln lam, d ln lam / d(param), f, g, h from 1 - s, ln s and their parameter derivatives."""
        g, j = self.gamma, float(self.j)
        x1 = 1.0 - (g - 1.0) / (2.0 * g) * oms
        x3 = 1.0 + self._kappa3 * oms
        if x4 is None:
            x4 = 1.0 + oms / g
        lnx1, lnx3 = np.log(x1), np.log(x3)
        with np.errstate(divide="ignore"):
            lnx4 = np.log(x4)
        lnlam = -self.a0 * lnx1 - self.a2 * ln_x2 - self.a1 * lnx3
        dlnlam = (self.a0 * (g - 1.0) / (2.0 * g) * doms / x1 - self.a2 * dlnx2
                  - self.a1 * self._kappa3 * doms / x3)
        if self._near2:
            y = j * (g + 1.0) * oms / (g * self._Dn * x4)
            phi = self._a45 * lnx4 - self.a1 * (j + 2.0) * y * _log1p_over((g - 2.0) * y)
        else:
            with np.errstate(invalid="ignore"):
                phi = self.a4 * lnx3 + self.a5 * lnx4
            phi = np.where(x4 == 0.0, -np.inf, phi)      # vacuum edge: x4^a5 -> 0 (a5 > 0 there)
        lam = np.exp(lnlam)
        with np.errstate(invalid="ignore"):
            lng = self.a3 * ln_x2 + phi
            lnh = self.a0 * j * lnx1 - 2.0 * self.a1 * lnx3 + lnx4 + phi
        G = np.exp(np.where(np.isnan(lng), -np.inf, lng))
        H = np.exp(np.where(np.isnan(lnh), -np.inf, lnh))
        return lnlam, dlnlam, x1 * lam, G, H

    def _eval_tau(self, tau):
        """Standard family, tau = ln x2 in [-inf, 0]."""
        tau = np.asarray(tau, dtype=float)
        return self._core(-np.expm1(tau), tau, -np.exp(tau), 1.0)

    def _eval_p(self, p):
        """Vacuum family, p = 1 - x4 in [0, 1] (p = 0 at the shock, 1 at the hole edge).

        Derivatives are with respect to p (lam decreases with p)."""
        p = np.asarray(p, dtype=float)
        g = self.gamma
        s = 1.0 + g * p
        return self._core(-g * p, np.log1p(g * p), -g, g / s, x4=1.0 - p)

    def similarity(self, lam):
        """Similarity functions (f, g, h) = (u/u2, rho/rho2, p/p2) at lam = r/r2 in [0, 1]."""
        lam = np.asarray(lam, dtype=float)
        shape = lam.shape
        lam = lam.ravel()
        if np.any((lam < 0.0) | (lam > 1.0)) or np.any(np.isnan(lam)):
            raise ValueError("lam must lie in [0, 1]")
        if self.family == "singular":
            return (lam.reshape(shape), (lam ** (self.j - 2)).reshape(shape), (lam ** self.j).reshape(shape))
        if self.family == "standard":
            par = self._invert_tau(lam)
            _, _, f, g, h = self._eval_tau(par)
        else:
            f, g, h = np.zeros_like(lam), np.zeros_like(lam), np.zeros_like(lam)
            m = lam >= self.hole_radius_fraction
            if m.any():
                _, _, f[m], g[m], h[m] = self._eval_p(self._invert_p(lam[m]))
        return f.reshape(shape), g.reshape(shape), h.reshape(shape)

    # ------------------------------------------------------------------ inversion lam -> parameter
    @staticmethod
    def _safeguarded_newton(fun, target, x, lo, hi, tol, max_iter=200):
        """Vectorised Newton on fun(x) = target for increasing fun, with bisection fallback.

        Converged when the Newton step is below tol * max(1, |x|)."""
        active = np.ones(x.shape, dtype=bool)
        for _ in range(max_iter):
            if not active.any():
                break
            xa = x[active]
            F, dF = fun(xa)
            F = F - target[active]
            lo_a = np.where(F < 0.0, xa, lo[active])
            hi_a = np.where(F > 0.0, xa, hi[active])
            with np.errstate(divide="ignore", invalid="ignore"):
                xn = xa - F / dF
            scale = tol * np.maximum(1.0, np.abs(xa))
            conv = (np.abs(xn - xa) <= scale) | (F == 0.0)
            xn = np.where(conv, np.clip(xn, lo_a, hi_a), xn)
            bad = ~conv & ~((xn > lo_a) & (xn < hi_a))
            xn = np.where(bad, 0.5 * (lo_a + hi_a), xn)
            conv |= (hi_a - lo_a) <= scale
            lo[active], hi[active], x[active] = lo_a, hi_a, xn
            idx = np.flatnonzero(active)
            active[idx[conv]] = False
        else:
            if active.any():
                raise RuntimeError("Sedov similarity inversion did not converge")
        return x

    def _invert_tau(self, lam):
        with np.errstate(divide="ignore"):
            lnl = np.log(lam)
        tau = (lnl - self._C) / (-self.a2)               # exact where tau < _TAU_ASYM
        m = tau >= _TAU_ASYM
        if m.any():
            def fun(x):
                r = self._eval_tau(x)
                return r[0], r[1]
            n = int(m.sum())
            tau[m] = self._safeguarded_newton(fun, lnl[m], np.clip(tau[m], _TAU_ASYM, 0.0),
                                              np.full(n, _TAU_ASYM - 1.0), np.zeros(n), 1e-15)
        return tau

    def _invert_p(self, lam):
        lnl = np.log(lam)

        def fun(x):                                       # x = -p, so that lam increases with x
            r = self._eval_p(-x)
            return r[0], -r[1]
        n = lam.size
        x0 = -np.clip((1.0 - lam) / (1.0 - self.hole_radius_fraction), 0.0, 1.0)
        return -self._safeguarded_newton(fun, lnl, x0, -np.ones(n), np.zeros(n), 1e-15)

    # ------------------------------------------------------------------ energy integral
    def _energy_integral(self):
        """Int_0^1 (g f^2 + h) lam^(j-1) dlam."""
        j = self.j
        if self.family == "singular":
            return 1.0 / j                                # Int 2 lam^(2j-1) dlam

        if self.family == "vacuum":
            def integrand(p):
                lnlam, dlnlam, f, g, h = self._eval_p(np.array([p]))
                return -float(((g * f * f + h) * np.exp(j * lnlam) * dlnlam)[0])
            # near g = 7 the profile lives in p ~ 1 / (g |kappa3|) behind the shock
            w = 1.0 / (self.gamma * abs(self._kappa3))
            edges = sorted({0.0, 1.0, *(c * w for c in _DECADES if c * w < 0.5)})
            return _quad_pieces(integrand, edges)

        def integrand(tau):
            lnlam, dlnlam, f, g, h = self._eval_tau(np.array([tau]))
            return float(((g * f * f + h) * np.exp(j * lnlam) * dlnlam)[0])

        # exact tail tau < T: lam = lam_T e^{-a2 (tau - T)}, g = g_T e^{a3 (tau - T)}, h = h_T, x1 = x1_T
        T = _TAU_ASYM
        lnlam, _, f, g, h = (float(v[0]) for v in self._eval_tau(np.array([T])))
        lamT = math.exp(lnlam)
        tail = h * lamT ** j / j + g * f * f * lamT ** j * (-self.a2) / (self.a3 - self.a2 * (j + 2))
        # breakpoints: the profile varies on 1 - s ~ 1/kappa3 near the shock (narrow for g -> 7, j = 3)
        pts = [-20.0, -10.0, -5.0, -2.0, -1.0]
        k = self._kappa3
        for c in _DECADES:
            if c / k < 0.5:
                pts.append(math.log1p(-c / k))
        pts = sorted(set(p for p in pts if T < p < 0.0))
        edges = [T] + pts + [0.0]
        return tail + _quad_pieces(integrand, edges)

    # ------------------------------------------------------------------ physical solution
    def shock_radius(self, t):
        """r2(t) = (E0 t^2 / (alpha rho0))^(1/(j+2))."""
        t = np.asarray(t, dtype=float)
        if np.any(t < 0.0):
            raise ValueError("t must be >= 0")
        r = (self.E0 * t * t / (self.alpha * self.rho0)) ** (1.0 / (self.j + 2.0))
        return float(r) if r.ndim == 0 else r

    def shock_velocity(self, t):
        """D = dr2/dt = 2 r2 / ((j+2) t)."""
        return 2.0 * self.shock_radius(t) / ((self.j + 2.0) * t)

    def post_shock(self, t):
        """Strong-shock Rankine-Hugoniot state (rho2, u2, p2) just behind the shock at time t."""
        g = self.gamma
        D = self.shock_velocity(t)
        return self.rho0 * (g + 1.0) / (g - 1.0), 2.0 * D / (g + 1.0), 2.0 * self.rho0 * D * D / (g + 1.0)

    def profiles(self, r, t):
        """Density, velocity and pressure at radii r (array) and time t > 0.

        Inside the shock (|r| <= r2) the similarity solution, outside the ambient
        state (rho0, 0, 0).  For the planar geometry r is the signed distance x from
        the blast plane and u is odd in x; for j = 2, 3 r must be >= 0.
        """
        t = float(t)
        if not t > 0.0:
            raise ValueError("t must be > 0")
        r = np.asarray(r, dtype=float)
        if self.j > 1 and np.any(r < 0.0):
            raise ValueError("radii must be >= 0 for cylindrical/spherical geometry")
        shape = r.shape
        r = r.ravel()
        r2 = self.shock_radius(t)
        rho2, u2, p2 = self.post_shock(t)
        rho = np.full(r.shape, self.rho0)
        u = np.zeros(r.shape)
        p = np.zeros(r.shape)
        inside = np.abs(r) <= r2
        if inside.any():
            f, g, h = self.similarity(np.minimum(np.abs(r[inside]) / r2, 1.0))
            rho[inside] = rho2 * g
            u[inside] = u2 * f * np.where(r[inside] < 0.0, -1.0, 1.0)
            p[inside] = p2 * h
        return rho.reshape(shape), u.reshape(shape), p.reshape(shape)

    def __repr__(self):
        return (f"SedovSolution(E0={self.E0!r}, rho0={self.rho0!r}, gamma={self.gamma!r}, geometry={self.j}, "
                f"alpha={self.alpha!r}, family={self.family!r})")
