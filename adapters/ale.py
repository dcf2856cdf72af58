"""Adapter of the ALE background solver (solvers.ale). Run by the launcher as
`python -m adapters.ale --case DIR --out DIR --roles coupler,...,ale --role ale`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adapters.base import SolverAdapter
from adapters.registry import register


@register
class AleAdapter(SolverAdapter):
    role = "ale"

    def setup(self) -> None:
        from solvers.ale.solver import AleSolver

        self.solver = AleSolver(self.comm, self.case["ale"])
        self._mesh_written = False

    def stable_dt(self) -> float:
        return self.solver.stable_dt()

    def predict(self, dt: float, step: int, time: float) -> None:
        self._step, self._time = step, time
        self.solver.predict(dt)

    def correct(self, impulse=None) -> None:
        self.solver.correct(impulse, step=self._step, time=self._time)

    def remap(self, fractions=None) -> None:
        self.solver.remap(fractions)

    def diagnostic_names(self) -> list[str]:
        return list(self.solver.diagnostics())

    def diagnostics(self) -> dict[str, float]:
        return self.solver.diagnostics()

    def write(self, index: int, step: int, time: float) -> None:
        from orchestrator import output

        data = self.solver.output()
        if self.comm.rank != 0:
            return
        points, cells, point_data, cell_data = data
        if not self._mesh_written:
            output.write_mesh(self.out_dir, self.role, cells, "hexahedron" if cells.shape[1] == 8 else "quad")
            self._mesh_written = True
        output.write_step(self.out_dir, self.role, index, step, time, np.asarray(points),
                          point_data=point_data, cell_data=cell_data)

    def checkpoint(self, path: Path) -> None:
        if self.comm.rank == 0:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.solver.checkpoint(path)

    def restart(self, path: Path) -> None:
        self.solver.restart(path)


if __name__ == "__main__":
    from adapters.runtime import serve

    serve(AleAdapter)
