"""Node-wise kernels of the central-difference step, fused so that each step makes one pass over
the nodes for the predictor and one for the update and its balance sums (numpy would make ~15)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def predict_velocity(v, v_old, f, inv_mass, dt_avg):
    """v_old <- v;  v <- v + dt_avg f / m."""
    nn, dim = v.shape
    for i in range(nn):
        for c in range(dim):
            v_old[i, c] = v[i, c]
            v[i, c] += dt_avg * f[i, c] * inv_mass[i]


@njit(cache=True)
def rigid_wall(x, v, point, normal, dt):
    """Frictionless wall: a node may not cross the plane during this step; tangential motion free."""
    nn, dim = v.shape
    for i in range(nn):
        gap = 0.0
        vn = 0.0
        for c in range(dim):
            gap += (x[i, c] - point[c]) * normal[c]
            vn += v[i, c] * normal[c]
        if gap + dt * vn < 0.0:
            dv = -gap / dt - vn
            for c in range(dim):
                v[i, c] += dv * normal[c]


@njit(cache=True, inline="always")
def account_node(i, x, v, v_old, v_free, f, mass, impulse, has_impulse, dt_avg, dv_prev, r, xi):
    """One node's share of a kick's balances, update_and_account's per node (subcycling.account_nodes
    calls it at each node's own dt_avg): its reaction R = m (v - v_free) (+ impulse) into r, its
    position before the move into xi, dv_prev updated; returns (internal work, R's work on the mean
    velocity, |dv - dv_prev|^2, |v|^2, whether a component is not finite).  update_and_account keeps
    the same arithmetic fused in its own loop: calling this from it cost 5 % of a quad's
    element-cycle (bench lagrange, 10^5 quads: 0.081 against 0.077 us) -- change the two together."""
    dim = v.shape[1]
    wi = 0.0
    we = 0.0
    hf = 0.0
    v2 = 0.0
    nonfinite = False
    for c in range(3):
        r[c] = 0.0
        xi[c] = 0.0
    for c in range(dim):
        vc = v[i, c]
        if not np.isfinite(vc):
            nonfinite = True
        rc = mass[i] * (vc - v_free[i, c])
        if has_impulse:
            rc += impulse[i, c]
        vbar = 0.5 * (v_old[i, c] + vc)
        wi -= dt_avg * f[i, c] * vbar
        we += rc * vbar
        r[c] = rc
        xi[c] = x[i, c]
        dv = vc - v_old[i, c]
        hf += (dv - dv_prev[i, c]) ** 2
        dv_prev[i, c] = dv
        v2 += vc * vc
    return wi, we, hf, v2, nonfinite


@njit(cache=True, inline="always")
def add_torque(sums, k, xi, a, w):
    """sums[k:k+3] += w xi x a (3-vectors: a 2-D one's z component in sums[k + 2])."""
    sums[k] += w * (xi[1] * a[2] - xi[2] * a[1])
    sums[k + 1] += w * (xi[2] * a[0] - xi[0] * a[2])
    sums[k + 2] += w * (xi[0] * a[1] - xi[1] * a[0])


@njit(cache=True)
def update_and_account(x, v, v_old, v_free, f, mass, owned, impulse, dt, dt_avg, sums, dv_prev):
    """Close the step on the nodes: reaction R = m (v - v_free) (+ coupling impulse), the exact
    discrete work of the internal forces and of R on the mean velocity, the impulse and torque of R
    (about the origin, at x^n), then x <- x + dt v. Shared nodes count once (owned).

    The highest temporal mode: with the step's velocity change dv = v^{n+1/2} - v^{n-1/2} and the
    last step's dv_prev (updated in place), sum m |dv - dv_prev|^2 is about 4 m |dv|^2 for a mode
    that turns each step (an unstable central difference grows one) and O(dt^2) of it for a motion
    the steps resolve (solvers/step_health.py watches it grow).

    sums (out): [W_int, W_ext, I_x, I_y, I_z, T_x, T_y, T_z, sum m |dv - dv_prev|^2, sum m |v|^2].
    Returns (the first node whose velocity is not finite or -1, the node of the largest
    m |dv - dv_prev|^2, that value).
    """
    nn, dim = v.shape
    for k in range(sums.shape[0]):
        sums[k] = 0.0
    has_impulse = impulse.shape[0] == nn
    bad = -1
    worst = -1
    worst_val = -1.0
    r = np.zeros(3)
    xi = np.zeros(3)
    for i in range(nn):
        w = 1.0 if owned[i] else 0.0
        wi = 0.0
        we = 0.0
        hf = 0.0
        v2 = 0.0
        for c in range(3):
            r[c] = 0.0
            xi[c] = 0.0
        for c in range(dim):
            vc = v[i, c]
            if not np.isfinite(vc) and bad < 0:
                bad = i
            rc = mass[i] * (vc - v_free[i, c])
            if has_impulse:
                rc += impulse[i, c]
            vbar = 0.5 * (v_old[i, c] + vc)
            wi -= dt_avg * f[i, c] * vbar
            we += rc * vbar
            r[c] = rc
            xi[c] = x[i, c]
            x[i, c] += dt * vc
            dv = vc - v_old[i, c]
            hf += (dv - dv_prev[i, c]) ** 2
            dv_prev[i, c] = dv
            v2 += vc * vc
        sums[0] += w * wi
        sums[1] += w * we
        for c in range(3):
            sums[2 + c] += w * r[c]
        sums[5] += w * (xi[1] * r[2] - xi[2] * r[1])
        sums[6] += w * (xi[2] * r[0] - xi[0] * r[2])
        sums[7] += w * (xi[0] * r[1] - xi[1] * r[0])
        hf *= mass[i]
        sums[8] += w * hf
        sums[9] += w * mass[i] * v2
        if hf > worst_val:
            worst_val = hf
            worst = i
    return bad, worst, worst_val
