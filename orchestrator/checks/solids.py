"""Checks of solid bodies alone: elastic waves in a bar, the Taylor bar, impacts, uniform stress,
free flight and momentum, a free end's motion and a probe's tip history.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.fields import body_meshes, cell_centroids, last_step
from orchestrator.checks.registry import AXIS, register_check
from orchestrator.history_spool import each_step_once
from orchestrator.schema.parts import number, table


@register_check("bar_wave", params=table(
    {"until_time": number("s", exclusiveMinimum=0), "expected_amplitude": number("Pa")},
    required=("expected_amplitude",)))
def bar_wave(case, out, history, params):
    """A bar along x struck at x=0: front position (half-amplitude crossing of sigma_xx) over time
    gives the wave speed; the mean stress behind the front gives the amplitude; the largest
    |sigma_xx| of any element at any output (``stress_max``) is the amplitude plus the front's
    ringing, and far more when a mode grows (a step sequence that pumps the highest modes read
    +3.8 GPa against 40 MPa)."""
    from orchestrator import output

    until = float(params.get("until_time", np.inf))
    amp_ref = abs(float(params["expected_amplitude"]))
    times, fronts, amps = [], [], []
    largest = 0.0
    for t, step, index in output.read_steps(out, "lagrange"):
        if t <= 0 or t > until:
            continue
        c, _, _, cd = cell_centroids(out, "lagrange", index)
        sxx = -cd["stress"][:, 0]  # compression positive
        largest = max(largest, float(np.abs(sxx).max()))
        order = np.argsort(c[:, 0])
        xs, s = c[order, 0], sxx[order]
        # average over the cross-section: cells sharing an x station
        xu, inv = np.unique(np.round(xs, 12), return_inverse=True)
        su = np.bincount(inv, weights=s) / np.bincount(inv)
        above = su >= 0.5 * amp_ref
        if not above.any():
            continue
        k = np.flatnonzero(above)[-1]
        if k + 1 >= len(xu):
            continue
        # linear interpolation of the half-amplitude crossing
        x0, x1, s0, s1 = xu[k], xu[k + 1], su[k], su[k + 1]
        front = x0 + (0.5 * amp_ref - s0) * (x1 - x0) / (s1 - s0)
        behind = (xu > 0.15 * front) & (xu < 0.6 * front)
        times.append(t)
        fronts.append(front)
        amps.append(su[behind].mean() if behind.any() else np.nan)
    times, fronts = np.array(times), np.array(fronts)
    speed = np.polyfit(times, fronts, 1)[0] if len(times) >= 2 else np.nan
    mask = history["time"] <= until
    vals = {"wave_speed": speed, "stress_amplitude": amps[-1] if amps else np.nan, "stress_max": largest}
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a[mask])))
    return vals


@register_check("taylor_bar")
def taylor_bar(case, out, history, params):
    """Rod along z hitting a wall at z=0: final length (max z) and impact-face diameter (twice the
    largest radius of the nodes that started on the impact face)."""
    from orchestrator import output

    steps = output.read_steps(out, "lagrange")
    _, _, index = steps[-1]
    points, pd, _ = output.read_step(out, "lagrange", index)
    X = points - pd["displacement"]
    face = np.abs(X[:, 2] - X[:, 2].min()) <= 1e-9 * np.ptp(X[:, 2])
    r = np.hypot(points[face, 0], points[face, 1])
    return {"final_length": float(points[:, 2].max() - points[:, 2].min()),
            "impact_diameter": float(2 * r.max())}


@register_check("impact", params=table(
    {"striker": {"type": "string"}, "target": {"type": "string"}, "axis": AXIS, "height": number("m", exclusiveMinimum=0.0)},
    required=("striker", "target", "axis", "height")))
def impact(case, out, history, params):
    """Two Lagrangian bodies in contact (the [contact] table's first pair; its force is the one the
    first body takes): the contact's duration (from the start of the step before its force first
    exceeds 1 % of its peak to the last step above it), the interface stress (median of |force| /
    height per unit thickness over the middle half of that time), each body's mass-weighted mean
    velocity along ``axis`` at the last output over the striker's initial one (``velocity_*_rel``),
    and the energy the contact took out (-contact_work over the initial kinetic energy)."""
    from orchestrator import output

    ax = "xyz".index(params["axis"])
    t = history["time"]
    force = np.abs(history[f"lagrange.contact_force_{params['axis']}"])
    on = np.flatnonzero(force > 0.01 * force.max())
    if not len(on):
        raise ValueError("the bodies never touched (no contact force)")
    start, end = t[max(on[0] - 1, 0)], t[on[-1]]
    middle = (t >= start + 0.25 * (end - start)) & (t <= start + 0.75 * (end - start))
    dim = case["run"]["dimension"]
    bodies = case["lagrange"]["bodies"]
    names = [b["name"] for b in bodies]
    meshes, first = body_meshes(case)
    _, _, index = output.read_steps(out, "lagrange")[-1]
    _, pd, _ = output.read_step(out, "lagrange", index)
    v = pd["velocity"][:, ax]

    def mean_velocity(name):
        k = names.index(name)
        m = meshes[k]
        mass = np.zeros(m.num_points)   # lumped: a quarter (eighth) of each cell's volume
        from solvers.lagrange.mesh import cell_volumes
        np.add.at(mass, m.cells.ravel(), np.repeat(cell_volumes(m) / m.cells.shape[1], m.cells.shape[1]))
        return float((mass * v[first[k]:first[k + 1]]).sum() / mass.sum())

    k0 = names.index(params["striker"])
    v0 = float(bodies[k0].get("initial_velocity", [0.0] * dim)[ax])
    ke0 = float(history["lagrange.kinetic_energy"][0])
    return {"contact_duration": float(end - start),
            "interface_stress": float(np.median(force[middle]) / params["height"]),
            "velocity_striker_rel": mean_velocity(params["striker"]) / v0,
            "velocity_target_rel": mean_velocity(params["target"]) / v0,
            "contact_dissipation_rel": float(-history["lagrange.contact_work"][-1] / ke0),
            "energy_balance_rel": float(np.max(np.abs(history["lagrange.energy_balance_rel"]))),
            "momentum_balance_rel": float(np.max(np.abs(history["lagrange.momentum_balance_rel"])))}


VOIGT = {"xx": 0, "yy": 1, "zz": 2, "xy": 3, "yz": 4, "zx": 5}


@register_check("uniform_stress", params=table(
    {"component": {"type": "string", "enum": list(VOIGT)}}, required=("component",)))
def uniform_stress(case, out, history, params):
    """A patch test: the stress of every element at the last output should be one uniform uniaxial
    state. ``stress_mean``: the mean of ``component`` (Pa); ``stress_deviation_rel``: its largest
    departure from that mean, and ``other_stress_rel``: the largest of the other components, both
    over |mean|; ``stress_error_rel`` (when the case gives the metric stress_mean a reference): the
    largest departure of any component from the exact state over |reference|; ``contact_pressure_mean`` and ``contact_pressure_deviation_rel``: the same of the
    contact pressure over the nodes that carry one (when the run writes it)."""
    from orchestrator import output

    _, _, index = last_step(out, "lagrange")
    _, pd, cd = output.read_step(out, "lagrange", index)
    s = cd["stress"]
    k = VOIGT[params["component"]]
    mean = float(s[:, k].mean())
    scale = max(abs(mean), 1e-300)
    vals = {"stress_mean": mean, "stress_deviation_rel": float(np.abs(s[:, k] - mean).max() / scale),
            "other_stress_rel": float(np.abs(np.delete(s, k, axis=1)).max() / scale)}
    ref = case["check"].get("metrics", {}).get("stress_mean", {}).get("reference")
    if ref:  # the whole error against the exact state: its mean and its spread (a campaign's measure)
        vals["stress_error_rel"] = max(float(np.abs(s[:, k] - ref).max() / abs(ref)), vals["other_stress_rel"])
    if "contact_pressure" in pd:
        p = pd["contact_pressure"][pd["contact_pressure"] > 0.0]
        if len(p):
            vals["contact_pressure_mean"] = float(p.mean())
            vals["contact_pressure_deviation_rel"] = float(np.abs(p - p.mean()).max() / p.mean())
    return vals


@register_check("momentum")
def momentum(case, out, history, params):
    """Conservation residuals of a free body: maxima over the whole run."""
    vals = {}
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a)))
    vals["steps"] = float(history["step"][-1])
    return vals


def _after_in_run(case, params):
    end = case["run"]["end_time"]
    return None if params["after"] <= end else ("after", f"must be <= run.end_time ({end:g} s)")


@register_check("free_flight", params=table({"after": number("s", minimum=0.0)}, required=("after",)),
                rule=_after_in_run)
def free_flight(case, out, history, params):
    """A body left to itself after its loads end (issue 12's l_block_free_flight): from the first
    step at or after ``after`` on, the largest drift of the total energy E = T + U (relative to E
    there), of the linear momentum (relative to sqrt(2 M T), the momentum the kinetic energy would
    give the mass moving as one) and of the angular momentum (relative to its size there); with the
    whole run's balances, the steps and the most Newton iterations of a step."""
    role = "lagrange"
    t = history["time"]
    sel = t >= params["after"] * (1.0 - 1e-12)
    if not sel.any():
        raise ValueError(f"check.params.after = {params['after']}: no step at or after it (end {t[-1]:g} s)")
    e = history[f"{role}.kinetic_energy"] + history[f"{role}.stress_power_energy"]
    dim = case["run"]["dimension"]
    p = np.stack([history[f"{role}.momentum_{c}"] for c in "xyz"[:dim]], axis=1)
    comps = "xyz" if dim == 3 else "z"
    ang = np.stack([history[f"{role}.angular_momentum_{c}"] for c in comps], axis=1)
    e, p, ang = e[sel], p[sel], ang[sel]
    mass = float(history[f"{role}.mass"][-1])
    p_scale = max(np.sqrt(2.0 * mass * float(history[f"{role}.kinetic_energy"][sel][0])), 1e-300)
    vals = {
        "energy_drift_rel": float(np.max(np.abs(e - e[0])) / max(abs(e[0]), 1e-300)),
        "momentum_drift_rel": float(np.max(np.linalg.norm(p - p[0], axis=1)) / p_scale),
        "angular_momentum_drift_rel": float(np.max(np.linalg.norm(ang - ang[0], axis=1))
                                            / max(float(np.linalg.norm(ang[0])), 1e-300)),
        "energy_after": float(e[0]),
        "steps": float(history["step"][-1]),
    }
    for k in ("energy_balance_rel", "momentum_balance_rel", "angular_momentum_balance_rel"):
        vals[k] = float(np.max(np.abs(history[f"{role}.{k}"])))
    if f"{role}.newton_iterations" in history:
        vals["newton_iterations_max"] = float(np.max(history[f"{role}.newton_iterations"]))
    return vals


def _probe_of_role(case, params):
    """A check reading a probe's history: the probe is a ``[probes]`` entry of the check's role."""
    if "probe" not in params:
        return None
    role = params.get("role", "sph")
    p = (case.get("probes") or {}).get(params["probe"])
    if p is None or p["role"] != role:
        have = [n for n, q in (case.get("probes") or {}).items() if q["role"] == role]
        return ("probe", f"not a [probes] entry of role {role!r}; allowed: {', '.join(have) or 'none (add one)'}")
    return None


def _free_end_curve(case, params):
    """free_end's reference on its probe: the triangle wave u(t) = v0 (L/c) tri(t c / L), rising to
    v0 L / c at L / c, through zero at 2 L / c, down to -v0 L / c at 3 L / c (1-D wave theory)."""
    if "probe" not in params:
        return None
    length, v0, c = float(params["length"]), float(params["speed"]), float(params["wave_speed"])
    end = float(case["run"]["end_time"])
    period = 4.0 * length / c
    t = np.arange(0.0, end + period / 4.0, period / 4.0)
    u = v0 * length / c * np.array([0.0, 1.0, 0.0, -1.0])[np.arange(t.size) % 4]
    return f"{params.get('role', 'sph')}.probe_{params['probe']}", t, u, "1-D wave theory (triangle wave)"


@register_check("free_end", rule=_probe_of_role, curve=_free_end_curve, params=table(
    {"role": {"type": "string"}, "axis": {"type": "string", "enum": ["x", "y", "z"]},
     "length": number("m", exclusiveMinimum=0), "speed": number("m/s", exclusiveMinimum=0),
     "wave_speed": number("m/s", exclusiveMinimum=0), "probe": {"type": "string"}},
    required=("axis", "length", "speed", "wave_speed")))
def free_end(case, out, history, params):
    """A bar of length L along ``axis``, clamped at one end and moving at v0 away from the clamp at
    t = 0 (1-D wave theory, bar speed c): the clamp sends a tension wave that the free end reflects,
    so the free end's displacement is a triangle wave of amplitude v0 L / c and period 4 L / c,
    through zero at t = 2 L / c.  Measured on the particles (or nodes) that start at the free end:
    their mean displacement along the axis, from the history of the case's probe ``probe`` (a
    ``[probes]`` entry of ``role``: displacement, the axis's component, mean over the free end; the
    diagnostics steps, so the figures do not depend on the output interval) or else from the output
    steps; the peak (parabola through the largest sample and its neighbours) and the first downward
    zero crossing (linear).  Metrics:
    relative errors of the peak displacement (the particle discretisation rounds the triangle's
    corner, so it converges slowly), of the peak's time (L / c), of the rebound time (2 L / c) and
    of the rebound speed (-v0, the slope over [1.5, 2.5] L / c)."""
    from orchestrator import output

    role, a = params.get("role", "sph"), "xyz".index(params["axis"])
    length, v0, c = float(params["length"]), float(params["speed"]), float(params["wave_speed"])
    if "probe" in params:
        ts, us = _probe_history(history, role, params["probe"])
    else:
        steps = output.read_steps(out, role)
        x0 = output.read_step(out, role, steps[0][2])[0][:, a]
        tip = x0 >= x0.max() - 1e-9 * max(abs(x0.max()), 1.0)
        ts = np.array([t for t, _, _ in steps])
        us = np.array([np.mean(output.read_step(out, role, i)[0][tip, a] - x0[tip]) for _, _, i in steps])
    k = int(np.argmax(us))
    if 0 < k < len(us) - 1:  # the vertex of the parabola through three samples
        t3, u3 = ts[k - 1:k + 2], us[k - 1:k + 2]
        p = np.polyfit(t3, u3, 2)
        t_peak = -p[1] / (2 * p[0])
        u_peak = float(np.polyval(p, t_peak))
    else:
        t_peak, u_peak = ts[k], us[k]
    down = np.flatnonzero((us[:-1] > 0) & (us[1:] <= 0) & (np.arange(len(us) - 1) >= k))
    t_zero = np.nan
    if down.size:
        j = down[0]
        t_zero = ts[j] + us[j] * (ts[j + 1] - ts[j]) / (us[j] - us[j + 1])
    # the rebound's speed: the slope of u over [1.5, 2.5] L / c (the reflected wave's -v0, away from
    # the smoothed corners of the triangle)
    window = (ts >= 1.5 * length / c) & (ts <= 2.5 * length / c)
    slope = np.polyfit(ts[window], us[window], 1)[0] if window.sum() >= 2 else np.nan
    vals = {"peak_displacement_error_rel": abs(u_peak - v0 * length / c) / (v0 * length / c),
            "peak_time_error_rel": abs(t_peak - length / c) / (length / c),
            "rebound_time_error_rel": abs(t_zero - 2 * length / c) / (2 * length / c),
            "rebound_speed_error_rel": abs(-slope - v0) / v0}
    for key, series in history.items():
        if key.endswith("_balance_rel"):
            vals[key.split(".", 1)[1]] = float(np.max(np.abs(series)))
    return vals


def _probe_history(history, role, probe):
    """A probe's history (times, values), each step once (a step recorded twice, at its diagnostics
    and at its output, counts once)."""
    key = f"{role}.probe_{probe}"
    if key not in history:
        raise ValueError(f"check.params.probe = {probe!r}: no history {key!r} (a [probes] entry of role {role!r})")
    first = each_step_once(history)
    return history["time"][first], history[key][first]


def _tip_curve(case, params):
    """tip_history's reference curve, on the probe it reads (none without one)."""
    if "probe" not in params:
        return None
    ref = np.asarray(params["reference"], float)
    label = "reference" + (f" ({params['reference_source']})" if params.get("reference_source") else "")
    return f"{params['role']}.probe_{params['probe']}", ref[:, 0], ref[:, 1], label


@register_check("tip_history", rule=_probe_of_role, curve=_tip_curve, params=table(
    {"role": {"type": "string", "enum": ["lagrange", "sph"]}, "axis": {"type": "string", "enum": ["x", "y", "z"]},
     "along": {"type": "string", "enum": ["x", "y", "z"]},
     "reference": {"type": "array", "minItems": 2, "items": {"type": "array", "minItems": 2, "maxItems": 2,
                                                             "items": {"type": "number"}}},
     "reference_source": {"type": "string"}, "probe": {"type": "string"}},
    required=("role", "axis", "along", "reference")))
def tip_history(case, out, history, params):
    """A body's tip (its nodes or particles that start at the largest coordinate ``along``): their
    mean displacement along ``axis`` against a reference history [[t, d], ...] (e.g. the same body
    modelled otherwise, finer: ``reference_source`` says which), linearly interpolated in time; read
    from the history of the case's probe ``probe`` (a ``[probes]`` entry of ``role`` that measures
    that displacement: every diagnostics step, drawn against the reference by ``immerse plot``) or
    else from the output steps.  Metrics: ``tip_history_error`` = the largest |d - d_ref| over the
    reference's span relative to the largest |d_ref| (one number for two curves, as an FE and an
    SPH model of one body are compared), ``tip_final_error`` = the relative error at the reference's
    last time."""
    from orchestrator import output

    role, a, b = params["role"], "xyz".index(params["axis"]), "xyz".index(params["along"])
    ref = np.asarray(params["reference"], float)
    if "probe" in params:
        ts, ds = _probe_history(history, role, params["probe"])
    else:
        steps = output.read_steps(out, role)
        x0 = output.read_step(out, role, steps[0][2])[0]
        top = x0[:, b] >= x0[:, b].max() - 1e-9 * max(abs(x0[:, b].max()), 1.0)
        ts = np.array([t for t, _, _ in steps])
        ds = np.array([np.mean(output.read_step(out, role, i)[0][top, a] - x0[top, a]) for _, _, i in steps])
    span = (ts >= ref[0, 0] - 1e-12) & (ts <= ref[-1, 0] + 1e-12)
    scale = np.abs(ref[:, 1]).max()
    err = np.abs(ds[span] - np.interp(ts[span], ref[:, 0], ref[:, 1]))
    final = float(np.interp(ref[-1, 0], ts, ds))
    return {"tip_history_error": float(err.max() / scale),
            "tip_final_error": abs(final - ref[-1, 1]) / max(abs(ref[-1, 1]), 1e-300)}
