"""Several materials per zone (solvers/ale/mixed.py): two-material Riemann problems against the exact
stiffened-gas solution, interface reconstruction in the remap (advected square), void, the closure
(pressure relaxation, work shares) and restart."""
from __future__ import annotations

import numpy as np
import pytest

from solvers.ale import mixed
from solvers.ale.exact.riemann import RiemannSolution
from solvers.ale.solver import AleSolver
from tests.solvers.ale.ale_helpers import advance, line, periodic

WATER = {"eos": "stiffened_gas", "gamma": 4.4, "p_inf": 6.0e8}
AIR = {"eos": "stiffened_gas", "gamma": 1.4, "p_inf": 0.0}
WA_X0, WA_T = 0.8, 2.9e-4
WA_EXACT = RiemannSolution((1000.0, 0.0, 1.0e9), (50.0, 0.0, 1.0e5), 4.4, 1.4, 6.0e8, 0.0)


def water_air_config(n=400, axis=0, dim=2):
    lower, upper, cells = [0.0] * dim, [1.0 / n] * dim, [1] * dim
    upper[axis], cells[axis] = 1.0, n
    name = "xyz"[axis]
    return {"dimension": dim, "mode": "eulerian",
            "grid": {"lower": lower, "upper": upper, "cells": cells},
            "materials": {"water": dict(WATER), "air": dict(AIR)},
            "regions": [{"material": "water", "density": 1000.0, "pressure": 1.0e9},
                        {"material": "air", "region": f"{name} > {WA_X0}", "density": 50.0, "pressure": 1.0e5}],
            "boundaries": {}}


@pytest.fixture(scope="module")
def water_air():
    s = AleSolver(None, water_air_config())
    d0 = s.diagnostics()
    advance(s, WA_T)
    return s, d0


def _plateau(x, a, lo, hi, margin):
    sel = (x > lo + margin) & (x < hi - margin)
    return a[sel]


def test_water_air_plateaus_interface_and_pressure(water_air):
    """N = 400 against the exact solution (tolerances a few times the measured errors, in brackets):
    density plateaus within 0.1 % (water, 2.6e-4) and 1 % (air, 4.3e-3), pressure plateau median
    within 0.5 % (1.7e-3) and mean within 6 % (4.0e-2: the start-up dip, see
    cases/water_air_shock_tube), interface within 0.3 cells (0.03) and one mixed zone, pressure within
    0.3 % of p* across it (1.2e-3)."""
    s, _ = water_air
    n = 400
    dx = 1.0 / n
    x = (np.arange(n) + 0.5) * dx
    w = WA_EXACT.waves(WA_T, WA_X0)
    rho = line(s, s.rho, 0)[:, 0]
    p = line(s, s.p, 0)[:, 0]
    fw = line(s, s.mm.fractions()[:, 0], 0)[:, 0]
    tail, contact, shock = w["left_rarefaction_tail"], w["contact"], w["right_shock"]
    m = 4 * dx
    rl = _plateau(x, rho, tail, contact, m).mean()
    rr = _plateau(x, rho, contact, shock, m).mean()
    assert abs(rl / WA_EXACT.rho_star_l - 1) < 1e-3, rl
    assert abs(rr / WA_EXACT.rho_star_r - 1) < 0.01, rr
    # pressure plateau: its median (see cases/water_air_shock_tube: a start-up wave in the stiff water
    # makes a dip behind the rarefaction tail; the mean is 0.96 p* at N = 400)
    ps = np.median(_plateau(x, p, tail, shock, m))
    assert abs(ps / WA_EXACT.p_star - 1) < 5e-3, ps
    assert abs(_plateau(x, p, tail, shock, m).mean() / WA_EXACT.p_star - 1) < 0.06
    # interface: where the water fraction crosses 1/2
    k = int(np.flatnonzero((fw[:-1] - 0.5) * (fw[1:] - 0.5) < 0)[0])
    xi = x[k] + (0.5 - fw[k]) * dx / (fw[k + 1] - fw[k])
    assert abs(xi - contact) / dx < 0.3, (xi, contact)
    # sharp: one mixed zone at most
    assert np.count_nonzero((fw > 1e-6) & (fw < 1 - 1e-6)) <= 2
    # pressure across the interface (5 zones either side, inside the star region)
    near = (np.abs(x - contact) < 5 * dx) & (x < shock - 2 * dx)
    osc = np.max(np.abs(p[near] - WA_EXACT.p_star)) / WA_EXACT.p_star
    assert osc < 3e-3, osc


def test_water_air_conservation(water_air):
    s, d0 = water_air
    d = s.diagnostics()
    assert abs(d["mass_balance_rel"]) < 1e-12
    assert abs(d["energy_balance_rel"]) < 1e-12
    assert abs(d["momentum_balance_rel"]) < 1e-12
    for k in ("mass_water", "mass_air"):
        assert abs(d[k] / d0[k] - 1) < 1e-12, (k, d[k], d0[k])
    vol = d["volume_water"] + d["volume_air"]
    assert abs(vol / (d0["volume_water"] + d0["volume_air"]) - 1) < 1e-12


