"""Constitutive models of the explicit Lagrangian solver.

Every material is described by an integer model code and a flat float64
parameter vector of length ``NPAR`` (one row of the ``mat_par`` table handed to
:func:`solvers.lagrange.kernels.element_forces`).  The layout is fixed and
named by the ``P_*`` index constants below::

    index  name      meaning                                   models
    -----  --------  ----------------------------------------  --------
      0    P_RHO     reference density rho0 (kg/m^3)            all
      1    P_E       Young's modulus E (Pa)                     all
      2    P_NU      Poisson ratio nu                           all
      3    P_G       shear modulus G = mu = E / (2 (1 + nu))    all
      4    P_K       bulk modulus K = E / (3 (1 - 2 nu))        all
      5    P_LAM     Lame lambda = K - 2 G / 3                  all
      6    P_A       JC yield stress A (Pa)                     JC
      7    P_B       JC hardening modulus B (Pa)                JC
      8    P_N       JC hardening exponent n                    JC
      9    P_C       JC strain-rate coefficient C               JC
     10    P_EPS0    JC reference strain rate (1/s)             JC
     11    P_M       JC thermal exponent m                      JC
     12    P_TMELT   melt temperature (K)                       JC
     13    P_TROOM   room temperature (K)                       JC
     14    P_CP      specific heat (J/(kg K))                   JC
     15    P_CHI     Taylor-Quinney coefficient                 JC

Unused entries are zero.

The numba functions work on scalars (no allocation) and are called per element
from the element loop.  Stresses are Cauchy stresses in Voigt order
``[xx, yy, zz, xy, yz, zx]`` (tensor shear components, not engineering ones);
the rate of deformation ``D`` is passed with tensor components as well.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

LINEAR_ELASTIC = 0
NEO_HOOKEAN = 1
JOHNSON_COOK = 2

MODEL_CODES = {
    "linear_elastic": LINEAR_ELASTIC,
    "neo_hookean": NEO_HOOKEAN,
    "johnson_cook": JOHNSON_COOK,
}

NPAR = 16

P_RHO = 0
P_E = 1
P_NU = 2
P_G = 3
P_K = 4
P_LAM = 5
P_A = 6
P_B = 7
P_N = 8
P_C = 9
P_EPS0 = 10
P_M = 11
P_TMELT = 12
P_TROOM = 13
P_CP = 14
P_CHI = 15

_ELASTIC_KEYS = ("density", "youngs_modulus", "poisson_ratio")
_JC_KEYS = {
    "yield_stress": P_A,
    "hardening_modulus": P_B,
    "hardening_exponent": P_N,
    "strain_rate_coefficient": P_C,
    "reference_strain_rate": P_EPS0,
    "thermal_exponent": P_M,
    "melt_temperature": P_TMELT,
    "room_temperature": P_TROOM,
    "specific_heat": P_CP,
    "taylor_quinney": P_CHI,
}

# Newton iterations of the Johnson-Cook return mapping (in ln of the increment).
JC_MAX_ITER = 60
JC_RTOL = 1.0e-13     # |f| <= JC_RTOL * q_tr
JC_YTOL = 1.0e-7      # |Newton step in ln(dg)|


def material_params(model_name: str, props: dict) -> tuple[int, np.ndarray]:
    """Return ``(code, params)`` for a material table of the case file.

    ``props`` holds the case keys (``density``, ``youngs_modulus``,
    ``poisson_ratio`` and, for ``johnson_cook``, the ten JC keys).  Extra keys
    such as ``model`` are ignored; missing or non-physical values raise
    ``ValueError``.
    """
    if model_name not in MODEL_CODES:
        raise ValueError(f"unknown material model {model_name!r}; allowed: {sorted(MODEL_CODES)}")
    code = MODEL_CODES[model_name]
    needed = list(_ELASTIC_KEYS) + (list(_JC_KEYS) if code == JOHNSON_COOK else [])
    missing = [k for k in needed if k not in props]
    if missing:
        raise ValueError(f"material model {model_name!r} misses keys {missing}")
    par = np.zeros(NPAR)
    rho = float(props["density"])
    E = float(props["youngs_modulus"])
    nu = float(props["poisson_ratio"])
    if not (rho > 0.0 and E > 0.0 and -1.0 < nu < 0.5):
        raise ValueError(f"invalid elastic constants density={rho}, youngs_modulus={E}, poisson_ratio={nu}")
    G = E / (2.0 * (1.0 + nu))
    K = E / (3.0 * (1.0 - 2.0 * nu))
    par[P_RHO] = rho
    par[P_E] = E
    par[P_NU] = nu
    par[P_G] = G
    par[P_K] = K
    par[P_LAM] = K - 2.0 * G / 3.0
    if code == JOHNSON_COOK:
        for key, idx in _JC_KEYS.items():
            par[idx] = float(props[key])
        if not (par[P_TMELT] > par[P_TROOM] > 0.0 and par[P_EPS0] > 0.0 and par[P_CP] > 0.0
                and par[P_N] > 0.0 and par[P_M] > 0.0 and 0.0 <= par[P_CHI] <= 1.0
                and par[P_A] >= 0.0 and par[P_B] >= 0.0 and par[P_C] >= 0.0):
            raise ValueError(f"invalid Johnson-Cook parameters {dict((k, props[k]) for k in _JC_KEYS)}")
    return code, par


# --------------------------------------------------------------------------------------
# numba constitutive updates (scalar in/out)
# --------------------------------------------------------------------------------------


@njit(cache=True)
def jaumann_rotation(s0, s1, s2, s3, s4, s5, wxy, wyz, wzx, dt):
    """sigma + dt (W sigma - sigma W) (explicit Jaumann co-rotation).

    ``W`` is the spin with ``W_xy = wxy``, ``W_yz = wyz``, ``W_zx = wzx``
    (``W_ij = (L_ij - L_ji)/2``, ``L = grad v``).
    """
    a = wxy
    b = wyz
    c = wzx
    # M = W sigma, with W = [[0, a, -c], [-a, 0, b], [c, -b, 0]]
    m00 = a * s3 - c * s5
    m01 = a * s1 - c * s4
    m02 = a * s4 - c * s2
    m10 = -a * s0 + b * s5
    m11 = -a * s3 + b * s4
    m12 = -a * s5 + b * s2
    m20 = c * s0 - b * s3
    m21 = c * s3 - b * s1
    m22 = c * s5 - b * s4
    # W sigma - sigma W = M + M^T (W skew, sigma symmetric)
    return (s0 + dt * 2.0 * m00, s1 + dt * 2.0 * m11, s2 + dt * 2.0 * m22,
            s3 + dt * (m01 + m10), s4 + dt * (m12 + m21), s5 + dt * (m20 + m02))


@njit(cache=True)
def elastic_increment(s0, s1, s2, s3, s4, s5, d0, d1, d2, d3, d4, d5, dt, G, K):
    """sigma + dt (K tr(D) I + 2 G dev(D))."""
    tr = d0 + d1 + d2
    dl = (K - 2.0 * G / 3.0) * tr * dt
    g2 = 2.0 * G * dt
    return (s0 + dl + g2 * d0, s1 + dl + g2 * d1, s2 + dl + g2 * d2,
            s3 + g2 * d3, s4 + g2 * d4, s5 + g2 * d5)


@njit(cache=True)
def jc_homologous_factor(temp, par):
    """1 - T*^m with T* = clip((T - Troom)/(Tmelt - Troom), 0, 1)."""
    ts = (temp - par[P_TROOM]) / (par[P_TMELT] - par[P_TROOM])
    if ts <= 0.0:
        return 1.0
    if ts >= 1.0:
        return 0.0
    return 1.0 - ts ** par[P_M]


@njit(cache=True)
def jc_yield(eps_p, eps_rate, temp, par):
    """Johnson-Cook flow stress (A + B eps^n)(1 + C ln(max(rate/eps0, 1)))(1 - T*^m)."""
    hard = par[P_A]
    if eps_p > 0.0:
        hard += par[P_B] * eps_p ** par[P_N]
    r = eps_rate / par[P_EPS0]
    rate = 1.0
    if r > 1.0:
        rate += par[P_C] * math.log(r)
    return hard * rate * jc_homologous_factor(temp, par)


@njit(cache=True)
def jc_return_increment(q_tr, eps_p, temp, dt, par):
    """Plastic increment of the Johnson-Cook radial return.

    Solves  f(dg) = q_tr - 3 G dg - sigma_y(eps_p + dg, dg/dt, T) = 0  for the
    equivalent plastic strain increment ``dg`` >= 0, where ``q_tr`` is the von
    Mises stress of the elastic trial state and T the temperature at the start
    of the step (heating is applied after the return, staggered).

    Newton iterations are done in ``y = ln(dg)``: g(y) = f(e^y) is strictly
    decreasing and concave in y (3 G e^y, (eps_p + e^y)^n and the rate factor
    max(1, 1 + C (y - ln(eps0 dt))) are convex and increasing in y), and
    ``dg0 = (q_tr - sigma_y(eps_p, 0, T)) / (3G)`` is an upper bound of the root
    (g(y0) <= 0).  Newton started right of the root of a concave decreasing
    function decreases monotonically to the root without overshoot, so no
    bracketing is needed (the log variable also removes the infinite slope of
    eps^n at eps_p = 0 and the 1/dg of the rate term).  Returns
    ``(dg, sigma_y)``; ``dg == 0`` means an elastic step
    (``q_tr <= sigma_y(eps_p, 0, T)``).
    """
    G3 = 3.0 * par[P_G]
    theta = jc_homologous_factor(temp, par)
    sy0 = jc_yield(eps_p, 0.0, temp, par)
    f0 = q_tr - sy0
    if f0 <= 0.0:
        return 0.0, sy0
    if theta <= 0.0:
        return q_tr / G3, 0.0
    A = par[P_A]
    B = par[P_B]
    n = par[P_N]
    C = par[P_C]
    y_ref = math.log(par[P_EPS0] * dt)     # rate factor 1 + C (y - y_ref) for y > y_ref
    dg = f0 / G3
    y = math.log(dg)
    tol = JC_RTOL * q_tr
    for _ in range(JC_MAX_ITER):
        ep = eps_p + dg
        epn = ep ** n
        hard = A + B * epn
        rate = 1.0
        drate = 0.0
        if y > y_ref:
            rate += C * (y - y_ref)
            drate = C
        sy = theta * hard * rate
        g = q_tr - G3 * dg - sy
        if abs(g) <= tol:
            return dg, sy
        dgdy = -G3 * dg - theta * (B * n * epn * (dg / ep) * rate + hard * drate)
        step = -g / dgdy
        y += step
        dg = math.exp(y)
        if abs(step) <= JC_YTOL:
            # quadratic convergence: the remaining error in ln(dg) is O(step^2) ~ 1e-14,
            # and consistency gives sigma_y = q_tr - 3 G dg to the same accuracy
            return dg, q_tr - G3 * dg
    return dg, jc_yield(eps_p + dg, dg / dt, temp, par)


@njit(cache=True)
def johnson_cook_update(s0, s1, s2, s3, s4, s5, d0, d1, d2, d3, d4, d5,
                        wxy, wyz, wzx, dt, eps_p, temp, rho, par):
    """Hypoelastic (Jaumann) J2 update with Johnson-Cook flow stress.

    Returns the new stress (6 values), the plastic strain increment and the
    temperature increment (adiabatic heating chi sigma_y deps_p / (rho Cp)).
    """
    G = par[P_G]
    K = par[P_K]
    s0, s1, s2, s3, s4, s5 = jaumann_rotation(s0, s1, s2, s3, s4, s5, wxy, wyz, wzx, dt)
    s0, s1, s2, s3, s4, s5 = elastic_increment(s0, s1, s2, s3, s4, s5,
                                               d0, d1, d2, d3, d4, d5, dt, G, K)
    p = (s0 + s1 + s2) / 3.0
    x0 = s0 - p
    x1 = s1 - p
    x2 = s2 - p
    q_tr = math.sqrt(1.5 * (x0 * x0 + x1 * x1 + x2 * x2
                            + 2.0 * (s3 * s3 + s4 * s4 + s5 * s5)))
    dg, sy = jc_return_increment(q_tr, eps_p, temp, dt, par)
    if dg <= 0.0:
        return s0, s1, s2, s3, s4, s5, 0.0, 0.0
    fac = 1.0 - 3.0 * G * dg / q_tr
    if fac < 0.0:
        fac = 0.0
    dT = par[P_CHI] * sy * dg / (rho * par[P_CP])
    return (p + fac * x0, p + fac * x1, p + fac * x2, fac * s3, fac * s4, fac * s5, dg, dT)


@njit(cache=True)
def neo_hookean_stress(f00, f01, f02, f10, f11, f12, f20, f21, f22, mu, lam):
    """Compressible neo-Hookean Cauchy stress mu/J (b - I) + lambda ln(J)/J I.

    Returns (J, s0..s5); J <= 0 gives NaN stresses (caller flags the element).
    """
    J = (f00 * (f11 * f22 - f12 * f21) - f01 * (f10 * f22 - f12 * f20)
         + f02 * (f10 * f21 - f11 * f20))
    if not (J > 0.0):
        nan = math.nan
        return J, nan, nan, nan, nan, nan, nan
    b00 = f00 * f00 + f01 * f01 + f02 * f02
    b11 = f10 * f10 + f11 * f11 + f12 * f12
    b22 = f20 * f20 + f21 * f21 + f22 * f22
    b01 = f00 * f10 + f01 * f11 + f02 * f12
    b12 = f10 * f20 + f11 * f21 + f12 * f22
    b20 = f20 * f00 + f21 * f01 + f22 * f02
    mj = mu / J
    pv = lam * math.log(J) / J - mj
    return J, mj * b00 + pv, mj * b11 + pv, mj * b22 + pv, mj * b01, mj * b12, mj * b20


@njit(cache=True)
def neo_hookean_modulus(J, mu, lam):
    """Dilatational tangent modulus of the neo-Hookean model in the current state.

    Spatial tangent c = lam/J I(x)I + 2 (mu - lam ln J)/J II, so the P-wave
    modulus is (lam + 2 mu - 2 lam ln J)/J; bounded below by (lam + 2 mu)/J so
    that the stable time step is never overestimated in tension.
    """
    m = lam + 2.0 * mu
    mt = m - 2.0 * lam * math.log(J)
    if mt > m:
        m = mt
    return m / J
