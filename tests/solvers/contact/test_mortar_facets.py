"""solvers/contact/mortar_facets.py: the 3-D mortar integrals of one pass of quadrilateral facets,
against integrals done by hand (matching and shifted squares, separable) and by nested Gauss rules
on the known overlap (two squares 45 degrees apart: a regular octagon), and their filters."""
import numpy as np
import pytest

from solvers.contact.dual_pass import mortar_pass
from solvers.contact.mortar_facets import TRIANGLE_RULE, facet_pair_integrals
from tests.solvers.contact.geometry import grid_face, rotation

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
ONE = np.array([[0, 0]])
MASS = np.array([[4, 2, 1, 2], [2, 4, 2, 1], [1, 2, 4, 2], [2, 1, 2, 4]]) / 36.0  # bilinear, unit square


def facing_quads(a_xy, b_xy, gap=0.0, tilt=0.0):
    """Facet a in z = 0 with corners a_xy (counter-clockwise seen from +z: normal +z) and facet b in
    z = gap + tilt * x with corners b_xy (given counter-clockwise too, listed in reverse: normal -z).
    Returns points (8, 3), fa (1, 4), fb (1, 4); b's corner c is node 4 + c."""
    a_xy, b_xy = np.asarray(a_xy, float), np.asarray(b_xy, float)
    pa = np.c_[a_xy, np.zeros(4)]
    pb = np.c_[b_xy, gap + tilt * b_xy[:, 0]]
    return np.r_[pa, pb], np.array([[0, 1, 2, 3]]), np.array([[4, 7, 6, 5]])


def by_corner(m, fb):
    """m (4, 4) of a pair with columns in fb's order -> columns by b's counter-clockwise corner."""
    out = np.zeros((4, 4))
    out[:, fb[0] - 4] = m
    return out


def test_the_triangle_rule_is_exact_to_degree_5():
    bary, w = TRIANGLE_RULE
    # integral of l1^i l2^j l3^k over the triangle / its area = 2 i! j! k! / (i + j + k + 2)!
    from math import factorial
    for i, j, k in [(0, 0, 0), (2, 1, 0), (3, 0, 2), (1, 1, 3), (5, 0, 0), (0, 2, 2)]:
        want = 2.0 * factorial(i) * factorial(j) * factorial(k) / factorial(i + j + k + 2)
        got = w @ (bary[:, 0] ** i * bary[:, 1] ** j * bary[:, 2] ** k)
        assert abs(got - want) <= 1e-16, (i, j, k)  # measured 0 to 2.8e-17
    assert abs(w @ bary[:, 0] ** 6 - 2.0 * 720 / factorial(8)) > 1e-5  # degree 6 is not


def test_matching_squares_give_the_facet_mass_matrix():
    pts, fa, fb = facing_quads(SQUARE, SQUARE, gap=0.01)
    d, m, ov = facet_pair_integrals(pts, fa, fb, ONE)
    assert abs(ov[0] - 1.0) <= 1e-15  # measured 0
    np.testing.assert_allclose(d[0], MASS, rtol=0, atol=1e-16)   # measured 1.4e-17
    np.testing.assert_allclose(by_corner(m[0], fb), MASS, rtol=0, atol=1e-16)  # measured 1.4e-17


def _hat_products_1d(lo, hi, shift):
    """P[i, k] = integral over [lo, hi] of L_i(x) L_k(x - shift), L_0 = 1 - x, L_1 = x (5-point Gauss:
    exact for these quadratics)."""
    g, w = np.polynomial.legendre.leggauss(5)
    x = 0.5 * (lo + hi) + 0.5 * (hi - lo) * g
    w = 0.5 * (hi - lo) * w
    la = np.stack([1 - x, x])
    lb = np.stack([1 - (x - shift), x - shift])
    return np.einsum("q,iq,kq->ik", w, la, lb)


CORNER_IJ = [(0, 0), (1, 0), (1, 1), (0, 1)]  # corner c of the unit square: L_i(x) L_j(y)


