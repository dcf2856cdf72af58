"""A coupled run in one process (tests, benchmarks, the kernel warm-up): the ALE background and the Lagrangian bodies on
MPI.COMM_SELF, driven through the same hooks and in the same order as adapters/runtime.py and the
coupler's _coupled_step, without launching a job."""
from __future__ import annotations

import numpy as np


def surface_of(lag):
    srf = dict(lag.surface())
    srf["x"] = lag.surface_state("x")
    srf["v"] = lag.surface_state("v")
    return srf


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
        self.ale = AleSolver(comm, case["ale"], bodies=self.coupling.geometry())
        self.t, self.step, self.dt_prev = 0.0, 0, 0.0
        self.dt_scale = float(case["run"].get("dt_scale", 0.9))

    def advance(self, dt: float) -> None:
        c, lag, ale = self.coupling, self.lag, self.ale
        self.step += 1
        t_new = self.t + dt
        dt_avg = 0.5 * dt if self.dt_prev == 0.0 else 0.5 * (self.dt_prev + dt)
        lag.predict(dt)
        ale.predict(dt)
        imp = c.solve(dt, dt_avg, lag.constraint_velocity(), ale.interface())
        lag.correct(surface_impulse=imp, step=self.step, time=t_new)
        corr = c.background_correction(lag.surface_state("x"), lag.surface_state("v"))
        nn, dim = ale._blk.nodes[0].size, ale.dim
        a, b = nn * dim, nn * dim + ale._blk.n_cut * dim
        ale.correct(None, self.step, t_new, coupling={"impulse": corr[:a].reshape(nn, dim),
                                                      "v_half": corr[a:b].reshape(-1, dim),
                                                      "v_bar": corr[b:].reshape(-1, dim)})
        ale.remap(c.geometry())
        self.t, self.dt_prev = t_new, dt

    def run(self, end_time: float, max_steps: int = 10**7) -> "InProcess":
        while self.t < end_time * (1 - 1e-12) and self.step < max_steps:
            dt = self.dt_scale * min(self.lag.stable_dt(), self.ale.stable_dt())
            self.advance(min(dt, end_time - self.t))
        return self
