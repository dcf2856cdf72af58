"""Tests for orchestrator/view.py: off-screen PNGs from small synthetic outputs; 1-D runs as line
plots against the exact solution; units in the labels; bad requests refused through the CLI with
one line (exit 2) and nothing written; nothing from VTK on stderr."""

import json
from pathlib import Path

import numpy as np
import pytest

from orchestrator.output import write_index, write_mesh, write_step
from orchestrator.units import unit_of, with_unit
from orchestrator.view import ViewError, line_figure, line_profile, one_d_axis, render, scalar_field
from solvers.ale.exact.riemann import RiemannSolution
from solvers.lagrange.mesh import box_mesh, quarter_cylinder_mesh
from tests.conftest import CASES, immerse
from tests.orchestrator.case_texts import SOD_2D

pytest.importorskip("pyvista")
mpimg = pytest.importorskip("matplotlib.image")
Image = pytest.importorskip("PIL.Image")


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
    # a full 3x3 tensor gives the same equivalent: uniaxial 2 plus a hydrostatic part
    label, v = scalar_field("stress", [[5.0, 0, 0, 0, 3.0, 0, 0, 0, 3.0]])
    assert "von Mises" in label and v[0] == pytest.approx(2.0)
    assert scalar_field("T", [1.0, 2.0])[0] == "T"


def test_units_table():
    assert with_unit("density", "density") == "density (kg/m^3)"
    assert with_unit("pressure", "pressure") == "pressure (Pa)"
    assert with_unit("velocity x", "velocity") == "velocity x (m/s)"
    assert with_unit("stress, von Mises", "stress") == "stress, von Mises (Pa)"
    assert with_unit("specific_internal_energy", "specific_internal_energy") == "specific_internal_energy (J/kg)"
    assert with_unit("temperature", "temperature") == "temperature (K)"
    assert with_unit("plastic_strain", "plastic_strain") == "plastic_strain (-)"
    assert unit_of("density_water") == "kg/m^3" and unit_of("volume_fraction_air") == "1"
    assert with_unit("mystery", "mystery") == "mystery"  # no unit rather than a guessed one


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
        assert "Software" not in Image.open(p).info  # a VTK rendering


def test_render_3d_selected_steps(tmp_path):
    out = tmp_path / "out"
    _synthetic(out, quarter_cylinder_mesh(1.0, 2.0, 4, 4), n=3)
    size = (320, 240)
    paths = render(out, fields=["stress"], steps=("first", "2", "last"), role="lagrange",
                   window_size=size)
    assert [p.name for p in paths] == ["lagrange_stress_000000.png", "lagrange_stress_000002.png"]
    for p in paths:
        _check_png(p, size)


@pytest.mark.parametrize("request_kw, fragment", [
    ({"fields": ["nope"]}, "--field nope: not in this output; fields: lagrange: temperature, velocity, stress"),
    ({"fields": ["stress", "nope"]}, "--field nope"),
    ({"steps": (7,)}, "--step 7: no output step with that index in lagrange; steps: lagrange: 0-2"),
    ({"steps": ("middle",)}, "--step 'middle': must be first, last, all or an output index"),
    ({"role": "ale"}, "role 'ale': no output of that role; roles: lagrange"),
])
def test_bad_requests_are_refused_before_drawing(tmp_path, request_kw, fragment):
    out = tmp_path / "out"
    _synthetic(out, quarter_cylinder_mesh(1.0, 2.0, 4, 4), n=3)
    with pytest.raises(ViewError) as e:
        render(out, window_size=(320, 240), **request_kw)
    assert fragment in str(e.value) and "\n" not in str(e.value)
    assert not (out / "pictures").exists()


# ------------------------------------------------------------------------------------------ 1-D
SOD = dict(left=(1.0, 0.0, 1.0), right=(0.125, 0.0, 0.1), gamma_l=1.4)
SOD_CASE = SOD_2D + """
[check]
kind = "riemann"
params = { axis = "x", x0 = 0.5, left = [1.0, 0.0, 1.0], right = [0.125, 0.0, 0.1], gamma_left = 1.4 }
metrics.p_star = { reference = 0.30313, tolerance = 0.02 }
"""


