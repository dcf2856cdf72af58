"""`immerse run CASE --engine slurm` against a real single-node Slurm (the campaign tests' fixture:
munged, slurmctld, slurmd started as root, stopped after): one batch job whose run gives the same
result as a local run, its log lines followed; a failed run and a cancelled job reported by name.
Skipped with the reason where no cluster can be started."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from tests.cases.test_coupled_cases import _penalty_case as _penalty
from tests.conftest import CASES, REPO
from tests.orchestrator.campaign.slurm_cluster import command_env, single_node_slurm, slurm_available

REASON = slurm_available()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")


def _run(env, *args, timeout=300):
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *map(str, args)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.mark.timeout(600)
def test_a_run_as_one_batch_job_same_result_log_followed_failures_named(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    local = _run(env, "run", CASES / "sod_immersed_wall", "--out", tmp_path / "local")
    assert local.returncode == 0, local.stderr
    with single_node_slurm(tmp_path / "cluster") as cluster:
        senv = command_env(cluster, env)
        # 1. the coupled case (coupler + 2 ranks = 3 tasks on a 2-CPU node: overcommitted)
        out = tmp_path / "slurm"
        r = _run(senv, "run", CASES / "sod_immersed_wall", "--out", out, "--engine", "slurm")
        assert r.returncode == 0, r.stdout + r.stderr
        assert "submitted slurm job" in r.stdout and "3 tasks" in r.stdout, r.stdout
        assert "] finished: 296 steps" in r.stdout and "check passed" in r.stdout, r.stdout  # the log, followed
        a = json.loads((tmp_path / "local" / "summary.json").read_text())
        b = json.loads((out / "summary.json").read_text())
        assert a["steps"] == b["steps"] and a["final"] == b["final"] and a["check"] == b["check"]
        job_out = list(out.glob("slurm-*.out"))
        assert len(job_out) == 1 and "check passed" in job_out[0].read_text()
        # bad input is refused before anything is submitted: the same rules as a local run
        r = _run(senv, "run", CASES / "sod_immersed_wall", "--out", out, "--engine", "slurm")
        assert r.returncode == 2 and "--replace" in r.stderr and "submitted" not in r.stdout, r.stderr
        # 2. a run that fails (penalty far beyond its stable step): the job FAILED, the run's message
        r = _run(senv, "run", _penalty(tmp_path, 1e7, 0.05), "--out", tmp_path / "bad", "--engine", "slurm")
        assert r.returncode == 1, r.stdout + r.stderr
        assert "coupling method 'penalty' is unstable" in r.stdout, r.stdout  # (its log line)
        assert "FAILED with exit code 1" in r.stderr and "immerse-penalty_1e+07" in r.stderr, r.stderr
        # 3. a job cancelled by the cluster (scancel) while it steps: named, steps written stay readable
        long = _penalty(tmp_path, 10.0, 2.0)
        proc = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "run", str(long), "--out",
                                 str(tmp_path / "long"), "--engine", "slurm"], cwd=REPO, env=senv,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not list((tmp_path / "long" / "steps").glob("ale_0*.h5"))[1:]:
            time.sleep(0.2)
        job = next((tmp_path / "long").glob("slurm-*.out")).name.split("-")[1].split(".")[0]
        subprocess.run(["scancel", job], env=senv, check=True, timeout=30)
        stdout, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 1, stdout + stderr
        assert f"slurm job {job} (immerse-penalty_10) ended CANCELLED" in stderr, stderr
    from orchestrator import output

    steps = output.read_steps(tmp_path / "long", "ale")
    assert len(steps) >= 2
    output.read_step(tmp_path / "long", "ale", steps[-1][2])
