"""solvers/contact/friction.py: the box-constrained quadratic program of the friction impulses, against
its optimality conditions."""
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from solvers.contact.friction import box_qp_gauss_seidel


def test_projected_gauss_seidel_meets_the_box_kkt_conditions():
    rng = np.random.default_rng(4)
    a = sp.random(30, 12, density=0.3, random_state=5) + sp.eye(30, 12)
    W = (a.T @ a + 0.1 * sp.eye(12)).tocsr()   # symmetric positive definite, sparse
    b = rng.normal(size=12)
    bound = rng.uniform(0.0, 0.5, 12)
    bound[3] = 0.0                              # a row with no normal impulse: no friction there
    q, sweeps = box_qp_gauss_seidel(W, b, bound, tol=1e-14)
    g = W @ q + b                               # the gradient: zero inside, opposing the bound at it
    inside = np.abs(q) < bound * (1 - 1e-12)
    assert np.all(np.abs(q) <= bound) and q[3] == 0.0
    assert np.abs(g[inside]).max() <= 1e-14 * np.abs(b).max()  # measured 1.8e-15 (35 sweeps)
    at = ~inside & (bound > 0)
    assert at.any() and np.all(g[at] * np.sign(q[at]) <= 1e-12)
    # unconstrained (large bounds): the linear solve, to the default tolerance (rates settled to 1e-10
    # of the largest |b|)
    q, _ = box_qp_gauss_seidel(W, b, np.full(12, 1e9))
    np.testing.assert_allclose(q, np.linalg.solve(W.toarray(), -b), rtol=1e-9)  # measured 2.3e-10


def test_disc_gauss_seidel_meets_the_cone_kkt_conditions():
    """Two components per block (3-D friction): inside its disc a block's gradient W q + b vanishes; on
    it, the gradient points against q (isotropic Coulomb: the impulse opposes the slip, along it)."""
    from solvers.contact.friction import disc_qp_gauss_seidel

    rng = np.random.default_rng(7)
    a = sp.random(40, 16, density=0.3, random_state=8) + sp.eye(40, 16)
    W = (a.T @ a + 0.1 * sp.eye(16)).tocsr()
    b = rng.normal(size=16)
    radius = rng.uniform(0.0, 0.5, 8)
    radius[2] = 0.0
    q, sweeps = disc_qp_gauss_seidel(W, b, radius, tol=1e-14)
    qb, g = q.reshape(8, 2), (W @ q + b).reshape(8, 2)
    size = np.linalg.norm(qb, axis=1)
    assert np.all(size <= radius * (1 + 1e-15)) and np.all(qb[2] == 0.0)
    inside = size < radius * (1 - 1e-12)
    assert inside.any() and np.abs(g[inside]).max() <= 3e-14 * np.abs(b).max()   # measured 5.9e-15 (74 sweeps)
    at = ~inside & (radius > 0)
    assert at.any()
    # on the disc: g = -c q, c >= 0: g's component across q vanishes and along q it is negative
    cross = g[at, 0] * qb[at, 1] - g[at, 1] * qb[at, 0]
    along = np.einsum("ij,ij->i", g[at], qb[at])
    assert np.abs(cross).max() <= 2e-15 * np.abs(b).max() * radius.max() and np.all(along < 0)  # measured 3.7e-16
    with pytest.raises(ValueError, match="do not split"):
        disc_qp_gauss_seidel(W, b, radius[:5])


def test_a_resting_blocks_singular_program_stops_on_its_floor():
    """The friction program of one step of the 3-D block resting on a 10 degree incline
    (cases/block_on_incline_3d at 0.2 s; data/: W = T M^-1 T^T, singular by the dual pass's redundant
    rows; 40 of 50 blocks stuck, the others at their rims): the sweeps converge geometrically to a
    change of about 1e-9 of |b| and then wander there. The iteration stops on that floor (no halving
    in 100 sweeps) with the stuck rows' slip rates as low as 10,000 sweeps leave them."""
    from solvers.contact.friction import disc_qp_gauss_seidel

    d = np.load(Path(__file__).parent / "data" / "resting_block_friction_qp.npz")
    W = sp.csr_matrix((d["data"], d["indices"], d["indptr"]), shape=tuple(d["shape"]))
    b, radius, start = d["b"], d["radius"], d["start"]

    def stuck_rates(q):
        size = np.linalg.norm(q.reshape(-1, 2), axis=1)
        stuck = np.repeat((radius > 0) & (size < radius * (1 - 1e-9)), 2)
        return np.abs((W @ q + b)[stuck]).max()

    q, sweeps = disc_qp_gauss_seidel(W, b, radius, start=start)
    assert sweeps < 1000                                                 # measured 226
    assert stuck_rates(q) <= 3e-9 * np.abs(b).max()                      # measured 9.6e-10, 6.9e-16 m/s
    assert np.all(np.linalg.norm(q.reshape(-1, 2), axis=1) <= radius * (1 + 1e-15))
    # without the floor's stop it takes all 10,000 sweeps, to no lower rates
    q_all, sweeps_all = disc_qp_gauss_seidel(W, b, radius, start=start, stall_tol=0.0)
    assert sweeps_all == 10000 and stuck_rates(q_all) >= 0.5 * stuck_rates(q)   # measured 6.2e-16
