"""Closed surfaces of SPH particle bodies on the background grid, for the embedded coupling.

The embedded-SPH method of Tsuji, Puso et al. ("Embedded smoothed particle hydrodynamics", CMAME
366 (2020) 113003) couples particle bodies to the ALE grid through a surface it rebuilds from the
particles every step: "identify exterior cut edges, add triangles to cell, connect dots".  Here:

1. *Colour function* at the grid nodes, ``c(x_n) = sum_j V_j W(|x_n - x_j|, h)`` with the particle
   volumes ``V_j = m_j / rho_j`` and the Lucy kernel of LAMMPS's SPH package (support radius h,
   ``_lucy``); ~1 inside a body, 0 farther than h from every particle, and 1/2 about half a particle
   spacing outside the outermost particles (the edge of the particles' own volumes), so the
   default iso level 0.5 gives a surface enclosing about ``sum_j V_j``.
2. *Iso-surface* ``c = iso`` zone by zone: marching squares in 2-D (segments), marching tetrahedra
   in 3-D (each hex zone cut into the 6 tetrahedra of the Kuhn triangulation around its main
   diagonal, the same in every zone, so the diagonals of shared faces match and the surface has no
   holes; inside a tetrahedron the interpolant is linear, so there is no ambiguous case).  A node
   with ``c >= iso`` is inside.  Surface vertices are the crossings of the grid's (or tetrahedra's)
   edges, placed by linear interpolation of c along the edge, and named by the global edge they lie
   on, so neighbouring zones share them: the surface comes out closed and consistently oriented,
   with merged vertices.
3. ``shepard_weights``: the Shepard-normalised kernel ``S_ij = V_j W_ij / sum_k V_k W_ik`` at
   arbitrary points, for the coupling operator ``B^f_ei = ∫ W_i / sum_j W_j``.

Conventions (those of geometry.py's ``clip_surface``): 2-D segments ``(a, b)`` with outward normal
``(yb - ya, -(xb - xa)) / L`` (a body's boundary runs counter-clockwise, holes clockwise); 3-D
triangles ``(a, b, c)`` with outward normal along ``(b - a) x (c - a)`` (``as_coupling_facets`` turns
them into the degenerate quads ``(a, b, c, c)`` clip_surface takes).

The grid: ``cells`` zones per axis, node ``i`` (per axis) at ``lower + L i / n`` with
``L = (lower + spacing n) - lower``: grid.Grid's canonical planes for ``upper = lower + spacing *
cells``, so a surface vertex on a grid line lies exactly on the plane clip_surface compares it with
(no slivers).  Node values are flat in C order of the (cells + 1) node array: node (i, j[, k]) is
``np.ravel_multi_index((i, j[, k]), cells + 1)`` -- x *slowest*, unlike grid.Grid's node ids (x
fastest).  Nodes beyond the grid count as outside (c = 0, the grid is padded by one layer of zero
nodes): a body whose colour reaches the grid's boundary nodes is closed, but by facets up to one
zone beyond the grid, which clip_surface rejects -- for the coupling, keep bodies at least h inside.

Cost: neighbour search by binning (particles into the nodes' box, or cell lists of size h for
``shepard_weights``), linear in particles + points; the marching is array work over the zones plus
work on the cut zones, no Python loops over data.
"""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse
from numba import njit

__all__ = ["colour_at_nodes", "shepard_weights", "reconstruct", "particle_surface", "enclosed_volume",
           "as_coupling_facets"]


# ------------------------------------------------------------------------------------- kernel
def _lucy_norm(dim: int, h: float) -> float:
    """Normalisation of the Lucy kernel of support h (LAMMPS SPH package): ∫ W = 1."""
    return 5.0 / (np.pi * h * h) if dim == 2 else 105.0 / (16.0 * np.pi * h ** 3)


@njit(cache=True, inline="always")
def _lucy(r2, h, norm):
    """Lucy kernel ``norm (1 + 3q)(1 - q)^3`` at q = r/h < 1 (from r^2: no sqrt outside the support)."""
    if r2 >= h * h:
        return 0.0
    q = np.sqrt(r2) / h
    s = 1.0 - q
    return norm * (1.0 + 3.0 * q) * s * s * s


