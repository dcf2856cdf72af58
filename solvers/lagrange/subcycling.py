"""Element subcycling of the explicit Lagrangian solver (``[lagrange] subcycling = R``): each element
and node at the step its own size allows, up to R times the smallest, so that one small or crushed
element no longer sets the whole body's step.

The scheme is the nodal partition with straight-line interpolation of Belytschko, Yen & Mullen
("Mixed methods for time integration", CMAME 17/18, 1979), the one LS-DYNA's *CONTROL_SUBCYCLE uses
(its theory manual, "Subcycling (mixed time integration)": steps in powers of two of the smallest).
One step of the solver (what the coupler and the step control see) is a major step dt = 2^K h, made
of 2^K substeps h:

* levels, from each element's stable step dte_e (the kernel's, at the end of a major step) and the
  smallest of them, h_min: an element's own level is the largest L <= log2 R with
  2^L s h_min <= MARGIN dte_e, s the share that advances the body fastest (cheapest_share), re-taken
  every WINDOW major steps (rising one level at a time); a node's level is the smallest of its
  elements' (it moves at the step of its stiffest element); an element is evaluated at the smallest
  level of its nodes (an element between fine and coarse nodes at the fine rate).  The substep h is
  the largest at which every element's own period 2^L h is within its stable step, re-taken every
  major step;
* substep j (t = t^n + j h): the nodes whose period 2^L divides j get their kick v += dt_avg f / m
  with the force of all their elements (every one of them is evaluated at the node's times: its
  level is at most the node's); a coarse node follows its straight path x^n + (t - t^n) v^{n+1/2}
  between its kicks (the interpolation of the method), taken where it is needed: at the period of
  its finest element (its position level), x += 2^P h v; then the elements whose period divides
  j + 1 are evaluated, their stress updated over their own period 2^L h (the velocities of their
  nodes are constant over it: a node's period is a multiple of it).  Each substep visits only the
  nodes due (sorted by level: those due are a prefix); the element kernel skips the others;
* every period divides 2^K: at the major step's ends every node is kicked and moved and every
  element evaluated (output, checkpoints and re-binning fall there).

An element's step is the single-rate one at its own size; the stability of the scheme with integer
ratios under element-wise Courant limits is Belytschko-Yen-Mullen's (the interface elements
evaluated at the fine rate).  The balances book what every node got, as the single-rate step does
(W_int, the reactions' work, impulse, torque): exact.  What the nodal partition does not conserve is
momentum at the interface elements: a coarse node takes an interface element's force at its own times
only, the fine nodes at every substep; the net impulse of the internal forces this leaves (a
quadrature difference, O(h) of the interface's impulse) is reported as ``subcycling_impulse`` and is
what ``momentum_balance_rel`` then shows (solvers/lagrange/solver.py: diagnostics).

Rigid walls hold each node over its own step; gravity and the surface loads (at the time of each
node's force evaluation) are booked at its kicks, as the single-rate step books them.  Not with (the
case schema refuses them in one line): coupling and contact (their multipliers are solved at one
step for the whole group), the implicit and quasi-static integrators.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers.lagrange.nodal import account_node, add_torque
from solvers.lagrange.solver import LagrangeSolver, SolverError

MARGIN = 0.9
"""The share of an element's stable step its period may take to be binned above the finest level:
the period is held for a whole major step (up to R substeps) while the element deforms; the finest
level keeps the single-rate margin (its step h_min, re-taken every major step)."""



SHARE_BINS = 64
"""Bins per octave of the candidate shares of the substep (_cheapest_share): 1.1 % apart."""

WINDOW = 8
"""Major steps between re-takings of the elements' own levels (an element rises at most one level
each time; it falls at once): the step control's window for the stable step (orchestrator/
step_control.py: fluctuations of a few steps reach the highest modes' resonance)."""


@njit(cache=True)
def trailing_levels(j, top):
    """The highest level whose period 2^level divides substep j (top for j = 0, every level)."""
    if j == 0:
        return top
    k = 0
    while k < top and (j >> (k + 1)) << (k + 1) == j:
        k += 1
    return k


