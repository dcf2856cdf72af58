"""Checks of compressible flow on the grid against exact solutions: Riemann problems (also at a
wall and as a reflected shock), Sedov's blast, positivity.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.fields import crossings, last_step, plateau, profile, zone_stations
from orchestrator.checks.registry import AXIS, STATE3, register_check
from orchestrator.schema.parts import number, table, vector


def _exact_eos():
    """An EOS table of the exact general-EOS Riemann solver: an [ale] material table without "void"
    or tait (barotropic: its shocks are not given by the energy condition)."""
    from orchestrator.schema.ale import FLUID

    return {**FLUID, "properties": {**FLUID["properties"],
                                    "eos": {"type": "string",
                                            "enum": ["ideal_gas", "stiffened_gas", "mie_gruneisen", "jwl"]}}}


_NOT_WITH_EOS = {"not": {}, "x-allowed": "not with eos_left (the EOS tables give both sides' EOS)"}


@register_check("riemann", params=table(
    {"axis": AXIS, "x0": number("m"), "left": STATE3, "right": STATE3, "gamma_left": number(exclusiveMinimum=1),
     "gamma_right": number(exclusiveMinimum=1), "p_inf_left": number("Pa", minimum=0),
     "p_inf_right": number("Pa", minimum=0), "eos_left": _exact_eos(), "eos_right": _exact_eos(),
     "plateau": {"type": "string", "enum": ["mean", "median"]},
     "interface_material": {"type": "string", "minLength": 1},
     "role": {"type": "string", "enum": ["ale", "sph"]}, "margin_cells": number(minimum=0)},
    required=("x0", "left", "right"),
    # the EOS of each side: gamma_left (gamma_right, p_inf_*: stiffened gas, closed form) or the
    # tables eos_left (eos_right, default eos_left: any EOS of the background, general solver)
    allOf=[{"if": {"required": ["eos_left"]},
            "then": {"properties": {k: _NOT_WITH_EOS for k in ("gamma_left", "gamma_right", "p_inf_left",
                                                               "p_inf_right")}},
            "else": {"required": ["gamma_left"]}},
           {"if": {"required": ["eos_right"]}, "then": {"required": ["eos_left"]}}]))
def riemann(case, out, history, params):
    """1-D Riemann problem on a grid (role "ale") or of particles (role "sph": stations one lattice
    spacing wide), against the exact solution (stiffened gas, ideal gas = p_inf 0; any EOS of the
    background with `eos_left` / `eos_right`, solvers.ale.exact.riemann_eos):
    star-state plateaus (zones more than `margin_cells` (4) cells inside the waves that bound them), the mean and the
    largest deviation of the pressure from the exact p* over the star region, shock and contact
    positions (in cells), L1 density error, and the positivity values of every output step
    (:func:`positivity`: near-vacuum problems)."""
    from orchestrator.exact_profiles import riemann_solution

    axis = "xyz".index(params.get("axis", "x"))
    x0 = float(params["x0"])
    ex = riemann_solution(params)
    role = params.get("role", "ale")
    t, _, index = last_step(out, role)
    prof = profile(case, out, role, index, axis)
    x = prof["x"]
    dx = float(np.diff(x).mean())
    w = ex.waves(t, x0)
    # plateaus start this many stations inside the waves that bound them (particles smear a wave over
    # a few smoothing lengths: an SPH case sets more)
    margin = float(params.get("margin_cells", 4)) * dx
    inner_l = w.get("left_rarefaction_tail", w.get("left_shock"))
    inner_r = w.get("right_rarefaction_tail", w.get("right_shock"))
    contact = w["contact"]
    # plateau value: the mean over the star region (or its median, `plateau = "median"`, where a
    # start-up wave crosses a stiff material: see cases/water_air_shock_tube)
    stat = params.get("plateau", "mean")
    vals = {
        "p_star": plateau(x, prof["p"], inner_l, inner_r, margin, stat),
        "u_star": plateau(x, prof["u"], inner_l, inner_r, margin, stat),
        "rho_star_left": plateau(x, prof["rho"], inner_l, contact, margin, stat),
        "rho_star_right": plateau(x, prof["rho"], contact, inner_r, margin, stat),
    }
    # the mean (whatever `plateau` says) and the largest deviation from the exact p* over the star
    # region: a start-up dip or a wiggle that a median would hide is bounded by these
    vals["p_star_mean"] = plateau(x, prof["p"], inner_l, inner_r, margin)
    star = (x > inner_l + margin) & (x < inner_r - margin)
    vals["p_star_max_deviation_rel"] = (float(np.max(np.abs(prof["p"][star] - ex.p_star))) / abs(ex.p_star)
                                        if star.any() else float("nan"))
    rho_ex = ex.sample(x, t, x0)[0]
    vals["l1_density"] = float(np.sum(np.abs(prof["rho"] - rho_ex)) * dx / (x[-1] - x[0] + dx))

    def crossing(level, near):
        """Position nearest `near` where the density profile crosses `level` (linear interpolation)."""
        k, xs = crossings(x, prof["rho"], level)
        if len(k) == 0:
            return float("nan")
        return float(xs[np.argmin(np.abs(xs - near))])

    if "right_shock" in w:
        level = 0.5 * (ex.rho_star_r + params["right"][0])
        vals["shock_position_error_cells"] = abs(crossing(level, w["right_shock"]) - w["right_shock"]) / dx
    elif "left_shock" in w:
        level = 0.5 * (ex.rho_star_l + params["left"][0])
        vals["shock_position_error_cells"] = abs(crossing(level, w["left_shock"]) - w["left_shock"]) / dx
    if ex.rho_star_l != ex.rho_star_r:
        level = 0.5 * (ex.rho_star_l + ex.rho_star_r)
        vals["contact_position_error_cells"] = abs(crossing(level, contact) - contact) / dx
    if "interface_material" in params:
        # two materials: where the left material's volume fraction crosses 1/2, and the largest
        # pressure deviation from p* over the star region (both sides of the interface)
        f = prof[f"volume_fraction_{params['interface_material']}"]
        k, xs = crossings(x, f, 0.5)
        if len(k):
            vals["interface_position_error_cells"] = float(np.min(np.abs(xs - contact))) / dx
        else:
            vals["interface_position_error_cells"] = float("nan")
        near = (np.abs(x - contact) < 5 * dx) & (x > inner_l + margin) & (x < inner_r - 2 * dx)
        vals["interface_pressure_oscillation_rel"] = float(np.max(np.abs(prof["p"][near] - ex.p_star))) / abs(ex.p_star)
    # every output step: positive density and energy, nothing non-finite (near-vacuum problems)
    if role == "ale":
        vals.update(positivity(case, out, history, params))
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("sedov", params=table(
    {"symmetry_factor": number(exclusiveMinimum=0), "geometry": {"type": "integer", "enum": [1, 2, 3]},
     "rho0": number("kg/m^3", exclusiveMinimum=0), "gamma": number(exclusiveMinimum=1), "centre": vector("m")},
    required=("rho0", "gamma")))
def sedov(case, out, history, params):
    """Point blast: shock radius (outer half-height of the density jump, zones binned by radius from
    `centre`) against the Kamm & Timmes semi-analytic solution; E0 of the full-space problem is the
    deposited energy times `symmetry_factor` (4 for a quarter plane, 8 for an octant); the L1 density
    error of the zones against the exact profile at their centres, relative to the mass."""
    from orchestrator import output
    from solvers.ale.exact.sedov import SedovSolution

    ale = case["ale"]
    dim = ale["dimension"]
    deposited = sum(e["energy"] for e in ale["energy_sources"])
    e_full = deposited * float(params.get("symmetry_factor", 1.0))
    geometry = int(params.get("geometry", dim))
    rho0 = float(params["rho0"])
    gamma = float(params["gamma"])
    ex = SedovSolution(e_full, rho0, gamma, geometry)
    t, _, index = last_step(out, "ale")
    cells, _ = output.read_mesh_file(out, "ale")
    points, _, cd = output.read_step(out, "ale", index)
    centre = np.asarray(params.get("centre", [0.0] * dim) + [0.0] * (3 - dim))
    r = np.linalg.norm(points[cells].mean(axis=1) - centre, axis=1)
    h = float(np.ptp(points[:, 0])) / ale["grid"]["cells"][0]
    bins = np.arange(0.0, r.max() + h, h)
    k = np.digitize(r, bins) - 1
    count = np.bincount(k, minlength=len(bins))
    rho_bin = np.bincount(k, weights=cd["density"], minlength=len(bins)) / np.maximum(count, 1)
    peak = int(np.argmax(rho_bin))
    half = rho0 + 0.5 * (rho_bin[peak] - rho0)
    outer = peak + int(np.argmax(rho_bin[peak:] < half))
    # interpolate the half-height crossing between bin centres outer-1 and outer
    rc = bins + 0.5 * h
    r0, r1, a0, a1 = rc[outer - 1], rc[outer], rho_bin[outer - 1], rho_bin[outer]
    r_shock = r0 + (half - a0) * (r1 - r0) / (a1 - a0) if a1 != a0 else r0
    # L1 density error against the exact profile at the zone centres, relative to the mass:
    # sum |rho - rho_exact| V / sum rho_exact V (the whole profile, not only the front)
    rho_ex = ex.profiles(r, t)[0]
    vol = np.prod(np.ptp(points[cells][:, :, :dim], axis=1), axis=1)
    vals = {"shock_radius": float(r_shock), "exact_shock_radius": float(ex.shock_radius(t)),
            "peak_density": float(rho_bin[peak]),
            "l1_density": float(np.sum(np.abs(cd["density"] - rho_ex) * vol) / np.sum(rho_ex * vol))}
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            vals[key.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("positivity")
def positivity(case, out, history, params):
    """Every output step: density and specific internal energy positive and everything finite, in
    every zone that holds material (a zone an immersed body covers whole is empty by design). The
    energy only where every material is a gas (ideal, stiffened): a Mie-Grueneisen, JWL or Tait
    material has e = 0 at its reference state and e < 0 in tension."""
    from orchestrator import output

    gases = all(m["eos"] in ("ideal_gas", "stiffened_gas", "void")
                for m in case.get("ale", {}).get("materials", {}).values())
    bad, rho_min, e_min = 0, np.inf, np.inf
    for _, _, index in output.read_steps(out, "ale"):
        _, pd, cd = output.read_step(out, "ale", index)
        arrays = [pd["velocity"], cd["density"], cd["pressure"], cd["specific_internal_energy"]]
        bad += int(sum(np.count_nonzero(~np.isfinite(a)) for a in arrays))
        gas = cd["blocked_fraction"] < 1.0 - 1e-9 if "blocked_fraction" in cd else slice(None)
        rho, e = cd["density"][gas], cd["specific_internal_energy"][gas]
        bad += int(np.count_nonzero(rho <= 0) + (np.count_nonzero(e <= 0) if gases else 0))
        rho_min = min(rho_min, float(rho.min(initial=np.inf)))
        e_min = min(e_min, float(e.min(initial=np.inf)))
    return {"invalid_values": float(bad), "min_density": rho_min, "min_specific_internal_energy": e_min}


@register_check("reflected_shock", params=table(
    {"axis": AXIS, "gamma": number(exclusiveMinimum=1), "mach": number(exclusiveMinimum=1),
     "ahead": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
               "x-allowed": "must be [density, pressure] (2 numbers)"},
     "p_inf": number("Pa", minimum=0), "x_shock0": number("m"), "x_wall": number("m")},
    required=("gamma", "mach", "ahead", "x_shock0", "x_wall")))
def reflected_shock(case, out, history, params):
    """A planar shock of Mach `mach` into gas at rest (`ahead` = [rho, p]), started at `x_shock0`,
    reflected by a wall at `x_wall` (a conforming wall or an immersed one: an obstacle beyond it),
    against the exact Rankine-Hugoniot solution (solvers.ale.exact.reflected_shock): plateau
    pressure and density between the reflected shock and the wall, the state behind the incident
    shock, the reflected shock position (half-height crossing of the density jump, in cells) and
    the L1 density error on [grid lower, x_wall].  Zones beyond the wall are ignored."""
    from orchestrator.exact_profiles import reflected_shock_solution

    axis = "xyz".index(params.get("axis", "x"))
    ex = reflected_shock_solution(params)
    x_wall, x0 = float(params["x_wall"]), float(params["x_shock0"])
    t, _, index = last_step(out, "ale")
    prof = zone_stations(out, "ale", index, axis)
    x = prof["x"]
    dx = float(np.diff(x).mean())
    keep = x < x_wall
    x, rho, p = x[keep], prof["rho"][keep], prof["p"][keep]
    kind, xs = ex.shock_position(t, x0, x_wall)
    if kind != "reflected":
        raise ValueError(f"reflected_shock check: at t={t:.6g} the incident shock has not reached the wall yet")
    margin = 4 * dx
    vals = {
        "p_reflected": plateau(x, p, xs, x_wall, margin),
        "rho_reflected": plateau(x, rho, xs, x_wall, margin),
        "p_behind_incident": plateau(x, p, x[0], xs, margin),
        "exact_p_reflected": ex.p5,
        "exact_reflected_shock_position": xs,
    }
    if x_wall - xs <= 2 * margin:   # why the reflected state's window is empty (summary, campaigns)
        why = (f"the reflected shock (exact position {xs:.6g} m at t = {t:.6g} s) is within 8 zones "
               f"({2 * margin:.3g} m) of the wall at {x_wall:g} m: no zone between them, 4 zones clear of "
               "each; a later end time measures it")
        vals["_notes"] = {"p_reflected": why, "rho_reflected": why}
    k, xc = crossings(x, rho, 0.5 * (ex.rho2 + ex.rho5))
    if len(k):
        vals["reflected_shock_position_error_cells"] = float(np.min(np.abs(xc - xs)) / dx)
    else:
        vals["reflected_shock_position_error_cells"] = float("inf")
    rho_ex = ex.sample(x, t, x0, x_wall)[0]
    vals["l1_density"] = float(np.sum(np.abs(rho - rho_ex)) / np.sum(rho_ex))
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            vals[key.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("riemann_wall", params=table(
    {"axis": AXIS, "x0": number("m"), "x_wall": number("m"), "left": STATE3, "right": STATE3,
     "gamma_left": number(exclusiveMinimum=1), "gamma_right": number(exclusiveMinimum=1),
     "p_inf_left": number("Pa", minimum=0), "p_inf_right": number("Pa", minimum=0)},
    required=("x0", "x_wall", "left", "right", "gamma_left")))
def riemann_wall(case, out, history, params):
    """A shock tube closed on the right by a wall at `x_wall` (the grid's own wall, or an immersed body
    beyond it), after the right-going shock has reflected (Sod into a wall): against the exact
    solution (:func:`orchestrator.exact_profiles.riemann_wall_sample`): the L1 density error over the
    gas [grid lower, x_wall] (sum |rho - rho_exact| dx / length, kg/m^3: the convergence measure of
    the campaign shock_tube_conforming_vs_immersed), the plateaus behind the reflected shock and in
    the left star region, the reflected shock position (cells) and the balances. Zones whose centre
    lies beyond the wall are not gas and are left out."""
    from orchestrator.exact_profiles import riemann_wall_sample, riemann_wall_solution

    axis = "xyz".index(params.get("axis", "x"))
    ex, refl = riemann_wall_solution(params)
    x0, x_wall = float(params["x0"]), float(params["x_wall"])
    t, _, index = last_step(out, "ale")
    prof = zone_stations(out, "ale", index, axis)
    dx = float(np.diff(prof["x"]).mean())
    keep = prof["x"] < x_wall
    x, rho, p, u = prof["x"][keep], prof["rho"][keep], prof["p"][keep], prof["u"][keep]
    kind, xs = refl.shock_position(t, x0, x_wall)
    if kind != "reflected":
        raise ValueError(f"riemann_wall check: at t = {t:.6g} the shock has not reached the wall yet")
    rho_ex = riemann_wall_sample(params, x, t)[0]
    lower = float(case["ale"]["grid"]["lower"][axis])
    w = ex.waves(t, x0)
    margin = 4 * dx
    tail = w.get("left_rarefaction_tail", w.get("left_shock"))
    vals = {
        "l1_density": float(np.sum(np.abs(rho - rho_ex)) * dx / (x_wall - lower)),
        "p_reflected": plateau(x, p, xs, x_wall, margin),
        "rho_reflected": plateau(x, rho, xs, x_wall, margin),
        "p_star": plateau(x, p, tail, w["contact"], margin),
        "u_star": plateau(x, u, tail, w["contact"], margin),
        "exact_p_reflected": refl.p5,
        "exact_reflected_shock_position": xs,
    }
    k, xc = crossings(x, rho, 0.5 * (refl.rho2 + refl.rho5))
    xc = xc[x[k] > w["contact"] + margin]  # (the reflected shock, not the contact)
    if len(xc):
        vals["reflected_shock_position_error_cells"] = float(np.min(np.abs(xc - xs)) / dx)
    else:
        vals["reflected_shock_position_error_cells"] = float("inf")
    vals.update(positivity(case, out, history, params))
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            vals[key.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals
