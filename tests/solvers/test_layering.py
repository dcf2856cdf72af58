"""The layering of the packages (DESIGN.md, Layout): the solvers are runnable alone, so nothing under
solvers/ imports the driver above them (orchestrator/, adapters/); and the two solvers share their
element geometry through solvers/elements.py, so neither imports the other.

Every import of every source file is read from its syntax tree (`ast`), the ones inside functions
included (lazy imports), and so are ``importlib.import_module("...")`` / ``__import__("...")``
calls with a literal name.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import REPO

SOLVERS = REPO / "solvers"
ABOVE = ("orchestrator", "adapters")


def _package(rel: Path) -> list[str]:
    """Dotted package of a source file, e.g. ['solvers', 'ale'] for solvers/ale/hydro.py."""
    parts = list(rel.with_suffix("").parts)
    return parts[:-1]


def imports(source: str, rel: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the source of file ``rel`` (relative to the
    repository); ``from a import b`` gives both ``a`` and ``a.b`` (b may be a module)."""
    tree = ast.parse(source, filename=str(rel))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            pkg = _package(rel)
            parts = pkg[: max(0, len(pkg) - node.level + 1)] if node.level else []
            parts += node.module.split(".") if node.module else []
            if parts:
                out.append((node.lineno, ".".join(parts)))
            out += [(node.lineno, ".".join(parts + [a.name])) for a in node.names if a.name != "*"]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name in ("import_module", "__import__"):
                out.append((node.lineno, node.args[0].value))
    return out


def offending(sources: dict[Path, str], forbidden: tuple[str, ...]) -> list[str]:
    """``file:line imports module`` for every import of a forbidden package (or its modules)."""
    bad = []
    for rel, source in sources.items():
        for line, mod in imports(source, rel):
            if any(mod == f or mod.startswith(f + ".") for f in forbidden):
                bad.append(f"{rel}:{line} imports {mod}")
    return sorted(set(bad))


def _sources(root: Path) -> dict[Path, str]:
    return {p.relative_to(REPO): p.read_text() for p in sorted(root.rglob("*.py"))}


def test_solvers_import_nothing_from_the_driver():
    files = _sources(SOLVERS)
    assert len(files) >= 20 and Path("solvers/elements.py") in files
    bad = offending(files, ABOVE)
    assert not bad, "solvers/ must not import orchestrator/ or adapters/:\n" + "\n".join(bad)


@pytest.mark.parametrize("solver, other", [("ale", "lagrange"), ("lagrange", "ale")])
def test_solvers_do_not_import_each_other(solver, other):
    files = _sources(SOLVERS / solver)
    assert files
    bad = offending(files, (f"solvers.{other}",))
    assert not bad, (f"solvers/{solver} must not import solvers/{other} (shared code belongs in "
                     "solvers/elements.py or another module below both):\n" + "\n".join(bad))


@pytest.mark.parametrize("source, found", [
    ("import orchestrator.case\n", "1 imports orchestrator.case"),
    ("import numpy\n\ndef f():\n    from orchestrator import case\n", "4 imports orchestrator.case"),
    ("import importlib\nimportlib.import_module('adapters.ale')\n", "2 imports adapters.ale"),
    ("from .. import elements\nfrom . import hydro\n", None),  # solvers.elements, solvers.ale.hydro
    ("from ... import orchestrator\n", "1 imports orchestrator"),  # (beyond the top package)
])
def test_the_scan_sees_every_kind_of_import(source, found):
    """The scanner itself, on sources given as if they were solvers/ale/probe.py."""
    bad = offending({Path("solvers/ale/probe.py"): source}, ABOVE)
    if found is None:
        assert bad == []
    else:
        assert f"solvers/ale/probe.py:{found}" in bad, bad
