"""The coupler: rank 0 of the job, owner of the time loop.

Per step it takes the smallest stable step of the solver groups times dt_scale, through the step
control (orchestrator/step_control.py: a fall followed at once, a rise only once it held, the end time
landed on exactly; output and checkpoint times never change a step), commands every group to advance,
and collects their next stable step and diagnostics.
It writes an output (then appends to the XDMF/HDF5 index) at the first step that reaches each output
time, stamped with that step's time, and checkpoints likewise; keeps the diagnostics history and, at
the end, writes summary.json with the case's own check.
Constraint coupling between groups (Lagrange multipliers) slots in between predict and correct.
"""
from __future__ import annotations

import functools
import os
import signal
import socket
import sys
import time as _time
from pathlib import Path

import numpy as np

from adapters import protocol as P
from orchestrator.history_spool import HistorySpool, remove_spool
from orchestrator.restart import FORMAT as CHECKPOINT_FORMAT
from orchestrator.restart import check_restart
from orchestrator.step_control import StepControl, next_time, reached

# h5py (and run_record, which imports it) only where a file is written or read: this module's imports
# come before the coupler joins the job (main), and every rank waits for it in MPI_Init (sod: the
# solver rank waited 0.1-0.2 s for the coupler's imports)

COUPLING = "coupling"  # the coupler's own diagnostics in the history (coupled runs)


