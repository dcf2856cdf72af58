"""The compiled kernels of the cut zones (blocked.py's model, its docstring): the face apertures and
open fractions, the open zones' EOS and Lagrangian open volumes, the fluxes through cut faces and
their outflow cap, the nodes held and merged in cut zones (held, light), and the aperture-weighted
zone pass of 2-D and 3-D cut zones."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers import elements as _elements
from solvers.ale import eos as _eos
from solvers.ale.hydro import _t4, _t8, hex_volume_sym, zone_dt, zone_q
from solvers.ale.merge import _split, _zone_around
from solvers.ale.remap import face_flux
from solvers.elements import hex_bvectors, quad_bvectors

TRACE_ZONE = 1e-6
"""A zone whose mass is below this share of a full zone -- at its own density, or at the case's
lightest initial density (AleSolver.rho_ref) if that is larger -- is a trace zone: its corners may
cross within a step (lagrangian_open_volumes).  A quarter-rod penetrator had one of 1.3e-9 invert
at 2.4 us (artificial viscosity 0.1) and one of 7e-11 at 12 us (viscosity 1).  The absolute
reference is for a zone nearly empty of material (8.6e-50 kg of aluminium in a void zone at the
crater, inverted): its own density, M / V, is as small as its mass, so at its own density alone
it never counted as a trace."""

PHI_Q = 0.5
"""The artificial viscosity of a cut zone takes its divergence over at least this fraction of the
zone's volume: the flux mismatch of a small zone's faces would be amplified by 1/phi (a small zone
shares its state with its neighbour after each remap: PHI_MERGE)."""


@njit(cache=True)
def body_apertures(b, face_ok, A_static, zs, A):
    """A[d, z] (the lower d-face of padded zone z) = min(A_static, 0 if z and its lower d-neighbour
    are both covered whole by the bodies (b == 1), else 1) on this block's faces (face_ok), A_static
    on the rest: the faces inside a body, which the coupler does not list (it lists the others it
    covers)."""
    dim = A.shape[0]
    for d in range(dim):
        s = zs[d]
        for z in range(b.size):
            if face_ok[d, z] == 0:
                A[d, z] = A_static[d, z]
            elif z >= s and b[z] >= 1.0 and b[z - s] >= 1.0:
                A[d, z] = 0.0
            else:
                A[d, z] = A_static[d, z]


@njit(cache=True)
def open_fractions(b, real, solid_tol):
    """From the bodies' blocked fractions b (padded, ghost layers too): the open fraction of the real
    zones (0 within solid_tol of full, 1 elsewhere: ghosts are filled after), b of the real zones,
    the number of real zones with some open volume."""
    n = b.size
    phi = np.empty(n)
    br = np.empty(n)
    n_open = 0.0
    for z in range(n):
        if real[z]:
            br[z] = b[z]
            phi[z] = 0.0 if b[z] >= 1.0 - solid_tol else 1.0 - b[z]
            if phi[z] > 0.0:
                n_open += 1.0
        else:
            br[z] = 0.0
            phi[z] = 1.0
    return phi, br, n_open


@njit(cache=True)
def open_eos(code, par, M, e, de_h, phi, VE, rho, p, c, q, zlo, zhi, zs):
    """rho = M / (phi VE) and the EOS at e + de_h of the zones in range; massless zones get
    rho = p = c = q = 0.  Returns the first zone with an invalid state (or -1)."""
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                if M[z] > 0.0:
                    r = M[z] / (phi[z] * VE[z])
                    pz, cz, ok = _eos.state(code, par, r, e[z] + de_h[z])
                    rho[z] = r
                    p[z] = pz
                    c[z] = cz
                    if not ok:
                        return z
                else:
                    rho[z] = 0.0
                    p[z] = 0.0
                    c[z] = 0.0
                    q[z] = 0.0
    return -1


@njit(cache=True)
def mid_face_volumes(A0, A1, SV, ASV):
    """ASV = (A0 + A1) / 2 * SV (the remap's face volumes with mid-step apertures)."""
    for d in range(SV.shape[0]):
        for f in range(SV.shape[1]):
            a0 = A0[d, f]
            a1 = A1[d, f]
            if 0.0 < a0 < 1.0 and 0.0 < a1 < 1.0:
                ASV[d, f] = 0.5 * (a0 + a1) * SV[d, f]


@njit(cache=True)
def lagrangian_open_volumes(ASV, SB, CUT, VE, phi, V, M, rho, p, q, de_h, zlo, zhi, zs, rho_ref):
    """V = phi VE + SB + sum_d (ASV_d[z + s_d] - ASV_d[z]) (open Lagrangian volume; SB the volume a
    coupled body's surface sweeps into the zone, negative when it advances), rho = M / V and the
    half-step EOS shift de_h of the zones with material.  A coupled body's cut zone (CUT) whose open
    part the body surface and its faces sweep away within the step keeps a sliver of volume (its
    material leaves through the positivity-limited fluxes and the small-zone merge) and no EOS shift.
    So does a zone that holds a trace (mass below ``TRACE_ZONE`` of a full zone at its density or at
    ``rho_ref``, the case's lightest initial density, whichever is larger):
    its corners, driven by the zones around them, may cross within the step (a void
    zone at the crater of a 3-D penetrator, 9e-18 kg at 1018 kg/m^3 in 1.25e-10 m^3, inverted at
    12 us and stopped the run); its content goes with the remap as a sliver's does.
    Returns the first other zone with V <= 0."""
    dim = ASV.shape[0]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                v0 = phi[z] * VE[z]
                vn = v0 + SB[z]
                for d in range(dim):
                    vn += ASV[d, z + zs[d]] - ASV[d, z]
                # (rho: the zone's density before the step)
                trace = M[z] < TRACE_ZONE * max(rho[z], rho_ref) * VE[z]
                swept = (CUT[z] != 0 or trace) and not (vn > 1e-9 * VE[z])
                if swept:
                    # a body surface and the zone's open faces swept past its whole open part
                    # within the step (the surface crossed a zone face, or the zone is small): its
                    # material goes through the open faces (the remap's positivity limit) and the
                    # small-zone merge; keep a sliver of volume here
                    vn = 1e-9 * VE[z]
                V[z] = vn
                if M[z] > 0.0:
                    if not (vn > 0.0):
                        return z
                    # the half-step EOS shift of the step's p dV; none for a zone a body surface
                    # swept or changed by more than half its volume (a small cut zone: its state
                    # merges with its neighbour's after the remap, the linear shift means nothing)
                    big = CUT[z] != 0 and abs(vn - v0) > 0.5 * v0
                    de_h[z] = 0.0 if (swept or big) else -(p[z] + q[z]) * (vn - v0) / (2.0 * M[z])
                    rho[z] = M[z] / vn
                else:
                    rho[z] = 0.0
    return -1


@njit(cache=True)
def cut_face_fluxes(cut, s, d, ASV, rhoL, eL, ML, VL, VE, solid, F, ES, zs, real):
    """Mass flux F and face energy ES of sweep d (stride s) through both d-faces of every cut zone,
    from the Lagrangian state (rho, e, M, V before the first sweep) instead of the sweep's
    intermediate state.

    Why: the split sweeps pass a cut zone's open volume through intermediate states that its open
    faces alone decide -- a sliver's x faces may sweep more than it holds before its y faces bring
    the volume back -- so its intermediate density, and every flux computed from it, is off by O(1)
    of itself (positivity-limited, 14x the true density in a sliver of 3e-4 in a uniform flow along
    an inclined wall).  Every flux of these faces from one state keeps a uniform state uniform
    exactly (each zone ends with rho (phi V)), and each face's flux is still the one both of its
    zones see (conservative).  All of a sweep's fluxes are computed before the sweeps (remap), so
    that cap_cut_outflow can keep a zone from passing on more than it has.  A zone a body surface
    swept whole (its Lagrangian volume the sliver lagrangian_open_volumes keeps) sends its material
    out through its open faces in proportion to their swept volumes, no more."""
    dim = ASV.shape[0]
    for t in range(cut.size):
        for o in range(2):
            f = cut[t] + o * s
            if real[f] == 0 and real[f - s] == 0:  # (only the faces of real zones; ``cut`` has ghosts)
                continue
            sv = ASV[d, f]
            if sv > 0.0:
                u = f - s
                sg = 0.5
            else:
                u = f
                sg = -0.5
            if not (VL[u] > 0.0) and real[u] == 0:  # (a ghost zone without a volume here, e.g.
                F[f] = np.nan  # beyond a wall: the face keeps the sweep's own flux, copy_cut_face_fluxes)
                continue
            if sv == 0.0 or not (ML[u] > 0.0):
                F[f] = 0.0
                ES[f] = eL[u]
                continue
            ru, rl, rh = rhoL[u], rhoL[u - s], rhoL[u + s]
            eu, el, eh = eL[u], eL[u - s], eL[u + s]
            if solid[u - s]:  # (a solid neighbour is a wall ghost, as in remap.sweep_fluxes)
                rl = ru
                el = eu
            if solid[u + s]:
                rh = ru
                eh = eu
            fl, es = face_flux(sv, sg, ru, rl, rh, eu, el, eh, VL[u], ML[u])
            if VL[u] <= 1e-9 * VE[u]:
                out = 0.0
                for a in range(dim):
                    out += max(ASV[a, u + zs[a]], 0.0) + max(-ASV[a, u], 0.0)
                # (out > 0 unless u is a ghost zone whose outer faces this rank has no swept volume for)
                cap = ML[u] * abs(sv) / out if out > 0.0 else abs(fl)
                if abs(fl) > cap:
                    fl = cap if fl > 0.0 else -cap
                    es = eL[u]
            F[f] = fl
            ES[f] = es


KEEP = 0.5
"""A cut zone whose outflow would exceed what it has (its Lagrangian mass and inflow) passes on this
fraction of it (cap_cut_outflow): a zone left with exactly nothing would lose the energy its
in- and outflows carry at different specific energies (sweep_zones keeps no state for it)."""


@njit(cache=True)
def cap_cut_outflow(cut, ML, FX, zs):
    """No zone of ``cut`` ends the remap with negative mass: where its Lagrangian mass and the
    inflow through its faces (all from the Lagrangian state, cut_face_fluxes) fall short of its
    outflow, its outgoing fluxes are scaled down to what it has (a sliver whose open face sweeps
    more than the sliver holds: its Lagrangian state is no donor for that much).  Each face's flux
    stays the one both of its zones see."""
    dim = FX.shape[0]
    for t in range(cut.size):
        z = cut[t]
        fin = 0.0
        fout = 0.0
        for d in range(dim):
            lo = FX[d, z]
            hi = FX[d, z + zs[d]]
            if np.isnan(lo):  # (a face left to the sweep: cut_face_fluxes)
                lo = 0.0
            if np.isnan(hi):
                hi = 0.0
            if lo > 0.0:
                fin += lo
            else:
                fout -= lo
            if hi < 0.0:
                fin -= hi
            else:
                fout += hi
        have = ML[z] + fin
        if fout > have and fout > 0.0:
            k = KEEP * max(have, 0.0) / fout
            for d in range(dim):
                if FX[d, z] < 0.0:
                    FX[d, z] *= k
                if FX[d, z + zs[d]] > 0.0:
                    FX[d, z + zs[d]] *= k


@njit(cache=True)
def copy_cut_face_fluxes(cut, s, d, FX, EX, F, ES, real):
    """The sweep-d fluxes of both d-faces of every zone of ``cut`` (cut_face_fluxes, capped) into the
    sweep's face arrays (the faces of real zones)."""
    for t in range(cut.size):
        for o in range(2):
            f = cut[t] + o * s
            if (real[f] == 0 and real[f - s] == 0) or np.isnan(FX[d, f]):
                continue
            F[f] = FX[d, f]
            ES[f] = EX[d, f]


@njit(cache=True, inline="always")
def _deposit_node(n, dk, m, e, M, zs, ns, dim):
    """A node's kinetic-energy defect dk to the internal energy of its zones with material, as
    remap.deposit shares it: 2^-dim dk / m per unit mass of each zone (the share depends on the
    node's mass only, so a node's copies -- periodic, other ranks' -- give each real zone its part;
    nothing for a node without positive mass)."""
    if not (m[n] > 0.0):
        return
    i, j, k = _split(n, ns)
    nc = 1 << dim
    for c in range(nc):
        z = _zone_around(i, j, k, c, zs, dim)
        if M[z] != 0.0:
            e[z] += dk / (nc * m[n])


@njit(cache=True)
def finish_held_nodes(hn, P, KF, m, v, vL, mL, e, M, code, zs, ns):
    """The held nodes' velocities after the last sweep, v = vL + P / m (the momentum the fluxes
    brought relative to their Lagrangian velocity vL, over the mass the sweeps left them; vL where
    that mass is zero), and their kinetic-energy
    defect 1/2 (mL |vL|^2 + KF - m |v|^2) to the internal energy of their zones with material, as
    remap.deposit shares it (2^-dim dK / m per unit mass of each zone).  A light node (``code`` >= 0,
    light_node_targets) deposits nothing: its kinetic energy in, mL |vL|^2 + KF, is left in KF for
    merge_light_nodes (its v = vL + P / m need not be bounded, nor its defect)."""
    dim = v.shape[1]
    for a in range(hn.size):
        n = hn[a]
        k0 = 0.0
        k1 = 0.0
        for c in range(dim):
            v[n, c] = vL[a, c] + P[n, c] / m[n] if m[n] != 0.0 else vL[a, c]
            k0 += vL[a, c] * vL[a, c]
            k1 += v[n, c] * v[n, c]
        if code[n] >= 0.0:
            KF[n] += mL[a] * k0
            continue
        dk = 0.5 * (mL[a] * k0 + KF[n] - m[n] * k1)
        _deposit_node(n, dk, m, e, M, zs, ns, dim)


@njit(cache=True, inline="always")
def _neighbour(n, o, ns, dim):
    """Node o (0 .. 3^dim - 1) of the 3^dim around node n (itself included): offset o % 3 - 1 along x,
    (o // 3) % 3 - 1 along y, (o // 9) % 3 - 1 along z."""
    dk = (o // 9) % 3 - 1 if dim == 3 else 0
    return n + (o % 3 - 1) * ns[0] + ((o // 3) % 3 - 1) * ns[1] + dk * ns[2]


@njit(cache=True)
def light_node_targets(hn, IN, m, ns, dim, code):
    """Which held nodes merge and into whom (decided where the node is real): a node whose inflow IN
    over the remap exceeds the mass it ends with has no convex update -- v = vL + sum phi_in (v_in -
    vL) / m weights its inflows by phi_in / m > 1 (a node of a sliver and covered zones with the
    flow passing through it: its deviation grows by that ratio every step) -- and shares one
    velocity with its heaviest neighbour node that is not light itself (the 3^dim - 1 around it,
    first in index order on ties).  code[n] = the neighbour's offset number (0 .. 3^dim - 1), or -1."""
    nb = 3 ** dim
    for a in range(hn.size):
        n = hn[a]
        if not (IN[n] > m[n]):  # (a node the sweeps left with negative mass included)
            continue
        best = -1
        mb = 0.0
        for o in range(nb):
            t = _neighbour(n, o, ns, dim)
            if t == n or IN[t] > m[t]:
                continue
            if m[t] > mb:
                mb = m[t]
                best = o
        code[n] = best


@njit(cache=True)
def merge_light_nodes(hn, code, K2, m, v, e, M, real_node, zs, ns, dim):
    """The light nodes (light_node_targets' code, filled to the ghost layers) and their targets:
    one velocity per group, sum m v / sum m (momentum conserved), and the kinetic-energy defect --
    the target's m |v|^2 and the light nodes' energy in K2 = mL |vL|^2 + KF (finish_held_nodes), less
    the group's after, halved -- to the internal energy of the target's zones (as finish_held_nodes
    deposits)."""
    tg = np.full(hn.size, -1, np.int64)
    q = 0
    for a in range(hn.size):
        n = hn[a]
        c = int(code[n])
        if c < 0:
            continue
        tg[a] = _neighbour(n, c, ns, dim)
        q += 1
    if q == 0:
        return
    targets = np.unique(tg[tg >= 0])
    for b in range(targets.size):
        t = targets[b]
        P = np.zeros(dim)
        ms = m[t]
        k0 = 0.0
        for c in range(dim):
            P[c] = m[t] * v[t, c]
            k0 += m[t] * v[t, c] * v[t, c]
        for a in range(hn.size):
            if tg[a] == t:
                n = hn[a]
                ms += m[n]
                k0 += K2[n]
                for c in range(dim):
                    P[c] += m[n] * v[n, c]
        k1 = 0.0
        for c in range(dim):
            P[c] /= ms
            k1 += ms * P[c] * P[c]
            v[t, c] = P[c]
        for a in range(hn.size):
            if tg[a] == t:
                for c in range(dim):
                    v[hn[a], c] = P[c]
        if real_node[t]:  # (a ghost target: its real copy deposits, here or on its owner)
            _deposit_node(t, 0.5 * (k0 - k1), m, e, M, zs, ns, dim)


@njit(cache=True, inline="always")
def _aperture(A, z, zs, d, o):
    return A[d, z] if o == 0 else A[d, z + zs[d]]


@njit(cache=True)
def apertures_2d(x, v, fc, M, rho, p, c, q, phi, A, SF, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
    """Aperture correction of the zones listed (after hydro.zone_pass_2d at the fixed grid):
    div v = sum v . b^A / (phi V), new q of the solver's kind (qkind; monotonic: from the strain
    rates ``grad`` of hydro.mono_gradients_2d, a solid neighbour as a wall ghost, hydro._mono_q),
    f_c = (p + q) b^A_c + phi f_hg,c, written as
    f_c + ((p + q_new) b^A_c - (p + q_old) b_c) + (phi - 1) (f_c - (p + q_old) b_c) so that a corner
    with an open face and an unchanged q keeps its bits.  SF: the flux a_e . v_surface of a coupled
    body's surface in the zone (the open volume's rate of change has -SF: a retreating surface is
    no compression), 0 elsewhere.  Returns the zones' stable step and the zone that sets it (-1 if
    none)."""
    xe = np.empty((4, 2))
    ve = np.empty((4, 2))
    b = np.empty((4, 2))
    bA = np.empty((4, 2))
    w = np.empty(4)
    dt_min = np.inf
    dt_at = -1   # the zone that sets dt_min (the step's limiter, named in the log)
    for t in range(zones.shape[0]):
        z = zones[t]
        if not (M[z] > 0.0):
            continue
        i = z // zs[0]
        j = (z - i * zs[0]) // zs[1]
        n0 = i * ns[0] + j * ns[1]
        for a in range(4):
            ox = 1 if (a == 1 or a == 2) else 0
            oy = 1 if a >= 2 else 0
            nd = n0 + ox * ns[0] + oy * ns[1]
            xe[a, 0] = x[nd, 0]
            xe[a, 1] = x[nd, 1]
            ve[a, 0] = v[nd, 0]
            ve[a, 1] = v[nd, 1]
        vol, _ = quad_bvectors(xe, b)
        for a in range(4):
            ox = 1 if (a == 1 or a == 2) else 0
            oy = 1 if a >= 2 else 0
            bA[a, 0] = b[a, 0] * _aperture(A, z, zs, 0, ox)
            bA[a, 1] = b[a, 1] * _aperture(A, z, zs, 1, oy)
            w[a] = ve[a, 0] * bA[a, 0] + ve[a, 1] * bA[a, 1]
        ph = phi[z]
        divv = (_t4(w[0], w[1], w[2], w[3]) - SF[z]) / (max(ph, PHI_Q) * vol)
        emax = 0.0
        for a in range(4):
            an = (a + 1) % 4
            ex = xe[an, 0] - xe[a, 0]
            ey = xe[an, 1] - xe[a, 1]
            l2 = ex * ex + ey * ey
            if l2 > emax:
                emax = l2
        lc = vol / math.sqrt(emax)
        cz = c[z]
        qz, qq = zone_q(qkind, grad, z, zs, 2, rho[z], cz, lc, divv, q_lin, q_quad, solid)
        s_old = p[z] + q[z]
        s_new = p[z] + qz
        q[z] = qz
        u = 0.0
        for a in range(4):
            s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1]
            if s2 > u:
                u = s2
        dte = zone_dt(lc, math.sqrt(u), qq, cz)
        if dte < dt_min:
            dt_min = dte
            dt_at = z
        for a in range(4):
            for d in range(2):
                hg = fc[z, a, d] - s_old * b[a, d]
                fc[z, a, d] = fc[z, a, d] + (s_new * bA[a, d] - s_old * b[a, d]) + (ph - 1.0) * hg
    return dt_min, dt_at


@njit(cache=True)
def apertures_3d(x, v, fc, M, rho, p, c, q, phi, A, SF, solid, zones, zs, ns, q_lin, q_quad, qkind, grad):
    """3D version of :func:`apertures_2d` (hydro.zone_pass_3d geometry)."""
    xe = np.empty((8, 3))
    ve = np.empty((8, 3))
    b = np.empty((8, 3))
    bA = np.empty((8, 3))
    w = np.empty(8)
    oo = np.empty((8, 3), np.int64)
    for a in range(8):
        oo[a, 0] = 1 if (a == 1 or a == 2 or a == 5 or a == 6) else 0
        oo[a, 1] = 1 if (a == 2 or a == 3 or a == 6 or a == 7) else 0
        oo[a, 2] = 1 if a >= 4 else 0
    dt_min = np.inf
    dt_at = -1   # the zone that sets dt_min (the step's limiter, named in the log)
    for t in range(zones.shape[0]):
        z = zones[t]
        if not (M[z] > 0.0):
            continue
        i = z // zs[0]
        r = z - i * zs[0]
        j = r // zs[1]
        k = r - j * zs[1]
        n0 = i * ns[0] + j * ns[1] + k * ns[2]
        for a in range(8):
            nd = n0 + oo[a, 0] * ns[0] + oo[a, 1] * ns[1] + oo[a, 2] * ns[2]
            for d in range(3):
                xe[a, d] = x[nd, d]
                ve[a, d] = v[nd, d]
        _, amax = hex_bvectors(xe, b)
        vol = hex_volume_sym(xe, b)
        for a in range(8):
            for d in range(3):
                bA[a, d] = b[a, d] * _aperture(A, z, zs, d, oo[a, d])
            w[a] = ve[a, 0] * bA[a, 0] + ve[a, 1] * bA[a, 1] + ve[a, 2] * bA[a, 2]
        ph = phi[z]
        divv = (_t8(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]) - SF[z]) / (max(ph, PHI_Q) * vol)
        lc = vol / amax
        cz = c[z]
        qz, qq = zone_q(qkind, grad, z, zs, 3, rho[z], cz, lc, divv, q_lin, q_quad, solid)
        s_old = p[z] + q[z]
        s_new = p[z] + qz
        q[z] = qz
        u = 0.0
        for a in range(8):
            s2 = ve[a, 0] * ve[a, 0] + ve[a, 1] * ve[a, 1] + ve[a, 2] * ve[a, 2]
            if s2 > u:
                u = s2
        dte = zone_dt(lc, math.sqrt(u), qq, cz)
        if dte < dt_min:
            dt_min = dte
            dt_at = z
        for a in range(8):
            for d in range(3):
                hg = fc[z, a, d] - s_old * b[a, d]
                fc[z, a, d] = fc[z, a, d] + (s_new * bA[a, d] - s_old * b[a, d]) + (ph - 1.0) * hg
    return dt_min, dt_at


@njit(cache=True)
def corner_force_sum(fc, zones, out):
    """out[d] = sum over the listed zones of sum_c fc[z, c, d]."""
    for d in range(out.shape[0]):
        out[d] = 0.0
    for t in range(zones.shape[0]):
        z = zones[t]
        for a in range(fc.shape[1]):
            for d in range(fc.shape[2]):
                out[d] += fc[z, a, d]



def _flush():
    from solvers.ale import hydro as _h
    from solvers.ale import merge as _merge
    from solvers.ale import remap as _remap
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([open_eos, lagrangian_open_volumes, _aperture, apertures_2d, apertures_3d, corner_force_sum,
                       cut_face_fluxes, cap_cut_outflow, copy_cut_face_fluxes, finish_held_nodes, light_node_targets,
                       merge_light_nodes],
                      [_eos.__file__, _elements.__file__, _h.__file__, _merge.__file__, _remap.__file__],
                      "cut_zone_kernels.deps.sha256")


_flush()
