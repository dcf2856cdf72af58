"""JSON Schema (Draft 2020-12) of ``case.toml``, as a Python dict.

The schema covers what a schema can express: types, ranges, required keys, enums and
unknown keys (``additionalProperties: false`` on every fixed-key table).  Cross-field
rules (vector lengths equal to ``run.dimension``, material references, mesh files,
expressions, ...) are checked in Python by :mod:`orchestrator.case`.

Non-standard annotation keywords (ignored by the validator, used to word messages):

``x-unit``     unit shown after the allowed range, e.g. ``must be > 0 (kg/m^3)``;
``x-allowed``  replaces the generated "allowed" text for errors on that node;
``x-when``     for per-variant key sets (``if``/``then``): names the variant in messages.
"""

from __future__ import annotations

import copy

from adapters.registry import roles as _registered_roles

SCHEMA_URI = "https://json-schema.org/draft/2020-12/schema"

NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_-]*$"
NAME_TEXT = "must start with a letter or '_' and contain only letters, digits, '_' and '-'"

MATERIAL_MODELS = ("linear_elastic", "neo_hookean", "johnson_cook")
BOUNDARY_TYPES = ("fixed", "velocity", "symmetry", "rigid_wall")
KNOWN_ROLES = tuple(_registered_roles())
"""Solver roles that exist in this code base (a case may only use some of them)."""

RUN_DEFAULTS = {
    "dt_scale": 0.9,
    # "output_interval": end_time / 20 (computed)
    "checkpoint_interval": None,
    "max_steps": 10_000_000,
    "diagnostics_every": 1,
}
LAGRANGE_DEFAULTS = {
    "hourglass": 0.1,
    "bulk_viscosity_linear": 0.06,
    "bulk_viscosity_quadratic": 1.5,
}
NON_FINITE_KEYS: tuple[str, ...] = ()
"""Keys whose floats may be ``nan``/``inf`` (every other float of a case must be finite): dotted
patterns, ``*`` for any one table key, ``[]`` for any index (``check.metrics.*.reference``).
None today; a key that means "no limit" by ``inf`` would be listed here."""

DEFAULT_ROOM_TEMPERATURE = 293.15
"""Initial temperature (K) of bodies whose material has no ``room_temperature``."""


def _num(unit: str | None = None, **bounds) -> dict:
    s: dict = {"type": "number", **bounds}
    if unit:
        s["x-unit"] = unit
    return s


def _int(unit: str | None = None, **bounds) -> dict:
    s: dict = {"type": "integer", **bounds}
    if unit:
        s["x-unit"] = unit
    return s


def _vector(unit: str | None, items: dict | None = None) -> dict:
    s: dict = {
        "type": "array",
        "items": items if items is not None else {"type": "number"},
        "minItems": 2,
        "maxItems": 3,
    }
    if unit:
        s["x-unit"] = unit
    return s


def _table(properties: dict, required: tuple[str, ...] = (), **extra) -> dict:
    s = {"type": "object", "properties": properties, "additionalProperties": False}
    if required:
        s["required"] = list(required)
    s.update(extra)
    return s


def _variants(selector: str, allowed: dict, required: dict | None = None) -> list:
    """`allOf` entries giving each value of `selector` its own key set: only `allowed[value]` keys
    may appear and `required[value]` (default: all of them) must."""
    required = required or allowed
    return [
        {
            "if": {"properties": {selector: {"const": value}}, "required": [selector]},
            "then": {
                "properties": {k: True for k in keys},
                "additionalProperties": False,
                "required": list(required[value]),
                "x-when": f"{selector} = {value!r}",
            },
        }
        for value, keys in allowed.items()
    ]


def _name() -> dict:
    return {"type": "string", "minLength": 1, "pattern": NAME_PATTERN, "x-allowed": NAME_TEXT}


RUN = _table(
    {
        "dimension": {"type": "integer", "enum": [2, 3]},
        "end_time": _num("s", exclusiveMinimum=0),
        "dt_scale": _num(None, exclusiveMinimum=0, maximum=1),
        "output_interval": _num("s", exclusiveMinimum=0),
        "checkpoint_interval": _num("s", exclusiveMinimum=0),
        "max_steps": _int("steps", minimum=1),
        "diagnostics_every": _int("steps", minimum=1),
    },
    required=("dimension", "end_time"),
)

RANKS = {
    "type": "object",
    "additionalProperties": _int("MPI ranks", minimum=1),
}

_ELASTIC_KEYS = ("model", "density", "youngs_modulus", "poisson_ratio")
_JC_EXTRA = (
    "yield_stress", "hardening_modulus", "hardening_exponent", "strain_rate_coefficient",
    "reference_strain_rate", "thermal_exponent", "melt_temperature", "room_temperature",
    "specific_heat", "taylor_quinney",
)
MODEL_KEYS = {
    "linear_elastic": _ELASTIC_KEYS,
    "neo_hookean": _ELASTIC_KEYS,
    "johnson_cook": _ELASTIC_KEYS + _JC_EXTRA,
}

