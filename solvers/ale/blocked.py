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
holds material is an error (the coupler must first push the material out); a zone that opens
would start empty (no pressure) and fill through its faces (not reachable yet: a zone only becomes
fully blocked when it is empty).  The coupler's fractions (``AleSolver.remap(blocked)``: one value
per zone of the whole grid, output order) combine with the static obstacles by the larger value.
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

import math

import numpy as np
from numba import njit

from solvers.expressions import compile_expression
from solvers.ale import eos as _eos
from solvers.ale.boundary import constrain as _constrain_kernel
from solvers.ale.grid import GHOST
from solvers.ale.points import subcell_offsets
from solvers.ale.hydro import BAD_STATE, BAD_VOLUME, _t4, _t8, hex_volume_sym, zone_q
from solvers.ale.remap import set_positions
from solvers import elements as _elements
from solvers.elements import hex_bvectors, quad_bvectors

SOLID_TOL = 1e-12
"""A zone with blocked fraction b >= 1 - SOLID_TOL is fully blocked (open fraction exactly 0)."""

PHI_Q = 0.5
"""The artificial viscosity of a cut zone takes its divergence over at least this fraction of the
zone's volume: the flux mismatch of a small zone's faces would be amplified by 1/phi (a small zone
shares its state with its neighbour after each remap: PHI_MERGE)."""


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
        self.SF = np.zeros(B.nzones)  # a_e . (surface velocity) of the cut zones (their q)
        self._cut_velocity = np.zeros((0, B.dim))
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
                A[d, fz] = np.minimum(self._A_static[d, fz], np.clip(1.0 - np.asarray(cov)[fm], 0.0, 1.0))
                named += [fz, fz - B.zs[d]]
            self.A_body = A
        else:
            self.A_body = None
        c = np.unique(np.concatenate(named))
        self._body_cand = c[B.real_zone[c]]
        self.cut_rows = np.flatnonzero(cm)
        self.n_cut = int(cut.size)
        vel = geometry.velocity if geometry.velocity is not None else np.zeros((cut.size, B.dim))
        self._cut_velocity = np.asarray(vel).reshape(-1, B.dim)[cm]
        nodes = np.zeros(0, np.int64) if geometry.nodes is None else geometry.nodes
        self.nodes = gi.nodes(nodes)  # (local index, real here, owned here) of the requested nodes
        return np.maximum(np.where(B.real_zone, b, 0.0), self.b_static)

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
        self._real = B.real_zone.astype(np.uint8)

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
        real = s.block.real_zone
        s.M[real] *= self.phi[real]
        sol = self.solid.astype(bool)
        s.M[sol] = 0.0
        s.rho[sol] = 0.0
        s.e[sol] = 0.0

    def eos(self, s) -> None:
        """rho = M / (phi V), EOS at e + de_h of the real zones (massless zones: no state)."""
        if s._initialising:
            sol = self.solid.astype(bool) & s.block.real_zone
            if np.any(s.e[sol] != 0.0):
                z = int(np.flatnonzero(sol & (s.e != 0.0))[0])
                raise ValueError(f"an energy source lies in the fully blocked ALE zone {s.block.zone_ijk(z)}")
        bad = open_eos(s.eos_code, s.eos_par, s.M, s.e, s.de_h, self.phi, self.VE, s.rho, s.p, s.c, s.q,
                       s.zr[0], s.zr[1], s.block.zs)
        if bad >= 0:
            s._check((0.0, bad, BAD_STATE))

    def apertures(self, s) -> float:
        """Aperture correction of the corner forces and q of the cut zones (after the zone pass);
        returns their stable step."""
        B = s.block
        k = apertures_3d if self.dim == 3 else apertures_2d
        return float(k(s.x, s.v, s.fc, s.M, s.rho, s.p, s.c, s.q, self.phi, self.A, self.SF, self.solid,
                       self.touched,
                       B.zs, B.ns, s.q_lin, s.q_quad, s.q_kind, s.qgrad))

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
                                      s.q, s.de_h, s.zr[0], s.zr[1], B.zs)
        if bad >= 0:
            s._check((0.0, bad, BAD_VOLUME), " (Lagrangian grid)")
        if self._sb_zones.size:  # the body-surface volumes belong to this step only
            self.SB[self._sb_zones] = 0.0
            self._sb_zones = np.zeros(0, np.int64)
        _sync(s)
        s._fill_remap_zones()
        order = range(dim) if s.parity == 0 else range(dim - 1, -1, -1)
        for d in order:
            s._sweep(d)  # (the remap kernels with this object's face volumes, solid flags, massless zones)
        set_positions(s.x, B.X)
        if b_new is not None:
            self._apply_new_fractions(s, b_new)
        s.parity ^= 1
        s._pending_remap = False
        s._dt_stable = s._forces(midstep=False, advect=True, eos=True)

    def _apply_new_fractions(self, s, b_new) -> None:
        """Open fractions of the remapped state: rho = M / (phi_new V).  Collective (ghost fills)."""
        B = s.block
        if self.A_body is not None:  # a coupled body's exact geometry: small zones merge
            _sync(s)
            self.set_fractions(s, b_new)
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
                from solvers.ale.solver import SolverError
                raise SolverError(msg)
            s._fail(msg)  # one rank: raises; parallel: raised on every rank by the _sync below
        _sync(s)
        self.set_fractions(s, b_new)

    def _merge(self, s, gdims, goff) -> int:
        """The small-zone merge (merge_groups, merge_velocities) with the groups' node sums over
        the ranks: every group that touches an owned node or zone is seen whole by the ranks that
        hold it, and each node is counted by its owner only, then summed by group (target id)."""
        B = s.block
        owned = B.owned.astype(np.uint8)
        # candidates: zones of the first ghost layer or inside that a body covers and that hold
        # material (the cut zones, and any a body has just covered)
        cand = np.flatnonzero((self.b_bodies > 0.0) & (s.M != 0.0) & self._layer1)
        bad, ugt, un, ugr, m0, m1, members, mgroup, Mg, part = merge_groups(
            cand, s.M, s.e, self.phi, self._VE_uniform, B.zact, self._usable, s.v, s.m,
            owned, B.zs, B.ns, PHI_MERGE, gdims, goff)
        dec = s.dec
        comm = dec.comm if dec.parallel else None
        nid = self._node_gid(B, un)
        mine = owned[un].astype(bool)
        # (collective: every rank takes part in both sums, with or without groups)
        part = _group_sums(comm, ugt, ugt[ugr[mine]], nid[mine], part[mine])
        ke1 = merge_velocities(un, ugr, m0, m1, s.v, part, owned) if bad < 0 else np.zeros(un.size)
        ke1 = _group_sums(comm, ugt, ugt[ugr[mine]], nid[mine], ke1[mine][:, None])[:, 0]
        if dec.parallel:  # the owners' node velocities to the other ranks' copies (the shared plane
            s.bc.fill_nodes_vector(s.v)  # of a cut and the ghosts) before anything reads them
        if bad >= 0 or ugt.size == 0:
            return int(bad)
        dim = B.dim
        s.e[members] += (part[mgroup, dim + 2] - ke1[mgroup]) / Mg[mgroup]
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


