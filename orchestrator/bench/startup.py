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

Each kind runs again with its processes forked from a warm process server (orchestrator/prestart, as
the test suite runs them): the same figures, the CPU being the stubs' plus what the server's log says
each forked process used (with everything it reaped), and the ratios plain / warm.
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

from orchestrator import prestart
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


def _env() -> dict:
    from orchestrator.launch import THREAD_ENV

    env = dict(os.environ, **THREAD_ENV)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop(prestart.ENV, None)
    return env


def _logged_cpu(log: Path) -> float:
    try:
        return sum(json.loads(line)["cpu_s"] for line in log.read_text().splitlines() if line.strip())
    except OSError:
        return 0.0


def time_job(case: Path, out: Path, server: Path | None = None) -> dict:
    """One `immerse run` of ``case`` in a process of its own (through the warm ``server`` if given):
    wall and CPU seconds of all its processes, first step."""
    env = _env()
    log = Path(f"{server}.log") if server else None
    logged0 = _logged_cpu(log) if log else 0.0
    cpu0, t0 = _children_cpu(), time.perf_counter()
    if server is None:
        r = cli_run(case, out, env=env, cwd=REPO)
    else:
        env[prestart.ENV] = str(server)
        r = subprocess.run(prestart.command("orchestrator.cli", ["run", str(case), "--out", str(out), "--replace"]),
                           capture_output=True, text=True, env=env, cwd=REPO)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if log:
        time.sleep(0.05)  # the watchers log as their processes are reaped, just after the stubs end
        cpu += _logged_cpu(log) - logged0
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


def start_server(tmp: Path) -> tuple[subprocess.Popen, Path]:
    """A warm process server of the bench's own; returns once it answers."""
    path = tmp / "prestart"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator.prestart.server", str(path)], env=_env(), cwd=REPO,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)
    line = proc.stdout.readline()
    if not line or not json.loads(line).get("ready"):
        proc.kill()
        raise RuntimeError("startup bench: the warm process server did not start")
    return proc, path


@bench("startup")
def bench_startup(out: Path, quick: bool = False) -> Path:
    """Medians over rounds (the kinds interleaved, so that the machine's load hits them alike)."""
    rounds = 1 if quick else 7
    kinds = {k: v for k, v in KINDS.items() if not quick or k == "ale"}
    floors = []
    runs = {k: [] for k in kinds}
    warm = {k: [] for k in kinds}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cases = {k: _two_step_case(name, tmp) for k, name in kinds.items()}
        server, path = start_server(tmp)
        try:
            for r in range(rounds):
                floors.append(floor_cpu())
                for k, case in cases.items():
                    runs[k].append(time_job(case, tmp / f"out_{case.name}_{r}"))
                    warm[k].append(time_job(case, tmp / f"warm_{case.name}_{r}", path))
        finally:
            server.terminate()
            server.wait(10)
    floor = float(np.median(floors))
    results = [{"name": "numpy_scipy_numba_setup", "metric": "cpu_time", "value": floor, "unit": "s",
                "params": {"rounds": rounds, "of": "a fresh python: import numpy, numba; numba's registries set up "
                                                  "(with its BLAS check's import of scipy.linalg)"}}]
    keys = ("wall_s", "cpu_s", "first_step_s", "steps_wall_s")
    for k, rs in runs.items():
        med = {key: float(np.median([x[key] for x in rs])) for key in keys}
        hot = {key: float(np.median([x[key] for x in warm[k]])) for key in keys}
        results.append({"name": KINDS[k], "metric": "job_cpu_time", "value": med["cpu_s"], "unit": "s",
                        "params": {"kind": k, "steps": STEPS, "rounds": rounds, "launcher_wall_s": med["wall_s"],
                                   "first_step_s": med["first_step_s"], "time_loop_wall_s": med["steps_wall_s"],
                                   "cpu_over_floor": med["cpu_s"] / floor,
                                   "of": "CPU of the launcher and every process it started (RUSAGE_CHILDREN), "
                                         f"median of {rounds}"}})
        results.append({"name": f"{KINDS[k]}_warm", "metric": "job_cpu_time", "value": hot["cpu_s"], "unit": "s",
                        "params": {"kind": k, "steps": STEPS, "rounds": rounds, "launcher_wall_s": hot["wall_s"],
                                   "first_step_s": hot["first_step_s"], "time_loop_wall_s": hot["steps_wall_s"],
                                   "cpu_plain_over_warm": med["cpu_s"] / hot["cpu_s"],
                                   "wall_plain_over_warm": med["wall_s"] / hot["wall_s"],
                                   "of": "the same job, its processes forked from a warm process server "
                                         "(orchestrator/prestart): the stubs' CPU and the forked processes' "
                                         f"(the server's log), median of {rounds}"}})
    out.write_text(json.dumps({"results": results, "machine": machine()}, indent=2))
    return out
