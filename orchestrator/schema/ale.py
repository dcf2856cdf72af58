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

from .parts import BOX, NAME_PATTERN, doc, integer, number, table, variants, vector
from .registry import register_table
from .rules import CaseError, check_expression, check_extent, check_faces, check_length, format_key, to_float


# ---- schema --------------------------------------------------------------------------------------
EOS_KEYS = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf", "cavitation_pressure"),
    "tait": ("eos", "density", "bulk_modulus", "exponent", "p0", "cavitation_pressure"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "density"),
    "mie_gruneisen": ("eos", "density", "c0", "s", "gamma0", "pressure_cutoff", "cavitation_pressure"),
    "void": ("eos",),   # empty space: volume only (several materials per zone)
}
EOS_REQUIRED = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf"),
    "tait": ("eos", "density", "bulk_modulus", "exponent"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "density"),
    "mie_gruneisen": ("eos", "density", "c0", "s", "gamma0"),
    "void": ("eos",),
}
# the equations the EOS keys are named in (solvers/ale/eos.py)
_JWL = "JWL's p = A (1 - omega/(R1 V)) exp(-R1 V) + B (1 - omega/(R2 V)) exp(-R2 V) + omega rho e, V = rho0/rho"
_MG = "the Mie-Grueneisen Hugoniot us = c0 + s up"
FLUID = {
    "type": "object",
    "properties": {
        "eos": doc({"type": "string", "enum": list(EOS_KEYS)},
                   "Equation of state p(rho, e). ideal_gas: p = (gamma - 1) rho e; stiffened_gas: p = (gamma - 1) "
                   "rho e - gamma p_inf (a liquid as a stiff gas); tait: p = p0 + K/n ((rho/rho0)^n - 1) "
                   "(barotropic liquid); jwl: Jones-Wilkins-Lee detonation products; mie_gruneisen: p = p_H + "
                   "gamma0 rho0 (e - e_H) about the us = c0 + s up Hugoniot (solids and liquids under shock, "
                   "LS-DYNA's *EOS_GRUNEISEN); void: empty space, volume only (several materials per zone)."),
        "gamma": number("dimensionless", exclusiveMinimum=1,
                        description="ideal_gas, stiffened_gas: the ratio of specific heats gamma in p = (gamma - "
                                    "1) rho e (- gamma p_inf)."),
        "p_inf": number("Pa", minimum=0, description="stiffened_gas: the stiffening pressure p_inf in p = (gamma - "
                                                     "1) rho e - gamma p_inf (c^2 = gamma (p + p_inf) / rho)."),
        "density": number("kg/m^3", exclusiveMinimum=0,
                          description="The reference density rho0 (the same key as [materials] and [sph] "
                                      "use; the older spelling rho0 is read with a note). tait: the density at "
                                      "p = p0; jwl: the unreacted explosive's, V = rho0/rho; mie_gruneisen: "
                                      "the density at zero pressure and energy, where the Hugoniot starts."),
        "bulk_modulus": number("Pa", exclusiveMinimum=0,
                               description="tait: the bulk modulus K at rho0 (the sound speed there: "
                                           "sqrt(K / rho0))."),
        "exponent": number("dimensionless", minimum=1,
                           description="tait: the exponent n in p = p0 + K/n ((rho/rho0)^n - 1) (about 7 for "
                                       "water)."),
        "p0": number("Pa", default=0.0,  # (solvers/ale/eos.py _SCHEMA)
                     description="tait: the reference pressure at rho0."),
        # a liquid's pressure below it stops the run naming cavitation (the EOS has no phase change)
        "cavitation_pressure": number("Pa", description="A zone whose pressure falls below this stops the run "
                                                        "naming cavitation (the EOS has no phase change; absent: "
                                                        "the EOS holds any tension)."),
        "A": number("Pa", description=f"jwl: the first pressure coefficient A in {_JWL}."),
        "B": number("Pa", description=f"jwl: the second pressure coefficient B in {_JWL}."),
        "R1": number("dimensionless", exclusiveMinimum=0, description=f"jwl: the first decay constant R1 in {_JWL}."),
        "R2": number("dimensionless", exclusiveMinimum=0,
                     description=f"jwl: the second decay constant R2 in {_JWL}."),
        "omega": number("dimensionless", exclusiveMinimum=0,
                        description=f"jwl: the Grueneisen coefficient omega of the products in {_JWL}."),
        "c0": number("m/s", exclusiveMinimum=0,          # Mie-Grueneisen: us = c0 + s up
                     description=f"mie_gruneisen: the bulk sound speed c0, intercept of {_MG}."),
        "s": number("dimensionless", minimum=0, description=f"mie_gruneisen: the slope s of {_MG}."),
        "gamma0": number("dimensionless", minimum=0,
                         description="mie_gruneisen: the Grueneisen gamma0 at rho0 (gamma rho = gamma0 rho0)."),
        # the pressure never falls below it: the material gives way in tension (LS-DYNA's PC)
        "pressure_cutoff": number("Pa", maximum=0,
                                  description="mie_gruneisen: the least pressure: the material gives way in "
                                              "tension instead of pulling (LS-DYNA's PC; absent: none)."),
    },
    "additionalProperties": False,
    "required": ["eos"],
    "allOf": variants("eos", EOS_KEYS, EOS_REQUIRED),
    "description": "A material of the background, by the name its regions use: an equation of state.",
}
# characteristic faces (solvers/ale/open_faces.py): relax = Poinsot-Lele's sigma, beta = the
# transverse (Engquist-Majda) coefficient; their defaults: open_faces.DEFAULT_RELAX, DEFAULT_BETA (not
# imported: the fragments import no solver module)
_TUNING = {"relax": number("dimensionless", minimum=0, default=0.25,
                           description="How firmly the face holds its given state or pressure against slow drift "
                                       "(Poinsot-Lele's sigma; 0: not at all, perfectly non-reflecting)."),
           "beta": number("dimensionless", minimum=0, maximum=1, default=0.64,
                          description="Weight of the transverse (Engquist-Majda) term that absorbs oblique waves "
                                      "(0: off; 0.64: the least largest reflection over 0-60 degrees).")}
