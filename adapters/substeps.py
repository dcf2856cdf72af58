"""A foreground group's share of one coupling step in m substeps (multi-rate stepping: DESIGN.md
"Time", orchestrator/coupling/multirate.py for the scheme and its reasons).

The group advances from t^n to t^{n+1} = t^n + dt in m central-difference substeps of h = dt / m.
The coupling force on its surface nodes is a ramp over the coupling step, f(t^n + s dt) = rate +
s slope (0 <= s <= 1, per node): substep k takes the impulse h (rate + s_k slope) with s_k = (k + 1/2)
/ m, the ramp at its middle, so that the m impulses sum to dt rate + dt slope / 2 exactly.  Returned:

* ``v_mean`` (per surface node): the mean of the substeps' velocities v^{k+1/2}, the surface's
  displacement over the coupling step divided by dt (the velocity the constraint ties to the
  background's, and the volume the surface sweeps);
* ``work``: the impulses' work on the time-centred velocities (v^{k-1/2} + v^{k+1/2}) / 2, summed
  over the substeps and the nodes: the kinetic energy they gave the surface nodes, as the solver
  books every impulse;
* ``v_end``: the last substep's velocity (the group's v^{n+1/2} for the next step).

Used by adapters/runtime.py (a job's foreground ranks) and orchestrator/coupling/inprocess.py.
"""
from __future__ import annotations

from typing import Callable

import numpy as np


def substeps(step_once: Callable[[float, float, np.ndarray], None], velocities: Callable[[], np.ndarray],
             m: int, dt: float, t_end: float, rate: np.ndarray, slope: np.ndarray, v_start: np.ndarray):
    """Advance ``m`` substeps: ``step_once(h, t_k, impulse_k)`` takes one substep of h = dt / m to t_k
    with the surface impulse impulse_k (predict, then correct); ``velocities()`` gives the surface
    velocities after it; ``v_start``: those before the coupling step.  Returns (v_mean, work, v_end)."""
    h = dt / m
    t0 = t_end - dt
    rate = np.asarray(rate, dtype=np.float64)
    slope = np.asarray(slope, dtype=np.float64)
    v_prev = np.asarray(v_start, dtype=np.float64)
    v_sum = np.zeros_like(v_prev)
    work = 0.0
    for k in range(m):   # (a loop over substeps, not over nodes: each substep is the solver's kernels)
        imp = h * (rate + ((k + 0.5) / m) * slope)
        step_once(h, t_end if k == m - 1 else t0 + (k + 1) * h, imp)
        v = np.asarray(velocities(), dtype=np.float64)
        v_sum += v
        work += 0.5 * float(np.sum(imp * (v_prev + v)))
        v_prev = v
    return v_sum / m, work, v_prev
