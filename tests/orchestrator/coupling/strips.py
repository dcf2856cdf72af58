"""An inclined wall that crosses the faces of a doubly periodic box: the strip of thickness t around
the box's diagonal (slope Ly / Lx = tan(angle)) and its periodic images, cut to the box -- a hexagon
along the diagonal and two corner triangles -- as one body of quads (test helper and the mesh of
cases/oblique_slip_wall; plain loops over a dozen polygons are fine here)."""
from __future__ import annotations

import numpy as np


def _strip(P, n):
    """n quads between the edges P0-P1 and P3-P2 of the convex quadrilateral P (counter-clockwise)."""
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    lo, hi = P[0] + s * (P[1] - P[0]), P[3] + s * (P[2] - P[3])
    k = np.arange(n)
    return np.vstack([lo, hi]), np.stack([k, k + 1, n + 2 + k, n + 1 + k], axis=1)


def _triangle_quads(T):
    """A triangle as three quads (corner, edge midpoint, centroid, edge midpoint)."""
    c = T.mean(axis=0)
    m = [(T[k] + T[(k + 1) % 3]) / 2 for k in range(3)]
    return [np.array([T[0], m[0], c, m[2]]), np.array([T[1], m[1], c, m[0]]), np.array([T[2], m[2], c, m[1]])]


def periodic_strip(angle_deg: float, thickness: float, lx: float = 1.0, n_along: int = 20):
    """(points (n, 3), quads (m, 4), ly): the strip of ``thickness`` around the diagonal of the box
    [0, lx] x [0, ly], ly = lx tan(angle), with its periodic images, counter-clockwise quads."""
    th = np.radians(angle_deg)
    ly = lx * np.tan(th)
    delta = 0.5 * thickness / np.cos(th)  # half the strip's height along y
    b = delta / np.tan(th)                 # and along x
    A, B, C = np.array([0.0, 0.0]), np.array([b, 0.0]), np.array([lx, ly - delta])
    D, E, F = np.array([lx, ly]), np.array([lx - b, ly]), np.array([0.0, delta])
    polys = [(np.array([A, B, C, F]), n_along), (np.array([F, C, D, E]), n_along)]
    for T in (np.array([[0.0, ly - delta], [b, ly], [0.0, ly]]), np.array([[lx - b, 0.0], [lx, 0.0], [lx, delta]])):
        polys += [(P, 1) for P in _triangle_quads(T)]
    pts, quads, off = [], [], 0
    for P, n in polys:
        p, q = _strip(P, n)
        pts.append(p)
        quads.append(q + off)
        off += len(p)
    pts, quads = np.vstack(pts), np.vstack(quads)
    # merge the shared corners (the polygons' common edges)
    key = np.round(pts / (1e-12 * lx)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    pts, quads = pts[first], inv.reshape(-1)[quads]
    return np.column_stack([pts, np.zeros(len(pts))]), quads, float(ly)