def test_water_air_same_along_y():
    """The tube along y gives the x tube's profile (material fluxes use the same arithmetic)."""
    sx = AleSolver(None, water_air_config(n=100))
    sy = AleSolver(None, water_air_config(n=100, axis=1))
    advance(sx, 1.0e-4)
    advance(sy, 1.0e-4)
    for a, b in ((sx.rho, sy.rho), (sx.p, sy.p), (sx.mm.fractions()[:, 0], sy.mm.fractions()[:, 0])):
        pa, pb = line(sx, a, 0)[:, 0], line(sy, b, 1)[:, 0]
        assert np.allclose(pa, pb, rtol=1e-12, atol=0.0)


def test_two_gases_reproduce_sod():
    """Sod with the two sides as two materials of the same EOS: the contact is the material
    interface; plateaus within 5e-4 (measured 1.4e-4, 9.4e-5, 1.4e-4), interface within 0.3 cells of
    the exact contact (0.03), conservation to round-off."""
    n = 200
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 1.0 / n], "cells": [n, 1]},
           "materials": {"left": {"eos": "ideal_gas", "gamma": 1.4}, "right": {"eos": "ideal_gas", "gamma": 1.4}},
           "regions": [{"material": "left", "density": 1.0, "pressure": 1.0},
                       {"material": "right", "region": "x > 0.5", "density": 0.125, "pressure": 0.1}]}
    s = AleSolver(None, cfg)
    advance(s, 0.2)
    ex = RiemannSolution((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.4)
    w = ex.waves(0.2, 0.5)
    x = (np.arange(n) + 0.5) / n
    rho = line(s, s.rho, 0)[:, 0]
    p = line(s, s.p, 0)[:, 0]
    m = 4.0 / n
    assert abs(_plateau(x, p, w["left_rarefaction_tail"], w["right_shock"], m).mean() / ex.p_star - 1) < 5e-4
    assert abs(_plateau(x, rho, w["left_rarefaction_tail"], w["contact"], m).mean() / ex.rho_star_l - 1) < 5e-4
    assert abs(_plateau(x, rho, w["contact"], w["right_shock"], m).mean() / ex.rho_star_r - 1) < 5e-4
    fl = line(s, s.mm.fractions()[:, 0], 0)[:, 0]
    k = int(np.flatnonzero((fl[:-1] - 0.5) * (fl[1:] - 0.5) < 0)[0])
    xi = x[k] + (0.5 - fl[k]) / n / (fl[k + 1] - fl[k])
    assert abs(xi - w["contact"]) * n < 0.3
    d = s.diagnostics()
    assert abs(d["energy_balance_rel"]) < 1e-12 and abs(d["mass_balance_rel"]) < 1e-12


# ---- advected square ---------------------------------------------------------------------------
SQ_LO, SQ_HI = 0.3, 0.7


def square_config(n, dim=2):
    inside = " and ".join(f"({c} > {SQ_LO}) and ({c} < {SQ_HI})" for c in "xyz"[:dim])
    vel = [1.0] * dim
    return {"dimension": dim, "mode": "eulerian",
            "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [n] * dim},
            # 10 samples per axis: the square's edges (0.3, 0.7) fall on sample boundaries at n = 16..128
            "fraction_samples": 10,
            "materials": {"heavy": {"eos": "ideal_gas", "gamma": 1.4}, "light": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "light", "density": 1.0, "pressure": 0.01, "velocity": vel},
                        {"material": "heavy", "region": inside, "density": 10.0, "pressure": 0.01, "velocity": vel}],
            "boundaries": periodic(dim)}


def exact_square_fractions(n, dim=2):
    x = np.arange(n + 1) / n
    ov = np.clip(np.minimum(x[1:], SQ_HI) - np.maximum(x[:-1], SQ_LO), 0.0, None) * n
    f = ov
    for _ in range(dim - 1):
        f = np.multiply.outer(ov, f)
    return f.ravel()  # output order (x fastest) for a symmetric shape


def square_error(n, dim=2):
    s = AleSolver(None, square_config(n, dim))
    f0 = s.zone_field(s.mm.fractions()[:, 0]).copy()
    d0 = s.diagnostics()
    advance(s, 1.0)  # one period along the diagonal
    f = s.zone_field(s.mm.fractions()[:, 0])
    d = s.diagnostics()
    fex = exact_square_fractions(n, dim)
    return s, f0, f, fex, d0, d


@pytest.fixture(scope="module")
def squares():
    return {n: square_error(n) for n in (32, 64, 128)}


