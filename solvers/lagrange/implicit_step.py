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

from solvers.lagrange.midpoint_svk import midpoint_tangent

__all__ = ["StepResult", "StepFailed", "midpoint_step", "newmark_step"]


class StepFailed(RuntimeError):
    """A step whose Newton iteration did not converge (or ran into a non-finite state)."""


@dataclass
class StepResult:
    u: np.ndarray            # (n d,) displacements at t_{n+1}
    v: np.ndarray            # (n d,) velocities at t_{n+1}
    iterations: int
    residuals: list
    reaction: np.ndarray     # (n d,) the force holding the prescribed dofs over the step (0 elsewhere)


def _svk(points, blocks, u0, u1):
    """(K, f) summed over the bodies: blocks [(cells, mu, lambda), ...] (each body its material)."""
    n = np.asarray(points).size
    k, f = sp.csr_matrix((n, n)), np.zeros(n)
    for cells, mu, lam in blocks:
        kb, fb = midpoint_tangent(points, cells, u0, u1, mu, lam)
        k, f = k + kb, f + fb
    return k, f


def _newton(name, residual_and_tangent, u_start, free, tol, max_iterations):
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
        du[free] = spla.spsolve(sp.csc_matrix(a[free][:, free]), -r[free])
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
                  tol: float = 1e-12, max_iterations: int = 25) -> StepResult:
    """The midpoint step from (u0, v0) (each (n d,)); blocks [(cells, mu, lambda), ...] the bodies;
    mass (n,) lumped; f_ext (n d,) constant over the step; fixed: dofs moving at v_fixed (default 0:
    held). Returns u1, v1, Newton's history and the reactions on the fixed dofs."""
    u0, v0, m, fe, free, vb = _step_arrays(points, mass, u0, v0, f_ext, fixed, v_fixed)

    def rt(u1):
        k, f = _svk(points, blocks, u0, u1)
        r = 2.0 * m * (u1 - u0 - dt * v0) / dt ** 2 + f - fe
        scale = max(float(np.linalg.norm(2.0 * m * v0 / dt)), float(np.linalg.norm(f)), float(np.linalg.norm(fe)))
        return r, sp.diags(2.0 * m / dt ** 2) + k, scale

    u1, it, hist, r = _newton("midpoint", rt, u0 + dt * v0, free, tol, max_iterations)
    v1 = np.where(free, 2.0 * (u1 - u0) / dt - v0, vb)
    return StepResult(u=u1, v=v1, iterations=it, residuals=hist, reaction=np.where(free, 0.0, r))


def newmark_step(points, blocks, mass, u0, v0, dt: float, f_ext=None, fixed=None, v_fixed=None,
                 tol: float = 1e-12, max_iterations: int = 25) -> StepResult:
    """The trapezoidal (Newmark gamma 1/2, beta 1/4) step from (u0, v0); arguments as midpoint_step."""
    u0, v0, m, fe, free, vb = _step_arrays(points, mass, u0, v0, f_ext, fixed, v_fixed)
    f0 = _svk(points, blocks, u0, u0)[1]
    a0 = np.where(free, (fe - f0) / m, 0.0)

    def rt(u1):
        k, f = _svk(points, blocks, u1, u1)
        r = 4.0 * m * (u1 - u0 - dt * v0) / dt ** 2 - m * a0 + f - fe
        scale = max(float(np.linalg.norm(m * v0 / dt)), float(np.linalg.norm(f)), float(np.linalg.norm(fe)))
        return r, sp.diags(4.0 * m / dt ** 2) + 2.0 * k, scale

    u1, it, hist, r = _newton("newmark", rt, u0 + dt * v0, free, tol, max_iterations)
    a1 = np.where(free, 4.0 * (u1 - u0 - dt * v0) / dt ** 2 - a0, 0.0)
    v1 = np.where(free, v0 + 0.5 * dt * (a0 + a1), vb)
    return StepResult(u=u1, v=v1, iterations=it, residuals=hist, reaction=np.where(free, 0.0, r))
