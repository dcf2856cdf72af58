"""Two-node shells of 2-D scenes (issue 45, its first piece): a plane-strain strip of a plate (a unit
depth of a shell in cylindrical bending), as a corotational Timoshenko beam with one-point quadrature
along it and integration points through its thickness, elastic or J2-plastic (strip_plasticity.py).
The element kernel only: internal forces and moments, lumped masses with their rotary inertia, the
stable step. Not yet in the solver, the case file or the coupling.

Why this element. A thin wall bends; a solid needs several elements through its thickness to bend
and zones smaller than the wall. A shell carries the bending in its rotations: one element through
the wall, whatever its thickness. In 2-D the four-node shell's Belytschko-Lin-Tsay kinematics reduce
to this beam (Belytschko, Liu, Moran, Nonlinear Finite Elements, section 9.4): a corotational frame
along the chord carries the rigid motion exactly (no strain from any rotation however large), and
in it the strains are small.

Kinematics (per element, nodes 1 and 2, positions x_i and rotations theta_i, both current; the
reference chord e0 of length L0, the current one e = (x2 - x1) / L):

    beta = the chord's rotation, atan2(e0 x e, e0 . e)       (|beta| < pi a step apart: any total)
    u    = L - L0                                           (stretch)
    t_i  = theta_i - beta                                   (each node's rotation off the chord)
    eps = u / L0,  kappa = (t_2 - t_1) / L0,  gamma = (t_1 + t_2) / 2   at the midpoint

(gamma: the linear Timoshenko element's transverse shear, -w' + theta at the one point; one-point
quadrature keeps the element free of shear locking, and with three deformation modes for three
strains it has no zero-energy mode). Through the thickness h, at the points z_k (Gauss, weights
w_k over [-h/2, h/2]): sigma_k = E' (eps - z_k kappa), E' = E / (1 - nu^2) (plane strain: the strip
cannot contract across the depth); the resultants per unit depth N = sum w_k sigma_k, M =
-sum w_k z_k sigma_k (linear elastic: N = E' h eps, M = E' h^3 / 12 kappa) and Q = k_s G h gamma
(k_s = 5/6) made softer by MacNeal's residual bending flexibility: Q = gamma / (1 / (k_s G h) + L0^2 /
(12 E' I)), I = h^3 / 12. One-point quadrature holds the curvature constant in the element, which
makes it too stiff by exactly the flexibility a linear moment over L0 would add; put into the shear,
that flexibility makes the element's stiffness the exact beam's (MacNeal's "residual bending
flexibility", Computers & Structures 8, 1978): nodal displacements under nodal loads exact (a
cantilever's tip to 1.5e-8, a clamped strip's midspan under pressure to 3.6e-9; without it
-1 / (4 n^2) and -1.56 % at 16 elements, tests). It does not change bending (kappa) or stretching, nor a thick wall's shear much
(L0^2 / (12 E' I) against 1 / (k_s G h)). Virtual work L0 (N d eps + M d kappa + Q d gamma) gives
the nodal forces and moments

    f_2 = N e - Q (L0 / L) n = -f_1,   m_1 = -M + Q L0 / 2,   m_2 = M + Q L0 / 2,

n = (-e_y, e_x); their moment about any point is zero (a rigid rotation does no work), their sum
too: the element keeps linear and angular momentum exactly, as the solids' elements do.

Masses (lumped, per unit depth): rho h L0 / 2 at each node; rotary inertia rho h L0 / 2 times
max(h^2 / 12, L0^2 / 12): the rotations' own (h^2 / 12) would make a thin wall's shear mode, of
frequency ~ sqrt(6 k_s G / rho) / h, set the step at the thickness; scaled to L0^2 / 12 (Key and
Beisinger's rotary-inertia scaling, LS-DYNA's for its beams and shells) that mode's frequency is
the element's length's and the stable step ~ L0 / c. The scaling adds rotary inertia a thin beam's
bending (Euler-Bernoulli) does not have; its effect on the low modes is of order (L0 / lambda)^2.

Stable step: 2 / omega_max, omega_max the largest frequency of any one element over its share of
the masses (Irons' element bound: the assembled system's is never larger). With the scaled rotary
inertia it is about the membrane wave's time across the element, L0 / sqrt(E' / rho).

Everything is vectorised numpy over elements and thickness points; assembly by np.add.at.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BeamSection", "internal_forces", "lumped_masses", "plastic_state", "stable_step", "SHEAR_FACTOR"]

SHEAR_FACTOR = 5.0 / 6.0
"""k_s: the shear correction of a rectangular section (Reissner-Mindlin's)."""


class BeamSection:
    """The elements' material and section: E, nu, rho (scalars or (ne,)), thickness h (ne,),
    ``points`` Gauss points through the thickness (5: exact for any linear-elastic profile);
    ``yield_stress`` (None: elastic) and linear isotropic ``hardening`` make the points J2-plastic
    (strip_plasticity.py)."""

    def __init__(self, youngs_modulus, poisson_ratio, density, thickness, points: int = 5,
                 yield_stress=None, hardening=0.0):
        self.yield_stress = None if yield_stress is None else np.asarray(yield_stress, float)
        self.hardening = np.asarray(hardening, float)
        self.e = np.asarray(youngs_modulus, float)
        self.nu = np.asarray(poisson_ratio, float)
        self.rho = np.asarray(density, float)
        self.h = np.asarray(thickness, float)
        self.e_plane = self.e / (1.0 - self.nu ** 2)            # plane strain E'
        self.g = self.e / (2.0 * (1.0 + self.nu))
        xi, w = np.polynomial.legendre.leggauss(int(points))
        self.z_unit = 0.5 * xi                                   # z / h
        self.w_unit = 0.5 * w                                    # weights / h (sum 1)


def _shear_stiffness(section: BeamSection, L0: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Q / gamma per unit depth: k_s G h with MacNeal's residual bending flexibility L0^2 / (E' h^3)
    added to its flexibility (module docstring)."""
    g = np.broadcast_to(section.g, L0.shape)
    e_p = np.broadcast_to(section.e_plane, L0.shape)
    return 1.0 / (1.0 / (SHEAR_FACTOR * g * h) + L0 * L0 / (e_p * h ** 3))


def _chords(X: np.ndarray, x: np.ndarray, elements: np.ndarray):
    d0 = X[elements[:, 1]] - X[elements[:, 0]]
    d = x[elements[:, 1]] - x[elements[:, 0]]
    L0 = np.hypot(d0[:, 0], d0[:, 1])
    L = np.hypot(d[:, 0], d[:, 1])
    beta = np.arctan2(d0[:, 0] * d[:, 1] - d0[:, 1] * d[:, 0], d0[:, 0] * d[:, 0] + d0[:, 1] * d[:, 1])
    return d / L[:, None], L0, L, beta


def plastic_state(n_elements: int, section: BeamSection):
    """The points' plastic state at rest: (plastic strains (ne, nz, 2) xx and yy, equivalent plastic
    strains (ne, nz))."""
    nz = len(section.z_unit)
    return np.zeros((n_elements, nz, 2)), np.zeros((n_elements, nz))


def internal_forces(X: np.ndarray, x: np.ndarray, theta: np.ndarray, elements: np.ndarray,
                    section: BeamSection, theta0: np.ndarray | None = None, plastic=None):
    """(f (n, 2), m (n,), resultants (ne, 3): N, M, Q) of the elements at positions x (n, 2) and
    rotations theta (n,), reference positions X and rotations theta0 (default 0): the forces the
    elements exert on the nodes are -f and -m (f, m are the internal forces, as the solids' kernels
    give them: M a = f_ext - f). With a plastic section, ``plastic`` is the points' state at the
    last step (plastic_state's layout) and a fourth item, the state at this one, is returned (the
    caller keeps it: nothing is changed in place)."""
    e, L0, L, beta = _chords(X, x, elements)
    th = theta - (0.0 if theta0 is None else theta0)
    t1 = th[elements[:, 0]] - beta
    t2 = th[elements[:, 1]] - beta
    eps = (L - L0) / L0
    kappa = (t2 - t1) / L0
    gamma = 0.5 * (t1 + t2)
    h = np.broadcast_to(section.h, L0.shape)
    z = section.z_unit[None, :] * h[:, None]                    # (ne, nz)
    e_p = np.broadcast_to(section.e_plane, L0.shape)
    strain = eps[:, None] - z * kappa[:, None]                  # (ne, nz): the points' eps_xx
    if section.yield_stress is None:
        sigma = e_p[:, None] * strain
        new_state = None
    else:
        from solvers.lagrange.strip_plasticity import strip_return

        if plastic is None:
            raise ValueError("a plastic section needs the points' state (beam2d.plastic_state)")
        ne = len(L0)
        col = lambda a: np.broadcast_to(a, (ne,))[:, None]   # noqa: E731  (per element, to the points)
        sigma, _, ep, al = strip_return(strain, plastic[0], plastic[1], col(section.e), col(section.nu),
                                        col(section.yield_stress), col(section.hardening))
        new_state = (ep, al)
    wz = section.w_unit[None, :] * h[:, None]
    N = np.sum(wz * sigma, axis=1)
    M = -np.sum(wz * z * sigma, axis=1)
    Q = _shear_stiffness(section, L0, h) * gamma
    n = np.stack([-e[:, 1], e[:, 0]], axis=1)
    f2 = N[:, None] * e - (Q * L0 / L)[:, None] * n
    f = np.zeros_like(x)
    np.add.at(f, elements[:, 1], f2)
    np.add.at(f, elements[:, 0], -f2)
    m = np.zeros(len(x))
    np.add.at(m, elements[:, 0], -M + 0.5 * Q * L0)
    np.add.at(m, elements[:, 1], M + 0.5 * Q * L0)
    if plastic is not None or section.yield_stress is not None:
        return f, m, np.stack([N, M, Q], axis=1), new_state
    return f, m, np.stack([N, M, Q], axis=1)


def lumped_masses(X: np.ndarray, elements: np.ndarray, section: BeamSection, n: int | None = None):
    """(m (n,), I_r (n,)): each node's translational mass and rotary inertia per unit depth, the
    rotary inertia scaled to max(h^2, L0^2) / 12 (module docstring)."""
    d0 = X[elements[:, 1]] - X[elements[:, 0]]
    L0 = np.hypot(d0[:, 0], d0[:, 1])
    h = np.broadcast_to(section.h, L0.shape)
    half = 0.5 * np.broadcast_to(section.rho, L0.shape) * h * L0
    rot = half * np.maximum(h * h, L0 * L0) / 12.0
    n = len(X) if n is None else n
    m, ir = np.zeros(n), np.zeros(n)
    np.add.at(m, elements[:, 0], half)
    np.add.at(m, elements[:, 1], half)
    np.add.at(ir, elements[:, 0], rot)
    np.add.at(ir, elements[:, 1], rot)
    return m, ir


def stable_step(X: np.ndarray, elements: np.ndarray, section: BeamSection) -> float:
    """The central difference's stable step, 2 / omega_max with omega_max the largest of the
    elements' own frequencies (each element's 6 x 6 stiffness at its reference state over its share
    of the lumped masses: Irons' bound, never below the assembled system's largest; the tests measure
    how close it comes)."""
    d0 = X[elements[:, 1]] - X[elements[:, 0]]
    L0 = np.hypot(d0[:, 0], d0[:, 1])
    ne = len(L0)
    h = np.broadcast_to(section.h, L0.shape)
    rho = np.broadcast_to(section.rho, L0.shape)
    e_p = np.broadcast_to(section.e_plane, L0.shape)
    # local dofs (u1, w1, t1, u2, w2, t2): strains eps = (u2 - u1) / L0, kappa = (t2 - t1) / L0,
    # gamma = (w1 - w2) / L0 + (t1 + t2) / 2 (the chord's rotation is (w2 - w1) / L0)
    b = np.zeros((ne, 3, 6))
    b[:, 0, 0], b[:, 0, 3] = -1.0 / L0, 1.0 / L0
    b[:, 1, 2], b[:, 1, 5] = -1.0 / L0, 1.0 / L0
    b[:, 2, 1], b[:, 2, 4], b[:, 2, 2], b[:, 2, 5] = 1.0 / L0, -1.0 / L0, 0.5, 0.5
    d = np.zeros((ne, 3, 3))
    d[:, 0, 0], d[:, 1, 1], d[:, 2, 2] = e_p * h, e_p * h ** 3 / 12.0, _shear_stiffness(section, L0, h)
    k = L0[:, None, None] * np.einsum("eki,ekl,elj->eij", b, d, b)
    half = 0.5 * rho * h * L0
    mass = np.stack([half, half, half * np.maximum(h * h, L0 * L0) / 12.0] * 2, axis=1)   # (ne, 6)
    scale = 1.0 / np.sqrt(mass)
    w2 = np.linalg.eigvalsh(scale[:, :, None] * k * scale[:, None, :])[:, -1]
    return float(2.0 / np.sqrt(w2.max()))
