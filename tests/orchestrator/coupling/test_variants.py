"""Coupling variants (orchestrator.coupling.variants): registry, checks, step limits, steps, state."""
from __future__ import annotations

import math

import jsonschema
import numpy as np
import pytest

from orchestrator.coupling import solve as S
from orchestrator.coupling import variants as V
from orchestrator.coupling.conditioning import straight_cut
from orchestrator.coupling.operators import Operators
from tests.orchestrator.coupling.stand_ins import two_masses


def _line(h=1 / 16, seed=3):
    lat, pieces, facets, nodes = straight_cut(2, h, np.random.default_rng(seed))
    ops = Operators.build(lat, pieces, facets, len(nodes))
    rng = np.random.default_rng(seed + 1)
    m_b = h * h * rng.uniform(0.5, 2.0, ops.bnodes.size)
    m_f = h * h * rng.uniform(0.5, 4.0, len(nodes))
    return ops, m_b, m_f


def _run(method, ops, m_b, m_f, v_b, v_f, dt, steps, state=None, modulus=None):
    """March the coupling alone (no other forces: v* = v^{n-1/2}); returns velocities and state."""
    state = state if state is not None else method.new_state()
    v_b, v_f = v_b.copy(), v_f.copy()
    for _ in range(steps):
        r = method.step(ops, v_b, m_b, v_f, m_f, dt, state, modulus=modulus)
        v_b += r.impulse_b / m_b[:, None]
        v_f += r.impulse_f / m_f[:, None]
    return v_b, v_f, state


# --------------------------------------------------------------------------------------------
def test_the_registry_has_the_three_variants_and_rejects_unknown_names_in_one_line():
    assert sorted(V.METHODS) == ["multiplier", "nitsche", "penalty"]
    with pytest.raises(ValueError) as err:
        V.make({"method": "lagrange"})
    assert str(err.value) == "coupling.method = 'lagrange': must be one of: 'multiplier', 'nitsche', 'penalty'"
    assert isinstance(V.make({}), V.Multiplier)  # the method is the default


@pytest.mark.parametrize("cfg, message", [
    ({"method": "penalty"}, "coupling.stiffness = <missing>: required with method = 'penalty'"),
    ({"method": "multiplier", "stiffness": 1e9},
     "coupling.stiffness = 1000000000.0: only with method = 'penalty'; method 'multiplier' takes alpha, beta, "
     "condition, method, min_fill, substep_passes, substep_tolerance"),
    ({"method": "penalty", "stiffness": 1e9, "gamma": 2.0},
     "coupling.gamma = 2.0: only with method = 'nitsche'; method 'penalty' takes condition, method, min_fill, "
         "stiffness"),
    ({"method": "nitsche", "shear": 1},
     "coupling.shear = 1: unknown key; method 'nitsche' takes condition, gamma, method, min_fill"),
    ({"method": "multiplier", "alpha": 0}, "coupling.alpha = 0: must be a finite number > 0"),
    ({"method": "multiplier", "beta": -0.5}, "coupling.beta = -0.5: must be a finite number >= 0"),
    ({"method": "nitsche", "gamma": math.inf}, "coupling.gamma = inf: must be a finite number > 0"),
    ({"method": "penalty", "stiffness": "stiff"}, "coupling.stiffness = 'stiff': must be a finite number > 0 (Pa/m)"),
    ({"method": "penalty", "stiffness": 1e9, "condition": "glued"},
     "coupling.condition = 'glued': must be one of: 'tied', 'slip'"),
])
def test_check_names_key_value_and_what_is_allowed(cfg, message):
    with pytest.raises(ValueError) as err:
        V.make(cfg)
    assert str(err.value) == message and "\n" not in str(err.value)


def test_schema_fragments_accept_the_valid_tables_and_refuse_the_others():
    schema = V.schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    for cls in V.METHODS.values():
        jsonschema.Draft202012Validator.check_schema(cls.SCHEMA)
    good = [{"method": "multiplier"}, {"method": "multiplier", "condition": "slip", "alpha": 10.0, "beta": 0.0},
            {"method": "penalty", "stiffness": 1e12}, {"method": "nitsche", "gamma": 2.0, "condition": "tied"}]
    bad = [{"method": "penalty"}, {"method": "multiplier", "stiffness": 1.0}, {"method": "nitsche", "gamma": 0.0},
           {"method": "multiplier", "condition": "glued"}, {"method": "simplex"}]
    for cfg in good:
        jsonschema.validate(cfg, schema)
        V.make(cfg)  # and the Python checks agree
    for cfg in bad:
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(cfg, schema)
        with pytest.raises(ValueError):
            V.make(cfg)


