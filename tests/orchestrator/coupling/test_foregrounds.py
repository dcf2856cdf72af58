"""Several foreground groups behind one coupling (orchestrator/coupling/foregrounds.py): the merged
geometry the background gets, the rows of it each member gets back, and the refusal of bodies of two
groups that share a background zone or node (contact, not two independent solves)."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.coupling.foregrounds import merge_geometries
from orchestrator.coupling.geometry import GeometryError
from solvers.ale.coupled import BodyGeometry


def _geom(zones, fractions, cut, nodes, velocity, runs=((), ())):
    faces = ((np.array(zones[:1]), np.array([0.25])), (np.array([], np.int64), np.array([])))
    return BodyGeometry(np.array(zones), np.array(fractions, float), faces, np.array(cut), np.array(nodes),
                        np.array(velocity, float).reshape(-1, 2), np.array(runs[0], np.int64),
                        np.array(runs[1], np.int64))


def test_the_merged_geometry_is_the_union_in_sorted_order():
    a = _geom([5, 9], [0.5, 1.0], [5], [5, 6, 11, 12], [[1.0, 0.0]], runs=([40], [3]))
    b = _geom([2, 7], [0.25, 0.75], [2, 7], [2, 3, 8, 9, 13, 14], [[0.0, 2.0], [0.0, 3.0]], runs=([20], [2]))
    m, rows = merge_geometries([a, b], ["sph", "lagrange"])
    assert m.zones.tolist() == [2, 5, 7, 9] and m.fractions.tolist() == [0.25, 0.5, 0.75, 1.0]
    assert m.faces[0][0].tolist() == [2, 5] and m.faces[0][1].tolist() == [0.25, 0.25]
    assert m.cut.tolist() == [2, 5, 7]
    assert m.velocity.tolist() == [[0.0, 2.0], [1.0, 0.0], [0.0, 3.0]]   # each cut zone keeps its own
    assert m.nodes.tolist() == [2, 3, 5, 6, 8, 9, 11, 12, 13, 14]
    assert m.run_start.tolist() == [20, 40] and m.run_length.tolist() == [2, 3]
    # each member's rows of the merged lists give back its own ids
    for g, (ic, inode) in zip((a, b), rows):
        assert np.array_equal(m.cut[ic], g.cut) and np.array_equal(m.nodes[inode], g.nodes)


@pytest.mark.parametrize("cut_b, nodes_b, what", [([5], [20, 21], "zone 5"), ([7], [6, 7], "node 6")])
def test_bodies_of_two_groups_in_one_zone_or_at_one_node_are_refused(cut_b, nodes_b, what):
    a = _geom([5], [0.5], [5], [5, 6], [[1.0, 0.0]])
    b = _geom([cut_b[0]], [0.25], cut_b, nodes_b, [[0.0, 1.0]])
    with pytest.raises(GeometryError, match=f"sph and lagrange groups share the background {what}"):
        merge_geometries([a, b], ["sph", "lagrange"])


def test_a_node_that_only_ties_orphan_particles_may_be_shared():
    """An SPH member's nodes include the corners of its orphan particles' zones (coupling/
    orphan_particles.py): one of them next to the other member's body is not a shared constraint;
    the merged list holds it once and both members' rows point at it (their impulses add)."""
    a = _geom([5], [0.5], [5], [5, 6, 7], [[1.0, 0.0]])           # node 7: an orphan's only
    b = _geom([7], [0.25], [7], [7, 8], [[0.0, 1.0]])
    m, rows = merge_geometries([a, b], ["sph", "lagrange"], [np.array([5, 6]), np.array([7, 8])])
    assert m.nodes.tolist() == [5, 6, 7, 8]
    assert rows[0][1].tolist() == [0, 1, 2] and rows[1][1].tolist() == [2, 3]
    with pytest.raises(GeometryError, match="share the background node 7"):
        merge_geometries([a, b], ["sph", "lagrange"], [np.array([5, 6, 7]), np.array([7, 8])])


