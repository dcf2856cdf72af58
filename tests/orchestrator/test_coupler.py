"""The coupler's time loop and summary: outputs and checkpoints at the first step that reaches their
times (they never clip a step), the end landed on exactly, and summary.json reports one mass-balance
figure, the solvers' own."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from orchestrator.run_record import conservation_residuals
from tests.conftest import immerse

# a shock tube moving through open ends (outflow at both faces): mass leaves and enters, so
# "mass now / mass at start - 1" (about 5e-2 here) is not a balance; the solver's mass balance
# (what crossed the faces accounted for) is round-off
CASE = """
[run]
dimension = 2
end_time = 0.1
output_interval = 0.03      # not a divisor of end_time: outputs at 0, 0.03, 0.06, 0.09, 0.1
checkpoint_interval = 0.04  # checkpoints at 0.04, 0.08

[ale]
mode = "eulerian"
grid = { lower = [0.0, 0.0], upper = [1.0, 0.01], cells = [100, 1] }
boundaries = { x_lower = "outflow", x_upper = "outflow", y_lower = "wall", y_upper = "wall" }
materials.gas = { eos = "ideal_gas", gamma = 1.4 }
regions = [
  { material = "gas", density = 1.0, pressure = 1.0, velocity = [0.5, 0.0] },
  { material = "gas", region = "x > 0.5", density = 0.125, pressure = 0.1, velocity = [0.5, 0.0] },
]

