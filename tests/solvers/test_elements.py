"""Element geometry shared by the solvers (solvers/elements.py) against analytic references.

References are computed independently in numpy: exact trilinear/bilinear volumes by 2x2(x2) Gauss
quadrature of det J (exact for these polynomials), their derivatives dV/dx_I by complex-step
differentiation, and for an affine element x = A xi + c the closed forms
``V = 2^dim det A`` and ``b_I = det A A^-T xi_I`` (the integral of grad N_I over the element:
``int dN_I/dxi_k dxi = xi_Ik`` on [-1, 1]^dim, times det A A^-T).
"""
import numpy as np
import pytest

from solvers.elements import HEX_HG, QUAD_HG, hex_bvectors, quad_bvectors

# natural coordinates of the VTK nodes, written out here (not taken from the module under test)
HEX_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                   [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
QUAD_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)


# ----------------------------------------------------------------------------- references
def gauss_volume(xe):
    """Exact volume (area) of a trilinear hex (bilinear quad) by 2-point Gauss."""
    dim = xe.shape[1]
    xi = HEX_XI if dim == 3 else QUAD_XI
    g = 1.0 / np.sqrt(3.0)
    pts = np.array(np.meshgrid(*([[-g, g]] * dim), indexing="ij")).reshape(dim, -1).T
    vol = 0.0
    for p in pts:
        dN = np.empty((len(xi), dim))
        for k in range(dim):
            t = xi[:, k] / 2 ** dim
            for m in range(dim):
                if m != k:
                    t = t * (1 + xi[:, m] * p[m])
            dN[:, k] = t
        vol = vol + np.linalg.det(xe.T @ dN)
    return vol


def complex_step_b(xe):
    """dV/dx_I by complex-step differentiation of the exact volume."""
    out = np.empty(xe.shape)
    h = 1e-30
    for i in range(xe.shape[0]):
        for k in range(xe.shape[1]):
            xc = xe.astype(complex)
            xc[i, k] += 1j * h
            out[i, k] = gauss_volume(xc).imag / h
    return out


def distorted_element(dim, seed, amp=0.2):
    rng = np.random.default_rng(seed)
    xi = HEX_XI if dim == 3 else QUAD_XI
    return 0.5 * (xi + 1.0) + rng.uniform(-amp, amp, xi.shape)


def bvectors(xe):
    """(b, V, amax | dmax) of the kernel for a (2^dim, dim) element."""
    b = np.empty(xe.shape)
    kernel = hex_bvectors if xe.shape[1] == 3 else quad_bvectors
    vol, size = kernel(np.ascontiguousarray(xe), b)
    return b, vol, size


def affine(dim, seed):
    """A well-conditioned affine map (det A > 0) and its element."""
    rng = np.random.default_rng(seed)
    A = np.eye(dim) + 0.3 * rng.normal(size=(dim, dim))
    if np.linalg.det(A) < 0:
        A[:, 0] *= -1
    c = rng.normal(size=dim)
    xi = HEX_XI if dim == 3 else QUAD_XI
    return A, xi @ A.T + c