# ------------------------------------------------------------------------------------ the grid
def _grid(lower, spacing, cells):
    lower = np.asarray(lower, dtype=np.float64).reshape(-1)
    spacing = np.asarray(spacing, dtype=np.float64).reshape(-1)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1)
    if lower.size not in (2, 3) or spacing.size != lower.size or cells.size != lower.size:
        raise ValueError(f"lower/spacing/cells must all have 2 or 3 entries, got "
                         f"{lower.size}/{spacing.size}/{cells.size}")
    if np.any(cells < 1) or not np.all(spacing > 0) or not np.all(np.isfinite(lower + spacing)):
        raise ValueError(f"need cells >= 1, spacing > 0, finite lower; got cells={cells.tolist()}, "
                         f"spacing={spacing.tolist()}, lower={lower.tolist()}")
    return lower, spacing, cells


def _planes(lower, spacing, cells, pad):
    """(dim, max n + 1 + 2 pad) node coordinates per axis, nodes -pad .. n + pad (zero padded rows):
    grid.Grid's canonical ``lower + L k / n`` (the end node ``lower + L`` exactly), extrapolated by
    the same formula onto the padding."""
    dim = cells.size
    out = np.zeros((dim, int(cells.max()) + 1 + 2 * pad))
    for d in range(dim):   # (per axis: dim <= 3)
        n = int(cells[d])
        upper = lower[d] + spacing[d] * n
        k = np.arange(-pad, n + pad + 1, dtype=np.float64)
        x = lower[d] + (upper - lower[d]) * k / float(n)
        x[pad + n] = upper
        out[d, : n + 1 + 2 * pad] = x
    return out


def _particles(x, volume, h, dim=None):
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] not in (2, 3) or (dim is not None and x.shape[1] != dim):
        raise ValueError(f"particle positions must have shape (n, {dim or '2|3'}), got {x.shape}")
    volume = np.broadcast_to(np.asarray(volume, dtype=np.float64), (x.shape[0],))
    h = float(h)
    if not h > 0.0 or not np.isfinite(h):
        raise ValueError(f"smoothing length h must be positive and finite, got {h}")
    if not np.all(np.isfinite(x)):
        raise ValueError("particle positions must be finite")
    return np.ascontiguousarray(x), np.ascontiguousarray(volume), h


def _as3(x):
    """(n, 3) copy: 2-D points get z = 0, so the kernels have one code path (a flat third axis)."""
    out = np.zeros((x.shape[0], 3))
    out[:, : x.shape[1]] = x
    return out


# ------------------------------------------------------------------------------ colour function
def colour_at_nodes(lower, spacing, cells, x, volume, h) -> np.ndarray:
    """Colour function ``c(x_n) = sum_j V_j W(|x_n - x_j|, h)`` at every node of the grid (Tsuji et
    al. 2020, the indicator the surface is the level set of), flat in C order of the (cells + 1)
    node array (module docstring).  ``x`` (np, dim) particle positions, ``volume`` (np,) or scalar
    ``m_j / rho_j``, ``h`` the Lucy kernel's support radius.

    The nodes are a lattice, so they are their own cell list: each particle visits the nodes of the
    box ``x_j ± h`` (index arithmetic), cost O(np (2h/spacing)^dim + nodes)."""
    lower, spacing, cells = _grid(lower, spacing, cells)
    dim = cells.size
    x, volume, h = _particles(x, volume, h, dim)
    planes = _planes(lower, spacing, cells, 0)
    p3 = np.zeros((3, planes.shape[1]))
    p3[:dim] = planes
    n3 = np.ones(3, np.int64)
    n3[:dim] = cells + 1
    out = np.zeros(int(np.prod(n3)))
    _scatter_colour(_as3(x), volume, h, _lucy_norm(dim, h), p3, n3, out)
    return out


@njit(cache=True)
def _scatter_colour(x, vol, h, norm, planes, nn, out):
    """out[node] += V_j W(|x_node - x_j|) over the nodes within h of each particle; planes (3, m)
    node coordinates per axis (a flat axis: one node at 0), nn (3,) node counts."""
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for p in range(x.shape[0]):
        for d in range(3):
            if nn[d] == 1:
                lo[d] = 0
                hi[d] = 0
                continue
            X0 = planes[d, 0]
            w = (planes[d, nn[d] - 1] - X0) / (nn[d] - 1)
            # one node of margin each side: the distance test below decides, on the exact planes
            lo[d] = max(int(np.floor((x[p, d] - h - X0) / w)), 0)
            hi[d] = min(int(np.floor((x[p, d] + h - X0) / w)) + 1, nn[d] - 1)
        for i in range(lo[0], hi[0] + 1):
            dx = planes[0, i] - x[p, 0]
            for j in range(lo[1], hi[1] + 1):
                dy = planes[1, j] - x[p, 1]
                for k in range(lo[2], hi[2] + 1):
                    dz = planes[2, k] - x[p, 2]
                    r2 = dx * dx + dy * dy + dz * dz
                    if r2 < h * h:
                        out[(i * nn[1] + j) * nn[2] + k] += vol[p] * _lucy(r2, h, norm)


