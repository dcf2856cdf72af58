"""Building blocks of the case schema (JSON Schema, Draft 2020-12) that every table fragment uses.

The core tables are assembled in :mod:`orchestrator.schema.case`, the solvers' tables in their
fragment modules (:mod:`orchestrator.schema.registry`).  Non-standard annotation keywords (ignored
by the validator, used by :mod:`orchestrator.case` to word messages):

``x-unit``     unit shown after the allowed range, e.g. ``must be > 0 (kg/m^3)``;
``x-allowed``  replaces the generated "allowed" text for errors on that node;
``x-when``     for per-variant key sets (``if``/``then``): names the variant in messages.
``x-physical`` the bounds :func:`number` added from :data:`UNIT_LIMITS` (named as the physical range).

Every key also carries the standard annotations (ignored by the validator as well) that ``immerse
keys`` prints (:mod:`orchestrator.keys`): ``description``, what the key means, and ``default``, the
value the code takes when the key is absent, only where that value is one constant (a default that
depends on other keys is said in the description).  The helpers take both as keyword arguments;
:func:`doc` adds them to a node written out as a dict.
"""
from __future__ import annotations

__all__ = ["SCHEMA_URI", "NAME_PATTERN", "NAME_TEXT", "UNIT_LIMITS", "number", "integer", "vector", "table",
           "variants", "name", "doc", "BOX"]

SCHEMA_URI = "https://json-schema.org/draft/2020-12/schema"

NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_-]*$"
NAME_TEXT = "must start with a letter or '_' and contain only letters, digits, '_' and '-'"


UNIT_LIMITS = {
    "m": 1e6,            # 1000 km: lengths and coordinates
    "s": 1e9,            # 30 years
    "m/s": 1e6,          # 1000 km/s (non-relativistic: the fastest impacts are ~10 km/s)
    "m/s^2": 1e9,
    "Pa": 1e14,          # 100 TPa (moduli ~1e12, detonation ~1e11, impact pressures ~1e12)
    "kg/m^3": 1e9,       # (osmium 2.26e4; an idealised heavy, nearly rigid body: 1e8)
    "K": 1e7,
    "J": 1e20,           # (a 20 Mt explosion: 8e16 J)
    "J/kg": 1e13,
    "J/(kg K)": 1e6,
    "1/s": 1e12,
    "dimensionless": 1e6,   # ratios, exponents, coefficients
}
"""The physical range of a number with a unit: ``number(unit)`` refuses beyond +- this (finite
but absurd values, e.g. gravity 1e308 or a velocity 1e308, overflow what is derived from them: a
sound speed, an energy, a stable step) unless the key gives its own bounds.  Non-dimensional
cases (Sod: pressures of 1) are well inside."""


def _annotate(s: dict, description: str | None, default) -> dict:
    """``s`` with the annotations that are given (None: none; TOML has no null, so no key's default
    is None)."""
    if description is not None:
        s["description"] = description
    if default is not None:
        s["default"] = default
    return s


def doc(node: dict, description: str, default=None) -> dict:
    """A copy of ``node`` (a schema written out, or a shared one such as :data:`BOX`) with its meaning
    and, when given, its default: the shared node keeps its own."""
    return _annotate(dict(node), description, default)


def number(unit: str | None = None, *, description: str | None = None, default=None, **bounds) -> dict:
    s: dict = {"type": "number", **bounds}
    if unit:
        s["x-unit"] = unit
    lim = UNIT_LIMITS.get(unit)
    if lim is not None:
        added = []
        if "maximum" not in bounds and "exclusiveMaximum" not in bounds:
            s["maximum"] = lim
            added.append("maximum")
        if "minimum" not in bounds and "exclusiveMinimum" not in bounds:
            s["minimum"] = -lim
            added.append("minimum")
        if added:
            s["x-physical"] = added   # (named apart in messages: orchestrator/case.py _range_text)
    return _annotate(s, description, default)


def integer(unit: str | None = None, *, description: str | None = None, default=None, **bounds) -> dict:
    s: dict = {"type": "integer", **bounds}
    if unit:
        s["x-unit"] = unit
    return _annotate(s, description, default)


def vector(unit: str | None, items: dict | None = None, *, description: str | None = None,
           default=None) -> dict:
    """A 2- or 3-vector (its length against run.dimension is a cross-field check)."""
    s: dict = {
        "type": "array",
        "items": items if items is not None else (number(unit) if unit in UNIT_LIMITS else {"type": "number"}),
        "minItems": 2,
        "maxItems": 3,
    }
    if unit:
        s["x-unit"] = unit
    return _annotate(s, description, default)


def table(properties: dict, required: tuple[str, ...] = (), *, description: str | None = None,
          **extra) -> dict:
    """A table with a fixed key set: any other key is an error ("unknown key; allowed: ...")."""
    s = {"type": "object", "properties": properties, "additionalProperties": False}
    if required:
        s["required"] = list(required)
    s.update(extra)
    return _annotate(s, description, None)


def variants(selector: str, allowed: dict, required: dict | None = None) -> list:
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


def name(*, description: str | None = None) -> dict:
    """A name the user gives (body, material): a TOML bare key."""
    return _annotate({"type": "string", "minLength": 1, "pattern": NAME_PATTERN, "x-allowed": NAME_TEXT},
                     description, None)


BOX = table(
    {
        "lower": vector("m", description="The box's lower corner: its smallest coordinate along each axis."),
        "upper": vector("m", description="The box's upper corner: its largest coordinate along each axis "
                                         "(above lower in every component)."),
        "cells": vector(None, {"type": "integer", "minimum": 1},
                        description="Cells (elements or zones) along each axis, of equal width along it."),
    },
    required=("lower", "upper", "cells"),
)
"""An axis-aligned box cut into cells: a body's mesh, the background grid (each use describes the box
itself: :func:`doc`)."""
