"""JSON Schema (Draft 2020-12) of ``case.toml``, as a Python dict.

The schema covers what a schema can express: types, ranges, required keys, enums and
unknown keys (``additionalProperties: false`` on every fixed-key table).  Cross-field
rules (vector lengths equal to ``run.dimension``, material references, mesh files,
expressions, ...) are checked in Python by :mod:`orchestrator.case`.

This module holds the core tables, ``[run]``, ``[ranks]`` and ``[check]``; the other top-level
tables are the solvers' fragments, registered in :mod:`orchestrator.schema.registry`
(:mod:`orchestrator.schema.lagrange`, :mod:`orchestrator.schema.ale`) and placed between
``ranks`` and ``check`` by their order.  The building blocks and the non-standard annotation
keywords (``x-unit``, ``x-allowed``, ``x-when``) are in :mod:`orchestrator.schema.parts`.
"""

from __future__ import annotations

import copy

from adapters.registry import roles as _registered_roles

from . import registry as schema_registry
from .lagrange import MODEL_KEYS  # noqa: F401  (re-exported: the keys of each material model)
from .parts import NAME_PATTERN, NAME_TEXT, SCHEMA_URI, integer, number, table

__all__ = ["CASE_SCHEMA", "KNOWN_ROLES", "NAME_PATTERN", "NAME_TEXT", "NON_FINITE_KEYS", "RUN_DEFAULTS",
           "SCHEMA_URI", "case_schema"]

KNOWN_ROLES = tuple(_registered_roles())
"""Solver roles that exist in this code base (a case may only use some of them)."""

RUN_DEFAULTS = {
    "dt_scale": 0.9,
    # "output_interval": end_time / 20 (computed)
    "checkpoint_interval": None,
    "max_steps": 10_000_000,
    "diagnostics_every": 1,
}
NON_FINITE_KEYS: tuple[str, ...] = ()
"""Keys whose floats may be ``nan``/``inf`` (every other float of a case must be finite): dotted
patterns, ``*`` for any one table key, ``[]`` for any index (``check.metrics.*.reference``).
None today; a key that means "no limit" by ``inf`` would be listed here."""


RUN = table(
    {
        "dimension": {"type": "integer", "enum": [2, 3]},
        "end_time": number("s", exclusiveMinimum=0),
        "dt_scale": number(None, exclusiveMinimum=0, maximum=4),
        "output_interval": number("s", exclusiveMinimum=0),
        "checkpoint_interval": number("s", exclusiveMinimum=0),
        "max_steps": integer("steps", minimum=1),
        "diagnostics_every": integer("steps", minimum=1),
        # a step below this stops the run by name (its limiter named; LS-DYNA's DTMIN); unset: none
        "dt_min": number("s", exclusiveMinimum=0),
        # multi-rate (orchestrator/coupling/multirate.py): foreground groups that can take each coupled
        # step in substeps of their own stable step (true: all must; false: none; unset: where it pays,
        # multirate.DEFAULT_ON: PAYS zones per element and a step ratio of at least MIN_RATIO)
        "multirate": {"type": "boolean"},
        "max_substeps": integer("substeps", minimum=1, maximum=1024),
        # a group's stable step capped (s): a stiffer body's step, for studies of the ratio
        "group_dt_max": {"type": "object", "propertyNames": {"enum": list(_registered_roles())},
                         "additionalProperties": number("s", exclusiveMinimum=0)},
    },
    required=("dimension", "end_time"),
)

RANKS = {
    "type": "object",
    "additionalProperties": integer("MPI ranks", minimum=1),
}

METRIC = table(
    {
        "reference": number(None),
        "tolerance": number("relative", exclusiveMinimum=0),
    },
    required=("reference", "tolerance"),
)
CHECK = table(
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


def _assemble() -> dict:
    """run, ranks, the registered tables by order, check."""
    properties = {"run": RUN, "ranks": RANKS}
    properties.update({t.name: t.schema for t in schema_registry.tables()})
    properties["check"] = CHECK
    return {
        "$schema": SCHEMA_URI,
        "$id": "immerse:case.toml",
        "title": "immerse case file (case.toml)",
        **table(properties, required=("run",)),
    }


CASE_SCHEMA = _assemble()


def case_schema() -> dict:
    """A deep copy of the case schema (safe to modify)."""
    return copy.deepcopy(CASE_SCHEMA)
