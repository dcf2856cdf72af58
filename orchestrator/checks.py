"""Case checks: each case's [check] names a registered check `kind`; the check computes metrics from
the run's output, and every metric the case lists is compared with its reference and tolerance.

Tolerances are relative (|value - reference| / |reference|); a reference of exactly 0 makes the
tolerance absolute (conservation residuals).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

CHECKS: dict[str, Callable] = {}


def register_check(name: str):
    def deco(fn):
        CHECKS[name] = fn
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


def _cell_centroids(out: Path, role: str, index: int):
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, role)
    points, point_data, cell_data = output.read_step(out, role, index)
    return points[cells].mean(axis=1), points, point_data, cell_data


@register_check("bar_wave")
def bar_wave(case, out, history, params):
    """A bar along x struck at x=0: front position (half-amplitude crossing of sigma_xx) over time
    gives the wave speed; the mean stress behind the front gives the amplitude."""
    from orchestrator import output

    until = float(params.get("until_time", np.inf))
    amp_ref = abs(float(params["expected_amplitude"]))
    times, fronts, amps = [], [], []
    for t, step, index in output.read_steps(out, "lagrange"):
        if t <= 0 or t > until:
            continue
        c, _, _, cd = _cell_centroids(out, "lagrange", index)
        sxx = -cd["stress"][:, 0]  # compression positive
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
    vals = {"wave_speed": speed, "stress_amplitude": amps[-1] if amps else np.nan}
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


@register_check("momentum")
def momentum(case, out, history, params):
    """Conservation residuals of a free body: maxima over the whole run."""
    vals = {}
    for k, a in history.items():
        if k.endswith("_balance_rel"):
            vals[k.split(".", 1)[1]] = float(np.max(np.abs(a)))
    vals["steps"] = float(history["step"][-1])
    return vals
