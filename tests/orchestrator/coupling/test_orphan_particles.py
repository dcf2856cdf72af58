"""Particles the reconstructed surface leaves out (orchestrator/coupling/orphan_particles.py): found
where no body blocks their zone, tied to the background velocity at their position by one sparse
solve, equal and opposite impulses, the kinetic energy removed that of an inelastic collision."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.coupling.embedded import EmbeddedCoupling
from orchestrator.coupling.grid import Grid
from orchestrator.coupling.orphan_particles import DENSITY_RATIO, MAX_COMPRESSION, find_orphans, may_tie, tie
from orchestrator.coupling.particle_operators import particle_interface
from tests.conftest import CASES
from tests.orchestrator.coupling.test_particle_operators import _ball


@pytest.mark.parametrize("dim", [2, 3])
def test_a_body_has_no_orphans_a_sheet_and_a_stray_particle_do(dim):
    """A ball of particles (h = 2 dx, 2.5 particles a zone) lies inside its reconstructed surface to
    the last particle: no orphan.  A sheet one particle thick and a lone particle far from it do not
    reach the iso value at any node: every one of them is an orphan, with multilinear weights that
    sum to 1 and interpolate its position exactly."""
    grid = Grid([0.0] * dim, [1.0] * dim, [16] * dim)
    dx = 1.0 / 40
    x, vol = _ball(dim, 0.2, dx, np.full(dim, 0.35))
    nb = len(x)
    sheet = np.stack(np.meshgrid(*([np.arange(0.1, 0.9, dx)] * (dim - 1)), indexing="ij"), -1).reshape(-1, dim - 1)
    sheet = np.column_stack([sheet, np.full(len(sheet), 0.8)])          # the plane x_dim = 0.8, far from the ball
    sheet = sheet[np.linalg.norm(sheet - 0.35, axis=1) > 0.35]
    stray = np.full((1, dim), 0.7)
    stray[0, -1] = 0.55
    xa = np.vstack([x, sheet, stray])
    va = np.full(len(xa), dx ** dim)
    pi = particle_interface(grid, xa, va, 2.0 * dx)
    orph = find_orphans(grid, xa, pi.coverage)
    assert np.array_equal(orph.index, np.arange(nb, len(xa)))
    assert np.allclose(orph.weights.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    node_x = grid.node_ijk(orph.nodes) * grid.h + grid.lower                # (no, 2^dim, dim)
    assert np.allclose(np.einsum("pc,pcd->pd", orph.weights, node_x), xa[orph.index], rtol=0, atol=1e-14)
    # the ball alone: none
    pib = particle_interface(grid, x, vol, 2.0 * dx)
    assert find_orphans(grid, x, pib.coverage).size == 0


def test_one_orphan_in_four_nodes_is_an_inelastic_collision():
    """A particle of mass m_p at u in a zone's centre (N = 1/4) with four nodes of mass m at rest:
    both end at m_p u / (m_p + 4 m) (the inelastic collision of m_p with 4 m), the impulses sum to
    zero and the energy removed is (1/2) m_p 4m / (m_p + 4m) u^2."""
    grid = Grid([0.0, 0.0], [1.0, 1.0], [2, 2])
    x = np.array([[0.25, 0.25]])

    class Nothing:  # no body blocks any zone
        zones = np.zeros(0, np.int64)
        total = fractions = np.zeros(0)
        run_start = run_length = np.zeros(0, np.int64)

    orph = find_orphans(grid, x, Nothing)
    assert orph.size == 1 and np.allclose(orph.weights, 0.25)
    m_p, m, u = 3.0, 2.0, np.array([[5.0, -1.0]])
    nodes = np.unique(orph.nodes)
    cols = np.searchsorted(nodes, orph.nodes)
    u_b, m_b = np.zeros((nodes.size, 2)), np.full(nodes.size, m)
    rho_p = np.array([m_b.sum() / 0.25])        # a background exactly as dense as the particle
    J, imp_b, n, removed = tie(orph, cols, u, np.array([m_p]), rho_p, u_b, m_b, grid.zone_volume)
    assert n == 1
    final = m_p * u / (m_p + 4 * m)
    assert np.allclose(u + J / m_p, final, rtol=1e-14, atol=0)
    assert np.allclose(imp_b / m_b[:, None], final, rtol=1e-14, atol=0)
    assert np.abs(J.sum(axis=0) + imp_b.sum(axis=0)).max() <= 1e-14 * np.abs(J).max()
    assert removed == pytest.approx(0.5 * m_p * 4 * m / (m_p + 4 * m) * float(np.sum(u * u)), rel=1e-14)
    # a background lighter than DENSITY_RATIO of the particle is left alone
    J, imp_b, n, removed = tie(orph, cols, u, np.array([m_p]), rho_p / (0.99 * DENSITY_RATIO), u_b, m_b,
                               grid.zone_volume)
    assert n == 0 and not np.any(J) and not np.any(imp_b) and removed == 0.0


def _tate_coupling(tmp_path, stray_at):
    """The 2-D Tate case's coupling with the rod's particles and one more steel particle at
    ``stray_at`` (in the aluminium: an eroded fragment)."""
    case = load_case(CASES / "tate_penetration_rate")
    sph = case["sph"]
    dx = sph["spacing"]
    ax = (np.arange(8) + 0.5) * dx, 0.02506 + (np.arange(80) + 0.5) * dx
    x = np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 2)
    x = np.vstack([x, stray_at])
    n = len(x)
    v = np.tile([0.0, -911.0], (n, 1))
    surface = {"facets": np.zeros((0, 2), np.int64), "body": np.zeros(0, np.int64), "volume": np.full(n, dx * dx),
               "smoothing_length": sph["smoothing_length"], "mass": np.full(n, 7850.0 * dx * dx),
               "free": np.ones(n * 2), "x": x, "v": v}
    return EmbeddedCoupling(case, surface), v


@pytest.mark.parametrize("density", [2700.0, 1.2])
def test_a_fragment_in_the_target_moves_with_it(tmp_path, density):
    """A steel particle left 5 mm deep in the aluminium, moving at the rod's 911 m/s: the coupler asks
    the background for its zone's nodes, and after the step its velocity is the background's at its
    position; the momentum it gives is what the nodes take (to round-off). In a background of air
    density (1.2 kg/m^3, below DENSITY_RATIO of steel) it flies on untouched."""
    ec, v = _tate_coupling(tmp_path, [[20.5 * 2.5e-4, 80.5 * 2.5e-4]])   # a zone's centre
    geom = ec.geometry()
    assert ec.orphans is not None and np.array_equal(ec.orphans.index, [len(v) - 1])
    assert np.all(np.isin(ec.orphans.nodes, geom.nodes))
    nn, nc, dim = geom.nodes.size, geom.cut.size, 2
    m_node = density * ec.grid.zone_volume
    background = np.concatenate([np.zeros(nn * dim), np.full(nn, m_node), np.zeros(nc * dim), np.ones(nc)])
    imp = ec.solve(1e-8, 1e-8, v, background)
    p = len(v) - 1
    imp_b = ec.imp_b
    if density < DENSITY_RATIO * 7850.0:
        assert ec.tied_orphans == 0 and not np.any(imp[p])
        return
    assert ec.tied_orphans == 1
    u_p = v[p] + imp[p] / ec.mass[p]
    cols = np.searchsorted(geom.nodes, ec.orphans.nodes[0])
    u_b = ec.orphans.weights[0] @ (imp_b[cols] / m_node)
    assert np.allclose(u_p, u_b, rtol=1e-12, atol=1e-12 * 911.0)   # measured: equal to ~1e-13
    # at its zone's centre, alone on its four nodes: the inelastic collision with them
    final = -911.0 * ec.mass[p] / (ec.mass[p] + 4 * m_node)
    assert u_p == pytest.approx([0.0, final], rel=1e-12, abs=1e-12)
    # equal and opposite: the particles' total impulse against the nodes'
    total = imp.sum(axis=0) + imp_b.sum(axis=0)
    assert np.abs(total).max() <= 1e-12 * np.abs(imp).sum()


def test_the_lookup_is_skipped_where_no_background_could_tie_a_particle():
    """Water particles (1000 kg/m^3) in air (1.2) never meet a background of a tenth of their
    density short of a ~80-fold compression: the coupling does not look for orphans (the embedded
    dam break). Steel in aluminium does; so does water in air fed by a dense enough inflow."""
    air = {"regions": [{"material": "air", "density": 1.2, "pressure": 1e5}], "boundaries": {"x_lower": "wall"}}
    assert not may_tie(air, 1000.0)
    assert may_tie({"regions": [{"material": "al", "density": 2700.0}]}, 7850.0)
    dense = DENSITY_RATIO * 1000.0 / MAX_COMPRESSION
    inflow = dict(air, boundaries={"x_lower": {"inflow": {"density": dense, "velocity": [1.0, 0.0], "pressure": 1e5}}})
    assert may_tie(inflow, 1000.0) and not may_tie(inflow, 1000.0 * 1.01)
    # the coupling follows it: the Tate case's rod in aluminium looks
    ec, _ = _tate_coupling(None, [[0.005, 0.02]])
    assert ec.find_orphans