def test_the_members_diagnostics_combine_into_the_couplings():
    """Momentum, work, dissipation and void zones add; the step limit is the smallest; iterations,
    residual, conditioning and oscillations the worst (cond(H) of a member that has not measured it
    yet, nan, does not count)."""
    from orchestrator.coupling.foregrounds import ForegroundCouplings

    names = ["foreground_momentum_x", "foreground_momentum_y", "iterations", "residual", "dissipation",
             "foreground_work", "stable_dt_limit", "cond_H", "lambda_oscillation", "lambda_oscillation_max",
             "void_zones"]

    class Member:
        def __init__(self, row, cond):
            self.row, self.cond_H = row, cond

        def diagnostics(self):
            return self.row

        def diagnostic_names(self):
            return names

    c = ForegroundCouplings.__new__(ForegroundCouplings)
    c.members = [Member([1.0, 2.0, 3, 1e-3, -1.0, 2.0, 0.1, np.nan, 0.2, 0.3, 1], np.nan),
                 Member([-1.0, 0.5, 5, 2e-3, -2.0, 3.0, 0.05, 7.0, 0.1, 0.4, 2], 7.0)]
    assert c.diagnostics() == [0.0, 2.5, 5, 2e-3, -3.0, 5.0, 0.05, 7.0, 0.2, 0.4, 3]
    assert c.cond_H == 7.0


def test_each_member_gets_its_rows_of_the_packet_when_a_node_is_shared():
    """The background's interface packet spans the merged lists ([v_b (nb, 2), m_b (nb), R (nc, 2),
    fill (nc)]); each member's solve gets exactly its own rows, and the members' corrections come
    back at theirs, the shared node's impulses added.  The merged node list holds the shared orphan
    node once: sizing the packet by the sum of the members' lists (5 nodes, not 4) read v_b, m_b and R
    shifted by rows."""
    from types import SimpleNamespace

    from orchestrator.coupling.foregrounds import ForegroundCouplings

    geoms = [_geom([5], [0.5], [5], [5, 6, 7], [[1.0, 0.0]]), _geom([7], [0.25], [7], [7, 8], [[0.0, 1.0]])]
    constraint = [np.array([5, 6]), np.array([7, 8])]
    got = []

    class Member:
        def __init__(self, g, bnodes):
            self.g, self.ops = g, SimpleNamespace(bnodes=bnodes)

        def geometry(self):
            return self.g

        def solve(self, dt, dt_avg, vstar, packet):
            got.append(packet)
            return vstar

        def take_state(self, state):  # [node impulses (its nodes), v_half (its cut), v_mean (its cut)]
            return state

    fc = ForegroundCouplings.__new__(ForegroundCouplings)
    fc.roles, fc.dim, fc._rows = ["sph", "lagrange"], 2, None
    fc.members = [Member(g, c) for g, c in zip(geoms, constraint)]
    merged = fc.geometry()
    nodes, cut = merged.nodes, merged.cut                       # [5, 6, 7, 8], [5, 7]
    v_b = np.column_stack([nodes * 10.0, nodes * 10.0 + 1.0])   # each value names its node
    m_b = nodes * 100.0
    R = np.column_stack([cut * 1000.0, cut * 1000.0 + 1.0])
    fill = cut * 1e4
    fc.solve(1e-3, 1e-3, [None, None], np.concatenate([v_b.ravel(), m_b, R.ravel(), fill]))
    for g, packet in zip(geoms, got):
        n, c = g.nodes.astype(float), g.cut.astype(float)
        want = np.concatenate([np.column_stack([n * 10.0, n * 10.0 + 1.0]).ravel(), n * 100.0,
                               np.column_stack([c * 1000.0, c * 1000.0 + 1.0]).ravel(), c * 1e4])
        assert np.array_equal(packet, want)
    # corrections: node impulses 1 per node and component, surface velocities naming their zone
    states = [np.concatenate([np.ones(2 * g.nodes.size), np.repeat(g.cut * 1.0, 2), np.repeat(g.cut * 2.0, 2)])
              for g in geoms]
    out = fc.take_state(states)
    imp, vh, vb = out[:8].reshape(4, 2), out[8:12].reshape(2, 2), out[12:].reshape(2, 2)
    assert imp[:, 0].tolist() == [1.0, 1.0, 2.0, 1.0]            # node 7 in both members' lists
    assert vh[:, 0].tolist() == [5.0, 7.0] and vb[:, 0].tolist() == [10.0, 14.0] and out.size == 16
