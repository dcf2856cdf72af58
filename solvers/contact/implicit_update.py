"""Steps 2 and 3 of the seed's contact update for the energy-momentum implicit step (issue 12, item 2;
seed slides "Structure preserving time integration w/ contact", "3 Step Process" and the one after).

Step 1 (the midpoint step with its multipliers) leaves velocities v^{n+1}. Step 2 removes the normal
gap rate on the active contact rows G (the dual pass's constraint operator on them) with a velocity
update at fixed positions:

    M (vbar - v) + G^T lbar = 0,   G vbar = 0
    =>  (G M^-1 G^T) lbar = G v,   vbar = v - M^-1 G^T lbar,

which is strictly dissipative: with d = vbar - v, vbar.M vbar = v.M v - d.M d because
vbar.M d = -(G vbar).lbar = 0, so the kinetic energy drops by

    kappa = 1/2 d.M d = 1/2 lbar.(G M^-1 G^T) lbar = 1/2 lbar.(G v)   (>= 0),

row A's share kappa_A = 1/2 lbar_A (G v)_A (the seed's kappa-bar, which sums to kappa). No chatter:
the contact rows leave the step with zero normal gap rate.

Step 3 returns stored dissipation K (the kappas of a contact episode) when its rows are released: a
velocity change along the released rows' forces f = G_rel^T k (k_A: the energy each row stored),

    vbarbar = vbar + s M^-1 f,   s >= 0 the root of  1/2 s^2 f.M^-1 f + s vbar.f = K,

so that 1/2 vbarbar.M vbarbar - 1/2 vbar.M vbar = K exactly (the seed's alpha^2 is s, there with
vbar.f = 0). f sums to zero, and to zero moment about the positions its rows were built at (the
caller builds them where the velocities change, x_{n+1}), so the momenta are unchanged.

M is the lumped (diagonal) mass, given as its inverse per dof (0 on held dofs); G a scipy sparse
matrix (rows x dofs). The normal system is singular as a rule (dependent rows: the dual pass's two
passes on one interface, rows on held dofs) but consistent: it is solved by least squares
(_consistent_solve), which gives G vbar = 0 and the energy identity to round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["GapRateUpdate", "release_impulse", "remove_gap_rate", "return_energy"]


@dataclass
class GapRateUpdate:
    v: np.ndarray          # (ndof,) vbar: no normal gap rate on the rows
    multipliers: np.ndarray  # (nrows,) lbar
    dissipated: float      # kappa = 1/2 (vbar - v).M (vbar - v) >= 0
    per_row: np.ndarray    # (nrows,) kappa_A = 1/2 lbar_A (G v)_A, summing to kappa


DENSE_ROWS = 2000
"""Up to this many rows S is solved dense (least squares, its rank decided by the SVD)."""


def _consistent_solve(S, rhs: np.ndarray) -> np.ndarray:
    """A solution of S x = rhs with rhs in S's range (S = G M^-1 G^T and rhs = G v: the free dofs'
    part), exact to round-off also when S is singular: the dual pass's two passes on one interface,
    or rows on held dofs, are dependent, and SuperLU then returned huge multipliers without failing
    (a ring bouncing on a held floor gained 0.8 J at a release). Dense least squares up to DENSE_ROWS
    rows, above them SuperLU checked by its residual, LSQR where that fails."""
    n = S.shape[0]
    if n <= DENSE_ROWS:
        return np.linalg.lstsq(S.toarray(), rhs, rcond=1e-12)[0]
    scale = max(float(np.linalg.norm(rhs)), 1e-300)
    try:
        x = spla.splu(S).solve(rhs)
        if np.all(np.isfinite(x)) and np.linalg.norm(S @ x - rhs) <= 1e-10 * scale:
            return x
    except RuntimeError:
        pass
    return spla.lsqr(S, rhs, atol=1e-15, btol=1e-15, iter_lim=10 * n)[0]


def remove_gap_rate(G, inv_mass: np.ndarray, v: np.ndarray) -> GapRateUpdate:
    """Step 2 (module docstring): vbar with G vbar = 0 at the least kinetic energy change."""
    G = sp.csr_matrix(G)
    v = np.asarray(v, dtype=np.float64)
    inv_mass = np.asarray(inv_mass, dtype=np.float64)
    if G.shape[0] == 0:
        return GapRateUpdate(v=v.copy(), multipliers=np.zeros(0), dissipated=0.0, per_row=np.zeros(0))
    rate = G @ v
    S = (G @ sp.diags(inv_mass) @ G.T).tocsc()
    lam = _consistent_solve(S, rate)
    vbar = v - inv_mass * (G.T @ lam)
    # kappa from the velocities themselves (the identity's 1/2 lbar.(G v) holds only as well as the
    # singular solve: 1.3e-10 on the dual pass's rows), the rows' shares scaled to sum to it
    free = inv_mass > 0.0
    d = (vbar - v)[free]
    kappa = -float(np.sum((v[free] * d + 0.5 * d * d) / inv_mass[free]))
    per_row = 0.5 * lam * rate
    total = float(per_row.sum())
    if total != 0.0:
        per_row = per_row * (kappa / total)
    return GapRateUpdate(v=vbar, multipliers=lam, dissipated=kappa, per_row=per_row)


def return_energy(G_released, inv_mass: np.ndarray, v: np.ndarray, stored: np.ndarray) -> np.ndarray:
    """Step 3 (module docstring): velocities with the energy K = sum(stored) given back along the
    released rows' forces (release_impulse's)."""
    return np.asarray(v, dtype=np.float64) + np.asarray(inv_mass, dtype=np.float64) * release_impulse(
        G_released, inv_mass, v, stored)


def release_impulse(G_released, inv_mass: np.ndarray, v: np.ndarray, stored: np.ndarray) -> np.ndarray:
    """Step 3's impulse s f on every dof, held ones included (there the supports take it), f =
    G_released^T stored: K = sum(stored) > 0 pushes the sides apart, the positive root s; K < 0, an
    episode that gained energy, is taken out, the root nearest zero. Where the direction cannot take
    out that much (b^2 + 2 a K < 0), as much as it can (s = -b / a); the caller books the change it
    got. Zeros where nothing can be given back."""
    G = sp.csr_matrix(G_released)
    v = np.asarray(v, dtype=np.float64)
    k = np.asarray(stored, dtype=np.float64)
    total = float(k.sum())
    if G.shape[0] == 0 or total == 0.0:
        return np.zeros_like(v)
    f = G.T @ k
    mf = np.asarray(inv_mass, dtype=np.float64) * f
    a = float(f @ mf)               # f.M^-1 f
    b = float(v @ f)                # vbar.f
    if a <= 0.0:
        return np.zeros_like(v)     # (no free dof along the released rows: nothing to give back)
    disc = b * b + 2.0 * a * total
    if disc < 0.0:                  # (K < 0 beyond this direction's reach: its most)
        s = -b / a
    elif total > 0.0:               # 1/2 a s^2 + b s - K = 0, the root s >= 0 (no cancellation)
        s = 2.0 * total / (b + np.sqrt(disc)) if b > 0.0 else (np.sqrt(disc) - b) / a
    else:
        s = 2.0 * total / (b + np.copysign(np.sqrt(disc), b)) if b != 0.0 else 0.0
    return s * f
