"""The registry of case.toml tables (orchestrator/schema/registry.py): the solvers' tables come from
their fragment modules, load_case loops over them without naming any, a new table is one
register_table call (schema, normaliser, checks) and runs at its documented place in the hook
order, and validating a case imports no solver kernel."""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import textwrap

import pytest

from orchestrator.schema import registry as R
from orchestrator.schema.case import CASE_SCHEMA
from tests.conftest import REPO


def test_the_schema_is_the_core_and_the_registered_tables_by_order():
    names = [t.name for t in R.tables()]
    assert names == ["materials", "lagrange", "contact", "ale", "boundaries", "sph", "coupling", "probes"]
    assert list(CASE_SCHEMA["properties"]) == ["run", "ranks", *names, "check"]
    for t in R.tables():
        assert CASE_SCHEMA["properties"][t.name] is t.schema
    assert [t.name for t in R.tables() if t.default] == ["lagrange"]


def test_case_py_names_no_registered_table():
    """load_case loops over the registry: no string constant of orchestrator/case.py outside the
    docstrings is the name of a registered table."""
    tree = ast.parse((REPO / "orchestrator" / "case.py").read_text())
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    names = {t.name for t in R.tables()}
    found = sorted({(n.lineno, n.value) for n in ast.walk(tree)
                    if isinstance(n, ast.Constant) and n.value in names and id(n) not in docstrings})
    assert not found, f"orchestrator/case.py names registered tables: {found}"


@pytest.mark.parametrize("kwargs, message", [
    ({"name": "run", "order": 99}, "core table"),
    ({"name": "ale", "order": 99}, "already registered"),
    ({"name": "probe", "order": 40}, "order 40 is taken by [ale]"),
    ({"name": "probe", "order": 99, "default": True}, "only one table may be the default"),
])
def test_register_table_refuses(kwargs, message):
    before = R.tables()
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        R.register_table(schema={"type": "object"}, normalise=lambda raw, case: raw, **kwargs)
    assert R.tables() == before


# A table registered with one call, before the case module builds its schema (as a fragment module
# listed in FRAGMENTS is): it records when its hooks run and what they see.
PROBE = r'''
import json, sys
from pathlib import Path
from orchestrator.schema import registry as R
from orchestrator.schema.rules import CaseError, check_length

seen = []

def normalise(raw, case):
    seen.append(("normalise", raw, sorted(case)))
    return None if raw is None else {"gain": float(raw.get("gain", 1.0)), "at": raw["at"]}

def check(case, data):
    seen.append(("check", sorted(case)))
    check_length("probe.at", data["probe"]["at"], case["run"]["dimension"])

def check_files(case, data):
    seen.append(("check_files", case["ranks"]))

R.register_table("probe", {"type": "object", "properties": {"gain": {"type": "number"},
                 "at": {"type": "array"}}, "additionalProperties": False, "required": ["at"]},
                 normalise, check, order=45, check_files=check_files)

from orchestrator.case import CaseError, load_case
out = {}
for name in sys.argv[1:]:
    seen.clear()
    try:
        case = load_case(Path(name))
        out[name] = {"probe": case.get("probe"), "seen": seen[:]}
    except CaseError as e:
        out[name] = {"error": str(e), "seen": seen[:]}
print(json.dumps(out))
'''

SOD = """\
[run]
dimension = 2
end_time = 0.2

[ale]
grid = { lower = [0.0, 0.0], upper = [1.0, 0.01], cells = [10, 1] }
materials.gas = { eos = "ideal_gas", gamma = 1.4 }
regions = [ { material = "gas", density = 1.0, pressure = 1.0 } ]
"""


def _probe(tmp_path, texts: dict[str, str]) -> dict:
    for name, text in texts.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "case.toml").write_text(text)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", PROBE, *(str(tmp_path / n) for n in texts)], cwd=REPO,
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    return {os.path.basename(k): v for k, v in json.loads(r.stdout).items()}


def test_a_new_table_is_one_call_and_runs_at_its_place(tmp_path):
    out = _probe(tmp_path, {
        "given": SOD + '[probe]\nat = [0.5, 0.0]\n',
        "absent": SOD,
        "unknown_key": SOD + '[probe]\nat = [0.5, 0.0]\nbogus = 1\n',
        "top_level": SOD + '[nope]\nx = 1\n',
        "short": SOD + '[probe]\nat = [0.5]\n',
        "ale_and_probe_bad": SOD.replace("cells = [10, 1]", "cells = [10, 1, 1]") + '[probe]\nat = [0.5]\n',
    })
    given = out["given"]
    assert given["probe"] == {"gain": 1.0, "at": [0.5, 0.0]}
    # normalise after [run] and the tables of lower order (materials 20, lagrange 30, ale 40),
    # check after every normaliser, check_files after [ranks]
    assert given["seen"] == [
        ["normalise", {"at": [0.5, 0.0]}, ["ale", "case_dir", "check", "materials", "name", "ranks", "run"]],
        ["check", ["ale", "boundaries", "case_dir", "check", "materials", "name", "probe", "ranks", "run"]],
        ["check_files", {"ale": 1}],
    ]
    assert out["absent"] == {"probe": None, "seen": [["normalise", None, given["seen"][0][2]]]}
    assert out["unknown_key"]["error"] == "probe.bogus = 1: unknown key; allowed: gain, at"
    assert out["unknown_key"]["seen"] == []  # the schema runs before any hook
    assert out["top_level"]["error"] == ("nope = {'x': 1}: unknown key; allowed: run, ranks, materials, "
                                         "lagrange, contact, ale, probe, boundaries, sph, coupling, probes, check")
    assert out["short"]["error"] == ("probe.at = [0.5]: dimension mismatch: must have 2 items "
                                     "(run.dimension = 2)")
    # two bad tables: the lower order's check speaks first ([ale] 40 before [probe] 45)
    assert out["ale_and_probe_bad"]["error"].startswith("ale.grid.cells = [10, 1, 1]: dimension mismatch")
    assert [h[0] for h in out["ale_and_probe_bad"]["seen"]] == ["normalise"]


def test_validating_a_case_imports_no_solver_kernel():
    """The fragments are light: load_case of an ALE and a Lagrangian case imports neither numba,
    h5py nor mpi4py, nor a solver or kernel module (only the expression compiler and the mesh sizes)."""
    code = textwrap.dedent(f"""
        import json, sys
        from orchestrator.case import load_case
        load_case({str(REPO / 'cases' / 'sod')!r})
        load_case({str(REPO / 'tests' / 'orchestrator' / 'valid_cases' / 'box3d')!r})
        print(json.dumps(sorted(m for m in sys.modules
                                if m.split('.')[0] in ('numba', 'h5py', 'mpi4py', 'solvers'))))
    """)
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=120)
    assert r.returncode == 0, r.stderr
    # (solvers.kernel_cache: the numba cache directory's name, hashlib and os only)
    # (solvers.contact.methods, solvers.lagrange.integrators: the names of the contact methods and of
    # the integrators, no kernel)
    assert json.loads(r.stdout) == ["solvers", "solvers.contact", "solvers.contact.methods", "solvers.expressions",
                                    "solvers.kernel_cache", "solvers.lagrange", "solvers.lagrange.integrators",
                                    "solvers.lagrange.mesh"]
