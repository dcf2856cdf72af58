"""Element erosion (``[lagrange] bodies[i].erosion = { strain = ... }``, solvers/lagrange/kernels.py
``_erode``): a soft bar driven into a rigid wall at twice its wave speed inverts its first elements
and stops the run without erosion; with erosion those elements erode instead, the run goes on, the
nodal energy balance stays at round-off, the eroded elements' internal energy is booked, the surface
is rebuilt from the live elements (closed, outward) when renewed, and a restart is bitwise; coupled,
the coupler takes the new surface and the coupled momentum balance holds."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from solvers.lagrange import kernels
from solvers.lagrange.solver import LagrangeSolver, SolverError
from tests.solvers.lagrange.test_solver import make_case

SOFT = {"model": "linear_elastic", "density": 1000.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}
WALL = [{"type": "rigid_wall", "point": [0.0, 0.0], "normal": [0.0, 1.0]}]
C = (1.0e7 * 0.7 / (1.3 * 0.4) / 1000.0) ** 0.5   # the bar's dilatational wave speed, 116 m/s


def bar(erosion=None):
    case = make_case(2, {"box": {"lower": [0.0, 0.0], "upper": [0.002, 0.02], "cells": [4, 40]}}, SOFT,
                     velocity=[0.0, -2.0 * C], boundaries=WALL)
    case["lagrange"]["bodies"][0]["erosion"] = erosion
    return case


def run(s: LagrangeSolver, steps: int, first: int = 0) -> float:
    t = s.time
    for n in range(first, first + steps):
        dt = 0.8 * s.stable_dt()
        t += dt
        s.predict(dt)
        s.correct(None, step=n + 1, time=t)
    return t


def test_without_erosion_the_crushed_bar_stops_naming_an_element():
    s = LagrangeSolver(MPI.COMM_SELF, bar())
    with pytest.raises(SolverError, match="inverted or invalid element"):
        run(s, 400)


def test_eroded_elements_leave_the_run_going_and_balanced():
    """10 steps: the front of crushed elements has eroded the end next to the wall (40 of 160
    elements, measured), 400 steps: all of them, and the free nodes go on at the last stable step."""
    s = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 0.8}))
    run(s, 10)
    d = s.diagnostics()
    ne = s.n_cells_global
    assert 8 <= d["eroded_elements"] < ne / 2, d["eroded_elements"]
    assert d["eroded_elements"] == ne - int(s.alive.sum())
    # the eroded elements are the crushed end: all of them nearer the wall than any live one
    y = s.X[s.conn].mean(axis=1)[:, 1]
    assert y[s.alive == 0].max() < y[s.alive == 1].min()
    # the nodal balance KE + W_int = KE0 + W_ext holds through the erosions (measured 0 and 2.1e-16)
    assert abs(d["energy_balance_rel"]) < 1e-14, d["energy_balance_rel"]
    # the eroded elements' internal energy is booked: sum e_int over the dead ones, > 0 (crushed)
    assert d["eroded_internal_energy"] == float(s.e_int[s.alive == 0].sum()) > 0.0
    # an eroded element gives no force: its strain stops growing, its bulk viscosity is 0
    assert np.all(s.q[s.alive == 0] == 0.0)
    # some reached the strain, the others would have inverted within one step (the wall's row at
    # twice the wave speed): both erode (measured 24 and 16 of 40); every live one is below it
    eps_dead = s.eps_eq[s.alive == 0]
    assert (eps_dead >= 0.8).any() and (eps_dead < 0.8).any() and np.all(s.eps_eq[s.alive == 1] < 0.8)
    assert np.array_equal(s.cell_fields()["eroded"], 1.0 - s.alive)
    e_dead, eps_dead = s.e_int[s.alive == 0].copy(), s.eps_eq[s.alive == 0].copy()
    dead = s.alive == 0
    run(s, 390, first=10)
    assert np.array_equal(s.e_int[dead], e_dead) and np.array_equal(s.eps_eq[dead], eps_dead)
    d = s.diagnostics()
    assert d["eroded_elements"] == ne and s.renew_surface() and s.surface()["facets"].shape == (0, 2)
    assert np.isfinite(s.stable_dt()) and abs(d["energy_balance_rel"]) < 1e-14


def test_the_surface_is_rebuilt_from_the_live_elements_closed_and_outward():
    s = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 0.8}))
    first = s.surface()
    assert s.surface_version == 0
    run(s, 10)
    # the surface the coupler has is kept until it is renewed (the step's state goes out on it)
    assert s.surface_stale and s.surface() is first and s.surface_version == 0
    assert s.renew_surface() and not s.surface_stale and s.surface_version == 1
    assert not s.renew_surface()
    surf = s.surface()
    assert len(surf["facets"]) < len(first["facets"]) or not np.array_equal(surf["node_ids"], first["node_ids"])
    # closed: every surface node ends exactly two segments; outward: the signed area the segments
    # enclose (at the reference positions) is the live elements' reference area
    f = surf["node_ids"][surf["facets"]]
    counts = np.bincount(f.ravel())
    assert set(counts[counts > 0]) == {2}
    p, q = s.X[f[:, 0]], s.X[f[:, 1]]
    enclosed = 0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1])
    live_area = float(s.vol0[s.alive == 1].sum())
    assert enclosed == pytest.approx(live_area, rel=1e-12)


def test_restart_with_eroded_elements_is_bitwise(tmp_path):
    a = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 0.8}))
    run(a, 5)
    assert 0 < a.eroded
    a.checkpoint(tmp_path / "c.h5")
    run(a, 10, first=5)
    assert a.eroded < a.n_cells_global
    b = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 0.8}))
    b.restart(tmp_path / "c.h5")
    run(b, 10, first=5)
    for k in ("x", "v", "sig", "e_int", "alive", "eps_eq"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert (a.eroded, a.surface_version) == (b.eroded, b.surface_version)
    a.renew_surface()
    b.renew_surface()
    assert np.array_equal(a.surface()["facets"], b.surface()["facets"])


def test_the_kernel_erodes_on_strain_and_on_inversion_and_skips_the_dead():
    """One quad stretched along x (d_xx = 0.5/dt, plane strain) over one step: an effective strain
    increment of sqrt(2/3 ((1/3)^2 + (1/6)^2 + (1/6)^2)) = 1/3: eroded with the limit below that,
    alive above; an eroded element adds no force; an inverting one erodes with erosion on and is
    reported without it."""
    X = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    conn = np.array([[0, 1, 2, 3]], np.int64)
    gradN0, vol0 = kernels.reference_gradients(X, conn)
    codes = np.array([kernels.LINEAR_ELASTIC])
    from solvers.lagrange import materials as M

    par = np.zeros((1, M.NPAR))
    par[0, M.P_RHO], par[0, M.P_G], par[0, M.P_K] = 1000.0, 1.0e6, 2.0e6
    dt = 1.0e-3
    v = np.array([[0.0, 0.0], [0.5 / dt, 0.0], [0.5 / dt, 0.0], [0.0, 0.0]])

    def call(limit, x=X, erode_dt=0.0):
        alive, eps = np.ones(1, np.uint8), np.zeros(1)
        f = np.zeros((4, 2))
        out = kernels.element_forces_cut(
            x.copy(), v, dt, conn, np.zeros(1, np.int64), codes, par, gradN0, vol0, np.array([1000.0]),
            np.zeros((1, 6)), np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), 0.1, 0.06, 1.5, f,
            np.full(1, -1, np.int64), np.zeros((0, 4, 2)), alive, eps, np.full(1, limit), np.full(1, erode_dt),
            np.zeros(1, np.uint8), np.zeros((1, 3)))
        return out, alive[0], eps[0], f

    x_now = X + 0.5 * dt * v   # so that the mid-step configuration x - dt/2 v is the unit square
    (dtm, bad, n, _), alive, eps, f = call(0.33, x_now)
    assert (bad, n, alive) == (-1, 1, 0) and dtm == np.inf and not f.any()
    assert eps == pytest.approx(1.0 / 3.0, rel=1e-12)
    (dtm, bad, n, _), alive, eps, f = call(0.34, x_now)
    assert (bad, n, alive) == (-1, 0, 1) and np.isfinite(dtm) and f.any()
    # erosion by the stable step (erosion.time_step): below the limit it erodes, above it lives
    (_, bad, n, _), alive, _, f = call(0.34, x_now, erode_dt=dtm * (1.0 + 1e-9))
    assert (bad, n, alive) == (-1, 1, 0) and not f.any()
    (_, bad, n, _), alive, _, f = call(0.34, x_now, erode_dt=dtm * (1.0 - 1e-9))
    assert (bad, n, alive) == (-1, 0, 1) and f.any()
    inverted = X[[1, 0, 3, 2]]
    (dtm, bad, n, _), alive, _, f = call(0.34, inverted)
    assert (bad, n, alive) == (-1, 1, 0) and not f.any()
    (dtm, bad, n, _), alive, _, _ = call(np.inf, inverted)
    assert (bad, n, alive) == (0, 0, 1)


def test_erosion_by_time_step_keeps_the_step_above_its_share_of_the_first(tmp_path):
    """erosion.time_step = 0.5: a crushed element erodes once its stable step falls below half the
    solver's first one (LS-DYNA's TSMIN, ERODE = 1), so the step never does while an element lives
    (measured: its lowest 0.72 of the first, all 160 elements eroded in 60 steps, energy balance
    2.1e-16; with the strain limit alone, 10 here, the step fell to 0.007 of the first before the
    crushed elements inverted); a restart from step 10 is bitwise."""
    lone = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 10.0, "time_step": 0.0001}))
    dt0 = lone.stable_dt()
    lowest = dt0
    for n in range(60):
        run(lone, 1, first=n)
        if lone.alive.any():
            lowest = min(lowest, lone.stable_dt())
    assert lowest < 0.05 * dt0, lowest / dt0
    s = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 10.0, "time_step": 0.5}))
    assert np.all(s.erode_dt == 0.5 * dt0)
    for n in range(60):
        if n == 10:
            s.checkpoint(tmp_path / "c.h5")
        run(s, 1, first=n)
        if s.alive.any():
            assert s.stable_dt() >= 0.5 * dt0
    d = s.diagnostics()
    assert d["eroded_elements"] > 0 and abs(d["energy_balance_rel"]) < 1e-14, d
    r = LagrangeSolver(MPI.COMM_SELF, bar({"strain": 10.0, "time_step": 0.5}))
    r.restart(tmp_path / "c.h5")
    run(r, 50, first=10)
    for k in ("x", "v", "sig", "alive"):
        assert np.array_equal(getattr(r, k), getattr(s, k)), k


@pytest.mark.mpi
def test_eroding_on_n_ranks_equals_one_rank():
    """The bar cut across ranks (elements at the cut erode: their corner forces leave the ordered
    shared sums): 25 steps on every rank of the world equal one rank bit for bit, the same elements
    eroded, the same surface."""
    world = MPI.COMM_WORLD
    runs = {}
    for name, comm in (("one", MPI.COMM_SELF), ("all", world)):
        s = LagrangeSolver(comm, bar({"strain": 0.8}))
        run(s, 25)
        if comm.size > 1:  # the erosion front has crossed the ranks' cut
            assert comm.allreduce(int(((s._cut_row >= 0) & (s.alive == 0)).sum())) > 0
        s.renew_surface()
        runs[name] = (s.gather_nodes(s.x), s.gather_cells(s.alive), s.eroded, s.surface()["facets"],
                      s.diagnostics()["eroded_internal_energy"])
    if world.rank != 0:
        return
    (x1, a1, n1, f1, e1), (xn, an, nn, fn, en) = runs["one"], runs["all"]
    assert 0 < n1 == nn < len(a1)
    assert np.array_equal(a1, an) and np.array_equal(x1, xn) and np.array_equal(f1, fn)
    assert en == pytest.approx(e1, rel=1e-13)
