"""Every picture `immerse view` draws of every shipped case is framed, and every coupled case reads
right in ParaView (issue 44): each case run for
two steps (its scene as the analyst first sees it: the same domain, bodies and fields as its full
run), every field of its last output step drawn, and each picture measured by
tests/picture_framing.py: a field picture's domain fills most of its frame, clear of the title above
and of the colour bar below, the bar's labels apart, nothing cut at the edges; a line plot's title,
axis labels, tick labels and legend inside the figure and clear of each other. A coupled case's
OUT/open_in_paraview.py under pvbatch (where installed): its blocks named by their roles and no
zone the bodies cover reading a gas pressure of 0 (tests/orchestrator/test_paraview.py)."""
from __future__ import annotations

import re
import shutil
import tomllib

import pytest

from orchestrator.output import list_roles
from tests.conftest import CASES, immerse
from tests.orchestrator.test_paraview import find_pvbatch, trace_check
from tests.picture_framing import assert_field_picture_framed, assert_line_figure_framed

pytest.importorskip("pyvista")

SHIPPED = sorted(str(p.parent.relative_to(CASES)) for p in CASES.rglob("case.toml"))


def _two_steps(tmp_path, name):
    """A copy of cases/<name> whose [run] stops after two steps (run.max_steps)."""
    case = tmp_path / "case"
    shutil.copytree(CASES / name, case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    text = p.read_text()
    if re.search(r"^max_steps\s*=", text, flags=re.M):
        text = re.sub(r"^max_steps\s*=.*$", "max_steps = 2", text, count=1, flags=re.M)
    else:
        text = re.sub(r"^\[run\]\s*$", "[run]\nmax_steps = 2", text, count=1, flags=re.M)
    p.write_text(text)
    assert tomllib.loads(text)["run"]["max_steps"] == 2
    return case


@pytest.mark.parametrize("name", SHIPPED)
def test_every_picture_of_a_shipped_case_is_framed(tmp_path, name, monkeypatch):
    from matplotlib.figure import Figure

    from orchestrator import view

    case = _two_steps(tmp_path, name)
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out)
    # exit 1: its check fails after two steps (not what is measured here); anything else is a fault
    assert r.returncode in (0, 1) and (out / "results.xdmf").is_file(), r.stdout + r.stderr
    lines = {}
    save = Figure.savefig

    def keep(fig, path, *a, **kw):   # the line plots' figures, measured from their own boxes
        lines[str(path)] = fig
        return save(fig, path, *a, **kw)

    monkeypatch.setattr(Figure, "savefig", keep)
    planar = tomllib.loads((case / "case.toml").read_text())["run"]["dimension"] == 2
    pictures = view.render(out)
    assert pictures
    for png in pictures:
        if str(png) in lines:
            assert_line_figure_framed(lines[str(png)])
        else:
            assert_field_picture_framed(png, planar)
    roles = sorted(list_roles(out))
    if "ale" not in roles or len(roles) < 2:
        return
    exe, why = find_pvbatch()
    if exe is None:
        pytest.skip(f"pictures framed; the ParaView view not checked: {why}")
    got = trace_check(exe, out, tmp_path)
    assert got["names"] == roles and got["roles"] == roles, got
    assert got["ale"]["covered_zeros"] == 0, got