def test_advected_square_volume_conserved(squares):
    """Volume of each material conserved to 1e-12 over one period; velocity and pressure stay
    uniform; the initial fractions are exact."""
    for n, (s, f0, f, fex, d0, d) in squares.items():
        assert np.max(np.abs(f0 - fex)) < 1e-12
        for k in ("volume_heavy", "volume_light", "mass_heavy", "mass_light"):
            assert abs(d[k] / d0[k] - 1) < 1e-12, (n, k, d[k] / d0[k] - 1)
        assert f.min() >= 0.0 and f.max() <= 1.0 + 1e-12
        v = s.node_field(s.v)
        assert np.max(np.abs(v - 1.0)) < 1e-10
        p = s.zone_field(s.p)
        assert np.max(np.abs(p / 0.01 - 1)) < 1e-10


def test_advected_square_error_decreases(squares):
    """Symmetric-difference area between the advected and the exact square at 3 meshes: measured
    6.5e-3, 2.27e-3, 7.5e-4 at 32, 64, 128 (ratios 0.35, 0.33: order 1.5, 1.6); asserted ratios
    below 0.45 and the coarsest below 8e-3."""
    err = {n: float(np.sum(np.abs(f - fex)) / n ** 2) for n, (s, f0, f, fex, d0, d) in squares.items()}
    print("advected square symmetric-difference area:", err)
    ns = sorted(err)
    for a, b in zip(ns, ns[1:]):
        assert err[b] < 0.45 * err[a], err
    # on the coarsest mesh the square (12.8 zones wide, area 0.16) keeps its area within 5 %
    assert err[32] < 8e-3


def test_advected_cube_3d():
    """3-D PLIC (Youngs' 27-point normals): the cube's material volume is kept to 1e-12 and its
    symmetric-difference volume falls from 16^3 to 24^3 (measured 0.0166, 0.0099; 32^3: 0.0071;
    the cube holds 0.064)."""
    err = {}
    for n in (16, 24):
        s, f0, f, fex, d0, d = square_error(n, dim=3)
        for k in ("volume_heavy", "volume_light"):
            assert abs(d[k] / d0[k] - 1) < 1e-12
        err[n] = float(np.sum(np.abs(f - fex)) / n ** 3)
    print("advected cube symmetric-difference volume:", err)
    assert err[24] < 0.7 * err[16] and err[16] < 0.3 * 0.064, err


# ---- void -------------------------------------------------------------------------------------
def test_gas_expands_into_void():
    """Gas (1, 0, 1), gamma 1.4, against void at x = 0.5: rarefaction into vacuum.  Conservation to
    round-off, no gas beyond the exact escape front, density L1 error small, the void keeps its
    volume share of the tube ahead of the gas."""
    n = 200
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 1.0 / n], "cells": [n, 1]},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}, "vacuum": {"eos": "void"}},
           "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0},
                       {"material": "vacuum", "region": "x > 0.5"}]}
    s = AleSolver(None, cfg)
    t = 0.06
    advance(s, t)
    ex = RiemannSolution((1.0, 0.0, 1.0), (0.0, 0.0, 0.0), 1.4)
    front = ex.waves(t, 0.5)["vacuum_left"]
    x = (np.arange(n) + 0.5) / n
    rho = line(s, s.rho, 0)[:, 0]
    fg = line(s, s.mm.fractions()[:, 0], 0)[:, 0]
    assert np.all(fg[x > front + 1.0 / n] == 0.0)
    assert np.all(rho[x > front + 1.0 / n] == 0.0)
    last = (np.flatnonzero(fg > 0.5)[-1] + 1) / n
    assert front - last < 0.1, (last, front)  # the thin tail of the fan lags (rho < 1e-3 there): 0.080
    l1 = float(np.mean(np.abs(rho - ex.sample(x, t, 0.5)[0])))
    assert l1 < 3e-3, l1  # measured 1.85e-3
    d = s.diagnostics()
    assert abs(d["mass_balance_rel"]) < 1e-12 and abs(d["energy_balance_rel"]) < 1e-12
    assert abs(d["volume_gas"] + d["volume_vacuum"] - 1.0 / n) < 1e-15


def test_void_at_an_outflow_face_keeps_the_balances():
    """Void reaching an outflow face: the face nodes there have no mass. The balances stay at
    round-off (the energy balance was NaN: the real-zone mass share of a massless node was 0/0)."""
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 0.05], "cells": [40, 2]},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}, "vacuum": {"eos": "void"}},
           "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0},
                       {"material": "vacuum", "region": "x > 0.8"}],
           "boundaries": {"x_upper": "outflow"}}
    s = AleSolver(None, cfg)
    advance(s, 0.02)
    d = s.diagnostics()
    assert abs(d["energy_balance_rel"]) < 1e-12 and abs(d["mass_balance_rel"]) < 1e-12, d


# ---- closure ----------------------------------------------------------------------------------
def _two_zone_solver():
    cfg = water_air_config(n=4)
    cfg["regions"][1]["region"] = "x > 0.375"  # zone 1 (0.25..0.5) half water, half air
    return AleSolver(None, cfg)


