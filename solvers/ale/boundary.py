"""Boundary conditions of the ALE grid: ghost fills and node constraints per face.

Ghost fills work on the padded arrays of a :class:`~solvers.ale.grid.Block` (``GHOST = 2``
layers).  The per-face rules (wall: mirror, normal velocity component reversed; outflow: zero
gradient; periodic: images; inflow: prescribed state and velocity) are applied once, at
construction, to index arrays, axis by axis (x, then y, then z over the whole extent of the other
axes, so edge and corner ghosts are consistent); every ghost entry thereby learns its ultimate real
source (and sign), and a fill is a single pass ``a[dst] = a[src]`` in numba.

Node constraints (after the predictor): on a wall face the normal velocity component is zero (on a
piston face, a wall in every other respect, it is the piston's speed, positive into the domain); on an
inflow face the nodes move with the inflow velocity.  The reaction impulse ``m (v_after -
v_before)`` and its work on the mean velocity enter the solver's balances.  Outflow and periodic
face nodes are free (their ghost zones act on them).

Face-centred arrays of direction d (swept volumes, mass fluxes) use their own map along d: images
on a periodic axis, otherwise zero gradient (a wall face's flux is zero anyway).

Rank cuts (grid.CUT) have no physical map; every fill is followed by the halo exchange of the same
arrays (``halo``, parallel.Halo), which gives their ghosts the neighbour's values.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from solvers.ale.grid import CUT, GHOST, INFLOW, OUTFLOW, PERIODIC, WALL, Block


class Boundaries:
    """Ghost maps and node constraints of a block."""

    def __init__(self, block: Block, halo=None):
        self.b = block
        self.halo = halo if halo is not None and halo.active else None
        self._build_maps()
        dim = block.dim
        wn, wc, wv, inn, ivel = [], [], [], [], []
        for d in range(dim):
            for s in range(2):
                nodes = block.face_nodes(d, s)
                if block.face[d, s] == WALL:
                    wn.append(nodes)
                    wc.append(np.full(nodes.size, d, np.int64))
                    # normal velocity component: 0, or the piston speed into the domain
                    up = block.piston.get((d, s), 0.0)
                    wv.append(np.full(nodes.size, up if s == 0 else -up, np.float64))
                elif block.face[d, s] == INFLOW:
                    inn.append(nodes)
                    ivel.append(np.tile(np.asarray(block.inflow[(d, s)]["velocity"], np.float64), (nodes.size, 1)))
        self.wall_nodes = np.concatenate(wn) if wn else np.zeros(0, np.int64)
        self.wall_comp = np.concatenate(wc) if wc else np.zeros(0, np.int64)
        self.wall_vel = np.concatenate(wv) if wv else np.zeros(0, np.float64)
        self.inflow_nodes = np.concatenate(inn) if inn else np.zeros(0, np.int64)
        self.inflow_vel = np.concatenate(ivel) if ivel else np.zeros((0, dim))
        # an inflow node on a wall (the face's edge) keeps the wall's normal velocity: its target
        # velocity is final before the wall pass, so the reaction and its work are recorded once,
        # on the velocity the node ends with (recorded in two stages, the work of the first stage
        # would use the inflow's normal component the wall then removes)
        if self.inflow_nodes.size and self.wall_nodes.size:
            pos = {int(n): t for t, n in enumerate(self.inflow_nodes)}
            for n, c, wv_ in zip(self.wall_nodes, self.wall_comp, self.wall_vel):
                t = pos.get(int(n))
                if t is not None:
                    self.inflow_vel[t, c] = wv_
        # inflow ghost nodes on the plane of a wall: (nodes, wall direction, wall normal velocity)
        dst, src, _ = self.nmap_vec
        pres = dst[src < 0]
        ijk = np.stack(np.unravel_index(pres, block.ndims), axis=1)
        iw, cw, vw = [], [], []
        for d in range(dim):
            for s in range(2):
                if block.face[d, s] != WALL:
                    continue
                plane = 2 if s == 0 else int(block.n3[d]) + 2
                on = pres[ijk[:, d] == plane]
                up = block.piston.get((d, s), 0.0)
                iw.append(on)
                cw.append(np.full(on.size, d, np.int64))
                vw.append(np.full(on.size, up if s == 0 else -up))
        self._inflow_wall_nodes = (np.concatenate(iw) if iw else np.zeros(0, np.int64),
                                   np.concatenate(cw) if cw else np.zeros(0, np.int64),
                                   np.concatenate(vw) if vw else np.zeros(0))

    def constrain(self, v, v_old, m, acc) -> None:
        """Impose the wall, piston and inflow velocities (in place); reactions summed into acc (see
        kernel)."""
        constrain(v, v_old, m, self.b.owned, self.inflow_nodes, self.inflow_vel, self.wall_nodes,
                  self.wall_comp, self.wall_vel, acc)

    def _planes(self, d: int, s: int, nodes: bool, face_dir: bool = False):
        """[(ghost plane, source plane)] of face (d, s), or [] for inflow (prescribed)."""
        n = int(self.b.n3[d])
        f = self.b.face[d, s]
        if f == CUT:  # ghosts by halo exchange
            return []
        if face_dir:  # face-centred array of direction d along its own axis
            if f == PERIODIC:
                return [(1, n + 1), (0, n)] if s == 0 else [(n + 2, 2), (n + 3, 3)]
            return [(1, 2), (0, 2)] if s == 0 else [(n + 3, n + 2)]
        if nodes:
            if f == WALL:
                return [(1, 3), (0, 4)] if s == 0 else [(n + 3, n + 1), (n + 4, n)]
            if f == OUTFLOW:
                return [(1, 2), (0, 2)] if s == 0 else [(n + 3, n + 2), (n + 4, n + 2)]
            if f == PERIODIC:
                return [(1, n + 1), (0, n)] if s == 0 else [(n + 2, 2), (n + 3, 3), (n + 4, 4)]
            return []
        if f == WALL:
            return [(1, 2), (0, 3)] if s == 0 else [(n + 2, n + 1), (n + 3, n)]
        if f == OUTFLOW:
            return [(1, 2), (0, 2)] if s == 0 else [(n + 2, n + 1), (n + 3, n + 1)]
        if f == PERIODIC:
            return [(1, n + 1), (0, n)] if s == 0 else [(n + 2, 2), (n + 3, 3)]
        return []

    def ghost_planes(self, d: int, s: int, nodes: bool) -> list[int]:
        n = int(self.b.n3[d])
        if nodes:
            return [1, 0] if s == 0 else [n + 3, n + 4]
        return [1, 0] if s == 0 else [n + 2, n + 3]

    @staticmethod
    def _copy(a, d, dst, src, sign=None):
        sd = [slice(None)] * a.ndim
        ss = [slice(None)] * a.ndim
        sd[d] = dst
        ss[d] = src
        if sign is None:
            a[tuple(sd)] = a[tuple(ss)]
        else:
            a[tuple(sd)] = a[tuple(ss)] * sign

    def _compose(self, nodes: bool, prescribed: bool, face_dir=None, vector: bool = False):
        """Ghost map: apply the plane copies (axis by axis) to an index array, so every ghost entry
        learns its ultimate (real) source; inflow ghosts get the sentinel -1 - (2 d + s) when
        ``prescribed`` (else a zero-gradient source).  Returns (dst, src[, sign (k, dim)])."""
        dims = self.b.ndims if nodes else self.b.zdims
        idx = np.arange(int(np.prod(dims)), dtype=np.int64).reshape(dims)
        sign = np.ones(dims + (self.b.dim,)) if vector else None
        for d in range(self.b.dim):
            for s in range(2):
                f = self.b.face[d, s]
                planes = self._planes(d, s, nodes, face_dir=(face_dir == d))
                if not planes and f == INFLOW:
                    n = int(self.b.n3[d])
                    if prescribed:
                        for g in self.ghost_planes(d, s, nodes):
                            sl = [slice(None)] * 3
                            sl[d] = g
                            idx[tuple(sl)] = -1 - (2 * d + s)
                            if vector:
                                sign[tuple(sl)] = 1.0
                        continue
                    src = 2 if s == 0 else (n + 2 if nodes else n + 1)
                    planes = [(g, src) for g in self.ghost_planes(d, s, nodes)]
                flip = None
                if vector and f == WALL and face_dir is None:
                    flip = np.ones(self.b.dim)
                    flip[d] = -1.0
                for dst, src in planes:
                    self._copy(idx, d, dst, src)
                    if vector:
                        self._copy(sign, d, dst, src, flip)
        flat = idx.ravel()
        dst = np.flatnonzero(flat != np.arange(flat.size))
        out = (dst.astype(np.int64), flat[dst].astype(np.int64))
        if vector:
            out += (np.ascontiguousarray(sign.reshape(-1, self.b.dim)[dst]),)
        return out

    def _build_maps(self) -> None:  # noqa: D401
        self.zmap_pres = self._compose(False, True)
        self.zmap_zg = self._compose(False, False)
        self.fmap = [self._compose(False, False, face_dir=d) for d in range(self.b.dim)]
        self.nmap_vec = self._compose(True, True, vector=True)
        self.nmap_sca = self._compose(True, False)

    def fill_zones(self, fields, inflow_values=None, face_dir=None, depth=GHOST):
        """Fill the ghost zones of zone-shaped flat arrays ``fields`` (in place).

        ``inflow_values[(d, s)]`` gives, per field, the prescribed ghost value (None = zero-gradient
        copy) on an inflow face.  ``face_dir`` = d marks face-centred arrays of direction d (fluxes).
        ``depth``: ghost layers exchanged at rank cuts.
        """
        self._fill_zones(fields, inflow_values, face_dir)
        if self.halo is not None:
            self.halo.zones(fields, depth)

    def _fill_zones(self, fields, inflow_values, face_dir):
        if face_dir is not None:
            dst, src = self.fmap[face_dir]
            for a in fields:
                copy_rows(a.reshape(a.shape[0], -1), dst, src)
            return
        for ia, a in enumerate(fields):
            a2 = a.reshape(a.shape[0], -1)
            vals = None
            if inflow_values:
                vals = {key: v[ia] for key, v in inflow_values.items() if v[ia] is not None}
            if not vals:
                copy_rows(a2, *self.zmap_zg)
                continue
            dst, src = self.zmap_pres
            copy_rows(a2, dst, src)
            for key, val in vals.items():
                a2[dst[src == -1 - (2 * key[0] + key[1])]] = val

    def fill_nodes_vector(self, v, inflow=True):
        """Ghost nodes of a nodal vector (velocity-like: normal component mirrored at walls;
        inflow ghosts get the inflow velocity, mirrored like any other value where the inflow's
        ghost layer continues beyond a wall, and with the wall's normal velocity on the wall's plane,
        so that the extended wall stays a wall for the inflow's ghost zones too)."""
        dst, src, sign = self.nmap_vec
        copy_rows_signed(v, dst, src, sign)
        for (d, s), st in self.b.inflow.items():
            sel = src == -1 - (2 * d + s)
            v[dst[sel]] = np.asarray(st["velocity"], np.float64) * sign[sel] if inflow else 0.0
        if inflow and self._inflow_wall_nodes[0].size:
            nodes, comp, vel = self._inflow_wall_nodes
            v[nodes, comp] = vel
        if self.halo is not None:
            self.halo.nodes([v])

    def fill_nodes_scalar(self, m):
        copy_rows(m.reshape(m.shape[0], -1), *self.nmap_sca)
        if self.halo is not None:
            self.halo.nodes([m])



@njit(cache=True)
def copy_rows(a, dst, src):
    """a[dst[t]] = a[src[t]] for the rows with src >= 0 (a: (n, k))."""
    k = a.shape[1]
    for t in range(dst.shape[0]):
        s = src[t]
        if s >= 0:
            r = dst[t]
            for c in range(k):
                a[r, c] = a[s, c]


@njit(cache=True)
def copy_rows_signed(a, dst, src, sign):
    """a[dst[t]] = a[src[t]] * sign[t] (component-wise) for the rows with src >= 0."""
    k = a.shape[1]
    for t in range(dst.shape[0]):
        s = src[t]
        if s >= 0:
            r = dst[t]
            for c in range(k):
                a[r, c] = a[s, c] * sign[t, c]


@njit(cache=True)
def constrain(v, v_old, m, owned, inflow_nodes, inflow_vel, wall_nodes, wall_comp, wall_vel, acc):
    """Inflow face nodes take the inflow velocity, then wall nodes set their normal component to
    wall_vel (0 on a wall, the signed piston speed on a piston face).  The reaction impulse
    m (v_after - v_before) of owned nodes is added to acc[0:dim] and its work on the mean velocity
    (v_old + v_after)/2 to acc[3] (a piston's work is boundary work)."""
    dim = v.shape[1]
    for t in range(inflow_nodes.shape[0]):
        n = inflow_nodes[t]
        w = 1.0 if owned[n] else 0.0
        for c in range(dim):
            r = m[n] * (inflow_vel[t, c] - v[n, c])
            v[n, c] = inflow_vel[t, c]
            acc[c] += w * r
            acc[3] += w * r * 0.5 * (v_old[n, c] + v[n, c])
    for t in range(wall_nodes.shape[0]):
        n = wall_nodes[t]
        c = wall_comp[t]
        w = 1.0 if owned[n] else 0.0
        r = m[n] * (wall_vel[t] - v[n, c])
        v[n, c] = wall_vel[t]
        acc[c] += w * r
        acc[3] += w * r * 0.5 * (v_old[n, c] + v[n, c])

