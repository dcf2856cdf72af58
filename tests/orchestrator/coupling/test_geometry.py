"""Interface geometry of the embedded-mesh coupling (orchestrator/coupling/geometry.py, grid.py).

References are analytic or computed by an independent method: polygon/polyhedron volumes by the
shoelace formula / divergence theorem on the facets, per-zone fractions of convex bodies by clipping
the body (2-D) or by exact Simpson integration of its slices (3-D), face coverages from the body's
chords/sections, quadrature against tensor Gauss-Legendre on whole flat facets.  Tolerances are a few
times the measured error, written beside them.
"""
import dataclasses
import itertools

import numpy as np
import pytest

from orchestrator.coupling.clipping import _TRI_BARY, _TRI_W
from orchestrator.coupling.geometry import (GeometryError, Pieces, blocked_fractions, clip_surface,
                                            closed_surface_from_cells, coverage, cube_sphere_surface, face_coverage,
                                            geometry_cost)
from orchestrator.coupling.grid import Grid


# ------------------------------------------------------------------------------------ bodies
def rotation_3d(a, b, c):
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, cc, -sc], [0, sc, cc]])
    return rz @ ry @ rx


def polygon(vertices):
    """Closed counter-clockwise polygon: (points, segments)."""
    n = len(vertices)
    return np.asarray(vertices, float), np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)


def hex_box(lower, upper, cells):
    """Structured hex mesh of a box: (points, cells) in VTK order."""
    axes = [np.linspace(lo, hi, n + 1) for lo, hi, n in zip(lower, upper, cells)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    nx, ny, nz = cells
    ids = np.arange(pts.shape[0]).reshape(nx + 1, ny + 1, nz + 1)
    c = ids[:-1, :-1, :-1].reshape(-1)
    sx, sy = (ny + 1) * (nz + 1), nz + 1
    return pts, np.stack([c, c + sx, c + sx + sy, c + sy, c + 1, c + sx + 1, c + sx + sy + 1, c + sy + 1], 1)


def box_surface(lower, upper, cells, rotation=None, centre=None):
    pts, hexes = hex_box(lower, upper, cells)
    quads = closed_surface_from_cells(pts, hexes, "hexahedron")
    if rotation is not None:
        c = 0.5 * (np.asarray(lower) + np.asarray(upper))
        pts = (pts - c) @ rotation.T + (c if centre is None else np.asarray(centre))
    return pts, quads


def enclosed_volume(x, facets):
    """Shoelace (2-D) / divergence theorem on the 0-2 triangulated quads (3-D)."""
    if facets.shape[1] == 2:
        a, b = x[facets[:, 0]], x[facets[:, 1]]
        return 0.5 * np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    a, b, c, d = (x[facets[:, i]] for i in range(4))
    return (np.sum(a * np.cross(b, c)) + np.sum(a * np.cross(c, d))) / 6.0


def facet_areas(x, facets):
    if facets.shape[1] == 2:
        return np.linalg.norm(x[facets[:, 1]] - x[facets[:, 0]], axis=1)
    a, b, c, d = (x[facets[:, i]] for i in range(4))
    return 0.5 * (np.linalg.norm(np.cross(b - a, c - a), axis=1) + np.linalg.norm(np.cross(c - a, d - a), axis=1))


def clip_convex_2d(poly, a, b, c):
    """Sutherland-Hodgman of a polygon (k, 2) against a x + b y <= c."""
    out = []
    for i in range(len(poly)):
        p, q = poly[i], poly[(i + 1) % len(poly)]
        sp, sq = a * p[0] + b * p[1] - c, a * q[0] + b * q[1] - c
        if sp <= 0:
            out.append(p)
        if sp * sq < 0:
            out.append(p + sp / (sp - sq) * (q - p))
    return np.array(out).reshape(-1, 2)


def shoelace(poly):
    if len(poly) < 3:
        return 0.0
    return 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])


def zone_box(grid, zone):
    """Lower and upper corners (..., dim) of zones."""
    ijk = grid.zone_ijk(zone)
    lo = np.stack([grid.planes(d)[ijk[..., d]] for d in range(grid.dim)], -1)
    hi = np.stack([grid.planes(d)[ijk[..., d] + 1] for d in range(grid.dim)], -1)
    return lo, hi


def convex_polygon_in_zone(grid, verts, zone):
    """Area of a convex counter-clockwise polygon inside a zone, by clipping the polygon."""
    lo, hi = zone_box(grid, zone)
    p = np.asarray(verts, float) - lo          # local coordinates: no cancellation in the shoelace
    hi = hi - lo
    for a, b, c in ((1, 0, hi[0]), (-1, 0, 0.0), (0, 1, hi[1]), (0, -1, 0.0)):
        p = clip_convex_2d(p, a, b, c)
    return shoelace(p)


def convex_polyhedron_in_zone(grid, normals, offsets, zone):
    """Volume of P = {n.x <= o} ∩ zone by exact integration of its z-slices: a slice is a convex
    polygon whose area is quadratic in z between the z of P's vertices (found by solving every triple
    of its planes), so Simpson's rule on each interval is exact."""
    lo, hi = zone_box(grid, zone)
    offsets = offsets - normals @ lo           # local coordinates from the zone's lower corner
    lo, hi = np.zeros(3), hi - lo
    A = np.concatenate([normals, np.eye(3), -np.eye(3)])
    b = np.concatenate([offsets, hi, -lo])
    tri = np.array([t for t in itertools.combinations(range(len(A)), 3)])
    M = A[tri]
    ok = np.abs(np.linalg.det(M)) > 1e-12
    v = np.linalg.solve(M[ok], b[tri[ok]][..., None])[..., 0]
    v = v[np.all(v @ A.T <= b + 1e-12, axis=1)]
    if len(v) == 0:
        return 0.0
    zs = np.unique(v[:, 2])
    rect = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])

    def area(z):
        p = rect
        for n, o in zip(normals, offsets):
            p = clip_convex_2d(p, n[0], n[1], o - n[2] * z)
        return shoelace(p)
    return sum((z1 - z0) / 6.0 * (area(z0) + 4 * area(0.5 * (z0 + z1)) + area(z1))
               for z0, z1 in zip(zs[:-1], zs[1:]))


