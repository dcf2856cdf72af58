"""Accuracy studies of the embedded-mesh coupling (issue 8), run through the normal run path
(orchestrator.launch.run_job, as `immerse run`) on modified copies of the cases' TOML; JSON in
the benches' format (orchestrator/bench/__init__.py: {"results": [{"name", "metric", "value",
"unit", "params"}], "machine"}) and charts written beside it.

`immerse bench plate_convergence`
    cases/plate_in_shock_2d (to its end time, 4 ms) over meshes refined together by 2: zone width 20,
    10, 5, 2.5 mm (80 x 30 .. 640 x 240 zones) with the plate 2 x 15, 4 x 30, 8 x 60, 16 x 120
    elements (4 across the thickness in the 10 mm mesh, where the case has 3: the thickness must
    halve with the zones, and 3 does not halve); and two split runs from the 10 mm mesh that refine
    the background alone (5 mm, plate 4 x 30) or the plate alone (10 mm, plate 8 x 60): which of
    the two makes the difference.  The tip's x displacement (the node at the top of the plate's
    mid-plane, from the Lagrangian output steps, every 0.1 ms) against time; per pair of successive
    meshes the largest difference over time (also up to 1/4, 1/2, 3/4 of the end time), the RMS over
    time and the signed difference at the end; for successive pairs their ratio and the observed
    order log2(ratio) (Richardson, refinement ratio 2), monotone or oscillating, the Richardson
    extrapolation where monotone.  Chart plate_convergence.png (tip deflection against time; the
    successive differences against time).
    --quick: three meshes (20, 10, 5 mm) on a cropped tube (x in [0.4, 0.9] m, the shock starting at
    0.5 m: it reaches the plate at 0.24 ms; its reflections and the outflow stay clear of the plate
    until the end) to 0.7 ms, every 0.05 ms.

`immerse bench plate_convergence_3d`
    cases/plate_in_shock_3d (to its end time, 3 ms) on its half z >= 0.2 m: the plate (z 0.1 .. 0.3)
    and the tube (z 0 .. 0.4) are symmetric about that plane, so the gas gets a wall there (a slip
    wall is the symmetry plane of inviscid flow) and the plate's nodes on it the `symmetry` condition:
    the same solution at half the zones.  Zone widths 25, 12.5, 6.25 mm (64 x 24 x 8 .. 256 x 96 x 32
    zones), the plate 2 x 12 x 4 .. 8 x 48 x 16 elements (1.6, 3.2, 6.4 zones thick); the tip node
    at the top of the plate's mid-plane on the symmetry plane.  The same rows and chart as the 2-D
    study (plate_convergence_3d.png).
    --quick: the cropped tube x in [0.4, 0.9] m, y in [0, 0.45] m, the shock starting at 0.5 m, to
    0.7 ms every 0.05 ms (the wave the tip sends up reaches y = 0.45 m at ~0.6 ms and is back at the
    tip after 1 ms: the tip's history within 1.1e-4 mm of the one to y = 0.6 m, measured, at 3/4 of
    the zones).

`immerse bench steel_panel_convergence`
    cases/steel_panel_shock_2d (a 3 x 60 mm steel cantilever, 2 elements thick, in a 160 x 100 mm
    tube, to 1.5 ms) on zones of 2, 1, 0.5 mm with the panel 2 x 40 throughout (the issue's "2
    elements thick"; the steel's step is then the same on every mesh), and the panel refined alone
    to 4 x 80 at 1 mm.  The same rows and chart (steel_panel_convergence.png).  --quick: 2 and 1 mm
    to 0.3 ms.

`immerse bench penalty_sweep`
    cases/embedded_piston_sod with `method = "penalty"` and `stiffness = k` (Pa/m) over k = 0.1 ..
    1e5, and the multiplier method (the case as it is) as the reference line; 20 output steps per
    run.  Per run the case's check metrics (piston centre, velocity, the pressure on both faces in
    windows 3 zones .. span from them, against Sod's exact solution), the centre's displacement
    error |centre - exact| / (exact - initial centre), the gas pressure right next to the faces
    (RMS of (p - p*)/p* over the open zones within 3 zones, mean over the outputs from t_end/5: where
    the coupling acts), wall time, steps, status (stable, or stopped as unstable with the coupler's
    message naming the penalty's explicit stable-step limit and the step used), and the penalty's
    stable-step limit (coupling.stable_dt_limit: its smallest value over the run and at the end, as
    summary.json; for a stopped run the limit its message names).  Charts penalty_sweep.png (error
    against stiffness, log-log, the multiplier's errors as horizontal lines, unstable runs marked,
    the stiffness where the computed limit meets the solvers' step) and penalty_sweep_cost.png (wall
    time against stiffness).
    --quick: end time 0.05 s instead of 0.2 (the exact solution is self-similar: centre
    0.5 + u* t, velocity u* and p* unchanged; the check's pressure windows shrink with t so that
    they stay inside the star states), k = 10, 1e3, 1e5.

Measured (full runs, 2-core VM shared with other jobs, one simulation at a time, 2026-11-24):
  steel_panel_convergence, 2026-12-05 (~13 min): tip peaks 0.4624, 0.4799, 0.4834 mm (at 0.65, 0.70,
    0.70 ms); the largest difference over time 0.0192 then 0.0079 mm (ratio 2.43, order 1.28; RMS
    order 1.32; at 1.5 ms ratio 2.77, Richardson -0.0297 mm), the coarsest mesh 4.5 % of the peak off
    the finest over the run, the middle 1.6 %; the panel refined alone (4 x 80 at 1 mm) moves the tip
    by at most 0.018 mm; coupled momentum <= 9.9e-15; stepping 67, 137, 333 s (9,772 steps each;
    the split 19,543 steps, 224 s).
  plate_convergence and plate_convergence_3d, 2026-12-05, with the cases' open faces now
    characteristic (non-reflecting) and the plates' bodies set to the assumed-strain hourglass
    stiffness: 2-D tip at 4 ms 10.53, 9.80, 11.52, 12.57 mm; the finest three monotone,
    ratio 1.64, order 0.71, Richardson 14.21 mm; the coarsest pair not (0.52); the background refined
    alone +1.75 mm, the plate alone -0.06 mm (the gas's shear layer, as before).  3-D at 3 ms 2.858,
    2.271, 2.127 mm: ratio 4.08, order 2.03, Richardson 2.080 mm (finest 2.2 % above); stepping
    3.5, 20, 252 s.
  plate_convergence, again on 2026-11-26 after the zones a moving surface uncovers took their gas
    from a neighbour (~2 min): tip deflection at 4 ms 9.37, 9.44, 11.41, 12.54 mm; differences
    largest over time 1.02, 1.97, 1.13 mm; the finest three converge monotonically (ratio 1.75,
    order 0.81, Richardson 14.05 mm), the coarsest pair still does not (0.52): at h = 20 mm the 30 mm
    plate is 1.5 zones thick, the thinnest the method holds (README "Coupled bodies"); the background
    refined alone moves the tip by +1.74 mm, the plate alone by +0.22 mm.  --quick (0.7 ms): 0.299,
    0.283, 0.283 mm, differences 0.016 and 0.0035 mm, ratio 4.5 (order 2.2, monotone; it was 1.97,
    order 0.98, oscillating).  Wall (stepping) 1.5, 4.2, 15, 77 s.
  plate_convergence (~7 min), 2026-11-24: tip deflection at 4 ms 9.75, 10.22, 11.90, 12.84 mm (h = 20, 10, 5,
    2.5 mm).  Successive differences, largest over time: 0.65, 1.67, 0.95 mm (at the end: +0.47,
    +1.67, +0.95).  The first ratio (20/10/5 mm) is 0.39: NOT converging there; the finer one
    (10/5/2.5 mm) 1.76 (observed order 0.82, monotone; Richardson: 14.1 mm at 4 ms, the 2.5 mm mesh
    ~1.2 mm (10 %) short).  The meshes part late: largest differences up to 1 ms 0.027, 0.008,
    0.002 mm; up to 2 ms 0.19, 0.12, 0.12 mm; up to 3 ms 0.63, 0.73, 0.56 mm.  The split runs put
    the mesh dependence in the gas: refining the background alone moves the tip at 4 ms by
    +1.45 mm, the plate alone by +0.01 mm (at most 0.15 mm over time).  (Inviscid gas: the shear
    layer shed at the plate's tip rolls up finer with every refinement and sucks harder on its lee
    side; the plate itself is resolved.)  Coupled momentum balance <= 1.8e-15 on all meshes.  Wall
    (stepping) 5.3, 15.7, 49, 240 s.
  plate_convergence_3d (~5.5 min, 2026-11-26, after the zones a moving surface uncovers took their
    gas from a neighbour): tip deflection at 3 ms 2.913, 2.253, 2.126 mm (h = 25, 12.5, 6.25 mm).
    Successive differences, largest over time, 0.660 and 0.133 mm: ratio 4.97 (observed order 2.31;
    at the end -0.660 and -0.127 mm, ratio 5.21, order 2.38, monotone; Richardson 2.096 mm, the
    finest mesh 1.4 % above it).  (Before that change: 2.882, 2.251, 2.124 mm, order 2.24.)
    --quick (to 0.7 ms): 0.309, 0.247, 0.227 mm; differences 0.062 and 0.021 mm, ratio 2.98 (order
    1.57, monotone).  Coupled momentum balance <= 9.5e-16 on all meshes.  Wall (stepping) 2.7, 22,
    286 s (786k zones, 347 steps).  Unlike the
    2-D plate the coarsest mesh already converges: the 3-D plate is 40 mm thick, 1.6 zones of 25 mm,
    where the 2-D plate's 30 mm is 1.5 zones of 20 mm, the thinnest the method holds (README
    "Coupled bodies"), and the 3-D tip's flow goes round the plate's side edges as well.
  penalty_sweep (~40 s), 2026-11-26, after the zones a moving surface uncovers took their gas from
    a neighbour: stable for k = 0.1 .. 2e3 Pa/m, 360 steps each (the penalty never cuts the step);
    1e4 stopped at step 6 by the energy check (limit 2.9e-4 s), 1e5 at step 1 (limit 1.0e-4 s).
    Errors, multiplier -> penalty over k = 0.1 .. 2e3: centre 0.65 % -> 0.63 .. 0.65 % (the block's
    own start-up), velocity 1e-5 -> <= 1e-5, pressure windows 3e-5 / 2e-5 -> <= 7e-5 / 4e-5,
    displacement 2.38 % -> 2.34 .. 2.39 %; near-face pressure left 0.033 % -> 0.026 .. 0.099 %,
    right 0.015 % -> 0.014 .. 0.055 %.  The stiffness still does not order the piston's errors: the
    blocked volume and the pressure load carry it; the spring shows in the pressure next to the
    faces, worst near k = 10 Pa/m.
  penalty_sweep (~2.5 min), 2026-11-24, before that change: t = 0.2 s, the solvers' step 5.97e-4 s:
    stable for k = 0.1 .. 1e3 Pa/m; k = 2e3 stopped at step 11 by the energy check (limit 3.28e-4 s,
    step 5.89e-4 s); 1e4 and 1e5 stopped at step 1 (limits 2.54e-4 and 8.02e-5 s against 5.92e-4
    s).  The computed limit scales as k^-1/2: limit x sqrt(k) = 0.0143 .. 0.0153 s (Pa/m)^1/2 over
    the stable runs, so it meets the step at k ~ 600 Pa/m; k = 1e3 (limit 4.5e-4 s) still runs: the
    bound (Irons' element bound) is conservative.  Errors, multiplier -> penalty over k = 0.1 ..
    1e3: centre 0.71 % -> 0.70 .. 0.75 %, velocity 0.18 % -> 0.2 .. 2.1 % (ringing, no order in k),
    pressure windows 0.15 / 0.20 % -> 0.01 .. 0.27 %, displacement 2.63 % -> 2.57 .. 2.76 %;
    near-face pressure left 3.6 % -> 2.8 .. 3.9 %, right 0.53 % -> 0.75 .. 1.37 %.  Wall (stepping)
    over three sweeps: multiplier 5.6 .. 8.9 s, penalty 4.0 .. 12.1 s (the machine's load, not k).

Nothing here asserts a time; tests/orchestrator/bench/test_coupling_studies.py checks the quick
modes' structure and physics.
"""
from __future__ import annotations

