"""orchestrator/plot.py (`immerse plot`): a run's histories against time, chosen by key, pattern or
probe name, with units; the case's check's reference curve beside the history it measures; an
unknown quantity refused in one line (exit 2) with nothing written.  The whole path on a real run:
tests/cases/test_coupled_cases.py (the demo's tip against its step files)."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from orchestrator.plot import PlotError, listing, plot, read_history, select
from orchestrator.units import history_unit
from tests.conftest import CASES, immerse

mpimg = pytest.importorskip("matplotlib.image")


def _run_dir(tmp_path, case_dir=None):
    """An output directory holding a history: 11 steps, the last recorded twice (its output)."""
    out = tmp_path / "out"
    out.mkdir()
    t = np.r_[np.linspace(0.0, 1e-3, 11), 1e-3]
    with h5py.File(out / "diagnostics.h5", "w") as h:
        h["time"] = t
        h["step"] = np.r_[np.arange(11), 10].astype(float)
        h["ale.total_energy"] = 1.0 + t
        h["lagrange.total_energy"] = 2.0 - t
        h["lagrange.momentum_x"] = 3.0 * t
        h["lagrange.probe_tip"] = t ** 2
    if case_dir is not None:
        (out / "summary.json").write_text(json.dumps({"case_dir": str(case_dir)}))
    return out


def test_quantities_by_key_pattern_and_probe_name(tmp_path):
    out = _run_dir(tmp_path)
    hist = read_history(out)
    assert len(hist["time"]) == 11   # (each step once)
    assert select(hist, [], None) == ["lagrange.probe_tip"]                     # default: the probes
    assert select(hist, ["*.total_energy"], None) == ["ale.total_energy", "lagrange.total_energy"]
    assert select(hist, ["tip", "lagrange.momentum_x"], None) == ["lagrange.probe_tip", "lagrange.momentum_x"]
    with pytest.raises(PlotError, match="QUANTITY = 'energy': not a history of this run .*did you mean "
                                        "ale.total_energy, lagrange.total_energy; probes: tip"):
        select(hist, ["energy"], None)


def test_the_picture_and_its_csv(tmp_path):
    out = _run_dir(tmp_path)
    png, csv = plot(out, ["*.total_energy"], csv_too=True)
    img = mpimg.imread(png)
    assert img.shape[1] == 1024 and len(np.unique(img[..., :3].reshape(-1, 3), axis=0)) > 20
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert csv.read_text().splitlines()[0] == "time (s),ale.total_energy (J),lagrange.total_energy (J)"
    np.testing.assert_array_equal(rows[:, 1], 1.0 + rows[:, 0])
    assert "lagrange.momentum_x (kg m/s)" in listing(out).splitlines()


def test_units_of_histories():
    assert history_unit("ale.kinetic_energy") == "J" and history_unit("ale.mass") == "kg"
    assert history_unit("lagrange.momentum_y") == "kg m/s" and history_unit("coupling.interface_work") == "J"
    assert history_unit("ale.energy_balance_rel") == "1" and history_unit("lagrange.contact_force_x") == "N"
    probes = {"tip": {"quantity": "velocity"}}
    assert history_unit("sph.probe_tip", probes) == "m/s" and history_unit("sph.probe_other", probes) is None


def test_the_checks_reference_is_drawn_beside_its_probe(tmp_path):
    """plate_in_shock_2d's check (tip_history on its probe "tip") gives its reference curve for
    lagrange.probe_tip: drawn as a second line of that panel, labelled with its source."""
    from orchestrator.case import load_case
    from orchestrator.checks import reference_curve
    from orchestrator.plot import figure

    case = load_case(CASES / "plate_in_shock_2d")
    key, t, v, label = reference_curve(case)
    assert key == "lagrange.probe_tip" and t[-1] == 0.004 and v[-1] == pytest.approx(0.0100869)
    out = _run_dir(tmp_path, CASES / "plate_in_shock_2d")
    fig, keys = figure(out, ["tip", "*.total_energy"])
    lines = [[ln.get_label() for ln in ax.get_lines()] for ax in fig.axes]
    assert lines[0] == ["lagrange.probe_tip (11 steps)", f"{label}"] and "24 x 240" in label
    assert all(len(ln) == 1 for ln in lines[1:]), lines
    assert fig.axes[0].get_ylabel() == "lagrange.probe_tip (m)"


def test_bad_requests_one_line_exit_2_nothing_written(tmp_path):
    out = _run_dir(tmp_path)
    r = immerse("plot", out, "nothing_like_it")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "QUANTITY = 'nothing_like_it'" in r.stderr
    assert not (out / "plots").exists()
    r = immerse("plot", tmp_path / "absent")
    assert r.returncode == 2 and "not a directory" in r.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    r = immerse("plot", empty)
    assert r.returncode == 2 and "no history there yet" in r.stderr, r.stderr