def on_boundary(grid, pieces):
    """Pieces lying on the grid boundary (counted as outside the grid in the coverage sums)."""
    out = np.zeros(pieces.zone.size, bool)
    for d in range(grid.dim):
        out |= (pieces.centroid[:, d] == grid.lower[d]) & (pieces.normal[:, d] == -1.0)
        out |= (pieces.centroid[:, d] == grid.upper[d]) & (pieces.normal[:, d] == 1.0)
    return out


# -------------------------------------------------------------------------------------- grid
def test_grid_ids_round_trip_and_corner_order():
    g = Grid([0.0, -1.0, 2.0], [1.0, 1.0, 3.0], [3, 4, 5])
    assert g.dim == 3 and np.allclose(g.h, [1 / 3, 0.5, 0.2]) and np.isclose(g.zone_volume, 1 / 30)
    ijk = np.stack(np.meshgrid(np.arange(3), np.arange(4), np.arange(5), indexing="ij"), -1).reshape(-1, 3)
    ids = g.zone_ids(ijk)
    assert np.array_equal(ids, ijk[:, 0] + 3 * (ijk[:, 1] + 4 * ijk[:, 2]))
    assert np.array_equal(g.zone_ijk(ids), ijk)
    assert np.array_equal(g.node_ijk(g.node_ids(ijk + 1)), ijk + 1)
    assert g.node_ids([3, 4, 5]) == g.n_nodes - 1
    for d in range(3):
        f = g.face_ids(d, ijk)
        assert np.unique(f).size == f.size and f.max() < np.prod(g.cells + (np.arange(3) == d))
        assert np.array_equal(g.face_ijk(d, f), ijk)
    assert g.face_ids(1, [2, 4, 4]) == 2 + 3 * (4 + 5 * 4)
    # corner c = offset (c&1, c>>1&1, c>>2&1) from the lower node
    zn = g.zone_nodes(ids)
    for c in range(8):
        off = np.array([c & 1, c >> 1 & 1, c >> 2 & 1])
        assert np.array_equal(g.node_ijk(zn[:, c]), ijk + off)
    x = g.planes(0)
    assert x[0] == 0.0 and x[-1] == 1.0 and np.array_equal(Grid([0, 0], [1, 1], [10, 10]).planes(0)[3:4], [0.3])
    ale = {"grid": {"lower": [0.0, 0.0], "upper": [2.0, 1.0], "cells": [4, 2]}}
    assert np.array_equal(Grid.from_ale(ale).cells, [4, 2])


def test_grid_neighbours_match_brute_force():
    g = Grid([0, 0, 0], [1, 1, 1], [4, 3, 5])
    rng = np.random.default_rng(1)
    z = rng.choice(g.n_zones, 30, replace=False)
    pairs, axis = g.neighbours(np.concatenate([z, z[:5]]))
    ijk = g.zone_ijk(z)
    ref = sorted((min(a, b), d, max(a, b)) for ia, a in zip(ijk, z) for ib, b in zip(ijk, z)
                 for d in range(3) if a < b and abs(ia - ib).sum() == 1 and ia[d] != ib[d])
    assert [(int(p[0]), int(d), int(p[1])) for p, d in zip(pairs, axis)] == ref


