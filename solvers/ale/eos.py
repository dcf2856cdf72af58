"""Equations of state of the ALE background solver (SI units).

Every material is described by an integer model code and a flat float64 parameter
vector ``par`` of length ``NPAR`` built by :func:`eos_params`.  The numba functions
work on scalars (no allocation); :func:`eos_update` is the array kernel of the
hydro step.  ``rho`` is the density (kg/m^3), ``e`` the specific internal energy
(J/kg), ``p`` the pressure (Pa), ``c`` the sound speed (m/s).

Models and parameter layout (unused entries are zero)::

    code  name            index constants                  pressure p(rho, e)
    ----  --------------  -------------------------------  -----------------------------------------
     0    ideal_gas       IG_GAMMA=0                       (gamma - 1) rho e
     1    stiffened_gas   SG_GAMMA=0, SG_PINF=1            (gamma - 1) rho e - gamma p_inf
     2    tait            TAIT_RHO0=0, TAIT_K0=1,          p0 + K0/n ((rho/rho0)^n - 1)
                          TAIT_N=2, TAIT_P0=3              (barotropic: e is carried, not used)
     3    jwl             JWL_A=0, JWL_B=1, JWL_R1=2,      A (1 - w/(R1 V)) exp(-R1 V)
                          JWL_R2=3, JWL_OMEGA=4,           + B (1 - w/(R2 V)) exp(-R2 V) + w rho e,
                          JWL_RHO0=5                       V = rho0/rho (Lee-Tarver form, e per unit mass)
     4    mie_gruneisen   MG_RHO0=0, MG_C0=1, MG_S=2,      p_H(eta) + Gamma0 rho0 (e - e_H(eta)), eta = 1 - rho0/rho,
                          MG_GAMMA0=3                      p_H = rho0 c0^2 eta / (1 - s eta)^2, e_H = p_H eta / (2 rho0)
                                                           (the linear us = c0 + s up Hugoniot from rest at p = e = 0
                                                           as the reference curve, Gamma rho = Gamma0 rho0; invalid
                                                           at eta >= 1/s). In tension (eta < 0) the linear form
                                                           rho0 c0^2 mu + Gamma0 rho0 e, mu = rho/rho0 - 1, as
                                                           LS-DYNA's *EOS_GRUNEISEN (the Hugoniot form's dp_H/deta
                                                           turns negative at eta < -1/s: c^2 < 0 in an expanded
                                                           zone); MG_PC=4: pressure_cutoff (p >= it; -inf: none)

Sound speed: ``c^2 = dp/drho|_e + p/rho^2 dp/de`` (the isentropic derivative
``dp/drho|_s``, since ``de = p/rho^2 drho`` along an isentrope).  Closed forms:

* ideal / stiffened gas: ``c^2 = gamma (p + p_inf) / rho`` (``p_inf = 0`` for the ideal gas);
* Tait: ``c^2 = K0/rho0 (rho/rho0)^(n-1)``;
* JWL, with ``s_i = R_i V``: ``dp/drho|_e = sum_i A_i exp(-s_i) (s_i - w - w/s_i) / rho + w e``,
  ``dp/de = w rho``, so ``c^2 = dp/drho|_e + w p / rho``.
* Mie-Grueneisen: ``deta/drho = rho0/rho^2``, ``dp_H/deta = rho0 c0^2 (1 + s eta)/(1 - s eta)^3``,
  ``de_H/deta = (p_H + eta dp_H/deta)/(2 rho0)``, ``dp/de = Gamma0 rho0``, so
  ``c^2 = rho0/rho^2 (dp_H/deta - Gamma0 rho0 de_H/deta) + Gamma0 rho0 p / rho^2``; in tension
  ``c^2 = c0^2 + Gamma0 rho0 p / rho^2``.  A zone held at its ``pressure_cutoff`` (LS-DYNA's PC
  of *MAT_NULL: the material gives way in tension instead of pulling) keeps the sound speed of
  the uncut form at the cut pressure (its derivatives with the cut p), so its step stays bounded.

The ideal/stiffened-gas and JWL formulas use the pressure passed in (it must be the
pressure of the same state, as returned by :func:`pressure`); Tait ignores it.

Validity: a state is *valid* when ``rho > 0``, ``rho``, ``e``, ``p`` and ``c^2`` are
finite and ``c^2 > 0``.  Invalid examples: ``rho <= 0`` or NaN, a stiffened gas in
tension at or beyond ``p = -p_inf``, an ideal gas with ``e <= 0``.  For ``rho`` not
in ``(0, inf)`` (including NaN) every scalar function returns NaN (never raises).

``energy_from_pressure`` inverts ``p(rho, e)`` for ``e`` (initial conditions given by
density and pressure).  For the barotropic Tait model ``p`` does not depend on ``e``;
it returns the isentropic compression energy
``e(rho) = int_rho0^rho p(r)/r^2 dr`` (zero at ``rho0``), which is the energy the
hydro step's ``de = -p dv`` carries, so kinetic + internal energy stays the
mechanical energy of the liquid.  The ``p`` argument is then not used.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numba import njit

IDEAL_GAS = 0
STIFFENED_GAS = 1
TAIT = 2
JWL = 3

MIE_GRUNEISEN = 4
VOID = -1  # the code of a material with eos = "void" (volume, no mass, energy or pressure: mixed.py)

EOS_CODES = {"ideal_gas": IDEAL_GAS, "stiffened_gas": STIFFENED_GAS, "tait": TAIT, "jwl": JWL,
             "mie_gruneisen": MIE_GRUNEISEN}
EOS_NAMES = {v: k for k, v in EOS_CODES.items()}

NPAR = 8

IG_GAMMA = 0

SG_GAMMA = 0
SG_PINF = 1

TAIT_RHO0 = 0
TAIT_K0 = 1
TAIT_N = 2
TAIT_P0 = 3

MG_RHO0 = 0
MG_C0 = 1
MG_S = 2
MG_GAMMA0 = 3
MG_PC = 4

JWL_A = 0
JWL_B = 1
JWL_R1 = 2
JWL_R2 = 3
JWL_OMEGA = 4
JWL_RHO0 = 5

# Keys of the material table that are not EOS parameters and are ignored.
IGNORED_KEYS = ("eos", "cavitation_pressure")  # (the solver reads the latter: solver._check_cavitation)


def _gt(lo):
    return (lambda v: v > lo), f"> {lo:g}"


def _ge(lo):
    return (lambda v: v >= lo), f">= {lo:g}"


def _le(hi):
    return (lambda v: v <= hi), f"<= {hi:g}"


_ANY = ((lambda v: True), "any finite real")

# name -> [(key, index, (predicate, allowed range text), default or None, unit)]
_SCHEMA = {
    "ideal_gas": [("gamma", IG_GAMMA, _gt(1.0), None, "")],
    "stiffened_gas": [("gamma", SG_GAMMA, _gt(1.0), None, ""),
                      ("p_inf", SG_PINF, _ge(0.0), None, "Pa")],
    "tait": [("rho0", TAIT_RHO0, _gt(0.0), None, "kg/m^3"),
             ("bulk_modulus", TAIT_K0, _gt(0.0), None, "Pa"),
             ("exponent", TAIT_N, _ge(1.0), None, ""),
             ("p0", TAIT_P0, _ANY, 0.0, "Pa")],
    "mie_gruneisen": [("rho0", MG_RHO0, _gt(0.0), None, "kg/m^3"),
                      ("c0", MG_C0, _gt(0.0), None, "m/s"),
                      ("s", MG_S, _ge(0.0), None, ""),
                      ("gamma0", MG_GAMMA0, _ge(0.0), None, ""),
                      ("pressure_cutoff", MG_PC, _le(0.0), -math.inf, "Pa")],
    "jwl": [("A", JWL_A, _ANY, None, "Pa"),
            ("B", JWL_B, _ANY, None, "Pa"),
            ("R1", JWL_R1, _gt(0.0), None, ""),
            ("R2", JWL_R2, _gt(0.0), None, ""),
            ("omega", JWL_OMEGA, _gt(0.0), None, ""),
            ("rho0", JWL_RHO0, _gt(0.0), None, "kg/m^3")],
}


def eos_params(name: str, props: Mapping) -> tuple[int, np.ndarray]:
    """Return ``(code, par)`` for the EOS ``name`` with the material-table keys ``props``.

    ``props`` may hold the ``eos`` key (ignored); every other key must belong to the
    model.  Missing keys (without a default), unknown keys, non-numeric, non-finite
    or out-of-range values raise ``ValueError`` naming the key and its allowed range.
    """
    if name not in _SCHEMA:
        raise ValueError(f"eos = {name!r}: unknown equation of state; allowed: {sorted(_SCHEMA)}")
    schema = _SCHEMA[name]
    if "density" in props and "rho0" not in props:   # (the case's one name for the reference density:
        props = {("rho0" if k == "density" else k): v for k, v in props.items()}   # orchestrator/schema/spellings.py)
    known = {k for k, *_ in schema}
    unknown = sorted(k for k in props if k not in known and k not in IGNORED_KEYS)
    if unknown:
        raise ValueError(f"eos {name!r}: unknown key(s) {unknown}; allowed keys: {[k for k, *_ in schema]}")
    par = np.zeros(NPAR, dtype=np.float64)
    for key, idx, (ok, allowed), default, unit in schema:
        if key not in props:
            if default is None:
                raise ValueError(f"eos {name!r}: missing key {key!r} (allowed range: {allowed})")
            par[idx] = default  # (a default may be -inf: "none")
            continue
        else:
            raw = props[key]
            if isinstance(raw, bool) or not isinstance(raw, (int, float, np.integer, np.floating)):
                raise ValueError(f"eos {name!r}: {key} = {raw!r} is not a number (allowed range: {allowed})")
            value = float(raw)
        if not (math.isfinite(value) and ok(value)):
            unit_txt = f" {unit}" if unit else ""
            raise ValueError(f"eos {name!r}: {key} = {value!r} out of range (allowed: {allowed}{unit_txt})")
        par[idx] = value
    return EOS_CODES[name], par


def describe(code: int, par: np.ndarray, rho: float | None = None, e: float | None = None) -> str:
    """Readable description of an EOS (and optionally of the state ``rho``, ``e``) for messages."""
    code = int(code)
    if code not in EOS_NAMES:
        return f"unknown eos code {code}"
    name = EOS_NAMES[code]
    items = ", ".join(f"{key}={par[idx]:.6g}" + (f" {unit}" if unit else "")
                      for key, idx, _, _, unit in _SCHEMA[name] if math.isfinite(par[idx]))
    text = f"{name}({items})"
    if rho is not None and e is not None:
        p = pressure(code, par, float(rho), float(e))
        c2 = sound_speed_squared(code, par, float(rho), float(e), p)
        text += f"; state rho={rho:.6g} kg/m^3, e={e:.6g} J/kg, p={p:.6g} Pa, c^2={c2:.6g} m^2/s^2"
    return text


# --------------------------------------------------------------------------------------
# numba scalar functions
# --------------------------------------------------------------------------------------


@njit(cache=True)
def _mg_reference(par, rho):
    """Mie-Grueneisen reference curve (the Hugoniot): (eta, p_H, e_H, dp_H/deta, de_H/deta); NaN at
    or beyond the compression limit eta = 1/s. In tension (eta < 0) the linear rho0 c0^2 mu, e_H = 0
    (mu = eta / (1 - eta)): the same value and slope at eta = 0."""
    rho0 = par[MG_RHO0]
    s = par[MG_S]
    eta = 1.0 - rho0 / rho
    if eta < 0.0:
        k = rho0 * par[MG_C0] * par[MG_C0]
        a = 1.0 - eta
        return eta, k * eta / a, 0.0, k / (a * a), 0.0
    d = 1.0 - s * eta
    if not d > 0.0:
        return eta, np.nan, np.nan, np.nan, np.nan
    k = rho0 * par[MG_C0] * par[MG_C0]
    ph = k * eta / (d * d)
    dph = k * (1.0 + s * eta) / (d * d * d)
    return eta, ph, ph * eta / (2.0 * rho0), dph, (ph + eta * dph) / (2.0 * rho0)


@njit(cache=True)
def pressure(code, par, rho, e):
    """p(rho, e); NaN unless 0 < rho < inf."""
    if not 0.0 < rho < math.inf:
        return np.nan
    if code == MIE_GRUNEISEN:
        _, ph, eh, _, _ = _mg_reference(par, rho)
        return max(ph + par[MG_GAMMA0] * par[MG_RHO0] * (e - eh), par[MG_PC])
    if code == IDEAL_GAS:
        return (par[IG_GAMMA] - 1.0) * rho * e
    if code == STIFFENED_GAS:
        g = par[SG_GAMMA]
        return (g - 1.0) * rho * e - g * par[SG_PINF]
    if code == TAIT:
        n = par[TAIT_N]
        return par[TAIT_P0] + par[TAIT_K0] / n * ((rho / par[TAIT_RHO0]) ** n - 1.0)
    if code == JWL:
        w = par[JWL_OMEGA]
        s1 = par[JWL_R1] * par[JWL_RHO0] / rho
        s2 = par[JWL_R2] * par[JWL_RHO0] / rho
        return (par[JWL_A] * (1.0 - w / s1) * math.exp(-s1)
                + par[JWL_B] * (1.0 - w / s2) * math.exp(-s2) + w * rho * e)
    return np.nan


@njit(cache=True)
def derivatives(code, par, rho, e):
    """(dp/drho at constant e, dp/de at constant rho); NaN unless 0 < rho < inf."""
    if not 0.0 < rho < math.inf:
        return np.nan, np.nan
    if code == IDEAL_GAS:
        g1 = par[IG_GAMMA] - 1.0
        return g1 * e, g1 * rho
    if code == STIFFENED_GAS:
        g1 = par[SG_GAMMA] - 1.0
        return g1 * e, g1 * rho
    if code == TAIT:
        rho0 = par[TAIT_RHO0]
        return par[TAIT_K0] / rho0 * (rho / rho0) ** (par[TAIT_N] - 1.0), 0.0
    if code == MIE_GRUNEISEN:
        _, _, _, dph, deh = _mg_reference(par, rho)
        g = par[MG_GAMMA0] * par[MG_RHO0]
        return par[MG_RHO0] / (rho * rho) * (dph - g * deh), g
    if code == JWL:
        w = par[JWL_OMEGA]
        s1 = par[JWL_R1] * par[JWL_RHO0] / rho
        s2 = par[JWL_R2] * par[JWL_RHO0] / rho
        dpdrho = ((par[JWL_A] * math.exp(-s1) * (s1 - w - w / s1)
                   + par[JWL_B] * math.exp(-s2) * (s2 - w - w / s2)) / rho + w * e)
        return dpdrho, w * rho
    return np.nan, np.nan


@njit(cache=True)
def sound_speed_squared(code, par, rho, e, p):
    """c^2 = dp/drho|_e + p/rho^2 dp/de (may be <= 0 for an invalid state; NaN unless 0 < rho < inf)."""
    if not 0.0 < rho < math.inf:
        return np.nan
    if code == IDEAL_GAS:
        return par[IG_GAMMA] * p / rho
    if code == STIFFENED_GAS:
        return par[SG_GAMMA] * (p + par[SG_PINF]) / rho
    if code == TAIT:
        rho0 = par[TAIT_RHO0]
        return par[TAIT_K0] / rho0 * (rho / rho0) ** (par[TAIT_N] - 1.0)
    if code == JWL:
        dpdrho, _ = derivatives(code, par, rho, e)
        return dpdrho + par[JWL_OMEGA] * p / rho
    if code == MIE_GRUNEISEN:
        dpdrho, dpde = derivatives(code, par, rho, e)
        return dpdrho + p / (rho * rho) * dpde
    return np.nan


@njit(cache=True)
def sound_speed(code, par, rho, e, p):
    """c = sqrt(c^2); NaN when c^2 is not > 0 or the state is otherwise undefined."""
    c2 = sound_speed_squared(code, par, rho, e, p)
    if c2 > 0.0:
        return math.sqrt(c2)
    return np.nan


@njit(cache=True)
def energy_from_pressure(code, par, rho, p):
    """e with p(rho, e) = p (Tait: isentropic compression energy from rho0, p unused)."""
    if not 0.0 < rho < math.inf:
        return np.nan
    if code == IDEAL_GAS:
        return p / ((par[IG_GAMMA] - 1.0) * rho)
    if code == STIFFENED_GAS:
        g = par[SG_GAMMA]
        return (p + g * par[SG_PINF]) / ((g - 1.0) * rho)
    if code == TAIT:
        rho0 = par[TAIT_RHO0]
        K0 = par[TAIT_K0]
        n = par[TAIT_N]
        x = rho / rho0
        # int_rho0^rho [p0 + K0/n ((r/rho0)^n - 1)] / r^2 dr
        e_p0 = par[TAIT_P0] * (1.0 / rho0 - 1.0 / rho)
        if n == 1.0:
            power = math.log(x)
        else:
            power = (x ** (n - 1.0) - 1.0) / (n - 1.0)
        return e_p0 + K0 / (n * rho0) * (power + 1.0 / x - 1.0)
    if code == JWL:
        w = par[JWL_OMEGA]
        s1 = par[JWL_R1] * par[JWL_RHO0] / rho
        s2 = par[JWL_R2] * par[JWL_RHO0] / rho
        cold = par[JWL_A] * (1.0 - w / s1) * math.exp(-s1) + par[JWL_B] * (1.0 - w / s2) * math.exp(-s2)
        return (p - cold) / (w * rho)
    if code == MIE_GRUNEISEN:
        _, ph, eh, _, _ = _mg_reference(par, rho)
        return eh + (p - ph) / (par[MG_GAMMA0] * par[MG_RHO0])
    return np.nan


@njit(cache=True)
def state(code, par, rho, e):
    """(p, c, valid) of one state; c is NaN when c^2 is not > 0."""
    p = pressure(code, par, rho, e)
    c2 = sound_speed_squared(code, par, rho, e, p)
    valid = (rho > 0.0 and math.isfinite(rho) and math.isfinite(e) and math.isfinite(p)
             and math.isfinite(c2) and c2 > 0.0)
    c = math.sqrt(c2) if c2 > 0.0 else np.nan
    return p, c, valid


# --------------------------------------------------------------------------------------
# array kernels
# --------------------------------------------------------------------------------------


@njit(cache=True)
def eos_update(code, par, rho, e, p_out, c_out):
    """p_out[i], c_out[i] from (rho[i], e[i]) over 1-D arrays; return the first invalid i or -1.

    Every entry is written (an invalid one gets whatever the formulas give, c = NaN when
    c^2 is not > 0); the caller raises on a return value >= 0.
    """
    bad = -1
    for i in range(rho.shape[0]):
        p, c, ok = state(code, par, rho[i], e[i])
        p_out[i] = p
        c_out[i] = c
        if not ok and bad < 0:
            bad = i
    return bad


@njit(cache=True)
def _state_kernel(code, par, rho, e, p_out, c_out, ok_out):
    for i in range(rho.shape[0]):
        p, c, ok = state(code, par, rho[i], e[i])
        p_out[i] = p
        c_out[i] = c
        ok_out[i] = ok


def thermodynamic_state(code: int, par: np.ndarray, rho, e) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised ``(p, c, valid)`` for broadcastable ``rho``, ``e`` (convenience, not for hot paths)."""
    r, en = np.broadcast_arrays(np.asarray(rho, dtype=np.float64), np.asarray(e, dtype=np.float64))
    shape = r.shape
    r = np.ascontiguousarray(r).reshape(-1)
    en = np.ascontiguousarray(en).reshape(-1)
    p = np.empty_like(r)
    c = np.empty_like(r)
    ok = np.empty(r.shape, dtype=np.bool_)
    _state_kernel(int(code), np.asarray(par, dtype=np.float64), r, en, p, c, ok)
    return p.reshape(shape), c.reshape(shape), ok.reshape(shape)
