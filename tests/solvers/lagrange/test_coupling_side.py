"""The Lagrangian solver's side of the embedded-mesh coupling: its surface (nodes, outward facets,
bodies, full lumped masses), the surface state gathered on every rank, the coupler's surface impulse
applied to every rank's copies with exact balances, the adapter hooks, and the failure messages a
coupled run needs. MPI tests run on all ranks of COMM_WORLD (partitioned under mpiexec -n 2) and
compare with a one-rank solver built on COMM_SELF in the same process."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from solvers.lagrange.solver import LagrangeSolver, SolverError
from solvers.lagrange.surface import facet_area_vectors

SOFT = {"model": "linear_elastic", "density": 1000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3}
RUBBER = {"model": "neo_hookean", "density": 1000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3}


def box(lower, upper, cells):
    return {"box": {"lower": list(lower), "upper": list(upper), "cells": list(cells)}}


def make_case(dim, bodies, materials, boundaries=()):
    """bodies: (name, material, mesh, initial_velocity or None)."""
    return {"name": "t", "case_dir": ".", "run": {"dimension": dim, "end_time": 1.0},
            "materials": {k: dict(v) for k, v in materials.items()},
            "lagrange": {"bodies": [{"name": n, "material": m, "mesh": mesh,
                                     "initial_velocity": v or [0.0] * dim} for n, m, mesh, v in bodies]},
            "boundaries": list(boundaries)}


def step(s: LagrangeSolver, n: int, t: float, dt: float, surface_impulse=None) -> float:
    s.predict(dt)
    s.correct(None, step=n, time=t + dt, surface_impulse=surface_impulse)
    return t + dt


# ---- the surface ---------------------------------------------------------------------------------
def test_surface_of_two_bodies():
    """Two 2-D boxes: a = [0, 0.2] x [0, 0.1] in 4 x 2 cells (rho 1000), b = [0.3, 0.4] x [0, 0.3] in
    2 x 3 cells (rho 3000). Surface nodes: 12 of a's 15, 10 of b's 12; facets 12 and 10; every facet
    names its body and lies on it; nodal mass = (cells at the node) x m_e / 4; per body the outward
    facets have zero net area vector, length = perimeter, and enclose the body's area."""
    dense = dict(SOFT, density=3000.0)
    case = make_case(2, [("a", "soft", box([0, 0], [0.2, 0.1], [4, 2]), None),
                         ("b", "dense", box([0.3, 0], [0.4, 0.3], [2, 3]), None)],
                     {"soft": SOFT, "dense": dense})
    s = LagrangeSolver(MPI.COMM_SELF, case)
    surf = s.surface()
    ids, facets, body, mass = surf["node_ids"], surf["facets"], surf["body"], surf["mass"]
    assert np.all(np.diff(ids) > 0)
    assert np.count_nonzero(ids < 15) == 12 and np.count_nonzero(ids >= 15) == 10
    assert facets.shape == (22, 2) and np.count_nonzero(body == 0) == 12 and np.count_nonzero(body == 1) == 10
    assert np.array_equal(ids[facets] >= 15, np.repeat(body[:, None] == 1, 2, axis=1))

    cells_at = np.bincount(s.global_cells.ravel(), minlength=s.n_nodes_global)[ids]
    m_e = np.where(ids < 15, 1000.0 * 0.05 * 0.05, 3000.0 * 0.05 * 0.1)
    np.testing.assert_allclose(mass, cells_at * m_e / 4, rtol=4e-15, atol=0)  # measured 8.9e-16

    x = s.surface_state("x")
    for b, perimeter, area in ((0, 0.6, 0.02), (1, 0.8, 0.03)):
        f = facets[body == b]
        a = facet_area_vectors(x, f)
        assert np.abs(a.sum(axis=0)).max() <= 1e-16  # measured 1.4e-17 / 0
        assert np.linalg.norm(a, axis=1).sum() == pytest.approx(perimeter, rel=1e-15)  # measured 2.2e-16 / 0
        enclosed = 0.5 * np.einsum("fi,fi->", x[f].mean(axis=1), a)
        assert enclosed == pytest.approx(area, rel=3e-15)  # measured 2.2e-16 / 6.7e-16
    assert surf is s.surface()  # computed once