def _group_sums(comm, keys, row_key, row_node, rows) -> np.ndarray:
    """Per group (keys: this rank's sorted group ids) the sum of the rows (one per owned node: its
    group id, global node id, values) of every rank, added in the order of (group id, node id): the
    same numbers in the same order whatever the ranks (float64 buffers; comm None: one rank)."""
    k = rows.shape[1]
    mine = np.hstack([row_key[:, None].astype(np.float64), row_node[:, None].astype(np.float64), rows])
    if comm is not None:
        from mpi4py import MPI

        counts = np.zeros(comm.size, dtype=np.int64)
        comm.Allgather(np.array([mine.size], dtype=np.int64), counts)
        allrows = np.empty(int(counts.sum()))
        comm.Allgatherv(mine.ravel(), [allrows, counts, np.concatenate([[0], np.cumsum(counts)[:-1]]), MPI.DOUBLE])
        mine = allrows.reshape(-1, k + 2)
    order = np.lexsort((mine[:, 1], mine[:, 0]))
    return _ordered_sums(keys.astype(np.int64), mine[order, 0].astype(np.int64), mine[order, 2:].copy())


@njit(cache=True)
def _ordered_sums(keys, row_key, rows):
    """out[g] = sum of the rows whose key is keys[g], added in row order (rows sorted by key)."""
    out = np.zeros((keys.size, rows.shape[1]))
    g = 0
    for r in range(row_key.size):
        while g < keys.size and keys[g] < row_key[r]:
            g += 1
        if g < keys.size and keys[g] == row_key[r]:
            for c in range(rows.shape[1]):
                out[g, c] += rows[r, c]
    return out


