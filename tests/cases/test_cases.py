"""Every shipped case run end to end through `immerse run` (launcher + coupler + solver ranks), its
own check (reference + tolerance from case.toml) asserted from summary.json."""
from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

from tests.conftest import CASES, immerse


def run_case(name, tmp_path, *extra, timeout=900):
    """`immerse run` of a shipped case (or of a case directory's path: a case_variant); asserts exit 0
    and that every metric of its [check] passed (tolerances: cases/<name>/case.toml, a few times the
    error measured)."""
    out = tmp_path / "out"
    r = immerse("run", CASES / name, "--out", out, *extra, timeout=timeout)
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert_check_passed(s)
    return out, s


def case_variant(tmp_path, name, *edits):
    """A copy of cases/<name> in tmp_path/<name> with its case.toml's texts replaced (``edits``:
    (old, new) pairs, each old text asserted present)."""
    case = tmp_path / name
    shutil.copytree(CASES / name, case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    text = p.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    p.write_text(text)
    return case


def assert_check_passed(s):
    m = s["check"]["metrics"]
    bad = {k: (v["value"], v["reference"], v["tolerance"]) for k, v in m.items() if not v["passed"]}
    assert not bad and s["check"]["passed"], f"failed metrics (value, reference, tolerance): {bad}"


def test_elastic_bar_wave(tmp_path):
    out, s = run_case("elastic_bar_wave", tmp_path)
    assert set(s["check"]["metrics"]) == {"wave_speed", "stress_amplitude", "stress_max", "energy_balance_rel",
                                          "momentum_balance_rel"}
    # the ParaView index lists every output step (t = 0, 1, ..., 16 us)
    with h5py.File(out / "results.h5") as h:
        assert len(h["lagrange/times"]) == 17
    assert (out / "results.xdmf").is_file() and (out / "log.txt").is_file()


@pytest.mark.parametrize("name, mesh_line, hg_share", [
    ("elastic_bar_wave", "cells = [400, 1, 1] } }", 1e-6),
    ("taylor_bar", "radial_cells = 6, axial_cells = 54 } }", 0.02)])
def test_bar_wave_and_taylor_bar_with_the_assumed_strain_stiffness(tmp_path, name, mesh_line, hg_share):
    """Issue 42: the bodies with hourglass_control = "assumed_strain" pass the cases' own checks
    (measured: bar wave speed 7.1e-5, stress 7.4e-5 against 3e-4; Taylor bar final length 0.13 %,
    impact diameter 0.21 % against 0.4 / 0.8 %, where the viscous control gives 0.12 / 0.31 %), and the
    stiffness's work stays a small share of the stress power (bar wave 2.3e-7, bound 1e-6; Taylor bar
    0.58 J of 81 J: 0.7 %, bound 2 %: it does not blow up where the flow is plastic and the hourglass
    part follows the return)."""
    case = case_variant(tmp_path, name, (mesh_line, mesh_line + '\nhourglass_control = "assumed_strain"'))
    out, s = run_case(case, tmp_path)
    with h5py.File(out / "diagnostics.h5") as h:
        hg = h["lagrange.hourglass_energy"][-1]
        sp = h["lagrange.stress_power_energy"][-1]
    assert 0.0 <= hg <= hg_share * sp, (hg, sp)


def test_elastic_bar_wave_at_240_outputs(tmp_path):
    """Issue 40: with an output every end_time / 240 (1.6 of its steps) the clipped steps once grew
    the bar's zigzag mode to +3.8 / -2.0 GPa with every balance at round-off. Outputs no longer touch
    a step: the stress behind the front is within 0.1 % of 40 MPa (measured 6.7e-5, as with 17
    outputs) and the largest stress of any output is the front's ringing (measured 4.25e7 Pa, 6.3e-2
    over; the 17-output run's 4.06e7 samples the same steps less often)."""
    case = case_variant(tmp_path, "elastic_bar_wave", ("output_interval = 1.0e-6", "output_interval = 6.666666666666667e-8"))
    out, s = run_case(case, tmp_path)
    m = s["check"]["metrics"]
    assert m["stress_amplitude"]["rel_error"] < 1e-3
    assert m["stress_max"]["value"] < 1.1 * 4.0e7
    with h5py.File(out / "results.h5") as h:
        assert len(h["lagrange/times"]) == 241


def test_taylor_bar_two_ranks_equals_one(tmp_path):
    """The whole job on 2 solver ranks equals 1 rank bit for bit (the cut nodes add their elements'
    forces and masses in the one-rank order, solvers/lagrange/shared_sums.py): positions, velocities,
    stresses and plastic strains of every output step of a plastic impact."""
    from orchestrator import output

    case = tmp_path / "case"
    shutil.copytree(CASES / "taylor_bar", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    text = text.replace("end_time = 80.0e-6", "end_time = 10.0e-6").replace(
        "output_interval = 4.0e-6", "output_interval = 2.5e-6").replace(
        "radial_cells = 6, axial_cells = 54", "radial_cells = 4, axial_cells = 36")
    (case / "case.toml").write_text(text)
    outs = {}
    for n in (1, 2):
        outs[n] = tmp_path / f"out{n}"
        r = immerse("run", case, "--out", outs[n], "--ranks", f"lagrange={n}")
        assert r.returncode in (0, 1), r.stderr  # the check is for 80 us; here only equality matters
    s1 = json.loads((outs[1] / "summary.json").read_text())
    s2 = json.loads((outs[2] / "summary.json").read_text())
    assert s2["ranks"] == {"lagrange": 2} and s1["steps"] == s2["steps"]
    steps = output.read_steps(outs[1], "lagrange")
    assert len(steps) == 5 and steps == output.read_steps(outs[2], "lagrange")
    for _, _, index in steps:
        p1, pd1, cd1 = output.read_step(outs[1], "lagrange", index)
        p2, pd2, cd2 = output.read_step(outs[2], "lagrange", index)
        for a, b in ((p1, p2), (pd1["velocity"], pd2["velocity"]), (cd1["stress"], cd2["stress"]),
                     (cd1["plastic_strain"], cd2["plastic_strain"])):
            assert np.array_equal(a, b)
    assert cd1["plastic_strain"].max() > 0.1  # the comparison covers plastic flow


@pytest.mark.slow
def test_spinning_block(tmp_path):
    out, s = run_case("spinning_block", tmp_path)
    assert s["steps"] == 10_000
    assert {"momentum_balance_rel", "angular_momentum_balance_rel"} <= set(s["check"]["metrics"])


def test_restart_is_bitwise_identical(tmp_path):
    """Stop-and-restart from a checkpoint at step k ends bitwise equal to the uninterrupted run."""
    case = tmp_path / "case"
    shutil.copytree(CASES / "elastic_bar_wave", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text().replace("output_interval = 1.0e-6",
                                                    "output_interval = 1.0e-6\ncheckpoint_interval = 5.0e-6")
    (case / "case.toml").write_text(text)
    full = tmp_path / "full"
    r = immerse("run", case, "--out", full)
    assert r.returncode == 0, r.stderr
    ckpts = sorted((full / "checkpoints").glob("checkpoint_*.h5"))
    assert len(ckpts) >= 2
    restarted = tmp_path / "restarted"
    shutil.copytree(full, restarted)
    r = immerse("run", case, "--out", restarted, "--restart", restarted / "checkpoints" / ckpts[0].name)
    assert r.returncode == 0, r.stderr
    with h5py.File(full / "results.h5") as a, h5py.File(restarted / "results.h5") as b:
        assert list(a["lagrange/times"][...]) == list(b["lagrange/times"][...])
        last = sorted(k for k in a["lagrange"] if k.isdigit())[-1]
        for key in ("points", "point_data/velocity", "cell_data/stress", "cell_data/plastic_strain"):
            assert (a[f"lagrange/{last}/{key}"][...] == b[f"lagrange/{last}/{key}"][...]).all(), key
    sa = json.loads((full / "summary.json").read_text())
    sb = json.loads((restarted / "summary.json").read_text())
    assert sa["final"] == sb["final"] and sa["steps"] == sb["steps"]


@pytest.mark.slow
def test_taylor_bar(tmp_path):
    """42CrMo4 Taylor impact, quarter model: final length and impact-face diameter against the
    published code results (26.52-26.56 mm, 11.15-11.22 mm; references are mid-points), within the
    case's tolerances (0.4 % and 0.8 %; measured 0.12 % and 0.31 %)."""
    out, s = run_case("taylor_bar", tmp_path)
    assert set(s["check"]["metrics"]) == {"final_length", "impact_diameter"}
    # the rod really mushroomed and heated: plastic strain and temperature rise at the impact face
    from orchestrator import output

    _, _, index = output.read_steps(out, "lagrange")[-1]
    _, _, cd = output.read_step(out, "lagrange", index)
    assert cd["plastic_strain"].max() > 1.0
    assert cd["temperature"].max() > 293.15 + 200.0


def test_cantilever_refined_corner_subcycled(tmp_path):
    """Element subcycling (issue 43): the cantilever whose refined corner would set its step, its
    tip against the same mesh single-rate (the case's check: measured 1.04e-4 of the peak); 10,320
    steps of 8 substeps against the single-rate 82,010, each evaluating 0.134 of the elements."""
    out, s = run_case("cantilever_refined_corner", tmp_path)
    from orchestrator import output

    steps = output.read_steps(out, "lagrange")
    cells = output.read_step(out, "lagrange", steps[-1][2])[2]
    levels = cells["subcycling_level"]   # (the analyst's view of the levels: the corner's fine)
    assert levels.min() == 0.0 and levels.max() == 3.0, np.bincount(levels.astype(int))
    assert (levels == 3.0).sum() > 0.95 * levels.size
    f = s["final"]
    assert f["lagrange.subcycling_substeps"] == 8.0 and f["lagrange.subcycling_element_share"] < 0.15
    assert s["steps"] < 82010 / 7
    assert abs(f["lagrange.energy_balance_rel"]) < 1e-13


def test_taylor_bar_subcycled(tmp_path):
    """The Taylor bar with element subcycling (lagrange.subcycling = 16): the O-grid core's small
    elements at the impact face set the single-rate step (5,173 steps); subcycled, 1,802 steps of 4
    substeps (7.5 s against 4.05 s on this machine), the wall holding each node over its own step,
    plastic flow and all.  Its own check passes, and the final length and impact diameter stay
    within 1e-4 and 1.5e-3 of the single-rate run's 26.5071 and 11.1761 mm (measured 2.6e-5 and
    3.8e-4; the measured values are 26.54 and 11.185 mm)."""
    case = case_variant(tmp_path, "taylor_bar", ("[[lagrange.bodies]]", "[lagrange]\nsubcycling = 16\n\n[[lagrange.bodies]]"))
    out, s = run_case(case, tmp_path)
    m = s["check"]["metrics"]
    assert abs(m["final_length"]["value"] / 0.0265071 - 1.0) < 1e-4, m["final_length"]
    assert abs(m["impact_diameter"]["value"] / 0.0111761 - 1.0) < 1.5e-3, m["impact_diameter"]
    assert s["steps"] < 0.4 * 5173 and s["final"]["lagrange.subcycling_substeps"] >= 4.0
    assert abs(s["final"]["lagrange.energy_balance_rel"]) < 1e-12
