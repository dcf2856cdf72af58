"""A coupled run in one process (tests, benchmarks, the kernel warm-up): the ALE background and the Lagrangian bodies on
MPI.COMM_SELF, driven through the same hooks and in the same order as adapters/runtime.py and the
coupler's _coupled_step, without launching a job.  What the job sends between its processes goes through
the same packing here (adapters/runtime.py's surface buffer, BodyGeometry.pack, float64 copies of the
per-step arrays): the coupling kernels see the arrays a job's coupler sees (new, writable, of the
wire's dtypes), so that they compile to the same specialisations (the kernel warm-up steps this class:
a signature only it used, a read-only surface array, was compiled there and never used by a job, and
the job's own was compiled at run time)."""
from __future__ import annotations

import numpy as np


class _Sender:
    """The Lagrange solver as adapters/runtime.pack_surface reads an adapter."""

    def __init__(self, lag):
        self.surface = lag.surface
        self.positions = lambda: lag.surface_state("x")
        self.velocities = lambda: lag.surface_state("v")


def surface_of(lag):
    """The surface as the coupler receives it (TAG_SURFACE: pack_surface, unpack_surface)."""
    from adapters.runtime import pack_surface, unpack_surface

    return unpack_surface(pack_surface(_Sender(lag)), lag.dim)


def _wire(a) -> np.ndarray:
    """An array as a message delivers it (protocol.send / recv: a new float64 buffer)."""
    return np.array(a, dtype=np.float64)


def _geometry(coupling, dim: int):
    """The bodies' geometry as the background receives it (TAG_GEOMETRY)."""
    from solvers.ale.coupled import BodyGeometry

    return BodyGeometry.unpack(coupling.geometry().pack(dim), dim)


class InProcess:
    def __init__(self, case: dict):
        from mpi4py import MPI

        from orchestrator.coupling.embedded import EmbeddedCoupling
        from solvers.ale.solver import AleSolver
        from solvers.lagrange.solver import LagrangeSolver

        comm = MPI.COMM_SELF
        self.case = case
        self.lag = LagrangeSolver(comm, case)
        self.coupling = EmbeddedCoupling(case, surface_of(self.lag))
        self.ale = AleSolver(comm, case["ale"], bodies=_geometry(self.coupling, self.lag.dim))
        self.t, self.step, self.dt_prev = 0.0, 0, 0.0
        self.dt_scale = float(case["run"].get("dt_scale", 0.9))

    def advance(self, dt: float) -> None:
        c, lag, ale = self.coupling, self.lag, self.ale
        self.step += 1
        t_new = self.t + dt
        dt_avg = 0.5 * dt if self.dt_prev == 0.0 else 0.5 * (self.dt_prev + dt)
        lag.predict(dt)
        ale.predict(dt)
        imp = c.solve(dt, dt_avg, _wire(lag.constraint_velocity()).reshape(-1, c.dim), _wire(ale.interface()))
        lag.correct(surface_impulse=_wire(imp), step=self.step, time=t_new)
        corr = _wire(c.background_correction(_wire(lag.surface_state("x")), _wire(lag.surface_state("v"))))
        nn, dim = ale._blk.nodes[0].size, ale.dim
        a, b = nn * dim, nn * dim + ale._blk.n_cut * dim
        ale.correct(None, self.step, t_new, coupling={"impulse": corr[:a].reshape(nn, dim),
                                                      "v_half": corr[a:b].reshape(-1, dim),
                                                      "v_bar": corr[b:].reshape(-1, dim)})
        ale.remap(_geometry(c, ale.dim))
        self.t, self.dt_prev = t_new, dt

    def run(self, end_time: float, max_steps: int = 10**7) -> "InProcess":
        while self.t < end_time * (1 - 1e-12) and self.step < max_steps:
            dt = self.dt_scale * min(self.lag.stable_dt(), self.ale.stable_dt())
            self.advance(min(dt, end_time - self.t))
        return self
