"""Remap kernels of the ALE background solver: direction-split, second-order, monotone advection
of a staggered grid (zone mass and internal energy, nodal momentum) from the Lagrangian grid back to
the fixed (Eulerian) grid.

Swept volumes
-------------
The lower d-face of zone z sweeps, from its Eulerian to its Lagrangian position, the hexahedron
(quad in 2D) spanned by the face's 4 (2) corners at both positions; ``SV_d[z]`` is its signed
volume, positive for a displacement towards +d.  The swept hexahedra of all faces tile the
difference between the Lagrangian and the Eulerian zone exactly (shared bilinear side patches), so
``V_lag = V_eul + sum_d (SV_d[z + s_d] - SV_d[z])`` to round-off and a uniform density stays
uniform through every sweep.  Volumes use ``V = 1/24 sum_faces (r_a + r_b + r_c + r_d) .
((r_c - r_a) x (r_d - r_b))`` (exact for trilinear hexahedra) with ``r = x - x_0``, evaluated
in the frame (t1, t2, d) with ``t1 = d+1, t2 = d+2 (mod 3)`` so that the same arithmetic runs
for each axis (a swept volume that is flat in d is exactly zero).

One sweep along d (material flows from the Lagrangian zone into the Eulerian one)
----------------------------------------------------------------------------------
Zones, per face f with upwind zone u (the zone the swept region belongs to on the Lagrangian grid)::

    F_f   = SV_f (rho_u +/- 1/2 drho_u (1 - |SV_f| / V_u))        mass flux (+ towards +d)
    e*_f  = e_u +/- 1/2 de_u (1 - |F_f| / M_u)                    face specific internal energy
    M'    = M + F_lo - F_hi ;  V' = V + SV_lo - SV_hi ;  rho' = M' / V'
    e'    = e + (F_lo (e*_lo - e) - F_hi (e*_hi - e)) / M'        (= (M e + F_lo e*_lo - F_hi e*_hi)/M')

with limited slopes ``drho, de`` (monotonised central: ``minmod(2a, 2b, (a+b)/2)`` of the one-sided
differences a, b).  Nodes (dual cells): the dual face between nodes n-s and n sits at the zone
centres of layer i-1; its mass flux is built from the zone fluxes (``1/8`` of the sum over the
4 zones of that layer around the node line of both faces of each zone, 2D: ``1/4`` over 2 zones)::

    Phi = 1/8 sum_zones act_z (F_lo,z + F_hi,z)

which makes the nodal mass change equal to the change of ``m_n = sum act_z M_z / 8``: the dual
fluxes are consistent with the zone fluxes.  With the limited upwind nodal velocity ``v*`` at the
dual face (same reconstruction in the mass fraction ``|Phi| / m_u``)::

    m' v' = m v + Phi_lo v*_lo - Phi_hi v*_hi     computed as   v' = v + (Phi_lo (v*_lo - v) - Phi_hi (v*_hi - v)) / m'

so a uniform velocity stays exactly uniform and momentum is conserved to round-off.  The kinetic
energy the momentum remap loses, ``dK_n = 1/2 m |v|^2 + 1/2 Phi_lo |v*_lo|^2 - 1/2 Phi_hi |v*_hi|^2
- 1/2 m' |v'|^2`` (its flux terms telescope), goes to the zones' internal energy (DeBar):
zone z gets ``M_z / (8 m_n)`` of it from each corner, i.e. ``de_z = sum_c dK_c / (8 m_c)``
(2D: 4), so kinetic + internal energy is conserved to round-off.

Obstacles and void
------------------
The same kernels serve grids with blocked volume fractions (blocked.py: ``solid`` flags, the
face volumes scaled by the face apertures, zones and nodes without material) and void regions
(mixed.py: nodes without mass); the extra branches are compiled out of the plain kernels
(``solid = None``, ``M = None``, ``massless = False``), which keep their bits and speed.
"""
from __future__ import annotations


import numpy as np
from numba import njit

from solvers.ale.hydro import _t4, _t8, zones_around_node_2d, zones_around_node_3d


@njit(cache=True, inline="always")
def limiter(a, b):
    """Monotonised-central limited difference (symmetric in a, b; odd)."""
    if a * b <= 0.0:
        return 0.0
    aa = abs(a)
    ab = abs(b)
    s = 0.5 * abs(a + b)
    m = 2.0 * aa if aa < ab else 2.0 * ab
    if s < m:
        m = s
    return m if a > 0.0 else -m


