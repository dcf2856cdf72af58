"""Structured block of the ALE background solver: layout, ghost layers, index maps, connectivity.

Layout
------
The box ``[lower, upper]`` carries ``cells`` zones (2D quads or 3D hexahedra).  A rank holds one
logically-Cartesian *block* of it: ``n`` real zones per axis starting at global zone ``offset``,
padded with ``GHOST = 2`` ghost layers on every side (physical boundary or, later, rank cut).
Every field is a flat C-ordered array over the padded block:

* zones: shape ``(N0, N1, N2)`` with ``N_d = n_d + 4`` (``N2 = 1`` in 2D), flat index
  ``z = i*zs[0] + j*zs[1] + k*zs[2]``;
* nodes: shape ``(M0, M1, M2)`` with ``M_d = n_d + 5`` (``M2 = 1`` in 2D), flat index
  ``n = i*ns[0] + j*ns[1] + k*ns[2]``; node ``(i, j, k)`` is the lower corner of zone ``(i, j, k)``.

Real zones have padded index ``2 <= i < n+2`` per axis, real nodes ``2 <= i <= n+2``.  The corners
of zone ``(i, j, k)`` in VTK order are the nodes ``(i, j, k) + o`` with ``o`` = (0,0,0), (1,0,0),
(1,1,0), (0,1,0), (0,0,1), (1,0,1), (1,1,1), (0,1,1) (quads: the first four), positively oriented.

Face-centred arrays of direction ``d`` (swept volumes, mass fluxes of the remap) are zone-shaped:
entry ``z`` belongs to the lower ``d``-face of zone ``z``.

Boundary faces (ghost fills in boundary.py) per face:

=========  ===========================  =================================  ======================
kind       zone ghosts (planes 1, 0)    node ghosts (planes 1, 0)          zone kind of ghosts
=========  ===========================  =================================  ======================
wall       mirror 2, 3                  mirror 3, 4 (normal component -1)  inactive
outflow    copy 2, 2 (zero gradient)    copy 2, 2                          open
periodic   images n+1, n                images n+1, n; plane n+2 = 2       image
inflow     prescribed state             prescribed velocity                open
cut        neighbour's n'+1, n'         neighbour's n'+1, n'; n+2.. = 2..  image
=========  ===========================  =================================  ======================

(the upper side is the mirror image).  Code ``outflow`` is every open face with zero-gradient maps:
the case's ``"zero_gradient"`` and the characteristic faces (``inflow``, ``outflow``, ``far_field``:
open_faces.py sets their ghost zones' pressure and donors).  Code ``inflow`` is a held-velocity
face (``{piston = {velocity = [..], density, pressure}}``, Eulerian mode).  A piston face with a
scalar velocity (``{piston = {velocity}}``, Lagrangian mode) is a wall whose nodes move at the
prescribed normal speed (``piston``, positive into the domain; boundary.py).  *Zone kinds* decide
which zones act on a real node:
real and image zones always, open ghosts (outflow/inflow, they stand for the fluid beyond) too,
ghosts beyond a wall never (a wall node has the half/quarter mass and force of its real zones).
A rank cut (``cut``, parallel.py) is an image face too: its ghosts are the neighbour's zones and
nodes (halo exchange), its zone ghosts are images and its upper node plane belongs to the upper
neighbour.
"""
from __future__ import annotations

import numpy as np

from solvers.ale.points import axis_centres, spacing


GHOST = 2

WALL, OUTFLOW, PERIODIC, INFLOW, CUT = 0, 1, 2, 3, 4
FACE_CODES = {"wall": WALL, "zero_gradient": OUTFLOW, "periodic": PERIODIC}
CHARACTERISTIC = ("inflow", "outflow", "far_field")
FACE_NAMES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")

# zone kinds
Z_INACTIVE, Z_REAL, Z_IMAGE, Z_OPEN = 0, 1, 2, 3

# VTK corner offsets (ox, oy, oz)
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.int64)


class GridError(ValueError):
    pass


