"""The ALE solver's state seen from outside: its diagnostics (totals and balances), its output
fields (gathered on rank 0 in parallel) and its checkpoint and restart (solver.py steps it; this
is the part of AleSolver that reads its state, not the part that advances it)."""
from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from solvers.ale import hydro
from solvers.ale.grid import CUT, GHOST
from solvers.ale.parallel import structured_cells


class SolverState:
    """AleSolver's diagnostics, output and checkpoint/restart (a base class of AleSolver: the
    attributes it reads are the solver's, set up in solver.py)."""

    # ------------------------------------------------------------------------------------------
    # diagnostics and output
    # ------------------------------------------------------------------------------------------
    def _node_ijk(self, n: int):
        B = self.block
        i, r = divmod(int(n), int(B.ns[0]))
        j, k = divmod(r, int(B.ns[1]))
        return tuple(int(v) for v in (np.array([i, j, k])[: self.dim] - GHOST + B.offset))

    def _totals(self) -> dict:
        """Sums over the owned zones and nodes and the boundary terms (all ranks: collective)."""
        B, dim = self.block, self.dim
        hydro.sums(self.M, self.e, B.real_zone, self.m, self.v, B.owned, self._sums)
        s = self._sums
        bal = (self.b_mass, self.b_energy, self.b_momentum, self.i_energy, self.i_momentum)
        if self.dec.parallel:
            s = self.dec.sum(np.concatenate([s, [self.b_mass, self.b_energy], self.b_momentum,
                                             [self.i_energy], self.i_momentum]))
            bal = (float(s[7]), float(s[8]), s[9:9 + dim].copy(), float(s[9 + dim]),
                   s[10 + dim:10 + 2 * dim].copy())
        return {"mass": s[0], "internal_energy": s[1], "kinetic_energy": s[2],
                "total_energy": s[1] + s[2], "momentum": s[3:3 + dim].copy(), "momentum_gross": s[6],
                "b_mass": bal[0], "b_energy": bal[1], "b_momentum": bal[2],
                "i_energy": bal[3], "i_momentum": bal[4]}

    def diagnostics(self) -> dict[str, float]:
        t = self._totals()
        b_energy, b_mass, b_momentum = t["b_energy"], t["b_mass"], t["b_momentum"]
        e_scale = max(abs(self.energy0), abs(t["total_energy"]), abs(b_energy), 1e-300)
        e_err = (t["total_energy"] - self.energy0 - b_energy) / e_scale
        m_err = (t["mass"] - self.mass0 - b_mass) / max(abs(self.mass0), 1e-300)
        # scale: the gross momentum sum m |v| (the net may cancel, e.g. a symmetric problem)
        p_scale = max(np.linalg.norm(self.momentum0), np.linalg.norm(t["momentum"]),
                      np.linalg.norm(b_momentum), t["momentum_gross"], 1e-300)
        p_err = np.linalg.norm(t["momentum"] - self.momentum0 - b_momentum) / p_scale
        d = {"mass": t["mass"]}
        for c, name in enumerate("xyz"[: self.dim]):
            d[f"momentum_{name}"] = float(t["momentum"][c])
        d.update({
            "kinetic_energy": t["kinetic_energy"],
            "internal_energy": t["internal_energy"],
            "total_energy": t["total_energy"],
            "boundary_work": b_energy,
            "energy_balance_rel": float(e_err),
            "mass_balance_rel": float(m_err),
            "momentum_balance_rel": float(p_err),
        })
        if self.coupled:  # what crossed the coupled bodies' surfaces (part of the balances above)
            for c, name in enumerate("xyz"[: self.dim]):
                d[f"interface_momentum_{name}"] = float(t["i_momentum"][c])
            d["interface_energy"] = float(t["i_energy"])
        if self.mm is not None:  # per material: volume (void included) and mass
            d.update(self.mm.totals(self))
        return d

    def values_at(self, points: np.ndarray, quantities: list[tuple[str, int | None]]) -> np.ndarray:
        """The state of the zones holding ``points`` (global, (n, dim)) for each (quantity, component)
        pair (component: None for a scalar, 0..dim-1, or -1 for the magnitude; velocity: the mean of
        the zone's nodes), as the outputs hold it; collective: each value from the rank that owns its
        zone, the same array on every rank.  The grid is the fixed (eulerian) one."""
        from mpi4py import MPI

        B, dim = self.block, self.dim
        pts = np.asarray(points, dtype=np.float64).reshape(-1, dim)
        g = np.floor((pts - B.lower) / B.h).astype(np.int64)
        g = np.clip(g, 0, B.cells - 1)                # (a point on the upper face: its last zone)
        local = g - B.offset
        mine = np.all((local >= 0) & (local < B.n), axis=1)
        out = np.zeros(len(quantities) * len(pts))
        idx = np.zeros((len(pts), 3), np.int64)
        idx[:, :dim] = local + GHOST
        zone = (idx[:, 0] * B.zs[0] + idx[:, 1] * B.zs[1] + idx[:, 2] * B.zs[2])
        fields = {"density": self.rho, "pressure": self.p, "specific_internal_energy": self.e + self.de_h,
                  "sound_speed": self.c}
        corners = np.array(np.meshgrid(*[[0, 1]] * dim, indexing="ij")).reshape(dim, -1).T
        for k, (q, comp) in enumerate(quantities):
            for i in np.flatnonzero(mine):            # (a few probes: not a loop over zones)
                if q == "velocity":
                    nidx = idx[i, :dim] + corners
                    nodes = sum(nidx[:, d] * B.ns[d] for d in range(dim))
                    v = self.v[nodes].mean(axis=0)
                    val = float(np.linalg.norm(v)) if comp == -1 else float(v[comp])
                else:
                    val = float(fields[q][zone[i]])
                out[k * len(pts) + i] = val
        if self.dec.parallel:
            self.dec.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out.reshape(len(quantities), len(pts))

    def zone_field(self, a: np.ndarray) -> np.ndarray:
        """Real-zone values in output order (x fastest), shape (ne,) + a.shape[1:]."""
        return a[self.block.out_zones]

    def node_field(self, a: np.ndarray) -> np.ndarray:
        return a[self.block.out_nodes]

    def output(self):
        """(points (nn, 3), cells (ne, 4|8) VTK order, point_data, cell_data) on rank 0 (the whole
        grid in global order; None on the other ranks).  Collective."""
        B = self.block
        if self.dec.parallel:
            return self._output_parallel()
        pts = np.zeros((B.out_nodes.size, 3))
        pts[:, : self.dim] = self.x[B.out_nodes]
        vel = np.zeros_like(pts)
        vel[:, : self.dim] = self.v[B.out_nodes]
        cell_data = {
            "density": self.zone_field(self.rho).copy(),
            "pressure": self.zone_field(self.p).copy(),
            # at the time level of x, rho and p (the conserved e lags by half a step)
            "specific_internal_energy": self.zone_field(self.e + self.de_h).copy(),
            "sound_speed": self.zone_field(self.c).copy(),
            "artificial_viscosity": self.zone_field(self.q).copy(),
        }
        if self._blk is not None:
            cell_data["blocked_fraction"] = self.zone_field(self._blk.blocked_fraction()).copy()
        if self.mm is not None:
            for name, a in self.mm.cell_columns():
                cell_data[name] = self.zone_field(a).copy()
        return pts, B.connectivity(), {"velocity": vel}, cell_data

    def _gather_real(self, a: np.ndarray, nodes: bool):
        """Rank 0: the real zones (nodes) of ``a`` over the whole grid in output order (x fastest)."""
        B, dim = self.block, self.dim
        rng = B.nreal if nodes else B.zreal
        glo = np.zeros(3, np.int64)
        glo[:dim] = B.offset
        gshape = np.ones(3, np.int64)
        gshape[:dim] = B.cells + (1 if nodes else 0)
        g = self.dec.gather_box(a, B.ndims if nodes else B.zdims, rng[0], rng[1], glo, gshape)
        if g is None:
            return None
        return np.ascontiguousarray(g.transpose((2, 1, 0) + tuple(range(3, g.ndim)))).reshape((-1,) + a.shape[1:])

    def _output_parallel(self):
        dim = self.dim
        nodal = self._gather_real(np.concatenate([self.x, self.v], axis=1), True)
        cols = [self.rho, self.p, self.e + self.de_h, self.c, self.q]
        names = ("density", "pressure", "specific_internal_energy", "sound_speed", "artificial_viscosity")
        if self._blk is not None:
            cols.append(self._blk.blocked_fraction())
            names += ("blocked_fraction",)
        if self.mm is not None:
            for name, a in self.mm.cell_columns():
                cols.append(a)
                names += (name,)
        zonal = self._gather_real(np.stack(cols, axis=1), False)
        if self.dec.rank != 0:
            return None
        pts = np.zeros((nodal.shape[0], 3))
        pts[:, :dim] = nodal[:, :dim]
        vel = np.zeros_like(pts)
        vel[:, :dim] = nodal[:, dim:]
        cell_data = {name: zonal[:, i].copy() for i, name in enumerate(names)}
        if self._out_cells is None:
            self._out_cells = structured_cells(self.block.cells)
        return pts, self._out_cells, {"velocity": vel}, cell_data

    # ------------------------------------------------------------------------------------------
    # checkpoint / restart: the global padded arrays (the one-rank layout: cells + 4 zones, + 5
    # nodes per axis), assembled on rank 0 from every rank's share (its real zones/nodes, plus the
    # ghost layers of its physical faces); each rank reads back its window, whatever the rank count
    # (the same count continues bitwise).  Boundary terms of the balances are kept per rank.
    # ------------------------------------------------------------------------------------------
    ARRAYS = ("M", "e", "V", "rho", "p", "c", "q", "de_h", "fc", "x", "v", "v_old", "f", "m")
    SCALARS = ("step", "time", "dt", "dt_prev", "dt_avg", "first_step", "parity", "_pending_remap",
               "mass0", "energy0", "_dt_stable")
    VECTORS = ("momentum0",)

    def _checkpoint_arrays(self):
        """(name, array) of the state a restart needs; material arrays are (zones, materials); with
        blocked fractions the combined blocked fraction of every zone (static obstacles and the
        coupler's, blocked.py: the open fractions, apertures and wall nodes follow from it)."""
        out = [(k, getattr(self, k)) for k in self.ARRAYS]
        if self.mm is not None:
            out += [(f"material_{k}", getattr(self.mm, k)) for k in self.mm.FIELDS + ("pm", "cm")]
        if self._char is not None:  # the open faces' exterior states and corrections
            out.append(("open_face_state", self._char.state_array()))
        if self._blk is not None:
            out.append(("blocked_fraction", self._blk.b))
            if self._blk.A_body is not None:  # (the small cut zones' merged state: blocked.py)
                out.append(("small_cut_state", self._blk.small_state_array()))
        return out

    def _layout(self, a: np.ndarray):
        """(nodes?, padded local dims) of a zone- or node-shaped array."""
        B = self.block
        nodes = a.shape[0] == B.nnodes
        return nodes, tuple(B.ndims if nodes else B.zdims)

    def _share(self, nodes: bool):
        """This rank's box [lo, hi) of the global padded array, its global corner and the global shape."""
        B, dim = self.block, self.dim
        lo = np.zeros(3, np.int64)
        hi = np.array(B.ndims if nodes else B.zdims, np.int64)
        for d in range(dim):
            if B.face[d, 0] == CUT:
                lo[d] = GHOST
            if B.face[d, 1] == CUT:
                hi[d] = int(B.n3[d]) + GHOST
        glo = lo.copy()
        glo[:dim] += B.offset
        gshape = np.ones(3, np.int64)
        gshape[:dim] = B.cells + 2 * GHOST + (1 if nodes else 0)
        return lo, hi, glo, gshape

    def checkpoint(self, path) -> None:
        """Collective; rank 0 writes ``path`` (under a temporary name, then moved into place)."""
        dec = self.dec
        path = Path(path)
        data = {}
        for k, a in self._checkpoint_arrays():
            nodes, layout = self._layout(a)
            if dec.parallel:
                data[k] = dec.gather_box(a, layout, *self._share(nodes))
            else:
                data[k] = a.reshape(layout + a.shape[1:])
        bal = np.concatenate([[self.b_mass, self.b_energy], self.b_momentum, [self.i_energy], self.i_momentum])
        rows = bal[None, :]
        if dec.parallel:
            rows = np.empty((dec.size, bal.size)) if dec.rank == 0 else None
            dec.comm.Gather(bal, rows, root=0)
        if dec.rank == 0:
            tmp = Path(f"{path}.{os.getpid()}.tmp")
            with h5py.File(tmp, "w") as h:
                for k, a in data.items():
                    h.create_dataset(k, data=a)
                for k in self.VECTORS:
                    h.create_dataset(k, data=getattr(self, k))
                h.create_dataset("balances", data=rows)  # per rank: b_mass, b_energy, b_momentum
                for k in self.SCALARS:
                    h.attrs[k] = getattr(self, k)
                h.attrs["cells"] = self.block.cells
                h.attrs["mode"] = self.mode
                h.attrs["ranks"] = dec.size
            os.replace(tmp, path)
        if dec.parallel:
            dec.comm.Barrier()  # the file exists when checkpoint returns on any rank

    def restart(self, path) -> None:
        """Collective (with blocked fractions: their ghost fills)."""
        B, dec = self.block, self.dec
        o = np.zeros(3, np.int64)
        o[: self.dim] = B.offset

        def window(h, k, a):  # this rank's padded block of the global array k, into a
            _, n = self._layout(a)
            a[...] = h[k][o[0]:o[0] + n[0], o[1]:o[1] + n[1], o[2]:o[2] + n[2]].reshape(a.shape)
            return a

        with h5py.File(path, "r") as h:
            if not np.array_equal(h.attrs["cells"], self.block.cells):
                raise ValueError(f"checkpoint {path} is for a grid of {list(h.attrs['cells'])} cells")
            for k, a in self._checkpoint_arrays():
                if k == "open_face_state":
                    self._char.set_state_array(window(h, k, a))
                elif k not in ("blocked_fraction", "small_cut_state"):
                    window(h, k, a)
            # blocked fractions (static obstacles and coupler) of the checkpointed state, if any
            b = window(h, "blocked_fraction", np.zeros(B.nzones)) if "blocked_fraction" in h else None
            small = window(h, "small_cut_state", np.zeros((B.nzones, 2))) if "small_cut_state" in h else None
            for k in self.VECTORS:
                setattr(self, k, h[k][...].copy())
            for k in self.SCALARS:
                val = h.attrs[k]
                setattr(self, k, val.item() if hasattr(val, "item") else val)
            rows = h["balances"][...]
        if rows.shape[0] == dec.size:
            mine = rows[dec.rank]
        else:  # another rank count: rank 0 carries the boundary terms so far
            mine = rows.sum(axis=0) if dec.rank == 0 else np.zeros(rows.shape[1])
        dim = self.dim
        self.b_mass, self.b_energy = float(mine[0]), float(mine[1])
        self.b_momentum = mine[2:2 + dim].copy()
        if mine.size > 2 + dim:  # (checkpoints before the coupling carry no interface terms)
            self.i_energy = float(mine[2 + dim])
            self.i_momentum = mine[3 + dim:3 + 2 * dim].copy()
        self.step = int(self.step)
        self.parity = int(self.parity)
        self.first_step = bool(self.first_step)
        self._pending_remap = bool(self._pending_remap)
        if b is not None:
            if self._blk is None:  # fractions from the coupler alone (remap(blocked=...))
                from solvers.ale.blocked import Blocked
                self._blk = Blocked(self)
            self._blk.set_fractions(self, b)
            if small is not None:
                self._blk.set_small_state(small)
