"""Blocked volume fractions in the Eulerian ALE solver: static obstacles and (later) coupled bodies.

A zone z has a blocked volume fraction ``b_z`` in [0, 1] (from the case's ``obstacles`` and/or the
coupler's per-zone fractions) and an *open fraction* ``phi_z = 1 - b_z``; ``b_z >= 1 - 1e-12`` is a
*fully blocked* (solid) zone with ``phi_z = 0``.  The fluid occupies the open volume ``phi_z V_z``:
the density is ``rho = M / (phi V)`` and a solid zone holds no material (``M = 0`` exactly).

Model (a porous / face-aperture discretisation of the same staggered scheme)
---------------------------------------------------------------------------
* **Face apertures.**  The face between zones l and r is open over the fraction
  ``A_f = min(phi_l, phi_r)`` (the simple model of the issue: never more open than the more blocked
  side, so a face of a solid zone is closed).  ``A_f <= phi`` on both sides keeps small cut zones
  stable: their stiffness ``~ A^2 / phi`` and their remap Courant number ``~ A / phi`` never exceed
  those of an open zone.
* **Forces.**  In Eulerian mode the forces are computed on the fixed Cartesian grid, where the
  component d of a corner vector ``b_c = dV/dx_c`` comes from the zone's lower or upper d-face
  only.  The open-volume gradient is ``b^A_c[d] = A_f(c, d) b_c[d]`` and the corner force is
  ``f_c = (p + q) b^A_c + phi f_hg,c`` (the Flanagan-Belytschko hourglass force scaled by the open
  fraction).  Across a face both zones see the same aperture, so a uniform pressure exerts no
  force anywhere; ``sum_c b^A_c != 0`` in a cut zone is the pressure of the obstacle surface in it,
  i.e. the obstacle's reaction on the fluid (added to the momentum balance like a wall reaction).
  The artificial viscosity is of the solver's kind and acts where
  ``div v = sum_c v_c . b^A_c / (phi V) < 0``: scalar, ``q = rho (C_q l^2 (div v)^2 + C_l l c |div v|)``
  with that divergence; monotonic (hydro.py), from the zone's directional strain rates and its
  neighbours' (the same pre-pass over the fixed grid as every zone), a solid neighbour counting
  as a wall ghost, i.e. the zone's mirror image with its own strain rate (as the ghost zone of a
  conforming wall; the solid zone's own nodes, at rest, would give it the full q).
* **Lagrangian open volume and remap.**  ``V_open^lag = phi V + sum_d (A SV_d[z + s_d] - A SV_d[z])``
  (``SV`` the geometric swept volumes of the faces, remap.py), i.e. the open-volume change is
  exactly the one whose gradient gives the forces, so the compatible energy update is the PdV work
  of the open volume.  The remap is the conservative second-order sweep of remap.py with the
  aperture-scaled swept volumes ``A SV`` as face volumes: a closed face (solid neighbour) moves
  nothing, ``M' = M + F_lo - F_hi`` and ``V'_open = phi V`` after the sweeps, a uniform density stays
  uniform.  The limited slopes treat a solid neighbour as a reflecting wall ghost: zone fields are
  copied (zero slope), nodal velocities mirrored (normal component reversed) -- exactly the ghost
  fills of a conforming wall (boundary.py).  Dual (nodal) fluxes are built from the zone fluxes as
  before; a node with no mass (inside an obstacle) keeps v = 0, and the DeBar kinetic-energy defect
  goes only to zones with material.
* **Immersed walls.**  A real node all of whose zones on one side along d (the 2^(dim-1) zones
  with offset 0, or those with offset 1) are solid gets its d-velocity zeroed after the predictor,
  like a conforming wall node (boundary.constrain: the reaction impulse and its work enter the
  balances); a node with only solid zones around it has v = 0.  A node at a convex obstacle corner
  (solid zones on no whole side) is free, as on a conforming L-shaped grid.  With the obstacle on
  zone faces the nodal masses (solid zones carry none), forces, fluxes and limiters are those of a
  conforming grid ending at the obstacle with a reflecting wall: the runs are bitwise equal until
  waves reach the wall.  One detail differs afterwards: the conforming wall node receives the
  pressure force of its zone and the constraint removes it again (together with the normal velocity
  the nodal remap gave it, on which that force does work), whereas the closed face of the immersed
  wall exerts no force (tests/solvers/ale/test_blocked.py: 5e-4 L1 difference after a reflection).
* **Conservation.**  Mass and total (kinetic + internal) energy are conserved to round-off (the
  compatible update conserves them for any corner forces; the remap is conservative); momentum up
  to the obstacle's reaction, which the balance records (``dt_avg sum_z sum_c f_zc`` over the
  zones with a closed or partly open face, plus the wall-like node constraints).

Fractions that change between remaps (coupled bodies): the Lagrange step and the Lagrangian open
volumes use the fractions of the state; the remap brings the material onto the new open volumes
``phi_new V`` (density ``M / (phi_new V)``).  A zone that becomes fully blocked while it still
holds material is an error unless it can pass it to a neighbour (the small-zone merge, merge.py); a
zone a body uncovers within the step has its faces closed in that step's remap and would start
empty: it takes its share of a neighbour's gas in the merge instead.  The remap's face volumes take
the apertures at mid-step where a surface stays inside the face over the step
(``mid_face_volumes``: the open part the gas crosses varies linearly there), so the remap brings a
cut zone onto its new open volume, not the old plus the surface's swept volume.  The coupler's
fractions (``AleSolver.remap(blocked)``: one value per zone of the whole grid, output order)
combine with the static obstacles by the larger value.
The cut zones of a coupled body whose surface stood still over the step (one material; the
switch is per zone, from the surface velocities of ``body_terms``, and collective) remap differently
in two ways (``remap``): (1) every
sweep takes the fluxes through their faces from the Lagrangian state (``cut_face_fluxes``), not
from the state the previous sweep left -- the split sweeps pass a sliver through intermediate
states its open faces alone decide, off by O(1) of its density (7.7e-3 of the flow speed in
uniform flow along a wall inclined 30 degrees, exact to round-off with this); (2) their corner
nodes, and those nodes' copies in the ghost layers, hold their velocity through the sweeps and
take the momentum the dual fluxes brought at the end (``finish_held_nodes``), since their mass may
pass through zero in between; a held node whose inflow exceeds the mass it ends with (no convex
update: its deviation would grow by that ratio every step) shares one velocity with its heaviest
neighbour (``light_node_targets``, ``merge_light_nodes``).  A moving surface's cut zones keep the
split sweeps (with the unsplit fluxes the prescribed piston's p* error grew from 7e-6 to 7e-3 and
the closed box lost positivity: not understood yet).
The combined fraction is checkpointed (``AleSolver.checkpoint``: dataset ``blocked_fraction``)
and restart sets it again (creating the Blocked object if only the coupler's fractions made one):
the open fractions, apertures, solid flags and wall nodes follow from it, so a restart continues
bitwise.

Static obstacles (``[ale] obstacles = [{region = "x > 0.75", subsamples = k}]``): the region
(boolean expression in x, y[, z]) is evaluated on a k^dim sub-grid of points per zone (points at
the centres of the k^dim sub-cells; k = 1: the zone centre), b = fraction of points inside; several
obstacles combine by the largest fraction per zone (obstacles sharing a cut zone are not merged).

Obstacles should not cut open (outflow/inflow) boundary faces: the ghost zones there are not
aperture-scaled.  Only Eulerian mode supports blocked fractions.
"""
from __future__ import annotations

