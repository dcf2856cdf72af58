"""The coupler and the solver ranks wait for each other without spinning a core (adapters.protocol).

MPI's blocking calls busy-poll: a rank waiting a second for another's start-up or step burns a core
the whole second, and the suite and small jobs run with more processes than cores.  Each wait here
lasts ``DELAY`` s on the waiting side; a spinning wait uses about that much CPU (measured with a
blocking ``recv``/``Bcast``: 0.89 and 0.90 of the wait's wall time, beside a running suite), the
protocol's waits 0.11 and 0.07 of it."""
import time

import numpy as np
import pytest
from mpi4py import MPI

from adapters import protocol as P

DELAY = 0.4
CPU_SHARE_BOUND = 0.5  # of the wait's wall time (measured 0.07-0.11; a spinning wait 0.89-0.90)

pytestmark = [pytest.mark.mpi,
              pytest.mark.skipif(MPI.COMM_WORLD.size != 2, reason="needs exactly 2 MPI ranks")]


def _cpu_share(wait) -> float:
    wall0, cpu0 = time.perf_counter(), time.process_time()
    wait()
    return (time.process_time() - cpu0) / (time.perf_counter() - wall0)


def test_recv_object_waits_without_spinning():
    world = MPI.COMM_WORLD
    world.Barrier()
    if world.rank == 1:
        time.sleep(DELAY)  # a solver rank's start-up
        world.send(["mass", "momentum_x"], dest=0, tag=6)
        return
    got = []
    share = _cpu_share(lambda: got.append(P.recv_object(world, 1, 6)))
    assert got == [["mass", "momentum_x"]]
    assert share < CPU_SHARE_BOUND


def test_wait_on_a_broadcast_does_not_spin_and_share_delivers():
    """A command broadcast the other ranks wait for (the coupler's solve, an output), then a buffer
    shared by the root (adapters.runtime.serve, protocol.share)."""
    world = MPI.COMM_WORLD
    world.Barrier()
    cmd = np.zeros(3)
    if world.rank == 0:
        time.sleep(DELAY)
        cmd[:] = [1.0, 2.5e-3, 7.0]
        P.wait(world.Ibcast(cmd, root=0))
        time.sleep(DELAY)
        P.share(world, np.arange(5.0))
        return
    share_cmd = _cpu_share(lambda: P.wait(world.Ibcast(cmd, root=0)))
    assert cmd.tolist() == [1.0, 2.5e-3, 7.0]
    out = []
    share_buf = _cpu_share(lambda: out.append(P.share(world, None)))
    assert out[0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert share_cmd < CPU_SHARE_BOUND and share_buf < CPU_SHARE_BOUND
