"""Lagrange step of the ALE solver: geometry, stable step, compatible energy, point blast, errors.

References: exact volumes of hexahedra (the FE solver's b-vector volume, and boxes), the
Courant limit of a gas at rest dt = l / c with l the smallest zone width, exact conservation
identities of the compatible discretisation (round-off), and the Sedov-Taylor similarity
solution (Kamm & Timmes 2007; solvers.ale.exact.SedovSolution): R(t) = (E t^2 / (alpha rho))^(1/(2+j))
with alpha(gamma = 1.4) = 0.984 (cylindrical, j = 2) and 0.851 (spherical, j = 3).
"""
import itertools

import numpy as np
import pytest

from tests.solvers.ale.ale_helpers import advance, periodic, run, sedov_config, uniform_config
from solvers.ale import hydro
from solvers.ale.solver import AleSolver, SolverError
from solvers.elements import hex_bvectors, quad_bvectors

HEX = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64)


def test_hex_volume_matches_fe_bvector_volume():
    rng = np.random.default_rng(3)
    b = np.empty((8, 3))
    for _ in range(50):
        xe = HEX * rng.uniform(0.5, 2.0, 3) + rng.uniform(-0.2, 0.2, (8, 3)) + rng.uniform(-5, 5, 3)
        vol, _ = hex_bvectors(xe, b)
        assert hydro.hex_volume_sym(xe, b) == pytest.approx(vol, rel=1e-13)