# ------------------------------------------------------------------------------------------------
# swept volumes
# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _face(r, a, b, c, d):
    p0 = r[c, 0] - r[a, 0]
    p1 = r[c, 1] - r[a, 1]
    p2 = r[c, 2] - r[a, 2]
    q0 = r[d, 0] - r[b, 0]
    q1 = r[d, 1] - r[b, 1]
    q2 = r[d, 2] - r[b, 2]
    s0 = (r[a, 0] + r[b, 0]) + (r[d, 0] + r[c, 0])
    s1 = (r[a, 1] + r[b, 1]) + (r[d, 1] + r[c, 1])
    s2 = (r[a, 2] + r[b, 2]) + (r[d, 2] + r[c, 2])
    return s0 * (p1 * q2 - p2 * q1) + s1 * (p2 * q0 - p0 * q2) + s2 * (p0 * q1 - p1 * q0)


@njit(cache=True)
def hex_volume(r):
    """Volume of the trilinear hexahedron with corner coordinates r (8, 3) (VTK order)."""
    t = (_face(r, 0, 3, 2, 1) + _face(r, 4, 5, 6, 7)) + (_face(r, 0, 1, 5, 4) + _face(r, 2, 3, 7, 6)) \
        + (_face(r, 1, 2, 6, 5) + _face(r, 3, 0, 4, 7))
    return t / 24.0


@njit(cache=True)
def swept_volumes_3d(X, x, SV, d, zlo, zhi, zs, ns):
    """SV[z] = signed volume swept by the lower d-face of zone z from X to x (zones in range)."""
    t1 = (d + 1) % 3
    t2 = (d + 2) % 3
    o1 = ns[t1]
    o3 = ns[t2]
    comp = np.array([t1, t2, d])
    r = np.empty((8, 3))
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                nodes = (n0, n0 + o1, n0 + o1 + o3, n0 + o3)
                for a in range(3):
                    ca = comp[a]
                    base = X[n0, ca]
                    for q in range(4):
                        r[q, a] = X[nodes[q], ca] - base
                        r[q + 4, a] = x[nodes[q], ca] - base
                SV[z] = hex_volume(r)


@njit(cache=True)
def swept_volumes_2d(X, x, SV, d, zlo, zhi, zs, ns):
    """2D: SV[z] = signed area swept by the lower d-edge of zone z from X to x."""
    t = 1 - d
    o = ns[t]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            z = i * zs[0] + j * zs[1]
            n0 = i * ns[0] + j * ns[1]
            n1 = n0 + o
            # quad (X0, X1, x1, x0) in the frame (t, d), relative to X0
            bt = X[n0, t]
            bn = X[n0, d]
            d1t = x[n1, t] - bt
            d1n = x[n1, d] - bn
            d2t = (x[n0, t] - bt) - (X[n1, t] - bt)
            d2n = (x[n0, d] - bn) - (X[n1, d] - bn)
            SV[z] = 0.5 * (d1t * d2n - d1n * d2t)


# ------------------------------------------------------------------------------------------------
# zone part of a sweep
# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def face_flux(sv, sg, ru, rl, rh, eu, el, eh, Vu, Mu):
    """Mass flux and face energy of a face sweeping ``sv`` out of its upwind zone u (rho, e of u and
    of its lower/upper neighbours; ``sg`` = +1/2 when the flux leaves u through its upper face)."""
    dr = limiter(ru - rl, rh - ru)
    fr = abs(sv) / Vu
    if fr > 1.0:
        fr = 1.0
    f = sv * (ru + sg * dr * (1.0 - fr))
    de = limiter(eu - el, eh - eu)
    fm = abs(f) / Mu
    if fm > 1.0:
        fm = 1.0
    return f, eu + sg * de * (1.0 - fm)


