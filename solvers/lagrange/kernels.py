"""Element kernels of the explicit Lagrangian finite-element solver.

One-point (uniform-gradient) 4-node plane-strain quadrilaterals (unit thickness)
and 8-node hexahedra with Flanagan-Belytschko viscous hourglass control.

Geometry: the corner vectors ``b_I = dV/dx_I`` (``B_I = b_I / V``), exact volumes and the
hourglass base vectors come from :mod:`solvers.elements` (shared with the ALE background).

Kinematics: ``L = sum_I v_I (x) B_I(x^{n-1/2})`` evaluated at the mid-step
configuration ``x^{n-1/2} = x^n - dt/2 v^{n-1/2}``; for a discrete rigid rotation
this makes ``D = 0`` exactly (the mid-point velocity field is the Cayley
transform of the rotation, a skew linear map of ``x^{n-1/2}``).

Internal force (force ON the nodes): ``f_I = -V (sigma - q I) B_I =
-(sigma - q I) b_I`` with b at x^n, plus the hourglass force.

Hourglass (FB viscous, LS-DYNA type 2/3 form): with the base vectors Gamma_a
(hex: eta zeta, zeta xi, xi eta, xi eta zeta; quad: xi eta) and
``gamma_a = Gamma_a - (Gamma_a . x_i) B_i`` (orthogonal to every linear field),
``g_ia = sum_I v_iI gamma_aI`` and ``f_iI = -a_h sum_a g_ia gamma_aI`` with
``a_h = hg_coef rho c V^(2/3) / 4`` (hex) and ``a_h = hg_coef rho c A^(1/2) / 4``
(quad, per unit thickness).  ``sum_I gamma_aI = 0`` and
``sum_I x_I gamma_aI = 0`` give exact conservation of linear and angular momentum
and zero force for any velocity field linear in x (rigid motion).

Hourglass (assumed-strain stiffness, elements of a body with hourglass_control = "assumed_strain";
Belytschko & Bindeman 1991 for the quad, 1993 for the hexahedron, whose form is in
_hex_assumed_strain: the strains linear in one coordinate, in plane stress normal to it). A
potential of the hourglass deformation H = sum_I gamma0_I x_I (gamma0 the FB vector of the
reference: H vanishes on every affine map of the reference) in the element's co-rotational frame.
Quads: e1 along the mean xi edge, ``h_k = e_k . H`` loads ``Q_k = K_k h_k`` with
``K_1 = E' b / (12 a)``, ``K_2 = E' a / (12 b)`` (a, b the reference half widths along e1, e2) and
``E' = 4 G (3K + G) / (3K + 4G)``: the energy of the bending strain the bilinear field holds, the
transverse stress relaxed, so that a rectangle bends exactly and nu -> 1/2 does not lock;
``f_I = -gamma0_I (Q_1 e1 + Q_2 e2)`` plus the frame's share, the exact gradient of 1/2 Q . h:
conservative and torque free (an incremental form pumped energy into a spinning block).
A body one or two elements thick then bends as Euler-Bernoulli (the viscous form adds no
stiffness: the constant-strain part alone holds 1 - 1/n^2 of the bending with n elements).

Artificial bulk viscosity (LS-DYNA form): for ``div v < 0``
``q = rho l (q_quad l (div v)^2 - q_lin c div v)``.

Stable step: ``dt_e = l / (Q + sqrt(Q^2 + c^2))`` with
``Q = q_lin c + q_quad l |div v|`` for ``div v < 0`` and ``Q = 0`` otherwise
(LS-DYNA); c = dilatational wave speed at the current density (elastic moduli
for Johnson-Cook, current tangent for neo-Hookean) and ``l = V / max face area``
(hex, LS-DYNA's), shortened to the element's eigenvalue bound where its stretch modes carry lambda
along every axis (``l c / sqrt(c^2 + lambda / rho (l^2 8 sum_I |b_I|^2 / V^2 / 4 - 1))``: h / sqrt(3) for
an incompressible cube, LS-DYNA's l for a flat one), or ``l = A / max diagonal`` (quad, the conservative LS-DYNA shell
option: for a square l = h/sqrt(2), the element eigenvalue bound 2/omega_max of
the one-point quad in the incompressible limit).

Stress update (dt_prev > 0): explicit Jaumann rate
``sigma^n = sigma^{n-1} + dt (W sigma^{n-1} - sigma^{n-1} W) + dt C:D`` for the
hypoelastic models (then a radial return for Johnson-Cook, temperature of the
start of the step in the flow stress, adiabatic heating added afterwards);
neo-Hookean stresses from ``F = sum_I x_I (x) gradN0_I`` at x^n.  Internal
energy increment ``1/2 (sigma^{n-1} + sigma^n) : D  V^{n-1/2} dt``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers import elements as _elements
from solvers.elements import HEX_HG, QUAD_HG, hex_bvectors, quad_bvectors, quad_viscous_hourglass
from solvers.numba_cache import flush_stale_cache

from . import materials as _materials
from .materials import (JOHNSON_COOK, LINEAR_ELASTIC, NEO_HOOKEAN, P_G, P_K, P_LAM,
                        elastic_increment, jaumann_rotation, jc_yield, johnson_cook_update,
                        neo_hookean_modulus, neo_hookean_stress)

# The viscous hourglass control's share kept with the assumed-strain stiffness: the stiffness alone
# leaves the hourglass modes undamped, and steps that vary from one to the next pump them (a struck
# steel bar one hexahedron across, its steps a random walk through the step control: hourglass
# energy 1e-9 -> 7e-6 J over 10^4 steps, then an inverted element at step 83,469; at constant steps
# it stays at 1e-10). A tenth of the viscous control's coefficient, as a damping of the hourglass
# coordinates' rate in the co-rotational frame (torque free; the state keeps their values a step
# before), holds it and leaves a cantilever's first peak within 0.01 % of the stiffness alone.
AS_VISCOUS_SHARE = 0.1


@njit(cache=True)
def _damping_share(kk):
    """The damping's factor on AS_VISCOUS_SHARE at the hourglass stiffness's factor kk this step (1
    elastic, down to 0 where the radial return or the fibre check takes all of it): the viscous
    control comes back as the stiffness vanishes, share + (1 - share)(1 - kk)^4 of the viscous
    coefficient, so an element that flows without strength is held as the viscous control holds
    it.  A rod of zero strength (a hydrodynamic penetrator, kap = 0 every step) at a tenth of the
    viscous control let a tip node run 0.25 mm sideways at 199 m/s across its symmetry plane in 3
    us.  A yielding metal keeps the share: kap = sigma_y / (sigma_y + 3 G de) is 0.6-0.9 at each
    step of a Taylor bar's flow, and (1 - kk) in place of (1 - kk)^4 moved its impact diameter at 6
    cells across from 0.2 % to 0.46 % off the measured one."""
    r = (1.0 - kk) * (1.0 - kk)
    return 1.0 + (1.0 / AS_VISCOUS_SHARE - 1.0) * r * r


__all__ = ["element_forces", "reference_gradients", "LINEAR_ELASTIC", "NEO_HOOKEAN", "JOHNSON_COOK"]


@njit(cache=True)
def reference_gradients(X, conn):
    """Uniform gradients ``gradN0 (ne, nen, dim)`` and volumes ``vol0 (ne,)`` at X.

    ``gradN0[e, I] = (1/V0) dV0/dX_I``; ``F = sum_I x_I (x) gradN0_I`` is then the
    volume average of the deformation gradient of the element.
    """
    ne = conn.shape[0]
    nen = conn.shape[1]
    dim = X.shape[1]
    grad = np.zeros((ne, nen, dim))
    vol0 = np.zeros(ne)
    xe = np.empty((nen, dim))
    b = np.empty((nen, dim))
    for e in range(ne):
        for i in range(nen):
            for k in range(dim):
                xe[i, k] = X[conn[e, i], k]
        if dim == 3:
            vol, _ = hex_bvectors(xe, b)
        else:
            vol, _ = quad_bvectors(xe, b)
        vol0[e] = vol
        inv = 1.0 / vol
        for i in range(nen):
            for k in range(dim):
                grad[e, i, k] = b[i, k] * inv
    return grad, vol0


@njit(cache=True)
def _is_bad(s0, s1, s2, s3, s4, s5):
    t = s0 + s1 + s2 + s3 + s4 + s5
    return not (t - t == 0.0)


@njit(cache=True)
def _erode(e, alive, q_out, cut_row, fe_cut):
    """Element e erodes (LS-DYNA's MAT_ADD_EROSION): it gives no force and no stable step from now
    on; its nodes keep their mass and momentum, its internal energy stays booked (the eroded energy).
    Its corner forces at a partition cut are zeroed (the shared sums add that buffer every step)."""
    alive[e] = 0
    q_out[e] = 0.0
    r = cut_row[e]
    if r >= 0:
        fe_cut[r, :, :] = 0.0
    return 1

@njit(cache=True, inline="always")
def _return_factor(s0, s1, s2, s3, s4, s5, G, dgp):
    """The radial return's factor q / q_trial = q / (q + 3 G dgp) of a step that yielded (J2: the
    returned deviator is the trial one times it)."""
    p = (s0 + s1 + s2) / 3.0
    q = math.sqrt(1.5 * ((s0 - p) ** 2 + (s1 - p) ** 2 + (s2 - p) ** 2 + 2.0 * (s3 * s3 + s4 * s4 + s5 * s5)))
    return q / (q + 3.0 * G * dgp)


@njit(cache=True, inline="always")
def _flow_stress_sq(s0, s1, s2, s3, s4, s5, eps_p, temp, par):
    """The fibre check's flow stress squared: the larger of the static Johnson-Cook flow stress at
    the element's plastic strain and the von Mises stress of the returned state (which carries the
    rate factor where the element yielded this step)."""
    return max(jc_yield(eps_p, 0.0, temp, par) ** 2,
               3.0 * (s3 * s3 + s4 * s4 + s5 * s5) + 0.5 * ((s0 - s1) ** 2 + (s1 - s2) ** 2 + (s2 - s0) ** 2))


# the 2-point Gauss abscissa: the fibre check samples the hourglass stress where a 2 x 2 (x 2) rule would
_GAUSS = 1.0 / math.sqrt(3.0)


@njit(cache=True, inline="always")
def _vm_dot(c, d):
    """The von Mises bilinear form of two stresses (xx, yy, zz, xy, yz, zx): vm(s)^2 = _vm_dot(s, s)."""
    return (0.5 * ((c[0] - c[1]) * (d[0] - d[1]) + (c[1] - c[2]) * (d[1] - d[2]) + (c[2] - c[0]) * (d[2] - d[0]))
            + 3.0 * (c[3] * d[3] + c[4] * d[4] + c[5] * d[5]))


@njit(cache=True, inline="always")
def _fibre_factor(c, d, sf2, k):
    """min(k, kf): kf the largest share in [0, 1] of the hourglass stress d that a fibre carries on top
    of the element's stress c without passing the flow stress sf (sf2 = sf^2):
    vm^2(c + kf d) = A kf^2 + 2 B kf + C <= sf2."""
    a = _vm_dot(d, d)
    if not (a > 0.0):
        return k
    b = _vm_dot(c, d)
    cc = min(_vm_dot(c, c), sf2)   # the element's stress is on or inside the surface (radial return)
    if a + 2.0 * b + cc <= sf2:
        return k
    kf = (-b + math.sqrt(max(b * b + a * (sf2 - cc), 0.0))) / a
    return min(k, max(kf, 0.0))


@njit(cache=True, inline="always")
def _may_yield_3d(fw, sc, sf2):
    """False when no Gauss point can pass the flow stress: vm(c + d) <= vm(c) + sqrt(3) |d| and
    |d| <= (|D_0| + |D_1| + |D_2|) / sqrt(3) + |E| / 3 for the hourglass stress d at any of the eight
    points (blocks D_s = fw[2 + s, 0:3] times xi_s, patterns E = fw[5, 0:3] times xi_i xi_j); vm is
    frame invariant, so the element's stress sc is taken as it is.  The eight-point check costs
    more than the rest of the stiffness: an elastic element far from yield skips it."""
    b = 0.0
    for r in range(2, 5):
        b += math.sqrt(fw[r, 0] * fw[r, 0] + fw[r, 1] * fw[r, 1] + fw[r, 2] * fw[r, 2])
    b = b * _GAUSS + math.sqrt(fw[5, 0] * fw[5, 0] + fw[5, 1] * fw[5, 1] + fw[5, 2] * fw[5, 2]) / 3.0
    v = math.sqrt(min(_vm_dot(sc, sc), sf2)) + math.sqrt(3.0) * b
    return v * v > sf2


@njit(cache=True, inline="always")
def _may_yield_2d(h1, h2, ep, a4, b4, kb, G, s0, s1, s2, s3, sf2):
    """The quad's _may_yield_3d: |d| <= (|d_11| + |d_22|)(1 + |nu|) at the 2 x 2 points,
    d_11 = E' h_1 / (4a) / sqrt(3), d_22 = E' h_2 / (4b) / sqrt(3); vm of the element's stress
    (xx, yy, zz, xy)."""
    nu = (3.0 * kb - 2.0 * G) / (2.0 * (3.0 * kb + G))
    b = (abs(ep * h1 / a4) + abs(ep * h2 / b4)) * _GAUSS * (1.0 + abs(nu))
    c2 = 0.5 * ((s0 - s1) ** 2 + (s1 - s2) ** 2 + (s2 - s0) ** 2) + 3.0 * s3 * s3
    v = math.sqrt(min(c2, sf2)) + math.sqrt(3.0) * b
    return v * v > sf2


@njit(cache=True, inline="always")
def _in_frame(ev, a, c, s):
    """e_a . S . e_c for the stress s (xx, yy, zz, xy, yz, zx) and the frame rows ev."""
    x = ev[c, 0]
    y = ev[c, 1]
    z = ev[c, 2]
    return (ev[a, 0] * (s[0] * x + s[3] * y + s[5] * z) + ev[a, 1] * (s[3] * x + s[1] * y + s[4] * z)
            + ev[a, 2] * (s[5] * x + s[4] * y + s[2] * z))


# the quad's mean xi edge m = sum_I s_I x_I = (x1 - x0) + (x2 - x3)
_QUAD_EDGE = (-1.0, 1.0, 1.0, -1.0)

# the in-plane index pairs (i, j) of the hexahedron's three bending blocks s = 0, 1, 2 (the strains
# linear in xi_s that lie in the plane normal to e_s)
_BLOCK_I = (1, 2, 0)
_BLOCK_J = (2, 0, 1)


@njit(cache=True, inline="always")
def _hex_moments(xe, d, m):
    """The eight moments sum_I p(xi_I) x_Id of coordinate d over the patterns p = 1, xi, eta, zeta,
    eta zeta, zeta xi, xi eta, xi eta zeta into m[0:8] (VTK node order), by three butterfly stages
    (24 additions instead of 56 multiply-adds)."""
    s00 = xe[1, d] + xe[0, d]
    d00 = xe[1, d] - xe[0, d]
    s10 = xe[2, d] + xe[3, d]
    d10 = xe[2, d] - xe[3, d]
    s01 = xe[5, d] + xe[4, d]
    d01 = xe[5, d] - xe[4, d]
    s11 = xe[6, d] + xe[7, d]
    d11 = xe[6, d] - xe[7, d]
    ss0 = s10 + s00
    sd0 = s10 - s00
    ss1 = s11 + s01
    sd1 = s11 - s01
    ds0 = d10 + d00
    dd0 = d10 - d00
    ds1 = d11 + d01
    dd1 = d11 - d01
    m[0] = ss1 + ss0
    m[1] = ds1 + ds0
    m[2] = sd1 + sd0
    m[3] = ss1 - ss0
    m[4] = sd1 - sd0
    m[5] = ds1 - ds0
    m[6] = dd1 + dd0
    m[7] = dd1 - dd0


@njit(cache=True, inline="always")
def _hex_spread(c, out, d):
    """The inverse of _hex_moments: out[I, d] += sum_p c[p] p(xi_I) for the eight patterns."""
    # zeta stage
    ss1 = c[0] + c[3]
    ss0 = c[0] - c[3]
    sd1 = c[2] + c[4]
    sd0 = c[2] - c[4]
    ds1 = c[1] + c[5]
    ds0 = c[1] - c[5]
    dd1 = c[6] + c[7]
    dd0 = c[6] - c[7]
    # eta stage
    s10 = ss0 + sd0
    s00 = ss0 - sd0
    s11 = ss1 + sd1
    s01 = ss1 - sd1
    d10 = ds0 + dd0
    d00 = ds0 - dd0
    d11 = ds1 + dd1
    d01 = ds1 - dd1
    # xi stage
    out[1, d] += s00 + d00
    out[0, d] += s00 - d00
    out[2, d] += s10 + d10
    out[3, d] += s10 - d10
    out[5, d] += s01 + d01
    out[4, d] += s01 - d01
    out[6, d] += s11 + d11
    out[7, d] += s11 - d11


@njit(cache=True, inline="always")
def _frame_of(j, ev):
    """The orthonormal e_k from the centre Jacobian columns j_k (Gram-Schmidt from e_1) into ev;
    returns (n0, n1, p) = (|j_0|, |j_1 - p e_1|, j_1 . e_1), which the frame's derivative needs."""
    n0 = math.sqrt(j[0, 0] ** 2 + j[0, 1] ** 2 + j[0, 2] ** 2)
    for d in range(3):
        ev[0, d] = j[0, d] / n0
    p = j[1, 0] * ev[0, 0] + j[1, 1] * ev[0, 1] + j[1, 2] * ev[0, 2]
    for d in range(3):
        ev[1, d] = j[1, d] - p * ev[0, d]
    n1 = math.sqrt(ev[1, 0] ** 2 + ev[1, 1] ** 2 + ev[1, 2] ** 2)
    for d in range(3):
        ev[1, d] /= n1
    ev[2, 0] = ev[0, 1] * ev[1, 2] - ev[0, 2] * ev[1, 1]
    ev[2, 1] = ev[0, 2] * ev[1, 0] - ev[0, 0] * ev[1, 2]
    ev[2, 2] = ev[0, 0] * ev[1, 1] - ev[0, 1] * ev[1, 0]
    return n0, n1, p


