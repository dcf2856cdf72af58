"""The stabilised multiplier solve of one coupled step (the talk's "Mathematical Details: Lagrange
Step"; Puso, Kokko, Settgast & Liu, IJNME 104 (2015) 697-720 -- the paper is not available here, so
what follows is exactly what this module implements, in the talk's notation).

Equations of motion with the multipliers, the constraint stabilised (slide 3 of that section):

    M^b a^b + K^b u^b + B^bT λ = 0,   M^f a^f + K^f u^f + B^fT λ = 0,
    B^b v^b + B^f v^f - C̄^-1 λ = 0,   C̄^-1 = J + I/α.

(Here `Bf` is the positive foreground operator, the talk's B^f = -Bf, see `operators`.)  Central
differences give v^{n+1/2} = v* - Δt M^-1 B^T λ; put into the constraint at n+1/2:

    H λ = g*,   H = Δt (B^b M_b^-1 B^bT + Bf M_f^-1 BfT) + C̄^-1,   g* = B^b v*_b - Bf v*_f,

which is the slide's matrix equation with its third row divided by Δt (the slide writes
H = Δt² (...) + C̄^-1 for the unknown λΔt).  The impulses are -Δt B^bT λ on the background and
+Δt BfT λ on the foreground: equal and opposite in total, because every row of B^b and of Bf sums
to the same cut area A_e.

Scaling of the stabilisation (our choice; the slides give only the form C̄^-1 = J + I/α):
with s_e = Δt A_full^2 (Σ_A (B^b_eA/A_e)^2 / m^b_A + Σ_A (Bf_eA/A_e)^2 / m^f_A), the diagonal that
zone e's unstabilised row would have if its cut were a full cut (area A_full = V_zone^{(d-1)/d})
with the same distribution of weights over its nodes,

    I/α  -> diag(s_e / α),
    J    =  β Σ_{face pairs (e,e')} sqrt(s_e s_e') (δ_e - δ_e')(δ_e - δ_e')^T.

s_e has the units of H (m^{2(d-1)} s / kg), so α and β are dimensionless, and it scales like the
unstabilised diagonal of a healthy zone (Δt A_full^2 / m ~ h h^{2(d-1)} / h^d for Δt ~ h, m ~ ρ h^d),
so the stabilisation keeps its relative size as h -> 0.  Unlike the true diagonal it does not vanish
for a sliver cut (A_e -> 0): that is what bounds the smallest eigenvalue.  J only sees jumps of λ
between neighbouring zones, so a uniform λ (a uniform pressure) is untouched by it (consistency) and
the checkerboard λ that the piecewise-constant multipliers on the background nodes cannot see
(the inf-sup defect) is penalised.  For an isolated, fully cut zone H = (1 + 1/α) s_e and one solve
removes the fraction α/(1+α) of the relative velocity (`test_solve` checks this).

Slip: λ_e = μ_e n_e with a scalar μ_e, the constraint n_e·(B^b v^b - Bf v^f) = C̄^-1 μ, so
H_ee' = Hu_ee' n_e·n_e' (Hu = the unstabilised scalar operator) and the same C̄^-1 acting on μ
(a uniform normal pressure is untouched by J).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # (scipy is imported where it is used: `immerse check` reads CONDITIONS, ALPHA, BETA
    # through the case schema and should not pay scipy's ~0.25 s import)
    import scipy.sparse as sp

    from orchestrator.coupling.operators import Operators

CONDITIONS = ("tied", "slip")
ALPHA = 1.0e3
"""Default α: an isolated full zone keeps 1/(1+α) ~ 1e-3 of its relative velocity per solve (the
constraint is a stiff dashpot C = B^T C̄ B, not an exact tie), and the net flux through a straight
interface is removed to ~1e-3 likewise.  The jump term, not 1/α, bounds the condition number, so α
can be large; 1/α only keeps H definite for a zone with no cut neighbour (a body inside one zone)."""
BETA = 1.0
"""Default β, chosen by the conditioning sweep (`conditioning.conditioning_sweep`, 2-D, 8 random
lines, h = 1/8 .. 1/64, α = 1e3), max cond(H) per h:
    β = 0: 645 .. 1180 (growing),  0.01: 71 .. 82,  0.1: 10 .. 13,  0.3: 5.8 .. 7.8,  1: 7.2 .. 8.2,
    3: 14 .. 16;
