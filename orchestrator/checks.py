"""Case checks: each case's [check] names a registered check `kind`; the check computes metrics from
the run's output, and every metric the case lists is compared with its reference and tolerance.

Tolerances are relative (|value - reference| / |reference|); a reference of exactly 0 makes the
tolerance absolute (conservation residuals).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from orchestrator.schema_parts import number, table, vector

CHECKS: dict[str, Callable] = {}
PARAMS: dict[str, dict] = {}
"""Each kind's ``[check] params`` schema (a table: unknown keys, types and ranges are refused when the
case is checked, before anything runs -- not by a KeyError after the run)."""

AXIS = {"type": "string", "enum": ["x", "y", "z"]}
STATE3 = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
          "x-allowed": "must be [density, velocity, pressure] (3 numbers)"}
WINDOW = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
          "x-allowed": "must be [lower, upper] (2 numbers, m)"}


RULES: dict[str, Callable] = {}
"""Each kind's cross-field rule on its params (optional): rule(case, params) returns None or
(param name, what is allowed), checked when the case is loaded."""


def register_check(name: str, params: dict | None = None, rule: Callable | None = None):
    """Register check ``name``; ``params``: the properties of its ``[check] params`` table (with
    ``required``: a ``schema_parts.table``), None for a kind that takes none; ``rule``: RULES'."""
    def deco(fn):
        CHECKS[name] = fn
        PARAMS[name] = params if params is not None else table({})
        if rule is not None:
            RULES[name] = rule
        return fn

    return deco


def compare(value: float, reference: float, tolerance: float) -> dict:
    err = abs(value - reference) / abs(reference) if reference != 0 else abs(value)
    return {"value": float(value), "reference": float(reference), "rel_error": float(err),
            "tolerance": float(tolerance), "passed": bool(err <= tolerance)}


def run_check(case: dict, out: Path, history: dict[str, np.ndarray]) -> dict:
    spec = case["check"]
    values = CHECKS[spec["kind"]](case, Path(out), history, spec.get("params", {}))
    metrics = {}
    for name, ref in spec.get("metrics", {}).items():
        if name not in values:
            raise KeyError(f"check.metrics.{name}: check kind {spec['kind']!r} computes "
                           f"only {', '.join(sorted(values))}")
        metrics[name] = compare(values[name], ref["reference"], ref["tolerance"])
    extra = {k: float(v) for k, v in values.items() if k not in metrics}
    return {"kind": spec["kind"], "passed": all(m["passed"] for m in metrics.values()),
            "metrics": metrics, "reported": extra}


def _body_meshes(case: dict):
    """The Lagrangian bodies' meshes (case order) and each body's first node in the solver's
    concatenated numbering (the output's), with the total last: (meshes, first (n_bodies + 1,))."""
    from solvers.lagrange.mesh import body_mesh

    meshes = [body_mesh(b, case["run"]["dimension"]) for b in case["lagrange"]["bodies"]]
    return meshes, np.cumsum([0] + [m.num_points for m in meshes])


def _cell_centroids(out: Path, role: str, index: int):
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, role)
    points, point_data, cell_data = output.read_step(out, role, index)
    return points[cells].mean(axis=1), points, point_data, cell_data


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
        c, _, _, cd = _cell_centroids(out, "lagrange", index)
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
    meshes, first = _body_meshes(case)
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


@register_check("sliding", params=table(
    {"body": {"type": "string"}, "axis": AXIS, "window": WINDOW}, required=("body", "axis", "window")))
