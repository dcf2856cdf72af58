"""The command line as a user meets it: bad input is one line naming the key, exit code 2, and
nothing launched or written; `check` validates only; `view` renders pictures of a finished run."""
from __future__ import annotations

import pytest

from tests.conftest import CASES, immerse
from tests.orchestrator.test_case import BAD, BAD_CASES

# one process per bad case is slow-ish (imports); a representative spread of the table
CLI_BAD = [c for c in BAD_CASES if c[0] in {
    "missing_required_key", "unknown_top_level_key", "unknown_nested_key", "negative_density",
    "poisson_ratio_half", "unknown_material_model", "missing_mesh_file", "corrupt_mesh_file",
    "end_time_zero", "dimension_mismatch", "ranks_zero", "bad_region_expression", "toml_syntax_error",
    "jc_missing_yield_stress", "undefined_material", "wrong_type"}]


def test_cli_bad_table_is_complete():
    assert len(CLI_BAD) == 16


@pytest.mark.parametrize("name, key, fragment", CLI_BAD, ids=[c[0] for c in CLI_BAD])
def test_run_rejects_bad_case_before_launch(name, key, fragment, tmp_path):
    out = tmp_path / "out"
    r = immerse("run", BAD / name, "--out", out, timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"immerse: {key} = ") and fragment in lines[0]
    assert not out.exists()  # nothing launched, nothing half-written
    assert r.stdout == ""


def test_bad_rank_override(tmp_path):
    r = immerse("run", CASES / "elastic_bar_wave", "--out", tmp_path / "o", "--ranks", "lagrange=0")
    assert r.returncode == 2 and "--ranks lagrange" in r.stderr
    assert not (tmp_path / "o").exists()
    r = immerse("run", CASES / "elastic_bar_wave", "--out", tmp_path / "o", "--ranks", "ale=2")
    assert r.returncode == 2 and "--ranks ale" in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["elastic_bar_wave", "spinning_block", "taylor_bar"])
def test_check_accepts_shipped_cases(name):
    r = immerse("check", CASES / name)
    assert r.returncode == 0 and f"{name}: ok" in r.stdout


def test_view_renders_pictures(tmp_path):
    out = tmp_path / "out"
    assert immerse("run", CASES / "elastic_bar_wave", "--out", out).returncode == 0
    r = immerse("view", out, "--field", "stress", "velocity")
    assert r.returncode == 0, r.stderr
    pngs = sorted((out / "pictures").glob("*.png"))
    assert len(pngs) == 2 and all(p.stat().st_size > 10_000 for p in pngs)
    r = immerse("view", tmp_path / "nothing")
    assert r.returncode == 2 and "results.h5" in r.stderr


def test_ctrl_c_while_checking_is_one_line(tmp_path):
    """SIGINT before any job runs (here: while the case is checked) gives one line and exit 130, no
    traceback; nothing is launched or written."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from tests.conftest import REPO

    slow_check = ("import sys, time, orchestrator.case as k, orchestrator.cli as c\n"
                  "orig = k.load_case\n"
                  "def slow(*a, **kw):\n    time.sleep(30); return orig(*a, **kw)\n"
                  "k.load_case = slow\n"
                  f"sys.exit(c.main(['run', 'cases/sod', '--out', {str(tmp_path / 'out')!r}]))\n")
    p = subprocess.Popen([sys.executable, "-c", slow_check], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    time.sleep(3)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=30)
    assert p.returncode == 130 and err == "immerse: interrupted (SIGINT)\n" and out == "", err
    assert not (tmp_path / "out").exists()
