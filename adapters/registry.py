"""Adapters register themselves by role name (as meshio's register_format does for formats).

The orchestrator never branches on solver names: it asks this registry which module serves a role
and which table of case.toml says a case uses it.
"""
from __future__ import annotations

import importlib

_ADAPTERS: dict[str, type] = {}
# role -> (module that registers it, top-level case.toml table whose presence means "used")
_MODULES: dict[str, tuple[str, str]] = {}
# role -> its side in the embedded-mesh coupling: "background" (the fixed grid the bodies move
# through) or "foreground" (bodies with a surface); absent: not coupled
_SIDES: dict[str, str] = {}


# role -> "module:function" that says why a case's group of that role cannot take its coupled steps
# in substeps (multi-rate, orchestrator/coupling/multirate.py), None when it can; absent: it cannot
_SUBSTEPS: dict[str, str] = {}
# roles whose groups substep only when the case asks (run.multirate = true), never by default
_SUBSTEPS_ON_REQUEST: set[str] = set()
_SUBSTEP_KICKS: set[str] = set()   # (roles whose substeps kick at their start times: substep_kicks)


def declare(role: str, module: str, case_table: str, coupling_side: str | None = None,
            substeps: str | None = None, substeps_by_default: bool = True, substep_kicks: bool = False) -> None:
    """Make a role known without importing its (heavy) module; ``substeps``: "module:function"
    (case -> reason or None) when its group can take substeps; ``substeps_by_default`` False: only
    when the case asks (run.multirate = true), not where multi-rate's default finds that it pays."""
    _MODULES[role] = (module, case_table)
    if coupling_side is not None:
        _SIDES[role] = coupling_side
    if substeps is not None:
        _SUBSTEPS[role] = substeps
    if not substeps_by_default:
        _SUBSTEPS_ON_REQUEST.add(role)
    if substep_kicks:
        _SUBSTEP_KICKS.add(role)


def substep_kicks(role: str) -> bool:
    """Whether the role's substeps kick at their start times (a central-difference group: its adapter
    gives substep_h_prev; adapters/substeps.py), so that the coupler's ramp counts their kicks so."""
    return role in _SUBSTEP_KICKS


def substeps_by_default(role: str) -> bool:
    """Whether multi-rate's default (run.multirate unset) may substep the role's group where it pays."""
    return role in _SUBSTEPS and role not in _SUBSTEPS_ON_REQUEST


def substep_refusal(role: str, case: dict) -> str | None:
    """Why the role's group of this case takes no substeps, or None when it can (multi-rate)."""
    if role not in _SUBSTEPS:
        return "its solver takes no substeps"
    module, func = _SUBSTEPS[role].split(":")
    return getattr(importlib.import_module(module), func)(case)


def coupling_side(role: str) -> str | None:
    return _SIDES.get(role)


def register(cls):
    """Class decorator: `@register` on an adapter class with a `role` attribute."""
    _ADAPTERS[cls.role] = cls
    return cls


def roles() -> list[str]:
    return sorted(_MODULES)


def module_of(role: str) -> str:
    return _MODULES[role][0]


def roles_used(case: dict) -> list[str]:
    """Solver roles a validated case uses: only those are launched."""
    return [r for r, (_, table) in sorted(_MODULES.items()) if table in case]


def adapter_class(role: str) -> type:
    if role not in _ADAPTERS:
        importlib.import_module(_MODULES[role][0])
    return _ADAPTERS[role]


# The solvers this project ships. A new solver adds one line here and an adapter module.
declare("lagrange", "adapters.lagrange", "lagrange", coupling_side="foreground",
        substeps="solvers.lagrange.integrators:substep_refusal", substep_kicks=True)
declare("ale", "adapters.ale", "ale", coupling_side="background")
declare("sph", "adapters.sph", "sph", coupling_side="foreground",  # LAMMPS particles
        substeps="adapters.registry:sph_substep_refusal", substeps_by_default=False)


def sph_substep_refusal(case: dict) -> str | None:
    """Why an SPH group takes no substeps, or None: it can (adapters/sph.py snapshot, restore).  Only
    on request (run.multirate = true): a body of particles substepped at coupling steps near its own
    lowest period rings (orchestrator/coupling/multirate.py, known limits)."""
    return None
