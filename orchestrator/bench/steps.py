"""The solver step benches: the Lagrangian hex step (elastic and J2) and the Taylor bar's error
against cost (`lagrange`, `taylor`), the ALE Lagrange step and remap on Sedov, Sod's mesh study and
the advected ball (`ale`, `sod`, `advect`); a two-rank timing runs as a job of its own
(`python -m orchestrator.bench.steps worker N LABEL`).
"""
from __future__ import annotations

import json
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, machine, run_worker


ELASTIC = {"model": "linear_elastic", "density": 7850.0, "youngs_modulus": 200e9, "poisson_ratio": 0.3}


J2 = {"model": "johnson_cook", "density": 7830.0, "youngs_modulus": 206.9e9, "poisson_ratio": 0.3,
      "yield_stress": 806e6, "hardening_modulus": 614e6, "hardening_exponent": 0.168,
      "strain_rate_coefficient": 0.0089, "reference_strain_rate": 1.0, "thermal_exponent": 1.1,
      "melt_temperature": 1813.15, "room_temperature": 293.15, "specific_heat": 460.0,
      "taylor_quinney": 0.9}


def lagrange_case(n: int, material: dict, velocity: float, control: str | None = None) -> dict:
    """A cube of n^3 hexahedra compressed by a velocity on one face (plastic flow for J2), with the
    given hourglass control (None: the default)."""
    body = {"name": "cube", "material": "m",
            "mesh": {"box": {"lower": [0, 0, 0], "upper": [0.01] * 3, "cells": [n] * 3}},
            "initial_velocity": [f"{-velocity}*z/0.01", 0.0, 0.0]}
    if control is not None:
        body["hourglass_control"] = control
    return {
        "name": "bench", "case_dir": ".",
        "run": {"dimension": 3, "end_time": 1.0},
        "materials": {"m": dict(material)},
        "lagrange": {"bodies": [body]},
        "boundaries": [],
    }


def lagrange_case_2d(n: int, material: dict, velocity: float, control: str) -> dict:
    """A square of n^2 plane-strain quads in a bending-like shear flow (its hourglass modes loaded),
    with the given hourglass control."""
    return {
        "name": "bench", "case_dir": ".",
        "run": {"dimension": 2, "end_time": 1.0},
        "materials": {"m": dict(material)},
        "lagrange": {"bodies": [{"name": "square", "material": "m", "hourglass_control": control,
                                 "mesh": {"box": {"lower": [0, 0], "upper": [0.01] * 2, "cells": [n] * 2}},
                                 "initial_velocity": [f"{velocity}*x*y/1e-4", 0.0]}]},
        "boundaries": [],
    }


def time_lagrange(comm, case: dict, steps: int, repeats: int) -> tuple[float, int]:
    """Median seconds per element-cycle (whole solver step: forces, update, BCs, sums)."""
    from solvers.lagrange.solver import LagrangeSolver

    s = LagrangeSolver(comm, case)
    ne = s.n_cells_global
    dt = 0.5 * s.stable_dt()
    for _ in range(3):  # warm-up (compilation is cached, first touches)
        s.predict(dt)
        s.correct(None)
    samples = []
    for _ in range(repeats):
        comm.Barrier()
        t0 = time.perf_counter()
        for _ in range(steps):
            s.predict(dt)
            s.correct(None)
        comm.Barrier()
        samples.append((time.perf_counter() - t0) / (steps * ne))
    return float(np.median(samples)), ne


def memory_per_element(case: dict) -> float:
    from mpi4py import MPI

    from solvers.lagrange.solver import LagrangeSolver

    tracemalloc.start()
    s = LagrangeSolver(MPI.COMM_SELF, case)
    s.predict(0.5 * s.stable_dt())
    s.correct(None)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / s.n_cells_global


