"""Lagrange-step kernels of the ALE background solver (staggered grid, 2D quads and 3D hexahedra).

Discretisation (one zone z with corners c, lumped nodal masses m_n, zone mass M_z)
----------------------------------------------------------------------------------
* Geometry: ``b_c = dV/dx_c`` of the trilinear hexahedron / bilinear quadrilateral
  (``hex_bvectors`` / ``quad_bvectors`` of solvers/elements.py, shared with the FE solver) and
  the exact zone volume, in 3D ``V = 1/3 sum_c (x_c - x_0) . b_c`` summed per component and
  then permutation-invariantly (:func:`hex_volume_sym`) so that boxes give the same bits whichever
  axis is which.
* Corner force (force ON node c from zone z)::

      f_zc = (p + q) b_c + f_hg,c

  with the Flanagan-Belytschko viscous hourglass force of the FE solver: base vectors Gamma_a
  (hex: eta zeta, zeta xi, xi eta, xi eta zeta; quad: xi eta), ``gamma_a = Gamma_a - (Gamma_a .
  (x_i - x_0)) b_i / V`` (orthogonal to every linear velocity field), ``g_a = sum_c gamma_ac v_c`` and
  ``f_hg,c = -a_h sum_a gamma_ac g_a``, ``a_h = C_hg rho c V^(2/3) / 4`` (3D) or
  ``C_hg rho c A^(1/2) / 4`` (2D, per unit thickness).
* Nodal force: gathered, never scattered: ``f_n = sum_{zones around n} f_zc`` in a fixed
  (balanced-tree) order over the active zones (real, periodic images and open-boundary ghosts;
  zones beyond a wall do not act).  The same order on every rank makes a decomposed run bitwise
  equal to a single-rank one.
* Artificial viscosity (scalar, bulk, compression only)::

      q = rho (C_q l^2 (div v)^2 + C_l l c |div v|)      if div v < 0, else 0

  with, in the Lagrange step, ``div v = (V^{n+1} - V^n) / (dt (V^{n+1} + V^n)/2)`` (the volume
  change of the step, equal to ``sum_c v_c . b_c(x^{n+1/2}) / V`` at the mid-step geometry
  exactly in 2D and to O(dt^2) in 3D), or ``sum_c v_c . b_c / V`` on the fixed grid after a
  remap; the length is ``l = V / (largest face area)`` (3D) or ``A / (longest edge)`` (2D): the
  smallest zone width for a box, identical in 2D and 3D.
* Artificial viscosity (monotonic, ``viscosity.kind = "monotonic"``; Christensen 1990, the form of
  ALE3D/LULESH): per logical direction d of the zone (xi, eta[, zeta]) the axis ``m_d`` (mean of
  the corners of the d+ face minus mean of the d- face), the same difference ``dv_d`` of the
  corner velocities, the area vector of the d-mid-surface ``A_d`` (3D: ``m_e x m_f``, (d, e, f)
  cyclic; 2D: ``m_eta`` turned by -90 degrees for xi, ``m_xi`` by +90 for eta) and the central
  Jacobian ``J_d = m_d . A_d`` give the directional strain rate and width::

      D_d = dv_d . A_d / J_d        (sum_d D_d = div v of the zone-centre velocity gradient)
      h_d = J_d / |A_d|             (D_d h_d = dv_d . A_d / |A_d|: the normal velocity jump)

  (:func:`mono_gradients_3d` / ``_2d``, a pre-pass over every zone of the padded block: the
  neighbours of the real zones and of the open-boundary ghosts come from the ghost nodes, i.e.
  mirrored at walls, images at periodic faces, the neighbour's nodes at rank cuts (so N ranks
  compute the one-rank bits); at the mid-step geometry
  ``x - dt/2 v`` in the Lagrange step, on the fixed grid after a remap).  With the ratios of the
  neighbours along d, ``r_- = D_d(z - e_d) / D_d(z)``, ``r_+ = D_d(z + e_d) / D_d(z)``, the limiter
  and the jump are::

      phi_d = max(0, min((r_- + r_+)/2, 2 r_-, 2 r_+, 1)),     du_d = -D_d h_d > 0
      q = rho sum_d [C_l c (1 - phi_d) du_d + C_q (1 - phi_d^2) du_d^2]   over the d with D_d < 0

  and q = 0 unless ``div v < 0`` (the same divergence as the scalar q, so that the work
  ``-q dV`` of the step is never negative).  A linear velocity field on a uniform grid has equal
  ratios 1: phi = 1 and q = 0 (homologous compression, no q); a 1-D shock on a box grid has
  phi = 0 in its zones and gets the scalar q (``du = l |div v|`` when the zone width along the
  shock is the smallest one).  A zone with ``J_d <= 0`` (only a distorted ghost) counts as
  ``D_d = 0``: its neighbour has ``phi = 0``, the full q.
* Compatible energy: with the central-difference step ``v^{n+1/2} = v^{n-1/2} + dt_avg f^n / m``
  the kinetic energy changes by ``sum_n dt_avg f^n . vbar_n`` exactly, ``vbar = (v^{n-1/2} +
  v^{n+1/2}) / 2``.  Each zone therefore changes its internal energy by minus the work of its own
  corner forces on the mean velocities of its corners::

      M_z (e^+ - e^-) = - dt_avg sum_c f_zc^n . vbar_c

  so kinetic + internal energy is conserved to round-off (walls do no work: vbar_normal = 0).
  The conserved ``e`` lags the positions by half a step (it holds the work up to
  t^{n+1/2}); the EOS is evaluated at the half-step extrapolation
  ``e_eos = e + de_h`` with ``de_h = -(p^n + q^n) (V^{n+1} - V^n) / (2 M)``, which keeps the
  pressure second-order in time without touching the conserved energy.
* Stable step: ``dt_z = l / (u + Q + sqrt(Q^2 + c^2))`` with ``Q = C_l c + C_q l |div v|`` in
  compression (0 otherwise) and ``u`` the largest corner speed in Eulerian mode (advection
  Courant number of the remap), 0 in Lagrangian mode.  Monotonic q: Q is that of the q actually
  applied, per unit jump and the largest over the directions, ``Q = max_d q_d / (rho du_d) =
  max_d [C_l c (1 - phi_d) + C_q (1 - phi_d^2) du_d]`` (the scalar Q for a 1-D shock, phi = 0).

Corner sums use balanced trees ``((c0 + c1) + (c3 + c2)) + ((c4 + c5) + (c7 + c6))`` (pairs along
x first), so a flow along x, y or z on a box grid sums the same numbers in the same order.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers.ale import eos as _eos
from solvers import elements as _elements
from solvers.elements import hex_bvectors, quad_bvectors, quad_viscous_hourglass

# zone-pass flags
ENERGY = 1     # compatible energy update from the stored corner forces (real zones only)
EOS = 2        # rho = M / V, EOS at e + de_h
FORCES = 4     # kinematics, q, hourglass, corner forces, stable step
MIDSTEP = 8    # div v from the volume change over the step (Lagrange step); else sum v.b/V at x
ADVECT = 16    # add the corner speed to the Courant condition (Eulerian mode)

# artificial viscosity kinds (zone pass argument qkind)
Q_SCALAR = 0
Q_MONOTONIC = 1
Q_KINDS = {"scalar": Q_SCALAR, "monotonic": Q_MONOTONIC}

# failure reasons of a zone pass
BAD_VOLUME = 1
BAD_STATE = 3


@njit(cache=True, inline="always")
def _t8(a0, a1, a2, a3, a4, a5, a6, a7):
    return ((a0 + a1) + (a3 + a2)) + ((a4 + a5) + (a7 + a6))


@njit(cache=True, inline="always")
def _t4(a0, a1, a2, a3):
    return (a0 + a1) + (a3 + a2)


@njit(cache=True, inline="always")
def zones_around_node_3d(i, j, k, zs):
    """The 8 zones around node (i, j, k): zone (i - 1, j - 1, k - 1) + o for the hexahedron corner
    offsets o in VTK order (000, 100, 110, 010, 001, 101, 111, 011); the node is the opposite
    corner (6, 7, 4, 5, 2, 3, 0, 1) of each."""
    z0 = (i - 1) * zs[0] + (j - 1) * zs[1] + (k - 1) * zs[2]
    z1 = z0 + zs[0]
    z3 = z0 + zs[1]
    z2 = z3 + zs[0]
    return z0, z1, z2, z3, z0 + zs[2], z1 + zs[2], z2 + zs[2], z3 + zs[2]


@njit(cache=True, inline="always")
def zones_around_node_2d(i, j, zs):
    """2D version of :func:`zones_around_node_3d`: offsets (00, 10, 11, 01), the node is the
    corner (2, 3, 0, 1) of each."""
    z0 = (i - 1) * zs[0] + (j - 1) * zs[1]
    z1 = z0 + zs[0]
    z3 = z0 + zs[1]
    return z0, z1, z3 + zs[0], z3


@njit(cache=True, inline="always")
def _sym3(a, b, c):
    """a + b + c summed smallest-first: invariant under any permutation of the arguments."""
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return (a + b) + c


@njit(cache=True, inline="always")
def _vcomp(xe, b, d):
    x0 = xe[0, d]
    return _t8(0.0, (xe[1, d] - x0) * b[1, d], (xe[2, d] - x0) * b[2, d], (xe[3, d] - x0) * b[3, d],
               (xe[4, d] - x0) * b[4, d], (xe[5, d] - x0) * b[5, d], (xe[6, d] - x0) * b[6, d],
               (xe[7, d] - x0) * b[7, d])


@njit(cache=True)
def hex_volume_sym(xe, b):
    """Volume ``1/3 sum_I (x_I - x_0) . b_I`` of a hexahedron from its b-vectors, per component
    with balanced-tree corner sums and a permutation-invariant sum of the three components (so a
    box gives the same bits whichever axis is which)."""
    return _sym3(_vcomp(xe, b, 0), _vcomp(xe, b, 1), _vcomp(xe, b, 2)) / 3.0



@njit(cache=True, inline="always")
def _hproj(g1, g2, g3, g4, g5, g6, g7, xe, d):
    x0 = xe[0, d]
    return _t8(0.0, g1 * (xe[1, d] - x0), g2 * (xe[2, d] - x0), g3 * (xe[3, d] - x0),
               g4 * (xe[4, d] - x0), g5 * (xe[5, d] - x0), g6 * (xe[6, d] - x0), g7 * (xe[7, d] - x0))


@njit(cache=True, inline="always")
def _hg_mode(g0, g1, g2, g3, g4, g5, g6, g7, xe, b, ve, ivol, ah, fc, z):
    """One FB hourglass mode of a hexahedron (signs g = Gamma as literals, folded after inlining):
    gamma = Gamma - (Gamma . x) b / V (coordinates relative to corner 0), f -= a_h gamma (gamma . v)."""
    hx = _hproj(g1, g2, g3, g4, g5, g6, g7, xe, 0) * ivol
    hy = _hproj(g1, g2, g3, g4, g5, g6, g7, xe, 1) * ivol
    hz = _hproj(g1, g2, g3, g4, g5, g6, g7, xe, 2) * ivol
    c0 = g0 - (hx * b[0, 0] + hy * b[0, 1] + hz * b[0, 2])
    c1 = g1 - (hx * b[1, 0] + hy * b[1, 1] + hz * b[1, 2])
    c2 = g2 - (hx * b[2, 0] + hy * b[2, 1] + hz * b[2, 2])
    c3 = g3 - (hx * b[3, 0] + hy * b[3, 1] + hz * b[3, 2])
    c4 = g4 - (hx * b[4, 0] + hy * b[4, 1] + hz * b[4, 2])
    c5 = g5 - (hx * b[5, 0] + hy * b[5, 1] + hz * b[5, 2])
    c6 = g6 - (hx * b[6, 0] + hy * b[6, 1] + hz * b[6, 2])
    c7 = g7 - (hx * b[7, 0] + hy * b[7, 1] + hz * b[7, 2])
    for d in range(3):
        g = ah * _t8(c0 * ve[0, d], c1 * ve[1, d], c2 * ve[2, d], c3 * ve[3, d],
                     c4 * ve[4, d], c5 * ve[5, d], c6 * ve[6, d], c7 * ve[7, d])
        fc[z, 0, d] -= c0 * g
        fc[z, 1, d] -= c1 * g
        fc[z, 2, d] -= c2 * g
        fc[z, 3, d] -= c3 * g
        fc[z, 4, d] -= c4 * g
        fc[z, 5, d] -= c5 * g
        fc[z, 6, d] -= c6 * g
        fc[z, 7, d] -= c7 * g


# ------------------------------------------------------------------------------------------------
# monotonic artificial viscosity: directional strain rates (pre-pass) and the limited q
# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def mono_gradients_3d(x, v, grad, shift, zlo, zhi, zs, ns):
    """Pre-pass of the monotonic q: per zone ``zlo <= (i, j, k) < zhi`` and logical direction d
    (xi, eta, zeta) the strain rate ``grad[z, d] = dv_d . A_d / J_d`` and the width
    ``grad[z, 3 + d] = J_d / |A_d|`` at the positions ``x - shift v`` (the mid-step geometry of
    the Lagrange step: shift = dt/2; 0 on the fixed grid).  ``m_d`` = the zone's logical axis
    (mean of the d+ face corners minus mean of the d- face corners), ``dv_d`` the same of the
    velocities, ``A_d`` = the cross product of the other two axes in cyclic order (the area
    vector of the zone's d-mid-surface) and ``J_d = m_d . A_d`` (the central Jacobian).  A zone
    with ``J_d <= 0`` (a degenerate ghost) gets 0 (as a neighbour: full q)."""
    co = np.empty(8, np.int64)
    for a in range(8):
        ox = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oy = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oz = 1 if a >= 4 else 0
        co[a] = ox * ns[0] + oy * ns[1] + oz * ns[2]
    xe = np.empty((8, 3))
    ve = np.empty((8, 3))
    m = np.empty((3, 3))    # m[d] logical axis d
    dv = np.empty((3, 3))   # dv[d] velocity difference along d
    A = np.empty((3, 3))    # A[d] area vector of the d-mid-surface
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                for a in range(8):
                    nd = n0 + co[a]
                    for c in range(3):
                        ve[a, c] = v[nd, c]
                        xe[a, c] = x[nd, c] - shift * v[nd, c] if shift != 0.0 else x[nd, c]
                for c in range(3):
                    m[0, c] = 0.25 * (((xe[1, c] + xe[2, c]) + (xe[5, c] + xe[6, c]))
                                      - ((xe[0, c] + xe[3, c]) + (xe[4, c] + xe[7, c])))
                    m[1, c] = 0.25 * (((xe[3, c] + xe[2, c]) + (xe[7, c] + xe[6, c]))
                                      - ((xe[0, c] + xe[1, c]) + (xe[4, c] + xe[5, c])))
                    m[2, c] = 0.25 * (((xe[4, c] + xe[5, c]) + (xe[7, c] + xe[6, c]))
                                      - ((xe[0, c] + xe[1, c]) + (xe[3, c] + xe[2, c])))
                    dv[0, c] = 0.25 * (((ve[1, c] + ve[2, c]) + (ve[5, c] + ve[6, c]))
                                       - ((ve[0, c] + ve[3, c]) + (ve[4, c] + ve[7, c])))
                    dv[1, c] = 0.25 * (((ve[3, c] + ve[2, c]) + (ve[7, c] + ve[6, c]))
                                       - ((ve[0, c] + ve[1, c]) + (ve[4, c] + ve[5, c])))
                    dv[2, c] = 0.25 * (((ve[4, c] + ve[5, c]) + (ve[7, c] + ve[6, c]))
                                       - ((ve[0, c] + ve[1, c]) + (ve[3, c] + ve[2, c])))
                for d in range(3):
                    e = (d + 1) % 3
                    f = (d + 2) % 3
                    A[d, 0] = m[e, 1] * m[f, 2] - m[e, 2] * m[f, 1]
                    A[d, 1] = m[e, 2] * m[f, 0] - m[e, 0] * m[f, 2]
                    A[d, 2] = m[e, 0] * m[f, 1] - m[e, 1] * m[f, 0]
                for d in range(3):
                    jd = (m[d, 0] * A[d, 0] + m[d, 1] * A[d, 1]) + m[d, 2] * A[d, 2]
                    a2 = (A[d, 0] * A[d, 0] + A[d, 1] * A[d, 1]) + A[d, 2] * A[d, 2]
                    if jd > 0.0 and a2 > 0.0 and jd < np.inf:
                        grad[z, d] = ((dv[d, 0] * A[d, 0] + dv[d, 1] * A[d, 1]) + dv[d, 2] * A[d, 2]) / jd
                        grad[z, 3 + d] = jd / math.sqrt(a2)
                    else:
                        grad[z, d] = 0.0
                        grad[z, 3 + d] = 0.0


@njit(cache=True)
def mono_gradients_2d(x, v, grad, shift, zlo, zhi, zs, ns):
    """2D version of :func:`mono_gradients_3d` (``grad[z, d]``, ``grad[z, 2 + d]``; the area vector
    of the xi-mid-line is the eta axis turned by -90 degrees, that of the eta-mid-line the xi axis
    turned by +90 degrees)."""
    co = np.empty(4, np.int64)
    co[0] = 0
    co[1] = ns[0]
    co[2] = ns[0] + ns[1]
    co[3] = ns[1]
    xe = np.empty((4, 2))
    ve = np.empty((4, 2))
    m = np.empty((2, 2))
    dv = np.empty((2, 2))
    A = np.empty((2, 2))
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            z = i * zs[0] + j * zs[1]
            n0 = i * ns[0] + j * ns[1]
            for a in range(4):
                nd = n0 + co[a]
                for c in range(2):
                    ve[a, c] = v[nd, c]
                    xe[a, c] = x[nd, c] - shift * v[nd, c] if shift != 0.0 else x[nd, c]
            for c in range(2):
                m[0, c] = 0.5 * ((xe[1, c] + xe[2, c]) - (xe[0, c] + xe[3, c]))
                m[1, c] = 0.5 * ((xe[3, c] + xe[2, c]) - (xe[0, c] + xe[1, c]))
                dv[0, c] = 0.5 * ((ve[1, c] + ve[2, c]) - (ve[0, c] + ve[3, c]))
                dv[1, c] = 0.5 * ((ve[3, c] + ve[2, c]) - (ve[0, c] + ve[1, c]))
            A[0, 0] = m[1, 1]
            A[0, 1] = -m[1, 0]
            A[1, 0] = -m[0, 1]
            A[1, 1] = m[0, 0]
            for d in range(2):
                jd = m[d, 0] * A[d, 0] + m[d, 1] * A[d, 1]
                a2 = A[d, 0] * A[d, 0] + A[d, 1] * A[d, 1]
                if jd > 0.0 and a2 > 0.0 and jd < np.inf:
                    grad[z, d] = (dv[d, 0] * A[d, 0] + dv[d, 1] * A[d, 1]) / jd
                    grad[z, 2 + d] = jd / math.sqrt(a2)
                else:
                    grad[z, d] = 0.0
                    grad[z, 2 + d] = 0.0


@njit(cache=True, inline="always")
def _mono_q(grad, z, zs, ndir, r, cz, q_lin, q_quad, solid):
    """Monotonic q of zone z (in compression) and its viscous speed Q (see the module docstring):
    returns ``(q, Q)``.  ``solid``: None, or per zone nonzero for a fully blocked zone (obstacles,
    blocked.py): such a neighbour is a wall ghost, the zone's mirror image (its own strain rate,
    as the ghost zone of a conforming wall)."""
    s = 0.0
    qmax = 0.0
    for d in range(ndir):
        g = grad[z, d]
        if g < 0.0:
            inv = 1.0 / g
            gm = grad[z - zs[d], d]
            gp = grad[z + zs[d], d]
            if solid is not None:
                if solid[z - zs[d]]:
                    gm = g
                if solid[z + zs[d]]:
                    gp = g
            rm = gm * inv
            rp = gp * inv
            phi = 0.5 * (rm + rp)
            if 2.0 * rm < phi:
                phi = 2.0 * rm
            if 2.0 * rp < phi:
                phi = 2.0 * rp
            if phi > 1.0:
                phi = 1.0
            if not (phi > 0.0):  # (also a non-finite ratio: full q)
                phi = 0.0
            w = 1.0 - phi
            jump = -(g * grad[z, ndir + d])            # compressive velocity jump >= 0
            qd = (q_lin * cz * w + q_quad * jump * (1.0 - phi * phi))
            s += qd * jump
            if qd > qmax:
                qmax = qd
    return r * s, qmax


# ------------------------------------------------------------------------------------------------
# 3D
# ------------------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def zone_dt(lc, u, qq, cz):
    """The zone's stable step lc / (u + Q + sqrt(Q^2 + c^2)) (u: its fastest node in Eulerian mode,
    Q: zone_q's Courant term); a still zone without sound speed -- void, or an outflow boundary's
    ghost of it -- limits nothing (infinity, not a division by zero)."""
    den = u + qq + math.sqrt(qq * qq + cz * cz)
    return lc / den if den > 0.0 else math.inf


@njit(cache=True, inline="always")
def zone_q(qkind, grad, z, zs, ndir, r, cz, lc, divv, q_lin, q_quad, solid):
    """Artificial viscosity of zone z and its Courant term Q: (q, Q), both 0 unless compressed
    (div v < 0); scalar q from div v and the length lc, or the monotonic q (:func:`_mono_q`)."""
    if not divv < 0.0:
        return 0.0, 0.0
    if qkind == Q_MONOTONIC:
        return _mono_q(grad, z, zs, ndir, r, cz, q_lin, q_quad, solid)
    qq = q_lin * cz - q_quad * lc * divv
    return r * lc * qq * (-divv), qq


@njit(cache=True)
def zone_pass_3d(x, v, v_old, fc, M, e, V, rho, p, c, q, de_h, zlo, zhi, rlo, rhi, zs, ns,
                 flags, dt, dt_avg, code, par, q_lin, q_quad, hg, qkind, grad):
    """One pass over the zones ``zlo <= (i, j, k) < zhi`` (padded indices).

    flags: ENERGY (only for real zones rlo <= ijk < rhi), EOS, FORCES, MIDSTEP, ADVECT.
    Arrays: x, v, v_old (nn, 3); fc (nz, 8, 3) corner forces (read by ENERGY, written by
    FORCES); M, e, V, rho, p, c, q, de_h (nz,).  V is always updated to the volume at x.
    qkind: Q_SCALAR or Q_MONOTONIC; grad (nz, 6): the directional strain rates and widths of
    :func:`mono_gradients_3d` (read for Q_MONOTONIC only, on the zone and its 6 face neighbours).
    Returns ``(dt_min, bad_zone, reason, dt_at)`` (bad_zone = -1 if none; the pass stops at the
    first; dt_at: the zone whose step is dt_min, -1 if none).
    """
    co = np.empty(8, np.int64)
    for a in range(8):
        ox = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oy = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oz = 1 if a >= 4 else 0
        co[a] = ox * ns[0] + oy * ns[1] + oz * ns[2]
    xe = np.empty((8, 3))
    ve = np.empty((8, 3))
    b = np.empty((8, 3))
    gam = np.empty(8)
    w = np.empty(8)
    do_energy = (flags & ENERGY) != 0
    do_eos = (flags & EOS) != 0
    do_forces = (flags & FORCES) != 0
    midstep = (flags & MIDSTEP) != 0
    advect = (flags & ADVECT) != 0
    half_dt = 0.5 * dt
    dt_min = np.inf
    dt_at = -1   # the zone that sets dt_min (the step's limiter, named in the log)
    for i in range(zlo[0], zhi[0]):
        ri = rlo[0] <= i < rhi[0]
        for j in range(zlo[1], zhi[1]):
            rj = ri and rlo[1] <= j < rhi[1]
            for k in range(zlo[2], zhi[2]):
                real = rj and rlo[2] <= k < rhi[2]
                z = i * zs[0] + j * zs[1] + k * zs[2]
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                for a in range(8):
                    nd = n0 + co[a]
                    for d in range(3):
                        xe[a, d] = x[nd, d]
                        ve[a, d] = v[nd, d]
                if do_energy and real:
                    for a in range(8):
                        nd = n0 + co[a]
                        w[a] = (fc[z, a, 0] * (0.5 * (v_old[nd, 0] + ve[a, 0]))
                                + fc[z, a, 1] * (0.5 * (v_old[nd, 1] + ve[a, 1]))
                                + fc[z, a, 2] * (0.5 * (v_old[nd, 2] + ve[a, 2])))
                    work = _t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7])
                    e[z] -= dt_avg * work / M[z]
                _, amax = hex_bvectors(xe, b)
                vol = hex_volume_sym(xe, b)
                if not (vol > 0.0):
                    return dt_min, z, BAD_VOLUME, -1
                if M[z] == 0.0:  # no material (a fully blocked zone, blocked.py): no state, no force
                    V[z] = vol
                    rho[z] = 0.0
                    p[z] = 0.0
                    c[z] = 0.0
                    q[z] = 0.0
                    fc[z, :, :] = 0.0
                    continue
                v_prev = V[z]
                if do_energy and real:
                    de_h[z] = -(p[z] + q[z]) * (vol - v_prev) / (2.0 * M[z])
                V[z] = vol
                if do_eos:
                    r = M[z] / vol
                    pz, cz, ok = _eos.state(code, par, r, e[z] + de_h[z])
                    rho[z] = r
                    p[z] = pz
                    c[z] = cz
                    if not ok:
                        return dt_min, z, BAD_STATE, -1
                if not do_forces:
                    continue
                r = rho[z]
                pz = p[z]
                cz = c[z]
                # velocity divergence: Lagrange step: volume change over the step (= sum v . b at
                # the mid-step geometry, to O(dt^2)); otherwise sum v . b / V at x
                if midstep:
                    divv = (vol - v_prev) / (half_dt * (vol + v_prev))
                else:
                    for a in range(8):
                        w[a] = ve[a, 0] * b[a, 0] + ve[a, 1] * b[a, 1] + ve[a, 2] * b[a, 2]
                    divv = _t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]) / vol
                lc = vol / amax
                qz, qq = zone_q(qkind, grad, z, zs, 3, r, cz, lc, divv, q_lin, q_quad, None)
                q[z] = qz
                u = 0.0
                if advect:
                    for a in range(8):
                        s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1] + ve[a, 2] * ve[a, 2]
                        if s2 > u:
                            u = s2
                    u = math.sqrt(u)
                dte = zone_dt(lc, u, qq, cz)
                if dte < dt_min:
                    dt_min = dte
                    dt_at = z
                s = pz + qz
                for a in range(8):
                    for d in range(3):
                        fc[z, a, d] = s * b[a, d]
                if hg > 0.0:
                    cb = np.cbrt(vol)
                    ah = hg * r * cz * cb * cb * 0.25
                    ivol = 1.0 / vol
                    # base vectors eta zeta, zeta xi, xi eta, xi eta zeta at the VTK corners
                    _hg_mode(1.0, 1.0, -1.0, -1.0, -1.0, -1.0, 1.0, 1.0, xe, b, ve, ivol, ah, fc, z)
                    _hg_mode(1.0, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, xe, b, ve, ivol, ah, fc, z)
                    _hg_mode(1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, xe, b, ve, ivol, ah, fc, z)
                    _hg_mode(-1.0, 1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0, xe, b, ve, ivol, ah, fc, z)
    return dt_min, -1, 0, dt_at


@njit(cache=True)
def gather_3d(fc, zact, M, f, m, nlo, nhi, zs, ns):
    """Nodal force f (nn, 3) and lumped mass m (nn,) of the nodes nlo <= ijk < nhi, gathered from
    the 8 surrounding zones (active ones only) in a fixed balanced-tree order."""
    for i in range(nlo[0], nhi[0]):
        for j in range(nlo[1], nhi[1]):
            for k in range(nlo[2], nhi[2]):
                n = i * ns[0] + j * ns[1] + k * ns[2]
                # zones (i-1+a, j-1+b, k-1+c); the node is their corner (1-a, 1-b, 1-c)
                z0, z1, z2, z3, z4, z5, z6, z7 = zones_around_node_3d(i, j, k, zs)
                for d in range(3):
                    f[n, d] = _t8(zact[z0] * fc[z0, 6, d], zact[z1] * fc[z1, 7, d],
                                  zact[z2] * fc[z2, 4, d], zact[z3] * fc[z3, 5, d],
                                  zact[z4] * fc[z4, 2, d], zact[z5] * fc[z5, 3, d],
                                  zact[z6] * fc[z6, 0, d], zact[z7] * fc[z7, 1, d])
                m[n] = 0.125 * _t8(zact[z0] * M[z0], zact[z1] * M[z1], zact[z2] * M[z2], zact[z3] * M[z3],
                                   zact[z4] * M[z4], zact[z5] * M[z5], zact[z6] * M[z6], zact[z7] * M[z7])


# ------------------------------------------------------------------------------------------------
# 2D (plane, unit thickness)
# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def zone_pass_2d(x, v, v_old, fc, M, e, V, rho, p, c, q, de_h, zlo, zhi, rlo, rhi, zs, ns,
                 flags, dt, dt_avg, code, par, q_lin, q_quad, hg, qkind, grad):
    """2D version of :func:`zone_pass_3d` (x, v, v_old (nn, 2); fc (nz, 4, 2); grad (nz, 4))."""
    co = np.empty(4, np.int64)
    co[0] = 0
    co[1] = ns[0]
    co[2] = ns[0] + ns[1]
    co[3] = ns[1]
    xe = np.empty((4, 2))
    ve = np.empty((4, 2))
    b = np.empty((4, 2))
    gam = np.empty(4)
    w = np.empty(4)
    do_energy = (flags & ENERGY) != 0
    do_eos = (flags & EOS) != 0
    do_forces = (flags & FORCES) != 0
    midstep = (flags & MIDSTEP) != 0
    advect = (flags & ADVECT) != 0
    half_dt = 0.5 * dt
    dt_min = np.inf
    dt_at = -1   # the zone that sets dt_min (the step's limiter, named in the log)
    for i in range(zlo[0], zhi[0]):
        ri = rlo[0] <= i < rhi[0]
        for j in range(zlo[1], zhi[1]):
            real = ri and rlo[1] <= j < rhi[1]
            z = i * zs[0] + j * zs[1]
            n0 = i * ns[0] + j * ns[1]
            for a in range(4):
                nd = n0 + co[a]
                xe[a, 0] = x[nd, 0]
                xe[a, 1] = x[nd, 1]
                ve[a, 0] = v[nd, 0]
                ve[a, 1] = v[nd, 1]
            if do_energy and real:
                for a in range(4):
                    nd = n0 + co[a]
                    w[a] = (fc[z, a, 0] * (0.5 * (v_old[nd, 0] + ve[a, 0]))
                            + fc[z, a, 1] * (0.5 * (v_old[nd, 1] + ve[a, 1])))
                work = _t4(w[0], w[1], w[2], w[3])
                e[z] -= dt_avg * work / M[z]
            vol, _ = quad_bvectors(xe, b)
            if not (vol > 0.0):
                return dt_min, z, BAD_VOLUME, -1
            if M[z] == 0.0:  # no material (a fully blocked zone, blocked.py): no state, no force
                V[z] = vol
                rho[z] = 0.0
                p[z] = 0.0
                c[z] = 0.0
                q[z] = 0.0
                fc[z, :, :] = 0.0
                continue
            v_prev = V[z]
            if do_energy and real:
                de_h[z] = -(p[z] + q[z]) * (vol - v_prev) / (2.0 * M[z])
            V[z] = vol
            if do_eos:
                r = M[z] / vol
                pz, cz, ok = _eos.state(code, par, r, e[z] + de_h[z])
                rho[z] = r
                p[z] = pz
                c[z] = cz
                if not ok:
                    return dt_min, z, BAD_STATE, -1
            if not do_forces:
                continue
            r = rho[z]
            pz = p[z]
            cz = c[z]
            if midstep:
                divv = (vol - v_prev) / (half_dt * (vol + v_prev))
            else:
                for a in range(4):
                    w[a] = ve[a, 0] * b[a, 0] + ve[a, 1] * b[a, 1]
                divv = _t4(w[0], w[1], w[2], w[3]) / vol
            # longest edge
            emax = 0.0
            for a in range(4):
                an = (a + 1) % 4
                ex = xe[an, 0] - xe[a, 0]
                ey = xe[an, 1] - xe[a, 1]
                l2 = ex * ex + ey * ey
                if l2 > emax:
                    emax = l2
            lc = vol / math.sqrt(emax)
            qz, qq = zone_q(qkind, grad, z, zs, 2, r, cz, lc, divv, q_lin, q_quad, None)
            q[z] = qz
            u = 0.0
            if advect:
                for a in range(4):
                    s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1]
                    if s2 > u:
                        u = s2
                u = math.sqrt(u)
            dte = zone_dt(lc, u, qq, cz)
            if dte < dt_min:
                dt_min = dte
                dt_at = z
            s = pz + qz
            for a in range(4):
                fc[z, a, 0] = s * b[a, 0]
                fc[z, a, 1] = s * b[a, 1]
            if hg > 0.0:
                quad_viscous_hourglass(xe, ve, b, vol, hg * r * cz * math.sqrt(vol) * 0.25, gam, fc[z])
    return dt_min, -1, 0, dt_at


@njit(cache=True)
def gather_2d(fc, zact, M, f, m, nlo, nhi, zs, ns):
    """2D version of :func:`gather_3d` (4 zones per node)."""
    for i in range(nlo[0], nhi[0]):
        for j in range(nlo[1], nhi[1]):
            n = i * ns[0] + j * ns[1]
            z0, z1, z2, z3 = zones_around_node_2d(i, j, zs)
            for d in range(2):
                f[n, d] = _t4(zact[z0] * fc[z0, 2, d], zact[z1] * fc[z1, 3, d],
                              zact[z2] * fc[z2, 0, d], zact[z3] * fc[z3, 1, d])
            m[n] = 0.25 * _t4(zact[z0] * M[z0], zact[z1] * M[z1], zact[z2] * M[z2], zact[z3] * M[z3])


# ------------------------------------------------------------------------------------------------
# node kernels (any dimension)
# ------------------------------------------------------------------------------------------------
@njit(cache=True)
def predict(v, v_old, f, m, nlo, nhi, ns, dt_avg):
    """v_old <- v; v <- v + dt_avg f / m on the nodes nlo <= ijk < nhi."""
    dim = v.shape[1]
    for i in range(nlo[0], nhi[0]):
        for j in range(nlo[1], nhi[1]):
            for k in range(nlo[2], nhi[2]):
                n = i * ns[0] + j * ns[1] + k * ns[2]
                s = dt_avg / m[n] if m[n] > 0.0 else 0.0  # massless: inside an obstacle (blocked.py)
                for d in range(dim):
                    v_old[n, d] = v[n, d]
                    v[n, d] += s * f[n, d]


@njit(cache=True)
def move(x, v, dt):
    """x <- x + dt v (all nodes, ghosts included)."""
    nn, dim = x.shape
    for n in range(nn):
        for d in range(dim):
            x[n, d] += dt * v[n, d]


@njit(cache=True)
def ghost_force_work(fc, zkind, v, v_old, owned, zlo, zhi, zs, ns, open_kind, out):
    """Impulse and work on owned nodes of the corner forces of open-boundary ghost zones
    (zkind == open_kind) during the step: out[0:dim] += sum f, out[3] += sum f . vbar
    (multiply by dt_avg outside)."""
    dim = v.shape[1]
    nc = fc.shape[1]
    co = np.empty(nc, np.int64)
    for a in range(nc):
        ox = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oy = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oz = 1 if a >= 4 else 0
        co[a] = ox * ns[0] + oy * ns[1] + oz * ns[2]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                if zkind[z] != open_kind:
                    continue
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                for a in range(nc):
                    nd = n0 + co[a]
                    if not owned[nd]:
                        continue
                    for d in range(dim):
                        out[d] += fc[z, a, d]
                        out[3] += fc[z, a, d] * 0.5 * (v[nd, d] + v_old[nd, d])


@njit(cache=True)
def sums(M, e, zreal, m, v, owned, out):
    """out = [mass, internal energy, kinetic energy, momentum x, y, z, sum m |v|]."""
    for a in range(out.shape[0]):
        out[a] = 0.0
    for z in range(M.shape[0]):
        if zreal[z]:
            out[0] += M[z]
            out[1] += M[z] * e[z]
    dim = v.shape[1]
    for n in range(m.shape[0]):
        if owned[n]:
            s2 = 0.0
            for d in range(dim):
                s2 += v[n, d] * v[n, d]
                out[3 + d] += m[n] * v[n, d]
            out[2] += 0.5 * m[n] * s2
            out[6] += m[n] * np.sqrt(s2)


@njit(cache=True)
def energy_from_pressure_array(code, par, rho, p, out):
    for i in range(rho.shape[0]):
        out[i] = _eos.energy_from_pressure(code, par, rho[i], p[i])


def _flush():
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([zone_pass_3d, zone_pass_2d, mono_gradients_3d, mono_gradients_2d, gather_3d,
                       gather_2d, predict, move, ghost_force_work, sums, energy_from_pressure_array, energy_update,
                       lagrangian_volumes, _t4, _t8, zones_around_node_3d, zones_around_node_2d, _mono_q, zone_q],
                      [_eos.__file__, _elements.__file__], "hydro.deps.sha256")




@njit(cache=True)
def energy_update(fc, v, v_old, e, M, zlo, zhi, zs, ns, dt_avg):
    """Compatible internal-energy update alone (Eulerian mode: the geometry of the Lagrangian grid
    comes from the remap's swept volumes): e -= dt_avg sum_c f_c . (v_old + v)_c / 2 / M."""
    nc = fc.shape[1]
    dim = fc.shape[2]
    co = np.empty(nc, np.int64)
    for a in range(nc):
        ox = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oy = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oz = 1 if a >= 4 else 0
        co[a] = ox * ns[0] + oy * ns[1] + oz * ns[2]
    w = np.empty(8)
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                for a in range(nc):
                    nd = n0 + co[a]
                    s = 0.0
                    for d in range(dim):
                        s += fc[z, a, d] * (0.5 * (v_old[nd, d] + v[nd, d]))
                    w[a] = s
                if nc == 8:
                    work = _t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7])
                else:
                    work = _t4(w[0], w[1], w[2], w[3])
                if M[z] > 0.0:  # (no material: a fully blocked zone, no force)
                    e[z] -= dt_avg * work / M[z]


@njit(cache=True)
def lagrangian_volumes(SV, V, M, rho, p, q, de_h, zlo, zhi, zs):
    """Eulerian mode: V_lag = V_eul + sum_d (SV_d[z + s_d] - SV_d[z]) (the swept volumes tile the
    difference exactly), rho = M / V_lag and the half-step EOS energy shift de_h.  Returns the first
    zone with V_lag <= 0 (or -1)."""
    dim = SV.shape[0]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                vn = V[z]
                for d in range(dim):
                    vn += SV[d, z + zs[d]] - SV[d, z]
                if not (vn > 0.0):
                    return z
                # (no material: void, mixed.py)
                de_h[z] = -(p[z] + q[z]) * (vn - V[z]) / (2.0 * M[z]) if M[z] > 0.0 else 0.0
                V[z] = vn
                rho[z] = M[z] / vn
    return -1


_flush()