import numpy as np

from solvers.expressions import compile_expression
from solvers.ale.boundary import constrain as _constrain_kernel
from solvers.ale.grid import GHOST
from solvers.ale.points import subcell_offsets
from solvers.ale.hydro import BAD_STATE, BAD_VOLUME
from solvers.ale.merge import (PHI_MERGE, _group_sums, group_components, group_material_totals, group_totals,
                               member_materials, merge_members, merge_nodes, merge_targets, merge_velocities,
                               opened_zones, zone_gids)
from solvers.ale.cut_zone_kernels import (apertures_2d, apertures_3d,
                                         body_apertures, cap_cut_outflow, copy_cut_face_fluxes, corner_force_sum,
                                         cut_face_fluxes, finish_held_nodes, lagrangian_open_volumes,
                                         light_node_targets, merge_light_nodes, mid_face_volumes, open_eos,
                                         open_fractions)
from solvers.ale.mixed import fit_open_volumes
from solvers.ale.remap import set_positions
from solvers.sorted_ids import sorted_unique

SOLID_TOL = 1e-12
"""A zone with blocked fraction b >= 1 - SOLID_TOL is fully blocked (open fraction exactly 0)."""



# ------------------------------------------------------------------------------------------------
# fractions
# ------------------------------------------------------------------------------------------------
def obstacle_fractions(block, obstacles) -> np.ndarray:
    """Blocked fraction (nzones,) of the real zones from the static obstacles (ghosts 0)."""
    dim = block.dim
    real = np.flatnonzero(block.real_zone)
    centres = block.zone_centres()[real]
    names = ("x", "y", "z")[:dim]
    b = np.zeros(block.nzones)
    for ob in obstacles or []:
        fn = compile_expression(ob["region"], names=names, kind="boolean")
        k = int(ob.get("subsamples", 1))
        if k < 1:
            raise ValueError(f"obstacle subsamples must be >= 1, got {k}")
        inside = np.zeros(real.size)
        for off in subcell_offsets(k, block.h):  # one sub-cell centre of every zone at a time
            pts = centres + off
            inside += np.broadcast_to(np.asarray(fn(*pts.T), dtype=bool), (real.size,))
        b[real] = np.maximum(b[real], inside / k ** dim)
    return b


