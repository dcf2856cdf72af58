"""J2 plasticity at the through-thickness points of a plane-strain shell strip (issue 45; beam2d.py's
points): the stress state of a shell's layer with the depth held (plane strain, eps_yy = 0) and the
normal through the thickness free (shell: sigma_zz = 0), i.e. plane stress in (xx, yy) with the
total strain (eps_xx, 0).

Return mapping (Simo & Hughes, Computational Inelasticity, section 3.4: plane stress J2 with linear
isotropic hardening), small strain, sigma = C (eps - eps_p) with C the plane-stress elasticity on
(xx, yy). In the eigenbasis shared by C and the plane-stress deviator projection P =
[[2, -1], [-1, 2]] / 3, s1 = (sigma_xx + sigma_yy) / sqrt 2 and s2 = (sigma_xx - sigma_yy) / sqrt 2:

    s1(dg) = s1_trial / (1 + dg E / (3 (1 - nu))),   s2(dg) = s2_trial / (1 + 2 G dg),
    f(dg)  = 1/2 (s1^2 / 3 + s2^2) - 1/3 (sigma_y + H alpha(dg))^2 = 0,
    alpha(dg) = alpha_n + dg sqrt(2/3 (s1^2 / 3 + s2^2)),

solved for the consistency parameter dg >= 0 by Newton on the scalar f from dg = 0, clipped at 0
(vectorised over the yielding points, until every one has converged); eps_p += dg P sigma. The von
Mises stress sqrt(sigma_xx^2 - sigma_xx sigma_yy + sigma_yy^2) is then sigma_y + H alpha. Fully plastic in uniaxial plane strain the flow is
incompressible: sigma_yy = sigma_xx / 2 and sigma_xx = 2 sigma_y / sqrt 3 (the plane-strain yield
stress)."""
from __future__ import annotations

import numpy as np

__all__ = ["strip_return", "plane_strain_yield"]

NEWTON_ITERATIONS = 30
"""The most Newton steps on the scalar consistency condition (it converges quadratically: 3-6; the
loop ends when every yielding point's f is within 1e-15 of k^2)."""


def plane_strain_yield(yield_stress: float) -> float:
    """sigma_xx of a fully plastic layer in uniaxial plane strain: 2 sigma_y / sqrt 3."""
    return 2.0 * float(yield_stress) / np.sqrt(3.0)


def strip_return(eps_xx: np.ndarray, eps_p: np.ndarray, alpha: np.ndarray, youngs_modulus, poisson_ratio,
                 yield_stress, hardening=0.0):
    """(sigma_xx, sigma_yy, eps_p new (..., 2), alpha new) at the points with total strain (eps_xx, 0),
    plastic strains eps_p (..., 2) (xx, yy) and equivalent plastic strains alpha (...), after the
    return mapping (module docstring). Inputs broadcast; nothing is changed in place."""
    shape = np.broadcast_shapes(np.shape(eps_xx), eps_p.shape[:-1], np.shape(alpha))
    full = lambda a: np.broadcast_to(np.asarray(a, float), shape)   # noqa: E731
    e, nu, alpha = full(youngs_modulus), full(poisson_ratio), full(alpha)
    g = e / (2.0 * (1.0 + nu))
    c = e / (1.0 - nu * nu)
    ex = full(eps_xx) - eps_p[..., 0]
    ey = -np.broadcast_to(eps_p[..., 1], shape)
    sx, sy = c * (ex + nu * ey), c * (ey + nu * ex)            # the elastic trial
    r2 = np.sqrt(2.0)
    s1t, s2t = (sx + sy) / r2, (sx - sy) / r2
    a1, a2 = e / (3.0 * (1.0 - nu)), 2.0 * g
    sy0, hard = full(yield_stress), full(hardening)

    def parts(dg):
        s1, s2 = s1t / (1.0 + a1 * dg), s2t / (1.0 + a2 * dg)
        q = s1 * s1 / 3.0 + s2 * s2                           # sigma^T P sigma
        return s1, s2, q

    q_trial = s1t * s1t / 3.0 + s2t * s2t
    dg = np.zeros(shape)
    on = np.flatnonzero(0.5 * q_trial - (sy0 + hard * alpha) ** 2 / 3.0 > 0.0)   # the points beyond yield
    if len(on):
        S1, S2 = s1t.ravel()[on], s2t.ravel()[on]
        A1, A2 = a1.ravel()[on], a2.ravel()[on]
        Y, Hh, Al = sy0.ravel()[on], hard.ravel()[on], alpha.ravel()[on]
        d = np.zeros(len(on))
        for _ in range(NEWTON_ITERATIONS):   # (scalar Newton per point, the yielding points at once)
            s1, s2 = S1 / (1.0 + A1 * d), S2 / (1.0 + A2 * d)
            q = s1 * s1 / 3.0 + s2 * s2
            root = np.sqrt(2.0 / 3.0 * np.maximum(q, 1e-300))
            k = Y + Hh * (Al + d * root)
            f = 0.5 * q - k * k / 3.0
            if np.all(np.abs(f) <= 1e-15 * k * k):
                break
            # df/d(dg) = q'/2 - 2 k k'/3: q' from the two eigen-parts, k' = H (root + dg (q'/3) / root)
            dq = -2.0 * (A1 * s1 * s1 / 3.0 / (1.0 + A1 * d) + A2 * s2 * s2 / (1.0 + A2 * d))
            dk = Hh * (root + d * (2.0 / 3.0) * dq / (2.0 * root))
            d = np.maximum(d - f / (0.5 * dq - 2.0 * k * dk / 3.0), 0.0)
        dg.ravel()[on] = d
    s1, s2, q = parts(dg)
    sx, sy = (s1 + s2) / r2, (s1 - s2) / r2
    flow = np.stack([(2.0 * sx - sy) / 3.0, (2.0 * sy - sx) / 3.0], axis=-1)   # P sigma
    eps_p_new = eps_p + dg[..., None] * flow
    alpha_new = alpha + dg * np.sqrt(2.0 / 3.0 * q)
    return sx, sy, eps_p_new, alpha_new
