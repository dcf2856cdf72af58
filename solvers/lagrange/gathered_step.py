"""The base of the integrators that solve the whole system on every rank (quasi_static.py,
implicit_dynamic.py): their step is the one they ask for (stable_dt returns the _dt_stable they set:
a load step, or the implicit step their control chose), predict only records the step given (no
predictor: correct solves the step), and _global turns this rank's nodal arrays into the global ones
every rank solves with."""
from __future__ import annotations

import time

import numpy as np
from mpi4py import MPI

from solvers.lagrange.solver import LagrangeSolver

__all__ = ["GatheredStepSolver", "RankShare", "on_root"]


def on_root(comm, fn, *args, **kw):
    """fn(*args, **kw) run on rank 0 of comm, its result broadcast to every rank (the others wait
    instead of doing the same solve side by side); an exception raised there is raised on every rank
    (none left waiting). One rank: fn here."""
    if comm.size == 1:
        return fn(*args, **kw)
    out = None
    if comm.rank == 0:
        try:
            out = (True, fn(*args, **kw))
        except Exception as err:
            out = (False, err)
    ok, value = comm.bcast(out, root=0)
    if not ok:
        raise value
    return value


class GatheredStepSolver(LagrangeSolver):
    WATCHES_HIGH_MODES = False   # no central difference: its own step control (implicit, quasi-static)

    def stable_dt(self) -> float:
        return self._dt_stable

    def _ask_for(self, step: float) -> None:
        """Ask the coupler for ``step``: it takes run.dt_scale times the step asked for (and lands on
        the end in two equal steps), so ask for a hair more than dt_scale's share."""
        self._dt_stable = step / self.case_dt_scale * (1.0 + 1e-12)

    def _asked(self) -> float:
        """The step this solver asks for (the inverse of _ask_for)."""
        return self._dt_stable * self.case_dt_scale / (1.0 + 1e-12)

    def step_choice(self) -> tuple[str, str]:
        """(kind of limit, what chose it) for the step this solver asks for (subclasses say)."""
        return "step control", "the solver's own step"

    def local_limiter(self) -> dict | None:
        """No element sets this step (no stability limit): the integrator chose it (the same on every
        rank; rank 0 says it)."""
        if self.comm.rank != 0:
            return None
        kind, what = self.step_choice()
        return {"dt": self._asked(), "kind": kind, "what": what, "at": None}

    def predict(self, dt: float) -> None:
        self.dt = dt

    def _global(self, a: np.ndarray) -> np.ndarray:
        """(n_global, k) from this rank's (nn_local, k): the owned rows summed over the ranks
        (collective)."""
        out = np.zeros((self.n_nodes_global, a.shape[1]))
        out[self.part.nodes[self.part.owned]] = a[self.part.owned]
        return self._allsum(out)


class RankShare:
    """How the ranks of a gathered solve share one step's work (implicit_step._svk's ``ranks``):

    * elements: the elements' matrices and forces of a body, either every rank evaluating all of
      them or each rank a contiguous share, gathered by Allgatherv in element order; both give every
      rank the same arrays, bit for bit what one rank computes (an element's values are its own).
      Which, is measured at a body's second evaluation (the first builds the reference gradients'
      cache; every rank evaluates all and the shares are gathered once, both timed, the slowest
      rank's times): split when the evaluation time it saves,
      (1 - 1/ranks) of it, exceeds the gathering's. Gathering dense element matrices moves 8 (a d)^2
      bytes an element to every rank: more than the numba St. Venant-Kirchhoff kernel costs on 2-D
      quads (0.9 us), less than the neo-Hookean numpy elements';
    * on_root: a solve (the sparse direct solve, the contact's KKT solve) runs on rank 0 and its
      result is broadcast: the other ranks wait instead of factorising the same matrix at the same
      time (two SuperLU factorisations side by side made 2 ranks 1.3x slower than one on 2744
      hexahedra), and every rank continues from the same result. An exception raised there is
      raised on every rank.

    blocks: the solver's [(cells, ...), ...]; points: the global points."""

    def __init__(self, comm, blocks, points):
        self.comm = comm
        self.points = points
        self.cells = [cells for cells, *_ in blocks]
        self.split: dict = {}            # (block, function) -> "measure", then bool (class docstring)
        self.shares = []
        for cells in self.cells:
            counts = np.array([len(c) for c in np.array_split(np.arange(len(cells)), comm.size)])
            lo = int(counts[: comm.rank].sum())
            self.shares.append((lo, np.ascontiguousarray(cells[lo:lo + counts[comm.rank]]), counts))

    def _gather(self, b, ke, fe):
        _, mine, counts = self.shares[b]
        a, d = mine.shape[1], self.points.shape[1]
        ke_all, fe_all = np.empty((int(counts.sum()), a * d, a * d)), np.empty((int(counts.sum()), a, d))
        self.comm.Allgatherv(np.ascontiguousarray(ke, dtype=np.float64), [ke_all, counts * (a * d) ** 2])
        self.comm.Allgatherv(np.ascontiguousarray(fe, dtype=np.float64), [fe_all, counts * (a * d)])
        return ke_all, fe_all

    def elements(self, b, fn, u0, u1, mu, lam):
        lo, mine, counts = self.shares[b]
        split = self.split.get((b, fn))
        if split is None:                # (the first evaluation: all, building the gradients' cache)
            self.split[(b, fn)] = "measure"
            return self._checked(fn, self.points, self.cells[b], u0, u1, mu, lam)
        if split == "measure":           # (the second: both ways, timed)
            t0 = time.perf_counter()
            ke, fe = self._checked(fn, self.points, self.cells[b], u0, u1, mu, lam)
            t1 = time.perf_counter()
            self._gather(b, ke[lo:lo + len(mine)], fe[lo:lo + len(mine)])
            t2 = time.perf_counter()
            every, gather = (self.comm.allreduce(t, op=MPI.MAX) for t in (t1 - t0, t2 - t1))
            self.split[(b, fn)] = bool(every * (1.0 - 1.0 / self.comm.size) > gather)
            return ke, fe
        if not split:
            return fn(self.points, self.cells[b], u0, u1, mu, lam)
        a, d = mine.shape[1], self.points.shape[1]
        if not len(mine):
            return self._gather(b, *self._checked(lambda: (np.zeros((0, a * d, a * d)), np.zeros((0, a, d)))))
        return self._gather(b, *self._checked(fn, self.points, mine, u0, u1, mu, lam))

    def _checked(self, fn, *args):
        """fn(*args) on every rank; if it raised on any, it raises on every one (an inverted element
        is one rank's share: the others would wait in the gather)."""
        err, out = None, None
        try:
            out = fn(*args)
        except Exception as e:
            err = e
        failed = [m for m in self.comm.allgather(None if err is None else f"{type(err).__name__}: {err}") if m]
        if failed:
            raise err if err is not None else RuntimeError(f"another rank's elements: {failed[0]}")
        return out

    def on_root(self, fn, *args, **kw):
        return on_root(self.comm, fn, *args, **kw)