@njit(cache=True)
def sweep_fluxes(rho, e, M, V, SV, F, ES, solid, s, zlo, zhi, zs):
    """Mass flux F and face energy e* of the lower faces (stride s) of the zones in range.

    ``solid``: None (no obstacles), or per zone nonzero for a fully blocked zone (obstacles,
    blocked.py; SV are then the aperture-scaled face volumes).  With obstacles a closed face
    (SV = 0) or an upwind zone without material carries nothing, and a solid neighbour of the
    upwind zone is a wall ghost (a copy of the upwind zone: zero one-sided slope).  (None is a
    type of its own to numba: the obstacle branches are compiled out of the plain kernel.)
    """
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                sv = SV[z]
                if sv > 0.0:
                    u = z - s
                    sg = 0.5
                else:
                    u = z
                    sg = -0.5
                if solid is not None and (sv == 0.0 or not (M[u] > 0.0)):
                    F[z] = 0.0
                    ES[z] = e[u]
                    continue
                ru = rho[u]
                rl = rho[u - s]
                rh = rho[u + s]
                eu = e[u]
                el = e[u - s]
                eh = e[u + s]
                if solid is not None:
                    if solid[u - s]:
                        rl = ru
                        el = eu
                    if solid[u + s]:
                        rh = ru
                        eh = eu
                f, es = face_flux(sv, sg, ru, rl, rh, eu, el, eh, V[u], M[u])
                if solid is not None:
                    # a face sweeping more than the upwind zone holds: a moving body swept that
                    # zone's open part past the face within the step (its swept volume is body,
                    # not fluid): the zone's material crosses, no more (positivity), shared with
                    # its other face in proportion to the volumes when both carry material out
                    so = SV[u] if sv > 0.0 else SV[z + s]
                    out = -so if sv > 0.0 else so
                    cap = M[u] if not (out > 0.0) else M[u] * abs(sv) / (abs(sv) + out)
                    if abs(f) > cap:
                        f = cap if f > 0.0 else -cap
                        es = eu
                F[z] = f
                ES[z] = es


@njit(cache=True)
def sweep_zones(rho, e, M, V, SV, F, ES, solid, s, zlo, zhi, zs):
    """Conservative zone update of one sweep (zones in range).

    ``solid`` as in :func:`sweep_fluxes` (only whether it is None matters here): with obstacles
    zones may hold no material (V is the open volume): a zone left without material gets rho = 0
    (and is left alone if it had none and nothing crossed its faces), a zone without open volume
    rho = 0."""
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                fl = F[z]
                fh = F[z + s]
                mn = M[z] + fl - fh
                vn = V[z] + SV[z] - SV[z + s]
                if solid is not None and not (mn > 0.0):
                    V[z] = vn
                    if not (M[z] == 0.0 and fl == 0.0 and fh == 0.0):
                        if mn != 0.0:  # (energy conserved: a zone a moving body empties may go
                            # slightly negative; its neighbour takes it over after the remap)
                            e[z] = (M[z] * e[z] + fl * ES[z] - fh * ES[z + s]) / mn
                        M[z] = mn
                        rho[z] = 0.0
                    continue
                ez = e[z]
                e[z] = ez + (fl * (ES[z] - ez) - fh * (ES[z + s] - ez)) / mn
                M[z] = mn
                V[z] = vn
                if solid is not None and not (vn > 0.0):
                    rho[z] = 0.0
                else:
                    rho[z] = mn / vn


# ------------------------------------------------------------------------------------------------
# node part of a sweep
# ------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _layer_solid(solid, z0, t1, t2, dim):
    """The zones z0 + {0, -t1} (+ {0, -t2} in 3D) around a node line are all solid."""
    if dim == 3:
        return solid[z0] != 0 and solid[z0 - t1] != 0 and solid[z0 - t2] != 0 and solid[z0 - t1 - t2] != 0
    return solid[z0] != 0 and solid[z0 - t1] != 0


