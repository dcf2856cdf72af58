"""The Slurm engine: the campaign's runs as one ``sbatch`` job array, each array task one run.

The script (``OUT/slurm/campaign_<n>.sbatch``, generated from the runs still to do) maps
``$SLURM_ARRAY_TASK_ID`` to a run directory (``OUT/slurm/runs_<n>.txt``, one a line) and runs
``python -m orchestrator.campaign.task`` there: the same ``immerse run`` and the same result.json
as the local engine, so both give the same campaign.csv. Resources: one task with as many CPUs as
the largest run has solver ranks (the coupler mostly waits; an array's tasks share one request),
capped at the largest node's CPUs (``sinfo``); the run's ``mpiexec`` starts its ranks
inside the task on its node (``HYDRA_BOOTSTRAP=fork``). A campaign ``timeout`` becomes the tasks'
``--time``. Task output goes to ``OUT/slurm/task_<job>_<task>.out``.

The campaign process watches the run directories for results and polls ``squeue`` for the tasks
still pending or running; a task that left the queue without a result is looked up with
``scontrol show job`` (or ``sacct`` where accounting runs) and reported by name with its state and
exit code (a cancelled, failed, timed-out or node-failed task): the run has no result and runs
again next time. SIGINT/SIGTERM to the campaign cancel the job (``scancel``). The submitted job is
recorded in ``OUT/slurm/job.json``; a campaign started again while that job still has tasks in the
queue cancels it first, so no two jobs write one run directory.
"""
from __future__ import annotations

import json
import math
import shlex
import signal
import sys
import time
from pathlib import Path

from orchestrator.slurm_commands import (  # noqa: F401  (SlurmError: what run_slurm raises)
    FINAL_STATES,
    POLL_S,
    SlurmError,
    command,
    final_states,
    node_cpus,
    queued_tasks,
)

def script_text(name: str, out: Path, runs_file: Path, n: int, cpus: int, timeout: float | None) -> str:
    from orchestrator.launch import thread_exports

    q = shlex.quote
    lines = ["#!/bin/bash",
             f"#SBATCH --job-name={q('immerse-' + name)}",
             f"#SBATCH --array=0-{n - 1}",
             "#SBATCH --ntasks=1",
             f"#SBATCH --cpus-per-task={cpus}",
             f"#SBATCH --output={q(str(out / 'slurm' / 'task_%A_%a.out'))}"]
    args = ""
    if timeout is not None:
        # the run's own timeout ends it in order; the task's limit leaves a minute for that
        lines.append(f"#SBATCH --time={max(1, math.ceil(timeout / 60) + 1)}")
        args = f" --timeout {timeout!r}"
    lines += ["set -eu",
              thread_exports(),
              "# the run's mpiexec starts its ranks here, in this task's allocation on this node",
              "export HYDRA_BOOTSTRAP=fork",
              f"run_dir=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" {q(str(runs_file))})",
              f"exec {q(sys.executable)} -m orchestrator.campaign.task \"$run_dir\" --engine slurm{args}"]
    return "\n".join(lines) + "\n"


def _cancel_previous(out: Path) -> None:
    rec = out / "slurm" / "job.json"
    try:
        job = json.loads(rec.read_text())["job"]
    except (OSError, ValueError, KeyError):
        return
    q = queued_tasks(job)
    if q:
        print(f"campaign: cancelling slurm job {job} of an earlier start ({len(q)} tasks still queued)",
              flush=True)
        command("scancel", job, check=False)
        deadline = time.monotonic() + 60
        while queued_tasks(job) and time.monotonic() < deadline:
            time.sleep(POLL_S)


def run_slurm(camp, out: Path, pending: list, on_done) -> None:
    """Submit ``pending`` [(RunSpec, run directory)] as one job array and follow it to its end."""
    from orchestrator.campaign.local import run_weight
    from orchestrator.campaign.rundir import atomic_write, record

    if not pending:
        return
    sdir = out / "slurm"
    sdir.mkdir(exist_ok=True)
    _cancel_previous(out)
    k = len(list(sdir.glob("campaign_*.sbatch")))
    runs_file = sdir / f"runs_{k}.txt"
    record(out, runs_file, sdir / f"campaign_{k}.sbatch", sdir / "job.json")
    atomic_write(runs_file, "".join(f"{d}\n" for _, d in pending))
    cap = node_cpus() or max(run_weight(r, 1 << 20) for r, _ in pending)
    cpus = max(run_weight(r, cap) for r, _ in pending)
    script = sdir / f"campaign_{k}.sbatch"
    atomic_write(script, script_text(camp.name, out, runs_file, len(pending), cpus, camp.timeout_s))
    r = command("sbatch", "--parsable", str(script))
    job = r.stdout.strip().split(";")[0]
    if not job.isdigit():
        raise SlurmError(f"sbatch printed {r.stdout.strip()!r}, not a job id")
    atomic_write(sdir / "job.json", json.dumps({"job": job, "script": script.name,
                                                "runs": [run.name for run, _ in pending]}) + "\n")
    print(f"campaign: slurm job {job}, {len(pending)} array tasks of {cpus} CPUs ({script.name})", flush=True)

    remaining = dict(enumerate(pending))

    def stop(signum, frame):
        raise KeyboardInterrupt(signum)

    old = signal.signal(signal.SIGTERM, stop)
    try:
        while remaining:
            for i, (run, d) in list(remaining.items()):
                if (d / "result.json").is_file():
                    del remaining[i]
                    on_done(run, d)
            if not remaining:
                break
            queued = queued_tasks(job)
            gone = [i for i in remaining if queued is not None and i not in queued]
            if gone:
                time.sleep(POLL_S)  # a result written just before the task left the queue
                states = final_states(job)
                for i in gone:
                    run, d = remaining[i]
                    if (d / "result.json").is_file():
                        continue
                    state, code = states.get(i, ("unknown (no longer known to slurmctld)", "?"))
                    if state not in FINAL_STATES and not state.startswith("unknown"):
                        continue  # (still completing)
                    del remaining[i]
                    on_done(run, d, f"slurm array task {job}_{i} ended {state} (exit code {code}) "
                                    f"without a result; see {sdir.name}/task_{job}_{i}.out")
            time.sleep(POLL_S)
    except KeyboardInterrupt as e:
        command("scancel", job, check=False)
        raise KeyboardInterrupt(*(e.args or (int(signal.SIGINT),))) from None
    finally:
        signal.signal(signal.SIGTERM, old)
