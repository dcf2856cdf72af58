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
        self.set_fractions(s, self.b_static)

    # ---- fractions -----------------------------------------------------------------------------
    def combined(self, s, fractions) -> np.ndarray:
        """max(static, coupler) blocked fraction (nzones,); ``fractions`` has one value per zone of
        the whole grid in output order (x fastest), on every rank."""
        B = s.block
        if fractions is None:
            return self.b_static
        f = np.asarray(fractions, dtype=np.float64).ravel()
        ncell = int(np.prod(B.cells))
        if f.size != ncell:
            raise ValueError(f"blocked fractions: expected {ncell} values (one per ALE zone), got {f.size}")
        if not hasattr(self, "_gzones"):  # global output index of this block's output zones
            ijk = np.stack(np.unravel_index(B.out_zones, B.zdims), axis=1)[:, : B.dim] - GHOST + B.offset
            stride = np.cumprod(np.concatenate([[1], B.cells[:-1]]))
            self._gzones = ijk @ stride
        b = np.zeros(B.nzones)
        b[B.out_zones] = f[self._gzones]
        bad = ~(np.isfinite(b) & (b >= 0.0) & (b <= 1.0))
        if np.any(bad):
            z = int(np.flatnonzero(bad)[0])
            raise ValueError(f"blocked fraction {b[z]!r} of ALE zone {B.zone_ijk(z)} is not in [0, 1]")
        return np.maximum(b, self.b_static)

    def set_fractions(self, s, b) -> None:
        """Open fractions (ghosts filled like zone fields), solid flags, apertures, cut zones and
        immersed-wall nodes from the blocked fraction b of the real zones."""
        B, dim = s.block, self.dim
        phi = np.where(b >= 1.0 - SOLID_TOL, 0.0, 1.0 - b)
        phi[~B.real_zone] = 1.0
        s.bc.fill_zones([phi])
        n_open = np.array([float(np.count_nonzero(phi[B.real_zone] > 0.0))])
        dec = getattr(s, "dec", None)
        if dec is not None and dec.parallel:
            n_open = dec.sum(n_open)
        if n_open[0] == 0.0:
            raise ValueError("the obstacles block every zone of the ALE grid")
        self.b = np.where(B.real_zone, b, 0.0)  # (checkpointed: the rest follows from it)
        self.phi = phi
        self.solid = (phi <= 0.0).astype(np.uint8)
        A = np.ones((dim, B.nzones))
        pv = B.zview(phi)
        for d in range(dim):
            av = B.zview(A[d])
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[d] = slice(0, B.zdims[d] - 1)
            hi[d] = slice(1, B.zdims[d])
            av[tuple(hi)] = np.minimum(pv[tuple(lo)], pv[tuple(hi)])
        self.A = A
        # zones whose forces need the aperture correction: cut zones and zones with a closed face
        t = (phi < 1.0)
        for d in range(dim):
            up = np.roll(A[d], -int(B.zs[d]))
            t |= (A[d] < 1.0) | (up < 1.0)
        t &= B.real_zone
        self.touched = np.flatnonzero(t).astype(np.int64)
        self._wall_nodes(s)

    def _wall_nodes(self, s) -> None:
        B, dim = s.block, self.dim
        sol = B.zview(self.solid.astype(bool))
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
        return float(k(s.x, s.v, s.fc, s.M, s.rho, s.p, s.c, s.q, self.phi, self.A, self.solid, self.touched,
                       B.zs, B.ns, s.q_lin, s.q_quad, s.q_kind, s.qgrad))

    def constrain(self, s, record: bool) -> None:
        """Immersed-wall node constraints into s._acc; when recording, the obstacle's pressure
        reaction dt_avg sum_cut zones sum_c f_c as well."""
        _constrain_kernel(s.v, s.v_old, s.m, s.block.owned, self._no_inflow[0], self._no_inflow[1],
                          self.wall_nodes, self.wall_comp, self._wall_vel, s._acc)
        if record:
            corner_force_sum(s.fc, self.touched, self._R)
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
        bad = lagrangian_open_volumes(self.ASV, self.VE, self.phi, s.V, s.M, s.rho, s.p, s.q, s.de_h,
                                      s.zr[0], s.zr[1], B.zs)
        if bad >= 0:
            s._check((0.0, bad, BAD_VOLUME), " (Lagrangian grid)")
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

    def blocked_fraction(self) -> np.ndarray:
        return 1.0 - self.phi


def _sync(s) -> None:
    """The solver's collective failure check (parallel runs), if it has one."""
    if hasattr(s, "_sync"):
        s._sync()


# ------------------------------------------------------------------------------------------------
# kernels
# ------------------------------------------------------------------------------------------------
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
def lagrangian_open_volumes(ASV, VE, phi, V, M, rho, p, q, de_h, zlo, zhi, zs):
    """V = phi VE + sum_d (ASV_d[z + s_d] - ASV_d[z]) (open Lagrangian volume), rho = M / V and the
    half-step EOS shift de_h of the zones with material.  Returns the first such zone with V <= 0."""
    dim = ASV.shape[0]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                v0 = phi[z] * VE[z]
                vn = v0
                for d in range(dim):
                    vn += ASV[d, z + zs[d]] - ASV[d, z]
                V[z] = vn
                if M[z] > 0.0:
                    if not (vn > 0.0):
                        return z
                    de_h[z] = -(p[z] + q[z]) * (vn - v0) / (2.0 * M[z])
                    rho[z] = M[z] / vn
                else:
                    rho[z] = 0.0
    return -1


@njit(cache=True, inline="always")
def _aperture(A, z, zs, d, o):
    return A[d, z] if o == 0 else A[d, z + zs[d]]


@njit(cache=True)
def apertures_2d(x, v, fc, M, rho, p, c, q, phi, A, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
    """Aperture correction of the zones listed (after hydro.zone_pass_2d at the fixed grid):
    div v = sum v . b^A / (phi V), new q of the solver's kind (qkind; monotonic: from the strain
    rates ``grad`` of hydro.mono_gradients_2d, a solid neighbour as a wall ghost, hydro._mono_q),
    f_c = (p + q) b^A_c + phi f_hg,c, written as
    f_c + ((p + q_new) b^A_c - (p + q_old) b_c) + (phi - 1) (f_c - (p + q_old) b_c) so that a corner
    with an open face and an unchanged q keeps its bits.  Returns the zones' stable step."""
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
        divv = _t4(w[0], w[1], w[2], w[3]) / (ph * vol)
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
def apertures_3d(x, v, fc, M, rho, p, c, q, phi, A, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
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
        divv = _t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]) / (ph * vol)
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
