"""Coulomb friction of the explicit contact step: the tangential impulses, after the normal ones.

With the normal impulses P_A of the step known (explicit.py), the tangential impulses q_A of each
multiplier (in 2-D one component, along t_A = (n_y, -n_x); in 3-D two, along the tangents t1_A,
t2_A: dual_pass.py) stop the sliding where they can and slide at the Coulomb bound where they
cannot:

    W q + b = s,   |q_A| <= mu P_A,   s_A = 0 where |q_A| < mu P_A (stick),
    otherwise s_A = -c q_A with c >= 0 (the impulse opposes the slip, along it: isotropic Coulomb),

with W = T M^-1 T^T (T the tangential operator, t_A in place of n_A in the gap operator G, the
dual pass's 1/2 included; no stabilization: stick is T v = 0 itself, and a J_t let stuck rows creep
at T v = -J_t q; W is then singular, the passes' rows being redundant) and b = T v the
tangential slip rates of the velocities after the normal impulses. That is the quadratic program
min 1/2 q.W q + b.q over the discs |q_A| <= mu P_A (in 2-D intervals), solved by projected block
Gauss-Seidel (numba; one pass over the rows of W in csr form per sweep) to a slip-rate change below
1e-12 of the largest, or to its floor below 1e-8 of it (disc_qp_gauss_seidel): in 2-D the exact Gauss-Seidel step of each row, clamped; in 3-D per multiplier one projected
gradient step q_A <- P(q_A - g_A / L_A) onto its disc, L_A the largest eigenvalue of W's 2 x 2 block
(at its fixed point g_A = -c q_A, c >= 0: the impulse opposes the slip along it). Friction dissipates: its impulses oppose the slip, and their work is in
the contact work.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["disc_qp_gauss_seidel", "box_qp_gauss_seidel"]


@njit(cache=True)
def _pgs(indptr, indices, data, diag, b, k, radius, q, atol, stall_atol, stall_sweeps, max_sweeps):
    n = b.shape[0]
    old = np.empty(k)
    g = np.empty(k)
    ref = np.inf      # the change the next halving is counted from, and the sweep it was reached at
    ref_sweep = 0
    for sweep in range(max_sweeps):
        change = 0.0
        for blk in range(n // k):
            r0 = blk * k
            rad = radius[blk]
            if k == 1:   # (an interval: the exact Gauss-Seidel step, clamped)
                old[0] = q[r0]
                if diag[r0] > 0.0:
                    r = b[r0]
                    for j in range(indptr[r0], indptr[r0 + 1]):
                        r += data[j] * q[indices[j]]
                    new = q[r0] - r / diag[r0]
                    q[r0] = -rad if new < -rad else (rad if new > rad else new)
            else:
                # a disc: one projected gradient step on the block, q_A <- P(q_A - g_A / L_A) with L_A
                # the largest eigenvalue of its 2 x 2 diagonal block W_AA. A step scaled per component
                # (by diag W) would settle where g is parallel to D q, not to q: not isotropic Coulomb.
                w01 = 0.0
                for c in range(k):
                    i = r0 + c
                    old[c] = q[i]
                    r = b[i]
                    for j in range(indptr[i], indptr[i + 1]):
                        r += data[j] * q[indices[j]]
                        if c == 0 and indices[j] == r0 + 1:
                            w01 = data[j]
                    g[c] = r
                a, d = diag[r0], diag[r0 + 1]
                lmax = 0.5 * (a + d) + np.sqrt(0.25 * (a - d) * (a - d) + w01 * w01)
                if lmax > 0.0:
                    norm = 0.0
                    for c in range(k):
                        q[r0 + c] = q[r0 + c] - g[c] / lmax
                        norm += q[r0 + c] * q[r0 + c]
                    norm = np.sqrt(norm)
                    if norm > rad:
                        f = rad / norm
                        for c in range(k):
                            q[r0 + c] *= f
            for c in range(k):   # (the change of the row's slip rate the update made)
                change = max(change, abs(q[r0 + c] - old[c]) * diag[r0 + c])
        if change <= atol:
            return sweep + 1
        if change < 0.5 * ref:
            ref, ref_sweep = change, sweep
        elif change <= stall_atol and sweep - ref_sweep >= stall_sweeps:
            return sweep + 1   # (settled on its floor: no halving in stall_sweeps sweeps)
    return max_sweeps


def disc_qp_gauss_seidel(W, b: np.ndarray, radius: np.ndarray, tol: float = 1e-12, max_sweeps: int = 10000,
                         atol: float | None = None, start: np.ndarray | None = None, stall_tol: float = 1e-8,
                         stall_sweeps: int = 100):
    """q minimising 1/2 q.W q + b.q with each block q[k A : k A + k] in the disc (k = 1: interval) of
    radius radius_A, k = len(b) / len(radius) (W sparse symmetric positive semidefinite, positive on
    the diagonal where the radius is > 0), from ``start`` (default 0; the last step's q where the
    multipliers are the same: a resting contact's impulses barely change); returns (q, sweeps).

    Stops when no update of a sweep changed its row's slip rate (W q + b)_i by more than atol
    (default tol times the largest |b_i|): a rate, not q itself, because a row whose overlap is a
    sliver has a tiny W_ii and its q wanders on in the null space of a singular W (the dual pass's
    redundant rows) without moving anything: stopping on q's change took the 10000 sweeps every step
    on a block resting in 3-D.

    Also stops on a floor: once the change is below stall_tol times the largest |b_i| and has not
    halved in stall_sweeps sweeps. The block resting on an incline in 3-D (40 of 50 blocks stuck, the
    others at their rims) converges geometrically to a change of 6e-16 (1e-9 of |b|) by sweep 200-
    1000 and then wanders there: 10,000 sweeps gave stuck rates of 6.2e-16, 1,000 of 6.6e-16, and
    each step took the 10,000 (0.13 s of its 0.17 s). A stop on the floor keeps the rates within
    stall_tol of |b| (a fixed cap of 100 sweeps left rates of 1e-5 of |b|: 4.5e-11 m of slip)."""
    W = W.tocsr()
    b = np.asarray(b, np.float64)
    radius = np.asarray(radius, np.float64)
    k = len(b) // max(len(radius), 1)
    if len(radius) * k != len(b) or k not in (1, 2):
        raise ValueError(f"disc_qp_gauss_seidel: {len(b)} rows do not split into {len(radius)} blocks of 1 or 2")
    b_max = float(np.abs(b).max(initial=0.0))
    if atol is None:
        atol = tol * b_max
    q = np.zeros(len(b)) if start is None else np.array(start, dtype=np.float64, copy=True)
    sweeps = _pgs(W.indptr.astype(np.int64), W.indices.astype(np.int64), W.data.astype(np.float64),
                  W.diagonal().astype(np.float64), b, k, radius, q, float(atol),
                  max(float(atol), stall_tol * b_max), int(stall_sweeps), max_sweeps)
    return q, sweeps


def box_qp_gauss_seidel(W, b: np.ndarray, bound: np.ndarray, tol: float = 1e-12, max_sweeps: int = 10000):
    """q minimising 1/2 q.W q + b.q with |q_i| <= bound_i (the 2-D case of disc_qp_gauss_seidel)."""
    return disc_qp_gauss_seidel(W, b, bound, tol, max_sweeps)
