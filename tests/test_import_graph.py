"""The import graph of the packages (issue 47): no module imports itself through others (an import
circle), and no floor imports a higher one: solvers/ lowest, adapters/ above them, orchestrator/ on
top (DESIGN.md, Layout). Read from every source file's syntax tree (tests/solvers/test_layering.py
`imports`: lazy imports inside functions and import_module calls included); a module importing a
package's submodule depends on that submodule (and the package's __init__)."""
from __future__ import annotations

from pathlib import Path

from tests.conftest import REPO
from tests.solvers.test_layering import imports

PACKAGES = ("solvers", "adapters", "orchestrator")
FLOOR = {"solvers": 0, "adapters": 1, "orchestrator": 2}

# none: the adapters read the case the launcher checked from its file (adapters/case_file.py), not
# through the loader on the orchestrator's floor (issue 47)
KNOWN_FLOOR_BREAKS: set[tuple[str, str]] = set()


def sources(root: Path = REPO) -> dict[str, tuple[Path, str]]:
    """module name -> (path relative to the repository, source) of every .py file of PACKAGES."""
    out = {}
    for pkg in PACKAGES:
        for p in sorted((root / pkg).rglob("*.py")):
            rel = p.relative_to(root)
            name = ".".join(rel.with_suffix("").parts)
            out[name.removesuffix(".__init__")] = (rel, p.read_text())
    return out


def graph(src: dict[str, tuple[Path, str]]) -> dict[str, set[str]]:
    """module -> the modules of PACKAGES it imports (a name that is an attribute of a module counts
    as that module; a package's own __init__ importing its submodules is not a circle)."""
    g = {}
    for mod, (rel, text) in src.items():
        deps = set()
        for _, name in imports(text, rel):
            while name and name not in src:
                name = name.rpartition(".")[0]
            if name and name != mod and not mod.startswith(name + "."):
                deps.add(name)
        g[mod] = deps
    return g


def circles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = 0
    for root in sorted(g):
        if root in index:
            continue
        work = [(root, iter(sorted(g[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(g.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def floor_breaks(g: dict[str, set[str]]) -> set[tuple[str, str]]:
    """(module, module it imports) where the import goes up a floor (the package itself, e.g.
    ``from orchestrator import output``, is reported through its submodule)."""
    return {(m, d) for m, deps in g.items() for d in deps
            if FLOOR[d.split(".")[0]] > FLOOR[m.split(".")[0]] and "." in d}


def test_no_import_circles():
    src = sources()
    assert len(src) > 100 and "orchestrator.coupler" in src
    found = circles(graph(src))
    assert not found, "import circles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_no_floor_imports_a_higher_one():
    found = floor_breaks(graph(sources()))
    new = found - KNOWN_FLOOR_BREAKS
    assert not new, "imports from a lower floor to a higher one:\n" + "\n".join(f"{a} imports {b}" for a, b in sorted(new))
    # the list only shrinks: an entry that no longer happens is taken off it
    assert not KNOWN_FLOOR_BREAKS - found, sorted(KNOWN_FLOOR_BREAKS - found)


def test_a_planted_back_import_is_found():
    """The checks see what they guard: a lazy import of the command line inside the step-file
    writer (which the CLI imports) is a circle; one of the coupler inside a solver, a floor break."""
    src = sources()
    rel, text = src["orchestrator.output"]
    src["orchestrator.output"] = (rel, text + "\n\ndef _planted():\n    from orchestrator.cli import main\n")
    assert any("orchestrator.output" in c and "orchestrator.cli" in c for c in circles(graph(src)))
    rel, text = src["solvers.elements"]
    src["solvers.elements"] = (rel, text + "\nimport orchestrator.coupler\n")
    assert ("solvers.elements", "orchestrator.coupler") in floor_breaks(graph(src))