def _sync(s) -> None:
    """The solver's collective failure check (parallel runs), if it has one."""
    if hasattr(s, "_sync"):
        s._sync()


# ------------------------------------------------------------------------------------------------
# kernels
# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def body_apertures(b, face_ok, A_static, zs, A):
    """A[d, z] (the lower d-face of padded zone z) = min(A_static, 0 if z and its lower d-neighbour
    are both covered whole by the bodies (b == 1), else 1) on this block's faces (face_ok), A_static
    on the rest: the faces inside a body, which the coupler does not list (it lists the others it
    covers)."""
    dim = A.shape[0]
    for d in range(dim):
        s = zs[d]
        for z in range(b.size):
            if face_ok[d, z] == 0:
                A[d, z] = A_static[d, z]
            elif z >= s and b[z] >= 1.0 and b[z - s] >= 1.0:
                A[d, z] = 0.0
            else:
                A[d, z] = A_static[d, z]


@njit(cache=True)
def open_fractions(b, real, solid_tol):
    """From the bodies' blocked fractions b (padded, ghost layers too): the open fraction of the real
    zones (0 within solid_tol of full, 1 elsewhere: ghosts are filled after), b of the real zones,
    the number of real zones with some open volume."""
    n = b.size
    phi = np.empty(n)
    br = np.empty(n)
    n_open = 0.0
    for z in range(n):
        if real[z]:
            br[z] = b[z]
            phi[z] = 0.0 if b[z] >= 1.0 - solid_tol else 1.0 - b[z]
            if phi[z] > 0.0:
                n_open += 1.0
        else:
            br[z] = 0.0
            phi[z] = 1.0
    return phi, br, n_open


@njit(cache=True)
def open_eos(code, par, M, e, de_h, phi, VE, rho, p, c, q, zlo, zhi, zs):
    """rho = M / (phi VE) and the EOS at e + de_h of the zones in range; massless zones get
    rho = p = c = q = 0.  Returns the first zone with an invalid state (or -1)."""
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                if M[z] > 0.0:
                    r = M[z] / (phi[z] * VE[z])
                    pz, cz, ok = _eos.state(code, par, r, e[z] + de_h[z])
                    rho[z] = r
                    p[z] = pz
                    c[z] = cz
                    if not ok:
                        return z
                else:
                    rho[z] = 0.0
                    p[z] = 0.0
                    c[z] = 0.0
                    q[z] = 0.0
    return -1


@njit(cache=True)
def lagrangian_open_volumes(ASV, SB, CUT, VE, phi, V, M, rho, p, q, de_h, zlo, zhi, zs):
    """V = phi VE + SB + sum_d (ASV_d[z + s_d] - ASV_d[z]) (open Lagrangian volume; SB the volume a
    coupled body's surface sweeps into the zone, negative when it advances), rho = M / V and the
    half-step EOS shift de_h of the zones with material.  A coupled body's cut zone (CUT) whose open
    part the body surface and its faces sweep away within the step keeps a sliver of volume (its
    material leaves through the positivity-limited fluxes and the small-zone merge) and no EOS shift.
    Returns the first other zone with V <= 0."""
    dim = ASV.shape[0]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                v0 = phi[z] * VE[z]
                vn = v0 + SB[z]
                for d in range(dim):
                    vn += ASV[d, z + zs[d]] - ASV[d, z]
                swept = CUT[z] != 0 and not (vn > 1e-9 * VE[z])
                if swept:
                    # a body surface and the zone's open faces swept past its whole open part
                    # within the step (the surface crossed a zone face, or the zone is small): its
                    # material goes through the open faces (the remap's positivity limit) and the
                    # small-zone merge; keep a sliver of volume here
                    vn = 1e-9 * VE[z]
                V[z] = vn
                if M[z] > 0.0:
                    if not (vn > 0.0):
                        return z
                    # the half-step EOS shift of the step's p dV; none for a zone a body surface
                    # swept or changed by more than half its volume (a small cut zone: its state
                    # merges with its neighbour's after the remap, the linear shift means nothing)
                    big = CUT[z] != 0 and abs(vn - v0) > 0.5 * v0
                    de_h[z] = 0.0 if (swept or big) else -(p[z] + q[z]) * (vn - v0) / (2.0 * M[z])
                    rho[z] = M[z] / vn
                else:
                    rho[z] = 0.0
    return -1


