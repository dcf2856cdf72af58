"""Explicit Lagrangian finite elements: central differences, lumped mass, one-point elements.

Time stepping (step n -> n+1, dt = dt^{n+1/2}, previous dt_prev = dt^{n-1/2}):
    predict:  v* = v^{n-1/2} + dt_avg M^-1 f^n,         dt_avg = (dt_prev + dt)/2  (dt/2 on the first step)
    correct:  v^{n+1/2} = v* + M^-1 impulse, then boundary conditions (reaction R = M (v - v_before))
              x^{n+1} = x^n + dt v^{n+1/2};  f^{n+1}, stresses at n+1 and the next stable step.
Energy is accounted so that the discrete balance is exact: KE(v^{n+1/2}) - KE(v^{n-1/2}) equals the
work of dt_avg f^n + R on the mean velocity (v^{n-1/2} + v^{n+1/2})/2, summed into W_int (internal
forces) and W_ext (reactions and coupling impulses). The stress-power internal energy of the elements
is reported beside it as an independent check.

Runs on the ranks of `comm` with an element partition; forces and masses on shared nodes are summed
in the one-rank order (shared_sums.py).

The embedded-mesh coupling sees the bodies through their exterior surface (`surface()`): the surface
nodes' positions and velocities gathered in one canonical order on every rank (`surface_state`), and
an impulse on those nodes that `correct(surface_impulse=...)` applies to every rank's copies.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from solvers.expressions import compile_expression
from solvers.lagrange import kernels, materials, nodal
from solvers.lagrange.boundary import BoundaryConditions
from solvers.lagrange.loads import SurfaceLoads
from solvers.lagrange.mesh import body_mesh, cell_volumes, concatenate
from solvers.lagrange.partition import partition
from solvers.lagrange.shared_sums import OrderedSharedSums
from solvers.lagrange.surface import exterior_facets
from solvers.step_health import GrowthWatch


_NO_STEPS = np.empty(0)
"""No per-element steps (kernels.element_forces_levels: every element at the pass's dt_prev)."""


class SolverError(RuntimeError):
    """A physical failure (inverted element, NaN) with the body, element or node, step and time named."""


@dataclass
class _SurfaceMaps:
    """How this rank's nodes map onto the canonical surface node list (built once by surface())."""
    held_local: np.ndarray   # local index of every surface node this rank holds (owned or not)
    held_pos: np.ndarray     # its position in the canonical list
    sent_local: np.ndarray   # local index of the surface nodes this rank owns: the copies it sends
    recv_pos: np.ndarray     # canonical position of each row of the Allgatherv'd buffer
    counts: np.ndarray       # rows sent by each rank
    displs: np.ndarray       # first row of each rank in the gathered buffer
    impulse: np.ndarray      # (nn_local, dim) impulse buffer: zero off the surface, rows held_local set


def _material_table(case: dict):
    names = sorted(case["materials"])
    codes, pars = [], []
    for n in names:
        props = dict(case["materials"][n])
        code, par = materials.material_params(props.pop("model"), props)
        codes.append(code)
        pars.append(par)
    return names, np.array(codes, dtype=np.int64), np.array(pars, dtype=np.float64)


class LagrangeSolver:
    WATCHES_HIGH_MODES = True   # the central difference's energy watch (diagnostic created_energy_share)

    # element fields written to output (name -> attribute); stress is (ne, 6) Voigt xx yy zz xy yz zx
    CELL_FIELDS = ("stress", "plastic_strain", "temperature", "density", "bulk_viscosity")

    def __init__(self, comm, case: dict):
        self.comm = comm
        self.case = case
        run = case["run"]
        self.dim = dim = int(run["dimension"])
        opts = case.get("lagrange", {})
        self.hg = float(opts.get("hourglass", 0.1))
        self.q_lin = float(opts.get("bulk_viscosity_linear", 0.06))
        self.q_quad = float(opts.get("bulk_viscosity_quadratic", 1.5))

        bodies = case["lagrange"]["bodies"]
        meshes = [body_mesh(b, dim) for b in bodies]
        mesh, body_of_cell = concatenate(meshes)
        self.global_points = mesh.points.astype(np.float64)
        self.global_cells = mesh.cells.astype(np.int64)
        self.cell_type = mesh.cell_type
        self.n_nodes_global = len(mesh.points)
        self.n_cells_global = len(mesh.cells)
        # bodies are concatenated without node merging: each owns a contiguous range of cells and of
        # nodes (used to name the body and its own element/node number in failure messages)
        self.body_names = [str(b.get("name", f"#{i}")) for i, b in enumerate(bodies)]
        self.body_of_cell = body_of_cell
        self._body_first_cell = np.cumsum([0] + [m.num_cells for m in meshes])
        self._body_first_node = np.cumsum([0] + [m.num_points for m in meshes])
        self.body_of_node = np.repeat(np.arange(len(bodies)), [m.num_points for m in meshes])
        self._surface = None
        self._surf = None

        part = partition(self.global_points, self.global_cells, comm.size, comm.rank)
        self.part = part
        self.conn = np.ascontiguousarray(part.conn)
        X = self.global_points[part.nodes].copy()
        self.X = X
        self.x = X.copy()
        nn, ne = len(X), len(part.cells)

        mat_names, self.mat_code, self.mat_par = _material_table(case)
        body_mat = np.array([mat_names.index(b["material"]) for b in bodies], dtype=np.int64)
        my_body = body_of_cell[part.cells]
        self.mat_id = body_mat[my_body]

        self.gradN0, self.vol0 = kernels.reference_gradients(X, self.conn)
        rho0 = self.mat_par[self.mat_id, materials.P_RHO]
        self.mass_e = rho0 * self.vol0
        node_mass = np.zeros(nn)
        nen = self.conn.shape[1]
        corner_mass = np.repeat(self.mass_e / nen, nen)
        np.add.at(node_mass, self.conn.ravel(), corner_mass)
        # nodes on partition cuts: contributions added in the one-rank order (shared_sums.py)
        self._cut = OrderedSharedSums(comm, part, nen) if comm.size > 1 else None
        self._cut_row = self._cut.row if self._cut else np.full(ne, -1, np.int64)
        self._fe_cut = self._cut.buffer(dim) if self._cut else np.zeros((0, nen, dim))
        if self._cut:
            cm = self._cut.buffer(1)
            rows = self._cut.row >= 0
            cm[self._cut.row[rows], :, 0] = corner_mass.reshape(-1, nen)[rows]
            self._cut.sum_into(cm, node_mass)
        self.mass = node_mass
        self.inv_mass = 1.0 / self.mass

        # initial velocity per body, evaluated at each node of that body (expressions in x, y, z)
        self.v = np.zeros((nn, dim))
        names = ("x", "y", "z")[:dim]
        for b_index, b in enumerate(bodies):
            nodes = np.unique(self.conn[my_body == b_index])
            for c, comp in enumerate(b.get("initial_velocity", [0.0] * dim)):
                if isinstance(comp, str):
                    val = compile_expression(comp, names=names)(*X[nodes].T)
                else:
                    val = float(comp)
                self.v[nodes, c] = val

        self.sig = np.zeros((ne, 6))
        self.eps_p = np.zeros(ne)
        self.temp = np.zeros(ne)
        for b_index, b in enumerate(bodies):
            m = case["materials"][b["material"]]
            t0 = b.get("initial_temperature", m.get("room_temperature", 293.15))
            self.temp[my_body == b_index] = t0
        self.e_int = np.zeros(ne)
        # hourglass control per body (bodies[i].hourglass_control): the viscous Flanagan-Belytschko
        # force, or the assumed-strain stiffness (kernels.py); has_hg_stiffness is the same on every
        # rank (the diagnostics' collective sum), hg_stiff this rank's elements
        stiff = np.array([b.get("hourglass_control", "assumed_strain") == "assumed_strain" for b in bodies])
        self.has_hg_stiffness = bool(stiff.any())
        self.hg_stiff = stiff[my_body].astype(np.uint8)
        # its state: the reference hourglass sums and widths, the plastic offsets, the hourglass
        # energy and the work so far (kernels.py: _hex_assumed_strain, _forces_quad)
        self.hgq = np.zeros((ne, (10 if dim == 2 else 41) if stiff.any() else 1))  # (1: the work column only)
        if stiff.any():  # the reference part: sum_I h_aI X_I and the element's widths (kernels.py)
            kernels.assumed_strain_reference(self.X, self.conn, self.hgq)
        self.q = np.zeros(ne)
        # element erosion (bodies[i].erosion.strain): the effective strain at which an element of the
        # body erodes (inf: never); alive 0 once eroded.  The surface is rebuilt from the live
        # elements after every step that eroded one (surface_version counts the rebuilds).
        limit = np.array([float(b["erosion"]["strain"]) if b.get("erosion") else np.inf for b in bodies])
        self.erosion = bool(np.isfinite(limit).any())
        self.erode_at = limit[my_body].astype(np.float64)
        # (erosion.time_step: a share of the solver's first stable step, set below once it is known)
        self.erode_dt = np.zeros(ne)
        self.alive = np.ones(ne, np.uint8)
        self.eps_eq = np.zeros(ne)
        self.eroded = 0
        self.surface_version = 0   # renewals of the surface so far
        self.surface_stale = False  # elements eroded since the surface was built
        self.f = np.zeros((nn, dim))
        # work arrays of the step (allocated once)
        self.v_old = np.zeros((nn, dim))
        self.v_free = np.zeros((nn, dim))
        self._sums = np.zeros(10)
        self._no_impulse = np.zeros((0, dim))
        # the highest temporal mode (solvers/step_health.py): the last step's velocity change per node
        self._dv_prev = np.zeros((nn, dim))
        self.watch = GrowthWatch()
        self.supplied_gross = 0.0   # the energy put in: the initial energy plus every external work, gross

        span = float(np.max(np.ptp(self.global_points, axis=0)))
        self.bcs = BoundaryConditions(case.get("boundaries", []), X, tol=1e-9 * span)

        self.dt_prev = 0.0
        self.first_step = True
        self.step = 0
        self.time = 0.0
        # balances: accumulated work and impulses (replicated on all ranks)
        self.w_int = 0.0
        self.w_ext = 0.0
        self.impulse = np.zeros(dim)
        self.impulse_gross = np.zeros(1)
        self.ang_impulse = np.zeros(3 if dim == 3 else 1)
        self.ke0 = None
        self.p0 = None
        self.l0 = None
        # gravity ([lagrange] gravity): m g on every node, added to the element forces; its work
        # w_gravity (on the step's mean velocity, like the elements') is taken out of the internal
        # work the node kernel books and reported with the external work
        self.gravity = np.array(opts.get("gravity", [0.0] * dim), dtype=np.float64)
        self.has_gravity = bool(np.any(self.gravity != 0.0))
        self.w_gravity = 0.0
        # surface loads ([[boundaries]] type = "traction", times their curves: loads.py) on the initial
        # exterior facets, added to the forces at t^n like gravity and booked the same way (w_load)
        self.loads = None
        self.w_load = 0.0
        if self.bcs.tractions:
            P, E = self.global_points, self.global_cells
            g = BoundaryConditions(case.get("boundaries", []), P, tol=1e-9 * span)
            self.loads = SurfaceLoads(P, exterior_facets(E, self.cell_type, len(P), P)[0], g.tractions,
                                      g.traction_curves)
        # contact between bodies ([contact] pairs: impulses from a multiplier solve every step,
        # solvers/contact/explicit.py); w_contact: their work on the step's mean velocity (<= 0: the
        # energy the contact takes out, booked in the energy balance with the other external work)
        self.contact = None
        self.w_contact = 0.0
        self.contact_force = np.zeros(dim)
        if case.get("contact"):
            from solvers.contact.explicit import ExplicitContact

            cfg = case["contact"]
            pairs = [(self.body_names.index(a), self.body_names.index(b)) for a, b in cfg["pairs"]]
            # default capture: the median element edge of the reference mesh (far more than a
            # step's approach, less than a body); from the reference so that a restart finds the same
            P, E = self.global_points, self.global_cells
            edge = np.linalg.norm(P[E[:, 1]] - P[E[:, 0]], axis=1)
            self.contact = ExplicitContact(pairs, cfg.get("method", "dual_pass_mortar"), cfg.get("alpha", 1.0),
                                           cfg.get("capture", float(np.median(edge))), cfg.get("friction", 0.0))
            self._contact_version = -1
        self._dt_stable = self._forces(0.0)
        # an element crushed below this share of the first stable step (all ranks, every body: LS-DYNA's
        # TSMIN = DTMIN * the first step, with ERODE = 1) erodes: it would stop the run by its step
        share = np.array([float(b["erosion"].get("time_step", 0.0)) if b.get("erosion") else 0.0 for b in bodies])
        self.erode_dt = share[my_body] * self._dt_stable
        self.ke0 = self.kinetic_energy()
        self.se0 = float(self._allsum(self.e_int.sum()))
        self.p0 = self.momentum()
        self.l0 = self.angular_momentum()

    # ---- parallel sums -------------------------------------------------------------------------
    def _allsum(self, a):
        """Global sum of per-node quantities, counting each shared node once."""
        a = np.asarray(a, dtype=np.float64)
        if self.comm.size == 1:
            return a
        from mpi4py import MPI

        out = np.zeros_like(a)
        self.comm.Allreduce(a, out, op=MPI.SUM)
        return out

    # ---- the step --------------------------------------------------------------------------------
    def _element_kernel(self, dt_prev: float, dt_el: np.ndarray = _NO_STEPS,
                        dte_out: np.ndarray = _NO_STEPS) -> tuple:
        """The element kernel's pass (kernels.element_forces_levels): (dt_min, bad, eroded, dt_at).
        Every element at dt_prev; a subclass stepping elements at their own rates (subcycling.py)
        gives each its step (dt_el) and takes each one's stable step (dte_out)."""
        return kernels.element_forces_levels(
            self.x, self.v, dt_prev, self.conn, self.mat_id, self.mat_code, self.mat_par,
            self.gradN0, self.vol0, self.mass_e, self.sig, self.eps_p, self.temp, self.e_int, self.q,
            self.hg, self.q_lin, self.q_quad, self.f, self._cut_row, self._fe_cut,
            self.alive, self.eps_eq, self.erode_at, self.erode_dt, self.hg_stiff, self.hgq, dt_el, dte_out,
        )

    def _clear_forces(self) -> None:
        """Zero the nodal forces before the element kernel adds its (a subclass stepping nodes at
        their own rates clears those it moved: subcycling.py)."""
        self.f[:] = 0.0

    def _forces(self, dt_prev: float) -> float:
        self._clear_forces()
        dt_min, bad, eroded, dt_at = self._element_kernel(dt_prev)
        if bad >= 0:
            gid = int(self.part.cells[bad])
            b = int(self.body_of_cell[gid])
            raise SolverError(
                f"inverted or invalid element {gid} at step {self.step}, t={self.time:.6g} s "
                f"(body {self.body_names[b]!r}, its element {gid - int(self._body_first_cell[b])}; "
                f"volume or stress not finite/positive)"
            )
        if self.erosion:
            eroded = int(self._allsum(float(eroded))) if self.comm.size > 1 else int(eroded)
            if eroded:  # the live elements' surface is another one: renew_surface() takes it
                self.eroded += eroded
                self.surface_stale = True
        if self._cut:  # the cut nodes' forces in the one-rank order (shared_sums.py)
            self._cut.sum_into(self._fe_cut, self.f)
        self._add_external_forces()
        self._limiter = (float(dt_min), int(dt_at))   # this rank's: local_limiter() names it
        return self._min(dt_min)

    def _add_external_forces(self) -> None:
        """Gravity and the surface loads at self.time into the nodal forces (a subclass stepping
        nodes at their own rates adds them to those it moved: subcycling.py)."""
        if self.has_gravity:  # (every copy of a node has its full mass: the copies agree)
            self.f += self.mass[:, None] * self.gravity
        if self.loads is not None:  # (global: every copy of a node gets its full load)
            self.f += self._load_local(self.time)

    def _load_local(self, t: float) -> np.ndarray:
        """(nn_local, dim) the surface loads at t on this rank's nodes."""
        return self.loads.at(t)[self.part.nodes]

    def _min(self, value: float) -> float:
        if self.comm.size == 1:
            return float(value)
        from mpi4py import MPI

        return float(self.comm.allreduce(float(value), op=MPI.MIN))

    def stable_dt(self) -> float:
        return self._dt_stable

    def local_limiter(self) -> dict | None:
        """The element of this rank that sets its stable step: its body, its index in the body, its
        centroid now and its volume over its initial one (a crushed element is the usual cause of a
        falling step)."""
        dt, at = getattr(self, "_limiter", (np.inf, -1))
        if at < 0:
            return None
        gid = int(self.part.cells[at])
        b = int(self.body_of_cell[gid])
        xe = self.x[self.conn[at]]
        vol = float(cell_volumes(xe, np.arange(len(xe))[None, :])[0])
        return {"dt": dt, "kind": "sound speed",
                "what": f"element {gid - int(self._body_first_cell[b])} of body {self.body_names[b]!r}",
                "at": xe.mean(axis=0).tolist(), "detail": f"volume {vol / float(self.vol0[at]):.3g} of its initial"}

    def predict(self, dt: float) -> None:
        self.dt = dt
        self.dt_avg = 0.5 * dt if self.first_step else 0.5 * (self.dt_prev + dt)
        nodal.predict_velocity(self.v, self.v_old, self.f, self.inv_mass, self.dt_avg)

    def correct(self, impulse: np.ndarray | None = None, step: int = 0, time: float = 0.0,
                surface_impulse: np.ndarray | None = None) -> None:
        """Close the step n -> n+1 (`step`, `time` are those after it). impulse: (nn_local, dim) on
        this rank's nodes, the same value on every copy of a shared node; or surface_impulse:
        (ns, dim) on the surface nodes in surface()'s order, the same array on every rank. Either is
        added as v += impulse / m (m the full nodal mass) on every copy, and enters W_ext, the
        impulse and the angular impulse once per node (owned)."""
        if surface_impulse is not None:
            if impulse is not None:
                raise ValueError("correct: give impulse or surface_impulse, not both")
            impulse = self._surface_impulse_local(surface_impulse)
        if impulse is not None:
            self.v += impulse * self.inv_mass[:, None]
        if self.contact is not None:
            contact = self._contact_impulse()
            self.v += contact * self.inv_mass[:, None]
            impulse = contact if impulse is None else impulse + contact
        np.copyto(self.v_free, self.v)
        self.bcs.apply(self.x, self.v, self.dt)
        bad, worst, worst_hf = nodal.update_and_account(
            self.x, self.v, self.v_old, self.v_free, self.f, self.mass, self.part.owned,
            impulse if impulse is not None else self._no_impulse, self.dt, self.dt_avg, self._sums,
            self._dv_prev)
        if bad >= 0:
            node = int(self.part.nodes[bad])
            b = int(self.body_of_node[node])
            raise SolverError(f"non-finite velocity at node {node} at step {step}, t={time:.6g} s "
                              f"(body {self.body_names[b]!r}, its node {node - int(self._body_first_node[b])})")
        w = self.part.owned
        w_other = self.w_gravity + self.w_load
        if self.has_gravity:
            self.w_gravity += self._book_force(self.mass[w, None] * self.gravity)
        if self.loads is not None:  # (the surface loads at t^n: those in this step's forces)
            self.w_load += self._book_force(self._load_local(self.time)[w])
        w_other = self.w_gravity + self.w_load - w_other
        # exact discrete work, impulse and torque of this step (shared nodes counted once)
        # the gross size of the impulses (scale of the momentum balance: a clamped body's coupling
        # impulses and reactions cancel, its momentum stays 0)
        gross = 0.0 if impulse is None else float(np.abs(impulse[self.part.owned]).sum())
        tot = self._allsum(np.concatenate([self._sums, [gross]]))
        self.w_int += tot[0]
        self.w_ext += tot[1]
        self.impulse += tot[2:2 + self.dim]
        self.ang_impulse += tot[5:8] if self.dim == 3 else tot[7:8]
        self.impulse_gross += tot[-1]
        self.supplied_gross += abs(tot[1]) + abs(w_other)
        if self.contact is not None:
            self._contact_internal(contact)

        self.step, self.time = step, time
        self.first_step = False
        self.dt_prev = self.dt
        dt = self._forces(self.dt)
        # (no live element left, every one eroded: the free nodes fly at any step; the last one kept)
        self._dt_stable = dt if np.isfinite(dt) else self._dt_stable
        # energy made from nothing (solvers/step_health.py): kinetic + stored (stress power, at n+1)
        # against what was put in; collective, every rank decides the same
        stored = float(self._allsum(self.e_int.sum()))
        created = 0.5 * tot[9] + stored - self.ke0 - self.se0 - (self.w_ext + self.w_gravity + self.w_load)
        if self.watch.update(step, tot[8] / 8.0, created, self.ke0 + self.se0 + self.supplied_gross):
            raise SolverError(self._growing_mode(step, time, worst, worst_hf))

    def _growing_mode(self, step: int, time: float, worst: int, worst_hf: float) -> str:
        """The message of a growing highest mode: the body, the node where it is largest, its
        position, the step it grew from and how much (collective)."""
        node = int(self.part.nodes[worst]) if worst >= 0 else -1
        where = (worst_hf, node, self.x[worst].tolist() if worst >= 0 else [])
        if self.comm.size > 1:
            where = max(self.comm.allgather(where))
        _, node, x = where
        b = int(self.body_of_node[node])
        at = ", ".join(f"{v:.4g}" for v in x)
        w = self.watch
        return (f"unstable: the central difference made {w.last:.3g} times the energy put in at step {step}, "
                f"t={time:.6g} s (kinetic + stored against the initial energy and the external work); the mode "
                f"that turns every step grew {w.growth():.3g} times since step {w.since()}, largest in body "
                f"{self.body_names[b]!r} at its node {node - int(self._body_first_node[b])} at ({at}) m (a step "
                f"sequence or a step beyond the scheme's limit: the energy balance books the scheme's own work "
                f"and cannot show it)")

    def _book_force(self, f: np.ndarray) -> float:
        """Book a force f (on the owned nodes, in the step's forces) as the node kernel books the
        element forces: its impulse f dt_avg and torque x^n x f dt_avg (x^n = x^{n+1} - dt v) into
        the balances; returns its work on the mean velocity (all ranks)."""
        w = self.part.owned
        fi = f * self.dt_avg
        vbar = 0.5 * (self.v_old[w] + self.v[w])
        xn = self.x[w] - self.dt * self.v[w]
        tot = self._allsum(np.concatenate([[np.sum(fi * vbar)], fi.sum(axis=0), self._cross(xn, fi).sum(axis=0)]))
        self.impulse += tot[1:1 + self.dim]
        self.ang_impulse += tot[1 + self.dim:]
        return float(tot[0])

    def _contact_impulse(self) -> np.ndarray:
        """(nn_local, dim) contact impulses of this step on this rank's nodes (collective: the nodes
        near a partner body are gathered (solvers/contact/zone.py) and every rank solves the same
        contact problem on them, so the copies agree)."""
        surf = self.surface()
        if self._contact_version != self.surface_version:
            self.contact.set_surface(surf["facets"], surf["body"], surf["mass"], surf["free"])
            self._contact_version = self.surface_version
            # the surface nodes of the first body of the first pair: the contact_force diagnostic's
            self._contact_first = np.zeros(len(surf["node_ids"]), bool)
            self._contact_first[np.unique(surf["facets"][surf["body"] == self.contact.pairs[0][0]])] = True
            self._zone_maps = self._contact_zone_maps(surf)
        # the solve sees held components at their prescribed values, not where the predictor put them
        # (boundary.py prescribed_velocity); the work below is on the velocities the nodes have
        v_solve = self.bcs.prescribed_velocity(self.v) if self.bcs.prescribed else self.v
        zone, (xs, vs, v_solve, vo) = self._gather_near((self.x, self.v, v_solve, self.v_old))
        imp = self.contact.impulses(xs, v_solve, self.dt, self.dt_avg, self._dt_stable, zone=zone)
        held = self.contact.last_held_impulse
        on = np.flatnonzero(np.any(held != 0.0, axis=1))
        # (the supports' reaction to the pair's share on held components, about x^n: every rank has
        # the same surface arrays, so these sums are global)
        r = -held[on]
        self._contact_reaction = np.concatenate([r.sum(axis=0), self._cross(xs[on], r).sum(axis=0)])
        m = np.where(surf["mass"] > 0, surf["mass"], np.inf)[:, None]
        self.w_contact += float(np.sum(imp * 0.5 * (vo + vs + imp / m)))
        # the force the first body of the first pair takes from the contact over the step
        self.contact_force = imp[self._contact_first].sum(axis=0) / self.dt_avg  # (the central difference's force time)
        return self._surface_impulse_local(imp).copy()

    def _contact_internal(self, contact: np.ndarray) -> None:
        """The contact as an internal pair in the momentum balances (its work stays in the energy's):
        the kernel booked this step's contact impulses on the nodes as external (with their moment
        about x^n); they are taken out again and only the supports' reaction to the pair's share on
        held components is booked. The pair sums to zero, and to zero moment about x^n where its
        operator is built (the dual pass's rows: 5e-17 of the pair's gross moment in 2-D, 6e-9 on 3-D
        warped facets, measured), so the balances close unless the operator is built elsewhere in
        time or space."""
        w = self.part.owned
        xn = self.x[w] - self.dt * self.v[w]        # (the kernel's x^n: the drift undone)
        c = contact[w]
        booked = self._allsum(np.concatenate([c.sum(axis=0), self._cross(xn, c).sum(axis=0)]))
        d = self.dim
        self.impulse += self._contact_reaction[:d] - booked[:d]
        self.ang_impulse += self._contact_reaction[d:] - booked[d:]

    def _contact_zone_maps(self, surf: dict) -> dict:
        """What the near-node test needs, once per surface: the canonical positions of the surface nodes
        this rank sends (owns) and their bodies, and the facets whole on this rank (as local node
        indices: their extents bound the margin, zone.py)."""
        m = self._surf
        ns = len(surf["node_ids"])
        node_body = np.zeros(ns, dtype=np.int64)
        node_body[surf["facets"]] = surf["body"][:, None]
        rank = self.comm.rank
        sent_pos = m.recv_pos[m.displs[rank]:m.displs[rank] + m.counts[rank]] if self.comm.size > 1 else m.recv_pos
        local = np.full(ns, -1, dtype=np.int64)
        local[m.held_pos] = m.held_local
        whole = np.all(local[surf["facets"]] >= 0, axis=1)
        sent_pos = np.asarray(sent_pos, dtype=np.int64)
        return {"ns": ns, "sent_pos": sent_pos, "sent_body": node_body[sent_pos],
                "local_facets": local[surf["facets"][whole]], "n_bodies": len(self.body_names)}

    def _gather_near(self, arrays):
        """The states (each (nn_local, dim)) of the surface nodes near a partner body, as (ns, dim)
        arrays on every rank (zeros off the zone), and the zone (ns,) bool (collective: a gather of
        every rank's body boxes, then one Allgatherv of the near nodes' rows; zone.py)."""
        from solvers.contact.zone import body_boxes, facet_extent, near_nodes

        z, m = self._zone_maps, self._surf
        ns, dim = z["ns"], self.dim
        xo = self.x[m.sent_local]
        bodies = z["sent_body"]
        mine = np.concatenate([body_boxes(xo, bodies, z["n_bodies"]).ravel(),
                               [facet_extent(self.x, z["local_facets"])]])
        every = np.array(self.comm.allgather(mine)) if self.comm.size > 1 else mine[None]
        boxes = every[:, :-1].reshape(len(every), z["n_bodies"], 2, dim)
        margin = 2.0 * (float(self.contact.capture) + float(every[:, -1].max()))
        near = near_nodes(xo, bodies, self.contact.pairs, boxes, margin)
        rows = np.concatenate([z["sent_pos"][near, None].astype(np.float64)]
                              + [np.asarray(a, dtype=np.float64)[m.sent_local[near]] for a in arrays], axis=1)
        if self.comm.size > 1:
            from mpi4py import MPI

            counts = np.zeros(self.comm.size, dtype=np.int64)
            self.comm.Allgather(np.array([len(rows)], dtype=np.int64), counts)
            width = rows.shape[1]
            recv = np.empty((int(counts.sum()), width))
            displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
            self.comm.Allgatherv(np.ascontiguousarray(rows), [recv, counts * width, displs * width, MPI.DOUBLE])
            rows = recv
        pos = rows[:, 0].astype(np.int64)
        zone = np.zeros(ns, dtype=bool)
        zone[pos] = True
        out = []
        for k in range(len(arrays)):
            a = np.zeros((ns, dim))
            a[pos] = rows[:, 1 + k * dim:1 + (k + 1) * dim]
            out.append(a)
        return zone, out

    def contact_pressure(self) -> np.ndarray:
        """(n_nodes_global,) the last step's contact pressure at every node (0 off the contact), the
        same on every rank (the contact is solved on the gathered surface)."""
        ns = len(self.surface()["node_ids"])
        return self._on_all_nodes(self.contact.nodal_pressure(ns))

    def _on_all_nodes(self, surface_values: np.ndarray) -> np.ndarray:
        """(n_nodes_global,) the values of the surface nodes (surface() order) at their nodes, 0 elsewhere."""
        out = np.zeros(self.n_nodes_global)
        out[self.surface()["node_ids"]] = surface_values
        return out

    def point_fields(self) -> dict[str, np.ndarray]:
        """Nodal output fields beyond the motion, when the case has contact (collective): the contact
        pressure and the gap (m; 0 off the surface, the capture distance where nothing faces a node);
        with friction the tangential slip accumulated since t = 0 (m)."""
        if self.contact is None:
            return {}
        ns = len(self.surface()["node_ids"])
        fields = {"contact_pressure": self.contact_pressure(),
                  "contact_gap": self._on_all_nodes(self.contact.nodal_gap(ns))}
        if self.contact.friction > 0.0:  # (the slip accumulated since t = 0, m)
            slip = self.contact.slip
            fields["contact_slip"] = self._on_all_nodes(np.zeros(ns) if slip is None else slip)
        return fields

    # ---- the surface seen by the embedded-mesh coupling -------------------------------------------
    def renew_surface(self) -> bool:
        """After elements eroded (``surface_stale``): the surface of the live elements from now on
        (collective; surface_version counts the renewals).  Until then surface() keeps the one a
        coupler built its operators on, so the step's state still goes out on those nodes.  Returns
        whether it changed."""
        if not self.surface_stale:
            return False
        self._surface = self._surf = None
        self.surface_stale = False
        self.surface_version += 1
        return True

    def surface(self) -> dict[str, np.ndarray]:
        """The bodies' exterior surface, the same on every rank; collective on its first call, then
        cached (the reference mesh and the lumped masses never change in a Lagrangian solver; the
        elements eroded since are left out at the next renew_surface()).

        node_ids (ns,): sorted global ids of the surface nodes; facets (nf, 2|4): outward facets
        (surface.exterior_facets, canonical order) as indices into node_ids; body (nf,): the body whose
        cell each facet bounds (case order); mass (ns,): full lumped nodal masses (summed over ranks).
        """
        if self._surface is None:
            self._build_surface()
        return self._surface

    def _live_cells(self) -> np.ndarray:
        """Global ids of the elements not eroded (all of them without erosion; collective)."""
        if not self.erosion:
            return np.arange(self.n_cells_global)
        dead = self.part.cells[self.alive == 0]
        if self.comm.size > 1:
            dead = np.concatenate(self.comm.allgather(dead))
        live = np.ones(self.n_cells_global, bool)
        live[dead] = False
        return np.flatnonzero(live)

    def _build_surface(self) -> None:
        live = self._live_cells()
        if live.size:
            facets_g, facet_cell = exterior_facets(self.global_cells[live], self.cell_type, self.n_nodes_global,
                                                   self.global_points)
            facet_cell = live[facet_cell]
        else:  # every element eroded: no surface
            facets_g = np.zeros((0, 2 if self.dim == 2 else 4), np.int64)
            facet_cell = np.zeros(0, np.int64)
        node_ids = np.unique(facets_g)
        ns = len(node_ids)
        p = self.part
        held_local = np.flatnonzero(np.isin(p.nodes, node_ids, assume_unique=True))
        held_pos = np.searchsorted(node_ids, p.nodes[held_local])
        # every surface node is sent by exactly one rank, the lowest holding it (partition.owned), so
        # the gathered values do not depend on which copies other ranks hold
        sent = p.owned[held_local]
        sent_local, sent_pos = held_local[sent], held_pos[sent]
        counts = np.array([len(sent_local)], dtype=np.int64)
        if self.comm.size == 1:
            recv_pos = sent_pos
        else:
            from mpi4py import MPI

            counts = np.zeros(self.comm.size, dtype=np.int64)
            self.comm.Allgather(np.array([len(sent_local)], dtype=np.int64), counts)
            recv_pos = np.empty(int(counts.sum()), dtype=np.int64)
            displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
            self.comm.Allgatherv(np.ascontiguousarray(sent_pos, dtype=np.int64),
                                 [recv_pos, counts, displs, MPI.INT64_T])
        if not np.array_equal(np.sort(recv_pos), np.arange(ns)):  # a partition without one owner per node
            raise RuntimeError("surface: the ranks do not send every surface node exactly once")
        self._surf = _SurfaceMaps(
            held_local=held_local, held_pos=held_pos, sent_local=sent_local, recv_pos=recv_pos,
            counts=counts, displs=np.concatenate([[0], np.cumsum(counts)[:-1]]),
            impulse=np.zeros((len(self.x), self.dim)),
        )
        self._surface = {
            "node_ids": node_ids,
            "facets": np.searchsorted(node_ids, facets_g),
            "body": self.body_of_cell[facet_cell],
            "mass": self._gather_surface(self.mass),
            # 0 where a boundary condition prescribes the velocity component (the coupler's solve
            # must not count on moving it), 1 elsewhere
            "free": self._gather_surface(self._free_components()),
        }
        for arr in self._surface.values():  # handed out by reference on every call: not to be edited
            arr.flags.writeable = False

    def _free_components(self) -> np.ndarray:
        return 1.0 - self.bcs.prescribed_arrays(len(self.X), self.dim)[0]

    def _gather_surface(self, a: np.ndarray) -> np.ndarray:
        """(ns, ...) values of the surface nodes on every rank, from the copies their owners hold:
        one Allgatherv of the surface rows (numpy buffers), then a scatter into canonical order."""
        m = self._surf
        send = np.ascontiguousarray(a[m.sent_local], dtype=np.float64)
        if self.comm.size == 1:
            recv = send
        else:
            from mpi4py import MPI

            width = int(np.prod(a.shape[1:], dtype=np.int64))
            recv = np.empty((len(m.recv_pos),) + a.shape[1:])
            self.comm.Allgatherv(send, [recv, m.counts * width, m.displs * width, MPI.DOUBLE])
        out = np.empty_like(recv)
        out[m.recv_pos] = recv
        return out

    def surface_state(self, which: str) -> np.ndarray:
        """(ns, dim) positions (which="x") or velocities ("v") of the surface nodes in surface()'s
        order, the same array on every rank (collective). After predict "v" is v*; after correct "x"
        is x^{n+1} and "v" is v^{n+1/2}."""
        if which not in ("x", "v"):
            raise ValueError(f"surface_state: which must be 'x' or 'v', got {which!r}")
        self.surface()
        return self._gather_surface(self.x if which == "x" else self.v)

    def constraint_velocity(self) -> np.ndarray:
        """(ns, dim) after predict: the surface nodes' v* with their held components at the prescribed
        values (boundary.py prescribed_velocity), the same array on every rank (collective): what a
        constraint solved before correct must see (the contact, the coupling). The predictor moves a
        held node by its force until correct's boundary conditions take that back."""
        if not self.bcs.prescribed:
            return self.surface_state("v")
        self.surface()
        return self._gather_surface(self.bcs.prescribed_velocity(self.v))

    def _surface_impulse_local(self, imp: np.ndarray) -> np.ndarray:
        """The (ns, dim) surface impulse as an (nn_local, dim) array on this rank's nodes: every copy
        of a surface node gets that node's full impulse (each copy is updated with the full nodal
        mass; the balances count the owned copy only). Writes only the surface rows of a buffer that
        is zero elsewhere."""
        self.surface()
        imp = np.asarray(imp, dtype=np.float64)
        ns = len(self._surface["node_ids"])
        if imp.shape != (ns, self.dim):
            raise ValueError(f"surface impulse must have shape ({ns}, {self.dim}), got {imp.shape}")
        m = self._surf
        m.impulse[m.held_local] = imp[m.held_pos]
        return m.impulse

    # ---- diagnostics -----------------------------------------------------------------------------
    def _cross(self, a, b):
        if self.dim == 3:
            return np.cross(a, b)
        return (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])[:, None]

    def kinetic_energy(self) -> float:
        w = self.part.owned
        return float(self._allsum(0.5 * np.sum(self.mass[w, None] * self.v[w] ** 2)))

    def momentum(self) -> np.ndarray:
        w = self.part.owned
        return self._allsum(np.sum(self.mass[w, None] * self.v[w], axis=0))

    def angular_momentum(self) -> np.ndarray:
        """sum m x^{n+1} x v^{n+1/2} (equal to sum m x^n x v^{n+1/2}: conserved exactly by the scheme)."""
        w = self.part.owned
        return self._allsum(self._cross(self.x[w], self.mass[w, None] * self.v[w]).sum(axis=0))

    def diagnostics(self) -> dict[str, float]:
        ke = self.kinetic_energy()
        p = self.momentum()
        ang = self.angular_momentum()
        e_int = float(self._allsum(self.e_int.sum()))
        mass = float(self._allsum(self.mass[self.part.owned].sum()))
        scale_e = max(abs(self.ke0), abs(ke), abs(self.w_int), abs(self.w_ext), 1e-300)
        e_err = (ke + self.w_int - self.w_ext - self.ke0) / scale_e
        p_scale = max(np.linalg.norm(self.p0), np.linalg.norm(p), np.linalg.norm(self.impulse),
                      float(self.impulse_gross[0]), 1e-300)
        p_err = np.linalg.norm(p - self.p0 - self.impulse) / p_scale
        # (angular: the gross impulse times the body's size)
        size = float(np.ptp(self.global_points, axis=0).max())
        l_scale = max(np.linalg.norm(self.l0), np.linalg.norm(ang), np.linalg.norm(self.ang_impulse),
                      float(self.impulse_gross[0]) * size, 1e-300)
        l_err = np.linalg.norm(ang - self.l0 - self.ang_impulse) / l_scale
        d = {
            "mass": mass,
            "kinetic_energy": ke,
            # (gravity's work, in the kernel's W_int, moved to the external work: the sum is unchanged)
            "internal_work": self.w_int + self.w_gravity + self.w_load,
            "external_work": self.w_ext + self.w_gravity + self.w_load,
            "stress_power_energy": e_int,
            "energy_balance_rel": float(e_err),
            "momentum_balance_rel": float(p_err),
            "angular_momentum_balance_rel": float(l_err),
        }
        if self.WATCHES_HIGH_MODES:   # the energy the scheme made from nothing, over that put in
            created = ke + e_int - self.ke0 - self.se0 - d["external_work"]
            d["created_energy_share"] = created / max(self.ke0 + self.se0 + self.supplied_gross, 1e-300)
        if self.has_hg_stiffness:  # the assumed-strain hourglass stiffness's work (in the stress-power energy)
            d["hourglass_energy"] = float(self._allsum(self.hgq[:, -1].sum()))
        if self.has_gravity:
            d["gravity_work"] = self.w_gravity
        if self.loads is not None:
            d["load_work"] = self.w_load
        if self.contact is not None:
            d["contact_work"] = self.w_contact
            d["contact_active"] = float(self.contact.last_active)
            if self.contact.friction > 0.0:
                d["contact_sliding"] = float(self.contact.last_sliding)
            # the deepest a surface node lay behind its partner (m): at the end of this step, and over
            # the run (every step, whichever are recorded); split into self and other pairs when the
            # case has self contact
            pen, pen_max = self.contact.last_penetration, self.contact.penetration_max
            d["contact_penetration"] = float(pen.max())
            d["contact_penetration_max"] = float(pen_max.max())
            if any(a == b for a, b in self.contact.pairs):
                d["contact_penetration_self_max"] = float(pen_max[0])
                d["contact_penetration_other_max"] = float(pen_max[1])
            for c, name in enumerate("xyz"[: self.dim]):
                d[f"contact_force_{name}"] = float(self.contact_force[c])
        if self.erosion:  # the eroded elements' internal energy leaves the body with them
            d["eroded_elements"] = float(self.eroded)
            d["eroded_internal_energy"] = float(self._allsum(self.e_int[self.alive == 0].sum()))
        for c, name in enumerate("xyz"[: self.dim]):
            d[f"momentum_{name}"] = float(p[c])
        for c, name in enumerate(("x", "y", "z") if self.dim == 3 else ("z",)):
            d[f"angular_momentum_{name}"] = float(ang[c])
        return d

    # ---- gathering for output and checkpoints -----------------------------------------------------
    def gather_nodes(self, a: np.ndarray):
        """Global (n_nodes, ...) array on rank 0 (None elsewhere), from the nodes each rank owns."""
        w = self.part.owned
        return self._gather(self.part.nodes[w], a[w], self.n_nodes_global)

    def gather_cells(self, a: np.ndarray):
        return self._gather(self.part.cells, a, self.n_cells_global)

    def _gather(self, ids, values, n):
        values = np.ascontiguousarray(values, dtype=np.float64)
        if self.comm.size == 1:
            out = np.empty((n,) + values.shape[1:])
            out[ids] = values
            return out
        all_ids = self.comm.gather(ids, root=0)
        all_vals = self.comm.gather(values, root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty((n,) + values.shape[1:])
        for i, v in zip(all_ids, all_vals):
            out[i] = v
        return out

    def cell_fields(self) -> dict[str, np.ndarray]:
        vol = cell_volumes(self.x, self.conn)
        return {
            "stress": self.sig,
            "plastic_strain": self.eps_p,
            "temperature": self.temp,
            # (an eroded element has no density: 0, its volume may have gone through zero)
            "density": np.divide(self.mass_e, vol, out=np.zeros_like(vol), where=self.alive == 1),
            "bulk_viscosity": self.q,
            **({"eroded": 1.0 - self.alive} if self.erosion else {}),
        }

    # ---- snapshot / restore (in memory: the substeps' corrector pass, adapters/substeps.py) ----------
    _SNAPSHOT_OBJECTS = ("watch",)   # small objects the step changes in place (deep-copied)

    def snapshot(self) -> dict:
        """Everything a step may change: every array attribute (copied), every scalar, the objects
        in _SNAPSHOT_OBJECTS (deep-copied); references to the rest (the surface caches are replaced,
        not changed, by a renewal).  Not for contact (its state lives in the contact object)."""
        import copy

        if self.contact is not None:
            raise ValueError("snapshot: a solver with contact takes no substeps")
        out = {}
        for k, v in vars(self).items():
            if isinstance(v, np.ndarray):
                out[k] = v.copy()
            elif k in self._SNAPSHOT_OBJECTS:
                out[k] = copy.deepcopy(v)
            elif v is None or k == "_surf" or isinstance(v, (bool, int, float, str, np.generic, dict, tuple)):
                out[k] = v
        return out

    def restore(self, snap: dict) -> None:
        """Take back a snapshot (its arrays copied into the solver's own, which others may hold)."""
        import copy

        for k, v in snap.items():
            cur = getattr(self, k, None)
            if isinstance(v, np.ndarray) and isinstance(cur, np.ndarray) and cur.shape == v.shape \
                    and cur.dtype == v.dtype:
                np.copyto(cur, v)
            elif k in self._SNAPSHOT_OBJECTS:
                setattr(self, k, copy.deepcopy(v))
            else:
                setattr(self, k, v.copy() if isinstance(v, np.ndarray) else v)

    # ---- checkpoint / restart (global arrays, so any rank count can read; same count is bitwise) --
    STATE_NODES = ("x", "v", "f")
    STATE_CELLS = ("sig", "eps_p", "temp", "e_int", "q", "hgq")
    STATE_SCALARS = ("dt_prev", "first_step", "step", "time", "w_int", "w_ext", "_dt_stable", "ke0",
                     "se0", "supplied_gross")
    STATE_VECTORS = ("impulse", "ang_impulse", "p0", "l0", "impulse_gross")

    # cells, and the scalars eroded and surface_version (erode_dt follows from the initial state,
    # which the solver is built on before a restart too)
    STATE_EROSION = ("alive", "eps_eq")

    def _work_scalars(self) -> tuple:
        """The accumulated works a checkpoint holds when the case has them (contact, gravity)."""
        return ((("w_contact",) if self.contact is not None else ()) + (("w_gravity",) if self.has_gravity else ())
                + (("w_load",) if self.loads is not None else ()))

    def _state_cells(self) -> tuple:
        return self.STATE_CELLS + (self.STATE_EROSION if self.erosion else ())

    def _extra_state(self) -> dict:
        """A subclass's further state for the checkpoint, {name: array} (replicated on every rank)."""
        return {}

    def _set_extra_state(self, state: dict) -> None:
        """Take back what _extra_state gave (restart)."""

    def checkpoint(self, path: Path) -> None:
        nodes = {k: self.gather_nodes(getattr(self, k)) for k in self.STATE_NODES}
        cells = {k: self.gather_cells(getattr(self, k)) for k in self._state_cells()}
        if self.comm.rank != 0:
            return
        tmp = Path(str(path) + ".tmp")
        with h5py.File(tmp, "w") as h:
            for k, a in {**nodes, **cells}.items():
                h.create_dataset(k, data=a)
            for k in (self.STATE_SCALARS + (("eroded", "surface_version") if self.erosion else ())
                      + self._work_scalars()):
                h.attrs[k] = getattr(self, k)
            for k in self.STATE_VECTORS:
                h.create_dataset(k, data=getattr(self, k))
            if self.contact is not None:  # friction's accumulated slip and the last impulses (its warm start)
                for name, value in self.contact.state().items():
                    h.create_dataset(f"contact_{name}", data=value)
            for name, value in self._extra_state().items():
                h.create_dataset(f"extra_{name}", data=value)
            h.attrs["ranks"] = self.comm.size
        tmp.replace(path)

    def restart(self, path: Path) -> None:
        with h5py.File(path, "r") as h:
            for k in self.STATE_NODES:
                getattr(self, k)[:] = h[k][...][self.part.nodes]
            for k in self._state_cells():
                getattr(self, k)[:] = h[k][...][self.part.cells]
            if self.erosion:
                self.eroded, self.surface_version = int(h.attrs["eroded"]), int(h.attrs["surface_version"])
                self._surface = self._surf = None   # (built from the live elements when asked for)
                self.surface_stale = False
            for k in self.STATE_SCALARS:
                setattr(self, k, h.attrs[k].item() if hasattr(h.attrs[k], "item") else h.attrs[k])
            for k in self._work_scalars():
                setattr(self, k, float(h.attrs[k]))
            for k in self.STATE_VECTORS:
                if k in h:  # (impulse_gross: not in checkpoints before the coupling)
                    setattr(self, k, h[k][...])
            if self.contact is not None:  # (kept by set_surface: the same surface)
                self.contact.set_state({k[len("contact_"):]: h[k][...] for k in h if k.startswith("contact_")})
            self._set_extra_state({k[len("extra_"):]: h[k][...] for k in h if k.startswith("extra_")})
        self.first_step = bool(self.first_step)
        self.step = int(self.step)
