"""The single-node Slurm test cluster of slurm_cluster.py works: an `sbatch --array` job runs, and
the state and exit code of every finished task can be read back (scontrol, the jobcomp file,
`sacct -c`); a cancelled job reads CANCELLED; the daemons and jobs are gone after the cluster,
also when the body raised.  Skipped with the reason where no cluster can be started (not root,
Slurm/munge not installed; `.ci/run` installs Debian's slurm-wlm and munge)."""
from __future__ import annotations

import subprocess
import textwrap
import time
from pathlib import Path

import pytest

from tests.orchestrator.campaign.slurm_cluster import (
    array_task_states,
    cluster_processes,
    command_env,
    read_jobcomp,
    single_node_slurm,
    slurm_available,
)

REASON = slurm_available()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

JOB = textwrap.dedent("""\
    #!/bin/bash
    echo "$SLURM_ARRAY_TASK_ID" > "task_${SLURM_ARRAY_TASK_ID}.txt"
    if [ "$SLURM_ARRAY_TASK_ID" = 2 ]; then exit 3; fi
    exit 0
    """)


def slurm(env: dict[str, str], *args: str, cwd: Path | None = None, check: bool = True) -> subprocess.CompletedProcess:
    r = subprocess.run(args, env=command_env(env), cwd=cwd, capture_output=True, text=True, timeout=30,
                       stdin=subprocess.DEVNULL)
    if check and r.returncode != 0:
        raise AssertionError(f"{' '.join(args)} exited {r.returncode}: {r.stdout}{r.stderr}")
    return r


def sbatch(env: dict[str, str], *args: str, cwd: Path) -> str:
    return slurm(env, "sbatch", "--parsable", *args, cwd=cwd).stdout.strip().split(";")[0]


def wait_until(what: str, predicate, timeout: float = 60.0):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout:.0f} s: {what}")
        time.sleep(0.2)


def active(env: dict[str, str], job_id: str) -> list[str]:
    """'<id> <state>' lines of the tasks of `job_id` still pending or running (squeue -r)."""
    return slurm(env, "squeue", "-h", "-r", "-j", job_id, "-o", "%i %T").stdout.split("\n")[:-1]


@pytest.mark.timeout(120)
def test_array_job_states_and_exit_codes(tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    (work / "job.sh").write_text(JOB)
    with single_node_slurm(tmp_path / "cluster") as env:
        assert Path(env["SLURM_CONF"]).is_file()
        job = sbatch(env, "--array=0-2", "--output=slurm-%A_%a.out", "job.sh", cwd=work)
        assert job.isdigit(), job
        wait_until("the array has no task pending or running", lambda: not active(env, job))

        for task in range(3):
            assert (work / f"task_{task}.txt").read_text().strip() == str(task)

        # method 1: scontrol -o show job <jobid>, one record per task
        states = array_task_states(env, job)
        assert states == {"0": ("COMPLETED", "0:0"), "1": ("COMPLETED", "0:0"), "2": ("FAILED", "3:0")}, states

        # method 2: the jobcomp/filetxt completion log
        def task_records():
            records = [r for r in read_jobcomp(tmp_path / "cluster") if r.get("ArrayJobId") == job]
            return records if len(records) == 3 else None

        records = wait_until("3 jobcomp records", task_records, timeout=10)
        by_task = {r["ArrayTaskId"]: (r["JobState"], r["ExitCode"]) for r in records}
        assert by_task == states, records

        # sacct has no accounting storage, but `sacct -c` reads the completion log by raw job id
        assert slurm(env, "sacct", "-j", job, check=False).returncode != 0
        raw_ids = {r["ArrayTaskId"]: r["JobId"] for r in records}
        out = slurm(env, "sacct", "-c", "-n", "-P", "-j", raw_ids["2"], "-o", "JobID,State,ExitCode").stdout
        assert out.split() == [f"{raw_ids['2']}|FAILED|3:0"], out


@pytest.mark.timeout(120)
def test_cancelled_job_reads_cancelled(tmp_path):
    with single_node_slurm(tmp_path / "cluster") as env:
        job = sbatch(env, "--output=/dev/null", "--wrap=sleep 300", cwd=tmp_path)
        wait_until("the job runs", lambda: active(env, job) == [f"{job} RUNNING"])
        wait_until("the job's sleep runs", lambda: "sleep" in {_comm(p) for p in cluster_processes(env)}, timeout=30)
        slurm(env, "scancel", job)
        wait_until("the cancelled job leaves squeue", lambda: not active(env, job))
        state, exit_code = array_task_states(env, job)[job]
        assert state == "CANCELLED", (state, exit_code)
        # killed by SIGTERM: slurm records the signal (0:15), or, when the batch shell outlives its
        # sleep by an instant (a loaded machine), the shell's exit status 128 + 15 (143:0)
        assert exit_code in ("0:15", "143:0"), exit_code
        records = wait_until("a jobcomp record", lambda: read_jobcomp(tmp_path / "cluster"), timeout=10)
        assert [(r["JobId"], r["JobState"]) for r in records] == [(job, "CANCELLED")]


@pytest.mark.timeout(120)
def test_everything_stops_when_the_body_raises(tmp_path):
    cluster = tmp_path / "cluster"
    with pytest.raises(RuntimeError, match="body failed"):
        with single_node_slurm(cluster) as env:
            job = sbatch(env, "--output=/dev/null", "--wrap=sleep 300", cwd=tmp_path)
            wait_until("the job runs", lambda: active(env, job) == [f"{job} RUNNING"])
            pids = {name: int((cluster / "run" / f"{name}.pid").read_text().split()[0])
                    for name in ("munged", "slurmctld", "slurmd")}
            # squeue says RUNNING once the job is allocated; slurmd starts slurmstepd right after
            wait_until("slurmstepd and the job's sleep run",
                       lambda: {"slurmstepd", "sleep"} <= {_comm(p) for p in cluster_processes(env)}, timeout=30)
            raise RuntimeError("body failed")
    for name, pid in pids.items():
        assert not _running(pid), f"{name} (pid {pid}) still runs"
    assert cluster_processes(env) == []


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def _comm(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm") as f:
            return f.read().strip()
    except OSError:
        return ""