def sliding(case, out, history, params):
    """A body sliding (or sticking) on a held one: its acceleration along ``axis`` (slope of the
    solver's momentum over the body's mass, a straight-line fit over ``window`` in s; every other body
    held, so the momentum is the body's) and its largest speed there. With friction, ``slip_max``
    (m): the most any of the body's nodes slid within the window (the output's contact_slip at the
    window's last output step less its first): a sticking body's is round-off, where its momentum
    still swings with its elastic ringing."""
    from solvers.lagrange.mesh import body_mesh, cell_volumes

    dim = case["run"]["dimension"]
    body = next(b for b in case["lagrange"]["bodies"] if b["name"] == params["body"])
    mass = float(cell_volumes(body_mesh(body, dim)).sum() * case["materials"][body["material"]]["density"])
    t = history["time"]
    lo, hi = params["window"]
    w = (t >= lo) & (t <= hi)
    if w.sum() < 3:
        raise ValueError(f"check.params.window = {params['window']}: fewer than 3 records in it")
    v = history[f"lagrange.momentum_{params['axis']}"][w] / mass
    out_metrics = {"acceleration": float(np.polyfit(t[w], v, 1)[0]), "speed_max": float(np.abs(v).max()),
                   "energy_balance_rel": float(np.max(np.abs(history["lagrange.energy_balance_rel"]))),
                   "momentum_balance_rel": float(np.max(np.abs(history["lagrange.momentum_balance_rel"])))}
    if float(case.get("contact", {}).get("friction", 0.0)) > 0.0:
        from orchestrator import output

        steps = [(ts, index) for ts, _, index in output.read_steps(out, "lagrange") if lo <= ts <= hi]
        if len(steps) < 2:
            raise ValueError(f"check.params.window = {params['window']}: fewer than 2 output steps in it")
        _, first = _body_meshes(case)
        k = [b["name"] for b in case["lagrange"]["bodies"]].index(params["body"])
        a, b = (output.read_step(out, "lagrange", index)[1]["contact_slip"][first[k]:first[k + 1]]
                for _, index in (steps[0], steps[-1]))
        out_metrics["slip_max"] = float(np.max(b - a))
    return out_metrics


@register_check("no_penetration", params=table({"depth": number(exclusiveMinimum=0.0)}))
def no_penetration(case, out, history, params):
    """Bodies in contact (every pair of the [contact] table, both ways; self contact is not measured):
    how far the surface nodes of one body lie behind the deformed exterior facets of the other
    (solvers/contact/penetration.py), the largest over the run relative to the median edge of the
    penetrated body's facets (``penetration_max_rel``; ``penetration_max`` in m). The explicit
    contact measures it at the end of every step (down to its capture: the record
    ``contact_penetration_other_max``, or ``contact_penetration_max`` without self pairs; relative to
    the smallest of the paired bodies' edges), so the figure is the same whichever steps are written;
    for a solver without that record, at every output step (``depth`` the deepest still measured, in
    those edges, default 1: a node deeper sits nearer another face).
    With the contact's record: ``contact_impulse`` (N s, |the time integral of the force the first
    pair's first body takes|), ``contact_force_peak`` (N), ``contact_time`` (from the record before
    the force first exceeds 1 % of its peak to the last record above it), ``contact_dissipation_rel``
    (-contact_work over the initial kinetic energy) and the balances' largest residuals."""
    from orchestrator import output
    from solvers.contact.penetration import surface_penetration
    from solvers.lagrange.surface import exterior_facets

    dim = case["run"]["dimension"]
    bodies = case["lagrange"]["bodies"]
    names = [b["name"] for b in bodies]
    meshes, first = _body_meshes(case)
    surfaces = []
    for k, m in enumerate(meshes):
        f, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
        edge = np.linalg.norm(m.points[f] - m.points[np.roll(f, -1, axis=1)], axis=2)
        surfaces.append((f + first[k], np.unique(f) + first[k], float(np.median(edge))))
    pairs = [(names.index(a), names.index(b)) for a, b in case["contact"]["pairs"] if a != b]
    worst, worst_rel = 0.0, 0.0
    record = next((f"lagrange.contact_penetration_{k}" for k in ("other_max", "max")
                   if f"lagrange.contact_penetration_{k}" in history), None)
    if record is not None:
        worst = float(history[record][-1])
        worst_rel = worst / min((surfaces[k][2] for pair in pairs for k in pair), default=np.inf)
    else:
        for _, _, index in output.read_steps(out, "lagrange"):
            points = output.read_step(out, "lagrange", index)[0][:, :dim]
            for a, b in pairs:
                for s, t in ((a, b), (b, a)):   # t's nodes behind s's facets
                    facets, _, h = surfaces[s]
                    pen = surface_penetration(points, facets, surfaces[t][1], float(params.get("depth", 1.0)) * h)
                    worst, worst_rel = max(worst, float(pen.max())), max(worst_rel, float(pen.max()) / h)
    t = history["time"]
    force = np.stack([history[f"lagrange.contact_force_{c}"] for c in "xyz"[:dim]], axis=1)
    mag = np.linalg.norm(force, axis=1)
    on = np.flatnonzero(mag > 0.01 * mag.max()) if mag.max() > 0 else np.zeros(0, int)
    # the force is each step's impulse over the central difference's (dt_prev + dt) / 2: the
    # trapezoid of the records (every step) sums those impulses up to the first and last half steps
    impulse = np.trapezoid(force, t, axis=0)
    vals = {"penetration_max_rel": worst_rel, "penetration_max": worst,
            "contact_impulse": float(np.linalg.norm(impulse)), "contact_force_peak": float(mag.max()),
            "contact_time": float(t[on[-1]] - t[max(on[0] - 1, 0)]) if len(on) else 0.0,
            "contact_dissipation_rel": float(-history["lagrange.contact_work"][-1] / history["lagrange.kinetic_energy"][0])}
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a)))
    return vals


