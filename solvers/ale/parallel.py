"""MPI domain decomposition of the ALE grid: Cartesian split, halo exchange, reductions, gathers.

Split
-----
The zone box (``cells`` per axis) is split over the ranks of the solver's communicator into a
Cartesian grid of blocks: ``MPI.Compute_dims`` (axes with fewer than ``2 * MIN_ZONES`` zones are
pinned to 1), then ``Create_cart`` with the periodic flags of the boundary configuration and
``reorder=False`` (rank numbers are those of the communicator; rank 0 writes).  Every block keeps at
least ``MIN_ZONES`` (= the ghost width) zones per split axis, so both ghost layers come from the
direct neighbour; when Compute_dims' choice violates that (a long thin box), the feasible
factorisation with the smallest cut area is taken instead.  The block at Cartesian coordinate
``c`` of ``P`` along an axis of ``C`` zones holds ``C // P`` zones, one more for ``c < C % P``.

Cuts
----
A face between two blocks is a *cut* (``grid.CUT``, on a periodic axis split over several ranks
also the box faces, through the cart's wrap-around neighbours).  Its ghosts are images of the
neighbour's zones and nodes, exactly as on a periodic face, so the padded index maps are::

    zones (depth g = 2, or 1 for corner forces):   lower ghosts [2-g, 2) <- neighbour's [n'+2-g, n'+2)
                                                   upper ghosts [n+2, n+2+g) <- neighbour's [2, 2+g)
    nodes:                                         lower ghosts [0, 2)    <- neighbour's [n', n'+2)
                                                   upper planes [n+2, n+5) <- neighbour's [2, 5)

(the shared node plane n+2 is computed by both blocks from the same inputs; taking the upper
neighbour's copy, like the periodic image plane, only makes that explicit).  Face-centred arrays
(swept volumes, remap fluxes) use the zone map: their upper face plane n+2 is the neighbour's
plane 2.

Exchange: after the physical ghost fill of the same arrays (boundary.py), axis by axis (x, y, z),
each slab over the full padded extent of the other axes.  An entry that is a cut ghost along the
axes C gets its final value from the exchange along max(C), from a neighbour entry whose cut axes
are C minus that one and were exchanged before, so edge and corner ghosts equal the one-rank
values.  Messages are packed contiguous numpy slabs in persistent buffers with persistent requests
(``Send_init``/``Recv_init``, one plan per set of array shapes); tag ``2 d`` carries the slabs
going down axis d, ``2 d + 1`` those going up (a 2-rank periodic axis has the same rank on both
sides).

Every kernel computes a zone's or node's values from the same inputs in the same order whichever
block holds it (nodal forces and masses are gathered, never scattered), so the decomposed run is
bitwise the one-rank run; only reductions over ranks (diagnostic sums) change the summation order.
"""
from __future__ import annotations

import math

import numpy as np

from solvers.ale.grid import GHOST, GridError

MIN_ZONES = GHOST


