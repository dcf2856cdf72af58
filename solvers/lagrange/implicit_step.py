"""One implicit dynamic step of St. Venant-Kirchhoff bodies with lumped masses (issue 12): the
energy-momentum midpoint scheme and, as the comparison that fails, Newmark's trapezoidal rule.

Midpoint (seed slide "Structure preserving time integration w/ contact"; Simo & Tarnow 1992):

    M (v1 - v0) / dt + f_int^{n+1/2}(u0, u1) = f_ext,     u1 - u0 = dt (v0 + v1) / 2,

so v1 = 2 (u1 - u0) / dt - v0 and the unknown is u1:

    R(u1) = 2 M (u1 - u0 - dt v0) / dt^2 + f_int^{n+1/2}(u0, u1) - f_ext = 0,
    dR/du1 = 2 M / dt^2 + K^{n+1/2}                       (midpoint_svk.py).

Without f_ext the discrete energy 1/2 v M v + U(u) is conserved to the Newton tolerance, linear and
angular momentum to round-off, whatever dt (midpoint_svk.py's identity).

Newmark (gamma = 1/2, beta = 1/4), a = M^-1 (f_ext - f_int(u)):

    u1 = u0 + dt v0 + dt^2 / 4 (a0 + a1),   v1 = v0 + dt / 2 (a0 + a1),
    R(u1) = 4 M (u1 - u0 - dt v0) / dt^2 - M a0 + f_int(u1) - f_ext,   dR/du1 = 4 M / dt^2 + K(u1),

with f_int(u) = f_int^{n+1/2}(u, u) and K(u) = 2 d f_int^{n+1/2}/du1 at u0 = u1 (the static
St. Venant-Kirchhoff force and tangent). It conserves energy for linear problems only: with large
rotations its energy drifts and grows (the seed's "many implicit time integrators are unstable").

Prescribed dofs move at their velocity (x1 - x0 = dt v_b); the residual there is the reaction.
Newton with the consistent tangent and a sparse direct solve (scipy) on the free dofs; stops when the
residual is below ``tol`` times the largest of |M v0 / dt|, |f_int|, |f_ext| (or stalls at its
round-off floor below 1000 tol: no longer halving); a step that does not
converge in ``max_iterations`` raises StepFailed naming the scheme and its residuals (never NaN).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from solvers.lagrange.discrete_gradient_nh import dg_elements
from solvers.lagrange.finite_strain import _assemble_matrix, _assemble_vector, assembly_pattern
from solvers.lagrange.midpoint_svk import midpoint_elements
from solvers.sorted_ids import find_sorted

__all__ = ["StepResult", "ContactState", "StepFailed", "midpoint_step", "newmark_step"]


class StepFailed(RuntimeError):
    """A step whose Newton iteration did not converge (or ran into a non-finite state)."""


@dataclass
class StepResult:
    u: np.ndarray            # (n d,) displacements at t_{n+1}
    v: np.ndarray            # (n d,) velocities at t_{n+1}
    iterations: int
    residuals: list
    reaction: np.ndarray     # (n d,) the force holding the prescribed dofs over the step (0 elsewhere)
    contact: "ContactState | None" = None


@dataclass
class ContactState:
    """Step 1's contact: the operator B and keys of its rows (at x_{n+1/2}; Newmark's at x_{n+1}), the
    pressures p >= 0 (0 off the active set) and the contact force B^T p (n d,)."""
    B: sp.csr_matrix
    keys: np.ndarray
    p: np.ndarray
    active: np.ndarray
    force: np.ndarray
    set_changes: int = 0     # of the step's longest solve with B frozen, its iterations that changed the active set


# each material model's elements' midpoint force and Newton matrix: St. Venant-Kirchhoff's
# (midpoint_svk.py, the linear_elastic bodies') and the neo-Hookean discrete gradient
# (discrete_gradient_nh.py)
ELEMENTS = {"linear_elastic": midpoint_elements, "neo_hookean": dg_elements}


def _svk(points, blocks, u0, u1, ranks=None, diagonal=None):
    """(K, f) summed over the bodies: blocks [(cells, mu, lambda[, model]), ...] (each body its
    material; model a key of ELEMENTS, default linear_elastic). ranks: None (one rank: every element
    here), or the solver's share of the work among its ranks (gathered_step.RankShare): its
    elements(k, function, u0, u1, mu, lam) gives block k's (ke, fe) of all its elements in order,
    each rank evaluating its share (an element's values are its own: the matrix is the same bit for
    bit), and its on_root(function, ...) runs a solve on one rank and hands every rank the result.
    diagonal: (n d,) added to K's diagonal (the inertia term's 2 M / dt^2: sp.diags(diagonal) + K,
    the same sums without a sparse addition)."""
    points = np.asarray(points)
    n, d = points.size, points.shape[1]
    f = np.zeros(n)
    values = []
    for b, (cells, mu, lam, *model) in enumerate(blocks):
        fn = ELEMENTS[model[0] if model else "linear_elastic"]
        ke, fe = fn(points, cells, u0, u1, mu, lam) if ranks is None else ranks.elements(b, fn, u0, u1, mu, lam)
        values.append(ke.ravel())
        f = f + _assemble_vector(cells, d, fe, len(points))
    # every Newton iterate assembles the same meshes: the slots of the element entries in the CSR
    # pattern are computed once (finite_strain.AssemblyPattern), each call one sum into them (the
    # rotating rod's step spent a quarter of its time in scipy's COO assembly and sparse sums)
    pattern = assembly_pattern([blk[0] for blk in blocks], d, len(points))
    return pattern.matrix(np.concatenate(values) if values else np.zeros(0), diagonal), f


def _on_root(ranks, fn, *args, **kw):
    """fn(*args, **kw), on one rank of ``ranks`` and broadcast (every rank the same result) or here."""
    return fn(*args, **kw) if ranks is None else ranks.on_root(fn, *args, **kw)


def _newton(name, residual_and_tangent, u_start, free, tol, max_iterations, ranks=None):
    u = u_start.copy()
    history = []
    for it in range(max_iterations + 1):
        r, a, scale = residual_and_tangent(u)
        res = float(np.linalg.norm(r[free])) / max(scale, 1e-300)
        history.append(res)
        if not np.isfinite(res):
            raise StepFailed(f"{name}: the residual is not finite at iteration {it} (residuals {history})")
        # converged at tol, or stalled at the residual's round-off floor within 1000 tol (the
        # inertia term's u1 - u0 - dt v0 cancels: its round-off grows with |u|; a pinned block
        # swinging under gravity stalled at 1.9e-12)
        if res <= tol or (it >= 2 and res <= 1e3 * tol and res >= 0.5 * history[-2]):
            return u, it, history, r
        if it == max_iterations:
            break
        du = np.zeros_like(u)
        du[free] = _on_root(ranks, spla.spsolve, sp.csc_matrix(a[free][:, free]), -r[free])
        u = u + du
    raise StepFailed(f"{name}: Newton did not converge in {max_iterations} iterations "
                     f"(relative residuals {['%.1e' % h for h in history]})")


def _step_arrays(points, mass, u0, v0, f_ext, fixed, v_fixed):
    """Flat u0, v0 (a prescribed dof's v0 its velocity: x1 - x0 = dt (v0 + v1) / 2 with v0 = v1),
    the dofs' masses, f_ext, the free dofs (bool) and the prescribed velocities v_b (the dofs
    ``fixed`` move at v_fixed, default 0)."""
    u0, v0 = np.asarray(u0, float).ravel(), np.asarray(v0, float).ravel()
    m = np.repeat(np.asarray(mass, float), np.asarray(points).shape[1])
    fe = np.zeros_like(u0) if f_ext is None else np.asarray(f_ext, float).ravel()
    free = np.ones(len(u0), bool)
    vb = np.zeros(len(u0))
    if fixed is not None:
        fixed = np.asarray(fixed)
        free[fixed] = False
        vb[fixed] = 0.0 if v_fixed is None else np.asarray(v_fixed, float)
    return u0, np.where(free, v0, vb), m, fe, free, vb


def midpoint_step(points, blocks, mass, u0, v0, dt: float, f_ext=None, fixed=None, v_fixed=None,
                  tol: float = 1e-12, max_iterations: int = 25, contact=None, active=None,
                  ranks=None) -> StepResult:
    """The midpoint step from (u0, v0) (each (n d,)); blocks [(cells, mu, lambda), ...] the bodies;
    mass (n,) lumped; f_ext (n d,) the load at t_{n+1/2}; fixed: dofs moving at v_fixed (default 0:
    held). Returns u1, v1, Newton's history and the reactions on the fixed dofs.

    contact: None, or a function of the positions x (n, d) and the dofs' inverse stiffness giving
    (B, J, keys) (gathered_contact.py's dynamic_operators):
    then step 1 of the seed's contact update, the midpoint equations with f_c = B^T p (B at the
    midpoint), p >= 0 and the stabilized gap B x_{n+1} + J p >= 0 (_newton_contact); ``active``: a warm start
    {key: pressure} of the rows active at the last step. ranks: the work's share among the solver's
    ranks (_svk's; default all of it here)."""
    u0, v0, m, fe, free, vb = _step_arrays(points, mass, u0, v0, f_ext, fixed, v_fixed)

    def rt(u1):
        a, f = _svk(points, blocks, u0, u1, ranks, diagonal=2.0 * m / dt ** 2)
        r = 2.0 * m * (u1 - u0 - dt * v0) / dt ** 2 + f - fe
        scale = max(float(np.linalg.norm(2.0 * m * v0 / dt)), float(np.linalg.norm(f)), float(np.linalg.norm(fe)))
        return r, a, scale

    u1, it, hist, r, state = _solve("midpoint", rt, points, u0, u0 + dt * v0, free, tol, max_iterations,
                                    contact, active, at=0.5, ranks=ranks)
    v1 = np.where(free, 2.0 * (u1 - u0) / dt - v0, vb)
    return StepResult(u=u1, v=v1, iterations=it, residuals=hist, reaction=np.where(free, 0.0, r), contact=state)


def _solve(name, rt, points, u0, u_start, free, tol, max_iterations, contact, active, at: float, ranks=None):
    """The step's Newton iteration: plain (_newton), or with contact (_newton_contact, B built at
    x_n + at (x_{n+1} - x_n)). Returns (u1, iterations, residuals, the residual less the contact force
    (the reactions on the prescribed dofs), the contact state or None)."""
    if contact is None:
        return (*_newton(name, rt, u_start, free, tol, max_iterations, ranks), None)
    u1, it, hist, r, state = _newton_contact(name, rt, np.asarray(points, float), u0, u_start, free, contact, active,
                                             tol, max_iterations, at=at, ranks=ranks)
    return u1, it, hist, r - state.force, state


def _largest(m) -> float:
    """The largest |entry| of a sparse matrix (0 when it has none)."""
    m = sp.csr_matrix(m)
    return float(abs(m.data).max()) if m.nnz else 0.0


def _last_pressures(keys: np.ndarray, active_keys: dict | None) -> np.ndarray:
    """Each row's pressure at the last step ({key: pressure} of the rows active there; 0 elsewhere)."""
    p = np.zeros(len(keys))
    if active_keys:
        known = np.fromiter(active_keys.keys(), dtype=np.int64, count=len(active_keys))
        value = np.fromiter(active_keys.values(), dtype=np.float64, count=len(active_keys))
        order = np.argsort(known)
        at, hit = find_sorted(known[order], keys)
        p[hit] = value[order][at[hit]]
    return p


def _was_active(keys: np.ndarray, active_keys: dict) -> np.ndarray:
    """Whether each row was active at the last step (the active set's warm start)."""
    return np.isin(keys, np.fromiter(active_keys.keys(), dtype=np.int64, count=len(active_keys)))


def _newton_contact(name, rt, points, u0, u_start, free, contact, active_keys, tol, max_iterations, at: float,
                    max_rebuilds: int = 30, ranks=None):
    """Newton on the midpoint equations with frictionless contact (seed slide "Structure preserving
    time integration w/ contact", step 1): the force f_c = B^T p with B built at x_{n+1/2} (balanced
    and torque-free there: the momenta stay exact), p >= 0, and the stabilized gap at the step's END,

        A (u' - u) + r(u) - B^T p = 0,   B (X + u') + J p >= min(B x_n, 0),  p >= 0, complementary,

    kkt.solve_frictionless's problem with K = A and F = A u - r (the floor its offset), each Newton
    iteration one such solve with B frozen. The seed holds the gap at the midpoint instead: then
    B x_{n+1} = -B x_n, the step ends as deep in as it began apart, the next step's contact pushes
    that out again with positive work, and a ring on a floor gained 0.8 J in a bounce. At the end,
    the contact's work B^T p . (x1 - x0) = p . (floor - J p - B x0) <= 0 is dissipative always: a
    row that starts the step in (J p's offset, or the operator of a turned configuration: a spinning
    rod's corners gained 1 J in an episode when pushed back to zero) is held where it is, not pushed
    out, LS-DYNA's "initial penetrations ignored"; a row active at the last step, at the offset -J p
    its pressure left it at (the floor B x_n + J p_last: the explicit contact's rule), so that a
    resting contact does not sink by J p a step. Its work p . J (p_last - p) is then the
    stabilization's compliance storing (p > p_last) and giving back (p < p_last) energy.
    Converged when the residual r - B^T p on the free dofs is below tol (relative to the inertia,
    internal, external or contact force) with the active set repeated (or stalled at the round-off
    floor within 1000 tol). Then B is rebuilt at the converged midpoint and the step solved again
    from there until B no longer changes (to 1e-9 of its largest entry, the same rows) or the step
    holds with it (residual within 1000 tol, no gap closed beyond round-off; then Newton converges
    once more with it, and it is the step's operator): rebuilding
    it at every Newton iterate instead made the pressures of the dual pass's redundant rows jump with
    the operator's tiny changes and Newton stagnate (bars_impact_implicit: 3e-8). The geometric
    contact stiffness is left out. Returns the most iterations of one solve with B frozen (what the
    step control weighs: each rebuild starts again near the solution), and in the state how many of
    them changed the active set (the control does not count those: Abaqus's "severe discontinuity
    iterations"; the first always does, from the last step's set).
    ``at``: where in the step B is built, x_n + at (x_{n+1} - x_n) (the midpoint scheme 1/2, Newmark's
    trapezoid 1: its contact force is the step end's); ``name`` the scheme's, in its failures."""
    from solvers.contact.kkt import solve_frictionless

    shape = points.shape
    X = points.ravel()
    fixed = ~free
    u = u_start.copy()
    history = []
    p = active = None
    keys_prev = None
    iterations = most = most_changes = 0   # all Newton iterations; the most of one solve with B frozen
    inv_a = None
    for rebuild in range(max_rebuilds + 1):
        if inv_a is None:   # J's weight: the step matrix's inverse diagonal on the free dofs
            a0 = rt(u)[1].diagonal()
            inv_a = np.where(free & (a0 > 0), 1.0 / np.where(a0 > 0, a0, 1.0), 0.0)
        B, J, keys = contact((X + u0 + at * (u - u0)).reshape(shape), inv_a)
        # the gap's floor with this B: where a row starts in, it is held there; a row that was active
        # at the last step rests at the offset -J p_last its pressure left it at, so that offset is
        # made up (its floor min(B x_n + J p_last, 0), 0 for a row at rest). Without it a resting
        # contact sank by J p every step: two bars held together at their cut were 24 % off the uncut
        # bar's answer after 192 midpoint steps, and the more steps the deeper (order 0.46 in the
        # step; with the offset 0.6 %, tests/cases/test_time_order.py)
        p_last = _last_pressures(keys, active_keys)
        floor = np.minimum(B @ (X + u0) + J @ p_last, 0.0)
        # the saddle point system scaled (rows beta B, pressures p / beta, J beta^2) so that beta B is
        # of the size of sqrt(A): unscaled (steel: A ~ 1e11, B ~ 1e-3, J ~ 1e-17) its LU gave the
        # pressures to 1e-7 only and Newton stalled there
        beta = np.sqrt(float(np.median(a0[free]))) / _largest(B) if B.nnz else 1.0
        if rebuild > 0 and np.array_equal(keys, keys_prev) and B.shape == B_prev.shape:
            if _largest(B - B_prev) <= 1e-9 * _largest(B):
                return u, most, history, r, ContactState(B=B_prev, keys=keys_prev, p=p, active=active,
                                                         force=B_prev.T @ p, set_changes=most_changes)
            # or the step already holds with the rebuilt operator: its residual at the Newton
            # tolerance's floor (the fixed point on B converges linearly, 0.2 a rebuild on the
            # rotating rod: 10 rebuilds were not enough to bring B's change to 1e-9)
            fc = B.T @ p
            res = float(np.linalg.norm((r - fc)[free])) / max(scale, float(np.linalg.norm(fc)), 1e-300)
            final = res <= 1e3 * tol and np.all(B @ (X + u) + J @ p - floor
                                                >= -1e-9 * _largest(B) * float(np.abs(X + u).max()))
        else:
            final = False
        if p is None or not np.array_equal(keys, keys_prev):
            p = np.zeros(B.shape[0])
            active = None if not active_keys else _was_active(keys, active_keys)
        same = False
        changes = 0
        for it in range(max_iterations + 1):
            r, a, scale = rt(u)
            fc = B.T @ p
            res = float(np.linalg.norm((r - fc)[free])) / max(scale, float(np.linalg.norm(fc)), 1e-300)
            history.append(res)
            if not np.isfinite(res):
                raise StepFailed(f"{name}: the residual is not finite at iteration {iterations} (residuals {history})")
            if it > 0 and same and (res <= tol or (it >= 2 and res <= 1e3 * tol and res >= 0.5 * history[-2])):
                break
            if it == max_iterations:
                raise StepFailed(f"{name}: Newton with contact did not converge in {max_iterations} iterations "
                                 f"(relative residuals {['%.1e' % h for h in history]})")
            try:
                sol = _on_root(ranks, solve_frictionless, a, a @ u - r, beta * B, (beta * beta) * J, X, fixed, u,
                               active=active, offset=beta * floor)
            except RuntimeError as err:
                raise StepFailed(f"{name}: the contact solve failed at iteration {iterations}: {err}") from None
            same = active is not None and np.array_equal(sol.active, active)
            u, p, active = sol.u, beta * sol.p, sol.active
            iterations += 1
            changes += 0 if same else 1
            if it + 1 >= most:
                most, most_changes = it + 1, changes
        if final:   # (converged again with the rebuilt operator: it is the step's)
            return u, most, history, r, ContactState(B=B, keys=keys, p=p, active=active, force=B.T @ p,
                                                     set_changes=most_changes)
        B_prev, keys_prev = B, keys
    raise StepFailed(f"{name}: the contact operators still changed after {max_rebuilds} rebuilds at the "
                     f"converged midpoint (relative residuals {['%.1e' % h for h in history]})")


def newmark_step(points, blocks, mass, u0, v0, dt: float, f_ext=None, fixed=None, v_fixed=None,
                 tol: float = 1e-12, max_iterations: int = 25, f_ext0=None, contact=None, active=None,
                 f_contact0=None, ranks=None) -> StepResult:
    """The trapezoidal (Newmark gamma 1/2, beta 1/4) step from (u0, v0); arguments as midpoint_step,
    but f_ext is the load at t_{n+1} and f_ext0 the one at t_n (default f_ext: constant).

    contact: as midpoint_step's, but the trapezoid's: f_c = B^T p at the step's end (B at x_{n+1}),
    the gap held there as the midpoint scheme holds it, and in a0 the last step's contact force
    f_contact0 (n d,). No gap-rate update, no energy given back: the comparison the seed's three steps
    are measured against."""
    u0, v0, m, fe, free, vb = _step_arrays(points, mass, u0, v0, f_ext, fixed, v_fixed)
    fe0 = fe if f_ext0 is None else np.asarray(f_ext0, float).ravel()
    f0 = _svk(points, blocks, u0, u0, ranks)[1]
    fc0 = 0.0 if f_contact0 is None else np.asarray(f_contact0, float).ravel()
    a0 = np.where(free, (fe0 - f0 + fc0) / m, 0.0)

    def rt(u1):
        k, f = _svk(points, blocks, u1, u1, ranks)
        r = 4.0 * m * (u1 - u0 - dt * v0) / dt ** 2 - m * a0 + f - fe
        scale = max(float(np.linalg.norm(m * v0 / dt)), float(np.linalg.norm(f)), float(np.linalg.norm(fe)))
        return r, sp.diags(4.0 * m / dt ** 2) + 2.0 * k, scale

    u1, it, hist, r, state = _solve("newmark", rt, points, u0, u0 + dt * v0, free, tol, max_iterations,
                                    contact, active, at=1.0, ranks=ranks)
    a1 = np.where(free, 4.0 * (u1 - u0 - dt * v0) / dt ** 2 - a0, 0.0)
    v1 = np.where(free, v0 + 0.5 * dt * (a0 + a1), vb)
    # the prescribed dofs' reaction over the step: the trapezoid's mean of its two ends (at t_n the
    # force that holds them, f_int - f_ext - f_c), with which the momenta's change is exact
    r0 = f0 - fe0 - fc0
    return StepResult(u=u1, v=v1, iterations=it, residuals=hist, reaction=np.where(free, 0.0, 0.5 * (r0 + r)),
                      contact=state)