@pytest.mark.parametrize("sx, sy", [(0.3, 0.2), (-0.45, 0.1), (0.0, -0.7)])
def test_shifted_squares_against_separable_integrals(sx, sy):
    pts, fa, fb = facing_quads(SQUARE, SQUARE + [sx, sy], gap=-0.02)
    d, m, ov = facet_pair_integrals(pts, fa, fb, ONE)
    px = (_hat_products_1d(max(0, sx), min(1, 1 + sx), 0.0), _hat_products_1d(max(0, sx), min(1, 1 + sx), sx))
    py = (_hat_products_1d(max(0, sy), min(1, 1 + sy), 0.0), _hat_products_1d(max(0, sy), min(1, 1 + sy), sy))
    want_d = np.array([[px[0][i, k] * py[0][j, l] for k, l in CORNER_IJ] for i, j in CORNER_IJ])
    want_m = np.array([[px[1][i, k] * py[1][j, l] for k, l in CORNER_IJ] for i, j in CORNER_IJ])
    np.testing.assert_allclose(ov[0], (1 - abs(sx)) * (1 - abs(sy)), rtol=1e-15)  # measured 2.2e-16
    np.testing.assert_allclose(d[0], want_d, rtol=0, atol=2e-16)  # measured 2.8e-17
    np.testing.assert_allclose(by_corner(m[0], fb), want_m, rtol=0, atol=2e-16)  # measured 5.6e-17


def _octagon_reference(fun):
    """Integral of fun(x, y) over the overlap of [-1/2, 1/2]^2 and |x| + |y| <= 1/sqrt 2 (the square
    turned 45 degrees): nested 8-point Gauss rules on the three x-intervals where the y-limits are
    linear in x (exact for the polynomials of these tests)."""
    r = np.sqrt(0.5)
    g, w = np.polynomial.legendre.leggauss(8)
    total = 0.0
    for x0, x1 in [(-0.5, 0.5 - r), (0.5 - r, r - 0.5), (r - 0.5, 0.5)]:
        x = 0.5 * (x0 + x1) + 0.5 * (x1 - x0) * g
        wx = 0.5 * (x1 - x0) * w
        yh = np.minimum(0.5, r - np.abs(x))
        y = yh[:, None] * g[None, :]
        total = total + np.einsum("i,j,i,...ij->...", wx, w, yh, fun(x[:, None], y))
    return total


def _square_shapes(x, y):
    """The 4 bilinear shape functions of the square [-1/2, 1/2]^2 (counter-clockwise corners)."""
    return np.stack([(0.5 - x) * (0.5 - y), (0.5 + x) * (0.5 - y), (0.5 + x) * (0.5 + y), (0.5 - x) * (0.5 + y)])


def _turned_45():
    a = SQUARE - 0.5
    return a, a @ rotation(np.pi / 4).T


def test_squares_turned_45_degrees_overlap_in_the_regular_octagon():
    a, b = _turned_45()
    pts, fa, fb = facing_quads(a, b, gap=0.01)
    d, m, ov = facet_pair_integrals(pts, fa, fb, ONE)
    np.testing.assert_allclose(ov[0], 2.0 * (np.sqrt(2.0) - 1.0), rtol=1e-15)  # measured 2.2e-16
    want_d = _octagon_reference(lambda x, y: np.einsum("a...,b...->ab...", _square_shapes(x, y), _square_shapes(x, y)))
    q = rotation(-np.pi / 4)  # b's own coordinates of a point: turned back

    def mixed(x, y):
        xb, yb = q[0, 0] * x + q[0, 1] * y, q[1, 0] * x + q[1, 1] * y
        return np.einsum("a...,c...->ac...", _square_shapes(x, y), _square_shapes(xb, yb))

    np.testing.assert_allclose(d[0], want_d, rtol=0, atol=3e-16)  # measured 6.9e-17
    np.testing.assert_allclose(by_corner(m[0], fb), _octagon_reference(mixed), rtol=0, atol=3e-16)  # measured 5.6e-17


