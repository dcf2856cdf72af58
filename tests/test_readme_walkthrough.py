"""README.md's "Write your first case" works as written: the case.toml block after the marker
`<!-- first-case -->`, written to a directory of the name the section's commands use, passes
`immerse check`, runs with its check passed, and the section's view and plot lines draw the pictures
and the plot the section names. The commands are the section's own lines, run as a user would type
them (tests/test_readme.py leaves this section's lines to this test: its case is not in cases/).
"""
from __future__ import annotations

import json
import re
import shlex

import pytest

from tests.conftest import REPO, immerse

README = (REPO / "README.md").read_text()
MARKER = "<!-- first-case -->"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def section() -> str:
    """The text of the section "## Write your first case", up to the next section of its level."""
    return README.split("\n## Write your first case\n", 1)[1].split("\n## ", 1)[0]


def case_toml() -> str:
    """The fenced toml block right after the marker."""
    after = section().split(MARKER, 1)[1]
    block = re.match(r"\s*```toml\n(.*?)^```", after, re.S | re.M)
    assert block, f"no ```toml block right after {MARKER}"
    return block.group(1)


def commands() -> list[list[str]]:
    return [shlex.split(line, comments=True) for lang, body in FENCE.findall(section())
            if lang in ("", "sh", "bash", "console") for line in body.splitlines() if line.startswith("immerse ")]


def test_the_section_has_one_case_and_its_commands():
    assert README.count(MARKER) == 1
    toml = case_toml()
    assert "[probes]" in toml and "[check]" in toml and "[coupling]" in toml
    cmds = commands()
    assert [c[1] for c in cmds] == ["check", "run", "view", "plot"], cmds
    case = cmds[0][2]
    assert all(c[2] == case or c[2] == f"{case}/out" for c in cmds), cmds


@pytest.mark.slow
def test_first_case_runs_as_written(tmp_path):
    """Every command line of the section, verbatim, in a fresh directory holding the case (~25 s on 2
    shared cores, most of it the job's start-up)."""
    cmds = commands()
    case = cmds[0][2]
    (tmp_path / case).mkdir()
    (tmp_path / case / "case.toml").write_text(case_toml())
    for cmd in cmds:
        r = immerse(*cmd[1:], cwd=tmp_path)
        assert r.returncode == 0, f"{' '.join(cmd)}: {r.stdout}{r.stderr}"
        if cmd[1] == "check":
            assert f"{case}: ok" in r.stdout, r.stdout
        if cmd[1] == "run":
            assert "check passed" in r.stdout, r.stdout
    out = tmp_path / case / "out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["check"]["kind"] == "embedded_piston" and summary["check"]["passed"], summary["check"]
    # every value the section names is written where it says
    for name in re.findall(rf"`{case}/out/((?:pictures|plots)/[\w.]+\.png)`", section()):
        assert (out / name).is_file(), name
    assert (out / "probes.csv").read_text().splitlines()[0] == "time,step,lagrange.slab"
