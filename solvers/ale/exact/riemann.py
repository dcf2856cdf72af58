"""Exact Riemann solver for the 1D Euler equations with stiffened-gas equations of state.

Each side K of the initial discontinuity carries its own stiffened-gas EOS

    p = (gamma_K - 1) rho e - gamma_K p_inf_K          (ideal gas: p_inf_K = 0),

with sound speed c^2 = gamma_K (p + p_inf_K) / rho.  In the shifted pressure
pbar = p + p_inf_K and the shifted energy eps = e - p_inf_K / rho the EOS reads
pbar = (gamma_K - 1) rho eps, and the Hugoniot, the isentropes and the Riemann
invariants of the stiffened gas are those of an ideal gas written in (pbar, eps)
(pressure *differences*, which enter the mass and momentum jumps, are the same in
p and pbar).  The solver is therefore Toro's exact solver (E. F. Toro, "Riemann
Solvers and Numerical Methods for Fluid Dynamics", 3rd ed., Springer 2009, ch. 4)
with p replaced by p + p_inf on each side:

    f_K(p) = (p - p_K) sqrt(A_K / (p + p_inf_K + B_K))                    p > p_K (shock)
    f_K(p) = 2 c_K / (gamma_K - 1) [((p + p_inf_K)/(p_K + p_inf_K))^z_K - 1]   p <= p_K (rarefaction)

    A_K = 2 / ((gamma_K + 1) rho_K),  B_K = (gamma_K - 1)/(gamma_K + 1) (p_K + p_inf_K),
    z_K = (gamma_K - 1) / (2 gamma_K),

and the star pressure is the root of G(p) = f_L(p) + f_R(p) + u_R - u_L.  G is
monotone increasing and concave on p > p_min = max(-p_inf_L, -p_inf_R) (the
pressure at which the weaker side's density reaches zero along its isentrope).
The root is found by Newton's method safeguarded by a bracket [p_min, p_hi]
(bisection whenever a Newton step leaves the bracket), started from the PVRS
guess or, if that falls outside the bracket, the two-rarefaction (TRRS) guess;
converged when |dp| <= tol (p - p_min) with tol = 1e-14 by default.

Vacuum.  If G(p_min) >= 0 no star state with positive pressures (positive
pbar on both sides) exists: the waves open a zero-density region (for ideal gases
this is Toro's pressure positivity condition
(Delta u)_crit = 2 c_L/(gamma_L - 1) + 2 c_R/(gamma_R - 1) <= u_R - u_L).
The solution returned is then two rarefactions into vacuum: each side
rarefies to p_min, the side(s) whose p_inf is the smaller one reach zero density at
the escape front u_L + 2 c_L/(gamma_L - 1) (resp. u_R - 2 c_R/(gamma_R - 1));
if p_inf differs, the other side stops at p_min with positive density and is
bounded by a contact.  Between the two edges the state is the vacuum state
(rho, u, p, e) = (0, 0, p_min, 0) (u and e are undefined there; 0 is a
convention so that rho u and rho e integrate to 0).  A side given with rho = 0 is
an initial vacuum (Toro ch. 4.6): the other side rarefies into it.

Public API: :class:`RiemannSolution`.  Any other EOS of the background (Mie-Grueneisen, JWL):
:class:`solvers.ale.exact.riemann_eos.EosRiemannSolution` (the same interface, no vacuum).
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

__all__ = ["RiemannSolution"]

# left-to-right order of the waves (breaks ties between coincident positions)
_WAVE_ORDER = ("left_shock", "left_rarefaction_head", "left_rarefaction_tail", "contact", "vacuum_left",
               "vacuum_right", "right_rarefaction_tail", "right_rarefaction_head", "right_shock")


def wave_regions(xi: np.ndarray, speeds: Mapping) -> tuple[np.ndarray, np.ndarray]:
    """(star, fan) masks of the samples xi = (x - x0) / t on one side, measured away from the
    contact (xi grows towards the contact), from the side's wave speeds: behind a shock or the
    rarefaction's tail lies the star state, between the fan's head and tail the fan."""
    if "shock" in speeds:
        return xi >= speeds["shock"], np.zeros(xi.shape[0], dtype=bool)
    star = xi >= speeds["rarefaction_tail"]
    return star, (xi >= speeds["rarefaction_head"]) & ~star


class _Side:
    """Constant initial state of one side with its stiffened-gas EOS."""

    def __init__(self, state, gamma, p_inf, name):
        try:
            rho, u, p = (float(v) for v in state)
        except (TypeError, ValueError):
            raise ValueError(f"{name} state must be (rho, u, p), got {state!r}") from None
        gamma = float(gamma)
        p_inf = float(p_inf)
        if not (math.isfinite(rho) and math.isfinite(u) and math.isfinite(p)):
            raise ValueError(f"{name} state must be finite, got {(rho, u, p)}")
        if not gamma > 1.0 or not math.isfinite(gamma):
            raise ValueError(f"gamma ({name}) must be > 1, got {gamma}")
        if not p_inf >= 0.0 or not math.isfinite(p_inf):
            raise ValueError(f"p_inf ({name}) must be >= 0, got {p_inf}")
        if rho < 0.0:
            raise ValueError(f"{name} density must be >= 0, got {rho}")
        self.rho, self.u, self.p, self.gamma, self.p_inf = rho, u, p, gamma, p_inf
        self.vacuum = rho == 0.0
        if self.vacuum:
            self.pbar = 0.0
            self.c = 0.0
            return
        self.pbar = p + p_inf
        if not self.pbar > 0.0:
            raise ValueError(f"{name} state needs p + p_inf > 0 (got p={p}, p_inf={p_inf})")
        self.c = math.sqrt(gamma * self.pbar / rho)
        self.A = 2.0 / ((gamma + 1.0) * rho)
        self.B = (gamma - 1.0) / (gamma + 1.0) * self.pbar
        self.z = (gamma - 1.0) / (2.0 * gamma)
        self.escape = 2.0 * self.c / (gamma - 1.0)      # u change when rarefying to zero density

    # ------------------------------------------------------------------ pressure function
    def f(self, p):
        """Toro's f_K(p) and its derivative for star pressure p (shifted EOS)."""
        pb = p + self.p_inf
        if p > self.p:                                    # shock
            q = math.sqrt(self.A / (pb + self.B))
            return (p - self.p) * q, q * (1.0 - 0.5 * (p - self.p) / (pb + self.B))
        if pb <= 0.0:                                     # full expansion to zero density
            return -self.escape, math.inf
        r = pb / self.pbar
        return (self.escape * (r ** self.z - 1.0),
                r ** (-(self.gamma + 1.0) / (2.0 * self.gamma)) / (self.rho * self.c))

    # ------------------------------------------------------------------ star state of this side
    def star_density(self, p):
        if self.vacuum:
            return 0.0
        pb = p + self.p_inf
        if pb <= 0.0:
            return 0.0
        r = pb / self.pbar
        if p > self.p:                                    # shock (Hugoniot in pbar)
            k = (self.gamma - 1.0) / (self.gamma + 1.0)
            return self.rho * (r + k) / (k * r + 1.0)
        return self.rho * r ** (1.0 / self.gamma)         # isentrope

    def star_sound_speed(self, p, rho_star):
        if rho_star <= 0.0:
            return 0.0
        return math.sqrt(self.gamma * (p + self.p_inf) / rho_star)


