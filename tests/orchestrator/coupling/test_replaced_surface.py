"""A Lagrangian foreground's surface replaced in the coupler after elements eroded
(EmbeddedCoupling.replace_surface, sent by adapters/runtime.py after the step's state): the next
geometry is the one a coupling built on the new surface from the start would have, whatever the old
surface was."""
from __future__ import annotations

import shutil

import numpy as np

from orchestrator.case import load_case
from orchestrator.coupling.embedded import EmbeddedCoupling
from orchestrator.coupling.inprocess import surface_of
from solvers.lagrange.solver import LagrangeSolver
from tests.conftest import CASES


def test_a_replaced_surface_gives_the_geometry_of_a_fresh_coupling(tmp_path):
    from mpi4py import MPI

    case = tmp_path / "box"
    shutil.copytree(CASES / "closed_box_body", case, ignore=shutil.ignore_patterns("out"))
    c = load_case(case)
    c["lagrange"]["bodies"][0]["erosion"] = {"strain": 1.0e9}   # (on, never reached: eroded by hand)
    lag = LagrangeSolver(MPI.COMM_SELF, c)
    ec = EmbeddedCoupling(c, surface_of(lag))
    before = ec.geometry()
    # a row of the block's elements gone (its lower edge): the surface of the rest
    y = lag.X[lag.conn].mean(axis=1)[:, 1]
    lag.alive[y < y.min() + 1e-12] = 0
    lag.surface_stale = True
    assert lag.renew_surface()
    new = surface_of(lag)
    assert len(new["node_ids"]) < len(lag.X)   # (an interior node count: the surface is a subset)
    ec.replace_surface(new)
    after = ec.geometry()
    fresh = EmbeddedCoupling(c, new)
    ref = fresh.geometry()
    assert ec.ns == fresh.ns and ec.mass.shape == (fresh.ns,) and ec.imp_f.shape == (fresh.ns, ec.dim)
    assert before.run_start.size > after.run_start.size   # the covered zones: the lower edge moved up
    for k in ("zones", "fractions", "cut", "nodes", "velocity", "run_start", "run_length"):
        assert np.array_equal(getattr(after, k), getattr(ref, k)), k
    assert (ec.ops.Bf != fresh.ops.Bf).nnz == 0 and (ec.ops.Bb != fresh.ops.Bb).nnz == 0
