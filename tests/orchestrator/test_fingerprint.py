"""The case fingerprint: the same for the same case wherever it lives and however far it runs; another
for any change of physics, mesh (also a mesh file's bytes) or numerics."""
from __future__ import annotations

import shutil

import pytest

from orchestrator.case import load_case
from orchestrator.fingerprint import case_fingerprint, case_identity, first_difference
from tests.conftest import CASES


def _variant(tmp_path, name, src="elastic_bar_wave", **replace):
    return load_case(_variant_dir(tmp_path, name, src, **replace))


def _variant_dir(tmp_path, name, src="elastic_bar_wave", **replace):
    case = tmp_path / name
    shutil.copytree(CASES / src, case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    for a, b in replace.items():
        assert a in text, a
        text = text.replace(a, b)
    (case / "case.toml").write_text(text)
    return case


@pytest.mark.parametrize("replace", [
    {},  # the same case in another directory under another name
    {"end_time = 16.0e-6": "end_time = 32.0e-6"},
    {"output_interval = 1.0e-6": "output_interval = 2.0e-6\ncheckpoint_interval = 4e-6\nmax_steps = 7\n"
                                 "diagnostics_every = 3"},
    {"[lagrange.bodies]]": "ranks]\nlagrange = 2\n\n[[lagrange.bodies]]"},
    {"tolerance = 3.0e-4 }": "tolerance = 0.5 }"},
])
def test_same_case(tmp_path, replace):
    base = load_case(CASES / "elastic_bar_wave")
    other = _variant(tmp_path, "elsewhere", **replace)
    assert case_fingerprint(other) == case_fingerprint(base)


@pytest.mark.parametrize("replace, key", [
    ({"density = 8000.0": "density = 8000.000001"}, "materials.steel.density"),
    ({"cells = [400, 1, 1]": "cells = [400, 1, 2]"}, "lagrange.bodies[0].mesh.box.cells[2]"),
    ({"velocity = { x = 1.0 }": "velocity = { x = 1.5 }"}, "boundaries[0].velocity.x"),
    ({"end_time = 16.0e-6": "end_time = 16.0e-6\ndt_scale = 0.8"}, "run.dt_scale"),
    ({'region = "x < 1e-9"': 'region = "x < 2e-9"'}, "boundaries[0].region"),
])
def test_another_case(tmp_path, replace, key):
    base = load_case(CASES / "elastic_bar_wave")
    other = _variant(tmp_path, "other", **replace)
    assert case_fingerprint(other) != case_fingerprint(base)
    assert first_difference(case_identity(base), case_identity(other))[0] == key


def test_mesh_file_bytes(tmp_path):
    """A mesh file counts by its bytes, not by its name or place."""
    import meshio
    import numpy as np

    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                   dtype=float) * 0.01

    def case_with(name, mesh_name, points):
        d = _variant_dir(tmp_path, name, **{
            "mesh = { box = { lower = [0.0, 0.0, 0.0], upper = [0.1, 0.0025, 0.0025], cells = [400, 1, 1] } }":
                f'mesh = {{ file = "{mesh_name}" }}'})
        meshio.write(d / mesh_name, meshio.Mesh(points, [("hexahedron", np.arange(8)[None])]))
        return load_case(d)

    a = case_with("a", "m.vtu", pts)
    b = case_with("b", "renamed.vtu", pts)
    c = case_with("c", "m.vtu", pts * 1.001)
    assert case_fingerprint(a) == case_fingerprint(b) != case_fingerprint(c)
    assert first_difference(case_identity(a), case_identity(c))[0] == "lagrange.bodies[0].mesh.file.file_sha256"


def test_ale_case(tmp_path):
    base = load_case(CASES / "sod")
    assert case_fingerprint(_variant(tmp_path, "s1", src="sod")) == case_fingerprint(base)
    other = _variant(tmp_path, "s2", src="sod", **{"gamma = 1.4": "gamma = 1.41"})
    assert first_difference(case_identity(base), case_identity(other))[0] == "ale.materials.gas.gamma"