def time_shell2d(n: int, plastic: bool, steps: int, repeats: int) -> float:
    """Median seconds per element-cycle of the two-node plane-strain shell (solvers/lagrange/beam2d.py:
    issue 45's first piece, not yet a solver): a free 1 m steel strip of n elements, 10 mm thick,
    swinging in its first mode; a cycle is the kernel's forces and moments (5 points through the
    thickness; plastic: J2 at them) and the central difference's kick and drift, vectorised numpy."""
    from solvers.lagrange import beam2d

    s = np.linspace(0.0, 1.0, n + 1)
    X = np.stack([s, np.zeros_like(s)], axis=1)
    el = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    sec = beam2d.BeamSection(2.0e11, 0.3, 7800.0, np.full(n, 0.01), yield_stress=2.5e8 if plastic else None)
    m, ir = beam2d.lumped_masses(X, el, sec)
    dt = 0.9 * beam2d.stable_step(X, el, sec)
    x, th = X.copy(), np.zeros(n + 1)
    v = np.zeros_like(X)
    v[:, 1] = 10.0 * np.sin(np.pi * s)
    w = np.zeros(n + 1)
    state = beam2d.plastic_state(n, sec) if plastic else None

    def cycle():
        nonlocal x, th, v, w, state
        out = beam2d.internal_forces(X, x, th, el, sec, plastic=state)
        if plastic:
            state = out[3]
        v = v - dt * out[0] / m[:, None]
        w = w - dt * out[1] / ir
        x = x + dt * v
        th = th + dt * w

    for _ in range(3):
        cycle()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            cycle()
        samples.append((time.perf_counter() - t0) / (steps * n))
    return float(np.median(samples))


@bench("lagrange")
def bench_lagrange(out: Path, quick: bool = False) -> Path:
    from mpi4py import MPI

    sizes = [10, 22] if quick else [22, 47]  # ~1e4 and ~1e5 elements (22^3 = 10648, 47^3 = 103823)
    results = []
    for label, mat, vel in (("elastic", ELASTIC, 1.0), ("j2_johnson_cook", J2, 200.0)):
        for n in sizes:
            case = lagrange_case(n, mat, vel)
            steps = max(5, int(2e6 / n**3)) if not quick else 5
            sec, ne = time_lagrange(MPI.COMM_SELF, case, steps, repeats=5)
            results.append({"name": f"lagrange_hex8_{label}", "metric": "time_per_element_cycle",
                            "value": sec * 1e6, "unit": "us", "params": {"elements": ne, "ranks": 1,
                                                                         "steps": steps, "repeats": 5}})
        mem = memory_per_element(lagrange_case(sizes[-1], mat, vel))
        results.append({"name": f"lagrange_hex8_{label}", "metric": "memory_per_element",
                        "value": mem, "unit": "B", "params": {"elements": sizes[-1] ** 3}})
    # the assumed-strain hourglass stiffness against the viscous control, one run each (the issue's
    # bound: at most 1.3x per element-cycle): 2-D quads, and hexahedra at the larger size
    n2 = 100 if quick else 316
    n3 = sizes[-1]
    for label, make, ne_n in (("quad4", lambda c: lagrange_case_2d(n2, ELASTIC, 1.0, c), n2**2),
                              ("hex8", lambda c: lagrange_case(n3, ELASTIC, 1.0, c), n3**3)):
        steps = 5 if quick else max(5, int(2e6 / ne_n))
        cost = {}
        for control in ("viscous", "assumed_strain"):
            sec, ne = time_lagrange(MPI.COMM_SELF, make(control), steps, repeats=5)
            cost[control] = sec * 1e6
            results.append({"name": f"lagrange_{label}_{control}", "metric": "time_per_element_cycle",
                            "value": sec * 1e6, "unit": "us",
                            "params": {"elements": ne, "ranks": 1, "steps": steps, "repeats": 5}})
        results.append({"name": f"lagrange_{label}_assumed_strain_vs_viscous", "metric": "cost_ratio",
                        "value": cost["assumed_strain"] / cost["viscous"], "unit": "", "params": {"elements": ne_n}})
    # the plane-strain shell strip's kernel (issue 45: not yet a solver step), elastic and J2
    for label, plastic in (("elastic", False), ("j2", True)):
        for n in ((1000, 10000) if quick else (10000, 100000)):
            steps = 5 if quick else max(5, int(2e6 / n))
            sec = time_shell2d(n, plastic, steps, repeats=5)
            results.append({"name": f"shell2d_strip_{label}", "metric": "time_per_element_cycle",
                            "value": sec * 1e6, "unit": "us",
                            "params": {"elements": n, "ranks": 1, "steps": steps, "repeats": 5,
                                       "points_through_thickness": 5, "kernel": "beam2d, vectorised numpy"}})
    # 2-rank speed-up at the largest size, measured in one run of mpiexec -n 2 against 1 rank
    for label, mat, vel in (("elastic", ELASTIC, 1.0),):
        n = sizes[-1]
        one = next(r for r in results if r["name"] == f"lagrange_hex8_{label}"
                   and r["metric"] == "time_per_element_cycle" and r["params"]["elements"] == n**3)
        two = _two_ranks(n, label)
        results.append({"name": f"lagrange_hex8_{label}", "metric": "time_per_element_cycle",
                        "value": two * 1e6, "unit": "us", "params": {"elements": n**3, "ranks": 2}})
        results.append({"name": f"lagrange_hex8_{label}", "metric": "speedup_2_ranks",
                        "value": one["value"] / (two * 1e6), "unit": "x", "params": {"elements": n**3}})
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


