"""How thick a coupled body is in the background's zones, and the rule ``immerse check`` applies.

One multiplier and one open fraction per cut zone (Puso et al. 2015) hold the gas on one side of a
surface in each zone. A body thinner than about a zone and a half leaves zones with gas on both of
its sides: the zone's single open fraction cannot keep them apart, and the body leaks or is pushed
as one (README, "Coupling"). So a coupled body thinner than MIN_ZONES zones is refused unless the
case accepts it (``lagrange.bodies[i].accept_thin = true``), with its thickness in zones and in
elements, where, and what to do.

The local thickness at a surface facet is the distance along its inward normal to the nearest facet
of the body that faces the other way and lies across from it (the shape-diameter idea: a ray cast
into the body); the body's thickness in zones is the smallest, over its facets, of that distance
over the zone's width along the normal (sum_d |n_d| h_d). Facets on a face of the grid's box touch
no gas (a wall, a symmetry plane, a periodic face the body continues across) and take no part. Only
facets within MIN_ZONES zones are searched (a k-d tree of the facet centroids), so the cost grows
with the surface, not the grid.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_ZONES = 1.5
"""The thinnest a coupled body may be, in zones of the background (README: thicker than 1.5 zones;
embedded_piston_sod's block is 1.5 zones thick and holds Sod's contact to 0.65 %)."""

PAIR_BUDGET = 5_000_000
"""Facet pairs examined at most (about 100 MB): finer surfaces are searched from every k-th facet."""

OPPOSED = -0.5
"""Two facets face each other across the body when their unit normals' product is below this
(antiparallel -1 for a plate; a curved wall's facets across from each other are not exactly)."""


@dataclass
class Thinnest:
    zones: float       # the thickness in zones along the normal there (inf: thicker than searched)
    thickness: float   # m
    where: np.ndarray  # the facet's centroid
    elements: int      # elements through the thickness there (its cell's extent along the normal)


def thinnest(points: np.ndarray, cells: np.ndarray, cell_type: str, lower, upper, cells_grid,
             reach: float = MIN_ZONES) -> Thinnest:
    """The body's thinnest place in zones of the grid (``lower``, ``upper``, ``cells_grid``),
    searched up to ``reach`` zones (thicker places read inf)."""
    from solvers.lagrange.surface import exterior_facets, facet_area_vectors

    points = np.asarray(points, dtype=np.float64)
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    h = (upper - lower) / np.asarray(cells_grid, dtype=np.float64)
    facets, facet_cell = exterior_facets(cells, cell_type, len(points), points)
    x = points[facets]                             # (nf, nodes, dim)
    tol = 1e-9 * float(np.max(upper - lower))
    on_box = (np.all(np.abs(x - lower) <= tol, axis=1) | np.all(np.abs(x - upper) <= tol, axis=1)).any(axis=1)
    facets, facet_cell = facets[~on_box], facet_cell[~on_box]
    if not len(facets):
        return Thinnest(np.inf, np.inf, points.mean(axis=0), 0)
    a = facet_area_vectors(points, facets)
    size = np.linalg.norm(a, axis=1)
    n = a / size[:, None]
    if points.shape[1] == 3:
        size = np.sqrt(size)                       # a quadrilateral's edge
    c = points[facets].mean(axis=1)
    width = np.abs(n) @ h                          # the zone's width along each normal
    radius = reach * float(width.max()) + float(size.max())
    # facets searched from: all, or every stride-th when elements much finer than the zones would give
    # more than PAIR_BUDGET pairs (a thin place spans many facets; a stride keeps the memory bounded)
    per = 4.0 * (radius / max(float(np.median(size)), 1e-300)) ** (points.shape[1] - 1)
    stride = max(1, int(np.ceil(len(c) * per / PAIR_BUDGET)))
    src = np.arange(0, len(c), stride)
    from scipy.spatial import cKDTree   # (here: scipy.spatial takes 0.25 s to import, every check and run paid it)

    m = cKDTree(c[src]).sparse_distance_matrix(cKDTree(c), radius, output_type="ndarray")
    best = np.full(len(c), np.inf)
    if len(m):
        i, j = src[m["i"]], m["j"]
        d = c[i] - c[j]
        depth = np.einsum("kd,kd->k", d, n[i])     # how far j lies behind i, along i's inward normal
        side = np.linalg.norm(d - depth[:, None] * n[i], axis=1)
        ok = (np.einsum("kd,kd->k", n[i], n[j]) < OPPOSED) & (depth > 0.0) & (side <= 0.5 * (size[i] + size[j]))
        np.minimum.at(best, i[ok], depth[ok])
    zones = best / width
    k = int(np.argmin(zones))   # (a facet searched from: the others stay inf)
    if not np.isfinite(zones[k]):
        return Thinnest(np.inf, np.inf, c[k], 0)
    x = points[cells[facet_cell[k]]]                # the facet's own cell: its extent along the normal
    extent = float(np.ptp(x @ n[k]))
    return Thinnest(float(zones[k]), float(best[k]), c[k], max(int(round(best[k] / extent)), 1))


def check_thin_bodies(case: dict) -> None:
    """A coupled case's Lagrangian bodies against MIN_ZONES; CaseError naming the first one thinner
    that does not accept it."""
    from orchestrator.schema.rules import CaseError
    from solvers.lagrange.mesh import MeshError, body_mesh

    if not case.get("coupling") or not case.get("lagrange"):
        return
    g = case["ale"]["grid"]
    dim = int(case["run"]["dimension"])
    h = (np.asarray(g["upper"], float) - np.asarray(g["lower"], float)) / np.asarray(g["cells"], float)
    cell_type = "quad" if dim == 2 else "hexahedron"
    for i, body in enumerate(case["lagrange"]["bodies"]):
        if body.get("accept_thin"):
            continue
        try:
            mesh = body_mesh(body, dim)
        except MeshError:
            continue   # the mesh's own check names it
        t = thinnest(mesh.points, mesh.cells, cell_type, g["lower"][:dim], g["upper"][:dim], g["cells"][:dim])
        if t.zones < MIN_ZONES * (1.0 - 1e-9):
            at = ", ".join(f"{v:.4g}" for v in t.where)
            zone = " x ".join(f"{v:.4g}" for v in h[:dim])
            raise CaseError(
                f"lagrange.bodies[{i}].mesh", body["mesh"],
                f"body {body['name']!r} is {t.zones:.2g} zones thick ({t.thickness:.4g} m at ({at}), "
                f"{t.elements} element{'s' if t.elements != 1 else ''} through it) in the [ale] grid's "
                f"{zone} m zones: a coupled body must be at least {MIN_ZONES:g} zones thick (thinner, one "
                f"zone holds gas on both its sides and cannot keep them apart); refine ale.grid.cells, "
                f"thicken the body, or set lagrange.bodies[{i}].accept_thin = true to run it anyway")