def _sod_output(tmp_path, nx=100, times=(0.0, 0.1, 0.2)):
    """A 1-D (nx x 1 zones) ALE output holding the exact Sod solution sampled at zone centres (and
    at the nodes for the velocity), with a summary.json naming its case, as `immerse run` leaves it."""
    case = tmp_path / "case"
    case.mkdir()
    (case / "case.toml").write_text(SOD_CASE)
    out = tmp_path / "out"
    mesh = box_mesh([0.0, 0.0], [1.0, 0.01], [nx, 1])
    write_mesh(out, "ale", mesh.cells, mesh.cell_type)
    ex = RiemannSolution(**SOD)
    xc = mesh.points[mesh.cells].mean(axis=1)[:, 0]
    for i, t in enumerate(times):
        rho, _, p, e = ex.sample(xc, t, 0.5)
        u = ex.sample(mesh.points[:, 0], t, 0.5)[1]
        vel = np.zeros((mesh.num_points, 3))
        vel[:, 0] = u
        write_step(out, "ale", i, 10 * i, t, mesh.points, {"velocity": vel},
                   {"density": rho, "pressure": p, "specific_internal_energy": e})
    write_index(out)
    (out / "summary.json").write_text(json.dumps({"case": "sod", "case_dir": str(case)}))
    return out, ex


def test_one_d_axis():
    assert one_d_axis(*_pc(box_mesh([0, 0], [1, 0.01], [50, 1]))) == 0
    assert one_d_axis(*_pc(box_mesh([0, 0, 0], [0.01, 0.01, 1], [1, 1, 30]))) == 2
    assert one_d_axis(*_pc(box_mesh([0, 0], [1, 1], [50, 2]))) is None
    assert one_d_axis(*_pc(quarter_cylinder_mesh(1.0, 2.0, 4, 4))) is None


def _pc(mesh):
    p = np.zeros((mesh.num_points, 3))
    p[:, : mesh.points.shape[1]] = mesh.points
    return p, mesh.cells


def test_one_d_run_is_a_line_plot_against_the_exact_solution(tmp_path):
    out, ex = _sod_output(tmp_path)
    size = (800, 500)
    paths = render(out, fields=["density", "velocity"], steps="last", window_size=size)
    assert [p.name for p in paths] == ["ale_density_000002.png", "ale_velocity_000002.png"]
    for p in paths:  # a full-size matplotlib chart, not a one-pixel strip rendered by VTK
        _check_png(p, size)
        assert Image.open(p).info.get("Software", "").startswith("Matplotlib")
    prof = line_profile(out, "ale", "density", 2, axis=0, case=_case(tmp_path))
    assert prof.time == 0.2 and len(prof.x) == 100
    np.testing.assert_allclose(prof.x, np.linspace(0.005, 0.995, 100), rtol=1e-12)
    assert prof.exact_x is not None and len(prof.exact_x) > 1000
    np.testing.assert_allclose(prof.exact_values, ex.sample(prof.exact_x, 0.2, 0.5)[0])
    fig = line_figure(prof, size)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "density (kg/m^3)"
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert set(lines) == {"exact (Riemann)", "ale (100 stations)"}
    np.testing.assert_array_equal(lines["exact (Riemann)"].get_xdata(), prof.exact_x)
    np.testing.assert_array_equal(lines["ale (100 stations)"].get_ydata(), prof.values)
    assert tuple(fig.get_size_inches() * fig.dpi) == size
    # nodes: the velocity along the axis, the two nodes of each station averaged
    v = line_profile(out, "ale", "velocity", 2, axis=0, case=_case(tmp_path))
    assert v.ylabel == "velocity x (m/s)" and len(v.x) == 101
    np.testing.assert_allclose(v.values, ex.sample(np.linspace(0, 1, 101), 0.2, 0.5)[1], atol=1e-12)


def _case(tmp_path):
    from orchestrator.case import load_case

    return load_case(tmp_path / "case")


def test_one_d_without_a_known_case_has_no_exact_curve(tmp_path):
    out, _ = _sod_output(tmp_path)
    (out / "summary.json").unlink()  # e.g. viewed while running
    paths = render(out, fields=["pressure"], window_size=(400, 300))
    assert len(paths) == 1
    prof = line_profile(out, "ale", "pressure", 2, axis=0, case=None)
    assert prof.exact_x is None and prof.ylabel == "pressure (Pa)"


# ------------------------------------------------------------------------------------------ CLI
def test_cli_view_is_quiet_on_success(tmp_path):
    """stdout lists the pictures; stderr stays empty (VTK's "bad X server connection" and other
    chatter must not reach the user), for a 3-D rendering and for a 1-D line plot."""
    out3 = tmp_path / "three"
    _synthetic(out3, quarter_cylinder_mesh(1.0, 2.0, 4, 4))
    r = immerse("view", out3, "--field", "stress", "velocity")
    assert r.returncode == 0 and r.stderr == ""
    assert [ln.rsplit("/", 1)[1] for ln in r.stdout.split()] == [
        "lagrange_stress_000001.png", "lagrange_velocity_000001.png"]
    out1, _ = _sod_output(tmp_path)
    r = immerse("view", out1, "--field", "density", "--step", "all")
    assert r.returncode == 0 and r.stderr == ""
    assert len(r.stdout.split()) == 3


