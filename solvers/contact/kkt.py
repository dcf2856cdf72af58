"""Frictionless contact of a linear(ised) problem: the stabilized KKT system of Puso & Solberg (seed
slide "KKT Conditions") solved by a primal-dual active set (semi-smooth Newton on the complementarity).

With the stiffness K, the loads F, the dual-pass constraint operator B = G/2 (dual_pass.py) and the
stabilization J, the pressures p >= 0 and the displacements u satisfy

    K u - B^T p = F                          equilibrium (B^T p pushes the sides apart)
    g~ = B (X + u) + J p >= 0,   p >= 0,   p g~ = 0

(the slide's g(u, mu) = B u + J mu >= 0 with lambda >= 0). On the active set A (g~ = 0) the system
is the symmetric saddle point [[K, -B_A^T], [-B_A, -J_AA]], which J keeps invertible although the two
passes carry twice the multipliers the interface resolves. The set is updated from p and g~
(A = {p - c g~ > 0}, Hintermueller, Ito & Kunisch 2002, c = 1 in units where it compares the two);
for a linear problem this ends when the set repeats, in a few iterations.

Dirichlet dofs are eliminated: u_d given, equations only for the free dofs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["ContactSolution", "solve_frictionless", "solve_schur_complement"]


@dataclass
class ContactSolution:
    u: np.ndarray          # (ndof,) displacements
    p: np.ndarray          # (nm,) multiplier pressures (0 off the active set)
    gap: np.ndarray        # (nm,) stabilized gaps g~ at the solution
    active: np.ndarray     # (nm,) bool
    iterations: int


def solve_frictionless(K: sp.spmatrix, F: np.ndarray, B: sp.spmatrix, J: sp.spmatrix, X: np.ndarray,
                       fixed: np.ndarray, u_fixed: np.ndarray, max_iterations: int = 50,
                       active: np.ndarray | None = None, offset: np.ndarray | None = None) -> ContactSolution:
    """The contact solution (module docstring). K (ndof, ndof); F (ndof,); B (nm, ndof); J (nm, nm);
    X (ndof,) reference positions (B X: the initial gaps); fixed (ndof,) bool Dirichlet dofs with
    values u_fixed (ndof,) (read where fixed). Starts from ``active`` (nm,) bool (default: every
    multiplier active); ``offset`` (nm,): the rows' floors, g~ >= offset (default 0); raises
    RuntimeError if the system is singular on an active set, or the set cycles or does not settle
    within max_iterations.

    A gap counts as closed down to round-off: a multiplier joins the set when its gap is below
    -1e-12 of the scale |B| |X + u| (a gap of -1e-17 on a released node is zero, and taking it in
    would make the set cycle), and leaves it when its pressure falls below c times that."""
    K, B, J = sp.csr_matrix(K), sp.csr_matrix(B), sp.csr_matrix(J)
    nm = B.shape[0]
    fixed = np.asarray(fixed, dtype=bool)
    free = np.flatnonzero(~fixed)
    ud = np.where(fixed, u_fixed, 0.0)
    g0 = B @ (X + ud)                              # the gaps with only the prescribed motion
    if offset is not None:                         # (g~ >= offset: each row's floor)
        g0 = g0 - offset
    rhs_u = (F - K @ ud)[free]
    # the saddle-point matrix of an active set is assembled from the triplets of K on the free dofs,
    # B's and J's, selected with index maps (scipy's fancy indexing and bmat on every active-set
    # iteration were 60 % of an implicit contact step on small meshes); the same canonical CSC
    nf = len(free)
    where = np.full(len(fixed), -1, np.int64)
    where[free] = np.arange(nf)
    kc = K.tocoo()
    on = (where[kc.row] >= 0) & (where[kc.col] >= 0)
    k_rows, k_cols, k_vals = where[kc.row[on]], where[kc.col[on]], kc.data[on]
    Bf = B[:, free]
    bc, jc = Bf.tocoo(), J.tocoo()
    # scale of the comparison p - c g~: pressures against gaps, by the stiffness over the constraint
    # norm (a pushed node: g ~ |B|^2 p / k); k of the softest dof the constraints move, which sets the
    # gaps of two bodies in series (a stiff side's k would make c g~ swamp p: the set cycles)
    touched = np.unique(B.indices[B.data != 0.0])   # the dofs the constraints move
    kd = abs(K.diagonal())[touched]
    kd = kd[kd > 0]
    b_max = float(np.abs(B.data).max()) if B.nnz else 0.0
    c = (float(kd.min()) if len(kd) else 1.0) / max(b_max, 1e-300) ** 2 if nm else 1.0

    def solve_on(a: np.ndarray, it: int):
        # [[K_ff, -B_a^T], [-B_a, -J_aa]]
        pos = np.full(nm, -1, np.int64)
        pos[a] = np.arange(len(a))
        b_on = pos[bc.row] >= 0
        br, bcol, bv = pos[bc.row[b_on]], bc.col[b_on], bc.data[b_on]
        j_on = (pos[jc.row] >= 0) & (pos[jc.col] >= 0)
        mat = sp.csc_matrix((np.concatenate([k_vals, -bv, -bv, -jc.data[j_on]]),
                             (np.concatenate([k_rows, bcol, nf + br, nf + pos[jc.row[j_on]]]),
                              np.concatenate([k_cols, nf + br, bcol, nf + pos[jc.col[j_on]]]))),
                            shape=(nf + len(a), nf + len(a)))
        sol = _lu_solve(mat, np.concatenate([rhs_u, g0[a]]), len(a), it,
                        "more independent constraints than the free motion can meet (a single-pass method "
                        "whose slave or non-mortar side is the finer or the rigid one, or double-pass nodes "
                        "that coincide)")
        u = ud.copy()
        u[free] = sol[: len(free)]
        p = np.zeros(nm)
        p[a] = sol[len(free):]
        return u, p, g0 + Bf @ u[free] + J @ p

    # |B| |X + u_d| row by row, summed in B's stored order (as the sparse product)
    scale = np.bincount(np.repeat(np.arange(nm), np.diff(B.indptr)), minlength=nm,
                        weights=np.abs(B.data) * np.abs(X + ud)[B.indices]) if nm else np.zeros(0)
    gap_tol = 1e-12 * float(scale.max()) if nm else 0.0
    return _active_set(nm, c, solve_on, max_iterations, active, c * gap_tol)


RESIDUAL_TOL = 1e-4
"""A direct solve whose residual exceeds this fraction of |rhs| met a singular system. Far from both
sides: a good solve's residual is 3e-16 |rhs| on the patch tests and 8e-8 |rhs| on the 3-D patch at
zero load (its right-hand side only the stabilized gaps, 1.6e-2, against forces of 1e7 in the
residual's rows: 1e-8 refused it); the singular solve below left 1.9e3 |rhs|."""


def _lu_solve(mat: sp.spmatrix, rhs: np.ndarray, n_active: int, it: int, why: str,
              permc_spec: str = "COLAMD") -> np.ndarray:
    """mat^-1 rhs by SuperLU (column ordering ``permc_spec``); a singular system raises one
    RuntimeError naming the active multipliers and ``why``: SuperLU's "Factor is exactly singular",
    a non-finite result, or a residual above RESIDUAL_TOL of |rhs|. Whether round-off leaves a
    dependent row's pivot exactly zero depends on the CPU's kernels: where it left 2e-23 instead,
    the solve returned multipliers of 7e23 with a residual of 1.9e3 |rhs| and the active set went on
    from them to a wrong answer."""
    mat = sp.csc_matrix(mat)
    try:
        sol = spla.splu(mat, permc_spec=permc_spec).solve(rhs)
    except RuntimeError:
        sol = np.full(mat.shape[0], np.nan)
    if np.all(np.isfinite(sol)):
        scale = float(np.linalg.norm(rhs))
        if np.linalg.norm(mat @ sol - rhs) > RESIDUAL_TOL * scale if scale > 0 else np.any(sol != 0):
            sol[:] = np.nan
    if not np.all(np.isfinite(sol)):
        raise RuntimeError(f"the contact KKT system is singular ({n_active} active multipliers, iteration {it}): {why}")
    return sol


def _active_set(nm: int, c: float, solve_on, max_iterations: int, active: np.ndarray | None = None,
                tol: float = 0.0) -> ContactSolution:
    """The primal-dual active set: from ``active`` (default every multiplier), solve_on(active ids,
    iteration) -> (u, p, g~) until A = {p - c g~ > tol} repeats (a set seen before: cycling, an error)."""
    active = np.ones(nm, dtype=bool) if active is None else np.asarray(active, dtype=bool).copy()
    seen = []
    for it in range(1, max_iterations + 1):
        u, p, gap = solve_on(np.flatnonzero(active), it)
        new = (p - c * gap) > tol
        if np.array_equal(new, active):
            return ContactSolution(u=u, p=p, gap=gap, active=active, iterations=it)
        if any(np.array_equal(new, s) for s in seen):
            raise RuntimeError(f"the contact active set cycles (iteration {it})")
        seen.append(active)
        active = new
    raise RuntimeError(f"the contact active set did not settle in {max_iterations} iterations")


def solve_schur_complement(S: sp.spmatrix, g0: np.ndarray, max_iterations: int = 50,
                           active: np.ndarray | None = None, gap_tol: float = 0.0) -> ContactSolution:
    """The same complementarity with the displacements eliminated (a diagonal K: the explicit step):
    gaps g~ = g0 + S p with S (nm, nm) sparse symmetric positive (semi)definite; p >= 0, g~ >= 0,
    p g~ = 0, by the same primal-dual active set (c = 1 / mean of diag S), from ``active`` (default
    every multiplier). gap_tol: the round-off of a gap (as solve_frictionless's: a row at p = 0 and
    g~ = -1e-20 must not join and leave the set by turns). Returns u empty."""
    S = sp.csc_matrix(S)
    nm = S.shape[0]
    d = S.diagonal()
    c = 1.0 / max(float(d[d > 0].mean()) if np.any(d > 0) else 1.0, 1e-300)

    def solve_on(a: np.ndarray, it: int):
        p = np.zeros(nm)
        if len(a):
            # S is symmetric: a minimum-degree ordering of S + S^T fills in less than SuperLU's
            # default COLAMD (the 10^4 multipliers of `immerse bench contact`: 5.8 against 14 ms a
            # factorisation, the same p to 2.6e-15); all active: S itself, not an indexed copy
            sub = S if len(a) == nm else S[a][:, a]
            p[a] = _lu_solve(sub, -g0[a], len(a), it, "the multipliers' system has no unique solution",
                             permc_spec="MMD_AT_PLUS_A")
        return np.zeros(0), p, g0 + S @ p

    return _active_set(nm, c, solve_on, max_iterations, active, c * gap_tol)
