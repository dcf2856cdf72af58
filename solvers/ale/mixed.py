"""Several materials per zone for the ALE background (Eulerian mode): volume fractions, void, the
mixed-zone closure and interface reconstruction (PLIC) in the remap.

State per zone z and material k (arrays shaped (nzones, nmat), so the checkpoint and the ghost
fills treat them like any zone field): volume ``vol``, mass ``mass``, specific internal energy
``ener`` (the conserved one, lagging half a step like the zone's ``e``), the half-step EOS shift
``deh`` and the material pressure/sound speed ``pm``/``cm``.  The zone keeps the sums the hydro
kernels use: ``M = sum_k mass_k``, ``M e = sum_k mass_k ener_k``, ``V = sum_k vol_k``.
A material named with ``eos = "void"`` has volume and nothing else (no mass, energy or pressure).

One step (solver.py calls these in this order)
----------------------------------------------
1. Forces at t^n use the zone pressure ``p = (1 - f_void) sum_k a_k p_k / sum_k a_k``,
   ``a_k = vol_k / K_k``, ``K = rho c^2``: the materials' linearised equilibrium pressure (the one
   whose work ``p dV`` equals ``sum_k p_k dV_k`` under the volume split of step 2), scaled by the
   share of the zone that is not void; and the zone's sound speed from the materials present (more
   than ``TRACE`` of the zone): the mass-weighted rms ``sqrt(sum m_k c_k^2 / sum m_k)`` (the
   stiffness of the equal-strain split, the stiffer bound of step 2), the largest with void.
2. Lagrange step, :func:`lagrange_split`: the zone's volume change ``dV`` is shared in proportion
   to the materials' compressibilities, ``dV_k = dV (vol_k / K_k) / sum_j (vol_j / K_j)`` with
   ``K = rho c^2`` (equal pressure changes: a zone in pressure equilibrium stays in it; equal strain
   for traces, or if a material would lose half its volume or more than double it); with void,
   compression closes the void first, expansion is shared by equal strain (a material cannot fill void faster than its own
   strain; a gas disc in void with all the expansion given to its 20 % share of a rim zone
   over-expanded to a negative EOS energy within two steps).  The zone's compatible energy change ``dE = M e_new -
   sum_k mass_k ener_k`` is shared in proportion to each material's work, ``w_k = (p_k + q) dV_k /
   sum_j (p_j + q) dV_j`` (by mass if the shares would have mixed signs), so the sum is exactly the
   zone's change.  A thin material (below ``RHO_THIN`` of the zone's mean density) takes its mass
   share instead, and a zone whose volume changes by more than half of itself within the step (a
   coupled body's small cut zone) shares it all by mass, with no half-step shift.
3. Remap, one sweep per direction, :func:`sweep_fluxes` + :func:`sweep_zones` (mixed_remap.py): each face's swept
   volume ``SV`` is split over the materials of its donor zone by the exact volume of the donor's
   piecewise-linear interface (Youngs' normals from the fraction field, the plane placed to hold the
   fraction; solvers/ale/plic.py) inside the slab of width ``|SV| / V_donor`` at that face.  With
   several materials the interfaces are nested (onion skins in material order): the plane of the
   cumulative fraction ``F_k = sum_{j <= k} f_j`` cuts off materials 0..k, material k gets the
   difference of two nested cuts (kept monotone and within what the donor holds, so no material
   volume turns negative).  Mass and energy go with the material at the donor's material density and
   energy; where the donor and its two neighbours along the sweep hold one and the same material the
   second-order limited flux of remap.py is used instead, so single-material regions keep their
   accuracy.  Volume, mass and energy of every material are conserved to round-off.
4. After the remap, :func:`relax` moves each mixed zone towards pressure equilibrium: the
   linearised equilibrium ``pbar = sum(vol_k p_k / K_k) / sum(vol_k / K_k)``, ``K = rho c^2``,
   ``dvol_k = vol_k (p_k - pbar) / K_k`` (sum 0; scaled so no material loses more than half its
   volume), with the work ``-pbar dvol_k`` exchanged between the materials (sum 0: the zone's energy
   is untouched).  Void takes no part (it has no pressure): a material next to void expands into it
   through the Lagrange step (step 2) and the advection, at the speed its nodes move.  Two passes
   per step.

References: D. L. Youngs, "Time-dependent multi-material flow with large fluid distortion" (1982);
D. J. Benson, "Volume of fluid interface reconstruction methods for multi-material problems",
Appl. Mech. Rev. 55 (2002) (nested dissection); the seed's "Time Splitting ALE" step.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers.ale import eos as _eos
from solvers.ale.eos import VOID
from solvers.ale.mixed_remap import cumulative_fractions, sweep_fluxes, sweep_zones
from solvers.ale.points import fraction_samples, subcell_offsets

TRACE = 1e-6       # volume fraction below which a material is a trace: no EOS call, no say in c
RHO_THIN = 1e-9
"""A material less dense than this share of its zone's mean density (sum of masses over the zone's
volume) is thin: it counts as a trace (no EOS call, the pressure of the rest) and takes no p dV work
in the Lagrange split (its energy changes by its mass share).  Air in a water zone holds 1.2e-3 of
it; a cavity a steel block's edge opened in water, filled by the air trace the compressibility split
let expand (doubling per step), reached 3e-16 of it at 0.9 % of the zone's volume and took its
volume's share of the zone's q work on no mass (e = 4e21 J/kg, then an invalid state).  The
case-wide ``RHO_CUTOFF`` below acts only where the case has a void material."""
RELAX_PASSES = 2
RHO_CUTOFF = 1e-12
"""A zone whose material is less dense than this share of the case's lightest initial density
(AleSolver.rho_ref), counted over the whole zone, is vacuum: its materials become void, their mass
and internal energy leave the balances as the cut-off's (``cut_off_vacuum``), as hydrocodes' density
cut-offs do.  Left, such a trace took its volume's share of the zone's work on no mass (aluminium
splashed into the void above a penetrator's crater went to 8e-34 kg/m^3 with e = 1.5e214 J/kg, then
nan), and the nodes between such zones (4e-31 kg) took the remap's round-off of their momentum
fluxes as velocity (1.6e14 m/s: the step collapsed to 3e-18 s).  At this share the mass removed is
at most ~3e-19 kg per 0.5 mm zone of a 2700 kg/m^3 case: round-off of the mass balance.  The
kinetic energy of the nodes between such zones (their velocity the remap's round-off over ~1e-30
kg) goes with their mass in the next remap, unbooked: 2.2e-12 of the FE penetrator's energy and
1.1e-12 of its momentum over 32 us (zeroing their velocity at the cut-off instead, booked, made the
coupled rod's surface leave the grid at 1.9 us, its steps shrinking: not understood yet)."""
RELAX_PASSES_INITIAL = 30   # initial mixed zones may be far from equilibrium

# failure reasons
BAD_MATERIAL_STATE = 5


@njit(cache=True)
def _present(vol, mass, code, z, k, vz, mz):
    """Material k of zone z (volume vz, mass mz) has a state of its own: not void, not a trace by
    volume (``TRACE``), not thin (``RHO_THIN``)."""
    return (code[k] != VOID and mass[z, k] > 0.0 and vol[z, k] > TRACE * vz
            and not _thin(vol, mass, z, k, vz, mz))


@njit(cache=True)
def _thin(vol, mass, z, k, vz, mz):
    return mass[z, k] * vz < RHO_THIN * mz * vol[z, k]


@njit(cache=True)
def zone_eos(vol, mass, ener, deh, pm, cm, code, par, M, V, rho, p, c, e, de_h, zlo, zhi, zs):
    """Material states, zone pressure (volume-weighted), sound speed (mass-weighted rms of those
    present; the largest with void), rho = M/V,
    zone e and de_h as mass-weighted sums.  Returns (zone, material) of an invalid state or (-1, -1)."""
    nm = vol.shape[1]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                vz = 0.0
                mz = 0.0
                for m in range(nm):
                    vz += vol[z, m]
                    mz += mass[z, m]
                pa = 0.0
                asum = 0.0
                vvoid = 0.0
                cmax = 0.0
                mc2 = 0.0   # sum of m_k c_k^2 over the materials present
                mp = 0.0    # their mass
                Mz = 0.0
                Ez = 0.0
                Dz = 0.0
                for m in range(nm):
                    if _present(vol, mass, code, z, m, vz, mz):
                        r = mass[z, m] / vol[z, m]
                        pk, ck, ok = _eos.state(code[m], par[m], r, ener[z, m] + deh[z, m])
                        if not ok:
                            return z, m
                        pm[z, m] = pk
                        cm[z, m] = ck
                        a = vol[z, m] / (r * ck * ck)
                        pa += a * pk
                        asum += a
                        if ck > cmax:
                            cmax = ck
                        mc2 += mass[z, m] * ck * ck
                        mp += mass[z, m]
                    else:
                        pm[z, m] = 0.0
                        cm[z, m] = 0.0
                        if code[m] == VOID:
                            vvoid += vol[z, m]
                    Mz += mass[z, m]
                    Ez += mass[z, m] * ener[z, m]
                    Dz += mass[z, m] * deh[z, m]
                # the materials' linearised equilibrium pressure (compressibility-weighted: the
                # pressure whose work matches the volume split of lagrange_split); void: no pressure
                peq = pa / asum if asum > 0.0 else 0.0
                # traces carry the pressure of the rest (they neither push nor pull)
                for m in range(nm):
                    if code[m] != VOID and mass[z, m] > 0.0 and not _present(vol, mass, code, z, m, vz, mz):
                        pm[z, m] = peq
                M[z] = Mz
                if Mz > 0.0:
                    e[z] = Ez / Mz
                    de_h[z] = Dz / Mz
                    rho[z] = Mz / V[z]
                    p[z] = peq * (1.0 - vvoid / vz)
                    # the zone's sound speed: with void, the largest present (compression closes the
                    # void first, then meets that material alone); without, the mass-weighted rms,
                    # sqrt(sum m_k c_k^2 / sum m_k) = sqrt(sum f_k K_k / rho): the zone's stiffness
                    # when its volume change is shared by equal strain (lagrange_split's bound; the
                    # compressibility split is softer, Wood's 1 / sum f_k / K_k). The largest c
                    # let a sliver of gas squeezed hot (0.03 % of a zone, c 3e6 m/s) set the step of
                    # a whole water-and-air scene (1e-9 s against 5e-7 s)
                    c[z] = cmax if vvoid > 0.0 or not mp > 0.0 else min(cmax, math.sqrt(mc2 / mp))
                else:
                    e[z] = 0.0
                    de_h[z] = 0.0
                    rho[z] = 0.0
                    p[z] = 0.0
                    c[z] = 0.0
    return -1, -1


@njit(cache=True)
def cut_off_vacuum(vol, mass, ener, code, void, rho_cut, zlo, zhi, zs, out):
    """Every real zone whose material (non-void) mass is below rho_cut times its volume becomes void:
    its materials' volumes go to material ``void``, their masses and energies to 0; out[0], out[1]
    += the mass and internal energy removed (``RHO_CUTOFF``)."""
    nm = vol.shape[1]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                vz = 0.0
                mz = 0.0
                for m in range(nm):
                    vz += vol[z, m]
                    if code[m] != VOID:
                        mz += mass[z, m]
                if not (mz > 0.0 and mz < rho_cut * vz):
                    continue
                for m in range(nm):
                    if code[m] == VOID:
                        continue
                    out[0] += mass[z, m]
                    out[1] += mass[z, m] * ener[z, m]
                    vol[z, void] += vol[z, m]
                    vol[z, m] = 0.0
                    mass[z, m] = 0.0
                    ener[z, m] = 0.0


@njit(cache=True)
def lagrange_split(vol, mass, ener, deh, pm, cm, code, M, e, V, q, zlo, zhi, zs):
    """Share the zone's Lagrange-step volume and energy change over its materials (real zones;
    V is the Lagrangian volume, e the updated zone energy).  See the module docstring."""
    nm = vol.shape[1]
    dvk = np.empty(nm)
    thin = np.zeros(nm, dtype=np.bool_)
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                vold = 0.0
                vvoid = 0.0
                for m in range(nm):
                    vold += vol[z, m]
                    if code[m] == VOID:
                        vvoid += vol[z, m]
                if not (vold > 0.0):  # no material volume (a solid or emptied open zone)
                    for m in range(nm):
                        deh[z, m] = 0.0
                    continue
                dv = V[z] - vold
                vmat = vold - vvoid
                if not (M[z] > 0.0 and vmat > 0.0):  # void only
                    for m in range(nm):
                        vol[z, m] *= V[z] / vold
                        deh[z, m] = 0.0
                    continue
                # void: compression closes it first; expansion by equal strain (the materials
                # cannot fill the void faster than their own strain: the advection moves the
                # interface at the speed of the nodes)
                dvoid = 0.0
                if dv < 0.0 and vvoid > 0.0:
                    dvoid = dv if -dv < vvoid else -vvoid
                elif dv > 0.0 and vvoid > 0.0:
                    dvoid = dv * vvoid / vold
                dmat = dv - dvoid
                # materials: traces by equal strain, the others in proportion to their
                # compressibility vol/K (K = rho c^2): equal pressure changes, so a zone in pressure
                # equilibrium stays in it
                rest = dmat
                asum = 0.0
                for m in range(nm):
                    dvk[m] = 0.0
                    if code[m] == VOID:
                        continue
                    if cm[z, m] > 0.0 and mass[z, m] > 0.0:
                        asum += vol[z, m] * vol[z, m] / (mass[z, m] * cm[z, m] * cm[z, m])
                    else:
                        dvk[m] = vol[z, m] * dmat / vmat
                        rest -= dvk[m]
                equal = not asum > 0.0
                if not equal:
                    for m in range(nm):
                        if code[m] != VOID and cm[z, m] > 0.0 and mass[z, m] > 0.0:
                            dvk[m] = rest * (vol[z, m] * vol[z, m] / (mass[z, m] * cm[z, m] * cm[z, m])) / asum
                            # (no material may lose half its volume or more than double it in
                            # one step: a trace of gas in water takes the larger part of an
                            # expansion by this rule, and a cut zone's open volume changes by O(1)
                            # of itself per step as a coupled body moves, blocked.py)
                            if vol[z, m] + dvk[m] < 0.5 * vol[z, m] or vol[z, m] + dvk[m] > 2.0 * vol[z, m]:
                                equal = True
                if equal:
                    for m in range(nm):
                        if code[m] != VOID:
                            dvk[m] = vol[z, m] * dmat / vmat
                # energy: shared by p dV work (by mass if the shares would have mixed signs); a
                # thin material (RHO_THIN) by its mass share, the rest by work
                qz = q[z]
                dE = M[z] * e[z]
                den = 0.0
                mthin = 0.0
                for m in range(nm):
                    dE -= mass[z, m] * ener[z, m]
                    if code[m] != VOID and mass[z, m] > 0.0:
                        if _thin(vol, mass, z, m, vold, M[z]):
                            mthin += mass[z, m]
                        else:
                            den += (pm[z, m] + qz) * dvk[m]
                worked = 1.0 - mthin / M[z]
                # a zone whose volume changes by more than half of itself within the step (only a
                # coupled body's small cut zone can: its open part grows or shrinks as the surface
                # moves; blocked.py merges it after the remap) gets the single-material zone's
                # treatment (cut_zone_kernels.lagrangian_open_volumes): no half-step EOS shift, and
                # the energy change shared by mass.  The linear p dV of a zone whose volume triples
                # takes more than a gas trace's energy (0.92 of it at gamma = 1.4): a steel block's
                # edge sliding along a zone row into water drove the air in those cut zones to a
                # negative EOS energy
                big = abs(dv) > 0.5 * vold
                use_work = den != 0.0 and not big
                for m in range(nm):
                    thin[m] = False
                    if code[m] != VOID and mass[z, m] > 0.0:
                        thin[m] = _thin(vol, mass, z, m, vold, M[z])
                        if not thin[m] and (pm[z, m] + qz) * dvk[m] * den < 0.0:
                            use_work = False
                for m in range(nm):
                    if code[m] == VOID:
                        vol[z, m] += dvoid * vol[z, m] / vvoid if vvoid > 0.0 else 0.0
                        deh[z, m] = 0.0
                        continue
                    vol[z, m] += dvk[m]
                    if not mass[z, m] > 0.0:
                        deh[z, m] = 0.0
                        continue
                    if use_work and not thin[m]:
                        w = worked * (pm[z, m] + qz) * dvk[m] / den
                    else:
                        w = mass[z, m] / M[z]
                    ener[z, m] += w * dE / mass[z, m]
                    deh[z, m] = 0.0 if (big or thin[m]) else -(pm[z, m] + qz) * dvk[m] / (2.0 * mass[z, m])


@njit(cache=True)
def relax(vol, mass, ener, deh, code, par, zlo, zhi, zs, passes):
    """Pressure relaxation of the mixed zones (see the module docstring); the zone's volume, mass
    and energy are unchanged."""
    nm = vol.shape[1]
    pk = np.empty(nm)
    kk = np.empty(nm)
    dv = np.empty(nm)
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                for _ in range(passes):
                    vz = 0.0
                    mz = 0.0
                    for m in range(nm):
                        vz += vol[z, m]
                        mz += mass[z, m]
                    npres = 0
                    a = 0.0
                    b = 0.0
                    for m in range(nm):
                        if _present(vol, mass, code, z, m, vz, mz):
                            r = mass[z, m] / vol[z, m]
                            p_, c_, ok = _eos.state(code[m], par[m], r, ener[z, m] + deh[z, m])
                            if not ok:
                                break
                            pk[m] = p_
                            kk[m] = r * c_ * c_
                            a += vol[z, m] * p_ / kk[m]
                            b += vol[z, m] / kk[m]
                            npres += 1
                        else:
                            pk[m] = 0.0
                            kk[m] = 0.0
                    if npres < 2:
                        break
                    pbar = a / b
                    th = 1.0
                    for m in range(nm):
                        dv[m] = 0.0
                        if kk[m] > 0.0:
                            dv[m] = vol[z, m] * (pk[m] - pbar) / kk[m]
                            if dv[m] < -0.5 * vol[z, m]:
                                t = 0.5 * vol[z, m] / (-dv[m])
                                if t < th:
                                    th = t
                    for m in range(nm):
                        if kk[m] > 0.0:
                            d_ = th * dv[m]
                            vol[z, m] += d_
                            ener[z, m] -= pbar * d_ / mass[z, m]


@njit(cache=True)
def density_at_pressure(code, par, P, e, r0):
    """rho > 0 with p(rho, e) = P (every EOS here has p increasing in rho at fixed e where its state
    is valid), by Newton from r0 safeguarded by bisection in the bracket found so far; NaN when
    there is none (P below the EOS's limit, or an energy no density brings to P)."""
    lo = 0.0
    hi = math.inf
    r = r0 if (r0 > 0.0 and r0 < math.inf) else 1.0
    for _ in range(200):
        p = _eos.pressure(code, par, r, e)
        if not math.isfinite(p):
            return np.nan
        f = p - P
        if f == 0.0:
            return r
        if f > 0.0:
            hi = r
        else:
            lo = r
        dp, _ = _eos.derivatives(code, par, r, e)
        rn = r - f / dp if dp > 0.0 else -1.0
        if not (rn > lo and rn < hi):
            rn = 2.0 * r if hi == math.inf else (0.5 * r if lo == 0.0 else math.sqrt(lo * hi))
        if abs(rn - r) <= 1e-14 * r:
            return rn
        r = rn
    return np.nan


@njit(cache=True)
def equilibrium_volumes(code, par, mass, ener, vraw, V, P0, out):
    """Volumes ``out`` (nm,) of materials with masses ``mass`` and specific energies ``ener`` that
    fill ``V`` at one common pressure (the mixture's equilibrium: sum_k m_k / rho_k(P, e_k) = V, a
    decreasing function of P, solved by Newton safeguarded by bisection from P0).  Used where a zone's material volumes carry no information (the small cut zones a
    merge joins: their open volume changed by O(1) of itself within the step, mass and energy are
    conserved, the volumes are not); ``vraw``: their volumes as carried (first density guesses).
    Returns False (out untouched) with void present or when no pressure fits every material.  One
    material with mass fills V whatever its state: True at once (most merge groups hold one)."""
    nm = mass.shape[0]
    rk = np.empty(nm)
    present = 0
    only = -1
    for m in range(nm):
        if code[m] == VOID and vraw[m] > 0.0:
            return False
        rk[m] = mass[m] / vraw[m] if vraw[m] > 0.0 else 1.0
        if mass[m] > 0.0 and code[m] != VOID:
            present += 1
            only = m
    if present == 1:  # one material fills V at whatever pressure its own density gives: no solve
        for m in range(nm):
            out[m] = V if m == only else 0.0
        return True
    p_lo = -math.inf
    p_hi = math.inf
    P = P0 if math.isfinite(P0) else 0.0
    for _ in range(200):
        g = -V
        dg = 0.0
        ok = True
        for m in range(nm):
            if not mass[m] > 0.0 or code[m] == VOID:
                continue
            r = density_at_pressure(code[m], par[m], P, ener[m], rk[m])
            if not (r > 0.0):
                ok = False
                break
            rk[m] = r
            dp, _ = _eos.derivatives(code[m], par[m], r, ener[m])
            g += mass[m] / r
            dg -= mass[m] / (r * r * dp)
        if ok and abs(g) <= 1e-13 * V:
            break
        if not ok or g > 0.0:  # P too low (a material has no density there, or too much volume)
            p_lo = P
        else:
            p_hi = P
        Pn = P - g / dg if (ok and dg < 0.0) else math.nan
        if not (Pn > p_lo and Pn < p_hi):
            step = abs(P) if abs(P) > 1.0 else 1.0
            if p_hi == math.inf:
                Pn = P + step
            elif p_lo == -math.inf:
                Pn = P - step
            else:
                Pn = 0.5 * (p_lo + p_hi)
        if Pn == P:
            break
        P = Pn
    else:
        return False
    if not ok:
        return False
    tot = 0.0
    for m in range(nm):
        tot += mass[m] / rk[m] if (mass[m] > 0.0 and code[m] != VOID) else 0.0
    for m in range(nm):
        out[m] = (mass[m] / rk[m]) * (V / tot) if (mass[m] > 0.0 and code[m] != VOID) else 0.0
    return True


@njit(cache=True)
def fit_open_volumes(vol, Vopen, real):
    """Blocked fractions (blocked.py): scale the material volumes of every real zone to its open
    volume ``Vopen = phi VE`` (the zone's composition kept).  The remap brings the material onto the
    open volumes of the fractions it started with, a coupled body's new fractions then open or close
    part of the zone (single material: rho = M / (phi_new V)); a face that swept more than its upwind
    zone held was capped (mixed_remap.sweep_fluxes), so its downwind zone holds less volume than its
    Lagrangian open volume says.  A zone without material volume stays empty (it fills through its
    faces); a solid zone holds none."""
    nz, nm = vol.shape
    for z in range(nz):
        if not real[z]:
            continue
        vz = 0.0
        for m in range(nm):
            vz += vol[z, m]
        if vz > 0.0:
            r = Vopen[z] / vz
            for m in range(nm):
                vol[z, m] *= r


@njit(cache=True)
def add_energy(ener, mass, code, de, zlo, zhi, zs):
    """ener_k += de[z] for the materials with mass (a zone-level specific energy increment)."""
    nm = ener.shape[1]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                for m in range(nm):
                    if code[m] != VOID and mass[z, m] > 0.0:
                        ener[z, m] += de[z]


# ------------------------------------------------------------------------------------------------
# the solver's side
# ------------------------------------------------------------------------------------------------
class Materials:
    """Material state of an :class:`~solvers.ale.solver.AleSolver` with several materials (or void)
    and the calls the solver makes at each stage of its step."""

    FIELDS = ("vol", "mass", "ener", "deh")   # checkpointed (pm, cm follow from them)

    def __init__(self, s, config: dict):
        used = {r["material"] for r in config["regions"]}
        self.names = [n for n in config["materials"] if n in used]
        nm = len(self.names)
        self.code = np.zeros(nm, np.int64)
        self.par = np.zeros((nm, _eos.NPAR))
        for k, name in enumerate(self.names):
            props = dict(config["materials"][name])
            eos_name = props.pop("eos")
            if eos_name == "void":
                self.code[k] = VOID
                continue
            code, par = _eos.eos_params(eos_name, props)
            self.code[k] = int(code)
            self.par[k] = par
        if np.all(self.code == VOID):
            raise ValueError("the ALE regions hold void only: at least one region needs a material with an EOS")
        B = s.block
        nz = B.nzones
        self.nm = nm
        for f in self.FIELDS + ("pm", "cm", "VF", "MF", "EF"):
            setattr(self, f, np.zeros((nz, nm)))
        self.FC = np.zeros((max(nm - 1, 1), nz))
        self.h = np.ascontiguousarray(B.h[: s.dim], dtype=np.float64)
        self.samples = fraction_samples(config, s.dim)
        self.has_void = bool(np.any(self.code == VOID))
        self.void_index = int(np.argmax(self.code == VOID))  # (the first void material: cut_off_vacuum)

    # ---- initial state -------------------------------------------------------------------------
    def sample(self, s, cfg: dict):
        """Zone-average density, specific energy and velocity of the real zones from the regions
        evaluated at ``samples^dim`` points per zone; keeps the per-material fractions, densities
        and energies for :meth:`set_initial`."""
        from solvers.expressions import compile_expression

        B, dim = s.block, s.dim
        real = B.real_zone
        centres = B.zone_centres()[real][:, :dim]
        nreal = centres.shape[0]
        offs = subcell_offsets(self.samples, B.h[:dim])
        ns = offs.shape[0]
        pts = (centres[:, None, :] + offs[None, :, :]).reshape(-1, dim)
        names = ("x", "y", "z")[:dim]
        regions = cfg["regions"]
        ridx = np.full(pts.shape[0], -1, np.int64)
        for i, r in enumerate(regions):
            if r.get("region"):
                mask = np.broadcast_to(np.asarray(compile_expression(r["region"], names=names)(*pts.T),
                                                  dtype=bool), (pts.shape[0],))
                ridx[mask] = i
            else:
                ridx[:] = i
        missing = bool(np.any(ridx < 0))
        if s.dec.parallel and s.dec.sum(np.array([float(missing)]))[0] > 0.0 and not missing:
            raise ValueError("a zone of another rank is not covered by any region")
        if missing:
            first = int(np.flatnonzero(ridx < 0)[0]) // ns
            z = np.flatnonzero(real)[first]
            raise ValueError(f"zone {B.zone_ijk(z)} (centre {centres[first]}) is not covered by any region")
        nr = len(regions)
        r_mat = np.array([self.names.index(r["material"]) for r in regions], np.int64)
        r_rho = np.zeros(nr)
        r_e = np.zeros(nr)
        r_vel = np.zeros((nr, dim))
        for i, r in enumerate(regions):
            k = r_mat[i]
            r_vel[i] = np.asarray(r.get("velocity", [0.0] * dim), np.float64)
            if self.code[k] == VOID:
                continue
            r_rho[i] = float(r["density"])
            if "pressure" in r:
                r_e[i] = float(_eos.energy_from_pressure(self.code[k], self.par[k], r_rho[i], float(r["pressure"])))
            else:
                r_e[i] = float(r["specific_internal_energy"])
        mat = r_mat[ridx].reshape(nreal, ns)
        rho = r_rho[ridx].reshape(nreal, ns)
        ee = r_e[ridx].reshape(nreal, ns)
        vel = r_vel[ridx].reshape(nreal, ns, dim)
        self._f0 = np.zeros((nreal, self.nm))
        self._rho0 = np.zeros((nreal, self.nm))
        self._e0 = np.zeros((nreal, self.nm))
        for k in range(self.nm):
            w = mat == k
            cnt = w.sum(axis=1)
            rs = (rho * w).sum(axis=1)
            self._f0[:, k] = cnt / ns
            with np.errstate(invalid="ignore", divide="ignore"):
                self._rho0[:, k] = np.where(cnt > 0, rs / np.maximum(cnt, 1), 0.0)
                self._e0[:, k] = np.where(rs > 0, (rho * ee * w).sum(axis=1) / np.where(rs > 0, rs, 1.0), 0.0)
        mz = rho.sum(axis=1)
        zrho = mz / ns
        with np.errstate(invalid="ignore", divide="ignore"):
            ze = np.where(mz > 0, (rho * ee).sum(axis=1) / np.where(mz > 0, mz, 1.0), 0.0)
            zvel = np.where(mz[:, None] > 0, (rho[..., None] * vel).sum(axis=1) / np.where(mz > 0, mz, 1.0)[:, None],
                            vel.mean(axis=1))
        return zrho, ze, zvel

    def set_initial(self, s) -> None:
        """Material volumes and masses from the sampled fractions and the zone volumes; mixed zones
        relaxed to pressure equilibrium."""
        real = s.block.real_zone
        Vr = s.V[real]
        self.vol[real] = self._f0 * Vr[:, None]
        self.mass[real] = self._rho0 * self.vol[real]
        self.ener[real] = self._e0
        relax(self.vol, self.mass, self.ener, self.deh, self.code, self.par, s.zr[0], s.zr[1], s.block.zs,
              RELAX_PASSES_INITIAL)
        self._e0 = self.ener[real]
        s.M[real] = self.mass[real].sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            s.e[real] = np.where(s.M[real] > 0, (self.mass[real] * self._e0).sum(axis=1)
                                 / np.where(s.M[real] > 0, s.M[real], 1.0), 0.0)
        s.rho[real] = s.M[real] / Vr
        del self._f0, self._rho0, self._e0
        self.fill(s)

    # ---- the step --------------------------------------------------------------------------------
    def fill(self, s) -> None:
        s.bc.fill_zones([self.vol, self.mass, self.ener, self.deh])

    def update_eos(self, s, V=None) -> None:
        """Material and zone states; ``V``: the zones' volumes for rho = M / V (blocked.py: the open
        volumes; default the solver's V)."""
        bad, k = zone_eos(self.vol, self.mass, self.ener, self.deh, self.pm, self.cm, self.code, self.par,
                          s.M, s.V if V is None else V, s.rho, s.p, s.c, s.e, s.de_h, s.zr[0], s.zr[1],
                          s.block.zs)
        if bad >= 0:
            self._bad_state(s, bad, k)

    def _bad_state(self, s, z: int, k: int) -> None:
        ijk = s.block.zone_ijk(z)
        vz = self.vol[z].sum()
        r = self.mass[z, k] / self.vol[z, k]
        st = (f"rho={r:.6g} kg/m^3, e={self.ener[z, k]:.6g} J/kg (EOS at {self.ener[z, k] + self.deh[z, k]:.6g}), "
              f"volume fraction {self.vol[z, k] / vz:.6g}")
        s._fail(f"ALE zone {ijk}: invalid thermodynamic state of material {self.names[k]!r} "
                f"({_eos.describe(int(self.code[k]), self.par[k])}) at step {s.step}, t={s.time:.6g} s; {st}")

    def deposit_energy(self, s, de: np.ndarray) -> None:
        """A zone-level specific energy increment (real zones) to every material; ghosts refilled."""
        add_energy(self.ener, self.mass, self.code, de, s.zr[0], s.zr[1], s.block.zs)
        s.bc.fill_zones([self.ener])

    def lagrange_step(self, s) -> None:
        """After lagrangian_volumes (s.V = Lagrangian volumes) and the zone energy update."""
        lagrange_split(self.vol, self.mass, self.ener, self.deh, self.pm, self.cm, self.code, s.M, s.e, s.V, s.q,
                       s.zr[0], s.zr[1], s.block.zs)

    def hold_shift(self) -> None:
        """Before the remap's sweeps: each material's mass (spread_shift)."""
        self._m0 = self.mass.copy()

    def spread_shift(self) -> None:
        """After the sweeps: the half-step EOS shift of a material the remap more than doubled in a
        zone, diluted by the mass it brought in, deh m0 / m (what came in did no work in that zone's
        Lagrange step).  Kept per unit mass, a trace's large shift (its p dV over its small mass)
        went to the air a remap brought in from a neighbour (a steel block's edge in water: e = 4.9e6
        J/kg, shifted by -5.8e6: invalid).  Elsewhere the shift stays per unit mass, as the zone's
        own does (hydro.py): diluted wherever a material gained mass, two labels of one gas beside a
        coupled piston moved it 1.1e-6 from the one-gas run, against 1.2e-8."""
        m, m0 = self.mass, self._m0
        gained = m > 2.0 * m0
        self.deh[gained] *= m0[gained] / m[gained]
        del self._m0

    def cut_off_vacuum(self, s) -> None:
        """After the remap's sweeps: zones thinner than vacuum become void (``RHO_CUTOFF``); what they
        held leaves through the balances' boundary terms (their nodes' mass goes in the next remap,
        and with it their kinetic energy: ~1e-12 of a penetrator's, measured).  Only with a void
        material."""
        if not self.has_void or not s.rho_ref > 0.0:
            return
        out = np.zeros(2)
        cut_off_vacuum(self.vol, self.mass, self.ener, self.code, self.void_index, RHO_CUTOFF * s.rho_ref,
                       s.zr[0], s.zr[1], s.block.zs, out)
        s.b_mass -= float(out[0])
        s.b_energy -= float(out[1])

    def relax_pressures(self, s) -> None:
        relax(self.vol, self.mass, self.ener, self.deh, self.code, self.par, s.zr[0], s.zr[1], s.block.zs,
              RELAX_PASSES)

    def sweep(self, s, d: int) -> None:
        """Zone part of one sweep: material fluxes (zone totals in s.F, s.ES), balances of the open
        faces, conservative update."""
        B = s.block
        st = int(B.zs[d])
        blk = s._blk  # blocked fractions: the aperture-scaled face volumes, solid zones as walls
        sv = s.SV[d] if blk is None else blk.ASV[d]
        solid = None if blk is None else blk.solid
        if self.nm > 1:
            cumulative_fractions(self.vol, self.FC)
        lo, hi = s.zr[0].copy(), s.zr[1].copy()
        hi[d] += 1
        sweep_fluxes(self.vol, self.mass, self.ener, self.code, self.FC, s.rho, s.e, s.M, s.V, sv,
                     s.F, s.ES, self.VF, self.MF, self.EF, solid, d, st, self.h, lo, hi, B.zs)
        s.bc.fill_zones([s.F, s.ES, self.VF, self.MF, self.EF], face_dir=d)
        s._boundary_fluxes(d)
        out = np.zeros(2)
        sweep_zones(self.vol, self.mass, self.ener, self.VF, self.MF, self.EF, s.M, s.V, s.rho, s.e, s.F, s.ES,
                    sv, st, s.zr[0], s.zr[1], B.zs, out)
        s.b_mass -= float(out[0])  # (the dropped residues: the balances' boundary terms)
        s.b_energy -= float(out[1])

    # ---- output ----------------------------------------------------------------------------------
    def fractions(self) -> np.ndarray:
        vz = self.vol.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(vz[:, None] > 0, self.vol / np.where(vz > 0, vz, 1.0)[:, None], 0.0)

    def densities(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.vol > 0, self.mass / np.where(self.vol > 0, self.vol, 1.0), 0.0)

    def cell_columns(self):
        """(name, zone array) pairs written with the zone fields."""
        f = self.fractions()
        r = self.densities()
        cols = []
        for k, name in enumerate(self.names):
            cols.append((f"volume_fraction_{name}", np.ascontiguousarray(f[:, k])))
            if self.code[k] != VOID:
                cols.append((f"density_{name}", np.ascontiguousarray(r[:, k])))
        return cols

    def totals(self, s) -> dict:
        real = s.block.real_zone
        v = self.vol[real].sum(axis=0)
        m = self.mass[real].sum(axis=0)
        buf = np.concatenate([v, m])
        if s.dec.parallel:
            buf = s.dec.sum(buf)
        out = {}
        for k, name in enumerate(self.names):
            out[f"volume_{name}"] = float(buf[k])
            if self.code[k] != VOID:
                out[f"mass_{name}"] = float(buf[self.nm + k])
        return out


def _flush():
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([_present, _thin, zone_eos, lagrange_split, relax, density_at_pressure, equilibrium_volumes,
                       fit_open_volumes, add_energy], [_eos.__file__], "mixed.deps.sha256")


_flush()
