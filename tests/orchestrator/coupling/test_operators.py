"""Coupling operators B^b, B^f per cut zone (orchestrator.coupling.operators) on analytic cuts."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from orchestrator.coupling.conditioning import straight_cut
from orchestrator.coupling.operators import MIN_AREA_FRACTION, Operators
from tests.orchestrator.coupling.stand_ins import Grid, circle_nodes, cut_polyline, cut_tilted_plane, line_nodes


def _row_sums(m):
    return np.asarray(m.sum(axis=1)).ravel()


def _cases():
    g2 = Grid.make([0.0, 0.0], [1.0, 1.0], [16, 16])
    yield "line", g2, *cut_polyline(g2, line_nodes(g2, [0.47, 0.52], 0.71, 0.09), closed=False)
    yield "circle", g2, *cut_polyline(g2, circle_nodes([0.5, 0.45], 0.31, 37), closed=True)
    g3 = Grid.make([0.0, 0.0, 0.0], [1.0, 1.0, 2.0], [5, 4, 8])
    yield "plane", g3, *cut_tilted_plane(g3, 0.6, 0.7, (0.17, 0.23), (0.05, 0.11))


@pytest.mark.parametrize("case", list(_cases()), ids=lambda c: c[0])
def test_rows_of_both_operators_sum_to_the_cut_area(case):
    """Σ_A B^b_eA = Σ_A B^f_eA = A_e (partition of unity of either mesh on Γ_e)."""
    _, grid, pieces, facets, ns = case
    ops = Operators.build(grid, pieces, facets, ns)
    scale = ops.area.max()
    err_b = np.abs(_row_sums(ops.Bb) - ops.area).max() / scale
    err_f = np.abs(_row_sums(ops.Bf) - ops.area).max() / scale
    assert err_b < 1e-14 and err_f < 1e-14, (err_b, err_f)  # measured <= 2e-16
    assert ops.area.sum() == pytest.approx(pieces.area.sum(), rel=1e-14)
    assert np.all(np.diff(ops.zones) > 0) and np.all(np.diff(ops.bnodes) > 0)
    assert ops.Bb.shape == (ops.zones.size, ops.bnodes.size) and ops.Bf.shape == (ops.zones.size, ns)
    assert np.all(ops.Bb.data >= 0.0) and np.all(ops.Bf.data >= 0.0)


def test_total_areas_match_the_analytic_surfaces():
    g2 = Grid.make([0.0, 0.0], [1.0, 1.0], [16, 16])
    n, r = 37, 0.31
    ops = Operators.build(g2, *cut_polyline(g2, circle_nodes([0.5, 0.45], r, n), closed=True))
    assert ops.area.sum() == pytest.approx(2 * n * r * np.sin(np.pi / n), rel=1e-14)  # polygon perimeter
    assert np.abs(ops.avec.sum(axis=0)).max() < 1e-15  # closed surface: ∮ n dΓ = 0; measured 3e-17
    # the outward normals of a circle point away from its centre
    pieces, _, _ = cut_polyline(g2, circle_nodes([0.5, 0.45], r, n), closed=True)
    zc = (g2.zone_index(ops.zones) + 0.5) * g2.h
    assert np.all((ops.normal * (zc - [0.5, 0.45])).sum(axis=1) > 0.0)

    slope, z0 = 0.7, 0.6  # z = z0 + slope x over [0,1]x[0,1], inside z in (0, 2): all of it
    g3 = Grid.make([0.0, 0.0, 0.0], [1.0, 1.0, 2.0], [5, 4, 8])
    ops3 = Operators.build(g3, *cut_tilted_plane(g3, z0, slope, (0.17, 0.23), (0.05, 0.11)))
    assert ops3.area.sum() == pytest.approx(np.sqrt(1 + slope**2), rel=1e-14)
    assert np.allclose(ops3.normal, np.array([-slope, 0, 1]) / np.sqrt(1 + slope**2), atol=1e-15)


def test_entries_of_a_horizontal_line_through_aligned_facets():
    """y = 0.3 on a 4x4 unit grid, facet nodes on the zone faces: in row j = 1 (local η = 0.2)
    B^b = h(1-η)/2 on the lower corners, h η/2 on the upper, B^f = h/2 on the facet's nodes."""
    g = Grid.make([0.0, 0.0], [1.0, 1.0], [4, 4])
    nodes = np.stack([np.linspace(0, 1, 5), np.full(5, 0.3)], axis=1)
    ops = Operators.build(g, *cut_polyline(g, nodes, closed=False))
    h, eta = 0.25, 0.2
    assert ops.zones.tolist() == [4, 5, 6, 7]
    Bb, Bf = ops.Bb.toarray(), ops.Bf.toarray()
    for e, zone in enumerate(ops.zones):
        corners = g.zone_nodes([zone])[0]
        cols = np.searchsorted(ops.bnodes, corners)
        expect = np.array([h * (1 - eta) / 2] * 2 + [h * eta / 2] * 2)
        assert np.allclose(Bb[e, cols], expect, rtol=0, atol=1e-16)
        assert np.allclose(Bf[e, [e, e + 1]], h / 2, rtol=0, atol=1e-16)
        assert Bb[e].sum() == pytest.approx(h, abs=1e-16)
    assert np.allclose(ops.normal, [0.0, -1.0]) and not ops.fallback.any()
    assert ops.pairs.tolist() == [[0, 1], [1, 2], [2, 3]]