@njit(cache=True)
def sweep_dual(F, zact, solid, v, m, PHI, VS, d, nlo, nhi, zs, ns):
    """Dual mass flux PHI[n] and limited upwind velocity VS[n] at the lower d-dual face of the
    nodes in range (between node n - ns[d] and n, at the zone centres of layer i_d - 1).

    ``solid`` as in :func:`sweep_fluxes`; at an immersed wall (the zone layer between the upwind
    node and its neighbour is solid) the neighbour's velocity is the mirror image of the other
    neighbour's (normal component reversed), as the ghost nodes of a conforming wall."""
    dim = v.shape[1]
    sd = zs[d]
    nsd = ns[d]
    if dim == 3:
        t1 = zs[(d + 1) % 3]
        t2 = zs[(d + 2) % 3]
        scale = 0.125
    else:
        t1 = zs[1 - d]
        t2 = 0
        scale = 0.25
    for i in range(nlo[0], nhi[0]):
        for j in range(nlo[1], nhi[1]):
            for k in range(nlo[2], nhi[2]):
                n = i * ns[0] + j * ns[1] + k * ns[2]
                zn = i * zs[0] + j * zs[1] + k * zs[2]
                if solid is not None and _layer_solid(solid, zn, t1, t2, dim) and \
                        _layer_solid(solid, zn - sd, t1, t2, dim):
                    # inside a body or obstacle: no flux (the faces are closed), the node's own
                    # velocity (what the wall ghosts below give: both layers solid)
                    PHI[n] = 0.0
                    for c in range(dim):
                        VS[n, c] = v[n, c]
                    continue
                za = zn - sd - t1
                zb = za + t1
                if dim == 3:
                    zc = za - t2
                    zd = zb - t2
                    phi = scale * _t4(zact[zc] * (F[zc] + F[zc + sd]), zact[zd] * (F[zd] + F[zd + sd]),
                                      zact[zb] * (F[zb] + F[zb + sd]), zact[za] * (F[za] + F[za + sd]))
                else:
                    phi = scale * (zact[za] * (F[za] + F[za + sd]) + zact[zb] * (F[zb] + F[zb + sd]))
                if phi > 0.0:
                    u = n - nsd
                    zu = zn - sd
                    sg = 0.5
                else:
                    u = n
                    zu = zn
                    sg = -0.5
                fr = abs(phi) / m[u] if m[u] > 0.0 else 1.0
                if fr > 1.0:
                    fr = 1.0
                PHI[n] = phi
                hi_solid = False
                lo_solid = False
                if solid is not None:
                    hi_solid = _layer_solid(solid, zu, t1, t2, dim)
                    lo_solid = _layer_solid(solid, zu - sd, t1, t2, dim)
                if not (hi_solid or lo_solid):
                    for c in range(dim):
                        vu = v[u, c]
                        dv = limiter(vu - v[u - nsd, c], v[u + nsd, c] - vu)
                        VS[n, c] = vu + sg * dv * (1.0 - fr)
                    continue
                for c in range(dim):  # wall ghosts
                    vu = v[u, c]
                    vl = v[u - nsd, c]
                    vh = v[u + nsd, c]
                    if hi_solid and lo_solid:
                        vl = vu
                        vh = vu
                    elif hi_solid:
                        vh = -vl if c == d else vl
                    else:
                        vl = -vh if c == d else vh
                    dv = limiter(vu - vl, vh - vu)
                    VS[n, c] = vu + sg * dv * (1.0 - fr)


@njit(cache=True)
def sweep_nodes(v, m, M, zact, PHI, VS, dK, d, nlo, nhi, zs, ns, massless, hold=None, P=None, KF=None, IN=None):
    """Nodal momentum update of one sweep, new lumped masses and the kinetic-energy defect dK.

    ``massless``: nodes may be left without mass (inside an obstacle, blocked.py, or in void,
    mixed.py): such a node gets v = 0, dK = 0.  ``hold`` (uint8 per node, or None): nodes whose
    update waits for the last sweep (blocked.py: the nodes of a body's cut zones, whose mass may pass
    through zero in between): their momentum P and kinetic-energy flux KF accumulate, their velocity
    stays (the upwind velocity of their dual faces), their mass follows the zones'; P holds the
    momentum the fluxes bring relative to that velocity, sum phi (v_upwind - v) (a uniform velocity
    brings none, to the bit); IN their inflow volume (mass) summed over the sweeps."""
    if massless:  # (the flag is a constant in each inlined copy: no test per node without it)
        _sweep_nodes(v, m, M, zact, PHI, VS, dK, d, nlo, nhi, zs, ns, True, hold, P, KF, IN)
    else:
        _sweep_nodes(v, m, M, zact, PHI, VS, dK, d, nlo, nhi, zs, ns, False, hold, P, KF, IN)