def _two_ranks(n: int, label: str) -> float:
    return float(run_worker("orchestrator.bench.steps", 2, n, label))


def _worker(n: int, label: str) -> None:
    from mpi4py import MPI

    if label.startswith("ale:"):
        sec = time_ale(MPI.COMM_WORLD, n, label[4:], max(5, int(4e6 / n**3)), repeats=5)
        if MPI.COMM_WORLD.rank == 0:
            print(sec)
        return
    mat = {"elastic": ELASTIC, "j2_johnson_cook": J2}[label]
    case = lagrange_case(n, mat, 1.0 if label == "elastic" else 200.0)
    sec, _ = time_lagrange(MPI.COMM_WORLD, case, max(5, int(2e6 / n**3)), repeats=5)
    if MPI.COMM_WORLD.rank == 0:
        print(sec)


@bench("taylor")
def bench_taylor(out: Path, quick: bool = False) -> Path:
    """Mesh convergence of the Taylor bar (final length, impact-face diameter) against cost, through
    the real launcher (coupler + solver ranks). Also charts error against wall time."""
    import shutil
    import tempfile

    from orchestrator.case import load_case, ranks_for
    from orchestrator.launch import run_job

    src = Path(__file__).resolve().parents[2] / "cases" / "taylor_bar"
    text = (src / "case.toml").read_text()
    meshes = [(4, 36), (6, 54)] if quick else [(4, 36), (6, 54), (8, 72), (10, 90)]
    results, rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for radial, axial in meshes:
            d = Path(tmp) / f"taylor_{radial}"
            d.mkdir()
            (d / "case.toml").write_text(text.replace("radial_cells = 6, axial_cells = 54",
                                                      f"radial_cells = {radial}, axial_cells = {axial}"))
            case = load_case(d)
            rc = run_job(case, d / "out", ranks_for(case, {}))
            if rc != 0:
                raise RuntimeError(f"taylor bar with radial_cells={radial} failed (exit {rc})")
            s = json.loads((d / "out" / "summary.json").read_text())
            import h5py

            with h5py.File(d / "out" / "steps" / "lagrange_mesh.h5") as h:
                ne = int(h["cells"].shape[0])
            params = {"radial_cells": radial, "axial_cells": axial, "elements": ne, "steps": s["steps"]}
            for name, m in s["check"]["metrics"].items():
                results.append({"name": "taylor_bar", "metric": name, "value": m["value"] * 1e3, "unit": "mm",
                                "params": {**params, "reference_mm": m["reference"] * 1e3,
                                           "rel_error": m["rel_error"]}})
            results.append({"name": "taylor_bar", "metric": "wall_time", "value": s["wall_time_s"],
                            "unit": "s", "params": params})
            rows.append((ne, s["wall_time_s"], s["check"]["metrics"]))
            shutil.rmtree(d / "out")
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    _chart_error_vs_cost(rows, out.with_suffix(".png"))
    return out


