"""Interval bounds of a case expression over a box of points: a proof that it is finite there.

The check evaluates every expression on every point its solver will (orchestrator/expressions.py).
Past its budget (a grid of billions of zones) it no longer samples: it bounds each expression over
boxes of the grid with interval arithmetic, and what a box's bounds prove (every operation finite,
a region certainly holding or not) holds for every point in it; boxes it cannot decide are split,
and small ones evaluated point by point. So what the check says is exact either way.

Every operation of solvers/expressions.py maps intervals to an enclosure of its values, widened by
one float step each side (rounding); an operation whose value may be non-finite somewhere in the box
(a divisor whose interval holds 0, sqrt or log of an interval reaching below or to 0, exp above 709,
a power of a base that may be negative with an exponent that is not one integer, an overflow)
raises :class:`Unproven`: the box must be split or evaluated. Booleans are the pair (may be false,
may be true). ``where(c, a, b)`` bounds only the branches ``c`` may take (the solver evaluates a
branch only where it is taken). Dependencies between operands are not tracked (``x - x`` over
[0, 1] is [-1, 1]): bounds are wider than the values, never narrower.
"""
from __future__ import annotations

import ast
import math

__all__ = ["Unproven", "bounds"]

_TAN_MAX = 1.7e16
"""|tan| of any float (the float nearest pi/2 gives 1.633e16): tan is finite everywhere."""


class Unproven(Exception):
    """The interval bounds cannot show the expression finite over the box."""


def _out(lo: float, hi: float) -> tuple[float, float]:
    """An enclosure widened one float step each side; Unproven unless finite."""
    lo, hi = math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise Unproven
    return lo, hi


def _mul(a, b):
    c = (a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1])
    return _out(min(c), max(c))


def _div(a, b):
    if b[0] <= 0.0 <= b[1]:
        raise Unproven
    return _mul(a, (1.0 / b[1], 1.0 / b[0]))


def _pow(a, b):
    if b[0] == b[1] and b[0] == int(b[0]) and abs(b[0]) <= 1024:
        n = int(b[0])
        if n < 0 and a[0] <= 0.0 <= a[1]:
            raise Unproven
        ends = [a[0] ** n, a[1] ** n] + ([0.0] if a[0] < 0.0 < a[1] and n > 0 else [])
    elif a[0] > 0.0:   # x > 0: x^y monotone in each argument, extremes at the corners
        ends = [a[i] ** b[j] for i in (0, 1) for j in (0, 1)]
    else:
        raise Unproven
    return _out(min(ends), max(ends))


def _mod(a, b):
    if b[0] <= 0.0 <= b[1]:
        raise Unproven
    return _out(min(0.0, b[0]), max(0.0, b[1]))   # numpy's mod takes the divisor's sign, |r| < |b|


def _tan(a):
    k0, k1 = math.floor((a[0] - math.pi / 2) / math.pi), math.floor((a[1] - math.pi / 2) / math.pi)
    if k0 == k1 and a[1] - a[0] < math.pi:
        return _out(math.tan(a[0]), math.tan(a[1]))
    return (-_TAN_MAX, _TAN_MAX)


def _exp(a):
    if a[1] > 709.0:
        raise Unproven
    return _out(math.exp(a[0]), math.exp(a[1]))


def _positive(fn):
    def f(a):
        if a[0] <= 0.0:
            raise Unproven
        return _out(fn(a[0]), fn(a[1]))
    return f


def _sqrt(a):
    if a[0] < 0.0:
        raise Unproven
    return _out(math.sqrt(a[0]), math.sqrt(a[1]))


def _abs(a):
    lo = 0.0 if a[0] <= 0.0 <= a[1] else min(abs(a[0]), abs(a[1]))
    return (lo, max(abs(a[0]), abs(a[1])))