@njit(cache=True)
def kick_nodes(v, v_old, f, inv_mass, order, count, level, j, h, step_prev, first, dt_avg):
    """Substep j of a major step of substeps h: the nodes order[:count] (those whose period 2^level
    divides j) take their kick v += dt_avg f / m, dt_avg their own step ((previous + this) / 2 at
    j = 0, half of it on the first step); dt_avg[i] and v_old[i] (v before) are kept for the balances."""
    dim = v.shape[1]
    for k in range(count):
        i = order[k]
        H = (1 << level[i]) * h
        if j > 0:
            dta = H
        elif first:
            dta = 0.5 * H
        else:
            dta = 0.5 * (step_prev[i] + H)
        dt_avg[i] = dta
        for c in range(dim):
            v_old[i, c] = v[i, c]
            v[i, c] += dta * f[i, c] * inv_mass[i]


@njit(cache=True)
def move_nodes(x, v, order, count, level, h):
    """The nodes order[:count] (those whose position is needed at the end of this substep: their
    position level's period divides it) move over that period, x += 2^level h v (their velocity is
    constant over it: their kicks fall at multiples of it)."""
    dim = v.shape[1]
    for k in range(count):
        i = order[k]
        s = (1 << level[i]) * h
        for c in range(dim):
            x[i, c] += s * v[i, c]


@njit(cache=True)
def rigid_wall_nodes(x, v, point, normal, order, count, level, h):
    """nodal.rigid_wall for the nodes order[:count] (those kicked now), each over its own step
    2^level h: none may cross the plane before its next kick (tangential motion free)."""
    dim = v.shape[1]
    for k in range(count):
        i = order[k]
        H = (1 << level[i]) * h
        gap = 0.0
        vn = 0.0
        for c in range(dim):
            gap += (x[i, c] - point[c]) * normal[c]
            vn += v[i, c] * normal[c]
        if gap + H * vn < 0.0:
            dv = -gap / H - vn
            for c in range(dim):
                v[i, c] += dv * normal[c]


@njit(cache=True)
def element_steps(level, t, h, out):
    """out[e] = the step of element e's evaluation at the end of a substep whose highest dividing
    level is t (its period 2^level h, when level <= t), -1 where it is not evaluated then
    (kernels.element_forces_levels)."""
    for e in range(level.shape[0]):
        out[e] = (1 << level[e]) * h if level[e] <= t else -1.0


@njit(cache=True)
def copy_rows(dst, src, order, count):
    """dst[i] = src[i] for i in order[:count]."""
    for k in range(count):
        i = order[k]
        for c in range(src.shape[1]):
            dst[i, c] = src[i, c]


@njit(cache=True)
def zero_rows(a, order, count):
    """a[i] = 0 for i in order[:count]."""
    for k in range(count):
        i = order[k]
        for c in range(a.shape[1]):
            a[i, c] = 0.0


@njit(cache=True)
def account_nodes(x, v, v_old, v_free, f, fg, fl, mass, owned, order, count, dt_avg, sums, dv_prev):
    """The kicked nodes' (order[:count]) share of the balances (nodal.account_node, as
    update_and_account takes it, at each node's own dt_avg: W_int, the reactions' work, impulse and
    torque about x at the kick, E_hf), added into ``sums``: its entries 10-12 the net internal
    impulse dt_avg (f - fg - fl), what the partition does not conserve; 13 the reactions' gross size;
    14, 15 the work of gravity fg and of the surface loads fl (in f) on the mean velocity, 16-18 their
    impulse, 19-21 its torque, booked as solver.py's _book_force books them.  Returns (the first node
    whose velocity is not finite or -1, the node of the largest m |dv - dv_prev|^2, that value)."""
    dim = v.shape[1]
    bad = -1
    worst = -1
    worst_val = -1.0
    r = np.zeros(3)
    xi = np.zeros(3)
    fe = np.zeros(3)
    no_impulse = np.empty((0, dim))
    for k in range(count):
        i = order[k]
        w = 1.0 if owned[i] else 0.0
        dta = dt_avg[i]
        wi, we, hf, _, nonfinite = account_node(i, x, v, v_old, v_free, f, mass, no_impulse, False, dta, dv_prev,
                                                r, xi)
        if nonfinite and bad < 0:
            bad = i
        gross = 0.0
        wg = 0.0
        wl = 0.0
        for c in range(3):
            fe[c] = 0.0
        for c in range(dim):
            vbar = 0.5 * (v_old[i, c] + v[i, c])
            sums[10 + c] += w * dta * (f[i, c] - fg[i, c] - fl[i, c])
            gross += abs(r[c])
            wg += dta * fg[i, c] * vbar
            wl += dta * fl[i, c] * vbar
            fe[c] = dta * (fg[i, c] + fl[i, c])
        sums[0] += w * wi
        sums[1] += w * we
        for c in range(3):
            sums[2 + c] += w * r[c]
        add_torque(sums, 5, xi, r, w)
        hf *= mass[i]
        sums[8] += w * hf
        sums[13] += w * gross
        sums[14] += w * wg
        sums[15] += w * wl
        for c in range(3):
            sums[16 + c] += w * fe[c]
        add_torque(sums, 19, xi, fe, w)
        if hf > worst_val:
            worst_val = hf
            worst = i
    return bad, worst, worst_val