# ---- partition invariance -------------------------------------------------------------------------
def exact_case():
    """Masses that every partition sums exactly: unit cells of density 8 (each node gets 1 per cell),
    at rest (zero forces at the first step). Two bodies so that a body index crosses ranks."""
    mat = dict(SOFT, density=8.0, youngs_modulus=1e3)
    return make_case(3, [("block", "m", box([0, 0, 0], [2, 2, 4], [2, 2, 4]), None),
                         ("cube", "m", box([3, 0, 0], [4, 1, 1], [1, 1, 1]), None)], {"m": mat})


def all_copies(s: LagrangeSolver, a: np.ndarray):
    """Every rank's copy of every node it holds: (global ids, values) of all ranks, on every rank."""
    got = s.comm.allgather((s.part.nodes, a))
    return np.concatenate([g[0] for g in got]), np.concatenate([g[1] for g in got])


@pytest.mark.mpi
def test_surface_state_and_impulse_partition_invariant_bitwise():
    """On COMM_WORLD (2 ranks under mpiexec) the surface, the gathered surface positions and
    velocities and the state after a surface impulse equal those of one rank bit for bit (the masses
    are sums of ones, so no sum depends on the partition); the gathered arrays equal the nodes' own
    values; every copy of a shared node receives the impulse; v^{n+1/2} = v* + J / m exactly."""
    world = MPI.COMM_WORLD
    runs = {}
    for name, comm in (("one", MPI.COMM_SELF), ("all", world)):
        s = LagrangeSolver(comm, exact_case())
        surf = s.surface()
        ns = len(surf["node_ids"])
        imp = np.random.default_rng(7).standard_normal((ns, 3))  # the same array on every rank
        x0 = s.surface_state("x")
        dt = 0.5 * s.stable_dt()
        s.predict(dt)
        v_star = s.surface_state("v")
        s.correct(surface_impulse=imp, step=1, time=dt)
        x1, v1 = s.surface_state("x"), s.surface_state("v")
        # the gathered surface rows are the nodes' own values (the owners' copies)
        ids, v_copies = all_copies(s, s.v)
        _, x_copies = all_copies(s, s.x)
        for gathered, copies in ((v1, v_copies), (x1, x_copies)):
            pos = np.searchsorted(surf["node_ids"], ids)
            on = (pos < ns) & (surf["node_ids"][np.minimum(pos, ns - 1)] == ids)
            assert np.array_equal(copies[on], gathered[pos[on]])  # every copy, shared ones included
        assert np.array_equal(v_star, np.zeros_like(v_star))
        assert np.array_equal(v1, v_star + imp * (1.0 / surf["mass"])[:, None])
        assert np.array_equal(x1, x0 + dt * v1)
        assert np.all(np.isin(surf["mass"], [1.0, 2.0, 4.0]))  # corners, edges, faces of unit cells
        full_v = s.gather_nodes(s.v)
        runs[name] = (surf, x0, v_star, x1, v1, comm.bcast(full_v, root=0), s.diagnostics())
    (s1, *a1, d1), (sn, *an, dn) = runs["one"], runs["all"]
    for k in ("node_ids", "facets", "body", "mass"):
        assert np.array_equal(s1[k], sn[k]), k
    for u, w in zip(a1, an):
        assert np.array_equal(u, w)
    for d in (d1, dn):
        assert abs(d["energy_balance_rel"]) < 1e-15  # measured 0 / 0 (1 / 2 ranks)
        assert d["momentum_balance_rel"] < 1e-15     # measured 0 / 0
        assert d["angular_momentum_balance_rel"] < 2e-15  # measured 4.1e-16 / 1.3e-16