[check]
kind = "riemann"
params = { axis = "x", x0 = 0.5, left = [1.0, 0.5, 1.0], right = [0.125, 0.5, 0.1], gamma_left = 1.4 }
metrics.mass_balance_rel = { reference = 0.0, tolerance = 1e-12 }
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("coupler")
    (tmp / "case").mkdir()
    (tmp / "case" / "case.toml").write_text(CASE)
    out = tmp / "out"
    r = immerse("run", tmp / "case", "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    return out, json.loads((out / "summary.json").read_text())


def first_steps_at(due, step_times):
    """The time of the first step that reaches each due time (within round-off)."""
    step_times = np.asarray(step_times)
    return np.array([step_times[np.flatnonzero(step_times >= d * (1 - 1e-12))[0]] for d in due])


def test_outputs_at_the_first_step_reaching_each_multiple_of_the_interval(run):
    """Outputs at 0, then at the first step at or after 0.03, 0.06, 0.09, and at the end, stamped
    with that step's own time; the end landed on exactly."""
    out, s = run
    with h5py.File(out / "results.h5") as h:
        times = h["ale/times"][()]
    with h5py.File(out / "diagnostics.h5") as h:
        steps = h["time"][()]   # every step's time (diagnostics_every = 1)
    assert len(times) == 5
    np.testing.assert_array_equal(times, first_steps_at([0.0, 0.03, 0.06, 0.09, 0.1], steps))
    assert np.all(times[1:4] - [0.03, 0.06, 0.09] < s["dt"]["max"])
    assert times[-1] == 0.1 and s["end_time"] == 0.1


def test_checkpoints_at_the_first_step_reaching_each_multiple_of_the_interval(run):
    out, _ = run
    times = []
    for f in sorted((out / "checkpoints").glob("checkpoint_*.h5")):
        with h5py.File(f) as h:
            times.append(float(h.attrs["t"]))
    with h5py.File(out / "diagnostics.h5") as h:
        steps = h["time"][()]
    np.testing.assert_array_equal(times, first_steps_at([0.04, 0.08], steps))


def test_one_mass_balance_figure(run):
    """summary.conservation.mass_rel = max |ale.mass_balance_rel| of diagnostics.h5 = the check's
    mass_balance_rel; the naive mass drift of the open tube is far larger (it is not a balance)."""
    out, s = run
    with h5py.File(out / "diagnostics.h5") as h:
        balance = float(np.max(np.abs(h["ale.mass_balance_rel"][()])))
        mass = h["ale.mass"][()]
    drift = float(np.max(np.abs(mass / mass[0] - 1)))
    assert s["conservation"]["mass_rel"] == balance
    assert s["check"]["metrics"]["mass_balance_rel"]["value"] == balance
    assert balance < 1e-12  # measured 1e-16 .. 1e-15
    assert drift > 1e-2  # measured 5e-2: mass really crossed the open faces


def test_summary_records_start_up(run):
    _, s = run
    assert 0.0 < s["first_step_s"] < s["wall_time_s"] + 600  # present and positive


def test_summary_splits_the_time_loop(run):
    """Where the loop's time went: writing the 5 outputs and 2 checkpoints, and the ALE group's own
    step work (its waits for the coupler excluded; no engine of its own): each a part of the loop."""
    _, s = run
    wall = s["wall_time_s"]
    assert 0.0 < s["output_time_s"] < wall
    assert set(s["solver_time_s"]) == {"ale"} and 0.0 < s["solver_time_s"]["ale"] < wall
    assert s["engine_time_s"] == {}


def test_conservation_residuals_of_a_closed_body():
    """A solver without a mass balance diagnostic (Lagrangian bodies: their mass cannot cross the
    boundary): the same definition with nothing crossing, from the mass history; the largest figure
    over the roles."""
    hist = {
        "time": np.array([0.0, 1.0, 2.0]),
        "lagrange.mass": np.array([2.0, 2.0 * (1 + 3e-16), 2.0]),
        "lagrange.energy_balance_rel": np.array([0.0, -4e-15, 1e-15]),
        "ale.mass": np.array([1.0, 0.5, 0.25]),  # open faces: not a balance
        "ale.mass_balance_rel": np.array([0.0, 1e-16, -2e-16]),
        "ale.energy_balance_rel": np.array([0.0, 1e-14, 0.0]),
    }
    rel = conservation_residuals(hist, ["lagrange", "ale"])
    assert rel["mass_rel"] == pytest.approx(3e-16, rel=1e-3)
    assert rel["energy_rel"] == 1e-14


def test_a_collapsed_time_step_stops_the_run_naming_the_solver():
    """coupler.collapsed_step: a stable step below DT_COLLAPSE (1e-6) of the largest so far names the
    group that gave it (a penetrator's background fell to 3e-18 s against 2.7e-8 s and went on for
    thousands of steps at one time); just above it, or before the first step (dt_max 0), no stop."""
    from orchestrator.coupler import DT_COLLAPSE, collapsed_step

    why = collapsed_step({"ale": 3.04e-18, "lagrange": 2.0e-9}, 2.68e-8)
    assert why is not None and "the ale solver's stable step is 3.04e-18 s" in why and "2.68e-08 s" in why
    assert collapsed_step({"ale": 1.01 * DT_COLLAPSE * 2.68e-8, "lagrange": 2.0e-9}, 2.68e-8) is None
    assert collapsed_step({"ale": 0.99 * DT_COLLAPSE * 2.68e-8}, 2.68e-8) is not None
    assert collapsed_step({"ale": 1e-30}, 0.0) is None


def test_the_progress_note_and_summary_name_an_implicit_solvers_steps_and_iterations():
    """The coupler's log line carries each implicit group's last recorded step and Newton iterations
    (substeps when a step was split); summary.json's "implicit" their min / median / max and median /
    max over the records after the first."""
    from types import SimpleNamespace

    from orchestrator.coupler import Coupler

    names = ["kinetic_energy", "newton_iterations", "time_step", "substeps"]
    rows = [np.array([1.0, 0.0, 1e-3, 1.0]), np.array([1.0, 3.0, 1e-3, 1.0]), np.array([1.0, 9.0, 5e-4, 2.0])]
    c = SimpleNamespace(roles=["lagrange", "ale"], names={"lagrange": names, "ale": ["mass"]},
                        history={"lagrange": rows, "ale": [np.array([1.0])] * 3})
    assert Coupler._implicit_note(c) == "lagrange: dt 0.0005 s, 9 Newton iterations (2 substeps)"
    hist = {f"lagrange.{n}": np.array([r[i] for r in rows]) for i, n in enumerate(names)}
    hist["ale.mass"] = np.ones(3)
    assert Coupler._implicit_summary(c, hist) == {"lagrange": {
        "time_step": {"min": 5e-4, "median": 7.5e-4, "max": 1e-3},
        "newton_iterations": {"median": 6.0, "max": 9.0}, "substeps_max": 2.0}}
