"""The pieces of multi-rate stepping (orchestrator/coupling/multirate.py, adapters/substeps.py): the
force ramp a substepping body feels and what it sums to, the rigid mean's answer the solve assumes,
the substep counts' rules, the passes' relaxation, and the Lagrangian solver's snapshot."""
from __future__ import annotations

import numpy as np
import pytest

from adapters.substeps import substeps
from orchestrator.coupling.multirate import Ramp, Relaxation, SubstepCounts, needed
from orchestrator.step_control import WINDOW


class RigidNodes:
    """Free point masses stepped as the Lagrangian solver steps them (predict: v* = v; correct:
    v += impulse / m, x += h v): the rigid body the solve's mobility is exact for."""

    def __init__(self, m, v):
        self.m = np.asarray(m, dtype=float)[:, None]
        self.v = np.array(v, dtype=float)
        self.x = np.zeros_like(self.v)

    def step(self, h, t, imp):
        self.v += imp / self.m
        self.x += h * self.v


def run_ramp(ramp, impulse, v0, m_nodes):
    body = RigidNodes(m_nodes, v0)
    buf = ramp.shape(impulse)
    n = impulse.size
    v_mean, work, v_end = substeps(body.step, lambda: body.v.copy(), ramp.m, ramp.dt, 1.0,
                                   buf[:n].reshape(impulse.shape), buf[n:].reshape(impulse.shape), v0)
    return body, v_mean, work, v_end


@pytest.mark.parametrize("m", [2, 7, 64])
@pytest.mark.parametrize("with_previous", [False, True])
def test_the_ramp_sums_to_its_total_and_the_rigid_mean_answers_it_by_c(m, with_previous):
    """Over the substeps the ramp gives the body dt F^n + dt^2 / (2 dt_prev) (F^n - F^{n-1}) (Ramp.total,
    to 1e-15 of it), the work it does is the kinetic energy it gave (the time-centred velocities:
    exact for point masses: round-off of the kinetic energy), the end velocity is v0 + total / m, and the mean velocity
    moves by exactly c I / m per unit impulse (the solve's mobility: a planted c without the ramp's
    (1 + rho s_k) weights is 40-46 % off here)."""
    rng = np.random.default_rng(m)
    dt, dt_prev = 1.0e-3, 0.9e-3
    dt_avg = 0.5 * (dt + dt_prev)
    f_prev = rng.normal(size=(3, 2)) if with_previous else None
    ramp = Ramp(m, dt, dt_prev, dt_avg, f_prev)
    mass = np.array([2.0, 3.0, 0.5])
    v0 = rng.normal(size=(3, 2))
    I = rng.normal(size=(3, 2)) * 1e-3
    body, v_mean, work, v_end = run_ramp(ramp, I, v0, mass)
    total = ramp.total(I)
    # (m additions: round-off m eps |v|; measured 3.1e-15 at m = 64)
    np.testing.assert_allclose(v_end, v0 + total / mass[:, None], rtol=0, atol=4e-16 * m * np.abs(v_end).max())
    ke = 0.5 * np.sum(mass[:, None] * (v_end ** 2 - v0 ** 2))
    assert abs(work - ke) <= 1e-14 * float(np.sum(mass[:, None] * v0 ** 2))   # (of the kinetic energy)
    np.testing.assert_allclose(body.x, dt * v_mean, rtol=1e-13)
    # the mean's answer to the impulse: linear with slope c / m (the F^{n-1} part held)
    _, v_mean0, _, _ = run_ramp(ramp, np.zeros_like(I), v0, mass)
    np.testing.assert_allclose(v_mean - v_mean0, ramp.c * I / mass[:, None], rtol=0, atol=1e-14)
    if not with_previous:   # no slope: the plain mean of (k+1)/m over the substeps
        assert ramp.c == pytest.approx(dt * (m + 1) / (2 * m) / dt_avg, rel=1e-14)


def test_a_steady_force_gives_the_steady_impulse_and_nothing_in_transit_but_half_a_step():
    """Steady steps and force: the ramp is flat (slope 0), the body gets dt F a step, what the
    background gets (dt_avg = dt), so nothing more goes into transit after the first step."""
    F = np.array([[1.0, -2.0]])
    ramp = Ramp(8, 1e-3, 1e-3, 1e-3, F)
    I = 1e-3 * F
    assert np.all(ramp.shape(I)[2:] == 0.0)
    np.testing.assert_allclose(ramp.total(I), I, rtol=1e-15)