@pytest.mark.parametrize("args, fragment", [
    (["--field", "nope"], "--field nope: not in this output; fields: ale: velocity, density, pressure, "
                          "specific_internal_energy"),
    (["--step", "9"], "--step 9: no output step with that index in ale; steps: ale: 0-2 (or first, last, all)"),
    (["--step", "middle"], "--step 'middle': must be first, last, all or an output index"),
])
def test_cli_view_unknown_field_or_step(tmp_path, args, fragment):
    out, _ = _sod_output(tmp_path)
    r = immerse("view", out, *args)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and fragment in r.stderr, r.stderr
    assert r.stdout == "" and not (out / "pictures").exists()


def test_view_owns_its_pictures_and_never_overwrites_a_users_file(tmp_path):
    """Pictures of `immerse view` are recorded as immerse's (orchestrator/outdir.py): drawn again
    freely, removed by `run --replace`; a user's file at a picture's path refuses the request
    (one line, exit 2) and stays as it was, also through --replace."""
    from tests.conftest import CASES

    out = tmp_path / "out"
    assert immerse("run", CASES / "sod", "--out", out).returncode in (0, 1)
    r = immerse("view", out, "--field", "density")
    assert r.returncode == 0, r.stderr
    (mine,) = [Path(p) for p in r.stdout.split()]
    assert immerse("view", out, "--field", "density").returncode == 0  # its own: drawn again
    users = mine.with_name(mine.name.replace("density", "pressure"))
    users.write_bytes(b"my picture")
    r = immerse("view", out, "--field", "pressure")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "did not write" in r.stderr, r.stderr
    assert users.read_bytes() == b"my picture"
    r = immerse("run", CASES / "sod", "--out", out, "--replace")
    assert r.returncode in (0, 1), r.stderr
    assert not mine.exists() and users.read_bytes() == b"my picture"


# ------------------------------------------------------------------ ranges, movies, framing
def _clims(monkeypatch):
    """Record the colour range each picture is drawn with (and still draw it)."""
    import orchestrator.view as view

    seen, real = [], view._render_pyvista

    def record(*a, **kw):
        seen.append((a[2].name, a[-1]))
        return real(*a, **kw)

    monkeypatch.setattr(view, "_render_pyvista", record)
    return seen


def test_all_steps_share_one_colour_range_and_animate(tmp_path, monkeypatch):
    """--step all: one colour range over the steps drawn (the temperature 300 + x is the same at both
    steps; the velocity magnitude grows with the step: its range is the union), and --movie writes a
    GIF of the frames; --range step gives each its own."""
    out = tmp_path / "out"
    mesh = box_mesh([0, 0], [2, 1], [8, 4])
    _synthetic(out, mesh, n=3)
    seen = _clims(monkeypatch)
    paths = render(out, fields=["velocity"], steps=("all",), window_size=(320, 240), animate=True)
    speeds = [np.hypot(mesh.points[:, 0] * (i + 1), mesh.points[:, 1] ** 2) for i in range(3)]
    assert [c for _, c in seen] == [(min(v.min() for v in speeds), max(v.max() for v in speeds))] * 3
    gif = out / "pictures" / "lagrange_velocity.gif"
    assert paths[-1] == gif and Image.open(gif).n_frames == 3
    seen.clear()
    import shutil

    shutil.rmtree(out / "pictures")   # (a synthetic output: not immerse's own, its pictures are not rewritten)
    render(out, fields=["velocity"], steps=("all",), window_size=(320, 240), value_range="step")
    assert [c for _, c in seen] == [None] * 3


def test_line_plots_of_all_steps_share_one_value_range(tmp_path):
    import orchestrator.view as view

    out, _ = _sod_output(tmp_path)
    paths = render(out, fields=["density"], steps=("all",), window_size=(400, 300))
    assert len(paths) == 3
    prof = line_profile(out, "ale", "density", 0, axis=0, case=_case(tmp_path))
    lo, hi = view._span([view.line_profile(out, "ale", "density", i, 0).values for _, _, i in view.read_steps(out, "ale")],
                        0.05)
    assert (lo, hi) == pytest.approx((0.125 - 0.04375, 1.0 + 0.04375)) and prof.values.max() == 1.0
    assert line_figure(prof, (400, 300), (lo, hi)).axes[0].get_ylim() == (lo, hi)


def _coloured_box(png):
    """Rows and columns (fractions of the picture, from its top-left) of the coloured pixels above
    the colour bar's band: the domain as drawn."""
    img = np.asarray(Image.open(png).convert("RGB"), dtype=float) / 255.0
    h = img.shape[0]
    sat = img.max(axis=2) - img.min(axis=2)     # viridis is saturated; white, black, grey are not
    rows, cols = np.nonzero(sat[: int(0.80 * h)] > 0.15)
    return rows.min() / h, rows.max() / h, cols.min() / img.shape[1], cols.max() / img.shape[1]