# -------------------------------------------------------------------------------- 2-D bodies
SQUARE = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * 0.27
ROT2 = np.array([[np.cos(0.37), -np.sin(0.37)], [np.sin(0.37), np.cos(0.37)]])
POLYGONS = {
    "rotated_square": SQUARE @ ROT2.T + [0.48, 0.53],
    "regular_64gon": np.stack([0.31 * np.cos(2 * np.pi * np.arange(64) / 64 + 0.1) + 0.51,
                               0.31 * np.sin(2 * np.pi * np.arange(64) / 64 + 0.1) + 0.47], 1),
}


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_polygon_fractions_are_exact(name):
    g = Grid([0.0, 0.0], [1.0, 1.0], [13, 11])
    x, segs = polygon(POLYGONS[name])
    pieces = clip_surface(g, x, segs)
    zones, frac = blocked_fractions(g, pieces, 1)
    area = enclosed_volume(x, segs)
    assert np.all(np.diff(zones) > 0) and frac.shape == (zones.size, 1)
    assert np.all((frac > 0) & (frac <= 1))
    # measured 0 (square) / 1.8e-16 (64-gon)
    assert abs(frac.sum() * g.zone_volume - area) <= 1e-13 * area
    # per zone against clipping the polygon to the zone; measured 1.4e-15 (fraction units), the
    # reference's round-off (intersections of edges ~0.3 long with zones 0.08 wide)
    ref = np.array([convex_polygon_in_zone(g, x, z) for z in range(g.n_zones)]) / g.zone_volume
    assert np.array_equal(np.flatnonzero(ref > 1e-14), zones)
    assert np.max(np.abs(frac[:, 0] - ref[zones])) < 4e-15
    uncut = ~np.isin(zones, pieces.zone)                        # fully covered zones: exactly 1
    assert np.all(frac[uncut, 0] == 1.0) and np.all(ref[zones[uncut]] > 1 - 1e-14)


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_polygon_pieces_areas_normals_and_face_coverage(name):
    g = Grid([0.0, 0.0], [1.0, 1.0], [13, 11])
    x, segs = polygon(POLYGONS[name])
    pieces = clip_surface(g, x, segs)
    # sorted by (zone, body, facet); areas add up to each facet's length (measured 2.1e-16 rel)
    assert np.all(np.diff(pieces.zone * len(segs) + pieces.facet) > 0)
    L = facet_areas(x, segs)
    assert np.max(np.abs(np.bincount(pieces.facet, pieces.area, len(segs)) - L) / L) < 1e-15
    # closed body: sum of area * normal vanishes (measured 1.5e-16 of the perimeter)
    assert np.abs(pieces.area @ pieces.normal).max() < 1e-15 * L.sum()
    # the outward normal: x . n integrates to dim * area (measured 2.2e-16 rel)
    assert np.isclose(np.sum(pieces.area * np.einsum("ij,ij->i", pieces.centroid, pieces.normal)),
                      2 * enclosed_volume(x, segs), rtol=1e-15, atol=0)
    # every piece lies in its zone
    lo, hi = zone_box(g, pieces.zone)
    assert np.all((pieces.qp >= lo[pieces.qpiece]) & (pieces.qp <= hi[pieces.qpiece]))
    # face coverage of the faces normal to x / y from the polygon's chords (measured 1.9e-15)
    for d in range(2):
        fids, cov = face_coverage(g, pieces, 1, d)
        e = 1 - d
        fijk = g.face_ijk(d, np.arange(np.prod(g.face_shape(d))))
        ref = np.zeros(fijk.shape[0])
        p, q = x, np.roll(x, -1, axis=0)
        for f, ij in enumerate(fijk):
            # the chord of the convex polygon on the line x_d = X, overlapped with the face
            X, lo_e, hi_e = g.planes(d)[ij[d]], g.planes(e)[ij[e]], g.planes(e)[ij[e] + 1]
            cross = (p[:, d] - X) * (q[:, d] - X) <= 0
            if not cross.any():
                continue
            t = (X - p[cross, d]) / (q[cross, d] - p[cross, d])
            ye = p[cross, e] + t * (q[cross, e] - p[cross, e])
            ref[f] = max(0.0, min(hi_e, ye.max()) - max(lo_e, ye.min())) / (hi_e - lo_e)
        assert np.array_equal(np.flatnonzero(ref > 1e-14), fids)
        assert np.max(np.abs(cov[:, 0] - ref[fids])) < 5e-15


def test_plate_clamped_at_the_wall_2d():
    """A plate on the grid boundary y = lower, its ends on grid lines: facets on the boundary belong to
    the inner zones, facets on interior grid lines to the zone on their outward side."""
    g = Grid([0.0, 0.0], [1.0, 0.5], [10, 5])
    x, segs = polygon([[0.3, 0.0], [0.6, 0.0], [0.6, 0.2], [0.3, 0.2]])
    pieces = clip_surface(g, x, segs)
    ijk = g.zone_ijk(pieces.zone)
    ny = pieces.normal[:, 1]
    assert np.array_equal(np.unique(ijk[ny == -1.0, 1]), [0])              # the wall: inner row 0
    assert np.array_equal(np.unique(ijk[ny == 1.0, 1]), [2])               # top y = 0.2: the row above
    assert np.array_equal(np.unique(ijk[pieces.normal[:, 0] == 1.0, 0]), [6])    # right x = 0.6: zone 6
    assert np.array_equal(np.unique(ijk[pieces.normal[:, 0] == -1.0, 0]), [2])   # left x = 0.3: zone 2
    zones, frac = blocked_fractions(g, pieces, 1)
    zi = g.zone_ijk(zones)
    assert np.array_equal(frac[:, 0], np.ones(6))                          # exactly
    assert set(map(tuple, zi.tolist())) == {(i, j) for i in (3, 4, 5) for j in (0, 1)}
    fy, cy = face_coverage(g, pieces, 1, 1)
    fijk = g.face_ijk(1, fy)
    assert set(map(tuple, fijk.tolist())) == {(i, j) for i in (3, 4, 5) for j in (0, 1, 2)}
    assert np.array_equal(cy[:, 0], np.ones(9))
    fx, cx = face_coverage(g, pieces, 1, 0)
    assert set(map(tuple, g.face_ijk(0, fx).tolist())) == {(i, j) for i in (3, 4, 5, 6) for j in (0, 1)}
    assert np.array_equal(cx[:, 0], np.ones(8))
    check_discrete_divergence(g, pieces, 1)
    # the same plate meshed with rounded coordinates (0.1 * 3 = 0.30000000000000004, 0.1 * 6 =
    # 0.6000000000000001, 0.1 * 2 = 0.2): snapped onto the grid lines, so the same zones, exactly 1
    x2 = np.array([[0.1 * 3, 0.0], [0.1 * 6, 0.0], [0.1 * 6, 0.1 * 2], [0.1 * 3, 0.1 * 2]])
    assert x2[0, 0] != 0.3
    p2 = clip_surface(g, x2, segs)
    assert np.array_equal(p2.zone, pieces.zone) and np.array_equal(p2.centroid, pieces.centroid)
    z2, f2 = blocked_fractions(g, p2, 1)
    assert np.array_equal(z2, zones) and np.array_equal(f2, frac)


# -------------------------------------------------------------------------------- 3-D bodies
R3 = rotation_3d(0.3, 0.5, -0.2)


