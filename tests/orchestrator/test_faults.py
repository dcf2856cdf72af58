"""Faults: a solver rank killed with SIGKILL mid-run brings the job down within 30 s with a non-zero
exit naming role and rank, and every completed output step stays readable; a rank that hits a
physical failure names the element, step and time. Every such run leaves summary.json (status
"failed", the message, the last recorded step and time) and a readable diagnostics.h5 with the
history up to there (orchestrator/run_record.py)."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time

import json

import h5py
import numpy as np
import pytest

from tests.conftest import CASES, REPO


def _spinning_case(tmp_path, **replace):
    case = tmp_path / "case"
    shutil.copytree(CASES / "spinning_block", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    for a, b in replace.items():
        text = text.replace(a, b)
    (case / "case.toml").write_text(text)
    return case


def _pids(out):
    d = out / ".run" / "pids"
    found = {}
    for f in d.glob("[0-9]*"):
        found[" ".join(f.read_text().split()[:2])] = int(f.name)  # "role rank" (then its start time)
    return found


def assert_ended_record(out, status: str, message: str | None = None) -> dict:
    """summary.json of a run that did not reach its end: ``status``, the message, the last recorded
    step and time equal to diagnostics.h5's last row (readable, every recorded step since the start)."""
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == status, s
    if message is not None:
        assert message in s["message"], s["message"]
    with h5py.File(out / "diagnostics.h5", "r") as h:
        t, steps = h["time"][()], h["step"][()]
        assert len(t) >= 1 and np.all(np.diff(t) > 0)
        assert steps[0] == 0 and np.all(np.diff(steps) > 0)   # every recorded step since the start
        assert steps[-1] == s["steps"] and t[-1] == s["end_time"]
        assert 0.0 <= s["end_time"] < s["requested_end_time"]
        assert all(h[k].shape == t.shape for k in h)
    assert "energy_rel" in s["conservation"] or "mass_rel" in s["conservation"], s["conservation"]
    return s


