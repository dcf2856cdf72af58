"""solvers/contact/friction.py: the box-constrained quadratic program of the friction impulses, against
its optimality conditions."""
import numpy as np
import scipy.sparse as sp

from solvers.contact.friction import box_qp_gauss_seidel


def test_projected_gauss_seidel_meets_the_box_kkt_conditions():
    rng = np.random.default_rng(4)
    a = sp.random(30, 12, density=0.3, random_state=5) + sp.eye(30, 12)
    W = (a.T @ a + 0.1 * sp.eye(12)).tocsr()   # symmetric positive definite, sparse
    b = rng.normal(size=12)
    bound = rng.uniform(0.0, 0.5, 12)
    bound[3] = 0.0                              # a row with no normal impulse: no friction there
    q, sweeps = box_qp_gauss_seidel(W, b, bound)
    g = W @ q + b                               # the gradient: zero inside, opposing the bound at it
    inside = np.abs(q) < bound * (1 - 1e-12)
    assert np.all(np.abs(q) <= bound) and q[3] == 0.0
    assert np.abs(g[inside]).max() <= 1e-13 * np.abs(b).max()  # measured 1.9e-14 (33 sweeps)
    at = ~inside & (bound > 0)
    assert at.any() and np.all(g[at] * np.sign(q[at]) <= 1e-12)
    # unconstrained (large bounds): the linear solve
    q, _ = box_qp_gauss_seidel(W, b, np.full(12, 1e9))
    np.testing.assert_allclose(q, np.linalg.solve(W.toarray(), -b), rtol=1e-12)  # measured 1.1e-13
