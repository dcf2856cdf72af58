"""solvers/contact/dual_pass.py: the dual-pass operators on non-matching flat faces (gaps, forces,
no side preferred, the stabilization) and self contact of a folded surface; in 2-D (segments) and
3-D (quadrilateral facets)."""
import numpy as np
import pytest

from solvers.contact.dual_pass import DualPassContact, nodal_normals
from tests.solvers.contact.geometry import facing_faces, grid_face, hat_integrals

XA = [0.0, 0.3, 0.55, 0.8, 1.0]
XB = [0.0, 0.4, 0.7, 1.0]


def test_weighted_gaps_of_parallel_faces_are_the_gap_times_the_area():
    d = 0.013
    pts, sa, sb = facing_faces(XA, XB, gap=d, ya=0.2)
    c = DualPassContact(pts, sa, sb, capture=0.05)
    assert c.n_multipliers == len(XA) + len(XB)
    area = np.concatenate([hat_integrals(np.array(XA)), hat_integrals(np.array(XB))])
    np.testing.assert_allclose(c.gaps(), d * area, rtol=1e-12)  # measured 8.4e-16
    # closed up by 2d: negative (penetration) of the same size
    shut = pts.copy()
    shut[len(XA):, 1] -= 2 * d
    np.testing.assert_allclose(c.gaps(shut), -d * area, rtol=1e-12)


def test_uniform_pressure_pushes_the_faces_apart_in_balance():
    pts, sa, sb = facing_faces(XA, XB, gap=0.0)
    c = DualPassContact(pts, sa, sb, capture=0.05)
    f = c.forces(np.full(c.n_multipliers, 7.0))
    na = len(XA)
    # each pass carries half: the face's total force is p times its length, on b upward
    np.testing.assert_allclose(f[na:].sum(axis=0), [0.0, 7.0], atol=1e-14)  # measured 8.9e-16
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-15)  # measured 0 and 2.2e-16
    # a uniform pressure gives a's nodes p times their tributary length
    np.testing.assert_allclose(f[:na, 1], -7.0 * hat_integrals(np.array(XA)), rtol=1e-13)


def test_no_side_is_preferred():
    pts, sa, sb = facing_faces(XA, XB, gap=0.002, tilt=0.01)
    ab = DualPassContact(pts, sa, sb, capture=0.05)
    ba = DualPassContact(pts, sb, sa, capture=0.05)
    na = len(ab.passes[0].nodes)
    perm = np.r_[np.arange(na, ab.n_multipliers), np.arange(na)]  # ba's multipliers are ab's, swapped
    assert abs(ab.constraint_operator()[perm] - ba.constraint_operator()).max() == 0.0
    assert abs(ab.stabilization(2.0, 0.1)[perm][:, perm] - ba.stabilization(2.0, 0.1)).max() == 0.0


def test_stabilization_vanishes_for_equal_sides_and_penalises_their_jump():
    pts, sa, sb = facing_faces(XA, XB, gap=0.0)
    c = DualPassContact(pts, sa, sb, capture=0.05)
    gamma, h = 1e-3, 0.3
    J = c.stabilization(gamma, h)
    p = np.full(c.n_multipliers, 5.0)
    # equal uniform pressures on both sides: the tractions p n^a + p n^b cancel pointwise
    assert np.abs(J @ p).max() <= 1e-17 * 5.0  # measured 0 (a few ulp of gamma h p)
    # pressure on one side only: j = (gamma h / 2) (its integral of p^2 over the face) > 0
    q = np.r_[np.full(len(XA), 5.0), np.zeros(len(XB))]
    np.testing.assert_allclose(q @ J @ q, 0.5 * gamma * h * 25.0 * 1.0, rtol=1e-13)


