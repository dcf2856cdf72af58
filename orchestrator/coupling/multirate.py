"""Multi-rate stepping of the embedded-mesh coupling: each foreground group at its own stable step
inside the coupling step, the multipliers acting once per coupling step (DESIGN.md "Time").

Why: the coupler used to step every group at the smallest stable step of any; a 1 mm steel panel in
air (0.5 mm elements) set the gas's step 15-25 times below its own.  Explicit codes subcycle (LS-DYNA
element groups); across partitioned solvers with multipliers the published way is a dual Schur
(FETI-like) coupling with velocity continuity at the coarse ("system") steps (Gravouil & Combescure,
IJNME 50, 2001; Karimi & Nakshatrala, JCP 273, 2014).  The scheme here, per coupling step
t^n -> t^{n+1} = t^n + dt (the step of the background and of every group that does not substep):

1. The force a substepping body feels is a ramp over the coupling step (adapters/substeps.py).  The
   background's leapfrog gives the interface the impulse I^n (the fluid's load and the multipliers')
   as a kick at t^n, the force F^n = I^n / dt_avg held over [t^n - dt_prev/2, t^n + dt/2].  The body,
   whose substeps fill [t^n, t^{n+1}], feels F extrapolated from the last two coupling steps,
   f(t) = F^n + (t - t^n) (F^n - F^{n-1}) / dt_prev: second order in time, and its work pairs with
   the background's to second order (the force's share of the body's velocities is centred at t^n,
   as the background's kick is).  Holding F^n over the step instead (a constant force, first tried)
   shifted the force half a step late: the interface did first-order work (-7.8e-5 J on a 1 MPa
   pulse through a solid in water, against -1.4e-7 single-rate), and a step that fell (the landing
   on the end time halves the last two) pressed a soft piston by dt_avg / dt = 1.5 times the gas's
   pressure and rang it (its velocity 40 times further off).
   A central-difference body (the Lagrangian solver) takes the ramp at its kicks' own times: its
   substep k kicks at t^n + k h with the impulse w_k f(t^n + k h), w_k its kick's length ((h_prev +
   h) / 2 for the first, h after it; adapters/substeps.py).  Sampling it at the substeps' middles
   with weights h instead (the first scheme, still that of SPH groups) put the force h/2 early at
   every kick and h/2 F too much into the run's first: the scheme was first order in the coupling
   step (a piston on a gas spring, 8 substeps: observed order 1.01, 400 times further from the
   single-rate limit; now 3.6 there and single-rate 2.02: tests/cases/test_time_order.py).
   The body so gets about dt F^n + dt^2 / (2 dt_prev) (F^n - F^{n-1}) in the step, not I^n: it runs
   ahead of the background's half-step velocities, a momentum in transit, tracked (the diagnostic
   ``momentum_in_transit``: :meth:`Ramp.total`), bounded (about dt/2 F) and never lost: the balances
   count what each side got.
2. The constraint on the mean:  B^b v_b^{n+1/2} + B^f vbar_f = Cbar^-1 lambda.  The background moves
   its surface zones by dt v_b; the body's surface moves by dt vbar_f (vbar_f: the mean of the
   substeps' velocities): tied means, the surfaces stay together over the coupling step.  The mean
   answers I^n, for a rigid body, as vbar_f(I) = v_pass + c M^-1 (I - I_pass) with
   c = sum_k w_k (1 + rho s_k) (m - k) / m / dt_avg (substep k's impulse moves the velocities of
   substeps k..m-1; rho = dt / dt_prev the ramp's share, s_k its place; :class:`Ramp`): the
   single-rate system with the body's masses M / c and predictor v_pass - c M^-1 I_pass, solved by
   the same code (embedded.py, variants.py).
3. Passes.  The group runs its substeps under a predicted ramp (F^{n-1} held), the coupler solves on
   their mean, and the group runs them again from the same start under the solve's ramp, until the
   solve would move the mean by at most coupling.substep_tolerance of its scale (:class:`Relaxation`
   for why the passes converge and how they are sped up).  Usually 2-3 passes.

4. The stabilisation keeps the size it has at the substeps' step.  Its compliance C̄^-1 = J + I/α
   scales with the step (solve.py: s_e ~ Δt), and so do the constraint's slip and the energy it
   takes; at a coupling step m times the body's it took m times more.  Measured on
   steel_panel_shock_2d (17 substeps): the tip history 1.82 % of the peak off the single-rate run's
   (at the same times: the outputs fall on coupling steps, up to one late), the interface's work
   -7.44 J against -2.17 J; with α m, β / m (the compliance of the body's step) 0.13 % and -3.4 J, the tip 4.47 % off the fine-zone reference (single-rate 4.53 %), cond(H) and
   the multipliers' zone-to-zone spread as single-rate's (1.66 against 1.81).  What remains of the
   extra work is the projection's own: each step removes the relative velocity gathered over the
   step, a dissipation O(dt) of the coupling step (a steel block ringing in a closed box of air,
   0.52 s: -7.8 J over 11,162 coupling steps against -3.95 J over 253,558 single-rate steps).

What is exact: every balance of each side (each books what it got: impulses, work) and the
coupler's momentum balance (both sides' I^n); the interface's work pairs to second order, like the
single-rate scheme's.  With m = 1 nothing of this runs: the step is the single-rate one, bit for bit.

Known limits (issue 43, measured): the constraint's projection dissipates O(dt) of the coupling step
(a steel block ringing in a closed box of air lost 7.8 J over 0.52 s against 3.95 J single-rate);
where the coupling step falls at once (the landing on the end time halves the last two) a soft body
rings a little (embedded_piston_sod at its own ratio of about 2: the piston's velocity error 2.5e-5
at the last step, 5e-6 before it); the 3-D steel plate in a shock is 1.5 % of its peak off the
single-rate run (2-D 0.65 %, the steel panel 0.13 %).  The plate shows the box's dissipation: with
the gas's step capped at 2, 4, 8 and 16 times the single-rate one, the interface's work is -26.4,
-27.9, -29.9 and -35.3 J against -26.2 J single-rate, growing with the coupling step; its tip is
0.32, 0.40, 0.50, 1.6, 3.4, 1.85 and 1.5 % off at 2, 3, 4, 6, 8, 12 and 16, not monotone (the passes'
tolerance is not it: 1e-9 gives 1.51 %).  Much of it is the gas's own step, not the coupling: the
single-rate run steps the gas at 1/16 of its limit, and the scene itself moves as much with the gas's
step (the shipped rubber plate, single-rate throughout, at dt_scale 0.9 against 0.056: 2.1 % of its
peak; 0.45 against 0.056: 1.5 %), so a single-rate reference cannot separate the coupling's error
from the gas's at the 1 % level.  SPH bodies (LAMMPS's particles, each pass from their per-atom
arrays put back by id): a steel plate of tlsph particles in the same shock (4 x 40 particles, 26
substeps) is 3.64 % of its peak off the single-rate run at 4 ms, 0.54 % at its peak, growing with
the coupling step (1.64 % at 8 substeps), its energy 1.27 J against 1.36 J and the interface's work
-49 J against -14 J, the time loop 6.0x faster (tests/cases/test_multirate.py).  A soft light body
of particles (embedded_sph_piston, 21-43 substeps) rings at the coupling step, which is near its
own lowest period (2.4e-3 s, the coupling step 0.9-1.9e-3 s): its mean velocity swings 1.5 % from
step to step and ends 6.9e-3 off (single-rate 1.95e-3); the FE piston in the same gas at the same
coupling step does not (1.9e-5): the particles' constraint reaches three layers into the body (the
kernel's support), not yet understood.  So SPH groups substep only when asked.  The energy is
dissipated by the stabilisation, steadily, not only while the body rings: a steel block (6 x 3
elements) ringing in its first mode in a closed box of air (30 x 20 zones, 0.05 s, 24 substeps) drifts
-0.51 J (interface work -0.36 J, -0.15 J in transit) against -0.17 J single-rate, the stabilisation's
dissipation 0.66 J against 0.24 J and still growing at the same rate once the block's energy is 1e-3
J; the I/alpha term taken on the increment of lambda (the ambient pressure's multiplier held without
slip) changed neither drift.  Next: find what the stabilisation keeps dissipating in a quiet box.

Why not the alternatives.  Constraining the end velocities with the multipliers' impulse given at
the end of the substeps (continuity at the coarse steps only) lets the end kick move a light body m
times as far as its mean: for a rigid body against a fixed wall the error of the relative velocity
maps through a matrix of trace -3 (m - 1) / 2, unstable from m = 2.  Tying the body at every substep
to the background's interpolated velocity (Gravouil-Combescure) needs a solve per substep and
dissipates at the interface for m > 1; doing it without dissipation (Prakash & Hjelmstad, IJNME 61,
2004) couples the substeps' multipliers into one system.  The price of this scheme is the passes of
the substepping group: the cheap group in the scenes multi-rate is for (a thin stiff body among many
fluid zones).

Which groups substep: a foreground group whose adapter can (adapters/base.py can_substep: the explicit
Lagrangian solver without contact, SPH through LAMMPS; not the implicit integrators), with the
multiplier method, when run.multirate = true, or (:data:`DEFAULT_ON`) when it is unset, the role
substeps by default (adapters/registry.py substeps_by_default: not SPH, see the known limits) and
substepping pays (:data:`PAYS`: the background has at least 4 zones per element of the group;
:data:`MIN_RATIO`: the group's stable step at least 4 times below the background's at the start).  The coupling step is the smallest of the
other groups' stable steps and max_substeps times each substepping group's; a substepping group's
count follows its need at once when it rises and only after it held lower for WINDOW coupling steps
when it falls (the substep is a central-difference step: a jittering step pumps the highest modes,
orchestrator/step_control.py).  A group whose count is 1 takes the single-rate step.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from orchestrator.step_control import WINDOW

MAX_SUBSTEPS = 64
"""The default most substeps of a group in one coupling step (run.max_substeps)."""


class Ramp:
    """The force ramp of a substepping body over one coupling step (module docstring, 1-2): built
    from the substeps m, the step dt, the last one dt_prev, the background's dt_avg and the body's
    last force F^{n-1} per surface node (None: none yet, the force held)."""

    def __init__(self, m: int, dt: float, dt_prev: float, dt_avg: float, force_prev: np.ndarray | None,
                 h_prev: float | None = None):
        from adapters.substeps import kick_weights

        self.m, self.dt, self.dt_avg = int(m), float(dt), float(dt_avg)
        self.force_prev = force_prev
        self.rho = dt / dt_prev if (force_prev is not None and dt_prev > 0.0) else 0.0
        k = np.arange(self.m)
        # where substep k samples the ramp and its kick's length (adapters/substeps.py; h_prev: the
        # group's last step, None: the substeps' middles)
        self.s, self.w = kick_weights(self.m, dt, h_prev)
        # the rigid mean's answer to I (module docstring, 2): c = sum_k w_k (1 + rho s_k)(m - k)/m / dt_avg
        self.c = float(np.sum(self.w * (1.0 + self.rho * self.s) * (self.m - k) / self.m)) / self.dt_avg

    def shape(self, impulse: np.ndarray) -> np.ndarray:
        """[rate, slope] of the ramp for the interface impulse I (the background's): rate = I / dt_avg,
        slope = rho (rate - F^{n-1}); one buffer (adapters/substeps.py)."""
        rate = impulse / self.dt_avg
        slope = self.rho * (rate - self.force_prev) if self.rho else np.zeros_like(rate)
        return np.concatenate([rate.ravel(), slope.ravel()])

    def total(self, impulse: np.ndarray) -> np.ndarray:
        """What the body gets over the step for I: sum_k w_k (rate + s_k slope) (per node)."""
        rate = impulse / self.dt_avg
        if not self.rho:
            return float(self.w.sum()) * rate
        return float(self.w.sum()) * rate + float(self.w @ self.s) * self.rho * (rate - self.force_prev)

    def predicted(self, last_force: np.ndarray | None, like: np.ndarray) -> np.ndarray:
        """The predictor pass's impulse: the last force held (dt_avg F^{n-1}), 0 without one."""
        return np.zeros_like(like) if last_force is None else self.dt_avg * last_force


PAYS = 4.0
"""Unset, run.multirate lets a group substep when the background has at least PAYS zones per element
of the group.  Why: single-rate, N coupling steps at the group's step cost N (Z + E) (Z zones, E
elements, about a zone-step each: bench ale, bench lagrange); in m substeps with about 2.5 passes,
N/m (Z + 2.5 m E).  That is less when Z (1 - 1/m) > 1.5 E: from m = 2 on when Z >= 3 E, with a margin
for the passes' messages.  An explicit run.multirate = true substeps whatever the sizes."""


MIN_RATIO = 4.0
"""Unset, run.multirate lets a group substep only when, at the start, the background's stable step
is at least MIN_RATIO times the group's.  Below it the passes (about 2.5) eat most of what the
substeps save, and the low ratios are where the scheme is least accurate: the landing on the end
time halves the last coupling steps and a soft body rings (embedded_piston_sod at its own ratio of
about 2: the piston's velocity error 2.5e-5 at the last step against 5e-6 before it;
embedded_piston_water_air's velocity 5.3e-5 against its check's 5e-5).  Measured where it is on by
default (steel_panel_shock_2d, 17 substeps): 6.3 s against 79.5 s, the tip 0.13 % of its peak off
the single-rate run."""


DEFAULT_ON = True
"""Whether an unset run.multirate substeps where it pays (PAYS) and the step ratio is at least
MIN_RATIO; run.multirate = false keeps a case single-rate, true substeps whatever the sizes.  Of the
shipped coupled cases this turns on steel_panel_shock_2d only (the others' bodies are within 2 of
the gas's step)."""


def pays(zones: float, cost: float, ratio: float = math.inf) -> bool:
    """Whether substepping a group of the given cost (zone-steps a substep) pays beside ``zones``,
    its stable step ``ratio`` times below the background's (PAYS, MIN_RATIO)."""
    return zones >= PAYS * cost and ratio >= MIN_RATIO


def needed(dt: float, stable: float) -> int:
    """Substeps of at most ``stable`` (dt_scale already applied) in a coupling step ``dt``."""
    if not (stable > 0.0 and math.isfinite(stable)):
        return 1
    return max(1, math.ceil(dt / stable * (1.0 - 1e-12)))


class SubstepCounts:
    """Each substepping group's substeps per coupling step: a rise followed at once, a fall only once
    it held for ``window`` coupling steps; checkpointed with the step control."""

    def __init__(self, roles, max_substeps: int = MAX_SUBSTEPS, window: int = WINDOW):
        self.roles = list(roles)
        self.max_substeps = int(max_substeps)
        self.recent = {r: deque(maxlen=int(window)) for r in self.roles}
        self.m = {r: 1 for r in self.roles}
        self.total = {r: 0 for r in self.roles}          # substeps taken so far
        self.lo = {r: 0 for r in self.roles}             # the fewest and most per coupling step
        self.hi = {r: 0 for r in self.roles}

    def bound(self, stable: dict) -> float:
        """The longest coupling step the substepping groups allow (their stable steps, dt_scale
        applied, times max_substeps); inf without them."""
        return min((self.max_substeps * stable[r] for r in self.roles), default=math.inf)

    def update(self, dt: float, stable: dict) -> dict:
        """The substeps of each group in the coupling step ``dt`` (``stable``: their stable steps,
        dt_scale applied)."""
        for r in self.roles:
            self.recent[r].append(min(needed(dt, stable[r]), self.max_substeps))
            m = max(self.recent[r])
            self.m[r] = m
            self.total[r] += m
            self.lo[r] = m if self.lo[r] == 0 else min(self.lo[r], m)
            self.hi[r] = max(self.hi[r], m)
        return dict(self.m)

    def state(self) -> np.ndarray:
        """[per role: m, total, lo, hi, window length, the window...] for a checkpoint."""
        out = []
        for r in self.roles:
            w = list(self.recent[r])
            out += [self.m[r], self.total[r], self.lo[r], self.hi[r], len(w), *w]
        return np.array(out, dtype=np.float64)

    def load(self, a: np.ndarray) -> None:
        a = [int(v) for v in np.asarray(a)]
        i = 0
        for r in self.roles:
            self.m[r], self.total[r], self.lo[r], self.hi[r], n = a[i: i + 5]
            self.recent[r].clear()
            self.recent[r].extend(a[i + 5: i + 5 + n])
            i += 5 + n

    def summary(self, steps: int) -> dict:
        """summary.json's "multirate": per group its substeps in all, and per coupling step the
        fewest, the mean and the most."""
        return {r: {"substeps": self.total[r], "per_step_min": self.lo[r], "per_step_max": self.hi[r],
                    "per_step_mean": self.total[r] / steps if steps else None} for r in self.roles}


PASS_TOLERANCE = 1e-6
"""The default coupling.substep_tolerance: a pass is accepted when the solve after it would change
the substeps' mean velocity by at most this share of the step's velocity scale (see
:func:`velocity_scale`)."""

MAX_PASSES = 12
"""The default coupling.substep_passes: the most passes of a coupling step's substeps (the last one is
accepted, its residual reported and said in the log)."""


def velocity_scale(v_mean: np.ndarray, impulse: np.ndarray, free: np.ndarray, mass: np.ndarray, c: float) -> float:
    """The scale the passes' residual is measured against: the largest of the surface's mean velocity
    and of the velocity change c I / m the step's impulse makes."""
    a = float(np.max(np.abs(v_mean))) if v_mean.size else 0.0
    b = float(np.max(np.abs(impulse * free * (c / mass[:, None])))) if impulse.size else 0.0
    return max(a, b, 1e-300)


class Relaxation:
    """Aitken's dynamic relaxation of the passes (Irons & Tuck, IJNME 1, 1969; for partitioned
    fluid-structure iterations Kuettler & Wall, Comput Mech 43, 2008): the next pass's impulses are
    I + omega (I_hat - I), omega from the last two residuals r = I_hat - I (in mean-velocity units),
    omega_k = -omega_{k-1} r_{k-1} . (r_k - r_{k-1}) / |r_k - r_{k-1}|^2, the first 1.  The rigid
    estimate c M^-1 of the body's answer over-estimates it (an elastic body's mean moves less: per
    mode 2 (1 - cos w dt) / (w dt)^2 <= 1 of it), so plain passes converge, monotonically but slowly
    where the body is light and stiff; Aitken's omega (> 1 there) takes the slow mode out."""

    LIMITS = (0.1, 10.0)

    def __init__(self):
        self.omega = 1.0
        self.r_prev = None

    def next(self, r: np.ndarray) -> float:
        r = np.asarray(r, dtype=np.float64).ravel()
        if self.r_prev is not None:
            d = r - self.r_prev
            dd = float(d @ d)
            if dd > 0.0:
                self.omega = float(np.clip(-self.omega * float(self.r_prev @ d) / dd, *self.LIMITS))
        self.r_prev = r.copy()
        return self.omega