def test_substep_counts_rise_at_once_and_fall_after_the_window():
    c = SubstepCounts(["lagrange"], max_substeps=64)
    assert c.update(1.0, {"lagrange": 0.3})["lagrange"] == 4
    assert c.update(1.0, {"lagrange": 0.1})["lagrange"] == 10          # a rise: at once
    got = [c.update(1.0, {"lagrange": 0.3})["lagrange"] for _ in range(WINDOW)]
    assert got[:-1] == [10] * (WINDOW - 1) and got[-1] == 4            # a fall: once it held
    assert c.update(1.0, {"lagrange": 1e-9})["lagrange"] == 64         # at most max_substeps
    state = c.state()
    d = SubstepCounts(["lagrange"], max_substeps=64)
    d.load(state)
    assert d.m == c.m and list(d.recent["lagrange"]) == list(c.recent["lagrange"]) and d.total == c.total
    assert needed(1.0, 1.0) == 1 and needed(1.0 + 1e-14, 1.0) == 1 and needed(1.01, 1.0) == 2


def test_aitken_relaxation_takes_out_the_slow_mode_of_the_passes():
    """The passes' fixed point with the rigid estimate over-estimating the body's answer: plain
    passes converge by 1 - g per pass on a mode the body answers with g of the estimate; Aitken's
    omega takes a 1-D slow mode out at the second relaxed pass (measured: plain 0.9^k, 1e-15 at 3)."""
    g = np.array([0.1, 0.1])            # the body answers 10 % of what the estimate assumes
    target = np.array([1.0, -2.0])

    def passes(relaxed, n=6):
        x, rel = np.zeros(2), Relaxation()
        out = []
        for _ in range(n):
            r = g * (target - x)         # what the solve after the pass would still change
            out.append(float(np.abs(target - x).max()))
            x = x + (rel.next(r) if relaxed else 1.0) * r
        return out

    plain, aitken = passes(False), passes(True)
    assert plain[-1] > 0.5 and aitken[3] < 1e-12, (plain, aitken)


def test_the_lagrangian_solvers_snapshot_takes_it_back_bit_for_bit(tmp_path):
    """snapshot -> 5 steps -> restore -> the same 5 steps: every state array and scalar as after the
    first five (the substeps' passes start each from the snapshot); a planted restore that leaves the
    hourglass state (hgq) out ends with other positions."""
    from mpi4py import MPI

    from orchestrator.case import load_case
    from solvers.lagrange.solver import LagrangeSolver

    (tmp_path / "case.toml").write_text("""
[run]
dimension = 2
end_time = 1.0
[materials.steel]
model = "johnson_cook"
density = 7830.0
youngs_modulus = 206.9e9
poisson_ratio = 0.3
yield_stress = 2.0e8
hardening_modulus = 6.14e8
hardening_exponent = 0.168
strain_rate_coefficient = 0.0089
reference_strain_rate = 1.0
thermal_exponent = 1.1
melt_temperature = 1813.15
room_temperature = 293.15
specific_heat = 460.0
taylor_quinney = 0.9
[[lagrange.bodies]]
name = "bar"
material = "steel"
mesh = { box = { lower = [0.0, 0.0], upper = [0.01, 0.002], cells = [10, 2] } }
initial_velocity = ["300.0 * x / 0.01", "50.0"]
""")
    lag = LagrangeSolver(MPI.COMM_SELF, load_case(tmp_path))

    def steps(n):
        for k in range(n):
            lag.predict(0.5 * lag.stable_dt())
            lag.correct(step=k + 1, time=lag.time + lag.dt)
        return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in vars(lag).items()
                if isinstance(v, (np.ndarray, float, int, bool))}

    steps(3)
    snap = lag.snapshot()
    first = steps(5)
    lag.restore(snap)
    again = steps(5)
    for k, a in first.items():
        b = again[k]
        assert (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b), k
    assert float(np.abs(first["eps_p"]).max()) > 0.0   # (plastic flow: the state that matters moved)


def test_the_coupling_step_is_bounded_by_max_substeps_and_substeps_pay_beside_enough_zones():
    """SubstepCounts.bound: max_substeps times the smallest substepping group's step (inf without
    one); pays: at least PAYS (4) zones per element of the group (multirate.py: the cost model) and,
    by default, a stable step at least MIN_RATIO (4) times below the background's."""
    from orchestrator.coupling.multirate import DEFAULT_ON, MIN_RATIO, PAYS, pays

    c = SubstepCounts(["lagrange", "other"], max_substeps=16)
    assert c.bound({"lagrange": 1e-6, "other": 3e-6}) == pytest.approx(16e-6, rel=1e-15)
    assert SubstepCounts([], max_substeps=16).bound({}) == float("inf")
    assert pays(4000.0, 1000.0) and not pays(3999.0, 1000.0) and PAYS == 4.0
    assert pays(4000.0, 1000.0, 4.0) and not pays(4000.0, 1000.0, 3.99) and MIN_RATIO == 4.0 and DEFAULT_ON
