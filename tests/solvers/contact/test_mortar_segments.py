"""solvers/contact/mortar_segments.py: the mortar integrals of one pass on non-matching flat meshes,
against the integrals of hat functions done by hand."""
import numpy as np
import scipy.sparse as sp

from solvers.contact.dual_pass import mortar_pass
from solvers.contact.mortar_segments import segment_pair_integrals
from tests.solvers.contact.geometry import facing_faces, hat_integrals

XA = [0.0, 0.3, 0.55, 0.8, 1.0]
XB = [0.0, 0.4, 0.7, 1.0]


def test_flat_non_matching_pass_reproduces_hat_integrals_and_linear_fields():
    pts, sa, sb = facing_faces(XA, XB, gap=0.01)
    p = mortar_pass(pts, sa, sb, capture=0.05)
    np.testing.assert_array_equal(p.nodes, np.arange(5))
    # D's rows integrate a's hat functions over the whole face (b covers it)
    np.testing.assert_allclose(p.area, hat_integrals(np.array(XA)), rtol=0, atol=1e-15)  # measured 5.6e-17
    # within the overlap b's shape functions sum to one: M's rows sum to D's (momentum balance)
    np.testing.assert_allclose(np.asarray(p.M.sum(axis=1)).ravel(), p.area, rtol=0, atol=1e-15)
    # a linear field f on b, integrated against a's hat functions, is the same as f on a's nodes
    # (2-point Gauss is exact for phi_a phi_b, a quadratic on every overlap)
    f = 2.0 + 3.0 * pts[:, 0]
    np.testing.assert_allclose(p.M @ f, p.D @ f, rtol=1e-14)  # measured 1.9e-16
    # and the D of a is a's consistent mass matrix of the face (tridiagonal, h/3 and h/6)
    h = np.diff(XA)
    want = sp.diags([h / 6, np.r_[h[0] / 3, (h[:-1] + h[1:]) / 3, h[-1] / 3], h / 6], [-1, 0, 1]).toarray()
    np.testing.assert_allclose(p.D[:, :5].toarray(), want, rtol=0, atol=1e-16)


def test_partial_overlap_integrates_only_where_b_projects():
    # b spans 0.2..0.65 of a face on 0..1: a's hat integrals over [0.2, 0.65] by hand
    pts, sa, sb = facing_faces([0.0, 0.5, 1.0], [0.2, 0.65], gap=0.0)
    p = mortar_pass(pts, sa, sb, capture=0.01)
    # hat of x=0 on [0.2,0.5]: int (1 - 2x) = 0.09; x=0.5: on [0.2,0.5] 0.21, on [0.5,0.65] 0.1275
    # x=1: on [0.5,0.65] int (2x - 1) = 0.0225
    np.testing.assert_allclose(p.area, [0.09, 0.3375, 0.0225], rtol=1e-14)
    np.testing.assert_allclose(np.asarray(p.M.sum(axis=1)).ravel(), p.area, rtol=1e-14)


def test_only_facing_segments_pair():
    pts, sa, sb = facing_faces(XA, XB, gap=0.01)
    pairs = np.array([[0, 0], [1, 1]])
    _, _, facing = segment_pair_integrals(pts, sa, sb, pairs)
    _, _, same_way = segment_pair_integrals(pts, sa, sb[:, ::-1], pairs)  # b turned to face away
    assert np.all(facing > 0) and np.all(same_way == 0)


def test_a_segment_pairs_only_within_capture_in_front_and_penetration_behind():
    pairs = np.array([[0, 0]])
    for gap, capture, penetration, pairs_up in [(0.1, 0.2, 0.05, True), (0.3, 0.2, 0.05, False),
                                                (-0.04, 0.2, 0.05, True), (-0.2, 0.2, 0.05, False),
                                                (-0.2, 0.2, 0.3, True)]:
        pts, sa, sb = facing_faces([0.0, 1.0], [0.0, 1.0], gap=gap)
        _, _, ov = segment_pair_integrals(pts, sa, sb, pairs, capture, penetration)
        assert (ov[0] > 0) == pairs_up, (gap, capture, penetration)
    # a tilted b counts if any part of the overlap is within reach: from gap 0.3 at x=0 to 0.1 at x=1
    pts, sa, sb = facing_faces([0.0, 1.0], [0.0, 1.0], gap=0.3, tilt=-0.2)
    assert segment_pair_integrals(pts, sa, sb, pairs, 0.2, 0.05)[2][0] == 1.0


def test_mortar_side_mass_integrates_bs_shape_functions_over_the_overlap():
    # b on 0.5..1.5 over a on 0..1: the overlap 0.5..1 is b's first half; with t = x - 0.5, b's shape
    # functions are 1 - t (node 2) and t (node 3): integrals (1 - t)^2 = 7/24, (1 - t) t = 1/12,
    # t^2 = 1/24 over t in [0, 0.5]
    pts, sa, sb = facing_faces([0.0, 1.0], [0.5, 1.5], gap=0.01)
    d, m, ov, e = segment_pair_integrals(pts, sa, sb, np.array([[0, 0]]), mortar_mass=True)
    want = np.array([[7 / 24, 1 / 12], [1 / 12, 1 / 24]])
    np.testing.assert_allclose(e[0], want, rtol=0, atol=1e-16)  # measured 5.6e-17
    np.testing.assert_array_equal(segment_pair_integrals(pts, sa, sb, np.array([[0, 0]]))[0], d)
    # assembled on global ids in the pass (rows and columns: b's nodes 2 and 3)
    p = mortar_pass(pts, sa, sb, capture=0.05)
    np.testing.assert_allclose(p.E[2:, 2:].toarray(), want, rtol=0, atol=1e-16)
    assert p.E[:2].nnz == 0 and p.E[:, :2].nnz == 0
    # over a whole face b's E is b's consistent mass matrix (b covers a exactly)
    pts, sa, sb = facing_faces(XA, XB, gap=0.01)
    p = mortar_pass(pts, sa, sb, capture=0.05)
    h = np.diff(XB)
    mass = sp.diags([h / 6, np.r_[h[0] / 3, (h[:-1] + h[1:]) / 3, h[-1] / 3], h / 6], [-1, 0, 1]).toarray()
    np.testing.assert_allclose(p.E[5:, 5:].toarray(), mass, rtol=0, atol=1e-16)
