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
    bodies = None  # coupled runs: the bodies' initial geometry (set by the runtime before setup)

    def setup(self) -> None:
        from solvers.ale.solver import AleSolver

        self.solver = AleSolver(self.comm, self.case["ale"], bodies=self.bodies)
        self._mesh_written = False

    def local_limiter(self) -> dict | None:
        return self.solver.local_limiter()

    def values_at(self, points, quantities):
        """The zones' state at points for the case's background probes (solvers/probes.py FieldProbes)."""
        return self.solver.values_at(points, quantities)

    def describe(self) -> str:
        cells = [int(c) for c in self.case["ale"]["grid"]["cells"]]
        n = len(self.case["ale"].get("materials", {}))
        return (f"{int(np.prod(cells)):,} zones ({' x '.join(map(str, cells))}), {n} material{'s' if n != 1 else ''}, "
                f"{self.case['ale'].get('mode', 'eulerian')}")

    # ---- the embedded-mesh coupling (background side; the runtime moves the buffers) --------------
    def unpack_geometry(self, buf):
        from solvers.ale.coupled import BodyGeometry

        return BodyGeometry.unpack(buf, self.solver.dim if hasattr(self, "solver") else
                                   len(self.case["ale"]["grid"]["cells"]))

    def interface(self):
        """After predict (collective): on rank 0 [v* (nn, dim), m (nn), R (nc, dim)] of the nodes and
        cut zones of the current geometry (solvers/ale/solver.AleSolver.interface)."""
        return self.solver.interface()

    def unpack_correction(self, buf):
        """The coupler's correction: [impulse (nn, dim), v_half (nc, dim), v_bar (nc, dim)]."""
        blk, dim = self.solver._blk, self.solver.dim
        nn = blk.nodes[0].size
        a = nn * dim
        b = a + blk.n_cut * dim
        return {"impulse": buf[:a].reshape(nn, dim), "v_half": buf[a:b].reshape(-1, dim),
                "v_bar": buf[b:].reshape(-1, dim)}

    def stable_dt(self) -> float:
        return self.solver.stable_dt()

    def predict(self, dt: float, step: int, time: float) -> None:
        self._step, self._time = step, time
        self.solver.predict(dt)

    def correct(self, coupling=None) -> None:
        self.solver.correct(None, step=self._step, time=self._time, coupling=coupling)

    def remap(self, fractions=None) -> None:
        self.solver.remap(fractions)

    def diagnostic_names(self) -> list[str]:
        return list(self.solver.diagnostics())

    def diagnostics(self) -> dict[str, float]:
        return self.solver.diagnostics()

    def write(self, index: int, step: int, time: float) -> None:
        from adapters import step_files

        data = self.solver.output()
        if self.comm.rank != 0:
            return
        points, cells, point_data, cell_data = data
        _blank_covered(cell_data)
        if not self._mesh_written:
            step_files.write_mesh(self.out_dir, self.role, cells, "hexahedron" if cells.shape[1] == 8 else "quad")
            self._mesh_written = True
        step_files.write_step(self.out_dir, self.role, index, step, time, np.asarray(points),
                          point_data=point_data, cell_data=cell_data)

    def checkpoint(self, path: Path) -> None:
        if self.comm.rank == 0:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.solver.checkpoint(path)

    def restart(self, path: Path) -> None:
        self.solver.restart(path)


GAS_STATE = ("density", "pressure", "specific_internal_energy", "sound_speed", "artificial_viscosity")
"""The zone fields that describe the gas in a zone (and their per-material columns, <name>_<material>):
NaN in the output where bodies fill the zone whole (_blank_covered)."""


def _blank_covered(cell_data: dict) -> None:
    """Zones wholly inside bodies (blocked_fraction 1) hold no gas: their gas state is written as NaN,
    so that ParaView's colour ranges and Plot Over Time see only gas (a covered zone's density and
    pressure read 0 before: the default range started at 0 and hid the gas around the body); the
    volume and blocked fractions stay (they say the zone is covered).  A covered zone that still
    holds gas (density > 0: a leak, what checks' covered_gas_mass measures) keeps its values."""
    bf = cell_data.get("blocked_fraction")
    if bf is None:
        return
    covered = np.asarray(bf) >= 1.0 - 1e-12
    if "density" in cell_data:
        covered &= np.asarray(cell_data["density"]) == 0.0
    if not covered.any():
        return
    for name, a in cell_data.items():
        if name in GAS_STATE or any(name.startswith(f"{g}_") for g in GAS_STATE):
            cell_data[name] = np.where(covered, np.nan, a)


if __name__ == "__main__":
    from adapters.protocol import exit_after_clean_end
    from adapters.runtime import serve

    serve(AleAdapter)
    exit_after_clean_end()
