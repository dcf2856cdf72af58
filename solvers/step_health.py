"""Step-to-step instability of an explicit central-difference scheme, caught while it grows.

An unstable central difference (a step beyond a mode's limit, or a step sequence that pumps the
highest modes: orchestrator/step_control.py) grows a mode that turns from one step to the next. The
solver's energy balance cannot see it: it books the discrete work of the internal forces, exact by
construction for any step, so a struck bar whose zigzag mode grew to 2.6 GPa (against 40 MPa) still
read 4e-15. What it cannot hide:

* energy made from nothing: the bodies' kinetic energy plus the energy their stresses stored (the
  stress power integrated element by element, independent of the nodal work) exceeds what was put in
  (the initial energy and every external work: boundaries, coupling, contact, gravity, loads).
  Dissipation (bulk viscosity, hourglass control, contact) only lowers it; the staggering of the two
  sums is one step's work. Measured on that bar: created / supplied 88 by step 40 and 765 by step 80
  with the clipped steps, -1 % at constant steps;
* the mode itself: with dv = v^{n+1/2} - v^{n-1/2} a node's velocity change in the step,
  E_hf = sum m |dv^n - dv^{n-1}|^2 / 8 is about the kinetic energy of a mode that turns each step and
  O(dt^2) of it for motions the steps resolve; where it is largest is where the mode grows.

The watch stops the run once, after MIN_STEPS steps, the energy created exceeds CREATED times the
energy supplied, naming the node where E_hf is largest and the step from which E_hf grew.
"""
from __future__ import annotations

from collections import deque

import numpy as np

MIN_STEPS = 20
"""Steps with energy in the bodies before the watch judges (counted from the first step that supplied
any: a body the loading reaches late starts then): the staggering of kinetic and stored energy is one
step's work, the whole supply at first (the struck bar: created / supplied 1.6 at step 1, 0.04 by
step 40)."""

CREATED = 2.0
"""The multiple of the supplied energy the scheme may not create. Stable runs: <= 0 (dissipation),
but the staggering of the two sums (the stored energy at t^{n+1}, the work up to the mean velocity)
is up to one step's work, all of the supply while it still grows geometrically: a body reached by a
smooth acoustic front read 0.6 for a few steps (acoustic_transmission); it cannot exceed 1. An
instability passes 2 within a few steps of passing 0.5 (the clipped bar: steps 23 and 27)."""

HISTORY = 200
"""Steps of E_hf kept to name the step the growth started from."""


class GrowthWatch:
    """Fed once a step; :meth:`update` is True when the scheme has made energy from nothing."""

    def __init__(self):
        self.hf: deque[float] = deque(maxlen=HISTORY)
        self.steps: deque[int] = deque(maxlen=HISTORY)
        self.seen = 0
        self.created_max = 0.0   # the largest created / supplied after MIN_STEPS (diagnostics)
        self.last = 0.0

    def update(self, step: int, e_hf: float, created: float, supplied: float) -> bool:
        if supplied > 0.0:
            self.seen += 1
        self.hf.append(e_hf)
        self.steps.append(step)
        rel = created / supplied if supplied > 0.0 else (0.0 if created <= 0.0 else np.inf)
        if not np.isfinite(rel) and not np.isinf(rel):
            rel = np.inf
        self.last = rel
        if self.seen < MIN_STEPS:
            return False
        self.created_max = max(self.created_max, rel)
        return bool(rel > CREATED)

    def since(self) -> int:
        """The step from which E_hf has grown: its last minimum in the kept history."""
        a = np.fromiter(self.hf, float)
        return int(self.steps[int(np.argmin(a))]) if len(a) else 0

    def growth(self) -> float:
        """E_hf now over its last minimum."""
        a = np.fromiter(self.hf, float)
        lo = float(a.min()) if len(a) else 0.0
        return float(a[-1] / lo) if lo > 0.0 else np.inf