@njit(cache=True, inline="always")
def _aperture(A, z, zs, d, o):
    return A[d, z] if o == 0 else A[d, z + zs[d]]


@njit(cache=True)
def apertures_2d(x, v, fc, M, rho, p, c, q, phi, A, SF, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
    """Aperture correction of the zones listed (after hydro.zone_pass_2d at the fixed grid):
    div v = sum v . b^A / (phi V), new q of the solver's kind (qkind; monotonic: from the strain
    rates ``grad`` of hydro.mono_gradients_2d, a solid neighbour as a wall ghost, hydro._mono_q),
    f_c = (p + q) b^A_c + phi f_hg,c, written as
    f_c + ((p + q_new) b^A_c - (p + q_old) b_c) + (phi - 1) (f_c - (p + q_old) b_c) so that a corner
    with an open face and an unchanged q keeps its bits.  SF: the flux a_e . v_surface of a coupled
    body's surface in the zone (the open volume's rate of change has -SF: a retreating surface is
    no compression), 0 elsewhere.  Returns the zones' stable step."""
    xe = np.empty((4, 2))
    ve = np.empty((4, 2))
    b = np.empty((4, 2))
    bA = np.empty((4, 2))
    w = np.empty(4)
    dt_min = np.inf
    for t in range(zones.shape[0]):
        z = zones[t]
        if not (M[z] > 0.0):
            continue
        i = z // zs[0]
        j = (z - i * zs[0]) // zs[1]
        n0 = i * ns[0] + j * ns[1]
        for a in range(4):
            ox = 1 if (a == 1 or a == 2) else 0
            oy = 1 if a >= 2 else 0
            nd = n0 + ox * ns[0] + oy * ns[1]
            xe[a, 0] = x[nd, 0]
            xe[a, 1] = x[nd, 1]
            ve[a, 0] = v[nd, 0]
            ve[a, 1] = v[nd, 1]
        vol, _ = quad_bvectors(xe, b)
        for a in range(4):
            ox = 1 if (a == 1 or a == 2) else 0
            oy = 1 if a >= 2 else 0
            bA[a, 0] = b[a, 0] * _aperture(A, z, zs, 0, ox)
            bA[a, 1] = b[a, 1] * _aperture(A, z, zs, 1, oy)
            w[a] = ve[a, 0] * bA[a, 0] + ve[a, 1] * bA[a, 1]
        ph = phi[z]
        divv = (_t4(w[0], w[1], w[2], w[3]) - SF[z]) / (max(ph, PHI_Q) * vol)
        emax = 0.0
        for a in range(4):
            an = (a + 1) % 4
            ex = xe[an, 0] - xe[a, 0]
            ey = xe[an, 1] - xe[a, 1]
            l2 = ex * ex + ey * ey
            if l2 > emax:
                emax = l2
        lc = vol / math.sqrt(emax)
        cz = c[z]
        qz, qq = zone_q(qkind, grad, z, zs, 2, rho[z], cz, lc, divv, q_lin, q_quad, solid)
        s_old = p[z] + q[z]
        s_new = p[z] + qz
        q[z] = qz
        u = 0.0
        for a in range(4):
            s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1]
            if s2 > u:
                u = s2
        dte = lc / (math.sqrt(u) + qq + math.sqrt(qq * qq + cz * cz))
        if dte < dt_min:
            dt_min = dte
        for a in range(4):
            for d in range(2):
                hg = fc[z, a, d] - s_old * b[a, d]
                fc[z, a, d] = fc[z, a, d] + (s_new * bA[a, d] - s_old * b[a, d]) + (ph - 1.0) * hg
    return dt_min


