"""AleSolver API: configuration, initial conditions, energy sources, output, checkpoint/restart."""
import numpy as np
import pytest

from tests.solvers.ale.ale_helpers import advance, sod_config, uniform_config
from solvers.ale import solver as ale_solver
from solvers.ale.solver import AleSolver
from solvers.elements import hex_bvectors, quad_bvectors


@pytest.mark.parametrize("mode", ["eulerian", "lagrangian"])
def test_checkpoint_restart_is_bitwise(tmp_path, mode):
    cfg = sod_config(2, 100, mode=mode)
    a = AleSolver(None, cfg)
    t, k = advance(a, 0.05)
    a.checkpoint(tmp_path / "c.h5")
    advance(a, 0.1, t0=t, step0=k)
    b = AleSolver(None, cfg)
    b.restart(tmp_path / "c.h5")
    assert b.step == k and b.time == pytest.approx(t, rel=1e-15)
    advance(b, 0.1, t0=t, step0=k)
    for name in AleSolver.ARRAYS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.diagnostics() == b.diagnostics()


@pytest.mark.parametrize("dim", [2, 3])
def test_output(dim):
    cfg = uniform_config(dim, 3, [0.5] + [0.0] * (dim - 1), {}, mode="lagrangian")
    cfg["grid"]["cells"] = [3, 2, 4][:dim]
    s = AleSolver(None, cfg)
    advance(s, 0.05)
    pts, cells, pdata, cdata = s.output()
    nn = int(np.prod(np.array(cfg["grid"]["cells"]) + 1))
    ne = int(np.prod(cfg["grid"]["cells"]))
    assert pts.shape == (nn, 3) and cells.shape == (ne, 4 if dim == 2 else 8)
    assert np.issubdtype(cells.dtype, np.integer) and cells.min() == 0 and cells.max() == nn - 1
    b = np.empty((cells.shape[1], dim))
    geom = hex_bvectors if dim == 3 else quad_bvectors
    assert all(geom(np.ascontiguousarray(pts[c, :dim]), b)[0] > 0 for c in cells)
    assert pdata["velocity"].shape == (nn, 3)
    assert set(cdata) == {"density", "pressure", "specific_internal_energy", "sound_speed", "artificial_viscosity"}
    assert all(v.shape == (ne,) for v in cdata.values())
    assert np.array_equal(cdata["density"], s.zone_field(s.rho)) and np.ptp(cdata["density"]) > 0.01
    assert np.allclose(cdata["sound_speed"], np.sqrt(1.4 * cdata["pressure"] / cdata["density"]), rtol=1e-3)
    assert np.allclose(cdata["pressure"], 0.4 * cdata["density"] * cdata["specific_internal_energy"], rtol=1e-14)


def test_regions_and_specific_energy():
    cfg = uniform_config(2, 4, [0.0, 0.0], {}, mode="lagrangian")
    cfg["regions"].append({"material": "gas", "region": "x > 0.5", "density": 2.0,
                           "specific_internal_energy": 3.0, "velocity": [1.0, 0.0]})
    s = AleSolver(None, cfg)
    rho = s.zone_field(s.rho).reshape(4, 4)
    p = s.zone_field(s.p).reshape(4, 4)
    assert np.all(rho[:, 2:] == 2.0) and np.all(rho[:, :2] == 1.3)
    assert np.allclose(p[:, 2:], 0.4 * 2.0 * 3.0) and np.allclose(p[:, :2], 0.7)
    # nodes on the interface get the mass-weighted mean velocity 2/(2+1.3); walls stop the normal part
    u = s.node_field(s.v)[:, 0].reshape(5, 5)
    assert np.allclose(u[1:4, 2], 2.0 / 3.3) and np.all(u[1:4, 3] == 1.0) and np.all(u[:, 4] == 0.0)


@pytest.mark.parametrize("at,shares", [([0.0, 0.0], {(0, 0): 1.0}),
                                       ([0.5, 0.25], {(1, 0): 0.25, (2, 0): 0.25, (1, 1): 0.25, (2, 1): 0.25}),
                                       ([0.3, 0.9], {(1, 3): 1.0})])
def test_energy_source_placement(at, shares):
    cfg = uniform_config(2, 4, [0.0, 0.0], {}, mode="lagrangian")
    base = AleSolver(None, cfg)
    cfg["energy_sources"] = [{"energy": 2.0, "at": at}]
    s = AleSolver(None, cfg)
    de = (s.zone_field(s.M * s.e) - base.zone_field(base.M * base.e)).reshape(4, 4)
    expect = np.zeros((4, 4))
    for (i, j), w in shares.items():
        expect[j, i] = 2.0 * w
    assert np.allclose(de, expect, atol=1e-14)
    assert s.diagnostics()["total_energy"] == pytest.approx(base.diagnostics()["total_energy"] + 2.0, rel=1e-14)


def test_configuration_errors():
    cfg = uniform_config(2, 4, [0.0, 0.0], {})
    cfg["regions"][0]["region"] = "x < 0.5"
    with pytest.raises(ValueError, match=r"zone \(2, 0\).*not covered"):
        AleSolver(None, cfg)
    # several materials per zone: Eulerian mode only (mixed.py)
    cfg = uniform_config(2, 4, [0.0, 0.0], {}, mode="lagrangian")
    cfg["materials"]["water"] = {"eos": "stiffened_gas", "gamma": 4.4, "p_inf": 6e8}
    cfg["regions"].append({"material": "water", "region": "x < 0.5", "density": 1000.0, "pressure": 1e5})
    with pytest.raises(ValueError, match="several materials .* need mode = 'eulerian'"):
        AleSolver(None, cfg)
    cfg = uniform_config(2, 4, [0.0, 0.0], {})
    cfg["materials"]["vacuum"] = {"eos": "void"}
    cfg["regions"] = [{"material": "vacuum"}]
    with pytest.raises(ValueError, match="void only"):
        AleSolver(None, cfg)


def test_defaults_and_lagrangian_remap_is_a_no_op():
    s = AleSolver(None, uniform_config(2, 4, [0.1, 0.0], {}, mode="lagrangian"))
    assert (s.q_lin, s.q_quad, s.hg) == (*ale_solver.DEFAULT_VISCOSITY["lagrangian"], ale_solver.DEFAULT_HOURGLASS)
    e = AleSolver(None, uniform_config(2, 4, [0.1, 0.0], {}))
    assert (e.q_lin, e.q_quad) == ale_solver.DEFAULT_VISCOSITY["eulerian"]
    s.predict(0.5 * s.stable_dt())
    s.correct(None, 1, 0.0)
    x = s.x.copy()
    s.remap()
    assert np.array_equal(s.x, x) and not np.array_equal(x, s.block.X)
