"""solvers/contact/zone.py: the nodes near a partner body, from every rank's body boxes, include every
node of every facet the search can pair (no contact lost), and leave the far ones out."""
import numpy as np

from solvers.contact.search import candidate_pairs, facet_boxes
from solvers.contact.zone import body_boxes, facet_extent, near_nodes


def _scattered_segments(rng, n, centre, spread):
    """n random segments (2-D) around ``centre``: (points (2n, 2), segments (n, 2))."""
    a = centre + spread * rng.uniform(-1.0, 1.0, (n, 2))
    b = a + rng.uniform(-0.05, 0.05, (n, 2))
    return np.r_[a, b], np.stack([np.arange(n), n + np.arange(n)], axis=1)


def test_near_nodes_keep_every_facet_the_search_pairs_and_drop_the_far_ones():
    rng = np.random.default_rng(3)
    pa, sa = _scattered_segments(rng, 400, np.array([0.0, 0.0]), 1.0)
    pb, sb = _scattered_segments(rng, 400, np.array([1.8, 0.3]), 1.0)     # overlapping a's right part
    x = np.r_[pa, pb]
    sb = sb + len(pa)
    body = np.r_[np.zeros(len(pa), np.int64), np.ones(len(pb), np.int64)]
    capture = 0.02
    pairs = candidate_pairs(facet_boxes(x, sa, capture), facet_boxes(x, sb, capture))
    assert len(pairs) > 50
    # the nodes dealt to 3 "ranks" at random: each rank's boxes of the nodes it owns
    rank = rng.integers(0, 3, len(x))
    boxes = np.array([body_boxes(x[rank == r], body[rank == r], 2) for r in range(3)])
    margin = 2.0 * (capture + facet_extent(x, np.r_[sa, sb]))
    near = near_nodes(x, body, [(0, 1)], boxes, margin)
    assert near[sa[pairs[:, 0]]].all() and near[sb[pairs[:, 1]]].all()
    # far from the other body: left out (a's left part, b's right part)
    assert 0.1 < near.mean() < 0.3, near.mean()            # measured 0.20
    assert not near[x[:, 0] < -0.6].any() and not near[x[:, 0] > 2.4].any()
    # the same with the boxes of one rank (all nodes): the same facets kept
    one = body_boxes(x, body, 2)[None]
    assert near_nodes(x, body, [(0, 1)], one, margin)[np.r_[sa[pairs[:, 0]].ravel(), sb[pairs[:, 1]].ravel()]].all()


def test_self_contact_keeps_the_whole_body_and_a_rank_without_the_partner_adds_no_box():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0], [6.0, 0.0]])
    body = np.array([0, 0, 1, 1])
    # rank 0 owns body 0 only, rank 1 body 1 only: rank 0's box of body 1 is empty (+inf, -inf)
    boxes = np.array([body_boxes(x[:2], body[:2], 2), body_boxes(x[2:], body[2:], 2)])
    assert np.isinf(boxes[0, 1]).all()
    assert not near_nodes(x, body, [(0, 1)], boxes, 1.0).any()      # 4 apart, margin 1
    np.testing.assert_array_equal(near_nodes(x, body, [(0, 1)], boxes, 4.0), [False, True, True, False])
    np.testing.assert_array_equal(near_nodes(x, body, [(0, 0)], boxes, 1.0), [True, True, False, False])
    assert facet_extent(x, np.zeros((0, 2), np.int64)) == 0.0
