"""The implicit integrators' step control (solvers/lagrange/implicit_dynamic.py, issue 12 item 4): a
step whose Newton iteration fails is done in halves (down to time_step_min, then the run stops by
name); the next step follows the Newton iterations (more than 8: halved, 3 or fewer: grown by 1.25 up
to time_step, split: the part that converged)."""
import numpy as np
import pytest
from mpi4py import MPI

from orchestrator.case import load_case
from solvers.lagrange import implicit_dynamic
from solvers.lagrange.implicit_step import StepFailed, StepResult
from solvers.lagrange.solver import SolverError
from tests.cases.test_cases import CASES


def _solver(monkeypatch, fail_above=None, iterations=None):
    """The spinning block's midpoint solver, its step function wrapped: failing (StepFailed) for dt
    above ``fail_above``, reporting ``iterations`` Newton iterations when given."""
    real = implicit_dynamic.MidpointSolver.step_function

    def step(*args, **kw):
        dt = args[5]
        if fail_above is not None and dt > fail_above * (1 + 1e-9):
            raise StepFailed("midpoint: Newton did not converge in 25 iterations (test)")
        res = real(*args, **kw)
        if iterations is not None:
            res = StepResult(u=res.u, v=res.v, iterations=iterations, residuals=res.residuals, reaction=res.reaction)
        return res

    monkeypatch.setattr(implicit_dynamic.MidpointSolver, "step_function", staticmethod(step))
    return implicit_dynamic.MidpointSolver(MPI.COMM_SELF, load_case(CASES / "spinning_block_midpoint"))


def _step(s, dt, k=1):
    s.predict(dt)
    s.correct(step=k, time=k * dt)
    return s.stable_dt() * 0.9 / (1 + 1e-12)   # the controller's next step (dt_scale 0.9)


def test_a_failed_step_is_done_in_halves_and_the_next_continues_at_the_half(monkeypatch):
    s = _solver(monkeypatch, fail_above=0.003)
    nxt = _step(s, 0.008)
    assert s.substeps == 4 and nxt == pytest.approx(0.002, rel=1e-12)   # 0.008 -> 4 x 0.002
    d = s.diagnostics()
    assert d["substeps"] == 4.0 and abs(d["energy_balance_rel"]) < 1e-12 and d["time_step"] == 0.008


def test_the_step_follows_the_newton_iterations(monkeypatch):
    s = _solver(monkeypatch, iterations=10)
    assert _step(s, 0.008) == pytest.approx(0.004, rel=1e-12)            # > 8: halved
    s = _solver(monkeypatch, iterations=3)
    s._dt_stable = 0.004 / 0.9 * (1 + 1e-12)
    assert _step(s, 0.004) == pytest.approx(0.005, rel=1e-12)            # <= 3: x 1.25
    s._dt_stable = 0.0075 / 0.9 * (1 + 1e-12)
    assert _step(s, 0.0075, 2) == pytest.approx(0.008, rel=1e-12)        # capped at time_step
    s = _solver(monkeypatch, iterations=5)
    assert _step(s, 0.008) == pytest.approx(0.008, rel=1e-12)            # 4 .. 8: kept


def test_the_contacts_active_set_changes_do_not_count_against_growing_the_step(monkeypatch):
    """4 Newton iterations of which 1 changed the contact's active set: 3 equilibrium iterations, the
    step grows by 1.25; 4 of which none did: kept."""
    s = _solver(monkeypatch)
    for changes, grown in ((1, 0.005), (0, 0.004)):
        s._dt_stable = 0.004 / 0.9 * (1 + 1e-12)
        s.iterations, s.equilibrium_iterations, s.substeps = 4, 4 - changes, 1
        s._control(0.004)
        assert s.stable_dt() * 0.9 / (1 + 1e-12) == pytest.approx(grown, rel=1e-12)


def test_below_time_step_min_the_run_stops_by_name(monkeypatch):
    s = _solver(monkeypatch, fail_above=1e-6)        # time_step_min = 0.008 / 1024 = 7.8e-6
    with pytest.raises(SolverError, match=r"midpoint step 1 .*halved down to lagrange.time_step_min = 7.8125e-06"):
        _step(s, 0.008)
    assert np.all(np.isfinite(s.vg))


def test_a_release_gives_the_energy_back_along_the_last_steps_rows_even_when_the_new_operator_lacks_them(tmp_path):
    """Step 3 gives a pair's stored energy back along the rows of B active at the episode's last
    step, kept from that step: the releasing step's operator need not have them (a rod's corner
    leaving a wall had dropped its row, and 8.2 J of a strike stayed lost). Here the coarse bars after
    5 steps in contact, then a release whose operator has no rows at all: all of the stored energy
    comes back into the kinetic energy (to round-off), none is booked lost."""
    import scipy.sparse as sp

    from solvers.lagrange.implicit_step import ContactState
    from tests.cases.test_cases import case_variant
    from tests.cases.test_implicit_cases import COARSE_BARS

    s = implicit_dynamic.MidpointSolver(MPI.COMM_SELF, load_case(case_variant(tmp_path, "bars_impact_implicit",
                                                                              *COARSE_BARS)))
    for k in range(1, 6):
        s.predict(1e-6)
        s.correct(step=k, time=k * 1e-6)
    stored = s.contact_stored
    assert stored > 0.1 and len(s._active_keys) > 0
    n = s.u.size
    ke = s.kinetic_energy()
    gone = ContactState(B=sp.csr_matrix((0, n)), keys=np.zeros(0, np.int64), p=np.zeros(0),
                        active=np.zeros(0, bool), force=np.zeros(n))
    s._contact_update(gone, np.zeros(n), 1e-6)
    s._sync_local()
    assert s.kinetic_energy() - ke == pytest.approx(stored, rel=1e-12)
    assert abs(s.contact_lost) < 1e-12 * stored and s.contact_stored == 0.0
