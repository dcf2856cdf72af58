"""The base of the integrators that solve the whole system on every rank (quasi_static.py,
implicit_dynamic.py): their step is the one they ask for (stable_dt returns the _dt_stable they set:
a load step, or the implicit step their control chose), and predict only records the step given
(no predictor: correct solves the step)."""
from __future__ import annotations

from solvers.lagrange.solver import LagrangeSolver

__all__ = ["GatheredStepSolver"]


class GatheredStepSolver(LagrangeSolver):
    def stable_dt(self) -> float:
        return self._dt_stable

    def predict(self, dt: float) -> None:
        self.dt = dt
