"""How far surface nodes lie behind another surface: the geometric measure of contact penetration.

The contact methods hold weighted gaps (a mortar row is a node's gap averaged over its segments,
seed eq. for g~), so a node between its neighbours can still dip into the other side; what an analyst
asks is how far any node went. This measures it node by node on the deformed facets: the explicit
contact calls it at the end of every step (explicit.py, so the figure does not depend on which steps
are written), the checks on output steps of solvers that do not.

A node is measured against the facets whose plane (line) it projects into the inside of, up to
``depth`` on either side; of those the nearest along its normal is the surface it belongs to (a node
behind a plate's top face is also behind its bottom face's plane, by the thickness: the nearer face
decides). The facets are taken as planar (centroid, unit area vector): deformed quadrilaterals warp
far below an element.

Self contact (``own``: the nodes and the facets of one body): only a facet that faces the node is a
surface it can have gone through (the node's normal, the sum of its facets' area vectors, against
the facet's: n_node . n_facet < -FACING_COS, the mortar's pairing rule). That drops the node's own
facets (n_k . sum_l a_l >= 0 for the two segments at a 2-D node, however sharp the kink) and its
neighbours' on either side of a fold; ``depth`` must then stay below the wall's thickness (the
contact's capture does: its own rule), or a node would be measured against the far face of its own
wall, which faces it.

One numba kernel per call: the facets binned by their boxes (grown by ``depth``; the bin as large as
the largest box, so a box starts in one of the 2^dim bins at and below a node's), each node's nearest
facet found in those bins. Every step of the explicit contact calls it: 94 us a step on
cases/ring_self_contact (166 nodes, 764 facets; 1 % of its step), where search.py's numpy broad
phase and the vectorised tests took 1.1 ms (13 %: the array calls' overhead on a few hundred facets).
"""
from __future__ import annotations

import numpy as np

from numba import njit

from solvers.contact.mortar_segments import FACING_COS

__all__ = ["surface_penetration", "paired_penetration"]