@njit(cache=True, inline="always")
def _quad_frame(xe):
    """The quad's co-rotational frame: e1 along the mean xi edge m = (x1 - x0) + (x2 - x3), e2 normal
    to it; returns (e1_x, e1_y, |m|)."""
    m0 = (xe[1, 0] - xe[0, 0]) + (xe[2, 0] - xe[3, 0])
    m1 = (xe[1, 1] - xe[0, 1]) + (xe[2, 1] - xe[3, 1])
    lm = math.sqrt(m0 * m0 + m1 * m1)
    return m0 / lm, m1 / lm, lm


@njit(cache=True)
def assumed_strain_reference(x, conn, hgq):
    """The reference part of the assumed-strain hourglass state, from the reference coordinates x:
    hexahedra hgq[e, 0:12] = sum_I h_aI X_I (a = 0..3, the patterns eta zeta, zeta xi, xi eta,
    xi eta zeta) and hgq[e, 12:15] the half widths a_k = j_k . e_k; quads hgq[e, 0:2] = sum_I h_I X_I
    and hgq[e, 2:4] the mean edge lengths (4 a, 4 b along and across the mean xi edge). The same
    moments and frames as the kernels'."""
    nen = conn.shape[1]
    xe = np.empty((nen, x.shape[1]))
    j = np.empty((3, 3))
    ev = np.empty((3, 3))
    mo = np.empty((3, 8))
    for e in range(conn.shape[0]):
        for i in range(nen):
            for d in range(x.shape[1]):
                xe[i, d] = x[conn[e, i], d]
        if nen == 8:
            for d in range(3):
                _hex_moments(xe, d, mo[d])
                for a in range(4):
                    hgq[e, 3 * a + d] = mo[d, 4 + a]
                for k in range(3):
                    j[k, d] = 0.125 * mo[d, 1 + k]
            _frame_of(j, ev)
            for k in range(3):
                hgq[e, 12 + k] = abs(j[k, 0] * ev[k, 0] + j[k, 1] * ev[k, 1] + j[k, 2] * ev[k, 2])
        else:
            for d in range(2):
                t = 0.0
                for i in range(4):
                    t += QUAD_HG[i] * xe[i, d]
                hgq[e, d] = t
            e10, e11, lm = _quad_frame(xe)
            hgq[e, 2] = lm
            hgq[e, 3] = abs(-e11 * ((xe[3, 0] - xe[0, 0]) + (xe[2, 0] - xe[1, 0]))
                            + e10 * ((xe[3, 1] - xe[0, 1]) + (xe[2, 1] - xe[1, 1])))


