"""The local engine: runs to completion with results collected, a failed run recorded with its
message without stopping the others, resumption after the campaign process is killed (SIGKILL)."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.orchestrator.campaign.test_spec import REPO, SHOCK

PISTON = REPO / "cases" / "embedded_piston_sod"


def _campaign(tmp_path, text) -> Path:
    p = tmp_path / "campaign.toml"
    p.write_text(text.replace("@SHOCK", str(SHOCK)).replace("@PISTON", str(PISTON)))
    return p


def _rows(out: Path) -> list[dict]:
    with open(out / "campaign.csv") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_failed_run_is_recorded_with_its_message_and_the_others_complete(tmp_path, run_immerse):
    """Penalty coupling of the embedded piston at k = 10 Pa/m (stable) and 1e7 Pa/m (its explicit limit
    1e-5 s against a 5.9e-4 s step: stopped at step 1 naming the method), and the multiplier: the
    unstable run is on the map as 'unstable' with the coupler's message; the others' rows are whole."""
    p = _campaign(tmp_path, '''
name = "penalty_limit"
[axes.stiffness]
values = [10.0, 1e7]
[[series]]
name = "penalty"
case = "@PISTON"
set = { "coupling.method" = "penalty", "run.end_time" = 0.02, "run.output_interval" = 0.02 }
[series.axes.stiffness]
"coupling.stiffness" = [10.0, 1e7]
[[series]]
name = "multiplier"
case = "@PISTON"
set = { "run.end_time" = 0.02, "run.output_interval" = 0.02 }
[report]
error = "velocity"
map = "stiffness"
''')
    out = tmp_path / "out"
    r = run_immerse("campaign", p, "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    rows = {x["run"]: x for x in _rows(out)}
    assert set(rows) == {"penalty-stiffness10", "penalty-stiffness1e+07", "multiplier-stiffness10",
                         "multiplier-stiffness1e+07"}
    bad = rows["penalty-stiffness1e+07"]
    assert bad["status"] == "unstable", bad
    assert "coupling method 'penalty' is unstable" in bad["message"] and "at step 1," in bad["message"], bad
    for name in ("penalty-stiffness10", "multiplier-stiffness10"):
        row = rows[name]
        assert row["status"] in ("passed", "check_failed"), row  # (the case's check is for t = 0.2)
        assert float(row["wall_time_s"]) > 0 and int(row["steps"]) > 10
        assert float(row["conservation.mass_rel"]) < 1e-12
    for f in ("report.html", "report.md", "figures/penalty_limit_stability.png"):
        assert (out / f).is_file(), f
    assert "coupling method 'penalty' is unstable" in (out / "report.md").read_text()
    # a rerun: everything is done, nothing runs; the report is rebuilt from campaign.h5 alone
    r = run_immerse("campaign", p, "--out", out)
    assert r.returncode == 0 and "4 done before, 0 to run" in r.stdout, r.stdout
    (out / "report.html").unlink()
    r = run_immerse("report", out)
    assert r.returncode == 0 and (out / "report.html").is_file(), r.stderr


KILLED = '''
name = "killed"
[axes.zones]
values = [100, 150, 200, 250, 300, 350]
"ale.grid.cells" = [[100, 1], [150, 1], [200, 1], [250, 1], [300, 1], [350, 1]]
[[series]]
name = "conforming"
case = "@SHOCK/conforming"
[report]
error = "l1_density"
resolution = "zones"
'''


def _job_processes(out: Path) -> list[str]:
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmd = (Path("/proc") / pid / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if str(out) in cmd:
            found.append(f"{pid} {cmd[:120]}")
    return found


@pytest.mark.timeout(300)
def test_a_campaign_killed_midway_runs_only_the_missing_runs_again(tmp_path):
    """SIGKILL to the campaign process once two runs have results: its runs end with it (no process of
    the campaign left within seconds), the run that was running has no result (not counted as done),
    and the next `immerse campaign` runs exactly the runs without a result."""
    p = _campaign(tmp_path, KILLED)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "campaign", str(p), "--out", str(out)],
                            cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 200
    while time.monotonic() < deadline:  # two runs done and the next one's job running
        running = [d for d in out.glob("runs/*") if (d / "out" / "log.txt").is_file() and not (d / "result.json").exists()]
        if len(list(out.glob("runs/*/result.json"))) >= 2 and running:
            break
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = {d.parent.name for d in out.glob("runs/*/result.json")}
    assert 2 <= len(finished) < 6, finished
    deadline = time.monotonic() + 5
    while _job_processes(out) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _job_processes(out), _job_processes(out)
    # nothing of the campaign went on after it died: no run finished since
    assert {d.parent.name for d in out.glob("runs/*/result.json")} == finished
    for d in (out / "runs").iterdir():  # a run without a result is not done, whatever it wrote
        if d.name not in finished:
            assert not (d / "result.json").exists()
    r = subprocess.run([sys.executable, "-m", "orchestrator.cli", "campaign", str(p), "--out", str(out)],
                       cwd=REPO, env=env, capture_output=True, text=True, timeout=250)
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{len(finished)} done before, {6 - len(finished)} to run" in r.stdout, r.stdout
    ran = [ln.split(":")[0].split("] ")[1] for ln in r.stdout.splitlines() if ln.startswith("[")]
    assert sorted(ran) == sorted({f"conforming-zones{n}" for n in (100, 150, 200, 250, 300, 350)} - finished)
    rows = _rows(out)
    assert len(rows) == 6 and all(x["status"] in ("passed", "check_failed") for x in rows), rows
    for d in (out / "runs").iterdir():
        assert json.loads((d / "result.json").read_text())["summary"]["steps"] > 0


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_runs_share_the_cores_by_their_ranks(tmp_path, run_immerse):
    """`--cores 2`: three 1-rank runs go two at a time (some pair overlaps, never three at once); the
    same runs with 2 ALE ranks each go one at a time (no overlap)."""
    import json

    spans = {}
    for ranks in (1, 2):
        p = _campaign(tmp_path, KILLED.replace('name = "killed"', f'name = "ranks{ranks}"')
                      .replace("values = [100, 150, 200, 250, 300, 350]", "values = [100, 150, 200]")
                      .replace('"ale.grid.cells" = [[100, 1], [150, 1], [200, 1], [250, 1], [300, 1], [350, 1]]',
                               '"ale.grid.cells" = [[100, 1], [150, 1], [200, 1]]')
                      .replace('case = "@SHOCK/conforming"', f'case = "@SHOCK/conforming"\nset = {{ "ranks.ale" = {ranks} }}'))
        out = tmp_path / f"out{ranks}"
        r = run_immerse("campaign", p, "--out", out, "--cores", "2")
        assert r.returncode == 0, r.stdout + r.stderr
        spans[ranks] = [(x["started_at"], x["ended_at"]) for x in
                        (json.loads(f.read_text()) for f in out.glob("runs/*/result.json"))]
        assert len(spans[ranks]) == 3

    def overlapping(s):
        return [(a, b) for i, a in enumerate(s) for b in s[i + 1:] if a[0] < b[1] and b[0] < a[1]]

    assert overlapping(spans[1]), spans[1]
    assert not any(a[0] < b[1] and b[0] < a[1] and c[0] < min(a[1], b[1]) and max(a[0], b[0]) < c[1]
                   for a, b in overlapping(spans[1]) for c in spans[1] if c not in (a, b))
    assert not overlapping(spans[2]), spans[2]
