"""Exterior facets of quad and hexahedron meshes (solvers/lagrange/surface.py) against analytic
geometry: facet counts, outward orientation (area vectors sum to zero; the divergence theorem gives
the volume), total area, canonical order, refusals.

Tolerances: box coordinates are exact binary fractions here, so the measured sums of area vectors,
total areas and enclosed volumes are exact (error 0); 1e-15 (relative) leaves room for round-off.
The quarter cylinder: sum of area vectors 1.0e-17 of the total area, enclosed volume error 0.
"""
from __future__ import annotations

import numpy as np
import pytest

from solvers.lagrange.mesh import _HEX_FLIP, _QUAD_FLIP, box_mesh, cell_volumes, quarter_cylinder_mesh
from solvers.lagrange.surface import exterior_facets, facet_area_vectors


def divergence_volume(points, facets):
    """Volume (area in 2-D) enclosed by outward facets: (1/dim) sum over facets of x_c . A (exact
    for planar facets; x_c the facet centroid)."""
    a = facet_area_vectors(points, facets)
    xc = points[facets].mean(axis=1)
    return np.einsum("fi,fi->", xc, a) / points.shape[1]


def exterior(mesh, with_points=True):
    return exterior_facets(mesh.cells, mesh.cell_type, mesh.num_points,
                           mesh.points if with_points else None)


def test_quad_box_2x3():
    """[0, 2] x [0, 3] in 2 x 3 cells: 2 (2 + 3) = 10 boundary segments, perimeter 10, area 6."""
    m = box_mesh([0.0, 0.0], [2.0, 3.0], [2, 3])
    facets, cell = exterior(m)
    assert facets.shape == (10, 2)
    a = facet_area_vectors(m.points, facets)
    assert np.abs(a.sum(axis=0)).max() <= 1e-15
    assert np.linalg.norm(a, axis=1).sum() == pytest.approx(10.0, rel=1e-15)
    assert divergence_volume(m.points, facets) == pytest.approx(6.0, rel=1e-15)
    # outward on a convex body: every area vector points away from the box centre
    mid = m.points[facets].mean(axis=1)
    assert np.all(np.einsum("fi,fi->f", a, mid - [1.0, 1.5]) > 0)
    # each facet is an edge of the cell it bounds, in the cell's own order (a->b counter-clockwise)
    for c in range(2):
        assert np.all(np.any(m.cells[cell] == facets[:, [c]], axis=1))


def test_hex_box_2x2x2():
    """[0, 1] x [0, 2] x [0, 3] in 2 x 2 x 2 cells: 6 x 4 = 24 quads, area 2 (2 + 6 + 3) = 22, volume 6."""
    m = box_mesh([0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [2, 2, 2])
    facets, cell = exterior(m)
    assert facets.shape == (24, 4)
    a = facet_area_vectors(m.points, facets)
    assert np.abs(a.sum(axis=0)).max() <= 1e-15
    assert np.linalg.norm(a, axis=1).sum() == pytest.approx(22.0, rel=1e-15)
    assert divergence_volume(m.points, facets) == pytest.approx(6.0, rel=1e-15)
    mid = m.points[facets].mean(axis=1)
    assert np.all(np.einsum("fi,fi->f", a, mid - [0.5, 1.0, 1.5]) > 0)
    # the documented right-hand rule (b - a) x (d - a) gives the same outward direction
    x = m.points[facets]
    n_corner = np.cross(x[:, 1] - x[:, 0], x[:, 3] - x[:, 0])
    assert np.all(np.einsum("fi,fi->f", n_corner, a) > 0)
    assert all(set(f) <= set(m.cells[c]) for f, c in zip(facets.tolist(), cell))


def test_curved_body_encloses_its_volume():
    """Quarter cylinder (butterfly cross-section): the outward facets enclose exactly the sum of
    the cell volumes (its faces are planar: extruded straight edges), and their area vectors sum to
    zero (closed surface)."""
    m = quarter_cylinder_mesh(0.01, 0.03, 5, 4)
    facets, _ = exterior(m)
    a = facet_area_vectors(m.points, facets)
    assert np.abs(a.sum(axis=0)).max() <= 1e-16 * np.linalg.norm(a, axis=1).sum()
    assert divergence_volume(m.points, facets) == pytest.approx(cell_volumes(m).sum(), rel=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_canonical_order_and_orientation_check(dim):
    """The facets do not depend on the order of the cells; facets of cells given with the mirrored
    (negative) node order are reversed to point outward when the points are given."""
    m = box_mesh([0.0] * dim, [1.0] * dim, [3] * dim)
    ref, ref_cell = exterior(m)
    keys = np.sort(ref, axis=1)
    assert np.all(np.diff(np.lexsort(keys.T[::-1])) > 0)  # already sorted lexicographically
    rng = np.random.default_rng(1)
    perm = rng.permutation(m.num_cells)
    f, c = exterior_facets(m.cells[perm], m.cell_type, m.num_points, m.points)
    assert np.array_equal(f, ref)
    assert np.array_equal(perm[c], ref_cell)

    mirrored = m.cells.copy()
    mirrored[::2] = mirrored[::2][:, _QUAD_FLIP if dim == 2 else _HEX_FLIP]
    raw, _ = exterior_facets(mirrored, m.cell_type, m.num_points)  # trusts the (now wrong) tables
    fixed, _ = exterior_facets(mirrored, m.cell_type, m.num_points, m.points)
    assert divergence_volume(m.points, raw) < 0.99  # some facets point inwards without the check
    assert np.array_equal(np.sort(fixed, axis=1), keys)
    assert divergence_volume(m.points, fixed) == pytest.approx(1.0, rel=1e-15)
    a = facet_area_vectors(m.points, fixed)
    mid = m.points[fixed].mean(axis=1)
    assert np.all(np.einsum("fi,fi->f", a, mid - 0.5) > 0)


def test_refusals():
    m = box_mesh([0.0, 0.0], [2.0, 1.0], [2, 1])
    with pytest.raises(ValueError, match="cell type 'triangle' is not supported"):
        exterior_facets(m.cells[:, :3], "triangle", m.num_points)
    with pytest.raises(ValueError, match=r"quad cells need shape \(ne, 4\)"):
        exterior_facets(m.cells[:, :3], "quad", m.num_points)
    with pytest.raises(ValueError, match="node ids must lie in 0..4"):
        exterior_facets(m.cells, "quad", 5)
    # a third cell on the interior edge (a duplicated cell): not a conforming mesh
    with pytest.raises(ValueError, match=r"facet with nodes \[1, 4\] belongs to 3 cells"):
        exterior_facets(np.vstack([m.cells, m.cells[:1]]), "quad", m.num_points)
    f, c = exterior_facets(np.zeros((0, 8), dtype=np.int64), "hexahedron", 0)
    assert f.shape == (0, 4) and c.shape == (0,)
