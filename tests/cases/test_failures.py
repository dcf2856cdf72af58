"""Each method driven into its known failure region: the failure is detected and reported with a
message that names the cause (never NaN output), and a campaign puts it on its stability map.

- penalty stiffness above its explicit limit: tests/cases/test_coupled_cases.py
  (test_penalty_beyond_its_stable_step_is_stopped_naming_the_limit) and the coupling_methods campaign;
- dt_scale > 1 (Courant violated), a near-vacuum rarefaction, inverted elements: here.
"""
from __future__ import annotations

import csv
import shutil

import numpy as np
import pytest

from orchestrator import output
from tests.conftest import CASES


def _variant(tmp_path, name, base, edits, drop_check=True):
    case = tmp_path / name
    shutil.copytree(CASES / base, case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    text = p.read_text()
    for a, b in edits.items():
        assert a in text, a
        text = text.replace(a, b)
    if drop_check:
        text = text[:text.index("[check]")]
    p.write_text(text)
    return case


def _failed_line(r) -> str:
    assert r.returncode not in (0, 2), r.stdout + r.stderr
    return [ln for ln in r.stderr.splitlines() if ln.startswith("immerse: run failed")][0]


def _written_steps_are_finite(out, role):
    steps = output.read_steps(out, role)
    assert steps
    for _, _, index in steps:
        points, pd, cd = output.read_step(out, role, index)
        for a in [points, *pd.values(), *cd.values()]:
            assert np.isfinite(a).all()


def test_dt_scale_above_one_is_reported_as_the_courant_limit(tmp_path, run_immerse):
    """Sod at 1.5 times the stable step: a zone of the Lagrange step turns inside out at step 1 (the
    detector: non-positive zone volume); the message names the cause (the Courant limit, dt_scale)
    before the solver's report; the start of the run warned; the steps written are finite."""
    case = _variant(tmp_path, "sod_dt", "sod", {"end_time = 0.2": "end_time = 0.2\ndt_scale = 1.5",
                                                 "checkpoint_interval = 0.1": ""})
    out = tmp_path / "out"
    r = run_immerse("run", case, "--out", out)
    line = _failed_line(r)
    assert line.startswith("immerse: run failed: unstable: run.dt_scale = 1.5 > 1 took steps beyond the "
                           "solvers' stable (Courant) limit; then: ale rank 0: SolverError: ALE zone"), line
    assert "non-positive zone volume" in line and "at step 1," in line, line
    assert "warning: run.dt_scale = 1.5 > 1" in (out / "log.txt").read_text()
    _written_steps_are_finite(out, "ale")


def test_a_near_vacuum_rarefaction_is_stopped_naming_negative_internal_energy(tmp_path, run_immerse):
    """Toro's 123 problem with the halves parting at 5 m/s (2u = 10 > 2c/(gamma - 1) = 3.74: a vacuum
    opens): the staggered scheme's internal energy goes negative at the centre at step 3; stopped
    there, the message names the state and the cause; the steps written are finite and positive."""
    case = _variant(tmp_path, "vacuum", "toro123", {"velocity = [-2.0, 0.0]": "velocity = [-5.0, 0.0]",
                                                     "velocity = [2.0, 0.0]": "velocity = [5.0, 0.0]"})
    out = tmp_path / "out"
    line = _failed_line(run_immerse("run", case, "--out", out))
    assert "SolverError: ALE zone (199, 0): invalid thermodynamic state: negative internal energy" in line, line
    assert "near-vacuum expansion" in line and "at step 3," in line, line
    _written_steps_are_finite(out, "ale")


def test_inverted_elements_are_stopped_naming_the_element(tmp_path, run_immerse):
    """The Taylor bar at 5000 m/s: an element at the impact face inverts (at step 15040, 6.8 us);
    stopped naming the body and element."""
    case = _variant(tmp_path, "taylor_fast", "taylor_bar",
                    {"initial_velocity = [0.0, 0.0, -287.0]": "initial_velocity = [0.0, 0.0, -5000.0]",
                     "end_time = 80.0e-6": "end_time = 20.0e-6"})
    out = tmp_path / "out"
    line = _failed_line(run_immerse("run", case, "--out", out))
    assert "lagrange rank 0: SolverError: inverted or invalid element 54" in line and "body 'rod'" in line, line
    _written_steps_are_finite(out, "lagrange")


@pytest.mark.timeout(600)
def test_a_campaign_puts_each_failure_on_its_stability_map(tmp_path, run_immerse):
    """dt_scale 0.9 and 1.5 on Sod, the parting halves at 2 and 5 m/s, the Taylor bar at 287 and 5000
    m/s, the water column's piston pushed and pulled (cavitation_pressure 0): the first of each runs,
    the second is 'unstable' with its message naming the cause, on the report's map and in its table."""
    (tmp_path / "campaign.toml").write_text(f'''
name = "failures"
[axes.push]
values = [1, 2]
[[series]]
name = "Sod, dt_scale"
case = "{CASES / 'sod'}"
[series.axes.push]
"run.dt_scale" = [0.9, 1.5]
[[series]]
name = "Toro 123, parting speed"
case = "{CASES / 'toro123'}"
[series.axes.push]
"ale.regions[0].velocity" = [[-2.0, 0.0], [-5.0, 0.0]]
"ale.regions[1].velocity" = [[2.0, 0.0], [5.0, 0.0]]
"check.params.left" = [[1.0, -2.0, 0.4], [1.0, -5.0, 0.4]]
"check.params.right" = [[1.0, 2.0, 0.4], [1.0, 5.0, 0.4]]
[[series]]
name = "Taylor bar, impact speed"
case = "{CASES / 'taylor_bar'}"
set = {{ "run.end_time" = 2.0e-5, "run.output_interval" = 1.0e-5 }}
[series.axes.push]
"lagrange.bodies[0].initial_velocity" = [[0.0, 0.0, -287.0], [0.0, 0.0, -5000.0]]
[[series]]
name = "water column, piston speed"
case = "{CASES / 'water_piston_column'}"
set = {{ "ale.materials.water.cavitation_pressure" = 0.0 }}
[series.axes.push]
"ale.boundaries.x_lower.piston.velocity" = [50.0, -50.0]
[report]
map = "push"
''')
    out = tmp_path / "out"
    r = run_immerse("campaign", tmp_path / "campaign.toml", "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    with open(out / "campaign.csv") as f:
        rows = {x["run"]: x for x in csv.DictReader(f)}
    assert rows["Sod_dt_scale-push1"]["status"] == "passed"
    assert rows["Toro_123_parting_speed-push1"]["status"] == "passed"
    for name, words in (("Sod_dt_scale-push2", "Courant"), ("Toro_123_parting_speed-push2", "negative internal energy"),
                        ("Taylor_bar_impact_speed-push2", "inverted or invalid element"),
                        ("water_column_piston_speed-push2", "material 'water' cavitates")):
        assert rows[name]["status"] == "unstable" and words in rows[name]["message"], rows[name]
        assert rows[name.replace("push2", "push1")]["status"] in ("passed", "check_failed"), rows
    md = (out / "report.md").read_text()
    for words in ("Courant", "negative internal energy", "inverted or invalid element", "cavitates"):
        assert words in md, words
    assert (out / "figures" / "failures_stability.png").stat().st_size > 10_000


def test_cavitating_water_is_stopped_naming_cavitation(tmp_path, run_immerse):
    """The water column with its piston pulled out at 50 m/s: the rarefaction would take the Tait
    water to about p0 - rho c u = -7e7 Pa, a tension it cannot hold. With cavitation_pressure = 0 the
    run stops at the first zone below it, the message naming the material, its pressure and the
    limit; the steps written are finite. (Without the key the EOS allows tension: linear acoustics
    about p = 0, cases/acoustic_transmission.)"""
    case = _variant(tmp_path, "pulled", "water_piston_column",
                    {"velocity = 50.0": "velocity = -50.0",
                     "p0 = 1.0e5 }": "p0 = 1.0e5, cavitation_pressure = 0.0 }"})
    out = tmp_path / "out"
    line = _failed_line(run_immerse("run", case, "--out", out))
    assert "SolverError: ALE zone (0, 0): material 'water' cavitates: its pressure -" in line, line
    assert "is below its cavitation_pressure 0 Pa" in line, line
    _written_steps_are_finite(out, "ale")


def test_cavitation_in_a_mixed_zone_names_the_material(tmp_path, run_immerse):
    """The water-air shock tube (several materials per zone) with a cavitation pressure of the water
    above its 1 GPa: stopped at once, naming the water."""
    case = _variant(tmp_path, "mixed", "water_air_shock_tube",
                    {"p_inf = 6.0e8 }": "p_inf = 6.0e8, cavitation_pressure = 2.0e9 }"})
    line = _failed_line(run_immerse("run", case, "--out", tmp_path / "out"))
    assert "material 'water' cavitates: its pressure 1e+09 Pa is below its cavitation_pressure 2e+09 Pa" in line, line
