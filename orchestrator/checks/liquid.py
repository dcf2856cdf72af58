"""Checks of free-surface liquid: the surge front of a dam break against measured points.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.registry import register_check
from orchestrator.schema.parts import number, table


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
