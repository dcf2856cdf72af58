"""Cut zones that are (mostly) void get no constraint (variants.MIN_FILL, LS-DYNA's FRCMIN): nothing
there pushes on the surface, and the nodes of nearly empty zones have nearly no mass, so a constraint
would throw them at any speed. The background reports each cut zone's fill (the share of its open
volume held by material) after the cut-zone forces (solvers/ale/solver.py interface)."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.coupling.embedded import EmbeddedCoupling
from orchestrator.coupling.inprocess import InProcess, surface_of
from orchestrator.coupling.operators import restrict
from solvers.lagrange.solver import LagrangeSolver
from tests.conftest import CASES


def _coupling(tmp_path, min_fill=None):
    case = tmp_path / f"box_{min_fill}"
    shutil.copytree(CASES / "closed_box_body", case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    extra = "" if min_fill is None else f"min_fill = {min_fill!r}\n"
    p.write_text(p.read_text().replace('condition = "slip"\n', 'condition = "slip"\n' + extra))
    c = load_case(case)
    from mpi4py import MPI

    lag = LagrangeSolver(MPI.COMM_SELF, c)
    ec = EmbeddedCoupling(c, surface_of(lag))
    ec.geometry()
    return ec, lag


def _background(ec, fill, mass=1e-120):
    """v* = 0 on nodes of (nearly) no mass, no cut-zone force, the given fill per cut zone."""
    nb, nc, dim = ec.ops.bnodes.size, ec.ops.n_zones, ec.dim
    return np.concatenate([np.zeros(nb * dim), np.full(nb, mass), np.zeros(nc * dim), fill])


def test_zones_below_the_fill_get_no_constraint(tmp_path):
    """The closed-box block (moving at (34.64, 20) m/s) with every cut zone empty: by default no
    impulse anywhere, the block keeps its velocity exactly, and the coupler counts every cut zone
    as void; with min_fill = 0 the constraint acts on nodes of 1e-120 kg (their velocity change
    from the impulse is of the block's speed: ~40 m/s on nodes that weigh nothing -- in a run, next
    to heavier nodes, ~1e5 m/s and an inverted zone). Zones at fill 0.5 keep their constraint."""
    ec, lag = _coupling(tmp_path)
    nc = ec.ops.n_zones
    v = lag.surface_state("v").copy()
    imp = ec.solve(1e-5, 1e-5, v, _background(ec, np.zeros(nc)))
    assert ec.void_zones == nc > 0
    assert not np.any(imp) and not np.any(ec.imp_b)

    ec0, _ = _coupling(tmp_path, 0.0)
    assert ec0.method.min_fill == 0.0
    ec0.solve(1e-5, 1e-5, v, _background(ec0, np.zeros(nc)))
    assert ec0.void_zones == 0
    dv = np.abs(ec0.imp_b / 1e-120).max()
    assert dv > 1.0, dv

    half = np.where(np.arange(nc) % 2 == 0, 0.5, 0.0)  # every other zone half full
    ec.solve(1e-5, 1e-5, v, _background(ec, half, mass=1e-3))
    assert ec.void_zones == nc - np.count_nonzero(half)
    assert np.abs(ec.imp_b).max() > 0.0


def test_restrict_keeps_the_rows_asked_for_and_their_pairs(tmp_path):
    ec, _ = _coupling(tmp_path)
    ops = ec.ops
    keep = np.arange(ops.n_zones) % 3 != 0
    r = restrict(ops, keep)
    assert np.array_equal(r.zones, ops.zones[keep]) and np.array_equal(r.bnodes, ops.bnodes)
    assert (r.Bb - ops.Bb[np.flatnonzero(keep)]).nnz == 0 and (r.Bf - ops.Bf[np.flatnonzero(keep)]).nnz == 0
    # the pairs: exactly those of two kept zones, as zone ids
    old = {tuple(ops.zones[p]) for p in ops.pairs if keep[p].all()}
    assert {tuple(r.zones[p]) for p in r.pairs} == old and len(old) > 0


@pytest.mark.parametrize("value", [1.0, -0.1, "a"])
def test_a_bad_min_fill_is_refused_naming_it(value):
    from orchestrator.coupling import variants

    with pytest.raises(ValueError, match="min_fill"):
        variants.make({"method": "multiplier", "min_fill": value})


def test_a_gas_without_void_reports_full_zones(tmp_path):
    """Without void the fill is 1 everywhere: nothing is dropped (one in-process step)."""
    c = load_case(CASES / "closed_box_body")
    r = InProcess(c)
    r.advance(0.9 * min(r.lag.stable_dt(), r.ale.stable_dt()))
    assert r.coupling.void_zones == 0
    nb, nc, dim = r.coupling.ops.bnodes.size, r.coupling.ops.n_zones, r.coupling.dim
    fill = r.ale.interface()[nb * (dim + 1) + nc * dim:]
    assert fill.size == nc and np.all(fill == 1.0)


def test_the_background_reports_the_material_share_of_each_cut_zone(tmp_path):
    """The closed-box block with void above y = 0.25 (half-way up the block; zones 0.01 tall, so no
    zone is split): the cut zones below report fill 1, those above 0; the step drops the latter."""
    from tests.cases.test_coupled_cases import closed_box_with_void_above

    r = InProcess(load_case(closed_box_with_void_above(tmp_path, 0.25)))
    c, ale = r.coupling, r.ale
    ale.predict(1e-7)
    nb, nc, dim = c.ops.bnodes.size, c.ops.n_zones, c.dim
    fill = ale.interface()[nb * (dim + 1) + nc * dim:]
    yc = (c.ops.zones // 100 + 0.5) * 0.01  # 100 x 60 zones of 0.01
    assert np.array_equal(fill, (yc < 0.25).astype(float)), np.column_stack([yc, fill])
    assert 0 < np.count_nonzero(fill) < nc