def test_self_contact_of_a_folded_strip_finds_the_facing_arms_only():
    # a U: outer polygon counter-clockwise; the inner arms x = 0.4 and x = 0.6 face each other
    # across 0.2 (the slot 0.4 < x < 0.6, 0.2 < y < 1)
    poly = np.array([[0, 0], [1, 0], [1, 1], [0.6, 1], [0.6, 0.2], [0.4, 0.2], [0.4, 1], [0, 1]], float)
    k = 4  # every edge in k segments
    pts = np.concatenate([poly[i] + np.linspace(0, 1, k, endpoint=False)[:, None] * (poly[(i + 1) % 8] - poly[i])
                          for i in range(8)])
    seg = np.stack([np.arange(len(pts)), (np.arange(len(pts)) + 1) % len(pts)], axis=1)
    c = DualPassContact(pts, seg, None, capture=0.25, penetration=0.05)  # the strip is 0.2 thick
    (p,) = c.passes
    on_arm = np.isclose(pts[p.nodes, 0], 0.4) | np.isclose(pts[p.nodes, 0], 0.6)
    assert on_arm.all() and on_arm.sum() == 2 * (k + 1)  # the slot's bottom (y = 0.2) is a neighbour
    # where both arms overlap the gap is 0.2 times the area, from either arm (the two passes)
    inner = (pts[p.nodes, 1] > 0.2 + 1e-12) & (pts[p.nodes, 1] < 1 - 1e-12)
    np.testing.assert_allclose(c.gaps()[inner], 0.2 * p.area[inner], rtol=1e-13)
    assert np.allclose(c.forces(np.ones(c.n_multipliers)).sum(axis=0), 0.0, atol=1e-15)
    # allowed to pair 0.25 behind, the strip's bottom pairs with the slot's through its thickness
    deep = DualPassContact(pts, seg, None, capture=0.25)
    assert not np.isclose(pts[deep.passes[0].nodes, 0], 0.4).all()
    assert np.isclose(pts[deep.passes[0].nodes, 1], 0.0).any()


def test_nodal_normals_average_the_segment_normals():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    n = nodal_normals(pts, np.array([[0, 1], [1, 2]]))
    np.testing.assert_allclose(n, [[0, -1], [np.sqrt(0.5), -np.sqrt(0.5)], [1, 0]], atol=1e-15)


# ----------------------------------------------------------------------------- 3-D (quadrilateral facets)
def _grids_3d(gap):
    """A 4 x 4 grid (normal +z, z = 0) under a 3 x 3 grid turned 25 degrees inside (normal -z, z = gap),
    both on [0, 1]^2."""
    pa, qa = grid_face(4, 0.0)
    pb, qb = grid_face(3, gap, turn=np.radians(25), up=False)
    return np.r_[pa, pb], qa, qb + len(pa)


def test_3d_weighted_gaps_forces_and_stabilization_of_parallel_faces():
    d = 0.013
    pts, qa, qb = _grids_3d(d)
    c = DualPassContact(pts, qa, qb, capture=0.05)
    assert c.n_multipliers == 25 + 16 and c.gap_operator().shape == (41, 3 * len(pts))
    area = np.concatenate([p.area for p in c.passes])
    np.testing.assert_allclose(area.sum(), 2.0, rtol=1e-15)  # each face's area 1: measured 1.1e-16
    np.testing.assert_allclose(c.gaps(), d * area, rtol=2e-15)  # measured 3.3e-16
    # a uniform pressure: each pass carries half, the upper face is pushed up by p times its area
    f = c.forces(np.full(c.n_multipliers, 7.0))
    np.testing.assert_allclose(f[25:].sum(axis=0), [0.0, 0.0, 7.0], atol=5e-15)  # measured 8.9e-16
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=5e-15)  # measured 8.0e-16
    # equal uniform pressures on both sides: the stabilization's traction jump vanishes
    J = c.stabilization(1e-3, 0.3)
    assert np.abs(J @ np.full(c.n_multipliers, 5.0)).max() <= 1e-19  # measured 1.5e-20 (gamma h p = 1.5e-3)


def test_3d_tangent_operator_measures_the_slip_in_two_directions():
    """T in 3-D: two rows per multiplier (interleaved), along tangents orthonormal to the nodal normal;
    the upper (turned) face slid by s = (3, -2, 0) against the lower: each multiplier's pair of rows
    is T x = area / 2 x (t1 . s, t2 . s) with the sign of its pass; a motion along the normal slips
    nothing; both faces moved together slip nothing."""
    pts, qa, qb = _grids_3d(0.01)
    c = DualPassContact(pts, qa, qb, capture=0.05)
    T = c.tangent_operator()
    assert T.shape == (2 * c.n_multipliers, 3 * len(pts))
    area = np.concatenate([p.area for p in c.passes])
    normals = np.concatenate([p.normals for p in c.passes])
    s = np.array([3.0, -2.0, 0.0])
    up = np.zeros_like(pts)
    up[len(pts) - 16:] = s                    # the 3 x 3 grid's 16 nodes last
    slip = (T @ up.ravel()).reshape(-1, 2)
    # the lower face (normal +z): t1 = x x n = -y, t2 = n x t1 = x; the mortar side (upper) moved by s:
    # (2, 3) area / 2. The upper face (normal -z): t1 = x x n = y, t2 = x; its mortar side did not
    # move, its own did: (t1, t2) . (-s) = (2, -3) area / 2
    want = np.where(np.arange(c.n_multipliers)[:, None] < 25, [2.0, 3.0], [2.0, -3.0]) * area[:, None] / 2
    np.testing.assert_allclose(slip, want, rtol=1e-14, atol=1e-16)  # measured 2.2e-16
    up[len(pts) - 16:] = [0.0, 0.0, 0.7]
    assert np.abs(T @ up.ravel()).max() <= 1e-15   # measured 0
    assert np.abs(T @ np.tile(s, len(pts))).max() <= 1e-15  # measured 2.2e-16