def shepard_weights(points, x, volume, h) -> scipy.sparse.csr_matrix:
    """(nq, np) CSR matrix ``S_ij = V_j W(|p_i - x_j|, h) / sum_k V_k W(|p_i - x_k|, h)``: the
    Shepard-normalised kernel at the query points (Tsuji et al. 2020's ``W_i / sum_j W_j`` of the
    coupling operator B^f).  A row with no particle within h is empty (zero).  Columns sorted within
    each row.  Neighbours by cell lists of size h: O(nq + np + bins of the particles' box)."""
    x, volume, h = _particles(x, volume, h)
    dim = x.shape[1]
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != dim:
        raise ValueError(f"points must have shape (nq, {dim}), got {points.shape}")
    nq, npart = points.shape[0], x.shape[0]
    if npart == 0 or nq == 0:
        return scipy.sparse.csr_matrix((nq, npart))
    x3, q3 = _as3(x), _as3(points)
    origin, nb, start, order = _cell_lists(x3, h)
    indptr, indices, data = _shepard_kernel(q3, x3, volume, h, _lucy_norm(dim, h), origin, nb, start, order)
    return scipy.sparse.csr_matrix((data, indices, indptr), shape=(nq, npart))


@njit(cache=True)
def _cell_lists(x, h):
    """Bins of size h over the particles' bounding box: (origin (3,), bins per axis (3,), start
    (nbins + 1,), particle order) -- the particles of bin b are order[start[b]:start[b + 1]],
    bin (i, j, k) = (i nb1 + j) nb2 + k, each sorted by particle index (a counting sort)."""
    n = x.shape[0]
    origin = np.empty(3)
    nb = np.empty(3, np.int64)
    for d in range(3):
        lo = x[0, d]
        hi = x[0, d]
        for p in range(n):
            lo = min(lo, x[p, d])
            hi = max(hi, x[p, d])
        origin[d] = lo
        nb[d] = int((hi - lo) / h) + 1
    bins = np.empty(n, np.int64)
    for p in range(n):
        b = 0
        for d in range(3):
            i = min(int((x[p, d] - origin[d]) / h), nb[d] - 1)
            b = b * nb[d] + i
        bins[p] = b
    start = np.zeros(nb[0] * nb[1] * nb[2] + 1, np.int64)
    for p in range(n):
        start[bins[p] + 1] += 1
    for b in range(start.size - 1):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[fill[bins[p]]] = p
        fill[bins[p]] += 1
    return origin, nb, start, order


@njit(cache=True)
def _shepard_kernel(q, x, vol, h, norm, origin, nb, start, order):
    """CSR (indptr, indices, data) of the Shepard weights: one pass counts each row's neighbours
    (the 3^dim bins around the point's), the second fills and normalises them."""
    nq = q.shape[0]
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    indptr = np.zeros(nq + 1, np.int64)
    for fill in range(2):
        if fill == 1:
            for i in range(nq):
                indptr[i + 1] += indptr[i]
            indices = np.empty(indptr[nq], np.int64)
            data = np.empty(indptr[nq])
        else:
            indices = np.empty(0, np.int64)
            data = np.empty(0)
        for i in range(nq):
            empty = False
            for d in range(3):
                f = np.floor((q[i, d] - origin[d]) / h)
                lo[d] = max(int(f) - 1, 0) if f > -2.0 else nb[d]   # (far from the bins: none)
                hi[d] = min(int(f) + 1, nb[d] - 1) if f < nb[d] + 1.0 else -1
                if lo[d] > hi[d]:
                    empty = True
            if empty:
                continue
            m = indptr[i]
            for a in range(lo[0], hi[0] + 1):
                for bb in range(lo[1], hi[1] + 1):
                    for c in range(lo[2], hi[2] + 1):
                        b = (a * nb[1] + bb) * nb[2] + c
                        for t in range(start[b], start[b + 1]):
                            p = order[t]
                            r2 = 0.0
                            for d in range(3):
                                r2 += (q[i, d] - x[p, d]) ** 2
                            if r2 < h * h:
                                if fill == 1:
                                    indices[m] = p
                                    data[m] = vol[p] * _lucy(r2, h, norm)
                                    m += 1
                                else:
                                    indptr[i + 1] += 1
            if fill == 1 and m > indptr[i]:
                # columns sorted (canonical CSR), then the row normalised
                o = np.argsort(indices[indptr[i]:m])
                cols = indices[indptr[i]:m][o]
                vals = data[indptr[i]:m][o]
                s = 0.0
                for t in range(vals.size):
                    s += vals[t]
                for t in range(vals.size):
                    indices[indptr[i] + t] = cols[t]
                    data[indptr[i] + t] = vals[t] / s
    return indptr, indices, data