def test_integrals_do_not_depend_on_the_pair_placement_in_space():
    a, b = _turned_45()
    pts, fa, fb = facing_quads(a + [0.1, -0.2], b + [0.3, 0.05], gap=0.01)
    d0, m0, ov0 = facet_pair_integrals(pts, fa, fb, ONE)
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))                     # a rotation
    d, m, ov = facet_pair_integrals(pts @ q.T + [5.0, -2.0, 7.0], fa, fb, ONE)
    np.testing.assert_allclose(ov, ov0, rtol=5e-15)  # measured 8.9e-16
    np.testing.assert_allclose(d, d0, rtol=0, atol=1e-15)  # measured 1.2e-16
    np.testing.assert_allclose(m, m0, rtol=0, atol=1e-15)  # measured 9.7e-17


def test_rows_balance_and_planar_linear_fields_pass_for_general_and_warped_facets():
    a = np.array([[0.0, 0.0], [1.1, 0.1], [0.9, 1.0], [-0.1, 0.8]])        # not parallelograms
    b = np.array([[0.3, -0.2], [1.2, 0.4], [1.0, 1.3], [0.2, 0.9]])
    pts, fa, fb = facing_quads(a, b, gap=0.02)
    d, m, ov = facet_pair_integrals(pts, fa, fb, ONE)
    assert ov[0] > 0.5
    np.testing.assert_allclose(m[0].sum(axis=1), d[0].sum(axis=1), rtol=1e-15)  # measured 2.2e-16
    # a field linear in the plane interpolated on b, against a's shape functions, is the same on a
    f = 2.0 + 3.0 * pts[:, 0] - 1.5 * pts[:, 1]
    np.testing.assert_allclose(m[0] @ f[fb[0]], d[0] @ f[fa[0]], rtol=1e-15)  # measured 2.2e-16
    # warped: a corner of each lifted out of the plane; the rows still balance
    pts[2, 2] += 0.05
    pts[5, 2] -= 0.04
    d, m, ov = facet_pair_integrals(pts, fa, fb, ONE)
    assert ov[0] > 0.5
    np.testing.assert_allclose(m[0].sum(axis=1), d[0].sum(axis=1), rtol=1e-15)  # measured 2.2e-16


def test_only_facing_facets_pair():
    pts, fa, fb = facing_quads(SQUARE, SQUARE + 0.2, gap=0.01)
    assert facet_pair_integrals(pts, fa, fb, ONE)[2][0] > 0
    assert facet_pair_integrals(pts, fa, fb[:, ::-1], ONE)[2][0] == 0.0  # b turned to face away
    # b at right angles (in the plane x = 0.5, normal -x): no pair although the boxes touch
    side = np.array([[0.5, 0, 0], [0.5, 1, 0], [0.5, 1, 1], [0.5, 0, 1]])
    pts2 = np.r_[pts[:4], side]
    assert facet_pair_integrals(pts2, fa, np.array([[4, 5, 6, 7]]), ONE)[2][0] == 0.0


def test_neighbours_touching_along_an_edge_do_not_pair():
    pts, fa, fb = facing_quads(SQUARE, SQUARE + [1.0, 0.0], gap=0.0)
    assert facet_pair_integrals(pts, fa, fb, ONE)[2][0] == 0.0
    pts, fa, fb = facing_quads(SQUARE, SQUARE + [1.0, 1.0], gap=0.0)
    assert facet_pair_integrals(pts, fa, fb, ONE)[2][0] == 0.0


