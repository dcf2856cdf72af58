"""The base of the integrators that solve the whole system on every rank (quasi_static.py,
implicit_dynamic.py): their step is the one they ask for (stable_dt returns the _dt_stable they set:
a load step, or the implicit step their control chose), predict only records the step given (no
predictor: correct solves the step), and _global turns this rank's nodal arrays into the global ones
every rank solves with."""
from __future__ import annotations

import numpy as np

from solvers.lagrange.solver import LagrangeSolver

__all__ = ["GatheredStepSolver"]


class GatheredStepSolver(LagrangeSolver):
    def stable_dt(self) -> float:
        return self._dt_stable

    def predict(self, dt: float) -> None:
        self.dt = dt

    def _global(self, a: np.ndarray) -> np.ndarray:
        """(n_global, k) from this rank's (nn_local, k): the owned rows summed over the ranks
        (collective)."""
        out = np.zeros((self.n_nodes_global, a.shape[1]))
        out[self.part.nodes[self.part.owned]] = a[self.part.owned]
        return self._allsum(out)
