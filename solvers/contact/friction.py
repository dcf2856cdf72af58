"""Coulomb friction of the explicit contact step: the tangential impulses, after the normal ones.

With the normal impulses P_A of the step known (explicit.py), the tangential impulses q (one per
multiplier, along its tangent t_A = (n_y, -n_x)) stop the sliding where they can and slide at the
Coulomb bound where they cannot:

    W q + b = s,   |q_A| <= mu P_A,   s_A = 0 where |q_A| < mu P_A (stick),
    otherwise s_A q_A <= 0 (the impulse opposes the slip),

with W = T M^-1 T^T (T the tangential operator, t_A in place of n_A in the gap operator G, the
dual pass's 1/2 included; no stabilization: stick is T v = 0 itself, and a J_t let stuck rows creep
at T v = -J_t q; W is then singular, the passes' rows being redundant) and b = T v the
tangential slip rates of the velocities after the normal impulses. That is the box-constrained
quadratic program min 1/2 q.W q + b.q over |q_A| <= mu P_A, solved by projected Gauss-Seidel (numba:
one pass over the rows of W in csr form per sweep) to a relative change below 1e-13. Friction
dissipates: its impulses oppose the slip, and their work is in the contact work.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["box_qp_gauss_seidel"]


@njit(cache=True)
def _pgs(indptr, indices, data, diag, b, lo, hi, q, tol, max_sweeps):
    n = b.shape[0]
    for sweep in range(max_sweeps):
        change = 0.0
        size = 0.0
        for i in range(n):
            if diag[i] <= 0.0:
                continue
            r = b[i]
            for k in range(indptr[i], indptr[i + 1]):
                r += data[k] * q[indices[k]]
            new = q[i] - r / diag[i]
            if new < lo[i]:
                new = lo[i]
            elif new > hi[i]:
                new = hi[i]
            change = max(change, abs(new - q[i]))
            size = max(size, abs(new))
            q[i] = new
        if change <= tol * max(size, 1e-300):
            return sweep + 1
    return max_sweeps


def box_qp_gauss_seidel(W, b: np.ndarray, bound: np.ndarray, tol: float = 1e-13, max_sweeps: int = 10000):
    """q minimising 1/2 q.W q + b.q with |q_i| <= bound_i (W sparse symmetric positive semidefinite,
    positive on the diagonal where bound > 0); returns (q, sweeps)."""
    W = W.tocsr()
    q = np.zeros(len(b))
    sweeps = _pgs(W.indptr.astype(np.int64), W.indices.astype(np.int64), W.data.astype(np.float64),
                  W.diagonal().astype(np.float64), np.asarray(b, np.float64), -np.asarray(bound, np.float64),
                  np.asarray(bound, np.float64), q, tol, max_sweeps)
    return q, sweeps