def test_relaxation_conserves_and_equilibrates():
    from solvers.ale import eos

    s = _two_zone_solver()  # (its mixed zone starts relaxed: put it back out of equilibrium)
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    V = mm.vol[z].sum()
    mm.vol[z] = 0.5 * V
    mm.mass[z] = [1000.0 * 0.5 * V, 50.0 * 0.5 * V]
    mm.ener[z] = [eos.energy_from_pressure(int(mm.code[k]), mm.par[k], r, p)
                  for k, (r, p) in enumerate(((1000.0, 1.0e9), (50.0, 1.0e5)))]
    v0, e0 = mm.vol[z].sum(), float(np.sum(mm.mass[z] * mm.ener[z]))

    def pressures():
        return [eos.state(int(mm.code[k]), mm.par[k], mm.mass[z, k] / mm.vol[z, k], mm.ener[z, k] + mm.deh[z, k])[0]
                for k in range(2)]

    p_before = pressures()
    assert p_before[0] / p_before[1] > 1e3
    for _ in range(6):
        mm.relax_pressures(s)
    p_after = pressures()
    # 12 passes: 1513, 29, 2.5e-5 off after 2, 4, 6 passes, then 3e-13 (quadratic convergence)
    assert abs(p_after[0] / p_after[1] - 1) < 1e-10, p_after
    assert abs(mm.vol[z].sum() / v0 - 1) < 1e-14
    assert abs(float(np.sum(mm.mass[z] * mm.ener[z])) / e0 - 1) < 1e-14


def _out_of_equilibrium(s, z, fractions, states):
    """Put zone z's materials at the given volume fractions and (rho, p) states."""
    from solvers.ale import eos

    mm = s.mm
    V = mm.vol[z].sum()
    for k, (f, (r, p)) in enumerate(zip(fractions, states)):
        mm.vol[z, k] = f * V
        mm.mass[z, k] = r * f * V
        mm.ener[z, k] = eos.energy_from_pressure(int(mm.code[k]), mm.par[k], r, p) if r > 0 else 0.0
        mm.deh[z, k] = 0.0
    s.M[z] = mm.mass[z].sum()


def test_a_hot_sliver_of_gas_does_not_set_the_zones_sound_speed():
    """Issue 40's stalled scene: air squeezed to 0.1 % of a water zone at 1e9 J/kg (c = 2.4e4 m/s)
    gave the zone that sound speed, and the whole job a step 100 times smaller. The zone's sound speed
    is the mass-weighted rms (the equal-strain stiffness): the water's, to 1e-4."""
    from solvers.ale import eos

    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    rho_air = 0.01
    p_air = 0.4 * rho_air * 1.0e9
    _out_of_equilibrium(s, z, (0.999, 0.001), ((1000.0, p_air), (rho_air, p_air)))
    mm.update_eos(s)
    c_water = eos.state(int(mm.code[0]), mm.par[0], 1000.0, mm.ener[z, 0])[1]
    c_air = eos.state(int(mm.code[1]), mm.par[1], rho_air, mm.ener[z, 1])[1]
    assert c_air > 10 * c_water
    assert s.c[z] == pytest.approx(c_water, rel=1e-4)


def test_mixed_zone_pressure_is_the_compressibility_weighted_mean():
    """The zone pressure that drives the nodes is the materials' linearised equilibrium pressure
    sum(a_k p_k) / sum(a_k), a_k = vol_k / (rho_k c_k^2) (mixed.zone_eos), computed here from the
    EOS of each material: water at 3e8 Pa and air at 2e5 Pa (30 / 70 % of the zone) give 2.09e5 Pa
    (a volume-weighted mean would be 9e7). Its work p dV on a compression equals the materials'
    sum p_k dV_k under the volume split of mixed.lagrange_split (the closure's energy consistency)."""
    from solvers.ale import eos

    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    _out_of_equilibrium(s, z, (0.3, 0.7), ((1000.0, 3.0e8), (2.0, 2.0e5)))
    mm.update_eos(s)
    vol = mm.vol[z]
    st = [eos.state(int(mm.code[k]), mm.par[k], mm.mass[z, k] / vol[k], mm.ener[z, k]) for k in range(2)]
    pk = np.array([a[0] for a in st])
    a = vol / (mm.mass[z] / vol * np.array([a[1] for a in st]) ** 2)
    assert np.allclose(mm.pm[z], pk, rtol=1e-14, atol=0.0)
    assert s.p[z] == pytest.approx(np.sum(a * pk) / np.sum(a), rel=1e-13)
    assert s.p[z] == pytest.approx(2.09e5, rel=0.01)
    # its sound speed: the mass-weighted rms of the materials' (the equal-strain stiffness), not the
    # largest (a hot sliver of gas set a whole scene's step by it); here water dominates the mass
    ck = np.array([a[1] for a in st])
    assert s.c[z] == pytest.approx(np.sqrt(np.sum(mm.mass[z] * ck**2) / np.sum(mm.mass[z])), rel=1e-14)
    assert s.c[z] < ck.max()
    # the work of a compression: zone p dV = sum_k p_k dV_k (energy shared consistently)
    s.q[:] = 0.0
    dV = -1e-2 * vol.sum()
    s.V[z] = vol.sum() + dV
    v0 = vol.copy()
    lo = np.zeros(3, np.int64)
    lo[: s.dim] = np.array(s.block.zone_ijk(z)) + 2
    mixed.lagrange_split(mm.vol, mm.mass, mm.ener, mm.deh, mm.pm, mm.cm, mm.code, s.M, s.e, s.V, s.q, lo, lo + 1,
                         s.block.zs)
    dVk = mm.vol[z] - v0
    # (dV_k are differences of volumes, the water's 3e-7 of its own: measured 1.8e-12)
    assert np.sum(mm.pm[z] * dVk) == pytest.approx(s.p[z] * dV, rel=1e-10)


