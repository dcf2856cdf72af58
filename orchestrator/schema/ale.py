"""The ALE background's table of case.toml, ``[ale]`` (compressible flow on a fixed grid): schema
fragment, normaliser and cross-field checks, registered in :mod:`orchestrator.schema.registry`.

Normalised layout (``case["ale"]``, present when the file has the table)::

    {dimension, mode, grid: {lower, upper, cells}, boundaries: {face: "wall" | "outflow" |
     "far_field" | "zero_gradient" | "periodic" | {"inflow" | "far_field": {density, pressure,
     velocity[, relax, beta]}} | {"outflow": {[pressure, relax, beta]}} | {"piston": {velocity}} |
     {"piston": {velocity (vector), density, pressure}}} (every face
     of the dimension, "wall" unless given), materials: {name: {eos, ...}}, regions: [{material,
     [region], [density, pressure | specific_internal_energy], velocity}], energy_sources: [{energy,
     at}], obstacles: [{region, subsamples}], [fraction_samples], [hourglass], [viscosity]}

Numbers are floats; the solver's own defaults (viscosity, hourglass, fraction samples) are left to
the solver unless given.
"""
from __future__ import annotations

from solvers.expressions import BOOL

from .parts import BOX, NAME_PATTERN, integer, number, table, variants, vector
from .registry import register_table
from .rules import CaseError, check_expression, check_extent, check_faces, check_length, format_key, to_float


# ---- schema --------------------------------------------------------------------------------------
EOS_KEYS = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf", "cavitation_pressure"),
    "tait": ("eos", "rho0", "bulk_modulus", "exponent", "p0", "cavitation_pressure"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "rho0"),
    "mie_gruneisen": ("eos", "rho0", "c0", "s", "gamma0", "pressure_cutoff", "cavitation_pressure"),
    "void": ("eos",),   # empty space: volume only (several materials per zone)
}
EOS_REQUIRED = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf"),
    "tait": ("eos", "rho0", "bulk_modulus", "exponent"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "rho0"),
    "mie_gruneisen": ("eos", "rho0", "c0", "s", "gamma0"),
    "void": ("eos",),
}
FLUID = {
    "type": "object",
    "properties": {
        "eos": {"type": "string", "enum": list(EOS_KEYS)},
        "gamma": number("dimensionless", exclusiveMinimum=1),
        "p_inf": number("Pa", minimum=0),
        "rho0": number("kg/m^3", exclusiveMinimum=0),
        "bulk_modulus": number("Pa", exclusiveMinimum=0),
        "exponent": number("dimensionless", minimum=1),
        "p0": number("Pa"),
        # a liquid's pressure below it stops the run naming cavitation (the EOS has no phase change)
        "cavitation_pressure": number("Pa"),
        "A": number("Pa"),
        "B": number("Pa"),
        "R1": number("dimensionless", exclusiveMinimum=0),
        "R2": number("dimensionless", exclusiveMinimum=0),
        "omega": number("dimensionless", exclusiveMinimum=0),
        "c0": number("m/s", exclusiveMinimum=0),          # Mie-Grueneisen: us = c0 + s up
        "s": number("dimensionless", minimum=0),
        "gamma0": number("dimensionless", minimum=0),
        # the pressure never falls below it: the material gives way in tension (LS-DYNA's PC)
        "pressure_cutoff": number("Pa", maximum=0),
    },
    "additionalProperties": False,
    "required": ["eos"],
    "allOf": variants("eos", EOS_KEYS, EOS_REQUIRED),
}
# characteristic faces (solvers/ale/open_faces.py): relax = Poinsot-Lele's sigma, beta = the
# transverse (Engquist-Majda) coefficient
_TUNING = {"relax": number("dimensionless", minimum=0), "beta": number("dimensionless", minimum=0, maximum=1)}
_STATE = {"density": number("kg/m^3", exclusiveMinimum=0), "velocity": vector("m/s"), "pressure": number("Pa")}
# (material: the exterior's, one of ale.materials; with several, default the one that fills most of
# the face at the start)
_MATERIAL = {"material": {"type": "string", "minLength": 1}}
INFLOW = table({"inflow": table({**_STATE, **_TUNING, **_MATERIAL}, required=("density", "velocity", "pressure"))},
               required=("inflow",))