def cube_halfspaces(rotation, centre, half):
    n = np.concatenate([rotation.T, -rotation.T])             # rows: the rotated +-axes
    o = n @ np.asarray(centre) + half
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    return n, o, corners @ rotation.T + centre


def bodies_3d():
    return {
        "rotated_cube": (Grid([0, 0, 0], [1, 1, 1], [7, 6, 8]),) + box_surface(
            [-0.25] * 3, [0.25] * 3, [3, 2, 4], rotation=R3, centre=[0.52, 0.49, 0.47]),
        "grid_box": (Grid([0, 0, 0], [1, 1, 1], [10, 10, 10]),) + box_surface(
            [0.3, 0.2, 0.0], [0.7, 0.5, 0.4], [3, 5, 2]),
        "sphere": (Grid([-1, -1, -1], [1, 1, 1], [9, 10, 11]),) + cube_sphere_surface(6, 0.7, (0.05, -0.1, 0.08)),
    }


@pytest.fixture(scope="module")
def clipped_3d():
    return {k: (g, x, q, clip_surface(g, x, q)) for k, (g, x, q) in bodies_3d().items()}


@pytest.mark.parametrize("name", ["rotated_cube", "grid_box", "sphere"])
def test_polyhedron_volume_areas_normals(clipped_3d, name):
    g, x, q, pieces = clipped_3d[name]
    zones, frac = blocked_fractions(g, pieces, 1)
    V = enclosed_volume(x, q)
    assert np.all(np.diff(zones) > 0) and np.all((frac > 0) & (frac <= 1))
    # measured 0 / 1.4e-16 / 0 (rotated cube / grid box / sphere)
    assert abs(frac.sum() * g.zone_volume - V) <= 1e-13 * V
    A = facet_areas(x, q)
    # measured 6.7e-16 / 4.3e-16 / 5.2e-16 relative
    assert np.max(np.abs(np.bincount(pieces.facet, pieces.area, len(q)) - A) / A) < 2e-15
    # measured 6.1e-17 / 4.3e-18 / 1.6e-16 of the surface area
    assert np.abs(pieces.area @ pieces.normal).max() < 1e-15 * A.sum()
    # quadrature weights sum to each piece's area (measured 6.7e-16 rel), all positive
    assert np.all(pieces.qw > 0)
    assert np.allclose(np.bincount(pieces.qpiece, pieces.qw), pieces.area, rtol=2e-15, atol=0)
    # shape functions: partitions of unity (measured 3.3e-16) that reproduce the position (3.3e-16
    # foreground, 2.2e-16 background; coordinates <= 1)
    assert np.allclose(pieces.qf.sum(1), 1, rtol=0, atol=1e-15)
    assert np.allclose(pieces.qb.sum(1), 1, rtol=0, atol=1e-15)
    assert np.allclose(np.einsum("qa,qak->qk", pieces.qf, x[q[pieces.facet[pieces.qpiece]]]), pieces.qp,
                       rtol=0, atol=1e-15)
    corners = g.node_ijk(g.zone_nodes(pieces.zone))[pieces.qpiece]     # (nq, 8, 3)
    cx = np.stack([g.planes(d)[corners[..., d]] for d in range(3)], -1)
    assert np.allclose(np.einsum("qc,qck->qk", pieces.qb, cx), pieces.qp, rtol=0, atol=1e-15)
    lo, hi = zone_box(g, pieces.zone)
    assert np.all((pieces.qp >= lo[pieces.qpiece]) & (pieces.qp <= hi[pieces.qpiece]))


def test_rotated_cube_fractions_per_zone(clipped_3d):
    g, x, q, pieces = clipped_3d["rotated_cube"]
    zones, frac = blocked_fractions(g, pieces, 1)
    n, o, _ = cube_halfspaces(R3, [0.52, 0.49, 0.47], 0.25)
    ref = np.array([convex_polyhedron_in_zone(g, n, o, z) for z in range(g.n_zones)]) / g.zone_volume
    assert np.array_equal(np.flatnonzero(ref > 1e-14), zones)
    # measured 1.9e-15 (fraction units), about the reference's own round-off; fully covered zones
    # exactly 1
    assert np.max(np.abs(frac[:, 0] - ref[zones])) < 5e-15
    uncut = ~np.isin(zones, pieces.zone)                        # fully covered zones: exactly 1
    assert np.all(frac[uncut, 0] == 1.0) and np.all(ref[zones[uncut]] > 1 - 1e-14)


def test_grid_box_fractions_and_coverage_exact(clipped_3d):
    """Box [0.3, 0.7] x [0.2, 0.5] x [0, 0.4] on a 10^3 grid of [0, 1]^3: faces on grid planes, one on
    the boundary z = 0: fractions and coverages exactly 1 on the box's zones/faces, nothing else."""
    g, x, q, pieces = clipped_3d["grid_box"]
    zones, frac = blocked_fractions(g, pieces, 1)
    rng = [range(3, 7), range(2, 5), range(0, 4)]
    ref = sorted(g.zone_ids(np.array([(i, j, k) for i in rng[0] for j in rng[1] for k in rng[2]])))
    assert np.array_equal(zones, ref) and np.all(frac == 1.0)
    for d in range(3):
        fids, cov = face_coverage(g, pieces, 1, d)
        r = list(rng)
        r[d] = range(r[d].start, r[d].stop + 1)
        ref = sorted(g.face_ids(d, np.array([(i, j, k) for i in r[0] for j in r[1] for k in r[2]])))
        assert np.array_equal(fids, ref) and np.all(cov == 1.0)
    # the face on z = 0 (grid boundary) went to the inner zones, the others to the outward zones
    ijk = g.zone_ijk(pieces.zone)
    nz = pieces.normal[:, 2]
    assert np.all(ijk[nz == -1.0, 2] == 0) and np.all(ijk[nz == 1.0, 2] == 4)
    assert np.all(ijk[pieces.normal[:, 0] == 1.0, 0] == 7) and np.all(ijk[pieces.normal[:, 0] == -1.0, 0] == 2)
    assert np.all(ijk[pieces.normal[:, 1] == 1.0, 1] == 5) and np.all(ijk[pieces.normal[:, 1] == -1.0, 1] == 1)


