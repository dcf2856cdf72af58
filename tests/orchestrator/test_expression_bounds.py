"""orchestrator/expression_bounds.py: interval bounds of case expressions, the proof behind the
check past its budget. Sound: over random boxes, every value the compiled expression gives at points
in the box lies in the bounds, and a box the bounds call finite never holds a point whose evaluation
fails; and tight enough to settle the usual regions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator.expression_bounds import Unproven, bounds
from solvers.expressions import BOOL, NUM, ExpressionError, compile_expression

NUMBERS = ["x * x - 3 * y", "(x - 0.4)**2 + (y - 0.15)**2", "1 / (x + 2)", "sqrt(x + 1) * exp(y)",
           "log(x + 1.5) - tan(y)", "x ** 3 - y ** -2", "(x + 2) ** y", "x % 0.3 + y % -0.7",
           "abs(x - y) / (1 + x * x)", "min(x, y, 0.2) + max(x, 2 * y)", "where(x > 0, 1 / x, 0)",
           "sin(3 * x) * cos(y) + tan(x / 3)", "-x + +y", "exp(40 * x)"]
BOOLEANS = ["x < y", "0 < x <= 0.5", "x == y", "x != 0.25", "not (x > 0.1 and y < 0.2) or x >= y",
            "where(y > 0, x < 1 / y, x > 0)", "(x - 0.4)**2 + (y - 0.15)**2 < 0.04"]


def _points(rng, lo, hi, n=400):
    """Random points of the box, its corners among them."""
    corners = np.array([[a, b] for a in (lo[0], hi[0]) for b in (lo[1], hi[1])])
    return np.concatenate([corners, rng.uniform(lo, hi, (n, 2))])


@pytest.mark.parametrize("text", NUMBERS + BOOLEANS)
def test_bounds_hold_every_value_of_the_box(text):
    """200 random boxes from 1e-6 to 4 wide about the origin: where the bounds are given, every
    value at 404 points of the box (corners included) lies within them (booleans: a value the
    bounds say cannot occur never does), and no evaluation there fails."""
    rng = np.random.default_rng(abs(hash(text)) % 2**32)
    fn = compile_expression(text, ("x", "y"), kind=BOOL if text in BOOLEANS else NUM)
    proven = 0
    for _ in range(200):
        width = 10 ** rng.uniform(-6, math.log10(4))
        lo = rng.uniform(-2, 2, 2)
        hi = lo + width * rng.uniform(0.1, 1, 2)
        try:
            b = bounds(text, {"x": (lo[0], hi[0]), "y": (lo[1], hi[1])})
        except Unproven:
            continue
        proven += 1
        p = _points(rng, lo, hi)
        v = fn(p[:, 0], p[:, 1])                       # (an ExpressionError here fails the test)
        if text in BOOLEANS:
            assert (b[0] or v.all()) and (b[1] or not v.any()), (text, lo, hi, b)
        else:
            assert b[0] <= v.min() and v.max() <= b[1], (text, lo, hi, b, v.min(), v.max())
    assert proven >= 20, proven   # (most boxes are settled: the bounds are not vacuous)


@pytest.mark.parametrize("text, box", [
    ("1 / x", {"x": (-1.0, 1.0)}), ("sqrt(x)", {"x": (-1e-300, 1.0)}), ("log(x)", {"x": (0.0, 1.0)}),
    ("exp(x)", {"x": (0.0, 710.0)}), ("x ** 0.5", {"x": (-1.0, 1.0)}), ("x % x", {"x": (-1.0, 1.0)}),
    ("x * 1e300 * 1e10", {"x": (0.0, 1.0)}), ("x ** -1", {"x": (0.0, 1.0)}),
    # (Python's float ** raises OverflowError where numpy's gives inf: unproven, not a traceback)
    ("(1e200 * x) ** 2", {"x": (-1.0, 1.0)}), ("(1e-300 * x) ** -2", {"x": (1e-20, 1.0)}),
    ("x ** 3e2", {"x": (1e3, 1e4)}),
])
def test_what_may_not_be_finite_is_unproven(text, box):
    with pytest.raises(Unproven):
        bounds(text, box)
    # and each really fails at some point of its box, or comes within a float step of it
    x = np.linspace(*box["x"], 100001)
    fn = compile_expression(text, ("x",), kind=NUM)
    with pytest.raises(ExpressionError):
        fn(np.concatenate([x, [0.0]]) if box["x"][0] <= 0.0 <= box["x"][1] else x)


def test_where_bounds_only_the_branch_taken():
    """where(x > 0, 1 / x, 0) over [0.5, 2]: the first branch only, [0.5, 2] widened a float step;
    over [-1, 1] it is unproven (the branch is taken at x just above 0), though finite: the check
    evaluates such boxes point by point."""
    lo, hi = bounds("where(x > 0, 1 / x, 0)", {"x": (0.5, 2.0)})
    assert lo == pytest.approx(0.5, rel=1e-15) and lo < 0.5 and hi == pytest.approx(2.0, rel=1e-15) and hi > 2.0
    assert bounds("(x - 0.4)**2 + (y - 0.15)**2 < 0.04", {"x": (0.9, 1.0), "y": (0.0, 0.3)}) == (True, False)
    with pytest.raises(Unproven):
        bounds("where(x > 0, 1 / x, 0)", {"x": (-1.0, 1.0)})