@njit(cache=True, inline="always")
def _hex_assumed_strain(xe, gn, dt, G, kb, kap, vol0, hs, fe, j, ev, hm, hf, q, fm, mo, cv, sc, sf2, fw, ah):
    """The assumed-strain hourglass stiffness of the one-point hexahedron (after Belytschko &
    Bindeman 1993), a potential: its forces added to fe; returns the step's hourglass work.

    Hourglass deformation (total, from the reference): H_a = sum_I gamma0_aI x_I with the reference
    hourglass vectors gamma0_aI = h_aI - (sum_J h_aJ X_J) . gradN0_I, which vanish on every affine
    map of the reference (patch test), so H_a = sum_I h_aI x_I - F hX0_a (F the uniform-gradient
    deformation gradient). Its components in the co-rotational frame (_frame_of), less the plastic
    offset hp, h_ka = e_k . H_a - hp_ka. On a box (half widths a_k, fixed at the reference) the mode
    u_k = c h_a has h_ka = 8 c, and the patterns a = 0..2 give strains linear in one coordinate each:
    the block s holds the strains linear in xi_s in the plane normal to e_s,
        eps_ii = h_ij / (8 a_i),  eps_jj = h_ji / (8 a_j),  gamma_ij = h_ii / (8 a_j) + h_jj / (8 a_i)
    ((i, j) the other two indices), loaded in plane stress (sigma_ss = 0, the transverse shears of
    the block dropped): a bending mode carries no parasitic shear (no shear locking) and no
    volumetric stiffness (E / (1 - nu^2) -> 4 G as nu -> 1/2: no volumetric locking); a plate strip
    one element thick bends with E / (1 - nu^2), a narrow beam, its transverse mode free, with E.
    The twist of a plate (the three modes h_kk together) carries its in-plane shear; each alone its
    transverse shears. The pattern xi eta zeta loads its normal strain eps_kk = h_k3 xi_i xi_j / (8 a_k)
    with E (weight V0 / 9). Energy E_h = 1/2 sum sigma : eps (weights V0 / 3, V0 / 9), Q_ka = dE_h /
    dh_ka; the forces are its exact gradient, f_I = -sum_ka Q_ka gamma0_aI e_k minus the frame's
    share (the frame turns with j_0, j_1: dE_h/dphi = T = sum_ka Q_ka e_k x H_a), so the stiffness
    is conservative and torque free: a spinning body neither gains energy nor turns its momenta
    (an incremental form, Q += K g dt in the turning frame, pumped energy into a spinning block).
    Plasticity (Johnson-Cook; sf2 the flow stress squared, else inf): while the element's centre is
    elastic, h - hp is scaled by the fibre factor, the largest share of the hourglass stress that
    the element's stress sc plus it can carry at the eight 2 x 2 x 2 Gauss points without passing
    the flow stress (_fibre_factor); once the centre yields, by the radial return's factor kap =
    q / q_trial; the offset hp takes the rest. So the bending across the element yields at its
    outer fibres, as a fully integrated element's would, and a plastic hinge forms when the section
    is plastic, not first when the element's mean stress yields (in a section two elements thick,
    that mean stress sits at a quarter depth: a cantilever stood 1.5x its limit load). (The fibre
    factor where the centre flows as well dropped the hourglass stress at once and let the Taylor
    bar's foot spread: impact diameter +1.4 %, against +0.2 % this way.) The work of a step (E_h
    before the return less E_h of the step before) goes to hs[40] and the element's internal energy;
    hs: [0:12] hX0, [12:15] a_k, [15:27] hp (k * 4 + a), [27:39] the frame components of the step
    before, [39] E_h, [40] the work so far; fw: (6, 6) work.
    Damping (ah > 0, the viscous control's coefficient times AS_VISCOUS_SHARE): Q_ka += ah (r_ka -
    r_ka') / dt, r_ka = e_k . (H_a - F hX0_a) the frame components now and r' a step before: the
    hourglass rate in the co-rotational frame (a rigid rotation leaves r unchanged: no torque),
    Flanagan-Belytschko's generalised force ah dH/dt at the price of 12 numbers per element, through
    the same spread."""
    for d in range(3):  # the moments of x: j_k = mo[:, 1 + k] / 8, sum_I h_aI x_I = mo[:, 4 + a]
        _hex_moments(xe, d, mo[d])
        for k in range(3):
            j[k, d] = 0.125 * mo[d, 1 + k]
    n0, n1, p = _frame_of(j, ev)
    for d in range(3):
        for c in range(3):
            t = 0.0
            for i in range(8):
                t += xe[i, d] * gn[i, c]
            fm[d, c] = t
    for a in range(4):
        for d in range(3):
            hm[a, d] = mo[d, 4 + a] - (fm[d, 0] * hs[3 * a] + fm[d, 1] * hs[3 * a + 1] + fm[d, 2] * hs[3 * a + 2])
    for k in range(3):
        for a in range(4):
            hf[k, a] = (ev[k, 0] * hm[a, 0] + ev[k, 1] * hm[a, 1] + ev[k, 2] * hm[a, 2]) - hs[15 + 4 * k + a]
    i0 = 0.125 / hs[12]
    i1 = 0.125 / hs[13]
    i2 = 0.125 / hs[14]
    # moduli: Young's, Poisson's and the plane-stress modulus E / (1 - nu^2) = 4 G (3K + G) / (3K + 4G)
    ey = 9.0 * kb * G / (3.0 * kb + G)
    nu = (3.0 * kb - 2.0 * G) / (2.0 * (3.0 * kb + G))
    eps = 4.0 * G * (3.0 * kb + G) / (3.0 * kb + 4.0 * G)
    w3 = vol0 / 3.0   # integral of xi_s^2 over the box
    w9 = vol0 / 9.0   # integral of (xi_i xi_j)^2
    q[:, :] = 0.0
    energy = 0.0
    for s in range(3):
        i = _BLOCK_I[s]
        jj = _BLOCK_J[s]
        ii_ = i0 if i == 0 else (i1 if i == 1 else i2)
        ij_ = i0 if jj == 0 else (i1 if jj == 1 else i2)
        e_ii = hf[i, jj] * ii_
        e_jj = hf[jj, i] * ij_
        g_ij = hf[i, i] * ij_ + hf[jj, jj] * ii_
        s0 = eps * (e_ii + nu * e_jj)
        s1 = eps * (e_jj + nu * e_ii)
        s2 = G * g_ij
        fw[2 + s, 0] = s0
        fw[2 + s, 1] = s1
        fw[2 + s, 2] = s2
        energy += 0.5 * w3 * (s0 * e_ii + s1 * e_jj + s2 * g_ij)
        q[i, jj] += w3 * s0 * ii_
        q[jj, i] += w3 * s1 * ij_
        q[i, i] += w3 * s2 * ij_
        q[jj, jj] += w3 * s2 * ii_
    for k in range(3):
        ik = i0 if k == 0 else (i1 if k == 1 else i2)
        e_kk = hf[k, 3] * ik
        sn = ey * e_kk
        fw[5, k] = sn
        energy += 0.5 * w9 * sn * e_kk
        q[k, 3] = w9 * sn * ik
    work = 0.0
    kk = 1.0
    if dt > 0.0:
        work = energy - hs[39]
        kk = kap
        if sf2 < np.inf and kap == 1.0 and _may_yield_3d(fw, sc, sf2):
            # (the centre elastic) the element's stress in the frame (xx, yy, zz, xy, yz, zx), then the hourglass
            # stress at each Gauss point: sum_s xi_s (block s) + sum_k xi_i xi_j (pattern k)
            for a in range(3):
                fw[0, a] = _in_frame(ev, a, a, sc)
            fw[0, 3] = _in_frame(ev, 0, 1, sc)
            fw[0, 4] = _in_frame(ev, 1, 2, sc)
            fw[0, 5] = _in_frame(ev, 2, 0, sc)
            for gp in range(8):
                x0 = _GAUSS if gp & 1 else -_GAUSS
                x1 = _GAUSS if gp & 2 else -_GAUSS
                x2 = _GAUSS if gp & 4 else -_GAUSS
                xyz = x0 * x1 * x2
                for c in range(6):
                    fw[1, c] = 0.0
                for s in range(3):
                    xs = x0 if s == 0 else (x1 if s == 1 else x2)
                    fw[1, _BLOCK_I[s]] += xs * fw[2 + s, 0]
                    fw[1, _BLOCK_J[s]] += xs * fw[2 + s, 1]
                    fw[1, 3 + (s + 1) % 3] += xs * fw[2 + s, 2]
                    fw[1, s] += xyz / xs * fw[5, s]
                kk = _fibre_factor(fw[0], fw[1], sf2, kk)
        if kk < 1.0:
            for k in range(3):
                for a in range(4):
                    hs[15 + 4 * k + a] += (1.0 - kk) * hf[k, a]
                    q[k, a] *= kk
            energy *= kk * kk
        hs[39] = energy
        hs[40] += work
    # damping (dt > 0): the frame components' rate over the step, r = hf + hp before the return = hp + kk hf
    # after it; with the frame's share: T = sum_ka Q_ka e_k x H_a; dE/dj_0 = c0, dE/dj_1 = c1
    ih = ah * _damping_share(kk) / dt if dt > 0.0 else 0.0
    if dt > 0.0:
        for k in range(3):
            for a in range(4):
                i = 27 + 4 * k + a
                r = hs[i - 12] + kk * hf[k, a]
                q[k, a] += ih * (r - hs[i])
                hs[i] = r
    # P_a = sum_k Q_ka e_k (into fw[0:4, 0:3], free after the fibre check) and the torque
    # t = sum_ka Q_ka e_k x H_a = sum_a P_a x H_a
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    for a in range(4):
        for d in range(3):
            fw[a, d] = q[0, a] * ev[0, d] + q[1, a] * ev[1, d] + q[2, a] * ev[2, d]
        t0 += fw[a, 1] * hm[a, 2] - fw[a, 2] * hm[a, 1]
        t1 += fw[a, 2] * hm[a, 0] - fw[a, 0] * hm[a, 2]
        t2 += fw[a, 0] * hm[a, 1] - fw[a, 1] * hm[a, 0]
    T1 = t0 * ev[0, 0] + t1 * ev[0, 1] + t2 * ev[0, 2]
    T2 = t0 * ev[1, 0] + t1 * ev[1, 1] + t2 * ev[1, 2]
    T3 = t0 * ev[2, 0] + t1 * ev[2, 1] + t2 * ev[2, 2]
    # f_I = -sum_a h_aI P_a + (sum_a P_a hX0_a^T) gradN0_I - (xi_I c0 + eta_I c1) / 8,
    # c0 = dE/dj_0, c1 = dE/dj_1: the pattern sums spread back to the nodes (_hex_spread)
    r0 = 0.125 / n0
    r1 = 1.0 / n1
    fm[:, :] = 0.0
    for d in range(3):
        cv[0] = 0.0
        cv[3] = 0.0
        cv[1] = -(T3 * ev[1, d] - T2 * ev[2, d] - T1 * p * ev[2, d] * r1) * r0
        cv[2] = -0.125 * T1 * ev[2, d] * r1
        for a in range(4):
            pa = fw[a, d]
            cv[4 + a] = -pa
            fm[d, 0] += pa * hs[3 * a]
            fm[d, 1] += pa * hs[3 * a + 1]
            fm[d, 2] += pa * hs[3 * a + 2]
        _hex_spread(cv, fe, d)
    for i in range(8):
        g0 = gn[i, 0]
        g1 = gn[i, 1]
        g2 = gn[i, 2]
        for d in range(3):
            fe[i, d] += fm[d, 0] * g0 + fm[d, 1] * g1 + fm[d, 2] * g2
    return work


