"""ALE background solver: staggered-grid Lagrange step + (Eulerian mode) remap to the fixed grid.

Time stepping (the central-difference pattern of the FE solver, so the coupler drives both alike;
step n -> n+1, dt = dt^{n+1/2}, dt_avg = (dt_prev + dt)/2, dt/2 on the first step)::

    predict(dt):  v* = v^{n-1/2} + dt_avg f^n / m
    correct():    v += impulse / m; boundary conditions (walls: normal velocity 0, pistons: the
                  piston speed, held faces: their velocity, characteristic open faces: the
                  implicit part of their dashpot, open_faces.py; the reaction impulse and its
                  work enter the balances); ghost nodes;
                  x^{n+1} = x^n + dt v^{n+1/2}; compatible internal-energy update
                  M (e^+ - e^-) = -dt_avg sum_c f_c^n . vbar_c;
                  Lagrangian mode: new volumes, densities, EOS, q, hourglass, corner forces f^{n+1}
                  and the stable step (one fused zone pass).
    remap():      Eulerian mode: swept volumes of the faces (they give the Lagrangian volumes),
                  direction-split remap back to the fixed grid (sweep order x,y,z on even steps,
                  z,y,x on odd ones), then EOS, q, forces and the stable step on the fixed grid.
                  Lagrangian mode: nothing.  (If the coupler skips it, stable_dt/predict run it.)

Kinetic energy is 1/2 m |v^{n+1/2}|^2; in Lagrangian mode with walls/periodic faces
kinetic + internal energy is conserved to round-off, in Eulerian mode the remap conserves mass,
momentum and total energy to round-off as well (see hydro.py, remap.py).

Defaults: viscosity (linear C_l, quadratic C_q) = (0.1, 0.5) in Eulerian mode, (0.2, 1.0) in
Lagrangian mode (length = smallest zone width), the same for ``kind = "monotonic"`` (the limited
q of hydro.py; ``"scalar"`` by default); hourglass 0.05 (FB viscous).

Energy sources: ``{energy=E, at=[..]}`` adds E (J; 2D: J per unit thickness) as internal energy.
If ``at`` is a grid node (within 1e-6 zone widths) E is split equally over the real zones that
share that node (the one corner zone for a point at a corner of the box, e.g. a Sedov blast at the
origin of an octant/quadrant grid; give the octant's share E_full/8 there); otherwise it all goes
to the zone containing the point.

Region velocities are zone values; a node gets the mass-weighted mean of its active zones.

Coupling impulses (correct(impulse=...)) are (nn, dim) arrays in output node order (the points of
output(), x fastest), the whole grid's array on every rank (each rank applies the rows of its nodes).

Balances (diagnostics): mass, momentum and energy against their initial values plus what crossed
the boundary (wall and inflow reactions, forces of open-boundary ghost zones, and the remap's
fluxes through open faces and through the boundary nodes' dual cells): exact to round-off for every
face kind.

Parallel runs (parallel.py): the zone box is split over the communicator's ranks (Cartesian); each
rank holds a padded block (2 ghost layers) with a global offset; faces between ranks are cuts whose
ghosts arrive by halo exchange right after every physical ghost fill (boundary.py).  Nodal forces
and masses are gathered from the zones in a fixed order, so N ranks reproduce one rank bitwise;
the stable step is a MIN, diagnostics SUM over owned zones/nodes (and each rank's share of the
boundary terms).  output() and checkpoint() gather to rank 0 in the one-rank (global) layout;
restart() reads any rank count's checkpoint.  A failure on one rank (bad zone, non-finite velocity)
is raised on every rank at the next collective check (the stable-step reduction, or the
Lagrangian-volume check of the remap), with the failing rank's message there.
"""
from __future__ import annotations

import numpy as np

from solvers.expressions import compile_expression
from solvers.ale.errors import SolverError  # noqa: F401  (raised here; its own module, below blocked.py too)
from solvers.ale import eos as _eos
from solvers.ale import hydro, remap
from solvers.ale.boundary import Boundaries
from solvers.ale.open_faces import CharacteristicFaces
from solvers.ale.grid import (FACE_NAMES, GHOST, INFLOW, OUTFLOW, PERIODIC, WALL, Z_OPEN, Block)
from solvers.ale.parallel import Decomposition, Halo
from solvers.ale.points import several_materials
from solvers.ale.solver_state import SolverState

# artificial viscosity defaults per mode (linear, quadratic): the remap of Eulerian mode adds its own
# dissipation, so a lighter q keeps shocks sharper there (Sedov 40^2: front half-height 1.6 % vs
# 2.6 % beyond the exact radius with the Lagrangian values); a pure Lagrange run needs the heavier q.
DEFAULT_VISCOSITY = {"eulerian": (0.1, 0.5), "lagrangian": (0.2, 1.0)}
# monotonic q (viscosity kind = "monotonic", hydro.py): in a shock (limiter phi = 0) it is the scalar
# q, so the scalar calibration carries over; the limiter only takes q out of smooth compression.
# Sod 400 zones: L1(rho) 1.44e-3 vs 1.45e-3 (Eulerian), 1.30e-3 vs 1.44e-3 (Lagrangian), the shock
# 10-90 % width 2.0 vs 2.1 and 1.6 vs 1.7 zones, no new overshoot; LULESH-like (0.5, 2/3) is
# wider in Lagrangian mode (1.7 zones) with 3x the star-pressure wiggle.
DEFAULT_MONOTONIC_VISCOSITY = {"eulerian": (0.1, 0.5), "lagrangian": (0.2, 1.0)}
DEFAULT_HOURGLASS = 0.05

_REASONS = {
    hydro.BAD_VOLUME: "non-positive zone volume",
    hydro.BAD_STATE: "invalid thermodynamic state (rho <= 0, non-finite or c^2 <= 0)",
}


def _bad_state_cause(rho: float, e: float, c: float) -> str:
    """What an invalid zone state says about its cause (the message names it: a campaign's stability
    map reads it)."""
    import math

    if not (math.isfinite(rho) and math.isfinite(e)):
        return "invalid thermodynamic state: non-finite density or energy"
    if rho <= 0.0:
        return "invalid thermodynamic state: non-positive density"
    if e < 0.0:
        return ("invalid thermodynamic state: negative internal energy (the zone's kinetic energy exceeds "
                "its total: a near-vacuum expansion, or a step beyond the stable limit)")
    return "invalid thermodynamic state: sound speed not real (c^2 <= 0: the EOS beyond its range)"


