"""Slurm's commands as the campaign engine and `immerse run --engine slurm` use them: sbatch,
squeue, scontrol (sacct where accounting runs), scancel, sinfo. Each call is bounded in time; a
missing command or a refusal is a :class:`SlurmError` with Slurm's own words."""
from __future__ import annotations

import shutil
import subprocess

POLL_S = 1.0
FINAL_STATES = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY",
                "PREEMPTED", "BOOT_FAIL", "DEADLINE", "REVOKED"}


class SlurmError(RuntimeError):
    pass


def command(*args: str, check: bool = True, timeout: float = 60, input: str | None = None) -> subprocess.CompletedProcess:
    """Run a Slurm command (found on PATH, or in the usual sbin directories); ``input``: its stdin."""
    exe = shutil.which(args[0]) or shutil.which(args[0], path="/usr/bin:/usr/sbin:/usr/local/bin")
    if exe is None:
        raise SlurmError(f"{args[0]} not found: --engine slurm needs Slurm's commands on PATH")
    r = subprocess.run([exe, *args[1:]], capture_output=True, text=True, timeout=timeout, input=input,
                       stdin=None if input is not None else subprocess.DEVNULL)
    if check and r.returncode != 0:
        raise SlurmError(f"{' '.join(args[:2])} failed (exit {r.returncode}): "
                         f"{' '.join((r.stderr or r.stdout).split())[:300]}")
    return r


def node_cpus() -> int | None:
    """CPUs of the largest node of the cluster (sinfo), None if unknown."""
    try:
        r = command("sinfo", "-h", "-o", "%c", check=False)
    except (SlurmError, subprocess.TimeoutExpired):
        return None
    vals = [int(v.rstrip("+")) for v in r.stdout.split() if v.rstrip("+").isdigit()]
    return max(vals) if vals else None


def cluster_size() -> tuple[int, int] | None:
    """(nodes, memory of the largest node in bytes) of the Slurm cluster this machine can reach
    (sinfo, within 3 s), or None: no Slurm, or it did not answer."""
    try:
        r = command("sinfo", "-h", "-o", "%D %m", check=False, timeout=3)
    except (SlurmError, subprocess.TimeoutExpired, OSError):
        return None
    nodes, mem = 0, 0
    for line in r.stdout.splitlines() if r.returncode == 0 else ():
        parts = [p.rstrip("+") for p in line.split()]
        if len(parts) == 2 and parts[0].isdigit() and parts[1].isdigit():
            nodes += int(parts[0])
            mem = max(mem, int(parts[1]) << 20)   # sinfo's %m: MB
    return (nodes, mem) if nodes > 0 else None


def queued_tasks(job: str) -> dict[int, str] | None:
    """{array task id: state} of the job's tasks still in the queue; None if squeue failed."""
    try:
        r = command("squeue", "-h", "-r", "-j", job, "-o", "%i %T", check=False)
    except (SlurmError, subprocess.TimeoutExpired):
        return None
    if r.returncode != 0:
        # a job slurmctld no longer knows at all: nothing of it is queued
        return {} if "Invalid job id" in r.stderr else None
    tasks = {}
    for line in r.stdout.splitlines():
        parts = line.split()
        if len(parts) == 2 and "_" in parts[0]:
            tid = parts[0].split("_", 1)[1]
            if tid.isdigit():
                tasks[int(tid)] = parts[1]
    return tasks


def final_states(job: str) -> dict[int, tuple[str, str]]:
    """{array task id: (state, exit code)} of the job's finished tasks: scontrol (while slurmctld
    keeps the job, MinJobAge), else sacct (where accounting runs)."""
    states: dict[int, tuple[str, str]] = {}
    try:
        r = command("scontrol", "-o", "show", "job", job, check=False)
        for line in r.stdout.splitlines():
            f = dict(kv.split("=", 1) for kv in line.split() if "=" in kv)
            tid = f.get("ArrayTaskId", "")
            if tid.isdigit():
                states[int(tid)] = (f.get("JobState", "?"), f.get("ExitCode", "?"))
        if states:
            return states
        r = command("sacct", "-n", "-P", "-X", "-j", job, "-o", "JobID,State,ExitCode", check=False)
        for line in r.stdout.splitlines():
            parts = line.split("|")
            if len(parts) == 3 and "_" in parts[0] and parts[0].split("_", 1)[1].isdigit():
                states[int(parts[0].split("_", 1)[1])] = (parts[1].split()[0], parts[2])
    except (SlurmError, subprocess.TimeoutExpired):
        pass
    return states


def job_state(job: str) -> tuple[str, str] | None:
    """(state, exit code) of a (non-array) job: from squeue while queued (exit code ''), then from
    scontrol or sacct; None if no command knows it."""
    try:
        r = command("squeue", "-h", "-j", job, "-o", "%T", check=False)
        if r.returncode == 0 and r.stdout.strip():
            return r.stdout.split()[0], ""
        r = command("scontrol", "-o", "show", "job", job, check=False)
        for line in r.stdout.splitlines():
            f = dict(kv.split("=", 1) for kv in line.split() if "=" in kv)
            if f.get("JobId") == job:
                return f.get("JobState", "?"), f.get("ExitCode", "?")
        r = command("sacct", "-n", "-P", "-X", "-j", job, "-o", "JobID,State,ExitCode", check=False)
        for line in r.stdout.splitlines():
            parts = line.split("|")
            if len(parts) == 3 and parts[0] == job:
                return parts[1].split()[0], parts[2]
    except (SlurmError, subprocess.TimeoutExpired):
        pass
    return None