@register_check("bounce", params=table({"depth": number(exclusiveMinimum=0.0)}))
def bounce(case, out, history, params):
    """Contact episodes of an implicit run (issue 12's ring_bounce, rotating_rod_wall): the runs of
    steps with active contact rows. For each, the mechanical energy E = T + U - W_gravity (gravity's
    work booked so far: E is T + U + the potential energy) at the step before it against the step after
    it: ``energy_rebound_rel`` the largest |E_after / E_before - 1| (the three-step update gives back
    what the contact took); ``state_changes_max`` the most changes of the number of active rows within
    one episode (chatter: rows leaving and rejoining), ``episodes``, and no_penetration's measures."""
    vals = no_penetration(case, out, history, params)
    active = history["lagrange.contact_active"] > 0
    e = history["lagrange.kinetic_energy"] + history["lagrange.stress_power_energy"]
    if "lagrange.gravity_work" in history:
        e = e - history["lagrange.gravity_work"]
    edges = np.flatnonzero(np.diff(active.astype(int)))
    starts = [k + 1 for k in edges if not active[k]]
    ends = [k + 1 for k in edges if active[k]]          # the first step without contact
    rebound, changes = [], []
    for a in starts:
        b = next((k for k in ends if k > a), None)
        if b is None:
            continue                                     # (still in contact at the end)
        rebound.append(abs(e[b] / e[a - 1] - 1.0))
        n = history["lagrange.contact_active"][a:b]
        changes.append(int(np.count_nonzero(np.diff(n))))
    vals.update({"episodes": float(len(rebound)),
                 "energy_rebound_rel": float(max(rebound)) if rebound else float("nan"),
                 "state_changes_max": float(max(changes)) if changes else 0.0})
    return vals


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

    _, _, index = _last_step(out, "lagrange")
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


@register_check("hertz", params=table(
    {"body": {"type": "string"}, "axis": AXIS}, required=("body", "axis")))
def hertz(case, out, history, params):
    """A cylinder (``body``) in contact with a flat, half model (the symmetry plane at ``axis`` = 0),
    at the last output, on the reference geometry. On each side of the first contact pair the contact pressure p of its
    surface nodes, piecewise linear along its exterior facets, is integrated along ``axis`` (Simpson
    on each facet: exact for p s^2); the integrals of the sides that carry pressure are averaged (the
    dual pass's force is the mean of its two passes' pressures; a single pass has one side's). ``pressure_load`` = integral of p ds, ``load`` the
    contact force the body takes (the largest component of the solver's contact_force, the one
    along the flat's normal: equilibrium with the applied load),
    ``half_width`` from the second moment (Hertz: integral p s^2 / integral p = a^2 / 4
    over 0 <= s <= a), ``peak_pressure`` the mean of the two sides' p at their node nearest the
    symmetry plane."""
    from orchestrator import output
    from solvers.lagrange.surface import exterior_facets

    ax = "xyz".index(params["axis"])
    dim = case["run"]["dimension"]
    bodies = case["lagrange"]["bodies"]
    names = [b["name"] for b in bodies]
    pair = case["contact"]["pairs"][0]
    if params["body"] not in pair:
        raise ValueError(f"check.params.body = {params['body']!r} is not in the first contact pair {pair}")
    meshes, first = _body_meshes(case)
    _, _, index = _last_step(out, "lagrange")
    points, pd, _ = output.read_step(out, "lagrange", index)
    loads, moments, peaks, count = [], [], [], 0
    for name in pair:
        k = names.index(name)
        m = meshes[k]
        # (the reference positions: Hertz's, and the small-strain contact's, gaps are those of the
        # undeformed profiles)
        x = (points - pd["displacement"])[first[k]:first[k + 1], :dim]
        p = pd["contact_pressure"][first[k]:first[k + 1]]
        facets, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
        # the facets carrying pressure on the model's side of the symmetry plane (a flat reaching
        # across it has no contact beyond it: its pressure falls to 0 there only by interpolation)
        tol = 1e-9 * float(np.ptp(x[:, ax]))
        facets = facets[(p[facets] > 0.0).any(axis=1) & (x[facets, ax] >= -tol).all(axis=1)]
        s0, s1 = np.abs(x[facets[:, 0], ax]), np.abs(x[facets[:, 1], ax])
        p0, p1 = p[facets[:, 0]], p[facets[:, 1]]
        ds = np.abs(s1 - s0)
        sm, pm = 0.5 * (s0 + s1), 0.5 * (p0 + p1)
        loads.append(float((ds * pm).sum()))
        moments.append(float((ds / 6 * (p0 * s0**2 + 4 * pm * sm**2 + p1 * s1**2)).sum()))
        on = np.flatnonzero(p > 0.0)
        peaks.append(float(p[on[np.argmin(np.abs(x[on, ax]))]]) if len(on) else 0.0)
        count += len(on) if name == params["body"] else 0
    # (a single-pass method has multipliers on its side a only: the sides that carry pressure)
    carry = np.array(loads) > 0.0
    if not carry.any():
        raise ValueError("no contact pressure at the last output")
    loads, moments, peaks = (np.asarray(a)[carry] for a in (loads, moments, peaks))
    load = float(np.mean(loads))
    force = np.array([history[f"lagrange.contact_force_{c}"][-1] for c in "xyz"[:dim]])
    return {"load": float(np.abs(force).max()), "pressure_load": load,
            "half_width": 2.0 * np.sqrt(np.mean(moments) / load),
            "peak_pressure": float(np.mean(peaks)), "contact_nodes": float(count)}


