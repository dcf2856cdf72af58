"""The LAMMPS model of a case's ``[sph]`` table: the input commands (box, pair style, integration
fixes, walls, gravity) and the particles (positions, types, masses, densities, energies), built from
the normalised case (orchestrator/schema/sph.py).  Nothing here runs LAMMPS.

A LAMMPS atom type per distinct (material, particle mass, fixed) of the bodies, numbered from 1 in
order of first appearance: atom_style sph keeps masses per type (a particle's mass is its body's
density times its lattice cell volume), and bodies that share all three share a type.  Why not a
type per body: LAMMPS's pair sph/idealgas symmetrises the cutoff of a type pair but not its
viscosity (PairSPHIdealGas::init_one), so the viscous force between two types depends on which
particle LAMMPS takes as "i", which changes with the domain decomposition (measured: 0.14 dx
apart after 100 steps of the two-type shock tube on 1 and 2 ranks, 5e-14 with one type).  Equal
particle masses (e.g. the lighter gas on a coarser lattice) keep a gas case on one type.  The adapter's own fixes and computes have IDs starting with ``immerse``
(adapters/lammps_lines.py refuses case lines that touch them).
"""
from __future__ import annotations

import numpy as np

from solvers.particles import IDEALGAS_GAMMA, body_points, tait_density

FREE_GROUP = "immerse_free"
FIXED_GROUP = "immerse_fixed"


def boundary_letters(sph: dict) -> list[str]:
    """LAMMPS boundary per face pair: p (periodic); per face f (a wall: the box stays, wall/reflect
    keeps the particles in) or s (open: the box follows the particles, shrink-wrapped)."""
    out = []
    for a in "xyz"[: sph["dimension"]]:
        faces = [sph["boundaries"][f"{a}_{side}"] for side in ("lower", "upper")]
        out.append("p" if faces[0] == "periodic" else "".join("f" if f == "wall" else "s" for f in faces))
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
        f"create_box {len(atom_types(sph)[1])} immerse_box",
        # (no "comm_modify vel yes": the SPH pair styles use the velocity estimate vest, which atom_style
        # sph sends to the ghosts with the positions; measured: 2 ranks = 1 rank to 1e-14 without it)
        f"neighbor {skin!r} bin",
        "neigh_modify every 1 delay 0 check yes",
    ]


def atom_types(sph: dict) -> tuple[list[int], list[dict]]:
    """(type of each body, [{material, mass, fixed} of each type]) (see the module docstring)."""
    dim = sph["dimension"]
    keys, of_body = [], []
    for body in sph["bodies"]:
        key = {"material": body["material"], "mass": body["density"] * body["spacing"] ** dim,
               "fixed": body["fixed"]}
        if key not in keys:
            keys.append(key)
        of_body.append(keys.index(key) + 1)
    return of_body, keys


def hydrostatic_density(body: dict, mat: dict, x: np.ndarray, gravity) -> np.ndarray:
    """Tait's density under the weight of the body's own column: p = rho0 |g| depth,
    rho = rho0 (1 + p / B)^(1/7), B = c0^2 rho0 / 7, depth below the body's top along g (its highest
    particle plus half a spacing)."""
    g = np.asarray(gravity, float)
    gmag = float(np.linalg.norm(g))
    down = x @ (g / gmag)
    depth = down - (down.min() - 0.5 * body["spacing"])
    return tait_density(mat, mat["density"] * gmag * depth)


CREATED = (("vest", 3, False), ("rho", 1, False), ("esph", 1, False))
"""Per-atom arrays set by id after create_atoms (x and v are given to create_atoms)."""
CHECKPOINT = (("x", 3, False), ("v", 3, False), ("vest", 3, False), ("rho", 1, False), ("esph", 1, False),
              ("f", 3, False), ("drho", 1, False), ("desph", 1, False), ("type", 1, True), ("image", 1, True),
              ("mask", 1, True))
"""Every per-atom array a step reads (image: periodic crossings; mask: group membership)."""
AFTER_SETUP = (("vest", 3, False), ("rho", 1, False), ("esph", 1, False), ("f", 3, False), ("drho", 1, False),
               ("desph", 1, False))
"""Restored after a reload's set-up run: what LAMMPS's set-up recomputes differently from the step
it replaces (fix sph sets vest = v, sph/rhosum sums rho afresh, the forces and rates are those of
that state)."""
REFERENCE = None
"""(tlsph's reload creates the particles at their reference positions first; fluids have none.)"""
DENSITY = "rho"
"""The per-atom density the adapter gathers (volumes m / rho, output)."""


