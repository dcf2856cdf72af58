"""The README's commands work as written and the files it names are in the repository.

Every `immerse ...` line of the README's code blocks parses with the real command line (verbs,
options, bench names), names case directories that exist, and names outputs only under the output
directory of a run the README starts before; the cheap ones run: every `immerse check`, and the
restart example (run, restart from the checkpoint it names, view) in a copy of the case, as a user
would type them. Paths of the repository named in README.md and DESIGN.md exist, and neither points
outside the repository.
"""
from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from orchestrator import bench, cli
from tests.conftest import REPO, immerse

README = (REPO / "README.md").read_text()
DESIGN = (REPO / "DESIGN.md").read_text()
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
# the walkthrough "Write your first case": its commands run on a case the user writes from the README, in a
# directory of their own (not in cases/): tests/test_readme_walkthrough.py runs them as written
WALKTHROUGH = re.compile(r"^## Write your first case\n.*?(?=^## )", re.S | re.M)


def shell_blocks(text: str) -> list[str]:
    text = WALKTHROUGH.sub("", text)
    return [body for lang, body in FENCE.findall(text) if lang in ("", "sh", "bash", "console")]


def commands(prefix: str) -> list[list[str]]:
    out = []
    for body in shell_blocks(README):
        for line in body.splitlines():
            if line.startswith(prefix + " "):
                out.append(shlex.split(line, comments=True))
    return out


IMMERSE = commands("immerse")


def _parse(argv: list[str], monkeypatch) -> SimpleNamespace:
    """Parse an immerse command line with the CLI's own parser; record instead of running."""
    seen = {}

    def record(args):
        seen["args"] = args
        return 0

    for name in ("cmd_check", "cmd_run", "cmd_view", "cmd_plot", "cmd_keys", "cmd_bench", "cmd_campaign",
                 "cmd_report"):
        monkeypatch.setattr(cli, name, record)
    assert cli.main(argv) == 0
    return seen["args"]


def test_readme_has_the_commands():
    verbs = {c[1] for c in IMMERSE}
    assert verbs == {"check", "run", "view", "plot", "keys", "bench", "campaign", "report"}
    assert [c[:2] for c in commands("make")] == [["make", "demo"], ["make", "test"]]


def test_make_targets_exist():
    makefile = (REPO / "Makefile").read_text()
    for _, target in commands("make"):
        assert re.search(rf"^{target}:", makefile, re.M), target


def test_every_immerse_command_parses_and_names_what_exists(monkeypatch):
    outputs: dict[str, str] = {}  # output directory -> case of a README run before
    for cmd in IMMERSE:
        args = _parse(cmd[1:], monkeypatch)
        line = " ".join(cmd)
        if cmd[1] in ("check", "run"):
            assert (REPO / args.case / "case.toml").is_file(), line
        if cmd[1] == "run":
            out = args.out or str(Path(args.case) / "out")
            assert not Path(out).is_absolute(), f"{line}: an output path of this machine"
            if args.restart:
                # the checkpoint lies in the output of a run of the same case the README started
                owner = [o for o in outputs if Path(args.restart).is_relative_to(o)]
                assert owner and outputs[owner[0]] == args.case, line
                assert Path(args.restart).parent.name == "checkpoints", line
            outputs[out] = args.case
            for item in args.ranks or []:
                assert cli._parse_ranks([item]) == {item.split("=")[0]: int(item.split("=")[1])}
        if cmd[1] in ("view", "plot"):
            assert args.out in outputs, f"{line}: draws an output no README run writes"
        if cmd[1] == "bench":
            assert args.name in bench.BENCHES, line
        if cmd[1] == "campaign":
            camp = REPO / args.campaign
            assert (camp / "campaign.toml").is_file() or camp.is_file(), line
            out = args.out or str(Path(args.campaign) / "out")
            assert not Path(out).is_absolute(), f"{line}: an output path of this machine"
            outputs[out] = args.campaign
        if cmd[1] == "report":
            assert args.out in outputs, f"{line}: reports on an output no README campaign writes"


@pytest.mark.parametrize("cmd", [c for c in IMMERSE if c[1] == "check"], ids=lambda c: " ".join(c))
def test_check_commands_run(cmd):
    r = immerse(*cmd[1:])
    assert r.returncode == 0 and ": ok" in r.stdout, r.stderr


