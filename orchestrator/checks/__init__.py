"""Case checks: each case's [check] names a registered check `kind`; the check computes metrics from
the run's output, and every metric the case lists is compared with its reference and tolerance.

The registry and the comparison are in registry.py, what the checks read from an output in
fields.py, and the kinds in one module per family (a new kind joins its family's module, or a new
module imported here, with ``@register_check``): solids.py, contact.py, gas.py, liquid.py,
penetration.py, coupled.py.
"""
from __future__ import annotations

from orchestrator.checks import contact, coupled, gas, liquid, penetration, solids  # noqa: F401  (they register)
from orchestrator.checks.registry import CHECKS, CURVES, PARAMS, RULES, compare, reference_curve, register_check, run_check

__all__ = ["CHECKS", "CURVES", "PARAMS", "RULES", "compare", "reference_curve", "register_check", "run_check"]
