"""solvers/contact/search.py: both kernels of the broad phase (binned, and every pair below
ALL_PAIRS_MAX) find exactly the overlapping box pairs a numpy test of all pairs finds, in its order."""
import numpy as np
import pytest

from solvers.contact import search
from solvers.contact.search import candidate_pairs, facet_boxes

KERNELS = {"binned": search._binned_pairs, "all_pairs": search._all_pairs, "chosen": candidate_pairs}


def _all_pairs(a, b):
    hit = np.all((a[:, None, 0] <= b[None, :, 1]) & (b[None, :, 0] <= a[:, None, 1]), axis=2)
    return np.argwhere(hit)


def _boxes(rng, n, dim, spread, size):
    lo = rng.uniform(0.0, spread, (n, dim))
    return np.stack([lo, lo + rng.uniform(0.0, size, (n, dim))], axis=1)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_binned_pairs_are_all_overlapping_pairs(kernel, dim, seed):
    rng = np.random.default_rng(seed)
    a, b = _boxes(rng, 300, dim, 10.0, 0.8), _boxes(rng, 200, dim, 10.0, 1.5)
    got = KERNELS[kernel](a, b)
    want = _all_pairs(a, b)
    assert len(want) > 50  # the draw has pairs to find
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("kernel", KERNELS)
def test_boxes_on_bin_faces_are_all_found(kernel):
    """Coordinates on a 0.1 lattice put box ends on bin faces, where round-off moves a box of the
    largest extent into a third bin along an axis (0.7 / 0.1 = 6.999...): the numpy search, which
    looked in two, missed pairs in 4 of these 100 draws."""
    rng = np.random.default_rng(2)
    for _ in range(100):
        dim = int(rng.choice([2, 3]))
        a = np.round(_boxes(rng, int(rng.integers(1, 200)), dim, 1.0, rng.uniform(0.0, 0.3)), 1)
        b = np.round(_boxes(rng, int(rng.integers(1, 200)), dim, 2.0, rng.uniform(0.0, 0.3)) - 0.5, 1)
        np.testing.assert_array_equal(KERNELS[kernel](a, b), _all_pairs(a, b).reshape(-1, 2))


@pytest.mark.parametrize("kernel", KERNELS)
def test_touching_boxes_pair_and_far_clusters_stay_cheap(kernel):
    # two clusters 1e6 apart: the bins are capped at one per box along an axis, so memory stays O(n)
    rng = np.random.default_rng(3)
    a = _boxes(rng, 100, 2, 1.0, 0.05)
    b = _boxes(rng, 100, 2, 1.0, 0.05)
    b[:50] += 1e6
    np.testing.assert_array_equal(KERNELS[kernel](a, b), _all_pairs(a, b))
    touch = np.array([[[0.0, 0.0], [1.0, 1.0]]]), np.array([[[1.0, 1.0], [2.0, 2.0]]])
    np.testing.assert_array_equal(KERNELS[kernel](*touch), [[0, 0]])


@pytest.mark.parametrize("kernel", KERNELS)
def test_point_boxes_and_empty_sides(kernel):
    a = np.zeros((3, 2, 2))
    a[:, :, 0] = np.arange(3.0)[:, None]  # three points on a line
    np.testing.assert_array_equal(KERNELS[kernel](a, a), [[0, 0], [1, 1], [2, 2]])
    assert candidate_pairs(a, np.zeros((0, 2, 2))).shape == (0, 2)


def test_facet_boxes_grow_by_the_capture_distance():
    pts = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]])
    box = facet_boxes(pts, np.array([[0, 1], [1, 2]]), capture=0.1)
    np.testing.assert_allclose(box[0], [[-0.1, -0.1], [1.1, 0.6]])
    np.testing.assert_allclose(box[1], [[0.9, -0.1], [2.1, 0.6]])