@njit(cache=True)
def _forces_hex(x, v, dt, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig, eps_p,
                temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut, alive, eps_eq, erode_at, erode_dt,
                hg_stiff, hgq, dt_el, dte_out):
    ne = conn.shape[0]
    xe = np.empty((8, 3))
    ve = np.empty((8, 3))
    xm = np.empty((8, 3))
    b = np.empty((8, 3))
    bm = np.empty((8, 3))
    fe = np.empty((8, 3))
    hj = np.empty((3, 3))
    hev = np.empty((3, 3))
    hhm = np.empty((4, 3))
    hgr = np.empty((3, 4))
    hq = np.empty((3, 4))
    hfm = np.empty((3, 3))
    hmo = np.empty((3, 8))
    hcv = np.empty(8)
    hsc = np.empty(6)
    hfw = np.empty((6, 6))
    dt_min = np.inf
    dt_at = -1   # the element that sets dt_min (the step's limiter, named in the log)
    n_eroded = 0
    half_dt = 0.5 * dt
    per_element = dt_el.shape[0] > 0   # subcycling (subcycling.py): each element its own step
    keep_dte = dte_out.shape[0] > 0
    for e in range(ne):
        if alive[e] == 0:  # eroded: no force, no stable step (its nodes keep their mass)
            continue
        if per_element:
            dt = dt_el[e]
            # not evaluated at this substep: no force (its corner forces at a cut zeroed); written out in
            # both kernels: an inlined helper for it cost 4 % of a quad's element-cycle (bench lagrange)
            if dt < 0.0:
                r = cut_row[e]
                if r >= 0:
                    fe_cut[r, :, :] = 0.0
                continue
            half_dt = 0.5 * dt
        for i in range(8):
            nd = conn[e, i]
            for k in range(3):
                xe[i, k] = x[nd, k]
                ve[i, k] = v[nd, k]
        vol, amax = hex_bvectors(xe, b)
        if not (vol > 0.0):
            if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                continue
            return dt_min, e, n_eroded, -1
        # velocity gradient at the mid-step configuration
        if dt > 0.0:
            for i in range(8):
                for k in range(3):
                    xm[i, k] = xe[i, k] - half_dt * ve[i, k]
            vm, _ = hex_bvectors(xm, bm)
            if not (vm > 0.0):
                if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                    n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                    continue
                return dt_min, e, n_eroded, -1
            bg = bm
        else:
            vm = vol
            bg = b
        l00 = 0.0
        l01 = 0.0
        l02 = 0.0
        l10 = 0.0
        l11 = 0.0
        l12 = 0.0
        l20 = 0.0
        l21 = 0.0
        l22 = 0.0
        for i in range(8):
            vx = ve[i, 0]
            vy = ve[i, 1]
            vz = ve[i, 2]
            bx = bg[i, 0]
            by = bg[i, 1]
            bz = bg[i, 2]
            l00 += vx * bx
            l01 += vx * by
            l02 += vx * bz
            l10 += vy * bx
            l11 += vy * by
            l12 += vy * bz
            l20 += vz * bx
            l21 += vz * by
            l22 += vz * bz
        ivm = 1.0 / vm
        d0 = l00 * ivm
        d1 = l11 * ivm
        d2 = l22 * ivm
        d3 = 0.5 * (l01 + l10) * ivm
        d4 = 0.5 * (l12 + l21) * ivm
        d5 = 0.5 * (l20 + l02) * ivm
        wxy = 0.5 * (l01 - l10) * ivm
        wyz = 0.5 * (l12 - l21) * ivm
        wzx = 0.5 * (l20 - l02) * ivm
        divv = d0 + d1 + d2
        if erode_at[e] < np.inf and dt > 0.0:
            # the effective (von Mises) strain, sqrt(2/3 d':d') integrated over the steps: the
            # erosion criterion of a body without strength (its plastic strain stays 0)
            t = divv / 3.0
            eps_eq[e] += dt * math.sqrt(2.0 / 3.0 * ((d0 - t) ** 2 + (d1 - t) ** 2 + (d2 - t) ** 2
                                                     + 2.0 * (d3 * d3 + d4 * d4 + d5 * d5)))
            if eps_eq[e] >= erode_at[e]:
                n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                continue

        # constitutive update
        mid = mat_id[e]
        code = mat_code[mid]
        rho = mass_e[e] / vol
        o0 = sig[e, 0]
        o1 = sig[e, 1]
        o2 = sig[e, 2]
        o3 = sig[e, 3]
        o4 = sig[e, 4]
        o5 = sig[e, 5]
        s0, s1, s2, s3, s4, s5 = o0, o1, o2, o3, o4, o5
        G = mat_par[mid, P_G]
        kap = 1.0   # the radial return's factor this step (1: elastic), applied to hourglass stresses
        sf2 = np.inf   # the flow stress squared (plastic materials): the hourglass stiffness's fibre check
        if code == NEO_HOOKEAN:
            f00 = 0.0
            f01 = 0.0
            f02 = 0.0
            f10 = 0.0
            f11 = 0.0
            f12 = 0.0
            f20 = 0.0
            f21 = 0.0
            f22 = 0.0
            for i in range(8):
                g0 = gradN0[e, i, 0]
                g1 = gradN0[e, i, 1]
                g2 = gradN0[e, i, 2]
                f00 += xe[i, 0] * g0
                f01 += xe[i, 0] * g1
                f02 += xe[i, 0] * g2
                f10 += xe[i, 1] * g0
                f11 += xe[i, 1] * g1
                f12 += xe[i, 1] * g2
                f20 += xe[i, 2] * g0
                f21 += xe[i, 2] * g1
                f22 += xe[i, 2] * g2
            lam = mat_par[mid, P_LAM]
            jac, n0, n1, n2, n3, n4, n5 = neo_hookean_stress(f00, f01, f02, f10, f11, f12,
                                                             f20, f21, f22, G, lam)
            if not (jac > 0.0):
                if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                    n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                    continue
                return dt_min, e, n_eroded, -1
            if dt > 0.0:
                s0, s1, s2, s3, s4, s5 = n0, n1, n2, n3, n4, n5
            csq = neo_hookean_modulus(jac, G, lam) / rho
        else:
            K = mat_par[mid, P_K]
            if dt > 0.0:
                if code == JOHNSON_COOK:
                    s0, s1, s2, s3, s4, s5, dgp, dT = johnson_cook_update(
                        o0, o1, o2, o3, o4, o5, d0, d1, d2, d3, d4, d5, wxy, wyz, wzx,
                        dt, eps_p[e], temp[e], rho, mat_par[mid])
                    eps_p[e] += dgp
                    temp[e] += dT
                    if dgp > 0.0:
                        kap = _return_factor(s0, s1, s2, s3, s4, s5, G, dgp)
                    elif hg_stiff[e]:   # (only the stiffness's fibre check, with the centre elastic, uses it)
                        sf2 = _flow_stress_sq(s0, s1, s2, s3, s4, s5, eps_p[e], temp[e], mat_par[mid])
                else:
                    s0, s1, s2, s3, s4, s5 = jaumann_rotation(o0, o1, o2, o3, o4, o5,
                                                              wxy, wyz, wzx, dt)
                    s0, s1, s2, s3, s4, s5 = elastic_increment(s0, s1, s2, s3, s4, s5, d0, d1,
                                                               d2, d3, d4, d5, dt, G, K)
            csq = (K + 4.0 / 3.0 * G) / rho
        if _is_bad(s0, s1, s2, s3, s4, s5):
            return dt_min, e, n_eroded, -1
        if dt > 0.0:
            pw = ((o0 + s0) * d0 + (o1 + s1) * d1 + (o2 + s2) * d2
                  + 2.0 * ((o3 + s3) * d3 + (o4 + s4) * d4 + (o5 + s5) * d5))
            e_int[e] += 0.5 * pw * vm * dt
            sig[e, 0] = s0
            sig[e, 1] = s1
            sig[e, 2] = s2
            sig[e, 3] = s3
            sig[e, 4] = s4
            sig[e, 5] = s5

        # bulk viscosity and stable step
        c = math.sqrt(csq)
        lc = vol / amax
        q = 0.0
        qq = 0.0
        if divv < 0.0:
            qq = q_lin * c - q_quad * lc * divv
            q = rho * lc * qq * (-divv)
        q_out[e] = q
        # the element's highest frequency (lumped mass rho V / 8): on a box of half widths a_k the
        # stretch modes v_I = (alpha xi_I, beta eta_I, gamma zeta_I) give
        # omega^2 = max eig D (lambda 1 1^T + 2 mu I) D / rho, D = diag(1 / a_k), bounded by
        # (2 mu / a_min^2 + lambda sum_k 1 / a_k^2) / rho = (8 mu / lc^2 + lambda 8 sum_I |b_I|^2 / V^2) / rho
        # (a cube: (3 lambda + 2 mu) / (rho a^2), LS-DYNA's lc / c alone takes (lambda + 2 mu): a free
        # cube or a column one element across rings at omega dt = 2.7 (nu = 0.3) to 3.5 (nu -> 1/2) and
        # diverges; in a bulky mesh the neighbours' phases keep it near lc / c). The effective length
        # lc_eff = 2 c / omega goes into LS-DYNA's formula with the bulk viscosity.
        sb = 0.0
        for i in range(8):
            sb += b[i, 0] * b[i, 0] + b[i, 1] * b[i, 1] + b[i, 2] * b[i, 2]
        ilc2 = 4.0 / (lc * lc)
        lam_r = max(csq - 2.0 * G / rho, 0.0)   # lambda / rho (the tangent's for neo-Hookean)
        lce = lc * math.sqrt(csq / (csq + lam_r * max(8.0 * sb / (vol * vol) - ilc2, 0.0) / ilc2))
        dte = lce / (qq + math.sqrt(qq * qq + csq))
        if dte < erode_dt[e]:  # crushed below the body's smallest allowed step: erodes (its work booked)
            n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
            continue
        if keep_dte:
            dte_out[e] = dte
        if dte < dt_min:
            dt_min = dte
            dt_at = e

        # stress divergence: f_I = -(sigma - q I) b_I
        p0 = s0 - q
        p1 = s1 - q
        p2 = s2 - q
        for i in range(8):
            bx = b[i, 0]
            by = b[i, 1]
            bz = b[i, 2]
            fe[i, 0] = -(p0 * bx + s3 * by + s5 * bz)
            fe[i, 1] = -(s3 * bx + p1 * by + s4 * bz)
            fe[i, 2] = -(s5 * bx + s4 * by + p2 * bz)

        if hg_stiff[e]:
            # assumed-strain hourglass stiffness (the bending the trilinear field holds; see
            # _hex_assumed_strain), its work into the element's internal energy
            if code == NEO_HOOKEAN:
                kb = mat_par[mid, P_LAM] + 2.0 / 3.0 * G
            else:
                kb = mat_par[mid, P_K]
            hsc[0] = s0
            hsc[1] = s1
            hsc[2] = s2
            hsc[3] = s3
            hsc[4] = s4
            hsc[5] = s5
            ah = hg_coef * rho * c * vol ** (2.0 / 3.0) * 0.25 * AS_VISCOUS_SHARE
            w = _hex_assumed_strain(xe, gradN0[e], dt, G, kb, kap, vol0[e], hgq[e], fe, hj, hev, hhm, hgr, hq, hfm, hmo,
                                    hcv, hsc, sf2, hfw, ah)
            e_int[e] += w
        # Flanagan-Belytschko viscous hourglass control
        elif hg_coef > 0.0:
            ah = hg_coef * rho * c * vol ** (2.0 / 3.0) * 0.25
            ivol = 1.0 / vol
            for a in range(4):
                hx = 0.0
                hy = 0.0
                hz = 0.0
                for i in range(8):
                    gam = HEX_HG[a, i]
                    hx += gam * xe[i, 0]
                    hy += gam * xe[i, 1]
                    hz += gam * xe[i, 2]
                hx *= ivol
                hy *= ivol
                hz *= ivol
                gx = 0.0
                gy = 0.0
                gz = 0.0
                for i in range(8):
                    gam = HEX_HG[a, i] - (hx * b[i, 0] + hy * b[i, 1] + hz * b[i, 2])
                    xm[i, 0] = gam  # reuse xm as storage for gamma
                    gx += gam * ve[i, 0]
                    gy += gam * ve[i, 1]
                    gz += gam * ve[i, 2]
                gx *= ah
                gy *= ah
                gz *= ah
                for i in range(8):
                    gam = xm[i, 0]
                    fe[i, 0] -= gam * gx
                    fe[i, 1] -= gam * gy
                    fe[i, 2] -= gam * gz

        for i in range(8):
            nd = conn[e, i]
            f[nd, 0] += fe[i, 0]
            f[nd, 1] += fe[i, 1]
            f[nd, 2] += fe[i, 2]
        r = cut_row[e]
        if r >= 0:  # an element at a partition cut: its corner forces for the ordered shared sums
            for i in range(8):
                fe_cut[r, i, 0] = fe[i, 0]
                fe_cut[r, i, 1] = fe[i, 1]
                fe_cut[r, i, 2] = fe[i, 2]
    return dt_min, -1, n_eroded, dt_at