import json
import re
import tempfile
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, machine

CASES = Path(__file__).resolve().parents[2] / "cases"


# ---- helpers -------------------------------------------------------------------------------------
def _replace(text: str, old: str, new: str, case: str) -> str:
    """``text`` with ``old`` replaced; an error naming the case if its TOML no longer has ``old``
    (the study would otherwise run the unmodified case and report it as the variant)."""
    if old not in text:
        raise RuntimeError(f"cases/{case}/case.toml no longer has {old!r}")
    return text.replace(old, new)


def _run(text: str, where: Path) -> dict:
    """Write ``text`` as a case in ``where``, run it through the launcher (as `immerse run`); the
    exit code, the launcher's wall time, the summary (a stopped run's record: status, where it stopped) and the failure
    line run_job wrote to the log (None if it succeeded)."""
    from orchestrator.case import load_case, ranks_for
    from orchestrator.launch import run_job

    where.mkdir(parents=True)
    (where / "case.toml").write_text(text)
    case = load_case(where)
    out = where / "out"
    t0 = time.perf_counter()
    rc = run_job(case, out, ranks_for(case, {}))
    wall = time.perf_counter() - t0
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else None
    message = None
    if rc != 0:
        lines = [ln for ln in (out / "log.txt").read_text().splitlines() if ln.startswith("immerse: ")]
        # (the last one: run_job's own line; an earlier copy may carry the rank's traceback)
        message = lines[-1][len("immerse: "):].split("Traceback")[0].strip() if lines else f"exit {rc}"
    return {"rc": rc, "launcher_wall_s": wall, "summary": summary, "message": message, "out": out}


