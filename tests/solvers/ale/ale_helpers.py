"""Shared configurations and a time loop for the ALE solver tests (not a test module)."""
from __future__ import annotations

import numpy as np

from solvers.ale.solver import AleSolver

FACES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")


def sod_config(dim=2, n=400, axis=0, mode="eulerian", ntrans=1, faces=None):
    """Sod tube of length 1 along ``axis`` (gamma 1.4, (1, 0, 1) | (0.125, 0, 0.1) at 0.5), one
    zone of the same width across (walls everywhere unless ``faces``)."""
    lower = [0.0] * dim
    upper = [ntrans / n] * dim
    cells = [ntrans] * dim
    upper[axis] = 1.0
    cells[axis] = n
    name = "xyz"[axis]
    return {"dimension": dim, "mode": mode,
            "grid": {"lower": lower, "upper": upper, "cells": cells},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": 1.0, "pressure": 1.0},
                        {"material": "gas", "region": f"{name} > 0.5", "density": 0.125, "pressure": 0.1}],
            "boundaries": dict(faces or {})}


def sedov_config(dim, n, energy):
    """Point blast at the origin of a quadrant/octant [0, 1]^dim with walls (Lagrangian)."""
    return {"dimension": dim, "mode": "lagrangian",
            "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [n] * dim},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": 1.0, "pressure": 1e-6}],
            "energy_sources": [{"energy": energy, "at": [0.0] * dim}]}


def uniform_config(dim, n, velocity, faces, mode="eulerian", density=1.3, pressure=0.7):
    return {"dimension": dim, "mode": mode,
            "grid": {"lower": [0.0] * dim, "upper": [1.0] * dim, "cells": [n] * dim},
            "materials": {"gas": {"eos": "ideal_gas", "gamma": 1.4}},
            "regions": [{"material": "gas", "density": density, "pressure": pressure, "velocity": list(velocity)}],
            "boundaries": dict(faces)}


def periodic(dim):
    return {f: "periodic" for f in FACES[: 2 * dim]}


def advance(s: AleSolver, t_end: float, scale: float = 0.5, t0: float = 0.0, step0: int = 0):
    """The coupler's loop: dt = scale * stable step, clipped to land on t_end."""
    t, step = t0, step0
    while t < t_end - 1e-14 * max(1.0, abs(t_end)):
        dt = min(scale * s.stable_dt(), t_end - t)
        step += 1
        t += dt
        s.predict(dt)
        s.correct(None, step, t)
        s.remap()
    return t, step


def run(cfg, t_end, scale=0.5):
    s = AleSolver(None, cfg)
    advance(s, t_end, scale)
    return s


def line(s: AleSolver, field: np.ndarray, axis: int) -> np.ndarray:
    """A zone field of a tube along ``axis`` as (n, transverse...) with the tube axis first."""
    cells = list(s.block.cells)
    a = s.zone_field(field).reshape(cells[::-1])  # output order: x fastest
    return np.moveaxis(a, s.dim - 1 - axis, 0).reshape(cells[axis], -1)


def node_line(s: AleSolver, comp: int, axis: int) -> np.ndarray:
    cells = [c + 1 for c in s.block.cells]
    a = s.node_field(s.v)[:, comp].reshape(cells[::-1])
    return np.moveaxis(a, s.dim - 1 - axis, 0).reshape(cells[axis], -1)