def test_hex_volume_is_bitwise_axis_symmetric_for_boxes():
    """A box gives the same volume bits whichever axis carries which width."""
    b = np.empty((8, 3))
    widths = (0.1, 0.0025, 0.37)
    vols = set()
    for perm in itertools.permutations(range(3)):
        w = np.array(widths)[list(perm)]
        xe = HEX * w + np.array([0.3, 0.3, 0.3])
        hex_bvectors(xe, b)
        vols.add(hydro.hex_volume_sym(xe, b))
    assert len(vols) == 1
    assert vols.pop() == pytest.approx(0.1 * 0.0025 * 0.37, rel=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_stable_step_of_gas_at_rest(dim):
    """dt = l / c with l the smallest zone width (no q at rest), c = sqrt(gamma p / rho)."""
    cfg = uniform_config(dim, 4, [0.0] * dim, {}, mode="lagrangian", density=1.3, pressure=0.7)
    cfg["grid"]["upper"] = [1.0, 0.5, 2.0][:dim]
    s = AleSolver(None, cfg)
    c = np.sqrt(1.4 * 0.7 / 1.3)
    assert s.stable_dt() == pytest.approx(0.5 / 4 / c, rel=1e-14)
    cfg["mode"] = "eulerian"  # at rest the advection term vanishes
    assert AleSolver(None, cfg).stable_dt() == pytest.approx(0.5 / 4 / c, rel=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_compatible_energy_and_momentum_periodic_shear(dim):
    """Lagrangian mode, periodic box, colliding/shearing regions (q and hourglass active): total
    energy and momentum are conserved to round-off (1e-12 relative)."""
    cfg = {"dimension": dim, "mode": "lagrangian",
           "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [10] * dim},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
           "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0, "velocity": [0.3, 0.1, -0.2][:dim]},
                       {"material": "gas", "region": "x < 0.35", "density": 2.0, "pressure": 1.5,
                        "velocity": [1.0, 0.5, 0.0][:dim]},
                       {"material": "gas", "region": "y > 0.6", "density": 0.5, "pressure": 0.4,
                        "velocity": [-0.7, 0.2, 0.4][:dim]}],
           "boundaries": periodic(dim)}
    s = AleSolver(None, cfg)
    ke0 = s.diagnostics()["kinetic_energy"]
    advance(s, 0.3)
    d = s.diagnostics()
    assert s.q.max() > 0.05  # the viscosity did work
    assert abs(d["energy_balance_rel"]) < 1e-12
    assert abs(d["momentum_balance_rel"]) < 1e-12
    assert d["mass_balance_rel"] == 0.0
    assert d["kinetic_energy"] < 0.995 * ke0  # not a trivial translation: kinetic energy was dissipated


SEDOV = {2: ("cylindrical", 40, 0.49), 3: ("spherical", 20, 0.41)}


@pytest.mark.parametrize("dim", [2, 3])
def test_sedov_point_blast_lagrangian(dim):
    """Quadrant/octant with walls, E_full deposited (its 1/4 or 1/8 share) in the corner zone:
    total energy to 1e-12 (measured 3.5e-14 / 6.1e-14), symmetry about the diagonal (x <-> y) to
    1e-12, the density peak at the Sedov shock radius within 0.8 zone widths (measured 0.32 / 0.26;
    the peak is a zone centroid, so it moves by whole zones), its height within 25 % / 30 % of the
    strong-shock 6 (5.46 / 4.76: smeared over 2-3 zones) and the L1 density error against the exact
    profile (at the zone centroids, relative to the mass) below 0.16 (0.134 / 0.131)."""
    from solvers.ale.exact import SedovSolution

    geometry, n, t = SEDOV[dim]
    e_full = SedovSolution(1.0, 1.0, 1.4, geometry).alpha  # then R(t) = t^(2/(2+j))
    sol = SedovSolution(e_full, 1.0, 1.4, geometry)
    s = run(sedov_config(dim, n, e_full / 2 ** dim), t)
    d = s.diagnostics()
    assert abs(d["energy_balance_rel"]) < 1e-12
    # the deposited share plus the cold gas, p V / (gamma - 1) = 1e-6 / 0.4
    assert d["total_energy"] == pytest.approx(e_full / 2 ** dim + 2.5e-6, rel=1e-12)
    rho = s.zone_field(s.rho).reshape([n] * dim)  # (z,) y, x
    x = s.node_field(s.x).reshape([n + 1] * dim + [dim])
    swap = (1, 0) if dim == 2 else (0, 2, 1)
    assert np.max(np.abs(rho - rho.transpose(swap))) < 1e-12 * rho.max()
    assert np.max(np.abs(x[..., 0] - x[..., 1].transpose(swap))) < 1e-12
    # zone centroids (moved grid) and the radius of the density maximum
    cen = np.mean([x[tuple(slice(o, o + n) for o in off[::-1])] for off in itertools.product((0, 1), repeat=dim)],
                  axis=0)
    r = np.sqrt(np.sum(cen ** 2, axis=-1))
    r_peak = r.ravel()[np.argmax(rho)]
    R = sol.shock_radius(t)
    assert R == pytest.approx(t ** (2.0 / (2 + dim)), rel=1e-9)
    assert abs(r_peak - R) < 0.8 / n
    assert rho.max() > (0.75 if dim == 2 else 0.7) * 6.0  # a real shock (strong-shock compression 6)
    V = s.zone_field(s.V).reshape([n] * dim)
    rho_ex = sol.profiles(r, t)[0]
    assert np.sum(np.abs(rho - rho_ex) * V) / np.sum(rho_ex * V) < 0.16


def test_invalid_initial_state_names_zone_step_time():
    cfg = uniform_config(2, 4, [0.0, 0.0], {}, mode="lagrangian")
    cfg["regions"].append({"material": "gas", "region": "x > 0.75 and y > 0.5", "density": 1.0, "pressure": -2.0})
    with pytest.raises(SolverError) as err:
        AleSolver(None, cfg)
    msg = str(err.value)
    assert "zone (3, 2)" in msg or "zone (3, 3)" in msg
    assert "step 0" in msg and "t=0 s" in msg
    assert "invalid thermodynamic state" in msg and "p=-2" in msg


def test_tangled_zone_during_a_step_is_reported():
    """An over-large step (50x the stable one) in a blast inverts or invalidates a zone; the error
    names the zone, the step and time given by the coupler."""
    s = AleSolver(None, sedov_config(2, 8, 1.0))
    dt = 50.0 * s.stable_dt()
    with pytest.raises(SolverError) as err:
        for k in range(1, 4):
            s.predict(dt)
            s.correct(None, step=41 + k, time=0.5 + k * dt)
    msg = str(err.value)
    assert "ALE zone (" in msg and "step 42," in msg and f"t={0.5 + dt:.6g} s" in msg


def test_hourglass_damps_only_hourglass_modes():
    """Corner forces of a linear velocity field carry no hourglass part; an hourglass velocity mode
    gets a force opposing it."""
    cfg = uniform_config(3, 3, [0.0] * 3, periodic(3), mode="lagrangian", density=1.0, pressure=1.0)
    cfg["hourglass"] = 0.1
    s = AleSolver(None, cfg)
    B = s.block
    z = int(np.flatnonzero(B.real_zone)[13])
    n0 = int(B._zone_to_node(np.array([z]))[0])
    nodes = n0 + B.corner_offsets()
    xs = s.x[nodes].copy()
    # linear field v = A x: forces are exactly p b (+ q b)
    A = np.array([[0.1, 0.2, -0.1], [0.0, -0.3, 0.2], [0.1, 0.1, 0.1]])
    s.v[:] = s.x @ A.T
    s._pass(s.zr, hydro.FORCES)
    b = np.empty((8, 3))
    hex_bvectors(xs, b)
    assert np.allclose(s.fc[z], (s.p[z] + s.q[z]) * b, rtol=0, atol=1e-14)
    # hourglass mode xi*eta*zeta in the x velocity: the hourglass force opposes it
    s.v[:] = 0.0
    gamma = np.array([-1, 1, -1, 1, 1, -1, 1, -1.0])
    s.v[nodes, 0] = 0.01 * gamma
    s._pass(s.zr, hydro.FORCES)
    f_hg = s.fc[z][:, 0] - s.p[z] * b[:, 0]
    assert np.dot(f_hg, gamma) < 0.0
    assert np.allclose(f_hg, f_hg @ gamma / 8 * gamma, atol=1e-15)


def _fe_hourglass(xe, ve, rho, c, hg):
    """The FE kernel's hourglass force on one element (solvers/lagrange/kernels.py): element_forces
    with and without the coefficient (no stress: dt = 0 and zero stress; the bulk viscosity is the
    same in both), for a linear elastic material of nu = 0 and E = rho c^2 (dilatational speed c)
    and the mass rho V, so that the element's rho and c are the zone's."""
    from solvers.lagrange.kernels import element_forces, reference_gradients
    from solvers.lagrange.materials import material_params

    dim = xe.shape[1]
    conn = np.arange(2 ** dim, dtype=np.int64)[None, :]
    vol = (hex_bvectors if dim == 3 else quad_bvectors)(xe, np.empty((2 ** dim, dim)))[0]
    code, par = material_params("linear_elastic", {"density": rho, "youngs_modulus": rho * c * c,
                                                   "poisson_ratio": 0.0})
    grad0, vol0 = reference_gradients(xe, conn)
    out = []
    for coef in (hg, 0.0):
        f = np.zeros_like(xe)
        _, bad = element_forces(xe, ve, 0.0, conn, np.zeros(1, np.int64), np.array([code], np.int64),
                                par[None, :].copy(), grad0, vol0, np.array([rho * vol]), np.zeros((1, 6)),
                                np.zeros(1), np.full(1, 293.0), np.zeros(1), np.zeros(1), coef, 0.2, 1.0, f)
        assert bad == -1
        out.append(f)
    return out[0] - out[1]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("hourglass", [None, 0.1])
def test_hourglass_force_is_the_fe_kernels_on_a_distorted_zone(dim, hourglass):
    """The ALE zone pass's Flanagan-Belytschko hourglass force equals the FE kernel's (the same
    formula, a_h = C rho c V^(2/3)/4 in 3-D, C rho c A^(1/2)/4 per unit thickness in 2-D) on a
    distorted zone with random corner velocities (hourglass modes and the rest), to round-off
    (measured <= 2.1e-15 of the largest hourglass force; asserted 1e-13). The coefficient is the
    case's, or the documented default 0.05 (README, solvers/ale/solver.py): twice it fails."""
    cfg = uniform_config(dim, 3, [0.0] * dim, periodic(dim), mode="lagrangian", density=1.3, pressure=0.7)
    if hourglass is not None:
        cfg["hourglass"] = hourglass
    cfg["viscosity"] = {"linear": 0.0, "quadratic": 0.0}  # (no q: the hourglass part is not lost in it)
    coef = 0.05 if hourglass is None else hourglass
    s = AleSolver(None, cfg)
    B = s.block
    z = int(np.flatnonzero(B.real_zone)[13 if dim == 3 else 4])  # the middle zone: all its nodes real
    nodes = int(B._zone_to_node(np.array([z]))[0]) + B.corner_offsets()
    rng = np.random.default_rng(7 + dim)
    h = 1.0 / 3
    s.x[nodes] += rng.uniform(-0.15 * h, 0.15 * h, (len(nodes), dim))
    s.v[:] = 0.0
    s.v[nodes] = 5.0 * rng.normal(size=(len(nodes), dim))  # (c = 0.87: a strong hourglass part)
    s._pass(s.zr, hydro.FORCES)
    xe, ve = s.x[nodes].copy(), s.v[nodes].copy()
    b = np.empty_like(xe)
    (hex_bvectors if dim == 3 else quad_bvectors)(xe, b)
    f_ale = s.fc[z] - (s.p[z] + s.q[z]) * b
    f_fe = _fe_hourglass(xe, ve, s.rho[z], s.c[z], coef)
    assert np.abs(f_fe).max() > 0.1 * np.abs(s.fc[z]).max()  # not lost in the pressure force
    assert np.abs(f_ale - f_fe).max() <= 1e-13 * np.abs(f_fe).max(), (f_ale, f_fe)


# ---- smooth flow: second order in space and time -------------------------------------------------
ACOUSTIC = {"gamma": 1.4, "rho0": 1.0, "c0": 1.0, "eps": 1e-6}


def _zone_mean_sin(a, b):
    """Mean of sin(2 pi x) over [a, b]."""
    k = 2 * np.pi
    return (np.cos(k * a) - np.cos(k * b)) / (k * (b - a))


def acoustic_config(n, dim, mode="lagrangian"):
    """A right-running sound wave of amplitude eps (rho' = rho0 eps S, u = c0 eps S, p' = rho0 c0^2 eps S
    with S = sin 2 pi (x - c0 t)) in a periodic tube of length 1, n x 1 (x 1) zones, no artificial
    viscosity (a smooth flow needs none; its linear term would be first order): zone
    means of the exact solution, one region per zone (`x > i h`, the later region wins)."""
    g, rho0, c0, eps = (ACOUSTIC[k] for k in ("gamma", "rho0", "c0", "eps"))
    h = 1.0 / n
    regions = []
    for i in range(n):
        S = _zone_mean_sin(i * h, (i + 1) * h)
        r = {"material": "gas", "density": rho0 * (1 + eps * S), "pressure": rho0 * c0 ** 2 * (1 / g + eps * S),
             "velocity": [c0 * eps * S] + [0.0] * (dim - 1)}
        if i:
            r["region"] = f"x > {i * h!r}"
        regions.append(r)
    lower, upper, cells = [0.0] * dim, [h] * dim, [1] * dim
    upper[0], cells[0] = 1.0, n
    return {"dimension": dim, "mode": mode, "grid": {"lower": lower, "upper": upper, "cells": cells},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": g}}, "regions": regions,
            "boundaries": {"x_lower": "periodic", "x_upper": "periodic"},
            "viscosity": {"linear": 0.0, "quadratic": 0.0}}


def acoustic_error(n, dim, mode, t_end=1.0, courant=0.5):
    """L1 error of the zone pressures after one period (dt = courant h / c0, landing on t_end), in
    units of the wave's pressure amplitude, against the exact zone means over the moved zones."""
    rho0, c0, eps = ACOUSTIC["rho0"], ACOUSTIC["c0"], ACOUSTIC["eps"]
    s = AleSolver(None, acoustic_config(n, dim, mode))
    steps = int(round(t_end * n * c0 / courant))
    for k in range(1, steps + 1):
        s.predict(t_end / steps)
        s.correct(None, k, k * t_end / steps)
        s.remap()
    x = s.node_field(s.x)[: n + 1, 0]        # the nodes of the row y = 0 (x fastest)
    p = s.zone_field(s.p)[:n]
    exact = rho0 * c0 ** 2 * (1 / ACOUSTIC["gamma"] + eps * _zone_mean_sin(x[:-1] - c0 * t_end, x[1:] - c0 * t_end))
    return float(np.mean(np.abs(p - exact))) / (rho0 * c0 ** 2 * eps)


@pytest.mark.parametrize("mode, dim", [("lagrangian", 2), ("lagrangian", 3), ("eulerian", 2)])
def test_smooth_sound_wave_converges_at_second_order(mode, dim):
    """A sound wave carried once round a periodic tube, dt proportional to h: the pressure error
    falls at second order, which needs the EOS evaluated at the time level of the positions (the
    half-step energy extrapolation e + de_h of the Lagrange step, hydro.py: zone_pass in Lagrangian
    mode, lagrangian_volumes in Eulerian mode, where the remap moves O(eps) and the errors are the
    Lagrangian ones). Measured (2-D and 3-D, both modes alike): 4.80e-3, 1.20e-3, 3.01e-4, 7.54e-5
    at n = 32 .. 256, orders 1.997, 1.998, 2.000; with de_h doubled: 2.7e-2 .. 3.6e-3, orders 0.95,
    0.97, 0.985; without it the Lagrangian run grows unstable. Asserted: every order within 2 +- 0.1,
    the finest error below 1.5e-4 (eps = 1e-6: the nonlinear terms, O(eps), stay far below)."""
    ns = (32, 64, 128, 256)
    errs = [acoustic_error(n, dim, mode) for n in ns]
    orders = [float(np.log2(errs[i] / errs[i + 1])) for i in range(len(ns) - 1)]
    assert all(abs(o - 2.0) < 0.1 for o in orders), (errs, orders)
    assert errs[-1] < 1.5e-4, errs