def particles(sph: dict) -> dict:
    """Per-particle arrays in id order (ids 1..n in body order): x (n, dim), v, vest (n, 3), rho,
    esph (the particle's internal energy, J: specific energy times mass, LAMMPS's convention),
    type, mass, fixed, body (the body index)."""
    dim = sph["dimension"]
    type_of_body, kinds = atom_types(sph)
    masses = np.array([k["mass"] for k in kinds])
    xs, types, vs, rhos, es, bodies = [], [], [], [], [], []
    for i, body in enumerate(sph["bodies"]):
        t = type_of_body[i]
        x = body_points(body, dim)
        n = len(x)
        mass = masses[t - 1]
        mat = sph["materials"][body["material"]]
        if mat["model"] == "idealgas":
            e_spec = body.get("specific_internal_energy",
                              body.get("pressure", 0.0) / ((IDEALGAS_GAMMA - 1.0) * body["density"]))
        else:
            e_spec = 0.0
        xs.append(x)
        types.append(np.full(n, t, np.int32))
        vs.append(np.tile(np.asarray(body["velocity"], float) * free_axes(body, dim), (n, 1)))
        rho = (hydrostatic_density(body, mat, x, sph["gravity"]) if body.get("hydrostatic")
               else np.full(n, body["density"]))
        rhos.append(rho)
        es.append(np.full(n, e_spec * mass))
        bodies.append(np.full(n, i, np.int64))
    x = np.concatenate(xs)
    n = len(x)
    t = np.concatenate(types)
    v = np.concatenate(vs)
    vest = np.zeros((n, 3))
    vest[:, :dim] = v
    fixed_of_type = np.array([False] + [k["fixed"] for k in kinds])
    return {"ids": np.arange(1, n + 1, dtype=np.int32), "x": x, "v": v, "vest": vest, "rho": np.concatenate(rhos),
            "esph": np.concatenate(es), "type": t, "mass": np.concatenate([[0.0], masses])[t],
            "fixed": fixed_of_type[t], "body": np.concatenate(bodies)}


def setup_commands(sph: dict, parts: dict) -> list[str]:
    """Per-type masses, then the physics (after the particles)."""
    _, kinds = atom_types(sph)
    return ([f"mass {t} {float(k['mass'])!r}" for t, k in enumerate(kinds, start=1)] + physics_commands(sph)
            + hold_commands(sph, parts))


def physics_commands(sph: dict) -> list[str]:
    """Groups, pair style and coefficients, integration, walls, gravity."""
    h = sph["smoothing_length"]
    mats = sph["materials"]
    _, kinds = atom_types(sph)
    ntypes = len(kinds)
    cmds = []
    free = [str(t) for t, k in enumerate(kinds, start=1) if not k["fixed"]]
    fixed = [str(t) for t, k in enumerate(kinds, start=1) if k["fixed"]]
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
            mi, mj = mats[kinds[i - 1]["material"]], mats[kinds[j - 1]["material"]]
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
    return cmds + gravity_and_walls(sph, bool(free))


def hold_commands(sph: dict, parts: dict) -> list[str]:
    """Each body's held velocity components (``hold``): zero force on them after every other force
    (the last post-force fix).  A body's particles are one id range (ids in body order); they start
    with those components zero (particles() of each family)."""
    cmds = []
    for i, body in enumerate(sph["bodies"]):
        if body["hold"]:
            ids = parts["ids"][parts["body"] == i]
            comps = " ".join("0.0" if a in body["hold"] else "NULL" for a in "xyz")
            cmds += [f"group immerse_hold{i} id {ids.min()}:{ids.max()}",
                     f"fix immerse_hold{i} immerse_hold{i} setforce {comps}"]
    return cmds


def free_axes(body: dict, dim: int) -> np.ndarray:
    """(dim,) 1.0 for a velocity component the body leaves free, 0.0 for one it holds."""
    return np.array([0.0 if a in body["hold"] else 1.0 for a in "xyz"[:dim]])


def held_components(sph: dict, body: np.ndarray) -> np.ndarray:
    """(n, dim) 1.0 where a particle's velocity component is free, 0.0 where its body holds it."""
    return np.array([free_axes(b, sph["dimension"]) for b in sph["bodies"]])[body]


def gravity_and_walls(sph: dict, free: bool) -> list[str]:
    """Gravity, reflecting walls and the 2-D constraint on the moving particles (shared by the
    fluids and the tlsph solids, adapters/lammps_tlsph.py)."""
    dim = sph["dimension"]
    if not free:
        return []
    cmds = []
    g = np.asarray(sph["gravity"], float)
    gmag = float(np.linalg.norm(g))
    if gmag > 0:
        d = g / gmag
        vec = " ".join(repr(float(a)) for a in (list(d) + [0.0] * (3 - dim)))
        cmds.append(f"fix immerse_gravity {FREE_GROUP} gravity {gmag!r} vector {vec}")
    walls = []
    for a in "xyz"[:dim]:
        for side, edge in (("lower", "lo"), ("upper", "hi")):
            if sph["boundaries"][f"{a}_{side}"] == "wall":
                walls.append(f"{a}{edge} EDGE")
    if walls:
        cmds.append(f"fix immerse_walls {FREE_GROUP} wall/reflect {' '.join(walls)}")
    if dim == 2:
        cmds.append(f"fix immerse_2d {FREE_GROUP} enforce2d")
    return cmds
