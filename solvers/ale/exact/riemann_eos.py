"""Exact Riemann solver for the 1D Euler equations with a general equation of state on each side.

Each side K of the initial discontinuity carries one EOS of the ALE background (solvers/ale/eos.py:
ideal gas, stiffened gas, Mie-Grueneisen, JWL; any model with dp/de > 0), given as the material
table of a case (``{"eos": "mie_gruneisen", "rho0": ..., "c0": ..., "s": ..., "gamma0": ...}``) or
as ``(code, par)`` of :func:`solvers.ale.eos.eos_params`.  The closed-form solver of the stiffened
gas (:mod:`solvers.ale.exact.riemann`) is the special case that has the wave curves in closed form;
here they are computed from the EOS functions p(rho, e), e(rho, p) and c^2(rho, e, p) themselves:

* shock (p > p_K): the post-shock density rho(p) is the root of the Rankine-Hugoniot energy
  condition (the Hugoniot of the state K)

      H(rho) = e(rho, p) - e_K - (p + p_K)/2 (1/rho_K - 1/rho) = 0,

  with e(rho, p) the EOS's energy inverse (``scipy.optimize.brentq`` on rho in (rho_K, rho_hi], H > 0
  at rho_K since dp/de > 0, rho_hi found by doubling the step, halving back where the EOS is invalid,
  e.g. beyond the Mie-Grueneisen compression limit).  Mass flux m^2 = (p - p_K)/(1/rho_K - 1/rho) and

      f_K(p) = (p - p_K)/m = sqrt((p - p_K)(1/rho_K - 1/rho)),       shock speed u_K -+ m/rho_K;

* rarefaction (p <= p_K): along the isentrope through K (de = p/rho^2 drho, i.e. drho/dp = 1/c^2 with
  the EOS's isentropic c^2 = dp/drho|_e + p/rho^2 dp/de, e = e(rho, p) on the way), the Riemann
  invariant u +- int dp/(rho c) is constant, so

      f_K(p) = int_{p_K}^{p} dp' / (rho c)         (negative),

  integrated as the ODE d(rho, f)/dp = (1/c^2, 1/(rho c)) from p_K (``scipy.integrate.solve_ivp``,
  DOP853, rtol 1e-13).  In the fan the state at xi = (x - x0)/t is the point of the isentrope with
  u -+ c = xi (a root in p on the ODE's dense output: bracketed by a table of 257 points of the fan,
  refined by regula falsi to round-off).

The star pressure is the root of G(p) = f_L(p) + f_R(p) + u_R - u_L (increasing in p; brentq, to
4 eps relative), bracketed by [min(p_L, p_R), max(p_L, p_R)] expanded downward / upward until G
changes sign; u* = (u_L + u_R)/2 + (f_R(p*) - f_L(p*))/2.  Vacuum (no star state down to the lowest
pressure the isentropes reach with a valid EOS state) is refused: use the closed-form solver for it.
A barotropic EOS (tait; Mie-Grueneisen with gamma0 = 0) is refused: the energy condition does not
determine its shocks.

Sides are mirrored as in :mod:`solvers.ale.exact.riemann`: the right side is solved as a left side
in the frame x -> -x, u -> -u.  Public API: :class:`EosRiemannSolution`, :class:`WaveCurve`.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from solvers.ale import eos as _eos
from solvers.ale.exact.riemann import wave_regions

__all__ = ["EosRiemannSolution", "WaveCurve"]

_RTOL = 4.0 * np.finfo(float).eps
_ODE_RTOL = 1e-13

_WAVE_ORDER = ("left_shock", "left_rarefaction_head", "left_rarefaction_tail", "contact",
               "right_rarefaction_tail", "right_rarefaction_head", "right_shock")


class _Pieces:
    """Dense output of an isentrope integrated in pieces (split at a kink of the EOS): ``sol(p)``
    from the piece whose pressure range holds p (pressures fall along the isentrope)."""

    def __init__(self, pieces):
        self.ends = [r.t[-1] for r in pieces[:-1]]
        self.sols = [r.sol for r in pieces]

    def sol(self, p):
        p = np.asarray(p, dtype=np.float64)
        out = self.sols[-1](p)
        for end, f in zip(reversed(self.ends), reversed(self.sols[:-1])):
            out = np.where(p >= end, f(p), out)
        return out


class _Invalid(Exception):
    """An EOS state without a finite pressure, energy or a positive c^2 on the way."""


def _eos_of(spec, name):
    if isinstance(spec, Mapping):
        if "eos" not in spec:
            raise ValueError(f"EOS ({name}): the table needs an 'eos' key, got {dict(spec)!r}")
        code, par = _eos.eos_params(str(spec["eos"]), spec)
    else:
        try:
            code, par = spec
        except (TypeError, ValueError):
            raise ValueError(f"EOS ({name}) must be a material table or (code, par), got {spec!r}") from None
        code, par = int(code), np.asarray(par, dtype=np.float64)
    if code == _eos.TAIT or (code == _eos.MIE_GRUNEISEN and par[_eos.MG_GAMMA0] == 0.0):
        raise ValueError(f"EOS ({name}) {_eos.describe(code, par)} is barotropic: the Rankine-Hugoniot "
                         "energy condition does not determine its shocks (not supported)")
    if code not in _eos.EOS_NAMES:
        raise ValueError(f"EOS ({name}): unknown eos code {code}")
    return code, par


class WaveCurve:
    """The states one side K = (rho, u, p) reaches by one wave: its Hugoniot (p > p_K) and its
    isentrope (p <= p_K), in the frame where K is the left side (``u`` as given)."""

    def __init__(self, state, eos, name="side"):
        try:
            rho, u, p = (float(v) for v in state)
        except (TypeError, ValueError):
            raise ValueError(f"{name} state must be (rho, u, p), got {state!r}") from None
        if not (math.isfinite(rho) and math.isfinite(u) and math.isfinite(p)):
            raise ValueError(f"{name} state must be finite, got {(rho, u, p)}")
        if not rho > 0.0:
            raise ValueError(f"{name} density must be > 0 (no vacuum with a general EOS), got {rho}")
        self.code, self.par = _eos_of(eos, name)
        self.name = name
        self.rho, self.u, self.p = rho, u, p
        self.e = float(_eos.energy_from_pressure(self.code, self.par, rho, p))
        _, dpde = _eos.derivatives(self.code, self.par, rho, self.e)
        c2 = _eos.sound_speed_squared(self.code, self.par, rho, self.e, p)
        if not (math.isfinite(self.e) and dpde > 0.0 and c2 > 0.0 and math.isfinite(c2)):
            raise ValueError(f"{name} state is not a valid state of "
                             f"{_eos.describe(self.code, self.par, rho, self.e)} (needs dp/de > 0, c^2 > 0)")
        self.c = math.sqrt(c2)
        self._cache = {}

    # ------------------------------------------------------------------ EOS at (rho, p)
    def energy(self, rho, p):
        return float(_eos.energy_from_pressure(self.code, self.par, rho, p))

    def sound_speed(self, rho, p):
        """c on the EOS at (rho, p); raises _Invalid if c^2 is not > 0 or not finite."""
        e = _eos.energy_from_pressure(self.code, self.par, rho, p)
        c2 = _eos.sound_speed_squared(self.code, self.par, rho, e, p)
        if not (c2 > 0.0 and math.isfinite(c2) and math.isfinite(e)):
            raise _Invalid(f"{self.name}: invalid state rho={rho!r}, p={p!r} (c^2={c2!r})")
        return math.sqrt(c2)

    # ------------------------------------------------------------------ shock
    def hugoniot_residual(self, rho, p):
        """H(rho) = e(rho, p) - e_K - (p + p_K)/2 (1/rho_K - 1/rho) (NaN where the EOS is invalid)."""
        return self.energy(rho, p) - self.e - 0.5 * (p + self.p) * (1.0 / self.rho - 1.0 / rho)

    def shock(self, p):
        """(rho, m) behind the shock from K to pressure p > p_K: the Hugoniot density and the mass flux."""
        p = float(p)
        if not p > self.p:
            raise ValueError(f"{self.name}: a shock needs p > p_K = {self.p!r}, got {p!r}")
        lo = self.rho
        if not self.hugoniot_residual(lo, p) > 0.0:
            raise _Invalid(f"{self.name}: H(rho_K) <= 0 at p={p!r}")
        step = max(self.rho * (p - self.p) / (self.rho * self.c * self.c), 1e-3 * self.rho)
        hi = lo + step
        for _ in range(400):
            h = self.hugoniot_residual(hi, p)
            if math.isfinite(h) and h < 0.0:
                break
            if math.isfinite(h):               # still below the Hugoniot density: go further
                lo, step = hi, 2.0 * step
            else:                              # invalid EOS state (compression limit): come back
                step = 0.5 * step
            hi = lo + step
        else:
            raise _Invalid(f"{self.name}: no Hugoniot density at p={p!r}")
        rho = brentq(self.hugoniot_residual, lo, hi, args=(p,), xtol=1e-300, rtol=_RTOL, maxiter=500)
        m = math.sqrt((p - self.p) / (1.0 / self.rho - 1.0 / rho))
        return rho, m

    # ------------------------------------------------------------------ rarefaction
    def _rhs(self, p, y):
        rho = y[0]
        if not rho > 0.0:
            raise _Invalid(f"{self.name}: density {rho!r} on the isentrope at p={p!r}")
        c = self.sound_speed(rho, p)
        return [1.0 / (c * c), 1.0 / (rho * c)]

    def isentrope(self, p, dense=False):
        """Integrate the isentrope from p_K to p <= p_K: (rho(p), f_K(p)) (and the solve_ivp result with
        dense output in p if ``dense``)."""
        p = float(p)
        if p == self.p:
            return (self.rho, 0.0, None) if dense else (self.rho, 0.0)
        atol = [1e-15 * self.rho, 1e-15 * self.c]
        kink = self.par[_eos.MG_RHO0] if self.code == _eos.MIE_GRUNEISEN else None
        events = None
        if kink is not None and self.rho > kink:
            # the Mie-Grueneisen form changes at rho0 (Hugoniot form / linear tension form: c(rho) is
            # continuous but not smooth there); a step across it would cost DOP853 its order
            def at_kink(_p, y):
                return y[0] - kink
            at_kink.terminal = True
            events = at_kink
        res = solve_ivp(self._rhs, (self.p, p), [self.rho, 0.0], method="DOP853", rtol=_ODE_RTOL,
                        atol=atol, dense_output=dense, events=events)
        pieces = [res]
        if res.status == 1 and res.t_events[0].size:
            p_k, y_k = float(res.t_events[0][0]), res.y_events[0][0]
            res = solve_ivp(self._rhs, (p_k, p), [float(y_k[0]), float(y_k[1])], method="DOP853",
                            rtol=_ODE_RTOL, atol=atol, dense_output=dense)
            pieces.append(res)
        if not res.success or not np.all(np.isfinite(res.y[:, -1])):
            raise _Invalid(f"{self.name}: isentrope to p={p!r} failed ({res.message})")
        rho, f = float(res.y[0, -1]), float(res.y[1, -1])
        return (rho, f, _Pieces(pieces) if len(pieces) > 1 else res) if dense else (rho, f)

    # ------------------------------------------------------------------ pressure function
    def f(self, p):
        """Toro's f_K(p): u* = u_K - f_K(p*) for the left side."""
        p = float(p)
        if p not in self._cache:
            if p > self.p:
                rho, m = self.shock(p)
                self._cache[p] = ((p - self.p) / m, rho)
            else:
                rho, f = self.isentrope(p)
                self._cache[p] = (f, rho)
        return self._cache[p][0]

    def star_density(self, p):
        self.f(p)
        return self._cache[float(p)][1]


