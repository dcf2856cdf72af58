"""Implicit dynamic modes of the Lagrangian solver (issue 12; solvers/lagrange/implicit_dynamic.py):
the midpoint scheme keeps a free spinning block's energy and momenta far above the explicit limit, on
1 and 2 ranks alike and across a restart; Newmark's trapezoid on the same run is stopped by name."""
import json

import h5py
import numpy as np
import pytest

from tests.cases.test_cases import CASES, case_variant, run_case
from tests.cases.test_contact_cases import continue_from_first_checkpoint
from tests.cases.test_coupled_cases import assert_same_steps
from tests.conftest import immerse


def test_spinning_block_midpoint_on_two_ranks_and_from_a_checkpoint(tmp_path):
    """Its check (energy 1.4e-12, momentum 1.7e-14, angular momentum 7.8e-13 measured) at 8 ms steps
    (16.6x the explicit limit), at most 6 Newton iterations a step (measured 5); 2 ranks (a gathered
    solve on each) equal 1 rank bit for bit; a checkpoint continues bit for bit."""
    case = case_variant(tmp_path, "spinning_block_midpoint",
                        ("output_interval = 0.05", "output_interval = 0.05\ncheckpoint_interval = 0.25"))
    out, s = run_case("spinning_block_midpoint", tmp_path)
    with h5py.File(out / "diagnostics.h5") as h:
        assert h["lagrange.newton_iterations"][1:].max() <= 6
        assert np.median(h["lagrange.time_step"][1:]) == pytest.approx(8.0e-3, rel=1e-11)
    two = tmp_path / "two"
    r = immerse("run", CASES / "spinning_block_midpoint", "--out", two, "--ranks", "lagrange=2")
    assert r.returncode == 0, r.stdout + r.stderr
    assert_same_steps(out, two, roles=("lagrange",))
    one = tmp_path / "one"
    r = immerse("run", case, "--out", one)
    assert r.returncode == 0, r.stdout + r.stderr
    cont = continue_from_first_checkpoint(case, one, tmp_path / "cont")
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (one, cont))
    assert sa["final"] == sb["final"]


def test_newmark_is_stopped_by_name(tmp_path):
    """integrator = "newmark" on the same block: its first step is off by 14.5 % of the energy (beyond
    lagrange.energy_limit = 0.01): the run stops, non-zero, naming the scheme, the step and the
    number; the output written before (t = 0) stays readable and finite."""
    from orchestrator import output

    case = case_variant(tmp_path, "spinning_block_midpoint", ('integrator = "midpoint"', 'integrator = "newmark"'))
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out)
    assert r.returncode != 0
    line = next(ln for ln in r.stderr.splitlines() if ln.startswith("immerse: run failed"))
    assert "newmark step 1" in line and "does not keep the energy" in line and "-0.145" in line, line
    steps = output.read_steps(out, "lagrange")
    assert steps and all(np.all(np.isfinite(output.read_step(out, "lagrange", i)[0])) for _, _, i in steps)


def test_pinned_block_swinging_under_gravity_balances_with_the_pin_and_gravity(tmp_path):
    """A 0.2 x 0.05 m block pinned at a corner swings down under gravity (midpoint, 8 ms steps): the
    balances book gravity's work and impulse and the pin's reaction (its impulse and moment; it does no
    work): energy 1.2e-10 of the energy (the Newton tolerance summed over 70 steps), momentum 3.5e-15,
    angular momentum 1.0e-14 (measured); gravity did 1.97 J by the end (measured)."""
    case = tmp_path / "case"
    case.mkdir()
    text = (CASES / "spinning_block_midpoint" / "case.toml").read_text()
    text = text[:text.index("\n[lagrange]\n") + 1] + '''[lagrange]
integrator = "midpoint"
time_step = 8.0e-3
gravity = [0.0, -9.81]

[[lagrange.bodies]]
name = "block"
material = "rubber"
mesh = { box = { lower = [0.0, -0.05], upper = [0.2, 0.0], cells = [8, 2] } }

[[boundaries]]
type = "fixed"
region = "x < 1e-9 and y > -1e-9"

[check]
kind = "momentum"
metrics.energy_balance_rel = { reference = 0.0, tolerance = 5e-10 }
metrics.momentum_balance_rel = { reference = 0.0, tolerance = 3e-14 }
metrics.angular_momentum_balance_rel = { reference = 0.0, tolerance = 5e-14 }
'''
    (case / "case.toml").write_text(text)
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["check"]["passed"], s["check"]
    with h5py.File(out / "diagnostics.h5") as h:
        assert h["lagrange.gravity_work"][-1] > 1.5 and h["lagrange.kinetic_energy"][-1] > 1.5
