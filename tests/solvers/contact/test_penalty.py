"""solvers/contact/penalty.py: the penalty variants as the KKT system's compliance J (issue 11).

Crisfield's patch test (test_patch_2d.py's blocks: 1 x 0.5 each, non-matching meshes, E = 1e6,
nu = 0, the top pressed 0.01): with the interface a spring of k = kappa E / h per unit area in series
with the two blocks (height 1 together), sigma_y = 1e4 / (1 + h / kappa), an error
(h / kappa) / (1 + h / kappa), first order in 1 / kappa; the interpenetration is sigma_y / k.
The penalty mortar has exactly that (its pressures uniform: consistent forces); single-pass
node-to-surface with a penalty keeps its non-uniform stress at every kappa. Then the price of a
penalty in an explicit step: the contact springs raise the highest frequency."""
import numpy as np
import pytest
import scipy.linalg as sla

from solvers.contact import methods
from solvers.contact.penalty import PENALTY, PenaltyMortar, PenaltyNodeToSurface
from solvers.lagrange.mesh import box_mesh, concatenate
from solvers.lagrange.small_strain import plane_strain_elasticity, quad_stiffness
from solvers.lagrange.surface import exterior_facets
from tests.solvers.contact import test_patch_2d as patch

KAPPAS = (1e1, 1e2, 1e3, 1e4)


def _pressed(monkeypatch, n_low, n_up, cls, kappa, **kw):
    """patch.blocks with a penalty method of factor kappa (alpha 1: kappa is the factor itself)."""
    def build(x, a, b, capture, penetration=None):
        return cls(x, a, b, capture, penetration, penalty=kappa, **kw)
    monkeypatch.setattr(patch, "DualPassContact", build)
    sol, s, contact = patch.blocks(n_low, n_up, -0.01, alpha=1.0)
    return sol, s, contact, min(1.0 / n_low[0], 1.0 / n_up[0])


def test_penalty_methods_are_registered_and_the_default_factor():
    for name in ("penalty", "node_to_surface_penalty", "node_to_surface_double_penalty"):
        assert name in methods.METHODS
    assert methods.METHODS["penalty"].self_contact and PENALTY == 100.0
    with pytest.raises(ValueError, match="penalty factor"):
        PenaltyMortar(np.zeros((2, 2)), np.zeros((0, 2), int), np.zeros((0, 2), int), 0.1, penalty=0.0)


@pytest.mark.parametrize("n_low, n_up", patch.MESHES)
def test_penalty_mortar_patch_error_is_the_compliance_first_order_in_one_over_kappa(monkeypatch, n_low, n_up):
    errors = []
    for kappa in KAPPAS:
        sol, s, contact, h = _pressed(monkeypatch, n_low, n_up, PenaltyMortar, kappa)
        sy = s[..., 1]
        # uniform: measured (max - min) / 1e4 <= 2.3e-12 over the 4 meshes and 4 factors
        assert np.ptp(sy) <= 1e-10 * 1.0e4
        err = abs(sy.mean() / -1.0e4 - 1)
        # the series spring's error exactly: measured to 5.1e-10 relative at worst (round-off of an
        # error down to 1.4e-5)
        exact = (h / kappa) / (1 + h / kappa)
        assert err == pytest.approx(exact, rel=1e-8)
        errors.append(err)
        # the interpenetration of the faces is the pressure over k = kappa E / h, to round-off
        # (measured 9.6e-10 relative at worst: an overlap down to 1.4e-7 from two positions 0.5)
        x, u = contact.points, sol.u.reshape(-1, 2)
        face = np.isclose(x[:, 1], 0.5)
        lower = face & (np.arange(len(x)) < (n_low[0] + 1) * (n_low[1] + 1))
        overlap = u[lower, 1].mean() - u[face & ~lower, 1].mean()
        assert np.ptp(u[face & ~lower, 1]) <= 1e-12 and np.ptp(u[lower, 1]) <= 1e-12
        assert overlap == pytest.approx(-sy.mean() / (kappa * patch.E / h), rel=1e-7)
        np.testing.assert_allclose(sol.p, -sy.mean(), rtol=1e-8)  # that pressure: measured 1.3e-9
    # first order: a decade of kappa, a decade of error (measured 9.780, 9.978, 9.998 with h = 1/4;
    # 9.873, 9.987, 9.999 with h = 1/7: 10 (1 + h / (10 kappa)) / (1 + h / kappa))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 9.7) & (ratios < 10.05)), ratios


@pytest.mark.parametrize("n_low, n_up", patch.MESHES)
def test_node_to_surface_penalty_fails_the_patch_test_at_every_kappa(monkeypatch, n_low, n_up):
    for kappa in KAPPAS:
        _, s, _, _ = _pressed(monkeypatch, n_low, n_up, PenaltyNodeToSurface, kappa, passes=1)
        # measured non-uniformity (max - min) / 1e4 of 0.107-0.256, errors 5.6e-2 - 1.4e-1, not
        # falling with kappa: the master side's share of the nodal forces is not its pressure's load
        assert np.ptp(s[..., 1]) > 5e-2 * 1.0e4
        assert np.abs(s[..., 1] / -1.0e4 - 1).max() > 1e-3


def test_double_pass_node_to_surface_penalty_passes_the_patch_test_as_kappa_grows(monkeypatch):
    """The classic result (Taylor & Papadopoulos): the double pass does pass the patch test; its
    Lagrange form is singular (test_methods.py), the penalty form tends to the uniform stress."""
    spread = []
    for kappa in KAPPAS:
        _, s, _, _ = _pressed(monkeypatch, (5, 3), (7, 2), PenaltyNodeToSurface, kappa, passes=2)
        spread.append(np.ptp(s[..., 1]) / 1.0e4)
    # (max - min) / 1e4 measured 4.0e-2, 1.8e-2, 4.3e-3, 5.3e-4 at kappa 10 ... 1e4: towards first
    # order in 1 / kappa
    assert spread[0] < 5e-2 and spread[-1] < 1e-3 and spread[-2] / spread[-1] > 7


