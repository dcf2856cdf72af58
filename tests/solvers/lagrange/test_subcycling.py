"""Element subcycling (solvers/lagrange/subcycling.py): the refined-corner cantilever against the
single-rate step, the levels, the balances, restarts and ranks."""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from orchestrator.case import CaseError, load_case
from solvers.lagrange.mesh import box_mesh, drawn_toward
from solvers.lagrange.solver import LagrangeSolver
from solvers.lagrange.subcycling import SubcyclingSolver, cheapest_share
from tests.solvers.lagrange.test_solver import make_case

CASES = Path(__file__).resolve().parents[3] / "cases"
STEEL = {"model": "linear_elastic", "density": 7850.0, "youngs_modulus": 200e9, "poisson_ratio": 0.3}


def beam(tmp: Path, cells=(40, 4), drawn=True, ratio=16) -> dict:
    """The shipped case's cantilever (200 x 20 mm, clamped at x = 0, 25 x^2 m/s across), its mesh
    drawn toward the clamped corner over 3 elements with power 3 (the corner element 8 times
    smaller) or not."""
    mesh = box_mesh([0.0, 0.0], [0.2, 0.02], list(cells))
    if drawn:
        mesh = drawn_toward(mesh, (0.0, 0.0), 3 * 0.2 / cells[0], 3.0)
    path = tmp / f"beam_{cells[0]}_{int(drawn)}.vtu"
    meshio.write(path, meshio.Mesh(np.c_[mesh.points, np.zeros(len(mesh.points))], [("quad", mesh.cells)]))
    return make_case(2, {"file": str(path)}, STEEL, velocity=[0.0, "25.0 * x * x"],
                     boundaries=[{"type": "fixed", "region": "x < 1e-9"}], subcycling=ratio)


def tip(s) -> float:
    top = s.X[:, 0] >= 0.2 - 1e-12
    return float(np.mean(s.x[top, 1] - s.X[top, 1])) if top.any() else np.nan   # (a rank without the tip)


def advance(s, t_end: float, t: float = 0.0, n: int = 0, scale: float = 0.9):
    """Steps of scale x the stable step to t_end; returns (t, n, [(t, tip)])."""
    hist = []
    while t < t_end * (1.0 - 1e-12):
        dt = min(scale * s.stable_dt(), t_end - t)
        s.predict(dt)
        t += dt
        n += 1
        s.correct(None, step=n, time=t)
        hist.append((t, tip(s)))
    return t, n, np.array(hist)


def test_the_shipped_mesh_is_the_documented_drawn_toward_box():
    """cases/cantilever_refined_corner/beam.vtu is what its case.toml says it is."""
    m = meshio.read(CASES / "cantilever_refined_corner" / "beam.vtu")
    want = drawn_toward(box_mesh([0.0, 0.0], [0.2, 0.02], [80, 8]), (0.0, 0.0), 0.0075, 3.0)
    assert np.array_equal(m.cells_dict["quad"], want.cells)
    assert np.allclose(m.points[:, :2], want.points, rtol=0.0, atol=1e-14)   # (12 digits in the file)


def test_drawn_toward_keeps_the_faces_through_the_point_and_shrinks_the_corner():
    m = box_mesh([0.0, 0.0], [0.2, 0.02], [80, 8])
    d = drawn_toward(m, (0.0, 0.0), 0.0075, 3.0)
    on_faces = (m.points[:, 0] == 0.0) | (m.points[:, 1] == 0.0)
    assert np.all((d.points[on_faces, 0] == 0.0) | (d.points[on_faces, 1] == 0.0))
    far = np.linalg.norm(m.points, axis=1) >= 0.0075
    assert np.array_equal(d.points[far], m.points[far])
    # the corner element: its far node at r = 2.5 sqrt(2) mm moves to 7.5 (r / 7.5)^3 on its ray
    i = int(np.argmin(np.linalg.norm(m.points - 2.5e-3, axis=1)))
    assert d.points[i] == pytest.approx(m.points[i] * (np.hypot(2.5e-3, 2.5e-3) / 7.5e-3) ** 2, rel=1e-12)


