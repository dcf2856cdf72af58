"""Output directories: `immerse run --out DIR` never deletes or overwrites a file it did not write.
A directory that is not empty and not an immerse output of the same case is refused (one line, exit
2, nothing touched); an earlier output of the same case is replaced only with --replace, which
deletes the files immerse wrote (by its record) and nothing else."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import pytest

from orchestrator import outdir
from tests.conftest import CASES, REPO
from tests.conftest import immerse as _immerse


def bar_case(where: Path, name="bar", **replace) -> Path:
    """elastic_bar_wave cut to 5 outputs (a few seconds), without its [check]: these tests are about
    the output directory, and the check's tolerances are set for the full 16 us."""
    case = where / name
    shutil.copytree(CASES / "elastic_bar_wave", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text().replace("end_time = 16.0e-6", "end_time = 4.0e-6")
    text = text[:text.index("[check]")]
    for a, b in replace.items():
        assert a in text, a
        text = text.replace(a, b)
    (case / "case.toml").write_text(text)
    return case


def snapshot(d: Path) -> dict:
    """Every entry below d: kind, bytes' digest and modification time (nothing may change)."""
    snap = {}
    for root, dirs, files in os.walk(d):
        for n in dirs + files:
            p = Path(root) / n
            st = p.lstat()
            digest = hashlib.sha256(p.read_bytes()).hexdigest() if stat.S_ISREG(st.st_mode) else None
            snap[p.relative_to(d).as_posix()] = (stat.S_IFMT(st.st_mode), digest, st.st_mtime_ns)
    return snap


def immerse(*args, **kw):
    """The CLI, timed: a refusal comes in under 5 s (measured ~1 s: imports and the case check)."""
    t0 = time.perf_counter()
    r = _immerse(*args, **kw)
    r.elapsed = time.perf_counter() - t0
    return r


def refused(r, *fragments) -> str:
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert getattr(r, "elapsed", 0.0) < 5.0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("immerse: --out = "), lines[0]
    for f in fragments:
        assert f in lines[0], lines[0]
    assert r.stdout == ""
    return lines[0]


@pytest.fixture(scope="module")
def earlier(tmp_path_factory):
    """One finished run of the bar case: (case dir, output dir); tests work on copies."""
    base = tmp_path_factory.mktemp("earlier")
    case = bar_case(base)
    out = base / "out"
    r = immerse("run", case, "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    return case, out


def user_files(d: Path) -> dict[str, bytes]:
    files = {"pictures/mine.png": b"\x89PNG user picture", "steps/measured.csv": b"t,x\n0,1\n",
             "notes.txt": b"my notes", "steps/notes.h5": b"not immerse's"}
    for rel, data in files.items():
        (d / rel).parent.mkdir(parents=True, exist_ok=True)
        (d / rel).write_bytes(data)
    return files


def test_foreign_directory_is_refused_untouched(tmp_path):
    """The seen failure: a PNG in pictures/ and a CSV in steps/ were deleted, log.txt overwritten."""
    case = bar_case(tmp_path)
    out = tmp_path / "mine"
    user_files(out)
    (out / "log.txt").write_text("my own log\n")
    before = snapshot(out)
    for flags in ((), ("--replace",)):
        r = immerse("run", case, "--out", out, *flags, timeout=60)
        refused(r, "not an immerse output")
        assert snapshot(out) == before


def test_earlier_output_needs_replace(earlier, tmp_path):
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    before = snapshot(out)
    r = immerse("run", case, "--out", out, timeout=60)
    refused(r, "--replace")
    assert snapshot(out) == before


def test_replace_deletes_only_what_immerse_wrote(earlier, tmp_path):
    """An earlier output (5 steps, a picture `immerse view` recorded) with the user's own files among
    them; the case now writes 3 steps: --replace leaves exactly the new run's files and the user's."""
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    shutil.copytree(case, tmp_path / "case")
    case = tmp_path / "case"
    # same case directory as the earlier run? no: a copy, so the same case by its fingerprint;
    # the output interval may differ (it is not part of the fingerprint)
    (case / "case.toml").write_text((case / "case.toml").read_text().replace(
        "output_interval = 1.0e-6", "output_interval = 2.0e-6"))
    mine = user_files(out)
    picture = out / "pictures" / "lagrange_stress_000004.png"
    picture.write_bytes(b"\x89PNG immerse's picture")
    outdir.record_written(out, picture)
    old_log = (out / "log.txt").read_text()
    assert sorted(p.name for p in (out / "steps").glob("lagrange_0*.h5")) == [
        f"lagrange_{i:06d}.h5" for i in range(5)]

    r = immerse("run", case, "--out", out, "--replace", timeout=300)
    assert r.returncode == 0, r.stderr
    for rel, data in mine.items():
        assert (out / rel).read_bytes() == data, rel
    assert not picture.exists()
    assert sorted(p.name for p in (out / "steps").glob("lagrange_0*.h5")) == [
        f"lagrange_{i:06d}.h5" for i in range(3)]
    with h5py.File(out / "results.h5") as h:
        assert list(h["lagrange/indices"][...]) == [0, 1, 2]
    log = (out / "log.txt").read_text()
    assert old_log.splitlines()[0] not in log.splitlines()[1:] and log.count("command:") == 1
    assert json.loads((out / ".immerse" / "owner.json").read_text())["run"] is None
    # the new run's files are recorded: a second --replace removes them and keeps the user's again
    written = outdir.read_record(out)
    assert {"steps/lagrange_000002.h5", "results.h5", "summary.json", "log.txt"} <= written
    assert not any(rel in written for rel in mine)


@pytest.mark.parametrize("foreign", ["steps/lagrange_000099.h5", "steps/lagrange_000003.h5",
                                     "checkpoints/checkpoint_00000010.h5", ".run/pids/1"])
def test_foreign_file_at_a_path_of_the_run_is_refused(earlier, tmp_path, foreign):
    """A file immerse did not write where the run would write it, or where the index would pick it
    up: refused, also with --replace, and nothing is touched."""
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    target = out / foreign
    if target.exists():  # the user replaced immerse's file with one of their own
        target.unlink()
        outdir._rewrite_record(out, outdir.read_record(out))
    (out / foreign).parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(first / "steps" / "lagrange_000001.h5", out / foreign)
    text = (out / ".immerse" / "written").read_text()
    (out / ".immerse" / "written").write_text(
        "\n".join(line for line in text.splitlines() if line not in (foreign, ".run/")) + "\n")
    before = snapshot(out)
    r = immerse("run", case, "--out", out, "--replace", timeout=60)
    refused(r, foreign, "not written by immerse")
    assert snapshot(out) == before


@pytest.mark.parametrize("route", ["linked_folder", "linked_file", "outside"])
def test_replace_deletes_nothing_through_a_link(earlier, tmp_path, route):
    """A record line naming a path through a link to the user's folder (``foo/x.txt``, ``foo`` a
    link), a link itself (``y.txt`` -> the user's file) or a path out of OUT: --replace deletes the
    run's own files and never the user's (issue 41: ``foo/x.txt`` was deleted)."""
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    user = tmp_path / "user"
    user.mkdir()
    (user / "x.txt").write_text("the user's data\n")
    line = {"linked_folder": "foo/x.txt", "linked_file": "y.txt", "outside": "../user/x.txt"}[route]
    if route == "linked_folder":
        (out / "foo").symlink_to(user)
    elif route == "linked_file":
        (out / "y.txt").symlink_to(user / "x.txt")
    with open(out / ".immerse" / "written", "a") as f:
        f.write(line + "\n")
    r = immerse("run", case, "--out", out, "--replace", timeout=300)
    assert r.returncode == 0, r.stderr
    assert (user / "x.txt").read_text() == "the user's data\n"
    assert (out / "summary.json").is_file()


def test_output_of_another_case_is_refused(earlier, tmp_path):
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    other = bar_case(tmp_path, name="other", **{"density = 8000.0": "density = 7800.0"})
    before = snapshot(out)
    r = immerse("run", other, "--out", out, "--replace", timeout=60)
    refused(r, "another case", "'bar'")
    assert snapshot(out) == before


def test_output_of_an_older_immerse_is_refused(earlier, tmp_path):
    """No ownership record: immerse cannot tell its files from the user's, so it touches none."""
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    shutil.rmtree(out / ".immerse")
    before = snapshot(out)
    r = immerse("run", case, "--out", out, "--replace", timeout=60)
    refused(r, "older immerse")
    assert snapshot(out) == before


def test_linked_steps_directory_is_refused(earlier, tmp_path):
    """steps/ turned into a link to the user's own data: immerse writes through no link."""
    case, first = earlier
    out = tmp_path / "out"
    shutil.copytree(first, out, symlinks=True)
    data = tmp_path / "data"
    (out / "steps").rename(data)
    (out / "steps").symlink_to(data)
    before, data_before = snapshot(out), snapshot(data)
    r = immerse("run", case, "--out", out, "--replace", timeout=60)
    refused(r, "steps is not a directory immerse made")
    assert snapshot(out) == before and snapshot(data) == data_before


def test_default_out_follows_the_same_rules(tmp_path):
    case = bar_case(tmp_path)
    (case / "out").mkdir()
    (case / "out" / "log.txt").write_text("mine\n")
    before = snapshot(case)
    r = immerse("run", case, timeout=60)
    refused(r, str(case / "out"), "not an immerse output")
    assert snapshot(case) == before


def test_out_naming_a_file_or_a_place_under_a_file(tmp_path):
    case = bar_case(tmp_path)
    f = tmp_path / "results.txt"
    f.write_text("keep me")
    before = snapshot(tmp_path)
    refused(immerse("run", case, "--out", f, timeout=60), "is an existing file")
    refused(immerse("run", case, "--out", f / "sub" / "out", timeout=60), "is not a directory")
    assert snapshot(tmp_path) == before


def _as_unprivileged_user(args, cwd):
    """Run the CLI as user `nobody` (root writes anywhere: permissions refuse only other users)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("IMMERSE_TTY", None)
    cmd = [sys.executable, "-m", "orchestrator.cli", *map(str, args)]
    if os.geteuid() == 0:
        if not shutil.which("setpriv"):
            pytest.skip("running as root without setpriv: cannot make a directory unwritable")
        drop = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        # `nobody` must be able to read this checkout and its venv (a clone under a private
        # directory, e.g. mktemp -d, is not): else this test cannot run here
        probe = subprocess.run([*drop, sys.executable, "-c", "import orchestrator.cli"], cwd=cwd,
                               capture_output=True, text=True, timeout=60, env=env)
        if probe.returncode != 0:
            pytest.skip("user nobody cannot read this checkout or its venv (a private parent "
                        "directory), so a directory cannot be made unwritable for the run")
        cmd = [*drop, *cmd]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=60, env=env)


def test_out_in_a_read_only_directory(tmp_path):
    # a tree `nobody` can read but not write (the pytest tree of root is private to root)
    top = Path(tempfile.mkdtemp(prefix="immerse-ro-"))
    try:
        os.chmod(top, 0o755)
        case = bar_case(top)
        ro = top / "ro"
        ro.mkdir(mode=0o555)
        os.chmod(ro, 0o555)
        for p in [case, *case.rglob("*")]:
            os.chmod(p, 0o755 if p.is_dir() else 0o644)
        before = snapshot(top)
        refused(_as_unprivileged_user(["run", case, "--out", ro / "out"], cwd=top), "cannot be created",
                "not writable")
        refused(_as_unprivileged_user(["run", case, "--out", ro], cwd=top), "not writable")
        assert snapshot(top) == before
    finally:
        os.chmod(top / "ro", 0o755)
        shutil.rmtree(top)


# ---- the record, unit by unit -------------------------------------------------------------------------
def _fake_case(tmp_path):
    return {"name": "c", "case_dir": tmp_path / "c"}


def test_record_written_api(tmp_path):
    """`immerse view` records its pictures with one call; nothing is recorded outside an output."""
    out = tmp_path / "out"
    outdir.record_written(out, out / "pictures" / "a.png")  # no output directory: a no-op
    assert not out.exists()
    outdir.prepare(outdir.plan(out, _fake_case(tmp_path), "sha256:x"))
    outdir.record_written(out, out / "pictures" / "a.png", tmp_path / "elsewhere.png")
    assert outdir.read_record(out) == {".run/", "log.txt", "pictures/a.png"}
    assert outdir.may_write(out, out / "pictures" / "a.png")
    (out / "pictures").mkdir()
    (out / "pictures" / "c.png").write_bytes(b"user")
    assert not outdir.may_write(out, out / "pictures" / "c.png")


def test_tampered_record_never_reaches_outside(tmp_path):
    out = tmp_path / "out"
    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    outdir.prepare(outdir.plan(out, _fake_case(tmp_path), "sha256:x"))
    outdir.finish_run(out, 0.0)
    with open(out / ".immerse" / "written", "a") as f:
        f.write("../precious.txt\n/etc/hostname\nsteps/../../precious.txt\n")
    assert outdir.read_record(out) == {".run/", "log.txt"}
    p = outdir.plan(out, _fake_case(tmp_path), "sha256:x", replace=True)
    outdir.prepare(p)
    assert outside.read_text() == "keep"


def test_files_of_a_launcher_that_died_are_claimed(tmp_path):
    """A launcher killed with SIGKILL could not record what its job wrote: the next run adopts the
    files of that run (it was the only writer of the run's paths) once the launcher is gone."""
    out = tmp_path / "out"
    case = _fake_case(tmp_path)
    outdir.prepare(outdir.plan(out, case, "sha256:x"), started=1000.0)
    (out / "steps").mkdir()
    (out / "steps" / "lagrange_000000.h5").write_bytes(b"step")
    (out / "steps" / "mine.csv").write_bytes(b"user")
    owner = json.loads((out / ".immerse" / "owner.json").read_text())
    # while that launcher lives, the directory is in use
    with pytest.raises(outdir.OutDirError, match="in use by a running immerse"):
        outdir.plan(out, case, "sha256:x", replace=True)
    owner["run"]["pid_start"] = -1  # that launcher is gone (its pid now another process or none)
    (out / ".immerse" / "owner.json").write_text(json.dumps(owner))
    p = outdir.plan(out, case, "sha256:x", replace=True)
    assert "steps/lagrange_000000.h5" in p.delete and "steps/mine.csv" not in p.delete
    outdir.prepare(p)
    assert not (out / "steps" / "lagrange_000000.h5").exists()
    assert (out / "steps" / "mine.csv").read_bytes() == b"user"