class EosRiemannSolution:
    """Exact solution of the Riemann problem of the Euler equations, a general EOS on each side.

    Parameters
    ----------
    left, right : (rho, u, p)
        Initial states (SI units), rho > 0.
    eos_l, eos_r : mapping or (code, par)
        The EOS of each side: a material table as in case.toml (``{"eos": "mie_gruneisen", "rho0":
        2700.0, "c0": 5350.0, "s": 1.34, "gamma0": 2.0}``) or ``solvers.ale.eos.eos_params``'s
        ``(code, par)``.  ``eos_r`` defaults to ``eos_l``.

    Attributes (as :class:`solvers.ale.exact.riemann.RiemannSolution`)
    ----------
    p_star, u_star, rho_star_l, rho_star_r, e_star_l, e_star_r : float
    u_star_l, u_star_r, p_star_l, p_star_r : float  (equal: no vacuum)
    vacuum : False
    left_wave, right_wave : ``"shock"`` or ``"rarefaction"``
    iterations : int  (evaluations of G by the root finder)
    """

    vacuum = False

    def __init__(self, left, right, eos_l, eos_r=None):
        if eos_r is None:
            eos_r = eos_l
        L = self._L = WaveCurve(left, eos_l, "left")
        Rm = self._R = WaveCurve((right[0], -float(right[1]), right[2]), eos_r, "right")  # mirrored
        self.left, self.right = (L.rho, L.u, L.p), (Rm.rho, -Rm.u, Rm.p)
        self.eos_l, self.eos_r = (L.code, L.par), (Rm.code, Rm.par)
        self.iterations = 0
        p = self._solve()
        self.p_star = self.p_star_l = self.p_star_r = p
        fl, fr = L.f(p), Rm.f(p)
        ur = -Rm.u
        self.u_star = 0.5 * (L.u + ur) + 0.5 * (fr - fl)
        self.u_star_l = self.u_star_r = self.u_star
        self.left_wave = "shock" if p > L.p else "rarefaction"
        self.right_wave = "shock" if p > Rm.p else "rarefaction"
        self.rho_star_l, self.rho_star_r = L.star_density(p), Rm.star_density(p)
        self.e_star_l, self.e_star_r = L.energy(self.rho_star_l, p), Rm.energy(self.rho_star_r, p)
        self._fans = {}

    # ------------------------------------------------------------------ star pressure
    def _G(self, p):
        self.iterations += 1
        return self._L.f(p) + self._R.f(p) - self._R.u - self._L.u     # f_L + f_R + u_R - u_L

    def _G_or_none(self, p):
        try:
            g = self._G(p)
        except _Invalid:
            return None
        return g if math.isfinite(g) else None

    def _solve(self):
        L, R = self._L, self._R
        lo, hi = min(L.p, R.p), max(L.p, R.p)
        # pressure scale of a step: the spread of the data, or the acoustic pressure of the speed jump
        scale = max(hi - lo, max(L.rho * L.c, R.rho * R.c) * max(abs(-R.u - L.u), 1e-3 * min(L.c, R.c)))
        g_lo = self._G_or_none(lo)
        if g_lo is None or g_lo > 0.0:
            # g_lo > 0: two rarefactions below min(p_L, p_R), go down from there; None: an isentrope
            # does not reach min(p_L, p_R) with a valid state (JWL products at p = 0): come down
            # from max(p_L, p_R) to where it stays valid
            step, valid = (scale, lo) if g_lo is not None else (hi - lo, hi)
            invalid = None                     # the highest pressure found invalid
            for _ in range(400):
                cand = valid - step if invalid is None else 0.5 * (valid + invalid)
                g = self._G_or_none(cand)
                if g is None:                  # beyond where the isentropes stay valid: bisect back
                    invalid = cand
                    if valid - invalid <= 1e-8 * scale:
                        raise ValueError("no star state: the rarefactions open a vacuum or reach an invalid "
                                         "EOS state (not supported by the general-EOS solver)")
                    continue
                if g <= 0.0:
                    lo, g_lo, hi = cand, g, valid
                    break
                valid = cand
                step *= 2.0
            else:
                raise RuntimeError("could not bracket the star pressure from below")
        if g_lo == 0.0:
            return lo
        g_hi = self._G(hi)
        step = scale
        while g_hi < 0.0:                      # shocks above max(p_L, p_R): go up
            lo, hi = hi, hi + step
            step *= 2.0
            g_hi = self._G(hi)
            if not math.isfinite(hi):
                raise RuntimeError("could not bracket the star pressure from above")
        if g_hi == 0.0:
            return hi
        return brentq(self._G, lo, hi, xtol=1e-300, rtol=_RTOL, maxiter=500)

    # ------------------------------------------------------------------ wave speeds
    def _side_speeds(self, S, sign):
        """Wave speeds of one side in the mirrored frame (sign +1 left, -1 right)."""
        ust = sign * self.u_star
        p = self.p_star
        if p > S.p:
            _, m = S.shock(p)
            return {"shock": S.u - m / S.rho}
        rst = self.rho_star_l if sign > 0 else self.rho_star_r
        return {"rarefaction_head": S.u - S.c, "rarefaction_tail": ust - S.sound_speed(rst, p)}

    def speeds(self):
        """Wave speeds (dict, keys as in :meth:`waves`, ordered left to right)."""
        out = {"contact": self.u_star}
        for name, side, sign in (("left", self._L, 1.0), ("right", self._R, -1.0)):
            for k, v in self._side_speeds(side, sign).items():
                out[f"{name}_{k}"] = sign * v
        return dict(sorted(out.items(), key=lambda kv: (kv[1], _WAVE_ORDER.index(kv[0]))))

    def waves(self, t, x0=0.0):
        """Wave positions at time t for a discontinuity initially at x0 (keys as the closed-form solver's)."""
        return {k: x0 + s * t for k, s in self.speeds().items()}

    # ------------------------------------------------------------------ sampling
    def _fan(self, S, sign):
        """(the isentrope's dense output from p_K to p*, a table of p and xi = u - c on 257 points of
        [p*, p_K]; xi decreasing in p) of a rarefaction side (mirrored frame)."""
        if sign not in self._fans:
            sol = S.isentrope(self.p_star, dense=True)[2]
            pt = np.linspace(self.p_star, S.p, 257)
            pt[-1] = S.p
            _, u, c = self._fan_state(S, sol, pt)
            self._fans[sign] = (sol, pt, u - c)
        return self._fans[sign]

    @staticmethod
    def _fan_state(S, sol, p):
        """(rho, u, c) on the isentrope at pressures p (mirrored frame)."""
        rho, f = sol.sol(p)
        c = np.array([S.sound_speed(r, q) for r, q in zip(rho, p)])
        return rho, S.u - f, c

    def _fan_states(self, S, sign, xi):
        """(rho, u, p) in the fan at mirrored xi: the root in p of u(p) - c(p) = xi, bracketed by the
        table and refined by regula falsi (Illinois) to round-off."""
        sol, pt, xt = self._fan(S, sign)
        k = np.clip(np.searchsorted(-xt, -xi), 1, len(pt) - 1)
        a, b = pt[k - 1], pt[k]                  # g = u - c - xi: ga >= 0 >= gb
        ga, gb = xt[k - 1] - xi, xt[k] - xi
        p = a.copy()
        side = np.zeros(xi.shape)
        for _ in range(100):
            den = ga - gb
            c = np.where(den != 0.0, (b * ga - a * gb) / np.where(den != 0.0, den, 1.0), a)
            c = np.clip(c, np.minimum(a, b), np.maximum(a, b))
            done = np.abs(c - p) <= 4.0 * np.finfo(float).eps * np.maximum(np.abs(c), np.abs(S.p - self.p_star))
            p = c
            if done.all():
                break
            _, u, cs = self._fan_state(S, sol, c)
            gc = u - cs - xi
            to_b = gc * gb > 0.0                 # replaces b
            to_a = (gc * ga > 0.0) & ~to_b
            ga = np.where(to_b & (side == -1), 0.5 * ga, ga)
            gb = np.where(to_a & (side == 1), 0.5 * gb, gb)
            b, gb = np.where(to_b, c, b), np.where(to_b, gc, gb)
            a, ga = np.where(to_a, c, a), np.where(to_a, gc, ga)
            side = np.where(to_b, -1, np.where(to_a, 1, side))
            hit = ~to_a & ~to_b                  # gc == 0: c is the root
            a, b, ga, gb = np.where(hit, c, a), np.where(hit, c, b), np.where(hit, 0.0, ga), np.where(hit, 0.0, gb)
        rho, u, _ = self._fan_state(S, sol, p)
        return rho, u, p

    def _sample_side(self, S, sign, xi):
        n = xi.shape[0]
        rho, u, p = np.full(n, S.rho), np.full(n, S.u), np.full(n, S.p)
        if n == 0:
            return rho, u, p
        sp = self._side_speeds(S, sign)
        star, fan = wave_regions(xi, sp)
        rho[star] = self.rho_star_l if sign > 0 else self.rho_star_r
        u[star] = sign * self.u_star
        p[star] = self.p_star
        if fan.any():
            rho[fan], u[fan], p[fan] = self._fan_states(S, sign, xi[fan])
        return rho, u, p

    def sample(self, x, t, x0=0.0):
        """Solution (rho, u, p, e) at positions x (array) and time t >= 0 for a discontinuity at x0
        (e from each side's EOS).  At t = 0 the initial data (x < x0 left, x >= x0 right)."""
        x = np.asarray(x, dtype=float)
        shape = x.shape
        x = x.ravel()
        t = float(t)
        if t < 0.0:
            raise ValueError("t must be >= 0")
        L, R = self._L, self._R
        if t == 0.0:
            left = x < x0
            out = (np.where(left, L.rho, R.rho), np.where(left, L.u, -R.u), np.where(left, L.p, R.p),
                   np.where(left, L.e, R.e))
            return tuple(a.reshape(shape) for a in out)
        xi = (x - x0) / t
        rho, u, p, e = (np.zeros_like(x) for _ in range(4))
        is_l = xi <= self.u_star
        for side, sign, m in ((L, 1.0, is_l), (R, -1.0, ~is_l)):
            r_, u_, p_ = self._sample_side(side, sign, sign * xi[m])
            rho[m], u[m], p[m] = r_, sign * u_, p_
            e[m] = [side.energy(a, b) for a, b in zip(r_, p_)]
        return rho.reshape(shape), u.reshape(shape), p.reshape(shape), e.reshape(shape)

    def __repr__(self):
        return (f"EosRiemannSolution(p_star={self.p_star!r}, u_star={self.u_star!r}, "
                f"rho_star_l={self.rho_star_l!r}, rho_star_r={self.rho_star_r!r})")