@pytest.mark.parametrize("upper, fills", [([1.6, 0.1], "width"), ([0.03, 0.3], "height"), ([1.0, 0.75], "height")])
def test_a_planar_domain_fills_its_picture_clear_of_the_colour_bar(tmp_path, upper, fills):
    """A long tube, a slender plate and a squarish box each fill the picture's frame (orchestrator/
    view.py FRAME) in the direction that limits them: at least 75 % of the width or 55 % of the
    height (the rest: title, axis labels, colour bar), and end above the colour bar's band (the
    bar's top at 88 % of the height)."""
    out = tmp_path / "out"
    _synthetic(out, box_mesh([0, 0], upper, [16, 4]), n=1)
    png = render(out, fields=["temperature"], window_size=(1024, 768))[0]
    top, bottom, left, right = _coloured_box(png)
    if fills in ("width", "both"):
        assert right - left > 0.75, (left, right)
    if fills in ("height", "both"):
        assert bottom - top > 0.55, (top, bottom)
    assert bottom < 0.80 and top > 0.10, (top, bottom)


def test_a_one_d_particle_run_is_a_line_plot_against_the_exact_solution(tmp_path):
    """Particles in a tube (two rows along x, as cases/sph_shock_tube's) whose case checks the SPH
    role's profile against Riemann's: drawn as a line plot (the particles starting at one x are one
    station) with the exact solution, not as a cloud of dots."""
    from orchestrator.case import load_case
    from orchestrator.exact_profiles import riemann_solution

    case = load_case(CASES / "sph_shock_tube")
    ex = riemann_solution(case["check"]["params"])
    out = tmp_path / "out"
    x = np.repeat(np.linspace(-0.5, 0.5, 101), 2)
    pts = np.zeros((x.size, 3))
    pts[:, 0], pts[:, 1] = x, np.tile([0.005, 0.015], 101)
    write_mesh(out, "sph", np.arange(x.size)[:, None], "vertex")
    for i, t in enumerate((0.0, 0.2)):
        rho = ex.sample(x, t, 0.0)[0]
        write_step(out, "sph", i, 10 * i, t, pts, {"density": rho}, {})
    write_index(out)
    (out / "summary.json").write_text(json.dumps({"case": "sph_shock_tube", "case_dir": str(CASES / "sph_shock_tube")}))
    paths = render(out, fields=["density"], steps="last", window_size=(640, 480))
    assert [p.name for p in paths] == ["sph_density_000001.png"]
    assert Image.open(paths[0]).info.get("Software", "").startswith("Matplotlib")
    prof = line_profile(out, "sph", "density", 1, axis=0, case=case)
    assert len(prof.x) == 101 and prof.exact_x is not None
    np.testing.assert_allclose(prof.values, ex.sample(prof.x, 0.2, 0.0)[0])


def test_cli_view_list_names_fields_with_units_and_steps(tmp_path):
    out = tmp_path / "out"
    _synthetic(out, box_mesh([0, 0], [2, 1], [4, 2]), n=2)
    r = immerse("view", out, "--list")
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout.splitlines() == ["lagrange: fields temperature (K), velocity (m/s), stress (Pa)",
                                     "lagrange: steps (index: step, time) 0: 0, 0 s, 1: 5, 0.0001 s"]
    assert not (out / "pictures").exists()


def test_a_uniform_field_says_so_in_its_title(tmp_path, monkeypatch):
    """A field the same everywhere at a step (bars_impact's contact pressure after the contact) is
    drawn with a title that says so: a blank picture is not a failed one."""
    import orchestrator.view as view

    titles, real = [], view._render_pyvista

    def record(*a, **kw):
        out = real(*a, **kw)
        titles.append(a[8])
        return out

    monkeypatch.setattr(view, "_render_pyvista", record)
    out = tmp_path / "out"
    mesh = box_mesh([0, 0], [2, 1], [4, 2])
    write_mesh(out, "lagrange", mesh.cells, mesh.cell_type)
    write_step(out, "lagrange", 0, 0, 0.0, mesh.points, {"contact_pressure": np.zeros(mesh.num_points)}, {})
    write_index(out)
    render(out, window_size=(320, 240))
    assert titles == ["lagrange: contact_pressure (uniform: 0 at this step)\nt = 0 s (step 0)"], titles


def test_cli_view_bad_range_is_one_line(tmp_path):
    out = tmp_path / "out"
    _synthetic(out, box_mesh([0, 0], [2, 1], [4, 2]), n=1)
    r = immerse("view", out, "--range", "global")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--range" in r.stderr and "'fixed', 'step'" in r.stderr
    assert not (out / "pictures").exists()