def test_offset_box_fractions_are_products_of_overlaps():
    g = Grid([-1.0, 0.0, 0.0], [1.0, 1.0, 2.0], [8, 5, 6])
    lo, hi = np.array([-0.61, 0.13, 0.4]), np.array([0.37, 0.71, 1.33])
    x, q = box_surface(lo, hi, [4, 3, 5])
    zones, frac = blocked_fractions(g, clip_surface(g, x, q), 1)
    ijk = g.zone_ijk(np.arange(g.n_zones))
    ref = np.ones(g.n_zones)
    for d in range(3):
        X = g.planes(d)
        ref *= np.clip(np.minimum(X[ijk[:, d] + 1], hi[d]) - np.maximum(X[ijk[:, d]], lo[d]), 0, None) / g.h[d]
    assert np.array_equal(np.flatnonzero(ref > 0), zones)
    assert np.max(np.abs(frac[:, 0] - ref[zones])) < 2e-15          # measured 3.3e-16


def test_rotated_cube_face_coverage_from_sections(clipped_3d):
    """Covered fraction of the faces normal to each axis: the cube's section by the face's plane is a
    convex polygon (clip the face rectangle by the cube's half-planes in that plane)."""
    g, x, q, pieces = clipped_3d["rotated_cube"]
    n, o, _ = cube_halfspaces(R3, [0.52, 0.49, 0.47], 0.25)
    for d in range(3):
        fids, cov = face_coverage(g, pieces, 1, d)
        e1, e2 = [e for e in range(3) if e != d]
        ref = []
        for f in g.face_ijk(d, np.arange(np.prod(g.face_shape(d)))):
            X = g.planes(d)[f[d]]
            a0, a1 = g.planes(e1)[f[e1]], g.planes(e1)[f[e1] + 1]
            b0, b1 = g.planes(e2)[f[e2]], g.planes(e2)[f[e2] + 1]
            # local coordinates from the face's corner (a0, b0)
            p = np.array([[0.0, 0.0], [a1 - a0, 0.0], [a1 - a0, b1 - b0], [0.0, b1 - b0]])
            for nn, oo in zip(n, o):
                p = clip_convex_2d(p, nn[e1], nn[e2], oo - nn[d] * X - nn[e1] * a0 - nn[e2] * b0)
            ref.append(shoelace(p) / ((a1 - a0) * (b1 - b0)))
        ref = np.array(ref)
        assert np.array_equal(np.flatnonzero(ref > 1e-14), fids)
        assert np.max(np.abs(cov[:, 0] - ref[fids])) < 6e-15          # measured 2.2e-15


def check_discrete_divergence(g, pieces, n_bodies):
    """For every zone and body: sum of the pieces' area vectors + (covered upper - lower face areas)
    per axis = 0 (divergence theorem on body ∩ zone; pieces on the grid boundary count as outside)."""
    inner = ~on_boundary(g, pieces)
    h = g.h
    for b in range(n_bodies):
        sel = inner & (pieces.body == b)
        total = np.zeros((g.n_zones, g.dim))
        for d in range(g.dim):
            total[:, d] = np.bincount(pieces.zone[sel], pieces.area[sel] * pieces.normal[sel, d], g.n_zones)
            fids, cov = face_coverage(g, pieces, n_bodies, d)
            ijk = g.face_ijk(d, fids)
            face_area = np.prod(h) / h[d]
            below = ijk[:, d] < g.cells[d]            # the face is the lower face of zone ijk
            total[g.zone_ids(ijk[below]), d] -= cov[below, b] * face_area
            above = ijk[:, d] > 0                      # ... and the upper face of zone ijk - e_d
            up = ijk[above].copy()
            up[:, d] -= 1
            total[g.zone_ids(up), d] += cov[above, b] * face_area
        assert np.abs(total).max() < 4e-15 * np.prod(h) / h.min()     # measured 1.1e-15 (64-gon 2-D)


@pytest.mark.parametrize("name", ["rotated_cube", "grid_box", "sphere"])
def test_discrete_divergence_theorem_per_zone(clipped_3d, name):
    g, x, q, pieces = clipped_3d[name]
    check_discrete_divergence(g, pieces, 1)


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_discrete_divergence_theorem_per_zone_2d(name):
    g = Grid([0.0, 0.0], [1.0, 1.0], [13, 11])
    x, segs = polygon(POLYGONS[name])
    check_discrete_divergence(g, clip_surface(g, x, segs), 1)


