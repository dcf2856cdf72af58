"""The check registry: each kind registers its function, its ``[check] params`` schema and an
optional cross-field rule (register_check); run_check computes a case's metrics and compares each with
its reference and tolerance. Tolerances are relative (|value - reference| / |reference|); a reference
of exactly 0 makes the tolerance absolute (conservation residuals).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from orchestrator.schema.parts import table


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


CURVES: dict[str, Callable] = {}
"""Each kind's reference curve against time, where it has one (optional): curve(case, params)
returns None or (history key, times, values, label): the history the check measures (e.g. a probe,
``lagrange.probe_tip``) and what it is compared with, drawn beside it by ``immerse plot``."""


def register_check(name: str, params: dict | None = None, rule: Callable | None = None,
                   curve: Callable | None = None):
    """Register check ``name``; ``params``: the properties of its ``[check] params`` table (with
    ``required``: a ``schema.parts.table``), None for a kind that takes none; ``rule``: RULES';
    ``curve``: CURVES'."""
    def deco(fn):
        CHECKS[name] = fn
        PARAMS[name] = params if params is not None else table({})
        if rule is not None:
            RULES[name] = rule
        if curve is not None:
            CURVES[name] = curve
        return fn

    return deco


def reference_curve(case: dict) -> tuple[str, np.ndarray, np.ndarray, str] | None:
    """The case's check's reference curve (CURVES), or None: no check, or a kind without one."""
    spec = case.get("check")
    if not spec or spec["kind"] not in CURVES:
        return None
    return CURVES[spec["kind"]](case, spec.get("params", {}))


def compare(value: float, reference: float, tolerance: float) -> dict:
    err = abs(value - reference) / abs(reference) if reference != 0 else abs(value)
    return {"value": float(value), "reference": float(reference), "rel_error": float(err),
            "tolerance": float(tolerance), "passed": bool(err <= tolerance)}


NAN_NOTE = ("not a number: the check had nothing to measure at the run's last output (an empty window: "
            "see the kind's measuring windows in `immerse keys check` and the check's docstring)")
"""A metric's note when its value is NaN and the check gives no reason of its own."""


def run_check(case: dict, out: Path, history: dict[str, np.ndarray]) -> dict:
    """The check's metrics compared with their references.  A check function may return, beside its
    numbers, ``"_notes": {metric: why}``: why a value is NaN (e.g. the window between a shock and
    the wall holding no zone); a NaN metric without one gets NAN_NOTE.  The note goes into the
    metric's record (summary.json) and a campaign's failure column."""
    spec = case["check"]
    values = dict(CHECKS[spec["kind"]](case, Path(out), history, spec.get("params", {})))
    notes = values.pop("_notes", {})
    metrics = {}
    for name, ref in spec.get("metrics", {}).items():
        if name not in values:
            raise KeyError(f"check.metrics.{name}: check kind {spec['kind']!r} computes "
                           f"only {', '.join(sorted(values))}")
        metrics[name] = compare(values[name], ref["reference"], ref["tolerance"])
        if not np.isfinite(metrics[name]["value"]):
            metrics[name]["note"] = notes.get(name, NAN_NOTE)
    extra = {k: float(v) for k, v in values.items() if k not in metrics}
    return {"kind": spec["kind"], "passed": all(m["passed"] for m in metrics.values()),
            "metrics": metrics, "reported": extra}