@njit(cache=True)
def _forces_quad(x, v, dt, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig, eps_p,
                 temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut, alive, eps_eq, erode_at, erode_dt,
                 hg_stiff, hgq, dt_el, dte_out):
    ne = conn.shape[0]
    xe = np.empty((4, 2))
    ve = np.empty((4, 2))
    xm = np.empty((4, 2))
    gq = np.empty(4)   # the viscous control's hourglass vector
    fc = np.empty(6)   # the fibre check's element stress and hourglass stress (frame components)
    fd = np.empty(6)
    b = np.empty((4, 2))
    bm = np.empty((4, 2))
    fe = np.empty((4, 2))
    dt_min = np.inf
    dt_at = -1   # the element that sets dt_min (the step's limiter, named in the log)
    n_eroded = 0
    half_dt = 0.5 * dt
    per_element = dt_el.shape[0] > 0   # subcycling (subcycling.py): each element its own step
    keep_dte = dte_out.shape[0] > 0
    for e in range(ne):
        if alive[e] == 0:  # eroded: no force, no stable step (its nodes keep their mass)
            continue
        if per_element:
            dt = dt_el[e]
            # not evaluated at this substep: no force (its corner forces at a cut zeroed); written out in
            # both kernels: an inlined helper for it cost 4 % of a quad's element-cycle (bench lagrange)
            if dt < 0.0:
                r = cut_row[e]
                if r >= 0:
                    fe_cut[r, :, :] = 0.0
                continue
            half_dt = 0.5 * dt
        for i in range(4):
            nd = conn[e, i]
            for k in range(2):
                xe[i, k] = x[nd, k]
                ve[i, k] = v[nd, k]
        vol, dmax = quad_bvectors(xe, b)
        if not (vol > 0.0):
            if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                continue
            return dt_min, e, n_eroded, -1
        if dt > 0.0:
            for i in range(4):
                for k in range(2):
                    xm[i, k] = xe[i, k] - half_dt * ve[i, k]
            vm, _ = quad_bvectors(xm, bm)
            if not (vm > 0.0):
                if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                    n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                    continue
                return dt_min, e, n_eroded, -1
            bg = bm
        else:
            vm = vol
            bg = b
        l00 = 0.0
        l01 = 0.0
        l10 = 0.0
        l11 = 0.0
        for i in range(4):
            l00 += ve[i, 0] * bg[i, 0]
            l01 += ve[i, 0] * bg[i, 1]
            l10 += ve[i, 1] * bg[i, 0]
            l11 += ve[i, 1] * bg[i, 1]
        ivm = 1.0 / vm
        d0 = l00 * ivm
        d1 = l11 * ivm
        d3 = 0.5 * (l01 + l10) * ivm
        wxy = 0.5 * (l01 - l10) * ivm
        divv = d0 + d1
        if erode_at[e] < np.inf and dt > 0.0:
            # the effective strain as in _forces_hex, in plane strain (d_zz = 0)
            t = divv / 3.0
            eps_eq[e] += dt * math.sqrt(2.0 / 3.0 * ((d0 - t) ** 2 + (d1 - t) ** 2 + t * t + 2.0 * d3 * d3))
            if eps_eq[e] >= erode_at[e]:
                n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                continue

        mid = mat_id[e]
        code = mat_code[mid]
        rho = mass_e[e] / vol
        o0 = sig[e, 0]
        o1 = sig[e, 1]
        o2 = sig[e, 2]
        o3 = sig[e, 3]
        o4 = sig[e, 4]
        o5 = sig[e, 5]
        s0, s1, s2, s3, s4, s5 = o0, o1, o2, o3, o4, o5
        G = mat_par[mid, P_G]
        kap = 1.0   # the radial return's factor this step (1: elastic), applied to hourglass stresses
        sf2 = np.inf   # the flow stress squared (plastic materials): the hourglass stiffness's fibre check
        if code == NEO_HOOKEAN:
            f00 = 0.0
            f01 = 0.0
            f10 = 0.0
            f11 = 0.0
            for i in range(4):
                g0 = gradN0[e, i, 0]
                g1 = gradN0[e, i, 1]
                f00 += xe[i, 0] * g0
                f01 += xe[i, 0] * g1
                f10 += xe[i, 1] * g0
                f11 += xe[i, 1] * g1
            lam = mat_par[mid, P_LAM]
            jac, n0, n1, n2, n3, n4, n5 = neo_hookean_stress(f00, f01, 0.0, f10, f11, 0.0,
                                                             0.0, 0.0, 1.0, G, lam)
            if not (jac > 0.0):
                if erode_at[e] < np.inf:  # erosion on: an element that would invert erodes
                    n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
                    continue
                return dt_min, e, n_eroded, -1
            if dt > 0.0:
                s0, s1, s2, s3, s4, s5 = n0, n1, n2, n3, n4, n5
            csq = neo_hookean_modulus(jac, G, lam) / rho
        else:
            K = mat_par[mid, P_K]
            if dt > 0.0:
                if code == JOHNSON_COOK:
                    s0, s1, s2, s3, s4, s5, dgp, dT = johnson_cook_update(
                        o0, o1, o2, o3, o4, o5, d0, d1, 0.0, d3, 0.0, 0.0, wxy, 0.0, 0.0,
                        dt, eps_p[e], temp[e], rho, mat_par[mid])
                    eps_p[e] += dgp
                    temp[e] += dT
                    if dgp > 0.0:
                        kap = _return_factor(s0, s1, s2, s3, s4, s5, G, dgp)
                    elif hg_stiff[e]:   # (only the stiffness's fibre check, with the centre elastic, uses it)
                        sf2 = _flow_stress_sq(s0, s1, s2, s3, s4, s5, eps_p[e], temp[e], mat_par[mid])
                else:
                    s0, s1, s2, s3, s4, s5 = jaumann_rotation(o0, o1, o2, o3, o4, o5,
                                                              wxy, 0.0, 0.0, dt)
                    s0, s1, s2, s3, s4, s5 = elastic_increment(s0, s1, s2, s3, s4, s5, d0, d1,
                                                               0.0, d3, 0.0, 0.0, dt, G, K)
            csq = (K + 4.0 / 3.0 * G) / rho
        if _is_bad(s0, s1, s2, s3, s4, s5):
            return dt_min, e, n_eroded, -1
        if dt > 0.0:
            pw = (o0 + s0) * d0 + (o1 + s1) * d1 + 2.0 * (o3 + s3) * d3
            e_int[e] += 0.5 * pw * vm * dt
            sig[e, 0] = s0
            sig[e, 1] = s1
            sig[e, 2] = s2
            sig[e, 3] = s3
            sig[e, 4] = s4
            sig[e, 5] = s5

        c = math.sqrt(csq)
        lc = vol / dmax
        q = 0.0
        qq = 0.0
        if divv < 0.0:
            qq = q_lin * c - q_quad * lc * divv
            q = rho * lc * qq * (-divv)
        q_out[e] = q
        dte = lc / (qq + math.sqrt(qq * qq + csq))
        if dte < erode_dt[e]:  # crushed below the body's smallest allowed step: erodes (its work booked)
            n_eroded += _erode(e, alive, q_out, cut_row, fe_cut)
            continue
        if keep_dte:
            dte_out[e] = dte
        if dte < dt_min:
            dt_min = dte
            dt_at = e

        p0 = s0 - q
        p1 = s1 - q
        for i in range(4):
            bx = b[i, 0]
            by = b[i, 1]
            fe[i, 0] = -(p0 * bx + s3 * by)
            fe[i, 1] = -(s3 * bx + p1 * by)

        if hg_stiff[e]:
            # assumed-strain hourglass stiffness (Belytschko & Bindeman 1991, ASQBI), a potential as the
            # hexahedron's (_hex_assumed_strain): the hourglass deformation H = sum_I gamma0_I x_I =
            # sum_I h_I x_I - F hX0 (zero on every affine map of the reference), its components in the
            # co-rotational frame (e1 along the mean xi edge m, e2 normal to it) less the plastic
            # offset, h_k = e_k . H - hp_k, carry the stiffness of the bending strain the bilinear
            # field holds with the transverse stress relaxed (E' = 2 mu (1 + nu / (1 - nu)) in plane
            # strain: no volumetric locking): K_1 = E' b / (12 a), K_2 = E' a / (12 b) (reference half
            # widths a, b), Q_k = K_k h_k, E_h = 1/2 Q . h; forces the exact gradient (the frame's
            # share -T s_I e2 / |m|, T = sum_k Q_k (e_k x H)_z: torque free, conservative); a step
            # that yields scales h by the radial return's factor (hp takes the rest). hgq[e]: [0:2]
            # hX0, [2:4] 4a, 4b, [4:6] hp, [6:8] the frame components of the step before (damping), [8] E_h,
            # [9] the work so far (also in e_int)
            e10, e11, lm = _quad_frame(xe)
            if code == NEO_HOOKEAN:
                kb = mat_par[mid, P_LAM] + 2.0 / 3.0 * G
            else:
                kb = mat_par[mid, P_K]
            ep = 4.0 * G * (3.0 * kb + G) / (3.0 * kb + 4.0 * G)
            # (gamma = h, the +-1 pattern, on a rectangle: h = 4 c for the mode u = c xi eta, whose
            # bending energy is 2/3 E' (b / a) c^2 per unit thickness)
            k1 = ep * hgq[e, 3] / (12.0 * hgq[e, 2])
            k2 = ep * hgq[e, 2] / (12.0 * hgq[e, 3])
            f00 = 0.0
            f01 = 0.0
            f10 = 0.0
            f11 = 0.0
            hx = 0.0
            hy = 0.0
            for i in range(4):
                f00 += xe[i, 0] * gradN0[e, i, 0]
                f01 += xe[i, 0] * gradN0[e, i, 1]
                f10 += xe[i, 1] * gradN0[e, i, 0]
                f11 += xe[i, 1] * gradN0[e, i, 1]
                hx += QUAD_HG[i] * xe[i, 0]
                hy += QUAD_HG[i] * xe[i, 1]
            hx -= f00 * hgq[e, 0] + f01 * hgq[e, 1]
            hy -= f10 * hgq[e, 0] + f11 * hgq[e, 1]
            h1 = e10 * hx + e11 * hy - hgq[e, 4]
            h2 = -e11 * hx + e10 * hy - hgq[e, 5]
            q1 = k1 * h1
            q2 = k2 * h2
            en = 0.5 * (q1 * h1 + q2 * h2)
            if dt > 0.0:
                w = en - hgq[e, 8]
                kk = kap
                if sf2 < np.inf and kap == 1.0 and _may_yield_2d(h1, h2, ep, hgq[e, 2], hgq[e, 3], kb, G, s0, s1,
                                                                 s2, s3, sf2):
                    # the fibre check while the centre is elastic (as the hexahedron's): the element's
                    # stress in the frame plus the hourglass stress at the 2 x 2 Gauss points,
                    # d_11 = E' h_1 eta / (4a), d_22 = E' h_2 xi / (4b), d_33 = nu (d_11 + d_22) (plane
                    # strain, the transverse stress relaxed)
                    fc[0] = e10 * e10 * s0 + 2.0 * e10 * e11 * s3 + e11 * e11 * s1
                    fc[1] = e11 * e11 * s0 - 2.0 * e10 * e11 * s3 + e10 * e10 * s1
                    fc[2] = s2
                    fc[3] = e10 * e11 * (s1 - s0) + (e10 * e10 - e11 * e11) * s3
                    fc[4] = 0.0
                    fc[5] = 0.0
                    fd[3] = 0.0
                    fd[4] = 0.0
                    fd[5] = 0.0
                    nu = (3.0 * kb - 2.0 * G) / (2.0 * (3.0 * kb + G))
                    b1 = ep * h1 / hgq[e, 2]
                    b2 = ep * h2 / hgq[e, 3]
                    for gp in range(4):
                        fd[0] = b1 * (_GAUSS if gp & 2 else -_GAUSS)
                        fd[1] = b2 * (_GAUSS if gp & 1 else -_GAUSS)
                        fd[2] = nu * (fd[0] + fd[1])
                        kk = _fibre_factor(fc, fd, sf2, kk)
                if kk < 1.0:
                    hgq[e, 4] += (1.0 - kk) * h1
                    hgq[e, 5] += (1.0 - kk) * h2
                    q1 *= kk
                    q2 *= kk
                    en *= kk * kk
                hgq[e, 8] = en
                hgq[e, 9] += w
                e_int[e] += w
                # damping (as the hexahedron's): the frame components' rate over the step
                if hg_coef > 0.0:
                    ih = hg_coef * rho * c * math.sqrt(vol) * 0.25 * AS_VISCOUS_SHARE * _damping_share(kk) / dt
                    r1 = hgq[e, 4] + kk * h1
                    r2 = hgq[e, 5] + kk * h2
                    q1 += ih * (r1 - hgq[e, 6])
                    q2 += ih * (r2 - hgq[e, 7])
                    hgq[e, 6] = r1
                    hgq[e, 7] = r2
            # T = Q_1 (e1 x H)_z + Q_2 (e2 x H)_z, e2 = (-e11, e10)
            tz = q1 * (e10 * hy - e11 * hx) + q2 * (-e11 * hy - e10 * hx)
            px = q1 * e10 - q2 * e11
            py = q1 * e11 + q2 * e10
            rx = -tz * (-e11) / lm
            ry = -tz * e10 / lm
            for i in range(4):
                gm = QUAD_HG[i] - (hgq[e, 0] * gradN0[e, i, 0] + hgq[e, 1] * gradN0[e, i, 1])
                si = _QUAD_EDGE[i]
                fe[i, 0] -= gm * px - si * rx
                fe[i, 1] -= gm * py - si * ry
        elif hg_coef > 0.0:
            quad_viscous_hourglass(xe, ve, b, vol, hg_coef * rho * c * math.sqrt(vol) * 0.25, gq, fe)

        for i in range(4):
            nd = conn[e, i]
            f[nd, 0] += fe[i, 0]
            f[nd, 1] += fe[i, 1]
        r = cut_row[e]
        if r >= 0:  # an element at a partition cut: its corner forces for the ordered shared sums
            for i in range(4):
                fe_cut[r, i, 0] = fe[i, 0]
                fe_cut[r, i, 1] = fe[i, 1]
    return dt_min, -1, n_eroded, dt_at