def spinning_case():
    """A free rubber block spinning and stretching (stresses build up within a few steps)."""
    return make_case(3, [("block", "rubber", box([-0.05, -0.04, -0.03], [0.05, 0.04, 0.03], [4, 3, 3]),
                          ["2 - 100*y + 30*x", "1 + 100*x", "0.5 - 20*z"])], {"rubber": RUBBER})


@pytest.mark.mpi
def test_uniform_surface_impulse_changes_momentum_by_its_sum():
    """A uniform impulse J on every surface node of a free, stressed, spinning body: the momentum
    changes by ns J and the angular momentum by sum x^n x J (internal forces add nothing but
    round-off); the balances (energy, momentum, angular momentum) stay at round-off."""
    s = LagrangeSolver(MPI.COMM_WORLD, spinning_case())
    ns = len(s.surface()["node_ids"])
    t = 0.0
    for n in range(20):
        t = step(s, n + 1, t, 0.9 * s.stable_dt())
    assert s.comm.allreduce(np.abs(s.sig).max(), op=MPI.MAX) > 1e4  # stressed
    p0, l0 = s.momentum(), s.angular_momentum()
    J = np.array([0.3, -0.2, 0.1]) * np.linalg.norm(p0) / ns  # total impulse ~ the momentum itself
    x_n = s.surface_state("x")
    t = step(s, 21, t, 0.9 * s.stable_dt(), surface_impulse=np.tile(J, (ns, 1)))
    dp = s.momentum() - p0
    dl = s.angular_momentum() - l0
    total = ns * J
    # measured on 1 / 2 ranks: 6.0e-16 / 1.1e-15
    assert np.linalg.norm(dp - total) <= 1e-14 * np.linalg.norm(total)
    torque = np.cross(x_n, J).sum(axis=0)
    assert np.linalg.norm(dl - torque) <= 2e-15 * np.linalg.norm(l0)  # measured 4.2e-16 / 2.4e-16
    d = s.diagnostics()
    assert abs(d["energy_balance_rel"]) < 2e-15         # measured 0 / 0
    assert d["momentum_balance_rel"] < 2e-15            # measured 3.3e-16 / 1.7e-16
    assert d["angular_momentum_balance_rel"] < 2e-15    # measured 3.1e-16 / 2.3e-16
    # the accumulated external impulse is the coupling impulse (no other reaction acts)
    assert np.linalg.norm(s.impulse - total) <= 4e-15 * np.linalg.norm(total)  # measured 1.1e-15 / 4.6e-16


@pytest.mark.mpi
def test_coupled_cycle_partitioned_equals_one_rank():
    """40 steps of predict -> v* of the surface -> an impulse computed from it (a drag of the surface
    towards a rest frame, like a constraint would apply) -> correct: COMM_WORLD equals one rank to
    round-off (the sums on shared nodes differ in order only), balances at round-off."""
    runs = {}
    for name, comm in (("one", MPI.COMM_SELF), ("all", MPI.COMM_WORLD)):
        s = LagrangeSolver(comm, spinning_case())
        m = s.surface()["mass"][:, None]
        t = 0.0
        for n in range(40):
            dt = 0.9 * s.stable_dt()
            s.predict(dt)
            imp = -0.02 * m * s.surface_state("v")
            t += dt
            s.correct(surface_impulse=imp, step=n + 1, time=t)
        runs[name] = (s.surface_state("x"), s.surface_state("v"), s.diagnostics())
    (x1, v1, d1), (xn, vn, dn) = runs["one"], runs["all"]
    assert np.abs(xn - x1).max() <= 2e-15 * np.abs(x1).max()  # measured 3.9e-16 (2 ranks)
    assert np.abs(vn - v1).max() <= 2e-13 * np.abs(v1).max()  # measured 3.1e-14 (2 ranks)
    for d in (d1, dn):
        assert abs(d["energy_balance_rel"]) < 2e-15         # measured <= 1.7e-16
        assert d["momentum_balance_rel"] < 2e-15            # measured <= 3.7e-16
        assert d["angular_momentum_balance_rel"] < 2e-15    # measured <= 5.5e-16
    assert d1["external_work"] < -0.1 * d1["kinetic_energy"]  # the drag really took energy out


