"""The LAMMPS model of a case's ``[sph]`` table: the input commands (box, pair style, integration
fixes, walls, gravity) and the particles (positions, types, masses, densities, energies), built from
the normalised case (orchestrator/schema_sph.py).  Nothing here runs LAMMPS.

One LAMMPS atom type per body (its mass per particle is the body's density times its lattice cell
volume, so bodies of different density on the same lattice keep their own masses), types numbered
from 1 in body order.  The adapter's own fixes and computes have IDs starting with ``immerse``
(orchestrator/lammps_lines.py refuses case lines that touch them).
"""
from __future__ import annotations

import numpy as np

from solvers.particles import lattice_points

FREE_GROUP = "immerse_free"
FIXED_GROUP = "immerse_fixed"


def boundary_letters(sph: dict) -> list[str]:
    """LAMMPS boundary per axis: p (periodic), else f (fixed box: particles must stay inside; walls
    keep them, open faces need room in the domain)."""
    out = []
    for a in "xyz"[: sph["dimension"]]:
        out.append("p" if sph["boundaries"][f"{a}_lower"] == "periodic" else "f")
    if sph["dimension"] == 2:
        out.append("p")
    return out


def box_commands(sph: dict) -> list[str]:
    dim = sph["dimension"]
    lo, hi = list(sph["domain"]["lower"]), list(sph["domain"]["upper"])
    if dim == 2:  # a thin periodic slab around z = 0 (LAMMPS's 2-D runs keep z = 0)
        lo.append(-0.5 * sph["spacing"])
        hi.append(0.5 * sph["spacing"])
    skin = sph.get("neighbor_skin", 0.1 * sph["smoothing_length"])
    return [
        "units si",
        f"dimension {dim}",
        "atom_style sph",
        "atom_modify map array",
        "boundary " + " ".join(boundary_letters(sph)),
        "newton on",
        "region immerse_box block " + " ".join(f"{a!r} {b!r}" for a, b in zip(lo, hi)),
        f"create_box {len(sph['bodies'])} immerse_box",
        "comm_modify vel yes",  # SPH forces need the ghosts' velocities
        f"neighbor {skin!r} bin",
        "neigh_modify every 1 delay 0 check yes",
    ]


def particles(sph: dict):
    """(ids, types, x (n, dim), v (n, dim), rho (n,), esph (n,), masses per type (ntypes,)):
    ids 1..n in body order, types 1.. per body, esph the particle's internal energy (J: specific
    energy times mass, LAMMPS's convention)."""
    dim = sph["dimension"]
    xs, types, vs, rhos, es, masses = [], [], [], [], [], []
    for t, body in enumerate(sph["bodies"], start=1):
        x = lattice_points(body["region"], body["spacing"], dim)
        n = len(x)
        mass = body["density"] * body["spacing"] ** dim
        masses.append(mass)
        mat = sph["materials"][body["material"]]
        if mat["model"] == "idealgas":
            from orchestrator.schema_sph import IDEALGAS_GAMMA

            e_spec = body.get("specific_internal_energy",
                              body.get("pressure", 0.0) / ((IDEALGAS_GAMMA - 1.0) * body["density"]))
        else:
            e_spec = 0.0
        xs.append(x)
        types.append(np.full(n, t, np.int32))
        vs.append(np.tile(np.asarray(body["velocity"], float), (n, 1)))
        rhos.append(np.full(n, body["density"]))
        es.append(np.full(n, e_spec * mass))
    x = np.concatenate(xs)
    ids = np.arange(1, len(x) + 1, dtype=np.int32)
    return ids, np.concatenate(types), x, np.concatenate(vs), np.concatenate(rhos), np.concatenate(es), np.array(masses)


def physics_commands(sph: dict) -> list[str]:
    """Masses, groups, pair style and coefficients, integration, walls, gravity."""
    dim, h = sph["dimension"], sph["smoothing_length"]
    bodies, mats = sph["bodies"], sph["materials"]
    ntypes = len(bodies)
    cmds = []
    free = [str(t) for t, b in enumerate(bodies, start=1) if not b["fixed"]]
    fixed = [str(t) for t, b in enumerate(bodies, start=1) if b["fixed"]]
    cmds.append(f"group {FREE_GROUP} type {' '.join(free)}" if free else f"group {FREE_GROUP} empty")
    cmds.append(f"group {FIXED_GROUP} type {' '.join(fixed)}" if fixed else f"group {FIXED_GROUP} empty")
    model = next(iter(mats.values()))["model"]
    style = {"taitwater": "sph/taitwater", "idealgas": "sph/idealgas"}[model]
    if sph["density_summation"]:
        cmds.append(f"pair_style hybrid/overlay sph/rhosum 1 {style}")
        cmds.append(f"pair_coeff * * sph/rhosum {h!r}")
        prefix = f"{style} "
    else:
        cmds.append(f"pair_style {style}")
        prefix = ""
    for i in range(1, ntypes + 1):
        for j in range(i, ntypes + 1):
            mi, mj = mats[bodies[i - 1]["material"]], mats[bodies[j - 1]["material"]]
            visc = 0.5 * (mi["viscosity"] + mj["viscosity"])
            if model == "taitwater":
                # LAMMPS sets rho0 and c0 of type i from every i-j line: give type i's own
                cmds.append(f"pair_coeff {i} {j} {prefix}{mi['density']!r} {mi['sound_speed']!r} {visc!r} {h!r}")
            else:
                cmds.append(f"pair_coeff {i} {j} {prefix}{visc!r} {h!r}")
    if free:
        cmds.append(f"fix immerse_integrate {FREE_GROUP} sph")
    if fixed:
        cmds.append(f"fix immerse_stationary {FIXED_GROUP} sph/stationary")
    g = np.asarray(sph["gravity"], float)
    gmag = float(np.linalg.norm(g))
    if gmag > 0 and free:
        d = g / gmag
        vec = " ".join(repr(float(a)) for a in (list(d) + [0.0] * (3 - dim)))
        cmds.append(f"fix immerse_gravity {FREE_GROUP} gravity {gmag!r} vector {vec}")
    walls = []
    for a in "xyz"[:dim]:
        for side, edge in (("lower", "lo"), ("upper", "hi")):
            if sph["boundaries"][f"{a}_{side}"] == "wall":
                walls.append(f"{a}{edge} EDGE")
    if walls and free:
        cmds.append(f"fix immerse_walls {FREE_GROUP} wall/reflect {' '.join(walls)}")
    if dim == 2 and free:
        cmds.append(f"fix immerse_2d {FREE_GROUP} enforce2d")
    return cmds
