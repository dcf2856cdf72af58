"""Velocity boundary conditions of the Lagrangian solver, applied after the predictor.

Each condition overwrites some velocity components of some nodes; the solver turns the change into a
reaction impulse m (v_after - v_before), which enters the momentum and energy balances. Conditions
apply in case order, so a later one wins where two overlap.

``traction`` conditions are loads, not velocities: kept as (node mask, traction) with their curves
(``curve``: [[t, factor], ...], None for none) for the solvers' load vectors (loads.py).
"""
from __future__ import annotations

import numpy as np

from solvers.expressions import compile_expression
from solvers.lagrange.nodal import rigid_wall

AXES = {"x": 0, "y": 1, "z": 2}
NAMES = ("x", "y", "z")


def _region(text: str, X: np.ndarray) -> np.ndarray:
    f = compile_expression(text, names=NAMES[: X.shape[1]])
    mask = np.asarray(f(*X.T), dtype=bool)
    return np.broadcast_to(mask, (len(X),)).copy()


class BoundaryConditions:
    def __init__(self, specs: list[dict], X: np.ndarray, tol: float):
        """specs: the case's [[boundaries]]; X: initial coordinates of this rank's nodes."""
        dim = X.shape[1]
        self.prescribed = []  # (node indices, component, value)
        self.walls = []       # (point, unit normal)
        self.tractions = []   # (node mask, traction (dim,)): surface loads (loads.py)
        self.traction_curves = []  # each traction's [[t, factor], ...] or None
        for spec in specs:
            kind = spec["type"]
            if kind == "fixed":
                nodes = np.flatnonzero(_region(spec["region"], X))
                self.prescribed += [(nodes, c, 0.0) for c in range(dim)]
            elif kind == "velocity":
                nodes = np.flatnonzero(_region(spec["region"], X))
                self.prescribed += [(nodes, AXES[c], float(val)) for c, val in spec["velocity"].items()]
            elif kind == "symmetry":
                c = AXES[spec["axis"]]
                nodes = np.flatnonzero(np.abs(X[:, c] - spec["at"]) <= tol)
                self.prescribed.append((nodes, c, 0.0))
            elif kind == "rigid_wall":
                n = np.asarray(spec["normal"], dtype=np.float64)
                p = np.asarray(spec["point"], dtype=np.float64)
                self.walls.append((p[:dim].copy(), (n / np.linalg.norm(n))[:dim].copy()))
            elif kind == "traction":
                t = np.array([float(spec["traction"].get(c, 0.0)) for c in NAMES[:dim]])
                self.tractions.append((_region(spec["region"], X), t))
                self.traction_curves.append(spec.get("curve"))
            else:  # the schema admits nothing else
                raise ValueError(f"boundaries.type = {kind!r}: unknown")

    def prescribed_arrays(self, n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """(held (n, dim) bool, values (n, dim)): which velocity components the conditions prescribe
        and to what (case order: a later condition wins), for the n nodes they were built on."""
        held = np.zeros((n, dim), bool)
        values = np.zeros((n, dim))
        for nodes, c, val in self.prescribed:
            held[nodes, c] = True
            values[nodes, c] = val
        return held, values

    def prescribed_velocity(self, v: np.ndarray) -> np.ndarray:
        """A copy of v with the prescribed components at their values (rigid walls not applied): the
        velocities a constraint solved before apply() must see. The predictor moves a held node by its
        force; apply() takes that back only after the contact impulses, and a contact that saw the
        predicted velocity of a held incline dragged the block resting on it along at g dt per step."""
        out = np.array(v, dtype=np.float64, copy=True)
        for nodes, c, val in self.prescribed:
            out[nodes, c] = val
        return out

    def apply(self, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        """Impose the conditions on the half-step velocity v (in place); x is the position at t^n."""
        for nodes, c, val in self.prescribed:
            v[nodes, c] = val
        for point, n in self.walls:
            rigid_wall(x, v, point, n, dt)
