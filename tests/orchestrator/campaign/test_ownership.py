"""A campaign deletes and overwrites only files it recorded writing, under a record it can trust
(orchestrator/campaign/rundir.py): a user's file planted behind each route stays, and the campaign
(or `immerse report`) is refused in one line, exit 2, nothing written."""
from __future__ import annotations

import json
import shutil
import pytest

from tests.conftest import CASES
from tests.orchestrator.test_outdir import snapshot

CAMPAIGN = '''
name = "owned"
[axes.zones]
values = [50]
"ale.grid.cells" = [[50, 1]]
[[series]]
name = "sod"
case = "@SOD"
set = { "run.end_time" = END, "run.output_interval" = 0.01, "run.checkpoint_interval" = 0.01 }
[report]
error = "density_l1"
'''
RUN = "sod-zones50"


def _campaign(tmp_path, end=0.01):
    p = tmp_path / "campaign.toml"
    p.write_text(CAMPAIGN.replace("@SOD", str(CASES / "sod")).replace("END", repr(end)))
    return p


def _refused(r, *fragments):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    """One finished campaign (one short Sod run): (campaign file, its output)."""
    from tests.conftest import immerse

    tmp = tmp_path_factory.mktemp("owned")
    p = _campaign(tmp)
    out = tmp / "out"
    r = immerse("campaign", p, "--out", out, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return p, out


@pytest.mark.parametrize("marker", ["copied", "older"])
def test_a_copied_marker_is_no_record(done, tmp_path, run_immerse, marker):
    """Another folder holding a copy of the campaign's marker (issue 41: it deleted
    runs/<run>/<run>/ with the user's file in it), or a marker without the folder's identity."""
    p, first = done
    out = tmp_path / "other"
    (out / "runs" / RUN / RUN).mkdir(parents=True)
    (out / "runs" / RUN / RUN / "mine.txt").write_text("the user's\n")
    owner = json.loads((first / ".immerse-campaign.json").read_text())
    if marker == "older":
        owner.pop("folder")
    (out / ".immerse-campaign.json").write_text(json.dumps(owner))
    before = snapshot(out)
    r = run_immerse("campaign", _campaign(tmp_path, end=0.02), "--out", out)
    _refused(r, "--out", "written in another folder")
    assert snapshot(out) == before


@pytest.mark.parametrize("planted", [f"runs/{RUN}/{RUN}/notes.txt", "runs/sod-zones60/result.json",
                                     "runs/sod-zones60/sod-zones60/case.toml", "slurm/job.json"])
def test_a_user_file_at_a_campaign_path_is_refused(done, tmp_path, run_immerse, planted):
    """The campaign's own output (moved within the file system: the same folder) with a file of the
    user's where the campaign would delete or overwrite it: in the run's case directory (replaced
    because the campaign changed), a result and a case directory of a run it is about to add, a
    file of the Slurm engine; `immerse report` on it too."""
    p, first = done
    out = tmp_path / "out"
    first.rename(out)   # the same folder (its identity moves with it)
    try:
        target = out / planted
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text("the user's\n")
        before = snapshot(out)
        more = _campaign(tmp_path, end=0.02)
        more.write_text(more.read_text().replace("values = [50]", "values = [50, 60]")
                        .replace("[[50, 1]]", "[[50, 1], [60, 1]]"))
        r = run_immerse("campaign", more, "--out", out)
        _refused(r, "--out", f"{planted} was not written by this campaign")
        assert snapshot(out) == before
        r = run_immerse("report", out)
        _refused(r, "OUT", f"{planted} was not written by this campaign")
        assert snapshot(out) == before
        target.unlink()
    finally:
        out.rename(first)


def test_the_campaign_replaces_its_own_files(done, tmp_path, run_immerse):
    """Its own output, the case changed (end time): the run's case directory is rewritten and run
    again; a file of the user's beside the campaign's paths stays."""
    p, first = done
    (first / "my_notes.md").write_text("mine\n")
    (first / "runs" / RUN / "my_plot.py").write_text("mine\n")
    r = run_immerse("campaign", _campaign(tmp_path, end=0.02), "--out", first)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 done before, 1 to run" in r.stdout
    assert (first / "my_notes.md").read_text() == "mine\n"
    assert (first / "runs" / RUN / "my_plot.py").read_text() == "mine\n"
    assert "end_time = 0.02" in (first / "runs" / RUN / RUN / "case.toml").read_text()


@pytest.mark.parametrize("entry", ["fifo", "socket", "link_to_64GiB", "dangling_link"])
def test_a_base_case_that_cannot_be_copied_is_one_line(tmp_path, run_immerse, entry):
    """A FIFO (the copy would block on it), a socket, a link to a 64 GiB sparse file (read whole by
    the copy's fingerprint), a dangling link: refused naming it, no output folder made."""
    import os
    import socket

    base = tmp_path / "base"
    shutil.copytree(CASES / "sod", base, ignore=shutil.ignore_patterns("out"))
    p = base / "extra"
    if entry == "fifo":
        os.mkfifo(p)
    elif entry == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
    elif entry == "link_to_64GiB":
        big = tmp_path / "sparse"
        with open(big, "wb") as f:
            f.truncate(64 << 30)
        p.symlink_to(big)
    else:
        p.symlink_to(tmp_path / "nowhere")
    camp = _campaign(tmp_path)
    camp.write_text(camp.read_text().replace(str(CASES / "sod"), str(base)))
    r = run_immerse("campaign", camp, "--out", tmp_path / "out", timeout=60)
    _refused(r, "run sod-zones50: case")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("where", ["/proc/immerse-campaign", "a_file/out"])
def test_an_out_that_cannot_be_made_is_one_line(tmp_path, run_immerse, where):
    (tmp_path / "a_file").write_text("mine\n")
    out = where if where.startswith("/") else tmp_path / where
    r = run_immerse("campaign", _campaign(tmp_path), "--out", out, timeout=60)
    _refused(r, "--out", "cannot be created")
    assert (tmp_path / "a_file").read_text() == "mine\n"


def test_a_damaged_table_is_one_line_for_report(done, tmp_path, run_immerse):
    p, first = done
    h5 = first / "campaign.h5"
    keep = h5.read_bytes()
    try:
        h5.write_bytes(b"\x89HDF not really" * 100)
        r = run_immerse("report", first)
        _refused(r, "OUT", "campaign.h5 is damaged")
    finally:
        h5.write_bytes(keep)