_UNARY = {"abs": _abs, "sqrt": _sqrt, "sin": lambda a: (-1.0, 1.0), "cos": lambda a: (-1.0, 1.0),
          "tan": _tan, "exp": _exp, "log": _positive(math.log)}
_BINARY = {ast.Add: lambda a, b: _out(a[0] + b[0], a[1] + b[1]),
           ast.Sub: lambda a, b: _out(a[0] - b[1], a[1] - b[0]),
           ast.Mult: _mul, ast.Div: _div, ast.Pow: _pow, ast.Mod: _mod}
_CONSTANTS = {"pi": math.pi, "e": math.e}


def _compare(op, a, b) -> tuple[bool, bool]:
    """(may be false, may be true) of ``a op b`` over the intervals."""
    if isinstance(op, ast.Lt):
        return a[1] >= b[0], a[0] < b[1]
    if isinstance(op, ast.LtE):
        return a[1] > b[0], a[0] <= b[1]
    if isinstance(op, ast.Gt):
        return a[0] <= b[1], a[1] > b[0]
    if isinstance(op, ast.GtE):
        return a[0] < b[1], a[1] >= b[0]
    point = a[0] == a[1] == b[0] == b[1]
    overlap = a[0] <= b[1] and b[0] <= a[1]
    if isinstance(op, ast.Eq):
        return not point, overlap
    return overlap, not point          # NotEq


def _eval(node, box):
    if isinstance(node, ast.Expression):
        return _eval(node.body, box)
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool):
            return (not node.value, node.value)
        return (float(node.value), float(node.value))
    if isinstance(node, ast.Name):
        if node.id in box:
            return box[node.id]
        if node.id in ("True", "False"):
            return (node.id == "False", node.id == "True")
        return (_CONSTANTS[node.id],) * 2
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_eval(node.left, box), _eval(node.right, box))
    if isinstance(node, ast.UnaryOp):
        v = _eval(node.operand, box)
        if isinstance(node.op, ast.USub):
            return (-v[1], -v[0])
        if isinstance(node.op, ast.Not):
            return (v[1], v[0])
        return v
    if isinstance(node, ast.BoolOp):
        parts = [_eval(v, box) for v in node.values]     # (every operand is evaluated: all must be finite)
        if isinstance(node.op, ast.And):
            return any(p[0] for p in parts), all(p[1] for p in parts)
        return all(p[0] for p in parts), any(p[1] for p in parts)
    if isinstance(node, ast.Compare):
        values = [_eval(o, box) for o in (node.left, *node.comparators)]
        may_false, may_true = False, True
        for op, a, b in zip(node.ops, values, values[1:]):
            f, t = _compare(op, a, b)
            may_false, may_true = may_false or f, may_true and t
        return may_false, may_true
    if isinstance(node, ast.Call):
        name = node.func.id
        if name == "where":
            c = _eval(node.args[0], box)
            taken = [_eval(arg, box) for arg, may in zip(node.args[1:], (c[1], c[0])) if may]
            if isinstance(taken[0][0], bool):
                return any(t[0] for t in taken), any(t[1] for t in taken)
            return min(t[0] for t in taken), max(t[1] for t in taken)
        args = [_eval(a, box) for a in node.args]
        if name == "min":
            return min(a[0] for a in args), min(a[1] for a in args)
        if name == "max":
            return max(a[0] for a in args), max(a[1] for a in args)
        return _UNARY[name](args[0])
    raise Unproven      # (compile_expression accepts nothing else)


def bounds(text: str, box: dict[str, tuple[float, float]]):
    """Bounds of the (already compiled, so valid) expression ``text`` over the box {name: (lo, hi)}:
    (lo, hi) of a number, (may be false, may be true) of a boolean; Unproven where an operation may
    not be finite in the box."""
    try:
        return _eval(ast.parse(text, mode="eval"), box)
    except ArithmeticError:   # (Python's float ** raises where numpy's gives inf: 1e200 ** 2)
        raise Unproven from None
