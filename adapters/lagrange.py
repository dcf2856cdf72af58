"""Adapter of the Lagrangian FE solver (solvers.lagrange; its integrator by name:
solvers.lagrange.integrators). Run by the launcher as `python -m adapters.lagrange --case DIR --out DIR --roles coupler,lagrange --role lagrange`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adapters.base import SolverAdapter
from adapters.registry import register


def _pad3(a: np.ndarray) -> np.ndarray:
    if a.shape[1] == 3:
        return a
    return np.hstack([a, np.zeros((len(a), 3 - a.shape[1]))])


@register
class LagrangeAdapter(SolverAdapter):
    role = "lagrange"

    def setup(self) -> None:
        from adapters import step_files
        from solvers.lagrange.integrators import solver_for

        self.solver = solver_for(self.case)(self.comm, self.case)
        self._dt = None
        self._step, self._time = 0, 0.0
        if self.comm.rank == 0:
            step_files.write_mesh(self.out_dir, self.role, self.solver.global_cells, self.solver.cell_type)

    def stable_dt(self) -> float:
        return self.solver.stable_dt()

    def local_limiter(self) -> dict | None:
        f = getattr(self.solver, "local_limiter", None)
        return f() if f is not None else None

    def central_difference(self) -> bool:
        from solvers.lagrange.integrators import INTEGRATORS

        it = INTEGRATORS[self.case["lagrange"].get("integrator", "explicit")]
        return it.dynamic and not it.implicit

    def can_substep(self) -> bool:
        """Substeps (multi-rate): the explicit central difference without contact (the contact's
        multipliers are solved per step of the whole group; the implicit integrators take their own
        steps)."""
        from solvers.lagrange.integrators import substep_refusal

        return substep_refusal(self.case) is None

    def describe(self) -> str:
        s = self.solver
        n = len(self.case["lagrange"].get("bodies", []))
        return (f"{n} bod{'y' if n == 1 else 'ies'}, {s.n_cells_global:,} {s.cell_type} elements, "
                f"{s.n_nodes_global:,} nodes")

    def substep_cost(self) -> float:
        """An element step costs about a zone step (bench lagrange / bench ale)."""
        return float(self.solver.n_cells_global)

    def snapshot(self):
        return self.solver.snapshot(), (self._step, self._time)

    def restore(self, state) -> None:
        self.solver.restore(state[0])
        self._step, self._time = state[1]

    def substep_h_prev(self) -> float:
        """The solver's last step (0 before its first): its next kick is (h_prev + h) / 2 long."""
        return 0.0 if self.solver.first_step else float(self.solver.dt_prev)

    def predict(self, dt: float, step: int, time: float) -> None:
        self._step, self._time = step, time
        self.solver.predict(dt)

    # ---- the embedded-mesh coupling (collective hooks; every rank returns the same arrays) --------
    def surface(self) -> dict[str, np.ndarray]:
        """The bodies' exterior surface (the live elements' after renew_surface): node_ids (ns,),
        facets (nf, 2|4) indices into node_ids (outward), body (nf,), mass (ns,) full lumped nodal
        masses."""
        return self.solver.surface()

    def renew_surface(self) -> bool:
        """After a step that eroded elements: take the live elements' surface (collective); True if
        it changed (the runtime then sends it to the coupler, adapters/runtime.py)."""
        return self.solver.renew_surface()

    def interface(self) -> dict[str, np.ndarray]:
        """After predict: {"v": (ns, dim) predictor velocities v* of the surface nodes, held components
        at their prescribed values (a clamped node does not move the fluid by its predicted force)}."""
        return {"v": self.solver.constraint_velocity()}

    def positions(self) -> np.ndarray:
        """(ns, dim) current positions of the surface nodes: x^{n+1} after correct (x^0 before the
        first step)."""
        return self.solver.surface_state("x")

    def velocities(self) -> np.ndarray:
        """(ns, dim) velocities of the surface nodes: v^{n+1/2} after correct (the initial velocity
        before the first step)."""
        return self.solver.surface_state("v")

    def correct(self, impulse=None) -> None:
        """impulse: (ns, dim) coupling impulse on the surface nodes (surface() order, the same array on
        every rank), or None when uncoupled."""
        self.solver.correct(surface_impulse=impulse, step=self._step, time=self._time)

    def diagnostic_names(self) -> list[str]:
        return list(self.solver.diagnostics())

    def diagnostics(self) -> dict[str, float]:
        return self.solver.diagnostics()

    def probe_points(self):
        """(X, x, v) of the nodes this rank owns: reference positions, positions, velocities."""
        s = self.solver
        w = s.part.owned
        return s.X[w], s.x[w], s.v[w]

    def write(self, index: int, step: int, time: float) -> None:
        from adapters import step_files

        s = self.solver
        x = s.gather_nodes(s.x)
        v = s.gather_nodes(s.v)
        X = s.gather_nodes(s.X)
        cells = {k: s.gather_cells(a) for k, a in s.cell_fields().items()}
        points = s.point_fields()  # (collective: the contact surface; every rank holds the same values)
        if self.comm.rank == 0:
            # scalars of the stress for ParaView users (no calculator needed); pressure = -trace/3
            cells["von_mises_stress"] = step_files.von_mises(cells["stress"])
            cells["pressure"] = step_files.pressure(cells["stress"])
            # points are the deformed coordinates; displacement is for colouring (README: Warp By
            # Vector with it would deform twice)
            step_files.write_step(
                self.out_dir, self.role, index, step, time, _pad3(x),
                point_data={"velocity": _pad3(v), "displacement": _pad3(x - X), **points},
                cell_data=cells,
            )

    def checkpoint(self, path: Path) -> None:
        if self.comm.rank == 0:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.solver.checkpoint(path)

    def restart(self, path: Path) -> None:
        self.solver.restart(path)


if __name__ == "__main__":
    from adapters.protocol import exit_after_clean_end
    from adapters.runtime import serve

    serve(LagrangeAdapter)
    exit_after_clean_end()