def cheapest_share(r: np.ndarray, top: int, allsum=lambda a: a) -> float:
    """The share s of the smallest element's step h_min the levels are binned on, 1/2 < s <= 1,
    that advances the body fastest for its element evaluations (``r``: the live elements' MARGIN dte
    / h_min, ``top``: the highest level; ``allsum``: the ranks' sum, collective).  Binned on s h_min,
    an element sits at level floor(log2(r / s)); as s falls from 1 the elements rise a level one by
    one (at s = r / 2^(L+1)), halving their cost, while the substep s h_min shrinks.  Maximising
    s / sum_e 2^-L_e(s) keeps a cluster of like elements in one level instead of splitting it at a
    bin's edge.  A cantilever's rows at 8.5 and 9 times its corner's step split between levels 2 and
    3 at s = 1: every element then at a fine-coarse interface, where the nodal partition is least
    accurate (its tip 0.66 % of the peak off the single-rate run with the levels re-taken every step,
    against 0.03 % for the coarse step alone, and 2-4 % with levels forced to alternate row by row);
    s = 0.95 puts them all at level 3 (0.018 %).  (The substep itself is then the largest the levels
    allow: _take_substep.)  The candidates are binned (SHARE_BINS per octave) so that ranks add
    histograms, not elements."""
    level = np.clip(np.floor(np.log2(r)), 0, top)
    weight = np.exp2(-level)
    rises = (level < top) & (r >= 1.0)
    s_rise = r[rises] / np.exp2(level[rises] + 1.0)      # in (1/2, 1]
    b = np.clip(np.floor((np.log2(s_rise) + 1.0) * SHARE_BINS), 0, SHARE_BINS - 1).astype(np.int64)
    hist = np.bincount(b, weights=0.5 * weight[rises], minlength=SHARE_BINS).astype(np.float64)
    tot = allsum(np.concatenate([hist, [weight.sum()]]))
    hist, cost1 = tot[:-1], tot[-1]
    if not cost1 > 0.0:
        return 1.0
    edges = np.exp2(np.arange(SHARE_BINS) / SHARE_BINS - 1.0)   # each bin's lower edge
    cost = cost1 - np.cumsum(hist[::-1])[::-1]                  # at s = edge: the bins above it risen
    speed = edges / np.maximum(cost, 1e-300)
    best = int(np.argmax(speed))
    return float(edges[best]) if speed[best] > (1.0 + 1e-12) / cost1 else 1.0


