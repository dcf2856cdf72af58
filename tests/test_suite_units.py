"""The parallel suite's units of work (tests/conftest.py): a module with a shared fixture stays on one
worker, so its fixture is built once; the Slurm tests run one at a time; everything else alone."""
from tests.conftest import _unit_of_work


def test_units_of_work():
    bad = "tests/orchestrator/test_bad_inputs.py"  # its module-scoped `results`: ~200 CLI calls
    assert _unit_of_work(f"{bad}::test_bad_input[end_time_nan-check]") == bad
    assert _unit_of_work(f"{bad}::test_bases_are_valid") == bad
    for nodeid in ("tests/orchestrator/campaign/test_slurm_engine.py::test_x",
                   "tests/orchestrator/test_slurm_run.py::test_y"):
        assert _unit_of_work(nodeid) == "slurm"
    alone = "tests/cases/test_campaigns.py::test_fe_vs_sph_bodies_penetrator_reaches_tates_depth"
    assert _unit_of_work(alone) == alone