FAR_FIELD = table({"far_field": table({**_STATE, **_TUNING, **_MATERIAL},
                                      required=("density", "velocity", "pressure"))},
                  required=("far_field",))
OUTFLOW = table({"outflow": table({"pressure": number("Pa"), **_TUNING})}, required=("outflow",))
# a moving wall (Lagrangian mode: the normal speed) or a face held at a velocity pushing in gas of a
# given state (the face nodes at that velocity, its ghost zones at that state)
PISTON = table({"piston": table(
    {"velocity": {"oneOf": [number("m/s"), vector("m/s")],
                  "x-allowed": "must be a number (a moving wall) or a vector (a held face) (m/s)"},
     "density": number("kg/m^3", exclusiveMinimum=0), "pressure": number("Pa")},
    required=("velocity",))}, required=("piston",))
ALE_FACE = {"oneOf": [{"type": "string", "enum": ["wall", "outflow", "far_field", "zero_gradient", "periodic"]},
                      INFLOW, FAR_FIELD, OUTFLOW, PISTON],
            "x-allowed": "must be \"wall\", \"outflow\", \"far_field\", \"zero_gradient\", \"periodic\", "
                         "{ inflow = { density, velocity, pressure[, material, relax, beta] } }, { far_field = { "
                         "density, velocity, pressure[, material, relax, beta] } }, { outflow = { [pressure, relax, beta] } }, "
                         "{ piston = { velocity } } (a moving wall, Lagrangian mode) or { piston = { velocity = "
                         "[...], density, pressure } } (a face held at a velocity)"}
ALE_FACES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")
ALE_REGION = {
    "type": "object",
    "properties": {
        "material": {"type": "string", "minLength": 1},
        "region": {"type": "string", "minLength": 1},
        "density": number("kg/m^3", exclusiveMinimum=0),
        "pressure": number("Pa"),
        "specific_internal_energy": number("J/kg"),
        "velocity": vector("m/s"),
    },
    "additionalProperties": False,
    "required": ["material"],
    # a void region has no state at all (checked against the material below)
    "oneOf": [{"required": ["density", "pressure"]}, {"required": ["density", "specific_internal_energy"]},
              {"not": {"anyOf": [{"required": ["density"]}, {"required": ["pressure"]},
                                 {"required": ["specific_internal_energy"]}]}}],
    "x-allowed": "needs material, density and exactly one of pressure, specific_internal_energy "
                 "(a void material: none of them)",
}
ALE = table(
    {
        "mode": {"type": "string", "enum": ["eulerian", "lagrangian"]},
        "grid": BOX,
        "hourglass": number("dimensionless", minimum=0, maximum=0.125),
        "viscosity": table({"kind": {"type": "string", "enum": ["scalar", "monotonic"]},
                            "linear": number("dimensionless", minimum=0),
                            "quadratic": number("dimensionless", minimum=0)}),
        "boundaries": table({f: ALE_FACE for f in ALE_FACES}),
        "materials": {
            "type": "object",
            "minProperties": 1,
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": FLUID,
        },
        "regions": {"type": "array", "minItems": 1, "items": ALE_REGION},
        # several materials: region expressions sampled at k^dim points per zone (volume fractions)
        "fraction_samples": integer(minimum=1, maximum=64),
        "energy_sources": {"type": "array", "items": table(
            {"energy": number("J", exclusiveMinimum=0), "at": vector("m")}, required=("energy", "at"))},
        # static obstacles: blocked where the region holds (fraction of k^dim sub-points per zone)
        "obstacles": {"type": "array", "items": table(
            {"region": {"type": "string", "minLength": 1}, "subsamples": integer(minimum=1, maximum=64)},
            required=("region",))},
    },
    required=("grid", "materials", "regions"),
)


