"""Open faces (inflow / outflow) of the ALE grid: exact balances and a near-vacuum.

References: conservation identities (what crosses an open face is accounted for exactly: remap
fluxes of the faces and of the boundary nodes' dual cells, ghost-zone forces, inflow reactions),
and Toro's test 1-2-3 (Toro 2009, sec. 4.3.3: left (1, -2, 0.4), right (1, 2, 0.4), gamma 1.4:
two strong rarefactions, star state p* = 0.00189, rho* = 0.02185, at t = 0.15).
"""
import numpy as np
import pytest

from tests.solvers.ale.ale_helpers import FACES, advance, line
from solvers.ale.solver import AleSolver


def _blast(dim, mode):
    faces = {f: "outflow" for f in FACES[: 2 * dim]}
    faces["x_lower"] = {"inflow": {"density": 1.0, "velocity": [0.5] + [0.0] * (dim - 1), "pressure": 1.0}}
    sphere = " + ".join(f"({c} - 0.5)**2" for c in "xyz"[:dim]) + " < 0.04"
    return {"dimension": dim, "mode": mode,
            "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [10] * dim},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0, "velocity": [0.5] + [0.0] * (dim - 1)},
                        {"material": "gas", "region": sphere, "density": 2.0, "pressure": 5.0}],
            "boundaries": faces}


@pytest.mark.parametrize("mode", ["eulerian", "lagrangian"])
@pytest.mark.parametrize("dim", [2, 3])
def test_open_faces_balances(dim, mode):
    """A blast in a stream (inflow on x_lower, outflow on every other face; the waves leave through
    faces, edges and corners): mass, momentum and energy balances close to 1e-12."""
    s = AleSolver(None, _blast(dim, mode))
    advance(s, 0.5 if mode == "eulerian" else 0.15)
    d = s.diagnostics()
    assert abs(d["mass_balance_rel"]) < 1e-12
    assert abs(d["momentum_balance_rel"]) < 1e-12
    assert abs(d["energy_balance_rel"]) < 1e-12
    assert abs(d["boundary_work"]) > 1e-4 * d["total_energy"]  # something crossed the faces


def test_double_rarefaction_near_vacuum():
    n = 200
    cfg = {"dimension": 2, "mode": "eulerian",
           "grid": {"lower": [0.0, 0.0], "upper": [1.0, 1.0 / n], "cells": [n, 1]},
           "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
           "regions": [{"material": "gas", "density": 1.0, "pressure": 0.4, "velocity": [-2.0, 0.0]},
                       {"material": "gas", "region": "x > 0.5", "density": 1.0, "pressure": 0.4, "velocity": [2.0, 0.0]}],
           "boundaries": {"x_lower": "outflow", "x_upper": "outflow"}}
    s = AleSolver(None, cfg)
    advance(s, 0.15, 0.9)
    rho = line(s, s.rho, 0)[:, 0]
    e = line(s, s.e, 0)[:, 0]
    assert np.all(rho > 0) and np.all(e > 0) and np.all(np.isfinite(s.v))
    assert 0.5 * 0.02185 < rho.min() < 2.0 * 0.02185
    assert np.max(np.abs(rho - rho[::-1]) / rho) < 1e-12  # mirror symmetry about x = 0.5
    d = s.diagnostics()
    assert abs(d["mass_balance_rel"]) < 1e-12 and abs(d["energy_balance_rel"]) < 1e-12
    assert abs(d["momentum_balance_rel"]) < 1e-12
