"""Exact 1-D profiles of the cases that have one, keyed by the kind of the case's `[check]`.

A case whose `[check] kind` is registered here has an exact solution along one axis at any time
(`solvers.ale.exact`): `exact_profile(case, t)` returns it as an :class:`ExactProfile`, whose
`sample(x)` gives the fields under their output names (density, pressure, velocity = the component
along the axis, specific_internal_energy where the solution has it) at positions x on that axis.
Pictures (`orchestrator.view`) draw it beside the computed profile; the case checks
(`orchestrator.checks`) compare the same solutions with the run.  A new exact solution is one
function with `@register_profile("<check kind>")`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

PROFILES: dict[str, Callable[[dict, dict, float], "ExactProfile"]] = {}


def register_profile(kind: str):
    def deco(fn):
        PROFILES[kind] = fn
        return fn

    return deco


@dataclass(frozen=True)
class ExactProfile:
    axis: int  # 0, 1, 2: the axis the solution varies along
    label: str  # what to call it in a legend
    sample: Callable[[np.ndarray], dict[str, np.ndarray]]  # x on the axis -> {field: values}


def exact_profile(case: dict, t: float) -> ExactProfile | None:
    """The exact profile of the case at time t, or None if its check kind has none."""
    spec = case.get("check") or {}
    fn = PROFILES.get(spec.get("kind"))
    return fn(case, spec.get("params", {}) or {}, float(t)) if fn is not None else None


def _axis(params: dict) -> int:
    return "xyz".index(params.get("axis", "x"))


# ----------------------------------------------------------------------------------------------
def riemann_solution(params: dict):
    """The exact Riemann solution of a `riemann` check's params: stiffened gases (ideal: p_inf 0) in
    closed form, or the EOS tables `eos_left` (`eos_right`, default the left one) by the general-EOS
    solver (solvers.ale.exact.riemann_eos: Mie-Grueneisen, JWL, ...)."""
    from solvers.ale.exact.riemann import RiemannSolution

    if "eos_left" in params:
        from solvers.ale.exact.riemann_eos import EosRiemannSolution

        return EosRiemannSolution(tuple(params["left"]), tuple(params["right"]), dict(params["eos_left"]),
                                  dict(params.get("eos_right", params["eos_left"])))
    g_l = float(params["gamma_left"])
    return RiemannSolution(left=tuple(params["left"]), right=tuple(params["right"]), gamma_l=g_l,
                           gamma_r=float(params.get("gamma_right", g_l)),
                           p_inf_l=float(params.get("p_inf_left", 0.0)),
                           p_inf_r=float(params.get("p_inf_right", 0.0)))


@register_profile("riemann")
def _riemann(case: dict, params: dict, t: float) -> ExactProfile:
    ex = riemann_solution(params)
    x0 = float(params["x0"])

    def sample(x):
        rho, u, p, e = ex.sample(np.asarray(x, np.float64), t, x0)
        return {"density": rho, "velocity": u, "pressure": p, "specific_internal_energy": e}

    return ExactProfile(_axis(params), "exact (Riemann)", sample)


def piston_solution(case: dict):
    """(exact PistonShock, axis, x of the piston face at t = 0, +1 if the piston drives along +axis
    else -1) of a case with one `{ piston = { velocity } }` face, or of a piston given in the check's
    params (`piston_velocity`, `x_face`, `axis`; driving along +axis): a body immersed in the grid."""
    from solvers.ale.exact import piston as exact

    ale = case["ale"]
    params = (case.get("check") or {}).get("params", {})
    if "piston_velocity" in params:
        u_p = float(params["piston_velocity"])
        axis = "xyz".index(params.get("axis", "x"))
        lower = True
    else:
        faces = [(f, b["piston"]["velocity"]) for f, b in ale["boundaries"].items()
                 if isinstance(b, dict) and "piston" in b]
        if len(faces) != 1:
            raise ValueError(f"piston: needs exactly one piston face (found {len(faces)})")
        face, u_p = faces[0]
        axis = "xyz".index(face[0])
        lower = face.endswith("lower")
    region = ale["regions"][0]
    mat = dict(ale["materials"][region["material"]])
    if mat["eos"] == "tait":
        ex = exact.tait(u_p, mat["rho0"], mat["bulk_modulus"], mat["exponent"], mat.get("p0", 0.0),
                        rho0=region["density"])
    elif mat["eos"] == "mie_gruneisen":
        if region["density"] != mat["rho0"] or region["pressure"] != 0.0:
            raise ValueError("piston: a Mie-Grueneisen material must start at its reference state "
                             "(density = rho0, pressure = 0)")
        ex = exact.mie_gruneisen(u_p, mat["rho0"], mat["c0"], mat["s"])
    elif mat["eos"] in ("stiffened_gas", "ideal_gas"):
        ex = exact.stiffened_gas(u_p, region["density"], region["pressure"], mat["gamma"], mat.get("p_inf", 0.0))
    else:
        raise ValueError(f"piston: eos {mat['eos']!r} (needs tait, stiffened_gas, ideal_gas or mie_gruneisen)")
    g = ale["grid"]
    x_face = params.get("x_face", g["lower"][axis] if lower else g["upper"][axis])
    return ex, axis, float(x_face), 1.0 if lower else -1.0


@register_profile("piston")
def _piston(case: dict, params: dict, t: float) -> ExactProfile:
    ex, axis, x_face, sign = piston_solution(case)

    def sample(x):
        rho, u, p = ex.sample(sign * (np.asarray(x, np.float64) - x_face), t)
        return {"density": rho, "velocity": sign * u, "pressure": p}

    return ExactProfile(axis, "exact (piston shock)", sample)


def reflected_shock_solution(params: dict):
    from solvers.ale.exact.reflected_shock import ReflectedShock

    return ReflectedShock(tuple(params["ahead"]), float(params["gamma"]), mach=float(params["mach"]),
                          p_inf=float(params.get("p_inf", 0.0)))


@register_profile("reflected_shock")
def _reflected_shock(case: dict, params: dict, t: float) -> ExactProfile:
    ex = reflected_shock_solution(params)
    x0, x_wall = float(params["x_shock0"]), float(params["x_wall"])

    def sample(x):
        rho, u, p = ex.sample(np.asarray(x, np.float64), t, x0, x_wall)
        return {"density": rho, "velocity": u, "pressure": p}

    return ExactProfile(_axis(params), "exact (reflected shock)", sample)


def riemann_wall_solution(params: dict):
    """(exact Riemann solution, exact reflection of its right-going shock) of a `riemann_wall` check:
    the shock tube of a `riemann` check closed on the right by a wall at `x_wall`, the right state at
    rest. The shock that reaches the wall reflects as a plane shock into the gas behind it
    (Rankine-Hugoniot, solvers.ale.exact.reflected_shock); the solution is exact until the reflected
    shock meets the contact."""
    import math

    ex = riemann_solution(params)
    speeds = ex.speeds()
    if "right_shock" not in speeds:
        raise ValueError("riemann_wall: the Riemann problem has no right-going shock to reflect")
    rho_r, u_r, p_r = (float(v) for v in params["right"])
    if u_r != 0.0:
        raise ValueError(f"riemann_wall: the right state must be at rest (u = {u_r:g})")
    g = float(params.get("gamma_right", params["gamma_left"]))
    p_inf = float(params.get("p_inf_right", 0.0))
    c = math.sqrt(g * (p_r + p_inf) / rho_r)
    return ex, reflected_shock_solution({"ahead": (rho_r, p_r), "gamma": g, "p_inf": p_inf,
                                         "mach": speeds["right_shock"] / c})


def riemann_wall_sample(params: dict, x, t: float):
    """(rho, u, p) of the `riemann_wall` solution at positions x < x_wall, time t; ValueError once
    the reflected shock has reached the contact (no simple exact solution after that)."""
    ex, refl = riemann_wall_solution(params)
    x0, x_wall = float(params["x0"]), float(params["x_wall"])
    x = np.asarray(x, np.float64)
    rho, u, p, _ = ex.sample(x, t, x0)
    kind, xs = refl.shock_position(t, x0, x_wall)
    if kind == "reflected":
        if xs <= ex.waves(t, x0)["contact"]:
            raise ValueError(f"riemann_wall: at t = {t:.6g} the reflected shock has reached the contact")
        beyond = x > xs
        rho, u, p = rho.copy(), u.copy(), p.copy()
        rho[beyond], u[beyond], p[beyond] = refl.rho5, 0.0, refl.p5
    return rho, u, p


@register_profile("riemann_wall")
def _riemann_wall(case: dict, params: dict, t: float) -> ExactProfile:
    def sample(x):
        rho, u, p = riemann_wall_sample(params, x, t)
        beyond = np.asarray(x) > float(params["x_wall"])  # no gas there: nothing to draw
        return {k: np.where(beyond, np.nan, a) for k, a in (("density", rho), ("velocity", u), ("pressure", p))}

    return ExactProfile(_axis(params), "exact (Riemann, shock reflected by the wall)", sample)


@register_profile("bar_wave")
def _bar_wave(case: dict, params: dict, t: float) -> ExactProfile:
    """A bar along x struck at x = 0 (the bar_wave check): the elastic 1-D bar wave, front at c t with
    c = sqrt(E / rho) of the first body's material, behind it the compression `expected_amplitude`
    and the particle velocity amplitude / (rho c)."""
    body = case["lagrange"]["bodies"][0]
    mat = case["materials"][body["material"]]
    rho, c = float(mat["density"]), float(np.sqrt(mat["youngs_modulus"] / mat["density"]))
    amp = abs(float(params["expected_amplitude"]))

    def sample(x):
        behind = np.asarray(x, np.float64) < c * t
        return {"stress": np.where(behind, -amp, 0.0), "velocity": np.where(behind, amp / (rho * c), 0.0)}

    return ExactProfile(0, "exact (1-D bar wave)", sample)