def test_two_bodies_and_sphere_touching_the_grid_boundary():
    """Two bodies in one call: fractions per body; a box filling the whole grid (every face on the
    boundary) is covered exactly."""
    g = Grid([0, 0, 0], [1, 1, 1], [4, 5, 3])
    x1, q1 = box_surface([0, 0, 0], [1, 1, 1], [2, 3, 2])
    x2, q2 = cube_sphere_surface(4, 0.3, (0.5, 0.5, 0.5))
    x = np.concatenate([x1, x2])
    q = np.concatenate([q1, q2 + len(x1)])
    body = np.repeat([0, 1], [len(q1), len(q2)])
    pieces = clip_surface(g, x, q, body)
    zones, frac = blocked_fractions(g, pieces, 2)
    assert np.array_equal(zones, np.arange(g.n_zones)) and np.all(frac[:, 0] == 1.0)
    V2 = enclosed_volume(x2, q2)
    assert abs(frac[:, 1].sum() * g.zone_volume - V2) < 1e-13 * V2             # measured 9.2e-16
    for d in range(3):
        fids, cov = face_coverage(g, pieces, 2, d)
        assert fids.size == np.prod(g.face_shape(d)) and np.all(cov[:, 0] == 1.0)
    check_discrete_divergence(g, pieces, 2)


# ---------------------------------------------------------------------------------- quadrature
def test_triangle_rule_is_degree_4():
    from math import factorial
    b = _TRI_BARY
    for i in range(6):
        for j in range(6 - i):
            exact = 2.0 * factorial(i) * factorial(j) / factorial(i + j + 2)
            got = np.sum(_TRI_W * b[:, 1] ** i * b[:, 2] ** j)
            if i + j <= 4:
                assert abs(got - exact) < 2e-16        # measured 5.6e-17
            elif i == 5:
                assert abs(got - exact) > 1e-5         # degree 5 is not exact (the rule's limit)


def poly4(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return 1 + 2 * x - y + 3 * z + x * y - 2 * z * z + x * y * z + 0.5 * x ** 2 * z + y ** 4 - x * y * z ** 2


def test_quadrature_on_flat_quad_3d():
    """∫ over a tilted parallelogram (one flat quad facet cut into many pieces) of a linear, a
    quadratic and a degree-4 polynomial (background x foreground degree) against tensor Gauss."""
    g = Grid([0, 0, 0], [1, 1, 1], [7, 5, 6])
    a = np.array([0.11, 0.17, 0.23])
    u, v = np.array([0.71, 0.13, 0.29]), np.array([-0.05, 0.62, 0.41])
    x = np.array([a, a + u, a + u + v, a + v])
    pieces = clip_surface(g, x, np.array([[0, 1, 2, 3]]))
    assert np.unique(pieces.zone).size > 20
    s, w = np.polynomial.legendre.leggauss(4)
    s, w = 0.5 * (s + 1), 0.5 * w
    S, T = np.meshgrid(s, s, indexing="ij")
    P = a + S[..., None] * u + T[..., None] * v
    J = np.linalg.norm(np.cross(u, v))
    for f in (lambda p: 1 + p[..., 0] - 2 * p[..., 1] + p[..., 2],
              lambda p: p[..., 0] * p[..., 1] - p[..., 2] ** 2 + p[..., 0], poly4):
        exact = J * np.sum(np.outer(w, w) * f(P))
        got = np.sum(pieces.qw * f(pieces.qp))
        assert abs(got - exact) < 2e-15 * abs(exact)     # measured 6.4e-16 / 4.6e-16 / 4.2e-16 relative


def test_quadrature_on_segment_2d():
    g = Grid([0.0, 0.0], [1.0, 1.0], [9, 7])
    x = np.array([[0.05, 0.93], [0.97, 0.08]])
    pieces = clip_surface(g, x, np.array([[0, 1]]))
    L = np.linalg.norm(x[1] - x[0])
    # ∫ of t (the foreground function of node 1) * t^2 and of x^2 y (degree 3) along the segment
    t = pieces.qf[:, 1]
    assert abs(np.sum(pieces.qw * t ** 3) - L / 4) < 1e-15       # measured 0
    d = x[1] - x[0]
    s, w = np.polynomial.legendre.leggauss(3)
    s, w = 0.5 * (s + 1), 0.5 * w
    P = x[0] + s[:, None] * d
    exact = L * np.sum(w * P[:, 0] ** 2 * P[:, 1])
    assert abs(np.sum(pieces.qw * pieces.qp[:, 0] ** 2 * pieces.qp[:, 1]) - exact) < 1e-16   # measured 2.8e-17


# ------------------------------------------------------------------------------- determinism
def reorder(pieces, perm_facet):
    """Pieces with their facets renumbered by perm_facet and re-sorted canonically."""
    facet = perm_facet[pieces.facet]
    part = np.zeros_like(facet)
    # the two parts of a 3-D quad: the piece order within (zone, facet) is part 0 then 1
    same = np.r_[False, (np.diff(pieces.zone) == 0) & (np.diff(pieces.facet) == 0)]
    part[same] = 1
    order = np.lexsort((part, facet, pieces.body, pieces.zone))
    counts = np.bincount(pieces.qpiece, minlength=pieces.zone.size)
    start = np.r_[0, np.cumsum(counts)[:-1]]
    new_start = np.r_[0, np.cumsum(counts[order])[:-1]]
    qidx = np.repeat(start[order] - new_start, counts[order]) + np.arange(counts.sum())
    return Pieces(zone=pieces.zone[order], body=pieces.body[order], facet=facet[order],
                  area=pieces.area[order], normal=pieces.normal[order], centroid=pieces.centroid[order],
                  qp=pieces.qp[qidx], qw=pieces.qw[qidx], qpiece=np.repeat(np.arange(order.size), counts[order]),
                  qf=pieces.qf[qidx], qb=pieces.qb[qidx])


def same(p1, p2):
    return all(np.array_equal(getattr(p1, k), getattr(p2, k)) for k in Pieces.__dataclass_fields__)


@pytest.mark.parametrize("name", ["sphere", "rotated_cube"])
def test_independent_of_facet_order_and_splitting(clipped_3d, name):
    g, x, q, pieces = clipped_3d[name]
    rng = np.random.default_rng(7)
    perm = rng.permutation(len(q))
    shuffled = clip_surface(g, x, q[perm])
    assert same(reorder(shuffled, perm), pieces)
    z0, f0 = blocked_fractions(g, pieces, 1)
    z1, f1 = blocked_fractions(g, shuffled, 1)
    assert np.array_equal(z0, z1) and np.array_equal(f0, f1)              # bitwise
    for d in range(3):
        a, b = face_coverage(g, pieces, 1, d), face_coverage(g, shuffled, 1, d)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # split the facet list in two calls: the pieces of each facet are the same
    k = len(q) // 3
    p1, p2 = clip_surface(g, x, q[:k]), clip_surface(g, x, q[k:])
    both = Pieces(*[np.concatenate([getattr(p1, f), getattr(p2, f) + (k if f == "facet" else 0)
                                    + (p1.zone.size if f == "qpiece" else 0)])
                    for f in Pieces.__dataclass_fields__])
    assert same(reorder(both, np.arange(len(q))), pieces)


# ------------------------------------------------------------------------------ inputs, utils
def test_body_outside_the_grid_is_refused():
    g = Grid([0.0, 0.0], [1.0, 1.0], [4, 4])
    x, segs = polygon([[0.2, 0.2], [0.5, 0.2], [0.5, 0.5]])
    x2, segs2 = polygon([[0.6, 0.6], [1.0 + 1e-9, 0.6], [0.8, 0.9]])
    with pytest.raises(GeometryError, match=r"body 1 .*node 4 at \[1.000000001, 0.6\]"):
        clip_surface(g, np.concatenate([x, x2]), np.concatenate([segs, segs2 + 3]), np.repeat([0, 1], 3))
    # on the closed box (and within a few ulps of it) is inside
    x3, s3 = polygon([[0.0, 0.0], [1.0 + 2e-16, 0.0], [1.0, 1.0]])
    assert clip_surface(g, x3, s3).area.sum() > 0


def test_closed_surface_from_cells_orientation():
    pts, hexes = hex_box([0, 0, 0], [1, 2, 3], [2, 3, 4])
    hexes[::3] = hexes[::3][:, [4, 5, 6, 7, 0, 1, 2, 3]]          # some inverted cells
    q = closed_surface_from_cells(pts, hexes, "hexahedron")
    assert q.shape == (2 * (6 + 8 + 12), 4)
    assert np.isclose(enclosed_volume(pts, q), 6.0, rtol=1e-14)
    p2 = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], float)
    quads = np.array([[0, 1, 4, 3], [1, 2, 5, 4]])
    quads[1] = quads[1][::-1]
    s = closed_surface_from_cells(p2, quads, "quad")
    assert s.shape == (6, 2) and np.isclose(enclosed_volume(p2, s), 2.0)


