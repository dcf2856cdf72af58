"""The remap of several materials per zone (step 3 of mixed.py's step): one sweep per direction,
:func:`cumulative_fractions` of the zones, then :func:`sweep_fluxes` (each face's material fluxes)
and :func:`sweep_zones` (the conservative update of every material and of the zone).

Each face's swept volume ``SV`` is split over the materials of its donor zone by the exact volume of
the donor's piecewise-linear interface (Youngs' normals from the fraction field, the plane placed to
hold the fraction; solvers/ale/plic.py) inside the slab of width ``|SV| / V_donor`` at that face,
the interfaces nested in material order (onion skins of the cumulative fractions).  Where the donor
and its two neighbours along the sweep hold one and the same material the second-order limited flux
of remap.py is used instead.  Volume, mass and energy of every material are conserved to round-off.
mixed.Materials.sweep calls these; the state and the other steps are in mixed.py.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from solvers.ale import plic
from solvers.ale.eos import VOID
from solvers.ale.remap import face_flux

PURE = 1e-12       # a zone whose other materials hold less than this fraction is pure
MASS_ROUNDOFF = 1e-13  # a material's mass after a sweep below this share of its terms is round-off (booked)


@njit(cache=True)
def cumulative_fractions(vol, FC):
    """FC[k, z] = sum_{j <= k} vol[z, j] / sum_j vol[z, j] (all zones; 0 for an empty zone)."""
    nz, nm = vol.shape
    for z in range(nz):
        vz = 0.0
        for m in range(nm):
            vz += vol[z, m]
        acc = 0.0
        for m in range(nm - 1):
            acc += vol[z, m]
            FC[m, z] = acc / vz if vz > 0.0 else 0.0


@njit(cache=True)
def sweep_fluxes(vol, mass, ener, code, FC, rho, e, M, V, SV, F, ES, VF, MF, EF, solid, d, s, h, zlo, zhi,
                 zs):
    """Material volume, mass and energy fluxes (VF, MF, EF: (nz, nm), + towards +d) of the lower
    d-faces of the zones in range, and the zone totals F (mass) and ES (face specific energy) that
    the nodal part of the sweep and the boundary balances use.

    ``solid``: None, or per zone nonzero for a fully blocked zone (blocked.py: SV are then the
    aperture-scaled face volumes, V the open volumes).  As in remap.sweep_fluxes: a closed face or an
    upwind zone without volume carries nothing, a solid neighbour of a pure upwind zone is a wall
    ghost (a copy of it: zero one-sided slope), and a face never sweeps more than the upwind zone's
    volume (its share of it when its other face carries material out too): a moving body swept
    the zone's open part past the face within the step, the rest of the swept volume is body."""
    nm = vol.shape[1]
    dim = h.shape[0]
    tk = np.empty(nm)
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                sv = SV[z]
                for m in range(nm):
                    VF[z, m] = 0.0
                    MF[z, m] = 0.0
                    EF[z, m] = 0.0
                if sv > 0.0:
                    u = z - s
                    sg = 0.5
                    upper = True
                else:
                    u = z
                    sg = -0.5
                    upper = False
                vu = 0.0
                for m in range(nm):
                    vu += vol[u, m]
                if sv == 0.0 or (solid is not None and not (vu > 0.0)):
                    F[z] = 0.0
                    ES[z] = e[u]
                    continue
                capped = False
                if solid is not None:  # positivity (docstring)
                    so = SV[u] if sv > 0.0 else SV[z + s]
                    out = -so if sv > 0.0 else so
                    cap = vu if not (out > 0.0) else vu * abs(sv) / (abs(sv) + out)
                    if abs(sv) > cap:
                        sv = cap if sv > 0.0 else -cap
                        capped = True
                # the one material of the donor, if it is pure
                pure = -1
                for m in range(nm):
                    if vol[u, m] >= (1.0 - PURE) * vu:
                        pure = m
                if pure >= 0:
                    lo_wall = solid is not None and solid[u - s] != 0
                    hi_wall = solid is not None and solid[u + s] != 0
                    same = ((lo_wall or vol[u - s, pure] >= (1.0 - PURE) * (vol[u - s, :].sum()))
                            and (hi_wall or vol[u + s, pure] >= (1.0 - PURE) * (vol[u + s, :].sum())))
                    VF[z, pure] = sv
                    if code[pure] == VOID:
                        F[z] = 0.0
                        ES[z] = 0.0
                        continue
                    if same and not capped:  # second order, as remap.sweep_fluxes
                        rl = rho[u] if lo_wall else rho[u - s]
                        rh = rho[u] if hi_wall else rho[u + s]
                        el = e[u] if lo_wall else e[u - s]
                        eh = e[u] if hi_wall else e[u + s]
                        f, es = face_flux(sv, sg, rho[u], rl, rh, e[u], el, eh, V[u], M[u])
                    else:
                        f = sv * mass[u, pure] / vol[u, pure]
                        es = ener[u, pure]
                    MF[z, pure] = f
                    EF[z, pure] = f * es
                    F[z] = f
                    ES[z] = es
                    continue
                # mixed donor: nested PLIC cuts of the slab at the face
                fr = abs(sv) / vu
                if fr > 1.0:
                    fr = 1.0
                w = fr * h[d]
                gprev = 0.0
                for m in range(nm - 1):
                    fc = FC[m, u]
                    if not vol[u, m] > 0.0:
                        g = gprev
                    elif fc >= 1.0:
                        g = 1.0
                    else:
                        if dim == 2:
                            nx, ny = plic.youngs_normal_2d(FC[m], u, zs[0], zs[1], h[0], h[1])
                            g = plic.slab_fraction_2d(nx, ny, fc, h[0], h[1], d, upper, w)
                        else:
                            nx, ny, nz_ = plic.youngs_normal_3d(FC[m], u, zs[0], zs[1], zs[2], h[0], h[1], h[2])
                            g = plic.slab_fraction_3d(nx, ny, nz_, fc, h[0], h[1], h[2], d, upper, w)
                    if g < gprev:
                        g = gprev
                    if g > 1.0:
                        g = 1.0
                    tk[m] = (g - gprev) * abs(sv)
                    gprev = g
                tk[nm - 1] = (1.0 - gprev) * abs(sv)
                # never more than the donor holds: the excess goes to materials with room left
                exc = 0.0
                room = 0.0
                for m in range(nm):
                    if tk[m] > vol[u, m]:
                        exc += tk[m] - vol[u, m]
                        tk[m] = vol[u, m]
                    room += vol[u, m] - tk[m]
                if exc > 0.0 and room > 0.0:
                    for m in range(nm):
                        tk[m] += exc * (vol[u, m] - tk[m]) / room
                ftot = 0.0
                etot = 0.0
                sgn = 1.0 if sv > 0.0 else -1.0
                for m in range(nm):
                    vf = sgn * tk[m]
                    VF[z, m] = vf
                    if code[m] != VOID and vol[u, m] > 0.0 and mass[u, m] > 0.0:
                        mf = vf * mass[u, m] / vol[u, m]
                        MF[z, m] = mf
                        EF[z, m] = mf * ener[u, m]
                        ftot += mf
                        etot += mf * ener[u, m]
                F[z] = ftot
                ES[z] = etot / ftot if ftot != 0.0 else e[u]


