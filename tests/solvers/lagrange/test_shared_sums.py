"""solvers/lagrange/shared_sums.py: the nodes on partition cuts sum their elements' contributions in
the one-rank order, so a body on several ranks runs bit for bit as on one (under mpiexec -n 2)."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from orchestrator.case import load_case
from solvers.lagrange.solver import LagrangeSolver
from tests.conftest import CASES


@pytest.mark.mpi
def test_taylor_bar_on_all_ranks_equals_one_rank_bitwise():
    """The Taylor bar (3-D hexahedra, plasticity, contact-free impact on a rigid wall) for 30 steps
    on COMM_WORLD and on one rank: masses, velocities and positions bit for bit.  (With each rank's
    partial sums added by an Allreduce the velocities differed by 1e-22 after 30 steps and by
    1.7e-13 after 200.)"""
    case = load_case(CASES / "taylor_bar")
    runs = {}
    for name, comm in (("one", MPI.COMM_SELF), ("all", MPI.COMM_WORLD)):
        s = LagrangeSolver(comm, case)
        t = 0.0
        for k in range(30):
            dt = 0.9 * s.stable_dt()
            s.predict(dt)
            t += dt
            s.correct(step=k + 1, time=t)
        runs[name] = (s.gather_nodes(s.mass[:, None]), s.gather_nodes(s.v), s.gather_nodes(s.x))
    if MPI.COMM_WORLD.rank == 0:  # (gathered on rank 0)
        for a, b in zip(runs["one"], runs["all"]):
            assert np.array_equal(a, b)