def paired_penetration(points: np.ndarray, facets: np.ndarray, facet_body: np.ndarray, nodes: np.ndarray,
                       node_body: np.ndarray, pairs, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """How far each of ``nodes`` lies behind the facets of the bodies its body is paired with
    (``pairs``: (a, b) body ids, both ways; (a, a) self contact: the facing rule), the nearest such
    facet deciding (module docstring): (len(nodes),) depths (0: in front or off), and (len(nodes),)
    bool, True where that facet is of the node's own body. facet_body (nf,) and node_body (the
    bodies of ``nodes``, (len(nodes),)) give the bodies; one search for all pairs."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    facets = np.ascontiguousarray(facets, dtype=np.int64)
    nodes = np.ascontiguousarray(nodes, dtype=np.int64)
    pen, own = np.zeros(len(nodes)), np.zeros(len(nodes), np.bool_)
    if len(nodes) == 0 or len(facets) == 0 or not len(pairs):
        return pen, own
    facet_body = np.ascontiguousarray(facet_body, dtype=np.int64)
    node_body = np.ascontiguousarray(node_body, dtype=np.int64)
    n_bodies = int(max(facet_body.max(), node_body.max(), np.max(pairs))) + 1
    allowed = np.zeros((n_bodies, n_bodies), np.bool_)
    for a, b in pairs:
        allowed[a, b] = allowed[b, a] = True
    _nearest_behind(points, facets, facet_body, nodes, node_body, allowed, float(depth), FACING_COS, pen, own)
    return pen, own


@njit(cache=True)
def _nearest_behind(points, facets, facet_body, nodes, node_body, allowed, depth, facing_cos, pen, own):
    nf, nk = facets.shape
    dim = points.shape[1]
    # the facets' unit normals (from their area vectors: lagrange.surface's), centroids and boxes;
    # the nodes' normals (the sums of their facets' area vectors: the facing rule)
    normal = np.zeros((nf, 3))
    centre = np.zeros((nf, 3))
    lo = np.empty((nf, dim))
    hi = np.empty((nf, dim))
    valid = np.zeros(nf, np.bool_)
    node_n = np.zeros((points.shape[0], 3))
    size = 0.0
    for f in range(nf):
        av = np.zeros(3)
        if nk == 2:
            a = points[facets[f, 0]]
            b = points[facets[f, 1]]
            av[0] = b[1] - a[1]
            av[1] = -(b[0] - a[0])
        else:
            d1 = points[facets[f, 2]] - points[facets[f, 0]]
            d2 = points[facets[f, 3]] - points[facets[f, 1]]
            av[0] = 0.5 * (d1[1] * d2[2] - d1[2] * d2[1])
            av[1] = 0.5 * (d1[2] * d2[0] - d1[0] * d2[2])
            av[2] = 0.5 * (d1[0] * d2[1] - d1[1] * d2[0])
        for c in range(nk):
            node_n[facets[f, c]] += av
        area = np.sqrt(av[0] * av[0] + av[1] * av[1] + av[2] * av[2])
        valid[f] = area > 0.0
        if area > 0.0:
            normal[f] = av / area
        for k in range(dim):
            lo[f, k] = np.inf
            hi[f, k] = -np.inf
            for c in range(nk):
                v = points[facets[f, c], k]
                centre[f, k] += v / nk
                lo[f, k] = min(lo[f, k], v)
                hi[f, k] = max(hi[f, k], v)
            lo[f, k] -= depth
            hi[f, k] += depth
            size = max(size, hi[f, k] - lo[f, k])
    if not size > 0.0:
        size = 1.0
    origin = np.empty(dim)
    shape = np.empty(dim, np.int64)
    for k in range(dim):
        origin[k] = lo[:, k].min()
        shape[k] = np.int64((hi[:, k].max() - origin[k]) / size) + 2
    key = np.empty(nf, np.int64)
    for f in range(nf):
        flat = 0
        for k in range(dim):
            flat = flat * shape[k] + np.int64((lo[f, k] - origin[k]) / size)
        key[f] = flat
    order = np.argsort(key, kind="mergesort")          # (stable: equal bins keep facet order)
    keys = key[order]
    bins = np.empty(dim, np.int64)
    for m in range(nodes.shape[0]):
        p = points[nodes[m]]
        best, best_d, best_f, best_same = np.inf, 0.0, nf, False
        nn = node_n[nodes[m]]
        nn_len = np.sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2])
        for corner in range(1 << dim):           # the bins a box holding p can start in
            ok = True
            flat = 0
            for k in range(dim):
                bins[k] = np.int64((p[k] - origin[k]) / size) - ((corner >> k) & 1)
                if bins[k] < 0 or bins[k] >= shape[k]:
                    ok = False
                flat = flat * shape[k] + bins[k]
            if not ok:
                continue
            s = np.searchsorted(keys, flat)
            while s < nf and keys[s] == flat:
                f = order[s]
                s += 1
                if not valid[f] or not allowed[node_body[m], facet_body[f]]:
                    continue
                inbox = True
                for k in range(dim):
                    if p[k] < lo[f, k] or p[k] > hi[f, k]:
                        inbox = False
                if not inbox:
                    continue
                same = node_body[m] == facet_body[f]
                if same and nn[0] * normal[f, 0] + nn[1] * normal[f, 1] + nn[2] * normal[f, 2] >= -facing_cos * nn_len:
                    continue
                d = 0.0
                for k in range(dim):
                    d += (p[k] - centre[f, k]) * normal[f, k]   # signed: < 0 behind the facet
                if abs(d) > depth:
                    continue
                # inside: the projection on the inner side of every edge (a little slack: a node over a
                # shared edge counts for both); a segment's two "edges" a->b and b->a
                inside = True
                for e in range(nk):
                    e0 = points[facets[f, e]]
                    e1 = points[facets[f, (e + 1) % nk]]
                    side = 0.0
                    scale = 0.0
                    if dim == 2:
                        for k in range(2):
                            side += (e1[k] - e0[k]) * (p[k] - d * normal[f, k] - e0[k])
                            scale += (e1[k] - e0[k]) ** 2
                    else:
                        ex, ey, ez = e1[0] - e0[0], e1[1] - e0[1], e1[2] - e0[2]
                        rx = p[0] - d * normal[f, 0] - e0[0]
                        ry = p[1] - d * normal[f, 1] - e0[1]
                        rz = p[2] - d * normal[f, 2] - e0[2]
                        side = ((ey * rz - ez * ry) * normal[f, 0] + (ez * rx - ex * rz) * normal[f, 1]
                                + (ex * ry - ey * rx) * normal[f, 2])
                        scale = ex * ex + ey * ey + ez * ez
                    if side < -1e-9 * scale:
                        inside = False
                if inside and (abs(d) < best or (abs(d) == best and f < best_f)):
                    best, best_d, best_f, best_same = abs(d), d, f, same
        if best_f < nf:
            pen[m] = max(-best_d, 0.0)
            own[m] = best_same


def surface_penetration(points: np.ndarray, facets: np.ndarray, nodes: np.ndarray, depth: float,
                        own: bool = False) -> np.ndarray:
    """(len(nodes),) how far each of ``nodes`` lies behind the surface ``facets`` (outward
    quadrilaterals or segments of ``points``), 0 where it lies in front or off it (module docstring;
    ``own``: self contact, the nodes are of the facets' own body)."""
    nodes = np.asarray(nodes)
    body = 0 if own else 1
    return paired_penetration(points, facets, np.full(len(facets), body), nodes, np.zeros(len(nodes), np.int64),
                              [(0, body)], depth)[0]