def _figure(ncols: int = 1):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(6.5 * ncols, 4.8))
    return plt, fig, axes


# ---- 1. plate_in_shock_2d: tip deflection over mesh refinement ---------------------------------
PLATE = "plate_in_shock_2d"
PLATE_GRID = "grid = { lower = [0.0, 0.0], upper = [1.6, 0.6], cells = [160, 60] }"
PLATE_MESH = "mesh = { box = { lower = [0.6, 0.0], upper = [0.63, 0.3], cells = [3, 30] } }"
PLATE_TIP = np.array([0.615, 0.3])  # m: the top of the plate's mid-plane (a node: even cells across)
SHOCK_SPEED = 409.9  # m/s, Mach 1.2 into air at rest (the case's comment, Rankine-Hugoniot)
REFINE = 2  # the ratio of successive meshes


def plate_text(factor: float, quick: bool, plate_factor: float | None = None) -> tuple[str, dict]:
    """The case's TOML at ``factor`` x its zone count per direction (zone width 10 mm / factor), the
    plate 4 x 30 elements times ``plate_factor`` (default: ``factor``); with its parameters."""
    text = (CASES / PLATE / "case.toml").read_text()
    pf = factor if plate_factor is None else plate_factor
    h = 0.01 / factor
    lower, upper, x_shock = ((0.4, 0.0), (0.9, 0.6), 0.5) if quick else ((0.0, 0.0), (1.6, 0.6), 0.3)
    cells = [(upper[0] - lower[0]) / h, (upper[1] - lower[1]) / h]
    if any(abs(n - round(n)) > 1e-9 for n in cells):  # (the grid would silently change its size)
        raise RuntimeError(f"{PLATE}: the tube {lower} .. {upper} m is not a whole number of zones of {h} m")
    cells = [round(n) for n in cells]
    plate = [round(4 * pf), round(30 * pf)]
    end, every = (0.7e-3, 0.05e-3) if quick else (4.0e-3, 0.1e-3)
    text = _replace(text, PLATE_GRID, f"grid = {{ lower = {list(lower)}, upper = {list(upper)}, cells = {cells} }}",
                    PLATE)
    text = _replace(text, PLATE_MESH, PLATE_MESH.replace("cells = [3, 30]", f"cells = {plate}"), PLATE)
    text = _replace(text, "end_time = 4.0e-3", f"end_time = {end!r}", PLATE)
    text = _replace(text, "output_interval = 0.5e-3", f"output_interval = {every!r}", PLATE)
    if quick:
        text = _replace(text, 'region = "x > 0.3"', f'region = "x > {x_shock}"', PLATE)
    params = {"factor": factor, "plate_factor": pf, "zone_width_m": h, "grid_cells": cells,
              "grid_lower_m": list(lower), "grid_upper_m": list(upper), "plate_cells": plate,
              "end_time_s": end, "output_interval_s": every, "shock_arrival_s": (0.6 - x_shock) / SHOCK_SPEED}
    return text, params


def tip_history(out: Path, tip_at=PLATE_TIP) -> tuple[np.ndarray, np.ndarray, list]:
    """Times and the x displacement of the node nearest ``tip_at`` at every Lagrangian output step;
    the node's initial position."""
    from orchestrator import output

    steps = output.read_steps(out, "lagrange")
    x0 = output.read_step(out, "lagrange", steps[0][2])[0]
    tip_at = np.asarray(tip_at, dtype=float)
    tip = int(np.argmin(np.linalg.norm(x0[:, :tip_at.size] - tip_at, axis=1)))
    t = np.array([s[0] for s in steps])
    dx = np.array([output.read_step(out, "lagrange", s[2])[0][tip, 0] - x0[tip, 0] for s in steps])
    return t, dx, x0[tip, :tip_at.size].tolist()


def plate_meshes(quick: bool) -> tuple[list, list]:
    """(background factor, plate factor) of the refinement series (both together) and, in the full
    study, of the split runs that refine one of the two alone from the middle mesh (which of them
    makes the middle -> fine difference)."""
    if quick:
        return [(0.5, 0.5), (1.0, 1.0), (2.0, 2.0)], []
    return [(0.5, 0.5), (1.0, 1.0), (2.0, 2.0), (4.0, 4.0)], [(2.0, 1.0), (1.0, 2.0)]