def test_a_facet_pairs_only_within_capture_in_front_and_penetration_behind():
    for gap, capture, penetration, pairs_up in [(0.1, 0.2, 0.05, True), (0.3, 0.2, 0.05, False),
                                                (-0.04, 0.2, 0.05, True), (-0.2, 0.2, 0.05, False),
                                                (-0.2, 0.2, 0.3, True)]:
        pts, fa, fb = facing_quads(SQUARE, SQUARE, gap=gap)
        ov = facet_pair_integrals(pts, fa, fb, ONE, capture, penetration)[2]
        assert (ov[0] > 0) == pairs_up, (gap, capture, penetration)
    # a tilted b counts if any part of the overlap is within reach: from gap 0.3 at x=0 to 0.1 at x=1
    pts, fa, fb = facing_quads(SQUARE, SQUARE, gap=0.3, tilt=-0.2)
    ov = facet_pair_integrals(pts, fa, fb, ONE, 0.2, 0.05)[2]
    assert abs(ov[0] - 1.0) <= 1e-14  # measured 0
    pts, fa, fb = facing_quads(SQUARE, SQUARE, gap=0.45, tilt=-0.2)   # 0.25 at its nearest
    assert facet_pair_integrals(pts, fa, fb, ONE, 0.2, 0.05)[2][0] == 0.0


def test_a_pass_of_non_matching_grids_integrates_the_shape_functions_of_a():
    pa, qa = grid_face(5, 0.0)
    pb, qb = grid_face(3, 0.01, turn=np.radians(25), up=False)
    pts = np.r_[pa, pb]
    p = mortar_pass(pts, qa, qb + len(pa), capture=0.05)
    np.testing.assert_array_equal(p.nodes, np.arange(len(pa)))
    # D's rows: the integral of a's bilinear shape functions over the face (b covers it all):
    # h^2 / 4 per facet at a node, h = 1/5
    n_facets = np.zeros(len(pa))
    np.add.at(n_facets, qa.ravel(), 1)
    np.testing.assert_allclose(p.area, n_facets * 0.04 / 4, rtol=3e-15)  # measured 5.6e-16
    np.testing.assert_allclose(np.asarray(p.M.sum(axis=1)).ravel(), p.area, rtol=3e-15)  # measured 5.6e-16
    np.testing.assert_allclose(p.normals, np.tile([0.0, 0.0, 1.0], (len(pa), 1)), atol=1e-15)  # measured 0
    # a field linear in x, y on b's nodes, against a's shape functions, is the same field on a's
    f = 2.0 + 3.0 * pts[:, 0] - 1.5 * pts[:, 1]
    np.testing.assert_allclose(p.M @ f, p.D @ f, rtol=3e-15)  # measured 4.4e-16


def _by_corners(e, fb):
    """e (4, 4) of a pair with rows and columns in fb's order -> both by b's counter-clockwise corner."""
    out = np.zeros((4, 4))
    out[np.ix_(fb[0] - 4, fb[0] - 4)] = e
    return out


@pytest.mark.parametrize("sx, sy", [(0.0, 0.0), (0.3, 0.2), (-0.45, 0.1)])
def test_mortar_side_mass_against_separable_integrals(sx, sy):
    # E_CC' = integral over the overlap of b's shape functions C and C': separable, each factor the
    # integral of two shifted hats L_k(x - s) L_l(x - s) over the overlap, i.e. of L_k L_l over the
    # overlap moved back by s
    pts, fa, fb = facing_quads(SQUARE, SQUARE + [sx, sy], gap=0.01)
    d, m, ov, e = facet_pair_integrals(pts, fa, fb, ONE, mortar_mass=True)
    px = _hat_products_1d(max(0, sx) - sx, min(1, 1 + sx) - sx, 0.0)
    py = _hat_products_1d(max(0, sy) - sy, min(1, 1 + sy) - sy, 0.0)
    want = np.array([[px[i, k] * py[j, l] for k, l in CORNER_IJ] for i, j in CORNER_IJ])
    np.testing.assert_allclose(_by_corners(e[0], fb), want, rtol=0, atol=2e-16)  # measured 4.2e-17
    if sx == sy == 0.0:
        np.testing.assert_allclose(_by_corners(e[0], fb), MASS, rtol=0, atol=1e-16)
    # the default return is unchanged
    d0, m0, ov0 = facet_pair_integrals(pts, fa, fb, ONE)
    np.testing.assert_array_equal(d0, d)
    np.testing.assert_array_equal(m0, m)