def _segment_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances of the points p (n, 2) to every segment a-b (m, 2): (n, m)."""
    d = b - a
    t = np.einsum("nmk,mk->nm", p[:, None, :] - a[None], d) / np.maximum(np.einsum("mk,mk->m", d, d), 1e-300)
    foot = a[None] + np.clip(t, 0.0, 1.0)[..., None] * d[None]
    return np.linalg.norm(p[:, None, :] - foot, axis=2)


@register_check("self_contact", params=table(
    {"body": {"type": "string"}, "thickness": number("m", exclusiveMinimum=0.0)}, required=("body", "thickness")))
def self_contact(case, out, history, params):
    """A 2-D body in contact with itself and with other bodies ([contact] pairs naming ``body``).

    ``penetration_rel``: the deepest a surface node went behind its partner's surface over the run,
    over ``thickness``, as the explicit contact measured it at the end of every step
    (solvers/contact/penetration.py; so whichever steps are written, the same figure);
    ``penetration_self_rel`` and ``penetration_other_rel`` split by pair; ``penetration_time`` the
    recorded step with the deepest. ``self_contact_nodes``: surface nodes of ``body`` that carry
    contact pressure at the last output and whose nearest exterior facet (of the bodies paired with
    it, its own not counting the two at the node) is its own: the self contact, both sides of it
    (the dual pass puts multipliers on both); ``self_contact_pressure`` their mean pressure.
    ``energy_balance_rel``: the largest |solver's energy balance| over the run (it books the
    boundaries' reactions and the contact's work)."""
    from orchestrator import output
    from solvers.lagrange.surface import exterior_facets

    dim = case["run"]["dimension"]
    if dim != 2:
        raise ValueError(f"check kind self_contact is 2-D (run.dimension = {dim})")
    bodies = case["lagrange"]["bodies"]
    names = [b["name"] for b in bodies]
    name = params["body"]
    pairs = [tuple(p) for p in case.get("contact", {}).get("pairs", []) if name in p]
    if (name, name) not in pairs:
        raise ValueError(f"check.params.body = {name!r}: no self contact pair [{name!r}, {name!r}] in [contact] pairs")
    meshes, first = _body_meshes(case)
    facets = []
    for k, m in enumerate(meshes):
        f, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
        facets.append(f + first[k])
    surf = [np.unique(f) for f in facets]

    def depth(x, nodes, k):
        """Distance of the points x[nodes] to body k's exterior facets that do not have them as a node."""
        f = facets[k]
        dist = _segment_distances(x[nodes], x[f[:, 0]], x[f[:, 1]])
        dist[(f[None, :, :] == nodes[:, None, None]).any(axis=2)] = np.inf
        return dist.min(axis=1)

    if "lagrange.contact_penetration_self_max" not in history:
        raise ValueError("check kind self_contact reads the explicit contact's penetration record "
                         "(lagrange.contact_penetration_self_max): this run's solver keeps none")
    worst = {k: float(history[f"lagrange.contact_penetration_{k}_max"][-1]) for k in ("self", "other")}
    worst_time = float(history["time"][int(np.argmax(history["lagrange.contact_penetration"]))])
    steps = output.read_steps(out, "lagrange")
    # the last output: the self contact's nodes
    x, pd, _ = output.read_step(out, "lagrange", steps[-1][2])
    x = x[:, :2]
    k = names.index(name)
    nodes = surf[k]
    p = pd["contact_pressure"][nodes]
    pressed = nodes[p > 0.0]
    partners = sorted({names.index(q) for pair in pairs for q in pair} - {k})
    own = depth(x, pressed, k)
    other = (np.min([depth(x, pressed, j) for j in partners], axis=0) if partners and len(pressed)
             else np.full(len(pressed), np.inf))
    mine = own < other
    t = float(params["thickness"])
    return {"penetration_rel": max(worst.values()) / t, "penetration_self_rel": worst["self"] / t,
            "penetration_other_rel": worst["other"] / t, "penetration_time": float(worst_time),
            "self_contact_nodes": float(np.count_nonzero(mine)),
            "self_contact_pressure": float(p[p > 0.0][mine].mean()) if mine.any() else 0.0,
            "energy_balance_rel": float(np.max(np.abs(history["lagrange.energy_balance_rel"])))}


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