def test_3d_nodal_normals_weigh_by_area():
    # a roof: a 2 x 1 facet in the plane z = 0 and a 1 x 1 facet sloping up at 45 degrees along x
    roof = np.array([[-2, 0, 0], [0, 0, 0], [0, 1, 0], [-2, 1, 0], [1, 0, 1], [1, 1, 1]], float)
    n = nodal_normals(roof, np.array([[0, 1, 2, 3], [1, 4, 5, 2]]))
    s = np.sqrt(2.0)  # the sloping facet's area, with its normal (-1, 0, 1) / sqrt 2
    want = np.array([0.0, 0.0, 2.0]) + np.array([-1.0, 0.0, 1.0])  # area-weighted sum at the ridge
    np.testing.assert_allclose(n[1], want / np.linalg.norm(want), atol=1e-15)
    np.testing.assert_allclose(n[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(n[4], [-1 / s, 0, 1 / s], atol=1e-15)


def test_3d_self_contact_of_a_slotted_block_finds_the_facing_walls_only():
    from solvers.lagrange.mesh import box_mesh
    from solvers.lagrange.surface import exterior_facets
    # a 1 x 0.2 x 1 block of 5 x 1 x 5 hexahedra with the slot 0.4 < x < 0.6, z > 0.2 cut out: its walls
    # x = 0.4 and x = 0.6 face each other across 0.2
    m = box_mesh([0.0, 0.0, 0.0], [1.0, 0.2, 1.0], [5, 1, 5])
    ix, iz = np.arange(25) % 5, np.arange(25) // 5
    cells = m.cells[~((ix == 2) & (iz >= 1))]
    facets, _ = exterior_facets(cells, "hexahedron", m.num_points, m.points)
    c = DualPassContact(m.points, facets, None, capture=0.25, penetration=0.05)  # the arms are 0.4 thick
    (p,) = c.passes
    x = m.points[p.nodes]
    on_wall = np.isclose(x[:, 0], 0.4) | np.isclose(x[:, 0], 0.6)
    assert on_wall.all() and len(p.nodes) == 2 * 5 * 2   # the slot's bottom (z = 0.2) is a neighbour
    np.testing.assert_allclose(np.abs(p.normals[:, 0]), 1.0, rtol=0, atol=1e-15)
    # the walls overlap fully: every gap is 0.2 times the area, from either wall (the two passes)
    np.testing.assert_allclose(c.gaps(), 0.2 * p.area, rtol=3e-15)  # measured 6.7e-16
    np.testing.assert_allclose(p.area.sum(), 2 * 0.8 * 0.2, rtol=1e-15)  # measured 2.2e-16
    assert np.allclose(c.forces(np.ones(c.n_multipliers)).sum(axis=0), 0.0, atol=1e-16)  # measured 0
    # allowed to pair 0.25 behind, the block's bottom (z = 0) pairs with the slot's (z = 0.2) through
    # the 0.2 under the slot
    deep = DualPassContact(m.points, facets, None, capture=0.25)
    assert np.isclose(m.points[deep.passes[0].nodes, 2], 0.0).any()


def test_3d_self_contact_leaves_out_facets_that_share_a_node():
    # a sheet folded back on itself along x = 1: the two facets face each other 0 to 0.1 apart, but
    # share the fold's edge (nodes 1 and 2): neighbours, not contact partners
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0.1], [0, 1, 0.1]], float)
    sheet = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    assert DualPassContact(pts, sheet, None, capture=0.2).n_multipliers == 0
    # the same facets as two surfaces do pair
    assert DualPassContact(pts, sheet[:1], sheet[1:], capture=0.2).n_multipliers > 0


