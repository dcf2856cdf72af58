"""The LAMMPS model of a case's ``[sph]`` table whose materials are MACHDYN solids (``model =
"tlsph"``: pair smd/tlsph, total-Lagrangian SPH, Ganzenmueller 2015): input commands and particles,
built from the normalised case (orchestrator/schema/sph.py).  Nothing here runs LAMMPS.

What differs from the SPH package's fluids (adapters/lammps_model.py):

* atom_style smd: each particle carries its own mass (rmass), volume (vfrac), kernel radius
  (radius = h / 2: a pair interacts within radius_i + radius_j = h, the same support as the fluids'
  h), contact radius, reference position x0, body (molecule: particles of different bodies never
  bond) and the history the constitutive update integrates: the unrotated Cauchy stress
  (smd_stress), the effective plastic strain and its rate, damage, and the deformation gradient of
  the reference configuration (smd_data_9).
* one atom type per material (tlsph interacts only within a type; masses are per particle), a
  group named ``tlsph`` (the pair style requires it), newton off, ghost velocities (PreCompute's
  smoothed velocity differences read ghosts' v).
* held particles (a body's ``fixed`` or its ``clamp`` region) stay bonded to their body (they carry
  stress) and are integrated with the rest, their force zeroed by a setforce after every other
  post-force fix: they never move (v = vest = 0, x = x0), and fix smd/integrate_tlsph still adds
  their share of each bond's energy to their esph (PairTlsph gives each end of a bond half its
  work, 0.5 f.(vest_j - vest_i)).  Left out of the integration, their esph stayed 0 and the bonds
  to the clamp lost half their strain energy: a clamped plate set moving at 1 m/s was up to 8.0e-3
  of its energy short in 400 steps (3.4e-5 with it; tests/adapters/test_sph.py).
* 2-D: LAMMPS needs z periodic, and PairTlsph::ComputeForces applies the minimum image to a
  reference distance before it is assigned (its first pair on each rank reads an uninitialised
  vector), so a thin periodic z slab can fail with "Atoms have moved too far apart".  The z extent
  is made as deep as LAMMPS's neighbour bins allow (+-4e8 h; +-1e6 h still failed on a
  plate): the z coordinates of a 2-D run stay 0 and nothing else depends on it.
"""
from __future__ import annotations

import numpy as np

from adapters.lammps_model import (FIXED_GROUP, FREE_GROUP, boundary_letters, free_axes, gravity_and_walls,
                                   hold_commands)
from solvers.particles import body_points, points_in

DEFAULTS = {"viscosity_q1": 1.0, "viscosity_q2": 0.0, "hourglass": 10.0, "heat_capacity": 1.0,
            "strength": "linear", "eos": "linear"}
"""MACHDYN's example values: Q1 = 1 and Q2 = 0 (linear artificial viscosity), hourglass
amplitude 10, heat capacity 1 (only Johnson-Cook's temperature term reads it)."""

CREATED = (("vfrac", 1, False), ("rmass", 1, False), ("radius", 1, False), ("contact_radius", 1, False),
           ("molecule", 1, True), ("x0", 3, False), ("vest", 3, False), ("esph", 1, False))
"""Per-atom arrays set by id after create_atoms (x and v are given to create_atoms)."""
HISTORY = (("smd_data_9", 9, False), ("smd_stress", 6, False), ("eff_plastic_strain", 1, False),
           ("eff_plastic_strain_rate", 1, False), ("damage", 1, False))
"""What the constitutive update integrates (stress and plastic strain are rate forms: LAMMPS's
setup force computation advances them once more, so a reload puts them back after it)."""
CHECKPOINT = (("x", 3, False), ("v", 3, False), ("f", 3, False), ("desph", 1, False)) + CREATED + HISTORY + (
    ("type", 1, True), ("image", 1, True), ("mask", 1, True))