def _station_means(key, fields: dict):
    """(the distinct station keys, ascending; {name: the mean of the field over each station})."""
    keys, inv = np.unique(key, return_inverse=True)
    count = np.bincount(inv)
    return keys, {name: np.bincount(inv, weights=a) / count for name, a in fields.items()}


def _zone_stations(out: Path, role: str, index: int, axis: int):
    """1-D profile along `axis` of a run on a grid: zone fields averaged over each station."""
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, role)
    points, pd, cd = output.read_step(out, role, index)
    centre = points[cells].mean(axis=1)[:, axis]
    fields = {"rho": cd["density"], "p": cd["pressure"], "u": pd["velocity"][cells].mean(axis=1)[:, axis]}
    if "specific_internal_energy" in cd:
        fields["e"] = cd["specific_internal_energy"]
    # several materials: volume fraction profiles
    fields.update({name: a for name, a in cd.items() if name.startswith("volume_fraction_")})
    xs, prof = _station_means(np.round(centre, 12), fields)
    return {"x": xs, **prof}


def _particle_stations(out: Path, role: str, index: int, axis: int, width: float):
    """1-D profile along `axis` of particles (a point cloud): density, pressure and velocity averaged
    over the particles of each station of `width` (m), stations without particles left out."""
    from orchestrator import output

    points, pd, _ = output.read_step(out, role, index)
    xa = points[:, axis]
    ks, prof = _station_means(np.floor((xa - xa.min()) / width).astype(np.int64),
                              {"rho": pd["density"], "p": pd["pressure"], "u": pd["velocity"][:, axis]})
    return {"x": xa.min() + (ks + 0.5) * width, **prof}


def _profile(case: dict, out: Path, role: str, index: int, axis: int):
    """The 1-D profile of a run along `axis`: grid zones (ALE) or particle stations one lattice spacing
    wide (SPH), by the kind of output the role writes."""
    from orchestrator import output

    _, cell_type = output.read_mesh_file(out, role)
    if cell_type == "vertex":
        return _particle_stations(out, role, index, axis, case[role]["spacing"])
    return _zone_stations(out, role, index, axis)


def _last_step(out: Path, role: str):
    from orchestrator import output

    return output.read_steps(out, role)[-1]


def _crossings(x, a, level):
    """(k, positions): the segments [x[k], x[k+1]] where the profile a crosses `level` (strictly,
    sign change) and the crossing positions by linear interpolation."""
    sgn = np.sign(a - level)
    k = np.flatnonzero(sgn[:-1] * sgn[1:] < 0)
    return k, x[k] + (level - a[k]) * (x[k + 1] - x[k]) / (a[k + 1] - a[k])


def _plateau(x, a, lo, hi, margin, stat="mean"):
    sel = (x > lo + margin) & (x < hi - margin)
    if not sel.any():
        return float("nan")
    return float(np.median(a[sel]) if stat == "median" else a[sel].mean())