def rotation(dim, seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(dim, dim)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1.0
    return q


# ----------------------------------------------------------------------------- b-vectors
@pytest.mark.parametrize("seed", range(5))
def test_hex_b_identities(seed):
    xe = distorted_element(3, seed)
    b, vol, _ = bvectors(xe)
    vref = gauss_volume(xe)
    assert vref > 0
    assert abs(vol - vref) <= 1e-12 * vref
    B = b / vol
    assert np.abs(B.sum(0)).max() <= 1e-12                 # translation keeps V
    assert np.abs(xe.T @ B - np.eye(3)).max() <= 1e-12     # V homogeneous of degree 3
    # V = (1/3) sum x_I . B_I V
    assert abs(np.sum(xe * B) * vol / 3 - vref) <= 1e-12 * vref
    # B_I = (1/V) dV/dx_I (exact derivative of the exact trilinear volume)
    assert np.abs(b - complex_step_b(xe)).max() <= 1e-12 * np.abs(b).max()


@pytest.mark.parametrize("seed", range(5))
def test_quad_b_identities(seed):
    xe = distorted_element(2, seed)
    b, area, dmax = bvectors(xe)
    aref = gauss_volume(xe)
    assert abs(area - aref) <= 1e-12 * aref
    B = b / area
    assert np.abs(B.sum(0)).max() <= 1e-12
    assert np.abs(xe.T @ B - np.eye(2)).max() <= 1e-12
    assert abs(np.sum(xe * B) * area / 2 - aref) <= 1e-12 * aref
    assert np.abs(b - complex_step_b(xe)).max() <= 1e-12 * np.abs(b).max()
    assert dmax == pytest.approx(max(np.linalg.norm(xe[2] - xe[0]), np.linalg.norm(xe[3] - xe[1])),
                                 rel=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_affine_element_closed_form(dim, seed):
    """x = A xi + c: V = 2^dim det A, b_I = det A A^-T xi_I; the largest face area of the hex is
    4 det A max_k |A^-T e_k| (face xi_k = +-1), the longer quad diagonal max |A (xi_2 - xi_0)|,
    |A (xi_3 - xi_1)|."""
    A, xe = affine(dim, seed)
    xi = HEX_XI if dim == 3 else QUAD_XI
    det = np.linalg.det(A)
    ainv_t = np.linalg.inv(A).T
    b, vol, size = bvectors(xe)
    assert abs(vol - 2 ** dim * det) <= 1e-15 * 2 ** dim * det          # measured <= 1.8e-16
    b_ref = det * xi @ ainv_t.T
    assert np.abs(b - b_ref).max() <= 1e-15 * np.abs(b_ref).max()       # measured <= 2.3e-16
    if dim == 3:
        size_ref = 4.0 * det * np.linalg.norm(ainv_t, axis=0).max()
    else:
        size_ref = max(np.linalg.norm(A @ (xi[2] - xi[0])), np.linalg.norm(A @ (xi[3] - xi[1])))
    assert abs(size - size_ref) <= 1e-15 * size_ref                      # measured <= 2.3e-16


@pytest.mark.parametrize("dim", [2, 3])
def test_box(dim):
    """An axis-aligned box of sides h (A = diag(h) / 2): V = prod h, b_I = V xi_I / (2^(dim-1) h)
    (componentwise); the hex's largest face area is the product of its two longest sides, the
    quad's diagonal |h|."""
    h = np.array([0.3, 0.02, 7.0])[:dim]
    xi = HEX_XI if dim == 3 else QUAD_XI
    b, vol, size = bvectors(0.5 * (xi + 1.0) * h + 0.25)
    assert vol == pytest.approx(np.prod(h), rel=4e-15)                   # measured <= 1.1e-15
    np.testing.assert_allclose(b, np.prod(h) * xi / (2 ** (dim - 1) * h), rtol=4e-15, atol=0)  # 1.1e-15
    ref = np.prod(np.sort(h)[1:]) if dim == 3 else np.linalg.norm(h)
    assert size == pytest.approx(ref, rel=1e-15)                         # measured <= 2.3e-16


@pytest.mark.parametrize("dim", [2, 3])
def test_rigid_motion_and_mirror(dim):
    """b(R x + t) = R b(x) and V unchanged for a rotation R (det 1); a mirror image (x -> -x in one
    component) has volume -V: the sign is the orientation the solvers test for."""
    xe = distorted_element(dim, 11)
    b, vol, size = bvectors(xe)
    R = rotation(dim, 5)
    b2, vol2, size2 = bvectors(xe @ R.T + np.arange(1.0, dim + 1.0))
    assert abs(vol2 - vol) <= 2e-15 * vol                                # measured <= 3.8e-16
    assert np.abs(b2 - b @ R.T).max() <= 2e-15 * np.abs(b).max()          # measured <= 5.3e-16
    assert abs(size2 - size) <= 2e-15 * size                             # measured <= 5.5e-16
    m = xe.copy()
    m[:, 0] *= -1.0
    assert bvectors(m)[1] == pytest.approx(-vol, rel=1e-15)              # measured: 0


# ----------------------------------------------------------------------------- hourglass base vectors
@pytest.mark.parametrize("dim", [2, 3])
def test_hourglass_base_vectors(dim):
    """Gamma_a is orthogonal to the constant and the linear nodal fields of the reference element
    and the modes are mutually orthogonal, |Gamma_a|^2 = 2^dim (entries +-1)."""
    gam = HEX_HG if dim == 3 else QUAD_HG[None, :]
    xi = HEX_XI if dim == 3 else QUAD_XI
    assert gam.shape == (4 if dim == 3 else 1, 2 ** dim)
    assert np.all(np.abs(gam) == 1.0)
    np.testing.assert_array_equal(gam @ np.ones(2 ** dim), 0.0)
    np.testing.assert_array_equal(gam @ xi, 0.0)
    np.testing.assert_array_equal(gam @ gam.T, 2 ** dim * np.eye(len(gam)))
    # the one-point element sees none of them: the patterns are xi-products, not linear in xi
    assert np.linalg.matrix_rank(np.column_stack([np.ones(2 ** dim), xi, gam.T])) == 2 ** dim


@pytest.mark.parametrize("dim", [2, 3])
def test_hourglass_projection_is_orthogonal_to_linear_fields(dim):
    """gamma_a = Gamma_a - (Gamma_a . x_i) B_i on a distorted element: sum_I gamma_aI = 0 and
    sum_I x_I gamma_aI = 0 (zero hourglass force for a rigid or any linear velocity field)."""
    xe = distorted_element(dim, 3, amp=0.15)
    b, vol, _ = bvectors(xe)
    gam = HEX_HG if dim == 3 else QUAD_HG[None, :]
    g = gam - (gam @ xe) @ (b / vol).T
    assert np.abs(g.sum(axis=1)).max() <= 2e-15                         # measured <= 4.5e-16
    assert np.abs(g @ xe).max() <= 2e-15                                # measured <= 5.5e-16
