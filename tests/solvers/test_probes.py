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
