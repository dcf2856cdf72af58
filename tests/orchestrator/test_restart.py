"""`immerse run --restart FILE`: anything that is not a checkpoint of this very case is refused with one
line naming --restart, exit 2, before the output directory is created; a checkpoint may continue
with a later end time and on another rank count."""
from __future__ import annotations

import json
import shutil
import time

import h5py
import meshio
import numpy as np
import pytest

from orchestrator import restart
from orchestrator.case import load_case
from tests.conftest import immerse
from tests.orchestrator.test_outdir import bar_case


def with_checkpoints(case, **replace):
    text = (case / "case.toml").read_text().replace(
        "output_interval = 1.0e-6", "output_interval = 1.0e-6\ncheckpoint_interval = 2.0e-6")
    for a, b in replace.items():
        assert a in text, a
        text = text.replace(a, b)
    (case / "case.toml").write_text(text)
    return case


@pytest.fixture(scope="module")
def run_a(tmp_path_factory):
    """Case A (the bar, 4 us, checkpoints every 2 us) and its finished output."""
    base = tmp_path_factory.mktemp("a")
    case = with_checkpoints(bar_case(base, "a"))
    out = base / "out"
    r = immerse("run", case, "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    ckpts = sorted((out / "checkpoints").glob("checkpoint_*.h5"))
    assert len(ckpts) == 1  # at 2 us; none at the end time
    return case, out, ckpts[0]


def refused(r, out, *fragments):
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("immerse: --restart = "), lines[0]
    for f in fragments:
        assert f in lines[0], lines[0]
    assert not out.exists(), "the output directory was created"
    return lines[0]


def _old_format(src, dst):
    """A checkpoint as written before checkpoints named their case."""
    shutil.copy(src, dst)
    with h5py.File(dst, "a") as h:
        for k in ("format", "case_name", "case_fingerprint", "case_identity"):
            del h.attrs[k]
    return dst


NOT_CHECKPOINTS = {
    "text file": (lambda a, t: (t / "notes.txt", (t / "notes.txt").write_text("hello"))[0], "not an HDF5 file"),
    "results index": (lambda a, t: a[1] / "results.h5", "results index"),
    "step file": (lambda a, t: a[1] / "steps" / "lagrange_000002.h5", "output step file"),
    "mesh file": (lambda a, t: a[1] / "steps" / "lagrange_mesh.h5", "output mesh file"),
    "solver state": (lambda a, t: next((a[1] / "checkpoints").glob("step_*/lagrange.h5")),
                     "state of one solver group"),
    "directory": (lambda a, t: a[1] / "checkpoints", "is a directory"),
    "missing file": (lambda a, t: a[1] / "checkpoints" / "checkpoint_00000120.h5", "no such file"),
    "older checkpoint": (lambda a, t: _old_format(a[2], t / "old.h5"), "without a case fingerprint"),
}


@pytest.mark.parametrize("kind", list(NOT_CHECKPOINTS))
def test_restart_on_what_is_not_a_checkpoint(run_a, tmp_path, kind):
    """The seen failure: a traceback, and the output directory created."""
    make, fragment = NOT_CHECKPOINTS[kind]
    path = make(run_a, tmp_path)
    out = tmp_path / "new_out"
    t0 = time.perf_counter()
    r = immerse("run", run_a[0], "--out", out, "--restart", path, timeout=60)
    refused(r, out, fragment, str(path))
    assert time.perf_counter() - t0 < 5.0


def _tampered(run_a, tmp_path, how):
    """A copy of the output with its real checkpoint (the right fingerprint) tampered with."""
    out = tmp_path / "copy"
    shutil.copytree(run_a[1], out, symlinks=True)
    ck = out / "checkpoints" / run_a[2].name
    with h5py.File(ck, "a") as h:
        a = h.attrs
        if how == "state_at_etc_passwd":
            a["file_lagrange"] = "/etc/passwd"
        elif how == "state_up_the_tree":
            a["file_lagrange"] = "../../../../../../etc/passwd"
        elif how == "state_link_out":
            (ck.parent / "link.h5").symlink_to("/etc/passwd")
            a["file_lagrange"] = "link.h5"
        elif how == "step_negative":
            a["step"] = -5
        elif how == "t_nan":
            a["t"] = float("nan")
        elif how == "ranks_1e9":
            a["ranks_lagrange"] = 10**9
        elif how == "identity_100000_deep":
            a["case_identity"] = "[" * 100_000 + "]" * 100_000
        elif how == "dataset_8TiB":
            h.create_dataset("history/huge", shape=(1 << 40,), dtype="f8", chunks=(1024,))
    return ck


@pytest.mark.parametrize("how, fragment", [
    ("state_at_etc_passwd", "allowed: a path inside the checkpoint's folder"),
    ("state_up_the_tree", "allowed: a path inside the checkpoint's folder"),
    ("state_link_out", "leads outside the checkpoint's folder"),
    ("step_negative", "step = -5, allowed: an integer from 0"),
    ("t_nan", "t = nan, allowed: a finite time >= 0 s"),
    ("ranks_1e9", "ranks_lagrange = 1000000000, allowed: an integer from 1 to 1048576"),
    ("identity_100000_deep", "case_identity nested too deeply"),
    ("dataset_8TiB", "declares 8 TiB of data"),
])
def test_a_tampered_checkpoint_is_refused(run_a, tmp_path, how, fragment):
    """Issue 41: a checkpoint with its real fingerprint but state pointing out of its folder, step
    -5, t = nan, 1e9 ranks, a 100,000-deep identity, an 8 TiB dataset: launched or a RecursionError.
    Everything read from it is validated: one line, exit 2, nothing created, under 5 s."""
    ck = _tampered(run_a, tmp_path, how)
    out = tmp_path / "new_out"
    t0 = time.perf_counter()
    r = immerse("run", run_a[0], "--out", out, "--restart", ck, timeout=60)
    refused(r, out, fragment)
    assert time.perf_counter() - t0 < 5.0


@pytest.mark.parametrize("change, key", [
    ({"cells = [400, 1, 1]": "cells = [200, 1, 1]"}, "lagrange.bodies[0].mesh.box.cells"),
    ({"density = 8000.0": "density = 7900.0"}, "materials.steel.density"),
    ({"dimension = 3": "dimension = 3\ndt_scale = 0.5"}, "run.dt_scale"),
])
def test_checkpoint_of_another_case_is_refused(run_a, tmp_path, change, key):
    """The seen failure: a checkpoint of another mesh was accepted, ran past its end time and
    reported the other case's mass. Now one line naming the key that differs."""
    other = with_checkpoints(bar_case(tmp_path, "b", **change))
    out = tmp_path / "out"
    line = refused(immerse("run", other, "--out", out, "--restart", run_a[2], timeout=60), out,
                   "checkpoint of another case ('a')", key)
    assert "in the checkpoint" in line


def _box_mesh_file(path, cells=(40, 1, 1), upper=(0.1, 0.0025, 0.0025)):
    """The bar as a .vtu file (hexahedra), as a user's mesher would write it."""
    nx, ny, nz = cells
    xs, ys, zs = (np.linspace(0, u, n + 1) for u, n in zip(upper, cells))
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])

    def nid(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k
    hexes = [[nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i, j + 1, k),
              nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)]
             for i in range(nx) for j in range(ny) for k in range(nz)]
    meshio.write(path, meshio.Mesh(pts, [("hexahedron", np.array(hexes))]))