_STATE = {"density": number("kg/m^3", exclusiveMinimum=0, description="The exterior state's density."),
          "velocity": vector("m/s", description="The exterior state's velocity."),
          "pressure": number("Pa", description="The exterior state's pressure.")}
# (material: the exterior's, one of ale.materials; with several, default the one that fills most of
# the face at the start)
_MATERIAL = {"material": {"type": "string", "minLength": 1,
                          "description": "Several materials: the exterior's material, one of ale.materials "
                                         "(default: the one filling most of the face at the start)."}}
INFLOW = table({"inflow": table({**_STATE, **_TUNING, **_MATERIAL}, required=("density", "velocity", "pressure"),
                                description="A characteristic inflow face feeding in the given exterior state "
                                            "(subsonic or supersonic); waves leave through it.")},
               required=("inflow",))
FAR_FIELD = table({"far_field": table({**_STATE, **_TUNING, **_MATERIAL},
                                      required=("density", "velocity", "pressure"),
                                      description="A characteristic face to a free stream of the given state, "
                                                  "in or out.")},
                  required=("far_field",))
OUTFLOW = table({"outflow": table({"pressure": number("Pa", description="The pressure the face relaxes to "
                                                                         "(absent: the state it starts with is "
                                                                         "held)."), **_TUNING},
                                  description="A characteristic outflow face that lets every wave leave.")},
                required=("outflow",))
# a moving wall (Lagrangian mode: the normal speed) or a face held at a velocity pushing in gas of a
# given state (the face nodes at that velocity, its ghost zones at that state)
PISTON = table({"piston": table(
    {"velocity": {"oneOf": [number("m/s"), vector("m/s")],
                  "x-allowed": "must be a number (a moving wall) or a vector (a held face) (m/s)",
                  "description": "A number: the wall's speed into the domain (a moving wall, Lagrangian mode); a "
                                 "vector: the velocity the face is held at (with density and pressure)."},
     "density": number("kg/m^3", exclusiveMinimum=0, description="Held face: the density of the gas pushed in."),
     "pressure": number("Pa", description="Held face: the pressure of the gas pushed in.")},
    required=("velocity",),
    description="A moving wall ({ velocity = u }, Lagrangian mode) or a face held at a velocity pushing in gas of "
                "a given state ({ velocity = [...], density, pressure }; reflects returning waves).")},
    required=("piston",))
ALE_FACE = {"oneOf": [{"type": "string", "enum": ["wall", "outflow", "far_field", "zero_gradient", "periodic"]},
                      INFLOW, FAR_FIELD, OUTFLOW, PISTON],
            "default": "wall",   # (normalise below; solvers/ale/solver.py)
            "description": "The condition on this face of the grid. wall: a free-slip wall (normal velocity 0); "
                           "outflow: a characteristic face holding the exterior state it starts with (waves leave); "
                           "far_field: a free stream at the state it starts with; zero_gradient: ghost zones copy "
                           "the zones inside (reflects); periodic: wraps to the opposite face (set both); or one "
                           "of the tables inflow, far_field, outflow, piston.",
            "x-allowed": "must be \"wall\", \"outflow\", \"far_field\", \"zero_gradient\", \"periodic\", "
                         "{ inflow = { density, velocity, pressure[, material, relax, beta] } }, { far_field = { "
                         "density, velocity, pressure[, material, relax, beta] } }, { outflow = { [pressure, relax, beta] } }, "
                         "{ piston = { velocity } } (a moving wall, Lagrangian mode) or { piston = { velocity = "
                         "[...], density, pressure } } (a face held at a velocity)"}
