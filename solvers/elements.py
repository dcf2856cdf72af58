"""Element geometry shared by the solvers: 4-node quadrilaterals and 8-node hexahedra.

Both the Lagrangian finite-element solver (solvers/lagrange/kernels.py) and the ALE background
(solvers/ale/hydro.py, blocked.py) compute their corner forces from the same uniform-gradient
geometry; it lives here, below both, so that neither solver imports the other.

Node order is VTK's (the natural coordinates ``HEX_XI`` / ``QUAD_XI``); a positively oriented
element has a positive volume.

Corner vectors (Flanagan & Belytschko 1981)
-------------------------------------------
Uniform gradient: ``B_I = (1/V) dV/dx_I``.  With
``b_I = V B_I = dV/dx_I = int_Omega grad N_I dV = oint N_I n dA``:

* hexahedron: every face is a bilinear patch ``x(s,t) = x0 + s e1 + t e2 + s t e3``
  (s, t in [-1, 1]) with corners a(-1,-1), b(1,-1), c(1,1), d(-1,1) ordered
  counter-clockwise seen from outside (``HEX_FACES``), so ``n dA = x_s x x_t ds dt =
  (e1 x e2 + s e1 x e3 + t e3 x e2) ds dt``.  Since ``int N_a ds dt = 1`` and
  ``int N_a s ds dt = s_a/3``, ``int N_a n dA = e1 x e2 + s_a/3 e1 x e3 +
  t_a/3 e3 x e2`` exactly; ``b_I`` is the sum over the three faces holding I.
  The volume follows from Euler's theorem for the cubic V(x):
  ``V = (1/3) sum_I x_I . b_I`` (computed relative to the centroid).
  The exact face-area vector of face f is ``4 e1 x e2`` (= half the cross product
  of its diagonals).
* quadrilateral: ``A = 1/2 sum_I (x_I y_{I+1} - x_{I+1} y_I)`` (exact for the
  bilinear quad, straight edges) so ``b_I = (y_{I+1} - y_{I-1}, x_{I-1} - x_{I+1})/2``.

Both satisfy ``sum_I b_I = 0`` (a translation keeps the volume) and
``sum_I x_I (x) b_I = V I`` (V is homogeneous of degree dim in x) exactly.

Hourglass base vectors
----------------------
``Gamma_a`` (hex: eta zeta, zeta xi, xi eta, xi eta zeta; quad: xi eta), evaluated at the
nodes: the nodal patterns orthogonal to the constant and to the linear fields of the reference
element, the modes a one-point element does not see.  Their projection ``gamma_a = Gamma_a -
(Gamma_a . x_i) B_i`` onto the current element is orthogonal to every linear field in x
(the Flanagan-Belytschko hourglass control of both solvers builds on it).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["HEX_XI", "QUAD_XI", "HEX_FACES", "HEX_HG", "QUAD_HG", "hex_bvectors", "quad_bvectors",
           "quad_gamma", "quad_viscous_hourglass", "facet_area_vectors"]

# Natural coordinates of the VTK nodes.
HEX_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                   [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64)
QUAD_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
# Hex faces (VTK node order), corners counter-clockwise seen from outside.
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4],
                      [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]], dtype=np.int64)
# Hourglass base vectors: eta*zeta, zeta*xi, xi*eta, xi*eta*zeta (hex); xi*eta (quad).
HEX_HG = np.ascontiguousarray(np.stack([
    HEX_XI[:, 1] * HEX_XI[:, 2],
    HEX_XI[:, 2] * HEX_XI[:, 0],
    HEX_XI[:, 0] * HEX_XI[:, 1],
    HEX_XI[:, 0] * HEX_XI[:, 1] * HEX_XI[:, 2],
]))
QUAD_HG = np.ascontiguousarray(QUAD_XI[:, 0] * QUAD_XI[:, 1])  # [1, -1, 1, -1]

_THIRD = 1.0 / 3.0


@njit(cache=True)
def hex_bvectors(xe, b):
    """b_I = dV/dx_I of a trilinear hexahedron (written into b (8,3)).

    Returns ``(V, amax)``: exact volume and the largest face area (magnitude of
    the face area vector).
    """
    for i in range(8):
        b[i, 0] = 0.0
        b[i, 1] = 0.0
        b[i, 2] = 0.0
    amax2 = 0.0
    for fc in range(6):
        ia = HEX_FACES[fc, 0]
        ib = HEX_FACES[fc, 1]
        ic = HEX_FACES[fc, 2]
        id_ = HEX_FACES[fc, 3]
        xa = xe[ia, 0]
        ya = xe[ia, 1]
        za = xe[ia, 2]
        xb = xe[ib, 0]
        yb = xe[ib, 1]
        zb = xe[ib, 2]
        xc = xe[ic, 0]
        yc = xe[ic, 1]
        zc = xe[ic, 2]
        xd = xe[id_, 0]
        yd = xe[id_, 1]
        zd = xe[id_, 2]
        # e1 = (-a + b + c - d)/4, e2 = (-a - b + c + d)/4, e3 = (a - b + c - d)/4
        e1x = 0.25 * ((xb - xa) + (xc - xd))
        e1y = 0.25 * ((yb - ya) + (yc - yd))
        e1z = 0.25 * ((zb - za) + (zc - zd))
        e2x = 0.25 * ((xd - xa) + (xc - xb))
        e2y = 0.25 * ((yd - ya) + (yc - yb))
        e2z = 0.25 * ((zd - za) + (zc - zb))
        e3x = 0.25 * ((xa - xb) + (xc - xd))
        e3y = 0.25 * ((ya - yb) + (yc - yd))
        e3z = 0.25 * ((za - zb) + (zc - zd))
        # c0 = e1 x e2 ; c1 = e1 x e3 / 3 ; c2 = e3 x e2 / 3
        c0x = e1y * e2z - e1z * e2y
        c0y = e1z * e2x - e1x * e2z
        c0z = e1x * e2y - e1y * e2x
        c1x = (e1y * e3z - e1z * e3y) * _THIRD
        c1y = (e1z * e3x - e1x * e3z) * _THIRD
        c1z = (e1x * e3y - e1y * e3x) * _THIRD
        c2x = (e3y * e2z - e3z * e2y) * _THIRD
        c2y = (e3z * e2x - e3x * e2z) * _THIRD
        c2z = (e3x * e2y - e3y * e2x) * _THIRD
        a2 = c0x * c0x + c0y * c0y + c0z * c0z
        if a2 > amax2:
            amax2 = a2
        # corners a(-,-) b(+,-) c(+,+) d(-,+)
        b[ia, 0] += c0x - c1x - c2x
        b[ia, 1] += c0y - c1y - c2y
        b[ia, 2] += c0z - c1z - c2z
        b[ib, 0] += c0x + c1x - c2x
        b[ib, 1] += c0y + c1y - c2y
        b[ib, 2] += c0z + c1z - c2z
        b[ic, 0] += c0x + c1x + c2x
        b[ic, 1] += c0y + c1y + c2y
        b[ic, 2] += c0z + c1z + c2z
        b[id_, 0] += c0x - c1x + c2x
        b[id_, 1] += c0y - c1y + c2y
        b[id_, 2] += c0z - c1z + c2z
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for i in range(8):
        cx += xe[i, 0]
        cy += xe[i, 1]
        cz += xe[i, 2]
    cx *= 0.125
    cy *= 0.125
    cz *= 0.125
    vol = 0.0
    for i in range(8):
        vol += (xe[i, 0] - cx) * b[i, 0] + (xe[i, 1] - cy) * b[i, 1] + (xe[i, 2] - cz) * b[i, 2]
    return vol * _THIRD, 4.0 * math.sqrt(amax2)


@njit(cache=True)
def quad_bvectors(xe, b):
    """b_I = dA/dx_I of a bilinear quadrilateral (written into b (4,2)).

    Returns ``(A, dmax)``: exact area and the longer diagonal.
    """
    for i in range(4):
        ip = (i + 1) % 4
        im = (i + 3) % 4
        b[i, 0] = 0.5 * (xe[ip, 1] - xe[im, 1])
        b[i, 1] = 0.5 * (xe[im, 0] - xe[ip, 0])
    # A = 1/2 (x2 - x0) x (x3 - x1)
    d1x = xe[2, 0] - xe[0, 0]
    d1y = xe[2, 1] - xe[0, 1]
    d2x = xe[3, 0] - xe[1, 0]
    d2y = xe[3, 1] - xe[1, 1]
    area = 0.5 * (d1x * d2y - d1y * d2x)
    dm = max(d1x * d1x + d1y * d1y, d2x * d2x + d2y * d2y)
    return area, math.sqrt(dm)


@njit(cache=True, inline="always")
def quad_gamma(xe, b, area, gam):
    """Flanagan-Belytschko hourglass vector of a quad into gam (4,): gamma = h - (h . x) b / A (h the
    +-1 pattern QUAD_HG, b from quad_bvectors), orthogonal to every linear field."""
    ia = 1.0 / area
    hx = 0.0
    hy = 0.0
    for i in range(4):
        hx += QUAD_HG[i] * xe[i, 0]
        hy += QUAD_HG[i] * xe[i, 1]
    hx *= ia
    hy *= ia
    for i in range(4):
        gam[i] = QUAD_HG[i] - (hx * b[i, 0] + hy * b[i, 1])


@njit(cache=True, inline="always")
def quad_viscous_hourglass(xe, ve, b, area, ah, gam, fc):
    """Flanagan-Belytschko viscous hourglass control of a quad: fc (4, 2) -= gamma ah (gamma . v),
    gamma from quad_gamma (into gam), ah the coefficient (kg/s)."""
    quad_gamma(xe, b, area, gam)
    gx = 0.0
    gy = 0.0
    for i in range(4):
        gx += gam[i] * ve[i, 0]
        gy += gam[i] * ve[i, 1]
    gx *= ah
    gy *= ah
    for i in range(4):
        fc[i, 0] -= gam[i] * gx
        fc[i, 1] -= gam[i] * gy


def facet_area_vectors(points: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Outward normal times area (3-D) or length (2-D) of every facet, shape (nf, dim).

    2-D: (dy, -dx) of the segment a->b. 3-D: (c - a) x (d - b) / 2, the exact integral of the unit
    normal over a bilinear quadrilateral (also for a warped one)."""
    x = np.asarray(points, dtype=np.float64)[facets]
    if facets.shape[1] == 2:
        d = x[:, 1] - x[:, 0]
        return np.stack([d[:, 1], -d[:, 0]], axis=1)
    return 0.5 * np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 1])