class Blocked:
    """Open fractions, face apertures and immersed-wall nodes of a solver's block."""

    def __init__(self, solver, obstacles=None):
        s = solver
        B = s.block
        self.dim = B.dim
        self.b_static = obstacle_fractions(B, obstacles)
        self.phi = np.ones(B.nzones)
        self.solid = np.zeros(B.nzones, np.uint8)
        self.A = np.ones((B.dim, B.nzones))
        self.touched = np.zeros(0, np.int64)
        self.wall_nodes = np.zeros(0, np.int64)
        self.wall_comp = np.zeros(0, np.int64)
        self._wall_vel = np.zeros(0)  # immersed walls are at rest (normal velocity 0)
        self.VE = s.V.copy()  # geometric volumes of the fixed grid (initial_state sets them at start-up)
        self._real = B.real_zone.astype(np.uint8)
        self.ASV = np.zeros((B.dim, B.nzones))
        self._no_inflow = (np.zeros(0, np.int64), np.zeros((0, B.dim)))
        self._R = np.zeros(B.dim)
        # coupled bodies (the coupler's BodyGeometry, solvers/ale/coupled.py): exact face apertures
        # (None: apertures from the fractions by the min model), the cut zones of this block that
        # carry a body surface (local index, row in the coupler's list) and their surface terms
        self.A_body = None
        self.cut = np.zeros(0, np.int64)
        self.cut_rows = np.zeros(0, np.int64)
        self.n_cut = 0
        self.b_bodies = np.zeros(B.nzones)  # the bodies' fractions, ghost layers included
        # entries of the face arrays that are faces of this block (entry z of direction d: the lower
        # d-face of zone z; the upper block face is a ghost zone's entry) and the zones a small zone
        # of this block's groups may lie in (real zones and the first ghost layer)
        pad = np.indices(B.zdims).reshape(3, -1)
        self._face_ok = np.zeros((B.dim, B.nzones), np.uint8)
        for d in range(B.dim):
            ok = np.ones(B.nzones, bool)
            for e in range(B.dim):
                ok &= (pad[e] >= GHOST) & (pad[e] < GHOST + B.n[e] + (1 if e == d else 0))
            self._face_ok[d] = ok
        self._layer1 = np.all([(pad[e] >= GHOST - 1) & (pad[e] < GHOST + B.n[e] + 1) for e in range(B.dim)], axis=0)
        # zones a small zone may merge into: real zones and images of the neighbours' (not the
        # ghosts of physical boundaries)
        from solvers.ale.grid import Z_IMAGE, Z_REAL
        self._usable = ((B.zkind == Z_REAL) | (B.zkind == Z_IMAGE)).astype(np.uint8)
        self._gper = np.zeros(3, np.uint8)  # periodic axes of the whole grid (merge group ids wrap)
        self._gper[: B.dim] = B.periodic
        self.SF = np.zeros(B.nzones)  # a_e . (surface velocity) of the cut zones (their q)
        self._cut_velocity = np.zeros((0, B.dim))
        self._lag, self._lag_on = None, False  # (the Lagrangian state of the remap: cut_face_fluxes)
        self._hold, self.hold = None, None  # (the held nodes of the remap: _hold_nodes)
        self._cutf, self._cutz = None, np.zeros(0, np.int64)  # (cut flags with their ghost images)
        self._near_real = None
        self._still = self._static = np.zeros(0, np.int64)  # (cut zones of a surface at rest: body_terms)
        self._FX = self._EX = None  # (their faces' fluxes and face energies per direction: cut_face_fluxes)
        self._small = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))  # (small cut zones' merged state)
        self.SB = np.zeros(B.nzones)  # body-surface swept volume of the Lagrange step (cut zones)
        self._sb_zones = np.zeros(0, np.int64)
        self.nodes = (np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, bool))
        self.set_fractions(s, self.b_static)

    # ---- fractions -----------------------------------------------------------------------------
    def combined(self, s, geometry) -> np.ndarray:
        """max(static, bodies) blocked fraction (nzones,) of the coupler's ``geometry``
        (solvers/ale/coupled.BodyGeometry: global ids and values of the zones the bodies cut, runs
        of the zones they cover whole, the same on every rank); also takes the geometry's exact face
        apertures and cut zones.  Work: the listed zones and faces, the runs' zones of this block,
        and one pass over the block's faces (no per-zone list of the bodies' interior)."""
        B = s.block
        if geometry is None:
            return self.b_static
        from solvers.ale.coupled import GlobalIndex

        gi = GlobalIndex(B)
        f = np.asarray(geometry.fractions, dtype=np.float64)
        bad = ~(np.isfinite(f) & (f >= 0.0) & (f <= 1.0))
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            ijk = tuple(int(v) for v in gi._split(geometry.zones[k:k + 1], gi.cells)[0, : B.dim])
            raise ValueError(f"blocked fraction {f[k]!r} of ALE zone {ijk} is not in [0, 1]")
        # the bodies' fractions on the padded block, ghost layers included (the small-zone merge sees
        # the groups of the first ghost layer; the faces of the block's edge see both zones)
        b = gi.runs(geometry.run_start, geometry.run_length)
        z, held = gi.zones(geometry.zones, ghosts=GHOST)
        b[z[held]] = f[held]
        # ghost layers like a zone field: a periodic image holds its zone's fraction (the small-zone
        # merge must see a group across a periodic face from both sides, or the mass it moves into
        # the image is lost); an open face's ghosts continue the body through the face (the face
        # between two zones it covers whole closes)
        s.bc.fill_zones([b])
        self.b_bodies = b
        cut = np.zeros(0, np.int64) if geometry.cut is None else geometry.cut
        cz, cm = gi.zones(cut)
        self.cut = np.ascontiguousarray(cz[cm])
        # the real zones the lists name (partly covered, cut, either side of a listed face): the
        # only ones besides the wholly covered where a body changes a fraction or an aperture
        named = [z[held], self.cut]
        if geometry.faces is not None:
            self._static_parts(s)
            # exact apertures: closed between two zones covered whole, the listed faces' values,
            # open elsewhere; with the static obstacles' min-model ones (the smaller of the two)
            A = np.empty((B.dim, B.nzones))
            body_apertures(b, self._face_ok, self._A_static, np.asarray(B.zs, np.int64), A)
            for d, (ids, cov) in enumerate(geometry.faces):
                fz, fm = gi.faces(d, ids)
                fz = fz[fm]
                a = np.minimum(self._A_static[d, fz], np.clip(1.0 - np.asarray(cov)[fm], 0.0, 1.0))
                # a face of a zone the bodies cover whole (b >= 1 - SOLID_TOL: phi 0, no material) is
                # closed, though the clipping may leave its coverage short of 1 by round-off or a
                # sliver: open by 1e-9 it let gas into the covered zone, which the nodes' dual
                # fluxes do not see (momentum lost: 5e-12 of it in one step of a block carried by
                # the flow, its faces 1e-9 off the grid lines)
                a[(b[fz] >= 1.0 - SOLID_TOL) | (b[fz - B.zs[d]] >= 1.0 - SOLID_TOL)] = 0.0
                A[d, fz] = a
                named += [fz, fz - B.zs[d]]
            self.A_body = A
        else:
            self.A_body = None
        c = sorted_unique(np.concatenate(named))
        self._body_cand = c[B.real_zone[c]]
        self.cut_rows = np.flatnonzero(cm)
        self.n_cut = int(cut.size)
        vel = geometry.velocity if geometry.velocity is not None else np.zeros((cut.size, B.dim))
        self._cut_velocity = np.asarray(vel).reshape(-1, B.dim)[cm]
        nodes = np.zeros(0, np.int64) if geometry.nodes is None else geometry.nodes
        self.nodes = gi.nodes(nodes)  # (local index, real here, owned here) of the requested nodes
        # the real zones' fractions (ghosts 0) with the static obstacles' (the larger)
        if not hasattr(self, "_real_f"):
            self._real_f = B.real_zone.astype(np.float64)
            self._has_static = bool(np.any(self.b_static > 0.0))
        out = np.multiply(b, self._real_f)
        if self._has_static:
            np.maximum(out, self.b_static, out=out)
        return out

    # ---- coupled bodies: the interface of the Lagrange step --------------------------------------
    def cut_forces(self, s) -> np.ndarray:
        """(nc_local, dim) net corner force sum_c f_c of this block's cut zones (time n): with exact
        apertures sum_c b^A_c = the zone's body-surface area vector a_e (discrete divergence
        theorem), so this is the fluid's reaction (p + q) a_e (+ hourglass, summing to ~0): the body
        gets exactly minus it (momentum exact)."""
        return s.fc[self.cut].sum(axis=1)

    def surface_vectors(self, s) -> np.ndarray:
        """(nc_local, dim) a_e = sum_c b^A_c of the cut zones from the apertures on the fixed grid
        (Eulerian: the Lagrange step starts from it): a_e[d] = (h^{dim-1}/h_d) (A_hi,d - A_lo,d)."""
        B = s.block
        out = np.empty((self.cut.size, self.dim))
        vol = float(np.prod(B.h))
        for d in range(self.dim):
            out[:, d] = (vol / B.h[d]) * (self.A[d, self.cut + B.zs[d]] - self.A[d, self.cut])
        return out

    def body_terms(self, s, v_half, v_bar) -> np.ndarray:
        """The body surface in the cut zones' Lagrange step (after the compatible energy update):
        internal energy M de = dt_avg R . vbar (the work of the fluid's reaction R on the surface
        moving at vbar = (v^{n-1/2} + v^{n+1/2})/2 of the body: exactly the work of -R on the body,
        whose impulse is -dt_avg R), and the surface's swept volume SB = -dt a_e . v^{n+1/2}
        (volume gradient -a_e of the open region w.r.t. the surface position) for the Lagrangian
        open volume; ``v_half``, ``v_bar`` (nc_local, dim).  Returns [momentum (dim), energy] that
        crossed into the fluid (this rank's zones)."""
        z = self.cut
        R = self.cut_forces(s)
        work = np.einsum("ij,ij->i", R, v_bar)
        M = s.M[z]
        s.e[z] += np.where(M > 0.0, s.dt_avg * work / np.where(M > 0.0, M, 1.0), 0.0)
        self.SB[z] = -s.dt * np.einsum("ij,ij->i", self.surface_vectors(s), v_half)
        self._sb_zones = z
        # the cut zones whose body surface stood still over the step (remap: unsplit fluxes there)
        self._still = z[~(np.any(v_half != 0.0, axis=1) | np.any(v_bar != 0.0, axis=1))]
        return np.concatenate([s.dt_avg * R.sum(axis=0), [s.dt_avg * float(work.sum())]])

    def set_fractions(self, s, b) -> None:
        """Open fractions (ghosts filled like zone fields), solid flags, apertures, cut zones and
        immersed-wall nodes from the blocked fraction b of the real zones."""
        B, dim = s.block, self.dim
        if self.A_body is None:
            phi = np.where(b >= 1.0 - SOLID_TOL, 0.0, 1.0 - b)
            phi[~B.real_zone] = 1.0
            self.b = np.where(B.real_zone, b, 0.0)  # (checkpointed: the rest follows from it)
            n_open = float(np.count_nonzero(phi[B.real_zone] > 0.0))
        else:  # (one pass: phi, b of the real zones, solid flags, open zones)
            phi, self.b, n_open = open_fractions(b, self._real, SOLID_TOL)
        s.bc.fill_zones([phi])
        n_open = np.array([n_open])
        dec = getattr(s, "dec", None)
        if dec is not None and dec.parallel:
            n_open = dec.sum(n_open)
        if n_open[0] == 0.0:
            raise ValueError("the obstacles block every zone of the ALE grid")
        self.phi = phi
        self._vopen = None
        self.solid = (phi <= 0.0).astype(np.uint8)
        if self.A_body is None:
            # min-model apertures of the fractions
            self.A = self._min_apertures(s, phi)
            self.touched = self._touched(s, phi < 1.0, self.A)
            self.is_cut = np.zeros(B.nzones, np.uint8)
            self.is_cut[self.cut] = 1
            self.SF[:] = 0.0
            self._wall_nodes(s)
        else:
            # a coupled body's exact face apertures with the static obstacles' (combined); what
            # depends on the static obstacles alone is computed once (_static_parts)
            self.A = self.A_body
            # zones whose forces need the aperture correction near the bodies: among the zones
            # the coupler lists (cut, partly covered, next to a listed face), those with phi < 1
            # or a closed face (a zone a body covers whole has no material and needs none)
            c = self._body_cand
            near = phi[c] < 1.0
            for d in range(dim):
                near |= (self.A[d, c] < 1.0) | (self.A[d, c + B.zs[d]] < 1.0)
            self.touched = (np.union1d(self._touched_static_all, c[near]).astype(np.int64)
                            if self._touched_static_all.size else c[near])
            self.is_cut[self._prev_cut] = 0  # (the previous step's cut zones: the flags are sparse)
            self.is_cut[self.cut] = 1
            self.SF[self._prev_cut] = 0.0
            self._prev_cut = self.cut
        # the reaction of the static obstacles only: a cut zone's is the body's load (coupler)
        self.touched_static = np.ascontiguousarray(self.touched[self.is_cut[self.touched] == 0])
        if self.cut.size:
            self.SF[self.cut] = np.einsum("ij,ij->i", self.surface_vectors(s), self._cut_velocity)

    def _static_parts(self, s) -> None:
        """What the static obstacles alone decide, computed once for the coupled steps: their
        min-model apertures, the zones those touch, the immersed-wall nodes (a coupled body moves:
        the constraint ties the nodes of its cut zones instead), the real-zone mask."""
        if hasattr(self, "_A_static"):
            return
        B = s.block
        ps = self._static_phi(s)
        self._A_static = self._min_apertures(s, ps)
        self._touched_static_all = self._touched(s, ps < 1.0, self._A_static)
        self._wall_nodes(s)
        self.is_cut = np.zeros(B.nzones, np.uint8)
        self._prev_cut = np.zeros(0, np.int64)

    def _min_apertures(self, s, phi) -> np.ndarray:
        """Min-model face apertures: a face is as open as the less open of its two zones."""
        B = s.block
        A = np.ones((self.dim, B.nzones))
        pv = B.zview(phi)
        for d in range(self.dim):
            av = B.zview(A[d])
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[d] = slice(0, B.zdims[d] - 1)
            hi[d] = slice(1, B.zdims[d])
            av[tuple(hi)] = np.minimum(pv[tuple(lo)], pv[tuple(hi)])
        return A

    def _touched(self, s, partial, A) -> np.ndarray:
        """Real zones that are partly blocked or have a closed face (the aperture correction's)."""
        B = s.block
        t = partial.copy()
        for d in range(self.dim):
            up = np.roll(A[d], -int(B.zs[d]))
            t |= (A[d] < 1.0) | (up < 1.0)
        t &= B.real_zone
        return np.flatnonzero(t).astype(np.int64)

    def _static_phi(self, s) -> np.ndarray:
        B = s.block
        ps = np.where(self.b_static >= 1.0 - SOLID_TOL, 0.0, 1.0 - self.b_static)
        ps[~B.real_zone] = 1.0
        s.bc.fill_zones([ps])
        return ps

    def _wall_nodes(self, s) -> None:
        B, dim = s.block, self.dim
        # immersed walls at rest: the static obstacles' (a coupled body moves: the constraint ties
        # the nodes of its cut zones instead)
        solid = self.solid.astype(bool) if self.A_body is None else self._static_phi(s) <= 0.0
        sol = B.zview(solid)
        lo, hi = B.nreal
        # zones around node (i, j, k): (i - 1 + o0, j - 1 + o1, k - 1 + o2)
        around = {}
        for o in np.ndindex(*([2] * dim)):
            sl = tuple(slice(int(lo[d]) - 1 + o[d], int(hi[d]) - 1 + o[d]) if d < dim else slice(None)
                       for d in range(3))
            around[o] = sol[sl]
        all_solid = np.logical_and.reduce(list(around.values()))
        ids = np.arange(B.nnodes).reshape(B.ndims)[tuple(slice(int(a), int(b)) for a, b in zip(lo, hi))]
        nodes, comps = [], []
        for d in range(dim):
            side = [np.logical_and.reduce([a for o, a in around.items() if o[d] == v]) for v in (0, 1)]
            sel = side[0] | side[1] | all_solid
            nodes.append(ids[sel])
            comps.append(np.full(int(sel.sum()), d, np.int64))
        self.wall_nodes = np.ascontiguousarray(np.concatenate(nodes), dtype=np.int64)
        self.wall_comp = np.ascontiguousarray(np.concatenate(comps), dtype=np.int64)
        self._wall_vel = np.zeros(self.wall_nodes.size)

    # ---- solver hooks ---------------------------------------------------------------------------
    def initial_state(self, s) -> None:
        """After the initial geometry: V is the geometric zone volume; M = rho phi V; solid zones
        get no material and no state."""
        self.VE = s.V.copy()
        self._vopen = None
        real = s.block.real_zone
        s.M[real] *= self.phi[real]
        sol = self.solid.astype(bool)
        s.M[sol] = 0.0
        s.rho[sol] = 0.0
        s.e[sol] = 0.0

    def initial_state_mixed(self, s) -> None:
        """Several materials (mixed.py), after their initial volumes and masses on the whole zone
        volume V = VE: every material's volume and mass scaled by the open fraction (densities and
        the relaxed pressures unchanged); solid zones get no material and no state."""
        self.VE = s.V.copy()
        self._vopen = None
        mm, real = s.mm, s.block.real_zone
        mm.vol[real] *= self.phi[real, None]
        mm.mass[real] *= self.phi[real, None]
        sol = self.solid.astype(bool) & real
        mm.vol[sol] = 0.0
        mm.mass[sol] = 0.0
        mm.ener[sol] = 0.0
        s.M[real] = mm.mass[real].sum(axis=1)
        s.e[sol] = 0.0
        s.rho[real] = np.divide(s.M[real], self.phi[real] * self.VE[real], out=np.zeros(int(real.sum())),
                                where=self.phi[real] > 0.0)

    def open_volumes(self) -> np.ndarray:
        """phi VE of every zone (several materials: their volumes' sum), kept until the fractions or
        the zone volumes change."""
        if self._vopen is None:
            self._vopen = self.phi * self.VE
        return self._vopen

    def eos(self, s) -> None:
        """rho = M / (phi V), EOS at e + de_h of the real zones (massless zones: no state); several
        materials: their states on the open volumes (mixed.Materials.update_eos)."""
        if s._initialising:
            sol = self.solid.astype(bool) & s.block.real_zone
            if np.any(s.e[sol] != 0.0):
                z = int(np.flatnonzero(sol & (s.e != 0.0))[0])
                raise ValueError(f"an energy source lies in the fully blocked ALE zone {s.block.zone_ijk(z)}")
        if s.mm is not None:
            s.mm.update_eos(s, V=self.open_volumes())
            s.q[s.M == 0.0] = 0.0
            return
        bad = open_eos(s.eos_code, s.eos_par, s.M, s.e, s.de_h, self.phi, self.VE, s.rho, s.p, s.c, s.q,
                       s.zr[0], s.zr[1], s.block.zs)
        if bad >= 0:
            s._check((0.0, bad, BAD_STATE))

    def apertures(self, s) -> tuple[float, int]:
        """Aperture correction of the corner forces and q of the cut zones (after the zone pass);
        returns their stable step and the zone that sets it (-1 if none)."""
        B = s.block
        k = apertures_3d if self.dim == 3 else apertures_2d
        dt, at = k(s.x, s.v, s.fc, s.M, s.rho, s.p, s.c, s.q, self.phi, self.A, self.SF, self.solid,
                   self.touched, B.zs, B.ns, s.q_lin, s.q_quad, s.q_kind, s.qgrad)
        return float(dt), int(at)

    def constrain(self, s, record: bool) -> None:
        """Immersed-wall node constraints into s._acc; when recording, the obstacle's pressure
        reaction dt_avg sum_cut zones sum_c f_c as well."""
        _constrain_kernel(s.v, s.v_old, s.m, s.block.owned, self._no_inflow[0], self._no_inflow[1],
                          self.wall_nodes, self.wall_comp, self._wall_vel, s._acc)
        if record:
            corner_force_sum(s.fc, self.touched_static, self._R)
            s._acc[: self.dim] += s.dt_avg * self._R

    # ---- remap ----------------------------------------------------------------------------------
    def remap(self, s, fractions=None) -> None:
        """The Eulerian remap with blocked fractions (AleSolver.remap with the open volumes);
        ``fractions`` (coupler, per zone, or None: the static obstacles only) apply to the remapped
        state (see the module docstring)."""
        B, dim = s.block, self.dim
        b_new = None if fractions is None else self.combined(s, fractions)
        for d in range(dim):
            lo, hi = s.zr[0].copy(), s.zr[1].copy()
            hi[d] += 1
            s._swept(B.X, s.x, s.SV[d], d, lo, hi, B.zs, B.ns)
            s.bc.fill_zones([s.SV[d]], face_dir=d)
            np.multiply(self.A[d], s.SV[d], out=self.ASV[d])
        bad = lagrangian_open_volumes(self.ASV, self.SB, self.is_cut, self.VE, self.phi, s.V, s.M, s.rho, s.p,
                                      s.q, s.de_h, s.zr[0], s.zr[1], B.zs, s.rho_ref)
        if bad >= 0:
            s._check((0.0, bad, BAD_VOLUME), " (Lagrangian grid)")
        if b_new is not None and self.A_body is not None and self.A_body is not self.A:
            # the remap's face volumes with the apertures at mid-step: the gas that crosses a fixed
            # face while a body's surface moves across it passes through the part open at each
            # instant, u dt h (A_old + A_new) / 2 for a surface in uniform motion; with the old
            # apertures alone the remap brings a cut zone onto phi_old V + SB, not onto the new open
            # volume phi_new V, and rho = M / (phi_new V) is off by the difference (6 % in a flow
            # that carries a body inclined 30 degrees along with it; 3.6 % with this).  Only where
            # the face is partly open at both ends of the step: a surface that enters or leaves a
            # face within the step makes its aperture a kink or a jump in time (the face parallel
            # to it), and there the old one stays (a zone uncovered so gets its gas in the merge).
            # The Lagrangian open volume above keeps the old ones: those of the forces (compatible
            # energy update).  Where no surface moved A_new = A_old and this is bitwise the same.
            mid_face_volumes(self.A, self.A_body, s.SV, self.ASV)
        # the cut zones of a body surface at rest over the step (body_terms): the unsplit fluxes and
        # held nodes below; a moving surface's cut zones keep the split sweeps and the small-zone
        # merge (with the unsplit fluxes there the prescribed piston's p* moved from 7e-6 to 7e-3
        # and the closed box lost positivity: not understood yet)
        self._static, self._still = self._still, self.cut[:0]
        if self._sb_zones.size:  # the body-surface volumes belong to this step only
            self.SB[self._sb_zones] = 0.0
            self._sb_zones = np.zeros(0, np.int64)
        _sync(s)
        if s.mm is not None:  # share the open volume's change over the materials (mixed.py)
            s.mm.lagrange_step(s)
            self._no_shift_in_swept_zones(s)
            s.mm.hold_shift()
        if s._char is not None:  # the exterior state the faces' motion makes: remap donors
            s._char.donors()
        s._fill_remap_zones()
        # the Lagrangian state, from which the faces of a body's cut zones take their fluxes in
        # every sweep (cut_face_fluxes)
        on = self.A_body is not None and s.mm is None and self._static.size > 0
        dec = getattr(s, "dec", None)
        if self.A_body is not None and s.mm is None and dec is not None and dec.parallel:
            on = bool(dec.sum(np.array([float(on)]))[0] > 0.0)  # (the path's ghost fills are collective)
        if on:
            if self._lag is None:
                self._lag = tuple(np.empty(B.nzones) for _ in range(4))
            for a, b in zip(self._lag, (s.rho, s.e, s.M, s.V)):
                np.copyto(a, b)
            # a small zone's fluxes carry the state it shares with its merge group (the end of the
            # last remap), not its Lagrangian one: its Lagrangian volume moves by O(1/phi) of itself
            # with its nodes, and so would the density its fluxes carry out (unstable)
            zs_, rs_, es_ = self._small
            self._lag[0][zs_] = rs_
            self._lag[1][zs_] = es_
            s.bc.fill_zones([self._lag[0], self._lag[1]])  # (a face's upwind zone may be a ghost)
            self._lag_on = True
            if self._FX is None:
                self._FX = np.zeros((dim, B.nzones))
                self._EX = np.zeros((dim, B.nzones))
            self._hold_nodes(s)  # (also the zones' flags with their ghost images: _cutz)
            rhoL, eL, ML, VL = self._lag
            for d in range(dim):  # (every face of a real zone a flagged zone has: the same on each rank)
                cut_face_fluxes(self._cutz, int(B.zs[d]), d, self.ASV, rhoL, eL, ML, VL, self.VE, self.solid,
                                self._FX[d], self._EX[d], B.zs, self._real)
            for _ in range(2):  # (capping a zone's outflow lowers its neighbours' inflow: twice)
                cap_cut_outflow(self._static, ML, self._FX, B.zs)
        else:
            self._lag_on = False
            self.hold = None
        order = range(dim) if s.parity == 0 else range(dim - 1, -1, -1)
        for d in order:
            s._sweep(d)  # (the remap kernels with this object's face volumes, solid flags, massless zones)
        if self._lag_on:  # the held nodes' velocities and kinetic-energy defects, once
            s.bc.fill_nodes_scalar(self._IN)  # (s.m: filled by the last sweep)
            light_node_targets(self._hn, self._IN, s.m, B.ns, dim, self._lcode)
            s.bc.fill_nodes_scalar(self._lcode)
            finish_held_nodes(self._hn, self._P, self._KF, s.m, s.v, self._vL, self._mL, s.e, s.M, self._lcode,
                              B.zs, B.ns)
            s.bc.fill_nodes_vector(s.v)
            s.bc.fill_nodes_scalar(self._KF)  # (a light node's kinetic energy in: merge_light_nodes)
            merge_light_nodes(self._hn_all, self._lcode, self._KF, s.m, s.v, s.e, s.M, B.real_node,
                              B.zs, B.ns, dim)
            s.bc.fill_nodes_vector(s.v)
            s.bc.fill_zones([s.e], s._inflow_values("energy"))
            if s._char is not None:
                s._char.apply_donors(energy_only=True)
            self.hold = None
        set_positions(s.x, B.X)
        if s.mm is not None:
            s.mm.spread_shift()
        if b_new is not None:
            self._apply_new_fractions(s, b_new)

        if s.mm is not None:  # the materials onto the (new) open volumes, then pressure relaxation
            fit_open_volumes(s.mm.vol, self.open_volumes(), self._real)
            s.mm.cut_off_vacuum(s)
            s.mm.relax_pressures(s)
        s.parity ^= 1
        s._pending_remap = False
        s._dt_stable = s._forces(midstep=False, advect=True, eos=True)
        if self.A_body is not None:  # the small cut zones' merged state (cut_face_fluxes, next step)
            c = self.cut
            small = c[(self.phi[c] > 0.0) & (self.phi[c] < PHI_MERGE)]
            self._small = (small, s.rho[small].copy(), s.e[small].copy())

    def small_state_array(self) -> np.ndarray:
        """(zones, 2): the small cut zones' merged density and specific energy (the end of the last
        remap: the next remap's fluxes through their faces carry it), NaN elsewhere (checkpoint)."""
        a = np.full((self.phi.size, 2), np.nan)
        z, r, e = self._small
        a[z, 0] = r
        a[z, 1] = e
        return a

    def set_small_state(self, a: np.ndarray) -> None:
        """The small cut zones' merged state from ``small_state_array`` (restart; real zones)."""
        z = np.flatnonzero(~np.isnan(a[:, 0]) & (self._real != 0))
        self._small = (z, a[z, 0].copy(), a[z, 1].copy())

    def _hold_nodes(self, s) -> None:
        """The corner nodes of the cut zones: their momentum update waits for the last sweep
        (remap.sweep_nodes ``hold``): with the cut zones' fluxes from the Lagrangian state a sliver's
        mass, and so its nodes', may pass through zero between the sweeps."""
        B = s.block
        if self._hold is None:
            self._hold = np.zeros(B.nnodes, np.uint8)
            self._P = np.zeros((B.nnodes, B.dim))
            self._KF = np.zeros(B.nnodes)
            self._IN = np.zeros(B.nnodes)
            self._lcode = np.full(B.nnodes, -1.0)
            self._hn = np.zeros(0, np.int64)
            self._hn_all = np.zeros(0, np.int64)
        self._hold[self._hn] = 0  # (the previous step's: the arrays are sparse)
        self._IN[self._hn] = 0.0
        self._lcode[self._hn_all] = -1.0
        # the cut zones with their images in the ghost layers (other ranks', periodic): every copy
        # of a node is held or none is
        if self._cutf is None:
            self._cutf = np.zeros(B.nzones)
        self._cutf[self._cutz] = 0.0
        self._cutf[self._static] = 1.0
        s.bc.fill_zones([self._cutf])
        if self._near_real is None:  # the real zones and their first ghost layer (faces and corner
            # nodes of these stay inside the padded arrays with their stencils)
            r = B.real_zone.reshape(B.zdims)
            near = r.copy()
            for d in range(B.dim):
                near[tuple(slice(1, None) if a == d else slice(None) for a in range(3))] |= \
                    r[tuple(slice(None, -1) if a == d else slice(None) for a in range(3))]
                near[tuple(slice(None, -1) if a == d else slice(None) for a in range(3))] |= \
                    r[tuple(slice(1, None) if a == d else slice(None) for a in range(3))]
            self._near_real = near.ravel()
            # (the first ghost layer: the fill writes there; the real zones are the flags we set)
            self._ghost_near = np.flatnonzero(self._near_real & (B.real_zone == 0))
        # sparse: the flagged real zones and the flagged zones of the first ghost layer, in
        # increasing order (as a whole-grid flatnonzero gave them), never a scan of the grid
        g = self._ghost_near
        self._cutz = np.union1d(self._static[B.real_zone[self._static] != 0], g[self._cutf[g] != 0.0])
        hn = np.unique((B._zone_to_node(self._cutz)[:, None] + B.corner_offsets()[None, :]).ravel())
        self._hn_all = hn  # (with the ghost copies: merge_light_nodes)
        hn = hn[B.real_node[hn]]
        self._hn = hn
        self._hold[hn] = 1
        self._vL = s.v[hn].copy()
        self._mL = s.m[hn].copy()
        self._P[hn] = 0.0
        self._KF[hn] = 0.0
        self._IN[hn] = 0.0
        self.hold = (self._hold, self._P, self._KF, self._IN)

    def cut_face_fluxes(self, s, d) -> None:
        """The fluxes of sweep d through the faces of a body's cut zones, from the Lagrangian state
        (kernel cut_face_fluxes): called by the solver's sweep after its own face fluxes."""
        if self._lag_on:
            copy_cut_face_fluxes(self._cutz, int(s.block.zs[d]), d, self._FX, self._EX, s.F, s.ES, self._real)

    def _no_shift_in_swept_zones(self, s) -> None:
        """Several materials: no half-step EOS shift in a body's cut zone (the zones flagged for
        lagrangian_open_volumes: the previous fractions' cut zones) whose open volume the step swept
        away (left at the sliver 1e-9 VE) or changed by more than half, as that kernel does for the
        zone's own shift."""
        z = getattr(self, "_prev_cut", None)
        if z is None or not z.size:
            return
        v0 = self.phi[z] * self.VE[z]
        vn = s.V[z]
        swept = vn <= 1e-9 * self.VE[z]
        s.mm.deh[z[swept | (np.abs(vn - v0) > 0.5 * v0)]] = 0.0

    def _apply_new_fractions(self, s, b_new) -> None:
        """Open fractions of the remapped state: rho = M / (phi_new V).  Collective (ghost fills)."""
        B = s.block
        if self.A_body is not None:  # a coupled body's exact geometry: small zones merge
            _sync(s)
            phi_old = self.phi
            self.set_fractions(s, b_new)
            # zones uncovered at once (an eroded element): they share with a neighbour (merge._is_donor)
            self._opened = np.empty(phi_old.size, np.uint8)
            opened_zones(phi_old, self.phi, PHI_MERGE, self._opened)
            gdims = np.ones(3, np.int64)
            gdims[: B.dim] = B.cells
            goff = np.zeros(3, np.int64)
            goff[: B.dim] = B.offset - GHOST
            if not hasattr(self, "_VE_uniform"):  # (the ghost layers' VE are placeholders; the
                # grid is uniform: every rank uses the same volume for a group's zones)
                self._VE_uniform = np.full(B.nzones, float(np.prod(B.h)))
            bad = self._merge(s, gdims, goff)
            if bad >= 0:
                s._fail(f"ALE zone {B.zone_ijk(bad)} is covered by a coupled body while it holds "
                        f"{s.M[bad]:.6g} kg of material and has no open neighbour to pass it to, at step "
                        f"{s.step}, t={s.time:.6g} s")
            _sync(s)
            return
        newly = (b_new >= 1.0 - SOLID_TOL) & B.real_zone & (s.M != 0.0)
        if np.any(newly):
            z = int(np.flatnonzero(newly)[0])
            msg = (f"ALE zone {B.zone_ijk(z)} became fully blocked while holding {s.M[z]:.6g} kg of "
                   f"material at step {s.step}, t={s.time:.6g} s")
            if not hasattr(s, "_fail"):
                from solvers.ale.errors import SolverError
                raise SolverError(msg)
            s._fail(msg)  # one rank: raises; parallel: raised on every rank by the _sync below
        _sync(s)
        self.set_fractions(s, b_new)

    def _merge(self, s, gdims, goff) -> int:
        """The small-zone merge (solvers/ale/merge.py): targets decided where the donors are real and
        handed to the ghost layers, group totals summed where the targets are real and handed out
        the same way, node sums by group over the ranks.  Collective (ghost fills, group sums).
        Returns -1, or a zone that cannot pass its content on."""
        B, dim = s.block, s.block.dim
        usable = self._usable
        code = np.full(B.nzones, -1.0)
        # candidates: real zones a body covers in part or whole that hold material, or are open
        # and empty, and those the step opened at once (merge._is_donor)
        cand = np.flatnonzero((((self.b_bodies > 0.0) & ((s.M != 0.0) | (self.phi > 0.0))) | (self._opened != 0))
                              & B.real_zone)
        bad = merge_targets(cand, s.M, self.phi, self.b_bodies, self._opened, usable, B.zs, dim, PHI_MERGE, code)
        dec = s.dec
        if not dec.parallel and not (code >= 0.0).any():
            return int(bad)
        zdims = np.array(B.zdims, np.int64)
        s.bc.fill_zones([code])
        code[usable == 0] = -1.0  # (the fills copy into the ghosts of physical faces: no zones of groups)
        donors = np.flatnonzero((code >= 0.0) & (usable != 0))
        donors = donors[np.argsort(zone_gids(donors, B.zs, gdims, goff, self._gper), kind="stable")]
        Mg, Eg, Vg = np.zeros(B.nzones), np.zeros(B.nzones), np.zeros(B.nzones)
        group_totals(donors, code, s.M, s.e, self.phi, self._VE_uniform, self._real, B.zs, zdims, Mg, Eg, Vg)
        s.bc.fill_zones([Mg, Eg, Vg])
        mm = s.mm
        if mm is not None:  # several materials: the groups' totals of every material too
            Vk, Mk, Ek = (np.zeros((B.nzones, mm.nm)) for _ in range(3))
            group_material_totals(donors, code, mm.vol, mm.mass, mm.ener, self._real, B.zs, zdims, Vk, Mk, Ek)
            s.bc.fill_zones([Vk, Mk, Ek])
        Vg[usable == 0] = 0.0
        member = ((code >= 0.0) | (Vg > 0.0)) & (usable != 0)
        members = np.flatnonzero(member & B.real_zone)
        dM = np.zeros(B.nzones)
        en = np.empty(members.size)
        mgid = np.empty(members.size, np.int64)
        mg = np.empty(members.size)
        bad2 = merge_members(members, code, s.M, self.phi, self._VE_uniform, Mg, Eg, Vg, B.zs, gdims, goff,
                             self._gper, dM, en, mgid, mg)
        bad = bad if bad >= 0 else bad2
        s.bc.fill_zones([dM])
        dM[usable == 0] = 0.0
        owned = B.owned.astype(np.uint8)
        un, m0, m1, ngid, part, edges = merge_nodes(np.flatnonzero(member & self._layer1), code, Vg, s.M, dM,
                                                    B.zact, s.v, owned, B.zs, B.ns, dim, gdims, goff, self._gper)
        comm = dec.comm if dec.parallel else None
        # groups that share a node pool their nodes' momentum together (merge.group_components)
        targets = (code[members] < 0.0) & (Vg[members] > 0.0)
        cids, comp, cmass = group_components(comm, edges, mgid[targets], Mg[members[targets]])
        ngid = comp[np.searchsorted(cids, ngid)]
        at = np.searchsorted(cids, mgid)
        mgid, mg = comp[at], cmass[at]
        keys = sorted_unique(np.concatenate([ngid, mgid]))
        nid = self._node_gid(B, un)
        # (collective: every rank takes part in both sums, with or without groups)
        tot = _group_sums(comm, keys, ngid, nid, part)
        ugr = np.searchsorted(keys, ngid)
        ke1 = merge_velocities(un, ugr, m0, m1, s.v, tot, owned) if bad < 0 else np.zeros(un.size)
        ke1 = _group_sums(comm, keys, ngid, nid, ke1[:, None])[:, 0]
        s.bc.fill_nodes_vector(s.v)  # (the owners' node velocities to the ghosts and images)
        if bad >= 0:
            return int(bad)
        # the real members' new state; the ghosts are refilled with the zone state (_forces)
        g = np.searchsorted(keys, mgid)
        s.M[members] += dM[members]
        de = (tot[g, dim + 2] - ke1[g]) / mg
        s.e[members] = en + de
        if mm is not None:
            member_materials(members, code, self.phi, self._VE_uniform, Vg, Vk, Mk, Ek, de, mm.code, mm.par,
                             B.zs, mm.vol, mm.mass, mm.ener)
        return -1

    @staticmethod
    def _node_gid(B, nodes) -> np.ndarray:
        """Global node ids (x fastest) of padded node indices."""
        dim = B.dim
        i, r = np.divmod(nodes, B.ns[0])
        j, k = np.divmod(r, B.ns[1])
        ijk = np.stack([i, j, k], axis=1)[:, :dim] - GHOST + B.offset
        stride = np.cumprod(np.concatenate([[1], B.cells[:-1] + 1]))
        return ijk @ stride

    def blocked_fraction(self) -> np.ndarray:
        return 1.0 - self.phi


def _sync(s) -> None:
    """The solver's collective failure check (parallel runs), if it has one."""
    if hasattr(s, "_sync"):
        s._sync()