# --------------------------------------------------------------------------------------------
def test_penalty_step_limit_is_the_two_mass_spring_limit():
    """Two masses M1, M2 on the spring k A (A = 1): ω² = k A (1/M1 + 1/M2), central differences
    are stable for Δt <= 2/ω and not above."""
    M1, M2, k = 3.0, 5.0, 1.0e3
    ops, m_b, m_f = two_masses(M1, M2)
    pen = V.make({"method": "penalty", "stiffness": k})
    dt_c = 2.0 / math.sqrt(k * (1 / M1 + 1 / M2))
    assert pen.stable_dt(ops, m_b, m_f) == pytest.approx(dt_c, rel=1e-14)  # measured 0
    v_b, v_f = np.tile([1.0, 0.5], (4, 1)), np.zeros((2, 2))
    final = {}
    for factor in (0.99, 1.01):
        vb, vf, _ = _run(pen, ops, m_b, m_f, v_b, v_f, factor * dt_c, 400)
        final[factor] = np.abs(vb - vf[0]).max()
        p = (m_b[:, None] * vb).sum(0) + (m_f[:, None] * vf).sum(0)
        # momentum: measured 1.3e-14 (0.99), 1e-15 of the velocities (1.01)
        assert np.abs(p - M1 * np.array([1.0, 0.5])).max() < 1e-12 * max(1.0, final[factor])
    # relative velocity after 400 steps (1 at the start): measured 0.05 (0.99), 4e49 (1.01)
    assert final[0.99] < 10.0 and final[1.01] > 1e10


def test_penalty_step_limit_bounds_the_true_frequency_of_many_zones():
    """The element bound (mass split by constraint weight) is >= the assembled system's ω_max,
    and marching at 0.99 of it stays bounded."""
    ops, m_b, m_f = _line()
    k = 1.0e6
    pen = V.make({"method": "penalty", "stiffness": k})
    omega_bound = 2.0 / pen.stable_dt(ops, m_b, m_f)
    B = np.hstack([ops.Bb.toarray(), -ops.Bf.toarray()])
    K = k * B.T @ (B / ops.area[:, None])
    m = np.concatenate([m_b, m_f])
    omega_true = math.sqrt(np.linalg.eigvalsh(K / np.sqrt(np.outer(m, m)))[-1])
    ratio = omega_true / omega_bound
    assert 0.5 < ratio <= 1.0 + 1e-12, ratio  # measured 0.81
    rng = np.random.default_rng(1)
    v_b, v_f = rng.normal(size=(ops.bnodes.size, 2)), rng.normal(size=(ops.Bf.shape[1], 2))
    ke = lambda vb, vf: (m_b[:, None] * vb**2).sum() + (m_f[:, None] * vf**2).sum()  # noqa: E731
    vb, vf, _ = _run(pen, ops, m_b, m_f, v_b, v_f, 0.99 * 2.0 / omega_bound, 2000)
    assert ke(vb, vf) < 10.0 * ke(v_b, v_f)  # measured 0.90 of the initial (energy in the springs)
    vb, vf, _ = _run(pen, ops, m_b, m_f, v_b, v_f, 1.02 * 2.0 / omega_true, 300)
    assert ke(vb, vf) > 1e6 * ke(v_b, v_f)  # above the true limit it blows up: measured 3e102


def test_penalty_impulses_conserve_momentum_and_slip_acts_along_the_normal_only():
    ops, m_b, m_f = _line()
    n = ops.normal[0]
    t = np.array([-n[1], n[0]])
    rng = np.random.default_rng(2)
    v_b, v_f = rng.normal(size=(ops.bnodes.size, 2)), rng.normal(size=(ops.Bf.shape[1], 2))
    for condition in ("tied", "slip"):
        pen = V.make({"method": "penalty", "stiffness": 1e5, "condition": condition})
        state = pen.new_state()
        _run(pen, ops, m_b, m_f, v_b, v_f, 1e-4, 3, state)
        r = pen.step(ops, v_b, m_b, v_f, m_f, 1e-4, state)
        size = np.abs(r.impulse_b).sum()
        assert size > 0.0
        assert np.abs(r.impulse_b.sum(0) + r.impulse_f.sum(0)).max() < 1e-14 * size  # measured 5e-17, 2e-17
        assert state.gap.shape == (ops.n_zones, 2 if condition == "tied" else 1)
        if condition == "slip":
            assert np.abs(r.impulse_b @ t).max() < 1e-15 * size and np.abs(r.impulse_f @ t).max() < 1e-15 * size


