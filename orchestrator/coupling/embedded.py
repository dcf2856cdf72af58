"""The coupler's share of a coupled step of the embedded-mesh method (DESIGN.md "The adapter
contract", "The constraint solve"): bodies of a foreground solver immersed in the background grid.

Per step n -> n+1, the coupler holds the geometry of the bodies at x^n (pieces, operators) and
(messages in adapters/protocol.py, hook order):

1. after both groups' ``predict``: the foreground's predictor velocities v*_f of its surface nodes
   and the background's v*_b, masses m_b of the nodes the geometry named, and the net corner force
   R_e = sum_c f_c of every cut zone (the fluid's reaction on the body surface in it: with exact
   face apertures sum_c b^A_c = a_e, the surface's area vector, so R_e = (p + q)_e a_e);
2. :meth:`EmbeddedCoupling.solve`: the fluid's load on the body -R_e, spread over the surface
   nodes by B^f_eA / A_e (consistent: a uniform traction over Gamma_e), enters v*_f as the impulse
   dt_avg F (the background got +R_e through its own corner forces: equal and opposite); then the
   variant's constraint solve (multiplier / penalty / nitsche, orchestrator/coupling/variants.py)
   on the loaded predictor velocities gives impulses -dt B^bT lambda to the background nodes and
   +dt B^fT lambda to the surface nodes;
3. the foreground corrects and returns x^{n+1}, v^{n+1/2} of its surface nodes;
   :meth:`EmbeddedCoupling.background_correction`: the background's node impulses and, per cut zone,
   the surface velocity v^{n+1/2}_e and the mean (v^{n-1/2} + v^{n+1/2})_e / 2 (B^f-weighted means):
   the background adds the work of R on the surface and the volume the surface sweeps
   (solvers/ale/blocked.py ``body_terms``);
4. :meth:`EmbeddedCoupling.geometry` at x^{n+1}: clipped pieces, exact blocked fractions and face
   coverages, operators of the next step; the background's remap takes the fractions.

Everything here is in the coupler's canonical orders (sorted global ids), so results do not depend
on how many ranks either group runs on.  Foreground velocity components a boundary condition
prescribes count as infinitely heavy in the solve (the condition overrides any impulse on them: the
constraint must be met by the other side; see ``_solve_masses``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orchestrator.coupling import variants
from orchestrator.coupling.geometry import clip_surface, coverage
from orchestrator.coupling.grid import Grid
from orchestrator.coupling.operator_rows import (correction_means, facing_the_grid, impulse_sums, oscillation,
                                                 row_means, surface_load)
from orchestrator.coupling.operators import Operators, restrict
from orchestrator.coupling.orphan_particles import find_orphans, may_tie, tie


@dataclass
class StepRecord:
    """What a step exchanged (the coupler's diagnostics)."""

    momentum_f: np.ndarray  # impulse on the foreground (load + constraint)
    work_f: float  # its work on the surface nodes' mean velocity
    iterations: int = 0
    residual: float = 0.0
    dissipation: float = 0.0


def background_modulus(ale: dict) -> float:
    """The largest rho c^2 (Pa) of the background's initial states (regions with a pressure): the
    modulus K of the Nitsche stiffness gamma K / h, an upper bound over the gas the bodies meet."""
    from solvers.ale import eos as E

    best = 0.0
    for r in ale.get("regions", []):
        if "density" not in r or "pressure" not in r:
            continue
        props = dict(ale["materials"][r["material"]])
        code, par = E.eos_params(props.pop("eos"), props)
        rho, p = float(r["density"]), float(r["pressure"])
        e = float(E.energy_from_pressure(code, par, rho, p))
        _, c, ok = E.state(code, par, rho, e)
        if ok:
            best = max(best, rho * float(c) ** 2)
    return best


def multiplier_oscillation(lam, pairs, normal) -> float:
    """Zone-to-zone spread of the multipliers: the mean |λ_i - λ_j| over face-adjacent cut zones of
    the same side of a surface (normals within 60 degrees: the two faces of a thin wall carry
    different loads) relative to the mean |λ| (0 for a smooth field; the unstabilised solve gives
    ~1.5 on a straight line with uniform masses, the stabilised one 0.02: coupling.solve.BETA).
    (One kernel, operator_rows.oscillation: the numpy form cost ~25 us a step in call overhead.)"""
    if lam is None or len(pairs) == 0:
        return 0.0
    lam = np.ascontiguousarray(np.asarray(lam, dtype=np.float64).reshape(len(lam), -1))
    return float(oscillation(lam, np.ascontiguousarray(pairs, dtype=np.int64),
                             np.ascontiguousarray(normal, dtype=np.float64)))


class EmbeddedCoupling:
    def __init__(self, case: dict, surface: dict):
        self.grid = Grid.from_ale(case["ale"])
        self.dim = self.grid.dim
        self.method = variants.make(case["coupling"])
        self.state = self.method.new_state()
        self.modulus = background_modulus(case["ale"])
        self.stable_limit = np.inf  # the variant's own explicit step limit, smallest over the run
        self.cond_H = np.nan  # cond(H) of the multiplier system at the first step with an interface
        self.lambda_oscillation = 0.0  # zone-to-zone spread of the multipliers this step (see solve)
        self.lambda_oscillation_max = 0.0
        self.void_zones = 0  # cut zones left without a constraint this step (mostly void: variants.MIN_FILL)
        self.orphans = None  # particles outside the reconstructed surface (orphan_particles.py)
        self.tied_orphans = 0  # of them, those tied to the background this step
        self.facets = np.ascontiguousarray(surface["facets"], dtype=np.int64)
        self.body = np.ascontiguousarray(surface["body"], dtype=np.int64)
        self.n_bodies = int(self.body.max()) + 1 if self.body.size else 0
        # a particle foreground (SPH): no facets; its surface is reconstructed every step from the
        # particles (their volumes and kernel support h), B^f over particles (particle_operators.py)
        self.volume = surface.get("volume")
        self.particles = self.volume is not None
        if self.particles:
            self.volume = np.asarray(self.volume, dtype=np.float64).copy()
            self.h = float(surface["smoothing_length"])
            self.n_bodies = 1
        # particles outside the reconstructed surface are looked for only where some could be tied
        # (the lightest particle is the easiest to tie)
        self.find_orphans = bool(self.particles and self.volume.size and may_tie(
            case["ale"], float(np.min(np.asarray(surface["mass"], dtype=np.float64) / self.volume))))
        self._take_nodes(surface)
        self.ops = None
        # multi-rate (multirate.py): this step's substeps of the foreground, its passes of them and how
        # far the accepted pass's mean velocity was from the constraint's (m/s)
        self.substeps, self.c, self.substep_passes, self.substep_residual = 1, 1.0, 0, 0.0
        # the body's last force per surface node (I / dt_avg: its ramp's start, multirate.Ramp), its
        # last mean velocity over a step, and the impulse it got ahead of the background (in transit)
        self.force_prev = None
        self.transit = np.zeros(self.dim)
        self.transit_work = 0.0
        self.impulse_size = 0.0
        self.last = StepRecord(np.zeros(self.dim), 0.0)
        # accumulated over the run (coupler diagnostics)
        self.momentum_f = np.zeros(self.dim)
        self.work_f = 0.0
        self.dissipation = 0.0

    def _take_nodes(self, surface: dict) -> None:
        """The surface nodes' masses, free components, positions and velocities, and the arrays
        sized by them."""
        self.mass = np.asarray(surface["mass"], dtype=np.float64)
        free = np.asarray(surface["free"]).reshape(-1, self.dim)
        self.free = (free > 0.0).astype(np.float64)
        self.m_solve = self.mass.copy()
        self.x = np.asarray(surface["x"], dtype=np.float64).reshape(-1, self.dim).copy()
        self.v = np.asarray(surface["v"], dtype=np.float64).reshape(-1, self.dim).copy()
        self.v_mean = self.v            # (the last step's mean surface velocity: multirate.py)
        self.force_prev = None          # (the body's last force per surface node: a new surface has none)
        self.ns = self.x.shape[0]
        self.load_f = np.zeros_like(self.x)
        self.imp_f = np.zeros_like(self.x)

    def replace_surface(self, surface: dict) -> None:
        """A Lagrangian foreground's surface after elements eroded (its live elements'): the facets
        and the nodes' arrays; the next geometry() builds the operators on it.  The multipliers' warm
        start is kept (per cut zone, not per node)."""
        if self.particles:
            raise ValueError("a particle foreground's surface is rebuilt every step, never replaced")
        self.facets = np.ascontiguousarray(surface["facets"], dtype=np.int64)
        self.body = np.ascontiguousarray(surface["body"], dtype=np.int64)
        self._take_nodes(surface)

    # ---- geometry --------------------------------------------------------------------------------
    def geometry(self):
        """Pieces, fractions, face coverages and operators at the current surface positions; returns
        the background's solvers.ale.coupled.BodyGeometry."""
        from solvers.ale.coupled import BodyGeometry

        if self.particles:
            from orchestrator.coupling.particle_operators import particle_interface

            # (its kernels give the coverage and the operators too: particle_operators.py, "Cost")
            pi = particle_interface(self.grid, self.x, self.volume, self.h)
            pieces, cov = pi.pieces, pi.coverage
        else:
            pieces = clip_surface(self.grid, self.x, self.facets, self.body)
            cov = coverage(self.grid, pieces, self.n_bodies)
        total = cov.total   # (bodies do not overlap: sums of disjoint parts)
        faces = tuple((ids, t) for (ids, _), t in zip(cov.faces, cov.face_totals))
        if not self.particles:
            inner = facing_the_grid(self.grid, pieces)
        # B^b over every corner of a cut zone (the bilinear interpolation of the gas velocity on
        # Gamma_e): the constraint ties the gas nodes in front of the surface too, so the interface
        # carries the gas's inertia.  An earlier form kept only the corners behind the surface: a
        # light body in water (rho 500, E 5e8 against rho c^2 = 2.2e9 Pa) then oscillated with period
        # two steps at dt_scale 0.9 (the gas's stiffness on the body's surface mass alone), stable
        # with every corner; and the shipped cases are as accurate or more (oblique_slip_wall normal
        # velocity 1.26e-2 -> 7.7e-3, embedded_piston_sod velocity 1.16e-2 -> 7.9e-3)
        self.ops = pi.ops if self.particles else Operators.build(self.grid, inner, self.facets, self.ns)
        self.pieces = pieces
        Bf = self.ops.Bf
        velocity = row_means(Bf.indptr, Bf.indices, Bf.data, self.v, self.ops.area)  # the surface's, per cut zone
        # the nodes the next solve needs: the constraint's, and (particles) the corners of the zones
        # of particles the reconstruction left out, tied point by point (orphan_particles.py)
        self.nodes = self.ops.bnodes
        self.orphans = None
        if self.find_orphans:
            orph = find_orphans(self.grid, self.x, cov)
            if orph.size:
                self.orphans = orph
                self.nodes = np.union1d(self.ops.bnodes, orph.nodes.ravel())
        # (no orphans: every node is the constraint's, in its order -- a slice, no copies per step)
        self.constraint_rows = (np.searchsorted(self.nodes, self.ops.bnodes) if self.orphans is not None
                                else slice(None))
        return BodyGeometry(cov.zones, total, faces, self.ops.zones, self.nodes, velocity, cov.run_start,
                            cov.run_length)

    def load_kernels(self) -> None:
        """Load the step's numba kernels (solve, correction) before the time loop: the first call of
        each reads it from numba's cache (~60 ms for the multiplier solve's, measured), a cost of the
        coupler's start-up that would otherwise land on the first coupled step.  Runs them on zero
        velocities with the current operators and a throwaway method state: nothing of this
        coupling's state changes."""
        ops, dim = self.ops, self.dim
        if ops is None or ops.n_zones == 0:
            return
        nb, nc = ops.bnodes.size, ops.zones.size
        zero_f = np.zeros((self.ns, dim))
        load, v_f = surface_load(ops.Bf.indptr, ops.Bf.indices, ops.Bf.data, np.zeros((nc, dim)), ops.area, self.ns,
                                 0.0, zero_f, self.free, np.ascontiguousarray(self.mass))
        impulse_sums(load, zero_f)
        correction_means(ops.Bf.indptr, ops.Bf.indices, ops.Bf.data, ops.area, self.v, self.v, zero_f)
        multiplier_oscillation(np.zeros((nc, 1)), ops.pairs, ops.normal)
        try:
            self.method.step(ops, np.zeros((nb, dim)), np.ones(nb), v_f, self._solve_masses(ops), 1.0,
                             self.method.new_state(), self.modulus)
        except Exception:   # (loading only: the step itself reports whatever this would have)
            pass

    # ---- the step ----------------------------------------------------------------------------------
    def solve(self, dt: float, dt_avg: float, vstar_f: np.ndarray, background: np.ndarray, substeps: int = 1,
              predicted: np.ndarray | None = None, mobility: float = 1.0) -> np.ndarray:
        """Steps 1-2 of the module docstring: returns the foreground's surface impulses (ns, dim);
        keeps the background's for :meth:`background_correction`.  A foreground in ``substeps`` > 1
        substeps (multirate.py) gives as ``vstar_f`` a pass's mean velocities under the interface
        impulses ``predicted``; their rigid answer to the impulses is ``mobility`` / m: the solve then
        sees its masses M / mobility and the predictor vstar_f - mobility M^-1 predicted."""
        self.dt_last = dt_avg   # (the interface force: the impulse of the leapfrog kick at t^n / its dt_avg)
        ops, dim = self.ops, self.dim
        self.substeps = int(substeps)
        self.c = float(mobility) if self.substeps > 1 else 1.0
        mass = self.mass
        if self.substeps > 1:
            mass = self.mass / self.c
            pred = np.zeros_like(vstar_f) if predicted is None else predicted
            vstar_f = vstar_f - pred * self.free / mass[:, None]
        nn, nb, nc = self.nodes.size, ops.bnodes.size, ops.zones.size
        v_all = background[: nn * dim].reshape(nn, dim)
        m_all = background[nn * dim: nn * (dim + 1)]
        a = nn * (dim + 1)
        R = background[a: a + nc * dim].reshape(nc, dim)
        fill = background[a + nc * dim:]   # (absent: no void)
        v_b, m_b = v_all[self.constraint_rows], m_all[self.constraint_rows]
        # the fluid's load on the body: -R_e over Gamma_e, consistent nodal forces B^f_eA / A_e, and
        # the loaded predictor velocities v_f = v*_f + load free / m (one pass over the surface nodes:
        # a particle body's are all its particles)
        load, v_f = surface_load(ops.Bf.indptr, ops.Bf.indices, ops.Bf.data, np.ascontiguousarray(R), ops.area,
                                 self.ns, float(dt_avg), np.ascontiguousarray(vstar_f, dtype=np.float64), self.free,
                                 np.ascontiguousarray(mass))
        self.m_solve = self._solve_masses(ops, mass)
        # the constraint where the gas is (variants.MIN_FILL); the load above over every cut zone
        self.void_zones = int(np.count_nonzero(fill < self.method.min_fill)) if fill.size else 0
        if self.void_zones:
            ops = restrict(ops, fill >= self.method.min_fill)
        self.stable_limit = min(self.stable_limit, self.method.stable_dt(ops, m_b, self.m_solve, self.modulus))
        # in substeps the stabilisation keeps the compliance it has at the substeps' step (multirate.py, 4)
        stab = {"stab_scale": 1.0 / self.substeps} if self.substeps > 1 else {}
        if np.isnan(self.cond_H) and ops.n_zones:
            # once: what the stabilisation is for (s_con = λmax/λmin independent of h when stabilised)
            self.cond_H = self.method.condition_number(ops, m_b, self.m_solve, dt, **stab)
        if ops.n_zones:
            res = self.method.step(ops, v_b, m_b, v_f, self.m_solve, dt, self.state, self.modulus, **stab)
        else:  # no constraint anywhere (a body in void, or out of the gas): no multiplier to carry on
            res = variants.StepResult(np.zeros((nb, dim)), np.zeros((self.ns, dim)), {})
            self.state = self.method.new_state()
        self.lambda_oscillation = multiplier_oscillation(self.state.lam, ops.pairs, ops.normal)
        self.lambda_oscillation_max = max(self.lambda_oscillation_max, self.lambda_oscillation)
        if self.orphans is None:
            self.imp_b = res.impulse_b
        else:
            self.imp_b = np.zeros((nn, dim))
            self.imp_b[self.constraint_rows] = res.impulse_b
        imp_f, removed = res.impulse_f, 0.0
        self.tied_orphans = 0
        if self.orphans is not None:
            imp_f, removed = self._tie_orphans(v_f, imp_f, v_all, m_all)
        imp, total = impulse_sums(load, np.ascontiguousarray(imp_f, dtype=np.float64))
        self.imp_f = imp
        diag = res.diagnostics
        self.last = StepRecord(total, 0.0, int(diag.get("iterations", 0)), float(diag.get("residual", 0.0)),
                               float(diag.get("interface_dissipation", 0.0)) + removed)
        return imp

    # ---- multi-rate: the substeps' passes (multirate.py) -------------------------------------------------
    def impulses(self) -> tuple:
        """The impulses of the last solve (surface, background nodes, the step's record) for
        :meth:`take_impulses` and :meth:`relax`."""
        rec = self.last
        return (self.imp_f, self.imp_b, StepRecord(rec.momentum_f.copy(), rec.work_f, rec.iterations, rec.residual,
                                                   rec.dissipation))

    def take_impulses(self, saved: tuple) -> None:
        """Take back what :meth:`impulses` gave (the pass the coupler accepts)."""
        self.imp_f, self.imp_b, self.last = saved

    def relax(self, saved: tuple, omega: float) -> None:
        """The impulses of a relaxed pass: saved + omega (the last solve's - saved), on the surface and
        the background nodes alike (both linear in the multipliers, the load the same): what one
        side gets the other gets opposite, as in a solve."""
        f, b, rec = saved
        self.imp_f = f + omega * (self.imp_f - f)
        self.imp_b = b + omega * (self.imp_b - b)
        self.last.momentum_f = rec.momentum_f + omega * (self.last.momentum_f - rec.momentum_f)
        self.last.dissipation = rec.dissipation + omega * (self.last.dissipation - rec.dissipation)

    def mean_velocity_defect(self, impulse: np.ndarray) -> np.ndarray:
        """How far the last solve wants the substeps' mean velocity from the one of the pass run with
        ``impulse``: c (its impulses - impulse) / m on the free components (m/s, per node)."""
        return (self.imp_f - impulse) * self.free * (self.c / self.mass[:, None])

    def accept_ramp(self, ramp, impulse: np.ndarray) -> None:
        """The accepted pass's ramp (multirate.Ramp) for ``impulse``: the body's force for the next
        ramp, and what it got beyond the background (momentum in transit)."""
        self.transit = self.transit + (ramp.total(impulse) - impulse).sum(axis=0)
        self.force_prev = impulse / ramp.dt_avg

    def _tie_orphans(self, v_f, imp_f, v_all, m_all):
        """The particles outside the reconstructed surface tied to the background's velocity after the
        constraint's impulses (orphan_particles.tie); returns the particles' impulses with theirs
        added (the nodes' go into imp_b) and the kinetic energy the tie removed."""
        o = self.orphans
        i = o.index
        u_p = v_f[i] + imp_f[i] / self.mass[i, None]
        m_safe = np.where(m_all > 0.0, m_all, 1.0)
        u_b = v_all + np.where(m_all[:, None] > 0.0, self.imp_b / m_safe[:, None], 0.0)
        cols = np.searchsorted(self.nodes, o.nodes)
        J, imp_nodes, self.tied_orphans, removed = tie(o, cols, u_p, self.mass[i], self.mass[i] / self.volume[i],
                                                       u_b, m_all, self.grid.zone_volume)
        imp_f = np.array(imp_f, dtype=np.float64, copy=True)
        imp_f[i] += J
        self.imp_b += imp_nodes
        return imp_f, removed

    def _solve_masses(self, ops, mass: np.ndarray | None = None) -> np.ndarray:
        """The surface nodes' masses as the solve sees them, with the components a boundary condition
        prescribes taken out (the condition undoes any impulse on them): `tied` -- a node with any
        prescribed component is immovable (inf); `slip` -- the constraint acts along the cut zones'
        normals n_e: the node's inverse mass along them, sum_c w_c free_c / m with w_c the
        B^f-weighted mean of n_ec^2 over its zones (exact for axis-aligned normals), inf when none
        of those components is free."""
        free = self.free
        mass = self.mass if mass is None else mass
        if np.all(free > 0.0):
            return mass
        if self.method.condition != "slip":
            return np.where(np.all(free > 0.0, axis=1), mass, np.inf)
        Bf = ops.Bf.tocsc()
        wsum = np.asarray(Bf.sum(axis=0)).ravel()
        w = (Bf.T @ (ops.normal ** 2)) / np.where(wsum > 0.0, wsum, 1.0)[:, None]
        inv = np.einsum("ij,ij->i", w, free) / mass
        inv[wsum == 0.0] = 1.0 / mass[wsum == 0.0]
        return np.divide(1.0, inv, out=np.full_like(inv, np.inf), where=inv > 1e-12 / mass)

    def take_state(self, buf: np.ndarray) -> np.ndarray:
        """The foreground's state after its correct (protocol TAG_STATE): x^{n+1}, v^{n+1/2} of its
        surface nodes (in substeps: then the substeps' mean velocity and the ramp's work,
        adapters/substeps.py; particles: then their volumes); returns
        :meth:`background_correction`'s."""
        n = self.ns * self.dim
        rest = 2 * n + (n + 1 if self.substeps > 1 else 0)   # (the volumes come last)
        if self.particles:
            self.volume = np.asarray(buf[rest:], dtype=np.float64).copy()
        if self.substeps > 1:
            return self.background_correction(buf[:n], buf[n: 2 * n], buf[2 * n: 3 * n], float(buf[3 * n]))
        return self.background_correction(buf[:n], buf[n: 2 * n])

    def background_correction(self, x_new: np.ndarray, v_new: np.ndarray, v_mean: np.ndarray | None = None,
                              work_f: float | None = None) -> np.ndarray:
        """Step 3: [node impulses (nb, dim), v^{n+1/2}_e (nc, dim), mean velocity_e (nc, dim)] for
        the background; advances the surface state and the diagnostics.  A foreground in substeps
        gives their mean velocity ``v_mean`` (the surface's displacement over the coupling step / dt:
        its v^{n+1/2}_e; the mean velocity_e is then that of the last two steps' means, centred at
        t^n as the background's is: multirate.py) and the work its ramp did, ``work_f``."""
        ops, Bf = self.ops, self.ops.Bf
        v_new = np.ascontiguousarray(np.asarray(v_new, dtype=np.float64).reshape(-1, self.dim))
        v_old, v_half = self.v, v_new
        if v_mean is not None:
            v_old = self.v_mean
            v_half = np.ascontiguousarray(np.asarray(v_mean, dtype=np.float64).reshape(-1, self.dim))
        # v^{n+1/2}_e, the mean (v^{n-1/2} + v^{n+1/2})_e / 2 and the impulses' work on it, one pass
        v_half_e, v_bar_e, work = correction_means(Bf.indptr, Bf.indices, Bf.data, ops.area, v_old, v_half,
                                                   self.imp_f)
        if work_f is not None:   # what the ramp gave the body beyond the work of I on its velocity at
            # t^n, (vbar^{n-1} + vbar^n) / 2: the energy it got ahead of the background (multirate.py)
            self.transit_work += work_f - float(work)
        work = float(work)
        self.last.work_f = work
        self.momentum_f += self.last.momentum_f
        # (the largest step's impulses in size, node by node: the momentum balance's scale)
        self.impulse_size = max(self.impulse_size, float(np.abs(self.imp_f).sum()))
        self.work_f += work
        self.dissipation += self.last.dissipation
        self.x = np.asarray(x_new, dtype=np.float64).reshape(-1, self.dim).copy()
        self.v = v_new.copy()
        self.v_mean = v_half if v_half is not v_new else self.v
        return np.concatenate([self.imp_b.ravel(), v_half_e.ravel(), v_bar_e.ravel()])

    # ---- diagnostics and checkpoints ---------------------------------------------------------------
    DIAGNOSTICS = ("iterations", "residual", "dissipation", "foreground_work", "stable_dt_limit", "cond_H",
                   "lambda_oscillation", "lambda_oscillation_max", "void_zones", "tied_orphans", "substeps",
                   "substep_passes", "substep_residual", "momentum_in_transit", "energy_in_transit")

    def diagnostic_names(self) -> list[str]:
        """foreground_momentum_<c>: the impulse the coupling gave the bodies so far (load and constraint);
        interface_force_<c>: the last step's of it over its dt, the force the background exerts on the
        bodies (N; per unit depth in 2-D), what an analyst plots against time; then DIAGNOSTICS."""
        return ([f"foreground_momentum_{c}" for c in "xyz"[: self.dim]]
                + [f"interface_force_{c}" for c in "xyz"[: self.dim]] + list(self.DIAGNOSTICS))

    def diagnostics(self) -> list[float]:
        dt = getattr(self, "dt_last", None)
        force = self.last.momentum_f / dt if dt and self.last.momentum_f is not None else np.zeros(self.dim)
        return list(self.momentum_f) + list(force) + [float(self.last.iterations), self.last.residual, self.dissipation,
                                        self.work_f, float(min(self.stable_limit, 1e300)),
                                        float(self.cond_H), self.lambda_oscillation, self.lambda_oscillation_max,
                                        float(self.void_zones), float(self.tied_orphans), float(self.substeps),
                                        float(self.substep_passes), self.substep_residual,
                                        float(np.linalg.norm(self.transit)), self.transit_work]

    def state_arrays(self) -> dict[str, np.ndarray]:
        out = {f"method_{k}": v for k, v in self.state.state_arrays().items()}
        out.update({"momentum_f": self.momentum_f,
                    "sums": np.array([self.work_f, self.dissipation, self.impulse_size]),
                    # the last impulses on the surface nodes (the next substeps' prediction, multirate.py)
                    "impulse_f": self.imp_f,
                    "transit": np.concatenate([self.transit, [self.transit_work]]), "v_mean": self.v_mean,
                    **({"force_prev": self.force_prev} if self.force_prev is not None else {}),
                    "conditioning": np.array([self.cond_H, self.lambda_oscillation, self.lambda_oscillation_max])})
        return out

    def load_state(self, arrays: dict) -> None:
        self.state.load_state({k[len("method_"):]: v for k, v in arrays.items() if k.startswith("method_")})
        self.momentum_f = np.array(arrays["momentum_f"], dtype=np.float64)
        self.work_f, self.dissipation = (float(a) for a in arrays["sums"][:2])
        if len(arrays["sums"]) > 2:
            self.impulse_size = float(arrays["sums"][2])
        if "transit" in arrays:
            self.transit = np.array(arrays["transit"][:-1], dtype=np.float64)
            self.transit_work = float(arrays["transit"][-1])
        if "v_mean" in arrays and np.shape(arrays["v_mean"]) == self.v.shape:
            self.v_mean = np.array(arrays["v_mean"], dtype=np.float64)
        if "force_prev" in arrays and np.shape(arrays["force_prev"]) == self.imp_f.shape:
            self.force_prev = np.array(arrays["force_prev"], dtype=np.float64)
        if "impulse_f" in arrays and np.shape(arrays["impulse_f"]) == self.imp_f.shape:
            self.imp_f = np.array(arrays["impulse_f"], dtype=np.float64)
        if "conditioning" in arrays:  # (a restart reports the first step's cond(H), not its own)
            self.cond_H, self.lambda_oscillation, self.lambda_oscillation_max = (
                float(a) for a in arrays["conditioning"])
