"""The Lagrangian solver's time integrators by name (``[lagrange] integrator``), each a solver class
with the explicit solver's interface (solver.LagrangeSolver: stable_dt, predict, correct,
diagnostics, output and checkpoint hooks), registered with the module that holds it so that the case
schema reads the names without importing the solvers:

* ``explicit`` (default): central differences, lumped mass (solver.py);
* ``quasi_static``: equilibrium under loads ramped with time, frictionless contact (quasi_static.py);
* ``midpoint``: the implicit energy-momentum midpoint scheme (implicit_dynamic.py, issue 12);
* ``newmark``: Newmark's trapezoidal rule, the implicit comparison that fails (implicit_dynamic.py).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["INTEGRATORS", "Integrator", "register", "solver_class", "solver_for", "substep_refusal", "SUBCYCLING_RATIOS"]


@dataclass(frozen=True)
class Integrator:
    module: str
    attr: str
    dynamic: bool = True   # False: no inertia (no coupling with the fluid, no initial velocities)
    implicit: bool = False  # True: steps of [lagrange] time_step, elastic bodies (no plasticity), no coupling yet


INTEGRATORS: dict[str, Integrator] = {}

SUBCYCLING_RATIOS = (1, 2, 4, 8, 16, 32, 64)
"""The allowed ``[lagrange] subcycling`` values (1: off; subcycling.py): powers of two, so that every
element's and node's period divides the solver's step (LS-DYNA's bins)."""


def register(name: str, integrator: Integrator) -> None:
    if name in INTEGRATORS:
        raise ValueError(f"integrator {name!r} registered twice")
    INTEGRATORS[name] = integrator


register("explicit", Integrator("solvers.lagrange.solver", "LagrangeSolver"))
register("quasi_static", Integrator("solvers.lagrange.quasi_static", "QuasiStaticSolver", dynamic=False))
register("midpoint", Integrator("solvers.lagrange.implicit_dynamic", "MidpointSolver", implicit=True))
register("newmark", Integrator("solvers.lagrange.implicit_dynamic", "NewmarkSolver", implicit=True))


def solver_class(name: str):
    """The solver class of integrator ``name`` (a KeyError names the registered ones)."""
    if name not in INTEGRATORS:
        raise KeyError(f"integrator {name!r}: registered: {', '.join(sorted(INTEGRATORS))}")
    it = INTEGRATORS[name]
    return getattr(importlib.import_module(it.module), it.attr)


def solver_for(case: dict):
    """The solver class of ``case``'s Lagrangian group: its integrator's, or the explicit one with
    element subcycling (subcycling.py) when ``[lagrange] subcycling`` is above 1."""
    opts = case.get("lagrange") or {}
    name = opts.get("integrator", "explicit")
    if int(opts.get("subcycling", 1)) > 1 and name == "explicit":
        from solvers.lagrange.subcycling import SubcyclingSolver

        return SubcyclingSolver
    return solver_class(name)


def substep_refusal(case: dict) -> str | None:
    """Why the Lagrangian group of ``case`` cannot take its coupled steps in substeps (multi-rate:
    orchestrator/coupling/multirate.py), None when it can: the explicit central difference can; an
    implicit or quasi-static integrator takes its own steps, and contact's multipliers are solved
    per step of the whole group (its state is not in the solver's snapshot)."""
    name = (case.get("lagrange") or {}).get("integrator", "explicit")
    it = INTEGRATORS.get(name)
    if it is None or it.implicit or not it.dynamic:
        return f"the {name!r} integrator takes its own steps"
    if case.get("contact"):
        return "contact between its bodies is solved once per step of the whole group"
    if int((case.get("lagrange") or {}).get("subcycling", 1)) > 1:
        return "its elements are subcycled inside its own step (lagrange.subcycling)"
    return None