def plate_runs(quick: bool, case: str = PLATE) -> tuple[list[dict], list[dict]]:
    meshes, text_of, tip_at = PLATE_STUDIES[case]
    series, split = meshes(quick)
    done = []
    with tempfile.TemporaryDirectory() as tmp:
        for factor, pf in series + split:
            text, params = text_of(factor, quick, pf)
            r = _run(text, Path(tmp) / f"plate_{factor:g}_{pf:g}")
            if r["rc"] != 0:
                raise RuntimeError(f"{case} at {params['grid_cells']} zones, plate {params['plate_cells']} "
                                   f"failed: {r['message']}")
            t, dx, tip = tip_history(r["out"], tip_at)
            s = r["summary"]
            done.append({**params, "tip_node_m": tip, "times_s": t, "tip_dx_m": dx,
                         "steps": s["steps"], "wall_time_s": s["wall_time_s"],
                         "launcher_wall_s": r["launcher_wall_s"],
                         "momentum_balance_rel": s["final"]["coupling.momentum_balance_rel"]})
    return done[:len(series)], done[len(series):]


def _label(r: dict) -> str:
    return (f"h = {r['zone_width_m'] * 1e3:g} mm ({r['grid_cells'][0]} × {r['grid_cells'][1]} zones), "
            f"plate {r['plate_cells'][0]} × {r['plate_cells'][1]}")


def plate_study(runs: list[dict], split: list[dict] = (), name: str = PLATE) -> list[dict]:
    """Result rows: per mesh its history; per pair of successive meshes their differences (the finer
    history interpolated onto the coarser's output times: each mesh writes at its first step past
    the same times): largest over time, root mean square over time, at the end; for every two
    successive pairs the ratio of their differences and the observed order log2(ratio).  At the end the differences are signed: a ratio
    > 1 converges monotonically (then the Richardson extrapolation and the finest mesh's error
    estimate d_fine / (2^p - 1)), a ratio < -1 converges oscillating (no extrapolation: the estimate
    is |d_fine|), |ratio| < 1 does not converge.  The split runs: their difference from the middle
    mesh of the series (background or plate refined alone)."""
    keys = ("factor", "plate_factor", "zone_width_m", "grid_cells", "plate_cells", "end_time_s", "output_interval_s",
            "tip_node_m", "steps", "wall_time_s", "launcher_wall_s", "momentum_balance_rel")
    results = []
    for r in runs:
        results.append({"name": name, "metric": "tip_deflection_final", "value": float(r["tip_dx_m"][-1] * 1e3),
                        "unit": "mm", "params": {**{k: r[k] for k in keys}, "times_s": r["times_s"].tolist(),
                                                 "tip_dx_mm": (r["tip_dx_m"] * 1e3).tolist()}})
    t = runs[0]["times_s"]
    u = [np.interp(t, r["times_s"], r["tip_dx_m"]) for r in runs]
    diffs = []
    for a, b, ua, ub in zip(runs, runs[1:], u, u[1:]):
        d = ub - ua
        diffs.append({"max": float(np.abs(d).max()), "rms": float(np.sqrt(np.mean(d**2))), "final": float(d[-1]),
                      "pair": {"zone_widths_m": [a["zone_width_m"], b["zone_width_m"]],
                               "grids": [a["grid_cells"], b["grid_cells"]],
                               "plates": [a["plate_cells"], b["plate_cells"]]}})
        pair = diffs[-1]["pair"]
        # (the largest difference up to a quarter, a half, ... of the end time: when the meshes part)
        until = [[float(q * t[-1]), float(np.abs(d[t <= q * t[-1] * (1 + 1e-9)]).max() * 1e3)]
                 for q in (0.25, 0.5, 0.75, 1.0)]
        results.append({"name": name, "metric": "tip_difference_max_over_time", "value": diffs[-1]["max"] * 1e3,
                        "unit": "mm", "params": {**pair, "at_time_s": float(t[int(np.argmax(np.abs(d)))]),
                                                 "max_until_s_mm": until}})
        results.append({"name": name, "metric": "tip_difference_rms_over_time", "value": diffs[-1]["rms"] * 1e3,
                        "unit": "mm", "params": {**pair, "times": int(t.size)}})
        results.append({"name": name, "metric": "tip_difference_final", "value": diffs[-1]["final"] * 1e3,
                        "unit": "mm", "params": {**pair, "time_s": float(t[-1]), "of": "finer minus coarser"}})
    for i, (d1, d2) in enumerate(zip(diffs, diffs[1:])):
        widths = d1["pair"]["zone_widths_m"] + d2["pair"]["zone_widths_m"][1:]
        for key in ("max", "rms"):
            ratio = d1[key] / d2[key] if d2[key] > 0 else float("inf")
            results.append({"name": name, "metric": f"convergence_ratio_{key}_over_time", "value": ratio, "unit": "",
                            "params": {"of": "difference(coarse, middle) / difference(middle, fine)",
                                       "zone_widths_m": widths, "refinement_ratio": REFINE,
                                       "converging": bool(d2[key] < d1[key]),
                                       "observed_order": float(np.log(ratio) / np.log(REFINE)) if 0 < ratio < np.inf
                                       else None}})
        ratio = d1["final"] / d2["final"] if d2["final"] != 0 else float("inf")
        order = float(np.log(abs(ratio)) / np.log(REFINE)) if 0 < abs(ratio) < np.inf else None
        behaviour = "monotone" if ratio > 1 else "oscillating" if ratio < -1 else "not converging"
        estimate = abs(d2["final"]) / (REFINE**order - 1.0) if behaviour == "monotone" else abs(d2["final"])
        results.append({"name": name, "metric": "convergence_ratio_final", "value": ratio, "unit": "",
                        "params": {"of": "(u_middle - u_coarse) / (u_fine - u_middle) at the end",
                                   "zone_widths_m": widths, "time_s": float(t[-1]), "refinement_ratio": REFINE,
                                   "observed_order": order, "behaviour": behaviour,
                                   "converging": bool(abs(d2["final"]) < abs(d1["final"])),
                                   "finest_error_estimate_mm": estimate * 1e3}})
        if behaviour == "monotone":
            extrap = u[i + 2][-1] + d2["final"] / (REFINE**order - 1.0)
            results.append({"name": name, "metric": "tip_deflection_final_richardson", "value": float(extrap * 1e3),
                            "unit": "mm", "params": {"observed_order": order, "time_s": float(t[-1]),
                                                     "zone_widths_m": widths,
                                                     "of": "u_fine + (u_fine - u_middle) / (2^p - 1)"}})
    base = next((r, ur) for r, ur in zip(runs, u) if r["factor"] == 1.0)
    for r in split:
        d = np.interp(t, r["times_s"], r["tip_dx_m"]) - base[1]
        what = "background" if r["factor"] != r["plate_factor"] and r["factor"] != 1.0 else "plate"
        results.append({"name": name, "metric": f"tip_difference_{what}_refined_alone", "value": float(d[-1] * 1e3),
                        "unit": "mm", "params": {**{k: r[k] for k in keys}, "of": "this run minus the middle mesh",
                                                 "max_over_time_mm": float(np.abs(d).max() * 1e3),
                                                 "times_s": r["times_s"].tolist(),
                                                 "tip_dx_mm": (r["tip_dx_m"] * 1e3).tolist()}})
    return results


