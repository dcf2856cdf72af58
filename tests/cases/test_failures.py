"""Each method driven into its known failure region: the failure is detected and reported with a
message that names the cause (never NaN output), and a campaign puts it on its stability map.

- penalty stiffness above its explicit limit: tests/cases/test_coupled_cases.py
  (test_penalty_beyond_its_stable_step_is_stopped_naming_the_limit) and the coupling_methods campaign
  (tests/cases/test_campaigns.py);
- multipliers without stabilisation: the multiplier_stabilization campaign (cond(H) warned, the
  multipliers' oscillation measured; tests/cases/test_campaigns.py);
- dt_scale > 1 (Courant violated), a near-vacuum rarefaction, inverted elements, cavitating water: here,
  as one campaign whose runs each pair a stable level with a failing one.
"""
from __future__ import annotations

import csv
import shutil

import numpy as np
import pytest

from orchestrator import output
from tests.conftest import CASES


def _written_steps_are_finite(out, role):
    steps = output.read_steps(out, role)
    assert steps
    for _, _, index in steps:
        points, pd, cd = output.read_step(out, role, index)
        for a in [points, *pd.values(), *cd.values()]:
            assert np.isfinite(a).all()


FAILURES = '''
name = "failures"
[axes.push]
values = [1, 2]
[[series]]
name = "Sod, dt_scale"
case = "@CASES/sod"
[series.axes.push]
"run.dt_scale" = [0.9, 1.5]
[[series]]
name = "Toro 123, parting speed"
case = "@CASES/toro123"
[series.axes.push]
"ale.regions[0].velocity" = [[-2.0, 0.0], [-5.0, 0.0]]
"ale.regions[1].velocity" = [[2.0, 0.0], [5.0, 0.0]]
"check.params.left" = [[1.0, -2.0, 0.4], [1.0, -5.0, 0.4]]
"check.params.right" = [[1.0, 2.0, 0.4], [1.0, 5.0, 0.4]]
[[series]]
name = "Taylor bar, impact speed"
case = "@CASES/taylor_bar"
set = { "run.end_time" = 1.0e-5, "run.output_interval" = 0.5e-5 }
[series.axes.push]
"lagrange.bodies[0].initial_velocity" = [[0.0, 0.0, -287.0], [0.0, 0.0, -10000.0]]
[[series]]
name = "water column, piston speed"
case = "@CASES/water_piston_column"
set = { "ale.materials.water.cavitation_pressure" = 0.0 }
[series.axes.push]
"ale.boundaries.x_lower.piston.velocity" = [50.0, -50.0]
[report]
map = "push"
'''


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_each_failure_is_detected_named_and_on_the_stability_map(tmp_path, run_immerse):
    """Level 1 of each series runs; level 2 is stopped, 'unstable', its message naming the cause:
    - Sod at dt_scale 1.5: a zone turns inside out at step 1 (non-positive zone volume), the message
      first names the Courant limit (run.dt_scale), the run's start warned of it;
    - Toro's 123 with the halves parting at 5 m/s (2u = 10 > 2c/(gamma-1) = 3.74: a vacuum opens):
      negative internal energy at the centre at step 3, named a near-vacuum expansion;
    - the Taylor bar at 10 km/s: an element at the impact face is crushed (element 170: with the
      default assumed-strain stiffness, whose damping holds a flowing element's hourglass modes as the
      viscous control does, it shrinks to 2.8e-11 of its volume and its stable step collapses at
      step 649, 0.56 us; with the viscous control it inverted at step 179, 0.52 us);
    - the water column's piston pulled out at 50 m/s: the rarefaction would reach p0 - rho c u = -7e7
      Pa; with cavitation_pressure = 0 the water is named cavitating at the first zone below it.
    Every failed run's written steps are finite; the report's map and table show each message."""
    (tmp_path / "campaign.toml").write_text(FAILURES.replace("@CASES", str(CASES)))
    out = tmp_path / "out"
    r = run_immerse("campaign", tmp_path / "campaign.toml", "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    with open(out / "campaign.csv") as f:
        rows = {x["run"]: x for x in csv.DictReader(f)}
    expect = {
        "Sod_dt_scale": ("ale", ["unstable: run.dt_scale = 1.5 > 1 took steps beyond the solvers' stable (Courant) "
                                 "limit; then: ale rank 0: SolverError: ALE zone", "non-positive zone volume",
                                 "at step 1,"]),
        "Toro_123_parting_speed": ("ale", ["SolverError: ALE zone (199, 0): invalid thermodynamic state: negative "
                                           "internal energy", "near-vacuum expansion", "at step 3,"]),
        "Taylor_bar_impact_speed": ("lagrange", ["time step collapsed", "element 170 of body 'rod'"]),
        "water_column_piston_speed": ("ale", ["SolverError: ALE zone (0, 0): material 'water' cavitates: its "
                                              "pressure -", "is below its cavitation_pressure 0 Pa"]),
    }
    md = (out / "report.md").read_text()
    for series, (role, words) in expect.items():
        ok, bad = rows[f"{series}-push1"], rows[f"{series}-push2"]
        assert ok["status"] in ("passed", "check_failed"), ok
        assert bad["status"] == "unstable", bad
        for w in words:
            assert w in bad["message"], (w, bad["message"])
        assert bad["message"] in md.replace("\\|", "|")
        _written_steps_are_finite(out / "runs" / bad["run"] / "out", role)
    assert "warning: run.dt_scale = 1.5 > 1" in (out / "runs" / "Sod_dt_scale-push2" / "out" / "log.txt").read_text()
    assert (out / "figures" / "failures_stability.png").stat().st_size > 10_000


def test_cavitation_in_a_mixed_zone_names_the_material(tmp_path, run_immerse):
    """The water-air shock tube (several materials per zone) with a cavitation pressure of the water
    above its 1 GPa: stopped at once, naming the water."""
    case = tmp_path / "mixed"
    shutil.copytree(CASES / "water_air_shock_tube", case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    p.write_text(p.read_text().replace("p_inf = 6.0e8 }", "p_inf = 6.0e8, cavitation_pressure = 2.0e9 }", 1))
    r = run_immerse("run", case, "--out", tmp_path / "out")
    assert r.returncode not in (0, 2), r.stdout + r.stderr
    line = [ln for ln in r.stderr.splitlines() if ln.startswith("immerse: run failed")][0]
    assert "material 'water' cavitates: its pressure 1e+09 Pa is below its cavitation_pressure 2e+09 Pa" in line, line
