"""The ALE solver's error: its own module, below the solver and its blocked-zone phase, which both
raise it."""
from __future__ import annotations


class SolverError(RuntimeError):
    """A physical failure (tangled zone, invalid EOS state) naming the zone, step, time and state."""
