"""The case handed to a job's processes (adapters/case_file.py): the launcher's normalised case dict
exactly (paths as Paths), read without the case loader or jsonschema, and refused once changed."""
from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import pytest

from adapters import case_file
from orchestrator.case import load_case
from tests.conftest import CASES, REPO

VALID = REPO / "tests" / "orchestrator" / "valid_cases"


def test_every_shipped_and_valid_case_arrives_as_the_launcher_checked_it(tmp_path):
    dirs = sorted(p.parent for p in CASES.glob("**/case.toml")) + sorted(p.parent for p in VALID.glob("*/case.toml"))
    assert len(dirs) >= 50
    for d in dirs:
        case = load_case(d)
        path, sha = case_file.write(case, tmp_path / d.name / ".run")
        back = case_file.read(path, sha)
        assert back == case, d
        assert isinstance(back["case_dir"], Path), d
    mesh = case_file.read(*case_file.write(load_case(VALID / "file3d"), tmp_path / "f"))
    assert mesh["lagrange"]["bodies"][0]["mesh"]["file"] == (VALID / "file3d" / "column.msh").resolve()


def test_a_process_reads_it_without_the_case_loader(tmp_path):
    """The ranks' and the coupler's start: no orchestrator.case, no TOML parse, no jsonschema."""
    path, sha = case_file.write(load_case(VALID / "box3d"), tmp_path)
    probe = ("import sys; from adapters import case_file; "
             f"c = case_file.read({str(path)!r}, {sha!r}); "
             "print(c['name'], sorted(m for m in ('orchestrator.case', 'jsonschema', 'tomllib') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert r.returncode == 0 and r.stdout.split() == ["box3d", "[]"], r.stdout + r.stderr


def test_a_changed_or_missing_file_is_refused_in_one_line(tmp_path):
    path, sha = case_file.write(load_case(VALID / "box3d"), tmp_path)
    path.write_bytes(path.read_bytes().replace(b'"box3d"', b'"box3e"'))
    with pytest.raises(case_file.CaseFileError) as e:
        case_file.read(path, sha)
    assert "changed since the run was launched" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(case_file.CaseFileError, match="cannot be read"):
        case_file.read(tmp_path / "none.json", sha)
    (tmp_path / "list.json").write_bytes(b"[]")
    with pytest.raises(case_file.CaseFileError, match="not a case"):
        case_file.read(tmp_path / "list.json", hashlib.sha256(b"[]").hexdigest())
