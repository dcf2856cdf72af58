"""Interface geometry of the embedded-mesh coupling: Lagrangian body surfaces clipped against the
zones of the fixed Cartesian background grid (DESIGN.md, "The constraint solve").

Surfaces
--------
A body is a closed surface of facets: 2-D segments ``(a, b)`` oriented so that the outward normal is
``(yb - ya, -(xb - xa)) / L`` (the body's counter-clockwise boundary), 3-D quads ``(a, b, c, d)`` with
outward normal along ``(b - a) x (d - a)``.  A quad is split along its diagonal 0-2 into the triangles
``(0, 1, 2)`` and ``(0, 2, 3)`` (its *parts*); that triangulated surface is what is clipped, integrated
and enclosed, so a warped quad is treated consistently everywhere (the volumes of the references
are those of the triangulated surface).

Pieces
------
A *piece* is the part of one segment / triangle inside one zone: a sub-segment or a convex polygon,
planar, so it has one normal (a quad gives up to two pieces per zone, one per part, both carrying
the quad's facet index).  Each element is split slab by slab (along x, then each slab piece along
y, then along z) at the grid planes strictly inside its range, so it only visits the zones its
bounding box covers and the work is linear in the number of facets for facets of bounded size;
every piece has a positive extent across each plane it was cut at (no zero-area slivers from a
facet that merely touches a plane).

*Facets on grid planes.*  A facet whose vertices all lie on a grid plane normal to d belongs to the
zone on its outward side (normal component > 0: the zone above the plane), at the grid boundary to
the inner zone.  Why this rule keeps everything exact: it is the limit of the body dilated outward
by epsilon -> 0, whose surface lies strictly inside the outward zone, and the volume fractions and
face coverages of the dilated body tend to those of the body.  Positions are compared with the
canonical grid planes of grid.py; node coordinates within ``SNAP_ULPS`` ulps (of the grid's
coordinate scale) of a plane are first moved onto it (``Grid.snap``), so a body face meshed at
``x = 0.3`` lies on the plane whichever way the mesh generator rounded it (the volume changes by
O(eps)).

Quadrature (degrees of exactness)
---------------------------------
Restricted to a planar piece, the background bilinear (2-D) / trilinear (3-D) shape functions are
polynomials of degree 2 / 3 in the piece's coordinates, the foreground P1 functions of degree 1.
2-D: 2-point Gauss on each sub-segment, exact to degree 3 (background x foreground products).
3-D: each clipped polygon is fan-triangulated from its first vertex and each triangle gets the
6-point degree-4 rule (Strang & Fix / Dunavant, all weights positive, points inside), exact for
background x foreground products (degree 4); background x background products (degree 6 in 3-D,
4 in 2-D) are NOT integrated exactly.

The module map: clipping.py (the kernels that cut facets at the grid planes), coverage.py (the
blocked fractions and face coverages of the clipped surface), pieces.py (the pieces' type and the
shared helpers), surfaces.py (closed surfaces from cells); this module clips and orders.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from orchestrator.coupling.clipping import _GAUSS2_T, _TRI_BARY, _TRI_W, _clip_kernel, _clip_segments_2d
from orchestrator.coupling.coverage import (Coverage, blocked_fractions, coverage,  # noqa: F401  (the API)
                                           face_coverage)
from orchestrator.coupling.grid import Grid
from orchestrator.coupling.pieces import GeometryError, Pieces, _planes
from orchestrator.coupling.surfaces import closed_surface_from_cells, cube_sphere_surface  # noqa: F401


@njit(cache=True)
def _gather_points(order, pq0, pqn, qx, qw, ql, part, zijk, planes, nv):
    """The quadrature points in sorted piece order, with the foreground shape functions of the
    parent facet's nv nodes (3-D: part 0 holds nodes (0, 1, 2), part 1 nodes (0, 2, 3)) and the
    background ones: tensor products of the 1-D hats of the zone's local coordinates
    ``xi_d = (x_d - X_i) / (X_{i+1} - X_i)`` (clipped against round-off); corner c has offset
    (c & 1, c >> 1 & 1, c >> 2 & 1)."""
    D = qx.shape[1]
    nq = 0
    for p in range(order.size):
        nq += pqn[order[p]]
    out_x = np.empty((nq, D))
    out_w = np.empty(nq)
    out_p = np.empty(nq, np.int64)
    out_f = np.zeros((nq, nv))
    nc = 1 << D
    out_b = np.empty((nq, nc))
    xi = np.empty(D)
    k = 0
    for p in range(order.size):
        o = order[p]
        for j in range(pq0[o], pq0[o] + pqn[o]):
            for d in range(D):
                out_x[k, d] = qx[j, d]
                i = zijk[p, d]
                t = (qx[j, d] - planes[d, i]) / (planes[d, i + 1] - planes[d, i])
                xi[d] = min(max(t, 0.0), 1.0)
            out_w[k] = qw[j]
            out_p[k] = p
            if D == 3:
                out_f[k, 0] = ql[j, 0]
                if part[o] == 0:
                    out_f[k, 1] = ql[j, 1]
                    out_f[k, 2] = ql[j, 2]
                else:
                    out_f[k, 2] = ql[j, 1]
                    out_f[k, 3] = ql[j, 2]
            else:
                out_f[k, 0] = ql[j, 0]
                out_f[k, 1] = ql[j, 1]
            for c in range(nc):
                v = 1.0
                for d in range(D):
                    v *= xi[d] if (c >> d) & 1 else 1.0 - xi[d]
                out_b[k, c] = v
            k += 1
    return out_x, out_w, out_p, out_f, out_b


# ------------------------------------------------------------------------------ public API
_SORT_KEY_LIMIT = 2.0**62
"""_sorted_pieces sorts by one int64 key below this bound, by four stable sorts above it."""


def _check_inputs(grid: Grid, x, facets, body):
    dim = grid.dim
    x = np.asarray(x, dtype=np.float64)
    facets = np.asarray(facets, dtype=np.int64)
    nv = 2 if dim == 2 else 4
    if x.ndim != 2 or x.shape[1] != dim:
        raise GeometryError(f"node positions must have shape (nn, {dim}) for a {dim}-D grid, got {x.shape}")
    if facets.ndim != 2 or facets.shape[1] != nv:
        raise GeometryError(f"facets must have shape (nf, {nv}) in {dim}-D, got {facets.shape}")
    if facets.size and (facets.min() < 0 or facets.max() >= x.shape[0]):
        raise GeometryError(f"facet node indices must lie in [0, {x.shape[0]}), got "
                            f"[{facets.min()}, {facets.max()}]")
    if body is None:
        body = np.zeros(facets.shape[0], dtype=np.int64)
    body = np.asarray(body, dtype=np.int64).reshape(-1)
    if body.size != facets.shape[0] or (body.size and body.min() < 0):
        raise GeometryError(f"body must give a non-negative body index per facet ({facets.shape[0]}), "
                            f"got {body.size} values")
    if not np.all(np.isfinite(x[facets])):
        raise GeometryError("facet node positions must be finite")
    return x, facets, body


def clip_surface(grid: Grid, x, facets, body=None) -> Pieces:
    """The body surfaces (facets into node positions x; body index per facet, default 0) clipped
    against the zones of the grid; see the module docstring for the rules and the quadrature."""
    dim = grid.dim
    x, facets, body = _check_inputs(grid, x, facets, body)
    xs = grid.snap(x)
    beyond = grid.beyond(xs)
    outside = None
    if beyond.any():   # (only then: which of those nodes a facet uses)
        used = np.zeros(x.shape[0], dtype=bool)
        used[facets.reshape(-1)] = True
        outside = used & beyond.any(axis=1)
    if outside is not None and outside.any():
        bad = np.any(outside[facets], axis=1)
        b = int(body[bad].min())
        nodes = facets[bad & (body == b)].reshape(-1)
        node = int(nodes[outside[nodes]].min())
        past = float(np.max(np.maximum(grid.lower - x[node], x[node] - grid.upper) / grid.h))
        hint = ("" if past > 1e-3 else
                f" ({past:.2g} of a zone past the face: a body on a face of the grid must be held on it, by a "
                f"[[boundaries]] symmetry (axis, at) or a fixed or velocity boundary there; the gas presses on "
                f"its other sides only)")
        raise GeometryError(f"body {b} is not inside the grid box [{grid.lower.tolist()}, "
                            f"{grid.upper.tolist()}]: node {node} at {x[node].tolist()}{hint}")
    if dim == 3:   # the quads' two triangles along the diagonal 0-2
        elems = np.concatenate([facets[:, [0, 1, 2]], facets[:, [0, 2, 3]]])
        e_facet = np.concatenate([np.arange(facets.shape[0])] * 2)
        e_part = np.repeat(np.arange(2), facets.shape[0])
    else:
        elems, e_facet, e_part = facets, np.arange(facets.shape[0]), np.zeros(facets.shape[0], np.int64)
    planes = _planes(grid)
    if dim == 2:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = _clip_segments_2d(
            np.ascontiguousarray(xs), np.ascontiguousarray(elems), planes[0, : grid.cells[0] + 1],
            planes[1, : grid.cells[1] + 1], _GAUSS2_T)
    else:
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal = _clip_kernel(
            np.ascontiguousarray(xs), np.ascontiguousarray(elems), planes, grid.cells.astype(np.int64),
            _GAUSS2_T, _TRI_BARY, _TRI_W)
    zone, pbody, facet, area, normal, centroid, qp, qw, qpiece, qf, qb = _sorted_pieces(
        pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal, e_facet.astype(np.int64), e_part.astype(np.int64), body,
        grid.cells.astype(np.int64), planes, facets.shape[1], _SORT_KEY_LIMIT)
    return Pieces(zone=zone, body=pbody, facet=facet, area=area, normal=normal, centroid=centroid, qp=qp, qw=qw,
                  qpiece=qpiece, qf=qf, qb=qb)


@njit(cache=True)
def _sorted_pieces(pz, pe, pa, pc, pq0, pqn, qx, qw, ql, enormal, e_facet, e_part, body, cells, planes, nv,
                   key_limit):
    """The clipped pieces in the canonical order (zone, body, facet, part: np.lexsort's), with their
    quadrature points (``_gather_points``), in one kernel.  A piece is one (zone, facet, part): a
    convex polygon clipped by a box is one polygon, so the order is that of the unique key
    ((zone nb + body) nf + facet) 2 + part; a key that could overflow takes four stable sorts."""
    n = pz.size
    dim = cells.size
    nb = 1
    nf = 1
    for p in range(n):
        f = e_facet[pe[p]]
        nb = max(nb, body[f] + 1)
        nf = max(nf, f + 1)
    nzones = 1
    for d in range(dim):
        nzones *= cells[d]
    if float(nzones) * nb * nf * 2.0 < key_limit:
        key = np.empty(n, np.int64)
        for p in range(n):
            f = e_facet[pe[p]]
            key[p] = ((pz[p] * nb + body[f]) * nf + f) * 2 + e_part[pe[p]]
        order = np.argsort(key)
    else:
        order = np.arange(n)
        col = np.empty(n, np.int64)
        for c in range(4):   # least significant first, each stable
            for t in range(n):
                p = order[t]
                f = e_facet[pe[p]]
                col[t] = e_part[pe[p]] if c == 0 else (f if c == 1 else (body[f] if c == 2 else pz[p]))
            order = order[np.argsort(col, kind="mergesort")]
    zone = np.empty(n, np.int64)
    pbody = np.empty(n, np.int64)
    facet = np.empty(n, np.int64)
    area = np.empty(n)
    normal = np.empty((n, enormal.shape[1]))
    centroid = np.empty((n, pc.shape[1]))
    zijk = np.empty((n, dim), np.int64)
    part = np.empty(n, np.int64)
    for p in range(pe.size):
        part[p] = e_part[pe[p]]
    for t in range(n):
        p = order[t]
        zone[t] = pz[p]
        f = e_facet[pe[p]]
        facet[t] = f
        pbody[t] = body[f]
        area[t] = pa[p]
        for d in range(dim):
            normal[t, d] = enormal[pe[p], d]
            centroid[t, d] = pc[p, d]
        rest = pz[p]
        for d in range(dim):
            zijk[t, d] = rest % cells[d]
            rest //= cells[d]
    qp, qw2, qpiece, qf, qb = _gather_points(order, pq0, pqn, qx, qw, ql, part, zijk, planes, nv)
    return zone, pbody, facet, area, normal, centroid, qp, qw2, qpiece, qf, qb



def warm_kernels() -> None:
    """Compile (or load from the cache) every kernel of this module: one tiny 2-D and 3-D body (for
    an install-time warm-up such as orchestrator/warmup.py)."""
    for dim, (x, f) in ((2, (np.array([[0.2, 0.2], [0.8, 0.3], [0.5, 0.7]]), np.array([[0, 1], [1, 2], [2, 0]]))),
                        (3, cube_sphere_surface(1, 0.5))):
        grid = Grid([-1.0] * dim, [1.0] * dim, [3] * dim)
        pieces = clip_surface(grid, x, f)
        blocked_fractions(grid, pieces, 1)
        face_coverage(grid, pieces, 1, 1)


def geometry_cost(n_facets: int) -> dict:
    """Wall times of the interface geometry for a sphere-like closed surface of about ``n_facets``
    quads on a grid whose zones are about the facets' size (for ``immerse bench coupling``; the
    kernels are compiled by a small warm-up call first, not timed)."""
    m = max(1, int(round(np.sqrt(n_facets / 6.0))))
    x, quads = cube_sphere_surface(m, radius=1.0)
    cells = max(2, int(round(1.5 * m)))          # zone width ~ the facets' arc length (pi/2 / m)
    grid = Grid([-1.25] * 3, [1.25] * 3, [cells] * 3)
    warm_kernels()
    t0 = time.perf_counter()
    pieces = clip_surface(grid, x, quads)
    t1 = time.perf_counter()
    zones, _ = blocked_fractions(grid, pieces, 1)
    t2 = time.perf_counter()
    for d in range(3):
        face_coverage(grid, pieces, 1, d)
    t3 = time.perf_counter()
    return {"n_facets": int(quads.shape[0]), "cells": [cells] * 3, "n_pieces": int(pieces.zone.size),
            "n_points": int(pieces.qw.size), "n_blocked_zones": int(zones.size),
            "clip_s": t1 - t0, "fractions_s": t2 - t1, "faces_s": t3 - t2}