@njit(cache=True)
def apertures_3d(x, v, fc, M, rho, p, c, q, phi, A, SF, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
    """3D version of :func:`apertures_2d` (hydro.zone_pass_3d geometry)."""
    xe = np.empty((8, 3))
    ve = np.empty((8, 3))
    b = np.empty((8, 3))
    bA = np.empty((8, 3))
    w = np.empty(8)
    oo = np.empty((8, 3), np.int64)
    for a in range(8):
        oo[a, 0] = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oo[a, 1] = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oo[a, 2] = 1 if a >= 4 else 0
    dt_min = np.inf
    for t in range(zones.shape[0]):
        z = zones[t]
        if not (M[z] > 0.0):
            continue
        i = z // zs[0]
        r = z - i * zs[0]
        j = r // zs[1]
        k = r - j * zs[1]
        n0 = i * ns[0] + j * ns[1] + k * ns[2]
        for a in range(8):
            nd = n0 + oo[a, 0] * ns[0] + oo[a, 1] * ns[1] + oo[a, 2] * ns[2]
            for d in range(3):
                xe[a, d] = x[nd, d]
                ve[a, d] = v[nd, d]
        _, amax = hex_bvectors(xe, b)
        vol = hex_volume_sym(xe, b)
        for a in range(8):
            for d in range(3):
                bA[a, d] = b[a, d] * _aperture(A, z, zs, d, oo[a, d])
            w[a] = ve[a, 0] * bA[a, 0] + ve[a, 1] * bA[a, 1] + ve[a, 2] * bA[a, 2]
        ph = phi[z]
        divv = (_t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]) - SF[z]) / (max(ph, PHI_Q) * vol)
        lc = vol / amax
        cz = c[z]
        qz, qq = zone_q(qkind, grad, z, zs, 3, rho[z], cz, lc, divv, q_lin, q_quad, solid)
        s_old = p[z] + q[z]
        s_new = p[z] + qz
        q[z] = qz
        u = 0.0
        for a in range(8):
            s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1] + ve[a, 2] * ve[a, 2]
            if s2 > u:
                u = s2
        dte = lc / (math.sqrt(u) + qq + math.sqrt(qq * qq + cz * cz))
        if dte < dt_min:
            dt_min = dte
        for a in range(8):
            for d in range(3):
                hg = fc[z, a, d] - s_old * b[a, d]
                fc[z, a, d] = fc[z, a, d] + (s_new * bA[a, d] - s_old * b[a, d]) + (ph - 1.0) * hg
    return dt_min


@njit(cache=True)
def corner_force_sum(fc, zones, out):
    """out[d] = sum over the listed zones of sum_c fc[z, c, d]."""
    for d in range(out.shape[0]):
        out[d] = 0.0
    for t in range(zones.shape[0]):
        z = zones[t]
        for a in range(fc.shape[1]):
            for d in range(fc.shape[2]):
                out[d] += fc[z, a, d]


def _flush():
    from solvers.ale import hydro as _h
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([open_eos, lagrangian_open_volumes, _aperture, apertures_2d, apertures_3d, corner_force_sum],
                      [_eos.__file__, _elements.__file__, _h.__file__], "blocked.deps.sha256")


_flush()


# ------------------------------------------------------------------------------------------------
# small cut zones of moving bodies: conservative merging after the remap
# ------------------------------------------------------------------------------------------------
PHI_MERGE = 0.5
"""A zone a coupled body cuts to an open fraction below this (or a fully covered zone that still
holds material, or one the remap left with negative mass) shares its content with its most open
face neighbour after every remap (one density and specific energy for both): a small cut zone's
state would otherwise follow its explicit Lagrange step with a time step set by full zones (its
volume changes by O(1) of itself per step), the remap's face fluxes and the body's swept volume
agree only to the order of the scheme, and a body crossing a zone face within one step sweeps more
than the zone holds."""


