"""The ALE side of coupled bodies (solvers/ale/blocked.py, coupled.py) with a body of prescribed
motion: a rigid piston face sweeping through the grid (the coupler's geometry computed exactly here
for a plane x = x_p, a 2-D channel of 2 zones).  References: the piston problem (exact shock,
e.g. Toro ch. 4): gas at rest rho0 = 1, p0 = 1, gamma = 1.4 pushed at up."""
import numpy as np
import pytest

from solvers.ale.coupled import BodyGeometry
from solvers.ale.solver import AleSolver

NY = 2


def channel(n):
    h = 1.0 / n
    return {"dimension": 2, "mode": "eulerian",
            "grid": {"lower": [0.0, 0.0], "upper": [1.0, NY * h], "cells": [n, NY]},
            "boundaries": {"x_lower": "wall", "x_upper": "outflow", "y_lower": "wall", "y_upper": "wall"},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0}]}


def piston_geometry(n, xp):
    """The body x < xp in the channel: covered zones and faces, the cut zones and their nodes."""
    h = 1.0 / n
    ic = int(np.floor(xp / h))
    frac = xp / h - ic
    j = np.arange(NY)
    full = (np.arange(ic)[None, :] + n * j[:, None]).ravel()
    cut = ic + n * j if frac > 0 else np.zeros(0, np.int64)
    zones = np.concatenate([full, cut])
    fr = np.concatenate([np.ones(full.size), np.full(cut.size, frac)])
    o = np.argsort(zones)
    nxf = ic + 1 if frac > 0 else ic  # x faces 0..ic are behind the surface
    fx = (np.arange(nxf)[None, :] + (n + 1) * j[:, None]).ravel()
    jy = np.arange(NY + 1)
    fy_full = (np.arange(ic)[None, :] + n * jy[:, None]).ravel()
    fy_cut = ic + n * jy if frac > 0 else np.zeros(0, np.int64)
    fy = np.concatenate([fy_full, fy_cut])
    cy = np.concatenate([np.ones(fy_full.size), np.full(fy_cut.size, frac)])
    nodes = np.unique(np.concatenate([[ic + a + (n + 1) * (jj + b) for a in (0, 1) for b in (0, 1)]
                                      for jj in range(NY)])) if frac > 0 else np.zeros(0, np.int64)
    return BodyGeometry(zones[o].astype(np.int64), fr[o],
                        ((fx.astype(np.int64), np.ones(fx.size)), (fy.astype(np.int64), cy)),
                        np.sort(cut).astype(np.int64), nodes.astype(np.int64))


def run_piston(n, up, end, x0=0.1):
    s = AleSolver(None, channel(n), bodies=piston_geometry(n, x0))
    t, k = 0.0, 0
    while t < end - 1e-12:
        dt = min(0.5 * s.stable_dt(), end - t)
        k += 1
        s.predict(dt)
        nn, nc = s._blk.nodes[0].size, s._blk.n_cut
        vs = np.zeros((nc, 2))
        vs[:, 0] = up
        # the piston moves at up since t = 0: v^{-1/2} = 0 (the first step's mean is up/2)
        s.correct(None, k, t + dt, coupling={"impulse": np.zeros((nn, 2)), "v_half": vs,
                                             "v_bar": vs if k > 1 else 0.5 * vs})
        t += dt
        s.remap(piston_geometry(n, x0 + up * t))
    return s, x0 + up * t


@pytest.mark.parametrize("up,shock,p_star,rho_star", [(1.0, 1.926650, 2.926650, 2.079156),
                                                      (0.5, 1.520656, 1.760328, 1.489881)])
def test_prescribed_piston_into_gas(up, shock, p_star, rho_star):
    """The body's surface terms (the volume it sweeps and the work of the fluid's reaction) and the
    remap of zones it covers give the exact shock state; balances to round-off; covered zones hold
    no gas."""
    n, end = 400, 0.25
    s, xp = run_piston(n, up, end)
    pts, cells, pd, cd = s.output()
    x = (np.arange(n) + 0.5) / n
    p, rho = cd["pressure"][:n], cd["density"][:n]
    star = (x > xp + 0.02) & (x < xp + 0.02 + 0.6 * (shock - up) * end)
    # measured (N = 400): p* 2.1e-6 / 7.3e-6 rel, rho* 8.3e-5 / -4.3e-5 rel (up = 1 / 0.5)
    assert abs(p[star].mean() / p_star - 1) < 3e-5
    assert abs(rho[star].mean() / rho_star - 1) < 3e-4
    # the shock (half-way pressure) within a zone of its exact position
    xs = x[np.flatnonzero(p > 0.5 * (p_star + 1.0))[-1]]
    assert abs(xs - (0.1 + shock * end)) < 1.5 / n
    d = s.diagnostics()
    # measured: mass 2.5e-15, energy 3e-17, momentum 5.5e-15 / 5.1e-14 (the piston's reaction is
    # momentum that crossed the boundary)
    assert abs(d["mass_balance_rel"]) < 1e-14
    assert abs(d["energy_balance_rel"]) < 1e-14
    assert abs(d["momentum_balance_rel"]) < 2e-13
    covered = cd["blocked_fraction"][:n] >= 1.0 - 1e-12
    assert np.all(s.M[s.block.out_zones][: n][covered] == 0.0)
    # the work the piston did is the energy that crossed into the gas: p* up t (per unit width,
    # channel of NY zones) up to the start-up (measured -2.4e-4 / -6.5e-4)
    assert d["interface_energy"] == pytest.approx(p_star * up * end * NY / n, rel=2e-3)
