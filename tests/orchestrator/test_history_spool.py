"""The history spooled while a run goes on (orchestrator/history_spool.py) and the record of a run that
ended early (orchestrator/run_record.py): every whole record survives a kill at any byte, the partial
last one is dropped, and the ended run's summary names its status, last step and time."""
from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from orchestrator.history_spool import ROWS, HistorySpool, read_history
from orchestrator.run_record import ended_summary, record_ended_run

NAMES = {"ale": ["mass", "total_energy", "energy_balance_rel"], "coupling": ["cond_H"]}


def spool_rows(out, n):
    sp = HistorySpool(out, NAMES)
    for k in range(n):
        sp.append(1e-3 * k, k, [np.array([1.0, 2.0 + k, 1e-16 * k]), np.array([3.0])])
    sp.close()


def test_every_whole_record_reads_back_and_a_cut_one_is_dropped(tmp_path):
    spool_rows(tmp_path, 5)
    full = (tmp_path / ".run" / ROWS).read_bytes()
    width = 8 * (2 + 4)
    for cut in range(len(full) + 1):   # a kill after any byte
        (tmp_path / ".run" / ROWS).write_bytes(full[:cut])
        h = read_history(tmp_path)
        n = cut // width
        assert len(h["time"]) == n
        np.testing.assert_array_equal(h["step"], np.arange(n))
        np.testing.assert_array_equal(h["ale.total_energy"], 2.0 + np.arange(n))
        np.testing.assert_array_equal(h["coupling.cond_H"], np.full(n, 3.0))


def test_a_record_of_the_wrong_width_is_refused(tmp_path):
    sp = HistorySpool(tmp_path, NAMES)
    with pytest.raises(ValueError, match="expected 6"):
        sp.append(0.0, 0, [np.array([1.0, 2.0]), np.array([3.0])])


def test_nothing_spooled_reads_as_none(tmp_path):
    assert read_history(tmp_path) is None


CASE = {"name": "c", "case_dir": "/nowhere", "run": {"end_time": 1.0}}


def test_the_ended_record_names_status_step_time_and_balances(tmp_path):
    spool_rows(tmp_path, 4)
    record_ended_run(CASE, tmp_path, "failed", "ale rank 0: SolverError: ...", started=0.0, ranks={"ale": 1})
    s = json.loads((tmp_path / "summary.json").read_text())
    assert (s["status"], s["steps"], s["end_time"], s["requested_end_time"]) == ("failed", 3, 3e-3, 1.0)
    assert s["message"].startswith("ale rank 0")
    assert s["conservation"] == {"energy_rel": 3e-16, "mass_rel": 0.0}
    with h5py.File(tmp_path / "diagnostics.h5") as h:
        np.testing.assert_array_equal(h["step"][()], [0, 1, 2, 3])
        assert h["step"].dtype == np.int64


def test_a_completed_summary_of_this_run_is_kept(tmp_path):
    """A failure after the coupler wrote its own summary (at a solver's close): the completed record stays."""
    spool_rows(tmp_path, 2)
    (tmp_path / "summary.json").write_text(json.dumps({"status": "completed", "steps": 9}))
    record_ended_run(CASE, tmp_path, "failed", "x", started=0.0, ranks={})
    assert json.loads((tmp_path / "summary.json").read_text())["steps"] == 9


def test_a_run_that_ended_before_its_first_record():
    s = ended_summary(CASE, None, "interrupted", "interrupted by SIGTERM during start-up", 1.5, {"ale": 2})
    assert (s["status"], s["steps"], s["end_time"], s["conservation"]) == ("interrupted", 0, 0.0, {})