@njit(cache=True, inline="always")
def _split(n, strides):
    """(i, j, k) of the flat padded index n (zone or node strides)."""
    i = n // strides[0]
    r = n - i * strides[0]
    j = r // strides[1]
    return i, j, r - j * strides[1]


@njit(cache=True)
def _corners(z, zs, ns, dim, out):
    i, j, k = _split(z, zs)
    n0 = i * ns[0] + j * ns[1] + k * ns[2]
    nc = 0
    for c in range(1 << dim):
        o0 = c & 1
        o1 = (c >> 1) & 1
        o2 = (c >> 2) & 1
        out[nc] = n0 + o0 * ns[0] + o1 * ns[1] + o2 * ns[2]
        nc += 1
    return nc


@njit(cache=True)
def _node_mass(n, M, zact, zs, ns, dim):
    """The gather's nodal mass (hydro.gather_*: 2^-dim sum of the active zones' masses)."""
    i, j, k = _split(n, ns)
    s = 0.0
    for c in range(1 << dim):
        zi = i - 1 + (c & 1)
        zj = j - 1 + ((c >> 1) & 1)
        zk = k - 1 + ((c >> 2) & 1) if dim == 3 else 0
        z = zi * zs[0] + zj * zs[1] + zk * zs[2]
        s += zact[z] * M[z]
    return s / (1 << dim)


@njit(cache=True)
def _gid(z, zs, gdims, goff):
    """Global zone id (x fastest) of padded zone z: the same number on every rank that holds it."""
    i, j, k = _split(z, zs)
    return (i + goff[0]) + gdims[0] * ((j + goff[1]) + gdims[1] * (k + goff[2]))


@njit(cache=True)
def _inside(n, ns, zs, nzones, dim):
    """Node n's 2^dim zones all lie in the padded block (zone dims from the strides and size)."""
    i, j, k = _split(n, ns)
    n0 = nzones // zs[0]
    n1 = zs[0] // zs[1]
    n2 = zs[1]
    if i < 1 or i > n0 - 1 or j < 1 or j > n1 - 1:
        return False
    if dim == 3 and (k < 1 or k > n2 - 1):
        return False
    return True


@njit(cache=True)
def _no_merge(status, dim):
    z = np.zeros(0, np.int64)
    f = np.zeros(0)
    return status, z, z, z, f, f, z, z, f, np.zeros((0, dim + 4))


@njit(cache=True)
def merge_velocities(un, ugr, m0, m1, v, tot, owned):
    """The nodes' new velocities from their group's totals ``tot`` (over all ranks: [pool, gain, mass
    after, kinetic energy before]): a node that gains mass takes its share of the momentum the others
    released with theirs; when no node of a group gains (its zones' mass moved between nodes of
    other groups) the pool goes to its nodes by mass; a node left without mass stops.  Returns the
    groups' kinetic energy after, over the nodes this rank owns."""
    dim = v.shape[1]
    ke1 = np.zeros(un.size)  # per node (owned ones), summed by group like merge_groups' rows
    ng = tot.shape[0]
    # the released mass moves at its mean velocity u = pool / released into the nodes that gain it;
    # what the gains do not take (a node's change may come from a neighbouring group's zones: gains
    # and releases of one group need not balance) goes to all of the group's nodes by mass
    u = np.zeros((ng, dim))
    rest = np.zeros((ng, dim))
    for g in range(ng):
        rel, gain = tot[g, dim + 3], tot[g, dim]
        for d in range(dim):
            u[g, d] = tot[g, d] / rel if rel > 0.0 else 0.0
            rest[g, d] = tot[g, d] - (gain * u[g, d] if rel > 0.0 else 0.0)
    for a in range(un.size):
        g = ugr[a]
        n = un[a]
        if m1[a] > m0[a] and m1[a] > 0.0:  # (u = 0 when nothing was released: diluted)
            m_own = m0[a] if m0[a] > 0.0 else 0.0  # (see merge_groups: negative masses)
            for d in range(dim):
                v[n, d] = (m_own * v[n, d] + (m1[a] - m_own) * u[g, d]) / m1[a]
        if m1[a] > 0.0 and tot[g, dim + 1] > 0.0:
            for d in range(dim):
                v[n, d] += rest[g, d] / tot[g, dim + 1]
        if not (m1[a] > 0.0):
            for d in range(dim):
                v[n, d] = 0.0
        if owned[n]:
            for d in range(dim):
                ke1[a] += 0.5 * m1[a] * v[n, d] * v[n, d]
    return ke1


