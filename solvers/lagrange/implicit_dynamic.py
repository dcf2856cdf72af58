"""Implicit dynamic modes of the Lagrangian solver (issue 12): ``[lagrange] integrator = "midpoint"``
(the energy-momentum midpoint scheme) or ``"newmark"`` (the trapezoidal rule, kept as the comparison
that fails), one step of ``[lagrange] time_step`` seconds at a time (implicit_step.py).

Bodies: ``linear_elastic`` materials are taken as St. Venant-Kirchhoff (the same E, nu; Green strain
and second Piola-Kirchhoff stress: identical at small strain, and frame-indifferent under large
rotations, which Hooke's law on the small strain is not), ``neo_hookean`` ones by Gonzalez's discrete
gradient (discrete_gradient_nh.py), on the elements of finite_strain.py; the masses are the explicit
solver's lumped ones. Loads: gravity (m g, constant), tractions times their
curves (loads.py: the midpoint scheme takes them at t_{n+1/2}, Newmark at t_n and t_{n+1}), boundary
conditions (fixed, velocity, symmetry: prescribed velocities; the residual there is the reaction).
Contact: the midpoint scheme's the seed's three steps (implicit_step.py step 1, _contact_update steps
2 and 3); Newmark's the trapezoid's own, the multipliers at the step's end and nothing after (the
comparison). Not yet: coupling, friction, plastic materials, erosion, rigid walls (refused by the
schema).

Balances (the explicit solver's diagnostics, fed the implicit step's exact quantities): the strain
energy U(u) is the internal work, gravity's work sum m g . (u1 - u0), the tractions' F . (u1 - u0)
and the reactions' R . (u1 - u0) the external; over a midpoint step T + U changes by exactly that work
(to the Newton tolerance), and the impulses (m g + F + R) dt and their moments about x_{n+1/2} close
the momenta (Newmark: F the mean of the step's two ends; its balances are not exact).
A step whose Newton iteration fails, or after which the energy balance is off by more than
``energy_limit`` (default 0.01 of the energy: Newmark on a large rotation), stops the run naming the
scheme, the step and the numbers (SolverError), never NaN.

Parallel: every rank holds the global mesh; the elements' matrices and forces are evaluated in
parallel (each rank a contiguous share of every body's elements, gathered with Allgatherv), every
rank assembles the whole system, and the solves (SuperLU, the contact's KKT) run on rank 0 and are
broadcast (gathered_step.RankShare); each rank keeps its own nodes' and elements' share. The ranks
agree bit for bit; the problem size is bounded by one rank's memory, and the solves do not get
faster with ranks.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.lagrange import discrete_gradient_nh, finite_strain, midpoint_svk
from solvers.lagrange.boundary import BoundaryConditions
from solvers.contact.implicit_update import release_impulse, remove_gap_rate
from solvers.lagrange.gathered_contact import GatheredContact
from solvers.lagrange.gathered_step import GatheredStepSolver, RankShare
from solvers.lagrange.implicit_step import StepFailed, midpoint_step, newmark_step
from solvers.lagrange.solver import LagrangeSolver, SolverError

__all__ = ["MidpointSolver", "NewmarkSolver"]


class _ImplicitDynamicSolver(GatheredStepSolver):
    scheme = ""
    step_function = None
    # the displacements are the state: checkpointed as they are (x - X would round them)
    STATE_NODES = LagrangeSolver.STATE_NODES + ("u_local",)

    def __init__(self, comm, case: dict):
        super().__init__(comm, case)
        self.contact = None
        opts = case["lagrange"]
        self.time_step = float(opts["time_step"])
        self.time_step_min = float(opts.get("time_step_min", self.time_step / 1024.0))
        self.energy_limit = float(opts.get("energy_limit", 0.01))
        self.case_dt_scale = float(case["run"].get("dt_scale", 0.9))
        self.substeps = 0
        self._ask_for(self.time_step)
        P, C = self.global_points, self.global_cells
        n, dim = len(P), self.dim
        self._blocks = []
        for k, b in enumerate(case["lagrange"]["bodies"]):
            mat = case["materials"][b["material"]]
            mu, lam = finite_strain.lame(mat["youngs_modulus"], mat["poisson_ratio"])
            self._blocks.append((C[self.body_of_cell == k], mu, lam, mat.get("model", "linear_elastic")))
        # the ranks' share of a step (gathered_step.RankShare): the elements evaluated in parallel,
        # the solves on rank 0
        self._ranks = RankShare(self.comm, self._blocks, P) if self.comm.size > 1 else None
        span = float(np.max(np.ptp(P, axis=0)))
        bcs = BoundaryConditions(case.get("boundaries", []), P, tol=1e-9 * span)
        fixed, vb = bcs.prescribed_arrays(n, dim)
        self._fixed = np.flatnonzero(fixed.ravel())
        self._v_fixed = vb.ravel()[self._fixed]
        self.gmass = self._global(self.mass[:, None])[:, 0]
        self.f_ext = (self.gmass[:, None] * self.gravity).ravel() if self.has_gravity else np.zeros(n * dim)
        self.u = np.zeros(n * dim)
        self.vg = self._global(self.v).ravel()
        self.vg[self._fixed] = self._v_fixed
        self.iterations = self.equilibrium_iterations = 0
        # contact (midpoint only): the seed's three steps (_contact_update); per multiplier key the
        # energy stored since its episode began, to be given back when it releases
        self._gcontact = None
        self.w_contact, self.contact_active, self.contact_stored = 0.0, 0, 0.0
        self.contact_force = np.zeros(dim)
        self._fc_end = np.zeros(n * dim)   # Newmark: the last step's end contact force (its next a0)
        self._active_keys: dict = {}
        # the rows of B active at the last step, in the order of sorted(self._active_keys): a release
        # gives the episode's energy back along them (the current B may no longer have those rows)
        self._last_rows = sp.csr_matrix((0, n * dim))
        self._stored: dict = {}
        if case.get("contact"):
            self._gcontact = GatheredContact(case["contact"], case, P, C, self.cell_type, self.body_of_cell,
                                             self.body_names)
            self._contact_body = self._gcontact.pairs[0][2]
        self._return_energy = bool((case.get("contact") or {}).get("return_energy", True))
        self.contact_lost = 0.0
        inv = np.zeros(n * dim)
        inv[np.setdiff1d(np.arange(n * dim), self._fixed)] = 1.0
        self._inv_mass = inv / np.repeat(self.gmass, dim)
        self._sync_local()
        # the initial balances' references on the velocities the step starts from (prescribed ones set)
        self.ke0, self.p0, self.l0 = self.kinetic_energy(), self.momentum(), self.angular_momentum()

    def _sync_local(self) -> None:
        """This rank's nodes and elements from the global state u, v."""
        P = self.global_points
        u = self.u.reshape(P.shape)
        self.u_local = u[self.part.nodes].copy()
        self.x = self.X + self.u_local
        self.v = self.vg.reshape(P.shape)[self.part.nodes].copy()
        sig = np.zeros((len(self.global_cells), 6))
        e = np.zeros(len(self.global_cells))
        for k, (cells, mu, lam, model) in enumerate(self._blocks):
            sel = self.body_of_cell == k
            mod = discrete_gradient_nh if model == "neo_hookean" else midpoint_svk
            sig[sel] = mod.cauchy_stresses(P, cells, u, mu, lam)
            e[sel] = mod.element_energies(P, cells, u, mu, lam)
        self.sig[:] = sig[self.part.cells]
        # each element's strain energy (J), on the rank that holds it (stress_power_energy), and the
        # bodies' total U (the global elements: every rank has them)
        self.e_int[:] = e[self.part.cells]
        self.strain_energy = float(e.sum())

    # ---- the step ----------------------------------------------------------------------------------
    def correct(self, impulse=None, step: int = 0, time: float = 0.0, surface_impulse=None) -> None:
        if impulse is not None or surface_impulse is not None:
            raise ValueError(f"{self.scheme}: no coupling impulses yet (issue 12)")
        dt = self.dt
        self.iterations, self.equilibrium_iterations, self.substeps, smallest = 0, 0, 0, dt
        try:
            smallest = self._advance(self.time, dt)
        except StepFailed as err:
            raise SolverError(f"{self.scheme} step {step} (t={time:.6g} s, dt={dt:.6g} s, halved down to "
                              f"lagrange.time_step_min = {self.time_step_min:.6g} s): {err}") from None
        self.step, self.time = step, time
        self.first_step = False
        self.dt_prev = dt
        self._sync_local()
        self.w_int = self.strain_energy - self.w_gravity - self.w_load
        d = super().diagnostics()
        if abs(d["energy_balance_rel"]) > self.energy_limit:
            raise SolverError(f"{self.scheme} step {step} (t={time:.6g} s, dt={dt:.6g} s): the energy balance is off "
                              f"by {d['energy_balance_rel']:.3g} of the energy (> lagrange.energy_limit = "
                              f"{self.energy_limit:g}): {self.scheme} does not keep the energy at this step")
        self._control(smallest)

    def _load_at(self, t: float) -> np.ndarray:
        """(n d,) the tractions' nodal forces at t (zeros without tractions; self.loads: the base
        solver's, on the global mesh)."""
        return self.loads.at(t).ravel() if self.loads is not None else np.zeros_like(self.u)

    def _step_loads(self, t0: float, dt: float) -> tuple[dict, np.ndarray]:
        """(the step function's load arguments, the step's mean traction force): the midpoint scheme's
        load at t_{n+1/2} (its work F . (u1 - u0) is then what the discrete energy takes up)."""
        fm = self._load_at(t0 + 0.5 * dt)
        return {"f_ext": self.f_ext + fm}, fm

    def _advance(self, t0: float, dt: float) -> float:
        """One step of dt from t0; a step whose Newton iteration fails is done as two of dt / 2 (down
        to time_step_min, then StepFailed). Books the works and impulses; returns the smallest step done."""
        P = self.global_points
        u0, v0 = self.u, self.vg
        loads, f_load = self._step_loads(t0, dt)
        if self._gcontact is not None:
            loads.update(contact=self._gcontact.dynamic_operators, active=self._active_keys)
        try:
            res = type(self).step_function(P, self._blocks, self.gmass, u0, v0, dt, fixed=self._fixed,
                                           v_fixed=self._v_fixed, ranks=self._ranks, **loads)
        except StepFailed:
            if 0.5 * dt < self.time_step_min * (1.0 - 1e-12):
                raise
            a = self._advance(t0, 0.5 * dt)
            return min(a, self._advance(t0 + 0.5 * dt, 0.5 * dt))
        du = res.u - u0
        force = self.f_ext + f_load + res.reaction
        # the works: gravity's into w_gravity and the tractions' into w_load (both out of w_int, as the
        # explicit kernel books them), the reactions' into w_ext; the impulses and their moments about
        # x_{n+1/2}
        self.w_gravity += float(self.f_ext @ du)
        self.w_load += float(f_load @ du)
        self.w_ext += float(res.reaction @ du)
        xm = P + (u0 + 0.5 * du).reshape(P.shape)
        fn = force.reshape(P.shape) * dt
        self.impulse += fn.sum(axis=0)
        self.ang_impulse += self._cross(xm, fn).sum(axis=0)
        self.impulse_gross += float(np.abs(fn).sum())
        self.u, self.vg = res.u, res.v
        if res.contact is not None:
            self._contact_update(res.contact, du, dt)
        self.iterations = max(self.iterations, res.iterations)
        changes = res.contact.set_changes if res.contact is not None else 0
        self.equilibrium_iterations = max(self.equilibrium_iterations, res.iterations - changes)
        self.substeps += 1
        return dt

    def _contact_update(self, c, du: np.ndarray, dt: float) -> None:
        """Steps 2 and 3 of the seed's contact update (solvers/contact/implicit_update.py) after the
        midpoint step (step 1) left v^{n+1} in self.vg and the contact c at t_{n+1/2}:

        2. the active rows' normal gap rate is removed, G vbar = 0 (no chatter; strictly dissipative);
        3. the energy a pair's contact episode took (step 1's work B^T p . du and step 2's losses)
           is given back when the episode ends, i.e. when none of the pair's rows is active any
           more, along the force its rows carried at the episode's last step (those rows weighted
           with its pressures: the releasing step's B need not have them, a rod's corner leaving a
           wall had dropped its row from it, and 8 J of a strike stayed lost). Kept per pair, not
           per row: the dual pass's two passes are redundant, so how step 2 splits its loss over
           the rows is arbitrary (on a ring bouncing on a floor single rows held +-1 J of a 0.08 J
           total) and a row released while its neighbours stay active would give back the wrong
           share.

        Both change velocities at x_{n+1}, so their rows are built there (GatheredContact.rows_at,
        the same keys; a key the operator no longer has there keeps its row as it was): a row of
        the dual pass is balanced and torque-free about the positions it is built at (the seed's
        "choice of contact normal n_A"), and the angular momentum sum x_{n+1} x m v^{n+1} is kept
        only by rows torque-free about x_{n+1}. With step 1's rows (x_{n+1/2}) for both, the spinning
        rod's first strike moved its angular momentum by 2.2e-3 of itself (rotating_rod_wall's first
        0.1 s; its balance 1.0e-4, measured).

        The contact is an internal pair in the balances: its forces and impulses are not booked as
        external impulses (they sum to zero, and to zero moment about the points they act at); only
        the share on held dofs, which the supports take, is (step 1's is in the reactions already).
        So the momentum balances check the pair: an operator built at the wrong time (B at x_n
        instead of x_{n+1/2}) leaves 2.9e-2 of the rod's angular momentum unaccounted at its first
        strike (its balance 7.6e-4 against 1.0e-12, measured), which the balance shows. The contact's work stays external work in the
        energy balance (w_contact). What a release cannot give back or take out along its
        direction is booked as contact_lost."""
        w0 = self.w_contact
        self.w_contact += float(c.force @ du)
        keys = c.keys
        n = self.n_nodes_global
        pair = keys // n
        step1 = c.p * (c.B @ du)                       # each row's work (<= 0 summed: dissipated)
        v = self.vg
        P = self.global_points
        x1 = P + self.u.reshape(P.shape)               # x_{n+1}: where steps 2 and 3 act
        rows = _active_rows(c)
        G = self._gcontact.rows_at(x1, keys[rows], c.B[rows])
        update = remove_gap_rate(G, self._inv_mass, v)
        pair_impulse = -(G.T @ update.multipliers)     # on every dof, held ones included
        stored = dict(self._stored)
        for q in np.unique(pair[rows]).tolist():
            on = pair[rows] == q
            stored[q] = stored.get(q, 0.0) - float(step1[rows][on].sum()) + float(update.per_row[on].sum())
        v_new = update.v
        m = np.repeat(self.gmass, self.dim)
        ke = lambda w: 0.5 * float(w @ (m * w))   # noqa: E731
        last = self._active_keys                    # {key: pressure} of the rows active at the last step
        last_keys = np.array(sorted(last), dtype=np.int64)   # (the order of self._last_rows)
        for q in sorted(stored):                    # (sorted: a restart's order)
            if np.any(pair[rows] == q):
                continue
            mine = np.flatnonzero(last_keys // n == q)
            k_total = stored.pop(q)
            if not self._return_energy or not len(mine):
                self.contact_lost += k_total
                continue
            w = np.array([last[k] for k in last_keys[mine].tolist()])
            released = self._gcontact.rows_at(x1, last_keys[mine], self._last_rows[mine])
            before = ke(v_new)
            give = release_impulse(released, self._inv_mass, v_new, w * (k_total / w.sum()))
            v_new = v_new + self._inv_mass * give
            pair_impulse += give
            self.contact_lost += k_total - (ke(v_new) - before)
        self._stored = stored
        by_key = np.argsort(keys[rows], kind="stable")
        order = rows[by_key]
        self._active_keys = {int(k): float(p) for k, p in zip(keys[order].tolist(), c.p[order].tolist())}
        self._last_rows = sp.csr_matrix(G[by_key])
        self.w_contact += ke(v_new) - ke(v)
        self.w_ext += self.w_contact - w0     # (the contact's work is external work in the energy balance)
        # the supports' reaction to the pair's share on held dofs: an external impulse at x_{n+1}
        held = np.zeros_like(pair_impulse)
        held[self._fixed] = -pair_impulse[self._fixed]
        held = held.reshape(P.shape)
        self.impulse += held.sum(axis=0)
        self.ang_impulse += self._cross(x1, held).sum(axis=0)
        self._book_contact_force(c, c.force, dt, len(rows), gross=float(np.abs(pair_impulse).sum()))
        self.vg = v_new
        self.contact_stored = float(sum(stored[k] for k in sorted(stored)))

    def _book_contact_force(self, c, f: np.ndarray, dt: float, active: int, gross: float = 0.0) -> None:
        """The contact force f (n d,) acting over the step, an internal pair (_contact_update): only
        its size into the balances' scale (with ``gross``, the size of the step's other contact
        impulses); the diagnostics' active rows and the force the first pair's first body takes at
        the step's end (c.force)."""
        P = self.global_points
        self.impulse_gross += gross + float(np.abs(f).sum()) * dt
        self.contact_active = int(active)
        self.contact_force = c.force.reshape(P.shape)[self.body_of_node == self._contact_body].sum(axis=0)

    def step_choice(self) -> tuple[str, str]:
        return ("step control", f"the {self.scheme} step's Newton control (time_step {self.time_step:g} s, "
                f"{int(self.iterations)} iterations last step)")

    def _control(self, smallest: float) -> None:
        """The next step from this one's Newton iterations (item 4 of issue 12): more than 8 halve it,
        3 or fewer grow it by 1.25 up to time_step (not counting the contact's iterations that changed
        its active set: the rotating rod's steps took 4 with one such, and a step halved once never
        grew back), a step that had to be split continues at the smallest part that converged; never
        below time_step_min. (A step shortened to land on the end
        time is judged against the controller's step, not its own.)"""
        ctrl = self._asked()
        if self.substeps > 1:
            ctrl = min(ctrl, smallest)
        elif self.iterations > 8:
            ctrl = 0.5 * ctrl
        elif self.equilibrium_iterations <= 3:
            ctrl = min(1.25 * ctrl, self.time_step)
        ctrl = max(ctrl, self.time_step_min)
        self._ask_for(ctrl)

    def diagnostics(self) -> dict[str, float]:
        d = super().diagnostics()
        d["newton_iterations"] = float(self.iterations)
        d["time_step"] = float(getattr(self, "dt", self.time_step))
        d["substeps"] = float(self.substeps)
        if self._gcontact is not None:
            d["contact_work"] = self.w_contact
            d["contact_active"] = float(self.contact_active)
            d["contact_stored_energy"] = self.contact_stored
            d["contact_lost_energy"] = self.contact_lost
            for c, name in enumerate("xyz"[: self.dim]):
                d[f"contact_force_{name}"] = float(self.contact_force[c])
        return d

    # ---- checkpoint / restart: u and v are the state ------------------------------------------------
    def _extra_state(self) -> dict:
        """The contact's accumulated works and, per multiplier key, the energy stored and the rows
        active at the last step (the next step's warm start and its releases)."""
        if self._gcontact is None:
            return {}
        keys = np.array(sorted(self._stored), dtype=np.int64)
        active = np.array(sorted(self._active_keys), dtype=np.int64)
        return {"contact_works": np.array([self.w_contact, self.contact_lost]),
                "stored_keys": keys, "stored": np.array([self._stored[k] for k in keys.tolist()], dtype=np.float64),
                "active_keys": active,
                "active_pressures": np.array([self._active_keys[k] for k in active.tolist()], dtype=np.float64),
                "last_rows_data": self._last_rows.data.copy(), "last_rows_indices": self._last_rows.indices.astype(np.int64),
                "last_rows_indptr": self._last_rows.indptr.astype(np.int64)}

    def _set_extra_state(self, state: dict) -> None:
        if self._gcontact is None:
            return
        self.w_contact, self.contact_lost = (float(v) for v in state["contact_works"])
        self._stored = dict(zip(state["stored_keys"].tolist(), state["stored"].tolist()))
        self._active_keys = dict(zip(state["active_keys"].tolist(), state["active_pressures"].tolist()))
        self._last_rows = sp.csr_matrix((np.asarray(state["last_rows_data"], np.float64),
                                         np.asarray(state["last_rows_indices"]), np.asarray(state["last_rows_indptr"])),
                                        shape=(len(state["last_rows_indptr"]) - 1, self.u.size))
        self.contact_stored = float(sum(self._stored[k] for k in sorted(self._stored)))

    def restart(self, path) -> None:
        super().restart(path)
        self.u = self._global(self.u_local).ravel()
        self.vg = self._global(self.v).ravel()


def _active_rows(c) -> np.ndarray:
    """The indices of the contact state's active rows (none without an active set)."""
    return np.flatnonzero(c.active) if c.active is not None else np.zeros(0, np.int64)


class MidpointSolver(_ImplicitDynamicSolver):
    """The energy-momentum midpoint scheme (module docstring)."""
    scheme = "midpoint"
    step_function = staticmethod(midpoint_step)


class NewmarkSolver(_ImplicitDynamicSolver):
    """Newmark's trapezoidal rule (gamma 1/2, beta 1/4): the comparison that fails (module docstring)."""
    scheme = "newmark"
    step_function = staticmethod(newmark_step)

    def _step_loads(self, t0: float, dt: float) -> tuple[dict, np.ndarray]:
        """The trapezoid's loads at both ends of the step; its work booked with their mean (and with
        contact, the last step's end contact force, in the step's start acceleration)."""
        f0, f1 = self._load_at(t0), self._load_at(t0 + dt)
        loads = {"f_ext": self.f_ext + f1, "f_ext0": self.f_ext + f0}
        if self._gcontact is not None:
            loads["f_contact0"] = self._fc_end
        return loads, 0.5 * (f0 + f1)

    def _contact_update(self, c, du: np.ndarray, dt: float) -> None:
        """Newmark's contact: the multipliers at the step's end and no update after them (no steps 2
        and 3: what the seed's update is measured against). Its force over the step is the mean of
        the two ends' (the trapezoid's: the kinetic energy changes by exactly its work on du), booked
        to w_contact; an internal pair in the momentum balances, as the midpoint scheme's (the mean
        of the two ends' forces is not torque-free about x_{n+1/2}: the balance shows the
        trapezoid's error in the angular momentum)."""
        f = 0.5 * (self._fc_end + c.force)
        w = float(f @ du)
        self.w_contact += w
        self.w_ext += w
        rows = _active_rows(c)
        self._active_keys = {int(k): float(p) for k, p in zip(c.keys[rows].tolist(), c.p[rows].tolist())}
        self._fc_end = c.force.copy()
        self._book_contact_force(c, f, dt, len(rows))

    def _extra_state(self) -> dict:
        """The midpoint scheme's, and the last step's end contact force (the next step's a0)."""
        state = super()._extra_state()
        if self._gcontact is not None:
            state["contact_force_end"] = self._fc_end.copy()
        return state

    def _set_extra_state(self, state: dict) -> None:
        super()._set_extra_state(state)
        if self._gcontact is not None:
            self._fc_end = np.array(state["contact_force_end"], dtype=np.float64)