MATERIAL = {
    "type": "object",
    "properties": {
        "model": {"type": "string", "enum": list(MATERIAL_MODELS)},
        "density": _num("kg/m^3", exclusiveMinimum=0),
        "youngs_modulus": _num("Pa", exclusiveMinimum=0),
        "poisson_ratio": _num("dimensionless", exclusiveMinimum=-1, exclusiveMaximum=0.5),
        "yield_stress": _num("Pa", minimum=0),
        "hardening_modulus": _num("Pa", minimum=0),
        "hardening_exponent": _num("dimensionless", exclusiveMinimum=0),
        "strain_rate_coefficient": _num("dimensionless", minimum=0),
        "reference_strain_rate": _num("1/s", exclusiveMinimum=0),
        "thermal_exponent": _num("dimensionless", exclusiveMinimum=0),
        "melt_temperature": _num("K", exclusiveMinimum=0),
        "room_temperature": _num("K", exclusiveMinimum=0),
        "specific_heat": _num("J/(kg K)", exclusiveMinimum=0),
        "taylor_quinney": _num("dimensionless", minimum=0, maximum=1),
    },
    "additionalProperties": False,
    "required": ["model", "density", "youngs_modulus", "poisson_ratio"],
    "allOf": _variants("model", MODEL_KEYS),
}

BOX = _table(
    {
        "lower": _vector("m"),
        "upper": _vector("m"),
        "cells": _vector(None, {"type": "integer", "minimum": 1}),
    },
    required=("lower", "upper", "cells"),
)
QUARTER_CYLINDER = _table(
    {
        "radius": _num("m", exclusiveMinimum=0),
        "length": _num("m", exclusiveMinimum=0),
        "radial_cells": _int(None, minimum=2),  # butterfly grid needs >= 2
        "axial_cells": _int(None, minimum=1),
    },
    required=("radius", "length", "radial_cells", "axial_cells"),
)
MESH = _table(
    {
        "box": BOX,
        "quarter_cylinder": QUARTER_CYLINDER,
        "file": {"type": "string", "minLength": 1},
    },
    minProperties=1,
    maxProperties=1,
)
MESH["x-allowed"] = "must have exactly one of: box, quarter_cylinder, file"

BODY = _table(
    {
        "name": _name(),
        "material": {"type": "string", "minLength": 1},
        "mesh": MESH,
        "initial_velocity": _vector("m/s", {"type": ["number", "string"]}),
        "initial_temperature": _num("K", exclusiveMinimum=0),
    },
    required=("name", "material", "mesh"),
)

LAGRANGE = _table(
    {
        # FB viscous hourglass damping is itself explicit: stable for coefficient <= 1/8 at dt = h/c
        "hourglass": _num("dimensionless", minimum=0, maximum=0.125),
        "bulk_viscosity_linear": _num("dimensionless", minimum=0),
        "bulk_viscosity_quadratic": _num("dimensionless", minimum=0),
        "bodies": {"type": "array", "items": BODY},
    },
)

# ---- [ale]: the background (compressible flow on a fixed grid) ------------------------------------
EOS_KEYS = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf"),
    "tait": ("eos", "rho0", "bulk_modulus", "exponent", "p0"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "rho0"),
    "void": ("eos",),   # empty space: volume only (several materials per zone)
}
EOS_REQUIRED = {
    "ideal_gas": ("eos", "gamma"),
    "stiffened_gas": ("eos", "gamma", "p_inf"),
    "tait": ("eos", "rho0", "bulk_modulus", "exponent"),
    "jwl": ("eos", "A", "B", "R1", "R2", "omega", "rho0"),
    "void": ("eos",),
}
FLUID = {
    "type": "object",
    "properties": {
        "eos": {"type": "string", "enum": list(EOS_KEYS)},
        "gamma": _num("dimensionless", exclusiveMinimum=1),
        "p_inf": _num("Pa", minimum=0),
        "rho0": _num("kg/m^3", exclusiveMinimum=0),
        "bulk_modulus": _num("Pa", exclusiveMinimum=0),
        "exponent": _num("dimensionless", minimum=1),
        "p0": _num("Pa"),
        "A": _num("Pa"),
        "B": _num("Pa"),
        "R1": _num("dimensionless", exclusiveMinimum=0),
        "R2": _num("dimensionless", exclusiveMinimum=0),
        "omega": _num("dimensionless", exclusiveMinimum=0),
    },
    "additionalProperties": False,
    "required": ["eos"],
    "allOf": _variants("eos", EOS_KEYS, EOS_REQUIRED),
}
INFLOW = _table(
    {"inflow": _table({"density": _num("kg/m^3", exclusiveMinimum=0), "velocity": _vector("m/s"),
                       "pressure": _num("Pa")}, required=("density", "velocity", "pressure"))},
    required=("inflow",),
)
PISTON = _table({"piston": _table({"velocity": _num("m/s")}, required=("velocity",))}, required=("piston",))
ALE_FACE = {"oneOf": [{"type": "string", "enum": ["wall", "outflow", "periodic"]}, INFLOW, PISTON],
            "x-allowed": "must be \"wall\", \"outflow\", \"periodic\", { inflow = { density, velocity, pressure } }"
                         " or { piston = { velocity } }"}