def test_mixed_zone_pressure_with_void():
    """Gas and void sharing a zone: the zone pressure is the gas pressure times the share of the
    zone that is not void (zone_eos: p = (1 - f_void) p_eq)."""
    from solvers.ale import eos

    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 0.25], "cells": [4, 1]},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}, "vacuum": {"eos": "void"}},
           "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0},
                       {"material": "vacuum", "region": "x > 0.3125"}]}  # zone 1 (0.25 .. 0.5): 1/4 gas
    s = AleSolver(None, cfg)
    z = int(np.flatnonzero(s.block.real_zone)[1])
    mm = s.mm
    _out_of_equilibrium(s, z, (0.25, 0.75), ((0.8, 0.6), (0.0, 0.0)))
    mm.update_eos(s)
    p_gas = eos.state(int(mm.code[0]), mm.par[0], 0.8, mm.ener[z, 0])[0]
    assert p_gas == pytest.approx(0.6, rel=1e-14)
    assert s.p[z] == pytest.approx(0.25 * p_gas, rel=1e-14)
    assert s.rho[z] == pytest.approx(0.8 * 0.25, rel=1e-14)


def test_lagrange_split_shares_exactly():
    """A mixed zone's volume change goes to its materials in proportion to their compressibility
    vol/(rho c^2) (equal pressure changes); the materials' energy changes add up to the zone's,
    shared by their p dV work."""
    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    s.q[:] = 0.0
    E0 = mm.mass[z] * mm.ener[z]
    V0 = mm.vol[z].copy()
    K = mm.mass[z] / V0 * mm.cm[z] ** 2
    assert np.all(K > 0)
    dE = -1.0e3
    s.e[z] = (E0.sum() + dE) / s.M[z]
    dV = 1e-3 * V0.sum()
    s.V[z] = V0.sum() + dV
    lo = np.zeros(3, np.int64)
    lo[: s.dim] = np.array(s.block.zone_ijk(z)) + 2
    hi = lo + 1
    mixed.lagrange_split(mm.vol, mm.mass, mm.ener, mm.deh, mm.pm, mm.cm, mm.code, s.M, s.e, s.V, s.q, lo, hi,
                         s.block.zs)
    dVk = mm.vol[z] - V0
    assert abs(dVk.sum() / dV - 1) < 1e-12
    # (dVk is a small difference of volumes: ~1e-12 relative of V0 is lost, 1e-9 of the water's share)
    assert np.allclose(dVk / dV, (V0 / K) / np.sum(V0 / K), rtol=1e-7)
    # equal pressure changes: dp_k = -K_k dV_k / V_k
    dp = K * dVk / V0
    assert abs(dp[0] / dp[1] - 1) < 1e-7
    dEk = mm.mass[z] * mm.ener[z] - E0
    assert abs(dEk.sum() / dE - 1) < 1e-9
    share = mm.pm[z] * dVk / np.sum(mm.pm[z] * dVk)
    assert np.allclose(dEk / dE, share, rtol=1e-7)


def _split_zone(s, z, dV, dE, q):
    """mixed.lagrange_split on zone z of s: its volume changed by dV, its energy by dE, q given."""
    mm = s.mm
    s.q[:] = 0.0
    s.q[z] = q
    s.e[z] = ((mm.mass[z] * mm.ener[z]).sum() + dE) / s.M[z]
    s.V[z] = mm.vol[z].sum() + dV
    lo = np.zeros(3, np.int64)
    lo[: s.dim] = np.array(s.block.zone_ijk(z)) + 2
    mixed.lagrange_split(mm.vol, mm.mass, mm.ener, mm.deh, mm.pm, mm.cm, mm.code, s.M, s.e, s.V, s.q, lo, lo + 1,
                         s.block.zs)


