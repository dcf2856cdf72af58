"""Probes of point sets (solvers/probes.py): the reductions over a set fixed at the start, over the
ranks of a group (the same test serially and under `mpiexec -n 2`), and a probe's history through a
real run (adapters/runtime.py appends it to the solver's diagnostics)."""
from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from solvers.probes import PointProbes
from tests.conftest import immerse
from tests.orchestrator.case_texts import SOD_2D


def _specs(**over):
    base = {"role": "sph", "quantity": "displacement", "component": "x", "reduce": "mean",
            "box": {"lower": [0.5, -1.0], "upper": [1.0, 1.0]}}
    return {name: {**base, **o} for name, o in over.items()}


@pytest.mark.mpi
def test_reductions_over_the_set_and_the_ranks():
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(3)
    X = rng.uniform(0.0, 1.0, (40, 2))          # the same points on every rank, split among them
    x = X + rng.normal(0.0, 0.1, X.shape)
    v = rng.normal(0.0, 1.0, X.shape)
    mine = np.arange(40) % comm.size == comm.rank
    probes = PointProbes(_specs(mean={}, top={"reduce": "max"}, low={"reduce": "min", "quantity": "velocity"},
                                speed={"quantity": "velocity", "component": "magnitude", "reduce": "max"},
                                y={"quantity": "position", "component": "y"},
                                other={"role": "lagrange"}), "sph", comm)
    assert probes.names == ["probe_mean", "probe_top", "probe_low", "probe_speed", "probe_y"]
    got = probes.values(X[mine], x[mine], v[mine])
    inside = X[:, 0] >= 0.5
    assert got["probe_mean"] == pytest.approx(np.mean(x[inside, 0] - X[inside, 0]), rel=1e-13)
    assert got["probe_top"] == np.max(x[inside, 0] - X[inside, 0])
    assert got["probe_low"] == np.min(v[inside, 0])
    assert got["probe_speed"] == np.max(np.linalg.norm(v[inside], axis=1))
    assert got["probe_y"] == pytest.approx(np.mean(x[inside, 1]), rel=1e-13)


@pytest.mark.mpi
def test_an_empty_box_is_named():
    comm = MPI.COMM_WORLD
    X = np.zeros((4, 2)) + 0.1 * comm.rank
    probes = PointProbes(_specs(far={"box": {"lower": [5.0, 5.0], "upper": [6.0, 6.0]}}), "sph", comm)
    with pytest.raises(ValueError, match=r"probes.far.box = .*holds no sph point at the start"):
        probes.check_sets(X, "sph")
    PointProbes(_specs(near={}), "sph", comm).check_sets(X + 0.6, "sph")  # holds points: no error


CASE = """\
[run]
dimension = 2
end_time = 2e-5
output_interval = 2e-5

[materials.steel]
model = "linear_elastic"
density = 7850
youngs_modulus = 210e9
poisson_ratio = 0.3

[[lagrange.bodies]]
name = "plate"
material = "steel"
mesh = { box = { lower = [0, 0], upper = [0.1, 0.02], cells = [5, 1] } }
initial_velocity = [10.0, -4.0]

[probes]
end_x = { role = "lagrange", quantity = "displacement", component = "x", box = { lower = [0.1, 0.0], upper = [0.1, 0.02] } }
speed = { role = "lagrange", quantity = "velocity", component = "magnitude", reduce = "max", box = { lower = [0.0, 0.0], upper = [0.1, 0.02] } }
"""