@njit(cache=True)
def element_forces_cut(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig,
                       eps_p, temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut,
                       alive, eps_eq, erode_at, erode_dt, hg_stiff, hgq):
    """Stress update n-1 -> n, internal + hourglass forces at x^n, stable step.

    Parameters
    ----------
    x : (nn, dim) positions at t^n;  v : (nn, dim) velocities at t^{n-1/2}
    dt_prev : dt^{n-1/2}; 0 means no stress update (forces from the current stress)
    conn : (ne, 4 | 8) int64 node ids (VTK order, positively oriented)
    mat_id : (ne,) int64 ; mat_code : (nmat,) int64 ; mat_par : (nmat, NPAR)
    gradN0 : (ne, nen, dim) reference uniform gradients (neo-Hookean F);
    vol0 : (ne,) reference volumes (unused by the kernel, kept for the API)
    mass_e : (ne,) element masses (current density = mass_e / V)
    sig (ne, 6), eps_p, temp, e_int, q_out (ne,) : state, updated in place
    hg_coef, q_lin, q_quad : hourglass and bulk-viscosity coefficients
    f : (nn, dim) nodal forces, internal contributions are ADDED (M a = f)
    cut_row : (ne,) int64 row of fe_cut for an element at a partition cut, -1 elsewhere;
    fe_cut : (ncut, nen, dim) the corner forces of those elements (written): the solver sums them
    into its shared nodes in global element order, so any partition gives the one-rank bits
    alive : (ne,) uint8, 0 for an eroded element (skipped; updated in place)
    eps_eq : (ne,) the effective strain integrated so far (updated where erosion is on)
    erode_at : (ne,) the effective strain at which the element erodes, inf without erosion; with
    erosion on, an element that would invert (volume or J) erodes instead of stopping the run
    erode_dt : (ne,) the stable step below which the element erodes (LS-DYNA's TSMIN with ERODE = 1:
    a crushed element would stop the run by its step long before it inverts), 0 for none
    hg_stiff : (ne,) uint8, 1 for an element with the assumed-strain hourglass stiffness instead
    of the viscous control; hgq : (ne, 10 | 41) its state (assumed_strain_reference fills the
    reference part: sum_I h_I X_I and the widths; then the plastic offsets, the hourglass energy
    and, last, the hourglass work so far, also in e_int), updated in place

    Returns ``(dt_min, bad, eroded, dt_at)``: the smallest stable step of the live elements, the first
    element with non-positive volume (at x^n or at the mid-step configuration), non-positive
    neo-Hookean J or non-finite stress (-1 if none), the number of elements eroded in this call,
    and the element whose stable step is dt_min (-1 if none: the step's limiter the log names).
    On ``bad >= 0`` the call returns immediately (state and f are partially updated).
    """
    none = np.empty(0)   # (one step for every element: no per-element steps)
    return element_forces_levels(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig,
                                 eps_p, temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut,
                                 alive, eps_eq, erode_at, erode_dt, hg_stiff, hgq, none, none)


