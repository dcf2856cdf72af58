"""The probes table of case.toml, ``[probes]``: time histories of node or particle sets, recorded
with the diagnostics at every diagnostics step (not only at the output steps), so that a figure
read from a history does not depend on how often the run writes its fields (solvers/probes.py).

    [probes]
    tip = { role = "sph", quantity = "displacement", component = "x",
            box = { lower = [0.99, -1.0], upper = [1.01, 1.0] } }      # reduce = "mean" (default)

Each probe takes the points (Lagrangian nodes, SPH particles) of ``role`` whose *initial* position
lies in ``box`` (bounds included), and records one number per diagnostics step: the ``reduce``
(mean, max or min) over them of ``component`` (x, y, z or magnitude) of ``quantity``
(displacement from the initial position, velocity, position).  It reads as ``<role>.probe_<name>``
in diagnostics.h5 (and the run's summary history).  A box that holds no point at the start stops
the run at its set-up, naming the probe.

Normalised layout (``case["probes"]``): ``{name: {role, quantity, component, reduce, box: {lower,
upper}}}`` with the defaults filled in.  Cross-field rules: the role is a point solver the case
runs; the box's vectors have the case's dimension, lower <= upper; a component the dimension has.
"""
from __future__ import annotations

from .parts import NAME_PATTERN, table, vector
from .registry import register_table
from .rules import CaseError, check_length, format_key

ROLES = ("lagrange", "sph")
"""The solver roles whose points a probe can follow (the ALE background's zones: not yet)."""
QUANTITIES = ("displacement", "velocity", "position")
COMPONENTS = ("x", "y", "z", "magnitude")
REDUCTIONS = ("mean", "max", "min")

PROBE = table(
    {
        "role": {"enum": list(ROLES), "description": "The solver whose points the probe follows: lagrange (the "
                                                     "bodies' nodes) or sph (the particles)."},
        "quantity": {"enum": list(QUANTITIES),
                     "description": "What is recorded: displacement (from the initial position), velocity or "
                                    "position."},
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
    required=("role", "quantity", "component", "box"),
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
    return {name: {"role": p["role"], "quantity": p["quantity"], "component": p["component"],
                   "reduce": p.get("reduce", "mean"),
                   "box": {"lower": [float(v) for v in p["box"]["lower"]],
                           "upper": [float(v) for v in p["box"]["upper"]]}}
            for name, p in raw.items()}


def check(case: dict, data: dict) -> None:
    dim = case["run"]["dimension"]
    for name, p in case["probes"].items():
        raw = data["probes"][name]
        key = format_key(["probes", name])
        if case.get(p["role"]) is None:
            runs = ", ".join(r for r in ROLES if case.get(r) is not None) or "none"
            raise CaseError(f"{key}.role", raw["role"], f"the case has no [{p['role']}] table; "
                            f"allowed: a point solver the case runs ({runs})")
        for side in ("lower", "upper"):
            check_length(f"{key}.box.{side}", raw["box"][side], dim)
        if any(lo > hi for lo, hi in zip(p["box"]["lower"], p["box"]["upper"])):
            raise CaseError(f"{key}.box.upper", raw["box"]["upper"], "must be >= box.lower in every component")
        if p["component"] == "z" and dim == 2:
            raise CaseError(f"{key}.component", raw["component"], "allowed in 2-D: x, y, magnitude")


register_table("probes", PROBES, normalise, check, order=70)