class AleSolver(SolverState):
    def __init__(self, comm, config: dict, bodies=None):
        """``bodies``: the coupled bodies' initial geometry in the grid (solvers/ale/coupled.py
        BodyGeometry, the same on every rank), or None (no coupled body)."""
        self.comm = comm
        self.config = config
        self.dim = dim = int(config["dimension"])
        self.mode = config.get("mode", "eulerian")
        if self.mode not in ("eulerian", "lagrangian"):
            raise ValueError(f"mode = {self.mode!r}: must be 'eulerian' or 'lagrangian'")
        visc = config.get("viscosity", {}) or {}
        kind = visc.get("kind", "scalar")
        if kind not in hydro.Q_KINDS:
            raise ValueError(f"viscosity kind = {kind!r}: must be one of {', '.join(map(repr, hydro.Q_KINDS))}")
        self.q_kind = hydro.Q_KINDS[kind]
        dq = (DEFAULT_VISCOSITY if kind == "scalar" else DEFAULT_MONOTONIC_VISCOSITY)[self.mode]
        self.q_lin = float(visc.get("linear", dq[0]))
        self.q_quad = float(visc.get("quadratic", dq[1]))
        self.hg = float(config.get("hourglass", DEFAULT_HOURGLASS))
        g = config["grid"]
        faces = {f: "wall" for f in ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")}
        faces.update(config.get("boundaries", {}) or {})
        periodic = [faces.get(FACE_NAMES[2 * d]) == "periodic" for d in range(min(len(g["cells"]), 3))]
        self.dec = Decomposition(comm, g["cells"], periodic)
        self.block = B = Block(g["lower"], g["upper"], g["cells"], faces, offset=self.dec.offset,
                               local_cells=self.dec.n, cuts=self.dec.cuts)
        if B.piston and self.mode != "lagrangian":
            raise ValueError("piston faces need mode = 'lagrangian' (the face nodes move with the piston)")
        self.halo = Halo(self.dec, B)
        self.bc = Boundaries(B, self.halo)
        self._error = None  # a failure message waiting for the next collective check (parallel)

        # materials: one (the zone state is the material's), or several per zone / void (mixed.py)
        used = list(dict.fromkeys(r["material"] for r in config["regions"]))
        self.mm = None
        if several_materials(config):
            self._check_mixed_supported(config)
            from solvers.ale.mixed import Materials
            self.mm = Materials(self, config)
            first = self.mm.names[int(np.flatnonzero(self.mm.code >= 0)[0])]
        else:
            first = used[0]
        self.material = first if self.mm is None else "+".join(self.mm.names)
        props = dict(config["materials"][first])
        self.eos_code, self.eos_par = _eos.eos_params(props.pop("eos"), props)
        self.eos_code = int(self.eos_code)
        self.eos_par = np.ascontiguousarray(self.eos_par, dtype=np.float64)
        # each material's cavitation_pressure (-inf: none; _check_cavitation), in the order of its
        # pressures: the zone's material, or the mixed zones' material columns
        names = self.mm.names if self.mm is not None else [first]
        self._pcav = np.array([float(config["materials"][n].get("cavitation_pressure", -np.inf)) for n in names])
        self._cavitation = bool(np.isfinite(self._pcav).any())

        nz, nn = B.nzones, B.nnodes
        nc = 4 if dim == 2 else 8
        self.M = np.zeros(nz)
        self.e = np.zeros(nz)
        self.V = np.zeros(nz)
        self.rho = np.zeros(nz)
        self.p = np.zeros(nz)
        self.c = np.zeros(nz)
        self.q = np.zeros(nz)
        self.de_h = np.zeros(nz)
        self.fc = np.zeros((nz, nc, dim))
        self.x = B.X.copy()
        self.v = np.zeros((nn, dim))
        self.v_old = np.zeros((nn, dim))
        self.f = np.zeros((nn, dim))
        self.m = np.zeros(nn)
        # remap work arrays
        self.SV = np.zeros((dim, nz))
        self.F = np.zeros(nz)
        self.ES = np.zeros(nz)
        self.PHI = np.zeros(nn)
        self.VS = np.zeros((nn, dim))
        self.dK = np.zeros(nn)
        self._sums = np.zeros(7)
        self._gw = np.zeros(4)

        # kernels and ranges
        self._zone_pass = hydro.zone_pass_3d if dim == 3 else hydro.zone_pass_2d
        # monotonic q: directional strain rates and widths of every zone of the padded block
        self._mono_grad = hydro.mono_gradients_3d if dim == 3 else hydro.mono_gradients_2d
        self.qgrad = np.zeros((B.nzones if self.q_kind == hydro.Q_MONOTONIC else 0, 2 * dim))
        self._zall = (np.zeros(3, np.int64), np.array(B.zdims, np.int64))
        self._gather = hydro.gather_3d if dim == 3 else hydro.gather_2d
        self._swept = remap.swept_volumes_3d if dim == 3 else remap.swept_volumes_2d
        self.zr = tuple(np.ascontiguousarray(a, dtype=np.int64) for a in B.zreal)
        self.nr = tuple(np.ascontiguousarray(a, dtype=np.int64) for a in B.nreal)
        act = np.arange(3) < dim
        self.z1 = (np.where(act, 1, 0).astype(np.int64), np.where(act, np.array(B.zdims) - 1, 1).astype(np.int64))
        self.open_faces = [(d, s) for d in range(dim) for s in range(2) if B.face[d, s] in (OUTFLOW, INFLOW)]
        self.has_images = any(B.face[d, 0] == PERIODIC for d in range(dim))
        self.has_cuts = self.halo.active
        self._out_cells = None
        self._gout = None  # global output index of the local output nodes (parallel impulses)
        if self.dec.parallel:
            ijk = np.stack(np.unravel_index(B.out_nodes, B.ndims), axis=1)[:, :dim] - GHOST + B.offset
            stride = np.cumprod(np.concatenate([[1], B.cells[:-1] + 1]))
            self._gout = ijk @ stride
        self._inflow_state = {}
        for (d, s), st in B.inflow.items():
            rho_in = float(st["density"])
            e_in = float(_eos.energy_from_pressure(self.eos_code, self.eos_par, rho_in, float(st["pressure"])))
            p_in, c_in, ok = _eos.state(self.eos_code, self.eos_par, rho_in, e_in)
            if not ok:
                raise ValueError(f"inflow state on {('x', 'y', 'z')[d]}_{('lower', 'upper')[s]} is not a valid "
                                 f"state of material {self.material!r}")
            self._inflow_state[(d, s)] = (rho_in, e_in, p_in, c_in)

        # characteristic faces (inflow, outflow, far field): their ghost pressure, dashpot and donors
        # (with several materials per zone, each face zone's exterior is one material: open_faces.py;
        # with a void material the open faces stay zero-gradient: measured on the penetrators, the
        # characteristic faces took the SPH rod past Tate's limit, open_faces.py's docstring)
        void = any(m.get("eos") == "void" for m in (config.get("materials") or {}).values())
        self._char = CharacteristicFaces(self, B.characteristic) if B.characteristic and not void else None

        self._acc = np.zeros(4)
        # owned nodes touching open-boundary ghost zones (balances of the open faces)
        cand = np.unique(np.concatenate([B.face_nodes(d, s_) for d, s_ in self.open_faces]
                                        + [np.zeros(0, np.int64)]))
        zn = self._node_zones(cand)
        touch = np.any(B.zkind[zn] == Z_OPEN, axis=1) & B.owned[cand]
        self._open_nodes = cand[touch]
        self._open_nodes_z = np.ascontiguousarray(zn[touch])
        # zones of real fluid: real here, beyond a cut on the neighbour rank, or periodic images (a
        # real zone across the box, whose share of a boundary node's kinetic-energy defect it gets
        # through the image node): the rest of an open-boundary node's zones are open ghosts
        inbox = np.ones(B.zdims, bool)
        for d in range(dim):
            if periodic[d]:
                continue
            gi = B.offset[d] + np.arange(B.zdims[d]) - GHOST
            shape = [1, 1, 1]
            shape[d] = B.zdims[d]
            inbox &= ((gi >= 0) & (gi < B.cells[d])).reshape(shape)
        self._real_f = inbox.ravel().astype(np.float64)
        self._open_face_nodes = {(d, s_): B.face_nodes(d, s_)[B.owned[B.face_nodes(d, s_)]]
                                 for d, s_ in self.open_faces}

        self.step = 0
        self.time = 0.0
        self.dt = 0.0
        self.dt_prev = 0.0
        self.dt_avg = 0.0
        self.first_step = True
        self.parity = 0
        self._pending_remap = False
        # balances: boundary contributions accumulated over the run
        self.b_mass = 0.0
        self.b_energy = 0.0
        self.b_momentum = np.zeros(dim)

        # the lightest initial density of the case's regions: the scale of "nearly empty" (a zone
        # with a trace of material, cut_zone_kernels.TRACE_ZONE), the same on every rank and after a restart
        self.rho_ref = min((float(r["density"]) for r in config["regions"] if float(r.get("density", 0.0)) > 0.0),
                           default=0.0)
        # blocked volume fractions: static obstacles of the case now, coupled bodies via remap()
        self._blk = None
        self.coupled = bodies is not None
        self.i_momentum = np.zeros(dim)  # what crossed the coupled bodies' surfaces (in b_* too)
        self.i_energy = 0.0
        if config.get("obstacles") or self.coupled:
            if self.mode != "eulerian":
                raise ValueError("obstacles and coupled bodies (blocked volume fractions) need mode = 'eulerian'")
            from solvers.ale.blocked import Blocked
            self._blk = Blocked(self, config.get("obstacles"))
            if self.coupled:
                self._blk.set_fractions(self, self._blk.combined(self, bodies))
        self._initialising = True
        self._initial_state(config)
        self._dt_stable = self._forces(midstep=False, advect=self.mode == "eulerian", eos=True)
        self._initialising = False
        d0 = self._totals()
        self.mass0, self.energy0, self.momentum0 = d0["mass"], d0["total_energy"], d0["momentum"]

    def _check_mixed_supported(self, config: dict) -> None:
        """Several materials per zone: what this increment covers."""
        if self.mode != "eulerian":
            raise ValueError("several materials (or void) in the ALE regions need mode = 'eulerian'")
        if self.block.inflow:
            raise ValueError("inflow faces with several ALE materials (or void) are not supported yet")

    # ------------------------------------------------------------------------------------------
    # initial conditions
    # ------------------------------------------------------------------------------------------
    def _initial_state(self, cfg: dict) -> None:
        if self.mm is not None:
            return self._initial_state_mixed(cfg)
        B, dim = self.block, self.dim
        real = B.real_zone
        centres = B.zone_centres()[real]
        nreal = int(real.sum())
        rho = np.full(nreal, np.nan)
        p = np.full(nreal, np.nan)
        e = np.full(nreal, np.nan)
        vel = np.zeros((nreal, dim))
        names = ("x", "y", "z")[:dim]
        for r in cfg["regions"]:
            if r.get("region"):
                mask = np.broadcast_to(np.asarray(compile_expression(r["region"], names=names)(*centres.T),
                                                  dtype=bool), (nreal,))
            else:
                mask = np.ones(nreal, bool)
            rho[mask] = float(r["density"])
            if "pressure" in r:
                p[mask] = float(r["pressure"])
                e[mask] = np.nan
            else:
                e[mask] = float(r["specific_internal_energy"])
                p[mask] = np.nan
            vel[mask] = np.asarray(r.get("velocity", [0.0] * dim), dtype=np.float64)
        missing = bool(np.any(np.isnan(rho)))
        if self.dec.parallel and self.dec.sum(np.array([float(missing)]))[0] > 0.0 and not missing:
            raise ValueError("a zone of another rank is not covered by any region")
        if missing:
            first = np.flatnonzero(np.isnan(rho))[0]
            z = np.flatnonzero(real)[first]
            raise ValueError(f"zone {B.zone_ijk(z)} (centre {centres[first]}) is not covered by any region")
        need = np.isnan(e)
        if np.any(need):
            out = np.empty(int(need.sum()))
            hydro.energy_from_pressure_array(self.eos_code, self.eos_par, rho[need], p[need], out)
            e[need] = out
        self.e[real] = e
        self.rho[real] = rho
        # geometry of the real zones, masses
        self.V[:] = 1.0
        self.M[:] = 1.0
        self._pass(self.z1, 0)
        self.M[real] = rho * self.V[real]
        if self._blk is not None:  # material in the open volume only
            self._blk.initial_state(self)
        # energy sources
        for src in cfg.get("energy_sources", []) or []:
            self._deposit_energy(float(src["energy"]), np.asarray(src["at"], dtype=np.float64))
        # zone velocities -> nodes (mass-weighted, exact for a uniform field)
        vz = np.zeros((B.nzones, dim))
        vz[real] = vel
        self._fill_zone_state()
        self._fill_zone_vector(vz)
        self._zones_to_nodes(vz)
        self._constrain(record=False)
        self.bc.fill_nodes_vector(self.v)
        self.v_old[:] = self.v

    def _initial_state_mixed(self, cfg: dict) -> None:
        """Several materials: regions sampled at sub-points of every zone (mixed.py)."""
        B, dim = self.block, self.dim
        real = B.real_zone
        rho, e, vel = self.mm.sample(self, cfg)
        self.e[real] = e
        self.rho[real] = rho
        self.V[:] = 1.0
        self.M[:] = 1.0
        self._pass(self.z1, 0)
        self.mm.set_initial(self)
        if self._blk is not None:  # material in the open volume only
            self._blk.initial_state_mixed(self)
        for src in cfg.get("energy_sources", []) or []:
            e0 = self.e.copy()
            self._deposit_energy(float(src["energy"]), np.asarray(src["at"], dtype=np.float64))
            self.mm.deposit_energy(self, self.e - e0)
        vz = np.zeros((B.nzones, dim))
        vz[real] = vel
        self._fill_zone_state()
        self.mm.fill(self)
        self._fill_zone_vector(vz)
        self._zones_to_nodes(vz)
        self._constrain(record=False)
        self.bc.fill_nodes_vector(self.v)
        self.v_old[:] = self.v

    def _node_zones(self, nid: np.ndarray) -> np.ndarray:
        """(len(nid), 2^dim) zones around the nodes nid (-1 beyond the block edge)."""
        B, dim = self.block, self.dim
        i, r = np.divmod(nid, B.ns[0])
        j, k = np.divmod(r, B.ns[1])
        ijk = np.stack([i, j, k], axis=1)
        out = []
        for off in np.ndindex(*([2] * dim)):
            zi = ijk.copy()
            zi[:, :dim] -= 1 - np.array(off)
            ok = np.all((zi >= 0) & (zi < np.array(B.zdims)), axis=1)
            out.append(np.where(ok, zi @ B.zs, -1))
        return np.stack(out, axis=1)

    def _deposit_energy(self, E: float, at: np.ndarray) -> None:
        B = self.block
        rel = (at - B.lower) / B.h
        near = np.rint(rel)
        zones = []
        if np.all(np.abs(rel - near) <= 1e-6):
            node = near.astype(np.int64)
            for off in np.ndindex(*([2] * self.dim)):
                zi = node - 1 + np.array(off)
                if np.all(zi >= 0) and np.all(zi < B.cells):
                    zones.append(zi)
        else:
            zi = np.clip(np.floor(rel).astype(np.int64), 0, B.cells - 1)
            zones.append(zi)
        if not zones:
            raise ValueError(f"energy source at {list(at)} is outside the grid")
        for zi in zones:
            if np.any(zi < B.offset) or np.any(zi >= B.offset + B.n):
                continue  # another rank's zone
            pad = np.zeros(3, np.int64)
            pad[: self.dim] = zi - B.offset + GHOST
            z = int(pad @ B.zs)
            self.e[z] += E / len(zones) / self.M[z]

    def _zones_to_nodes(self, vz: np.ndarray) -> None:
        """Nodal velocity = mass-weighted mean of the active zones around the node."""
        B, dim = self.block, self.dim
        w = self.M * B.zact
        wz = B.zview(w)
        vzv = B.zview(vz)
        ref = vz[np.flatnonzero(B.real_zone)[0]].copy()
        if self.dec.parallel:  # the first zone of the box, as on one rank (same rounding)
            self.dec.bcast(ref, self.dec.rank_of([0] * dim))
        num = np.zeros(B.ndims + (dim,))
        den = np.zeros(B.ndims)
        nsl = [slice(1, B.ndims[d] - 1) if d < dim else slice(None) for d in range(3)]
        for off in np.ndindex(*([2] * dim)):
            zsl = []
            for d in range(3):
                if d < dim:
                    zsl.append(slice(off[d], off[d] + B.ndims[d] - 2))
                else:
                    zsl.append(slice(None))
            num[tuple(nsl)] += wz[tuple(zsl)][..., None] * (vzv[tuple(zsl)] - ref)
            den[tuple(nsl)] += wz[tuple(zsl)]
        with np.errstate(invalid="ignore", divide="ignore"):
            v = ref + np.where(den[..., None] > 0, num / np.where(den > 0, den, 1.0)[..., None], 0.0)
        self.v[:] = v.reshape(-1, dim)

    # ------------------------------------------------------------------------------------------
    # ghost fills
    # ------------------------------------------------------------------------------------------
    def _inflow_values(self, kind: str):
        out = {}
        for key, (rho_in, e_in, p_in, c_in) in self._inflow_state.items():
            if kind == "state":
                out[key] = (rho_in, e_in, p_in, c_in, 0.0, 0.0)
            elif kind == "energy":
                out[key] = (e_in,)
            else:  # remap fields rho, e
                out[key] = (rho_in, e_in)
        return out

    def _fill_zone_state(self) -> None:
        """Ghost zones: rho, e, p, c, q, de_h; M = rho V (the ghost's own volume) on open faces."""
        B = self.block
        self.bc.fill_zones([self.rho, self.e, self.p, self.c, self.q, self.de_h], self._inflow_values("state"))
        self.bc.fill_zones([self.M])
        self._open_ghost_mass()

    def _open_ghost_mass(self) -> None:
        g = self.block.open_ghosts
        if g.size:
            self.M[g] = self.rho[g] * self.V[g]

    def _fill_zone_vector(self, a: np.ndarray) -> None:
        B = self.block
        views = B.zview(a)
        for d in range(self.dim):
            for s in range(2):
                f = B.face[d, s]
                planes = self.bc._planes(d, s, nodes=False)
                if planes:
                    sign = None
                    if f == WALL:
                        sign = np.ones(self.dim)
                        sign[d] = -1.0
                    for dst, src in planes:
                        self.bc._copy(views, d, dst, src, sign)
                elif f == INFLOW:
                    vin = np.asarray(B.inflow[(d, s)]["velocity"], np.float64)
                    for g in self.bc.ghost_planes(d, s, nodes=False):
                        sl = [slice(None)] * 4
                        sl[d] = g
                        views[tuple(sl)] = vin
        self.halo.zones([a])

    def _constrain(self, record: bool) -> None:
        """Walls: normal velocity 0 (pistons: the piston speed); inflow faces: the inflow velocity (on
        the real face nodes)."""
        self._acc[:] = 0.0
        self.bc.constrain(self.v, self.v_old, self.m, self._acc)
        if self._blk is not None:  # immersed walls of the obstacles and their pressure reaction
            self._blk.constrain(self, record)
        if self._char is not None and record:  # the implicit part of the open faces' dashpot
            self._char.constrain(self.v, self.v_old, self.m, self.block.owned, self.dt_avg, self._acc)
        if record:
            self.b_momentum += self._acc[: self.dim]
            self.b_energy += self._acc[3]

    # ------------------------------------------------------------------------------------------
    # zone passes
    # ------------------------------------------------------------------------------------------
    def _pass(self, rng, flags: int, dt: float = 0.0, dt_avg: float = 0.0):
        B = self.block
        return self._zone_pass(self.x, self.v, self.v_old, self.fc, self.M, self.e, self.V, self.rho,
                               self.p, self.c, self.q, self.de_h, rng[0], rng[1], self.zr[0], self.zr[1],
                               B.zs, B.ns, flags, dt, dt_avg, self.eos_code, self.eos_par,
                               self.q_lin, self.q_quad, self.hg, self.q_kind, self.qgrad)

    def _check(self, res, what: str = "") -> float:
        dt_min, bad, reason = res[:3]
        if bad >= 0:
            B = self.block
            ijk = B.zone_ijk(bad)
            state = (f"rho={self.rho[bad]:.6g} kg/m^3, e={self.e[bad]:.6g} J/kg (EOS at "
                     f"{self.e[bad] + self.de_h[bad]:.6g}), p={self.p[bad]:.6g} Pa, c={self.c[bad]:.6g} m/s, "
                     f"q={self.q[bad]:.6g} Pa, V={self.V[bad]:.6g}, M={self.M[bad]:.6g} kg")
            why = _REASONS.get(reason, "failure")
            if reason == hydro.BAD_STATE:
                why = _bad_state_cause(self.rho[bad], self.e[bad] + self.de_h[bad], self.c[bad])
            self._fail(f"ALE zone {ijk}: {why}{what} at step {self.step}, "
                       f"t={self.time:.6g} s; state {state}; material {self.material!r} "
                       f"{_eos.describe(self.eos_code, self.eos_par)}")
        return float(dt_min)

    def _fail(self, msg: str) -> None:
        """One rank: raise now.  Parallel: keep the first message for the next :meth:`_sync` (every
        rank must reach it, or the others would wait in a halo exchange)."""
        if not self.dec.parallel:
            raise SolverError(msg)
        if self._error is None:
            self._error = msg

    def _check_cavitation(self) -> None:
        """A liquid (tait, stiffened_gas) with a `cavitation_pressure` whose pressure fell below it:
        the EOS would go on into tension it cannot hold (no phase change), so the run stops here
        naming cavitation (the zone, its pressure and the limit)."""
        if not self._cavitation:
            return
        zones, limits = self.block.out_zones, self._pcav
        if self.mm is None:
            p = self.p[zones]
            k = int(np.argmin(p))
            if p[k] >= limits[0]:
                return
            bad, name, pk, limit = int(zones[k]), self.material, float(p[k]), limits[0]
        else:
            pm = np.where(self.mm.vol[zones] > 0.0, self.mm.pm[zones], np.inf) - limits[None, :]
            z, m = np.unravel_index(int(np.argmin(pm)), pm.shape)
            if pm[z, m] >= 0.0:
                return
            bad, name, pk, limit = int(zones[z]), self.mm.names[m], float(self.mm.pm[zones[z], m]), limits[m]
        self._fail(f"ALE zone {self.block.zone_ijk(bad)}: material {name!r} cavitates: its pressure {pk:.6g} Pa "
                   f"is below its cavitation_pressure {limit:.6g} Pa at step {self.step}, t={self.time:.6g} s "
                   f"(the EOS has no phase change: model the cavity as void, or lower cavitation_pressure "
                   f"where the liquid holds tension)")

    def _sync(self, dt_min: float = np.inf) -> float:
        """Collective: the smallest stable step over the ranks; raises SolverError on every rank if
        one recorded a failure (its message there, the failing rank's number elsewhere)."""
        if not self.dec.parallel:
            return dt_min
        flag = 0.0 if self._error is None else -1.0 - self.dec.rank
        buf = self.dec.min(np.array([dt_min, flag]))
        if buf[1] < 0.0:
            msg, self._error = self._error, None
            raise SolverError(msg or f"ALE failure on rank {int(-buf[1]) - 1} of the ALE group at step "
                                     f"{self.step}, t={self.time:.6g} s (see that rank's error)")
        return float(buf[0])

    def _forces(self, midstep: bool, advect: bool, eos: bool, energy: bool = False) -> float:
        """(energy update,) EOS, q, hourglass and corner forces of the real zones; ghost zones;
        nodal forces and masses; returns the stable step."""
        flags = hydro.FORCES | (hydro.MIDSTEP if midstep else 0) | (hydro.ADVECT if advect else 0)
        if eos and self._blk is not None:  # rho = M / open volume (blocked.py)
            self._blk.eos(self)
            eos = False
        if eos and self.mm is not None:  # material states and the zone's mixture (mixed.py)
            self.mm.update_eos(self)
            eos = False
        flags |= (hydro.EOS if eos else 0) | (hydro.ENERGY if energy else 0)
        if self.q_kind == hydro.Q_MONOTONIC:  # at the mid-step geometry x - dt/2 v in a Lagrange step
            self._mono_grad(self.x, self.v, self.qgrad, 0.5 * self.dt if midstep else 0.0, *self._zall,
                            self.block.zs, self.block.ns)
        res = self._pass(self.zr, flags, self.dt, self.dt_avg)
        dt_min = self._check(res)
        self._limiter = (dt_min, int(res[3]), "sound speed")   # this rank's: step_limiter() names it
        if self._blk is not None:  # face apertures of the cut zones
            dt_cut, at = self._blk.apertures(self)
            if dt_cut < dt_min:
                dt_min = dt_cut
                self._limiter = (dt_min, at, "cut zone")
        self._fill_zone_state()
        if self._char is not None:  # the exterior's pressure on the characteristic faces
            self._char.ghost_pressure()
        self._check_cavitation()
        B = self.block
        if self.has_images:  # periodic images carry their image's corner forces exactly
            self.bc.fill_zones([self.fc], depth=1)  # (the gather reads one ghost layer)
        elif self.has_cuts:
            self.halo.zones([self.fc], depth=1)
        if self.open_faces:
            gflags = hydro.FORCES | (hydro.MIDSTEP if midstep else 0)
            for d, s in self.open_faces:
                lo, hi = self.z1[0].copy(), self.z1[1].copy()
                g = 1 if s == 0 else int(B.n3[d]) + GHOST
                lo[d], hi[d] = g, g + 1
                self._check(self._pass((lo, hi), gflags, self.dt, self.dt_avg), " (boundary ghost zone)")
        bn = self._open_nodes
        if bn.size:
            m_before = self.m[bn].copy()
        self._gather(self.fc, B.zact, self.M, self.f, self.m, self.nr[0], self.nr[1], B.zs, B.ns)
        if self._char is not None:
            self._char.add_normal_force(self.f)
        self.bc.fill_nodes_scalar(self.m)
        if bn.size and not self._initialising:
            # refilled open ghost zones change the mass of the boundary nodes' dual cells
            dm = self.m[bn] - m_before
            vb = self.v[bn]
            self.b_momentum += (dm[:, None] * vb).sum(axis=0)
            self.b_energy += 0.5 * float(np.sum(dm * np.sum(vb * vb, axis=1)))
        return self._sync(dt_min)

    # ------------------------------------------------------------------------------------------
    # time stepping
    # ------------------------------------------------------------------------------------------
    def stable_dt(self) -> float:
        if self._pending_remap:
            self.remap()
        return self._dt_stable

    def local_limiter(self) -> dict | None:
        """The zone of this rank that sets its stable step: "sound speed" (its Courant limit
        l / (|u| + Q + sqrt(Q^2 + c^2))) or "cut zone" (a zone a body's surface cuts, by its aperture
        corrected compression), with its (i, j[, k]), centre, state and open fraction."""
        dt, z, kind = getattr(self, "_limiter", (np.inf, -1, ""))
        if z < 0:
            return None
        B = self.block
        ijk = B.zone_ijk(z)
        centre = [float(B.lower[d] + (ijk[d] + 0.5) * B.h[d]) for d in range(self.dim)]
        detail = (f"c = {self.c[z]:.4g} m/s, rho = {self.rho[z]:.4g} kg/m^3, p = {self.p[z]:.4g} Pa, "
                  f"q = {self.q[z]:.4g} Pa")
        if self._blk is not None:
            detail += f", open fraction {float(self._blk.phi[z]):.3g}"
        return {"dt": float(dt), "kind": kind, "what": f"zone {ijk}", "at": centre, "detail": detail}

    def predict(self, dt: float) -> None:
        if self._pending_remap:
            self.remap()
        self.dt = float(dt)
        self.dt_avg = 0.5 * self.dt if self.first_step else 0.5 * (self.dt_prev + self.dt)
        B = self.block
        hydro.predict(self.v, self.v_old, self.f, self.m, self.nr[0], self.nr[1], B.ns, self.dt_avg)

    def interface(self):
        """The coupled bodies' interface after predict (collective): on rank 0 the predictor velocity
        v* and the mass of every node the coupler asked for (BodyGeometry.nodes) and the net force
        sum_c f_c of every cut zone (BodyGeometry.cut) and the fill of every cut zone (the share of
        its open volume that is not void: 1 without void), as one buffer [v* (nn, dim), m (nn),
        R (nc, dim), fill (nc)]; None on the other ranks.  Each value comes from the rank that owns
        it (zeros elsewhere, summed: the same bits on any number of ranks)."""
        blk, dim = self._blk, self.dim
        n, inside, owned = blk.nodes
        nc = blk.n_cut
        buf = np.zeros(n.size * (dim + 1) + nc * (dim + 1))
        buf[: n.size * dim].reshape(-1, dim)[owned] = self.v[n[owned]]
        buf[n.size * dim: n.size * (dim + 1)][owned] = self.m[n[owned]]
        a = n.size * (dim + 1)
        buf[a: a + nc * dim].reshape(-1, dim)[blk.cut_rows] = blk.cut_forces(self)
        buf[a + nc * dim:][blk.cut_rows] = self._fill(blk.cut)
        if self.dec.parallel:
            out = np.empty_like(buf) if self.dec.rank == 0 else None
            self.dec.comm.Reduce(buf, out, root=0)
            return out
        return buf

    def _fill(self, zones: np.ndarray) -> np.ndarray:
        """The share of each zone's open volume held by a material (not void): 1 without void."""
        from solvers.ale.mixed import VOID

        mm = self.mm
        if mm is None or not mm.has_void:
            return np.ones(zones.size)
        vol = mm.vol[zones]
        total = vol.sum(axis=1)
        void = vol[:, mm.code == VOID].sum(axis=1)
        return np.where(total > 0.0, 1.0 - void / np.where(total > 0.0, total, 1.0), 0.0)

    def correct(self, impulse=None, step: int = 0, time: float = 0.0, coupling=None) -> None:
        """Close the step (see the module docstring); ``step`` and ``time`` (after the step) name
        failures.  ``coupling`` (coupled bodies, the same on every rank): {"impulse": (nn, dim) on the
        nodes asked for, "v_half": (nc, dim) v^{n+1/2} and "v_bar": (nc, dim) (v^{n-1/2} + v^{n+1/2})/2
        of the body surface in every cut zone} (blocked.Blocked.body_terms).  ``impulse``: the
        same impulse given as {"nodes": global node ids, "impulse": (nn, dim)}."""
        B = self.block
        self.step, self.time = int(step), float(time)
        applied = []
        if coupling is not None:
            n, inside, owned = self._blk.nodes
            applied.append(self._node_impulse(n, inside, owned, np.asarray(coupling["impulse"]).reshape(-1, self.dim)) + (True,))
        if impulse is not None:
            from solvers.ale.coupled import GlobalIndex
            n, inside, owned = GlobalIndex(B).nodes(np.asarray(impulse["nodes"], np.int64))
            applied.append(self._node_impulse(n, inside, owned, np.asarray(impulse["impulse"]).reshape(-1, self.dim)) + (False,))
        self._constrain(record=True)
        for nodes, imp, interface in applied:  # (their work on the final mean velocity: see _node_impulse)
            self._impulse_balance(nodes, imp, interface)
        self.bc.fill_nodes_vector(self.v)
        if self._char is not None:  # the faces' transverse terms and relaxation over the step
            self._char.advance(self.dt)  # (after the fill: the velocities of the face zones at cuts)
        if not np.all(np.isfinite(self.v)):
            n = int(np.flatnonzero(~np.all(np.isfinite(self.v), axis=1))[0])
            self._fail(f"non-finite velocity at ALE node {self._node_ijk(n)} at step {self.step}, "
                       f"t={self.time:.6g} s")
        if self.open_faces:
            self._gw[:] = 0.0
            hydro.ghost_force_work(self.fc, B.zkind, self.v, self.v_old, B.owned, self.z1[0], self.z1[1],
                                   B.zs, B.ns, Z_OPEN, self._gw)
            self.b_momentum += self.dt_avg * self._gw[: self.dim]
            self.b_energy += self.dt_avg * self._gw[3]
        if self._char is not None:
            imp, work = self._char.normal_force_terms(self.v, self.v_old, B.owned, self.dt_avg)
            self.b_momentum += imp
            self.b_energy += work
        hydro.move(self.x, self.v, self.dt)
        if self.mode == "lagrangian":
            self._dt_stable = self._forces(midstep=True, advect=False, eos=True, energy=True)
        else:
            # energy update of the real zones; their Lagrangian volumes follow from the remap's
            # swept volumes
            hydro.energy_update(self.fc, self.v, self.v_old, self.e, self.M, self.zr[0], self.zr[1],
                                B.zs, B.ns, self.dt_avg)
            if coupling is not None:
                rows = self._blk.cut_rows
                vh = np.asarray(coupling["v_half"]).reshape(-1, self.dim)[rows]
                vb = np.asarray(coupling["v_bar"]).reshape(-1, self.dim)[rows]
                crossed = self._blk.body_terms(self, vh, vb)
                self.b_momentum += crossed[: self.dim]
                self.b_energy += crossed[self.dim]
                self.i_momentum += crossed[: self.dim]
                self.i_energy += crossed[self.dim]
            self._pending_remap = True
        self.first_step = False
        self.dt_prev = self.dt

    def _node_impulse(self, n, inside, owned, imp):
        """v += impulse / m on the real nodes of this block listed (every copy of a node, so that the
        ranks sharing it stay equal).  A node without mass takes no impulse (the coupler leaves such
        nodes out of the constraint).  Returns (owned nodes, their impulses) for the balances."""
        idx = n[inside]
        m = self.m[idx]
        ok = m > 0.0
        self.v[idx[ok]] += imp[inside][ok] / m[ok, None]
        return n[owned], imp[owned]

    def _impulse_balance(self, nodes, imp, interface: bool) -> None:
        """An impulse's momentum and its work on the mean velocity (v^{n-1/2} + v^{n+1/2})/2, with
        v^{n+1/2} the final one (after the boundary constraints): only then do the force, impulse and
        constraint work add up to the exact kinetic energy change when an impulse and a constraint
        act on the same component."""
        vb = 0.5 * (self.v[nodes] + self.v_old[nodes])
        dp = imp.sum(axis=0)
        de = float(np.sum(imp * vb))
        self.b_momentum += dp
        self.b_energy += de
        if interface:
            self.i_momentum += dp
            self.i_energy += de

    def remap(self, blocked=None) -> None:
        """Eulerian mode: remap the Lagrangian state back to the fixed grid.

        ``blocked``: the coupled bodies' geometry after the step (solvers/ale/coupled.BodyGeometry:
        ids and blocked fractions of the zones they cover, exact face apertures, cut zones; or None),
        combined with the case's static obstacles (the larger fraction); the remap then never moves
        material into the blocked part (solvers/ale/blocked.py).
        """
        if self.mode != "eulerian" or not self._pending_remap:
            if blocked is not None and self.mode != "eulerian" and blocked.blocks_anything():
                raise ValueError("blocked volume fractions need mode = 'eulerian'")
            return
        if self._blk is None and blocked is not None and blocked.blocks_anything():
            from solvers.ale.blocked import Blocked
            self._blk = Blocked(self)
        if self._blk is not None:
            self._blk.remap(self, blocked)
            return
        B, dim = self.block, self.dim
        # swept volumes of the real faces of every direction (planes 2 .. n+2)
        for d in range(dim):
            lo, hi = self.zr[0].copy(), self.zr[1].copy()
            hi[d] += 1
            self._swept(B.X, self.x, self.SV[d], d, lo, hi, B.zs, B.ns)
            self.bc.fill_zones([self.SV[d]], face_dir=d)
        # Lagrangian volumes and densities of the real zones
        bad = hydro.lagrangian_volumes(self.SV, self.V, self.M, self.rho, self.p, self.q, self.de_h,
                                       self.zr[0], self.zr[1], B.zs)
        if bad >= 0:
            self._check((0.0, bad, hydro.BAD_VOLUME), " (Lagrangian grid)")
        self._sync()
        if self.mm is not None:  # share the step's energy and volume change over the materials
            self.mm.lagrange_step(self)
            self.mm.hold_shift()
        if self._char is not None:  # the exterior state the faces' motion makes: remap donors
            self._char.donors()
        self._fill_remap_zones()
        order = range(dim) if self.parity == 0 else range(dim - 1, -1, -1)
        for d in order:
            self._sweep(d)
        if self.mm is not None:
            self.mm.spread_shift()
            self.mm.cut_off_vacuum(self)
            self.mm.relax_pressures(self)
        remap.set_positions(self.x, B.X)
        self.parity ^= 1
        self._pending_remap = False
        self._dt_stable = self._forces(midstep=False, advect=True, eos=True)

    def _fill_remap_zones(self) -> None:
        B = self.block
        self.bc.fill_zones([self.rho, self.e], self._inflow_values("remap"))
        if self._char is not None:
            self._char.apply_donors()
        self.bc.fill_zones([self.M, self.V])
        self._open_ghost_mass()
        if self.mm is not None:
            self.mm.fill(self)
            if self._char is not None:
                self._char.apply_material_donors()

    def _sweep(self, d: int) -> None:
        """One direction of the remap.  Obstacles (blocked.py): the aperture-scaled face volumes,
        solid zones as wall ghosts, zones and nodes without material; void (mixed.py): nodes and
        zones without material."""
        B = self.block
        s = int(B.zs[d])
        blk = self._blk
        solid = None if blk is None else blk.solid
        massless = blk is not None or (self.mm is not None and self.mm.has_void)
        Mz = self.M if massless else None
        if self.mm is not None:  # material fluxes (interface reconstruction), zone sums
            self.mm.sweep(self, d)
        else:
            sv = self.SV[d] if blk is None else blk.ASV[d]
            # fluxes of the real faces (planes 2 .. n+2), ghost faces by the face fill
            lo, hi = self.zr[0].copy(), self.zr[1].copy()
            hi[d] += 1
            remap.sweep_fluxes(self.rho, self.e, self.M, self.V, sv, self.F, self.ES, solid, s, lo, hi, B.zs)
            if blk is not None:  # a body's cut zones: their faces' fluxes from the Lagrangian state
                blk.cut_face_fluxes(self, d)
            self.bc.fill_zones([self.F, self.ES], face_dir=d)
            self._boundary_fluxes(d)
            remap.sweep_zones(self.rho, self.e, self.M, self.V, sv, self.F, self.ES, solid, s,
                              self.zr[0], self.zr[1], B.zs)
        self._fill_remap_zones()
        # nodes: dual faces of nodes 2 .. n+3 along d, then the real nodes
        nlo, nhi = self.nr[0].copy(), self.nr[1].copy()
        nhi[d] += 1
        remap.sweep_dual(self.F, B.zact, solid, self.v, self.m, self.PHI, self.VS, d, nlo, nhi, B.zs, B.ns)
        bn = self._open_nodes
        if bn.size:
            m0, v0 = self.m[bn].copy(), self.v[bn].copy()
        if blk is not None and blk.hold is not None:  # (a body's cut zones: their nodes at the end)
            remap.sweep_nodes(self.v, self.m, self.M, B.zact, self.PHI, self.VS, self.dK, d,
                              self.nr[0], self.nr[1], B.zs, B.ns, massless, *blk.hold)
        else:
            remap.sweep_nodes(self.v, self.m, self.M, B.zact, self.PHI, self.VS, self.dK, d,
                              self.nr[0], self.nr[1], B.zs, B.ns, massless)
        if bn.size:
            self._open_node_terms(d, m0, v0)
        e0 = self.e.copy() if self.mm is not None else None
        remap.deposit(self.e, self.m, self.dK, self.zr[0], self.zr[1], B.zs, B.ns, self.dim, Mz)
        if self.mm is not None:  # the kinetic-energy defect goes to every material of the zone
            self.mm.deposit_energy(self, self.e - e0)
        self.bc.fill_nodes_vector(self.v)
        self.bc.fill_nodes_scalar(self.m)
        self.bc.fill_zones([self.e], self._inflow_values("energy"))
        if self._char is not None:
            self._char.apply_donors(energy_only=True)

    def _open_node_terms(self, d: int, m0: np.ndarray, v0: np.ndarray) -> None:
        """Exact balance terms of the nodal remap at open faces: momentum and kinetic energy through
        the outer dual faces, the momentum of the dual-cell mass the refilled ghost zones add
        (m' - m - Phi_lo + Phi_hi) v, and the part of the kinetic-energy defect that falls to ghost
        zones (1 - w) dK, w = real-zone mass share of the node."""
        B = self.block
        bn = self._open_nodes
        nsd = int(B.ns[d])
        dm = self.m[bn] - m0 - self.PHI[bn] + self.PHI[bn + nsd]
        self.b_momentum += (dm[:, None] * v0).sum(axis=0)
        zl = self._open_nodes_z
        # a massless node (void or a blocked corner at the face) has no defect: share 1, not 0/0
        m = self.m[bn]
        w = np.divide((self.M[zl] * self._real_f[zl]).sum(axis=1) / (2 ** self.dim), m,
                      out=np.ones_like(m), where=m > 0.0)
        self.b_energy -= float(np.sum((1.0 - w) * self.dK[bn]))
        for (dd, s), nodes in self._open_face_nodes.items():
            if dd != d:
                continue
            k = nodes if s == 0 else nodes + nsd
            sign = 1.0 if s == 0 else -1.0
            ph, vs = self.PHI[k], self.VS[k]
            self.b_momentum += sign * (ph[:, None] * vs).sum(axis=0)
            self.b_energy += sign * 0.5 * float(np.sum(ph * np.sum(vs * vs, axis=1)))

    def _boundary_fluxes(self, d: int) -> None:
        """Mass and energy (internal + kinetic, momentum) advected through open faces (balances)."""
        B = self.block
        for s in range(2):
            if B.face[d, s] not in (OUTFLOW, INFLOW):
                continue
            n = int(B.n3[d])
            plane = GHOST if s == 0 else n + GHOST
            sl = [slice(int(a), int(b)) for a, b in zip(*self.zr)]
            sl[d] = plane
            sl = tuple(sl)
            F = B.zview(self.F)[sl]
            ES = B.zview(self.ES)[sl]
            self.b_mass += float(F.sum()) * (1 if s == 0 else -1)
            self.b_energy += float((F * ES).sum()) * (1 if s == 0 else -1)