def _factorisations(size: int, dim: int):
    if dim == 1:
        yield (size,)
        return
    for p in range(1, size + 1):
        if size % p == 0:
            for rest in _factorisations(size // p, dim - 1):
                yield (p,) + rest


def _feasible(dims, cells, size) -> bool:
    return (int(np.prod(dims)) == size
            and all(p == 1 or c // p >= MIN_ZONES for p, c in zip(dims, cells)))


def split_possible(size: int, cells) -> bool:
    """Whether ``size`` ranks can split a grid of ``cells`` zones by the rule of split_dims (every
    split axis keeps MIN_ZONES zones a block).  Pure Python over the divisors of ``size`` (about
    sqrt(size) steps), no MPI: the orchestrator asks before anything launches."""
    size = int(size)
    if size < 1:
        return False
    cap = [max(1, int(c) // MIN_ZONES) for c in cells]  # the most blocks an axis can take
    divisors = sorted({d for i in range(1, math.isqrt(size) + 1) if size % i == 0 for d in (i, size // i)})

    def fits(rest: int, axes: list[int]) -> bool:
        if len(axes) == 1:
            return rest <= axes[0]
        return any(rest % p == 0 and fits(rest // p, axes[1:]) for p in divisors if p <= min(axes[0], rest))
    return fits(size, cap)


def split_dims(size: int, cells) -> list[int]:
    """Blocks per axis for ``size`` ranks (see the module docstring)."""
    from mpi4py import MPI

    cells = [int(c) for c in cells]
    if size == 1:
        return [1] * len(cells)
    try:
        dims = list(MPI.Compute_dims(size, [0 if c >= 2 * MIN_ZONES else 1 for c in cells]))
    except Exception:  # pinned axes leave no factorisation
        dims = None
    if dims is not None and _feasible(dims, cells, size):
        return dims
    total = float(np.prod(cells))
    best = None
    for dims in _factorisations(size, len(cells)):
        if _feasible(dims, cells, size):
            area = sum((p - 1) * total / c for p, c in zip(dims, cells))
            if best is None or area < best[0]:
                best = (area, list(dims))
    if best is None:
        raise GridError(f"a grid of {cells} zones cannot be split over {size} ranks with at least "
                        f"{MIN_ZONES} zones per rank along every split axis")
    return best[1]


class Decomposition:
    """This rank's place in the Cartesian split: ``offset``, ``n`` (zones per axis), ``cuts`` (3, 2)
    (face is a rank cut) and the neighbour ranks ``nbr[d] = (lower, upper)`` (None: no cut)."""

    def __init__(self, comm, cells, periodic):
        cells = np.asarray(cells, dtype=np.int64)
        self.dim = dim = cells.size
        self.cells = cells
        self.size = 1 if comm is None else int(comm.size)
        self.parallel = self.size > 1
        self.nbr = [(None, None)] * 3
        if self.parallel:
            from mpi4py import MPI

            self.dims = split_dims(self.size, cells)
            self.comm = comm.Create_cart(self.dims, periods=[bool(p) for p in periodic], reorder=False)
            self.rank = self.comm.rank
            self.coords = list(self.comm.Get_coords(self.rank))
            for d in range(dim):
                if self.dims[d] > 1:
                    lo, hi = self.comm.Shift(d, 1)
                    self.nbr[d] = tuple(None if r == MPI.PROC_NULL else int(r) for r in (lo, hi))
        else:
            self.comm = comm
            self.dims = [1] * dim
            self.rank = 0
            self.coords = [0] * dim
        self.offset, self.n = self.box(self.coords)
        self.cuts = np.array([[self.nbr[d][s] is not None for s in range(2)] for d in range(3)], bool)

    def box(self, coords):
        """(offset, zones) per axis of the block at Cartesian coordinates ``coords``."""
        off = np.zeros(self.dim, np.int64)
        n = np.zeros(self.dim, np.int64)
        for d in range(self.dim):
            q, r = divmod(int(self.cells[d]), self.dims[d])
            c = int(coords[d])
            n[d] = q + (1 if c < r else 0)
            off[d] = c * q + min(c, r)
        return off, n

    def free(self) -> None:
        if self.parallel and self.comm is not None:
            self.comm.Free()
            self.comm = None

    # ---- reductions -----------------------------------------------------------------------------
    def sum(self, a: np.ndarray) -> np.ndarray:
        if not self.parallel:
            return a
        from mpi4py import MPI

        out = np.empty_like(a)
        self.comm.Allreduce(np.ascontiguousarray(a), out, op=MPI.SUM)
        return out

    def min(self, a: np.ndarray) -> np.ndarray:
        if not self.parallel:
            return a
        from mpi4py import MPI

        out = np.empty_like(a)
        self.comm.Allreduce(np.ascontiguousarray(a), out, op=MPI.MIN)
        return out

    def bcast(self, a: np.ndarray, root: int) -> np.ndarray:
        if self.parallel:
            self.comm.Bcast(a, root=root)
        return a

    def rank_of(self, coords) -> int:
        return int(self.comm.Get_cart_rank(list(coords))) if self.parallel else 0

    # ---- gathers to rank 0 ----------------------------------------------------------------------
    def gather_box(self, a: np.ndarray, layout, lo, hi, glo, gshape):
        """Rank 0: the array of shape ``gshape + a.shape[1:]`` assembled from every rank's box
        ``[lo, hi)`` (3 axes) of ``a`` (flat over the padded ``layout``), placed at ``glo``;
        None on the other ranks."""
        from mpi4py import MPI

        tail = a.shape[1:]
        a4 = a.reshape(tuple(layout) + (-1,))
        k = a4.shape[3]
        box = np.ascontiguousarray(a4[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
        meta = np.array(list(glo) + list(box.shape[:3]), np.int64)
        root = self.rank == 0
        metas = np.empty((self.size, 6), np.int64) if root else None
        self.comm.Gather(meta, metas, root=0)
        counts = displs = recv = None
        if root:
            counts = np.prod(metas[:, 3:], axis=1) * k
            displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
            recv = np.empty(int(counts.sum()))
        self.comm.Gatherv(box.ravel(), [recv, counts, displs, MPI.DOUBLE] if root else None, root=0)
        if not root:
            return None
        out = np.empty(tuple(int(g) for g in gshape) + (k,))
        for r in range(self.size):
            g0 = metas[r, :3]
            sh = metas[r, 3:]
            out[g0[0]:g0[0] + sh[0], g0[1]:g0[1] + sh[1], g0[2]:g0[2] + sh[2]] = \
                recv[displs[r]:displs[r] + counts[r]].reshape(tuple(sh) + (k,))
        return out.reshape(tuple(int(g) for g in gshape) + tail)


class Halo:
    """Halo exchange of a block's ghost layers at its rank cuts (see the module docstring)."""

    def __init__(self, dec: Decomposition, block):
        self.dec = dec
        self.b = block
        self.axes = [d for d in range(block.dim) if dec.cuts[d].any()]
        self.active = bool(self.axes)
        self._plans = {}

    def zones(self, arrays, depth: int = GHOST) -> None:
        """Exchange the cut ghosts of zone-shaped (or face-centred) flat arrays, ``depth`` layers."""
        if self.active:
            self._exchange(arrays, False, depth)

    def nodes(self, arrays) -> None:
        if self.active:
            self._exchange(arrays, True, 0)

    def _ranges(self, d: int, nodes: bool, depth: int):
        """(recv_lo, recv_hi, send_lo, send_hi) plane ranges along axis d."""
        n = int(self.b.n3[d])
        if nodes:
            return (0, 2), (n + 2, n + 5), (2, 5), (n, n + 2)
        g = depth
        return (2 - g, 2), (n + 2, n + 2 + g), (2, 2 + g), (n + 2 - g, n + 2)

    def _plan(self, nodes: bool, depth: int, comps: tuple):
        key = (nodes, depth, comps)
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        layout = self.b.ndims if nodes else self.b.zdims
        kt = sum(comps)
        comm = self.dec.comm
        plan = []
        for d in self.axes:
            rl, rh, sl, sh = self._ranges(d, nodes, depth)
            other = int(np.prod(layout)) // layout[d]
            lo_nb, hi_nb = self.dec.nbr[d]
            ax = {"d": d, "ranges": (rl, rh, sl, sh), "reqs": [], "lo": lo_nb is not None, "hi": hi_nb is not None}
            if lo_nb is not None:
                ax["send_lo"] = np.empty((sl[1] - sl[0]) * other * kt)
                ax["recv_lo"] = np.empty((rl[1] - rl[0]) * other * kt)
                ax["reqs"] += [comm.Send_init(ax["send_lo"], lo_nb, tag=2 * d),
                               comm.Recv_init(ax["recv_lo"], lo_nb, tag=2 * d + 1)]
            if hi_nb is not None:
                ax["send_hi"] = np.empty((sh[1] - sh[0]) * other * kt)
                ax["recv_hi"] = np.empty((rh[1] - rh[0]) * other * kt)
                ax["reqs"] += [comm.Send_init(ax["send_hi"], hi_nb, tag=2 * d + 1),
                               comm.Recv_init(ax["recv_hi"], hi_nb, tag=2 * d)]
            plan.append(ax)
        self._plans[key] = plan
        return plan

    @staticmethod
    def _slab(a4, d, rng):
        sl = [slice(None)] * 4
        sl[d] = slice(rng[0], rng[1])
        return a4[tuple(sl)]

    def _copy(self, views, d, rng, buf, pack: bool) -> None:
        o = 0
        for a4 in views:
            s = self._slab(a4, d, rng)
            c = s.size
            if pack:
                np.copyto(buf[o:o + c].reshape(s.shape), s)
            else:
                s[...] = buf[o:o + c].reshape(s.shape)
            o += c

    def _exchange(self, arrays, nodes: bool, depth: int) -> None:
        from mpi4py import MPI

        layout = tuple(self.b.ndims if nodes else self.b.zdims)
        if not all(a.flags.c_contiguous for a in arrays):
            raise ValueError("halo exchange needs C-contiguous arrays (views are filled in place)")
        views = [a.reshape(layout + (-1,)) for a in arrays]
        plan = self._plan(nodes, depth, tuple(v.shape[3] for v in views))
        for ax in plan:
            d = ax["d"]
            rl, rh, sl, sh = ax["ranges"]
            if ax["lo"]:
                self._copy(views, d, sl, ax["send_lo"], True)
            if ax["hi"]:
                self._copy(views, d, sh, ax["send_hi"], True)
            MPI.Prequest.Startall(ax["reqs"])
            MPI.Request.Waitall(ax["reqs"])
            if ax["lo"]:
                self._copy(views, d, rl, ax["recv_lo"], False)
            if ax["hi"]:
                self._copy(views, d, rh, ax["recv_hi"], False)


def structured_cells(cells) -> np.ndarray:
    """(ne, 4|8) VTK connectivity of a box of ``cells`` zones, nodes and zones numbered x fastest
    (the order of Block.connectivity for a single block)."""
    cells = [int(c) for c in cells]
    dim = len(cells)
    m = [c + 1 for c in cells]
    if dim == 2:
        j, i = np.meshgrid(np.arange(cells[1]), np.arange(cells[0]), indexing="ij")
        n0 = (i + m[0] * j).ravel()
        offs = np.array([0, 1, 1 + m[0], m[0]], np.int64)
    else:
        k, j, i = np.meshgrid(np.arange(cells[2]), np.arange(cells[1]), np.arange(cells[0]), indexing="ij")
        n0 = (i + m[0] * (j + m[1] * k)).ravel()
        s1, s2 = m[0], m[0] * m[1]
        offs = np.array([0, 1, 1 + s1, s1, s2, 1 + s2, 1 + s1 + s2, s1 + s2], np.int64)
    return (n0[:, None] + offs[None, :]).astype(np.int64)