@njit(cache=True, inline="always")
def _sweep_nodes(v, m, M, zact, PHI, VS, dK, d, nlo, nhi, zs, ns, massless, hold, P, KF, IN):
    dim = v.shape[1]
    nsd = ns[d]
    for i in range(nlo[0], nhi[0]):
        for j in range(nlo[1], nhi[1]):
            for k in range(nlo[2], nhi[2]):
                n = i * ns[0] + j * ns[1] + k * ns[2]
                if dim == 3:
                    z0, z1, z2, z3, z4, z5, z6, z7 = zones_around_node_3d(i, j, k, zs)
                    mn = 0.125 * _t8(zact[z0] * M[z0], zact[z1] * M[z1], zact[z2] * M[z2], zact[z3] * M[z3],
                                     zact[z4] * M[z4], zact[z5] * M[z5], zact[z6] * M[z6], zact[z7] * M[z7])
                else:
                    z0, z1, z2, z3 = zones_around_node_2d(i, j, zs)
                    mn = 0.25 * _t4(zact[z0] * M[z0], zact[z1] * M[z1], zact[z2] * M[z2], zact[z3] * M[z3])
                if hold is not None and hold[n] != 0:
                    pl = PHI[n]
                    ph = PHI[n + nsd]
                    for c in range(dim):
                        sl = VS[n, c]
                        sh = VS[n + nsd, c]
                        vc = v[n, c]  # (its velocity before the remap: held)
                        P[n, c] += pl * (sl - vc) - ph * (sh - vc)
                        KF[n] += pl * sl * sl - ph * sh * sh
                    IN[n] += max(pl, 0.0) + max(-ph, 0.0)
                    dK[n] = 0.0
                    m[n] = mn
                    continue
                if massless and not (mn > 0.0):
                    for c in range(dim):
                        v[n, c] = 0.0
                    dK[n] = 0.0
                    m[n] = 0.0
                    continue
                pl = PHI[n]
                ph = PHI[n + nsd]
                k_old = 0.0
                k_fl = 0.0
                k_new = 0.0
                for c in range(dim):
                    vc = v[n, c]
                    sl = VS[n, c]
                    sh = VS[n + nsd, c]
                    vn = vc + (pl * (sl - vc) - ph * (sh - vc)) / mn
                    k_old += vc * vc
                    k_fl += pl * sl * sl - ph * sh * sh
                    k_new += vn * vn
                    v[n, c] = vn
                dK[n] = 0.5 * ((m[n] * k_old + k_fl) - mn * k_new)
                m[n] = mn


@njit(cache=True)
def deposit(e, m, dK, zlo, zhi, zs, ns, dim, M):
    """Zone share of the nodal kinetic-energy defect: e += sum_c dK_c / (2^dim m_c).

    ``M``: None (every zone holds material), or the zone masses when zones may hold none
    (obstacles, void; their corner nodes may be massless): those zones get nothing."""
    o1 = ns[0]
    o2 = ns[1]
    o4 = ns[2]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                if M is not None and M[z] == 0.0:  # (a zone of negative mass takes its negative
                    continue  # share: the shares of a node's zones sum to its defect exactly)
                n0 = i * ns[0] + j * ns[1] + k * ns[2]
                if dim == 3:
                    s = 0.125 * _t8(_per_mass(dK, m, n0), _per_mass(dK, m, n0 + o1),
                                    _per_mass(dK, m, n0 + o1 + o2), _per_mass(dK, m, n0 + o2),
                                    _per_mass(dK, m, n0 + o4), _per_mass(dK, m, n0 + o1 + o4),
                                    _per_mass(dK, m, n0 + o1 + o2 + o4), _per_mass(dK, m, n0 + o2 + o4))
                else:
                    s = 0.25 * _t4(_per_mass(dK, m, n0), _per_mass(dK, m, n0 + o1),
                                   _per_mass(dK, m, n0 + o1 + o2), _per_mass(dK, m, n0 + o2))
                e[z] += s


@njit(cache=True, inline="always")
def _per_mass(dK, m, n):
    """dK / m of a node; a node without mass has no defect (a zone with a round-off of material
    next to a coupled body's covered zones can have one)."""
    return dK[n] / m[n] if m[n] > 0.0 else 0.0


@njit(cache=True)
def set_positions(x, X):
    nn, dim = x.shape
    for n in range(nn):
        for c in range(dim):
            x[n, c] = X[n, c]


def _flush():
    from solvers.ale import hydro as _h
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([limiter, face_flux, hex_volume, swept_volumes_3d, swept_volumes_2d, sweep_fluxes,
                       sweep_zones, _layer_solid, sweep_dual, sweep_nodes, _sweep_nodes, deposit, set_positions],
                      [_h.__file__], "remap.deps.sha256")


_flush()
