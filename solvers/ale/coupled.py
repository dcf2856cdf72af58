"""What the ALE background exchanges with the coupler for immersed (coupled) bodies, in global ids.

The coupler sees the background grid as a descriptor (lower, upper, cells): zone id
``i + nx (j + ny k)``, node id ``i + (nx+1) (j + (ny+1) k)``, face id of the faces normal to axis d
``i + (n0 + [d==0]) (j + (n1 + [d==1]) k)`` (x fastest, the output order).  Everything it sends or
asks for is a list of ids of the cut region and values for them, identical on every rank of the
group; each rank picks what lies in its block (:class:`GlobalIndex`).  Values it asks for come back
as sums over the ranks of (owner's value, zeros elsewhere): ``x + 0 = x`` exactly, so the coupler
receives the same bits whatever the number of background ranks.

:class:`BodyGeometry` is the state of the bodies in the grid after a step (from the coupler's
clipping of the body surfaces, orchestrator/coupling/geometry.py): the blocked fraction of every
zone a body covers, the exact covered fraction of every zone face a body covers (the face
apertures of solvers/ale/blocked.py; ``None``: apertures from the fractions by the min model), the
cut zones (those holding a piece of a body surface: one multiplier each, the surface terms of
blocked.py) and the background nodes whose predictor velocities and masses the next step's
constraint solve needs, and the surface's velocity in every cut zone (the artificial viscosity of a
cut zone sees the open volume's rate of change, surface included).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from solvers.ale.grid import GHOST


@dataclass
class BodyGeometry:
    zones: np.ndarray  # (nb,) int64 zone ids with a blocked fraction > 0 (besides the runs)
    fractions: np.ndarray  # (nb,) float64 blocked fraction (all bodies together) in [0, 1]
    faces: tuple | None = None  # per axis d: (face ids (nf,) int64, covered fraction (nf,)) or None
    cut: np.ndarray | None = None  # (nc,) int64 cut zones (sorted)
    nodes: np.ndarray | None = None  # (nn,) int64 nodes the next constraint solve needs (sorted)
    velocity: np.ndarray | None = None  # (nc, dim) the surface's mean velocity in each cut zone
    # zones covered whole, as runs of consecutive zone ids [start, start + length) (along x): a body's
    # interior costs one pair per grid row, not one entry per zone; every face between two covered
    # zones (fraction 1) is covered whole unless ``faces`` lists it
    run_start: np.ndarray | None = None
    run_length: np.ndarray | None = None

    def blocks_anything(self) -> bool:
        return bool(np.any(np.asarray(self.fractions) != 0.0)
                    or (self.run_length is not None and np.any(self.run_length > 0)))

    def pack(self, dim: int) -> np.ndarray:
        """One float64 buffer (ids below 2^53 are exact in float64)."""
        parts = [np.array([float(self.zones.size)]), self.zones.astype(np.float64), self.fractions]
        faces = self.faces if self.faces is not None else [None] * dim
        parts.append(np.array([0.0 if self.faces is None else 1.0]))
        for f in faces:
            ids, cov = f if f is not None else (np.zeros(0), np.zeros(0))
            parts += [np.array([float(len(ids))]), np.asarray(ids, np.float64), np.asarray(cov, np.float64)]
        for a in (self.cut, self.nodes, self.velocity, self.run_start, self.run_length):
            a = np.zeros(0) if a is None else a
            parts += [np.array([float(a.size)]), a.astype(np.float64).ravel()]
        return np.concatenate(parts)

    @classmethod
    def unpack(cls, buf: np.ndarray, dim: int) -> "BodyGeometry":
        pos = 0

        def take(n):
            nonlocal pos
            out = buf[pos:pos + n]
            pos += n
            return out

        n = int(take(1)[0])
        zones = take(n).astype(np.int64)
        fractions = take(n).copy()
        has_faces = take(1)[0] == 1.0
        faces = []
        for _ in range(dim):
            k = int(take(1)[0])
            faces.append((take(k).astype(np.int64), take(k).copy()))
        cut = take(int(take(1)[0])).astype(np.int64)
        nodes = take(int(take(1)[0])).astype(np.int64)
        velocity = take(int(take(1)[0])).reshape(-1, dim).copy()
        run_start = take(int(take(1)[0])).astype(np.int64)
        run_length = take(int(take(1)[0])).astype(np.int64)
        return cls(zones, fractions, tuple(faces) if has_faces else None, cut, nodes, velocity, run_start,
                   run_length)


class GlobalIndex:
    """Global ids of the coupler -> this rank's padded block indices."""

    def __init__(self, block):
        B = block
        self.block = B
        self.dim = B.dim
        self.cells = np.asarray(B.cells, np.int64)

    def _split(self, ids, extent):
        ijk = np.zeros((ids.size, 3), np.int64)
        r = np.asarray(ids, np.int64)
        for d in range(self.dim):
            r, ijk[:, d] = np.divmod(r, extent[d])
        return ijk

    def padded_range(self):
        """Global ijk (3,) of padded zone 0 and the end (exclusive) of the padded block, clipped to
        the grid below (the ghost layers beyond the grid's faces hold no coupled-body zone)."""
        B = self.block
        lo = np.zeros(3, np.int64)
        hi = np.ones(3, np.int64)
        lo[: self.dim] = B.offset - GHOST
        hi[: self.dim] = B.offset + B.n + GHOST
        return lo, hi

    def runs(self, start, length) -> np.ndarray:
        """(nzones,) 1.0 in every padded zone (ghost layers included) of the runs, else 0."""
        B = self.block
        out = np.zeros(B.nzones)
        if start is None or len(start) == 0:
            return out
        lo, hi = self.padded_range()
        cells = np.ones(3, np.int64)
        cells[: self.dim] = self.cells
        fill_runs(np.asarray(start, np.int64), np.asarray(length, np.int64), cells, lo, hi,
                  np.asarray(B.zs, np.int64), out)
        return out

    def _local(self, ids, extent, lo, hi, strides):
        """(padded index, mask) of global ids on the lattice ``extent`` whose block-local ijk lies in
        [lo, hi) per axis (index 0 where outside): one pass of ``local_index``."""
        B = self.block
        ids = np.ascontiguousarray(ids, dtype=np.int64).reshape(-1)
        out = np.empty(ids.size, np.int64)
        inside = np.empty(ids.size, np.bool_)
        local_index(ids, np.asarray(extent, np.int64), np.asarray(B.offset, np.int64), np.asarray(lo, np.int64),
                    np.asarray(hi, np.int64), np.asarray(strides, np.int64), GHOST, out, inside)
        return out, inside

    def zones(self, ids, ghosts: int = 0):
        """(local padded zone index, mask: a real zone of this block -- or, with ``ghosts`` = k,
        a zone of the first k ghost layers too) of global zone ids."""
        B = self.block
        g = int(ghosts)
        return self._local(ids, self.cells, np.full(self.dim, -g), B.n + g, B.zs)

    def nodes(self, ids):
        """(local padded node index, mask: a real node of this block, mask: owned here)."""
        B = self.block
        n, inside = self._local(ids, self.cells + 1, np.zeros(self.dim, np.int64), B.n + 1, B.ns)
        return n, inside, inside & B.owned[n]

    def faces(self, d, ids):
        """(local zone-shaped index, mask) of global faces normal to axis d: entry z of a face array
        of direction d is the lower d-face of zone z (the upper box face: the ghost zone's)."""
        B = self.block
        ext = self.cells.copy()
        ext[d] += 1
        hi = B.n.copy()
        hi[d] += 1
        return self._local(ids, ext, np.zeros(self.dim, np.int64), hi, B.zs)