def process_age_s() -> float | None:
    """Seconds since this process started (Linux /proc; None elsewhere): the coupler starts with the
    job, so at the end of step 1 this is the job's start-up (imports, solver set-up, kernels)."""
    ticks = P.start_ticks(os.getpid())
    if ticks is None:
        return None
    try:
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return max(uptime - ticks / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return None


DT_COLLAPSE = 1e-6
"""A stable step below this share of the largest step so far stops the run (LS-DYNA's DTMIN): a
penetrator's background went on at t = 21.4 us with steps of 3e-18 s (a node driven to ~1e14 m/s),
a job that would have run until killed."""


def collapsed_step(stable: dict, dt_max: float) -> str | None:
    """Why the run must stop, or None: the solver group whose stable step (``stable``: role -> s)
    fell below DT_COLLAPSE of the largest step so far, ``dt_max`` (0 before the first)."""
    role = min(stable, key=stable.get)
    if not stable[role] < DT_COLLAPSE * dt_max:
        return None
    return (f"the {role} solver's stable step is {stable[role]:.6g} s, below {DT_COLLAPSE:g} of the largest so "
            f"far {dt_max:.6g} s (the run would not reach its end time)")


def describe_limiter(role: str, lim: dict | None) -> str:
    """One phrase for what sets the step: the group, the kind of limit, the element, zone or particle,
    where, and its state (a group's step_limiter(), adapters/base.py)."""
    if not lim:
        return f"the {role} solver"
    text = f"{role}: {lim['kind']} limit in {lim['what']}"
    if lim.get("at") is not None:
        text += " at (" + ", ".join(f"{v:.4g}" for v in lim["at"]) + ") m"
    if lim.get("detail"):
        text += f" ({lim['detail']})"
    return text


EARLY_STEPS = 50
"""The steps whose median step is the run's reference for a falling step (the stable steps of a
scene once started: the first steps of a blast or an impact may still be growing)."""

FALL_WARN = 100.0
"""A step this many times below the early median is said once in the log, with what sets it (a scene
that crawls without a word looks like a stall)."""


@functools.lru_cache(maxsize=2)
def _median(values: tuple) -> float:
    """np.median of the early steps (the same value: the middle one, or the mean (a + b) / 2 of the two
    middle ones; nan if one is nan), once per list of them (fixed after EARLY_STEPS; ~25 us a step).
    Not np.median itself: its first call imports numpy.ma (40-60 ms of the coupler's time loop)."""
    s = sorted(values)
    if any(v != v for v in s):
        return float("nan")
    m = len(s) // 2
    return float(s[m]) if len(s) % 2 else (float(s[m - 1]) + float(s[m])) / 2.0


LIMITER_NOTE_S = 10.0
"""How often the progress line asks the groups what sets the step (a collective query of its own)."""


class Coupler:
    def __init__(self, place, case: dict, out: Path, restart: str | None):
        self.place = place
        self.case = case
        self.out = out
        self.roles = place.roles[1:]
        self.inter = place.inter
        run = case["run"]
        self.end_time = float(run["end_time"])
        self.dt_scale = float(run.get("dt_scale", 0.9))
        self.output_interval = float(run.get("output_interval", self.end_time / 20))
        self.checkpoint_interval = run.get("checkpoint_interval")
        self.max_steps = int(run.get("max_steps", 10_000_000))
        self.diag_every = int(run.get("diagnostics_every", 1))
        self.logf = open(out / "log.txt", "a")
        self.coupling = None
        if case.get("coupling"):
            self._start_coupling()
        self.log(f"case {self.case['name']}: solvers {', '.join(self.roles)}; end time {self.end_time:g} s; "
                 "setting up")
        started = {}
        t_start = _time.perf_counter()
        for r in self.roles:   # each group's start-up message once it is set up, said as it comes
            started[r] = P.recv_object(self.inter[r], 0, 6)
            n = self.inter[r].Get_remote_size()
            what = started[r][4] if len(started[r]) > 4 else ""
            self.log(f"{r}: {what + '; ' if what else ''}{n} rank{'s' if n > 1 else ''}; ready "
                     f"{_time.perf_counter() - t_start:.1f} s after the coupler; stable step {started[r][3]:.4g} s")
        self.names = {r: names for r, (names, *_) in started.items()}
        # multi-rate (orchestrator/coupling/multirate.py): the foreground groups that take each coupled
        # step in substeps of their own stable step; run.group_dt_max caps a group's stable step
        self.group_dt_max = {r: float(v) for r, v in (run.get("group_dt_max") or {}).items()}
        self.multirate = self._substepping(started, restart)
        if self.multirate:
            from orchestrator.coupling.multirate import SubstepCounts

            self.counts = SubstepCounts(self.multirate, int(run.get("max_substeps", 64)))
        self.reply = {r: np.zeros(P.REPLY_HEAD + len(self.names[r])) for r in self.roles}
        self.history_t: list[float] = []
        self.history_step: list[int] = []
        self.history: dict[str, list[np.ndarray]] = {r: [] for r in self.roles}
        if self.coupling is not None:  # the coupler's own diagnostics, recorded like a solver's
            self.names[COUPLING] = (self.coupling.diagnostic_names() + ["momentum_balance_rel", "interface_work"]
                                    + [f"substeps_{r}" for r in self.multirate])
            self.history[COUPLING] = []
        self.t = 0.0
        self.step = 0
        self.output_s = 0.0  # the time loop's share spent writing outputs and checkpoints (summary)
        self.out_index = 0  # number of the next output step's files (not a time: see step_control.next_time)
        self.dt_min = np.inf
        self.dt_max = 0.0
        self.dt_floor = run.get("dt_min")   # run.dt_min: a step below it stops the run by name
        self.early: list[float] = []        # the first EARLY_STEPS steps (the falling step's reference)
        self._fall_said = False
        self._note, self._note_at = "", None
        # a jittering stable step destabilises central differences, not an implicit step: the step
        # control filters the rises only when a group steps by central differences
        self.clock = (StepControl(self.end_time) if any(cd for _, cd, *_ in started.values())
                      else StepControl(self.end_time, window=1, growth=np.inf))
        self._receive_all()
        self._record(spool=False)
        if restart:
            self._load(Path(restart))
        # every recorded row also on disk at once (history_spool.py): a run that fails or is
        # interrupted still leaves its history; a restart's loaded rows first
        self.spool = HistorySpool(out, {r: self.names[r] for r in self.history})
        for k in range(len(self.history_t)):
            self.spool.append(self.history_t[k], self.history_step[k], [self.history[r][k] for r in self.history])

    def _substepping(self, started: dict, restart: str | None = None) -> list[str]:
        """The foreground roles that take their coupled steps in substeps: run.multirate = true (unset:
        where it pays, multirate.DEFAULT_ON: the sizes and the stable steps at the start), the
        multiplier method, and a group that can (its start-up message: its substep cost, 0 when it
        cannot, and its stable step; unset, only a role adapters/registry.py substeps_by_default).  A restart keeps the choice of the run it continues (its
        checkpoint's): the stable steps it starts from are another state's."""
        from adapters import registry as roles
        from orchestrator.coupling.multirate import DEFAULT_ON, pays

        choice = self.case["run"].get("multirate")
        if (self.coupling is None or choice is False or (choice is None and not DEFAULT_ON)
                or self.coupling.method.NAME != "multiplier"):
            return []
        if restart and choice is None:
            import h5py

            with h5py.File(restart, "r") as h:
                if "multirate" in h.attrs:
                    kept = str(h.attrs["multirate"])
                    return [r for r in self.fgs if r in kept.split(",")]
        zones = float(np.prod(self.case["ale"]["grid"]["cells"]))
        bg = started[self.bg][3]

        def ratio(r):
            return bg / min(started[r][3], self.group_dt_max.get(r, np.inf))

        return [r for r in self.fgs if started[r][2] and (choice is True or (
            roles.substeps_by_default(r) and pays(zones, started[r][2], ratio(r))))]

    def _stable(self) -> dict[str, float]:
        """Each group's stable step from its last reply, capped by run.group_dt_max."""
        return {r: min(self.reply[r][1], self.group_dt_max.get(r, np.inf)) for r in self.roles}

    # ---- the embedded-mesh coupling ----------------------------------------------------------------
    def _start_coupling(self) -> None:
        """The foreground's surface, the bodies' initial geometry to the background (before either
        group's start-up finishes: the background's initial state leaves the bodies' volume empty)."""
        from adapters.registry import coupling_side
        from adapters.runtime import unpack_surface
        from orchestrator.coupling.foregrounds import ForegroundCouplings

        # every foreground group (SPH particles, Lagrangian bodies) in one background
        self.fgs = [r for r in self.roles if coupling_side(r) == "foreground"]
        self.bg = next(r for r in self.roles if coupling_side(r) == "background")
        dim = int(self.case["run"]["dimension"])
        surfaces = [unpack_surface(P.recv(self.inter[r], 0, P.TAG_SURFACE), dim) for r in self.fgs]
        self.coupling = ForegroundCouplings(self.case, surfaces, self.fgs)
        # the coupler's own work per part (its waits for the solver groups excluded): summary.json
        self.coupling_s = {"solve": 0.0, "correction": 0.0, "geometry": 0.0}
        P.send(self.inter[self.bg], self.coupling.geometry().pack(dim), 0, P.TAG_GEOMETRY)
        self.coupling.load_kernels()   # (start-up: the first step would pay the kernels' cache loading)
        self.dt_prev = 0.0

    def _coupled_step(self, dt: float, subs: dict | None = None) -> None:
        """The coupler's part of a coupled step (orchestrator/coupling/embedded.py, hook order);
        ``subs``: the substeps of the substepping groups (multirate.py: they first run a predictor
        pass under the impulses predicted here)."""
        c, fgs, bg = self.coupling, [self.inter[r] for r in self.fgs], self.inter[self.bg]
        dt_avg = 0.5 * dt if self.dt_prev == 0.0 else 0.5 * (self.dt_prev + dt)
        subs = subs or {}
        m = [int(subs.get(r, 1)) for r in self.fgs]
        predicted, ramps = [None] * len(self.fgs), [None] * len(self.fgs)
        if any(k > 1 for k in m):   # the substepping groups' predictor passes (multirate.py)
            from adapters.registry import substep_kicks
            from orchestrator.coupling.multirate import Ramp

            for i, (fg, k) in enumerate(zip(fgs, m)):
                if k > 1:
                    mem = c.members[i]
                    # (a central-difference group's kicks sample the ramp at their times: its last
                    # step, the last coupling step over its substeps then, adapters/substeps.py)
                    h_prev = (self.dt_prev / self._m_last.get(self.fgs[i], 1)
                              if substep_kicks(self.fgs[i]) else None)
                    ramps[i] = Ramp(k, dt, self.dt_prev, dt_avg, mem.force_prev, h_prev)
                    predicted[i] = ramps[i].predicted(mem.force_prev, mem.imp_f)
                    P.send(fg, ramps[i].shape(predicted[i]), 0, P.TAG_PREDICT)
        vstars = [P.recv(fg, 0, P.TAG_VSTAR).reshape(-1, c.dim) for fg in fgs]
        background = P.recv(bg, 0, P.TAG_INTERFACE)
        t0 = _time.perf_counter()
        impulses = c.solve(dt, dt_avg, vstars, background, m, predicted, [r.c if r else 1.0 for r in ramps])
        self.coupling_s["solve"] += _time.perf_counter() - t0
        if dt > self.FAR_BEYOND * c.stable_limit:
            raise RuntimeError(
                f"coupling method {c.method.NAME!r} is unstable at step {self.step}, t = {self.t:.6g} s: the "
                f"step {dt:.6g} s is more than {self.FAR_BEYOND:g} times its explicit stable-step limit "
                f"{c.stable_limit:.6g} s (a stiffer spring needs a smaller step: lower its stiffness, or "
                f"run.dt_scale)")
        for k, fg, impulse in zip(m, fgs, impulses):
            if k == 1:
                P.send(fg, impulse, 0, P.TAG_IMPULSE)
        if any(k > 1 for k in m):
            self._substep_passes(dt, dt_avg, background, m, predicted, vstars, ramps)
        states = [P.recv(fg, 0, P.TAG_STATE) for fg in fgs]
        t0 = _time.perf_counter()
        # (each state ends with a flag: 1 when that group's surface changed, eroded elements)
        P.send(bg, c.take_state([st[:-1] for st in states]), 0, P.TAG_CORRECT)
        for i, (fg, st) in enumerate(zip(fgs, states)):
            if st[-1] != 0.0:   # the next geometry on the group's new surface
                from adapters.runtime import unpack_surface

                c.replace_surface(i, unpack_surface(P.recv(fg, 0, P.TAG_SURFACE), c.dim))
        from orchestrator.coupling.geometry import GeometryError

        t1 = _time.perf_counter()
        self.coupling_s["correction"] += t1 - t0
        try:
            geometry = c.geometry()
            self.coupling_s["geometry"] += _time.perf_counter() - t1
        except GeometryError as e:  # a body left the background grid: say when
            raise RuntimeError(f"{e} at step {self.step}, t = {self.t + dt:.6g} s") from None
        P.send(bg, geometry.pack(c.dim), 0, P.TAG_GEOMETRY)
        self._note_stability(dt)
        self.dt_prev = dt
        self.dt_max = max(getattr(self, "dt_max", 0.0), dt)
        if self.step == 1 and c.cond_H > self.COND_WARN:
            self.log(f"warning: coupling {c.method.NAME}: cond(H) = {c.cond_H:.3g} > {self.COND_WARN:g} "
                     f"(beta = {c.method.cfg.get('beta', 'n/a')}): the multiplier system is ill-conditioned, "
                     "its multipliers oscillate zone to zone (lambda_oscillation in the diagnostics); the "
                     "stabilisation beta > 0 (default 1) keeps cond(H) independent of h")
        if self.step == 1 or (dt > c.stable_limit and not getattr(self, "_warned_limit", False)):
            if np.isfinite(c.stable_limit):
                self.log(f"coupling {c.method.NAME}: its explicit stable-step limit is {c.stable_limit:.6g} s; "
                         f"step {self.step} used {dt:.6g} s" + (" (beyond it: unstable)" if dt > c.stable_limit else ""))
                self._warned_limit = dt > c.stable_limit

    def _substep_passes(self, dt, dt_avg, background, m, predicted, vstars, ramps) -> None:
        """The passes of the substepping groups (orchestrator/coupling/multirate.py): after each, the
        solve on its mean velocities; a pass is accepted when the solve would change that mean by at
        most coupling.substep_tolerance of the step's velocity scale (never the predictor pass: its
        impulses were not a solve's), else the next pass runs under the relaxed impulses."""
        from orchestrator.coupling.multirate import MAX_PASSES, PASS_TOLERANCE, Relaxation, velocity_scale

        c = self.coupling
        cfg = self.case.get("coupling") or {}
        tol = float(cfg.get("substep_tolerance", PASS_TOLERANCE))
        most = int(cfg.get("substep_passes", MAX_PASSES))
        pending = [i for i, k in enumerate(m) if k > 1]
        cur = {i: predicted[i] for i in pending}      # the impulses of the pass each group ran last
        saved = {i: None for i in pending}           # and the solve's impulses that go with them
        relax = {i: Relaxation() for i in pending}
        passes = {i: 1 for i in pending}
        v_pass = {i: vstars[i] for i in pending}
        t_solve = 0.0
        while pending:
            for i in list(pending):
                mem, fg = c.members[i], self.inter[self.fgs[i]]
                d = mem.mean_velocity_defect(cur[i])
                res = float(np.max(np.abs(d))) if d.size else 0.0
                scale = velocity_scale(v_pass[i], mem.imp_f, mem.free, mem.mass, mem.c)
                if saved[i] is not None and (res <= tol * scale or passes[i] >= most):
                    mem.take_impulses(saved[i])
                    mem.accept_ramp(ramps[i], mem.imp_f)
                    mem.substep_passes, mem.substep_residual = passes[i], res
                    if res > tol * scale and not getattr(self, "_passes_said", False):
                        self._passes_said = True
                        self.log(f"warning: multirate: the {self.fgs[i]} group's substeps ({m[i]}) still miss the "
                                 f"constraint by {res:.3g} m/s ({res / scale:.3g} of its velocity scale) after "
                                 f"{passes[i]} passes at step {self.step}, t = {self.t:.6g} s (coupling.substep_passes "
                                 f"= {most}, substep_tolerance = {tol:g}); the run goes on with it")
                    P.send(fg, np.zeros(1), 0, P.TAG_IMPULSE)      # (last element 0: accepted)
                    pending.remove(i)
                    continue
                omega = relax[i].next(d)
                if saved[i] is not None:
                    mem.relax(saved[i], omega)
                saved[i] = mem.impulses()
                cur[i] = mem.imp_f
                passes[i] += 1
                P.send(fg, np.concatenate([ramps[i].shape(cur[i]), [1.0]]), 0, P.TAG_IMPULSE)
            for i in pending:
                v_pass[i] = P.recv(self.inter[self.fgs[i]], 0, P.TAG_VSTAR).reshape(-1, c.dim)
                t0 = _time.perf_counter()
                c.solve_member(i, dt, dt_avg, v_pass[i], background, m[i], cur[i], ramps[i].c)
                t_solve += _time.perf_counter() - t0
        self.coupling_s["solve"] += t_solve

    COND_WARN = 100.0
    """cond(H) above which the multiplier system is named ill-conditioned: stabilised (beta 0.1-3) it
    stays 5-16 at every h, unstabilised 645-1180 and growing (coupling.solve.BETA's sweep)."""

    STILL_UNSTABLE_STEPS = 20
    """Steps within its limit after which an oscillation that grew while the step was beyond it no
    longer counts as the cause of a solver's failure (within the limit it stops growing, but it does
    not decay: the spring is undamped)."""

    def _note_stability(self, dt: float) -> None:
        """Keep the launcher's note (protocol.note_unstable_coupling) while the step is beyond the
        coupling's explicit stable-step limit, and STILL_UNSTABLE_STEPS steps after. Between 1 and 2
        times the limit an unstable spring grows by a factor rho^2 per step (|rho| + 1/|rho| =
        (w dt)^2 - 2 for central differences: about 20 at 1.3 times the limit), fast enough to
        invert a zone next to the surface before the interface work reaches UNSTABLE_WORK, and the
        growing oscillation shortens the solvers' steps below the limit as it goes; the solver that
        fails then is named after the coupling. Written only on the way in and out: no cost per step."""
        c = self.coupling
        if dt > c.stable_limit:
            if getattr(self, "_beyond_since", None) is None:
                self._beyond_since = self.step
                P.note_unstable_coupling(self.out, (
                    f"coupling method {c.method.NAME!r} is unstable: from step {self.step}, t = {self.t:.6g} s "
                    f"its step {dt:.6g} s is beyond its explicit stable-step limit {c.stable_limit:.6g} s (a "
                    f"stiffer spring needs a smaller step: lower its stiffness, or run.dt_scale)"))
            self._last_beyond = self.step
        elif (getattr(self, "_beyond_since", None) is not None
              and self.step - self._last_beyond >= self.STILL_UNSTABLE_STEPS):
            self._beyond_since = None
            P.note_unstable_coupling(self.out, None)

    def _coupling_record(self) -> np.ndarray:
        """The coupler's diagnostics row: the exchange totals, and the coupled balances: momentum
        the interface gave the fluid plus what it gave the bodies (zero up to round-off: every
        impulse is paired), and the interface work (energy the coupling added to fluid + bodies:
        the stabilisation's dissipation, negative)."""
        c = self.coupling
        row = np.array(c.diagnostics())
        names = self.names[self.bg]
        bgrow = self.reply[self.bg][P.REPLY_HEAD:]
        p_fluid = np.array([bgrow[names.index(f"interface_momentum_{a}")] for a in "xyz"[: c.dim]])
        scale = max(np.linalg.norm(p_fluid), c.momentum_scale, 1e-300)
        bal = np.linalg.norm(p_fluid + c.momentum_f) / scale
        work = bgrow[names.index("interface_energy")] + c.work_f
        self._check_coupling_energy(work)
        return np.concatenate([row, [bal, work], [self.counts.m[r] for r in self.multirate]])

    FAR_BEYOND = 2.0
    """A step this many times a coupling method's own explicit stable-step limit blows up within a
    few steps: the run stops before it (closer to the limit the energy check below catches it)."""

    UNSTABLE_WORK = 0.01
    """A coupling that has given fluid and bodies more than this share of their energy at the start
    is unstable (a penalty spring stiffer than its explicit step allows): the run stops, naming the
    method's stable-step limit and the step used."""

    def _check_coupling_energy(self, work: float) -> None:
        energy = self._coupled_energy()
        if not hasattr(self, "_energy0"):
            self._energy0 = max(abs(energy), 1e-300)
        if work > self.UNSTABLE_WORK * self._energy0:
            c = self.coupling
            limit = c.stable_limit
            lim = f"{limit:.6g} s" if np.isfinite(limit) else "none (it never limits the step)"
            raise RuntimeError(
                f"coupling method {c.method.NAME!r} is unstable at step {self.step}, t = {self.t:.6g} s: "
                f"the interface gave fluid and bodies {work:.6g} J, more than {self.UNSTABLE_WORK:.0%} of "
                f"their initial energy {self._energy0:.6g} J; its explicit stable-step limit is {lim}, the "
                f"step used {self.dt_prev:.6g} s (the largest so far {getattr(self, 'dt_max', self.dt_prev):.6g} s: "
                f"a growing oscillation shortens the solvers' steps)")

    def _coupled_energy(self) -> float:
        """Total energy of the background plus the bodies' kinetic energy, from their last replies."""
        total = 0.0
        for r, name in ((self.bg, "total_energy"), *((f, "kinetic_energy") for f in self.fgs)):
            names = self.names[r]
            if name in names:
                total += float(self.reply[r][P.REPLY_HEAD + names.index(name)])
        return total

    # ---- messaging -----------------------------------------------------------------------------
    def log(self, msg: str) -> None:
        line = f"[{_time.strftime('%H:%M:%S')}] {msg}"
        self.logf.write(line + "\n")
        self.logf.flush()
        if not os.environ.get("IMMERSE_TTY"):
            print(line, flush=True)

    def _broadcast(self, cmd: np.ndarray, substeps: dict | None = None) -> None:
        """The command to every group; ``substeps``: a group's own count in the command's last slot."""
        from mpi4py import MPI

        cmds = {r: cmd for r in self.roles}
        for r, k in (substeps or {}).items():
            cmds[r] = cmd.copy()
            cmds[r][6] = float(k)
        # non-blocking on both sides (a blocking and a non-blocking broadcast do not match): the solver
        # ranks wait for the command without spinning a core (adapters.runtime.serve)
        for req in [self.inter[r].Ibcast(cmds[r], root=MPI.ROOT) for r in self.roles]:
            P.wait(req)

    def _receive_all(self) -> None:
        """Wait for every group's reply without spinning a core: MPI's blocking receive busy-polls,
        and the coupler shares the machine with the solver ranks (often oversubscribed). Polled for
        protocol.SPIN_S, then in sleeps of protocol.SLEEP_S (in a long wait up to 2 % of the time
        waited, protocol.SLEEP_SHARE), which bound the latency added."""
        from mpi4py import MPI

        reqs = [self.inter[r].Irecv(self.reply[r], source=0, tag=7) for r in self.roles]
        P.poll(lambda: MPI.Request.Testall(reqs))
        for r in self.roles:
            if self.reply[r][0] != 0.0:
                raise RuntimeError(f"{r} reported failure status {self.reply[r][0]}")

    def limiters(self) -> dict[str, dict | None]:
        """What sets each group's stable step now (a collective query: CMD_LIMITER, no step)."""
        self._broadcast(P.command(P.CMD_LIMITER))
        got = {r: P.recv_object(self.inter[r], 0, P.TAG_LIMITER) for r in self.roles}
        self._receive_all()
        return got

    def step_limit_text(self) -> str:
        """The group that sets the step and what in it: the one whose stable step is the smallest (in
        multi-rate: of the groups that do not substep, or a substepping one at max_substeps)."""
        st = self._stable()
        key = {r: v * (self.counts.max_substeps if r in self.multirate else 1) for r, v in st.items()}
        role = min(self.roles, key=lambda r: key[r])
        return describe_limiter(role, self.limiters()[role])

    def _progress_note(self) -> str:
        """The progress line's note: the step and what sets it (asked at most every LIMITER_NOTE_S),
        and each implicit solver's steps and Newton iterations."""
        now = _time.perf_counter()
        if self._note_at is None or now - self._note_at >= LIMITER_NOTE_S:
            self._note = f"dt {self.clock.dt:.4g} s set by {self.step_limit_text()}"
            self._note_at = now
        subs = ", ".join(f"{r} in {self.counts.m[r]} substeps" for r in self.multirate) if self.multirate else ""
        return "; ".join(n for n in (self._note, subs, self._implicit_note()) if n)

    def _watch_step(self, dt: float) -> None:
        """The step chosen for the next step (before the landing on the end): below run.dt_min it
        stops the run by name; more than FALL_WARN below the early median it is said once."""
        if len(self.early) < EARLY_STEPS:
            self.early.append(dt)
        if self.dt_floor is not None and dt < self.dt_floor:
            raise RuntimeError(f"time step {dt:.6g} s below run.dt_min = {self.dt_floor:g} s at step {self.step + 1}, "
                               f"t = {self.t:.6g} s; set by {self.step_limit_text()}")
        if not self._fall_said and len(self.early) >= min(EARLY_STEPS, 10):
            ref = _median(tuple(self.early))
            if dt < ref / FALL_WARN:
                self._fall_said = True
                self.log(f"warning: the step fell to {dt:.4g} s at step {self.step + 1}, t = {self.t:.6g} s, "
                         f"{ref / dt:.3g} times below its early median {ref:.4g} s (steps 1-{len(self.early)}): "
                         f"set by {self.step_limit_text()}")

    def _implicit_note(self) -> str:
        """The progress line's note: each implicit solver's last recorded step size and Newton
        iterations (the groups whose diagnostics have newton_iterations and time_step)."""
        notes = []
        for r in self.roles:
            names = list(self.names[r])
            if "newton_iterations" in names and "time_step" in names and self.history[r]:
                row = self.history[r][-1]
                note = (f"{r}: dt {row[names.index('time_step')]:.4g} s, "
                        f"{row[names.index('newton_iterations')]:.0f} Newton iterations")
                if "substeps" in names and row[names.index("substeps")] > 1:
                    note += f" ({row[names.index('substeps')]:.0f} substeps)"
                notes.append(note)
        return "; ".join(notes)

    def _implicit_summary(self, hist: dict) -> dict:
        """summary.json's "implicit": per implicit solver (diagnostics with newton_iterations), the
        step sizes (min, median, max, s), the Newton iterations (median, max) and the most substeps of
        a step, over the recorded steps after the first record."""
        out = {}
        for r in self.roles:
            if f"{r}.newton_iterations" not in hist or len(hist[f"{r}.newton_iterations"]) < 2:
                continue
            it, dt = hist[f"{r}.newton_iterations"][1:], hist[f"{r}.time_step"][1:]
            out[r] = {"time_step": {"min": float(dt.min()), "median": float(np.median(dt)), "max": float(dt.max())},
                      "newton_iterations": {"median": float(np.median(it)), "max": float(it.max())},
                      "substeps_max": float(hist[f"{r}.substeps"][1:].max()) if f"{r}.substeps" in hist else 1.0}
        return out

    def _record(self, spool: bool = True) -> None:
        self.history_t.append(self.t)
        self.history_step.append(self.step)
        for r in self.roles:
            self.history[r].append(self.reply[r][P.REPLY_HEAD:].copy())
        if self.coupling is not None:
            self.history[COUPLING].append(self._coupling_record())
        if spool:
            self.spool.append(self.t, self.step, [self.history[r][-1] for r in self.history])

    # ---- output and checkpoints ----------------------------------------------------------------
    def write_output(self) -> None:
        t0 = _time.perf_counter()
        index = self.output_index  # (built on first use, before this output's files exist)
        self._broadcast(P.command(P.CMD_WRITE, step=self.step, time=self.t, index=self.out_index))
        self._receive_all()
        index.append(self.out_index, self.roles)  # a cost independent of the outputs before
        self.out_index += 1
        self.output_s += _time.perf_counter() - t0

    @functools.cached_property
    def output_index(self):
        """The output index held in memory for the whole run, built once from the files on disk
        (on restart: the steps before the checkpoint)."""
        from orchestrator import output

        return output.OutputIndex(self.out)

    def checkpoint(self) -> None:
        t0 = _time.perf_counter()
        self._checkpoint()
        self.output_s += _time.perf_counter() - t0

    def _checkpoint(self) -> None:
        self._broadcast(P.command(P.CMD_CHECKPOINT, step=self.step, time=self.t))
        self._receive_all()
        d = self.out / "checkpoints"
        path = d / f"checkpoint_{self.step:08d}.h5"
        tmp = path.with_suffix(".tmp")
        ident = self._case_identity()
        import h5py

        with h5py.File(tmp, "w") as h:
            for k in ("t", "step", "out_index", "dt_min", "dt_max"):
                h.attrs[k] = getattr(self, k)
            # which case this state belongs to: a restart of any other case is refused
            h.attrs["format"] = CHECKPOINT_FORMAT
            h.attrs["case_name"] = self.case["name"]
            h.attrs["case_fingerprint"] = ident["fingerprint"]
            h.attrs["case_identity"] = ident["json"]
            for r in self.roles:
                h.attrs[f"file_{r}"] = f"step_{self.step:08d}/{r}.h5"
                h.attrs[f"ranks_{r}"] = self.inter[r].Get_remote_size()
                h.create_dataset(f"history/{r}", data=np.array(self.history[r]))
            if self.coupling is not None:
                h.attrs["dt_prev"] = self.dt_prev
                h.create_dataset(f"history/{COUPLING}", data=np.array(self.history[COUPLING]))
                for k, a in self.coupling.state_arrays().items():
                    h.create_dataset(f"coupling/{k}", data=a)
            h.create_dataset("step_control", data=self.clock.state())
            h.attrs["multirate"] = ",".join(self.multirate)   # (the groups in substeps: a restart keeps them)
            if self.multirate:
                h.create_dataset("substep_counts", data=self.counts.state())
            h.create_dataset("early_steps", data=np.array(self.early, dtype=np.float64))
            h.attrs["fall_said"] = self._fall_said
            h.create_dataset("history/t", data=np.array(self.history_t))
            h.create_dataset("history/step", data=np.array(self.history_step))
        os.replace(tmp, path)
        self.log(f"checkpoint {path.relative_to(self.out)} at step {self.step}, t = {self.t:.6e} s")

    def _case_identity(self) -> dict:
        """The case's fingerprint and the canonical JSON it hashes (mesh files hashed once)."""
        if getattr(self, "_ident", None) is None:
            from orchestrator.fingerprint import canonical_json, case_identity, fingerprint_of

            text = canonical_json(case_identity(self.case))
            self._ident = {"fingerprint": fingerprint_of(text), "json": text}
        return self._ident

    def _load(self, path: Path) -> None:
        # the launcher checked it already; a coupler started by other means must not continue
        # another case's state either
        check_restart(path, self.case)
        import h5py

        with h5py.File(path, "r") as h:
            self.t = float(h.attrs["t"])
            self.step = int(h.attrs["step"])
            self.out_index = int(h.attrs["out_index"])
            self.dt_min = float(h.attrs["dt_min"])
            self.dt_max = float(h.attrs["dt_max"])
            self.clock.load(h["step_control"][...])
            if self.multirate and "substep_counts" in h:
                self.counts.load(h["substep_counts"][...])
            self.early = [float(v) for v in h["early_steps"][...]]
            self._fall_said = bool(h.attrs["fall_said"])
            self.history_t = list(h["history/t"][...])
            self.history_step = [int(s) for s in h["history/step"][...]]
            for r in self.roles:
                self.history[r] = list(h[f"history/{r}"][...])
            if self.coupling is not None:
                self.dt_prev = float(h.attrs["dt_prev"])
                self.history[COUPLING] = list(h[f"history/{COUPLING}"][...])
                self.coupling.load_state({k: h[f"coupling/{k}"][...] for k in h["coupling"]})
        self.log(f"restarted from {path.name}: step {self.step}, t = {self.t:.6e} s")

    # ---- the time loop ---------------------------------------------------------------------------
    def run(self) -> dict:
        from orchestrator.progress import Progress

        wall0 = _time.perf_counter()
        self.first_step_s = None
        if self.dt_scale > 1.0:
            self.log(f"warning: run.dt_scale = {self.dt_scale:g} > 1: every step is beyond the solvers' "
                     "stable (Courant) limit (a stability study); a failure is reported as that")
        if self.out_index == 0:
            from adapters.registry import coupling_side
            from orchestrator import paraview_script

            paraview_script.write(self.out, self.roles,   # (OUT/open_in_paraview.py: groups named in ParaView)
                                  next((r for r in self.roles if coupling_side(r) == "background"), None))
            self.write_output()
        self.next_output_t = next_time(self.t, self.output_interval)
        self.next_checkpoint_t = next_time(self.t, self.checkpoint_interval)
        prog = Progress(self.end_time, self.t, bool(os.environ.get("IMMERSE_TTY")), self.log)
        done = self.t >= self.end_time
        while not done and self.step < self.max_steps:
            groups = self._stable()
            stable = min(groups.values())
            if not np.isfinite(stable) or stable <= 0.0:
                raise RuntimeError(f"stable time step is {stable} at step {self.step}, t={self.t:.6g} s")
            why = collapsed_step(groups, self.dt_max)
            if why:
                raise RuntimeError(f"time step collapsed at step {self.step}, t = {self.t:.6g} s: {why}; "
                                   f"set by {self.step_limit_text()}")
            subs = None
            if self.multirate:  # the coupling step: the other groups' step, or max_substeps substeps
                proposed = min([self.dt_scale * v for r, v in groups.items() if r not in self.multirate]
                               + [self.counts.bound({r: self.dt_scale * groups[r] for r in self.multirate})])
            else:
                proposed = self.dt_scale * stable
            # the step control (step_control.py): outputs and checkpoints never change a step
            dt, t_new, done = self.clock.next(self.t, proposed)
            if self.multirate:
                # (the last step's substeps: a restart has them back from the checkpointed counts)
                self._m_last = dict(self.counts.m)
                subs = self.counts.update(self.clock.dt, {r: self.dt_scale * groups[r] for r in self.multirate})
            self._watch_step(self.clock.dt)
            self.step += 1
            # the last step (end_time or run.max_steps) always writes: a run cut short keeps its state
            output_due = reached(t_new, self.next_output_t) or done or self.step >= self.max_steps
            checkpoint_due = reached(t_new, self.next_checkpoint_t) and not done and self.step < self.max_steps
            # a record at every output and checkpoint step too: the history of a run that ends
            # early reaches its last written output (run_record.py)
            diag = output_due or checkpoint_due or self.step % self.diag_every == 0
            self._broadcast(np.array([P.CMD_STEP, dt, self.step, t_new, -1, float(diag), 1.0]), subs)
            if self.coupling is not None:
                self._coupled_step(dt, subs)
            self._receive_all()
            self.t = t_new
            if not done:  # dt statistics of the steps the control chose (not the landing on the end)
                self.dt_min = min(self.dt_min, dt)
                self.dt_max = max(self.dt_max, dt)
            if self.first_step_s is None:
                self.first_step_s = process_age_s()
                if self.first_step_s is not None:
                    self.log(f"first step done {self.first_step_s:.2f} s after start "
                             f"(imports, set-up, kernels loaded or compiled)")
            if diag:
                self._record()
            if output_due:
                self.write_output()
                self.next_output_t = next_time(self.t, self.output_interval)
            if checkpoint_due:
                self.checkpoint()
                self.next_checkpoint_t = next_time(self.t, self.checkpoint_interval)
            prog.update(self.t, self.step, self._progress_note)
        prog.close()
        set_by = self.step_limit_text() if self.step > 0 else ""
        self._broadcast(P.command(P.CMD_STOP))
        self._receive_all()
        # each group's time in its own step work, and in its engine (LAMMPS's runs) where it has one
        self.solver_time = {r: P.recv(self.inter[r], 0, P.TAG_TIMING) for r in self.roles}
        wall = _time.perf_counter() - wall0
        self.log(f"finished: {self.step} steps, t = {self.t:.6e} s, wall {wall:.2f} s"
                 + (f"; the last step {self.clock.dt:.4g} s set by {set_by}" if set_by else "")
                 + "".join(f"; {r} in {self.counts.total[r]} substeps ({self.counts.lo[r]}-{self.counts.hi[r]} "
                           f"a step)" for r in self.multirate))
        return self.summary(wall)

    # ---- summary -------------------------------------------------------------------------------
    def diagnostics_history(self) -> dict[str, np.ndarray]:
        hist = {"time": np.array(self.history_t), "step": np.array(self.history_step)}
        for r in self.history:
            arr = np.array(self.history[r])
            for j, n in enumerate(self.names[r]):
                hist[f"{r}.{n}"] = arr[:, j]
        return hist

    def summary(self, wall: float) -> dict:
        from orchestrator import checks
        from orchestrator.run_record import (conservation_residuals, contact_balances, final_units, write_diagnostics,
                                             write_summary)

        hist = self.diagnostics_history()
        write_diagnostics(self.out, hist)
        self.spool.close()
        remove_spool(self.out)   # (diagnostics.h5 holds it now)
        conservation = conservation_residuals(hist, list(self.history))
        final = {k: float(a[-1]) for k, a in hist.items() if k not in ("time", "step")}
        s = {
            "case": self.case["name"],
            "case_dir": str(self.case["case_dir"]),
            # completed: the end time reached; max_steps: run.max_steps stopped it before (failed and
            # interrupted runs get theirs from the launcher, run_record.record_ended_run)
            "status": "completed" if self.t >= self.end_time * (1 - 1e-12) else "max_steps",
            "wall_time_s": wall,
            "output_time_s": self.output_s,   # of wall_time_s: writing outputs and checkpoints
            # of wall_time_s: each group's rank 0 in its own step work (its waits excluded), and in
            # its engine where it has one (the SPH group: LAMMPS's runs)
            "solver_time_s": {r: float(a[0]) for r, a in getattr(self, "solver_time", {}).items()},
            "engine_time_s": {r: float(a[1]) for r, a in getattr(self, "solver_time", {}).items() if np.isfinite(a[1])},
            "first_step_s": self.first_step_s,
            "steps": self.step,
            "end_time": self.t,
            "dt": {"min": self.dt_min if np.isfinite(self.dt_min) else None, "max": self.dt_max},
            "implicit": self._implicit_summary(hist),
            # multi-rate: each substepping group's substeps in all and per coupling step
            **({"multirate": self.counts.summary(self.step)} if self.multirate else {}),
            "ranks": {r: self.inter[r].Get_remote_size() for r in self.roles},
            "conservation": conservation,
            **({"contact": contact} if (contact := contact_balances(hist, list(self.history))) else {}),
            "final": final,
            "units": final_units(final, self.case.get("probes")),   # (of "final"'s values)
            "machine": {"host": socket.gethostname(), "cores": os.cpu_count()},
        }
        if self.coupling is not None:  # the coupler's own work: solve, correction, geometry (the
            # surfaces clipped; particle bodies: also reconstructed), and its share of the time loop
            s["coupling_time_s"] = dict(self.coupling_s)
            s["coupling_share"] = sum(self.coupling_s.values()) / wall if wall > 0 else None
        if self.case.get("check"):
            s["check"] = checks.run_check(self.case, self.out, hist)
        write_summary(self.out, s)
        if "check" in s:
            for name, m in s["check"]["metrics"].items():
                self.log(f"check {name}: {m['value']:.6g} vs {m['reference']:.6g} "
                         f"(rel. error {m['rel_error']:.3g}, tolerance {m['tolerance']:g}) "
                         f"{'passed' if m['passed'] else 'FAILED'}" + (f": {m['note']}" if m.get("note") else ""))
        return s


def main(argv=None) -> None:
    from adapters.runtime import parse_args

    args = parse_args(argv)   # (the solver ranks' arguments: launch.build_command gives every process the same)
    out = Path(args.out)
    running: list[Coupler] = []

    def stopped(signum, frame):
        # the launcher ends the job (SIGTERM to every process): say where the time loop was, so the
        # interruption message can name the step, then go without touching MPI (the others are dying)
        if running:
            P.write_stop_state(out, step=running[0].step, t=running[0].t, signal=signum)
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, stopped)
    place = P.join(P.COUPLER, args.roles.split(","))
    P.install_fault_handler(out, P.COUPLER, 0)
    P.register_process(out, P.COUPLER, 0)
    from adapters import case_file   # (after joining: the ranks wait in MPI_Init until then)

    case = case_file.read(args.case, args.case_sha256)
    running.append(Coupler(place, case, out, args.restart))
    running[0].run()
    (P.run_dir(out) / "pids" / str(os.getpid())).unlink(missing_ok=True)


if __name__ == "__main__":
    main(sys.argv[1:])
    P.exit_after_clean_end()
