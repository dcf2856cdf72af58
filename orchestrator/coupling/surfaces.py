"""Closed surfaces for the interface geometry: the exterior facets of a cell mesh, oriented outward
(clip_surface's convention), and a sphere-like quad surface for tests and the cost probe."""
from __future__ import annotations

import numpy as np

from orchestrator.coupling.pieces import GeometryError

# Exterior faces of positively oriented cells, right-handed outward (the meshio/VTK node order).
_QUAD_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
_HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]],
                      dtype=np.int64)
_QUAD_FLIP = np.array([0, 3, 2, 1], dtype=np.int64)
_HEX_FLIP = np.array([0, 3, 2, 1, 4, 7, 6, 5], dtype=np.int64)



def closed_surface_from_cells(points, cells, cell_type: str) -> np.ndarray:
    """Exterior facets of a quad (2-D: segments (nf, 2)) or hexahedron (3-D: quads (nf, 4)) mesh,
    oriented with the outward normal of clip_surface's convention; inverted cells are mirrored
    first.  Facets in the order of their cells and local faces."""
    points = np.asarray(points, dtype=np.float64)
    cells = np.asarray(cells, dtype=np.int64)
    if cell_type == "quad":
        local, flip = _QUAD_EDGES, _QUAD_FLIP
        x = points[cells]
        signed = 0.5 * np.sum(x[:, :, 0] * np.roll(x[:, :, 1], -1, axis=1)
                              - np.roll(x[:, :, 0], -1, axis=1) * x[:, :, 1], axis=1)   # shoelace
    elif cell_type == "hexahedron":
        local, flip = _HEX_FACES, _HEX_FLIP
        f = points[cells[:, local]]                                   # (ne, 6, 4, 3)
        s = 0.5 * np.cross(f[:, :, 2] - f[:, :, 0], f[:, :, 3] - f[:, :, 1])
        signed = np.sum(np.einsum("efk,efk->ef", f.mean(axis=2), s), axis=1) / 3.0   # div theorem
    else:
        raise GeometryError(f"cell_type must be 'quad' or 'hexahedron', got {cell_type!r}")
    if cells.ndim != 2 or cells.shape[1] != flip.size:
        raise GeometryError(f"{cell_type} cells must have shape (ne, {flip.size}), got {cells.shape}")
    cells = np.where((signed < 0)[:, None], cells[:, flip], cells)
    faces = cells[:, local].reshape(-1, local.shape[1])
    _, inv, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inv.reshape(-1)] == 1]


def cube_sphere_surface(n: int, radius: float = 1.0, centre=(0.0, 0.0, 0.0)):
    """A closed sphere-like quad surface: the 6 n^2 boundary quads of an n^3 hex cube projected
    radially onto the sphere (outward).  Returns (points (nn, 3), quads (6 n^2, 4))."""
    t = np.linspace(-1.0, 1.0, n + 1)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    ids = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    c = ids[:-1, :-1, :-1].reshape(-1)
    sx, sy, sz = (n + 1) ** 2, n + 1, 1
    cells = np.stack([c, c + sx, c + sx + sy, c + sy, c + sz, c + sx + sz, c + sx + sy + sz, c + sy + sz], 1)
    quads = closed_surface_from_cells(g, cells, "hexahedron")
    used = np.unique(quads)
    remap = np.full(g.shape[0], -1, np.int64)
    remap[used] = np.arange(used.size)
    p = g[used]
    p = np.asarray(centre, dtype=np.float64) + radius * p / np.linalg.norm(p, axis=1)[:, None]
    return p, remap[quads]