# ----------------------------------------------------------------------- marching tables (built once)
# Corner c of a zone has offset (c & 1, c >> 1 & 1, c >> 2 & 1) along (x, y, z) (geometry.py's order).
# An edge of the (triangulated) grid runs from a node to the node at a positive offset e in
# {0, 1}^dim \ {0}; its global id is ``node * (2^dim - 1) + code(e) - 1``, code(e) = e_x + 2 e_y + 4 e_z.
# Table rows name an edge by (start corner, code) within a zone.

def _corner(c, dim):
    return np.array([(c >> d) & 1 for d in range(dim)])


def _edge(ca, cb, dim):
    """(start corner, code) of the zone edge between corners ca and cb (one dominates the other)."""
    oa, ob = _corner(ca, dim), _corner(cb, dim)
    if np.any(ob < oa):
        ca, cb, oa, ob = cb, ca, ob, oa
    e = ob - oa
    return ca, int(sum(int(e[d]) << d for d in range(dim)))


def _orient(pts, inside_side, dim):
    """True when the simplex pts (reference positions) already has the outward orientation: its
    normal (2-D: (dy, -dx); 3-D: (b - a) x (c - a)) points away from ``inside_side`` (a point of
    the inside, relative to the first vertex)."""
    if dim == 2:
        t = pts[1] - pts[0]
        n = np.array([t[1], -t[0]])
    else:
        n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
    return float(np.dot(n, inside_side - pts[0])) < 0.0


def _squares_table():
    """Marching squares: (2 saddle variants, 16 cases, 2 segments, 2 ends, [start corner, code]),
    counts (2, 16).  Variant 0 separates the two inside corners of a saddle (cases 6, 9), variant 1
    joins them (cuts off the two outside corners); elsewhere the variants agree.  Segments oriented
    with the inside on their left, on reference positions (edge midpoints): orientation is
    topological, it does not depend on where along the edges the crossings lie."""
    dim = 2
    edges = [(0, 1), (2, 3), (0, 2), (1, 3)]
    table = np.zeros((2, 16, 2, 2, 2), np.int64)
    count = np.zeros((2, 16), np.int64)
    for variant, case in itertools.product(range(2), range(16)):
        inside = [(case >> c) & 1 for c in range(4)]
        cut = [e for e in edges if inside[e[0]] != inside[e[1]]]
        if not cut:
            continue
        if len(cut) == 2:
            groups = [(cut, next(c for c in range(4) if inside[c]), True)]
        else:   # saddle: pair the two edges around each corner of one kind
            kind = 1 if variant == 0 else 0
            groups = [([e for e in cut if c in e], c, kind == 1) for c in range(4) if inside[c] == kind]
        for s, (pair, corner, corner_inside) in enumerate(groups):
            mids = np.array([0.5 * (_corner(a, dim) + _corner(b, dim)) for a, b in pair], dtype=float)
            ref = _corner(corner, dim).astype(float)
            if not corner_inside:   # the inside is across the segment from a cut-off outside corner
                ref = mids.mean(axis=0) - (ref - mids.mean(axis=0))
            if not _orient(mids, ref, dim):
                pair = pair[::-1]
            for k, (a, b) in enumerate(pair):
                table[variant, case, s, k] = _edge(a, b, dim)
        count[variant, case] = len(groups)
    return table, count


def _kuhn_tets():
    """The 6 tetrahedra (corner ids) of a hex zone around its main diagonal 0-7, one per order of
    the axes: every zone splits the same way, so a shared face has the same diagonal on both sides."""
    tets = []
    for perm in itertools.permutations(range(3)):
        c, chain = 0, [0]
        for d in perm:
            c |= 1 << d
            chain.append(c)
        tets.append(chain)
    return np.array(tets, np.int64)


