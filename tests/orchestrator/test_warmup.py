"""The install-time warm-up (orchestrator/warmup.py, run by `make venv`) leaves nothing for a run to
compile: its tiny synthetic cases cover every kernel specialisation that the shipped cases and the
valid test cases step through, and the MPI ranks of `immerse run` load those kernels from the same
cache (numba's "[cache] data saved" never appears in a run after the warm-up)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from orchestrator import warmup
from orchestrator.case import load_case
from tests.conftest import CASES, REPO, immerse

VALID = REPO / "tests" / "orchestrator" / "valid_cases"


def _python(*args, env=None, timeout=900):
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    e.update(env or {})
    return subprocess.run([sys.executable, *args], cwd=REPO, capture_output=True, text=True, env=e,
                          timeout=timeout)


@pytest.fixture(scope="module")
def warm():
    r = _python("-m", "orchestrator.warmup")  # seconds when `make venv` did it; ~1-2 min cold
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("numba kernels warm: ")
    return r.stdout


def test_warmup_cases_are_valid_and_cover_the_options(tmp_path):
    """Every warm-up case passes the validation a user's case passes; together they cover both
    dimensions, every material model and EOS, both q kinds and ALE modes, mixed zones and void,
    obstacles and every face kind."""
    texts = warmup.cases()
    seen = set()
    for name, text in texts.items():
        d = tmp_path / name
        d.mkdir()
        (d / "case.toml").write_text(text)
        case = load_case(d)
        seen.add(f"dim{case['run']['dimension']}")
        if "ale" in case:
            a = case["ale"]
            seen.add(a["mode"])
            seen.add((a.get("viscosity") or {}).get("kind", "scalar"))
            seen.update(m["eos"] for m in a["materials"].values())
            seen.update(b if isinstance(b, str) else next(iter(b)) for b in (a.get("boundaries") or {}).values())
            if a.get("obstacles"):
                seen.add("obstacles")
            if len(a["materials"]) > 1:
                seen.add("mixed")
        else:
            seen.update(m["model"] for m in case["materials"].values())
            seen.update(b["type"] for b in case["boundaries"])
    assert seen >= {"dim2", "dim3", "eulerian", "lagrangian", "scalar", "monotonic", "ideal_gas",
                    "stiffened_gas", "tait", "jwl", "mie_gruneisen", "void", "mixed", "obstacles", "wall", "outflow",
                    "periodic", "inflow", "piston", "linear_elastic", "neo_hookean", "johnson_cook",
                    "fixed", "velocity", "symmetry", "rigid_wall"}


@pytest.mark.timeout(1200)
def test_shipped_cases_compile_nothing_after_the_warmup(warm):
    dirs = sorted(p.parent for p in CASES.glob("*/case.toml")) + sorted(p.parent for p in VALID.glob("*/case.toml"))
    assert len(dirs) >= 14
    r = _python("-m", "orchestrator.warmup", "--check", *map(str, dirs))
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.strip().splitlines()[-1]) == {}


@pytest.mark.timeout(1200)
def test_ranks_load_the_warm_kernels(warm, tmp_path, monkeypatch):
    """A two-rank ALE run and a Lagrangian run: numba's cache log shows kernels loaded by the ranks
    and none compiled and saved."""
    case = tmp_path / "case"
    case.mkdir()
    (case / "case.toml").write_text((CASES / "sod" / "case.toml").read_text().replace(
        "end_time = 0.2", "end_time = 0.02").replace("output_interval = 0.05", "output_interval = 0.01"))
    monkeypatch.setenv("NUMBA_DEBUG_CACHE", "1")  # numba logs every cache load and save
    for args in ((case, "--ranks", "ale=2"), (VALID / "box3d", "--ranks", "lagrange=1")):
        out = tmp_path / f"out{len(args)}_{args[0].name}"
        r = immerse("run", *args, "--out", out)
        assert r.returncode in (0, 1), r.stderr  # box3d's own check is about its momentum only
        log = r.stdout + r.stderr
        assert "[cache] data loaded" in log
        assert "saved" not in log, [ln for ln in log.splitlines() if "saved" in ln][:5]