def _chart_error_vs_cost(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for metric, marker in (("final_length", "o-"), ("impact_diameter", "s-")):
        ax.loglog([r[1] for r in rows], [max(r[2][metric]["rel_error"], 1e-6) for r in rows], marker, label=metric)
        for ne, wall, m in rows:
            ax.annotate(f"{ne}", (wall, max(m[metric]["rel_error"], 1e-6)), fontsize=7)
    ax.set_xlabel("wall time (s), 1 rank")
    ax.set_ylabel("relative error vs published mid-point")
    ax.set_title("Taylor bar: accuracy against cost (labels: elements)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def sedov_config(n: int, mode: str, upper: str = "wall") -> dict:
    """3-D Sedov octant on n^3 zones (the benchmark problem of LULESH as well); ``upper``: the kind
    of the three upper faces (the lower ones are the octant's symmetry walls)."""
    faces = {f"{a}_{s}": ("wall" if s == "lower" else upper) for a in "xyz" for s in ("lower", "upper")}
    return {"dimension": 3, "mode": mode,
            "grid": {"lower": [0.0] * 3, "upper": [1.2] * 3, "cells": [n] * 3},
            "boundaries": faces,
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": 1.0, "pressure": 1e-6, "velocity": [0.0] * 3}],
            "energy_sources": [{"energy": 0.106384, "at": [0.0, 0.0, 0.0]}]}


def time_ale(comm, n: int, mode: str, steps: int, repeats: int, upper: str = "wall") -> float:
    """Median seconds per zone-cycle: Lagrange step alone (mode lagrangian) or Lagrange + remap."""
    from solvers.ale.solver import AleSolver

    s = AleSolver(comm, sedov_config(n, mode, upper))
    t = 0.0

    def cycle(k):
        nonlocal t
        dt = 0.5 * s.stable_dt()
        t += dt
        s.predict(dt)
        s.correct(None, step=k, time=t)
        s.remap(None)

    for k in range(3):  # warm-up; the blast is past its first, tiny steps
        cycle(k)
    samples = []
    for _ in range(repeats):
        comm.Barrier()
        t0 = time.perf_counter()
        for k in range(steps):
            cycle(k)
        comm.Barrier()
        samples.append((time.perf_counter() - t0) / (steps * n**3))
    return float(np.median(samples))


def ale_memory_per_zone(n: int) -> float:
    from mpi4py import MPI

    from solvers.ale.solver import AleSolver

    tracemalloc.start()
    s = AleSolver(MPI.COMM_SELF, sedov_config(n, "eulerian"))
    dt = 0.5 * s.stable_dt()
    s.predict(dt)
    s.correct(None, step=1, time=dt)
    s.remap(None)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / n**3


@bench("ale")
def bench_ale(out: Path, quick: bool = False) -> Path:
    from mpi4py import MPI

    sizes = [12, 20] if quick else [30, 60]
    results = []
    for n in sizes:
        steps = 5 if quick else max(5, int(4e6 / n**3))
        for mode, label in (("lagrangian", "lagrange_step"), ("eulerian", "lagrange_plus_remap")):
            sec = time_ale(MPI.COMM_SELF, n, mode, steps, repeats=5)
            results.append({"name": f"ale_sedov3d_{label}", "metric": "time_per_zone_cycle", "value": sec * 1e6,
                            "unit": "us", "params": {"zones": n**3, "ranks": 1, "steps": steps, "repeats": 5}})
    n = sizes[-1]
    for mode, label in (("lagrangian", "lagrange_step"), ("eulerian", "lagrange_plus_remap")):
        one = next(r for r in results if r["name"] == f"ale_sedov3d_{label}" and r["params"]["zones"] == n**3)
        two = _two_ranks(n, f"ale:{mode}")
        results.append({"name": f"ale_sedov3d_{label}", "metric": "time_per_zone_cycle", "value": two * 1e6,
                        "unit": "us", "params": {"zones": n**3, "ranks": 2}})
        results.append({"name": f"ale_sedov3d_{label}", "metric": "parallel_efficiency_2_ranks",
                        "value": one["value"] / (2 * two * 1e6), "unit": "", "params": {"zones": n**3}})
    # open faces: the characteristic (non-reflecting) upper faces against zero-gradient ones and
    # walls, Lagrange + remap, the same run (the bound: at most 1.3x per zone-cycle)
    steps = 5 if quick else max(5, int(4e6 / n**3))
    open_cost = {}
    for upper in ("wall", "zero_gradient", "outflow"):
        open_cost[upper] = time_ale(MPI.COMM_SELF, n, "eulerian", steps, repeats=5, upper=upper) * 1e6
        results.append({"name": f"ale_sedov3d_upper_{upper}", "metric": "time_per_zone_cycle",
                        "value": open_cost[upper], "unit": "us", "params": {"zones": n**3, "ranks": 1, "steps": steps}})
    for ref in ("wall", "zero_gradient"):
        results.append({"name": f"ale_sedov3d_outflow_vs_{ref}", "metric": "cost_ratio",
                        "value": open_cost["outflow"] / open_cost[ref], "unit": "", "params": {"zones": n**3}})
    results.append({"name": "ale_sedov3d", "metric": "memory_per_zone", "value": ale_memory_per_zone(sizes[-1]),
                    "unit": "B", "params": {"zones": sizes[-1] ** 3}})
    results.append({"name": "lulesh_2.0_reference", "metric": "time_per_zone_cycle", "value": 0.72, "unit": "us",
                    "params": {"note": "LULESH 2.0 serial -O3 Lagrange step on this machine kind (quoted, not run)"}})
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


@bench("sod")
def bench_sod(out: Path, quick: bool = False) -> Path:
    """Sod on 100..1600 zones through the launcher: L1 density error against the exact solution, its
    observed order, and wall time (accuracy against cost)."""
    import tempfile

    from orchestrator.case import load_case, ranks_for
    from orchestrator.launch import run_job

    src = Path(__file__).resolve().parents[2] / "cases" / "sod"
    text = (src / "case.toml").read_text()
    sizes = [100, 200, 400] if quick else [100, 200, 400, 800, 1600]
    results, rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            d = Path(tmp) / f"sod_{n}"
            d.mkdir()
            (d / "case.toml").write_text(text.replace("upper = [1.0, 0.0025], cells = [400, 1]",
                                                      f"upper = [1.0, {1.0 / n!r}], cells = [{n}, 1]"))
            case = load_case(d)
            if run_job(case, d / "out", ranks_for(case, {})) != 0:
                raise RuntimeError(f"sod with {n} zones failed")
            s = json.loads((d / "out" / "summary.json").read_text())
            c = s["check"]  # (a checked metric is under "metrics", the rest under "reported")
            l1 = c["metrics"]["l1_density"]["value"] if "l1_density" in c["metrics"] else c["reported"]["l1_density"]
            rows.append((n, l1, s["wall_time_s"]))
    for i, (n, l1, wall) in enumerate(rows):
        order = float(np.log2(rows[i - 1][1] / l1)) if i else None
        results.append({"name": "sod", "metric": "l1_density_error", "value": l1, "unit": "",
                        "params": {"zones": n, "observed_order": order, "wall_time_s": wall}})
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


def _mesh_study(case_name: str, old: str, grid, sizes, metrics) -> list:
    """Run cases/<case_name> with its grid line ``old`` replaced by ``grid(n)`` for every n through
    the launcher; (n, {metric: value}, wall time, steps) per size."""
    import tempfile

    from orchestrator.case import load_case, ranks_for
    from orchestrator.launch import run_job

    src = Path(__file__).resolve().parents[2] / "cases" / case_name
    text = (src / "case.toml").read_text()
    if old not in text:
        raise RuntimeError(f"cases/{case_name}/case.toml no longer has the grid line {old!r}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            d = Path(tmp) / f"{case_name}_{n}"
            d.mkdir()
            (d / "case.toml").write_text(text.replace(old, grid(n)))
            case = load_case(d)
            if run_job(case, d / "out", ranks_for(case, {})) != 0:
                raise RuntimeError(f"{case_name} with {n} zones failed")
            s = json.loads((d / "out" / "summary.json").read_text())
            vals = {**s["check"]["reported"], **{k: m["value"] for k, m in s["check"]["metrics"].items()}}
            # (a plateau narrower than the check's margins has no value: null, not NaN, in the JSON)
            rows.append((n, {k: (vals[k] if np.isfinite(vals[k]) else None) for k in metrics},
                         s["wall_time_s"], s["steps"]))
    return rows


def ball_config(n: int, two: bool) -> dict:
    """3-D periodic box n^3 with a ball (radius 0.3) of a heavy gas in a light one (``two``; else both
    the same material) carried by a uniform velocity: the cost of several materials per zone."""
    vel = [0.3, -0.2, 0.1]
    ball = "(x - 0.5)**2 + (y - 0.5)**2 + (z - 0.5)**2 < 0.09"
    return {"dimension": 3, "mode": "eulerian",
            "grid": {"lower": [0.0] * 3, "upper": [1.0] * 3, "cells": [n] * 3},
            "boundaries": {f: "periodic" for f in ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")},
            "materials": {"light": {"eos": "ideal_gas", "gamma": 1.4}, "heavy": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "light", "density": 1.0, "pressure": 1.0, "velocity": vel},
                        {"material": "heavy" if two else "light", "region": ball, "density": 5.0, "pressure": 1.0,
                         "velocity": vel}]}


def time_ball(n: int, two: bool, steps: int, repeats: int) -> tuple[float, float]:
    """Median seconds per zone-cycle (Lagrange + remap) and the share of mixed zones."""
    from mpi4py import MPI

    from solvers.ale.solver import AleSolver

    s = AleSolver(MPI.COMM_SELF, ball_config(n, two))
    t = 0.0
    samples = []
    for r in range(repeats + 1):
        t0 = time.perf_counter()
        for k in range(steps):
            dt = 0.5 * s.stable_dt()
            t += dt
            s.predict(dt)
            s.correct(None, step=r * steps + k + 1, time=t)
            s.remap(None)
        if r:  # the first round warms up
            samples.append((time.perf_counter() - t0) / (steps * n**3))
    mixed = 0.0
    if s.mm is not None:
        f = s.mm.fractions()[s.block.real_zone]
        mixed = float(np.mean(np.sum((f > 1e-12) & (f < 1 - 1e-12), axis=1) > 0))
    return float(np.median(samples)), mixed


@bench("advect")
def bench_advect(out: Path, quick: bool = False) -> Path:
    """Two materials: the advected square (one diagonal period, 32/64/128 zones a side) and the
    water-air shock tube (200..800 zones): interface accuracy and conservation against cost; the
    cost per zone-cycle of two materials against one (3-D advected ball)."""
    results = []
    n = 16 if quick else 32
    one, _ = time_ball(n, False, 5, 3)
    two, mixed = time_ball(n, True, 5, 3)
    for label, val in (("one_material", one), ("two_materials", two)):
        results.append({"name": "advected_ball_3d", "metric": "us_per_zone_cycle", "value": val * 1e6, "unit": "us",
                        "params": {"zones": n**3, "materials": label, "mixed_zone_share": mixed if label != "one_material" else 0.0,
                                   "ratio_to_one_material": val / one}})
    sq = _mesh_study("advected_square", "cells = [64, 64]", lambda n: f"cells = [{n}, {n}]",
                     [32, 64] if quick else [32, 64, 128], ["symmetric_difference", "volume_drift_rel"])
    for i, (n, v, wall, steps) in enumerate(sq):
        order = float(np.log2(sq[i - 1][1]["symmetric_difference"] / v["symmetric_difference"])) if i else None
        results.append({"name": "advected_square", "metric": "symmetric_difference_area",
                        "value": v["symmetric_difference"], "unit": "m^2",
                        "params": {"zones_per_side": n, "observed_order": order, "square_area": 0.16,
                                   "volume_drift_rel": v["volume_drift_rel"], "steps": steps,
                                   "wall_time_s": wall}})
    wa = _mesh_study("water_air_shock_tube", "upper = [1.0, 0.0025], cells = [400, 1]",
                     lambda n: f"upper = [1.0, {1.0 / n!r}], cells = [{n}, 1]",
                     [200, 400] if quick else [200, 400, 800],
                     ["p_star", "p_star_mean", "rho_star_left", "rho_star_right", "u_star", "l1_density",
                      "interface_position_error_cells", "interface_pressure_oscillation_rel"])
    for n, v, wall, steps in wa:
        results.append({"name": "water_air_shock_tube", "metric": "l1_density_error", "value": v["l1_density"],
                        "unit": "kg/m^3", "params": {"zones": n, **v, "steps": steps, "wall_time_s": wall}})
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


if __name__ == "__main__" and sys.argv[1:2] == ["worker"]:
    _worker(int(sys.argv[2]), sys.argv[3])
