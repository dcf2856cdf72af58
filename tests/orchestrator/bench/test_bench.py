"""`immerse bench` writes the documented JSON (smoke run of the cheapest sweep; speed is never
asserted, but the Sod sweep's accuracy is: first-order convergence of the L1 density error)."""
import json

import pytest

from tests.conftest import immerse


def test_bench_sod_quick(tmp_path):
    out = tmp_path / "bench-sod.json"
    r = immerse("bench", "sod", "--quick", "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"results", "machine"}
    res = doc["results"]
    assert [x["params"]["zones"] for x in res] == [100, 200, 400]
    assert all(x["metric"] == "l1_density_error" and x["unit"] == "" for x in res)
    errors = [x["value"] for x in res]
    assert errors[0] > errors[1] > errors[2]
    assert all(x["params"]["observed_order"] > 0.7 for x in res[1:])  # shocks: order ~1 expected


def test_bench_unknown_name():
    r = immerse("bench", "nonsense")
    assert r.returncode == 2 and "bench NAME = 'nonsense'" in r.stderr


def test_bench_out_that_is_not_a_file_path_is_refused_in_one_line(tmp_path):
    """--out naming a directory, or a path under a file: one line naming --out, exit 2, nothing
    written (it was an IsADirectoryError traceback after the whole bench had run)."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out in (tmp_path, afile / "b.json"):
        before = sorted(tmp_path.rglob("*"))
        r = immerse("bench", "coupling", "--quick", "--out", out, timeout=60)
        assert r.returncode == 2 and r.stderr.startswith("immerse: bench --out = "), r.stderr
        assert len(r.stderr.splitlines()) == 1, r.stderr
        assert sorted(tmp_path.rglob("*")) == before


@pytest.mark.slow
def test_bench_advect_quick(tmp_path):
    """Two-material bench: the square's symmetric difference falls with the mesh, volumes are kept,
    the water-air tube's interface sits within 2 cells; the cost of two materials is reported."""
    out = tmp_path / "bench-advect.json"
    r = immerse("bench", "advect", "--quick", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())["results"]
    sq = [x for x in res if x["name"] == "advected_square"]
    assert [x["params"]["zones_per_side"] for x in sq] == [32, 64]
    assert sq[1]["value"] < 0.6 * sq[0]["value"]
    assert all(x["params"]["volume_drift_rel"] <= 1e-12 for x in sq)
    wa = [x for x in res if x["name"] == "water_air_shock_tube"]
    assert [x["params"]["zones"] for x in wa] == [200, 400]
    assert all(x["params"]["interface_position_error_cells"] <= 2.0 for x in wa)
    ball = {x["params"]["materials"]: x for x in res if x["name"] == "advected_ball_3d"}
    assert set(ball) == {"one_material", "two_materials"} and ball["two_materials"]["params"]["mixed_zone_share"] > 0


@pytest.mark.slow
def test_bench_output_quick(tmp_path):
    """The output bench: per-output cost at 10 and 100 outputs (the bench itself fails if the
    appended index differs from the one rebuilt from the step files) and the bar wave's wall time
    at two output counts; timings are reported, not asserted."""
    out = tmp_path / "bench-output.json"
    r = immerse("bench", "output", "--quick", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())["results"]
    per_output = [x for x in res if x["metric"] == "time_per_output"]
    assert [x["params"]["outputs"] for x in per_output] == [10, 100]
    assert all(x["unit"] == "ms" and x["value"] > 0 and x["params"]["index_append_ms"] > 0 for x in per_output)
    walls = [x for x in res if x["name"] == "elastic_bar_wave" and x["metric"] == "wall_time"]
    assert [x["params"]["output_steps"] for x in walls] == [13, 49]  # output_interval end/12, end/48, and t = 0
    extra = next(x for x in res if x["metric"] == "wall_time_per_extra_output")  # one for each pair of runs
    assert extra["params"]["outputs"] == [13, 49] and "write_time_per_output_ms" in extra["params"]


@pytest.mark.slow
def test_bench_sph_quick(tmp_path):
    """The SPH bench writes LAMMPS alone and the driver alone for the same particles and steps, and the
    coupler's share of a coupled embedded run (speed itself is not asserted: `immerse bench sph`
    measures it)."""
    out = tmp_path / "bench-sph.json"
    r = immerse("bench", "sph", "--quick", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    rows = {r["name"]: r for r in json.loads(out.read_text())["results"]}
    row = rows["dam_break_2d"]
    p = row["params"]
    assert row["name"] == "dam_break_2d" and row["metric"] == "particle_steps_per_s"
    assert p["particles"] == 5688 and p["lammps_alone"] > 0 and p["driver_sph_alone"] == row["value"]
    # one repeat: the pair's ratio is the driver's speed over LAMMPS's; the in-run ratio is LAMMPS's
    # share of the driver's loop less the batch calls' own cost
    assert p["ratio_of_each_pair"] == [pytest.approx(row["value"] / p["lammps_alone"], rel=1e-12)]
    (share,) = p["lammps_share_of_driver_loop"]
    assert 0.0 < share < 1.0 and 0.0 < p["call_cost_s"] < 1e-3
    assert 0.0 < p["ratio_driver_to_lammps"] < share
    emb = rows["embedded_dam_break_2d"]  # the coupled run: the coupler's share of the time loop
    assert emb["metric"] == "coupler_share" and 0.0 < emb["value"] < 1.0
    assert emb["params"]["geometry_s"] > 0.0 and emb["params"]["particles"] == 4050


def test_bench_contact_quick(tmp_path):
    """The contact bench times the search, the dual-pass operators and the multipliers' solve per
    facet at 10^2 and 10^3 facets and the all-pairs test they replace (speed itself is not asserted: `immerse bench contact`
    measures it)."""
    out = tmp_path / "bench-contact.json"
    r = immerse("bench", "contact", "--quick", "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.read_text())["results"]
    ops = [x for x in rows if x["name"] == "contact_operators" and x["metric"] == "time_per_facet"]
    assert [x["params"]["facets_a"] for x in ops] == [100, 1000]
    for x in ops:
        p = x["params"]
        # every node of both faces carries a multiplier (they overlap end to end); a candidate pair
        # per facet and its neighbours: linear in the facets, not their product
        assert p["multipliers"] == p["facets_a"] + p["facets_b"] + 2
        assert p["facets_a"] <= p["candidate_pairs"] <= 4 * p["facets_a"]
        assert x["value"] > 0 and p["all_pairs_s"] > 0
        # the multipliers' solve with the interface pressed: all but the faces' end rows active
        assert p["multipliers"] - 4 <= p["solve_active"] <= p["multipliers"] and p["solve_iterations"] <= 3
    solves = [x for x in rows if x["name"] in ("contact_solve", "contact_search_operators_solve")
              and x["metric"] == "time_per_facet"]
    assert len(solves) == 4 and all(x["value"] > 0 for x in solves)
    (step,) = [x for x in rows if x["name"] == "contact_step"]
    # the quick size: 10^4 elements, 999 contact facets, all of the interface in contact
    assert step["params"]["elements"] == 9990 and step["params"]["active_multipliers"] == 1001
    assert 0.0 < step["value"] < 1.0 and step["params"]["step_with_s"] > step["params"]["step_without_s"]


def test_bench_implicit_quick(tmp_path):
    """The implicit bench times a midpoint step of the spinning block at 10^2 and 10^3 elements (its
    Newton iterations, the tangent's and the solve's share) and the L-block's explicit and midpoint
    steps, whose ratio is the break-even step ratio (speed itself is not asserted: `immerse bench
    implicit` measures it)."""
    out = tmp_path / "bench-implicit.json"
    r = immerse("bench", "implicit", "--quick", "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.read_text())["results"]
    steps = [x for x in rows if x["name"] == "midpoint_step" and x["metric"] == "time_per_element_step"]
    assert [(x["params"]["elements"], x["params"]["ranks"]) for x in steps] == [(100, 1), (1024, 1), (1024, 2)]
    for x in steps:
        p = x["params"]
        assert 2 <= p["newton_iterations"] <= 6 and 0 < p["tangent_s"] + p["solve_s"] < p["step_s"]
    (sp,) = [x for x in rows if x["metric"] == "speedup_2_ranks"]     # (the tangent's share in parallel)
    assert sp["value"] == pytest.approx(sp["params"]["step_s"][0] / sp["params"]["step_s"][1])
    (be,) = [x for x in rows if x["metric"] == "break_even_dt_ratio"]
    p = be["params"]
    assert be["value"] == pytest.approx(p["midpoint_step_s"] / p["explicit_step_s"])
    assert p["elements"] == 117 and 10 < p["dt_ratio"] < 40


def test_bench_startup_quick(tmp_path):
    """The start-up bench: the floor of a kernel-loading process and a two-step ALE job's process tree
    (its CPU includes at least the ALE rank's floor; the first step comes before the launcher ends).
    Times are reported, not asserted (`immerse bench startup`: 0.49 s floor, 1.19 s an ALE job, 3.68 s
    a coupled one, 2026-12-03)."""
    out = tmp_path / "bench-startup.json"
    r = immerse("bench", "startup", "--quick", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    res = {x["name"]: x for x in json.loads(out.read_text())["results"]}
    floor, job = res["numpy_scipy_numba_setup"], res["sod"]
    assert floor["unit"] == "s" and 0.0 < floor["value"] < 60.0
    assert job["metric"] == "job_cpu_time" and job["params"]["steps"] == 2
    assert job["value"] > floor["value"], (job["value"], floor["value"])
    assert 0.0 < job["params"]["first_step_s"] < job["params"]["launcher_wall_s"]
    warm = res["sod_warm"]  # the same job forked from a warm process server (orchestrator/prestart)
    assert warm["metric"] == "job_cpu_time" and warm["value"] > 0.0
    assert 0.0 < warm["params"]["first_step_s"] < warm["params"]["launcher_wall_s"]
    assert warm["params"]["cpu_plain_over_warm"] == pytest.approx(job["value"] / warm["value"])


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_bench_multirate_quick(tmp_path):
    """`immerse bench multirate --quick`: the piston at ratios 1, 4, 16, single- and multi-rate; the
    documented JSON and chart, the substeps per coupling step following the ratio, the multi-rate
    runs' coupling steps those of the gas (213) and their check errors within the case's tolerances
    (measured at 16: centre 6.37e-3, velocity 1.86e-5, pressures 2.56e-5, 2.55e-5; speed is the
    bench's to report, not this test's: 11.8x at 16 on a loaded machine)."""
    out = tmp_path / "bench-multirate.json"
    r = immerse("bench", "multirate", "--quick", "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"results", "rows", "machine"} and (tmp_path / "multirate.png").is_file()
    rows = {(x["ratio"], x["multirate"]): x for x in doc["rows"]}
    assert sorted(rows) == [(1, False), (1, True), (4, False), (4, True), (16, False), (16, True)]
    assert rows[(16, True)]["substeps_mean"] > 25 and rows[(4, True)]["substeps_mean"] > 6
    assert all(rows[(k, True)]["steps"] == 213 for k in (1, 4, 16))
    for (ratio, multi), row in rows.items():
        e = row["errors"]
        assert e["centre"] < 0.015 and e["velocity"] < 1e-4 and e["p_left"] < 1e-4 and e["p_right"] < 1e-4, (ratio, multi, e)
    assert {x["name"] for x in doc["results"] if x["metric"] == "wall_time_single_over_multi"} == {
        "speedup_ratio_1", "speedup_ratio_4", "speedup_ratio_16"}


@pytest.mark.timeout(300)
def test_bench_subcycling_quick(tmp_path):
    """`immerse bench subcycling --quick`: the refined-corner cantilever in 2-D (80 x 8) and 3-D
    (40 x 4 x 1), single-rate and subcycled: the documented JSON and chart, 8 substeps a step
    (single-rate: 668 and 228 steps over the span, subcycled 84 and 38), the tip within 1e-3 of the
    single-rate run (measured 5.0e-5, 1.3e-4); speed is the bench's to report (2.7x, 2.5x quick)."""
    out = tmp_path / "bench-subcycling.json"
    r = immerse("bench", "subcycling", "--quick", "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"results", "machine", "chart"} and (tmp_path / doc["chart"]).is_file()
    res = {(x["name"], x["metric"]): x for x in doc["results"]}
    for name in ("cantilever_2d_80x8", "cantilever_3d_40x4x1"):
        single, sub = res[(f"{name}_single", "wall_time")], res[(f"{name}_subcycled", "wall_time")]
        assert sub["params"]["substeps_per_step"] == 8.0 and single["params"]["substeps_per_step"] == 1.0
        assert single["params"]["steps"] > 5.5 * sub["params"]["steps"]
        assert res[(name, "tip_difference_over_peak")]["value"] < 1e-3
        assert res[(name, "speedup_single_over_subcycled")]["value"] > 0.0