and by what it does to λ: on a straight line with uniform masses the zone-to-zone spread of λ is
1.5 at β = 0 (oscillating, so is the foreground velocity: 13 %), 0.02 at β = 1 (velocity 1 %).  The
price: zone values of B v' oscillate about zero (up to ~10 % of the removed relative velocity in
single zones) while the net flux through the interface stays at the 1/(1+α) level."""
RTOL = 1e-10
MAX_ITER = 1000


class MultiplierSolveError(RuntimeError):
    """The CG iteration did not reach the tolerance within the iteration cap."""


@dataclass(frozen=True)
class System:
    """The stabilised system of one step on its active zones.

    rows     (n,) rows of `ops` (zones) in the system: zones with material background nodes
    H        (n, n) CSR   Δt (B^b M_b^-1 B^bT + Bf M_f^-1 BfT) [∘ n·n for slip] + C̄^-1
    Cinv     (n, n) CSR   C̄^-1 = J + diag(s/α)
    scale    (n,)         s_e
    Bb, Bf   active rows; Bb with the void columns dropped and its rows rescaled to sum to A_e
    ref      (n,)         column of Bb whose velocity is the zone's reference (Galilean RHS)
    normal   (n, dim)     slip directions (used for slip only)
    """

    condition: str
    dt: float
    rows: np.ndarray
    H: sp.csr_matrix
    Cinv: sp.csr_matrix
    scale: np.ndarray
    Bb: sp.csr_matrix
    Bf: sp.csr_matrix
    ref: np.ndarray
    normal: np.ndarray

    @property
    def size(self) -> int:
        return int(self.rows.size)


@dataclass(frozen=True)
class Solution:
    """λ per zone of `ops` (rows not in the system: 0), the impulses and the diagnostics."""

    zones: np.ndarray  # (nz,) ops.zones
    lam: np.ndarray  # (nz, dim) tied; (nz,) slip: the normal component μ_e
    impulse_b: np.ndarray  # (nb, dim) on ops.bnodes: -Δt B^bT λ
    impulse_f: np.ndarray  # (ns, dim) on surface nodes: +Δt BfT λ
    iterations: int
    residual: float  # final ||g* - H λ|| / ||g*|| (0 when g* = 0)
    dissipation: float  # Δt λ·C̄^-1 λ, energy the stabilisation dissipates this step (J)


def _canonical(m) -> sp.csr_matrix:
    import scipy.sparse as sp
    m = sp.csr_matrix(m)
    m.sum_duplicates()
    m.eliminate_zeros()
    m.sort_indices()
    return m


@dataclass(frozen=True)
class MaterialOperators:
    """B^b and Bf restricted to the material: rows = zones with a material background node."""

    rows: np.ndarray  # (n,) rows of ops in use
    Bb: sp.csr_matrix  # (n, nb) void columns dropped, rows rescaled to sum to A_e
    Bf: sp.csr_matrix  # (n, ns)
    inv_mb: np.ndarray  # (nb,) 1/m_b, 0 for void nodes
    inv_mf: np.ndarray  # (ns,) 1/m_f, 0 for surface nodes off the interface
    ref: np.ndarray  # (n,) first material column of each row of Bb (Galilean RHS reference)


def check_masses(ops: Operators, m_b: np.ndarray, m_f: np.ndarray) -> np.ndarray:
    """One mass per background node (finite, >= 0: 0 is void) and per surface node (> 0 on the
    interface; +inf: a node whose velocity a boundary condition prescribes, immovable for the solve).
    Returns the surface nodes the operators touch."""
    if m_b.shape != ops.bnodes.shape:
        raise ValueError(f"m_b has shape {m_b.shape}; one mass per background node {ops.bnodes.shape} expected")
    if m_f.shape != (ops.Bf.shape[1],):
        raise ValueError(f"m_f has shape {m_f.shape}; one mass per surface node ({ops.Bf.shape[1]},) expected")
    if not np.all((m_b >= 0.0) & (m_b < np.inf)):   # (NaN fails both)
        bad_b = float(m_b[~((m_b >= 0.0) & (m_b < np.inf))][0])
        raise ValueError(f"background mass {bad_b!r}: masses must be finite and >= 0")
    touched_f = np.zeros(m_f.size, bool)
    touched_f[ops.Bf.indices] = True
    bad = touched_f & ~(m_f > 0.0)
    if bad.any() or np.isnan(m_f).any():
        i = int(np.flatnonzero(bad | np.isnan(m_f))[0])
        raise ValueError(f"surface node {i} has mass {float(m_f[i])!r}: a surface node on the interface "
                         f"needs a mass > 0 (inf: immovable)")
    return touched_f


def material_operators(ops: Operators, m_b, m_f) -> MaterialOperators:
    """The operators of the material nodes.

    m_b (nb,) lumped background masses on ops.bnodes; m_f (ns,) lumped surface-node masses.
    A background node with m_b = 0 (no material: void) is left out of the constraint -- its column
    is dropped -- because it has no momentum to exchange (M^-1 is undefined there and its velocity
    is not a material velocity).  The zone's remaining weights are rescaled to sum to A_e again, so
    that the impulses stay equal and opposite (momentum conserved) and a uniform motion still gives
    a zero relative velocity; each rescaled weight stays <= A_e, so a zone whose material nodes carry
    little weight does not blow up.  A zone with no material node at all is left out (λ_e = 0): a
    surface in void has nothing to be tied to."""
    import scipy.sparse as sp
    m_b = np.asarray(m_b, dtype=float)
    m_f = np.asarray(m_f, dtype=float)
    touched_f = check_masses(ops, m_b, m_f)
    inv_mb = np.zeros_like(m_b)
    inv_mb[m_b > 0.0] = 1.0 / m_b[m_b > 0.0]
    inv_mf = np.zeros_like(m_f)
    inv_mf[touched_f] = 1.0 / m_f[touched_f]

    kept = sp.diags((m_b > 0.0).astype(float))
    Bb_k = _canonical(ops.Bb @ kept)
    row_sum = np.asarray(Bb_k.sum(axis=1)).ravel()
    rows = np.flatnonzero(row_sum > 0.0)
    Bb = _canonical(sp.diags(ops.area[rows] / row_sum[rows]) @ Bb_k[rows])
    Bf = _canonical(ops.Bf[rows])
    ref = Bb.indices[Bb.indptr[:-1]]  # every row has a material node
    return MaterialOperators(rows=rows, Bb=Bb, Bf=Bf, inv_mb=inv_mb, inv_mf=inv_mf, ref=ref)


def assemble(ops: Operators, m_b, m_f, dt: float, condition: str = "tied", alpha: float = ALPHA,
             beta: float = BETA) -> System:
    """The system matrix H of one step.

    m_b (nb,) lumped background masses on ops.bnodes; m_f (ns,) lumped surface-node masses.
    Void background nodes are left out (`material_operators`).  1/α = 0 (alpha=inf) and β = 0 give
    the unstabilised H."""
    import scipy.sparse as sp
    if condition not in CONDITIONS:
        raise ValueError(f"condition = {condition!r}: must be one of {', '.join(CONDITIONS)}")
    if not (dt > 0.0 and np.isfinite(dt)):
        raise ValueError(f"dt = {dt!r}: must be a finite number > 0")
    if not alpha > 0.0:
        raise ValueError(f"alpha = {alpha!r}: must be > 0 (inf for no I/alpha term)")
    if not (beta >= 0.0 and np.isfinite(beta)):
        raise ValueError(f"beta = {beta!r}: must be a finite number >= 0")
    mat = material_operators(ops, m_b, m_f)
    rows, Bb, Bf, normal, area = mat.rows, mat.Bb, mat.Bf, ops.normal[mat.rows], ops.area[mat.rows]
    inv_mb, inv_mf = mat.inv_mb, mat.inv_mf

    Hu = _canonical(dt * (Bb @ sp.diags(inv_mb) @ Bb.T + Bf @ sp.diags(inv_mf) @ Bf.T))
    # s_e: zone e's unstabilised diagonal rescaled from its cut area A_e to a full cut's A_full
    scale = (ops.full_area / area) ** 2 * Hu.diagonal()
    if condition == "slip":
        coo = Hu.tocoo()
        dots = (normal[coo.row] * normal[coo.col]).sum(axis=1)
        Hu = _canonical(sp.coo_matrix((coo.data * dots, (coo.row, coo.col)), shape=Hu.shape))

    Cinv = _canonical(sp.diags(scale / alpha) + jump_matrix(ops.pairs, rows, scale, beta))
    H = _canonical(Hu + Cinv)
    return System(condition=condition, dt=float(dt), rows=rows, H=H, Cinv=Cinv, scale=scale, Bb=Bb, Bf=Bf,
                  ref=mat.ref, normal=normal)


def jump_matrix(pairs: np.ndarray, rows: np.ndarray, scale: np.ndarray, beta: float) -> sp.csr_matrix:
    """J = β Σ_{pairs} sqrt(s_e s_e') (δ_e - δ_e')(δ_e - δ_e')^T over the pairs whose two zones are
    both in the system (`rows`: rows of ops kept, `scale`: s_e per kept row)."""
    import scipy.sparse as sp
    n = rows.size
    local = np.full(int(rows.max()) + 1 if n else 0, -1, dtype=np.int64)
    local[rows] = np.arange(n)
    if pairs.size and n:
        inside = (pairs < local.size).all(axis=1)
        p = pairs[inside]
        i, j = local[p[:, 0]], local[p[:, 1]]
        ok = (i >= 0) & (j >= 0)
        i, j = i[ok], j[ok]
    else:
        i = j = np.zeros(0, np.int64)
    w = beta * np.sqrt(scale[i] * scale[j])
    r = np.concatenate([i, j, i, j])
    c = np.concatenate([i, j, j, i])
    return _canonical(sp.coo_matrix((np.concatenate([w, w, -w, -w]), (r, c)), shape=(n, n)))


def relative_velocity(system, v_b, v_f) -> np.ndarray:
    """g* = B^b v_b - Bf v_f per zone of a `System` or `MaterialOperators` (fields Bb, Bf, ref), (n, dim).

    Computed as Σ_A B^b_eA (v_A - v_ref) - Σ_A Bf_eA (v_A - v_ref) with v_ref the velocity of the
    zone's first material background node: the same value (both rows sum to A_e, so the v_ref terms
    cancel) but a uniform translation gives exactly 0 instead of the round-off mismatch of the two
    row sums times the translation speed (Galilean invariance of the constraint to the last bit)."""
    v_b = np.asarray(v_b, dtype=float)
    v_f = np.asarray(v_f, dtype=float)
    v_ref = v_b[system.ref]
    return _rows_apply(system.Bb, v_b, v_ref) - _rows_apply(system.Bf, v_f, v_ref)


def _rows_apply(B: sp.csr_matrix, v: np.ndarray, v_ref: np.ndarray) -> np.ndarray:
    row = np.repeat(np.arange(B.shape[0]), np.diff(B.indptr))
    contrib = B.data[:, None] * (v[B.indices] - v_ref[row])
    return np.stack([np.bincount(row, weights=contrib[:, c], minlength=B.shape[0])
                     for c in range(v.shape[1])], axis=1)


def pcg(H: sp.csr_matrix, b: np.ndarray, x0: np.ndarray, rtol: float = RTOL, max_iter: int = MAX_ITER):
    """Jacobi-preconditioned conjugate gradients on the columns of b (one matrix, k right-hand sides).

    H is SPD (Hu is a Gram matrix, J >= 0, s/α > 0), so CG applies.  Jacobi because the diagonal is
    where H's zone-to-zone scale lives (cut area, masses: a steel/air interface gives s_e spread
    over orders of magnitude that the stabilisation does not equalise), while the stabilisation
    bounds the remaining condition number independently of h -- so the iteration count is bounded
    as the grid is refined, and a warm start from the previous step's λ cuts it further.  Jacobi is
    also deterministic and local per zone (the coupler may be split like the background later);
    heavier preconditioners (IC, AMG) buy nothing at a bounded condition number.

    Converged when ||b - H x||_F <= rtol ||b||_F (all columns together: a column with b = 0 needs no
    accuracy of its own).  Returns (x, iterations, relative residual).  Dot products are numpy sums
    (pairwise, fixed order), so equal inputs give bitwise-equal results."""
    b = np.asarray(b, dtype=float)
    bnorm = float(np.sqrt((b * b).sum()))
    if bnorm == 0.0:
        return np.zeros_like(b), 0, 0.0
    dinv = 1.0 / H.diagonal()
    x = np.array(x0, dtype=float, copy=True)
    r = b - H @ x
    z = dinv[:, None] * r
    p = z.copy()
    rz = (r * z).sum(axis=0)
    it = 0
    rnorm = float(np.sqrt((r * r).sum()))
    while rnorm > rtol * bnorm:
        if it >= max_iter:
            raise MultiplierSolveError(
                f"multiplier solve: no convergence in {max_iter} CG iterations (relative residual "
                f"{rnorm / bnorm:.3e} > tolerance {rtol:.1e}) on {H.shape[0]} cut zones; H is too ill "
                f"conditioned: raise coupling.beta or lower coupling.alpha")
        Hp = H @ p
        pHp = (p * Hp).sum(axis=0)
        a = np.divide(rz, pHp, out=np.zeros_like(rz), where=pHp > 0.0)
        x += a * p
        r -= a * Hp
        z = dinv[:, None] * r
        rz_new = (r * z).sum(axis=0)
        g = np.divide(rz_new, rz, out=np.zeros_like(rz), where=rz > 0.0)
        p = z + g * p
        rz = rz_new
        rnorm = float(np.sqrt((r * r).sum()))
        it += 1
    true_r = b - H @ x
    return x, it, float(np.sqrt((true_r * true_r).sum())) / bnorm


def solve(ops: Operators, m_b, m_f, v_b, v_f, dt: float, condition: str = "tied", alpha: float = ALPHA,
          beta: float = BETA, warm: tuple[np.ndarray, np.ndarray] | None = None, rtol: float = RTOL,
          max_iter: int = MAX_ITER) -> Solution:
    """λ of one step and the impulses.

    v_b (nb, dim) predictor velocities v* on ops.bnodes, v_f (ns, dim) on the surface nodes; masses as
    in `assemble`.  warm = (zones, lam) of the previous step: matched by zone id, new zones start at 0.
    Returns a `Solution`; λ is 0 for zones outside the system (no material background node)."""
    system = assemble(ops, m_b, m_f, dt, condition, alpha, beta)
    return solve_system(ops, system, v_b, v_f, warm=warm, rtol=rtol, max_iter=max_iter)


def solve_system(ops: Operators, system: System, v_b, v_f, warm=None, rtol: float = RTOL,
                 max_iter: int = MAX_ITER) -> Solution:
    dim = ops.dim
    v_b = np.asarray(v_b, dtype=float).reshape(-1, dim)
    v_f = np.asarray(v_f, dtype=float).reshape(-1, dim)
    g = relative_velocity(system, v_b, v_f)
    slip = system.condition == "slip"
    if slip:
        g = (g * system.normal).sum(axis=1, keepdims=True)
    x0 = np.zeros_like(g)
    if warm is not None and np.size(warm[0]):
        wz, wl = np.asarray(warm[0], np.int64), np.asarray(warm[1], dtype=float)
        wl = wl.reshape(wz.size, -1)
        if wl.shape[1] == g.shape[1]:
            zones = ops.zones[system.rows]
            pos = np.minimum(np.searchsorted(wz, zones), wz.size - 1)
            hit = wz[pos] == zones
            x0[hit] = wl[pos[hit]]
    lam, iterations, residual = pcg(system.H, g, x0, rtol=rtol, max_iter=max_iter)

    vec = lam * system.normal if slip else lam  # λ_e as a vector per zone
    impulse_b = -system.dt * (system.Bb.T @ vec)
    impulse_f = system.dt * (system.Bf.T @ vec)
    dissipation = system.dt * float((lam * (system.Cinv @ lam)).sum())

    full = np.zeros((ops.n_zones, lam.shape[1]))
    full[system.rows] = lam
    return Solution(zones=ops.zones, lam=full[:, 0] if slip else full, impulse_b=np.asarray(impulse_b),
                    impulse_f=np.asarray(impulse_f), iterations=iterations, residual=residual,
                    dissipation=dissipation)


def condition_number(H) -> float:
    """λ_max/λ_min of the SPD matrix H: dense eigenvalues up to 2000 rows, else the two extremal
    eigenvalues by Lanczos (largest directly, smallest by shift-invert about 0)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    n = H.shape[0]
    if n == 0:
        return 1.0
    if n <= 2000:
        ev = np.linalg.eigvalsh(H.toarray() if sp.issparse(H) else np.asarray(H))
        return float(ev[-1] / ev[0]) if ev[0] > 0.0 else float("inf")
    hi = spla.eigsh(H, k=1, which="LA", return_eigenvectors=False)[0]
    lo = spla.eigsh(sp.csc_matrix(H), k=1, sigma=0.0, which="LM", return_eigenvectors=False)[0]
    return float(hi / lo) if lo > 0.0 else float("inf")
