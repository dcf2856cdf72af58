"""A foreground group's share of one coupling step in m substeps (multi-rate stepping: DESIGN.md
"Time", orchestrator/coupling/multirate.py for the scheme and its reasons).

The group advances from t^n to t^{n+1} = t^n + dt in m central-difference substeps of h = dt / m.
The coupling force on its surface nodes is a ramp over the coupling step, f(t^n + s dt) = rate +
s slope (0 <= s <= 1, per node).  A central-difference group (``h_prev`` given: the Lagrangian
solver) kicks its velocities at the substeps' start times t_k = t^n + k h, each kick of length
(h_{k-1} + h_k) / 2: substep k takes the impulse w_k f(t_k), s_k = k / m, w_0 = (h_prev + h) / 2
(h / 2 at the run's first step, h_prev = 0), w_k = h after it -- the force at the time the kick
stands for, as the solver's own forces are.  Sampling the ramp at the substeps' middles instead,
(k + 1/2) / m with weights h (the first scheme, kept for groups that give no ``h_prev``: SPH through
LAMMPS), put the force h/2 early at every kick and a whole h/2 F too much into the first step: the
multi-rate scheme was first order in the coupling step (issue 46's order test: the piston on a gas
spring, observed order 1.01 against 3.6 now; tests/cases/test_time_order.py).  Returned:

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


def kick_weights(m: int, dt: float, h_prev: float | None) -> tuple[np.ndarray, np.ndarray]:
    """(s_k, w_k) of the m substeps of a coupling step dt: where each samples the ramp and the length
    of its kick (module docstring); ``h_prev`` None: the substeps' middles, weights h."""
    h = dt / m
    k = np.arange(m, dtype=np.float64)
    if h_prev is None:
        return (k + 0.5) / m, np.full(m, h)
    w = np.full(m, h)
    w[0] = 0.5 * (h_prev + h) if h_prev > 0.0 else 0.5 * h
    return k / m, w


def substeps(step_once: Callable[[float, float, np.ndarray], None], velocities: Callable[[], np.ndarray],
             m: int, dt: float, t_end: float, rate: np.ndarray, slope: np.ndarray, v_start: np.ndarray,
             h_prev: float | None = None):
    """Advance ``m`` substeps: ``step_once(h, t_k, impulse_k)`` takes one substep of h = dt / m to t_k
    with the surface impulse impulse_k (predict, then correct); ``velocities()`` gives the surface
    velocities after it; ``v_start``: those before the coupling step; ``h_prev``: the group's last
    step (0 before its first; None: the midpoint sampling, module docstring).  Returns (v_mean, work,
    v_end)."""
    h = dt / m
    s, w = kick_weights(m, dt, h_prev)
    t0 = t_end - dt
    rate = np.asarray(rate, dtype=np.float64)
    slope = np.asarray(slope, dtype=np.float64)
    v_prev = np.asarray(v_start, dtype=np.float64)
    v_sum = np.zeros_like(v_prev)
    work = 0.0
    for k in range(m):   # (a loop over substeps, not over nodes: each substep is the solver's kernels)
        imp = w[k] * (rate + s[k] * slope)
        step_once(h, t_end if k == m - 1 else t0 + (k + 1) * h, imp)
        v = np.asarray(velocities(), dtype=np.float64)
        v_sum += v
        work += 0.5 * float(np.sum(imp * (v_prev + v)))
        v_prev = v
    return v_sum / m, work, v_prev
