"""Explicit dynamic contact: impulses from a multiplier solve at the end of every step, the same
operators as the static solve (issue 11, item 3; like the embedded-mesh constraint of the coupling:
no penalty stiffness, so the stable step is the bodies' own).

After the predictor, the surface nodes would move to x* = x^n + dt v*. The contact impulses I = dt
B^T p (p >= 0 per multiplier) change the velocities by M^-1 I, so the end-of-step positions are
x* + u with u = dt^2 M^-1 B^T p, and the constraint is the stabilized gap at the end of the step:

    g~ = B (x* + u) + J p >= 0,   p >= 0,   p g~ = 0.

That is kkt.solve_frictionless with the stiffness K = M / dt^2 (the nodes' inertia over the step)
and no load. K being diagonal, u is eliminated: what is solved is the multipliers' system
S p = -B x* on the active set, S = dt^2 B M^-1 B^T + J (kkt.solve_schur_complement). Approaching
nodes are stopped at the surface within the step (no penetration), and a multiplier that would pull
is released (no sticking). The impulses of a pass balance (B^T p sums to
zero), so momentum is exact.

A row that starts the step already in, beyond the stabilized gap it ended the last step at (a row
new to the set, found with a corner already across: a rod's end turning into a wall; or the
operator of a turned configuration), is held where it is, not pushed out: the gap's floor is
min(B x^n + (J p)_last, 0), (J p)_last the row's stabilized offset at the end of the last step (0
for a row that was not there), matched by the row's key (pair, pass, surface node). Pushed out
within one step, such a row's impulse did positive work: the spinning rod of
cases/rotating_rod_wall striking its walls, explicit with the dual pass, gained 10.7 J of its 52.7
over 0.4 s (one strike 17 J); held, the contact takes 11.2 J (each strike stops its nodes) and no
node is behind a wall (LS-DYNA's "initial penetrations ignored" holds them likewise). For a
row resting in contact the floor is 0 (its offset made up), so nothing sinks step by step.

Stabilization: J scaled so that alpha = 1 weighs it like the nodes'
inertia over the stable step dt_s, J_dyn = alpha * median(diag(dt_s^2 B M^-1 B^T)) / median(diag(J_1))
* J_1, with J_1 the operator of gamma h = 1 (J's static scale gamma = alpha / E has no meaning for
the inertia). dt_s, not the step's own dt: a shortened step (the landing on the end time) keeps
J (see impulses).

Prescribed velocity components (boundary conditions) are fixed dofs of the solve at their
prescribed values (the solver passes them so): the contact cannot move them. With friction (mu > 0)
the tangential impulses follow the normal ones (friction.py), unstabilized.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.contact import methods
from solvers.contact.kkt import solve_schur_complement
from solvers.contact.nodal_values import constraint_weights, nodal_mean, row_sums, scale_columns
from solvers.contact.penetration import paired_penetration
from solvers.sorted_ids import find_sorted

__all__ = ["ExplicitContact"]


class ExplicitContact:
    """Contact impulses of surface nodes (a solver's exterior surface, the same on every rank).

    pairs: [(body_a, body_b), ...] body indices (equal: self contact); method: a name of
    methods.METHODS; alpha: the stabilization's weight; capture: the search distance (also the
    deepest penetration still paired).
    """

    def __init__(self, pairs, method: str = "dual_pass_mortar", alpha: float = 1.0, capture: float | None = None,
                 friction: float = 0.0):
        self.pairs = [(int(a), int(b)) for a, b in pairs]
        self.friction = float(friction)  # Coulomb's mu (friction.py); 0: frictionless
        if method not in methods.METHODS:
            raise KeyError(f"contact method {method!r}: registered: {', '.join(sorted(methods.METHODS))}")
        self.method = method
        self.alpha = float(alpha)
        self.capture = capture
        self.last_active = 0
        self.last_sliding = 0
        self.multiplier_nodes = np.zeros(0, np.int64)   # the surface node of each multiplier
        self.last_pressure = np.zeros(0)                # each multiplier's pressure of the last step
        # the last step's weighted end-of-step gaps B x and its B: turned into distances only when
        # written (nodal_gap), not every step
        self._gap_rows, self._gap_op, self._dim = np.zeros(0), None, 0
        self.slip = None                                # (ns,) accumulated slip, from set_surface on
        self._q_last, self._q_nodes = None, None        # the last friction impulses and their nodes
        # each row's key (pair, pass, surface node) and its stabilized offset J p at the end of the last
        # step (sorted by key): the floor of the next step's gap (module docstring)
        self._last_keys, self._last_offset = np.zeros(0, np.int64), np.zeros(0)
        self.last_sweeps = 0                            # the friction solve's sweeps of the last step
        # the deepest a surface node lay behind its partner's surface at the end of the last step and
        # over the run, [self pairs, pairs of two bodies] (m; penetration.py, measured every step)
        self.last_penetration = np.zeros(2)
        self.penetration_max = np.zeros(2)
        self._measured = np.zeros(0, np.int64)          # the last step's measured nodes

    def set_surface(self, facets: np.ndarray, body: np.ndarray, mass: np.ndarray, free: np.ndarray) -> None:
        """facets (nf, 2 | 4) outward segments or quadrilaterals as indices into the surface nodes; body (nf,); mass (ns,);
        free (ns, dim) 1 where a velocity component is not prescribed."""
        self.facets, self.body = np.asarray(facets), np.asarray(body)
        self.mass, self.free = np.asarray(mass, float), np.asarray(free, float)
        # the tangential slip accumulated at every surface node (friction): |slip rate| dt summed over
        # the steps, the rate of each multiplier row T v over its weight, averaged per node
        if self.slip is None or len(self.slip) != len(self.mass):
            self.slip = np.zeros(len(self.mass))
        self.node_body = np.full(len(self.mass), -1, np.int64)
        self.node_body[self.facets] = self.body[:, None]
        self._measured = self._measured[self._measured < len(self.mass)]

    def _operators(self, x: np.ndarray, zone: np.ndarray | None = None):
        if self.capture is None:  # a segment: far more than a step's approach, less than a body
            self.capture = float(np.median(np.linalg.norm(x[self.facets[:, 1]] - x[self.facets[:, 0]], axis=1)))
        keep = np.ones(len(self.facets), bool) if zone is None else np.all(zone[self.facets], axis=1)
        blocks_b, blocks_j, blocks_t, nodes, keys = [], [], [], [], []
        ns = len(x)
        for k, (a, b) in enumerate(self.pairs):
            seg_a = self.facets[(self.body == a) & keep]
            seg_b = None if a == b else self.facets[(self.body == b) & keep]
            c = methods.build(self.method, x, seg_a, seg_b, self.capture, self.capture)
            if c.n_multipliers:
                passes = [q.nodes for q in c.passes] if hasattr(c, "passes") else [c.nodes]
                nodes.append(np.concatenate(passes))
                keys.append(np.concatenate([q + (2 * k + i) * ns for i, q in enumerate(passes)]))
                blocks_b.append(c.constraint_operator())
                blocks_j.append(c.stabilization(1.0, 1.0))
                if self.friction > 0.0:
                    if not hasattr(c, "tangent_operator"):
                        raise NotImplementedError(f"friction with {self.method!r}: only the mortar methods")
                    blocks_t.append(c.tangent_operator())
        self.multiplier_nodes = np.concatenate(nodes).astype(np.int64) if nodes else np.zeros(0, np.int64)
        self._keys = np.concatenate(keys).astype(np.int64) if keys else np.zeros(0, np.int64)
        if not blocks_b:
            return None, None, None
        if len(blocks_b) == 1:  # (one pair: no stacking, each scipy call costs ~50 us)
            return blocks_b[0].tocsr(), blocks_j[0].tocsr(), blocks_t[0].tocsr() if blocks_t else None
        T = sp.vstack(blocks_t, format="csr") if blocks_t else None
        return sp.vstack(blocks_b, format="csr"), sp.block_diag(blocks_j, format="csr"), T

    def _floor(self, B, x: np.ndarray) -> np.ndarray:
        """Each row's floor of the stabilized gap: min(B x^n + (J p)_last, 0) (module docstring)."""
        start = B @ x.reshape(-1)
        last = np.zeros(len(start))
        i, hit = find_sorted(self._last_keys, self._keys)
        last[hit] = self._last_offset[i[hit]]
        return np.minimum(start + last, 0.0)

    def _remember(self, offset: np.ndarray) -> None:
        order = np.argsort(self._keys, kind="stable")
        self._last_keys, self._last_offset = self._keys[order], np.asarray(offset, float)[order]

    def impulses(self, x: np.ndarray, v: np.ndarray, dt: float, dt_force: float | None = None,
                 dt_scale: float | None = None, zone: np.ndarray | None = None) -> np.ndarray:
        """(ns, dim) contact impulses of the step: x = x^n and v = v* (predictor, after any other
        impulse) of the surface nodes.  dt_force: the time the step's forces act over in the central
        difference ((dt_prev + dt) / 2; default dt), by which the reported pressures are impulses
        (the impulses are dt B^T p: a shortened step, the landing on the end time, would otherwise
        show its pressure dt_force / dt too high).  dt_scale: the step J's scale is weighed with
        (default dt; the solver passes its stable step). J p is the offset of the stabilized gap the
        surfaces rest at: a J that shrank with a shortened step (once: steps clipped onto output
        times) pushed them apart in that step (a kick of |J p| / dt, 5e-5 m/s on a block resting on
        an incline, that made it slip).
        zone: (ns,) bool, the surface nodes whose states x and v hold (zone.py: the nodes near a
        partner body); only the facets all of whose nodes are in it are searched (default: all)."""
        x = np.asarray(x, float)
        ns, dim = x.shape
        out = np.zeros((ns, dim))
        B, J1, T = self._operators(x, zone)
        self.last_active = 0
        self.last_sliding = 0
        self.last_pressure = np.zeros(len(self.multiplier_nodes))
        self._gap_rows, self._gap_op, self._dim = np.zeros(len(self.multiplier_nodes)), None, dim
        self.last_held_impulse = out
        if B is None:
            self._remember(np.zeros(0))
            self._measure_penetration(x + dt * np.asarray(v, float), zone)
            return out
        inv_m = np.repeat(np.where(self.mass > 0, 1.0 / np.where(self.mass > 0, self.mass, 1.0), 0.0), dim)
        inv_m = inv_m * self.free.reshape(-1)
        j1 = J1.diagonal()

        def weight(op, factor):
            """J's scale: alpha times the median of diag(factor op M^-1 op^T) over J_1's (module docstring)."""
            w = row_sums(op, op.data * op.data * inv_m[op.indices]) * factor
            return self.alpha * np.median(w[w > 0]) / np.median(j1[j1 > 0]) if np.any(j1 > 0) and np.any(w > 0) else 0.0

        # J p is the offset of the stabilized gap: with p the physical pressure, the same in a
        # shortened step (the landing on the end time). The step's p is its impulse over dt, which
        # the central difference's forces give over dt_force: p dt / dt_force is the pressure, so J
        # is scaled by dt / dt_force (with J fixed, a block resting in 3-D was kicked at every output
        # time when steps were clipped onto them)
        scale = weight(B, (dt_scale or dt) ** 2) * (dt / (dt_force or dt))
        xstar = (x + dt * np.asarray(v, float)).reshape(-1)
        # K = M/dt^2 is diagonal: the displacements u = dt^2 M^-1 B^T p eliminate, leaving the
        # multipliers' own system (the Schur complement of the KKT matrix, kkt.py's equations)
        floor = self._floor(B, x)
        g0 = B @ xstar - floor
        # the active set starts from the multipliers whose gap the predictor closes (the set the first
        # iteration from p = 0 would pick), not from all of them: the first factorisation is of the
        # approaching surface's rows only, not the whole system's (mostly gaps that stay open). The
        # solution (p > 0 exactly where its set settles) is the same: the same last factorisation.
        BT = B.T   # (one transposed view for the step's products)
        sol = solve_schur_complement(((dt * dt) * (scale_columns(B, inv_m) @ BT) + scale * J1).tocsc(), g0,
                                     active=g0 < 0.0, gap_tol=1e-12 * float((abs(B) @ np.abs(xstar)).max()))
        self.last_active = int(sol.active.sum())
        self.last_pressure = sol.p * (dt / (dt_force or dt))
        u = (dt * dt) * inv_m * (BT @ sol.p)
        self._gap_rows, self._gap_op = g0 + floor + B @ u, B
        self._remember(scale * (J1 @ sol.p))
        impulse = np.repeat(self.mass, dim) * u / dt
        # the pair's share on held components (0 in the impulse: the contact cannot move them), which
        # the supports take: the balances book its reaction (the contact itself is an internal pair)
        self.last_held_impulse = (dt * (BT @ sol.p) * (1.0 - self.free.reshape(-1))).reshape(ns, dim)
        if T is not None and self.last_active:
            # Coulomb: the tangential impulses on the velocities after the normal ones, bounded by mu
            # times each row's normal impulse dt p_A (friction.py)
            from solvers.contact.friction import disc_qp_gauss_seidel

            # W = T M^-1 T^T without the stabilization: stick is T v = 0 itself. With J_t the stuck
            # rows held T v = -J_t q instead, a slip rate as large as the friction impulse's jump
            # between the passes: a block at rest on a 10 degree incline (mu = 0.2) crept at 2.7 um/s;
            # without, it stays to 1e-16 m/s. W is singular (the passes' rows are redundant); the
            # Gauss-Seidel iteration takes any of the equivalent splittings of q.
            v1 = np.asarray(v, float).reshape(-1) + u / dt
            TT = T.T
            W = (scale_columns(T, inv_m) @ TT).tocsr()
            bound = self.friction * dt * sol.p
            k = dim - 1                      # tangential components per multiplier (T's row blocks)
            # warm start: the last step's q where the multipliers are the same nodes
            same = self._q_last is not None and np.array_equal(self._q_nodes, self.multiplier_nodes)
            q, self.last_sweeps = disc_qp_gauss_seidel(W, T @ v1, bound, start=self._q_last if same else None)
            self._q_last, self._q_nodes = q, self.multiplier_nodes
            q_size = np.linalg.norm(q.reshape(-1, k), axis=1)
            self.last_sliding = int(np.sum((bound > 0) & (q_size >= bound * (1 - 1e-9))))
            tq = TT @ q
            impulse = impulse + tq
            u = u + dt * inv_m * tq
            # slip where the surfaces touch: pressed, or closed to within the stabilized gap's offset
            # J p (a dual pass's redundant row may rest at p = 0; the gaps of pressed rows scatter by
            # J p, +-1e-8 m on a sliding block). An open row's tangential rate is flight, not slip.
            on = (sol.p > 0.0) | (self._gap_rows <= np.abs(scale * (J1 @ sol.p)).max())
            rate = (np.linalg.norm((T @ (v1 + inv_m * tq)).reshape(-1, k), axis=1)[on]
                    / constraint_weights(T, dim)[::k][on])
            self.slip += dt * nodal_mean(self.multiplier_nodes[on], rate, ns, 0.0)
        self._measure_penetration((xstar + u).reshape(ns, dim), zone)
        return impulse.reshape(ns, dim)

    def _measure_penetration(self, x_end: np.ndarray, zone: np.ndarray | None) -> None:
        """The deepest a surface node lies behind its partner's surface at the end of the step
        (penetration.py, down to the capture: the deepest still paired), for the self pairs and the
        pairs of two bodies; and their maxima over the run. Measured: the nodes that carry a
        multiplier this step or did the last (a node behind a facet within the capture has a row; one
        that crossed the band in a step had one the step before), against the facets of the bodies
        paired with its own, the nearest deciding (one search for all pairs)."""
        cand = np.union1d(self.multiplier_nodes, self._measured)
        keep = np.ones(len(self.facets), bool)
        if zone is not None:                 # (only the zone's states hold)
            cand = cand[zone[cand]]
            keep = np.all(zone[self.facets], axis=1)
        self._measured = self.multiplier_nodes.copy()
        pen, own = paired_penetration(x_end, self.facets[keep], self.body[keep], cand, self.node_body[cand],
                                      self.pairs, float(self.capture))
        step = np.array([pen[own].max(initial=0.0), pen[~own].max(initial=0.0)])
        self.last_penetration = step
        self.penetration_max = np.maximum(self.penetration_max, step)

    def state(self) -> dict[str, np.ndarray]:
        """What a restart needs to continue bit for bit: the rows' keys and stabilized offsets of the
        last step (the next floor); with friction the accumulated slip, and the last friction
        impulses with their multipliers' nodes (the next solve's warm start)."""
        out = {} if self.slip is None else {"slip": self.slip}
        out.update(last_keys=self._last_keys, last_offset=self._last_offset,
                   penetration_max=self.penetration_max, measured_nodes=self._measured)
        if self._q_last is not None:
            out.update(friction_q=self._q_last, friction_nodes=self._q_nodes)
        return out

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        if "slip" in state:
            self.slip = np.asarray(state["slip"], dtype=np.float64)
        if "last_keys" in state:   # (checkpoints before the floor: none, every row new)
            self._last_keys = np.asarray(state["last_keys"], dtype=np.int64)
            self._last_offset = np.asarray(state["last_offset"], dtype=np.float64)
        if "penetration_max" in state:   # (checkpoints before the measure: from the restart on)
            self.penetration_max = np.asarray(state["penetration_max"], dtype=np.float64)
            self._measured = np.asarray(state["measured_nodes"], dtype=np.int64)
        if "friction_q" in state:
            self._q_last = np.asarray(state["friction_q"], dtype=np.float64)
            self._q_nodes = np.asarray(state["friction_nodes"], dtype=np.int64)

    def nodal_gap(self, ns: int) -> np.ndarray:
        """(ns,) the gap (m) at the end of the last step at the surface nodes: the mean over the
        multipliers a node carries, the capture distance where it carries none (nothing facing it
        within reach)."""
        gap = self._gap_rows
        if self._gap_op is not None:
            gap = gap / constraint_weights(self._gap_op, self._dim)
        return nodal_mean(self.multiplier_nodes, gap, ns, self.capture or 0.0)

    def nodal_pressure(self, ns: int) -> np.ndarray:
        """(ns,) the last step's contact pressure at the surface nodes: the mean of the multipliers a
        node carries (both passes of the dual pass), 0 where it carries none (node-to-surface methods:
        their multipliers are forces per unit thickness, reported as they are)."""
        return nodal_mean(self.multiplier_nodes, self.last_pressure, ns, 0.0)