def test_a_zone_whose_volume_triples_shares_its_energy_by_mass_without_a_shift():
    """A coupled body's small cut zone may change its open volume by O(1) of itself within a step (a
    steel block's edge sliding along a zone row): there the linear p dV split and the half-step shift
    -p dV_k / (2 m_k) mean nothing, and at a tripling they took more than an air trace's energy.
    Such a zone (|dV| > V / 2) gets the single-material zone's treatment: no shift, each material's
    energy change in proportion to its mass (the same specific change), the sum still exact.  (The
    work split gives the air 0.92 of its energy here and a shift of -0.46 of it.)"""
    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    _out_of_equilibrium(s, z, (0.99, 0.01), ((1000.0, 3.0e5), (1.2, 3.0e5)))
    mm.update_eos(s)
    E0 = mm.mass[z] * mm.ener[z]
    dE = -1.0e-3 * E0.sum()
    _split_zone(s, z, 2.0 * mm.vol[z].sum(), dE, q=0.0)
    dEk = mm.mass[z] * mm.ener[z] - E0
    assert np.all(mm.deh[z] == 0.0)
    assert abs(dEk.sum() / dE - 1) < 1e-9
    assert np.allclose(dEk / dE, mm.mass[z] / mm.mass[z].sum(), rtol=1e-9)
    # (half a volume's change or less: the work split and its shift, as before)
    s2 = _two_zone_solver()
    _out_of_equilibrium(s2, z, (0.99, 0.01), ((1000.0, 3.0e5), (1.2, 3.0e5)))
    s2.mm.update_eos(s2)
    _split_zone(s2, z, 0.4 * s2.mm.vol[z].sum(), dE, q=0.0)
    assert np.all(s2.mm.deh[z] < 0.0)


def test_a_material_thinner_than_its_zone_takes_no_work_and_no_state():
    """An air trace that filled a cavity in water expanded to 3e-16 of its zone's density at 0.9 %
    of its volume; it took that volume's share of the zone's q work on no mass (e = 4e21 J/kg, then
    an invalid state).  A material below RHO_THIN of its zone's mean density is thin: its energy
    changes by its mass share only, it gets no half-step shift, no EOS call (the pressure of the rest)
    and no say in the sound speed, while the zone's energy change is still shared exactly."""
    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    _out_of_equilibrium(s, z, (0.99, 0.01), ((1000.0, 1.0e5), (1.2, 1.0e5)))
    mm.mass[z, 1] *= 1e-12          # the air at 1.2e-12 kg/m^3: 1.2e-15 of the zone's mean density
    mm.ener[z, 1] = -5.0e6          # and a state no EOS takes (ideal gas, e < 0)
    s.M[z] = mm.mass[z].sum()
    mm.update_eos(s)                # (no error: not asked its state)
    assert mm.cm[z, 1] == 0.0 and mm.pm[z, 1] == s.p[z]
    E0 = mm.mass[z] * mm.ener[z]
    dE = 0.01 * E0[0]
    _split_zone(s, z, -1e-3 * mm.vol[z].sum(), dE, q=1.0e7)
    dEk = mm.mass[z] * mm.ener[z] - E0
    assert abs(dEk.sum() / dE - 1) < 1e-9
    assert dEk[1] / dE == pytest.approx(mm.mass[z, 1] / s.M[z], rel=1e-9)   # ~1e-15: its mass share
    assert mm.deh[z, 1] == 0.0 and mm.deh[z, 0] != 0.0


def test_the_remap_dilutes_the_half_step_shift_of_a_material_that_gains_mass():
    """The Lagrange split's half-step EOS shift deh_k is the work of what was in the zone, per unit
    of its mass; a material the remap more than doubles in a zone keeps that work, spread over the
    new mass (deh m0 / m); one that loses mass, or gains less, keeps its shift per unit mass.  (Kept per unit mass, an air
    trace's shift of -5.8e6 J/kg met air brought in at 4.9e6 J/kg behind a steel block in water:
    an invalid state.)"""
    s = _two_zone_solver()
    mm = s.mm
    z = int(np.flatnonzero(s.block.real_zone)[1])
    mm.deh[z] = [-3.0e3, -5.0e6]
    m0 = mm.mass[z].copy()
    mm.hold_shift()
    mm.mass[z, 0] *= 1.5       # more water comes in
    mm.mass[z, 1] *= 1.0e3     # air comes in
    mm.spread_shift()
    assert mm.deh[z, 0] == -3.0e3
    assert mm.deh[z, 1] == pytest.approx(-5.0e6 * m0[1] / mm.mass[z, 1], rel=1e-15)


def test_checkpoint_restart_bitwise(tmp_path):
    cfg = water_air_config(n=50)
    a = AleSolver(None, cfg)
    t, k = advance(a, 5.0e-5)
    a.checkpoint(tmp_path / "c.h5")
    advance(a, 1.0e-4, t0=t, step0=k)
    b = AleSolver(None, cfg)
    b.restart(tmp_path / "c.h5")
    advance(b, 1.0e-4, t0=t, step0=k)
    for f in ("vol", "mass", "ener", "deh"):
        assert np.array_equal(getattr(a.mm, f), getattr(b.mm, f)), f
    assert np.array_equal(a.v, b.v) and np.array_equal(a.p, b.p)