def test_thin_plate_zones_fall_back_to_the_plate_normal():
    """Both faces of a plate thinner than a zone cancel in ∫ n dΓ; what is left is the end cap's
    normal (±x), a wrong slip direction: the fallback gives the plate normal (±y) instead."""
    g = Grid.make([0.0, 0.0], [1.0, 1.0], [4, 4])
    t, yc = 1e-3, 0.375
    plate = np.array([[0.1, yc - t / 2], [0.9, yc - t / 2], [0.9, yc + t / 2], [0.1, yc + t / 2]])
    ops = Operators.build(g, *cut_polyline(g, plate, closed=True))
    assert ops.zones.tolist() == [4, 5, 6, 7]
    ratio = np.sqrt((ops.avec**2).sum(axis=1)) / ops.area
    # end zones: faces of length 0.15 and the cap t; middle zones: the faces cancel exactly
    assert np.allclose(ratio, [t / (2 * 0.15 + t), 0.0, 0.0, t / (2 * 0.15 + t)], rtol=1e-12, atol=1e-16)
    assert ops.fallback.all()
    assert np.allclose(ops.normal, [0.0, 1.0], atol=0)  # sign rule: largest component positive
    # a right-angle corner (a square body) keeps its area vector's direction
    square = np.array([[0.3, 0.3], [0.7, 0.3], [0.7, 0.7], [0.3, 0.7]])
    ops_sq = Operators.build(g, *cut_polyline(g, square, closed=True))
    assert not ops_sq.fallback.any()
    assert np.allclose(ops_sq.normal, ops_sq.avec / np.linalg.norm(ops_sq.avec, axis=1)[:, None], atol=1e-15)


