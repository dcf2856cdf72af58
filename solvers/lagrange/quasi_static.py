"""Quasi-static mode of the Lagrangian solver (``[lagrange] integrator = "quasi_static"``): a sequence
of equilibrium states under loads ramped with the run's time, with frictionless contact (issue 11,
item 2: patch tests and Hertz).

Time is a load parameter: at time t the load factor is s = t / end_time; a ``velocity`` boundary
prescribes the displacement u = v t of its nodes (its "velocity" is the displacement rate), a
``traction`` boundary applies s times its traction, gravity s times m g. The orchestrator's steps
are the load steps (``[lagrange] load_steps``, dt = end_time / load_steps).

Each load step solves the static equilibrium with the contact conditions (seed slide "KKT
Conditions"):

    K u - B^T p = F(s),   g~ = B (X + u) + J p >= 0,   p >= 0,   p g~ = 0,

with the contact operators B, J of the case's method (solvers.contact.methods) built once on the
reference configuration X: geometrically linear, the gap linearised about the initial geometry, which
is the theory of the small-strain patch tests and of Hertz (whose gap is that of the undeformed
profiles; evaluating the contact on the deformed one instead moves Hertz's peak pressure by 2 % at
E = 1, P' = 0.01, where the strains reach 6 %). Large sliding needs the finite-strain contact of the Newton mode below (a neo_hookean body).
The complementarity is solved by the primal-dual active set (a semi-smooth Newton method,
solvers.contact.kkt), warm-started from the previous load step's set; the material being linear,
each set's solve is exact (one Newton step).

Materials: ``linear_elastic`` as Hooke's law in small strain (the reference of the patch tests and
of Hertz's theory), full-integration bilinear quads (plane strain) and trilinear hexahedra
(solvers.lagrange.small_strain), whose stiffness is the consistent tangent of this linear problem: a
linear_elastic body is always small strain, whatever its deformation. ``neo_hookean`` bodies are
finite strain (total-Lagrangian, solvers.lagrange.finite_strain: the internal force f_int(u) and its
consistent tangent K_T(u)). A case with any neo_hookean body solves each load step by Newton
(QuasiStaticSolver._newton): at the iterate u_k the contact problem of the linearised equilibrium

    K_T(u_k) u - B_k^T p = F - f_int(u_k) + K_T(u_k) u_k,   g~ = B_k (X + u) + J_k p >= 0, ...

with B_k, J_k the contact operators rebuilt at x_k = X + u_k (finite strain: the gap of the current
configuration, B(x_k) x, not the reference's), until the residual f_int - F - B^T p on the free dofs
is below 1e-10 of the load and the active set repeats. B is frozen over each solve: the geometric
contact stiffness d(B^T p)/dx is left out, so the convergence is only linear while the contact
geometry changes (quadratic where it does not, e.g. flat-on-flat: rubber_block_compression). Cases
with only linear_elastic bodies keep the single solve on the reference configuration above.

Parallel: a gathered solve. Every rank assembles the whole system from the global mesh it already
holds; the solve (scipy's SuperLU in the contact's active-set iteration) runs on rank 0 and its
answer is broadcast (gathered_step.on_root: the ranks do not factorise side by side; a failure is
raised on every rank); each keeps its own nodes' and elements' share: the ranks agree bit for bit,
the problem size is bounded by one rank's memory (about 1e5 - 1e6 dofs in 2-D); more ranks make it
no faster.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.lagrange import finite_strain, small_strain
from solvers.lagrange.boundary import BoundaryConditions
from solvers.lagrange.gathered_step import GatheredStepSolver, on_root
from solvers.lagrange.gathered_contact import GatheredContact
from solvers.lagrange.loads import traction_loads
from solvers.lagrange.solver import SolverError
from solvers.lagrange.surface import exterior_facets

__all__ = ["QuasiStaticSolver"]

def _elasticity(dim: int, mat: dict) -> np.ndarray:
    e, nu = mat["youngs_modulus"], mat["poisson_ratio"]
    return small_strain.plane_strain_elasticity(e, nu) if dim == 2 else small_strain.elasticity_3d(e, nu)


class QuasiStaticSolver(GatheredStepSolver):
    """The explicit solver's bodies, mesh, partition, output and checkpoints; steps are load steps
    (module docstring)."""

    def __init__(self, comm, case: dict):
        super().__init__(comm, case)
        self.contact = None  # (the explicit solver's impulses are not used: the static contact below)
        dim = self.dim
        opts = case["lagrange"]
        self.end_time = float(case["run"]["end_time"])
        self.case_dt_scale = float(case["run"].get("dt_scale", 0.9))
        self.load_steps = int(opts.get("load_steps", 1))
        self._ask_for(self.end_time / self.load_steps)   # load steps of end / load_steps
        P, C = self.global_points, self.global_cells
        n = len(P)
        # the stiffness of every body (its material's Hooke matrix) and the stresses' matrices
        # (neo_hookean bodies: total-Lagrangian finite strain, their (mu, lambda) in self._nh; their
        # tangent and internal force are evaluated at every Newton iterate, not here)
        self._d, self._nh = {}, {}
        blocks = [sp.csr_matrix((dim * n, dim * n))]
        bodies = case["lagrange"]["bodies"]
        for k, b in enumerate(bodies):
            cells = C[self.body_of_cell == k]
            mat = case["materials"][b["material"]]
            if mat.get("model", "linear_elastic") == "neo_hookean":
                self._nh[k] = finite_strain.lame(mat["youngs_modulus"], mat["poisson_ratio"])
                continue
            d = _elasticity(dim, mat)
            self._d[k] = (d, mat["poisson_ratio"])
            blocks.append(self._stiffness(P, cells, d))
        self.K = sp.csr_matrix(sum(blocks))
        # prescribed displacement components (global dofs): values per unit time (u = rate * t)
        span = float(np.max(np.ptp(P, axis=0)))
        bcs = BoundaryConditions(case.get("boundaries", []), P, tol=1e-9 * span)
        if bcs.walls:
            raise ValueError("quasi_static: rigid_wall boundaries are not supported (model the wall as a held body in contact)")
        self.fixed, self.rate = bcs.prescribed_arrays(n, dim)
        facets = exterior_facets(C, self.cell_type, n, P)[0]
        self.load = traction_loads(P, facets, bcs.tractions)
        if self.has_gravity:
            self.load = self.load + self._global(self.mass[:, None]) * self.gravity
        # contact: each pair's facets on the global exterior surface (gathered_contact.py)
        self._cfg = case.get("contact") or None
        self._contact = (GatheredContact(self._cfg, case, P, C, self.cell_type, self.body_of_cell, self.body_names)
                         if self._cfg else None)
        self.pairs = self._contact.pairs if self._contact else []
        if self._contact:
            self.h, self.capture = self._contact.h, self._contact.capture
        self._B, self._J, self.multiplier_nodes = self._contact_operators(P)
        self._active = None
        self.u = np.zeros((n, dim))
        self.p = np.zeros(self._B.shape[0])
        self.iterations = 0
        self.active = 0
        self.residual = 0.0
        self.contact_force = np.zeros(dim)
        self.reaction = np.zeros(dim)

    @staticmethod
    def _stiffness(points, cells, d):
        if cells.shape[1] == 4:
            return small_strain.quad_stiffness(points, cells, d)
        return small_strain.hex_stiffness(points, cells, d)

    def _stresses(self, u: np.ndarray) -> np.ndarray:
        """(n_cells, 6) Voigt xx yy zz xy yz zx: the mean over each element's Gauss points (plane
        strain: sigma_zz = nu (sigma_xx + sigma_yy); neo-Hookean: the Cauchy stress, sigma_zz =
        lambda ln J / J)."""
        P, C = self.global_points, self.global_cells
        out = np.zeros((len(C), 6))
        for k, (mu, lam) in self._nh.items():
            sel = self.body_of_cell == k
            out[sel] = finite_strain.cauchy_stresses(P, C[sel], u, mu, lam).mean(axis=1)
        for k, (d, nu) in self._d.items():
            sel = self.body_of_cell == k
            if self.dim == 2:
                s = small_strain.quad_stresses(P, C[sel], d, u).mean(axis=1)
                out[sel] = np.stack([s[:, 0], s[:, 1], nu * (s[:, 0] + s[:, 1]), s[:, 2],
                                     np.zeros(len(s)), np.zeros(len(s))], axis=1)
            else:
                out[sel] = small_strain.hex_stresses(P, C[sel], d, u).mean(axis=1)
        return out

    # ---- the step --------------------------------------------------------------------------------
    def step_choice(self) -> tuple[str, str]:
        return "load step", f"lagrange.load_steps = {self.load_steps} over the end time"

    def correct(self, impulse=None, step: int = 0, time: float = 0.0, surface_impulse=None) -> None:
        if impulse is not None or surface_impulse is not None:
            raise ValueError("quasi_static: no coupling impulses (a static solve has no inertia)")
        from solvers.contact.kkt import solve_frictionless

        s = time / self.end_time
        P = self.global_points
        F = s * self.load.ravel()
        u_fixed = (time * self.rate).ravel()
        fixed = self.fixed.ravel()
        if self._nh:
            return self._newton(F, u_fixed, fixed, step, time)
        B, J = self._B, self._J
        # warm start: the last step's active set (the loads grow monotonically in most cases)
        try:
            sol = on_root(self.comm, solve_frictionless, self.K, F, B, J, P.ravel(), fixed, u_fixed,
                          active=self._active)
        except RuntimeError as err:
            raise SolverError(f"quasi_static step {step} (t={time:.6g}): {err}") from None
        u = sol.u
        self.iterations, self.p = sol.iterations, sol.p
        self._active = sol.active
        self.active = int(np.count_nonzero(sol.active))
        # equilibrium: the reactions on the prescribed dofs, the residual on the free ones
        fc = B.T @ sol.p
        r = self.K @ u - F - fc
        scale = max(float(np.abs(F).max()), float(np.abs(fc).max(initial=0.0)),
                    float(np.abs(r[fixed]).max(initial=0.0)), 1e-300)
        self.residual = float(np.abs(r[~fixed]).max(initial=0.0)) / scale
        self._finish(u, r, fc, step, time)

    def _finish(self, u: np.ndarray, r: np.ndarray, fc: np.ndarray, step: int, time: float) -> None:
        """Close a load step at displacements u with equilibrium residual r (the reactions on the
        prescribed dofs) and contact forces fc (ndof,)."""
        P = self.global_points
        self.reaction = r.reshape(P.shape)[self.fixed.any(axis=1)].sum(axis=0)
        if self.pairs:
            self.contact_force = fc.reshape(P.shape)[self.body_of_node == self.pairs[0][2]].sum(axis=0)
        self.u = u.reshape(P.shape)
        self.strain_energy = self._energy(u)
        self.x = self.X + self.u[self.part.nodes]
        self.sig[:] = self._stresses(self.u)[self.part.cells]
        self.step, self.time = step, time
        self.first_step = False

    def _tangent(self, u: np.ndarray):
        """(K_T, f_int) at displacements u (ndof,): the small-strain bodies' K and K u plus the
        neo-Hookean bodies' finite-strain tangent and internal force."""
        P, C = self.global_points, self.global_cells
        k, f = self.K, self.K @ u
        for b, (mu, lam) in self._nh.items():
            kb, fb = finite_strain.tangent(P, C[self.body_of_cell == b], u, mu, lam)
            k, f = k + kb, f + fb
        return sp.csr_matrix(k), f

    def _newton(self, F, u_fixed, fixed, step: int, time: float, max_iterations: int = 25) -> None:
        """One load step with neo-Hookean bodies (module docstring): Newton on the equilibrium with
        the contact conditions. At iterate u_k the contact KKT problem of the linearised equilibrium
        K_T(u_k) (u - u_k) - B^T p = F - f_int(u_k) is solve_frictionless's with K = K_T(u_k) and
        loads F - f_int(u_k) + K_T(u_k) u_k: its u is the next iterate's total displacement. The
        contact operators are rebuilt at x_k = X + u_k every iteration and frozen over the solve (the
        gap B(x_k) x, a fixed point in B: the geometric contact stiffness d(B^T p)/dx is left out, so
        the convergence is linear while the contact geometry changes, quadratic once it does not).
        Converged when the residual f_int - F - B^T p on the free dofs is below 1e-10 of the load's
        norm (the external loads', the contact forces' or the reactions', the largest) and the active
        set repeats; else a SolverError naming the step and the residual history."""
        from solvers.contact.kkt import solve_frictionless

        P = self.global_points
        X = P.ravel()
        free = ~fixed
        u = self.u.ravel().copy()
        p, active = self.p, self._active
        history = []
        for it in range(1, max_iterations + 2):
            kt, fint = self._tangent(u)
            if self.pairs:
                B, J, keys = self._contact_operators(P + u.reshape(P.shape))
            else:
                B, J, keys = self._B, self._J, self.multiplier_nodes
            if len(p) != B.shape[0]:       # (the rebuilt operators have other rows: start afresh)
                p, active = np.zeros(B.shape[0]), None
            fc = B.T @ p
            r = fint - F - fc
            scale = max(float(np.linalg.norm(F)), float(np.linalg.norm(fc)),
                        float(np.linalg.norm(r[fixed])), 1e-300)
            res = float(np.linalg.norm(r[free])) / scale
            if it > 1:
                history.append(res)
                if res < 1e-10 and same:
                    break
            if it > max_iterations:
                raise SolverError(f"quasi_static step {step} (t={time:.6g}): Newton did not converge in "
                                  f"{max_iterations} iterations; relative residuals {history}")
            try:
                sol = on_root(self.comm, solve_frictionless, kt, F - fint + kt @ u, B, J, X, fixed, u_fixed,
                              active=active)
            except RuntimeError as err:
                raise SolverError(f"quasi_static step {step} (t={time:.6g}), Newton iteration {it}: {err}") from None
            same = active is not None and np.array_equal(sol.active, active)
            u, p, active = sol.u, sol.p, sol.active
        self._B, self._J, self.multiplier_nodes = B, J, keys
        self.p, self._active = p, active
        self.iterations = it - 1
        self.residual_history = history
        self.active = int(np.count_nonzero(active)) if active is not None else 0
        self.residual = res
        self._finish(u, r, fc, step, time)

    def _energy(self, u: np.ndarray) -> float:
        """The stored energy: 1/2 u K u of the small-strain bodies plus the integral of the
        neo-Hookean W over the reference."""
        P, C = self.global_points, self.global_cells
        e = 0.5 * float(u @ (self.K @ u))
        for b, (mu, lam) in self._nh.items():
            f, _, w = finite_strain.kinematics(P, C[self.body_of_cell == b], u)
            j = np.linalg.det(f)
            i1 = np.einsum("...ij,...ij->...", f, f) + (1.0 if f.shape[-1] == 2 else 0.0)
            e += float(np.sum(w * (0.5 * mu * (i1 - 3) - mu * np.log(j) + 0.5 * lam * np.log(j) ** 2)))
        return e

    def _contact_operators(self, x: np.ndarray):
        """B, J (every pair's, stacked) at positions x (n, dim), and each multiplier's key: its node
        + pair index * n (gathered_contact.py)."""
        if not self.pairs:
            return sp.csr_matrix((0, x.size)), sp.csr_matrix((0, 0)), np.zeros(0, np.int64)
        return self._contact.operators(x)

    def contact_pressure(self) -> np.ndarray:
        """(n_nodes_global,) contact pressure at every node: the mean of the multipliers it carries
        (both passes of the dual pass), 0 off the contact."""
        from solvers.contact.nodal_values import nodal_mean

        n = self.n_nodes_global
        return nodal_mean(self.multiplier_nodes % n, self.p, n, 0.0)

    def point_fields(self) -> dict[str, np.ndarray]:
        """The contact pressure and gap (m: of the linearised contact, B (X + u) over each row's
        weight; the capture distance where nothing faces a node), when the case has contact."""
        if not self.pairs:
            return {}
        from solvers.contact.nodal_values import constraint_weights, nodal_mean

        n = self.n_nodes_global
        gap = (self._B @ (self.global_points + self.u).ravel()) / constraint_weights(self._B, self.dim)
        return {"contact_pressure": self.contact_pressure(),
                "contact_gap": nodal_mean(self.multiplier_nodes % n, gap, n, self.capture)}

    def diagnostics(self) -> dict[str, float]:
        d = {"load_factor": self.time / self.end_time, "iterations": float(self.iterations),
             "strain_energy": float(getattr(self, "strain_energy", 0.0)),
             "equilibrium_residual_rel": self.residual}
        if self._nh:   # Newton's relative residual one iteration before the last (quadratic: ~ sqrt of it)
            h = getattr(self, "residual_history", [])
            d["newton_residual_previous"] = float(h[-2]) if len(h) > 1 else 0.0
        for c, name in enumerate("xyz"[: self.dim]):
            d[f"reaction_{name}"] = float(self.reaction[c])
        if self.pairs:
            d["contact_active"] = float(self.active)
            for c, name in enumerate("xyz"[: self.dim]):
                d[f"contact_force_{name}"] = float(self.contact_force[c])
        return d

    # ---- checkpoint / restart: the displacements are the state -----------------------------------
    def restart(self, path) -> None:
        super().restart(path)
        self.u = self._global(self.x - self.X)