def _interface(n, kappa, cls, **kw):
    """Two unit-thick 1 x 0.5 blocks with matching n x 2 meshes, bottom and top held in y, one node
    of each in x (test_patch_2d's conditions), rho = 1: the free dofs' stiffness K, the contact
    stiffness Kc = B^T J^-1 B of every multiplier active, the lumped masses m (per dof) and h."""
    lo = box_mesh([0.0, 0.0], [1.0, 0.5], (n, 2))
    up = box_mesh([0.0, 0.5], [1.0, 1.0], (n, 2))
    mesh, _ = concatenate([lo, up])
    x = mesh.points
    K = quad_stiffness(x, mesh.cells, plane_strain_elasticity(patch.E, 0.0)).toarray()
    fa, _ = exterior_facets(lo.cells, "quad", lo.num_points, lo.points)
    fb, _ = exterior_facets(up.cells, "quad", up.num_points, up.points)
    h = 1.0 / n
    c = cls(x, fa, fb + lo.num_points, 0.1 * h, penalty=kappa, **kw)
    B = c.constraint_operator().toarray()
    Kc = B.T @ (B / c.stabilization(1.0 / patch.E, h).diagonal()[:, None])
    m = np.zeros(len(x))
    np.add.at(m, mesh.cells.ravel(), np.repeat(np.full(len(mesh.cells), h * 0.25 / 4), 4))
    fixed = np.zeros(x.shape, bool)
    bot, top = np.isclose(x[:, 1], 0.0), np.isclose(x[:, 1], 1.0)
    fixed[bot | top, 1] = True
    fixed[np.flatnonzero(bot)[0], 0] = fixed[np.flatnonzero(top)[0], 0] = True
    free = ~fixed.ravel()
    return K[free][:, free], Kc[free][:, free], np.repeat(m, 2)[free], h


def _omega2(K, m):
    return sla.eigh(K, np.diag(m), eigvals_only=True)[-1]


@pytest.mark.parametrize("kappa", [1e1, 1e2, 1e3])
def test_a_penalty_cuts_the_explicit_stable_step(kappa):
    """An explicit penalty force f = -k A g adds the springs Kc to the nodes' equations: the central
    difference's stable step 2 / omega_max falls. Node to surface on matching meshes: an interface
    node pair (masses m1 = m2 = rho h t / 2, t = 0.25 the element height) on one spring k A = kappa E
    (A = h): omega_c^2 = kappa E (1/m1 + 1/m2) = 4 kappa E / (rho h t). With the bodies' own
    omega_0, Weyl: max(omega_0^2, omega_c^2) <= omega_max^2 <= omega_0^2 + omega_c^2 (Kc >= 0)."""
    K, Kc, m, h = _interface(4, kappa, PenaltyNodeToSurface, passes=1)
    w0, w = _omega2(K, m), _omega2(K + Kc, m)
    wc = 4 * kappa * patch.E / (h * 0.25)
    assert max(w0, wc) * (1 - 1e-9) <= w <= (w0 + wc) * (1 + 1e-9)
    # the step ratio dt_penalty / dt_0 = omega_0 / omega_max: measured 0.307, 0.0991, 0.0314 at
    # kappa 10, 100, 1000 (omega_c^2 / omega_0^2 = 10.1, 101, 1013: the step falls as
    # kappa^-1/2); the estimate (1 + omega_c^2 / omega_0^2)^(-1/2) = 0.300, 0.0989, 0.0314, within
    # 2.2 %, 0.24 %, 0.02 %
    ratio = np.sqrt(w0 / w)
    assert ratio == pytest.approx(1 / np.sqrt(1 + wc / w0), rel=0.03)
    # the penalty mortar (both passes, consistent D) on these matching meshes: the same highest
    # frequency (measured equal to 1e-15)
    Km, Kcm, mm, _ = _interface(4, kappa, PenaltyMortar)
    assert np.sqrt(_omega2(Km, mm) / _omega2(Km + Kcm, mm)) == pytest.approx(ratio, rel=1e-9)


@pytest.mark.parametrize("method", ["penalty", "node_to_surface_penalty", "node_to_surface_double_penalty"])
def test_explicit_contact_runs_the_penalty_methods_unchanged(method):
    """explicit.py solves them as any method (its J rescaled to the nodes' inertia, module docstring
    there: kappa then drops out, a mass-scaled penalty solved implicitly in the multipliers): two
    faces closing at 1 per unit time stop, the impulses balance."""
    from solvers.contact.explicit import ExplicitContact
    from tests.solvers.contact.geometry import facing_faces

    pts, sa, sb = facing_faces([0.0, 0.3, 0.55, 0.8, 1.0], [0.0, 0.4, 0.7, 1.0], gap=0.005)
    c = ExplicitContact([(0, 1)], method=method, capture=0.05)
    c.set_surface(np.concatenate([sa, sb]), np.repeat([0, 1], [len(sa), len(sb)]), np.ones(len(pts)),
                  np.ones(pts.shape))
    v = np.zeros(pts.shape)
    na = len(sa) + 1                                           # side a's nodes come first
    v[na:, 1] = -1.0                                           # side b moves down onto a
    imp = c.impulses(pts, v, dt=0.01)
    assert c.last_active > 0
    np.testing.assert_allclose(imp.sum(axis=0), 0.0, atol=1e-12)  # momentum: measured 0 to 1e-16
    assert imp[na:, 1].sum() > 0.0                             # b pushed back up