class Block:
    """One rank's padded block of the structured grid: ``local_cells`` zones per axis from global
    zone ``offset`` (default: the whole box); ``cuts`` (3, 2) marks faces shared with another rank."""

    def __init__(self, lower, upper, cells, faces, offset=None, local_cells=None, cuts=None):
        lower = np.asarray(lower, dtype=np.float64)
        upper = np.asarray(upper, dtype=np.float64)
        cells = np.asarray(cells, dtype=np.int64)
        dim = lower.size
        if dim not in (2, 3) or upper.size != dim or cells.size != dim:
            raise GridError(f"grid lower/upper/cells must all have 2 or 3 entries, got "
                            f"{lower.size}/{upper.size}/{cells.size}")
        if np.any(cells < 1) or np.any(~(upper > lower)):
            raise GridError(f"grid needs cells >= 1 and upper > lower, got {cells}, {lower}, {upper}")
        self.dim = dim
        self.lower, self.upper, self.cells = lower, upper, cells
        self.h = spacing(lower, upper, cells)
        self.offset = np.zeros(dim, np.int64) if offset is None else np.asarray(offset, np.int64)
        n = cells.copy() if local_cells is None else np.asarray(local_cells, np.int64)
        self.n = n
        G = GHOST
        n3 = np.ones(3, np.int64)
        n3[:dim] = n
        self.n3 = n3
        self.zdims = tuple(int(v) for v in np.where(np.arange(3) < dim, n3 + 2 * G, 1))
        self.ndims = tuple(int(v) for v in np.where(np.arange(3) < dim, n3 + 2 * G + 1, 1))
        N0, N1, N2 = self.zdims
        M0, M1, M2 = self.ndims
        self.zs = np.array([N1 * N2, N2, 1], np.int64)
        self.ns = np.array([M1 * M2, M2, 1], np.int64)
        self.nzones = N0 * N1 * N2
        self.nnodes = M0 * M1 * M2
        # index ranges [lo, hi) per axis (3 entries, the third [0, 1) in 2D)
        act = np.arange(3) < dim
        self.zreal = (np.where(act, G, 0), np.where(act, G + n3, 1))
        self.nreal = (np.where(act, G, 0), np.where(act, G + n3 + 1, 1))

        # faces: kind codes (dim, 2), inflow states and piston speeds (a piston is a wall whose
        # nodes move at the prescribed normal speed, positive into the domain)
        # characteristic faces (inflow, outflow, far field: open_faces.py) are open faces with
        # zero-gradient ghost maps whose pressure (and donors) open_faces.py sets; their specs in
        # ``characteristic``.  ``inflow`` holds the states of held-velocity faces (``piston`` with a
        # velocity vector, Eulerian mode: code INFLOW)
        self.face = np.zeros((3, 2), np.int64)
        self.inflow = {}
        self.piston = {}
        self.characteristic = {}
        for d in range(dim):
            for s in range(2):
                spec = faces[FACE_NAMES[2 * d + s]]
                kind, body = (spec, {}) if isinstance(spec, str) else next(iter(spec.items()))
                if kind == "piston" and np.ndim(body["velocity"]) == 0:
                    self.face[d, s] = WALL
                    self.piston[(d, s)] = float(body["velocity"])
                elif kind == "piston":
                    self.face[d, s] = INFLOW
                    self.inflow[(d, s)] = body
                elif kind in CHARACTERISTIC:
                    self.face[d, s] = OUTFLOW
                    c = {"kind": kind, **{k: v for k, v in body.items() if k not in ("density", "velocity", "pressure")}}
                    if "density" in body:
                        c["state"] = (float(body["density"]), [float(u) for u in body["velocity"]],
                                      float(body["pressure"]))
                    elif "pressure" in body:
                        c["pressure"] = float(body["pressure"])
                    self.characteristic[(d, s)] = c
                else:
                    self.face[d, s] = FACE_CODES[kind]
            if (self.face[d, 0] == PERIODIC) != (self.face[d, 1] == PERIODIC):
                raise GridError(f"periodic must be set on both {FACE_NAMES[2 * d]} and {FACE_NAMES[2 * d + 1]}")
        # periodic axes of the whole grid (a rank cut may replace the face code on this block)
        self.periodic = np.array([self.face[d, 0] == PERIODIC for d in range(dim)], dtype=bool)
        if cuts is not None:
            for d in range(dim):
                for s in range(2):
                    if cuts[d][s]:
                        self.face[d, s] = CUT
                        self.inflow.pop((d, s), None)
                        self.piston.pop((d, s), None)
                        self.characteristic.pop((d, s), None)

        # Eulerian (reference) node coordinates of the padded block, ghosts included
        self.X = np.zeros((self.nnodes, dim))
        Xv = self.X.reshape(M0, M1, M2, dim)
        for d in range(dim):
            gi = self.offset[d] + np.arange(self.ndims[d]) - G
            coord = lower[d] + gi * self.h[d]
            # the upper boundary exactly at upper (no accumulated rounding)
            coord[gi == cells[d]] = upper[d]
            shape = [1, 1, 1]
            shape[d] = self.ndims[d]
            Xv[..., d] = coord.reshape(shape)

        # zone kinds
        kind = np.full(self.zdims, Z_REAL, np.int64)
        for d in range(dim):
            idx = np.arange(self.zdims[d])
            for s, ghost in ((0, idx < G), (1, idx >= G + n3[d])):
                sl = [slice(None)] * 3
                sl[d] = ghost
                f = self.face[d, s]
                sub = kind[tuple(sl)]
                if f == WALL:
                    sub[...] = Z_INACTIVE
                elif f in (PERIODIC, CUT):
                    sub[sub == Z_REAL] = Z_IMAGE
                else:
                    sub[sub != Z_INACTIVE] = Z_OPEN
                kind[tuple(sl)] = sub
        self.zkind = kind.ravel().astype(np.int8)
        self.zact = (self.zkind != Z_INACTIVE).astype(np.float64)

        # owned nodes (diagnostics): real nodes, minus the upper plane of a periodic axis or a cut
        own = np.zeros(self.ndims, bool)
        sl = tuple(slice(int(a), int(b)) for a, b in zip(*self.nreal))
        own[sl] = True
        for d in range(dim):
            if self.face[d, 1] in (PERIODIC, CUT):
                s2 = [slice(None)] * 3
                s2[d] = G + n3[d]
                own[tuple(s2)] = False
        self.owned = own.ravel()
        real = np.zeros(self.ndims, bool)
        real[sl] = True
        self.real_node = real.ravel()
        self.real_zone = np.zeros(self.zdims, bool)
        self.real_zone[tuple(slice(int(a), int(b)) for a, b in zip(*self.zreal))] = True
        self.real_zone = self.real_zone.ravel()

        # output numbering: real nodes (periodic upper planes included), x fastest
        nsl = tuple(slice(int(a), int(b)) for a, b in zip(*self.nreal))
        zsl = tuple(slice(int(a), int(b)) for a, b in zip(*self.zreal))
        node_ids = np.arange(self.nnodes).reshape(self.ndims)[nsl]
        zone_ids = np.arange(self.nzones).reshape(self.zdims)[zsl]
        self.out_nodes = np.ascontiguousarray(node_ids.transpose(2, 1, 0).ravel())
        self.out_zones = np.ascontiguousarray(zone_ids.transpose(2, 1, 0).ravel())
        self.open_ghosts = np.flatnonzero(self.zkind == Z_OPEN)

    def connectivity(self) -> np.ndarray:
        """(ne, 4|8) connectivity of the real zones in VTK order, in output numbering (built on
        demand: it is only needed for output)."""
        local = np.full(self.nnodes, -1, np.int64)
        local[self.out_nodes] = np.arange(self.out_nodes.size)
        base = self._zone_to_node(self.out_zones)
        return local[base[:, None] + self.corner_offsets()[None, :]]

    # ---- index helpers ------------------------------------------------------------------------
    def corner_offsets(self) -> np.ndarray:
        """Flat node offsets of the zone corners (VTK order) from the zone's lower corner node."""
        c = HEX_CORNERS[: 4 if self.dim == 2 else 8]
        return (c * self.ns[None, :]).sum(axis=1)

    def _zone_to_node(self, z):
        i, r = np.divmod(z, self.zs[0])
        j, k = np.divmod(r, self.zs[1])
        return i * self.ns[0] + j * self.ns[1] + k * self.ns[2]

    def zone_ijk(self, z: int):
        """Global (i, j[, k]) of padded zone z (0-based over the real box)."""
        i, r = divmod(int(z), int(self.zs[0]))
        j, k = divmod(r, int(self.zs[1]))
        ijk = np.array([i, j, k])[: self.dim] - GHOST + self.offset
        return tuple(int(v) for v in ijk)

    def zone_centres(self) -> np.ndarray:
        """(nzones, dim) centres of the Eulerian zones (ghosts included)."""
        out = np.zeros((self.nzones, self.dim))
        ov = out.reshape(*self.zdims, self.dim)
        for d in range(self.dim):
            gi = self.offset[d] + np.arange(self.zdims[d]) - GHOST
            shape = [1, 1, 1]
            shape[d] = self.zdims[d]
            ov[..., d] = axis_centres(self.lower[d], self.h[d], gi).reshape(shape)
        return out

    def zview(self, a):
        return a.reshape(self.zdims + a.shape[1:])

    def nview(self, a):
        return a.reshape(self.ndims + a.shape[1:])

    # ---- boundary node sets ---------------------------------------------------------------------
    def face_nodes(self, d: int, s: int) -> np.ndarray:
        """Flat indices of the real nodes on face (d, s)."""
        n = int(self.n3[d])
        plane = 2 if s == 0 else n + 2
        sl = [slice(int(a), int(b)) for a, b in zip(*self.nreal)]
        sl[d] = plane
        return np.arange(self.nnodes).reshape(self.ndims)[tuple(sl)].ravel()
