"""Checks of coupled runs (bodies in a gas or liquid): pistons, advected shapes, acoustic
transmission, a body carried by a uniform flow and the coupled balances.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.fields import cell_centroids, crossings, last_step, zone_stations
from orchestrator.checks.registry import AXIS, WINDOW, register_check
from orchestrator.schema.parts import number, table, vector


@register_check("piston", params=table(
    {"piston_velocity": number("m/s", exclusiveMinimum=0), "x_face": number("m"), "axis": AXIS}))
def piston(case, out, history, params):
    """A piston face (ale.boundaries, { piston = { velocity } }, Lagrangian mode) driving a shock into
    the fluid at rest of the first region, against the exact Rankine-Hugoniot solution
    (solvers.ale.exact.piston; Tait or stiffened/ideal gas, from the region's material): plateau
    pressure and density behind the shock (zones between the piston and the exact shock position,
    4 zones excluded at each end), piston position, and the shock position (half-height crossing of
    the pressure jump) in undisturbed zone widths."""
    from orchestrator.exact_profiles import piston_solution

    ex, axis, x_face, sign = piston_solution(case)
    g = case["ale"]["grid"]
    dx0 = (g["upper"][axis] - g["lower"][axis]) / g["cells"][axis]
    t, _, index = last_step(out, "ale")
    prof = zone_stations(out, "ale", index, axis)
    # distance from the piston's initial position, into the domain
    x = sign * (prof["x"] - x_face)
    order = np.argsort(x)
    x, p, rho = x[order], prof["p"][order], prof["rho"][order]
    xp, xs = ex.piston_position(t), ex.shock_position(t)
    gas = x > xp - 0.5 * dx0  # (a piston immersed in the grid: the zones it fills hold no gas)
    x, p, rho = x[gas], p[gas], rho[gas]
    if xs >= abs(g["upper"][axis] - g["lower"][axis]):
        raise ValueError(f"piston check: at t={t:.6g} the shock has left the column")
    inside = np.flatnonzero((x > xp) & (x < xs))[4:-4]
    vals = {
        "p_plateau": float(p[inside].mean()) if inside.size else float("nan"),
        "rho_plateau": float(rho[inside].mean()) if inside.size else float("nan"),
        "exact_p1": ex.p1, "exact_rho1": ex.rho1, "exact_shock_speed": ex.D,
        "exact_shock_position": xs,
        "plateau_zones": float(inside.size),
    }
    k, xc = crossings(x, p, 0.5 * (ex.p0 + ex.p1))
    if len(k):
        vals["shock_position_error_cells"] = float(np.min(np.abs(xc - xs)) / dx0)
    else:
        vals["shock_position_error_cells"] = float("inf")
    # the piston face: the first zone's centre is half a compressed zone ahead of it
    vals["piston_position_error_cells"] = float(abs(x[0] - 0.5 * dx0 * ex.rho0 / ex.rho1 - xp) / dx0)
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            vals[key.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("advected_shape", params=table(
    {"material": {"type": "string", "minLength": 1}, "lower": vector("m"), "upper": vector("m")},
    required=("material", "lower", "upper")))
def advected_shape(case, out, history, params):
    """A box of one material carried through a periodic grid for whole periods: the volume of every
    material against its initial value (largest relative drift over the run), and the area (volume)
    of the symmetric difference between the final material region and the exact box, from the zone
    volume fractions: sum |f - f_exact| V (f_exact from the box's overlap with each zone)."""
    from orchestrator import output

    material = params["material"]
    lo = np.asarray(params["lower"], np.float64)
    hi = np.asarray(params["upper"], np.float64)
    cells, _ = output.read_mesh_file(out, "ale")
    t, _, index = last_step(out, "ale")
    points, _, cd = output.read_step(out, "ale", index)
    dim = lo.size
    corners = points[cells][:, :, :dim]
    cmin, cmax = corners.min(axis=1), corners.max(axis=1)
    overlap = np.clip(np.minimum(cmax, hi) - np.maximum(cmin, lo), 0.0, None)
    vol = np.prod(cmax - cmin, axis=1)
    f_exact = np.prod(overlap, axis=1) / vol
    f = cd[f"volume_fraction_{material}"]
    vals = {"symmetric_difference": float(np.sum(np.abs(f - f_exact) * vol)),
            "shape_volume": float(np.prod(hi - lo))}
    drift = 0.0
    for k, a in history.items():
        if k.startswith("ale.volume_"):
            drift = max(drift, float(np.max(np.abs(a / a[0] - 1.0))))
    vals["volume_drift_rel"] = drift
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("embedded_piston", params=table(
    {"axis": AXIS, "gap": number("zone widths", minimum=0), "span": number("m", exclusiveMinimum=0),
     "span_left": number("m", exclusiveMinimum=0), "span_right": number("m", exclusiveMinimum=0),
     "role": {"type": "string", "enum": ["lagrange", "sph"]},
     "roles": {"type": "array", "items": {"type": "string", "enum": ["lagrange", "sph"]}, "minItems": 1,
               "uniqueItems": True}}))
def embedded_piston(case, out, history, params):
    """A free body (the Lagrangian solver's, or particles: `role = "sph"`) immersed in a 1-D flow along
    `axis` (a piston between two gases): at the last output, the body's centre (mean node or particle
    position) and velocity (mean node or particle velocity) along the axis, and the pressure of the gas on each side (mean over the zones between
    `gap` and `span` from the body's faces, cut zones excluded; `span_left` / `span_right` where the
    uniform regions either side differ in width), against `centre`, `velocity` and `pressure` (the
    exact solution's, given in the case).  `roles = ["lagrange", "sph"]`: one piston per group, its
    values named `<role>_centre`, ... (a case with both groups immersed)."""
    vals = {}
    if "roles" in params:
        for role in params["roles"]:
            vals.update({f"{role}_{k}": v for k, v in _piston(case, out, role, params).items()})
    else:
        vals = _piston(case, out, params.get("role", "lagrange"), params)
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            name = key.split(".", 1)[1]
            vals[name] = max(vals.get(name, 0.0), float(np.max(np.abs(a))))
    return vals


def _piston(case, out, role, params):
    from orchestrator import output

    axis = "xyz".index(params.get("axis", "x"))
    t, _, index = last_step(out, role)
    points, pd, _ = output.read_step(out, role, index)
    x = points[:, axis]
    lo, hi = float(x.min()), float(x.max())
    _, _, aindex = last_step(out, "ale")
    prof = zone_stations(out, "ale", aindex, axis)
    g = case["ale"]["grid"]
    h = (g["upper"][axis] - g["lower"][axis]) / g["cells"][axis]
    gap, span = float(params.get("gap", 3.0)) * h, float(params.get("span", 0.05))
    span_l, span_r = float(params.get("span_left", span)), float(params.get("span_right", span))
    xs, p = prof["x"], prof["p"]
    left = (xs < lo - gap) & (xs > lo - span_l)
    right = (xs > hi + gap) & (xs < hi + span_r)
    return {
        "centre": float(x.mean()),
        "velocity": float(pd["velocity"][:, axis].mean()),
        "p_left": float(p[left].mean()) if left.any() else float("nan"),
        "p_right": float(p[right].mean()) if right.any() else float("nan"),
        "thickness": hi - lo,
    }


@register_check("acoustic_transmission", params=table(
    {"incident": number("Pa"), "ambient": number("Pa"), "axis": AXIS, "reflected_window": WINDOW,
     "transmitted_window": WINDOW},
    required=("incident", "reflected_window", "transmitted_window")))
def acoustic_transmission(case, out, history, params):
    """A plane pressure pulse of amplitude `incident` (Pa above `ambient`) in the background fluid,
    reflected from and transmitted into an immersed body at normal incidence along `axis`: at the last
    output, the reflected amplitude = mean fluid pressure over `reflected_window` (zone centres
    along the axis, m) and the transmitted one = mean of -stress_aa of the body's elements whose
    centroids lie in `transmitted_window`, both divided by the incident amplitude (the windows: the
    plateaus of the two pulses at that time, given in the case with their derivation).  Reference:
    the acoustic coefficients 2 Z2/(Z1+Z2) and (Z2-Z1)/(Z1+Z2)."""
    axis = "xyz".index(params.get("axis", "x"))
    amp = float(params["incident"])
    ambient = float(params.get("ambient", 0.0))
    _, _, aindex = last_step(out, "ale")
    prof = zone_stations(out, "ale", aindex, axis)
    lo, hi = (float(v) for v in params["reflected_window"])
    w = (prof["x"] > lo) & (prof["x"] < hi)
    _, _, lindex = last_step(out, "lagrange")
    cen, _, _, cd = cell_centroids(out, "lagrange", lindex)
    stress = np.asarray(cd["stress"])
    saa = stress[:, axis, axis] if stress.ndim == 3 else stress[:, axis]
    tlo, thi = (float(v) for v in params["transmitted_window"])
    ws = (cen[:, axis] > tlo) & (cen[:, axis] < thi)
    vals = {
        "reflection": float((prof["p"][w] - ambient).mean() / amp) if w.any() else float("nan"),
        "transmission": float(-saa[ws].mean() / amp) if ws.any() else float("nan"),
        "reflected_zones": float(w.sum()), "transmitted_elements": float(ws.sum()),
    }
    for key, a in history.items():
        if key.endswith("_balance_rel"):
            name = key.split(".", 1)[1]
            vals[name] = max(vals.get(name, 0.0), float(np.max(np.abs(a))))
    return vals


@register_check("uniform_flow", params=table(
    {"velocity": vector("m/s"), "normal": vector(None), "min_open": number(exclusiveMinimum=0, maximum=1)},
    required=("velocity", "normal")))
def uniform_flow(case, out, history, params):
    """A uniform flow `velocity` (m/s) that the bodies should leave undisturbed (a slip wall along
    it): at the last output, over the background's nodes whose zones are on average at least
    `min_open` (default 0.5) open, the largest normal component |v . n| along the unit `normal` and
    the largest deviation |v - u|, both relative to |u| (`normal_velocity_max`,
    `velocity_deviation_max`); plus every balance's largest |value| over the run."""
    from orchestrator import output

    u = np.asarray(params["velocity"], dtype=float)
    n = np.asarray(params["normal"], dtype=float)
    n = n / np.linalg.norm(n)
    speed = float(np.linalg.norm(u))
    _, _, index = last_step(out, "ale")
    cells, _ = output.read_mesh_file(out, "ale")
    points, pd, cd = output.read_step(out, "ale", index)
    v = np.asarray(pd["velocity"])[:, : u.size]
    open_z = 1.0 - np.asarray(cd.get("blocked_fraction", np.zeros(cells.shape[0])))
    # the mean open fraction of each node's zones
    share = np.bincount(cells.ravel(), weights=np.repeat(open_z, cells.shape[1]), minlength=len(points))
    count = np.bincount(cells.ravel(), minlength=len(points))
    gas = share >= float(params.get("min_open", 0.5)) * np.maximum(count, 1)
    vals = {
        "normal_velocity_max": float(np.abs(v[gas] @ n).max() / speed) if gas.any() else float("nan"),
        "velocity_deviation_max": float(np.linalg.norm(v[gas] - u, axis=1).max() / speed) if gas.any() else float("nan"),
        "gas_nodes": float(gas.sum()),
    }
    for key, a in history.items():
        if key.endswith("_balance_rel") and len(a):
            name = key.split(".", 1)[1]
            vals[name] = max(vals.get(name, 0.0), float(np.max(np.abs(a))))
    return vals


@register_check("coupled_balances")
def coupled_balances(case, out, history, params):
    """A coupled run's bookkeeping: the largest |balance| of every solver and of the coupling over
    the run (`<role>.<Q>_balance_rel` -> metric `<Q>_balance_rel`, the largest over the roles), the
    interface work relative to the initial energy of gas + bodies (`interface_work_rel`), and the gas
    mass left in zones a body fills at the last output (`covered_gas_mass`, kg), the largest
    displacement of a body node between the first and the last output (`max_displacement`, m), cond(H) of the
    multiplier system and the multipliers' zone-to-zone spread (`cond_H`, `lambda_oscillation_max`,
    `lambda_oscillation`: orchestrator.coupling.embedded.multiplier_oscillation); with several
    background materials, the largest relative change of one material's mass over the run
    (`material_mass_balance_rel`: every material is conserved on its own in a closed box)."""
    from orchestrator import output

    vals: dict = {}
    for key, a in history.items():
        if key.endswith("_balance_rel") and len(a):
            name = key.split(".", 1)[1]
            vals[name] = max(vals.get(name, 0.0), float(np.max(np.abs(a))))
    masses = [np.asarray(a, dtype=np.float64) for key, a in history.items()
              if key.startswith("ale.mass_") and not key.endswith("_rel") and len(a) and a[0] > 0.0]
    if len(masses) > 1:
        vals["material_mass_balance_rel"] = max(float(np.max(np.abs(a / a[0] - 1.0))) for a in masses)
    e0 = 0.0
    for key in ("ale.total_energy", "lagrange.kinetic_energy", "lagrange.stress_power_energy"):
        if key in history and len(history[key]):
            e0 += float(history[key][0])
    if "coupling.interface_work" in history and e0 > 0.0:
        vals["interface_work_rel"] = float(np.max(np.abs(history["coupling.interface_work"]))) / e0
    _, _, index = last_step(out, "ale")
    cells, _ = output.read_mesh_file(out, "ale")
    points, _, cd = output.read_step(out, "ale", index)
    if "blocked_fraction" in cd:
        g = case["ale"]["grid"]
        zone_volume = float(np.prod((np.array(g["upper"]) - np.array(g["lower"])) / np.array(g["cells"])))
        full = cd["blocked_fraction"] >= 1.0 - 1e-12
        # (a covered zone that holds nothing is written as NaN, one that holds gas with its density:
        # adapters/ale.py _blank_covered; the check's reference is exactly 0)
        vals["covered_gas_mass"] = float(np.nansum(cd["density"][full]) * zone_volume)
    # the largest displacement of a body node at the end (m): what a body did, for comparing methods
    lag = output.read_steps(out, "lagrange")
    if lag:
        x0 = output.read_step(out, "lagrange", lag[0][2])[0]
        x1 = output.read_step(out, "lagrange", lag[-1][2])[0]
        vals["max_displacement"] = float(np.max(np.linalg.norm(x1 - x0, axis=1)))
    # the multiplier system's conditioning (first step) and the multipliers' zone-to-zone spread
    # (the largest over the run, and at the end): what the stabilisation is for
    for key in ("cond_H", "lambda_oscillation_max", "lambda_oscillation"):
        a = history.get(f"coupling.{key}")
        if a is not None and len(a) and np.isfinite(a[-1]):
            vals[key] = float(a[-1])
    return vals