def test_face_pairs_are_the_face_adjacent_cut_zones():
    g = Grid.make([0.0, 0.0], [1.0, 1.0], [16, 16])
    ops = Operators.build(g, *cut_polyline(g, circle_nodes([0.52, 0.44], 0.33, 41), closed=True))
    idx = g.zone_index(ops.zones)
    brute = sorted((i, j) for i in range(len(idx)) for j in range(i + 1, len(idx))
                   if np.abs(idx[i] - idx[j]).sum() == 1)
    assert ops.pairs.tolist() == [list(p) for p in brute]
    g3 = Grid.make([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [6, 6, 6])
    ops3 = Operators.build(g3, *cut_tilted_plane(g3, 0.3, 0.5, (0.2, 0.2), (0.05, 0.05)))
    idx = g3.zone_index(ops3.zones)
    brute = sorted((i, j) for i in range(len(idx)) for j in range(i + 1, len(idx))
                   if np.abs(idx[i] - idx[j]).sum() == 1)
    assert ops3.pairs.tolist() == [list(p) for p in brute]


def test_face_pairs_across_a_periodic_face():
    """Zones 0 and 3 of a row of 4 are neighbours only when x is periodic; with 2 layers the wrap is
    the ordinary neighbour already (no second pair)."""
    from orchestrator.coupling.operator_rows import face_pair_rows

    zones = np.array([0, 3, 4], np.int64)  # (0, 0), (3, 0), (0, 1) of 4 x 4
    cells = np.array([4, 4], np.int64)
    assert face_pair_rows(zones, cells, np.array([0, 0], np.uint8)).tolist() == [[0, 2]]
    assert face_pair_rows(zones, cells, np.array([1, 0], np.uint8)).tolist() == [[0, 1], [0, 2]]
    two = np.array([2, 2], np.int64)
    assert face_pair_rows(np.array([0, 1], np.int64), two, np.array([1, 1], np.uint8)).tolist() == [[0, 1]]


def test_zones_of_negligible_area_get_no_multiplier():
    g = Grid.make([0.0, 0.0], [1.0, 1.0], [4, 4])
    nodes = np.stack([np.linspace(0, 1, 5), np.full(5, 0.3)], axis=1)
    pieces, facets, ns = cut_polyline(g, nodes, closed=False)

    def with_extra(fraction):
        """One more piece, in zone 14 (not cut otherwise), of area `fraction` of a full cut."""
        p = pieces
        a = fraction * 0.25
        q = np.array([[0.6, 0.9], [0.61, 0.9]])
        extra = dict(zone=[14], body=[0], facet=[0], area=[a], normal=[[0.0, 1.0]], centroid=[[0.6, 0.9]],
                     qp=q, qw=[a / 2, a / 2], qpiece=[p.zone.size] * 2, qf=[[0.5, 0.5]] * 2, qb=[[0.25] * 4] * 2)
        return dataclasses.replace(p, **{k: np.concatenate([getattr(p, k), np.asarray(v, dtype=getattr(p, k).dtype)])
                                         for k, v in extra.items()})

    assert 14 not in Operators.build(g, with_extra(0.5 * MIN_AREA_FRACTION), facets, ns).zones
    assert 14 in Operators.build(g, with_extra(2.0 * MIN_AREA_FRACTION), facets, ns).zones


def test_straight_cut_of_the_conditioning_study_matches_the_stand_in_clipper():
    """conditioning.straight_cut (vectorised) against the loop-per-facet stand-in, same line."""
    for seed in range(3):
        lat, pieces, facets, nodes = straight_cut(2, 1 / 16, np.random.default_rng(seed))
        a = Operators.build(lat, pieces, facets, len(nodes))
        g = Grid.make([0.0, 0.0], [1.0, 1.0], [16, 16])
        b = Operators.build(g, *cut_polyline(g, nodes, closed=False))
        assert np.array_equal(a.zones, b.zones) and np.array_equal(a.bnodes, b.bnodes)
        assert abs(a.Bb - b.Bb).max() < 1e-15 and abs(a.Bf - b.Bf).max() < 1e-15  # measured 1e-17
        assert np.abs(a.area - b.area).max() < 1e-15 and np.array_equal(a.pairs, b.pairs)
    lat, pieces, facets, nodes = straight_cut(3, 1 / 8, np.random.default_rng(5))
    ops = Operators.build(lat, pieces, facets, len(nodes))
    n3 = ops.normal[0]
    slope = -n3[0] / n3[2]
    z0 = nodes[0, 2]  # node (0, 0) of the plane
    x_in = np.clip((np.array([0.0, 1.0]) - z0) / slope, 0.0, 1.0) if slope else np.array([0.0, 1.0])
    assert ops.area.sum() == pytest.approx(np.sqrt(1 + slope**2) * abs(np.diff(x_in)[0]), rel=1e-13)
    assert np.abs(_row_sums(ops.Bb) - ops.area).max() < 1e-16 and np.abs(_row_sums(ops.Bf) - ops.area).max() < 1e-16


@pytest.mark.parametrize("periodic", [(), (0,), (0, 1)], ids=["walls", "periodic_x", "periodic_xy"])
@pytest.mark.parametrize("cells", [(7, 5), (4, 3, 5)], ids=["2d", "3d"])
def test_corner_columns_are_the_distinct_zone_nodes(cells, periodic):
    """B^b's columns from the merge kernel: bnodes = the distinct corner nodes of Grid.zone_nodes
    (wrapped on periodic axes: the kernel's sort fallback), bnodes[column] = the corner's node."""
    from orchestrator.coupling.grid import Grid as RealGrid
    from orchestrator.coupling.operator_rows import corner_columns

    dim = len(cells)
    grid = RealGrid(np.zeros(dim), np.ones(dim), cells, periodic)
    rng = np.random.default_rng(3)
    per = np.asarray(grid.periodic, np.uint8)
    for size in (0, 1, 9, grid.n_zones):
        zones = np.sort(rng.choice(grid.n_zones, size, replace=False)).astype(np.int64)
        nodes = grid.zone_nodes(zones)
        bnodes, columns = corner_columns(zones, grid.cells, per)
        np.testing.assert_array_equal(bnodes, np.unique(nodes))
        np.testing.assert_array_equal(bnodes[columns], nodes.reshape(columns.shape))