class RiemannSolution:
    """Exact solution of the Riemann problem for the stiffened-gas Euler equations.

    Parameters
    ----------
    left, right : (rho, u, p)
        Initial states (SI units).  rho = 0 marks an initial vacuum.
    gamma_l, gamma_r : float
        Ratios of specific heats (``gamma_r`` defaults to ``gamma_l``).
    p_inf_l, p_inf_r : float
        Stiffened-gas constants (0 = ideal gas).
    tol : float
        Relative convergence tolerance on p* - p_min of the Newton iteration.

    Attributes
    ----------
    p_star, u_star, rho_star_l, rho_star_r : float
        Star pressure, contact velocity and the densities on either side of the
        contact.  With a vacuum, ``p_star`` is p_min, ``u_star`` is nan and
        ``u_star_l`` / ``u_star_r`` are the velocities of the two edges of the
        zero-density region.
    u_star_l, u_star_r : float
        Velocities at the left/right edge of the star region (equal unless vacuum).
    vacuum : bool
        True if the solution contains a zero-density region.
    left_wave, right_wave : str
        ``"shock"``, ``"rarefaction"`` or ``"none"`` (initial-vacuum side).
    iterations : int
        Newton iterations used.
    """

    def __init__(self, left, right, gamma_l, gamma_r=None, p_inf_l=0.0, p_inf_r=0.0, *,
                 tol=1e-14, max_iter=200):
        if gamma_r is None:
            gamma_r = gamma_l
        L = self._L = _Side(left, gamma_l, p_inf_l, "left")
        R = self._R = _Side(right, gamma_r, p_inf_r, "right")
        self.gamma_l, self.gamma_r = L.gamma, R.gamma
        self.p_inf_l, self.p_inf_r = L.p_inf, R.p_inf
        self.left, self.right = (L.rho, L.u, L.p), (R.rho, R.u, R.p)
        self.iterations = 0
        if L.vacuum and R.vacuum:
            raise ValueError("both states are vacuum")
        if L.vacuum or R.vacuum:
            self._initial_vacuum()
            return
        self._p_min = max(-L.p_inf, -R.p_inf) + 0.0      # (+0.0: no negative zero)
        du = R.u - L.u
        g_min = L.f(self._p_min)[0] + R.f(self._p_min)[0] + du
        if g_min >= 0.0:
            self._generated_vacuum()
            return
        self.vacuum = False
        p = self._solve(tol, max_iter)
        self.p_star = p
        fl, fr = L.f(p)[0], R.f(p)[0]
        self.u_star = 0.5 * (L.u + R.u) + 0.5 * (fr - fl)
        self.u_star_l = self.u_star_r = self.u_star
        self.p_star_l = self.p_star_r = p
        self.left_wave = "shock" if p > L.p else "rarefaction"
        self.right_wave = "shock" if p > R.p else "rarefaction"
        self.rho_star_l = L.star_density(p)
        self.rho_star_r = R.star_density(p)

    # ------------------------------------------------------------------ vacuum cases
    def _generated_vacuum(self):
        L, R = self._L, self._R
        pm = self._p_min
        self.vacuum = True
        self.p_star = self.p_star_l = self.p_star_r = pm
        self.u_star = math.nan
        self.u_star_l = L.u - L.f(pm)[0]
        self.u_star_r = R.u + R.f(pm)[0]
        self.left_wave = "shock" if pm > L.p else "rarefaction"
        self.right_wave = "shock" if pm > R.p else "rarefaction"
        self.rho_star_l = L.star_density(pm)
        self.rho_star_r = R.star_density(pm)

    def _initial_vacuum(self):
        L, R = self._L, self._R
        self.vacuum = True
        self.u_star = math.nan
        if R.vacuum:
            self._p_min = -L.p_inf
            self.u_star_l, self.u_star_r = L.u + L.escape, math.inf
            self.left_wave, self.right_wave = "rarefaction", "none"
        else:
            self._p_min = -R.p_inf
            self.u_star_l, self.u_star_r = -math.inf, R.u - R.escape
            self.left_wave, self.right_wave = "none", "rarefaction"
        self.p_star = self.p_star_l = self.p_star_r = self._p_min
        self.rho_star_l = self.rho_star_r = 0.0

    # ------------------------------------------------------------------ star pressure
    def _G(self, p):
        fl, dl = self._L.f(p)
        fr, dr = self._R.f(p)
        return fl + fr + (self._R.u - self._L.u), dl + dr

    def _guess(self, lo, hi):
        L, R = self._L, self._R
        ppv = 0.5 * (L.p + R.p) - 0.125 * (R.u - L.u) * (L.rho + R.rho) * (L.c + R.c)
        if lo < ppv < hi:
            return ppv
        if L.gamma == R.gamma and L.p_inf == R.p_inf:     # two-rarefaction guess (exact if both rarefy)
            z = L.z
            num = L.c + R.c - 0.5 * (L.gamma - 1.0) * (R.u - L.u)
            if num > 0.0:
                den = L.c / L.pbar ** z + R.c / R.pbar ** z
                p = (num / den) ** (1.0 / z) - L.p_inf
                if lo < p < hi:
                    return p
        return lo + 0.5 * (hi - lo)

    def _solve(self, tol, max_iter):
        L, R = self._L, self._R
        lo = self._p_min                                   # G(lo) < 0 (checked by the caller)
        hi = max(L.p, R.p)
        while self._G(hi)[0] < 0.0:                        # G is increasing: expand the bracket
            hi = lo + 4.0 * (hi - lo)
            if not math.isfinite(hi):
                raise RuntimeError("could not bracket the star pressure")
        p = self._guess(lo, hi)
        for it in range(1, max_iter + 1):
            g, dg = self._G(p)
            if g == 0.0:
                break
            if g < 0.0:
                lo = p
            else:
                hi = p
            p_new = p - g / dg if math.isfinite(dg) and dg > 0.0 else math.nan
            if abs(p_new - p) <= tol * (p - self._p_min):  # Newton step below tolerance: converged
                p = min(max(p_new, lo), hi)
                break
            if not lo < p_new < hi:
                p_new = 0.5 * (lo + hi)
            p = p_new
            if hi - lo <= tol * (lo - self._p_min):
                break
        else:
            raise RuntimeError(f"star pressure did not converge in {max_iter} iterations")
        self.iterations = it
        return p

    # ------------------------------------------------------------------ wave speeds
    def _side_speeds(self, side, sign):
        """Wave speeds of one side in the frame where the side is 'left' (sign=+1 left, -1 right)."""
        S = side
        if S.vacuum:
            return {}
        u, ust = sign * S.u, sign * (self.u_star_l if sign > 0 else self.u_star_r)
        pst = self.p_star_l if sign > 0 else self.p_star_r
        rst = self.rho_star_l if sign > 0 else self.rho_star_r
        if pst > S.p:
            r = (pst + S.p_inf) / S.pbar
            s = u - S.c * math.sqrt((S.gamma + 1.0) / (2.0 * S.gamma) * r + (S.gamma - 1.0) / (2.0 * S.gamma))
            return {"shock": s}
        return {"rarefaction_head": u - S.c, "rarefaction_tail": ust - S.star_sound_speed(pst, rst)}

    def speeds(self):
        """Wave speeds (dict, keys as in :meth:`waves`, ordered left to right)."""
        out = {}
        for name, side, sign in (("left", self._L, 1.0), ("right", self._R, -1.0)):
            for k, v in self._side_speeds(side, sign).items():
                out[f"{name}_{k}"] = sign * v
        if self.vacuum:
            if math.isfinite(self.u_star_l):
                out["vacuum_left"] = self.u_star_l
            if math.isfinite(self.u_star_r):
                out["vacuum_right"] = self.u_star_r
        else:
            out["contact"] = self.u_star
        return dict(sorted(out.items(), key=lambda kv: (kv[1], _WAVE_ORDER.index(kv[0]))))

    def waves(self, t, x0=0.0):
        """Wave positions at time t for a discontinuity initially at x0.

        Keys (whichever exist): ``left_shock`` | ``left_rarefaction_head``,
        ``left_rarefaction_tail``; ``contact`` (or ``vacuum_left``, ``vacuum_right``,
        the edges of the zero-density region); ``right_shock`` |
        ``right_rarefaction_tail``, ``right_rarefaction_head``.  Ordered by position.
        """
        return {k: x0 + s * t for k, s in self.speeds().items()}

    # ------------------------------------------------------------------ sampling
    def _sample_side(self, side, sign, xi):
        """Sample one side on xi (already restricted to that side) in the mirrored frame."""
        S = side
        n = xi.shape[0]
        rho = np.full(n, S.rho)
        u = np.full(n, sign * S.u)
        pb = np.full(n, S.pbar)
        if S.vacuum or n == 0:
            return rho, u, pb - S.p_inf
        ust = sign * (self.u_star_l if sign > 0 else self.u_star_r)
        pst = self.p_star_l if sign > 0 else self.p_star_r
        rst = self.rho_star_l if sign > 0 else self.rho_star_r
        sp = self._side_speeds(S, sign)
        star, fan = wave_regions(xi, sp)
        rho[star] = rst
        u[star] = ust
        pb[star] = pst + S.p_inf
        if fan.any():
            g = S.gamma
            x = xi[fan]
            base = 2.0 / (g + 1.0) + (g - 1.0) / ((g + 1.0) * S.c) * (sign * S.u - x)
            base = np.maximum(base, 0.0)
            rho[fan] = S.rho * base ** (2.0 / (g - 1.0))
            u[fan] = 2.0 / (g + 1.0) * (S.c + 0.5 * (g - 1.0) * sign * S.u + x)
            pb[fan] = S.pbar * base ** (2.0 * g / (g - 1.0))
        return rho, u, pb - S.p_inf

    def sample(self, x, t, x0=0.0):
        """Solution at positions x (array) and time t >= 0 for a discontinuity at x0.

        Returns (rho, u, p, e) as float arrays of the shape of x, where
        e = (p + gamma p_inf) / ((gamma - 1) rho) with the EOS of the side the
        point belongs to (e = 0 where rho = 0).  At t = 0 the initial data are
        returned (x < x0 left, x >= x0 right).
        """
        x = np.asarray(x, dtype=float)
        shape = x.shape
        x = x.ravel()
        t = float(t)
        if t < 0.0:
            raise ValueError("t must be >= 0")
        if t == 0.0:
            left = x < x0
            L, R = self._L, self._R
            rho = np.where(left, L.rho, R.rho)
            u = np.where(left, L.u, R.u)
            p = np.where(left, L.p, R.p)
            with np.errstate(divide="ignore", invalid="ignore"):
                e = np.where(left, (L.p + L.gamma * L.p_inf) / ((L.gamma - 1.0) * L.rho) if L.rho > 0 else 0.0,
                             (R.p + R.gamma * R.p_inf) / ((R.gamma - 1.0) * R.rho) if R.rho > 0 else 0.0)
            return rho.reshape(shape), u.reshape(shape), p.reshape(shape), e.reshape(shape)
        xi = (x - x0) / t
        rho = np.zeros_like(x)
        u = np.zeros_like(x)
        p = np.full_like(x, self._p_min if self.vacuum else 0.0)
        e = np.zeros_like(x)
        is_l = xi <= self.u_star_l
        is_r = (xi >= self.u_star_r) & ~is_l
        for side, sign, m in ((self._L, 1.0, is_l), (self._R, -1.0, is_r)):
            r_, u_, p_ = self._sample_side(side, sign, sign * xi[m])
            rho[m], u[m], p[m] = r_, sign * u_, p_
            with np.errstate(divide="ignore", invalid="ignore"):
                e_ = (p_ + side.gamma * side.p_inf) / ((side.gamma - 1.0) * r_)
            e[m] = np.where(r_ > 0.0, e_, 0.0)
        return rho.reshape(shape), u.reshape(shape), p.reshape(shape), e.reshape(shape)

    def __repr__(self):
        return (f"RiemannSolution(p_star={self.p_star!r}, u_star={self.u_star!r}, "
                f"rho_star_l={self.rho_star_l!r}, rho_star_r={self.rho_star_r!r}, vacuum={self.vacuum})")