@pytest.mark.slow
def test_a_lagrange_probe_records_every_step(tmp_path):
    """A plate in free flight at (10, -4) m/s: its end moves 10 t along x (round-off) at every
    diagnostics step, not only at the one output."""
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "case.toml").write_text(CASE)
    r = immerse("run", tmp_path / "case", "--out", tmp_path / "out", timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    with h5py.File(tmp_path / "out" / "diagnostics.h5") as h:
        t, u, s = h["time"][()], h["lagrange.probe_end_x"][()], h["lagrange.probe_speed"][()]
    assert len(t) > 10                       # every step, against 2 output steps
    assert np.max(np.abs(u - 10.0 * t)) < 1e-12 * 10.0 * t[-1]
    assert np.max(np.abs(s - np.hypot(10.0, 4.0))) < 1e-12


# Sod (tests/orchestrator/case_texts.py) on two rows of zones, 0.01 m each, outputs every 0.05 s
SOD_PROBED = (SOD_2D.replace("end_time = 0.2\n", "end_time = 0.2\noutput_interval = 0.05\n")
              .replace("upper = [1.0, 0.01], cells = [100, 1]", "upper = [1.0, 0.02], cells = [100, 2]") + """
[probes]
p_star = { role = "ale", quantity = "pressure", point = [0.6, 0.005] }
u_star = { role = "ale", quantity = "velocity", component = "x", point = [0.6, 0.015] }
rho_left = { role = "ale", quantity = "density", point = [0.0, 0.0] }
""")
assert "cells = [100, 2]" in SOD_PROBED and "output_interval = 0.05" in SOD_PROBED


def test_background_probes_read_the_zone_at_their_point_on_any_rank_count(tmp_path):
    """Sod on 100 x 2 zones with probes at points: p at (0.6, 0.005) is zone (60, 0)'s pressure, u at
    (0.6, 0.015) the mean x velocity of zone (60, 1)'s four nodes, rho at the grid's corner zone
    (0, 0)'s: equal to the output steps' values at every output, and the same on 2 ALE ranks (a
    point's zone on the other rank: summed from its owner); at 0.2 s the probe sits between the
    contact (0.685) and the rarefaction's tail (0.486): p* = 0.30313 (measured 0.30294, 6.3e-4 off; u 0.92806
    against u* = 0.92745)."""
    from orchestrator import output

    case = tmp_path / "case"
    case.mkdir()
    (case / "case.toml").write_text(SOD_PROBED)
    rows = {}
    for ranks in (1, 2):
        out = tmp_path / f"out{ranks}"
        r = immerse("run", case, "--out", out, "--ranks", f"ale={ranks}")
        assert r.returncode == 0, r.stderr
        rows[ranks] = np.loadtxt(out / "probes.csv", delimiter=",", skiprows=1)
        head = (out / "probes.csv").read_text().splitlines()[0]
        assert head == "time,step,ale.p_star,ale.u_star,ale.rho_left"
    out = tmp_path / "out1"
    for t, step, i in output.read_steps(out, "ale"):
        pts, pd, cd = output.read_step(out, "ale", i)
        row = rows[1][rows[1][:, 1] == step][0]
        assert row[2] == cd["pressure"][60] and row[4] == cd["density"][0]
        nodes = [60, 61, 60 + 101, 61 + 101]          # zone (60, 0)'s nodes: x fastest, 101 a row
        assert row[3] == pytest.approx(pd["velocity"][[n + 101 for n in nodes], 0].mean(), rel=1e-14, abs=1e-15)
    np.testing.assert_allclose(rows[2], rows[1], rtol=1e-12, atol=1e-14)
    assert rows[1][-1, 2] == pytest.approx(0.30313, rel=1e-3)


@pytest.mark.parametrize("probe, key, fragment", [
    ('{ role = "ale", quantity = "pressure", point = [1.5, 0.01] }', "probes.x.point", "must lie in the grid"),
    ('{ role = "ale", quantity = "displacement", point = [0.5, 0.01] }', "probes.x.quantity", "allowed for role = 'ale'"),
    ('{ role = "ale", quantity = "velocity", point = [0.5, 0.01] }', "probes.x.component", "allowed for the velocity"),
    ('{ role = "ale", quantity = "pressure", component = "x", point = [0.5, 0.01] }', "probes.x.component", "a scalar"),
    ('{ role = "ale", quantity = "pressure", line = { start = [0.0, 0.01], end = [1.2, 0.01], points = 3 } }',
     "probes.x.line.end", "must lie in the grid"),
    ('{ role = "ale", quantity = "pressure", point = [0.5, 0.01], line = { start = [0.0, 0.01], end = [1.0, 0.01], '
     'points = 3 } }', "probes.x.line", "at a point or along a line"),
    ('{ role = "ale", quantity = "pressure", line = { start = [0.0, 0.01], end = [1.0, 0.01], points = 1 } }',
     "probes.x.line.points", ">= 2"),
])
def test_bad_background_probes_are_refused_in_one_line(tmp_path, probe, key, fragment):
    case = tmp_path / "case"
    case.mkdir()
    text = SOD_PROBED.split("[probes]")[0] + f"[probes]\nx = {probe}\n"
    (case / "case.toml").write_text(text)
    r = immerse("check", case)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and key in r.stderr and fragment in r.stderr, r.stderr


def test_a_line_of_background_probes_is_a_history_per_point(tmp_path):
    """line = { start, end, points = 5 } along the Sod tube: five histories probe_gauge_0..4, each
    the zone at its point (x = 0.105, 0.3025, 0.5, 0.6975, 0.895), as a point probe there reads;
    `immerse plot OUT gauge` draws the five."""
    case = tmp_path / "case"
    case.mkdir()
    text = SOD_PROBED.split("[probes]")[0] + """[probes]
gauge = { role = "ale", quantity = "pressure", line = { start = [0.105, 0.005], end = [0.895, 0.005], points = 5 } }
third = { role = "ale", quantity = "pressure", point = [0.6975, 0.005] }
"""
    (case / "case.toml").write_text(text)
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out)
    assert r.returncode == 0, r.stderr
    head = (out / "probes.csv").read_text().splitlines()[0]
    assert head == "time,step,ale.gauge_0,ale.gauge_1,ale.gauge_2,ale.gauge_3,ale.gauge_4,ale.third"
    rows = np.loadtxt(out / "probes.csv", delimiter=",", skiprows=1)
    assert np.array_equal(rows[:, 5], rows[:, 7])          # gauge_3 is the point probe's zone
    # (the ends undisturbed: measured 1 - 5.8e-15 and 0.1 + 2.1e-8, the shock at 0.85 m, its smear ahead)
    assert rows[-1, 2] == pytest.approx(1.0, rel=1e-13) and rows[-1, 6] == pytest.approx(0.1, rel=1e-6)
    r = immerse("plot", out, "gauge", "--csv")
    assert r.returncode == 0, r.stderr
    plotted = (out / "plots").glob("*.csv")
    assert [p.read_text().splitlines()[0] for p in plotted] == [
        "time (s)," + ",".join(f"ale.probe_gauge_{k} (Pa)" for k in range(5))]


def test_a_line_alone_is_a_background_probe():
    """A role whose only probe is a line reads the background's fields (FieldProbes), one history per
    point, the points evenly spaced with both ends."""
    from solvers.probes import FieldProbes, probes_for

    spec = {"g": {"role": "ale", "quantity": "pressure", "component": None, "reduce": "mean",
                  "line": {"start": [0.0, 0.5], "end": [1.0, 0.5], "points": 3}}}
    p = probes_for(spec, "ale", MPI.COMM_SELF)
    assert isinstance(p, FieldProbes) and p.names == ["probe_g_0", "probe_g_1", "probe_g_2"]
    np.testing.assert_array_equal(np.array(p.points), [[0.0, 0.5], [0.5, 0.5], [1.0, 0.5]])