def test_restart_example_works_as_written(tmp_path):
    """The README's sod lines, verbatim, in a copy of the case: the run writes the checkpoint the
    restart line names, the restart ends where the run ended, the view draws the pictures and the
    plot the total energy's history."""
    sod = [c for c in IMMERSE if any(a.startswith("cases/sod") for a in c[2:3])]
    assert [c[1] for c in sod] == ["run", "run", "view", "plot"], sod
    assert "--restart" in sod[1]
    shutil.copytree(REPO / "cases" / "sod", tmp_path / "cases" / "sod", ignore=shutil.ignore_patterns("out"))
    results = []
    for cmd in sod:
        r = immerse(*cmd[1:], cwd=tmp_path)
        assert r.returncode == 0, f"{' '.join(cmd)}: {r.stdout}{r.stderr}"
        results.append(r)
        if cmd[1] == "run" and "--restart" not in cmd:
            assert (tmp_path / sod[1][sod[1].index("--restart") + 1]).is_file()
    assert results[2].stderr == "" and len(results[2].stdout.split()) == 3
    assert results[3].stderr == "" and results[3].stdout.split() == ["cases/sod/out/plots/ale.total_energy.png"]
    assert "check passed" in results[0].stdout and "check passed" in results[1].stdout


# ------------------------------------------------------------------------------------------ paths
def _named_paths(text: str) -> set[str]:
    """Paths of the repository named anywhere in the text (backticked or in code blocks), except
    templates (<name>), globs and outputs (under an `out` directory)."""
    found = set()
    for token in re.findall(r"(?<![\w/.<])((?:orchestrator|adapters|solvers|cases|tests|docker|\.ci)/[\w./<>*-]*)",
                            text):
        token = token.rstrip("/.")
        if re.search(r"[<>*]", token) or "out" in token.split("/"):
            continue
        found.add(token)
    for token in re.findall(r"`(DESIGN\.md|README\.md|Makefile|requirements\.txt|pyproject\.toml)`", text):
        found.add(token)
    return found


def _named_modules(text: str) -> set[str]:
    """Python modules named by their dotted name (orchestrator.coupler, solvers.ale.exact, ...)."""
    return {m for m in re.findall(r"(?<![\w/.])((?:orchestrator|adapters|solvers)(?:\.\w+)+)", text)}


def _listed_modules(text: str) -> set[str]:
    """Modules of the "How it is built" listing: `dir/  a.py, b.py ...`, `sub/: c.py ...`."""
    block = text.split("## How it is built", 1)[1]
    block = FENCE.search(block).group(2)
    found, top, sub = set(), "", ""
    for line in block.splitlines():
        head = re.match(r"^(\w+/)\s", line)
        if head:
            top, sub = head.group(1), ""
        for m in re.finditer(r"(\w+)/:|(\w+\.py)|(\w+)/ \(", line):
            if m.group(1):
                sub = m.group(1) + "/"
            elif m.group(2):
                found.add(top + sub + m.group(2))
            elif m.group(3) and top:
                found.add(top + sub + m.group(3))
    return found


def test_paths_named_exist():
    named = _named_paths(README) | _named_paths(DESIGN)
    assert {"orchestrator/checks/registry.py", "adapters/base.py", "docker/Dockerfile", "cases/sod", "DESIGN.md"} <= named
    missing = sorted(p for p in named if not (REPO / p).exists())
    assert not missing, missing
    dotted = _named_modules(README) | _named_modules(DESIGN)
    assert {"orchestrator.coupler", "orchestrator.warmup"} <= dotted
    missing = sorted(m for m in dotted if not (REPO / (m.replace(".", "/") + ".py")).is_file()
                     and not (REPO / m.replace(".", "/")).is_dir())
    assert not missing, missing
    modules = _listed_modules(README)
    assert len(modules) > 30 and "solvers/ale/hydro.py" in modules and "solvers/ale/exact" in modules
    missing = sorted(p for p in modules if not (REPO / p).exists())
    assert not missing, missing


def test_nothing_points_outside_the_repository():
    for name, text in (("README.md", README), ("DESIGN.md", DESIGN)):
        assert "../" not in text, name
        assert "/work/" not in text and "/home/" not in text, name
    assert "DESIGN.md" in README


def test_design_module_map_lists_every_module():
    """DESIGN.md's module map: one line for each module of orchestrator/, adapters/ and solvers/, and
    no line for a module that is gone (a moved module must move its line)."""
    block = DESIGN.split("### Module map", 1)[1].split("```")[1]
    listed = [line.split()[0] for line in block.strip().splitlines()]
    actual = sorted(p.relative_to(REPO).as_posix() for pkg in ("orchestrator", "adapters", "solvers")
                    for p in (REPO / pkg).rglob("*.py") if "__pycache__" not in p.parts)
    assert len(listed) == len(set(listed))
    assert sorted(listed) == actual, (sorted(set(actual) - set(listed)), sorted(set(listed) - set(actual)))
