"""Crisfield's contact patch test with the dual-pass mortar operators and the KKT solve (issue 11's
contact_patch_2d, at the library level): two 1 x 0.5 blocks with non-matching meshes, E = 1e6,
nu = 0, the top pressed down 0.01: sigma_y = -1e4 uniform, sigma_x = tau_xy = 0, with either mesh on
top, for any stabilization alpha. Linear small-strain plane-strain quads (small_strain.py)."""
import numpy as np
import pytest

from solvers.contact.dual_pass import DualPassContact
from solvers.contact.kkt import solve_frictionless
from solvers.lagrange.mesh import box_mesh, concatenate
from solvers.lagrange.small_strain import plane_strain_elasticity, quad_stiffness, quad_stresses
from solvers.lagrange.surface import exterior_facets

E = 1.0e6


def blocks(n_low, n_up, top_displacement, alpha=1.0):
    """The two blocks, bottom held in y (and one node in x), the top moved by top_displacement in y
    (one node held in x): the contact solution and the Gauss-point stresses (ne, 4, 3)."""
    lo = box_mesh([0.0, 0.0], [1.0, 0.5], n_low)
    up = box_mesh([0.0, 0.5], [1.0, 1.0], n_up)
    mesh, _ = concatenate([lo, up])
    x = mesh.points
    d = plane_strain_elasticity(E, 0.0)
    fa, _ = exterior_facets(lo.cells, "quad", lo.num_points, lo.points)
    fb, _ = exterior_facets(up.cells, "quad", up.num_points, up.points)
    h = min(1.0 / n_low[0], 1.0 / n_up[0])
    contact = DualPassContact(x, fa, fb + lo.num_points, capture=0.1 * h)  # every exterior facet
    fixed, uf = np.zeros(x.shape, bool), np.zeros(x.shape)
    bot, top = np.isclose(x[:, 1], 0.0), np.isclose(x[:, 1], 1.0)
    fixed[bot, 1] = fixed[top, 1] = True
    uf[top, 1] = top_displacement
    fixed[np.flatnonzero(bot & (x[:, 0] == 0))[0], 0] = True
    fixed[np.flatnonzero(top & (x[:, 0] == 0))[0], 0] = True
    sol = solve_frictionless(quad_stiffness(x, mesh.cells, d), np.zeros(x.size), contact.constraint_operator(),
                             contact.stabilization(alpha / E, h), x.ravel(), fixed.ravel(), uf.ravel())
    return sol, quad_stresses(x, mesh.cells, d, sol.u.reshape(-1, 2)), contact


MESHES = [((4, 2), (3, 2)), ((3, 2), (4, 2)), ((5, 3), (7, 2)), ((7, 2), (5, 3))]


@pytest.mark.parametrize("n_low, n_up", MESHES)
@pytest.mark.parametrize("alpha", [1e-3, 1.0, 10.0])
def test_pressed_blocks_carry_the_uniform_stress(n_low, n_up, alpha):
    sol, s, contact = blocks(n_low, n_up, -0.01, alpha)
    assert contact.n_multipliers == n_low[0] + n_up[0] + 2 and sol.active.all() and sol.iterations == 1
    # measured with the symmetric J: sigma_y 4.4e-12, sigma_x 1.9e-12, tau_xy 4.9e-12 relative to 1e4
    # (worst of the 12; round-off)
    np.testing.assert_allclose(s[..., 1], -1.0e4, rtol=1e-11)
    assert np.abs(s[..., [0, 2]]).max() <= 1e-11 * 1.0e4
    # the multipliers are the contact pressure, on both passes (measured 1.3e-9 at alpha 1e-3: a small
    # stabilization leaves the split between the passes' twin multipliers ill-conditioned)
    np.testing.assert_allclose(sol.p, 1.0e4, rtol=5e-9)


@pytest.mark.parametrize("n_low, n_up", MESHES[:2])
def test_pulled_blocks_separate_without_stress(n_low, n_up):
    sol, s, contact = blocks(n_low, n_up, +0.01)
    assert not sol.active.any() and np.all(sol.p == 0.0) and sol.iterations == 2
    assert np.abs(s).max() <= 1e-14 * 1.0e4  # nothing loads the blocks: measured 1.5e-15 of E * 0.01
    # the dual pass's gaps are half the weighted gaps (B = G/2): 0.01 times each node's area
    area = np.concatenate([p.area for p in contact.passes])
    np.testing.assert_allclose(sol.gap, 0.5 * 0.01 * area, rtol=1e-12)