@njit(cache=True)
def element_forces_levels(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig,
                          eps_p, temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut,
                          alive, eps_eq, erode_at, erode_dt, hg_stiff, hgq, dt_el, dte_out):
    """element_forces_cut with each element's own step (subcycling.py): dt_el (ne,) the time since
    the element's last evaluation (0: none yet, no stress update), negative for an element not
    evaluated now (no force, its state untouched); dte_out (ne,): each evaluated element's stable
    step (written).  Empty dt_el, dte_out: dt_prev for every element, element_forces_cut."""
    if x.shape[1] == 3:
        return _forces_hex(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig, eps_p,
                           temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut, alive, eps_eq, erode_at,
                           erode_dt, hg_stiff, hgq, dt_el, dte_out)
    return _forces_quad(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig, eps_p,
                        temp, e_int, q_out, hg_coef, q_lin, q_quad, f, cut_row, fe_cut, alive, eps_eq, erode_at,
                        erode_dt, hg_stiff, hgq, dt_el, dte_out)


@njit(cache=True)
def element_forces(x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig,
                   eps_p, temp, e_int, q_out, hg_coef, q_lin, q_quad, f):
    """element_forces_cut without partition cuts or erosion (one rank, kernel tests): (dt_min, bad)."""
    ne = conn.shape[0]
    dt_min, bad, _, _ = element_forces_cut(
        x, v, dt_prev, conn, mat_id, mat_code, mat_par, gradN0, vol0, mass_e, sig, eps_p, temp, e_int, q_out,
        hg_coef, q_lin, q_quad, f, np.full(ne, -1, np.int64), np.zeros((0, conn.shape[1], x.shape[1])),
        np.ones(ne, np.uint8), np.zeros(ne), np.full(ne, np.inf), np.zeros(ne), np.zeros(ne, np.uint8),
        np.zeros((ne, 3)))
    return dt_min, bad


def _flush_stale_cache() -> None:
    """The constitutive functions of materials.py and the geometry of solvers/elements.py are
    compiled into these kernels (see solvers.numba_cache): drop the cache when either changed."""
    flush_stale_cache([reference_gradients, _is_bad, _erode, _return_factor, _damping_share, _flow_stress_sq, _vm_dot,
                       _fibre_factor, _may_yield_3d, _may_yield_2d, _in_frame, _hex_moments, _hex_spread, _frame_of,
                       _quad_frame, assumed_strain_reference, _hex_assumed_strain, _forces_hex, _forces_quad,
                       element_forces_cut, element_forces_levels, element_forces],
                      [_materials.__file__, _elements.__file__], "kernels.deps.sha256")


_flush_stale_cache()