def test_output_has_material_fields():
    s = AleSolver(None, water_air_config(n=20))
    _, _, _, cd = s.output()
    for k in ("volume_fraction_water", "volume_fraction_air", "density_water", "density_air"):
        assert k in cd and cd[k].shape == (20,)
    assert np.allclose(cd["volume_fraction_water"] + cd["volume_fraction_air"], 1.0, rtol=0, atol=1e-14)


@pytest.mark.parametrize("change, match", [
    ({"mode": "lagrangian"}, "mode = 'eulerian'"),
])
def test_unsupported_combinations(change, match):
    cfg = water_air_config(n=20)
    cfg.update(change)
    with pytest.raises(ValueError, match=match):
        AleSolver(None, cfg)


@pytest.mark.parametrize("dim, n", [(2, 24), (3, 10)])
def test_gas_ball_expands_into_void(dim, n):
    """A gas disc / ball at rest in void (mixed zones on its rim): it expands without invalid states,
    the balances hold to round-off, the gas volume grows and no gas is found beyond the exact escape
    radius r0 + 2 c0 t / (gamma - 1) (plus one zone diagonal)."""
    ball = " + ".join(f"({c} - 0.5)**2" for c in "xyz"[:dim]) + " < 0.04"
    cfg = {"dimension": dim, "mode": "eulerian",
           "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [n] * dim},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}, "vacuum": {"eos": "void"}},
           "regions": [{"material": "vacuum"}, {"material": "gas", "region": ball, "density": 1.0, "pressure": 1.0}]}
    s = AleSolver(None, cfg)
    d0 = s.diagnostics()
    t = 0.02
    advance(s, t)
    d = s.diagnostics()
    for k in ("energy_balance_rel", "mass_balance_rel", "momentum_balance_rel"):
        assert abs(d[k]) < 1e-12, (k, d[k])
    assert d["volume_gas"] > 1.05 * d0["volume_gas"]
    centres = s.block.zone_centres()[s.block.real_zone][:, :dim]
    f = s.mm.fractions()[s.block.real_zone][:, 0]
    r = np.linalg.norm(centres - 0.5, axis=1)
    r_front = 0.2 + 2.0 * np.sqrt(1.4) * t / 0.4
    assert np.all(f[r > r_front + np.sqrt(dim) / n] == 0.0)


def test_equilibrium_volumes_give_one_pressure_and_fill_the_volume():
    """mixed.equilibrium_volumes (the small-zone merge's composition): water (stiffened gas), air
    (ideal gas) and a Tait liquid with given masses and energies share a volume at one pressure:
    every material's pressure equal to 2e-13 relative (measured 3.7e-14 at p = 6.3e8 Pa), the volumes
    sum to V to round-off; the air's density is the exact p / ((gamma - 1) e).  An energy no density
    brings to the pressure: NaN.  Void in the group: not solved (False)."""
    from solvers.ale import eos
    from solvers.ale.mixed import VOID, density_at_pressure, equilibrium_volumes

    codes, pars = [], []
    for name, props in (("stiffened_gas", {"gamma": 4.4, "p_inf": 6e8}), ("ideal_gas", {"gamma": 1.4}),
                        ("tait", {"rho0": 1000.0, "bulk_modulus": 2.19e9, "exponent": 7.15, "p0": 1e5})):
        c, p = eos.eos_params(name, props)
        codes.append(c)
        pars.append(p)
    code, par = np.array(codes, np.int64), np.array(pars)
    mass = np.array([2.0, 0.012, 1.0])
    ener = np.array([7.9e5, 2.5e5, 0.0])
    vraw = np.array([1e-3, 3e-3, 2e-3])  # carried volumes far from any equilibrium
    V = 2.5e-3
    out = np.zeros(3)
    assert equilibrium_volumes(code, par, mass, ener, vraw, V, 0.0, out)
    p = [eos.pressure(code[k], par[k], mass[k] / out[k], ener[k]) for k in range(3)]
    assert max(abs(pk / p[1] - 1.0) for pk in p) < 2e-13, p
    assert abs(out.sum() / V - 1.0) < 1e-15
    assert mass[1] / out[1] == pytest.approx(p[1] / (0.4 * ener[1]), rel=1e-14)
    assert density_at_pressure(code[1], par[1], 1e5, -1.0, 1.0) != density_at_pressure(code[1], par[1], 1e5, -1.0, 1.0)
    code_v = code.copy()
    code_v[2] = VOID
    assert not equilibrium_volumes(code_v, par, np.array([2.0, 0.012, 0.0]), ener, vraw, V, 0.0, out)
    # one material with mass (the others none): it fills V exactly, at any energy, with no solve
    # (an energy no density brings to a pressure included: the group's volume is still all its own)
    for e in (ener, np.array([7.9e5, -1.0, 0.0])):
        assert equilibrium_volumes(code, par, np.array([0.0, 0.012, 0.0]), e, vraw, V, 0.0, out)
        assert out.tolist() == [0.0, V, 0.0]


