"""solvers/contact/methods.py: the comparison methods behind one interface, and where they fail (issue
11's "stability where methods fail", library level): single-pass node-to-surface fails the patch test,
single-pass mortar and node-to-surface are biased (they need the coarser deformable side as their
slave / non-mortar side), double-pass node-to-surface over-constrains, the two passes without
their stabilization leave the multipliers free; the stabilized dual pass passes all."""
import numpy as np
import pytest

from solvers.contact import methods
from tests.solvers.contact import test_hertz_2d as hertz
from tests.solvers.contact import test_patch_2d as patch


def _with_method(monkeypatch, module, method, swap=False):
    def build(x, a, b, capture, penetration=None):
        return methods.build(method, x, *((b, a) if swap else (a, b)), capture, penetration)
    monkeypatch.setattr(module, "DualPassContact", build)


def test_registered_names_and_an_unknown_one():
    assert set(methods.METHODS) == {"dual_pass_mortar", "mortar", "node_to_surface", "node_to_surface_double",
                                    "penalty", "node_to_surface_penalty", "node_to_surface_double_penalty"}
    with pytest.raises(KeyError, match="registered: dual_pass_mortar, mortar"):
        methods.build("penalty_magic", np.zeros((2, 2)), np.zeros((0, 2), int), np.zeros((0, 2), int), 0.1)


@pytest.mark.parametrize("n_low, n_up", patch.MESHES)
def test_single_pass_node_to_surface_fails_the_patch_test_and_mortar_passes_it(monkeypatch, n_low, n_up):
    _with_method(monkeypatch, patch, "node_to_surface")
    _, s, _ = patch.blocks(n_low, n_up, -0.01)
    # measured 7.1e-2, 1.3e-1, 1.1e-1, 5.7e-2: the nodal forces cannot carry a uniform pressure
    assert np.abs(s[..., 1] / -1.0e4 - 1).max() > 1e-2
    _with_method(monkeypatch, patch, "mortar")
    _, s, _ = patch.blocks(n_low, n_up, -0.01)
    np.testing.assert_allclose(s[..., 1], -1.0e4, rtol=1e-11)  # measured 2.2e-13


def test_double_pass_node_to_surface_over_constrains(monkeypatch):
    # the blocks' corner nodes coincide: each side's node is constrained on the other's segment twice
    _with_method(monkeypatch, patch, "node_to_surface_double")
    with pytest.raises(RuntimeError, match="KKT system is singular"):
        patch.blocks((4, 2), (3, 2), -0.01)


@pytest.mark.parametrize("method", ["mortar", "node_to_surface"])
def test_single_pass_methods_are_biased(monkeypatch, method):
    # with the cylinder (the coarser, deformable side) as slave / non-mortar side they reach Hertz
    _with_method(monkeypatch, hertz, method)
    x, nq, contact, sol = hertz.cylinder_on_flat(80)
    fy, xs = contact.forces(sol.p)[:nq, 1], x[:nq, 0]
    a = 2 * np.sqrt((fy * xs**2).sum() / fy.sum())  # second moment of the cylinder's contact forces
    assert abs(a / hertz.A_EXACT - 1) < 0.03  # measured -8.5e-3 (mortar), +6.2e-3 (node to surface)
    # with the rigid flat's fine segments as that side, its constraints outnumber what the cylinder can meet
    _with_method(monkeypatch, hertz, method, swap=True)
    with pytest.raises(RuntimeError, match="KKT system is singular"):
        hertz.cylinder_on_flat(80)


def test_the_dual_pass_does_not_care_which_side_is_which(monkeypatch):
    results = []
    for swap in (False, True):
        _with_method(monkeypatch, hertz, "dual_pass_mortar", swap)
        x, nq, contact, sol = hertz.cylinder_on_flat(80)
        results.append(contact.forces(sol.p))
    # the same operators with the passes' multipliers in the other order: forces equal to the sparse
    # LU's round-off (another pivot order; measured 1.2e-12 of the largest)
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-11 * np.abs(results[0]).max())


@pytest.mark.parametrize("n_low, n_up", patch.MESHES[:3])
def test_two_pass_mortar_without_stabilization_leaves_its_multipliers_free(n_low, n_up):
    """The two passes carry twice the multipliers the interface resolves: with J = 0 their split is
    undetermined (the KKT system singular, or the active set cycling through splits, or pressures 0
    and 2 p on the twin nodes); a vanishing J (alpha 1e-12) pins it poorly (oscillation 0.3-13 % of
    p), alpha 1e-4 to 2e-9 (measured 1.2e-10, 4.0e-10, 2.2e-9). The stresses are exact in every case
    that solves: the forces do not see the split."""
    try:
        sol, s, _ = patch.blocks(n_low, n_up, -0.01, alpha=0.0)
        assert np.abs(sol.p / 1.0e4 - 1).max() > 0.5  # measured 1.0 (the (4, 2) / (3, 2) pair)
    except RuntimeError as e:
        assert "singular" in str(e) or "cycles" in str(e)
    sol, s, _ = patch.blocks(n_low, n_up, -0.01, alpha=1e-12)
    assert np.abs(sol.p / 1.0e4 - 1).max() > 1e-3  # measured 1.2e-2, 3.0e-3, 1.3e-1
    np.testing.assert_allclose(s[..., 1], -1.0e4, rtol=1e-9)  # measured 4.3e-11 at worst
    sol, s, _ = patch.blocks(n_low, n_up, -0.01, alpha=1e-4)
    np.testing.assert_allclose(sol.p, 1.0e4, rtol=1e-8)
