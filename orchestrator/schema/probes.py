"""The probes table of case.toml, ``[probes]``: time histories of node or particle sets, and of the
background's fields at points, recorded with the diagnostics at every diagnostics step (not only at
the output steps), so that a figure read from a history does not depend on how often the run writes
its fields (solvers/probes.py).

    [probes]
    tip = { role = "sph", quantity = "displacement", component = "x",
            box = { lower = [0.99, -1.0], upper = [1.01, 1.0] } }      # reduce = "mean" (default)
    wall = { role = "ale", quantity = "pressure", point = [0.8, 0.1] }  # the zone holding the point

Each probe takes the points (Lagrangian nodes, SPH particles) of ``role`` whose *initial* position
lies in ``box`` (bounds included), and records one number per diagnostics step: the ``reduce``
(mean, max or min) over them of ``component`` (x, y, z or magnitude) of ``quantity``
(displacement from the initial position, velocity, position).  It reads as ``<role>.probe_<name>``
in diagnostics.h5 (and the run's summary history).  A box that holds no point at the start stops
the run at its set-up, naming the probe.

Normalised layout (``case["probes"]``): ``{name: {role, quantity, component (None: a scalar), reduce,
box: {lower, upper} | point: [...]}}`` with the defaults filled in.  Cross-field rules: the role is a
solver the case runs; points of lagrange/sph in a box whose vectors have the case's dimension, lower
<= upper; the background's (ale) at a point inside its fixed (eulerian) grid; a component the
dimension has, for vector quantities only.
"""
from __future__ import annotations

import numpy as np

from .parts import NAME_PATTERN, table, vector
from .registry import register_table
from .rules import CaseError, check_length, format_key

ROLES = ("lagrange", "sph", "ale")
"""The solver roles a probe reads: the points (nodes, particles) of lagrange and sph, in a box; the
background's (ale) fields at a point."""
QUANTITIES = ("displacement", "velocity", "position")
FIELDS = ("density", "pressure", "specific_internal_energy", "sound_speed", "velocity")
"""What a background probe records at its point: the zone's state there (velocity: the mean of the
zone's nodes, by component)."""
SCALARS = ("density", "pressure", "specific_internal_energy", "sound_speed")
COMPONENTS = ("x", "y", "z", "magnitude")
REDUCTIONS = ("mean", "max", "min")

PROBE = table(
    {
        "role": {"enum": list(ROLES), "description": "The solver the probe reads: lagrange (the bodies' nodes) "
                                                     "or sph (the particles), in a box; ale (the background's "
                                                     "fields), at a point."},
        "quantity": {"enum": sorted(set(QUANTITIES) | set(FIELDS)),
                     "description": "What is recorded: of points (lagrange, sph) displacement (from the initial "
                                    "position), velocity or position; of the background (ale) density, pressure, "
                                    "specific_internal_energy, sound_speed or velocity in the zone holding the "
                                    "point (its state at the step's end, as written in the outputs)."},
        "point": vector("m", description="A background probe's point (ale): the zone that holds it is read "
                                         "(ale.mode = 'eulerian': the grid does not move)."),
        "line": table({"start": vector("m", description="The line's first point."),
                       "end": vector("m", description="The line's last point."),
                       "points": {"type": "integer", "minimum": 2, "maximum": 1000,
                                  "description": "Points along the line, evenly spaced, ends included."}},
                      required=("start", "end", "points"),
                      description="A background probe along a line (ale, instead of point): one history per "
                                  "point, <role>.probe_<name>_<k> for k = 0 (start) .. points - 1 (end), e.g. "
                                  "a row of pressure gauges."),
        "component": {"enum": list(COMPONENTS),
                      "description": "The component of quantity recorded: x, y, z or its magnitude."},
        "reduce": {"enum": list(REDUCTIONS), "default": "mean",
                   "description": "How the points' values make one number per step: their mean, max or min."},
        "box": table({"lower": vector("m", description="The box's lower corner."),
                      "upper": vector("m", description="The box's upper corner (>= lower).")},
                     required=("lower", "upper"),
                     description="The points whose initial position lies in this box (bounds included) are "
                                 "the probe's; a box that holds none stops the run at its set-up."),
    },
    required=("role", "quantity"),
    description="One probe: a time history <role>.probe_<name> in diagnostics.h5, recorded at every "
                "diagnostics step.",
)

PROBES = {"type": "object", "minProperties": 1, "propertyNames": {"pattern": NAME_PATTERN},
          "additionalProperties": PROBE,
          "description": "Time histories of node or particle sets, by name, recorded with the diagnostics at every "
                         "diagnostics step (independent of run.output_interval)."}