# ---- normalise and check -------------------------------------------------------------------------
def _normalise(a: dict, dim: int) -> dict:
    """The [ale] table with numbers as floats; solver defaults (viscosity, hourglass) left to the
    solver unless given."""
    grid = a["grid"]
    out = {
        "dimension": dim,
        "mode": a.get("mode", "eulerian"),
        "grid": {"lower": [to_float(v) for v in grid["lower"]],
                 "upper": [to_float(v) for v in grid["upper"]],
                 "cells": [int(v) for v in grid["cells"]]},
        "boundaries": {},
        "materials": {n: {k: (v if k == "eos" else to_float(v)) for k, v in m.items()}
                      for n, m in a["materials"].items()},
        "regions": [],
        "energy_sources": [{"energy": to_float(e["energy"]), "at": [to_float(v) for v in e["at"]]}
                           for e in a.get("energy_sources", [])],
        "obstacles": [{"region": o["region"], "subsamples": int(o.get("subsamples", 1))}
                      for o in a.get("obstacles", [])],
    }
    if "fraction_samples" in a:
        out["fraction_samples"] = int(a["fraction_samples"])
    if "hourglass" in a:
        out["hourglass"] = to_float(a["hourglass"])
    if "viscosity" in a:
        out["viscosity"] = {k: (v if k == "kind" else to_float(v)) for k, v in a["viscosity"].items()}
    faces = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")[: 2 * dim]
    for f in faces:
        face = a.get("boundaries", {}).get(f, "wall")
        if isinstance(face, dict):
            (kind, body), = face.items()
            face = {kind: {k: (v if k == "material" else [to_float(x) for x in v] if isinstance(v, list)
                               else to_float(v)) for k, v in body.items()}}
        out["boundaries"][f] = face
    for r in a["regions"]:
        reg = {k: (v if k in ("material", "region") else to_float(v))
               for k, v in r.items() if k != "velocity"}
        reg["velocity"] = [to_float(v) for v in r.get("velocity", [0.0] * dim)]
        out["regions"].append(reg)
    return out