AFTER_SETUP = (("vest", 3, False), ("esph", 1, False), ("f", 3, False), ("desph", 1, False)) + HISTORY
DENSITY = "c_immerse_rho"
"""compute smd/rho: the current density (mass over the deformed volume)."""
REFERENCE = "x0"
"""A reload creates the particles at their reference positions first: the pair's partner list and
kernel weights are built from the positions at set-up (FixSMD_TLSPH_ReferenceConfiguration::setup),
which were x0 when the run began."""


def signal_speed(mat: dict) -> float:
    """The P-wave speed sqrt((lambda + 2 mu) / rho0) LAMMPS uses as tlsph's signal velocity."""
    e, nu, rho = mat["youngs_modulus"], mat["poisson_ratio"], mat["density"]
    lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = e / (2.0 * (1.0 + nu))
    return float(np.sqrt((lam + 2.0 * mu) / rho))


def atom_types(sph: dict) -> tuple[list[int], list[dict]]:
    """(type of each body, [{material} of each type]): one type per material."""
    names = []
    for body in sph["bodies"]:
        if body["material"] not in names:
            names.append(body["material"])
    return [names.index(b["material"]) + 1 for b in sph["bodies"]], [{"material": n} for n in names]


def box_commands(sph: dict) -> list[str]:
    dim, h = sph["dimension"], sph["smoothing_length"]
    lo, hi = list(sph["domain"]["lower"]), list(sph["domain"]["upper"])
    if dim == 2:  # see the module docstring: a deep z slab
        lo.append(-4e8 * h)
        hi.append(4e8 * h)
    skin = sph.get("neighbor_skin", 0.1 * h)
    return [
        "units si",
        f"dimension {dim}",
        "atom_style smd",
        "atom_modify map array",
        "boundary " + " ".join(boundary_letters(sph)),
        "newton off",  # PairTlsph::init_style refuses newton pair on
        "comm_modify vel yes",
        "region immerse_box block " + " ".join(f"{a!r} {b!r}" for a, b in zip(lo, hi)),
        f"create_box {len(atom_types(sph)[1])} immerse_box",
        f"neighbor {skin!r} bin",
        "neigh_modify every 1 delay 0 check yes",
    ]


def particles(sph: dict) -> dict:
    """Per-particle arrays in id order (ids 1..n in body order)."""
    dim, h = sph["dimension"], sph["smoothing_length"]
    type_of_body, _ = atom_types(sph)
    parts = {k: [] for k in ("x", "type", "v", "mass", "vfrac", "fixed", "body", "contact_radius")}
    for i, body in enumerate(sph["bodies"]):
        x = body_points(body, dim)
        n = len(x)
        vol = body["spacing"] ** dim
        fixed = np.full(n, body["fixed"])
        if "clamp" in body:
            fixed |= points_in(body["clamp"], x, dim)
        parts["x"].append(x)
        parts["type"].append(np.full(n, type_of_body[i], np.int32))
        velocity = np.asarray(body["velocity"], float) * free_axes(body, dim)
        parts["v"].append(np.where(fixed[:, None], 0.0, velocity[None, :]))
        parts["mass"].append(np.full(n, body["density"] * vol))
        parts["vfrac"].append(np.full(n, vol))
        parts["fixed"].append(fixed)
        parts["body"].append(np.full(n, i, np.int64))
        parts["contact_radius"].append(np.full(n, 0.5 * body["spacing"]))
    out = {k: np.concatenate(v) for k, v in parts.items()}
    n = len(out["x"])
    out["ids"] = np.arange(1, n + 1, dtype=np.int32)
    out["rmass"] = out["mass"]
    out["radius"] = np.full(n, 0.5 * h)
    out["molecule"] = (out["body"] + 1).astype(np.int32)
    x3 = np.zeros((n, 3))
    x3[:, :dim] = out["x"]
    out["x0"] = x3
    out["vest"] = np.zeros((n, 3))
    out["vest"][:, :dim] = out["v"]
    out["esph"] = np.zeros(n)
    return out