def normalise(raw: dict | None, case: dict) -> dict | None:
    if raw is None:
        return None
    out = {}
    for name, p in raw.items():
        q = {"role": p["role"], "quantity": p["quantity"], "component": p.get("component"),
             "reduce": p.get("reduce", "mean")}
        if "box" in p:
            q["box"] = {"lower": [float(v) for v in p["box"]["lower"]], "upper": [float(v) for v in p["box"]["upper"]]}
        if "point" in p:
            q["point"] = [float(v) for v in p["point"]]
        if "line" in p:
            a, b, n = (np.array(p["line"][k], dtype=float) for k in ("start", "end", "points"))
            q["line"] = {"start": a.tolist(), "end": b.tolist(), "points": int(n)}
        out[name] = q
    return out


def check(case: dict, data: dict) -> None:
    dim = case["run"]["dimension"]
    for name, p in case["probes"].items():
        raw = data["probes"][name]
        key = format_key(["probes", name])
        if case.get(p["role"]) is None:
            runs = ", ".join(r for r in ROLES if case.get(r) is not None) or "none"
            raise CaseError(f"{key}.role", raw["role"], f"the case has no [{p['role']}] table; "
                            f"allowed: a solver the case runs ({runs})")
        if p["role"] == "ale":
            _check_field_probe(case, p, raw, key, dim)
            continue
        if "box" not in p or "point" in p:
            raise CaseError(f"{key}.box" if "box" not in p else f"{key}.point", raw.get("point", "missing"),
                            f"a {p['role']} probe follows the points in a box: give box = {{ lower, upper }} "
                            "(point is for role = 'ale')")
        if p["quantity"] not in QUANTITIES:
            raise CaseError(f"{key}.quantity", raw["quantity"], f"allowed for role = {p['role']!r}: "
                            f"{', '.join(QUANTITIES)}")
        if p["component"] is None:
            raise CaseError(f"{key}.component", "missing", f"allowed: {', '.join(COMPONENTS)}")
        for side in ("lower", "upper"):
            check_length(f"{key}.box.{side}", raw["box"][side], dim)
        if any(lo > hi for lo, hi in zip(p["box"]["lower"], p["box"]["upper"])):
            raise CaseError(f"{key}.box.upper", raw["box"]["upper"], "must be >= box.lower in every component")
        if p["component"] == "z" and dim == 2:
            raise CaseError(f"{key}.component", raw["component"], "allowed in 2-D: x, y, magnitude")


def _check_field_probe(case: dict, p: dict, raw: dict, key: str, dim: int) -> None:
    """A background probe: a point inside the fixed grid, a field the background writes, a component
    for the velocity (none for a scalar), no box."""
    if ("point" in p) == ("line" in p) or "box" in p:
        bad = "box" if "box" in p else ("line" if "point" in p else "point")
        raise CaseError(f"{key}.{bad}", raw.get(bad, "missing"), "a background (ale) probe reads the zones at a "
                        "point or along a line: give point = [x, y(, z)] or line = { start, end, points }, no box")
    if p["quantity"] not in FIELDS:
        raise CaseError(f"{key}.quantity", raw["quantity"], f"allowed for role = 'ale': {', '.join(FIELDS)}")
    grid = case["ale"]["grid"]
    spots = [("point", raw.get("point"), p.get("point"))] if "point" in p else [
        (f"line.{k}", raw["line"][k], p["line"][k]) for k in ("start", "end")]
    for sub, given, x in spots:
        check_length(f"{key}.{sub}", given, dim)
        if not all(lo <= v <= hi for v, lo, hi in zip(x, grid["lower"], grid["upper"])):
            raise CaseError(f"{key}.{sub}", given, f"must lie in the grid [{grid['lower']}, {grid['upper']}]")
    if case["ale"].get("mode", "eulerian") != "eulerian":
        raise CaseError(f"{key}.role", raw["role"], "a background probe needs ale.mode = 'eulerian' (a fixed "
                        "grid: the zone at the point is the same at every step)")
    if p["quantity"] == "velocity" and p["component"] is None:
        raise CaseError(f"{key}.component", "missing", f"allowed for the velocity: {', '.join(COMPONENTS)}")
    if p["quantity"] in SCALARS and p["component"] is not None:
        raise CaseError(f"{key}.component", raw["component"], f"{p['quantity']} is a scalar: no component")


register_table("probes", PROBES, normalise, check, order=70)