class SubcyclingSolver(LagrangeSolver):
    """The explicit solver with element subcycling (module docstring); its step is the major step."""

    STATE_NODES = LagrangeSolver.STATE_NODES + ("node_step_prev",)
    STATE_CELLS = LagrangeSolver.STATE_CELLS + ("dte", "own_level")
    STATE_VECTORS = LagrangeSolver.STATE_VECTORS + ("subcycling_impulse",)
    STATE_SCALARS = LagrangeSolver.STATE_SCALARS + ("share", "since_rebin")

    def __init__(self, comm, case: dict):
        ratio = int(case["lagrange"].get("subcycling", 1))   # (a power of two: the schema's
        self.max_level = int(round(math.log2(ratio)))          # integrators.SUBCYCLING_RATIOS)
        self._dt_el = None   # the kernel pass's per-element steps (None: every element at dt_prev)
        self.dte = None
        self.own_level = None  # each element's own level (its stable step's), with its rise held back
        self.since_rebin = 0   # major steps since the own levels were last re-taken
        self.share = 1.0       # the share of the smallest element's step the levels are binned on (cheapest_share)
        super().__init__(comm, case)
        if self.contact is not None:
            raise ValueError("subcycling: not with contact yet (the case schema refuses it: lagrange.subcycling)")
        nn = len(self.x)
        # gravity m g and the surface loads at each node's last force evaluation (its kick's)
        self._fg = self.mass[:, None] * self.gravity if self.has_gravity else np.zeros((nn, self.dim))
        self._fl = self._load_local(self.time) if self.loads is not None else np.zeros((nn, self.dim))
        self.node_step_prev = np.zeros(nn)    # each node's last own step (its dt_avg at the next kick)
        self.node_dt_avg = np.zeros(nn)
        self.subcycling_impulse = np.zeros(self.dim)
        self._sums_sc = np.zeros(22)
        self._dt_el_buf = np.zeros(len(self.conn))
        self._h = 0.0
        self._rebin()

    # ---- levels ------------------------------------------------------------------------------------
    def _element_kernel(self, dt_prev: float) -> tuple:
        ne = len(self.conn)
        if self.dte is None:   # (the base's set-up makes the first pass: all elements, at dt_prev)
            self.dte = np.full(ne, np.inf)
        dt_el = self._dt_el if self._dt_el is not None else np.full(ne, dt_prev)
        return super()._element_kernel(dt_prev, dt_el, self.dte)

    def _rebin(self) -> None:
        """The levels and the substep of the next major step (module docstring).  The elements' own
        levels are re-taken every WINDOW major steps, an element rising at most one level each time:
        levels that jitter with the bulk viscosity's share of the stable step (51 of 205 nodes
        changed level at every step of a ringing cantilever) pump the highest modes, as a jittering
        step does (orchestrator/step_control.py); re-taking them takes a few passes over the elements
        and nodes.  The substep follows every step: the largest at which every element's period
        2^level h is within its stable step (collective)."""
        self.since_rebin += 1
        if self.own_level is None or self.since_rebin >= WINDOW:
            self.since_rebin = 0
            top = self.max_level
            live = (self.alive == 1) & np.isfinite(self.dte)
            h_min = self._dt_stable
            fits = np.full(len(self.conn), top, np.int64)   # (an eroded element holds no node back)
            if np.isfinite(h_min) and h_min > 0.0:
                r = MARGIN * self.dte[live] / h_min
                self.share = cheapest_share(r, top, self._allsum)
                fits[live] = np.clip(np.floor(np.log2(r / self.share)), 0, top).astype(np.int64)
            self.own_level = fits if self.own_level is None else np.minimum(fits, self.own_level + 1)
            self._levels()
        self._take_substep()

    def _take_substep(self) -> None:
        """The largest substep at which every live element's own period is within its stable step."""
        live = (self.alive == 1) & np.isfinite(self.dte)
        h = float(np.min(self.dte[live] / np.exp2(self.own_level[live]))) if live.any() else np.inf
        self._h_stable = self._min(h)

    def _levels(self) -> None:
        """The nodes' and elements' levels from the elements' own (module docstring), and the orders
        the substeps take the nodes in (by level: those due at a substep are a prefix)."""
        self.node_level = self._node_min(self.own_level)
        self.element_level = self.node_level[self.conn].min(axis=1)
        # a node's position is needed where one of its elements is evaluated: at its position level,
        # the smallest of its elements' (<= its own; over every rank's elements: the copies agree)
        self.position_level = self._node_min(self.element_level)
        top = self.max_level
        self._kick_order = np.argsort(self.node_level, kind="stable").astype(np.int64)
        self._kick_count = np.searchsorted(self.node_level[self._kick_order], np.arange(top + 1), side="right")
        self._move_order = np.argsort(self.position_level, kind="stable").astype(np.int64)
        self._move_count = np.searchsorted(self.position_level[self._move_order], np.arange(top + 1), side="right")
        self._moved = len(self.x)
        node = self.node_level
        k = int(node.max()) if len(node) else 0
        self.levels = int(self.comm.allreduce(k, op=_max_op())) if self.comm.size > 1 else k
        # the element evaluations of a major step against every element at every substep (cost share)
        n = 1 << self.levels
        alive = self.alive == 1
        mine = np.array([float(np.sum(n >> self.element_level[alive])), float(alive.sum())])
        self._evaluations = self._allsum(mine)

    def _node_min(self, per_element: np.ndarray) -> np.ndarray:
        """Each node's smallest value of a level over its elements, every rank's at a shared node (a
        histogram of the levels summed in the one-rank order, shared_sums.py: its first non-empty bin)."""
        top = self.max_level
        nen = self.conn.shape[1]
        node = np.full(len(self.x), top, np.int64)
        np.minimum.at(node, self.conn.ravel(), np.repeat(per_element, nen))
        if self._cut:
            rows = np.flatnonzero(self._cut.row >= 0)
            buf = self._cut.buffer(top + 1)
            buf[self._cut.row[rows][:, None], np.arange(nen)[None, :], per_element[rows][:, None]] = 1.0
            hist = np.zeros((len(self.x), top + 1))
            self._cut.sum_into(buf, hist)
            sh = self._cut.shared
            node[sh] = np.argmax(hist[sh] > 0.0, axis=1)
        return node

    def _add_external_forces(self) -> None:
        """Gravity and the surface loads at this substep's time on the nodes moved now (those whose
        forces the next kicks read), kept per node for their booking at the kick."""
        if not hasattr(self, "_fl") or self._dt_el is None:
            super()._add_external_forces()
            if hasattr(self, "_fl") and self.loads is not None:
                self._fl[:] = self._load_local(self.time)
            return
        rows = self._move_order[:self._moved]
        if self.has_gravity:
            self.f[rows] += self._fg[rows]
        if self.loads is not None:
            self._fl[rows] = self._load_local(self.time)[rows]
            self.f[rows] += self._fl[rows]

    def _clear_forces(self) -> None:
        """Zero the forces of the nodes whose position moved this substep (every node of an element
        evaluated now is one; the others' forces are not read until theirs are)."""
        if self._dt_el is None:
            self.f[:] = 0.0
        else:
            zero_rows(self.f, self._move_order, self._moved)

    def _boundaries(self, due: int, h: float) -> None:
        """The velocity conditions on the nodes kicked now (bcs.apply's, each node over its own
        step): prescribed components on every node (unchanged on the others), rigid walls on those."""
        for nodes, c, val in self.bcs.prescribed:
            self.v[nodes, c] = val
        for point, normal in self.bcs.walls:
            rigid_wall_nodes(self.x, self.v, point, normal, self._kick_order, due, self.node_level, h)

    def stable_dt(self) -> float:
        return float((1 << self.levels) * self._h_stable) if np.isfinite(self._h_stable) else self._dt_stable

    def local_limiter(self) -> dict | None:
        """The element with the smallest step (the base of the levels), and what the body's step is
        of it."""
        d = super().local_limiter()
        if d is not None:
            n = 1 << self.levels
            d["detail"] += (f"; subcycled: the body's step {self.stable_dt() / d['dt']:.3g} times that "
                            f"element's, in {n} substeps")
        return d

    # ---- the major step ------------------------------------------------------------------------------
    def predict(self, dt: float) -> None:
        self.dt = dt
        self.dt_avg = 0.5 * dt if self.first_step else 0.5 * (self.dt_prev + dt)
        self._h = dt / (1 << self.levels)
        self._sums_sc[:] = 0.0
        kick_nodes(self.v, self.v_old, self.f, self.inv_mass, self._kick_order, len(self._kick_order),
                   self.node_level, 0, self._h, self.node_step_prev, self.first_step, self.node_dt_avg)

    def correct(self, impulse: np.ndarray | None = None, step: int = 0, time: float = 0.0,
                surface_impulse: np.ndarray | None = None) -> None:
        if impulse is not None or surface_impulse is not None:
            raise ValueError("subcycling: a subcycled body takes no coupling impulses (the schema refuses "
                             "[coupling] with lagrange.subcycling)")
        n, h = 1 << self.levels, self._h
        sums = self._sums_sc
        worst, worst_hf = -1, -1.0
        t0 = self.time
        for j in range(n):   # (a loop over substeps: each one is the kernels' pass over nodes and elements)
            due = self._kick_count[trailing_levels(j, self.levels)]
            if j:
                kick_nodes(self.v, self.v_old, self.f, self.inv_mass, self._kick_order, due, self.node_level, j, h,
                           self.node_step_prev, self.first_step, self.node_dt_avg)
            copy_rows(self.v_free, self.v, self._kick_order, due)
            self._boundaries(due, h)
            bad, w_at, w_hf = account_nodes(self.x, self.v, self.v_old, self.v_free, self.f, self._fg, self._fl,
                                            self.mass,
                                            self.part.owned, self._kick_order, due, self.node_dt_avg, sums,
                                            self._dv_prev)
            if bad >= 0:
                node = int(self.part.nodes[bad])
                b = int(self.body_of_node[node])
                raise SolverError(f"non-finite velocity at node {node} at step {step} (substep {j + 1} of {n}), "
                                  f"t={t0 + (j + 1) * h:.6g} s (body {self.body_names[b]!r}, its node "
                                  f"{node - int(self._body_first_node[b])})")
            if w_hf > worst_hf:
                worst, worst_hf = w_at, w_hf
            t = trailing_levels(j + 1, self.levels)
            self._moved = self._move_count[t]
            move_nodes(self.x, self.v, self._move_order, self._moved, self.position_level, h)
            element_steps(self.element_level, t, h, self._dt_el_buf)
            self._dt_el = self._dt_el_buf
            self.time = t0 + (j + 1) * h if j + 1 < n else time
            dt_min = self._forces(h)
        self._dt_el = None
        tot = self._allsum(np.concatenate([sums, [0.5 * float(np.sum(self.mass[self.part.owned, None]
                                                                    * self.v[self.part.owned] ** 2))]]))
        self.w_int += tot[0]
        self.w_ext += tot[1]
        self.impulse += tot[2:2 + self.dim]
        self.ang_impulse += tot[5:8] if self.dim == 3 else tot[7:8]
        self.impulse_gross += tot[13]
        self.subcycling_impulse += tot[10:10 + self.dim]
        self.w_gravity += tot[14]
        self.w_load += tot[15]
        self.impulse += tot[16:16 + self.dim]
        self.ang_impulse += tot[19:22] if self.dim == 3 else tot[21:22]
        self.supplied_gross += abs(tot[1]) + abs(tot[14]) + abs(tot[15])
        self.step, self.time = step, time
        self.first_step = False
        self.dt_prev = self.dt
        self.node_step_prev = (1 << self.node_level) * h
        self._dt_stable = dt_min if np.isfinite(dt_min) else self._dt_stable
        self._rebin()
        stored = float(self._allsum(self.e_int.sum()))
        created = tot[22] + stored - self.ke0 - self.se0 - (self.w_ext + self.w_gravity + self.w_load)
        if self.watch.update(step, tot[8] / 8.0, created, self.ke0 + self.se0 + self.supplied_gross):
            raise SolverError(self._growing_mode(step, time, worst, worst_hf))

    def diagnostics(self) -> dict[str, float]:
        d = super().diagnostics()
        p_scale = max(np.linalg.norm(self.p0), np.linalg.norm(self.momentum()), np.linalg.norm(self.impulse),
                      float(self.impulse_gross[0]), 1e-300)
        d["subcycling_substeps"] = float(1 << self.levels)
        # element evaluations per major step over those of every element at every substep (its cost share)
        n = 1 << self.levels
        d["subcycling_element_share"] = float(self._evaluations[0] / max(self._evaluations[1] * n, 1.0))
        for c, name in enumerate("xyz"[: self.dim]):
            d[f"subcycling_impulse_{name}"] = float(self.subcycling_impulse[c])
        d["subcycling_impulse_rel"] = float(np.linalg.norm(self.subcycling_impulse) / p_scale)
        return d

    def cell_fields(self) -> dict[str, np.ndarray]:
        """The explicit solver's, and each element's subcycling level (its evaluations every 2^level
        substeps: where the step ratio goes, for the analyst's picture)."""
        return {**super().cell_fields(), "subcycling_level": self.element_level.astype(np.float64)}

    def restart(self, path) -> None:
        super().restart(path)
        self._levels()
        self._take_substep()
        if self.loads is not None:   # (the loads in the checkpoint's forces: every node's, at its time)
            self._fl[:] = self._load_local(self.time)

    def snapshot(self) -> dict:
        raise ValueError("snapshot: a subcycled solver takes no coupled substeps")


def _max_op():
    from mpi4py import MPI

    return MPI.MAX


def _flush_stale_cache() -> None:
    """nodal.account_node and add_torque are compiled into account_nodes (solvers.numba_cache):
    drop these kernels' cache when nodal.py changed."""
    from solvers import numba_cache
    from solvers.lagrange import nodal

    numba_cache.flush_stale_cache([trailing_levels, kick_nodes, move_nodes, rigid_wall_nodes, element_steps,
                                   copy_rows, zero_rows, account_nodes], [nodal.__file__],
                                  "subcycling.deps.sha256")


_flush_stale_cache()
