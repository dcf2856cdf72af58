"""The Slurm engine against a real single-node Slurm (munged, slurmctld, slurmd started by the
fixture as root, stopped after): a 6-run campaign through one sbatch job array gives the same
campaign.csv metrics as the local engine; a cancelled array task is reported by name and its run
has no result (it runs again next time). Skipped with the reason where no cluster can be started."""
from __future__ import annotations

import csv
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.orchestrator.campaign.slurm_cluster import command_env, single_node_slurm, slurm_available
from tests.orchestrator.campaign.test_local_engine import KILLED
from tests.orchestrator.campaign.test_spec import REPO, SHOCK

REASON = slurm_available()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

TIMING = ("wall_time_s", "elapsed_s")


def _campaign(tmp_path, text=KILLED) -> Path:
    p = tmp_path / "campaign.toml"
    p.write_text(text.replace("@SHOCK", str(SHOCK)))
    return p


def _immerse(env, *args, timeout=400):
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *map(str, args)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def _rows(out: Path) -> list[dict]:
    with open(out / "campaign.csv") as f:
        return list(csv.DictReader(f))


@pytest.mark.timeout(600)
def test_slurm_and_local_engines_give_the_same_campaign_csv(tmp_path):
    p = _campaign(tmp_path)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = _immerse(env, "campaign", p, "--out", tmp_path / "local")
    assert r.returncode == 0, r.stdout + r.stderr
    with single_node_slurm(tmp_path / "cluster") as cluster:
        senv = command_env(cluster, env)
        r = _immerse(senv, "campaign", p, "--out", tmp_path / "slurm", "--engine", "slurm")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "slurm job" in r.stdout and "6 array tasks" in r.stdout, r.stdout
    local, slurm = _rows(tmp_path / "local"), _rows(tmp_path / "slurm")
    assert len(local) == len(slurm) == 6
    assert list(local[0]) == list(slurm[0])
    for a, b in zip(local, slurm):
        assert all(b[c] for c in TIMING)
        assert {k: v for k, v in a.items() if k not in TIMING} == {k: v for k, v in b.items() if k not in TIMING}
    res = (tmp_path / "slurm" / "runs" / "conforming-zones100" / "result.json").read_text()
    assert '"engine": "slurm"' in res
    script = next((tmp_path / "slurm" / "slurm").glob("campaign_*.sbatch")).read_text()
    assert "#SBATCH --array=0-5" in script and "#SBATCH --cpus-per-task=1" in script, script


@pytest.mark.timeout(600)
def test_a_cancelled_array_task_is_reported_by_name_and_runs_again(tmp_path):
    """A long run (3000 zones, ~10 s) and a short one (100 zones: the other task of the array, which
    completes); the long task is cancelled with scancel while it runs: the campaign names the task, its
    state and the run, exits 1, and that run has no result; the next start runs only it."""
    p = _campaign(tmp_path, KILLED.replace("values = [100, 150, 200, 250, 300, 350]", "values = [3000, 100]")
                  .replace('"ale.grid.cells" = [[100, 1], [150, 1], [200, 1], [250, 1], [300, 1], [350, 1]]',
                           '"ale.grid.cells" = [[3000, 1], [100, 1]]'))
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    with single_node_slurm(tmp_path / "cluster") as cluster:
        senv = command_env(cluster, env)
        proc = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "campaign", str(p), "--out", str(out),
                                 "--engine", "slurm"], cwd=REPO, env=senv, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        job = None
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the first run's job stepping
            if (out / "runs" / "conforming-zones3000" / "out" / "log.txt").is_file() and (out / "slurm" / "job.json").is_file():
                job = __import__("json").loads((out / "slurm" / "job.json").read_text())["job"]
                break
            time.sleep(0.2)
        assert job, "the first run never started"
        time.sleep(2.0)
        subprocess.run(["scancel", f"{job}_0"], env=senv, check=True, timeout=30)
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 1, stdout + stderr
        line = [ln for ln in stdout.splitlines() if "conforming-zones3000" in ln and ln.startswith("[")][0]
        assert f"slurm array task {job}_0 ended CANCELLED" in line and "without a result" in line, line
        assert not (out / "runs" / "conforming-zones3000" / "result.json").exists()
        assert (out / "runs" / "conforming-zones100" / "result.json").exists()
        r = _immerse(senv, "campaign", p, "--out", out, "--engine", "slurm")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "1 done before, 1 to run" in r.stdout, r.stdout