def _draw_plate(runs, split, path: Path, quick: bool, name: str = PLATE) -> None:
    plt, fig, (ax, bx) = _figure(2)
    for r, lw in zip(runs, (1.0, 1.4, 1.8, 2.2)):
        ax.plot(r["times_s"] * 1e3, r["tip_dx_m"] * 1e3, "-", lw=lw, label=_label(r))
    for r, colour in zip(split, ("tab:purple", "tab:brown")):
        ax.plot(r["times_s"] * 1e3, r["tip_dx_m"] * 1e3, ":", lw=1.5, color=colour, label=_label(r) + " (split)")
    ax.axvline(runs[0]["shock_arrival_s"] * 1e3, color="gray", lw=0.8, ls=":", label="shock reaches the plate")
    ax.set_xlabel("time t (ms)")
    ax.set_ylabel("tip displacement along x (mm)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6.5, loc="upper left")
    t = runs[0]["times_s"]
    u = [np.interp(t, r["times_s"], r["tip_dx_m"]) for r in runs]
    for a, b, ua, ub in zip(runs, runs[1:], u, u[1:]):
        bx.plot(t * 1e3, np.abs(ub - ua) * 1e3,
                label=f"|h = {b['zone_width_m'] * 1e3:g} mm  −  h = {a['zone_width_m'] * 1e3:g} mm|")
    bx.set_xlabel("time t (ms)")
    bx.set_ylabel("difference of tip displacement between meshes (mm)")
    bx.grid(True, alpha=0.3)
    bx.legend(fontsize=7, loc="upper left")
    if name == "steel_panel_shock_2d":
        where = ("--quick: to 0.3 ms; " if quick else "") + "the tube 0.16 × 0.1 m, the 3 × 60 mm steel panel"
    else:
        where = "--quick: cropped tube x ∈ [0.4, 0.9] m" if quick else "the case's tube 1.6 × 0.6 m"
        if name != PLATE:
            where += " × 0.2 m, its half z ≥ 0.2 m (symmetry plane)"
    fig.suptitle(f"cases/{name}: tip deflection of the clamped plate struck by a Mach 1.2 shock, meshes "
                 f"refined together by 2\n({where}; multiplier coupling, slip; split: one of the two refined alone)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plate_bench(out: Path, quick: bool, case: str, chart: str) -> Path:
    """Run one plate study, write its JSON to ``out`` and its chart beside it."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    runs, split = plate_runs(quick, case)
    doc = {"results": plate_study(runs, split, case), "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    _draw_plate(runs, split, out.parent / chart, quick, case)
    return out


@bench("plate_convergence")
def bench_plate_convergence(out: Path, quick: bool = False) -> Path:
    return _plate_bench(out, quick, PLATE, "plate_convergence.png")


# ---- 1b. plate_in_shock_3d: the same study in 3-D, on the half the plate's mid-plane cuts off --------
PLATE3D = "plate_in_shock_3d"
PLATE3D_GRID = "grid = { lower = [0.0, 0.0, 0.0], upper = [1.6, 0.6, 0.4], cells = [64, 24, 16] }"
PLATE3D_MESH = "mesh = { box = { lower = [0.6, 0.0, 0.1], upper = [0.64, 0.3, 0.3], cells = [2, 12, 8] } }"
PLATE3D_TIP = np.array([0.62, 0.3, 0.2])  # m: the top of the plate's mid-plane, on the symmetry plane
PLATE3D_MID_Z = 0.2  # m: the plate (z 0.1 .. 0.3) and the tube (z 0 .. 0.4) are symmetric about it


def plate3d_text(factor: float, quick: bool, plate_factor: float | None = None) -> tuple[str, dict]:
    """cases/plate_in_shock_3d at ``factor`` x its zone count per direction (zone width 25 mm /
    factor, the plate 2 x 12 x 8 elements per half times ``plate_factor``), on the half z >= 0.2 m:
    the plate and the tube are symmetric about that plane, the gas's wall there is its symmetry
    plane (a slip wall, inviscid) and the plate's nodes on it get the `symmetry` condition (no z
    motion): the same solution at half the zones."""
    text = (CASES / PLATE3D / "case.toml").read_text()
    pf = factor if plate_factor is None else plate_factor
    h = 0.025 / factor
    lower, upper, x_shock = (((0.4, 0.0, 0.2), (0.9, 0.45, 0.4), 0.5) if quick
                             else ((0.0, 0.0, 0.2), (1.6, 0.6, 0.4), 0.3))
    cells = [(hi - lo) / h for lo, hi in zip(lower, upper)]
    if any(abs(n - round(n)) > 1e-9 for n in cells):
        raise RuntimeError(f"{PLATE3D}: the tube {lower} .. {upper} m is not a whole number of zones of {h} m")
    cells = [round(n) for n in cells]
    plate = [round(2 * pf), round(12 * pf), round(4 * pf)]
    end, every = (0.7e-3, 0.05e-3) if quick else (3.0e-3, 0.1e-3)
    text = _replace(text, PLATE3D_GRID, f"grid = {{ lower = {list(lower)}, upper = {list(upper)}, cells = {cells} }}",
                    PLATE3D)
    text = _replace(text, PLATE3D_MESH, f"mesh = {{ box = {{ lower = [0.6, 0.0, {PLATE3D_MID_Z}], "
                                        f"upper = [0.64, 0.3, 0.3], cells = {plate} }} }}", PLATE3D)
    text = _replace(text, "end_time = 3.0e-3", f"end_time = {end!r}", PLATE3D)
    text = _replace(text, "output_interval = 1.0e-3", f"output_interval = {every!r}", PLATE3D)
    if quick:
        text = _replace(text, 'region = "x > 0.3"', f'region = "x > {x_shock}"', PLATE3D)
    text += f'\n[[boundaries]]\ntype = "symmetry"\naxis = "z"\nat = {PLATE3D_MID_Z}\n'
    params = {"factor": factor, "plate_factor": pf, "zone_width_m": h, "grid_cells": cells,
              "grid_lower_m": list(lower), "grid_upper_m": list(upper), "plate_cells": plate,
              "end_time_s": end, "output_interval_s": every, "shock_arrival_s": (0.6 - x_shock) / SHOCK_SPEED}
    return text, params


def plate3d_meshes(quick: bool) -> tuple[list, list]:
    """Zone widths 25, 12.5, 6.25 mm (the plate 1.6, 3.2, 6.4 zones thick), both refined together."""
    return [(1.0, 1.0), (2.0, 2.0), (4.0, 4.0)], []


# ---- 1c. steel_panel_shock_2d: a thin steel cantilever, 2 elements thick, in a short tube ----------
PANEL = "steel_panel_shock_2d"
PANEL_GRID = "grid = { lower = [0.0, 0.0], upper = [0.16, 0.1], cells = [80, 50] }"
PANEL_CELLS = "cells = [2, 40]"
PANEL_TIP = np.array([0.0515, 0.06])  # m: the top of the panel's mid-plane (a node)


def panel_text(factor: float, quick: bool, plate_factor: float | None = None) -> tuple[str, dict]:
    """cases/steel_panel_shock_2d at ``factor`` x its zone count per direction (zone width 2 mm /
    factor), the panel 2 x 40 elements times ``plate_factor`` (default 1: the panel stays 2 elements
    thick, as the case is meant; the steel's step is then the same on every mesh)."""
    text = (CASES / PANEL / "case.toml").read_text()
    pf = 1.0 if plate_factor is None else plate_factor
    cells = [round(80 * factor), round(50 * factor)]
    plate = [round(2 * pf), round(40 * pf)]
    end, every = (0.3e-3, 0.05e-3) if quick else (1.5e-3, 0.05e-3)
    text = _replace(text, PANEL_GRID, PANEL_GRID.replace("cells = [80, 50]", f"cells = {cells}"), PANEL)
    text = _replace(text, PANEL_CELLS, f"cells = {plate}", PANEL)
    text = _replace(text, "end_time = 1.5e-3", f"end_time = {end!r}", PANEL)
    params = {"factor": factor, "plate_factor": pf, "zone_width_m": 0.002 / factor, "grid_cells": cells,
              "grid_lower_m": [0.0, 0.0], "grid_upper_m": [0.16, 0.1], "plate_cells": plate,
              "end_time_s": end, "output_interval_s": every, "shock_arrival_s": 0.01 / SHOCK_SPEED}
    return text, params


def panel_meshes(quick: bool) -> tuple[list, list]:
    """Zones of 2, 1, 0.5 mm (the 3 mm panel 1.5, 3, 6 zones thick), the panel 2 x 40 throughout; and
    (full study) the panel refined alone at the middle mesh (4 x 80)."""
    if quick:
        return [(1.0, 1.0), (2.0, 1.0)], []
    return [(1.0, 1.0), (2.0, 1.0), (4.0, 1.0)], [(2.0, 2.0)]


PLATE_STUDIES = {PLATE: (plate_meshes, plate_text, PLATE_TIP), PLATE3D: (plate3d_meshes, plate3d_text, PLATE3D_TIP),
                 PANEL: (panel_meshes, panel_text, PANEL_TIP)}
"""Per plate case: its mesh series, its TOML at a refinement, the point its tip node is nearest."""


@bench("plate_convergence_3d")
def bench_plate_convergence_3d(out: Path, quick: bool = False) -> Path:
    return _plate_bench(out, quick, PLATE3D, "plate_convergence_3d.png")


@bench("steel_panel_convergence")
def bench_steel_panel_convergence(out: Path, quick: bool = False) -> Path:
    return _plate_bench(out, quick, PANEL, "steel_panel_convergence.png")


# ---- 2. penalty stiffness sweep on the embedded piston -------------------------------------------
PISTON = "embedded_piston_sod"
PISTON_X0 = 0.5  # m: the piston's initial centre ((0.498125 + 0.501875) / 2, the case's mesh box)
CHECKED = ("centre", "velocity", "p_left", "p_right")


OUTPUTS = 20  # output steps per run: the near-face pressure is averaged over them


def piston_text(method: str, stiffness: float | None, end_time: float) -> str:
    """The case's TOML with the method (and stiffness), OUTPUTS output steps, and for a shorter end
    time the references and pressure windows of the self-similar exact solution at that time."""
    text = (CASES / PISTON / "case.toml").read_text()
    if method == "penalty":
        text = _replace(text, 'method = "multiplier"', f'method = "penalty"\nstiffness = {stiffness!r}', PISTON)
    text = _replace(text, "output_interval = 0.05", f"output_interval = {end_time / OUTPUTS!r}", PISTON)
    if end_time != 0.2:
        s = end_time / 0.2
        centre = PISTON_X0 + (0.685491 - PISTON_X0) * s
        text = _replace(text, "end_time = 0.2", f"end_time = {end_time!r}", PISTON)
        text = _replace(text, "metrics.centre = { reference = 0.685491,",
                        f"metrics.centre = {{ reference = {centre:.6f},", PISTON)
        # the windows (3 zones .. span from the faces) inside the star states: span proportional to t
        text = _replace(text, "span = 0.05 }", f"span = {0.05 * s!r} }}", PISTON)
    return text


def near_face_pressure(out: Path, p_star: float, zones: int = 3) -> dict:
    """The gas pressure next to the piston, where the coupling acts (the check's windows start 3
    zones away): per face the RMS of (p - p*) / p* over the open zones within ``zones`` zone widths of
    the face (cut zones included), averaged over the output steps from a fifth of the end time on
    (the start-up at the diaphragm over)."""
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, "ale")
    asteps, lsteps = output.read_steps(out, "ale"), output.read_steps(out, "lagrange")
    t_end = asteps[-1][0]
    err = {"left": [], "right": []}
    for (ta, _, ia), (tl, _, il) in zip(asteps, lsteps):
        if ta < 0.2 * t_end or ta != tl:
            continue
        pts, _, cd = output.read_step(out, "ale", ia)
        body = output.read_step(out, "lagrange", il)[0][:, 0]
        lo, hi = float(body.min()), float(body.max())
        xc = pts[cells, 0].mean(axis=1)
        h = float(np.ptp(pts[cells[0], 0]))  # zone width along x (uniform grid)
        open_ = cd["blocked_fraction"] < 1.0
        rel = (cd["pressure"] - p_star) / p_star
        for side, sel in (("left", (xc < lo) & (xc > lo - zones * h)), ("right", (xc > hi) & (xc < hi + zones * h))):
            err[side].append(np.sqrt(np.mean(rel[sel & open_] ** 2)))
    return {k: float(np.mean(v)) for k, v in err.items()}


def _stable_limits(out: Path) -> tuple[float | None, float | None]:
    """The penalty's explicit stable-step limit: smallest over the run's steps and at the end (None
    where the method has none: the multiplier reports 1e300)."""
    import h5py

    with h5py.File(out / "diagnostics.h5") as h:
        lim = h["coupling.stable_dt_limit"][1:]  # (row 0: the initial state, before any step)
    lim = lim[lim < 1e299]
    return (float(lim.min()), float(lim[-1])) if lim.size else (None, None)


def piston_run(method: str, stiffness: float | None, end_time: float, where: Path) -> dict:
    r = _run(piston_text(method, stiffness, end_time), where)
    row = {"method": method, "stiffness_pa_per_m": stiffness, "end_time_s": end_time,
           "launcher_wall_s": r["launcher_wall_s"]}
    if r["rc"] == 0:
        s = r["summary"]
        m = s["check"]["metrics"]
        lim_min, lim_end = _stable_limits(r["out"])
        ref = m["centre"]["reference"]
        near = near_face_pressure(r["out"], m["p_left"]["reference"])
        row.update(status="stable", steps=s["steps"], wall_time_s=s["wall_time_s"], dt_max_s=s["dt"]["max"],
                   dt_min_s=s["dt"]["min"], check_passed=s["check"]["passed"],
                   values={k: m[k]["value"] for k in CHECKED}, references={k: m[k]["reference"] for k in CHECKED},
                   rel_errors={k: m[k]["rel_error"] for k in CHECKED},
                   displacement_rel_error=abs(m["centre"]["value"] - ref) / (ref - PISTON_X0),
                   near_face_p_rel_error=near,
                   stable_dt_limit_min_s=lim_min, stable_dt_limit_final_s=lim_end,
                   summary_stable_dt_limit_s=s["final"]["coupling.stable_dt_limit"],
                   momentum_balance_rel=s["final"]["coupling.momentum_balance_rel"])
        return row
    msg = r["message"]
    grab = lambda pat: (float(x.group(1)) if (x := re.search(pat, msg)) else None)  # noqa: E731
    row.update(status="unstable" if "is unstable" in msg else "failed", message=msg,
               stopped_at_step=int(x.group(1)) if (x := re.search(r"at step (\d+),", msg)) else None,
               stopped_at_time_s=grab(r"at step \d+, t = ([0-9.e+-]+) s"),
               stable_dt_limit_s=grab(r"stable-step limit (?:is )?([0-9.e+-]+) s"),
               step_used_s=grab(r"the step (?:used )?([0-9.e+-]+) s"))
    return row


def penalty_sweep(quick: bool) -> tuple[list[dict], dict]:
    end_time = 0.05 if quick else 0.2
    ks = (10.0, 1e3, 1e5) if quick else (0.1, 1.0, 10.0, 100.0, 300.0, 1e3, 2e3, 1e4, 1e5)
    with tempfile.TemporaryDirectory() as tmp:
        ref = piston_run("multiplier", None, end_time, Path(tmp) / "multiplier")
        if ref["status"] != "stable":
            raise RuntimeError(f"{PISTON} with the multiplier method failed: {ref['message']}")
        rows = [piston_run("penalty", k, end_time, Path(tmp) / f"penalty_{k:g}") for k in ks]
    return rows, ref


def penalty_results(rows: list[dict], ref: dict) -> list[dict]:
    results = []
    for r in [ref] + rows:
        name = f"{PISTON}_{r['method']}"
        k = r["stiffness_pa_per_m"]
        if r["status"] == "stable":
            for key in CHECKED:
                results.append({"name": name, "metric": f"{key}_rel_error", "value": r["rel_errors"][key], "unit": "",
                                "params": {"stiffness_pa_per_m": k, "end_time_s": r["end_time_s"],
                                           "value": r["values"][key], "reference": r["references"][key]}})
            results.append({"name": name, "metric": "displacement_rel_error", "value": r["displacement_rel_error"],
                            "unit": "", "params": {"stiffness_pa_per_m": k,
                                                   "of": "|centre - exact| / (exact - initial centre)"}})
            for side in ("left", "right"):
                results.append({"name": name, "metric": f"near_face_pressure_rel_error_{side}",
                                "value": r["near_face_p_rel_error"][side], "unit": "",
                                "params": {"stiffness_pa_per_m": k, "of": "RMS (p - p*)/p* over the open zones "
                                           "within 3 zone widths of the face, mean over the outputs t >= end/5"}})
        results.append({"name": name, "metric": "run", "value": r["launcher_wall_s"], "unit": "s",
                        "params": {**{key: v for key, v in r.items() if key not in ("rel_errors", "values")},
                                   "value_is": "launcher wall time (start-up included)"}})
    stable = [r["stiffness_pa_per_m"] for r in rows if r["status"] == "stable"]
    unstable = [r["stiffness_pa_per_m"] for r in rows if r["status"] == "unstable"]
    # k_e sqrt-scaling of the computed limit: Δt_limit = 2/ω, ω² ∝ k (variants._Spring.stable_dt)
    scaled = [r["stable_dt_limit_min_s"] * np.sqrt(r["stiffness_pa_per_m"]) for r in rows if r["status"] == "stable"]
    k_star = _k_at_step(rows, ref)
    results.append({"name": f"{PISTON}_penalty", "metric": "stability_boundary",
                    "value": min(unstable, default=None), "unit": "Pa/m",
                    "params": {"largest_stable_stiffness": max(stable, default=None),
                               "smallest_unstable_stiffness": min(unstable, default=None),
                               "solver_step_max_s": ref["dt_max_s"],
                               "limit_times_sqrt_k_over_stable_runs": scaled,
                               "stiffness_where_limit_equals_step": k_star}})
    return results


def _k_at_step(rows: list[dict], ref: dict) -> float | None:
    """The stiffness at which the computed limit (∝ k^-1/2: its median limit x sqrt(k) over the
    stable runs) equals the solvers' largest step: above it the bound says unstable."""
    c = [r["stable_dt_limit_min_s"] * np.sqrt(r["stiffness_pa_per_m"]) for r in rows if r["status"] == "stable"]
    return float((np.median(c) / ref["dt_max_s"]) ** 2) if c else None


def _draw_penalty(rows, ref, path_err: Path, path_cost: Path, end_time: float) -> None:
    colours = {"centre": "tab:blue", "velocity": "tab:orange", "p_left": "tab:green", "p_right": "tab:red",
               "displacement": "tab:purple", "near_left": "tab:green", "near_right": "tab:red"}
    labels = {"centre": "centre position", "velocity": "velocity", "p_left": "pressure, left window",
              "p_right": "pressure, right window", "displacement": "centre displacement from 0.5 m",
              "near_left": "left face", "near_right": "right face"}
    stable = [r for r in rows if r["status"] == "stable"]
    unstable = [r for r in rows if r["status"] != "stable"]
    ks = [r["stiffness_pa_per_m"] for r in stable]
    k_star = _k_at_step(rows, ref)
    panels = [
        ("check metrics (windows 3 zones .. span from the faces)",
         {**{k: ([r["rel_errors"][k] for r in stable], ref["rel_errors"][k]) for k in CHECKED},
          "displacement": ([r["displacement_rel_error"] for r in stable], ref["displacement_rel_error"])}),
        ("gas pressure next to the faces (≤ 3 zones), RMS of (p − p*)/p*",
         {f"near_{s}": ([r["near_face_p_rel_error"][s] for r in stable], ref["near_face_p_rel_error"][s])
          for s in ("left", "right")}),
    ]
    plt, fig, axes = _figure(2)
    for ax, (title, series) in zip(axes, panels):
        lo = min(min(v for v in vals + [m] if v > 0) for vals, m in series.values())
        hi = max(max(vals + [m]) for vals, m in series.values())
        for key, (vals, mult) in series.items():
            ax.loglog(ks, np.maximum(vals, lo), "o-", color=colours[key], label=f"penalty: {labels[key]}")
            ax.axhline(max(mult, lo), color=colours[key], ls="--", lw=0.9, alpha=0.8)
        ax.plot([], [], "k--", lw=0.9, label="multiplier method (same colours)")
        top = hi * 3.0
        for i, r in enumerate(unstable):
            ax.plot(r["stiffness_pa_per_m"], top, "x", color="k", ms=10, mew=2)
            lim = r.get("stable_dt_limit_s")
            note = f"step {r.get('stopped_at_step')}\nlimit {lim:.2g} s" if lim else "failed"
            ax.annotate(note, (r["stiffness_pa_per_m"], top), textcoords="offset points",
                        xytext=(0, -22 - 16 * (i % 2)), ha="center", fontsize=6)
        ax.plot([], [], "kx", ms=8, mew=2, label="unstable: stopped by the coupler")
        if k_star is not None:
            ax.axvline(k_star, color="gray", ls=":", lw=1.0,
                       label=f"computed limit = solver step (k ≈ {k_star:.3g} Pa/m)")
        ax.set_ylim(lo / 3, top * 4)
        ax.set_xlabel("penalty stiffness k (Pa/m)")
        ax.set_ylabel("relative error against Sod's exact solution")
        ax.set_title(title, fontsize=8)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=6.5, loc="lower left")
    fig.suptitle(f"cases/{PISTON}: penalty coupling error against stiffness at t = {end_time:g} s (400 × 2 zones, "
                 f"solver step ≈ {ref['dt_max_s']:.2g} s); dashed: the multiplier method", fontsize=9)
    fig.tight_layout()
    fig.savefig(path_err, dpi=120)
    plt.close(fig)

    plt, fig, ax = _figure()
    ax.semilogx(ks, [r["wall_time_s"] for r in stable], "o-", color="tab:blue",
                label="penalty: coupled stepping (summary wall_time_s)")
    ax.semilogx([r["stiffness_pa_per_m"] for r in rows], [r["launcher_wall_s"] for r in rows], "s:",
                color="tab:orange", label="penalty: whole run incl. start-up (launcher)")
    ax.axhline(ref["wall_time_s"], color="tab:blue", ls="--", lw=0.9, label="multiplier: coupled stepping")
    ax.axhline(ref["launcher_wall_s"], color="tab:orange", ls="--", lw=0.9, label="multiplier: whole run")
    for r in unstable:
        ax.plot(r["stiffness_pa_per_m"], r["launcher_wall_s"], "kx", ms=10, mew=2)
    ax.plot([], [], "kx", ms=8, mew=2, label="unstable: stopped by the coupler")
    ax.set_xlabel("penalty stiffness k (Pa/m)")
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("wall time (s), 1 + 1 ranks")
    ax.set_title(f"cases/{PISTON}: cost against penalty stiffness, t_end = {end_time:g} s\n"
                 f"(steps: {', '.join(str(r['steps']) for r in stable)}; multiplier {ref['steps']})", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path_cost, dpi=120)
    plt.close(fig)


@bench("penalty_sweep")
def bench_penalty_sweep(out: Path, quick: bool = False) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows, ref = penalty_sweep(quick)
    doc = {"results": penalty_results(rows, ref), "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    _draw_penalty(rows, ref, out.parent / "penalty_sweep.png", out.parent / "penalty_sweep_cost.png",
                  ref["end_time_s"])
    return out
