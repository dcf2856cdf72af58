"""The top-level tables of case.toml beyond the core, each registered by the code that owns it.

The core of a case file, ``[run]``, ``[ranks]`` and ``[check]``, belongs to
:mod:`orchestrator.schema.case` and :mod:`orchestrator.case`.  Every other top-level table comes
from a *fragment* module (one per solver role, e.g. :mod:`orchestrator.schema.ale`; the coupling's
next) listed in :data:`FRAGMENTS`, which registers each of its tables with one call::

    register_table("ale", schema=ALE, normalise=normalise, check=check, order=40)

``load_case`` never names a table of a fragment: it loops over :func:`tables`.  The fragment
modules are light (schemas as dicts, plain Python checks); the solver modules stay unimported
until a solver runs.  Which role a table means for the launch (and its ranks) is the adapter
registry's business (:mod:`adapters.registry`, ``declare(role, module, case_table)``).

Hook order
----------
Each stage runs over the registered tables in ascending ``order`` (ties are refused, so the
order never depends on import order); within ``load_case`` (:mod:`orchestrator.case`) the first
failure wins:

1. ``schema``: the table's JSON-schema fragment (:mod:`orchestrator.schema.parts`) is
   ``properties[name]`` of the case schema, placed after ``run`` and ``ranks`` and before
   ``check`` by ``order``; the order is also that of the ``unknown key; allowed: ...`` list of
   top-level keys.  Then every float must be finite (case.py).
2. ``normalise(raw, case) -> value | None``: after ``[run]``; ``raw`` is the file's table
   (already schema-valid, a private copy) or ``None`` when the file has none; ``case`` holds the
   normalised ``name``, ``case_dir``, ``run``, ``check`` (``ranks`` still empty) and the tables
   of lower order.  The returned value
   becomes ``case[name]``; ``None`` leaves the table out of the case.  A table registered with
   ``default=True`` (the Lagrangian solver's) gets ``raw = {}`` when the file has no table of any
   solver role at all.
3. ``check(case, data)``: cross-field rules, for the tables present in the normalised case (every
   table normalised by then), after those of ``[run]``; ``data`` is the raw file (for reporting values as written).  Raise
   :class:`orchestrator.schema.rules.CaseError` (helpers there).  Then ``[ranks]`` (the roles of
   the tables now known) and the ``[check]`` kind.
4. ``check_files(case, data)``: the slow part (reading data files such as meshes), last, once
   every table passed its checks.

A fragment module imports only light modules (parts, rules, this one; never
orchestrator.case or orchestrator.schema.case, which build the schema from the registry).  A new
table, e.g. ``[coupling]``: a module ``orchestrator/schema/coupling.py`` ending in
``register_table("coupling", COUPLING, normalise, check, order=60)``, and its name in FRAGMENTS.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable

__all__ = ["FRAGMENTS", "CORE_TABLES", "Table", "register_table", "tables", "table"]

FRAGMENTS = ("orchestrator.schema.lagrange", "orchestrator.schema.ale", "orchestrator.schema.sph",
             "orchestrator.schema.coupling", "orchestrator.schema.contact", "orchestrator.schema.probes")
"""Modules that register tables, imported on first use.  A new table: a module with one
``register_table(...)`` call per table, named here."""

CORE_TABLES = ("run", "ranks", "check")
"""Tables of the core schema (orchestrator/schema/case.py): no fragment may register them."""


@dataclass(frozen=True)
class Table:
    """One registered top-level table of case.toml (see the module docstring for the hooks)."""

    name: str
    schema: dict
    normalise: Callable[[Any, dict], Any]
    check: Callable[[dict, dict], None] | None
    check_files: Callable[[dict, dict], None] | None
    order: int
    default: bool


_TABLES: dict[str, Table] = {}
_state = "unloaded"   # -> "loading" -> "loaded"


def register_table(name: str, schema: dict, normalise: Callable[[Any, dict], Any],
                   check: Callable[[dict, dict], None] | None = None, *, order: int,
                   check_files: Callable[[dict, dict], None] | None = None,
                   default: bool = False) -> Table:
    """Register the top-level table ``name``: its schema fragment, normaliser and checkers, at
    place ``order`` among the registered tables.  Refuses a core table, a second registration of
    a name and an ``order`` already taken."""
    if name in CORE_TABLES:
        raise ValueError(f"[{name}] is a core table of case.toml (orchestrator/schema/case.py)")
    if name in _TABLES:
        raise ValueError(f"table [{name}] is already registered")
    taken = {t.order: t.name for t in _TABLES.values()}
    if order in taken:
        raise ValueError(f"table [{name}]: order {order} is taken by [{taken[order]}]")
    if default and any(t.default for t in _TABLES.values()):
        raise ValueError(f"table [{name}]: only one table may be the default")
    t = Table(name, schema, normalise, check, check_files, order, default)
    _TABLES[name] = t
    return t


def _load() -> None:
    global _state
    if _state == "loaded":
        return
    if _state == "loading":  # a half-registered set would give a schema without some tables
        raise RuntimeError("a fragment module asked for the tables while they are being registered "
                           "(fragments must not import orchestrator.schema.case or orchestrator.case)")
    _state = "loading"
    try:
        for module in FRAGMENTS:
            importlib.import_module(module)
    except BaseException:
        _state = "unloaded"
        raise
    _state = "loaded"


def tables() -> tuple[Table, ...]:
    """Every registered table, by ascending order (the fragment modules imported first)."""
    _load()
    return tuple(sorted(_TABLES.values(), key=lambda t: t.order))


def table(name: str) -> Table:
    _load()
    return _TABLES[name]