def test_geometry_cost_reports_timings():
    out = geometry_cost(600)
    assert out["n_facets"] == 600 and out["n_pieces"] > out["n_facets"]
    assert all(out[k] >= 0 for k in ("clip_s", "fractions_s", "faces_s"))


# ------------------------------------------------------------------ the interior as runs (coverage)
def _coverage_cases():
    out = {}
    for name in sorted(POLYGONS):
        g = Grid([0.0, 0.0], [1.0, 1.0], [13, 11])
        x, segs = polygon(POLYGONS[name])
        out[name] = (g, clip_surface(g, x, segs))
    for name, (g, x, q) in bodies_3d().items():
        out[name] = (g, clip_surface(g, x, q))
    return out


@pytest.mark.parametrize("name", ["rotated_square", "regular_64gon", "rotated_cube", "grid_box", "sphere"])
def test_coverage_runs_and_listed_values_are_the_full_lists(name):
    """`coverage` lists only what the surface touches and gives the interior as runs along x; with the
    runs' zones at fraction 1 and every face between two zones at fraction 1 covered whole, it is
    exactly (bit for bit) the full lists of blocked_fractions / face_coverage -- and it lists fewer."""
    g, pieces = _coverage_cases()[name]
    c = coverage(g, pieces, 1)
    zones, frac = blocked_fractions(g, pieces, 1)
    run_zones = np.concatenate([np.arange(s, s + n) for s, n in zip(c.run_start, c.run_length)] or [[]])
    run_zones = run_zones.astype(np.int64)
    assert np.intersect1d(run_zones, c.zones).size == 0
    b = np.zeros(g.n_zones)
    b[c.zones] = c.fractions[:, 0]
    b[run_zones] = 1.0
    assert np.array_equal(np.flatnonzero(b), zones) and np.array_equal(b[zones], frac[:, 0])
    if name != "grid_box":  # (a box on the grid planes: every covered zone in a run, none listed)
        assert c.zones.size < zones.size
    shape = [int(v) for v in g.cells[::-1]]
    full = (b == 1.0).reshape(shape)  # zones covered whole, indexed [k, j, i] (x fastest)
    for d in range(g.dim):
        fids, cov = face_coverage(g, pieces, 1, d)
        a = g.dim - 1 - d  # axis of d in the [k, j, i] array
        lo = [slice(None)] * g.dim
        hi = [slice(None)] * g.dim
        lo[a], hi[a] = slice(0, -1), slice(1, None)
        inner = np.zeros([v + (1 if i == a else 0) for i, v in enumerate(shape)], bool)
        mid = [slice(None)] * g.dim
        mid[a] = slice(1, -1)
        inner[tuple(mid)] = full[tuple(lo)] & full[tuple(hi)]
        f = np.where(inner.ravel(), 1.0, 0.0)
        ids, val = c.faces[d]
        assert not np.any(inner.ravel()[ids] & (val[:, 0] != 1.0))
        f[ids] = val[:, 0]
        assert np.array_equal(np.flatnonzero(f), fids) and np.array_equal(f[fids], cov[:, 0])


