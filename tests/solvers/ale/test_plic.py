"""PLIC geometry kernels (solvers.ale.plic): cut volumes of a box by a plane, their inverse, Youngs
normals and remap slab fractions.

References (independent of the module's formulas):
* closed-form simple cases (axis-aligned planes, the 45-degree triangle/tetrahedron, a plane
  through the centre of a box cuts it in half by central symmetry);
* the Scardovelli-Zaleski inclusion-exclusion sum evaluated in exact rational arithmetic
  (``fractions.Fraction``, every float is a rational), valid for non-zero normal components;
* a piecewise-exact Gauss quadrature: the cut length along y is piecewise linear in x (2-point
  Gauss per piece is exact) and the cut area piecewise quadratic in z (3-point Gauss exact);
* Monte-Carlo sampling (5 sigma) as a coarse fully independent check;
* Youngs' gradient is exact for a linear field; its stencil weights are checked by the impulse
  response; on a disc / ball of fractions the normal is compared with the radial direction.
"""
import itertools
from fractions import Fraction

import numpy as np
import pytest
from numba import njit

from solvers.ale import plic


# ----------------------------------------------------------------------------------------------
# references
# ----------------------------------------------------------------------------------------------
def _exact_measure(n, alpha, lo, hi):
    """Exact rational measure of {n.x <= alpha} in the box (all n_i != 0), inclusion-exclusion."""
    dim = len(n)
    n = [Fraction(float(v)) for v in n]
    lo = [Fraction(float(v)) for v in lo]
    h = [Fraction(float(b)) - a for a, b in zip(lo, hi)]
    a = Fraction(float(alpha)) - sum(ni * li for ni, li in zip(n, lo))
    m = []
    for ni, hi_ in zip(n, h):
        mi = ni * hi_
        if mi < 0:
            a -= mi
            mi = -mi
        m.append(mi)
    tot = Fraction(0)
    for s in itertools.product([0, 1], repeat=dim):
        t = a - sum(mi for mi, si in zip(m, s) if si)
        if t > 0:
            tot += (-1) ** sum(s) * t ** dim
    den = Fraction(1)
    for k in range(1, dim + 1):
        den *= k
    for mi in m:
        den *= mi
    box = Fraction(1)
    for hi_ in h:
        box *= hi_
    return tot / den * box


def _ref_area(nx, ny, alpha, x0, x1, y0, y1):
    """Piecewise-exact quadrature of the cut length L(x) (piecewise linear)."""
    def length(x):
        if ny > 0:
            return np.clip((alpha - nx * x) / ny, y0, y1) - y0
        if ny < 0:
            return y1 - np.clip((alpha - nx * x) / ny, y0, y1)
        return (y1 - y0) * (nx * x <= alpha)

    bps = [x0, x1]
    if nx != 0:
        for yb in (y0, y1):
            xb = (alpha - ny * yb) / nx
            if x0 < xb < x1:
                bps.append(xb)
    bps = np.sort(bps)
    g, w = np.polynomial.legendre.leggauss(2)
    tot = 0.0
    for a, b in zip(bps[:-1], bps[1:]):
        x = 0.5 * (a + b) + 0.5 * (b - a) * g
        tot += 0.5 * (b - a) * float(np.sum(w * length(x)))
    return tot


def _ref_volume(nx, ny, nz, alpha, x0, x1, y0, y1, z0, z1):
    """Piecewise-exact quadrature over z of the (piecewise quadratic) cut area."""
    bps = [z0, z1]
    if nz != 0:
        for xc in (x0, x1):
            for yc in (y0, y1):
                zb = (alpha - nx * xc - ny * yc) / nz
                if z0 < zb < z1:
                    bps.append(zb)
    bps = np.sort(bps)
    g, w = np.polynomial.legendre.leggauss(3)
    tot = 0.0
    for a, b in zip(bps[:-1], bps[1:]):
        for gk, wk in zip(g, w):
            z = 0.5 * (a + b) + 0.5 * (b - a) * gk
            tot += 0.5 * (b - a) * wk * _ref_area(nx, ny, alpha - nz * z, x0, x1, y0, y1)
    return tot