def test_nitsche_is_the_penalty_with_stiffness_gamma_modulus_over_h():
    ops, m_b, m_f = _line()
    K, gamma = 2.2e9, 3.0
    nit = V.make({"method": "nitsche", "gamma": gamma})
    pen = V.make({"method": "penalty", "stiffness": gamma * K / ops.width})
    rng = np.random.default_rng(4)
    v_b, v_f = rng.normal(size=(ops.bnodes.size, 2)), rng.normal(size=(ops.Bf.shape[1], 2))
    dt = 0.5 * nit.stable_dt(ops, m_b, m_f, modulus=K)
    assert nit.stable_dt(ops, m_b, m_f, modulus=K) == pen.stable_dt(ops, m_b, m_f)
    a = _run(nit, ops, m_b, m_f, v_b, v_f, dt, 5, modulus=K)
    b = _run(pen, ops, m_b, m_f, v_b, v_f, dt, 5)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[2].gap, b[2].gap)
    with pytest.raises(ValueError, match="nitsche coupling needs the modulus K > 0"):
        nit.step(ops, v_b, m_b, v_f, m_f, dt, nit.new_state())


def test_multiplier_variant_is_the_solve_with_no_step_limit_and_a_warm_start():
    ops, m_b, m_f = _line()
    mult = V.make({"method": "multiplier", "condition": "slip", "alpha": 100.0, "beta": 0.5})
    assert mult.stable_dt(ops, m_b, m_f) == math.inf
    rng = np.random.default_rng(5)
    v_b, v_f = rng.normal(size=(ops.bnodes.size, 2)), rng.normal(size=(ops.Bf.shape[1], 2))
    state = mult.new_state()
    r = mult.step(ops, v_b, m_b, v_f, m_f, 1e-3, state)
    sol = S.solve(ops, m_b, m_f, v_b, v_f, 1e-3, "slip", 100.0, 0.5)
    # (the variant applies H without assembling it, coupling.matrix_free: equal to round-off)
    def close(a, b):
        return np.abs(a - b).max() <= 1e-13 * np.abs(b).max()
    assert close(r.impulse_b, sol.impulse_b) and close(r.impulse_f, sol.impulse_f)
    assert r.diagnostics["iterations"] == sol.iterations
    assert abs(r.diagnostics["interface_dissipation"] - sol.dissipation) <= 1e-13 * sol.dissipation
    assert close(state.lam[:, 0], sol.lam) and np.array_equal(state.zones, ops.zones)
    r2 = mult.step(ops, v_b * 1.001, m_b, v_f * 1.001, m_f, 1e-3, state)
    assert r2.diagnostics["iterations"] < r.diagnostics["iterations"]  # measured 14 -> 11


def test_state_survives_a_checkpoint_bitwise(tmp_path):
    ops, m_b, m_f = _line()
    rng = np.random.default_rng(6)
    v_b, v_f = rng.normal(size=(ops.bnodes.size, 2)), rng.normal(size=(ops.Bf.shape[1], 2))
    for cfg in ({"method": "penalty", "stiffness": 1e5}, {"method": "multiplier"}):
        method = V.make(cfg)
        vb, vf, state = _run(method, ops, m_b, m_f, v_b, v_f, 1e-4, 4)
        np.savez(tmp_path / "coupling.npz", **state.state_arrays())
        restored = method.new_state()
        with np.load(tmp_path / "coupling.npz") as data:
            restored.load_state({k: data[k] for k in data.files})
        a = _run(method, ops, m_b, m_f, vb, vf, 1e-4, 3, state)
        b = _run(method, ops, m_b, m_f, vb, vf, 1e-4, 3, restored)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        assert all(np.array_equal(a[2].state_arrays()[k], b[2].state_arrays()[k]) for k in ("zones", "lam", "gap"))
    with pytest.raises(ValueError, match="one row per zone"):
        V.CouplingState().load_state({"zones": np.arange(3), "lam": np.zeros((2, 2)), "gap": np.zeros((3, 2))})


def test_gaps_follow_zone_ids_as_zones_come_and_go():
    state = V.CouplingState()
    state.load_state({"zones": np.array([3, 5, 7]), "lam": np.zeros((3, 1)), "gap": np.array([[1.0], [2.0], [3.0]])})
    assert state.on(np.array([5, 7, 9]), state.gap).ravel().tolist() == [2.0, 3.0, 0.0]
    assert state.on(np.array([1, 2]), state.gap).ravel().tolist() == [0.0, 0.0]
