"""Probes of node and particle sets, and of the background's fields at points (case ``[probes]``,
orchestrator/schema/probes.py): one number per probe at every diagnostics step, appended to the
solver's diagnostics as ``probe_<name>`` (PointProbes, FieldProbes; probes_for picks by role).

A figure read from the output steps (a peak, a zero crossing) depends on how often the run writes
its fields; the same figure read from a probe's history does not (the diagnostics are recorded at
every step, or every ``run.diagnostics_every``).  LS-DYNA users know these as nodal time histories
(*DATABASE_HISTORY_NODE, nodout).

The set of a probe is fixed at the start: the points whose initial position lies in its box.  An
adapter hands over its points as ``(X, x, v)``: initial positions, current positions and velocities
of the points this rank counts (every point on exactly one rank), so the sums need one reduction
per step over the group (two: sums, extrema), and nothing at all when the case has no probe.
"""
from __future__ import annotations

import numpy as np

_COMPONENT = {"x": 0, "y": 1, "z": 2}


class PointProbes:
    """The probes of one solver role (``specs``: the normalised ``case["probes"]``)."""

    def __init__(self, specs: dict | None, role: str, comm):
        self.comm = comm
        self.probes = [(name, p) for name, p in (specs or {}).items() if p["role"] == role]
        self.names = [f"probe_{name}" for name, _ in self.probes]

    def __bool__(self) -> bool:
        return bool(self.probes)

    def _masks(self, X: np.ndarray) -> list[np.ndarray]:
        dim = X.shape[1]
        out = []
        for _, p in self.probes:
            lo = np.asarray(p["box"]["lower"][:dim])
            hi = np.asarray(p["box"]["upper"][:dim])
            out.append(np.all((X >= lo) & (X <= hi), axis=1))
        return out

    def start(self, adapter, role: str) -> None:
        """At set-up, before a restart moves the points: every probe's box holds a point."""
        self.check_sets(adapter.probe_points()[0], role)

    def values_of(self, adapter) -> dict[str, float]:
        return self.values(*adapter.probe_points())

    def check_sets(self, X: np.ndarray, role: str) -> None:
        """Every probe's box holds a point at the start (collective): else one line naming it."""
        from mpi4py import MPI

        counts = np.array([m.sum() for m in self._masks(X)], dtype=np.int64)
        self.comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
        for (name, p), n in zip(self.probes, counts):
            if n == 0:
                raise ValueError(f"probes.{name}.box = {p['box']}: holds no {role} point at the start "
                                 "(a probe follows the points whose initial position lies in its box)")

    def values(self, X: np.ndarray, x: np.ndarray, v: np.ndarray) -> dict[str, float]:
        """Every probe's value now (collective over the group; the same on every rank)."""
        from mpi4py import MPI

        k = len(self.probes)
        sums = np.zeros(2 * k)                    # sum, count
        ext = np.full(2 * k, -np.inf)             # max, -min
        for i, ((_, p), mask) in enumerate(zip(self.probes, self._masks(X))):
            q = {"displacement": lambda: x[mask] - X[mask], "velocity": lambda: v[mask],
                 "position": lambda: x[mask]}[p["quantity"]]()
            c = p["component"]
            a = np.linalg.norm(q, axis=1) if c == "magnitude" else q[:, _COMPONENT[c]]
            sums[2 * i], sums[2 * i + 1] = a.sum(), a.size
            if a.size:
                ext[2 * i], ext[2 * i + 1] = a.max(), -a.min()
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
            self.comm.Allreduce(MPI.IN_PLACE, ext, op=MPI.MAX)
        out = {}
        for i, (name, p) in enumerate(self.probes):
            r = p["reduce"]
            out[f"probe_{name}"] = float(sums[2 * i] / max(sums[2 * i + 1], 1.0) if r == "mean"
                                         else ext[2 * i] if r == "max" else -ext[2 * i + 1])
        return out


class FieldProbes:
    """The probes of the background (``point``): the zone holding each point, its density, pressure,
    specific internal energy, sound speed or velocity component (the adapter's values_at)."""

    def __init__(self, specs: dict | None, role: str, comm):
        self.comm = comm
        self.probes = [(name, p) for name, p in (specs or {}).items() if p["role"] == role]
        # every point of every probe: a line's N points are N histories probe_<name>_<k>
        self.points, self.names, self.quantities = [], [], []
        for name, p in self.probes:
            q = (p["quantity"], None if p["component"] is None else
                 (-1 if p["component"] == "magnitude" else _COMPONENT[p["component"]]))
            if "line" in p:
                a, b, n = np.array(p["line"]["start"]), np.array(p["line"]["end"]), p["line"]["points"]
                pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
                names = [f"probe_{name}_{k}" for k in range(n)]
            else:
                pts, names = np.array([p["point"]]), [f"probe_{name}"]
            self.points += list(pts)
            self.names += names
            self.quantities += [q] * len(names)

    def __bool__(self) -> bool:
        return bool(self.probes)

    def start(self, adapter, role: str) -> None:
        """Nothing to check at the start (the case's check put every point in the fixed grid)."""

    def values_of(self, adapter) -> dict[str, float]:
        kinds = sorted(set(self.quantities), key=self.quantities.index)
        v = adapter.values_at(np.array(self.points), kinds)     # (kinds, points)
        return {n: float(v[kinds.index(q), i]) for i, (n, q) in enumerate(zip(self.names, self.quantities))}


def probes_for(specs: dict | None, role: str, comm):
    """The probes of ``role``: of its points (PointProbes) or, for the background, of its fields at
    points (FieldProbes)."""
    mine = {n: p for n, p in (specs or {}).items() if p["role"] == role}
    if any("point" in p or "line" in p for p in mine.values()):
        return FieldProbes(mine, role, comm)
    return PointProbes(mine, role, comm)
