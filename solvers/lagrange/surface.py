"""The exterior surface of a Lagrangian mesh: the facets the embedded-mesh coupling integrates over.

A facet (edge of a quad in 2-D, quadrilateral face of a hexahedron in 3-D) is exterior when exactly
one cell has it; in a conforming mesh every other facet is shared by exactly two cells. Facets are
oriented so that the right-hand rule gives the outward normal:

* 2-D segment (a, b):      n |ab| = (y_b - y_a, -(x_b - x_a))
* 3-D quadrilateral (a, b, c, d): n ~ (b - a) x (d - a); its exact area vector (integral of the
  normal over the bilinear face) is (c - a) x (d - b) / 2, which the orientation check uses.

The local face tables of mesh.py (QUAD_FACES, HEX_FACES) already give outward facets for positively
oriented cells (mesh.py flips every cell it builds or reads to a positive volume); with the points
given the orientation is checked against the cell centroid and corrected, so the result does not
rest on that convention. Only quad and hexahedron cells exist in mesh.py; any other cell type is
refused.

Everything is vectorised numpy: faces are keyed by their sorted node tuples, sorted
lexicographically, and the keys that occur once are the exterior facets (no loop over cells).
"""
from __future__ import annotations

import numpy as np

from solvers.elements import facet_area_vectors  # (re-exported: the surface's area vectors)
from solvers.lagrange.mesh import HEX_FACES, QUAD_FACES

__all__ = ["exterior_facets", "facet_area_vectors"]

# cell type (mesh.Mesh.cell_type) -> (nodes per cell, local facets in outward order)
_FACE_TABLES = {"quad": (4, QUAD_FACES), "hexahedron": (8, HEX_FACES)}
# reversal of a facet's orientation that keeps its first node: (a, b) -> (b, a); (a,b,c,d) -> (a,d,c,b)
_REVERSE = {2: np.array([1, 0]), 4: np.array([0, 3, 2, 1])}


def exterior_facets(cells: np.ndarray, cell_type: str, n_nodes: int, points: np.ndarray | None = None):
    """Exterior facets of a mesh and the cell each one bounds.

    cells: (ne, 4) quads or (ne, 8) hexahedra (global node ids, mesh.py orderings); cell_type:
    "quad" or "hexahedron"; n_nodes: number of mesh nodes (ids must lie in 0..n_nodes-1); points:
    (n_nodes, dim) coordinates, when given used to check every facet points away from its cell's
    centroid (and to reverse any that does not).

    Returns (facets, facet_cell): facets (nf, 2) segments or (nf, 4) quadrilaterals of global node
    ids, outward by the right-hand rule, in canonical order (sorted lexicographically by their
    sorted node tuples, so independent of the cell order); facet_cell (nf,) the cell each bounds.
    Raises ValueError for another cell type, a connectivity that does not fit it, or a facet shared
    by more than two cells (a non-conforming or overlapping mesh).
    """
    if cell_type not in _FACE_TABLES:
        raise ValueError(f"exterior_facets: cell type {cell_type!r} is not supported "
                         f"(the Lagrangian meshes are {' or '.join(sorted(_FACE_TABLES))})")
    per_cell, local = _FACE_TABLES[cell_type]
    cells = np.asarray(cells, dtype=np.int64)
    k = local.shape[1]
    if cells.ndim != 2 or cells.shape[1] != per_cell:
        raise ValueError(f"exterior_facets: {cell_type} cells need shape (ne, {per_cell}), got {cells.shape}")
    if len(cells) == 0:
        return np.zeros((0, k), dtype=np.int64), np.zeros(0, dtype=np.int64)
    if cells.min() < 0 or cells.max() >= n_nodes:
        raise ValueError(f"exterior_facets: node ids must lie in 0..{n_nodes - 1}, "
                         f"got {cells.min()}..{cells.max()}")

    nlf = local.shape[0]
    faces = cells[:, local].reshape(-1, k)             # (ne * nlf, k), face f of cell f // nlf
    key = np.sort(faces, axis=1)
    order = np.lexsort(key.T[::-1])                    # lexicographic, first column most significant
    ks = key[order]
    starts = np.flatnonzero(np.concatenate([[True], np.any(ks[1:] != ks[:-1], axis=1)]))
    counts = np.diff(np.append(starts, len(ks)))
    if counts.max() > 2:
        g = int(np.argmax(counts))
        raise ValueError(f"exterior_facets: the facet with nodes {ks[starts[g]].tolist()} belongs to "
                         f"{int(counts[g])} cells (a conforming mesh has at most 2)")
    sel = order[starts[counts == 1]]                   # keys are unique and sorted: canonical order
    facets = faces[sel]
    facet_cell = sel // nlf

    if points is not None:
        pts = np.asarray(points, dtype=np.float64)
        area = facet_area_vectors(pts, facets)
        outward = pts[facets].mean(axis=1) - pts[cells[facet_cell]].mean(axis=1)
        inward = np.einsum("fi,fi->f", area, outward) < 0.0
        if np.any(inward):
            facets[inward] = facets[inward][:, _REVERSE[k]]
    return facets, facet_cell