def _check(ale: dict, raw: dict, dim: int) -> None:
    """Cross-field rules of [ale]: vector lengths, grid extent, periodic pairs, material references,
    region and obstacle expressions (obstacles in Eulerian mode only)."""
    for k in ("lower", "upper", "cells"):
        check_length(format_key(["ale", "grid", k]), raw["grid"][k], dim)
    for j, (lo, hi) in enumerate(zip(ale["grid"]["lower"], ale["grid"]["upper"])):
        if not hi > lo:
            raise CaseError("ale.grid.upper", raw["grid"]["upper"],
                            f"must be > lower component-wise (component {j})")
    check_extent("ale.grid", ale["grid"], raw["grid"])
    raw_faces = raw.get("boundaries", {})
    check_faces("ale", ale["boundaries"], raw_faces, dim)
    for a in "xyz"[:dim]:
        for f in (f"{a}_lower", f"{a}_upper"):
            face = ale["boundaries"][f]
            if not isinstance(face, dict):
                continue
            (kind, body), = face.items()
            moving_wall = kind == "piston" and not isinstance(body["velocity"], list)
            given = [k in body for k in ("density", "pressure")]
            if kind == "piston" and not (all(given) if not moving_wall else not any(given)):
                raise CaseError(format_key(["ale", "boundaries", f, "piston"]), raw_faces[f]["piston"],
                                "must be { velocity = u } (a moving wall, Lagrangian mode) or { velocity = [...], "
                                "density, pressure } (a face held at a velocity pushing in that state)")
            if moving_wall and ale["mode"] != "lagrangian":
                raise CaseError(format_key(["ale", "boundaries", f, "piston"]), raw_faces[f]["piston"],
                                "a piston with a scalar velocity is a moving wall and needs ale.mode = "
                                "\"lagrangian\" (the face nodes move with it); in Eulerian mode give "
                                "{ velocity = [...], density, pressure } (a face held at a velocity)")
            if "velocity" in body and not moving_wall:
                check_length(format_key(["ale", "boundaries", f, kind, "velocity"]), raw_faces[f][kind]["velocity"], dim)
            if "material" in body:
                solid = [m for m, v in ale["materials"].items() if v["eos"] != "void"]
                if body["material"] not in solid:
                    raise CaseError(format_key(["ale", "boundaries", f, kind, "material"]), body["material"],
                                    "must be one of the materials in [ale.materials] with an equation of "
                                    "state: " + ", ".join(solid))
    for i, (reg, r) in enumerate(zip(ale["regions"], raw["regions"])):
        base = ["ale", "regions", i]
        if reg["material"] not in ale["materials"]:
            raise CaseError(format_key(base + ["material"]), reg["material"],
                            "undefined material; defined in [ale.materials]: " + ", ".join(ale["materials"]))
        void = ale["materials"][reg["material"]]["eos"] == "void"
        if void and "density" in r:
            raise CaseError(format_key(base + ["density"]), r["density"],
                            f"material {reg['material']!r} is void: a void region has no density, "
                            "pressure or specific_internal_energy")
        if not void and "density" not in r:
            raise CaseError(format_key(base), r, "needs material, density and exactly one of pressure, "
                            "specific_internal_energy (a void material: none of them)")
        if "velocity" in r:
            check_length(format_key(base + ["velocity"]), r["velocity"], dim)
        if "region" in r:
            check_expression(format_key(base + ["region"]), r["region"], dim, BOOL)
    _check_mixed(ale, raw)
    lo, hi = ale["grid"]["lower"], ale["grid"]["upper"]
    for i, e in enumerate(raw.get("energy_sources", [])):
        check_length(format_key(["ale", "energy_sources", i, "at"]), e["at"], dim)
        if not all(a <= float(x) <= b for a, x, b in zip(lo, e["at"], hi)):
            raise CaseError(format_key(["ale", "energy_sources", i, "at"]), e["at"],
                            f"must lie in the grid, from ale.grid.lower = {raw['grid']['lower']} to "
                            f"ale.grid.upper = {raw['grid']['upper']} (m)")
    for i, o in enumerate(raw.get("obstacles", [])):
        check_expression(format_key(["ale", "obstacles", i, "region"]), o["region"], dim, BOOL)
        if ale["mode"] != "eulerian":
            raise CaseError(format_key(["ale", "obstacles"]), raw["obstacles"],
                            "obstacles need ale.mode = \"eulerian\" (the remap keeps material out of them)")


def _check_mixed(ale: dict, raw: dict) -> None:
    """Several materials per zone (or void): Eulerian mode, no inflow faces yet."""
    used = list(dict.fromkeys(r["material"] for r in ale["regions"]))
    voids = [m for m in used if ale["materials"][m]["eos"] == "void"]
    if len(used) == 1 and not voids:
        return
    if len(voids) == len(used):
        raise CaseError("ale.regions", [r["material"] for r in raw["regions"]],
                        "void only: at least one region needs a material with an equation of state")
    what = "several materials" if len(used) > 1 else "a void material"
    if ale["mode"] != "eulerian":
        raise CaseError("ale.mode", raw.get("mode"), f"{what} in ale.regions need mode = \"eulerian\"")
    for f, face in ale["boundaries"].items():
        if isinstance(face, dict) and "piston" in face:
            raise CaseError(format_key(["ale", "boundaries", f]), raw["boundaries"][f],
                            f"held pistons are not supported yet with {what} in ale.regions (inflow, "
                            f"outflow and far_field faces are)")
        if isinstance(face, dict) and voids and ("inflow" in face or "far_field" in face):
            raise CaseError(format_key(["ale", "boundaries", f]), raw["boundaries"][f],
                            "faces with a given state (inflow, far_field tables) are not supported yet "
                            "with a void material in ale.regions (its open faces are zero-gradient)")


def normalise(raw: dict | None, case: dict) -> dict | None:
    """The registry's hook: [ale] as given, or absent."""
    return None if raw is None else _normalise(raw, case["run"]["dimension"])


def check(case: dict, data: dict) -> None:
    """The registry's hook."""
    _check(case["ale"], data["ale"], case["run"]["dimension"])


# ---- registration (after [materials] 20, [lagrange] 30; before [[boundaries]] 50) -----------------
register_table("ale", ALE, normalise, check, order=40)