ALE_FACES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")
ALE_REGION = {
    "type": "object",
    "properties": {
        "material": {"type": "string", "minLength": 1,
                     "description": "The material filling the region: one of ale.materials."},
        "region": {"type": "string", "minLength": 1,
                   "description": "Where the state applies: a boolean expression in the coordinates x, y (, z), "
                                  "e.g. \"x > 0.5\" (absent: the whole grid)."},
        "density": number("kg/m^3", exclusiveMinimum=0, description="Initial density."),
        "pressure": number("Pa", description="Initial pressure (the internal energy follows from the EOS)."),
        "specific_internal_energy": number("J/kg", description="Initial specific internal energy e, instead of "
                                                               "pressure."),
        "velocity": vector("m/s", description="Initial velocity (default: at rest)."),
    },
    "additionalProperties": False,
    "required": ["material"],
    # a void region has no state at all (checked against the material below)
    "oneOf": [{"required": ["density", "pressure"]}, {"required": ["density", "specific_internal_energy"]},
              {"not": {"anyOf": [{"required": ["density"]}, {"required": ["pressure"]},
                                 {"required": ["specific_internal_energy"]}]}}],
    "x-allowed": "needs material, density and exactly one of pressure, specific_internal_energy "
                 "(a void material: none of them)",
    "description": "One initial state: a material, its density and pressure (or energy) and velocity where the "
                   "region holds.",
}
# (the solver's defaults, not imported: solvers/ale/solver.py DEFAULT_HOURGLASS, DEFAULT_VISCOSITY,
# solvers/ale/points.py DEFAULT_FRACTION_SAMPLES, solvers/ale/blocked.py the subsamples)
ALE = table(
    {
        "mode": {"type": "string", "enum": ["eulerian", "lagrangian"], "default": "eulerian",
                 "description": "eulerian: the material is remapped back to the fixed grid every step; lagrangian: "
                                "the grid moves with the material (no remap)."},
        "grid": doc(BOX, "The background grid: a box of quadrilateral (2-D) or hexahedral (3-D) zones."),
        "hourglass": number("dimensionless", minimum=0, maximum=0.125, default=0.05,
                            description="Flanagan-Belytschko viscous hourglass coefficient of the zones."),
        "viscosity": table({"kind": {"type": "string", "enum": ["scalar", "monotonic"], "default": "scalar",
                                     "description": "scalar: a q in every compressing zone; monotonic: "
                                                    "Christensen-limited per direction (no q in smooth "
                                                    "compression)."},
                            "linear": number("dimensionless", minimum=0,
                                             description="Linear coefficient of q (default: 0.1 eulerian, 0.2 "
                                                         "lagrangian)."),
                            "quadratic": number("dimensionless", minimum=0,
                                                description="Quadratic coefficient of q (default: 0.5 eulerian, 1.0 "
                                                            "lagrangian).")},
                           description="The artificial viscosity q that spreads shocks over a few zones."),
        "boundaries": table({f: ALE_FACE for f in ALE_FACES},
                            description="The condition on each face of the grid, x_lower ... z_upper (faces not "
                                        "given: wall)."),
        "materials": {
            "type": "object",
            "minProperties": 1,
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": FLUID,
            "description": "The background's materials, each an equation of state, by name, e.g. materials.gas = "
                           "{ eos = \"ideal_gas\", gamma = 1.4 }.",
        },
        "regions": {"type": "array", "minItems": 1, "items": ALE_REGION,
                    "description": "The initial state, region by region; later entries win where they apply, and "
                                   "together they cover the grid. Regions of two or more materials (or a void one) "
                                   "make several materials per zone (Eulerian mode)."},
        # several materials: region expressions sampled at k^dim points per zone (volume fractions)
        "fraction_samples": integer(minimum=1, maximum=64,
                                    description="Several materials per zone: the region expressions are sampled at "
                                                "fraction_samples^dim points per zone for the volume fractions "
                                                "(default: 8 in 2-D, 4 in 3-D)."),
        "energy_sources": {"type": "array", "items": table(
            {"energy": number("J", exclusiveMinimum=0, description="The energy deposited."),
             "at": vector("m", description="The point in the grid whose zone (or zones, on a node: shared) takes "
                                           "it.")},
            required=("energy", "at"),
            description="An energy deposited as internal energy at the start (a point blast, Sedov)."),
            "description": "Energy deposited at the start in the zones at given points."},
        # static obstacles: blocked where the region holds (fraction of k^dim sub-points per zone)
        "obstacles": {"type": "array", "items": table(
            {"region": {"type": "string", "minLength": 1,
                        "description": "Where the obstacle is: a boolean expression in x, y (, z)."},
             "subsamples": integer(minimum=1, maximum=64, default=1,
                                   description="A zone is blocked by the share of its subsamples^dim sub-points "
                                               "inside the region (1: its centre decides).")},
            required=("region",),
            description="A static obstacle: the grid is blocked where the region holds."),
            "description": "Immersed static walls (Eulerian mode): the remap keeps the material out of them."},
    },
    required=("grid", "materials", "regions"),
    description="The ALE background: compressible flow on a fixed (Eulerian) or moving (Lagrangian) grid.",
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
        # (the reference density under the solvers' own name, rho0: solvers/ale/eos.py)
        "materials": {n: {("rho0" if k == "density" else k): (v if k == "eos" else to_float(v))
                          for k, v in m.items()} for n, m in a["materials"].items()},
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
