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
``shepard_weights``), linear in particles + points; the marching is one numba pass over the zones
plus work on the cut zones (``_march``: the ~25 numpy calls it replaced cost ~0.1 ms per step of
the coupled run in call overhead alone), no Python loops over data.  The coupler runs the colour
function and the marching inside particle_operators._surface_kernel.
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
    p3, n3 = colour_planes(lower, spacing, cells)
    out = np.zeros(int(np.prod(n3)))
    none = np.zeros(dim)
    _colour_kernel(x, volume, h, _lucy_norm(dim, h), p3, n3, none, none, np.zeros(dim, np.uint8), False, out)
    return out


def colour_planes(lower, spacing, cells):
    """The node lattice of ``colour_at_nodes`` as its kernel takes it: (3, m) node coordinates per
    axis (``_planes`` without padding; a 2-D grid's flat third axis one node at 0) and (3,) node
    counts."""
    dim = cells.size
    planes = _planes(lower, spacing, cells, 0)
    p3 = np.zeros((3, planes.shape[1]))
    p3[:dim] = planes
    n3 = np.ones(3, np.int64)
    n3[:dim] = cells + 1
    return p3, n3


@njit(cache=True)
def _colour_kernel(x, vol, h, norm, planes, nn, lower, upper, periodic, images, out):
    """out[node] += V_j W(|x_node - x_j|) over the nodes within h of each particle (x (np, dim));
    planes (3, m) node coordinates per axis (a flat axis: one node at 0), nn (3,) node counts.

    ``images``: then also the particles' images across the box [lower, upper] (within h of a face:
    mirrored across it, or shifted by the period on an axis with ``periodic[d]``), the particles
    first, then per axis the images across its lower face, then its upper face (the order, and so
    the sums, of ``particle_operators.boundary_images``'s concatenation) -- without copying the
    particles into a padded array every step.

    Each particle visits the index box of the nodes within h, one node of margin each side (the
    distance test decides, on the exact planes; the box bounds come from the inverse spacing, a
    multiplication instead of a division per bound, ~15 % of the kernel).  A row (column) of the box
    farther than h along its own axis is skipped whole -- the box is 3 nodes wide at h = w/2 and
    this drops ~7 of its 9 distance tests in 2-D -- and exactly so: a sum of non-negative terms
    cannot fall below a partial sum in floating point, so the same nodes get the same terms as the
    full test.  One loop body for particles and images (a helper function per particle costs more
    than the work: numba passes each array as ~7 scalars)."""
    n, dim = x.shape
    X0 = np.empty(3)
    iw = np.ones(3)
    for d in range(3):
        X0[d] = planes[d, 0]
        if nn[d] > 1:
            iw[d] = 1.0 / ((planes[d, nn[d] - 1] - X0[d]) / (nn[d] - 1))
    h2 = h * h
    c = np.zeros(3)
    for stage in range(1 + 2 * dim if images else 1):
        # stage 0: the particles; 1 + 2 d + side: their images across face `side` of axis d
        d = (stage - 1) // 2
        side = (stage - 1) % 2
        lo = lower[d] if stage > 0 else 0.0
        hi = upper[d] if stage > 0 else 0.0
        for p in range(n):
            if stage > 0 and not ((x[p, d] < lo + h) if side == 0 else (x[p, d] > hi - h)):
                continue
            for e in range(dim):
                c[e] = x[p, e]
            if stage > 0:
                if periodic[d] != 0:
                    c[d] = x[p, d] + ((hi - lo) if side == 0 else (lo - hi))
                else:
                    c[d] = (2.0 * lo if side == 0 else 2.0 * hi) - x[p, d]
            x0 = c[0]
            x1 = c[1]
            x2 = c[2]
            v = vol[p]
            lo0 = max(int(np.floor((x0 - h - X0[0]) * iw[0])), 0)
            hi0 = min(int(np.floor((x0 + h - X0[0]) * iw[0])) + 1, nn[0] - 1)
            lo1 = max(int(np.floor((x1 - h - X0[1]) * iw[1])), 0)
            hi1 = min(int(np.floor((x1 + h - X0[1]) * iw[1])) + 1, nn[1] - 1)
            if nn[2] == 1:
                lo2 = 0
                hi2 = 0
            else:
                lo2 = max(int(np.floor((x2 - h - X0[2]) * iw[2])), 0)
                hi2 = min(int(np.floor((x2 + h - X0[2]) * iw[2])) + 1, nn[2] - 1)
            for i in range(lo0, hi0 + 1):
                dx = planes[0, i] - x0
                dx2 = dx * dx
                if dx2 >= h2:
                    continue
                for j in range(lo1, hi1 + 1):
                    dy = planes[1, j] - x1
                    dxy = dx2 + dy * dy
                    if dxy >= h2:
                        continue
                    for k in range(lo2, hi2 + 1):
                        dz = planes[2, k] - x2
                        r2 = dxy + dz * dz
                        if r2 < h2:
                            out[(i * nn[1] + j) * nn[2] + k] += v * _lucy(r2, h, norm)


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
    c = np.asarray(node_values, dtype=np.float64)
    if c.size != int(np.prod(cells + 1)):
        raise ValueError(f"node_values must have {int(np.prod(cells + 1))} entries (cells + 1 = "
                         f"{(cells + 1).tolist()} nodes), got {c.size}")
    iso = float(iso)
    if not iso > 0.0 or not np.isfinite(iso):
        raise ValueError(f"iso must be positive (nodes beyond the grid count as c = 0), got {iso}")
    planes = march_planes(lower, spacing, cells, close_on_boundary)
    return _march(np.ascontiguousarray(c.reshape(-1)), cells, iso, planes, _SQ_TABLE, _SQ_COUNT, _TETS, _TET_TABLE,
                  _TET_COUNT)


