"""The start-up bench (`startup`): what a job costs around its steps, per kind of job.

A job is 3-5 processes (the launcher, mpiexec, the coupler, a rank per solver group), and every one
that loads numba kernels first pays numpy's, scipy's and numba's own set-up (numba's typing and
lowering registries, and its BLAS check, which imports scipy.linalg). Short jobs are mostly this:
the test suite runs ~330 jobs, and their start-up to the first step was 552 s of its 2,340 s of
tests (README, Tests). Measured here, as medians of repeated runs:

* the floor: the CPU seconds of a fresh Python that imports numpy and numba and sets up numba's
  registries (what loading the first cached kernel costs a solver process, before any of ours);
* per job kind, one shipped case cut to two steps (``run.max_steps``): the launcher's wall time,
  the CPU seconds of the whole process tree (the launcher and everything it started, reaped:
  ``RUSAGE_CHILDREN``), and the first step's age (summary.json ``first_step_s``). The kinds: an ALE
  background alone (sod), a Lagrangian body alone (elastic_bar_wave), both coupled
  (acoustic_transmission), SPH particles alone (sph_shock_tube).

The job's CPU over the floor says how many floors a job pays and what our own start-up adds.
"""
from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, cli_run, machine

REPO = Path(__file__).resolve().parents[2]
KINDS = {"ale": "sod", "lagrange": "elastic_bar_wave", "coupled ale+lagrange": "acoustic_transmission",
         "sph": "sph_shock_tube"}
STEPS = 2
FLOOR = ("import time; t = time.process_time(); import numpy, numba; "
         "from numba.core.registry import cpu_target; cpu_target.target_context.refresh(); "
         "print(time.process_time() - t)")


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _two_step_case(name: str, tmp: Path) -> Path:
    """cases/<name> stopped after STEPS steps (its outputs and checkpoints left as they are: the run
    ends at the step limit, before any of them but the first)."""
    case = tmp / name
    shutil.copytree(REPO / "cases" / name, case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    text, n = re.subn(r"(?m)^\[run\]\s*$", f"[run]\nmax_steps = {STEPS}", p.read_text(), count=1)
    if n != 1:
        raise RuntimeError(f"cases/{name}/case.toml has no [run] table")
    p.write_text(text)
    return case


def time_job(case: Path, out: Path) -> dict:
    """One `immerse run` of ``case`` in a process of its own: wall and tree CPU seconds, first step."""
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    cpu0, t0 = _children_cpu(), time.perf_counter()
    r = cli_run(case, out, env=env, cwd=REPO)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    summary = out / "summary.json"
    if not summary.is_file():
        raise RuntimeError(f"startup bench: {case.name} wrote no summary (exit {r.returncode}): {r.stderr.strip()[-300:]}")
    s = json.loads(summary.read_text())
    if s.get("steps") != STEPS:
        raise RuntimeError(f"startup bench: {case.name} ran {s.get('steps')} steps, not {STEPS}")
    return {"wall_s": wall, "cpu_s": cpu, "first_step_s": s.get("first_step_s"), "steps_wall_s": s["wall_time_s"]}


def floor_cpu() -> float:
    """CPU seconds of numpy + numba + numba's registries in a fresh process (its own clock)."""
    r = subprocess.run([sys.executable, "-c", FLOOR], capture_output=True, text=True, check=True,
                       env=dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1"))
    return float(r.stdout.strip().splitlines()[-1])


@bench("startup")
def bench_startup(out: Path, quick: bool = False) -> Path:
    """Medians over rounds (the kinds interleaved, so that the machine's load hits them alike)."""
    rounds = 1 if quick else 7
    kinds = {k: v for k, v in KINDS.items() if not quick or k == "ale"}
    floors = []
    runs = {k: [] for k in kinds}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cases = {k: _two_step_case(name, tmp) for k, name in kinds.items()}
        for r in range(rounds):
            floors.append(floor_cpu())
            for k, case in cases.items():
                runs[k].append(time_job(case, tmp / f"out_{case.name}_{r}"))
    floor = float(np.median(floors))
    results = [{"name": "numpy_scipy_numba_setup", "metric": "cpu_time", "value": floor, "unit": "s",
                "params": {"rounds": rounds, "of": "a fresh python: import numpy, numba; numba's registries set up "
                                                  "(with its BLAS check's import of scipy.linalg)"}}]
    for k, rs in runs.items():
        med = {key: float(np.median([x[key] for x in rs])) for key in ("wall_s", "cpu_s", "first_step_s", "steps_wall_s")}
        results.append({"name": KINDS[k], "metric": "job_cpu_time", "value": med["cpu_s"], "unit": "s",
                        "params": {"kind": k, "steps": STEPS, "rounds": rounds, "launcher_wall_s": med["wall_s"],
                                   "first_step_s": med["first_step_s"], "time_loop_wall_s": med["steps_wall_s"],
                                   "cpu_over_floor": med["cpu_s"] / floor,
                                   "of": "CPU of the launcher and every process it started (RUSAGE_CHILDREN), "
                                         f"median of {rounds}"}})
    out.write_text(json.dumps({"results": results, "machine": machine()}, indent=2))
    return out