# ----------------------------------------------------------------------- the stabilization's sign
def _assert_symmetric_psd(J):
    """J symmetric to round-off and positive semidefinite: its smallest eigenvalue >= -1e-12 of its
    largest (the Gram form of the module docstring)."""
    J = J.toarray()
    assert J.shape[0] > 0 and np.abs(J).max() > 0
    assert np.abs(J - J.T).max() <= 1e-15 * np.abs(J).max()
    ev = np.linalg.eigvalsh(J)
    assert ev[0] >= -1e-12 * ev[-1], (ev[0], ev[-1])
    return ev


def test_stabilization_is_symmetric_psd_on_non_matching_tilted_faces():
    pts, sa, sb = facing_faces(XA, XB, gap=0.002, tilt=0.01)
    c = DualPassContact(pts, sa, sb, capture=0.05)
    _assert_symmetric_psd(c.stabilization(2.0, 0.1))


def test_stabilization_is_symmetric_psd_on_the_hertz_geometry():
    from tests.solvers.contact import test_hertz_2d as hertz
    x, nq, contact, sol = hertz.cylinder_on_flat(40)
    _assert_symmetric_psd(contact.stabilization(1.0, 0.04))


def test_stabilization_is_symmetric_psd_in_self_contact_of_a_curved_fold():
    # a flat elliptic hole (semi-axes 1 and 0.03, clockwise: the body's outward normals point into
    # it), its upper and lower walls facing across up to 0.06, nodes unevenly spaced (non-matching)
    t = np.linspace(0.0, 2 * np.pi, 61)[:-1]
    t = t + 0.3 * np.sin(3 * t) / 3  # uneven, still increasing
    pts = np.stack([np.cos(t), -0.03 * np.sin(t)], axis=1)  # clockwise
    seg = np.stack([np.arange(len(pts)), (np.arange(len(pts)) + 1) % len(pts)], axis=1)
    c = DualPassContact(pts, seg, None, capture=0.1)
    assert c.n_multipliers > 30
    ev = _assert_symmetric_psd(c.stabilization(1.0, 0.1))
    # J's null space is the equal pressures of facing sides: a uniform p has j(p, p) small against
    # one wall's pressure alone
    p = np.ones(c.n_multipliers)
    up = (pts[c.passes[0].nodes, 1] < 0).astype(float)
    J = c.stabilization(1.0, 0.1)
    assert p @ J @ p < 0.1 * (up @ J @ up)
    # self contact gives what two separate bodies give: the walls without the segments near the ends
    # (no longer joined) as one surface in self contact, and as two surfaces
    inner = seg[(np.abs(pts[seg, 0]) < 0.9).all(axis=1)]
    top, bot = inner[pts[inner[:, 0], 1] < 0], inner[pts[inner[:, 0], 1] >= 0]
    one = DualPassContact(pts, inner, None, capture=0.1)
    two = DualPassContact(pts, top, bot, capture=0.1)
    assert two.n_multipliers == one.n_multipliers > 30
    k = np.argsort(np.concatenate([q.nodes for q in two.passes]))  # two's multipliers in one's order
    J1, J2 = one.stabilization(1.0, 0.1), two.stabilization(1.0, 0.1)[k][:, k]
    _assert_symmetric_psd(J1)
    np.testing.assert_allclose(J2.toarray(), J1.toarray(), rtol=0, atol=1e-15 * abs(J1).max())


def test_3d_stabilization_is_symmetric_psd_on_turned_grids_and_in_self_contact():
    pts, qa, qb = _grids_3d(0.013)
    _assert_symmetric_psd(DualPassContact(pts, qa, qb, capture=0.05).stabilization(1e-3, 0.3))
    # tilted: the upper grid sloping 0.02 along x
    tilted = pts.copy()
    tilted[25:, 2] += 0.02 * tilted[25:, 0]
    _assert_symmetric_psd(DualPassContact(tilted, qa, qb, capture=0.05).stabilization(1e-3, 0.3))
    from solvers.lagrange.mesh import box_mesh
    from solvers.lagrange.surface import exterior_facets
    m = box_mesh([0.0, 0.0, 0.0], [1.0, 0.2, 1.0], [5, 1, 5])   # the slotted block (above)
    ix, iz = np.arange(25) % 5, np.arange(25) // 5
    facets, _ = exterior_facets(m.cells[~((ix == 2) & (iz >= 1))], "hexahedron", m.num_points, m.points)
    _assert_symmetric_psd(DualPassContact(m.points, facets, None, capture=0.25, penetration=0.05).stabilization(1.0, 0.2))