@njit(cache=True)
def sweep_zones(vol, mass, ener, VF, MF, EF, M, V, rho, e, F, ES, SV, s, zlo, zhi, zs, out):
    """Conservative update of every material of the zones in range, and of the zone (M = sum of the
    material masses); out[0], out[1] += the mass and energy of the round-off residues it drops.  Written as increments so that a sweep without flux changes no bit (the sweep
    order then does not matter for a flow along one axis)."""
    nm = vol.shape[1]
    for i in range(zlo[0], zhi[0]):
        for j in range(zlo[1], zhi[1]):
            for k in range(zlo[2], zhi[2]):
                z = i * zs[0] + j * zs[1] + k * zs[2]
                Mz = 0.0
                for m in range(nm):
                    vn = vol[z, m] + (VF[z, m] - VF[z + s, m])
                    fl = MF[z, m]
                    fh = MF[z + s, m]
                    mn = mass[z, m] + (fl - fh)
                    # round-off only: the fluxes never take more than a donor holds
                    if vn < 0.0:
                        vn = 0.0
                    # a material emptied by its fluxes keeps their cancellation residue (a few ulp
                    # of them, of either sign): dropped, and booked (out); left, such residues
                    # (1e-30 kg) gave their nodes the remap's round-off as velocity, and the coarse
                    # FE penetrator's momentum balance went from 1.1e-12 to 1.3e-9
                    if mn <= MASS_ROUNDOFF * (mass[z, m] + abs(fl) + abs(fh)):
                        out[0] += mn
                        out[1] += mass[z, m] * ener[z, m] + (EF[z, m] - EF[z + s, m])
                        mn = 0.0
                    if mn > 0.0:
                        en = ener[z, m]
                        ener[z, m] = en + ((EF[z, m] - fl * en) - (EF[z + s, m] - fh * en)) / mn
                    else:
                        ener[z, m] = 0.0
                    vol[z, m] = vn
                    mass[z, m] = mn
                    Mz += mn
                fl = F[z]
                fh = F[z + s]
                if Mz > 0.0:
                    ez = e[z]
                    e[z] = ez + (fl * (ES[z] - ez) - fh * (ES[z + s] - ez)) / Mz
                else:
                    e[z] = 0.0
                vz = V[z] + SV[z] - SV[z + s]
                V[z] = vz
                M[z] = Mz
                rho[z] = Mz / vz if vz > 0.0 else 0.0  # (a solid zone: no volume, no material)


def _flush():
    from solvers.ale import remap as _r
    from solvers.numba_cache import flush_stale_cache

    flush_stale_cache([cumulative_fractions, sweep_fluxes, sweep_zones], [plic.__file__, _r.__file__],
                      "mixed_remap.deps.sha256")


_flush()
