"""`immerse view` on damaged outputs (issue 41): an immerse output whose index is damaged, lost or
behind its step files (a launcher killed by SIGKILL) gets its index rebuilt from the step files and
every completed step drawn; a folder that is not an immerse output gets one line, exit 2, nothing
created."""
from __future__ import annotations

import os
import shutil

import h5py
import pytest

from orchestrator import output
from tests.conftest import CASES
from tests.orchestrator.test_outdir import snapshot


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from tests.conftest import immerse

    tmp = tmp_path_factory.mktemp("damaged")
    out = tmp / "out"
    # (5 outputs, not the case's 53: every test draws every step)
    case = tmp / "case"
    shutil.copytree(CASES / "sph_elastic_bar", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    assert "output_interval = 0.05e-3" in text
    (case / "case.toml").write_text(text.replace("output_interval = 0.05e-3", "output_interval = 0.65e-3"))
    r = immerse("run", case, "--out", out, timeout=300)
    assert r.returncode in (0, 1), r.stderr
    return out


def _damage(out, how):
    if how == "random_bytes":
        (out / "results.h5").write_bytes(os.urandom(4096))
    elif how == "no_indices":
        with h5py.File(out / "results.h5", "a") as h:
            del h["sph/indices"]
    elif how == "lists_no_steps":   # what a SIGKILLed launcher left: the role's group without its steps
        with h5py.File(out / "results.h5", "a") as h:
            for k in list(h["sph"]):
                if k not in ("mesh",):
                    del h[f"sph/{k}"]
    elif how == "lost":
        (out / "results.h5").unlink()
        (out / "results.xdmf").unlink()


@pytest.mark.parametrize("how", ["random_bytes", "no_indices", "lists_no_steps", "lost"])
def test_a_damaged_index_is_rebuilt_from_the_step_files(finished, tmp_path, run_immerse, how):
    out = tmp_path / "out"
    shutil.copytree(finished, out, symlinks=True)
    n = len(output.read_steps(finished, "sph"))
    _damage(out, how)
    r = run_immerse("view", out, "--step", "all", "--field", "velocity")
    assert r.returncode == 0, r.stderr
    assert n == 5 and len(r.stdout.split()) == n      # every completed step drawn
    assert [s[2] for s in output.read_steps(out, "sph")] == list(range(n))


def test_not_an_immerse_output_is_one_line(tmp_path, run_immerse):
    out = tmp_path / "junk"
    (out / "steps").mkdir(parents=True)
    (out / "results.h5").write_bytes(os.urandom(100))
    before = snapshot(out)
    r = run_immerse("view", out)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "damaged or not immerse's" in lines[0], r.stderr
    assert snapshot(out) == before


def test_a_damaged_step_file_is_left_out_of_the_index_by_name(finished, tmp_path, run_immerse):
    """A step file of random bytes: view rebuilds the index without it, draws the others, and says
    which file it left out in one warning line (output.py's per-file UserWarning printed two lines of source)."""
    out = tmp_path / "out"
    shutil.copytree(finished, out, symlinks=True)
    n = len(output.read_steps(finished, "sph"))
    (out / "steps" / "sph_000002.h5").write_bytes(os.urandom(500))
    r = run_immerse("view", out, "--step", "all", "--field", "velocity")
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip() == (f"immerse: warning: OUT = {str(out)!r}: 1 step file(s) damaged or unreadable, "
                                "left out of the index: steps/sph_000002.h5"), r.stderr
    assert [s[2] for s in output.read_steps(out, "sph")] == [i for i in range(n) if i != 2]
    assert len(r.stdout.split()) == n - 1
