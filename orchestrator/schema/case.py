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
from .parts import NAME_PATTERN, NAME_TEXT, SCHEMA_URI, doc, integer, number, table

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
        "dimension": doc({"type": "integer", "enum": [2, 3]},
                         "Space dimension of the whole case: 2 (planar: quadrilateral elements and zones in x, y; "
                         "solids in plane strain) or 3 (hexahedra in x, y, z). Every vector of the case has this "
                         "many components."),
        "end_time": number("s", exclusiveMinimum=0, description="Simulated time at which the run ends."),
        "dt_scale": number(None, exclusiveMinimum=0, maximum=4, default=RUN_DEFAULTS["dt_scale"],
                           description="Each step is this fraction of the smallest stable step of the solver "
                                       "groups (the Courant number; above 1 only for stability studies: warned)."),
        "output_interval": number("s", exclusiveMinimum=0,
                                  description="Fields are written at the first step reaching each multiple of "
                                              "this time (default: end_time / 20)."),
        "checkpoint_interval": number("s", exclusiveMinimum=0,
                                      description="A restartable checkpoint is written at the first step reaching "
                                                  "each multiple of this time (absent: no checkpoints)."),
        "max_steps": integer("steps", minimum=1, default=RUN_DEFAULTS["max_steps"],
                             description="The run stops after this many steps even before end_time (status "
                                         "max_steps)."),
        "diagnostics_every": integer("steps", minimum=1, default=RUN_DEFAULTS["diagnostics_every"],
                                     description="Steps between two records of the diagnostics (energies, "
                                                 "balances, probes); output and checkpoint steps are recorded too."),
        # a step below this stops the run by name (its limiter named; LS-DYNA's DTMIN); unset: none
        "dt_min": number("s", exclusiveMinimum=0,
                         description="A stable step below this stops the run, naming what limits the step "
                                     "(LS-DYNA's DTMIN; absent: no lower limit)."),
        # multi-rate (orchestrator/coupling/multirate.py): foreground groups that can take each coupled
        # step in substeps of their own stable step (true: all must; false: none; unset: where it pays,
        # multirate.DEFAULT_ON: PAYS zones per element and a step ratio of at least MIN_RATIO)
        "multirate": doc({"type": "boolean"},
                         "Coupled runs: bodies whose stable step is below the background gas's take each coupling "
                         "step in substeps of their own. true: every body group must; false: none; absent: where "
                         "it pays (at least 4 zones per element and a step ratio of at least 4 at the start; SPH "
                         "groups only when true)."),
        "max_substeps": integer("substeps", minimum=1, maximum=1024, default=64,  # (orchestrator/case.py)
                                description="The most substeps a group takes in one coupling step (multirate); "
                                            "the coupling step is shortened to keep within it."),
        # a group's stable step capped (s): a stiffer body's step, for studies of the ratio
        "group_dt_max": doc({"type": "object", "propertyNames": {"enum": list(_registered_roles())},
                             "additionalProperties": number("s", exclusiveMinimum=0,
                                                            description="The cap of this role's stable step.")},
                            "Caps the stable step of solver groups by role, e.g. { lagrange = 1e-8 }: stands in "
                            "for a stiffer body in studies of the step ratio (absent: no cap)."),
    },
    required=("dimension", "end_time"),
    description="Time stepping and output of the whole run.",
)

RANKS = {
    "type": "object",
    "additionalProperties": integer("MPI ranks", minimum=1, default=1,  # (orchestrator/case.py ranks_for)
                                    description="MPI ranks of this solver role."),
    "description": "MPI ranks per solver role, e.g. { lagrange = 2, ale = 4 } (default 1 each; the command "
                   "line's --ranks ROLE=N overrides).",
}

METRIC = table(
    {
        "reference": number(None, description="The metric's expected value (measured, exact or a reference "
                                              "run's), in the metric's own unit."),
        "tolerance": number("relative", exclusiveMinimum=0,
                            description="The largest error passed, relative to reference (absolute when "
                                        "reference is 0)."),
    },
    required=("reference", "tolerance"),
    description="One figure the check measures (its name is the check's metric name) against a reference.",
)
CHECK = table(
    {
        "kind": {"type": "string", "minLength": 1,
                 "description": "The check that measures the run's error, one of the registered kinds "
                                "(orchestrator/checks/; e.g. taylor_bar, riemann, sedov, bar_wave)."},
        "params": {"type": "object",  # free-form, interpreted by the check itself
                   "description": "The kind's own keys (checked against that kind's schema with the case)."},
        "metrics": {
            "type": "object",
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": METRIC,
            "description": "The figures the check compares, by name, each with a reference and a tolerance.",
        },
    },
    required=("kind",),
    description="How the case measures its own error after the run (summary.json's check).",
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