# ---- the adapter ------------------------------------------------------------------------------------
def test_adapter_hooks(tmp_path):
    """surface() / interface() after predict (v*) / correct(surface impulse) / positions() (x^{n+1}
    = x^n + dt (v* + J / m), bit for bit), and the uncoupled correct(None)."""
    from adapters.lagrange import LagrangeAdapter

    a = LagrangeAdapter(MPI.COMM_SELF, spinning_case(), tmp_path)
    a.setup()
    surf = a.surface()
    ns = len(surf["node_ids"])
    x0 = a.positions()
    dt = 0.9 * a.stable_dt()
    a.predict(dt, 1, dt)
    v_star = a.interface()["v"]
    assert v_star.shape == (ns, 3) and np.abs(v_star).max() > 1.0
    imp = np.random.default_rng(3).standard_normal((ns, 3)) * surf["mass"][:, None]
    a.correct(imp)
    assert np.array_equal(a.positions(), x0 + dt * (v_star + imp * (1.0 / surf["mass"])[:, None]))
    a.predict(dt, 2, 2 * dt)
    a.correct(None)
    assert a.diagnostics()["momentum_balance_rel"] < 1e-14
    with pytest.raises(ValueError, match=rf"surface impulse must have shape \({ns}, 3\), got \(3,\)"):
        a.predict(dt, 3, 3 * dt)
        a.correct(np.ones(3))


# ---- failures ---------------------------------------------------------------------------------------
def test_inverted_element_names_body_element_step_time():
    """The second body's corner node thrown into its element at 100 times the wave speed: the error
    names the global element, the body and its own element number, the step and the time."""
    case = make_case(3, [("first", "soft", box([0, 0, 0], [0.02, 0.01, 0.01], [2, 1, 1]), None),
                         ("second", "soft", box([0.05, 0, 0], [0.06, 0.01, 0.01], [2, 2, 2]),
                          ["where((x > 0.0599) and (y > 0.0099) and (z > 0.0099), -1e4, 0)", 0.0, 0.0])],
                     {"soft": SOFT})
    case["lagrange"].update(bulk_viscosity_linear=0.0, bulk_viscosity_quadratic=0.0, hourglass=0.0)  # (no bounce)
    s = LagrangeSolver(MPI.COMM_SELF, case)
    with pytest.raises(SolverError, match=r"element 9 at step [1-9], t=[0-9.e-]+ s "
                                          r"\(body 'second', its element 7;"):
        t = 0.0
        for n in range(1000):
            t = step(s, n + 1, t, 0.9 * s.stable_dt())


def test_non_finite_surface_impulse_names_body_node_step_time():
    case = make_case(2, [("first", "soft", box([0, 0], [0.02, 0.01], [2, 1]), None),
                         ("second", "soft", box([0.05, 0], [0.06, 0.01], [2, 2]), None)],
                     {"soft": SOFT})
    s = LagrangeSolver(MPI.COMM_SELF, case)
    ids = s.surface()["node_ids"]
    imp = np.zeros((len(ids), 2))
    k = int(np.flatnonzero(ids == 6 + 5)[0])  # node 5 of the second body (the first has 6 nodes)
    imp[k, 1] = np.nan
    dt = 0.5 * s.stable_dt()
    s.predict(dt)
    with pytest.raises(SolverError, match=r"non-finite velocity at node 11 at step 1, t=[0-9.e-]+ s "
                                          r"\(body 'second', its node 5\)"):
        s.correct(surface_impulse=imp, step=1, time=dt)