def _exact_eos():
    """An EOS table of the exact general-EOS Riemann solver: an [ale] material table without "void"
    or tait (barotropic: its shocks are not given by the energy condition)."""
    from orchestrator.schema_ale import FLUID

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
    t, _, index = _last_step(out, role)
    prof = _profile(case, out, role, index, axis)
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
        "p_star": _plateau(x, prof["p"], inner_l, inner_r, margin, stat),
        "u_star": _plateau(x, prof["u"], inner_l, inner_r, margin, stat),
        "rho_star_left": _plateau(x, prof["rho"], inner_l, contact, margin, stat),
        "rho_star_right": _plateau(x, prof["rho"], contact, inner_r, margin, stat),
    }
    # the mean (whatever `plateau` says) and the largest deviation from the exact p* over the star
    # region: a start-up dip or a wiggle that a median would hide is bounded by these
    vals["p_star_mean"] = _plateau(x, prof["p"], inner_l, inner_r, margin)
    star = (x > inner_l + margin) & (x < inner_r - margin)
    vals["p_star_max_deviation_rel"] = (float(np.max(np.abs(prof["p"][star] - ex.p_star))) / abs(ex.p_star)
                                        if star.any() else float("nan"))
    rho_ex = ex.sample(x, t, x0)[0]
    vals["l1_density"] = float(np.sum(np.abs(prof["rho"] - rho_ex)) * dx / (x[-1] - x[0] + dx))

    def crossing(level, near):
        """Position nearest `near` where the density profile crosses `level` (linear interpolation)."""
        k, xs = _crossings(x, prof["rho"], level)
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
        k, xs = _crossings(x, f, 0.5)
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


POINTS = {"type": "array", "minItems": 1, "items": {"type": "array", "items": {"type": "number"}, "minItems": 2,
                                                    "maxItems": 2},
          "x-allowed": "must be a list of [T, Z] pairs"}


@register_check("surge_front", params=table(
    {"wall": number("m"), "width": number("m", exclusiveMinimum=0), "gravity": number("m/s^2", exclusiveMinimum=0),
     "points": POINTS, "from_T": number(minimum=0)},
    required=("wall", "width", "gravity", "points")))
def surge_front(case, out, history, params):
    """Dam break (Martin & Moyce 1952): the surge front of the moving SPH particles, Z = (x_front -
    wall) / a against the measured points at T = t sqrt(2 g / a), the front interpolated linearly
    between output steps.  The front is the largest x of the moving particles that have a neighbour
    within two lattice spacings (a lone droplet thrown ahead is spray, not the front).  Metrics:
    the largest relative error over the points with T >= from_T, and each point's error."""
    from scipy.spatial import cKDTree

    from orchestrator import output

    a, g, wall = float(params["width"]), float(params["gravity"]), float(params["wall"])
    free = np.array([not b["fixed"] for b in case["sph"]["bodies"]])
    dx = case["sph"]["spacing"]
    ts, zs = [], []
    for t, _, index in output.read_steps(out, "sph"):
        pts, pd, _ = output.read_step(out, "sph", index)
        x = pts[free[pd["body"].astype(np.int64)]]
        d, _ = cKDTree(x).query(x, k=2)
        attached = d[:, 1] <= 2.0 * dx
        ts.append(t * np.sqrt(2.0 * g / a))
        zs.append((x[attached, 0].max() - wall) / a)
    ts, zs = np.array(ts), np.array(zs)
    vals, worst = {}, 0.0
    for T, Z in params["points"]:
        if T > ts[-1]:
            continue
        err = abs(float(np.interp(T, ts, zs)) - Z) / Z
        vals[f"front_error_T{T:g}"] = err
        if T >= float(params.get("from_T", 0.0)):
            worst = max(worst, err)
    vals["front_error_max_rel"] = worst
    return vals