def march_planes(lower, spacing, cells, close_on_boundary):
    """(dim, m) coordinates of the padded node planes ``_march`` places vertices on: ``_planes`` with
    one layer of padding, whose outer planes are moved onto the boundary planes when
    ``close_on_boundary``."""
    planes = _planes(lower, spacing, cells, 1)
    if close_on_boundary:
        for d in range(cells.size):   # (per axis)
            n = int(cells[d])
            planes[d, 0], planes[d, n + 2] = planes[d, 1], planes[d, n + 1]
    return planes


@njit(cache=True)
def _march(c, cells, iso, planes, sq_table, sq_count, tets, tet_table, tet_count):
    """``reconstruct``'s marching in one pass over the zones (it was ~25 numpy calls per step): the
    node values padded by one layer of outside nodes (c = 0), each zone's case (bit k = corner k
    inside, c >= iso), the facets of the cut zones from the tables -- grouped as the array version
    grouped them, by (tetrahedron,) segment / triangle slot, then zone in C order -- named by their
    global edges, and the crossed edges, sorted, as the vertices (linear interpolation of c along
    each edge).  Axes of a 2-D grid are padded to 3 with a flat third axis (extent 1, stride 0)."""
    dim = cells.size
    N = np.ones(3, np.int64)   # node counts (without padding)
    P = np.ones(3, np.int64)   # padded node counts
    S = np.zeros(3, np.int64)  # padded strides, C order (x slowest)
    for d in range(dim):
        N[d] = cells[d] + 1
        P[d] = cells[d] + 3
    s = 1
    for d in range(dim - 1, -1, -1):
        S[d] = s
        s *= P[d]
    cp = np.zeros(s)
    t = 0
    for i in range(N[0]):
        for j in range(N[1]):
            for k in range(N[2]):
                cp[(i + 1) * S[0] + (j + 1) * S[1] + (k + 1) * S[2]] = c[t]
                t += 1
    nc = 1 << dim
    off = np.zeros(nc, np.int64)
    for cn in range(nc):
        for d in range(dim):
            off[cn] += ((cn >> d) & 1) * S[d]
    full = (1 << nc) - 1
    Z2 = P[2] - 1 if dim == 3 else 1
    zcap = 64
    znode = np.empty(zcap, np.int64)
    zcase = np.empty(zcap, np.int64)
    zvar = np.empty(zcap, np.int64)
    nzc = 0
    for i in range(P[0] - 1):
        for j in range(P[1] - 1):
            for k in range(Z2):
                zn = i * S[0] + j * S[1] + k * S[2]
                case = 0
                for cn in range(nc):
                    if cp[zn + off[cn]] >= iso:
                        case |= 1 << cn
                if case == 0 or case == full:
                    continue
                if nzc == zcap:
                    zcap *= 2
                    znode = _grow_int(znode, zcap)
                    zcase = _grow_int(zcase, zcap)
                    zvar = _grow_int(zvar, zcap)
                znode[nzc] = zn
                zcase[nzc] = case
                if dim == 2:   # saddle rule: join through the centre (the mean of the 4 corners)
                    m = (cp[zn + off[0]] + cp[zn + off[1]] + cp[zn + off[2]] + cp[zn + off[3]]) / 4.0
                    zvar[nzc] = 1 if m >= iso else 0
                nzc += 1
    ndir = nc - 1
    nf = 0
    if dim == 2:
        for z in range(nzc):
            nf += sq_count[zvar[z], zcase[z]]
    else:
        for z in range(nzc):
            for tt in range(6):
                tc = 0
                for k in range(4):
                    tc |= ((zcase[z] >> tets[tt, k]) & 1) << k
                nf += tet_count[tt, tc]
    eids = np.empty((nf, dim), np.int64)
    f = 0
    if dim == 2:
        for sl in range(2):
            for z in range(nzc):
                v, cs = zvar[z], zcase[z]
                if sq_count[v, cs] > sl:
                    for e in range(2):
                        eids[f, e] = (znode[z] + off[sq_table[v, cs, sl, e, 0]]) * ndir + sq_table[v, cs, sl, e, 1] - 1
                    f += 1
    else:
        tcase = np.empty(nzc, np.int64)
        for tt in range(6):
            for z in range(nzc):
                tc = 0
                for k in range(4):
                    tc |= ((zcase[z] >> tets[tt, k]) & 1) << k
                tcase[z] = tc
            for sl in range(2):
                for z in range(nzc):
                    tc = tcase[z]
                    if tet_count[tt, tc] > sl:
                        for e in range(3):
                            eids[f, e] = ((znode[z] + off[tet_table[tt, tc, sl, e, 0]]) * ndir
                                          + tet_table[tt, tc, sl, e, 1] - 1)
                        f += 1
    # the crossed edges, sorted and distinct, are the vertices; facets name them by rank
    flat = eids.ravel()
    order = np.argsort(flat)
    facets = np.empty((nf, dim), np.int64)
    ff = facets.ravel()
    edge = np.empty(flat.size, np.int64)
    nv = 0
    for r in range(flat.size):
        e = flat[order[r]]
        if nv == 0 or edge[nv - 1] != e:
            edge[nv] = e
            nv += 1
        ff[order[r]] = nv - 1
    points = np.empty((nv, dim))
    for r in range(nv):
        a = edge[r] // ndir
        code = edge[r] % ndir + 1
        b = a
        for d in range(dim):
            b += ((code >> d) & 1) * S[d]
        ca = cp[a]
        cb = cp[b]
        tt_ = min(max((iso - ca) / (cb - ca), 0.0), 1.0)
        for d in range(dim):
            ia = (a // S[d]) % P[d]
            xa = planes[d, ia]
            if (code >> d) & 1:
                points[r, d] = xa + tt_ * (planes[d, ia + 1] - xa)
            else:   # an axis the edge does not move along keeps the plane's coordinate exactly
                points[r, d] = xa
    return points, facets


@njit(cache=True)
def _grow_int(a, n):
    out = np.empty(n, np.int64)
    out[: a.size] = a
    return out


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