def test_without_a_smaller_element_it_is_the_single_rate_step_bit_for_bit(tmp_path):
    """Every element alike (a box mesh): one level, one substep; 200 steps equal the explicit
    solver's bit for bit (positions, velocities, stresses, the balances' works)."""
    case = beam(tmp_path, drawn=False)
    a, b = LagrangeSolver(MPI.COMM_SELF, case), SubcyclingSolver(MPI.COMM_SELF, case)
    assert b.levels == 0 and b.stable_dt() == a.stable_dt()
    t_end = 200 * 0.9 * a.stable_dt()
    for s in (a, b):
        advance(s, t_end)
    for k in ("x", "v", "sig", "e_int", "hgq"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert (a.w_int, a.w_ext, a.step) == (b.w_int, b.w_ext, b.step)


def test_the_cheapest_share_keeps_a_cluster_of_like_elements_in_one_level():
    """Rows at 8.48 and 9 times the corner's step (the cantilever's, r = 0.9 of that): at share 1
    they would split between levels 2 and 3; the share that advances fastest, 0.947 (the bin edge
    below 7.63 / 8), puts all of them at level 3.  A body already in whole levels keeps share 1."""
    r = np.r_[0.9, 2.2, 3.5, np.full(96, 0.9 * 8.48), np.full(56, 0.9 * 9.0)]
    s = cheapest_share(r, 4)
    assert s == pytest.approx(2.0 ** (59 / 64 - 1), rel=1e-15) and s <= 0.9 * 8.48 / 8 < 2.0 ** (60 / 64 - 1)
    levels = np.clip(np.floor(np.log2(r / s)), 0, 4)
    assert np.all(levels[3:] == 3) and list(levels[:3]) == [0, 1, 1]
    assert cheapest_share(np.r_[0.9, np.full(100, 0.9 * 8.9)], 4) == 1.0
    assert cheapest_share(np.full(10, 0.9), 4) == 1.0


def test_the_refined_corner_cantilever_follows_the_single_rate_run(tmp_path):
    """The cantilever refined toward its clamped corner (40 x 4, the corner element 8 times smaller)
    over 1 ms (its first peak and back): 8 substeps a step, the corner's 8 elements at the finer
    levels and the rest at level 3 (element evaluations 0.16 of every element at every substep);
    the tip within 5e-4 of its peak of the single-rate run (measured 1.8e-4; levels split at a bin's
    edge, share 1: 6.6e-3); the energy balance to round-off and no energy made; the momentum the
    nodal partition does not conserve is the reported subcycling_impulse to round-off, and small
    (measured 4.3e-5 of the gross impulse: the clamp's)."""
    case = beam(tmp_path)
    a, b = LagrangeSolver(MPI.COMM_SELF, case), SubcyclingSolver(MPI.COMM_SELF, case)
    assert b.levels == 3 and list(np.bincount(b.element_level)) == [4, 4, 7, 145]
    _, na, ha = advance(a, 1e-3)
    _, nb, hb = advance(b, 1e-3)
    assert na / nb == pytest.approx(8.0, rel=0.05)
    peak = np.abs(ha[:, 1]).max()
    err = np.abs(np.interp(hb[:, 0], ha[:, 0], ha[:, 1]) - hb[:, 1]).max() / peak
    assert err < 5e-4, err
    d = b.diagnostics()
    assert d["subcycling_substeps"] == 8.0 and d["subcycling_element_share"] < 0.2
    assert abs(d["energy_balance_rel"]) < 1e-13 and d["created_energy_share"] < 0.0
    p = b.momentum()
    residual = np.linalg.norm(p - b.p0 - b.impulse - b.subcycling_impulse) / float(b.impulse_gross[0])
    assert residual < 1e-13, residual
    assert d["subcycling_impulse_rel"] == pytest.approx(d["momentum_balance_rel"], rel=1e-9)
    assert 0.0 < d["subcycling_impulse_rel"] < 1e-4, d["subcycling_impulse_rel"]
    print(f"tip {err:.3g}, subcycling impulse {d['subcycling_impulse_rel']:.3g}, share {d['subcycling_element_share']:.3g}")


def test_restart_between_steps_is_bitwise(tmp_path):
    """A checkpoint of the subcycled solver (its levels, their ages, each node's last step, the
    elements' steps, the loads in its forces) continues bit for bit, across a re-taking of the
    levels, under gravity and a traction pulse."""
    case = beam(tmp_path)
    case["lagrange"]["gravity"] = [0.0, -1.0e4]
    case["boundaries"] += [{"type": "traction", "region": "y > 0.02 - 1e-9 and x > 0.15", "traction": {"y": -2.0e5},
                            "curve": [[0.0, 0.0], [1e-5, 1.0], [2e-5, 0.0]]}]
    a = SubcyclingSolver(MPI.COMM_SELF, case)
    t, n, _ = advance(a, 57 * 2.4e-7)
    a.checkpoint(tmp_path / "c.h5")
    advance(a, t + 30 * 2.4e-7, t, n)
    b = SubcyclingSolver(MPI.COMM_SELF, case)
    b.restart(tmp_path / "c.h5")
    assert b.since_rebin != 0
    advance(b, t + 30 * 2.4e-7, t, n)
    for k in ("x", "v", "sig", "e_int", "hgq", "own_level", "node_level", "subcycling_impulse"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert (a.w_int, a.w_ext, a.w_gravity, a.w_load, a.share, a.stable_dt()) == (
        b.w_int, b.w_ext, b.w_gravity, b.w_load, b.share, b.stable_dt())


@pytest.mark.mpi
def test_on_n_ranks_equals_one_rank(tmp_path_factory):
    """The cantilever cut across the ranks (levels of the shared nodes: the smallest over every
    rank's elements): 60 steps on every rank of the world equal one rank bit for bit."""
    world = MPI.COMM_WORLD
    tmp = Path(world.bcast(str(tmp_path_factory.mktemp("sub")) if world.rank == 0 else None))
    case = beam(tmp) if world.rank == 0 else None
    case = world.bcast(case)
    runs = {}
    for name, comm in (("one", MPI.COMM_SELF), ("all", world)):
        s = SubcyclingSolver(comm, case)
        advance(s, 60 * 2.4e-7)
        runs[name] = (s.gather_nodes(s.x), s.gather_nodes(s.v), s.gather_cells(s.sig), s.levels, s.step)
    if world.rank != 0:
        return
    (x1, v1, s1, k1, n1), (xn, vn, sn, kn, nn) = runs["one"], runs["all"]
    assert (k1, n1) == (kn, nn) == (3, n1)
    assert np.array_equal(x1, xn) and np.array_equal(v1, vn) and np.array_equal(s1, sn)


def test_coupled_bodies_are_refused_in_one_line(tmp_path):
    """Subcycling is the standalone explicit solver's for now: a coupled case with it says so."""
    text = (CASES / "plate_in_shock_2d" / "case.toml").read_text()
    assert "\n[lagrange]\n" not in text
    case = tmp_path / "case"
    case.mkdir()
    (case / "case.toml").write_text(text.replace("[[lagrange.bodies]]", "[lagrange]\nsubcycling = 8\n\n"
                                                 "[[lagrange.bodies]]", 1))
    with pytest.raises(CaseError) as ei:
        load_case(case)
    assert ei.value.key == "lagrange.subcycling" and "not with [coupling] yet" in str(ei.value)
    assert "\n" not in str(ei.value)


def test_a_bar_bouncing_off_a_rigid_wall_on_its_refined_corner(tmp_path):
    """The refined-corner beam thrown at 10 m/s against a rigid wall with its corner first: every
    node is held at the wall over its own step (no node crosses it), and over the impact and the
    rebound (90 us: the bar's contact lasts about 2 L / c = 74 us) the far end's motion and the body's
    momentum follow the single-rate run as closely as the coarse step itself does (measured: far
    end 1.7e-3 of its travel, momentum 5.3e-4 of the initial; the same bar on a uniform mesh at its
    own step against 8 times finer: 1.8e-3 and 3.2e-4, the wall's contact resolved at the step;
    single-rate at 0.9 against 0.45 of the step: 3.6e-5, 3.4e-6), the energy balance (the wall's
    reactions booked) to round-off and no energy made."""
    case = beam(tmp_path)
    case["boundaries"] = [{"type": "rigid_wall", "point": [-1e-6, 0.0], "normal": [1.0, 0.0]}]
    case["lagrange"]["bodies"][0]["initial_velocity"] = [-10.0, 0.0]
    a, b = LagrangeSolver(MPI.COMM_SELF, case), SubcyclingSolver(MPI.COMM_SELF, case)
    far = a.X[:, 0] >= 0.2 - 1e-12

    def far_x(s):
        return float(np.mean(s.x[far, 0]))

    out = {}
    for name, s in (("single", a), ("sub", b)):
        t, n, hist = 0.0, 0, []
        while t < 90e-6 * (1.0 - 1e-12):
            dt = min(0.9 * s.stable_dt(), 90e-6 - t)
            s.predict(dt)
            t += dt
            n += 1
            s.correct(None, step=n, time=t)
            hist.append((t, far_x(s)))
            assert s.x[:, 0].min() >= -1e-6 - 1e-12
        out[name] = (np.array(hist), s.momentum()[0], n)
    (ha, pa, na), (hb, pb, nb) = out["single"], out["sub"]
    assert b.levels == 3 and na > 6 * nb
    p0 = float(a.p0[0])
    assert pa > 0.5 * abs(p0)   # (it rebounds)
    travel = np.ptp(ha[:, 1])
    err = np.abs(np.interp(hb[:, 0], ha[:, 0], ha[:, 1]) - hb[:, 1]).max() / travel
    assert err < 4e-3, err
    assert abs(pb - pa) / abs(p0) < 1.5e-3, (pa, pb)
    d = b.diagnostics()
    assert abs(d["energy_balance_rel"]) < 1e-13 and d["created_energy_share"] < 1e-3, d
    print(f"far end {err:.3g}, momentum {abs(pb - pa) / abs(p0):.3g}, steps {na} / {nb}")


def test_gravity_and_a_traction_pulse_follow_the_single_rate_run(tmp_path):
    """The clamped refined-corner beam at rest under a deceleration of 10^4 m/s^2 and a hat pulse of
    traction (peak 2e5 Pa over its last quarter's top face, 0.2 ms): each node gets them at its own
    kicks, evaluated at its own times, booked as the single-rate step books them.  Over 1 ms the tip
    follows the single-rate run within 2e-5 of its peak (measured 4.2e-6), the energy balance
    (gravity's and the loads' work in it) closes to round-off, no energy is made (beyond the
    staggering of the sums), and the momentum
    balance less what the partition does not conserve (subcycling_impulse) closes to round-off of
    the gross impulse; gravity's and the loads' work equal the single-rate run's within 1.5e-4
    (measured 3.6e-5, 1.8e-6)."""
    case = beam(tmp_path)
    case["lagrange"]["bodies"][0]["initial_velocity"] = [0.0, 0.0]
    case["lagrange"]["gravity"] = [0.0, -1.0e4]
    case["boundaries"] += [{"type": "traction", "region": "y > 0.02 - 1e-9 and x > 0.15", "traction": {"y": -2.0e5},
                            "curve": [[0.0, 0.0], [1e-4, 1.0], [2e-4, 0.0]]}]
    a, b = LagrangeSolver(MPI.COMM_SELF, case), SubcyclingSolver(MPI.COMM_SELF, case)
    assert b.levels == 3
    _, na, ha = advance(a, 1e-3)
    _, nb, hb = advance(b, 1e-3)
    peak = np.abs(ha[:, 1]).max()
    err = np.abs(np.interp(hb[:, 0], ha[:, 0], ha[:, 1]) - hb[:, 1]).max() / peak
    assert err < 2e-5, err
    da, db = a.diagnostics(), b.diagnostics()
    # (created / supplied: 5.8e-5 against the single-rate -1.1e-5: kinetic energy at the half step
    # against the work to the mean velocity, half a step's work of the loads, the coarse nodes' steps 8
    # times the single-rate one; a growing mode reads 2 within a few steps, solvers/step_health.py)
    assert abs(db["energy_balance_rel"]) < 1e-13 and db["created_energy_share"] < 3e-4, db
    residual = np.linalg.norm(b.momentum() - b.p0 - b.impulse - b.subcycling_impulse) / float(b.impulse_gross[0])
    assert residual < 1e-13, residual
    for k in ("gravity_work", "load_work"):
        assert db[k] == pytest.approx(da[k], rel=1.5e-4), (k, da[k], db[k])
    print(f"tip {err:.3g}, gravity work {db['gravity_work'] / da['gravity_work'] - 1:.2g}, "
          f"load work {db['load_work'] / da['load_work'] - 1:.2g}, steps {na} / {nb}")