@pytest.mark.parametrize("fraction", [5e-7, 2e-6])
def test_a_trace_of_metal_is_not_asked_its_state(fraction):
    """Aluminium (Mie-Grueneisen, s = 1.34: no Hugoniot beyond rho0 / (1 - 1/s) = 10.6e3 kg/m^3) as
    a sliver in a void zone, squeezed to 15.1e3 kg/m^3 -- the state a 3-D penetrator's crater left
    in a zone holding 1.5e-8 of it, which stopped the run at 0.48 us while TRACE was 1e-9.  Below
    TRACE = 1e-6 of the zone it is a trace: no EOS call, it carries the pressure of the rest (void:
    none).  At 2e-6 the same state is asked for and refused, naming the zone and the material."""
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 0.25], "cells": [4, 1]},
           "materials": {"aluminium": {"eos": "mie_gruneisen", "rho0": 2700.0, "c0": 5350.0, "s": 1.34,
                                       "gamma0": 2.0},
                         "vacuum": {"eos": "void"}},
           "regions": [{"material": "aluminium", "density": 2700.0, "pressure": 0.0},
                       {"material": "vacuum", "region": "x > 0.3125"}]}
    s = AleSolver(None, cfg)
    z = int(np.flatnonzero(s.block.real_zone)[1])
    mm = s.mm
    V = mm.vol[z].sum()
    mm.vol[z] = [fraction * V, (1.0 - fraction) * V]
    mm.mass[z] = [15114.9 * fraction * V, 0.0]
    mm.ener[z] = [491121.0, 0.0]
    mm.deh[z] = 0.0
    s.M[z] = mm.mass[z].sum()
    if fraction < mixed.TRACE:
        mm.update_eos(s)
        assert mm.pm[z, 0] == 0.0 and s.p[z] == 0.0 and s.c[z] == 0.0
    else:
        with pytest.raises(Exception, match="invalid thermodynamic state of material 'aluminium'"):
            mm.update_eos(s)


def test_a_material_thinner_than_vacuum_becomes_void_and_leaves_the_balances():
    """mixed.RHO_CUTOFF: a zone whose aluminium, counted over the whole zone, is below 1e-12 of the
    case's lightest initial density (2700 kg/m^3 here) becomes void -- the aluminium's volume to the
    void material, its mass and energy out through the balances' boundary terms: spread over 0.9 of
    the zone at 1e-13 of it, or a sliver of 1e-22 of the zone at 221 kg/m^3 (the penetrator's: its
    nodes, 4e-31 kg, took the remap's round-off as 1.6e14 m/s) -- while a trace at 1e-11 stays.
    Left, a trace of the first kind took its volume's share of the zone's work on no mass: a
    penetrator's splash went to e = 1.5e214 J/kg at 8e-34 kg/m^3, then nan."""
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 0.25], "cells": [4, 1]},
           "materials": {"aluminium": {"eos": "mie_gruneisen", "rho0": 2700.0, "c0": 5350.0, "s": 1.34,
                                       "gamma0": 2.0, "pressure_cutoff": 0.0},
                         "vacuum": {"eos": "void"}},
           "regions": [{"material": "aluminium", "density": 2700.0, "pressure": 0.0},
                       {"material": "vacuum", "region": "x > 0.5"}]}
    s = AleSolver(None, cfg)
    assert s.rho_ref == 2700.0
    mm = s.mm
    z1, z2, z3 = (int(z) for z in np.flatnonzero(s.block.real_zone)[1:4])
    V = mm.vol[z2].sum()
    for z, share in ((z2, 1e-13), (z3, 1e-11)):
        mm.vol[z] = [0.9 * V, 0.1 * V]
        mm.mass[z] = [share * 2700.0 * 0.9 * V, 0.0]
        mm.ener[z] = [1.0e6, 0.0]
    mm.vol[z1] = [1e-22 * V, V]
    mm.mass[z1] = [221.0 * 1e-22 * V, 0.0]
    mm.ener[z1] = [2.0e5, 0.0]
    b_mass, b_energy = s.b_mass, s.b_energy
    cut = mm.mass[z2, 0] + mm.mass[z1, 0]
    cut_e = mm.mass[z1, 0] * 2.0e5 + mm.mass[z2, 0] * 1.0e6
    mm.cut_off_vacuum(s)
    assert mm.vol[z2].tolist() == [0.0, V] and mm.mass[z2, 0] == 0.0 and mm.ener[z2, 0] == 0.0
    assert mm.vol[z1].tolist() == [0.0, V + 1e-22 * V] and mm.mass[z1, 0] == 0.0
    assert s.b_mass == pytest.approx(b_mass - cut, rel=1e-15, abs=0)
    assert s.b_energy == pytest.approx(b_energy - cut_e, rel=1e-15, abs=0)
    assert mm.mass[z3, 0] == 1e-11 * 2700.0 * 0.9 * V and mm.vol[z3, 1] == 0.1 * V
    mm.update_eos(s)
    assert s.M[z2] == 0.0 and s.M[z3] > 0.0