@njit(cache=True)
def local_index(ids, extent, offset, lo, hi, strides, ghost, out, inside):
    """For each global id on the lattice ``extent`` (x fastest): its padded index on this block
    (sum over the axes of (ijk - offset + ghost) * stride) and whether its local ijk = ijk - offset
    lies in [lo, hi) on every axis (index 0 where not)."""
    dim = extent.size
    for a in range(ids.size):
        r = ids[a]
        idx = 0
        ok = True
        for d in range(dim):
            q = r % extent[d]
            r //= extent[d]
            loc = q - offset[d]
            if loc < lo[d] or loc >= hi[d]:
                ok = False
            idx += (loc + ghost) * strides[d]
        inside[a] = ok
        out[a] = idx if ok else 0


@njit(cache=True)
def fill_runs(start, length, cells, lo, hi, zs, out):
    """out[z] = 1 for every padded zone z of the runs (global zone ids ``[start, start + length)``
    along x, x fastest) whose global ijk lies in [lo, hi) (the part of the grid the padded block
    holds: its real zones and ghost layers; padded index of ``lo`` is 0).  Work: runs + zones set."""
    nx, ny = cells[0], cells[1]
    for r in range(start.size):
        s0 = start[r]
        i0 = s0 % nx
        j = (s0 // nx) % ny
        k = s0 // (nx * ny)
        if j < lo[1] or j >= hi[1] or k < lo[2] or k >= hi[2]:
            continue
        a = max(i0, lo[0])
        b = min(i0 + length[r], hi[0])
        base = (j - lo[1]) * zs[1] + (k - lo[2]) * zs[2]
        for i in range(a, b):
            out[(i - lo[0]) * zs[0] + base] = 1.0