def _random_normal(rng, dim, kind):
    """kind 0: generic; 1: one tiny component; 2: two tiny (3D) ; 3: axis-aligned; signs random."""
    n = rng.normal(size=dim)
    if kind == 1:
        n[rng.integers(dim)] *= 10.0 ** rng.uniform(-18, -3)
    elif kind == 2:
        for i in rng.permutation(dim)[:dim - 1]:
            n[i] *= 10.0 ** rng.uniform(-18, -3)
    elif kind == 3:
        i = rng.integers(dim)
        n[:] = 0.0
        n[i] = rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 10.0)
    return n


def _corner_range(n, lo, hi):
    vals = [float(np.dot(n, c)) for c in itertools.product(*zip(lo, hi))]
    return min(vals), max(vals)


def _cut(n, alpha, lo, hi):
    if len(n) == 2:
        return plic.cut_area_2d(n[0], n[1], alpha, lo[0], hi[0], lo[1], hi[1])
    return plic.cut_volume_3d(n[0], n[1], n[2], alpha, lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])


def _alpha(n, f, h):
    if len(n) == 2:
        return plic.plane_constant_2d(n[0], n[1], f, h[0], h[1])
    return plic.plane_constant_3d(n[0], n[1], n[2], f, h[0], h[1], h[2])


# ----------------------------------------------------------------------------------------------
# cut volumes
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n, alpha, expected", [
    ((1.0, 0.0), 0.3, 0.3),                    # vertical line x <= 0.3
    ((0.0, -2.0), -0.5, 0.75),                 # y >= 0.25
    ((1.0, 1.0), 0.5, 0.125),                  # 45-degree triangle
    ((1.0, 1.0), 1.0, 0.5),                    # diagonal through the centre
    ((1.0, 1.0), 1.5, 1.0 - 0.125),
    ((-1.0, -1.0), -1.5, 0.125),               # x + y >= 1.5
    ((1.0, 1.0), -1e-3, 0.0),                  # beyond the box
    ((1.0, 1.0), 2.0 + 1e-3, 1.0),
    ((1.0, 1.0), 2.0, 1.0),
    ((1.0, 1.0), 0.0, 0.0),
    ((0.0, 0.0), 0.0, 1.0),                    # zero normal: everything or nothing
    ((0.0, 0.0), -1.0, 0.0),
])
def test_cut_area_unit_square_closed_form(n, alpha, expected):
    assert plic.cut_area_2d(n[0], n[1], alpha, 0.0, 1.0, 0.0, 1.0) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize("n, alpha, expected", [
    ((0.0, 0.0, 1.0), 0.3, 0.3),
    ((0.0, -1.0, 0.0), -0.25, 0.75),
    ((1.0, 1.0, 1.0), 0.5, 0.5 ** 3 / 6.0),    # corner tetrahedron
    ((1.0, 1.0, 1.0), 1.5, 0.5),               # plane through the centre
    ((1.0, 1.0, 1.0), 2.5, 1.0 - 0.5 ** 3 / 6.0),
    ((1.0, 1.0, 1.0), 1.0, 1.0 / 6.0),
    ((1.0, 1.0, 0.0), 0.5, 0.125),             # prism
    ((2.0, 1.0, 1.0), 1.0, 1.0 / 12.0),        # tetra with legs 1/2, 1, 1
    ((1.0, 1.0, 1.0), -1e-9, 0.0),
    ((1.0, 1.0, 1.0), 3.0 + 1e-9, 1.0),
    ((0.0, 0.0, 0.0), 1.0, 1.0),
])
def test_cut_volume_unit_cube_closed_form(n, alpha, expected):
    v = plic.cut_volume_3d(n[0], n[1], n[2], alpha, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0)
    assert v == pytest.approx(expected, abs=1e-15)


