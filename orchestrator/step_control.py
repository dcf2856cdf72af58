"""How the time loop chooses each step from the solver groups' stable steps (the coupler's clock).

Why it is shaped this way. The explicit solvers step by central differences with a variable step,
``v^{n+1/2} = v^{n-1/2} + (dt^{n-1/2} + dt^{n+1/2})/2 a^n``, ``x^{n+1} = x^n + dt^{n+1/2} v^{n+1/2}``.
That is a chain of velocity-Verlet steps, one of size dt^{n+1/2} per step, and each conserves its own
modified energy per mode, ``E_h = |v|^2 + w^2 |x|^2 (1 - (w h / 2)^2)``. Steps of one size are stable
up to ``w h = 2``; a change of size changes the energy the next steps conserve, by up to the ratio of
the factors ``1 - (w h / 2)^2``, and that ratio is large for the highest modes (``w h`` near
``2 dt_scale``). A monotone sequence of steps stays bounded (the factors telescope), but a sequence
that jitters pumps the highest modes (parametric resonance; Skeel, BIT 33, 1993): steps clipped onto
output times 1.5 steps apart (step, half step, step, ...) grew an elastic bar's zigzag mode by 1.8
per two steps, to +3.8 GPa where the exact stress is -40 MPa, with every balance still at round-off.

The rules, in the order :meth:`StepControl.next` applies them:

1. Outputs and checkpoints never change a step: they are written at the first step that reaches
   their time, stamped with that step's own time (the solution is the same bits for any output
   interval).
2. A fall of the stable step is followed at once (it is a limit).
3. A rise is followed only as far as the smallest stable step of the last ``WINDOW`` steps and by at
   most ``GROWTH`` per step: a stable step that fluctuates faster than ``WINDOW`` steps (a jittering
   limiter, two zones trading the minimum) leaves the step constant, and a rise becomes a ramp.
   LULESH holds its step in the same spirit (no rise below 10 %, at most 20 % a cycle).
4. The end time is reached exactly, the time left split evenly over the last two steps when it is
   more than one step (never a sliver of a step after a full one).

The state (the last step, the window) is checkpointed, so a restart continues with the same steps.
"""
from __future__ import annotations

from collections import deque

import numpy as np

WINDOW = 8
"""Steps over which a rise of the stable step must hold before the step follows it (the smallest of
them is followed). Only fluctuations of period 3.5 steps or less reach the highest modes' resonance at
dt_scale 0.9 (a modulation at twice their phase per step, 2 (pi - arccos(1 - 1.8^2/2)) = 1.8 rad a
step), and the window keeps a margin for undamped bodies. Measured on a struck steel bar (100 hexahedra,
nu = 0, 5e4 steps, stable steps proposed at random): with the default bulk viscosity 4 steps hold every
sequence tried (max |stress| 4.3e7 Pa against the exact 4e7; unfiltered: 2e11 or an inverted element);
without it (q = 0) 4 steps let a uniform random proposal in [0.5, 1] invert an element, 8 hold it
(7e7 Pa, the undamped ringing), a random walk of 20 % a step still grows (1.5e8 Pa; 16 steps hold it).
The price: steps 1.3 % smaller on a random walk of 1 % a step, a lag of WINDOW steps on a rise."""

GROWTH = 1.1
"""The most a step may exceed the one before (a rise is a ramp: about 7 steps to double)."""

ROUND_OFF = 1e-12
"""Relative distance under which a time counts as reached (the end, an output time)."""

LAST_STEP_STRETCH = 1e-6
"""The most the last step may exceed the step (as a fraction of it) to land on the end time instead
of leaving a sliver: the summed time carries a round-off of about n eps t after n steps, 1e-9 of
the step after 8192 equal steps to 0.46 s, and ROUND_OFF of the step alone split such a run's last
step into two halves (a step change that spoiled the order-of-accuracy tests' answers)."""


class StepControl:
    """The coupler's step sequence: :meth:`next` gives the step from the groups' smallest stable step
    (already multiplied by dt_scale) and the time; :meth:`state` / :meth:`load` for checkpoints."""

    def __init__(self, end_time: float, window: int = WINDOW, growth: float = GROWTH):
        self.end_time = float(end_time)
        self.growth = float(growth)
        self.recent: deque[float] = deque(maxlen=int(window))
        self.dt = 0.0   # the last step the rules chose (0 before the first)

    def next(self, t: float, proposed: float) -> tuple[float, float, bool]:
        """(dt, t + dt, done) for the step from ``t``; ``proposed`` = dt_scale x the smallest stable
        step. ``done``: the step lands on the end time."""
        self.recent.append(proposed)
        if self.dt == 0.0 or proposed < self.dt:
            dt = proposed                                    # rule 2: a limit, followed at once
        else:                                                # rule 3: only what held, as a ramp
            dt = max(self.dt, min(self.growth * self.dt, min(self.recent)))
        self.dt = dt
        left = self.end_time - t
        if left <= dt * (1.0 + LAST_STEP_STRETCH):            # rule 4: the last step
            return left, self.end_time, True
        if dt < left < 2.0 * dt:                             # the two last steps, equal
            dt = 0.5 * left
        return dt, t + dt, False

    def state(self) -> np.ndarray:
        """[dt, window length, the window's steps...] for a checkpoint."""
        return np.array([self.dt, float(len(self.recent)), *self.recent])

    def load(self, a: np.ndarray) -> None:
        a = np.asarray(a, dtype=float)
        self.dt = float(a[0])
        self.recent.clear()
        self.recent.extend(float(x) for x in a[2:2 + int(a[1])])


def next_time(t: float, interval: float | None) -> float:
    """The first multiple k * interval after t (inf without an interval): when the next output or
    checkpoint is due. Derived from t, not counted: a restart with another interval continues on the
    new interval's times, and a step across several of them writes once. A time within ROUND_OFF of
    t counts as reached."""
    if not interval:
        return np.inf
    k = np.floor(t / interval * (1 + ROUND_OFF)) + 1.0
    return float(k * interval)


def reached(t: float, due: float) -> bool:
    """Whether time t has reached the due time (within round-off)."""
    return t >= due * (1.0 - ROUND_OFF)
