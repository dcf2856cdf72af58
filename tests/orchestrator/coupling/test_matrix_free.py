"""The multiplier solve without the assembled H (orchestrator.coupling.matrix_free): the same system as
the assembled solve (orchestrator.coupling.solve), so the same multipliers and impulses to round-off."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.coupling import matrix_free as MF
from orchestrator.coupling import solve as S
from tests.orchestrator.coupling.test_solve import _circle_ops, _ops, _random_state


def _close(a, b, tol):
    return np.abs(a - b).max() <= tol * max(np.abs(b).max(), 1e-300)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("condition", ["tied", "slip"])
def test_equal_to_the_assembled_solve_with_void_nodes(dim, condition):
    """Random masses (10 % void background nodes), velocities and warm start: λ, both impulses and the
    dissipation equal to 1e-13 relative (measured <= 6.3e-16), the same CG iterations."""
    ops = _ops(dim, 1 / 16 if dim == 2 else 1 / 6, seed=7)
    m_b, m_f, v_b, v_f = _random_state(ops, 8, void_fraction=0.1)
    dt = 0.3 * ops.width
    rng = np.random.default_rng(9)
    k = 1 if condition == "slip" else dim
    warm = (ops.zones[::2], rng.normal(size=(ops.zones[::2].size, k)))
    a = S.solve(ops, m_b, m_f, v_b, v_f, dt, condition, warm=warm)
    b = MF.solve(ops, m_b, m_f, v_b, v_f, dt, condition, S.ALPHA, S.BETA, warm=warm)
    assert a.iterations == b.iterations > 3
    for x, y in ((b.lam, a.lam), (b.impulse_b, a.impulse_b), (b.impulse_f, a.impulse_f)):
        assert _close(x, y, 1e-13)
    assert abs(b.dissipation - a.dissipation) <= 1e-13 * a.dissipation
    assert b.residual <= S.RTOL


@pytest.mark.parametrize("condition", ["tied", "slip"])
def test_rigid_translation_exactly_zero_and_impulses_equal_and_opposite(condition):
    ops = _circle_ops()
    m_b, m_f, v_b, v_f = _random_state(ops, 3)
    u = np.array([0.37, -1.3])
    z = MF.solve(ops, m_b, m_f, np.tile(u, (ops.bnodes.size, 1)), np.tile(u, (ops.Bf.shape[1], 1)), 0.01,
                 condition, S.ALPHA, S.BETA)
    assert not np.any(z.lam) and z.iterations == 0
    s = MF.solve(ops, m_b, m_f, v_b, v_f, 0.01, condition, S.ALPHA, S.BETA)
    total = s.impulse_b.sum(axis=0) + s.impulse_f.sum(axis=0)
    assert np.abs(total).max() <= 1e-14 * np.abs(s.impulse_f).sum(axis=0).max()  # measured 3.4e-17


def test_the_iteration_cap_is_a_clear_error_and_bad_masses_are_refused():
    ops = _circle_ops()
    m_b, m_f, v_b, v_f = _random_state(ops, 4)
    with pytest.raises(S.MultiplierSolveError, match="no convergence in 2 CG iterations"):
        MF.solve(ops, m_b, m_f, v_b, v_f, 0.01, "tied", S.ALPHA, S.BETA, max_iter=2)
    bad = m_b.copy()
    bad[3] = -1.0
    with pytest.raises(ValueError, match="background mass -1.0"):
        MF.solve(ops, bad, m_f, v_b, v_f, 0.01, "tied", S.ALPHA, S.BETA)
