"""The ranks' share of a gathered step (solvers/lagrange/gathered_step.py RankShare): the elements,
evaluated in parallel and gathered or all on every rank, equal one rank's bit for bit; a solve on rank 0 reaches every rank,
its exception too (no rank left waiting). Run serially and under mpiexec -n 2."""
import numpy as np
import pytest
from mpi4py import MPI

from solvers.lagrange.gathered_step import RankShare
from solvers.lagrange.midpoint_svk import midpoint_elements
from tests.solvers.lagrange.test_finite_strain import MESHES


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["quad", "hex"])
def test_the_elements_gathered_from_the_ranks_are_one_ranks(kind):
    p, cells = MESHES[kind]()
    rng = np.random.default_rng(2)
    u0, u1 = 0.01 * rng.standard_normal(p.shape), 0.01 * rng.standard_normal(p.shape)
    share = RankShare(MPI.COMM_WORLD, [(cells, 1.0, 2.0)], p)
    k1, f1 = midpoint_elements(p, cells, u0, u1, 1.0, 2.0)
    # the first evaluation, the second (measuring both ways), then each way
    for split in (None, None, True, False):
        if split is not None:
            share.split[(0, midpoint_elements)] = split
        ke, fe = share.elements(0, midpoint_elements, u0, u1, 1.0, 2.0)
        assert np.array_equal(ke, k1) and np.array_equal(fe, f1), split
    assert isinstance(share.split[(0, midpoint_elements)], bool)


@pytest.mark.mpi
def test_a_solve_on_rank_0_reaches_every_rank_and_so_does_its_failure():
    share = RankShare(MPI.COMM_WORLD, [], np.zeros((1, 2)))
    got = share.on_root(lambda: MPI.COMM_WORLD.rank + 41.0)
    assert got == 41.0                                    # rank 0's result, on every rank

    def fail():
        raise RuntimeError("the contact KKT system is singular (test)")
    with pytest.raises(RuntimeError, match="singular"):
        share.on_root(fail)


@pytest.mark.mpi
def test_an_element_failing_on_one_rank_fails_every_rank():
    """An inverted element sits in one rank's share: every rank raises (none waits in the gather)."""
    p, cells = MESHES["quad"]()
    share = RankShare(MPI.COMM_WORLD, [(cells, 1.0, 2.0)], p)

    def fails(points, mine, *args):
        if share.shares[0][0] == 0:            # (rank 0's share, the only one serially)
            raise ValueError("an element is inverted (J <= 0 at a Gauss point)")
        return midpoint_elements(points, mine, *args)
    share.split[(0, fails)] = True
    with pytest.raises((ValueError, RuntimeError), match="inverted"):
        share.elements(0, fails, np.zeros(p.shape), np.zeros(p.shape), 1.0, 2.0)
