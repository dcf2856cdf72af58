"""Tests for orchestrator/view.py: off-screen PNGs from a small synthetic output."""

import numpy as np
import pytest

from orchestrator.output import write_index, write_mesh, write_step
from orchestrator.view import render, scalar_field
from solvers.lagrange.mesh import box_mesh, quarter_cylinder_mesh

pytest.importorskip("pyvista")
mpimg = pytest.importorskip("matplotlib.image")


def _synthetic(out, mesh, role="lagrange", n=2):
    write_mesh(out, role, mesh.cells, mesh.cell_type)
    x = mesh.points
    centres = x[mesh.cells].mean(axis=1)
    for i in range(n):
        vel = np.zeros((mesh.num_points, 3))
        vel[:, 0] = x[:, 0] * (i + 1)
        vel[:, 1] = x[:, 1] ** 2
        stress = np.zeros((mesh.num_cells, 6))
        stress[:, 0] = centres[:, 0]  # uniaxial xx varying in x
        write_step(out, role, i, 5 * i, 1e-4 * i, x, {"velocity": vel, "temperature": 300 + x[:, 0]},
                   {"stress": stress})
    write_index(out)


def _check_png(path, size):
    assert path.is_file() and path.stat().st_size > 0
    img = mpimg.imread(path)
    assert img.shape[:2] == (size[1], size[0])
    colours = np.unique(img[..., :3].reshape(-1, 3), axis=0)
    assert len(colours) > 20, f"{path.name} looks blank ({len(colours)} colours)"


def test_scalar_field():
    label, v = scalar_field("velocity", [[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    assert label == "velocity magnitude"
    np.testing.assert_allclose(v, [5.0, 1.0])
    label, v = scalar_field("stress", [[2.0, 0, 0, 0, 0, 0]])
    assert "von Mises" in label and v[0] == pytest.approx(2.0)
    assert scalar_field("T", [1.0, 2.0])[0] == "T"


def test_render_2d_all_fields_last_step(tmp_path):
    out = tmp_path / "out"
    _synthetic(out, box_mesh([0, 0], [2, 1], [16, 8]))
    size = (400, 300)
    paths = render(out, window_size=size)
    assert sorted(p.name for p in paths) == [
        "lagrange_stress_000001.png", "lagrange_temperature_000001.png",
        "lagrange_velocity_000001.png"]
    assert all(p.parent == out / "pictures" for p in paths)
    for p in paths:
        _check_png(p, size)


def test_render_3d_selected_steps(tmp_path):
    out = tmp_path / "out"
    _synthetic(out, quarter_cylinder_mesh(1.0, 2.0, 4, 4), n=3)
    size = (320, 240)
    paths = render(out, fields=["stress"], steps=("first", "2", "last"), role="lagrange",
                   window_size=size)
    assert [p.name for p in paths] == ["lagrange_stress_000000.png", "lagrange_stress_000002.png"]
    for p in paths:
        _check_png(p, size)
    with pytest.raises(ValueError):
        render(out, fields=["nope"], window_size=size)
    with pytest.raises(ValueError):
        render(out, steps=(7,), window_size=size)
    with pytest.raises(ValueError):
        render(out, steps=("middle",), window_size=size)
