"""The adapter contract: the same small set of hooks for every solver (cf. LLNL Smith's BasePhysics).

Hook order, once:      setup() -> [restart(path)] -> stable_dt()
Hook order, per coupled step n -> n+1 (driven by the coupler, see orchestrator.coupler):
    predict(dt)        internal + external forces, predictor velocity v* = v^{n-1/2} + dt M^-1 f
    interface()        what the coupler needs to build the constraints (empty when uncoupled)
    correct(impulse)   v^{n+1/2} = v* + M^-1 impulse; boundary conditions; positions, stresses
    remap(fractions)   background only: advection restricted by the bodies' volume fractions
    stable_dt()        the solver's own explicit limit for the next step (collective, same on all ranks)
    diagnostics()      mass, momentum, energies (collective; meaningful on the group root)
and when the coupler asks: write(index, step, time), checkpoint(path), step_limiter() (what sets the
stable step: local_limiter() of every rank); close() after the last command.
A foreground group that can_substep() may be told to take the coupled step in m substeps: snapshot(),
then m x (predict, correct) twice, restore() between the passes (adapters/substeps.py,
orchestrator/coupling/multirate.py).  A case with
``[probes]`` of the role: probe_points() after setup() and with every diagnostics() (solvers/probes.py).
Every hook is collective over the solver group's communicator `self.comm`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np


class SolverAdapter(ABC):
    role: str = ""

    def __init__(self, comm, case: dict, out_dir: Path):
        self.comm = comm
        self.case = case
        self.out_dir = Path(out_dir)

    @abstractmethod
    def setup(self) -> None: ...

    @abstractmethod
    def stable_dt(self) -> float: ...

    @abstractmethod
    def predict(self, dt: float, step: int, time: float) -> None: ...

    def interface(self) -> dict[str, np.ndarray]:
        return {}

    @abstractmethod
    def correct(self, impulse: dict[str, np.ndarray] | None = None) -> None: ...

    def remap(self, fractions: np.ndarray | None = None) -> None:
        return None

    def local_limiter(self) -> dict | None:
        """What sets this rank's part of the stable step (collective over the group: called on every
        rank), or None: {"dt": its step (s), "kind": "sound speed" | "cut zone" | "particle" | ...,
        "what": "element 12 of body 'block'" | "zone (38, 30)" | "particle 512", "at": [x, y(, z)],
        "detail": optional text}."""
        return None

    def step_limiter(self) -> dict | None:
        """What sets the group's stable step, on the group root (collective; rare: the coupler asks
        for it for a progress line or a message): the rank candidate with the smallest step."""
        local = self.local_limiter()
        if self.comm.size == 1:
            return local
        every = self.comm.gather(local, root=0)
        if self.comm.rank != 0:
            return None
        found = [c for c in every if c]
        return min(found, key=lambda c: c["dt"]) if found else None

    def probe_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the case's ``[probes]`` of this role (solvers/probes.py; collective): ``(X, x, v)``,
        initial positions, positions and velocities of the points this rank counts, each point on
        exactly one rank.  Asked right after setup() (then X is the start's) and at every
        diagnostics step.  A solver without points (the background) has none."""
        raise NotImplementedError(f"{self.role}: no points to probe")

    def central_difference(self) -> bool:
        """Whether the solver steps by explicit central differences (leapfrog, velocity Verlet): the
        coupler's step control then keeps the step from following a jittering stable step
        (orchestrator/step_control.py). An implicit or quasi-static solver says False."""
        return True

    def can_substep(self) -> bool:
        """Whether the group can take a coupling step in substeps of its own stable step (multi-rate,
        orchestrator/coupling/multirate.py): it then also gives snapshot() and restore()."""
        return False

    def describe(self) -> str:
        """What the group holds, in a few words for the start-up line (e.g. "9,600 zones, 1 material");
        called once after setup() (collective; meaningful on the group root)."""
        return ""

    def substep_cost(self) -> float:
        """What one substep costs, in background zone-steps (multi-rate's default weighs it against the
        background's zones, orchestrator/coupling/multirate.py pays): e.g. the group's element count."""
        return 1.0

    def substep_h_prev(self) -> float | None:
        """A central-difference group's last step (0 before its first): its substeps' kicks then take
        the coupling force at their own times (adapters/substeps.py); None (the default): the force
        ramp sampled at the substeps' middles."""
        return None

    def snapshot(self):
        """The group's whole state at the start of a coupling step (in memory), for restore()."""
        raise NotImplementedError(f"{self.role}: no substeps")

    def restore(self, state) -> None:
        """Take back the state snapshot() gave (the substeps' corrector pass starts from it)."""
        raise NotImplementedError(f"{self.role}: no substeps")

    def close(self) -> None:
        """Release what the solver holds (e.g. a LAMMPS instance) while MPI is still up."""
        return None

    @abstractmethod
    def diagnostics(self) -> dict[str, float]: ...

    @abstractmethod
    def write(self, index: int, step: int, time: float) -> None: ...

    @abstractmethod
    def checkpoint(self, path: Path) -> None: ...

    @abstractmethod
    def restart(self, path: Path) -> None: ...

    @abstractmethod
    def diagnostic_names(self) -> list[str]:
        """Fixed order of the values diagnostics() returns (sent to the coupler as one float64 buffer)."""