ALE_FACES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")
ALE_REGION = {
    "type": "object",
    "properties": {
        "material": {"type": "string", "minLength": 1},
        "region": {"type": "string", "minLength": 1},
        "density": _num("kg/m^3", exclusiveMinimum=0),
        "pressure": _num("Pa"),
        "specific_internal_energy": _num("J/kg"),
        "velocity": _vector("m/s"),
    },
    "additionalProperties": False,
    "required": ["material"],
    # a void region has no state at all (checked against the material in case.py)
    "oneOf": [{"required": ["density", "pressure"]}, {"required": ["density", "specific_internal_energy"]},
              {"not": {"anyOf": [{"required": ["density"]}, {"required": ["pressure"]},
                                 {"required": ["specific_internal_energy"]}]}}],
    "x-allowed": "needs material, density and exactly one of pressure, specific_internal_energy "
                 "(a void material: none of them)",
}
ALE = _table(
    {
        "mode": {"type": "string", "enum": ["eulerian", "lagrangian"]},
        "grid": BOX,
        "hourglass": _num("dimensionless", minimum=0, maximum=0.125),
        "viscosity": _table({"kind": {"type": "string", "enum": ["scalar", "monotonic"]},
                             "linear": _num("dimensionless", minimum=0),
                             "quadratic": _num("dimensionless", minimum=0)}),
        "boundaries": _table({f: ALE_FACE for f in ALE_FACES}),
        "materials": {
            "type": "object",
            "minProperties": 1,
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": FLUID,
        },
        "regions": {"type": "array", "minItems": 1, "items": ALE_REGION},
        # several materials: region expressions sampled at k^dim points per zone (volume fractions)
        "fraction_samples": _int(minimum=1, maximum=64),
        "energy_sources": {"type": "array", "items": _table(
            {"energy": _num("J", exclusiveMinimum=0), "at": _vector("m")}, required=("energy", "at"))},
        # static obstacles: blocked where the region holds (fraction of k^dim sub-points per zone)
        "obstacles": {"type": "array", "items": _table(
            {"region": {"type": "string", "minLength": 1}, "subsamples": _int(minimum=1, maximum=64)},
            required=("region",))},
    },
    required=("grid", "materials", "regions"),
)

BOUNDARY_KEYS = {
    "fixed": ("type", "region"),
    "velocity": ("type", "region", "velocity"),
    "symmetry": ("type", "axis", "at"),
    "rigid_wall": ("type", "point", "normal"),
}
BOUNDARY = {
    "type": "object",
    "properties": {
        "type": {"type": "string", "enum": list(BOUNDARY_TYPES)},
        "region": {"type": "string", "minLength": 1},
        "velocity": _table(
            {c: _num("m/s") for c in ("x", "y", "z")},
            minProperties=1,
        ),
        "axis": {"type": "string", "enum": ["x", "y", "z"]},
        "at": _num("m"),
        "point": _vector("m"),
        "normal": _vector(None),
    },
    "additionalProperties": False,
    "required": ["type"],
    "allOf": _variants("type", BOUNDARY_KEYS),
}

METRIC = _table(
    {
        "reference": _num(None),
        "tolerance": _num("relative", exclusiveMinimum=0),
    },
    required=("reference", "tolerance"),
)
CHECK = _table(
    {
        "kind": {"type": "string", "minLength": 1},
        "params": {"type": "object"},  # free-form, interpreted by the check itself
        "metrics": {
            "type": "object",
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": METRIC,
        },
    },
    required=("kind",),
)

CASE_SCHEMA = {
    "$schema": SCHEMA_URI,
    "$id": "immerse:case.toml",
    "title": "immerse case file (case.toml)",
    **_table(
        {
            "run": RUN,
            "ranks": RANKS,
            "materials": {
                "type": "object",
                "minProperties": 1,
                "propertyNames": {"pattern": NAME_PATTERN},
                "additionalProperties": MATERIAL,
                "x-allowed": "at least one material table, e.g. [materials.steel]",
            },
            "lagrange": LAGRANGE,
            "ale": ALE,
            "boundaries": {"type": "array", "items": BOUNDARY},
            "check": CHECK,
        },
        required=("run",),
    ),
}


def case_schema() -> dict:
    """A deep copy of the case schema (safe to modify)."""
    return copy.deepcopy(CASE_SCHEMA)