def _main_body(x: np.ndarray, link: float) -> np.ndarray:
    """The particles of the largest cluster whose members are linked by neighbours within ``link``
    (connected components of the neighbour graph)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(x).query_pairs(link, output_type="ndarray")
    n = x.shape[0]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return label == np.argmax(np.bincount(label))


def _particle_rod(case, out, ax: int, surface: float):
    """(times, depths, rear depths, h) of an SPH rod (``penetration``)."""
    from orchestrator import output

    dx = case["sph"]["spacing"]
    ts, ds, rs = [], [], []
    rear = None
    for t, _, index in output.read_steps(out, "sph"):
        x = output.read_step(out, "sph", index)[0][:, : case["run"]["dimension"]]
        if rear is None:
            rear = x[:, ax] >= x[:, ax].max() - 0.5 * dx
        ts.append(t)
        ds.append(surface - float(x[_main_body(x, 2.0 * dx), ax].min()))
        rs.append(surface - float(x[rear, ax].mean()))
    return np.array(ts), np.array(ds), np.array(rs), case["sph"]["smoothing_length"]


def _element_rod(case, out, ax: int, surface: float):
    """(times, depths, rear depths, h) of a rod of Lagrangian elements that erode (``penetration``):
    the lowest node of a live element; the rear, the nodes of the first step's rear face, followed
    by index; h, the median length of the elements along the axis at the first step.  Once no
    element is left both depths keep their last values and the rear is put at the tip (used up)."""
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, "lagrange")
    ts, ds, rs = [], [], []
    rear = h = None
    for t, _, index in output.read_steps(out, "lagrange"):
        x, _, cd = output.read_step(out, "lagrange", index)
        eroded = np.asarray(cd.get("eroded", np.zeros(len(cells)))).ravel()
        if rear is None:
            ext = x[cells, ax]
            h = float(np.median(ext.max(axis=1) - ext.min(axis=1)))
            rear = x[:, ax] >= x[:, ax].max() - 0.5 * h
        live = np.unique(cells[eroded == 0])
        ts.append(t)
        if live.size:
            ds.append(surface - float(x[live, ax].min()))
            rs.append(surface - float(x[rear, ax].mean()))
        else:
            ds.append(ds[-1] if ds else float("nan"))
            rs.append(ds[-1] + h)
    return np.array(ts), np.array(ds), np.array(rs), h


@register_check("penetration", params=table(
    {"surface": number("m"), "axis": AXIS, "window": WINDOW, "depth_time": number("s", exclusiveMinimum=0)},
    required=("surface", "axis", "window")))
def penetration(case, out, history, params):
    """A particle penetrator into a target whose surface is the plane ``axis`` = ``surface``, moving
    towards -axis: its depth (surface minus the lowest particle of the rod's main body, the largest
    cluster of particles linked by neighbours within two lattice spacings: a lone particle or a
    fragment thrown off at impact is not the rod's tip) at every output step; metrics: the penetration
    velocity (least-squares slope of the depth over the output steps in ``window``, s), the depth
    at the last step, and the primary penetration ``depth_consumed``: the depth when the rod is used
    up (Tate's hydrodynamic limit L sqrt(rho_p / rho_t) is this depth), i.e. when its rear face
    (the particles within half a spacing of its initial rear, followed by id) has come within one
    smoothing length of the tip, linearly interpolated between the output steps; the time is
    reported as ``consumed_time``.  Not reached by the last step: depth_consumed is NaN (fails).
    With ``depth_time`` (s): ``depth_at_time``, the depth then (interpolated; NaN past the last
    step), for a model's depth history such as Tate's, U t up to its erosion time L / (v - U).
    A rod of Lagrangian elements (no ``[sph]``): the nodes of its live (not eroded) elements in place
    of the main body, its element length along ``axis`` in place of the spacing and the smoothing
    length; once every element has eroded the rod is used up and its depth stays the last one
    (``_element_rod``)."""
    ax = "xyz".index(params["axis"])
    track = _particle_rod if "sph" in case else _element_rod
    ts, ds, rs, h = track(case, out, ax, float(params["surface"]))
    lo, hi = params["window"]
    sel = (ts >= lo * (1 - 1e-9)) & (ts <= hi * (1 + 1e-9))
    if np.count_nonzero(sel) < 2:
        raise ValueError(f"check.params.window = {[lo, hi]}: fewer than 2 output steps in it "
                         f"(outputs at {ts.tolist()})")
    slope = float(np.polyfit(ts[sel], ds[sel], 1)[0])
    # the rod's remaining length less h: positive while the rear is more than h behind the tip
    left = ds - rs - h
    done = np.flatnonzero(left <= 0.0)
    consumed_time = consumed = float("nan")
    if done.size:
        k = int(done[0])
        w = 1.0 if k == 0 else left[k - 1] / (left[k - 1] - left[k])
        consumed_time = float(ts[k - 1] + w * (ts[k] - ts[k - 1])) if k else float(ts[0])
        consumed = float(ds[k - 1] + w * (ds[k] - ds[k - 1])) if k else float(ds[0])
    values = {"penetration_velocity": slope, "depth": float(ds[-1]), "depth_consumed": consumed,
              "consumed_time": consumed_time}
    if "depth_time" in params:
        t = float(params["depth_time"])
        values["depth_at_time"] = float(np.interp(t, ts, ds)) if ts[0] <= t <= ts[-1] * (1 + 1e-12) else float("nan")
    return values


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
    t, _, index = _last_step(out, "ale")
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
    t, _, index = _last_step(out, "ale")
    prof = _zone_stations(out, "ale", index, axis)
    x = prof["x"]
    dx = float(np.diff(x).mean())
    keep = x < x_wall
    x, rho, p = x[keep], prof["rho"][keep], prof["p"][keep]
    kind, xs = ex.shock_position(t, x0, x_wall)
    if kind != "reflected":
        raise ValueError(f"reflected_shock check: at t={t:.6g} the incident shock has not reached the wall yet")
    margin = 4 * dx
    vals = {
        "p_reflected": _plateau(x, p, xs, x_wall, margin),
        "rho_reflected": _plateau(x, rho, xs, x_wall, margin),
        "p_behind_incident": _plateau(x, p, x[0], xs, margin),
        "exact_p_reflected": ex.p5,
        "exact_reflected_shock_position": xs,
    }
    k, xc = _crossings(x, rho, 0.5 * (ex.rho2 + ex.rho5))
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
    t, _, index = _last_step(out, "ale")
    prof = _zone_stations(out, "ale", index, axis)
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
        "p_reflected": _plateau(x, p, xs, x_wall, margin),
        "rho_reflected": _plateau(x, rho, xs, x_wall, margin),
        "p_star": _plateau(x, p, tail, w["contact"], margin),
        "u_star": _plateau(x, u, tail, w["contact"], margin),
        "exact_p_reflected": refl.p5,
        "exact_reflected_shock_position": xs,
    }
    k, xc = _crossings(x, rho, 0.5 * (refl.rho2 + refl.rho5))
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
    t, _, index = _last_step(out, "ale")
    prof = _zone_stations(out, "ale", index, axis)
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
    k, xc = _crossings(x, p, 0.5 * (ex.p0 + ex.p1))
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
    t, _, index = _last_step(out, "ale")
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
    t, _, index = _last_step(out, role)
    points, pd, _ = output.read_step(out, role, index)
    x = points[:, axis]
    lo, hi = float(x.min()), float(x.max())
    _, _, aindex = _last_step(out, "ale")
    prof = _zone_stations(out, "ale", aindex, axis)
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
    _, _, aindex = _last_step(out, "ale")
    prof = _zone_stations(out, "ale", aindex, axis)
    lo, hi = (float(v) for v in params["reflected_window"])
    w = (prof["x"] > lo) & (prof["x"] < hi)
    _, _, lindex = _last_step(out, "lagrange")
    cen, _, _, cd = _cell_centroids(out, "lagrange", lindex)
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
    _, _, index = _last_step(out, "ale")
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
    _, _, index = _last_step(out, "ale")
    cells, _ = output.read_mesh_file(out, "ale")
    points, _, cd = output.read_step(out, "ale", index)
    if "blocked_fraction" in cd:
        g = case["ale"]["grid"]
        zone_volume = float(np.prod((np.array(g["upper"]) - np.array(g["lower"])) / np.array(g["cells"])))
        full = cd["blocked_fraction"] >= 1.0 - 1e-12
        # (density there is 0 when the zone holds nothing: the check's reference is exactly 0)
        vals["covered_gas_mass"] = float(np.sum(cd["density"][full]) * zone_volume)
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


@register_check("free_end", rule=_probe_of_role, params=table(
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
        key = f"{role}.probe_{params['probe']}"
        if key not in history:
            raise ValueError(f"check.params.probe = {params['probe']!r}: no history {key!r} (a [probes] "
                             f"entry of role {role!r})")
        # (a step recorded twice, at its diagnostics and at its output, counts once)
        _, first = np.unique(history["step"], return_index=True)
        ts, us = history["time"][first], history[key][first]
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


@register_check("tip_history", params=table(
    {"role": {"type": "string", "enum": ["lagrange", "sph"]}, "axis": {"type": "string", "enum": ["x", "y", "z"]},
     "along": {"type": "string", "enum": ["x", "y", "z"]},
     "reference": {"type": "array", "minItems": 2, "items": {"type": "array", "minItems": 2, "maxItems": 2,
                                                             "items": {"type": "number"}}},
     "reference_source": {"type": "string"}},
    required=("role", "axis", "along", "reference")))
def tip_history(case, out, history, params):
    """A body's tip (its nodes or particles that start at the largest coordinate ``along``): their
    mean displacement along ``axis`` over the output steps against a reference history [[t, d],
    ...] (e.g. the same body modelled otherwise, finer: ``reference_source`` says which), linearly
    interpolated in time.  Metrics: ``tip_history_error`` = the largest |d - d_ref| over the
    reference's span relative to the largest |d_ref| (one number for two curves, as an FE and an
    SPH model of one body are compared), ``tip_final_error`` = the relative error at the reference's
    last time."""
    from orchestrator import output

    role, a, b = params["role"], "xyz".index(params["axis"]), "xyz".index(params["along"])
    ref = np.asarray(params["reference"], float)
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
