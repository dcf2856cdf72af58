"""Checks of penetration: a rod's depth into a target (particles or eroding elements) against
Tate's hydrodynamic limit.
"""
from __future__ import annotations

import numpy as np

from orchestrator.checks.registry import AXIS, WINDOW, register_check
from orchestrator.schema.parts import number, table


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