def test_2d_segment_clipper_equals_the_generic_kernel():
    """clip_surface's 2-D kernel (_clip_segments_2d, scalars) gives the generic kernel's pieces and
    points bit for bit: random segments, segments on grid planes (both directions), along them,
    through nodes, degenerate ones, and one crossing many zones."""
    from orchestrator.coupling import clipping as CL
    from orchestrator.coupling.pieces import _planes

    grid = Grid([0.0, -1.0], [1.0, 1.0], [9, 13])
    X0, X1 = grid.planes(0), grid.planes(1)
    rng = np.random.default_rng(5)
    pts = [rng.uniform([0, -1], [1, 1], (40, 2)),
           np.array([[X0[3], -0.5], [X0[3], 0.7], [0.2, X1[4]], [0.9, X1[4]], [X0[2], X1[2]], [X0[5], X1[9]],
                     [0.4, 0.4], [0.4, 0.4], [0.0, -1.0], [1.0, 1.0], [X0[0], 0.2], [X0[0], -0.3]])]
    x = np.concatenate(pts)
    n = x.shape[0]
    segs = np.concatenate([rng.integers(0, n, (60, 2)), np.arange(40, n).reshape(-1, 2),
                           np.arange(40, n).reshape(-1, 2)[:, ::-1]]).astype(np.int64)
    planes = _planes(grid)
    generic = CL._clip_kernel(x, segs, planes, grid.cells.astype(np.int64), CL._GAUSS2_T, CL._TRI_BARY, CL._TRI_W)
    special = CL._clip_segments_2d(x, segs, X0, X1, CL._GAUSS2_T)
    assert generic[0].size > 150  # pieces
    for a, b in zip(generic, special):
        np.testing.assert_array_equal(a, b)


def test_stable_order_and_by_id_equal_the_numpy_references():
    """_stable_order = np.argsort(kind="mergesort") (already sorted keys, keys sorted within rows, any
    keys); _by_id = np.unique with the values scattered by the inverse (sorted or not)."""
    from orchestrator.coupling import coverage as CV

    rng = np.random.default_rng(7)
    n_rows, n_pos = 11, 9
    for trial in range(6):
        npc = 200
        body = rng.integers(0, 3, npc).astype(np.int64)
        row = rng.integers(0, n_rows, npc)
        pos = rng.integers(0, n_pos, npc)
        key = (body * n_rows + row) * n_pos + pos
        if trial % 3 == 0:
            key = np.sort(key)
        elif trial % 3 == 1:   # sorted by position within (body, row) but rows interleaved
            o = np.lexsort((pos, row * 0 + rng.integers(0, 5, npc)))
            key, body = key[o], body[o]
        np.testing.assert_array_equal(CV._stable_order(key, body, n_rows, n_pos), np.argsort(key, kind="mergesort"))
        ids = rng.integers(0, 50, npc)
        ids = np.sort(ids) if trial % 2 else ids
        bodies = rng.integers(0, 2, npc)
        pairs = np.unique(ids * 2 + bodies, return_index=True)[1]   # one value per (id, body)
        if trial % 2 == 0:
            pairs = rng.permutation(pairs)
        ids, bodies, vals = ids[pairs], bodies[pairs], rng.random(pairs.size)
        u, inv = np.unique(ids, return_inverse=True)
        ref = np.zeros((u.size, 2))
        ref[inv, bodies] = vals
        got_u, got = CV._by_id(ids, bodies, vals, 2)
        np.testing.assert_array_equal(got_u, u)
        np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("dim", [2, 3])
def test_piece_order_is_the_same_by_one_key_or_four_sorts(monkeypatch, dim):
    """clip_surface orders the pieces by (zone, body, facet, part) with one packed int64 key, or by four
    stable sorts where the key could overflow: the same pieces in the same order, two bodies."""
    from orchestrator.coupling import geometry as G

    if dim == 2:
        grid = Grid([0.0, 0.0], [1.0, 1.0], [7, 6])
        t = np.linspace(0, 2 * np.pi, 23, endpoint=False)
        ring = np.stack([np.cos(t), np.sin(t)], axis=1)
        x = np.concatenate([[0.3, 0.5] + 0.2 * ring, [0.7, 0.45] + 0.15 * ring])
        n = t.size
        facets = np.concatenate([np.stack([np.arange(n), (np.arange(n) + 1) % n], 1),
                                 n + np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)])
    else:
        grid = Grid([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [5, 4, 6])
        pts, quads = G.cube_sphere_surface(3, radius=0.2, centre=(0.3, 0.5, 0.5))
        pts2, _ = G.cube_sphere_surface(3, radius=0.15, centre=(0.72, 0.45, 0.5))
        x = np.concatenate([pts, pts2])
        facets = np.concatenate([quads, quads + pts.shape[0]])
    body = np.repeat([0, 1], facets.shape[0] // 2)
    ref = G.clip_surface(grid, x, facets, body)
    monkeypatch.setattr(G, "_SORT_KEY_LIMIT", 1.0)
    got = G.clip_surface(grid, x, facets, body)
    assert ref.zone.size > 40 and np.any(np.diff(ref.zone) == 0)   # zones with several pieces
    for f in dataclasses.fields(ref):
        np.testing.assert_array_equal(getattr(got, f.name), getattr(ref, f.name), err_msg=f.name)