@njit(cache=True)
def merge_groups(cand, M, e, phi, VE, zact, usable, v, m, owned, zs, ns, phi_merge, gdims, goff):
    """Merge every candidate zone with material and an open fraction below phi_merge (or negative
    mass) into its face neighbour with the largest open fraction (the group's mass and internal
    energy shared in proportion to the open volumes: one density and one specific energy).  Nodal
    momentum is conserved: a node keeps its velocity when its mass falls and hands the momentum of
    the lost mass to the nodes of its group that gain mass; the kinetic energy this inelastic
    exchange removes becomes the group's internal energy (total energy conserved).

    Parallel runs: ``cand`` holds the candidates of this rank's padded block, ghosts (images of the
    neighbours' zones, ``usable``) included, so every rank sees the whole of every group that
    touches its real zones and nodes and computes it alike: groups, their order and the group a
    node belongs to (the one with the lowest target) follow global ids (``gdims``: zones per axis;
    ``goff``: global index of padded index 0 per axis), not the block's layout.  Values written to
    ghosts are refilled by the next halo exchange.  Returns -1, or a zone that holds material and
    has no open neighbour."""
    dim = v.shape[1]
    nd = 0
    donors = np.empty(cand.size, np.int64)
    targets = np.empty(cand.size, np.int64)
    for t in range(cand.size):
        z = cand[t]
        if not usable[z] or M[z] == 0.0 or (phi[z] >= phi_merge and M[z] > 0.0):
            continue
        best = -1
        bphi = 0.0
        for d in range(dim):
            for sgn in (-1, 1):
                nb = z + sgn * zs[d]
                if nb < 0 or nb >= M.shape[0]:
                    continue
                if usable[nb] and phi[nb] > bphi:
                    bphi = phi[nb]
                    best = nb
        if best < 0:
            return _no_merge(z, dim)
        donors[nd] = z
        targets[nd] = best
        nd += 1
    if nd == 0:
        return _no_merge(-1, dim)
    donors = donors[:nd]
    targets = targets[:nd]
    gd = np.empty(nd, np.int64)
    for a in range(nd):
        gd[a] = _gid(donors[a], zs, gdims, goff)
    o = np.argsort(gd, kind="mergesort")
    donors = donors[o]
    targets = targets[o]
    # a target that is itself a donor passes its group on to its own target
    for it in range(nd):
        changed = False
        for a in range(nd):
            for b in range(nd):
                if targets[a] == donors[b] and targets[b] != donors[a]:
                    targets[a] = targets[b]
                    changed = True
        if not changed:
            break
    gt = np.empty(nd, np.int64)
    for a in range(nd):
        gt[a] = _gid(targets[a], zs, gdims, goff)
    ot = np.argsort(gt, kind="mergesort")
    ng = 0
    ut = np.empty(nd, np.int64)
    ugt = np.empty(nd, np.int64)
    for a in range(nd):
        t = targets[ot[a]]
        if ng == 0 or ut[ng - 1] != t:
            ut[ng] = t
            ugt[ng] = gt[ot[a]]
            ng += 1
    ut = ut[:ng]
    ugt = ugt[:ng]
    gid_of = np.empty(nd, np.int64)
    for a in range(nd):
        for g in range(ng):
            if ut[g] == targets[a]:
                gid_of[a] = g
                break
    members = np.concatenate((ut, donors))
    mgroup = np.concatenate((np.arange(ng), gid_of))
    # affected nodes; a node belongs to the group with the lowest target id among its zones' groups
    corners = np.empty(8, np.int64)
    nodes = np.empty(members.size * (1 << dim), np.int64)
    ngr = np.empty(members.size * (1 << dim), np.int64)
    q = 0
    for a in range(members.size):
        nc = _corners(members[a], zs, ns, dim, corners)
        for c in range(nc):
            nodes[q] = corners[c]
            ngr[q] = mgroup[a]
            q += 1
    order = np.argsort(nodes, kind="mergesort")
    nodes_s = nodes[order]
    ngr_s = ngr[order]
    un = np.empty(q, np.int64)
    ugr = np.empty(q, np.int64)
    nu = 0
    for a in range(q):
        if nu > 0 and un[nu - 1] == nodes_s[a]:
            if ngr_s[a] < ugr[nu - 1]:  # groups are numbered in target-id order
                ugr[nu - 1] = ngr_s[a]
        else:
            un[nu] = nodes_s[a]
            ugr[nu] = ngr_s[a]
            nu += 1
    un = un[:nu]
    ugr = ugr[:nu]
    # the nodes' masses before (the remap's, ghosts filled) and their change: 2^-dim of the change
    # of every member zone around them (only members change)
    m0 = np.empty(nu)
    for a in range(nu):
        # the gather's nodal mass (what the diagnostics and the next step use) where all the node's
        # zones lie in the padded block; the remap's nodal mass at its edge (ghost nodes: refilled)
        m0[a] = _node_mass(un[a], M, zact, zs, ns, dim) if _inside(un[a], ns, zs, M.shape[0], dim) else m[un[a]]
    Mold = np.empty(members.size)
    for a in range(members.size):
        Mold[a] = M[members[a]]
    # zone masses and energies of every group
    Mg = np.zeros(ng)
    Eg = np.zeros(ng)
    Vg = np.zeros(ng)
    for a in range(members.size):
        z = members[a]
        g = mgroup[a]
        Mg[g] += M[z]
        Eg[g] += M[z] * e[z]
        Vg[g] += phi[z] * VE[z]
    for a in range(members.size):
        z = members[a]
        g = mgroup[a]
        if not (Mg[g] > 0.0):
            return _no_merge(z, dim)
        M[z] = Mg[g] * (phi[z] * VE[z]) / Vg[g]
        e[z] = Eg[g] / Mg[g]
    # nodal momentum: each node's mass change, and the group sums over the nodes this rank owns
    m1 = m0.copy()
    for a in range(members.size):
        z = members[a]
        dmz = zact[z] * (M[z] - Mold[a]) / (1 << dim)
        nc = _corners(z, zs, ns, dim, corners)
        for c in range(nc):
            m1[np.searchsorted(un, corners[c])] += dmz
    # per owned node: [pool (dim), gain, mass after, kinetic energy before, mass released]; summed
    # by group in a canonical order (Blocked._merge), so any number of ranks gives the same bits
    part = np.zeros((nu, dim + 4))
    for a in range(nu):
        if not owned[un[a]]:
            continue
        g = ugr[a]
        n = un[a]
        for d in range(dim):
            part[a, dim + 2] += 0.5 * m0[a] * v[n, d] * v[n, d]
        if m1[a] <= m0[a] or not (m1[a] > 0.0):
            # (a node that gains only up to zero mass -- a negative zone mass filled -- can hold no
            # momentum: its own goes to the pool)
            c = (m0[a] - m1[a]) if m1[a] <= m0[a] else m0[a]
            for d in range(dim):
                part[a, d] += c * v[n, d]
            part[a, dim + 3] += c
        elif m0[a] < 0.0:
            # a node of negative mass (round-off of a zone a body empties) that ends with some: its
            # momentum goes to the pool and it gains all of its new mass from it (bounded velocity)
            for d in range(dim):
                part[a, d] += m0[a] * v[n, d]
            part[a, dim + 3] += m0[a]
            part[a, dim] += m1[a]
        else:
            part[a, dim] += m1[a] - m0[a]
        if m1[a] > 0.0:
            part[a, dim + 1] += m1[a]
    return -1, ugt, un, ugr, m0, m1, members, mgroup, Mg, part