def test_checkpoint_of_another_mesh_file_is_refused(tmp_path):
    """The mesh's bytes are part of the case: the same case file with an edited mesh file is
    another case; the same mesh under another name (or the case moved) is the same case."""
    a = bar_case(tmp_path, "a", **{
        "mesh = { box = { lower = [0.0, 0.0, 0.0], upper = [0.1, 0.0025, 0.0025], cells = [400, 1, 1] } }":
            'mesh = { file = "bar.vtu" }'})
    _box_mesh_file(a / "bar.vtu")
    with_checkpoints(a)
    full = tmp_path / "full"
    r = immerse("run", a, "--out", full, timeout=300)
    assert r.returncode == 0, r.stderr
    ckpt = next((full / "checkpoints").glob("checkpoint_*.h5"))
    # the same case moved, its mesh renamed: accepted (checked without running it)
    moved = tmp_path / "moved"
    shutil.copytree(a, moved)
    (moved / "bar.vtu").rename(moved / "renamed.vtu")
    (moved / "case.toml").write_text((moved / "case.toml").read_text().replace("bar.vtu", "renamed.vtu"))
    restart.check_restart(ckpt, load_case(moved))
    # the mesh file edited (a finer mesh of the same bar)
    _box_mesh_file(a / "bar.vtu", cells=(50, 1, 1))
    out = tmp_path / "out"
    refused(immerse("run", a, "--out", out, "--restart", ckpt, timeout=60), out,
            "checkpoint of another case", "lagrange.bodies[0].mesh.file.file_sha256")


