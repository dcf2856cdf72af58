"""`immerse bench implicit`: the cost of the implicit dynamic step (issue 12) against the number of
elements, and where it beats the explicit one.

* Scaling: a free plane-strain rubber block spinning at 50 rad/s (spinning_block_midpoint's material
  and motion), n x n quads, 10^3 ... 10^5 elements (10^2, 10^3 with --quick), one midpoint step at
  16.6 times the explicit limit of the 4 x 4 case scaled with h: Newton iterations per step, seconds
  per step and per element-step, and the split between the element tangent (assembly) and the
  sparse direct solve (SuperLU, one per Newton iteration). 2-D: a 3-D block of 10^5 hexahedra is a
  3 x 10^5 dof system whose fill-in exceeds what a gathered direct solve on one rank should carry.
* Ranks: the largest block's step on 1 and 2 ranks (mpiexec, this module's worker): the solves run
  on rank 0 (the others wait), the elements are split among the ranks where that was measured to
  pay (gathered_step.RankShare; ``elements_split``), every rank assembles.
* Break-even on the L-block (cases/l_block_free_flight): the median seconds of an explicit step (at
  run.dt_scale 0.5, the stable fraction at its Poisson ratio 0.495) and of a midpoint step (0.1 s,
  during the free flight), both in this process; the implicit run wins when its step is more than
  ``break_even_dt_ratio`` = t_midpoint / t_explicit times the explicit one. Reported with the ratio the
  case runs at and the wall time each would take to t = 30 s.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, machine, run_worker

RUBBER = {"model": "linear_elastic", "density": 1000.0, "youngs_modulus": 1.0e6, "poisson_ratio": 0.3}


def spinning_block(n: int, dt_ratio: float = 16.6) -> tuple[dict, float]:
    """(the case of an n x n block 0.1 m wide spinning at 50 rad/s, its implicit step: dt_ratio times
    the explicit limit h / c)."""
    c = (RUBBER["youngs_modulus"] * 0.7 / (1.3 * 0.4) / RUBBER["density"]) ** 0.5
    dt = dt_ratio * (0.1 / n) / c
    case = {"name": "bench", "case_dir": ".", "run": {"dimension": 2, "end_time": 1.0, "dt_scale": 0.9},
            "materials": {"m": dict(RUBBER)},
            "lagrange": {"integrator": "midpoint", "time_step": dt,
                         "bodies": [{"name": "block", "material": "m",
                                     "mesh": {"box": {"lower": [-0.05, -0.05], "upper": [0.05, 0.05], "cells": [n, n]}},
                                     "initial_velocity": ["0.5 - 50.0 * y + 2.0 * x", "0.2 + 50.0 * x + 2.0 * y"]}]},
            "boundaries": []}
    return case, dt


def time_midpoint_step(n: int, comm=None) -> dict:
    """One midpoint step of the n x n spinning block (on comm, default this process alone), the
    tangent (the elements' evaluation, gathering and assembly) and the solve timed apart."""
    from mpi4py import MPI

    from solvers.lagrange import implicit_step
    from solvers.lagrange.implicit_dynamic import MidpointSolver

    comm = comm or MPI.COMM_SELF
    case, dt = spinning_block(n)
    s = MidpointSolver(comm, case)
    spent = {"tangent": 0.0, "solve": 0.0}
    real_svk, real_spsolve = implicit_step._svk, implicit_step.spla.spsolve

    def svk(*a, **k):
        t0 = time.perf_counter()
        out = real_svk(*a, **k)
        spent["tangent"] += time.perf_counter() - t0
        return out

    def spsolve(*a, **k):
        t0 = time.perf_counter()
        out = real_spsolve(*a, **k)
        spent["solve"] += time.perf_counter() - t0
        return out

    implicit_step._svk, implicit_step.spla.spsolve = svk, spsolve
    try:
        comm.Barrier()
        t0 = time.perf_counter()
        s.predict(dt)
        s.correct(step=1, time=dt)
        wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    finally:
        implicit_step._svk, implicit_step.spla.spsolve = real_svk, real_spsolve
    ne = n * n
    return {"name": "midpoint_step", "metric": "time_per_element_step", "value": wall / ne * 1e6, "unit": "us",
            "params": {"elements": ne, "ranks": comm.size, "dofs": 2 * (n + 1) ** 2, "dt_s": dt, "dt_over_explicit": 16.6,
                       "elements_split": bool(s._ranks and any(v is True for v in s._ranks.split.values())),
                       "step_s": wall, "newton_iterations": s.iterations, "tangent_s": spent["tangent"],
                       "solve_s": spent["solve"]}}


def break_even(quick: bool) -> dict:
    """The L-block's explicit and midpoint step costs (module docstring)."""
    from mpi4py import MPI

    from orchestrator.case import load_case
    from solvers.lagrange.implicit_dynamic import MidpointSolver
    from solvers.lagrange.solver import LagrangeSolver

    cases = Path(__file__).resolve().parents[2] / "cases"
    case = load_case(cases / "l_block_free_flight")
    steps = 10 if quick else 40
    mid = MidpointSolver(MPI.COMM_SELF, case)
    dt_mid = float(case["lagrange"]["time_step"])
    t, per_mid = 0.0, []
    while t < 5.0 + (steps + 1) * dt_mid:      # through the load phase; the free flight's steps timed
        t0 = time.perf_counter()
        mid.predict(dt_mid)
        mid.correct(step=1, time=t + dt_mid)
        if t >= 5.0 - 1e-9:
            per_mid.append(time.perf_counter() - t0)
        t += dt_mid
    explicit = {**case, "lagrange": {k: v for k, v in case["lagrange"].items()
                                     if k not in ("integrator", "time_step")}}
    exp = LagrangeSolver(MPI.COMM_SELF, explicit)
    per_exp = []
    for k in range(50 if quick else 300):
        dt = 0.5 * exp.stable_dt()
        t0 = time.perf_counter()
        exp.predict(dt)
        exp.correct(None, step=k + 1, time=(k + 1) * dt)
        per_exp.append(time.perf_counter() - t0)
    dt_exp = 0.5 * exp.stable_dt()
    t_mid, t_exp = float(np.median(per_mid)), float(np.median(per_exp[5:]))
    return {"name": "l_block", "metric": "break_even_dt_ratio", "value": t_mid / t_exp, "unit": "",
            "params": {"midpoint_step_s": t_mid, "explicit_step_s": t_exp, "midpoint_dt_s": dt_mid,
                       "explicit_dt_s": dt_exp, "dt_ratio": dt_mid / dt_exp,
                       "midpoint_to_30s_s": t_mid * 30.0 / dt_mid, "explicit_to_30s_s": t_exp * 30.0 / dt_exp,
                       "elements": int(mid.n_cells_global), "midpoint_steps_timed": len(per_mid),
                       "note": "the implicit run is cheaper when dt_ratio > value"}}


@bench("implicit")
def bench_implicit(out: Path, quick: bool = False) -> Path:
    sizes = [10, 32] if quick else [32, 100, 317]
    results = [time_midpoint_step(n) for n in sizes]
    ne = np.array([r["params"]["elements"] for r in results], float)
    steps = np.array([r["params"]["step_s"] for r in results])
    results.append({"name": "midpoint_step", "metric": "loglog_slope_vs_elements",
                    "value": float(np.polyfit(np.log(ne), np.log(steps), 1)[0]), "unit": "",
                    "params": {"elements": ne.astype(int).tolist(), "target": "1 (linear); the direct solve's fill-in above"}})
    results += on_ranks(sizes[-1])
    results.append(break_even(quick))
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


def on_ranks(n: int) -> list[dict]:
    """The n x n block's step on 1 and 2 ranks, each in one mpiexec job (the same start-up), and the
    2-rank speed-up of the step and of its tangent."""
    runs = {ranks: json.loads(run_worker("orchestrator.bench.implicit", ranks, n)) for ranks in (1, 2)}
    one, two = runs[1]["params"], runs[2]["params"]
    return [runs[2], {"name": "midpoint_step", "metric": "speedup_2_ranks", "value": one["step_s"] / two["step_s"],
                      "unit": "x", "params": {"elements": one["elements"], "step_s": [one["step_s"], two["step_s"]],
                                              "tangent_s": [one["tangent_s"], two["tangent_s"]],
                                              "tangent_speedup": one["tangent_s"] / two["tangent_s"],
                                              "solve_s": [one["solve_s"], two["solve_s"]],
                                              "note": "1 and 2 ranks, each one mpiexec job; the solves are rank 0's"}}]


if __name__ == "__main__" and sys.argv[1:2] == ["worker"]:
    from mpi4py import MPI

    row = time_midpoint_step(int(sys.argv[2]), MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(row))
