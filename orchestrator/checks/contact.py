"""Checks of contact: sliding on an incline, no penetration, bounces, Hertz's pressure and self
contact.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.fields import body_meshes, last_step
from orchestrator.checks.registry import AXIS, WINDOW, register_check
from orchestrator.schema.parts import number, table


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
        _, first = body_meshes(case)
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
    meshes, first = body_meshes(case)
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
    meshes, first = body_meshes(case)
    _, _, index = last_step(out, "lagrange")
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
    meshes, first = body_meshes(case)
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