def _tets_table():
    """Marching tetrahedra: (6 tets, 16 cases, 2 triangles, 3 vertices, [start corner, code]), counts
    (6, 16).  Case bit k = vertex k of the tet inside.  One vertex apart: a triangle on its 3 edges;
    two and two: the quad on the 4 mixed edges (a cycle), 2 triangles.  Oriented on the reference
    field (1 inside, 0 outside, linear in the tet): the outward normal is along -grad."""
    dim = 3
    tets = _kuhn_tets()
    table = np.zeros((6, 16, 2, 3, 2), np.int64)
    count = np.zeros((6, 16), np.int64)
    for t, case in itertools.product(range(6), range(16)):
        ins = [(case >> k) & 1 for k in range(4)]
        n_in = sum(ins)
        if n_in in (0, 4):
            continue
        v = tets[t]
        if n_in in (1, 3):
            lone = next(k for k in range(4) if ins[k] == (1 if n_in == 1 else 0))
            polys = [[(lone, k) for k in range(4) if k != lone]]
        else:
            a, b = [k for k in range(4) if ins[k]]
            c, d = [k for k in range(4) if not ins[k]]
            quad = [(a, c), (a, d), (b, d), (b, c)]
            polys = [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
        X = np.array([_corner(c, dim) for c in v], dtype=float)
        inside_pt = X[[k for k in range(4) if ins[k]]].mean(axis=0)
        for s, tri in enumerate(polys):
            pts = np.array([0.5 * (X[i] + X[j]) for i, j in tri])
            if not _orient(pts, inside_pt, dim):
                tri = [tri[0], tri[2], tri[1]]
            for k, (i, j) in enumerate(tri):
                table[t, case, s, k] = _edge(int(v[i]), int(v[j]), dim)
        count[t, case] = len(polys)
    return tets, table, count


_SQ_TABLE, _SQ_COUNT = _squares_table()
_TETS, _TET_TABLE, _TET_COUNT = _tets_table()


# ------------------------------------------------------------------------------------- marching
def reconstruct(lower, spacing, cells, node_values, iso=0.5, close_on_boundary=False):
    """The closed surface ``c = iso`` of node values c on the grid (Tsuji et al. 2020: exterior cut
    edges, facets per cut zone, connected through the shared edge crossings): marching squares in
    2-D, marching tetrahedra (Kuhn split of each zone) in 3-D; see the module docstring.

    ``node_values`` flat (or shaped cells + 1) in C order of the node array; ``iso > 0`` (nodes
    beyond the grid count as c = 0, outside).  Returns ``(points (nv, dim), facets (nf, 2|3) int64)``:
    segments / triangles into points, outward oriented, every vertex shared by the facets around it.
    2-D saddle zones (diagonal corners inside) are joined when the zone's mean value is >= iso.
    ``close_on_boundary``: the outside layer lies ON the grid's boundary planes (zero-width zones),
    so a body that reaches the boundary is closed by facets on the boundary plane itself (as a mesh
    body resting on a wall is), not one zone beyond it."""
    lower, spacing, cells = _grid(lower, spacing, cells)
    dim = cells.size
    c = np.asarray(node_values, dtype=np.float64)
    if c.size != int(np.prod(cells + 1)):
        raise ValueError(f"node_values must have {int(np.prod(cells + 1))} entries (cells + 1 = "
                         f"{(cells + 1).tolist()} nodes), got {c.size}")
    iso = float(iso)
    if not iso > 0.0 or not np.isfinite(iso):
        raise ValueError(f"iso must be positive (nodes beyond the grid count as c = 0), got {iso}")
    cp = np.pad(c.reshape(tuple(cells + 1)), 1)            # one layer of outside nodes around
    nshape = np.array(cp.shape, np.int64)
    zshape = tuple(nshape - 1)
    inside = cp >= iso
    # case of every (padded) zone: bit c = corner c inside
    case = np.zeros(zshape, np.int64)
    for cn in range(2 ** dim):   # (per corner: 4 or 8 slices of the whole arrays)
        o = _corner(cn, dim)
        case |= inside[tuple(slice(o[d], o[d] + zshape[d]) for d in range(dim))].astype(np.int64) << cn
    full = 2 ** (2 ** dim) - 1
    zijk = np.nonzero((case != 0) & (case != full))
    zcase = case[zijk]
    znode = np.ravel_multi_index(zijk, tuple(nshape))       # each cut zone's corner-0 node
    stride = np.array([int(np.prod(nshape[d + 1:])) for d in range(dim)], np.int64)
    corner_off = np.array([int(_corner(cn, dim) @ stride) for cn in range(2 ** dim)], np.int64)
    ndir = 2 ** dim - 1
    if dim == 2:
        cv = np.stack([cp.reshape(-1)[znode + corner_off[k]] for k in range(4)], axis=1)
        variant = (cv.mean(axis=1) >= iso).astype(np.int64)  # saddle rule: join through the centre
        ent, cnt = _SQ_TABLE[variant, zcase], _SQ_COUNT[variant, zcase]
        groups = [(ent[:, s], cnt > s, znode) for s in range(2)]
    else:
        groups = []
        for t in range(6):   # (per tetrahedron of the split)
            tcase = np.zeros_like(zcase)
            for k in range(4):
                tcase |= ((zcase >> _TETS[t, k]) & 1) << k
            ent, cnt = _TET_TABLE[t, tcase], _TET_COUNT[t, tcase]
            groups += [(ent[:, s], cnt > s, znode) for s in range(2)]
    eids = np.concatenate([(zn[m, None] + corner_off[e[m, :, 0]]) * ndir + e[m, :, 1] - 1 for e, m, zn in groups])
    if eids.size == 0:
        return np.zeros((0, dim)), np.zeros((0, dim), np.int64)
    edge, inv = np.unique(eids, return_inverse=True)         # the crossed edges = the vertices
    facets = inv.reshape(eids.shape).astype(np.int64)
    # vertices: linear interpolation of c along the edge from its start node a to b
    a = edge // ndir
    code = edge % ndir + 1
    off = (code[:, None] >> np.arange(dim)) & 1
    b = a + off @ stride
    ca, cb = cp.reshape(-1)[a], cp.reshape(-1)[b]
    t = np.clip((iso - ca) / (cb - ca), 0.0, 1.0)
    ia = np.stack(np.unravel_index(a, tuple(nshape)), axis=1)
    planes = _planes(lower, spacing, cells, 1)
    if close_on_boundary:
        for d in range(dim):   # (per axis)
            n = int(cells[d])
            planes[d, 0], planes[d, n + 2] = planes[d, 1], planes[d, n + 1]
    axes = np.arange(dim)
    xa = planes[axes, ia]
    xb = planes[axes, ia + off]
    # an axis the edge does not move along keeps the plane's coordinate exactly
    points = np.where(off == 1, xa + t[:, None] * (xb - xa), xa)
    return points, facets


def particle_surface(lower, spacing, cells, x, volume, h, iso=0.5, close_on_boundary=False):
    """``reconstruct`` of ``colour_at_nodes``: the closed outward surface (points, facets) of the
    particle bodies x (volumes V_j, Lucy support h) on the grid."""
    c = colour_at_nodes(lower, spacing, cells, x, volume, h)
    return reconstruct(lower, spacing, cells, c, iso, close_on_boundary)


# ------------------------------------------------------------------------------------ utilities
def enclosed_volume(points, facets) -> float:
    """Signed area (2-D segments) / volume (3-D triangles, or quads split along 0-2) enclosed by a
    closed surface, by the divergence theorem: positive for an outward orientation; holes and
    inner shells (oriented inward) subtract."""
    x = np.asarray(points, dtype=np.float64)
    f = np.asarray(facets, dtype=np.int64)
    if f.size == 0:
        return 0.0
    if f.shape[1] == 2:
        a, b = x[f[:, 0]], x[f[:, 1]]
        return float(0.5 * np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))
    tris = f if f.shape[1] == 3 else np.concatenate([f[:, [0, 1, 2]], f[:, [0, 2, 3]]])
    a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    return float(np.sum(a * np.cross(b, c)) / 6.0)


def as_coupling_facets(facets) -> np.ndarray:
    """Facets in geometry.clip_surface's form: 2-D segments unchanged; 3-D triangles (a, b, c) as
    the degenerate quads (a, b, c, c), whose second part (0, 2, 3) has zero area (clip_surface skips
    a zero-area part) and whose normal (b - a) x (d - a) is the triangle's."""
    f = np.asarray(facets, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] not in (2, 3):
        raise ValueError(f"facets must have shape (nf, 2) or (nf, 3), got {f.shape}")
    return f if f.shape[1] == 2 else np.concatenate([f, f[:, 2:3]], axis=1)