def _strength(s) -> list[str]:
    if s == "linear":
        return ["*STRENGTH_LINEAR"]
    if "linear_plastic" in s:
        p = s["linear_plastic"]
        return ["*STRENGTH_LINEAR_PLASTIC", repr(p["yield_stress"]), repr(p.get("hardening", 0.0))]
    jc = s["johnson_cook"]
    return ["*JOHNSON_COOK"] + [repr(float(jc[k])) for k in ("A", "B", "n", "C", "strain_rate0",
                                                              "room_temperature", "melt_temperature", "m")]


def _eos(e) -> list[str]:
    if e == "linear":
        return ["*EOS_LINEAR"]
    if e == "none":
        return ["*EOS_NONE"]
    s = e["shock"]
    return ["*EOS_SHOCK", repr(s["c0"]), repr(s["s"]), repr(s["gamma"])]


def pair_commands(sph: dict, reload: bool = False) -> list[str]:
    """pair_style smd/tlsph and one pair_coeff per type.  A reload makes a new pair instance (re-issuing
    the same style only re-reads its settings, so "none" first): it skips its first force
    computation and its new partner fix builds the reference partner list afresh at the next
    set-up.  The old partner fix goes first: PairTlsph::init_style takes the last fix as the one it
    created, which a fix replaced in place (same ID) is not."""
    _, kinds = atom_types(sph)
    cmds = (["unfix SMD_TLSPH_NEIGHBORS", "pair_style none"] if reload else []) + ["pair_style smd/tlsph"]
    for t, k in enumerate(kinds, start=1):
        m = {**DEFAULTS, **sph["materials"][k["material"]]}
        common = [m["density"], m["youngs_modulus"], m["poisson_ratio"], m["viscosity_q1"], m["viscosity_q2"],
                  m["hourglass"], m["heat_capacity"]]
        cmds.append(" ".join([f"pair_coeff {t} {t} *COMMON"] + [repr(float(a)) for a in common]
                             + _strength(m["strength"]) + _eos(m["eos"]) + ["*END"]))
    return cmds


def _id_ranges(ids: np.ndarray) -> list[str]:
    """Sorted ids as LAMMPS ranges "a:b" (runs of consecutive ids)."""
    if len(ids) == 0:
        return []
    breaks = np.flatnonzero(np.diff(ids) != 1)
    starts = np.concatenate([[ids[0]], ids[breaks + 1]])
    ends = np.concatenate([ids[breaks], [ids[-1]]])
    return [f"{a}:{b}" if b > a else f"{a}" for a, b in zip(starts, ends)]


def setup_commands(sph: dict, parts: dict) -> list[str]:
    """Groups, pair style and coefficients, integration, walls, gravity (after the particles)."""
    cmds = ["group tlsph type " + " ".join(str(t) for t in range(1, len(atom_types(sph)[1]) + 1))]
    fixed_ids = parts["ids"][parts["fixed"]]
    ranges = _id_ranges(fixed_ids)
    cmds.append(f"group {FIXED_GROUP} id {' '.join(ranges)}" if ranges else f"group {FIXED_GROUP} empty")
    cmds.append(f"group {FREE_GROUP} subtract all {FIXED_GROUP}")
    cmds += pair_commands(sph)
    free = not parts["fixed"].all()
    if free:  # every particle: the held ones for their esph (module docstring), held by the setforce below
        cmds.append("fix immerse_integrate all smd/integrate_tlsph")
    cmds += gravity_and_walls(sph, free) + hold_commands(sph, parts)
    if free and ranges:
        cmds.append(f"fix immerse_clamp {FIXED_GROUP} setforce 0.0 0.0 0.0")
    cmds += ["compute immerse_stress all smd/tlsph/stress", "compute immerse_rho all smd/rho",
             "compute immerse_dt all smd/tlsph/dt"]
    return cmds
