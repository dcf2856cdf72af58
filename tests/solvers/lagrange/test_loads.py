"""Surface loads in time (solvers/lagrange/loads.py SurfaceLoads: a traction times its curve) on the
explicit and the implicit integrators: a free block pushed sideways on one face by a pulse takes
exactly the impulse each scheme's discrete load history gives, and its balances book the loads'
work, impulse and moment."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from solvers.lagrange.implicit_dynamic import MidpointSolver, NewmarkSolver
from solvers.lagrange.loads import SurfaceLoads
from solvers.lagrange.solver import LagrangeSolver
from solvers.lagrange.surface import exterior_facets
from tests.solvers.lagrange.test_erosion import SOFT
from tests.solvers.lagrange.test_solver import make_case

# up from 0 to 1 at 1 ms, down to 0.5 at 2 ms, held there: not zero at the end (a hat that is would
# give the same sum with the load taken at either end of the steps)
PULSE = [[0.0, 0.0], [1e-3, 1.0], [2e-3, 0.5]]
T_Y = 1.0e5                                     # Pa along y on the face x = 0.1 (length 0.05 m)


def pushed_block(**lagrange):
    bc = [{"type": "traction", "region": "x > 0.1 - 1e-9", "traction": {"y": T_Y}, "curve": PULSE}]
    return make_case(2, {"box": {"lower": [0.0, 0.0], "upper": [0.1, 0.05], "cells": [4, 2]}}, SOFT,
                     boundaries=bc, **lagrange)


def pulse(t):
    return np.interp(t, *np.array(PULSE).T)


def test_the_curve_scales_the_traction_linearly_and_holds_its_end_values():
    P = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0], [0.0, 2.0]])
    C = np.array([[0, 1, 2, 3]])
    facets = exterior_facets(C, "quad", 4, P)[0]
    right = P[:, 0] > 0.5
    loads = SurfaceLoads(P, facets, [(right, np.array([0.0, 3.0])), (right, np.array([1.0, 0.0]))],
                         [[[1.0, 2.0], [3.0, 4.0]], None])
    for t, c in ((0.0, 2.0), (1.0, 2.0), (2.0, 3.0), (2.5, 3.5), (3.0, 4.0), (9.0, 4.0)):
        f = loads.at(t)
        # the face x = 1 is 2 m long: 3 Pa x 2 m x the curve, and the constant 1 Pa x 2 m
        np.testing.assert_allclose(f.sum(axis=0), [2.0, 6.0 * c], rtol=1e-15)
        np.testing.assert_array_equal(f[~right], 0.0)


def test_explicit_the_block_takes_the_leapfrogs_impulse_of_the_pulse():
    """v^{n+1/2} = v^{n-1/2} + F(t^n) dt_avg / m: the momentum after N steps is F sum_n c(t^n) dt_avg
    exactly (measured: equal; x 6.5e-17 of it); the balances close with the loads' impulse and
    moment booked (measured 1.9e-16, 6.5e-17, 1.1e-16)."""
    s = LagrangeSolver(MPI.COMM_SELF, pushed_block())
    dt = 0.5 * s.stable_dt()
    n = int(np.ceil(3e-3 / dt))
    for k in range(n):
        s.predict(dt)
        s.correct(None, step=k + 1, time=(k + 1) * dt)
    t = dt * np.arange(n)
    weights = np.full(n, dt)
    weights[0] = 0.5 * dt
    d = s.diagnostics()
    expected = T_Y * 0.05 * np.sum(pulse(t) * weights)
    assert d["momentum_y"] == pytest.approx(expected, rel=4e-16)
    assert abs(d["momentum_x"]) < 1e-15 * expected
    assert d["load_work"] > 0.0 and d["external_work"] == d["load_work"]
    for k in ("energy_balance_rel", "momentum_balance_rel", "angular_momentum_balance_rel"):
        assert abs(d[k]) < 1e-15, (k, d[k])


@pytest.mark.parametrize("solver", [MidpointSolver, NewmarkSolver])
def test_implicit_the_block_takes_the_pulses_whole_impulse(solver):
    """Steps of 0.25 ms land on the curve's points: the midpoint scheme's load at t_{n+1/2} and the
    trapezoid's mean of both ends integrate the piecewise linear pulse exactly, so the momentum is
    F x 1.75 ms at 3 ms (measured: equal / 6.7e-16 off); the midpoint balances close to the Newton tolerance
    (measured energy 1.0e-15, momentum 2.6e-16, angular 1.1e-16)."""
    s = solver(MPI.COMM_SELF, pushed_block(integrator=solver.scheme, time_step=2.5e-4))
    dt = 2.5e-4
    for k in range(12):
        s.predict(dt)
        s.correct(step=k + 1, time=(k + 1) * dt)
    d = s.diagnostics()
    assert d["momentum_y"] == pytest.approx(T_Y * 0.05 * 1.75e-3, rel=4e-15)
    if solver is MidpointSolver:
        for k in ("energy_balance_rel", "momentum_balance_rel", "angular_momentum_balance_rel"):
            assert abs(d[k]) < {"energy_balance_rel": 1e-14}.get(k, 2e-15), (k, d[k])
        assert d["load_work"] > 0.0
