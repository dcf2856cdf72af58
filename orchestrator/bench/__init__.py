"""Benchmarks (`immerse bench NAME`): medians of repeated runs, written as JSON
{"results": [{"name", "metric", "value", "unit", "params"}], "machine": {...}}. Not timed tests.

The registry and what every bench shares are in registry.py; each bench is a function registered
with ``@bench("name")`` in the module of its subject, imported here so that it registers: steps.py
(lagrange, taylor, ale, sod, advect), memory.py, output.py, coupling.py, coupling_studies.py
(plate_convergence, plate_convergence_3d, penalty_sweep), sph.py, contact.py, implicit.py, startup.py,
multirate.py, subcycling.py.
"""
from __future__ import annotations

from orchestrator.bench import (contact, coupling, coupling_studies, implicit, memory, multirate,  # noqa: F401
                                output, sph, startup, steps, subcycling)  # (they register)
from orchestrator.bench.registry import BENCHES, bench, machine, run_worker

__all__ = ["BENCHES", "bench", "machine", "run_worker"]
