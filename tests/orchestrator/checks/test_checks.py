"""Every registered [check] kind (orchestrator/checks.py) fed a known result: synthetic output files
(orchestrator.output.write_mesh/write_step) holding the exact solution of the shipped case, as a
numerical solution would show it (fronts smeared over a few zones), pass the case's own check with
the tolerances of its case.toml; the same files with a known error (another gamma, a lower
amplitude, a shifted front, a dip, a non-finite value, a conservation residual) fail it, on the
metric that measures that error.  The last test runs `immerse run` on a case whose check cannot
pass: exit 1, "check FAILED".
"""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from orchestrator import checks, output
from orchestrator.checks import fields
from orchestrator.case import load_case
from tests.conftest import CASES, immerse


# ---- synthetic output ----------------------------------------------------------------------------
def structured(xn, yn, zn=None):
    """Points (nn, 3) and VTK cells (quads, or hexahedra with zn) of the tensor grid of the node
    coordinates xn, yn (, zn), x fastest (the ALE solver's output order)."""
    if zn is None:
        X, Y = np.meshgrid(xn, yn, indexing="xy")
        pts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
        nx, ny = len(xn), len(yn)
        i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="xy")
        n0 = (j * nx + i).ravel()
        return pts, np.stack([n0, n0 + 1, n0 + 1 + nx, n0 + nx], axis=1).astype(np.int64)
    Z, Y, X = np.meshgrid(zn, yn, xn, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    nx, ny, nz = len(xn), len(yn), len(zn)
    k, j, i = np.meshgrid(np.arange(nz - 1), np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    n0 = ((k * ny + j) * nx + i).ravel()
    q = np.stack([n0, n0 + 1, n0 + 1 + nx, n0 + nx], axis=1)
    return pts, np.concatenate([q, q + nx * ny], axis=1).astype(np.int64)


def write(out, role, cells, steps):
    """steps: [(time, points, point_data, cell_data)], written as output steps 0, 1, ..."""
    output.write_mesh(out, role, cells, "quad" if cells.shape[1] == 4 else "hexahedron")
    for k, (t, pts, pd, cd) in enumerate(steps):
        output.write_step(out, role, k, 10 * k, t, pts, pd, cd)
    return out


def smear(a, width):
    """A box filter over `width` zones (edge values held): jumps spread like captured fronts."""
    pad = width // 2
    ap = np.concatenate([np.full(pad, a[0]), a, np.full(pad, a[-1])])
    return np.convolve(ap, np.ones(width) / width, mode="valid")


def cell_average(sample, xn, k=64):
    """Zone averages of the profiles sample(x) -> tuple of arrays over the zones [xn[i], xn[i+1]] (k
    midpoint samples a zone): a front inside a zone shows at its sub-zone position."""
    xs = (xn[:-1, None] + (np.arange(k) + 0.5) / k * np.diff(xn)[:, None]).ravel()
    return tuple(np.asarray(a).reshape(-1, k).mean(axis=1) for a in sample(xs))


def history(role, n=5, **residuals):
    """A diagnostics history: zero balances unless given (name=value at the last record)."""
    h = {"time": np.linspace(0.0, 1.0, n), "step": np.arange(n) * 10}
    for name in ("mass", "energy", "momentum", "angular_momentum"):
        a = np.zeros(n)
        a[-1] = residuals.get(name, 0.0)
        h[f"{role}.{name}_balance_rel"] = a
    return h


def failed(result):
    return sorted(k for k, m in result["metrics"].items() if not m["passed"])


def case_with(name, **params):
    case = load_case(CASES / name)
    case["check"]["params"] = {**case["check"].get("params", {}), **params}
    return case


# ---- riemann -------------------------------------------------------------------------------------
def riemann_output(out, ex, t, x0, n, width=5, dip=None, bad_step=False, fraction=None, length=1.0):
    """A 1-D Riemann solution on n x 1 zones of [0, length] (as the shipped 1-D cases): the exact
    solution `ex` at the zone centres (nodes for the velocity) smeared over `width` zones; `dip`
    = (x_from, x_to, depth): the pressure lowered by depth p* there; `bad_step`: an earlier step
    with one negative density; `fraction`: the left material's volume fraction."""
    xn = np.linspace(0.0, length, n + 1)
    xc = 0.5 * (xn[1:] + xn[:-1])
    pts, cells = structured(xn, np.array([0.0, length / n]))
    rho, _, p, e = (smear(a, width) for a in cell_average(lambda s: ex.sample(s, t, x0), xn))
    u = np.tile(smear(ex.sample(xn, t, x0)[1], width), 2)
    if dip is not None:
        lo, hi, depth = dip
        p = np.where((xc > lo) & (xc < hi), p - depth * ex.p_star, p)
    cd = {"density": rho, "pressure": p, "specific_internal_energy": e}
    if fraction is not None:
        cd[f"volume_fraction_{fraction}"] = smear((xc < ex.waves(t, x0)["contact"]).astype(float), 3)
    vel = np.zeros((len(pts), 3))
    vel[:, 0] = u
    first = dict(cd, density=np.where(np.arange(n) == 7, -1.0, 1.0) if bad_step else np.ones(n))
    steps = [(0.0, pts, {"velocity": np.zeros_like(vel)}, first), (t, pts, {"velocity": vel}, cd)]
    return write(out, "ale", cells, steps)


def riemann_exact(case):
    from solvers.ale.exact.riemann import RiemannSolution

    P = case["check"]["params"]
    return RiemannSolution(tuple(P["left"]), tuple(P["right"]), P["gamma_left"], P.get("gamma_right", P["gamma_left"]),
                           P.get("p_inf_left", 0.0), P.get("p_inf_right", 0.0))


def test_riemann_passes_the_exact_sod_profile_and_fails_another_gamma(tmp_path):
    from solvers.ale.exact.riemann import RiemannSolution

    case = load_case(CASES / "sod")
    ex = riemann_exact(case)
    t = case["run"]["end_time"]
    good = riemann_output(tmp_path / "good", ex, t, 0.5, 400)
    r = checks.run_check(case, good, history("ale"))
    assert r["passed"], r
    # the plateaus 4 zones inside the smeared fronts are the exact star state: the margin keeps the
    # front zones out of them (without it the plateau means move by 1e-3 .. 1e-2)
    exact = {"p_star": ex.p_star, "u_star": ex.u_star, "rho_star_left": ex.rho_star_l, "rho_star_right": ex.rho_star_r}
    for name, value in exact.items():
        assert abs(r["metrics"][name]["value"] / value - 1) < 1e-12, (name, r["metrics"][name])
    assert r["metrics"]["shock_position_error_cells"]["value"] < 0.05
    # the solution of gamma = 1.42 on both sides, judged against the case's gamma 1.4
    wrong = RiemannSolution((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.42)
    r = checks.run_check(case, riemann_output(tmp_path / "wrong", wrong, t, 0.5, 400), history("ale"))
    assert not r["passed"]
    assert {"p_star", "u_star", "rho_star_left", "rho_star_right", "shock_position_error_cells",
            "l1_density"} <= set(failed(r)), failed(r)


def test_riemann_with_eos_tables_passes_the_exact_mg_profile_and_fails_another_gamma0(tmp_path):
    """cases/mg_shock_tube (Mie-Grueneisen aluminium, `eos_left`): its exact profile (the general-EOS
    solver) passes its check with the plateaus exact to round-off; the exact solution of Gamma0 =
    2.2 fails the star state."""
    from orchestrator.exact_profiles import riemann_solution
    from solvers.ale.exact.riemann_eos import EosRiemannSolution

    case = load_case(CASES / "mg_shock_tube")
    P = case["check"]["params"]
    ex = riemann_solution(P)
    assert isinstance(ex, EosRiemannSolution)
    t = case["run"]["end_time"]
    r = checks.run_check(case, riemann_output(tmp_path / "good", ex, t, 0.05, 400, length=0.1), history("ale"))
    assert r["passed"], failed(r)
    exact = {"p_star": ex.p_star, "u_star": ex.u_star, "rho_star_left": ex.rho_star_l, "rho_star_right": ex.rho_star_r}
    for name, value in exact.items():
        assert abs(r["metrics"][name]["value"] / value - 1) < 1e-12, (name, r["metrics"][name])
    assert r["reported"]["invalid_values"] == 0  # e = 0 ahead of the shock is the metal's reference state
    wrong = EosRiemannSolution(tuple(P["left"]), tuple(P["right"]), {**P["eos_left"], "gamma0": 2.2})
    r = checks.run_check(case, riemann_output(tmp_path / "wrong", wrong, t, 0.05, 400, length=0.1), history("ale"))
    assert {"p_star", "u_star", "rho_star_left", "rho_star_right"} <= set(failed(r)), failed(r)


@pytest.mark.parametrize("residual", ["mass", "energy"])
def test_riemann_fails_a_conservation_residual(tmp_path, residual):
    case = load_case(CASES / "sod")
    out = riemann_output(tmp_path, riemann_exact(case), case["run"]["end_time"], 0.5, 400)
    r = checks.run_check(case, out, history("ale", **{residual: 1e-9}))
    assert failed(r) == [f"{residual}_balance_rel"]


def test_riemann_plateau_margin_keeps_the_fronts_out(tmp_path):
    """Fronts smeared over 7 zones (3 either side, as captured shocks and contacts are): the
    plateaus 4 zones inside the exact wave positions are still exact to round-off. A plateau taken
    without the margin averages the front zones in (what removing the margin would do)."""
    case = load_case(CASES / "sod")
    ex = riemann_exact(case)
    out = riemann_output(tmp_path, ex, case["run"]["end_time"], 0.5, 400, width=7)
    r = checks.run_check(case, out, history("ale"))
    exact = {"p_star": ex.p_star, "rho_star_left": ex.rho_star_l, "rho_star_right": ex.rho_star_r}
    for name, value in exact.items():
        assert abs(r["metrics"][name]["value"] / value - 1) < 1e-12, (name, r["metrics"][name])
    # the same profile read without a margin: the front zones count (what the margin prevents)
    prof = fields.zone_stations(out, "ale", 1, 0)
    w = ex.waves(case["run"]["end_time"], 0.5)
    no_margin = fields.plateau(prof["x"], prof["rho"], w["left_rarefaction_tail"], w["contact"], 0.0)
    assert abs(no_margin / ex.rho_star_l - 1) > 2e-3


def test_riemann_bounds_the_water_air_dip(tmp_path):
    """The water-air case's median plateau hides a dip; its mean and its largest deviation do not:
    a dip 0.9 p* deep (the case measures 0.75) over 40 zones behind the rarefaction tail passes the
    median and fails p_star_max_deviation_rel and p_star_mean."""
    case = load_case(CASES / "water_air_shock_tube")
    ex = riemann_exact(case)
    t = case["run"]["end_time"]
    good = riemann_output(tmp_path / "good", ex, t, 0.8, 400, width=1, fraction="water")
    r = checks.run_check(case, good, history("ale"))
    assert r["passed"], failed(r)
    tail = ex.waves(t, 0.8)["left_rarefaction_tail"]
    dipped = riemann_output(tmp_path / "dip", ex, t, 0.8, 400, width=1, fraction="water",
                            dip=(tail + 0.01, tail + 0.11, 0.9))
    r = checks.run_check(case, dipped, history("ale"))
    assert failed(r) == ["p_star_max_deviation_rel", "p_star_mean"], failed(r)
    assert r["metrics"]["p_star"]["passed"]  # the median alone would not have seen it


def test_riemann_interface_and_positivity(tmp_path):
    """Water-air: a pressure spike at the interface fails the interface metric; toro123: a negative
    density in an earlier output step fails invalid_values."""
    case = load_case(CASES / "water_air_shock_tube")
    ex = riemann_exact(case)
    t = case["run"]["end_time"]
    contact = ex.waves(t, 0.8)["contact"]
    spike = riemann_output(tmp_path / "spike", ex, t, 0.8, 400, width=1, fraction="water",
                           dip=(contact - 0.003, contact + 0.003, -0.02))
    assert "interface_pressure_oscillation_rel" in failed(checks.run_check(case, spike, history("ale")))
    case = load_case(CASES / "toro123")
    ex = riemann_exact(case)
    t = case["run"]["end_time"]
    good = riemann_output(tmp_path / "good", ex, t, 0.5, 400, width=3)
    r = checks.run_check(case, good, history("ale"))
    assert r["passed"], failed(r)
    bad = riemann_output(tmp_path / "bad", ex, t, 0.5, 400, width=3, bad_step=True)
    r = checks.run_check(case, bad, history("ale"))
    assert failed(r) == ["invalid_values", "min_density"] and r["metrics"]["min_density"]["value"] == -1.0


# ---- positivity ----------------------------------------------------------------------------------
@pytest.mark.parametrize("field, value", [(None, None), ("density", -1e-3), ("specific_internal_energy", 0.0),
                                          ("pressure", np.nan), ("velocity", np.inf)])
def test_positivity(tmp_path, field, value):
    n = 8
    pts, cells = structured(np.linspace(0, 1, n + 1), np.array([0.0, 0.1]))
    steps = []
    for k in range(3):
        cd = {"density": np.ones(n), "pressure": np.ones(n), "specific_internal_energy": np.ones(n)}
        pd = {"velocity": np.zeros((len(pts), 3))}
        if field is not None and k == 1:
            a = pd["velocity"][:, 0] if field == "velocity" else cd[field]
            a[3] = value
        steps.append((0.1 * k, pts, pd, cd))
    out = write(tmp_path, "ale", cells, steps)
    case = {"check": {"kind": "positivity", "metrics": {"invalid_values": {"reference": 0.0, "tolerance": 0.5}}}}
    r = checks.run_check(case, out, history("ale"))
    assert r["passed"] == (field is None)
    assert r["metrics"]["invalid_values"]["value"] == (0.0 if field is None else 1.0)


# ---- sedov ---------------------------------------------------------------------------------------
def sedov_output(out, case, energy_factor=1.0):
    """The exact Sedov density (the case's E0 times energy_factor) at the zone centres of the case's
    grid at its end time."""
    from solvers.ale.exact.sedov import SedovSolution

    ale, P = case["ale"], case["check"]["params"]
    e0 = sum(e["energy"] for e in ale["energy_sources"]) * P["symmetry_factor"] * energy_factor
    ex = SedovSolution(e0, P["rho0"], P["gamma"], P["geometry"])
    g = ale["grid"]
    xn = np.linspace(g["lower"][0], g["upper"][0], g["cells"][0] + 1)
    yn = np.linspace(g["lower"][1], g["upper"][1], g["cells"][1] + 1)
    pts, cells = structured(xn, yn)
    r = np.linalg.norm(pts[cells].mean(axis=1), axis=1)
    t = case["run"]["end_time"]
    rho = ex.profiles(r, t)[0]
    return write(out, "ale", cells, [(t, pts, {"velocity": np.zeros_like(pts)}, {"density": rho})])


def test_sedov(tmp_path):
    """The exact profile passes sedov_2d's check (shock radius within a zone: the half-height
    crossing of the peak sampled at zone centres); the blast of 1.2 E0 (radius 4.7 % larger) fails
    it, as does an energy residual."""
    case = load_case(CASES / "sedov_2d")
    good = sedov_output(tmp_path / "good", case)
    r = checks.run_check(case, good, history("ale"))
    assert r["passed"], r
    assert r["metrics"]["l1_density"]["value"] == 0.0
    assert r["metrics"]["shock_radius"]["rel_error"] < 1.0 / 120
    r = checks.run_check(case, sedov_output(tmp_path / "wrong", case, 1.2), history("ale"))
    assert failed(r) == ["l1_density", "shock_radius"], failed(r)
    r = checks.run_check(case, good, history("ale", energy=1e-9))
    assert failed(r) == ["energy_balance_rel"]


# ---- reflected_shock -----------------------------------------------------------------------------
def reflected_output(out, case, t, p_factor=1.0):
    from solvers.ale.exact.reflected_shock import ReflectedShock

    P = case["check"]["params"]
    ex = ReflectedShock(tuple(P["ahead"]), P["gamma"], mach=P["mach"])
    g = case["ale"]["grid"]
    n = g["cells"][0]
    xn = np.linspace(g["lower"][0], g["upper"][0], n + 1)
    xc = 0.5 * (xn[1:] + xn[:-1])
    pts, cells = structured(xn, np.array([g["lower"][1], g["upper"][1]]))
    # (beyond the wall: the wall's state; the check ignores those zones)
    rho, _, p = (smear(a, 3) for a in cell_average(
        lambda s: ex.sample(np.minimum(s, P["x_wall"]), t, P["x_shock0"], P["x_wall"]), xn))
    _, xs = ex.shock_position(t, P["x_shock0"], P["x_wall"])
    p = np.where(xc > xs, p * p_factor, p)
    vel = np.zeros_like(pts)
    return write(out, "ale", cells, [(t, pts, {"velocity": vel}, {"density": rho, "pressure": p})])


def test_reflected_shock(tmp_path):
    case = load_case(CASES / "shock_reflection_obstacle")
    t = case["run"]["end_time"]
    r = checks.run_check(case, reflected_output(tmp_path / "good", case, t), history("ale"))
    assert r["passed"], r
    assert r["metrics"]["p_reflected"]["rel_error"] < 1e-12
    r = checks.run_check(case, reflected_output(tmp_path / "wrong", case, t, 1.01), history("ale"))
    assert failed(r) == ["p_reflected"], failed(r)
    # before the incident shock reached the wall there is nothing to check: an error, not a pass
    with pytest.raises(ValueError, match="has not reached the wall"):
        checks.run_check(case, reflected_output(tmp_path / "early", case, 0.05), history("ale"))


# ---- riemann_wall --------------------------------------------------------------------------------
def riemann_wall_output(out, case, t, gamma=None):
    """Zone averages of the exact Sod-into-a-wall solution (gamma: solve it with another gamma)."""
    from orchestrator.exact_profiles import riemann_wall_sample

    P = dict(case["check"]["params"])
    if gamma is not None:
        P["gamma_left"] = gamma
    g = case["ale"]["grid"]
    xn = np.linspace(g["lower"][0], g["upper"][0], g["cells"][0] + 1)
    pts, cells = structured(xn, np.array([g["lower"][1], g["upper"][1]]))
    rho, u, p = (smear(a, 3) for a in cell_average(lambda x: riemann_wall_sample(P, x, t), xn))
    vel = np.zeros_like(pts)
    vel[:, 0] = np.tile(np.concatenate([u, u[-1:]]), 2)  # (nodes: two rows)
    e = p / (0.4 * rho)
    return write(out, "ale", cells, [(t, pts, {"velocity": vel}, {"density": rho, "pressure": p,
                                                                 "specific_internal_energy": e})])


def test_riemann_wall(tmp_path):
    """Sod into a wall (the conforming base case of the shock-tube campaign): the exact solution's
    reflected state is the Rankine-Hugoniot one of Sod's shock (Mach 1.655632: p 0.780387, rho
    0.509395, as cases/sod_immersed_wall); zone averages of it pass with the case's tolerances;
    gamma 1.6 fails the L1 error and the reflected pressure; after the reflected shock meets the
    contact there is no exact solution to check against: an error."""
    from orchestrator.exact_profiles import riemann_wall_solution

    case = load_case(CASES / "campaigns" / "shock_tube_conforming_vs_immersed" / "conforming")
    _, refl = riemann_wall_solution(case["check"]["params"])
    assert abs(refl.mach - 1.655632) < 1e-6 and abs(refl.p5 - 0.780387) < 1e-6 and abs(refl.rho5 - 0.509395) < 1e-6
    t = case["run"]["end_time"]
    r = checks.run_check(case, riemann_wall_output(tmp_path / "good", case, t), history("ale"))
    assert r["passed"], r
    assert r["metrics"]["l1_density"]["value"] < 1.5e-3  # (the smearing over 3 zones: 8.2e-4)
    assert abs(r["metrics"]["p_reflected"]["value"] / refl.p5 - 1) < 1e-12
    r = checks.run_check(case, riemann_wall_output(tmp_path / "wrong", case, t, gamma=1.6), history("ale"))
    assert failed(r) == ["l1_density", "p_reflected"], failed(r)
    with pytest.raises(ValueError, match="reached the contact"):  # (they meet at t = 0.33)
        riemann_wall_output(tmp_path / "late", case, 0.5)


# ---- piston --------------------------------------------------------------------------------------
def piston_output(out, case, p_factor=1.0, shock_shift=0.0):
    """The exact piston solution on the case's Lagrangian grid: the material between the piston
    and the shock (initially [0, D t]) compressed by rho0/rho1 behind the piston face."""
    from solvers.ale.exact.piston import tait

    ale = case["ale"]
    mat = ale["materials"]["water"]
    ex = tait(50.0, mat["rho0"], mat["bulk_modulus"], mat["exponent"], mat["p0"])
    g = ale["grid"]
    n = g["cells"][0]
    t = case["run"]["end_time"]
    X = np.linspace(g["lower"][0], g["upper"][0], n + 1)
    xs = ex.shock_position(t) + shock_shift
    x = np.where(X < xs, ex.u_p * t + X * ex.rho0 / ex.rho1, X)
    xc = 0.5 * (x[1:] + x[:-1])
    behind = xc < xs
    p = np.where(behind, ex.p1 * p_factor, ex.p0)
    rho = np.where(behind, ex.rho1, ex.rho0)
    pts, cells = structured(x, np.array([g["lower"][1], g["upper"][1]]))
    return write(out, "ale", cells, [(t, pts, {"velocity": np.zeros_like(pts)}, {"density": rho, "pressure": p})])


def test_piston(tmp_path):
    case = load_case(CASES / "water_piston_column")
    r = checks.run_check(case, piston_output(tmp_path / "good", case), history("ale"))
    assert r["passed"], r
    r = checks.run_check(case, piston_output(tmp_path / "p", case, p_factor=1.005), history("ale"))
    assert failed(r) == ["p_plateau"], failed(r)
    r = checks.run_check(case, piston_output(tmp_path / "xs", case, shock_shift=2.0 / 400), history("ale"))
    assert "shock_position_error_cells" in failed(r)


# ---- advected_shape ------------------------------------------------------------------------------
def square_output(out, case, shift=0.0):
    P = case["check"]["params"]
    g = case["ale"]["grid"]
    xn = np.linspace(g["lower"][0], g["upper"][0], g["cells"][0] + 1)
    yn = np.linspace(g["lower"][1], g["upper"][1], g["cells"][1] + 1)
    pts, cells = structured(xn, yn)
    c = pts[cells][:, :, :2]
    lo, hi = np.array(P["lower"]) + shift, np.array(P["upper"]) + shift
    ov = np.clip(np.minimum(c.max(axis=1), hi) - np.maximum(c.min(axis=1), lo), 0.0, None)
    f = np.prod(ov, axis=1) / np.prod(c.max(axis=1) - c.min(axis=1), axis=1)
    t = case["run"]["end_time"]
    return write(out, "ale", cells, [(t, pts, {"velocity": np.zeros_like(pts)}, {f"volume_fraction_{P['material']}": f})])


def test_advected_shape(tmp_path):
    case = load_case(CASES / "advected_square")
    h = history("ale")
    h["ale.volume_heavy"] = np.full(5, 0.16)
    r = checks.run_check(case, square_output(tmp_path / "good", case), h)
    assert r["passed"] and r["metrics"]["symmetric_difference"]["value"] < 1e-14, r
    # the square a quarter zone off: 2 x 0.4 x 0.25/64 = 3.1e-3 ... 4.7e-3 of area misplaced
    r = checks.run_check(case, square_output(tmp_path / "off", case, shift=0.5 / 64), h)
    assert failed(r) == ["symmetric_difference"], failed(r)
    h["ale.volume_heavy"] = np.array([0.16, 0.16, 0.16, 0.16, 0.16 * (1 + 1e-10)])
    r = checks.run_check(case, square_output(tmp_path / "good", case), h)
    assert failed(r) == ["volume_drift_rel"], failed(r)


# ---- bar_wave ------------------------------------------------------------------------------------
def bar_output(out, case, speed=5000.0, amplitude=4.0e7):
    """The elastic bar's step wave (front smeared over 3 elements) at every output time of the
    case, on its 400 x 1 x 1 hexahedra."""
    box = case["lagrange"]["bodies"][0]["mesh"]["box"]
    n = box["cells"][0]
    xn = np.linspace(box["lower"][0], box["upper"][0], n + 1)
    pts, cells = structured(xn, np.array([0.0, box["upper"][1]]), np.array([0.0, box["upper"][2]]))
    xc = 0.5 * (xn[1:] + xn[:-1])
    steps = []
    for k, t in enumerate(np.arange(17) * 1.0e-6):
        s = np.zeros((n, 6))
        s[:, 0] = -amplitude * smear((xc < speed * t).astype(float), 3)
        steps.append((t, pts, {"velocity": np.zeros_like(pts), "displacement": np.zeros_like(pts)}, {"stress": s}))
    return write(out, "lagrange", cells, steps)


def test_bar_wave(tmp_path):
    case = load_case(CASES / "elastic_bar_wave")
    h = history("lagrange", n=17)
    h["time"] = np.arange(17) * 1.0e-6
    r = checks.run_check(case, bar_output(tmp_path / "good", case), h)
    assert r["passed"], r
    r = checks.run_check(case, bar_output(tmp_path / "slow", case, speed=4990.0), h)
    assert failed(r) == ["wave_speed"], failed(r)
    r = checks.run_check(case, bar_output(tmp_path / "weak", case, amplitude=3.98e7), h)
    assert failed(r) == ["stress_amplitude"], failed(r)
    h["lagrange.energy_balance_rel"][3] = 1e-12
    r = checks.run_check(case, bar_output(tmp_path / "good", case), h)
    assert failed(r) == ["energy_balance_rel"], failed(r)


# ---- taylor_bar ----------------------------------------------------------------------------------
def taylor_output(out, length, diameter):
    """A quarter rod 3.2 mm x 32.4 mm (the case's) deformed to `length` with its impact face (z = 0)
    spread to `diameter`: points and the displacement that took them there."""
    r0, l0 = 3.2e-3, 32.4e-3
    rr, th, zz = np.meshgrid(np.linspace(0, r0, 4), np.linspace(0, np.pi / 2, 4), np.linspace(0, l0, 10), indexing="ij")
    X = np.column_stack([(rr * np.cos(th)).ravel(), (rr * np.sin(th)).ravel(), zz.ravel()])
    spread = 1.0 + (0.5 * diameter / r0 - 1.0) * (1.0 - X[:, 2] / l0)
    x = np.column_stack([X[:, 0] * spread, X[:, 1] * spread, X[:, 2] * length / l0])
    cells = np.arange(8, dtype=np.int64)[None, :]  # (not read by the check)
    return write(out, "lagrange", cells, [(0.0, X, {"displacement": np.zeros_like(X)}, {}),
                                          (80e-6, x, {"displacement": x - X}, {})])


def test_taylor_bar(tmp_path):
    case = load_case(CASES / "taylor_bar")
    r = checks.run_check(case, taylor_output(tmp_path / "good", 26.54e-3, 11.185e-3), {})
    assert r["passed"] and max(m["rel_error"] for m in r["metrics"].values()) < 1e-12, r
    # the 10 % softer rod of the issue: 1.3 % shorter, 1.2 % wider
    r = checks.run_check(case, taylor_output(tmp_path / "soft", 26.20e-3, 11.32e-3), {})
    assert failed(r) == ["final_length", "impact_diameter"], failed(r)


# ---- momentum ------------------------------------------------------------------------------------
@pytest.mark.parametrize("residual, fails", [({}, []), ({"momentum": 1e-12}, ["momentum_balance_rel"]),
                                             ({"angular_momentum": -1e-11}, ["angular_momentum_balance_rel"])])
def test_momentum(tmp_path, residual, fails):
    case = load_case(CASES / "spinning_block")
    r = checks.run_check(case, tmp_path, history("lagrange", **residual))
    assert failed(r) == fails and r["passed"] == (not fails)


# ---- free_flight ---------------------------------------------------------------------------------
def tumbling_history(energy_kick=0.0, momentum_kick=0.0, spin_kick=0.0):
    """A 3-D body loaded to t = 5 (energy, spin growing), then free to t = 30: the energy E = T + U
    (T 1000 J + U 500 J, exchanging), the momentum 0 and the angular momentum (3, 2, -1) from t = 5,
    with a kick of the given relative size at t = 20."""
    t = np.linspace(0.0, 30.0, 301)
    after = t >= 5.0
    late = t >= 20.0
    ramp = np.minimum(t / 5.0, 1.0)
    u = 500.0 * ramp * (1.0 + 0.3 * np.sin(t)) / 1.3
    ke = 1500.0 * ramp - u + 1500.0 * energy_kick * late
    h = {"time": t, "step": np.arange(len(t), dtype=float),
         "lagrange.kinetic_energy": ke, "lagrange.stress_power_energy": u,
         "lagrange.mass": np.full(len(t), 1170.0), "lagrange.newton_iterations": np.full(len(t), 4.0)}
    scale = np.sqrt(2.0 * 1170.0 * ke[after][0])
    for c, w in zip("xyz", (1.0, 0.0, 0.0)):
        h[f"lagrange.momentum_{c}"] = momentum_kick * scale * w * late
    for c, w in zip("xyz", (3.0, 2.0, -1.0)):
        h[f"lagrange.angular_momentum_{c}"] = w * ramp * (1.0 + spin_kick * late)
    for k in ("energy", "momentum", "angular_momentum"):
        h[f"lagrange.{k}_balance_rel"] = np.full(len(t), 1e-14)
    return h


@pytest.mark.parametrize("kick, fails", [({}, []), ({"energy_kick": 1e-11}, ["energy_drift_rel"]),
                                         ({"momentum_kick": 1e-12}, ["momentum_drift_rel"]),
                                         ({"spin_kick": 1e-12}, ["angular_momentum_drift_rel"])])
def test_free_flight(tmp_path, kick, fails):
    """The L-block's check: drifts from t = 5 on, each caught at 10 times its tolerance; the load phase
    before (energy and spin growing) is not counted."""
    case = load_case(CASES / "l_block_free_flight")
    r = checks.run_check(case, tmp_path, tumbling_history(**kick))
    assert failed(r) == fails and r["passed"] == (not fails), r
    if not fails:
        assert r["metrics"]["energy_drift_rel"]["value"] < 1e-15
        assert r["reported"]["newton_iterations_max"] == 4.0


# ---- bounce --------------------------------------------------------------------------------------
def bouncing_history(lost=0.0, flicker=False):
    """A body falling (T + U - W_gravity = 10 J throughout), in contact over steps 5-14 and 20-24:
    the second episode loses ``lost`` of the energy; ``flicker``: its active rows go 2, 4, 2, 4, ..."""
    n = 30
    active = np.zeros(n)
    active[5:15] = 4.0
    active[20:25] = np.where(np.arange(5) % 2, 4.0, 2.0) if flicker else 3.0
    e = np.full(n, 10.0)
    e[25:] -= 10.0 * lost
    wg = np.linspace(0.0, 3.0, n)
    ke = 0.6 * (e + wg)
    return {"time": np.linspace(0.0, 0.029, n), "step": np.arange(n, dtype=float),
            "lagrange.contact_active": active, "lagrange.kinetic_energy": ke,
            "lagrange.stress_power_energy": e + wg - ke, "lagrange.gravity_work": wg}


@pytest.mark.parametrize("kw, expect", [({}, (2, 0.0, 0)), ({"lost": 1e-6}, (2, 1e-6, 0)),
                                        ({"flicker": True}, (2, 0.0, 4))])
def test_bounce_episodes(monkeypatch, tmp_path, kw, expect):
    """The episodes (runs of steps with active rows), the energy after each against before (gravity's
    potential counted), and the changes of the active count within one; the penetration measures are
    no_penetration's (tested there; replaced here)."""
    monkeypatch.setattr("orchestrator.checks.contact.no_penetration", lambda *a: {})
    vals = checks.CHECKS["bounce"](None, tmp_path, bouncing_history(**kw), {})
    assert (vals["episodes"], vals["state_changes_max"]) == (expect[0], expect[2])
    assert vals["energy_rebound_rel"] == pytest.approx(expect[1], abs=1e-15)


# ---- embedded_piston -----------------------------------------------------------------------------
def embedded_piston_output(out, case, centre_shift=0.0, p_factor=1.0):
    """Sod's exact solution at t on the case's grid with the piston (the body's box moved with the
    contact) at 0.5 + u* t + centre_shift, and the body's nodes there moving at u*."""
    from solvers.ale.exact.riemann import RiemannSolution

    t = case["run"]["end_time"]
    g = case["ale"]["grid"]
    n = g["cells"][0]
    xn = np.linspace(g["lower"][0], g["upper"][0], n + 1)
    ex = RiemannSolution((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.4, 1.4, 0.0, 0.0)
    xc = 0.5 * (xn[1:] + xn[:-1])
    rho, u, p = ex.sample(xc, t, 0.5)[:3]
    pts, cells = structured(xn, np.array([g["lower"][1], g["upper"][1]]))
    write(out, "ale", cells, [(t, pts, {"velocity": np.zeros_like(pts)}, {"density": rho, "pressure": p * p_factor})])
    box = case["lagrange"]["bodies"][0]["mesh"]["box"]
    lo, hi = np.array(box["lower"]), np.array(box["upper"])
    shift = ex.u_star * t + centre_shift
    bp, bc = structured(np.array([lo[0], hi[0]]) + shift, np.array([lo[1], hi[1]]))
    vel = np.zeros_like(bp)
    vel[:, 0] = ex.u_star
    write(out, "lagrange", bc, [(t, bp, {"velocity": vel}, {})])
    return out


def test_embedded_piston(tmp_path):
    case = load_case(CASES / "embedded_piston_sod")
    r = checks.run_check(case, embedded_piston_output(tmp_path / "good", case), history("ale"))
    assert r["passed"], r
    # (the references are given to 6 digits)
    assert r["metrics"]["centre"]["rel_error"] < 1e-6 and r["metrics"]["velocity"]["rel_error"] < 1e-6
    assert r["metrics"]["p_left"]["rel_error"] < 1e-6 and r["metrics"]["p_right"]["rel_error"] < 1e-6
    # the piston 0.02 behind the contact (3 %), the gas pressure 3 % high
    r = checks.run_check(case, embedded_piston_output(tmp_path / "lag", case, centre_shift=-0.02), history("ale"))
    assert failed(r) == ["centre"], failed(r)
    r = checks.run_check(case, embedded_piston_output(tmp_path / "p", case, p_factor=1.03), history("ale"))
    assert failed(r) == ["p_left", "p_right"], failed(r)


# ---- acoustic_transmission -----------------------------------------------------------------------
def acoustic_output(out, case, r_factor=1.0, t_factor=1.0):
    """The exact plane pulses at the case's end time: the reflected one (R p_i) in the fluid over
    0.317 .. 0.467 m, the transmitted one (stress_xx = -T p_i) in the body over 0.690 .. 0.791 m
    (the case's geometry), zero elsewhere; R and T scaled by the factors."""
    t = case["run"]["end_time"]
    z1, z2 = 1000.0 * (2.19e9 / 1000.0) ** 0.5, 4000.0 * 1000.0
    R, T = (z2 - z1) / (z1 + z2) * r_factor, 2.0 * z2 / (z1 + z2) * t_factor
    g = case["ale"]["grid"]
    xn = np.linspace(g["lower"][0], g["upper"][0], g["cells"][0] + 1)
    pts, cells = structured(xn, np.linspace(g["lower"][1], g["upper"][1], g["cells"][1] + 1))
    xc = np.tile(0.5 * (xn[1:] + xn[:-1]), g["cells"][1])
    p = np.where((xc > 0.317) & (xc < 0.467), R * 1e6, 0.0)
    write(out, "ale", cells, [(t, pts, {"velocity": np.zeros_like(pts)}, {"density": np.full(xc.size, 1e3),
                                                                          "pressure": p})])
    box = case["lagrange"]["bodies"][0]["mesh"]["box"]
    bx = np.linspace(box["lower"][0], box["upper"][0], box["cells"][0] + 1)
    bp, bc = structured(bx, np.linspace(box["lower"][1], box["upper"][1], box["cells"][1] + 1))
    bxc = np.tile(0.5 * (bx[1:] + bx[:-1]), box["cells"][1])
    stress = np.zeros((bxc.size, 6))
    stress[:, 0] = np.where((bxc > 0.690) & (bxc < 0.791), -T * 1e6, 0.0)
    write(out, "lagrange", bc, [(t, bp, {"velocity": np.zeros_like(bp)}, {"stress": stress})])
    return out


def test_acoustic_transmission(tmp_path):
    """The exact amplitudes pass (to the 6 digits of the references); a reflected pulse 1 % low fails
    the reflection only, a transmitted one 1 % high the transmission only."""
    case = load_case(CASES / "acoustic_transmission")
    r = checks.run_check(case, acoustic_output(tmp_path / "good", case), history("ale"))
    assert r["passed"], r
    assert r["metrics"]["reflection"]["rel_error"] < 2e-6 and r["metrics"]["transmission"]["rel_error"] < 2e-6
    r = checks.run_check(case, acoustic_output(tmp_path / "r", case, r_factor=0.99), history("ale"))
    assert failed(r) == ["reflection"], failed(r)
    r = checks.run_check(case, acoustic_output(tmp_path / "t", case, t_factor=1.01), history("ale"))
    assert failed(r) == ["transmission"], failed(r)


# ---- uniform_flow --------------------------------------------------------------------------------
def uniform_flow_output(out, case, kick=0.0, at_wall=True):
    """The oblique wall case's exact state (its initial velocity everywhere, the strip's zones
    blocked) with one gas node given a normal velocity ``kick`` (relative to the flow speed): next
    to the wall (half-open zones around it), or in a zone the wall covers (not gas: ignored)."""
    g = case["ale"]["grid"]
    nx, ny = g["cells"]
    xn, yn = np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, g["upper"][1], ny + 1)
    pts, cells = structured(xn, yn)
    xc = np.tile(0.5 * (xn[1:] + xn[:-1]), ny)
    yc = np.repeat(0.5 * (yn[1:] + yn[:-1]), nx)
    th = np.radians(30.0)
    dist = -np.sin(th) * xc + np.cos(th) * yc  # from the diagonal, along the wall's normal
    bf = np.clip((0.05 + 0.5 * 0.02 - np.abs(dist)) / 0.02, 0.0, 1.0)  # the strip, smeared over a zone
    u = np.array(case["check"]["params"]["velocity"])
    n = np.array(case["check"]["params"]["normal"])
    v = np.tile(np.append(u, 0.0), (len(pts), 1))
    share = np.bincount(cells.ravel(), weights=np.repeat(1.0 - bf, 4), minlength=len(pts))
    count = np.bincount(cells.ravel(), minlength=len(pts))
    frac = share / count
    node = np.flatnonzero((frac > 0.6) & (frac < 0.9) if at_wall else frac < 0.3)[0]
    v[node, :2] += kick * np.linalg.norm(u) * n
    return write(out, "ale", cells, [(1.0, pts, {"velocity": v}, {"density": np.ones(nx * ny), "blocked_fraction": bf})])


def test_uniform_flow(tmp_path):
    """The initial state passes exactly; a gas node next to the wall moving across it at 2e-14 of the
    flow speed passes (tolerances 3e-14 and 5e-14), at 1e-13 fails both metrics, a kick of 6 % at a node inside
    the wall counts for nothing; a mass balance of 1e-12 fails that metric only."""
    case = load_case(CASES / "oblique_slip_wall")
    r = checks.run_check(case, uniform_flow_output(tmp_path / "good", case), history("ale"))
    assert r["passed"], r
    assert r["metrics"]["normal_velocity_max"]["value"] < 1e-15
    r = checks.run_check(case, uniform_flow_output(tmp_path / "kick", case, 2e-14), history("ale"))
    assert r["passed"], r
    r = checks.run_check(case, uniform_flow_output(tmp_path / "kick2", case, 1e-13), history("ale"))
    assert failed(r) == ["normal_velocity_max", "velocity_deviation_max"], failed(r)
    r = checks.run_check(case, uniform_flow_output(tmp_path / "inside", case, 0.06, at_wall=False), history("ale"))
    assert r["passed"], r
    r = checks.run_check(case, uniform_flow_output(tmp_path / "m", case), history("ale", mass=1e-12))
    assert failed(r) == ["mass_balance_rel"], failed(r)


# ---- coupled_balances ----------------------------------------------------------------------------
def test_coupled_balances(tmp_path):
    """The bookkeeping of a coupled run: balances from the history, gas left in zones a body fills
    from the output (a zone filled by the body with density 0.1 left in it fails)."""
    case = load_case(CASES / "closed_box_body")
    g = case["ale"]["grid"]
    nx, ny = g["cells"]
    pts, cells = structured(np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 0.6, ny + 1))
    bf = np.zeros(nx * ny)
    bf[:10] = 1.0
    rho = np.where(bf >= 1.0, 0.0, 1.2)
    hist = history("ale")
    hist.update({"coupling.interface_work": np.full(5, 1e-6), "ale.total_energy": np.full(5, 1.0)})
    good = write(tmp_path / "good", "ale", cells, [(4e-3, pts, {"velocity": np.zeros_like(pts)},
                                                    {"density": rho, "blocked_fraction": bf})])
    r = checks.run_check(case, good, hist)
    assert r["passed"], r
    rho[3] = 0.1
    bad = write(tmp_path / "bad", "ale", cells, [(4e-3, pts, {"velocity": np.zeros_like(pts)},
                                                  {"density": rho, "blocked_fraction": bf})])
    r = checks.run_check(case, bad, hist)
    assert failed(r) == ["covered_gas_mass"], failed(r)


# ---- surge_front (SPH particles) -----------------------------------------------------------------
def dam_break_output(out, case, scale=1.0):
    """Particles along the floor up to the front Z(T) of Martin & Moyce (linear between their points,
    Z = 1 at T = 0), scaled by `scale`, at output times that include every measured T; a lone
    droplet 0.3 m ahead (spray) and the fixed right wall (bodies 1..3) that the front must ignore."""
    a, g = 0.25, 9.81
    pts = case["check"]["params"]["points"]
    T_ref = np.array([0.0] + [p[0] for p in pts])
    Z_ref = np.array([1.0] + [p[1] for p in pts])
    dx = case["sph"]["spacing"]
    T_out = np.unique(np.concatenate([np.linspace(0.0, 4.2, 22), T_ref]))
    n_free = 800
    wall = np.column_stack([np.full(50, 1.5 + dx), np.linspace(0.0, 0.5, 50)])
    output.write_mesh(out, "sph", np.arange(n_free + 1 + 50, dtype=np.int64)[:, None], "vertex")
    for k, T in enumerate(T_out):
        front = a * np.interp(T, T_ref, Z_ref) * scale
        x = np.column_stack([np.linspace(0.0, front, n_free), np.full(n_free, 0.5 * dx)])
        spray = np.array([[front + 0.3, 0.1]])
        body = np.concatenate([np.zeros(n_free + 1, np.int64), np.full(50, 3)])
        output.write_step(out, "sph", k, k, T / np.sqrt(2 * g / a), np.vstack([x, spray, wall]),
                          {"body": body})
    return out


def test_surge_front(tmp_path):
    case = load_case(CASES / "dam_break")
    r = checks.run_check(case, dam_break_output(tmp_path / "good", case), history("sph"))
    assert r["passed"], r
    assert r["metrics"]["front_error_max_rel"]["value"] < 1e-9
    # the front 12 % ahead of the measurements everywhere: fails
    r = checks.run_check(case, dam_break_output(tmp_path / "fast", case, scale=1.12), history("sph"))
    assert failed(r) == ["front_error_max_rel"], failed(r)
    assert r["metrics"]["front_error_max_rel"]["value"] == pytest.approx(0.12, rel=1e-6)


# ---- free_end (a clamped bar set moving) ---------------------------------------------------------
def free_end_output(out, c=1000.0, v0=1.0, length=1.0, n=53):
    """Particles of a bar whose free end (x = L) follows the 1-D triangle wave of wave speed c
    (displacement v0 t until L / c, then falling at v0), the rest at rest, sampled every 0.05 L / c."""
    x0 = np.column_stack([np.linspace(0.0, length, 11), np.zeros(11)])
    output.write_mesh(out, "sph", np.arange(11, dtype=np.int64)[:, None], "vertex")
    for k, t in enumerate(np.arange(n) * 0.05 * length / 1000.0):
        u = v0 * (t if t <= length / c else 2 * length / c - t)
        x = x0.copy()
        x[-1, 0] += u
        output.write_step(out, "sph", k, k, t, x, {"body": np.zeros(11, np.int64)})
    return out


def free_end_history(c=1000.0, v0=1.0, length=1.0, n=53):
    """The same triangle as a probe's history (every step; the output steps need not be there)."""
    h = history("sph", n)
    h["time"] = np.arange(n) * 0.05 * length / 1000.0
    h["step"] = np.arange(n)
    h["sph.probe_free_end"] = v0 * np.where(h["time"] <= length / c, h["time"], 2 * length / c - h["time"])
    return h


@pytest.mark.parametrize("source", ["outputs", "probe"])
def test_free_end(tmp_path, source):
    """The exact triangle (c = 1000 m/s): every error at round-off (the peak falls on a sample, the
    zero crossing and the slope are linear); a bar whose waves run 4 % slow fails the times.  Read
    from the output steps (no ``probe`` param), or from the probe's history (the outputs then hold
    the bar at rest: only the history has the wave)."""
    case = load_case(CASES / "sph_elastic_bar")
    if source == "outputs":
        del case["check"]["params"]["probe"]
        run = lambda d, c=1000.0: checks.run_check(case, free_end_output(tmp_path / d, c=c), history("sph"))
    else:
        run = lambda d, c=1000.0: checks.run_check(case, free_end_output(tmp_path / d, v0=0.0), free_end_history(c=c))
    r = run("good")
    assert r["passed"], r
    for k in ("peak_time_error_rel", "rebound_time_error_rel", "rebound_speed_error_rel"):
        assert r["metrics"][k]["value"] < 1e-9, k
    r = run("slow", c=960.0)
    assert failed(r) == ["peak_time_error_rel", "rebound_time_error_rel"], failed(r)
    assert r["metrics"]["rebound_time_error_rel"]["value"] == pytest.approx(1000 / 960 - 1, rel=1e-6)


# ---- tip_history (a body's tip against a reference history) ---------------------------------------
def tip_output(out, case, scale=1.0):
    """A plate's particles whose top row moves along x by `scale` times the case's reference
    history, sampled at other times than the reference's (interpolated by the check)."""
    ref = np.asarray(case["check"]["params"]["reference"], float)
    x0 = np.column_stack([np.full(5, 0.6), np.linspace(0.0, 0.3, 5)])
    output.write_mesh(out, "sph", np.arange(5, dtype=np.int64)[:, None], "vertex")
    for k, t in enumerate(np.linspace(0.0, ref[-1, 0], 23)):
        x = x0.copy()
        x[-1, 0] += scale * np.interp(t, ref[:, 0], ref[:, 1])
        output.write_step(out, "sph", k, k, t, x, {"body": np.zeros(5, np.int64)})
    return out


def test_tip_history(tmp_path):
    """The reference itself passes at round-off; a tip deflecting 12 % more fails both metrics with
    the error it was given (largest at the last time)."""
    case = load_case(CASES / "sph_vs_fe_plate" / "sph")
    r = checks.run_check(case, tip_output(tmp_path / "good", case), history("sph"))
    assert r["passed"], r
    assert r["metrics"]["tip_history_error"]["value"] < 1e-12
    r = checks.run_check(case, tip_output(tmp_path / "far", case, scale=1.12), history("sph"))
    assert failed(r) == ["tip_final_error", "tip_history_error"], failed(r)
    assert r["metrics"]["tip_history_error"]["value"] == pytest.approx(0.12, rel=1e-9)


# ---- penetration (a rod's depth into a target) --------------------------------------------------
def rod_output(out, speed, lone=False):
    """A rod of particles (2 x 6 on dx = 1.25e-4) whose tip enters the surface y = 0.025 at
    ``speed`` from t = 1 us (0.06 mm above it before), sampled every 1 us to 8 us; ``lone``: one
    particle 5 mm ahead of it (spray: no neighbour)."""
    dx = 1.25e-4
    i, j = np.meshgrid(np.arange(2), np.arange(6), indexing="ij")
    x0 = np.column_stack([i.ravel() * dx, 0.02506 + j.ravel() * dx])
    if lone:
        x0 = np.vstack([x0, [0.0, 0.02]])
    n = x0.shape[0]
    output.write_mesh(out, "sph", np.arange(n, dtype=np.int64)[:, None], "vertex")
    for k in range(9):
        t = k * 1e-6
        x = x0.copy()
        x[: 12, 1] -= 6e-5 + speed * max(t - 1e-6, 0.0) if k else 0.0
        output.write_step(out, "sph", k, k, t, x, {"body": np.zeros(n, np.int64)})
    return out


def test_penetration(tmp_path):
    """A tip moving into the target at exactly 574.3 m/s: the velocity to round-off and the depth
    574.3 * 7 us; at 650 m/s the velocity fails with its error (+13.2 %); a lone particle ahead of
    the rod is not its tip; a window with fewer than 2 outputs is an error naming it."""
    case = load_case(CASES / "tate_penetration_rate")
    r = checks.run_check(case, rod_output(tmp_path / "good", 574.3), history("sph"))
    assert r["passed"], r
    assert r["metrics"]["penetration_velocity"]["rel_error"] < 1e-9
    assert r["reported"]["depth"] == pytest.approx(574.3 * 7e-6, rel=1e-9)
    r = checks.run_check(case, rod_output(tmp_path / "fast", 650.0), history("sph"))
    assert failed(r) == ["penetration_velocity"]
    assert r["metrics"]["penetration_velocity"]["rel_error"] == pytest.approx(650 / 574.3 - 1, rel=1e-9)
    r = checks.run_check(case, rod_output(tmp_path / "spray", 574.3, lone=True), history("sph"))
    assert r["passed"], r
    case = case_with("tate_penetration_rate", depth_time=5.5e-6)
    r = checks.run_check(case, rod_output(tmp_path / "good", 574.3), history("sph"))
    assert r["reported"]["depth_at_time"] == pytest.approx(574.3 * 4.5e-6, rel=1e-12)
    r = checks.run_check(case_with("tate_penetration_rate", depth_time=9e-6), tmp_path / "good", history("sph"))
    assert np.isnan(r["reported"]["depth_at_time"])
    case = case_with("tate_penetration_rate", window=[2.5e-6, 2.9e-6])
    with pytest.raises(ValueError, match=r"check.params.window = \[2.5e-06, 2.9e-06\]: fewer than 2"):
        checks.run_check(case, rod_output(tmp_path / "few", 574.3), history("sph"))


def eroding_rod_output(out):
    """A rod 2 x 40 particles (dx = 1.25e-4, length 4.875 mm between its tip and rear layers) whose
    tip enters the surface y = 0.025 at t = 0 and moves at U = 574.3 m/s while its rear keeps
    v = 911 m/s (the particles between spaced evenly): Tate's erosion, the rod's length shrinking
    at v - U; sampled every 1 us to 16 us."""
    dx, n, U, v = 1.25e-4, 40, 574.3, 911.0
    L = (n - 1) * dx
    write_mesh = output.write_mesh
    write_mesh(out, "sph", np.arange(2 * n, dtype=np.int64)[:, None], "vertex")
    for k in range(17):
        t = k * 1e-6
        tip = 0.025 - U * t
        length = max(L - (v - U) * t, 1e-6)
        y = tip + length * np.arange(n) / (n - 1)
        x = np.column_stack([np.repeat([0.0, dx], n), np.tile(y, 2)])
        output.write_step(out, "sph", k, k, t, x, {"body": np.zeros(2 * n, np.int64)})
    return out


def test_penetration_depth_when_the_rod_is_consumed(tmp_path):
    """The rod is used up when its rear face comes within h = 3.75e-4 of its tip: at
    t = (L - h) / (v - U) = 13.365 us, depth U t = 7.676 mm (linear in t, so interpolation between the
    1-us outputs is exact to round-off).  A rod that is not eroded (rigid, rod_output) is never used
    up: NaN, which fails a depth_consumed metric."""
    case = load_case(CASES / "tate_penetration_rate")
    r = checks.run_check(case, eroding_rod_output(tmp_path / "eroding"), history("sph"))
    t = (39 * 1.25e-4 - 3.75e-4) / (911.0 - 574.3)
    assert r["reported"]["consumed_time"] == pytest.approx(t, rel=1e-12)
    assert r["reported"]["depth_consumed"] == pytest.approx(574.3 * t, rel=1e-12)
    r = checks.run_check(case, rod_output(tmp_path / "rigid", 574.3), history("sph"))
    assert np.isnan(r["reported"]["depth_consumed"])
    spec = dict(case["check"], metrics={"depth_consumed": {"reference": 1.0, "tolerance": 1.0}})
    assert not checks.run_check(dict(case, check=spec), tmp_path / "rigid", history("sph"))["passed"]


# ---- the registry and the CLI --------------------------------------------------------------------
def test_every_registered_kind_is_tested_here():
    tested = {"bar_wave", "taylor_bar", "momentum", "riemann", "sedov", "positivity", "reflected_shock", "piston",
              "advected_shape", "embedded_piston", "coupled_balances", "acoustic_transmission",
              "uniform_flow", "riemann_wall", "surge_front", "free_end", "tip_history", "penetration", "impact", "sliding",
              "uniform_stress", "hertz", "self_contact", "no_penetration", "free_flight", "bounce"}
    assert set(checks.CHECKS) == tested


def test_a_metric_the_kind_does_not_compute_is_an_error(tmp_path):
    case = load_case(CASES / "spinning_block")
    case["check"]["metrics"]["wave_speed"] = {"reference": 1.0, "tolerance": 0.1}
    with pytest.raises(KeyError, match="check.metrics.wave_speed"):
        checks.run_check(case, tmp_path, history("lagrange"))


def test_immerse_run_exits_1_when_the_check_fails(tmp_path):
    """The water piston column (a 2 s run) with a plateau pressure reference 1 % off: the run
    completes, summary.json records the failed metric, `immerse run` prints "check FAILED" and
    exits 1."""
    case = tmp_path / "case"
    shutil.copytree(CASES / "water_piston_column", case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    assert "reference = 7.91832e7" in text
    (case / "case.toml").write_text(text.replace("reference = 7.91832e7", "reference = 7.99750e7"))
    r = immerse("run", case, "--out", tmp_path / "out")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "check FAILED" in r.stdout
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert not s["check"]["passed"]
    assert [k for k, m in s["check"]["metrics"].items() if not m["passed"]] == ["p_plateau"]


# ---- impact (two bodies in contact) ---------------------------------------------------------------
def impact_run(out, release):
    """cases/bars_impact's bodies: a contact force of 197.5 MPa x 0.005 m from the first step (t = 0.1
    us) to ``release``, then none; at the end the striker at rest and the target at 10 m/s;
    the contact took 0.2 % of the initial kinetic energy."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "bars_impact")
    mesh, body = concatenate([body_mesh(b, 2) for b in case["lagrange"]["bodies"]])
    first_target = mesh.cells[body == 1].min()
    v = np.zeros((mesh.num_points, 2))
    v[first_target:, 0] = 10.0
    output.write_mesh(out, "lagrange", mesh.cells, "quad")
    output.write_step(out, "lagrange", 0, 600, 60e-6, mesh.points, {"velocity": v}, {})
    h = history("lagrange", n=601)
    h["time"] = np.linspace(0.0, 60e-6, 601)
    h["lagrange.contact_force_x"] = np.where((h["time"] > 0) & (h["time"] <= release), -197.5e6 * 0.005, 0.0)
    h["lagrange.kinetic_energy"] = np.full(601, 195.0)
    h["lagrange.contact_work"] = np.full(601, -0.002 * 195.0)
    return case, h


def test_impact(tmp_path):
    """The 1-D bar values themselves pass: duration 2 L / c to one record (0.1 us), stress and
    velocities exact; a contact released at 30 us fails its duration with that error."""
    case, h = impact_run(tmp_path / "good", release=39.55e-6)  # (the last record in contact: 39.5 us)
    r = checks.run_check(case, tmp_path / "good", h)
    assert r["passed"], r
    m = r["metrics"]
    assert m["contact_duration"]["value"] == pytest.approx(39.5e-6, rel=1e-12)
    assert m["interface_stress"]["rel_error"] < 1e-12 and m["contact_dissipation_rel"]["value"] == pytest.approx(0.002)
    assert m["velocity_striker_rel"]["value"] == 0.0 and m["velocity_target_rel"]["rel_error"] < 1e-12
    case, h = impact_run(tmp_path / "short", release=30.05e-6)
    r = checks.run_check(case, tmp_path / "short", h)
    assert failed(r) == ["contact_duration"]
    assert r["metrics"]["contact_duration"]["rel_error"] == pytest.approx(9.5 / 39.5, rel=1e-9)  # 30 us against 39.5


def sliding_output(out, slips):
    """cases/block_on_incline's meshes at the given (time, block slip, incline slip) records."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "block_on_incline")
    meshes = [body_mesh(b, 2) for b in case["lagrange"]["bodies"]]
    mesh, _ = concatenate(meshes)
    n0 = meshes[0].num_points
    steps = []
    for t, a, b in slips:
        slip = np.concatenate([np.full(n0, a), np.full(mesh.num_points - n0, b)])
        steps.append((t, mesh.points, {"contact_slip": slip}, {}))
    write(out, "lagrange", mesh.cells, steps)


def test_sliding(tmp_path):
    """A body whose momentum grows as m a t: its acceleration to round-off and its largest speed in the
    window; 10 % faster fails with that error; a window with fewer than 3 records is an error. With
    friction its slip within the window (the output's contact_slip at the window's last output step
    less its first; the held body's slip not counted); fewer than 2 output steps in the window: an
    error."""
    case = load_case(CASES / "block_on_incline")
    sliding_output(tmp_path, [(0.0, 0.0, 0.0), (0.05, 1e-3, 5.0), (0.1, 1e-3 + 2.5e-6, 9.0)])
    m = 1000.0 * 0.1 * 0.05
    h = history("lagrange", n=101)
    h["time"] = np.linspace(0.0, 0.1, 101)
    h["lagrange.momentum_x"] = m * 1.511541 * h["time"]
    r = checks.run_check(case, tmp_path, h)
    assert r["passed"], r
    assert r["metrics"]["acceleration"]["rel_error"] < 1e-9 and r["reported"]["speed_max"] == pytest.approx(0.1511541)
    assert r["reported"]["slip_max"] == pytest.approx(2.5e-6, rel=1e-9)
    h["lagrange.momentum_x"] = 1.1 * m * 1.511541 * h["time"]
    r = checks.run_check(case, tmp_path, h)
    assert failed(r) == ["acceleration"] and r["metrics"]["acceleration"]["rel_error"] == pytest.approx(0.1, rel=1e-9)
    with pytest.raises(ValueError, match="fewer than 3 records"):
        checks.run_check(case_with("block_on_incline", window=[0.0405, 0.0415]), tmp_path, h)
    with pytest.raises(ValueError, match="fewer than 2 output steps"):
        checks.run_check(case_with("block_on_incline", window=[0.04, 0.09]), tmp_path, h)



# ---- no_penetration (3-D plates) ----------------------------------------------------------------
def plates_output(out, drop, tilt=0.0):
    """cases/impacting_plates's meshes: at step 0 as built (the striker 1 mm above the plate), at
    step 1 the striker lowered by ``drop`` less ``tilt`` per metre of y above its edge y = -0.03 (a
    sheared striker: its edge deepest); a contact force of 1e4 N along z for 1 us of a 2 us record."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "impacting_plates")
    # (only the penetration judged: the other metrics' references are the run's)
    case["check"]["metrics"] = {"penetration_max_rel": case["check"]["metrics"]["penetration_max_rel"]}
    meshes = [body_mesh(b, 3) for b in case["lagrange"]["bodies"]]
    mesh, _ = concatenate(meshes)
    moved = mesh.points.copy()
    s = slice(0, meshes[0].num_points)  # the striker: the first body
    moved[s, 2] -= drop - tilt * (moved[s, 1] + 0.03)
    write(out, "lagrange", mesh.cells, [(0.0, mesh.points, {}, {}), (1e-6, moved, {}, {})])
    h = history("lagrange", n=21)
    h["time"] = np.linspace(0.0, 2e-6, 21)
    for c in "xy":
        h[f"lagrange.contact_force_{c}"] = np.zeros(21)
    h["lagrange.contact_force_z"] = np.where((h["time"] > 0.5e-6) & (h["time"] <= 1.5e-6 + 1e-12), 1e4, 0.0)
    h["lagrange.kinetic_energy"] = np.full(21, 10.0)
    h["lagrange.contact_work"] = np.full(21, -0.1)
    return case, h


def test_no_penetration(tmp_path):
    """Plates 1 mm apart, then touching: no penetration (0 exactly: nodes on the surface are not
    behind it); lowered 1.2 mm, each plate's face 0.2 mm behind the other's: 2e-4 m, over the
    striker's median edge (5 mm, its own facets the plate's nodes are behind) 0.04, failing the case's
    tolerance; a sheared striker whose edge dips 0.1 mm: that edge's depth, 1e-4 / 6.25e-3 (the plate's
    edge); the contact record's impulse (1e4 N over 1 us), peak, time and dissipation."""
    case, h = plates_output(tmp_path / "apart", drop=1e-3)
    r = checks.run_check(case, tmp_path / "apart", h)
    assert r["metrics"]["penetration_max_rel"]["value"] == 0.0
    v = {**r["reported"], **{k: m["value"] for k, m in r["metrics"].items()}}
    assert v["contact_impulse"] == pytest.approx(1e-2, rel=1e-9) and v["contact_force_peak"] == 1e4
    assert v["contact_time"] == pytest.approx(1.0e-6, rel=1e-9) and v["contact_dissipation_rel"] == pytest.approx(0.01)
    case, h = plates_output(tmp_path / "deep", drop=1.2e-3)
    r = checks.run_check(case, tmp_path / "deep", h)
    assert failed(r) == ["penetration_max_rel"]
    assert r["reported"]["penetration_max"] == pytest.approx(2e-4, rel=1e-9)
    assert r["metrics"]["penetration_max_rel"]["value"] == pytest.approx(2e-4 / 5e-3, rel=1e-9)
    case, h = plates_output(tmp_path / "edge", drop=1.1e-3, tilt=1e-3 / 5e-3)
    r = checks.run_check(case, tmp_path / "edge", h)
    assert r["reported"]["penetration_max"] == pytest.approx(1e-4, rel=1e-9)
    assert r["metrics"]["penetration_max_rel"]["value"] == pytest.approx(1e-4 / 6.25e-3, rel=1e-9)
    # a node beyond the other body's faces (the striker 2 mm aside of the plate's edge, below its top)
    # is not behind them: 0
    case, h = plates_output(tmp_path / "aside", drop=1.5e-3)
    pts = output.read_step(tmp_path / "aside", "lagrange", 1)[0]
    pts[:13 * 13 * 4, 0] += 0.082   # (the striker's 13 x 13 x 4 nodes first)
    write(tmp_path / "aside", "lagrange", output.read_mesh_file(tmp_path / "aside", "lagrange")[0],
          [(0.0, pts, {}, {}), (1e-6, pts, {}, {})])
    assert checks.run_check(case, tmp_path / "aside", h)["metrics"]["penetration_max_rel"]["value"] == 0.0


# ---- static contact: uniform_stress (patch test), hertz ------------------------------------------
def patch_output(out, stress, pressure=1.0e4):
    """cases/contact_patch_2d's meshes with every element at ``stress`` (6 Voigt components) and the
    nodes of the interface y = 0.5 at ``pressure``."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "contact_patch_2d")
    mesh, _ = concatenate([body_mesh(b, 2) for b in case["lagrange"]["bodies"]])
    p = np.where(np.isclose(mesh.points[:, 1], 0.5), pressure, 0.0)
    output.write_mesh(out, "lagrange", mesh.cells, "quad")
    output.write_step(out, "lagrange", 0, 1, 1.0, mesh.points, {"contact_pressure": p},
                      {"stress": np.tile(stress, (mesh.num_cells, 1))})
    return case


def test_uniform_stress(tmp_path):
    """The exact patch-test state passes to round-off; 1e-10 of it in sigma_x fails other_stress_rel by
    that much; a contact pressure 1e-10 off fails its metric."""
    s = np.array([0.0, -1.0e4, 0.0, 0.0, 0.0, 0.0])
    case = patch_output(tmp_path / "good", s)
    r = checks.run_check(case, tmp_path / "good", history("lagrange"))
    assert r["passed"], r
    assert r["metrics"]["stress_mean"]["rel_error"] == 0.0 and r["metrics"]["other_stress_rel"]["value"] == 0.0
    case = patch_output(tmp_path / "bad", s + np.array([1e-6, 0, 0, 0, 0, 0]), pressure=1.0e4 * (1 + 1e-10))
    r = checks.run_check(case, tmp_path / "bad", history("lagrange"))
    assert failed(r) == ["contact_pressure_mean", "other_stress_rel"], r
    assert r["metrics"]["other_stress_rel"]["value"] == pytest.approx(1e-10, rel=1e-6)


def hertz_output(out, a, p0, force):
    """cases/hertz_cylinder's meshes, undeformed, with Hertz's pressure p0 sqrt(1 - x^2/a^2) on the
    surface nodes of both bodies within |x| < a (x >= 0 on the cylinder; the flat's too), and the
    history's contact force ``force`` along y."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "hertz_cylinder")
    mesh, body = concatenate([body_mesh(b, 2) for b in case["lagrange"]["bodies"]])
    x = mesh.points
    on_contact = np.isclose(x[:, 1], 1.0, atol=0.02) & (x[:, 0] >= 0.0)  # near the flat's face y = 1
    p = np.where(on_contact, p0 * np.sqrt(np.clip(1 - x[:, 0]**2 / a**2, 0.0, None)), 0.0)
    output.write_mesh(out, "lagrange", mesh.cells, "quad")
    output.write_step(out, "lagrange", 0, 1, 1.0, np.pad(x, ((0, 0), (0, 1))), {"contact_pressure": p, "displacement": np.zeros((len(x), 3))},
                      {"stress": np.zeros((mesh.num_cells, 6))})
    h = history("lagrange")
    h["lagrange.contact_force_x"] = np.zeros(5)
    h["lagrange.contact_force_y"] = np.full(5, force)
    return case, h


def test_hertz(tmp_path):
    """Hertz's own pressure, sampled at the case's nodes, gives back its half-width and peak (the
    second moment of the piecewise-linear samples: measured +1.2 % at these 80 arc segments, the
    samples' own discretisation; peak exact) and the load from the
    contact force; a pressure 5 % wider fails half_width."""
    a, p0 = 0.107641, 0.059143
    case, h = hertz_output(tmp_path / "good", a, p0, -0.005)
    r = checks.run_check(case, tmp_path / "good", h)
    assert r["passed"], r
    assert abs(r["metrics"]["half_width"]["rel_error"]) < 0.015 and r["metrics"]["peak_pressure"]["rel_error"] < 1e-12
    assert r["metrics"]["load"]["rel_error"] == 0.0
    case, h = hertz_output(tmp_path / "wide", 1.05 * a, p0, -0.005)
    assert failed(checks.run_check(case, tmp_path / "wide", h)) == ["half_width"]


# ---- self_contact (a ring crushed onto itself) ---------------------------------------------------
def ring_output(out, pressed=(50, 150)):
    """cases/ring_self_contact's bodies at their reference positions (the ring 0.1 mm from each plate),
    contact pressure on the ring's inner nodes ``pressed`` (ids j of angle 2 pi j / 200: the top and
    bottom of the hole)."""
    from solvers.lagrange.mesh import body_mesh, concatenate

    case = load_case(CASES / "ring_self_contact")
    mesh, body = concatenate([body_mesh(b, 2) for b in case["lagrange"]["bodies"]])
    p = np.zeros(mesh.num_points)
    p[list(pressed)] = 1.0e5
    write(out, "lagrange", mesh.cells, [(0.0, mesh.points, {"contact_pressure": np.zeros(mesh.num_points)}, {}),
                                        (0.05, mesh.points, {"contact_pressure": p}, {})])
    return case, mesh


def ring_history(self_max=0.0, other_max=0.0, deepest_at=2, **residuals):
    """A diagnostics history with the explicit contact's penetration record: the run's maxima at the
    last record, the step's deepest at record ``deepest_at``."""
    h = history("lagrange", **residuals)
    n = len(h["time"])
    step = np.zeros(n)
    step[deepest_at] = max(self_max, other_max)
    h.update({"lagrange.contact_penetration": step,
              "lagrange.contact_penetration_self_max": np.full(n, self_max),
              "lagrange.contact_penetration_other_max": np.full(n, other_max)})
    return h


def test_self_contact(tmp_path):
    """Nothing inside anything: no penetration, the 2 pressed inner nodes counted as the self contact
    (their nearest facet is the ring's own). The penetration is the contact's record (measured every
    step, solvers/contact/penetration.py): 0.4 mm into a plate fails penetration_rel by 0.4 / 4.5 at
    the record's time; 0.4 mm into itself fails penetration_self_rel and penetration_rel; no pressure fails
    self_contact_nodes; an energy residual of 1e-13 fails its metric; a run without the record (a
    solver that keeps none) is refused by name."""
    case, mesh = ring_output(tmp_path / "good")
    r = checks.run_check(case, tmp_path / "good", ring_history())
    assert r["passed"], r
    assert r["metrics"]["penetration_rel"]["value"] == 0.0 and r["metrics"]["self_contact_nodes"]["value"] == 2.0
    assert r["reported"]["self_contact_pressure"] == pytest.approx(1.0e5)

    r = checks.run_check(case, tmp_path / "good", ring_history(other_max=4e-4, deepest_at=3))
    assert failed(r) == ["penetration_rel"]
    assert r["metrics"]["penetration_rel"]["value"] == pytest.approx(4e-4 / 0.0045, rel=1e-12)
    assert r["reported"]["penetration_time"] == 0.75

    r = checks.run_check(case, tmp_path / "good", ring_history(self_max=4e-4))
    assert failed(r) == ["penetration_rel", "penetration_self_rel"]
    assert r["metrics"]["penetration_self_rel"]["value"] == pytest.approx(4e-4 / 0.0045, rel=1e-12)
    assert r["reported"]["penetration_other_rel"] == 0.0

    with pytest.raises(ValueError, match="contact_penetration_self_max"):
        checks.run_check(case, tmp_path / "good", history("lagrange"))

    case, _ = ring_output(tmp_path / "none", pressed=())
    r = checks.run_check(case, tmp_path / "none", ring_history(energy=1e-13))
    assert failed(r) == ["energy_balance_rel", "self_contact_nodes"]


def test_a_nan_metric_says_why_in_the_summary_the_log_and_a_campaigns_message(tmp_path):
    """shock_reflection_obstacle ended at 0.12 s, 13 ms after the shock met the wall: the reflected
    shock is within 8 zones of the wall, so the reflected state's window is empty and p_reflected is
    NaN; its record says why (the reflected_shock check's own note), the log line too, and the
    message a campaign lists for the run (task.failed_metrics) carries it."""
    from orchestrator.campaign.task import failed_metrics

    case = tmp_path / "case"
    shutil.copytree(CASES / "shock_reflection_obstacle", case, ignore=shutil.ignore_patterns("out"))
    p = case / "case.toml"
    p.write_text(p.read_text().replace("end_time = 0.25", "end_time = 0.12").replace(
        "output_interval = 0.05", "output_interval = 0.06"))
    r = immerse("run", case, "--out", tmp_path / "out")
    assert r.returncode == 1, r.stdout + r.stderr
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    m = s["check"]["metrics"]["p_reflected"]
    assert m["value"] != m["value"] and not m["passed"]
    assert m["note"].startswith("the reflected shock (exact position 0.7367") and "of the wall at 0.7525 m" in m["note"]
    assert "check p_reflected: nan vs 15 (rel. error nan, tolerance 0.0003) FAILED: the reflected shock" in r.stdout
    msg = failed_metrics(s)
    assert msg.startswith("p_reflected: nan vs 15 (rel. error nan, tolerance 0.0003): the reflected shock"), msg