def _last_step(out, role="lagrange"):
    with h5py.File(out / "results.h5") as h:
        last = sorted(k for k in h[role] if k.isdigit())[-1]
        return {k: h[f"{role}/{last}/{k}"][...] for k in ("points", "point_data/velocity", "cell_data/stress")}, \
            list(h[f"{role}/times"][...])


def test_restart_with_a_later_end_time(run_a, tmp_path):
    """Extending end_time on restart (as LS-DYNA's and ALE3D's users do) continues to the new end,
    bitwise equal to a run that had that end time from the start."""
    case_a, out_a, ckpt = run_a
    longer = tmp_path / "longer"
    shutil.copytree(case_a, longer)
    (longer / "case.toml").write_text((longer / "case.toml").read_text().replace(
        "end_time = 4.0e-6", "end_time = 6.0e-6"))
    cont = tmp_path / "cont"
    shutil.copytree(out_a, cont, symlinks=True)
    r = immerse("run", longer, "--out", cont, "--restart", cont / "checkpoints" / ckpt.name, timeout=300)
    assert r.returncode == 0, r.stderr
    full = tmp_path / "full"
    r = immerse("run", longer, "--out", full, timeout=300)
    assert r.returncode == 0, r.stderr
    (a, ta), (b, tb) = _last_step(full), _last_step(cont)
    assert ta == tb and ta[-1] == pytest.approx(6.0e-6, rel=1e-12)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (full, cont))
    assert sa["final"] == sb["final"] and sa["steps"] == sb["steps"]


def test_restart_with_another_output_interval(run_a, tmp_path):
    """Outputs after a restart follow the new interval's times, one per interval, each at the first
    step that reaches it (step_control: outputs never clip a step): the schedule follows the time,
    not a count of earlier outputs (a halved interval once wrote an output on every step until the
    count caught up)."""
    case_a, out_a, ckpt = run_a
    finer = tmp_path / "finer"
    shutil.copytree(case_a, finer)
    (finer / "case.toml").write_text((finer / "case.toml").read_text().replace(
        "output_interval = 1.0e-6", "output_interval = 0.25e-6"))
    cont = tmp_path / "cont"
    shutil.copytree(out_a, cont, symlinks=True)
    r = immerse("run", finer, "--out", cont, "--restart", cont / "checkpoints" / ckpt.name, timeout=300)
    assert r.returncode == 0, r.stderr
    times = np.array(_last_step(cont)[1])
    # before the checkpoint at 2 us: 0, 1, 2 us; after it every 0.25 us up to the end at 4 us
    expected = np.concatenate([[0.0, 1e-6, 2e-6], 2e-6 + 0.25e-6 * np.arange(1, 9)])
    assert len(times) == len(expected), times
    dt_max = json.loads((cont / "summary.json").read_text())["dt"]["max"]
    late = times - expected
    assert np.all(late >= -1e-12 * 4e-6) and np.all(late < dt_max), (times, dt_max)
    assert times[-1] == pytest.approx(4e-6, rel=1e-15)   # the end: landed on exactly


def test_restart_on_another_rank_count(run_a, tmp_path):
    """A one-rank Lagrangian checkpoint continued on two ranks ends equal to the one-rank run bit
    for bit (the cut nodes' sums in the one-rank order, solvers/lagrange/shared_sums.py)."""
    case_a, out_a, ckpt = run_a
    cont = tmp_path / "cont"
    shutil.copytree(out_a, cont, symlinks=True)
    r = immerse("run", case_a, "--out", cont, "--restart", cont / "checkpoints" / ckpt.name,
                "--ranks", "lagrange=2", timeout=300)
    assert r.returncode == 0, r.stderr
    (a, ta), (b, tb) = _last_step(out_a), _last_step(cont)
    assert ta == tb
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_restart_into_its_own_output_needs_no_replace_and_refuses_it(run_a, tmp_path):
    case_a, out_a, ckpt = run_a
    cont = tmp_path / "cont"
    shutil.copytree(out_a, cont, symlinks=True)
    r = immerse("run", case_a, "--out", cont, "--restart", cont / "checkpoints" / ckpt.name, "--replace",
                timeout=60)
    assert r.returncode == 2 and "--replace would delete the checkpoint" in r.stderr, r.stderr
    # a checkpoint from elsewhere into an earlier output of the case: that output is replaced only
    # on request
    r = immerse("run", case_a, "--out", cont, "--restart", ckpt, timeout=60)
    assert r.returncode == 2 and "--replace" in r.stderr, r.stderr