def _kill_rank_mid_run(case, out, role, rank, ranks):
    """Run `case`, SIGKILL `role` rank `rank` once 3 output steps exist; (return code, stderr, seconds
    from the kill to the job's end)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "run", str(case), "--out", str(out),
                             "--ranks", *ranks.split()], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    try:
        deadline = time.time() + 120
        while time.time() < deadline:
            steps = list((out / "steps").glob(f"{role}_[0-9]*.h5")) if (out / "steps").is_dir() else []
            if len(steps) >= 3 and f"{role} {rank}" in _pids(out):
                break
            time.sleep(0.2)
        else:
            raise AssertionError("run did not produce output in time")
        t_kill = time.time()
        os.kill(_pids(out)[f"{role} {rank}"], signal.SIGKILL)
        _, stderr = proc.communicate(timeout=30)
        return proc.returncode, stderr, time.time() - t_kill
    finally:
        if proc.poll() is None:
            proc.kill()


def test_sigkill_of_a_solver_rank(tmp_path):
    case = _spinning_case(tmp_path, **{"max_steps = 10000": "max_steps = 100000000",
                                       "output_interval = 0.2": "output_interval = 0.05"})
    out = tmp_path / "out"
    rc, stderr, elapsed = _kill_rank_mid_run(case, out, "lagrange", 1, "lagrange=2")
    assert rc != 0
    assert elapsed < 30
    assert "lagrange rank 1" in stderr, stderr
    # no process of the job survives
    time.sleep(0.5)
    for pid in _pids(out).values():
        assert not os.path.exists(f"/proc/{pid}") or open(f"/proc/{pid}/stat").read().split(") ")[1][0] == "Z"
    with h5py.File(out / "results.h5", "r") as h:
        times = h["lagrange/times"][...]
        assert len(times) >= 3
        for key in h["lagrange"]:
            if key.isdigit():  # the step links (also: times, steps, indices, mesh)
                assert h[f"lagrange/{key}/points"].shape[1] == 3
    s = assert_ended_record(out, "failed", "lagrange rank 1")
    assert s["end_time"] >= times[-1]   # the history reaches past the last output


def test_physical_failure_names_element_step_time(tmp_path, run_immerse):
    """One corner node thrown into its element at 10 km/s (100 times the wave speed): the element
    inverts within a few stable steps and the run stops naming element, step and time."""
    case = _spinning_case(tmp_path, **{
        '"2 - 100*y", "1 + 100*x", "0.5"':
            '"where((x > 0.049) and (y > 0.049) and (z > 0.049), -1e4, 0)", "0", "0"',
        "max_steps = 10000": "max_steps = 1000",
        "model = \"neo_hookean\"": "model = \"linear_elastic\""})
    r = run_immerse("run", case, "--out", tmp_path / "out", timeout=300)
    assert r.returncode != 0
    assert "lagrange rank 0" in r.stderr
    assert "element" in r.stderr and "step" in r.stderr and "t=" in r.stderr, r.stderr
    s = assert_ended_record(tmp_path / "out", "failed", "inverted or invalid element")
    assert s["steps"] > 0


def _ale_case(tmp_path, name, **replace):
    case = tmp_path / "case"
    shutil.copytree(CASES / name, case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    for a, b in replace.items():
        assert a in text, a
        text = text.replace(a, b)
    (case / "case.toml").write_text(text)
    return case


def test_sigkill_of_an_ale_rank(tmp_path):
    """The background on 2 ranks: SIGKILL of ALE rank 1 ends the job within 30 s, non-zero, naming
    the role and rank; the completed output steps stay readable."""
    case = _ale_case(tmp_path, "sedov_2d", **{"end_time = 1.0": "end_time = 100.0",
                                             "output_interval = 0.25": "output_interval = 0.01"})
    out = tmp_path / "out"
    rc, stderr, elapsed = _kill_rank_mid_run(case, out, "ale", 1, "ale=2")
    assert rc != 0 and elapsed < 30
    assert "ale rank 1" in stderr, stderr
    with h5py.File(out / "results.h5", "r") as h:
        assert len(h["ale/times"][...]) >= 3
        for key in h["ale"]:
            if key.isdigit():
                assert h[f"ale/{key}/cell_data/density"].shape[0] == 120 * 120


def test_ale_physical_failure_names_zone_step_time(tmp_path, run_immerse):
    """Water (stiffened gas) pulled apart by a piston moving out at 3 km/s: it cavitates past
    p = -p_inf, and the run stops naming the zone, the state, step and time."""
    case = _ale_case(tmp_path, "water_piston_column", **{
        "piston = { velocity = 50.0 }": "piston = { velocity = -3000.0 }",
        'materials.water = { eos = "tait", density = 1000.0, bulk_modulus = 2.19e9, exponent = 7.15, p0 = 1.0e5 }':
            'materials.water = { eos = "stiffened_gas", gamma = 4.4, p_inf = 6.0e8 }'})
    r = run_immerse("run", case, "--out", tmp_path / "out", timeout=300)
    assert r.returncode != 0
    assert "ale rank 0" in r.stderr, r.stderr
    assert "ALE zone (" in r.stderr and "invalid thermodynamic state" in r.stderr, r.stderr
    assert "step" in r.stderr and "t=" in r.stderr and "rho=" in r.stderr
    assert_ended_record(tmp_path / "out", "failed", "invalid thermodynamic state")


@pytest.mark.parametrize("role", ["ale", "lagrange"])
def test_sigkill_of_a_rank_of_a_coupled_run(tmp_path, role):
    """A coupled run (the embedded piston, 2 background + 2 body ranks): SIGKILL of rank 1 of either
    group ends the job within 30 s, non-zero, naming the role and rank (the coupler waiting for a
    message from that group included); the completed output steps of both groups stay readable."""
    case = _ale_case(tmp_path, "embedded_piston_sod", **{"end_time = 0.2": "end_time = 50.0",
                                                         "output_interval = 0.05": "output_interval = 0.005"})
    out = tmp_path / "out"
    rc, stderr, elapsed = _kill_rank_mid_run(case, out, role, 1, "ale=2 lagrange=2")
    assert rc != 0 and elapsed < 30
    assert f"{role} rank 1" in stderr, stderr
    with h5py.File(out / "results.h5", "r") as h:
        for r in ("ale", "lagrange"):
            assert len(h[f"{r}/times"][...]) >= 3