def test_cut_translated_scaled_boxes_closed_form():
    # box [2,5] x [-1,1] (area 6): x + y <= 3 -> triangle with legs 2 at corner (2,-1)
    assert plic.cut_area_2d(1.0, 1.0, 3.0, 2.0, 5.0, -1.0, 1.0) == pytest.approx(2.0, rel=1e-15)
    # box [1,3] x [0,1] x [-2,2] (volume 8), plane 2x <= 4 -> half
    assert plic.cut_volume_3d(2.0, 0.0, 0.0, 4.0, 1.0, 3.0, 0.0, 1.0, -2.0, 2.0) == pytest.approx(4.0, rel=1e-15)
    # corner tetrahedron of legs 1, 1/2, 2 at (1,0,-2): (x-1) + 2y + (z+2)/2 <= 1
    v = plic.cut_volume_3d(1.0, 2.0, 0.5, 1.0 + 1.0 - 1.0, 1.0, 3.0, 0.0, 1.0, -2.0, 2.0)
    assert v == pytest.approx(1.0 * 0.5 * 2.0 / 6.0, rel=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_plane_through_centre_halves_the_box(dim):
    rng = np.random.default_rng(10 + dim)
    for k in range(400):
        n = _random_normal(rng, dim, k % 4)
        lo = rng.uniform(-2.0, 2.0, dim)
        hi = lo + rng.uniform(0.01, 3.0, dim)
        c = 0.5 * (lo + hi)
        box = float(np.prod(hi - lo))
        v = _cut(n, float(np.dot(n, c)), lo, hi)
        assert abs(v - 0.5 * box) <= 1e-14 * box, (n, lo, hi, v / box)


@pytest.mark.parametrize("dim", [2, 3])
def test_cut_random_planes_vs_exact_rational(dim):
    """Random boxes, planes (including components 1e-18..1e-3 relative), alpha beyond the box:
    error <= 1e-14 of the box (measured: <= 1e-15)."""
    rng = np.random.default_rng(20 + dim)
    worst = 0.0
    for k in range(600):
        n = _random_normal(rng, dim, k % 3)
        lo = rng.uniform(-1.0, 1.0, dim)
        hi = lo + rng.uniform(0.05, 2.0, dim)
        cmin, cmax = _corner_range(n, lo, hi)
        alpha = rng.uniform(cmin - 0.1 * (cmax - cmin), cmax + 0.1 * (cmax - cmin))
        box = float(np.prod(hi - lo))
        v = _cut(n, alpha, lo, hi)
        err = abs(float(Fraction(v) - _exact_measure(n, alpha, lo, hi))) / box
        worst = max(worst, err)
    assert worst <= 1e-14


@pytest.mark.parametrize("dim", [2, 3])
def test_cut_random_planes_vs_piecewise_quadrature(dim):
    """Independent reference including axis-aligned normals; tolerance 1e-13 of the box."""
    rng = np.random.default_rng(30 + dim)
    for k in range(300):
        n = _random_normal(rng, dim, k % 4)
        lo = rng.uniform(-1.0, 1.0, dim)
        hi = lo + rng.uniform(0.05, 2.0, dim)
        cmin, cmax = _corner_range(n, lo, hi)
        alpha = rng.uniform(cmin - 0.05 * (cmax - cmin), cmax + 0.05 * (cmax - cmin))
        box = float(np.prod(hi - lo))
        if dim == 2:
            ref = _ref_area(n[0], n[1], alpha, lo[0], hi[0], lo[1], hi[1])
        else:
            ref = _ref_volume(n[0], n[1], n[2], alpha, lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
        assert abs(_cut(n, alpha, lo, hi) - ref) <= 1e-13 * box, (n, alpha, lo, hi)


def test_cut_volume_vs_monte_carlo():
    """Fully independent sampling check: |V - V_mc| <= 5 sigma (sigma = sqrt(p(1-p)/N) box)."""
    rng = np.random.default_rng(40)
    N = 200_000
    for _ in range(10):
        n = rng.normal(size=3)
        lo = rng.uniform(-1.0, 1.0, 3)
        hi = lo + rng.uniform(0.2, 2.0, 3)
        cmin, cmax = _corner_range(n, lo, hi)
        alpha = rng.uniform(cmin, cmax)
        pts = lo + (hi - lo) * rng.random((N, 3))
        p = float(np.mean(pts @ n <= alpha))
        box = float(np.prod(hi - lo))
        sigma = max(np.sqrt(p * (1.0 - p) / N), 1.0 / N)
        assert abs(_cut(n, alpha, lo, hi) / box - p) <= 5.0 * sigma


@pytest.mark.parametrize("dim", [2, 3])
def test_complement_symmetry(dim):
    """V(n, alpha) + V(-n, -alpha) = box to 1e-13 (the plane itself has measure 0)."""
    rng = np.random.default_rng(50 + dim)
    for k in range(1000):
        n = _random_normal(rng, dim, k % 4)
        lo = rng.uniform(-1.0, 1.0, dim)
        hi = lo + rng.uniform(0.01, 2.0, dim)
        cmin, cmax = _corner_range(n, lo, hi)
        alpha = rng.uniform(cmin - 0.1 * (cmax - cmin), cmax + 0.1 * (cmax - cmin))
        box = float(np.prod(hi - lo))
        s = _cut(n, alpha, lo, hi) + _cut(-n, -alpha, lo, hi)
        assert abs(s - box) <= 1e-13 * box


def test_tiny_components_match_zero_components():
    """A component 1e-17 relative to the others changes the volume by <= ~1e-17 of the box."""
    lo, hi = np.zeros(3), np.array([0.7, 1.3, 0.4])
    for alpha in (0.05, 0.3, 0.6, 0.9):
        for i in range(3):
            n0 = np.array([0.8, -0.5, 1.1])
            n0[i] = 0.0
            n1 = n0.copy()
            n1[i] = 1e-17
            assert abs(_cut(n1, alpha, lo, hi) - _cut(n0, alpha, lo, hi)) <= 1e-15
            n1[i] = -1e-17
            assert abs(_cut(n1, alpha, lo, hi) - _cut(n0, alpha, lo, hi)) <= 1e-15
    # only one non-zero component left: 1D formula
    assert _cut(np.array([1e-20, -3.0, 1e-19]), -0.9, lo, hi) == pytest.approx(1.3 * 0.4 * 0.7 * (1.0 - 0.3 / 1.3),
                                                                                 rel=1e-14)


# ----------------------------------------------------------------------------------------------
# plane constant (inverse)
# ----------------------------------------------------------------------------------------------
_SPECIAL_NORMALS = {
    2: [(1.0, 0.0), (0.0, -2.0), (1e-17, 1.0), (-1.0, -1e-17), (1e-17, -1e-17 * 3), (-0.3, -0.7),
        (1.0, 1.0), (2.0, -1e-9)],
    3: [(1.0, 0.0, 0.0), (0.0, -2.0, 0.0), (0.0, 0.0, 5.0), (1e-17, 1.0, 0.3), (-1e-17, -1.0, 1e-17),
        (-0.3, -0.2, -0.5), (1.0, 1.0, 1.0), (1.0, 1.0, 0.0), (1e-17, 0.0, -1e-17), (3.0, 1e-9, -2.0)],
}


@pytest.mark.parametrize("dim", [2, 3])
def test_plane_constant_inverse(dim):
    """cut(plane_constant(f)) = f box to 1e-13 of the box (measured <= 1e-15); also against the exact
    rational volume for non-zero components (1e-14)."""
    rng = np.random.default_rng(60 + dim)
    normals = [np.array(n) for n in _SPECIAL_NORMALS[dim]]
    normals += [_random_normal(rng, dim, k % 4) for k in range(300)]
    worst = 0.0
    for n in normals:
        h = rng.uniform(0.05, 3.0, dim)
        box = float(np.prod(h))
        for f in (0.0, 1e-12, rng.uniform(), rng.uniform(), 0.5, 1.0 - 1e-12, 1.0):
            alpha = _alpha(n, f, h)
            v = _cut(n, alpha, np.zeros(dim), h)
            worst = max(worst, abs(v - f * box) / box)
            if np.all(n != 0.0) and 0.0 < f < 1.0:
                ex = _exact_measure(n, alpha, np.zeros(dim), h)
                assert abs(float(ex - Fraction(f) * Fraction(box))) <= 1e-14 * box
    assert worst <= 1e-13


@pytest.mark.parametrize("dim", [2, 3])
def test_plane_constant_bracket_ends_and_clamping(dim):
    rng = np.random.default_rng(70 + dim)
    for n in [np.array(v) for v in _SPECIAL_NORMALS[dim]] + [rng.normal(size=dim) for _ in range(20)]:
        h = rng.uniform(0.1, 2.0, dim)
        cmin, cmax = _corner_range(n, np.zeros(dim), h)
        assert _alpha(n, 0.0, h) == pytest.approx(cmin, abs=1e-15 * (1 + abs(cmin)))
        assert _alpha(n, 1.0, h) == pytest.approx(cmax, abs=1e-15 * (1 + abs(cmax)))
        assert _alpha(n, -0.5, h) == _alpha(n, 0.0, h)
        assert _alpha(n, 1.5, h) == _alpha(n, 1.0, h)
    # zero normal: no plane; the cut is all (f >= 1/2) or nothing
    z, one = np.zeros(dim), np.ones(dim)
    for f, full in ((0.0, 0.0), (0.3, 0.0), (0.5, 1.0), (0.7, 1.0), (1.0, 1.0)):
        assert _cut(z, _alpha(z, f, one), z, one) == full


def test_plane_constant_closed_form():
    # unit cube, n = (1,1,1): f = 1/48 -> alpha = 1/2 (tetra), f = 1/2 -> 3/2
    assert plic.plane_constant_3d(1.0, 1.0, 1.0, 1.0 / 48.0, 1.0, 1.0, 1.0) == pytest.approx(0.5, rel=1e-15)
    assert plic.plane_constant_3d(1.0, 1.0, 1.0, 0.5, 1.0, 1.0, 1.0) == pytest.approx(1.5, rel=1e-15)
    # cubic interval: n = (1,1,1), f = 1/6 -> alpha = 1
    assert plic.plane_constant_3d(1.0, 1.0, 1.0, 1.0 / 6.0, 1.0, 1.0, 1.0) == pytest.approx(1.0, rel=1e-14)
    # axis-aligned in a [0,2]x[0,3] box: y <= 3 f ; n = (0,-1): y >= 3 (1-f)
    assert plic.plane_constant_2d(0.0, 1.0, 0.25, 2.0, 3.0) == pytest.approx(0.75, rel=1e-15)
    assert plic.plane_constant_2d(0.0, -1.0, 0.25, 2.0, 3.0) == pytest.approx(-2.25, rel=1e-15)
    # 2D triangle: x + y <= a, a^2/2 = f -> a = sqrt(2 f)
    assert plic.plane_constant_2d(1.0, 1.0, 0.02, 1.0, 1.0) == pytest.approx(0.2, rel=1e-15)


# ----------------------------------------------------------------------------------------------
# Youngs normals
# ----------------------------------------------------------------------------------------------
def _grid_layout(shape, order):
    """Flat strides of a padded grid stored in C or Fortran order, axis 0 = x."""
    a = np.zeros(shape, order=order)
    return tuple(s // 8 for s in a.strides)


@pytest.mark.parametrize("order", ["C", "F"])
def test_youngs_linear_field_2d(order):
    rng = np.random.default_rng(80)
    nx, ny = 7, 9
    hx, hy = 0.3, 0.11
    sx, sy = _grid_layout((nx, ny), order)
    for _ in range(5):
        a = rng.normal(size=2)
        b = rng.normal()
        X, Y = np.meshgrid((np.arange(nx) + 0.5) * hx, (np.arange(ny) + 0.5) * hy, indexing="ij")
        F = (a[0] * X + a[1] * Y + b).ravel(order=order)
        for i in range(1, nx - 1):
            for j in range(1, ny - 1):
                n = np.array(plic.youngs_normal_2d(F, i * sx + j * sy, sx, sy, hx, hy))
                assert np.linalg.norm(n + a) <= 1e-12 * np.linalg.norm(a)


@pytest.mark.parametrize("order", ["C", "F"])
def test_youngs_linear_field_3d(order):
    rng = np.random.default_rng(81)
    shape = (5, 6, 7)
    h = np.array([0.3, 0.11, 0.7])
    sx, sy, sz = _grid_layout(shape, order)
    for _ in range(5):
        a = rng.normal(size=3)
        b = rng.normal()
        X = np.meshgrid(*[(np.arange(s) + 0.5) * hh for s, hh in zip(shape, h)], indexing="ij")
        F = (a[0] * X[0] + a[1] * X[1] + a[2] * X[2] + b).ravel(order=order)
        for i, j, k in itertools.product(*[range(1, s - 1) for s in shape]):
            n = np.array(plic.youngs_normal_3d(F, i * sx + j * sy + k * sz, sx, sy, sz, *h))
            assert np.linalg.norm(n + a) <= 1e-12 * np.linalg.norm(a)


def test_youngs_uniform_field_gives_zero():
    F = np.full(27, 0.37)
    assert plic.youngs_normal_3d(F, 13, 1, 3, 9, 1.0, 2.0, 3.0) == (0.0, 0.0, 0.0)
    assert plic.youngs_normal_2d(F[:9], 4, 1, 3, 1.0, 2.0) == (0.0, 0.0)


def test_youngs_stencil_weights():
    """Impulse response = Youngs' weights: d/dx uses (F[i+1]-F[i-1]) weighted 1-2-1 (x 1-2-1)."""
    w = {-1: 1.0, 0: 2.0, 1: 1.0}
    hx, hy, hz = 0.5, 2.0, 0.25
    for di, dj in itertools.product((-1, 0, 1), repeat=2):
        F = np.zeros(9)
        F[4 + di + 3 * dj] = 1.0
        n = plic.youngs_normal_2d(F, 4, 1, 3, hx, hy)
        assert n[0] == pytest.approx(-di * w[dj] / (8 * hx), abs=1e-15)
        assert n[1] == pytest.approx(-dj * w[di] / (8 * hy), abs=1e-15)
    for di, dj, dk in itertools.product((-1, 0, 1), repeat=3):
        F = np.zeros(27)
        F[13 + di + 3 * dj + 9 * dk] = 1.0
        n = plic.youngs_normal_3d(F, 13, 1, 3, 9, hx, hy, hz)
        assert n[0] == pytest.approx(-di * w[dj] * w[dk] / (32 * hx), abs=1e-15)
        assert n[1] == pytest.approx(-dj * w[di] * w[dk] / (32 * hy), abs=1e-15)
        assert n[2] == pytest.approx(-dk * w[di] * w[dj] / (32 * hz), abs=1e-15)


def _disc_fractions(N, h, c, R, nsub=200):
    """Cell fractions of a disc: exact in y, composite 2-point Gauss in x (error << 1e-6)."""
    g, wg = np.polynomial.legendre.leggauss(2)
    t = (np.arange(nsub)[:, None] + 0.5 + 0.5 * g[None, :]).ravel() / nsub
    wt = np.tile(0.5 * wg, nsub) / nsub
    y0 = np.arange(N)[:, None] * h
    F = np.zeros((N, N))
    for i in range(N):
        half = np.sqrt(np.maximum(R * R - ((i + t) * h - c[0]) ** 2, 0.0))[None, :]
        lo = np.clip(c[1] - half, y0, y0 + h)
        hi = np.clip(c[1] + half, y0, y0 + h)
        F[i] = ((hi - lo) * wt).sum(axis=1) / h
    return F


def _ball_fractions(N, h, c, R, nsub=16):
    """Cell fractions of a ball: exact in z, midpoint nsub x nsub in (x, y) (error ~1e-3)."""
    t = (np.arange(nsub) + 0.5) / nsub
    z0 = np.arange(N) * h
    F = np.zeros((N, N, N))
    for i in range(N):
        for j in range(N):
            r2 = R * R - ((i + t)[:, None] * h - c[0]) ** 2 - ((j + t)[None, :] * h - c[1]) ** 2
            half = np.sqrt(np.maximum(r2, 0.0))[..., None]
            lo = np.clip(c[2] - half, z0, z0 + h)
            hi = np.clip(c[2] + half, z0, z0 + h)
            F[i, j] = (hi - lo).mean(axis=(0, 1)) / h
    return F


def _angle(n, r):
    cosang = float(np.dot(n, r)) / (np.linalg.norm(n) * np.linalg.norm(r))
    return float(np.arccos(min(1.0, cosang)))


def test_youngs_circle_normal_angle():
    """Disc of radius 32 zones (off-centre): angle between Youngs' normal and the radial direction
    through the zone centre, over all interface zones.  Measured max 0.065, rms 0.026 rad (Youngs
    is not exact even for straight lines, the error does not vanish with resolution: the same
    numbers at 8 and 16 zones per radius); asserted max < 0.08, rms < 0.03."""
    R_h = 32
    h = 1.0 / R_h
    N = 2 * R_h + 8
    c = np.array([0.5 * N * h + 0.123 * h, 0.5 * N * h - 0.377 * h])
    F = _disc_fractions(N, h, c, 1.0).ravel(order="F")  # sx = 1, sy = N
    err = []
    for i, j in itertools.product(range(1, N - 1), repeat=2):
        f = F[i + N * j]
        if 1e-9 < f < 1.0 - 1e-9:
            n = plic.youngs_normal_2d(F, i + N * j, 1, N, h, h)
            err.append(_angle(n, (np.array([i, j]) + 0.5) * h - c))
    err = np.array(err)
    assert err.size > 200
    assert err.max() < 0.08
    assert np.sqrt(np.mean(err ** 2)) < 0.03


def test_youngs_sphere_normal_angle():
    """Ball of radius 8 zones: measured max 0.075, rms 0.026 rad; asserted max < 0.1, rms < 0.035."""
    R_h = 8
    h = 1.0 / R_h
    N = 2 * R_h + 6
    c = np.array([0.5 * N * h + 0.123 * h, 0.5 * N * h - 0.377 * h, 0.5 * N * h + 0.21 * h])
    F = _ball_fractions(N, h, c, 1.0).ravel(order="F")
    err = []
    for i, j, k in itertools.product(range(1, N - 1), repeat=3):
        z = i + N * j + N * N * k
        if 1e-9 < F[z] < 1.0 - 1e-9:
            n = plic.youngs_normal_3d(F, z, 1, N, N * N, h, h, h)
            err.append(_angle(n, (np.array([i, j, k]) + 0.5) * h - c))
    err = np.array(err)
    assert err.size > 1000
    assert err.max() < 0.1
    assert np.sqrt(np.mean(err ** 2)) < 0.035


# ----------------------------------------------------------------------------------------------
# slab fractions
# ----------------------------------------------------------------------------------------------
def _slab(n, f, h, d, upper, w):
    if len(n) == 2:
        return plic.slab_fraction_2d(n[0], n[1], f, h[0], h[1], d, upper, w)
    return plic.slab_fraction_3d(n[0], n[1], n[2], f, h[0], h[1], h[2], d, upper, w)


@pytest.mark.parametrize("dim", [2, 3])
def test_slab_partition_reproduces_fraction(dim):
    """w1 frac_lower(w1) + w2 frac_upper(w2) = f h_d for w1 + w2 = h_d (1e-13 h_d)."""
    rng = np.random.default_rng(90 + dim)
    for k in range(600):
        n = _random_normal(rng, dim, k % 4)
        h = rng.uniform(0.05, 2.0, dim)
        f = [rng.uniform(), 1e-10, 1.0 - 1e-10, 0.5][k % 4]
        d = int(rng.integers(dim))
        w1 = [rng.uniform(0.0, h[d]), 0.0, h[d], 1e-9 * h[d], 1e-3 * h[d]][k % 5]
        w2 = h[d] - w1
        lo = _slab(n, f, h, d, False, w1)
        up = _slab(n, f, h, d, True, w2)
        assert 0.0 <= lo <= 1.0 and 0.0 <= up <= 1.0
        assert abs(w1 * lo + w2 * up - f * h[d]) <= 1e-13 * h[d], (n, f, h, d, w1)


@pytest.mark.parametrize("dim", [2, 3])
def test_slab_fraction_vs_exact_rational(dim):
    rng = np.random.default_rng(100 + dim)
    for k in range(200):
        n = rng.normal(size=dim)
        h = rng.uniform(0.1, 2.0, dim)
        f = rng.uniform()
        d = int(rng.integers(dim))
        upper = bool(k % 2)
        w = rng.uniform(0.05, 1.0) * h[d]
        alpha = _alpha(n, f, h)
        lo, hi = np.zeros(dim), h.copy()
        if upper:
            lo[d] = h[d] - w
        else:
            hi[d] = w
        slab_vol = float(np.prod(hi - lo))
        ex = float(_exact_measure(n, alpha, lo, hi)) / slab_vol
        assert abs(_slab(n, f, h, d, upper, w) - ex) <= 1e-13


def test_slab_fraction_closed_form():
    # unit square, x + y <= 1/2 (f = 1/8): lower x-slab of width w <= 1/2 -> 1/2 - w/2; upper -> 0
    for w in (0.0, 0.1, 0.3, 0.5):
        assert plic.slab_fraction_2d(1.0, 1.0, 0.125, 1.0, 1.0, 0, False, w) == pytest.approx(0.5 - 0.5 * w,
                                                                                              abs=1e-14)
        assert plic.slab_fraction_2d(1.0, 1.0, 0.125, 1.0, 1.0, 1, True, w) == 0.0
    # unit cube, x + y + z <= 1/2 (f = 1/48): lower slab ((1/2)^3 - (1/2 - w)^3) / (6 w); face: 1/8
    assert plic.slab_fraction_3d(1.0, 1.0, 1.0, 1.0 / 48.0, 1.0, 1.0, 1.0, 2, False, 0.0) == pytest.approx(
        0.125, abs=1e-14)
    for w in (0.1, 0.25, 0.5):
        ref = (0.125 - (0.5 - w) ** 3) / (6.0 * w)
        for d in range(3):
            assert plic.slab_fraction_3d(1.0, 1.0, 1.0, 1.0 / 48.0, 1.0, 1.0, 1.0, d, False, w) == pytest.approx(
                ref, abs=1e-14)
    # axis-aligned: x <= 0.3 (h = 1), slabs and face limits
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 0, False, 0.2) == 1.0
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 0, False, 0.5) == pytest.approx(0.6, abs=1e-15)
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 0, True, 0.5) == 0.0
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 0, True, 0.0) == 0.0
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 0, False, 0.0) == 1.0
    assert plic.slab_fraction_3d(1.0, 0.0, 0.0, 0.3, 1.0, 2.0, 3.0, 1, True, 0.7) == pytest.approx(0.3, abs=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_slab_fraction_edge_cases(dim):
    rng = np.random.default_rng(110 + dim)
    h = rng.uniform(0.5, 1.5, dim)
    for _ in range(20):
        n = rng.normal(size=dim)
        d = int(rng.integers(dim))
        for upper in (False, True):
            for w in (0.0, 0.3 * h[d], h[d]):
                assert _slab(n, 0.0, h, d, upper, w) == 0.0
                assert _slab(n, -0.2, h, d, upper, w) == 0.0
                assert _slab(n, 1.0, h, d, upper, w) == 1.0
                assert _slab(n, 1.3, h, d, upper, w) == 1.0
                assert _slab(np.zeros(dim), 0.37, h, d, upper, w) == 0.37
            f = rng.uniform(0.05, 0.95)
            # the whole box is the slab
            assert _slab(n, f, h, d, upper, h[d]) == pytest.approx(f, abs=1e-14)
            # w -> 0 is continuous with the face limit (the slab fraction varies O(w / h))
            s0 = _slab(n, f, h, d, upper, 0.0)
            assert np.isfinite(s0) and 0.0 <= s0 <= 1.0
            assert abs(_slab(n, f, h, d, upper, 1e-6 * h[d]) - s0) <= 1e-4
            assert abs(_slab(n, f, h, d, upper, 2e-8 * h[d]) - s0) <= 1e-5


# ----------------------------------------------------------------------------------------------
# numba: the kernels are callable from a nopython per-zone loop
# ----------------------------------------------------------------------------------------------
@njit
def _zone_loop(F, shape, h, w, out):
    sx, sy, sz = 1, shape[0], shape[0] * shape[1]
    for k in range(1, shape[2] - 1):
        for j in range(1, shape[1] - 1):
            for i in range(1, shape[0] - 1):
                z = i * sx + j * sy + k * sz
                nx, ny, nz = plic.youngs_normal_3d(F, z, sx, sy, sz, h[0], h[1], h[2])
                a = plic.plane_constant_3d(nx, ny, nz, F[z], h[0], h[1], h[2])
                v = plic.cut_volume_3d(nx, ny, nz, a, 0.0, h[0], 0.0, h[1], 0.0, h[2])
                s = plic.slab_fraction_3d(nx, ny, nz, F[z], h[0], h[1], h[2], 0, True, w)
                m2x, m2y = plic.youngs_normal_2d(F, z, sx, sy, h[0], h[1])
                a2 = plic.plane_constant_2d(m2x, m2y, F[z], h[0], h[1])
                v2 = plic.cut_area_2d(m2x, m2y, a2, 0.0, h[0], 0.0, h[1])
                s2 = plic.slab_fraction_2d(m2x, m2y, F[z], h[0], h[1], 1, False, w)
                out[z, 0] = v
                out[z, 1] = s
                out[z, 2] = v2
                out[z, 3] = s2


def test_kernels_run_in_nopython_loop():
    shape = np.array([10, 10, 10])
    h = np.array([0.1, 0.1, 0.1])
    F = _ball_fractions(10, 0.1, np.array([0.52, 0.47, 0.5]), 0.3, nsub=4).ravel(order="F")
    out = np.zeros((F.size, 4))
    _zone_loop(F, shape, h, 0.03, out)
    for i, j, k in itertools.product(range(1, 9), repeat=3):
        z = i + 10 * j + 100 * k
        n = plic.youngs_normal_3d(F, z, 1, 10, 100, 0.1, 0.1, 0.1)
        assert out[z, 0] == pytest.approx(F[z] * 1e-3, abs=1e-16)
        assert out[z, 1] == plic.slab_fraction_3d(*n, F[z], 0.1, 0.1, 0.1, 0, True, 0.03)
        assert out[z, 2] == pytest.approx(F[z] * 1e-2, abs=1e-16)
