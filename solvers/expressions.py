"""Safe arithmetic / boolean expressions for case files (shared by the solvers, which evaluate them,
and the orchestrator, which checks them before anything launches).

Case files describe initial fields (``initial_velocity = ["0", "-200 * (z > 0.01)", ...]``)
and boundary regions (``region = "z < 1e-6 and x <= 0.5"``) as short expression strings in
the initial coordinates ``x, y, z``.  They are compiled here WITHOUT ``eval``/``exec``: the
text is parsed with ``ast.parse(mode="eval")`` and the tree is walked against a whitelist;
every accepted node is turned into a small closure that evaluates on numpy arrays.

Accepted (everything else is an :class:`ExpressionError`):

* numbers (finite int/float literals), ``True``/``False``;
* the variable names given to :func:`compile_expression` (default ``x, y, z``) and the
  constants ``pi`` and ``e``;
* binary ``+ - * / ** %``, unary ``-``/``+``;
* comparisons ``< <= > >= == !=`` (chained: ``0 < x < 1``);
* ``and``, ``or``, ``not`` (operands must be boolean);
* calls of ``abs sqrt sin cos tan exp log`` (one argument), ``min max`` (two or more
  arguments, element-wise) and ``where(cond, a, b)``.

Expressions are statically typed: numbers and booleans do not mix (``x + (y > 0)`` is
rejected, write ``where(y > 0, 1, 0)``).  Results are broadcast to the common shape of
the inputs, so a constant expression still gives one value per point.

Finite values only.  Every arithmetic operation and function value must be finite where it
is used: ``1/x`` at ``x = 0``, ``sqrt(-1)``, ``0/(x-x) > 1`` (a NaN compared is silently
False), ``exp(1000) > 1`` raise :class:`ExpressionError` naming the sub-expression and the
point, instead of propagating NaN/inf into a simulation or a region.  ``where(c, a, b)``
evaluates ``a`` only where ``c`` holds and ``b`` only where it does not, so
``where(x > 0, 1/x, 0)`` is valid at ``x = 0``.  Sub-expressions without variables are
folded at compile time, so ``9**9**9**9`` is refused before any point exists.

Bounded cost.  At most :data:`MAX_LENGTH` characters and :data:`MAX_DEPTH` levels; every
number is a float64 (no Python big integers: ``9**9**9`` is ``inf``, refused); evaluation
walks the points in chunks of :data:`CHUNK` so temporaries stay a few MB whatever the
number of points (values are element-wise, so chunking does not change them).
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Sequence

import numpy as np

__all__ = [
    "ExpressionError",
    "CompiledExpression",
    "compile_expression",
    "MAX_LENGTH",
    "MAX_DEPTH",
    "FUNCTIONS",
    "CONSTANTS",
    "CHUNK",
]

MAX_LENGTH = 1000
"""Longest accepted expression text (characters)."""

MAX_DEPTH = 40
"""Deepest accepted nesting of the syntax tree."""

CHUNK = 1 << 16
"""Points evaluated at once: with at most MAX_DEPTH live temporaries of CHUNK float64 each, an
evaluation holds about 20 MB at most, whatever the number of points."""

_N = " n"  # environment key of the chunk length (not an identifier, so never a variable name)

CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e}

# name -> (numpy implementation, minimum arity, maximum arity or None)
FUNCTIONS: dict[str, tuple[Callable, int, int | None]] = {
    "abs": (np.abs, 1, 1),
    "sqrt": (np.sqrt, 1, 1),
    "sin": (np.sin, 1, 1),
    "cos": (np.cos, 1, 1),
    "tan": (np.tan, 1, 1),
    "exp": (np.exp, 1, 1),
    "log": (np.log, 1, 1),
    "min": (np.minimum, 2, None),
    "max": (np.maximum, 2, None),
    "where": (np.where, 3, 3),
}

_BINOPS = {
    ast.Add: ("+", np.add),
    ast.Sub: ("-", np.subtract),
    ast.Mult: ("*", np.multiply),
    ast.Div: ("/", np.true_divide),
    ast.Pow: ("**", np.power),
    ast.Mod: ("%", np.mod),
}
_COMPARE = {
    ast.Lt: ("<", np.less),
    ast.LtE: ("<=", np.less_equal),
    ast.Gt: (">", np.greater),
    ast.GtE: (">=", np.greater_equal),
    ast.Eq: ("==", np.equal),
    ast.NotEq: ("!=", np.not_equal),
}
# Symbols of operators we refuse, for messages.
_REJECTED_OPS = {
    ast.FloorDiv: "//", ast.MatMult: "@", ast.LShift: "<<", ast.RShift: ">>",
    ast.BitAnd: "&", ast.BitOr: "|", ast.BitXor: "^", ast.Invert: "~",
    ast.Is: "is", ast.IsNot: "is not", ast.In: "in", ast.NotIn: "not in",
}
_HINTS = {
    "&": " (use 'and')", "|": " (use 'or')", "~": " (use 'not')", "//": " (use '/')",
}

NUM = "number"
BOOL = "boolean"

Evaluator = Callable[[dict], np.ndarray]


class ExpressionError(ValueError):
    """An expression is not accepted (or evaluates to non-finite values).

    ``str(error)`` is always a single line naming the offending construct and the
    allowed set.
    """

    def __init__(self, message: str, *, segment: str | None = None, value: float | None = None,
                 point: dict | None = None):
        super().__init__(" ".join(str(message).split()))
        self.segment = segment  # the sub-expression that is not finite (None: other errors)
        self.value = value      # its value there (nan, inf or -inf)
        self.point = point      # {name: coordinate} of the first point where it is not finite


class _NonFinite(Exception):
    """Raised inside an evaluation: ``segment`` is not finite at entry ``index`` of the current
    environment's arrays (remapped by where() to the enclosing environment on the way out)."""

    def __init__(self, segment: str, index: int, value: float):
        super().__init__(segment)
        self.segment, self.index, self.value = segment, index, value


def _non_finite_text(text: str, segment: str, value: float, point: dict | None) -> str:
    where = ""
    if point:
        where = " at " + ", ".join(f"{k} = {v:.9g}" for k, v in point.items())
    what = f"({value})" if segment == text.strip() else f"({segment!r} = {value})"
    return (f"expression {_quote(text)} gives a non-finite value {what}{where}; allowed: finite "
            f"results only (guard divisions and roots with where(cond, a, b))")


def _quote(text: str, limit: int = 60) -> str:
    """repr() of an expression text, shortened for messages (always one line)."""
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return repr(text)


def _allowed_text(names: Sequence[str]) -> str:
    return (
        "allowed: numbers, True/False, names "
        + ", ".join(list(names) + list(CONSTANTS))
        + "; operators + - * / ** % and unary -, comparisons < <= > >= == != (chainable),"
        " and/or/not; functions " + ", ".join(FUNCTIONS) + "(cond, a, b)"
    )


class CompiledExpression:
    """A checked expression; call it with numpy arrays (positional in ``names`` order,
    or by keyword).

    Attributes: ``text``, ``names`` (accepted variables), ``kind`` (``"number"`` or
    ``"boolean"``), ``used_names`` (variables that actually occur), ``size`` (syntax tree nodes:
    the cost of one point is about ``size`` numpy operations).
    """

    __slots__ = ("text", "names", "kind", "used_names", "size", "_fn")

    def __init__(self, text: str, names: tuple[str, ...], kind: str,
                 used_names: frozenset[str], fn: Evaluator, size: int = 1):
        self.text = text
        self.names = names
        self.kind = kind
        self.used_names = used_names
        self.size = size
        self._fn = fn

    def __repr__(self) -> str:
        return f"CompiledExpression({self.text!r}, names={self.names!r}, kind={self.kind!r})"

    def __call__(self, *args, **kwargs) -> np.ndarray:
        if len(args) > len(self.names):
            raise TypeError(f"expression takes {len(self.names)} arguments "
                            f"({', '.join(self.names)}), got {len(args)}")
        env: dict[str, np.ndarray] = {}
        for name, value in zip(self.names, args):
            env[name] = value
        for name, value in kwargs.items():
            if name not in self.names:
                raise TypeError(f"unexpected variable {name!r}; expression variables: "
                                f"{', '.join(self.names)}")
            if name in env:
                raise TypeError(f"variable {name!r} given twice")
            env[name] = value
        missing = [n for n in self.names if n not in env]
        if missing:
            raise TypeError(f"missing value(s) for {', '.join(missing)}")
        arrays = {n: np.asarray(v, dtype=np.float64) for n, v in env.items()}
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values()))
        size = math.prod(shape)
        flat = {n: np.broadcast_to(a, shape).reshape(-1) for n, a in arrays.items()}
        out = np.empty(size, dtype=bool if self.kind == BOOL else np.float64)
        with np.errstate(all="ignore"):
            for start in range(0, max(size, 1), CHUNK):
                stop = min(start + CHUNK, size)
                chunk = {n: a[start:stop] for n, a in flat.items()}
                chunk[_N] = stop - start
                try:
                    out[start:stop] = self._fn(chunk)  # scalars broadcast to the chunk
                    if self.kind == NUM and not np.all(np.isfinite(out[start:stop])):
                        i = int(np.argmax(~np.isfinite(out[start:stop])))
                        raise _NonFinite(self.text.strip(), i, float(out[start + i]))
                except _NonFinite as exc:
                    point = {n: float(a[start + exc.index]) for n, a in flat.items()
                             if n in self.used_names}
                    raise ExpressionError(_non_finite_text(self.text, exc.segment, exc.value, point),
                                          segment=exc.segment, value=exc.value, point=point) from None
        return out.reshape(shape)

    def at_points(self, points) -> np.ndarray:
        """Evaluate at the rows of a ``(n, d)`` coordinate array (columns x, y[, z]).

        Variables beyond the number of columns (``z`` for 2D points) are zero.
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2:
            raise ValueError(f"points must be a 2-D array (n, dim), got shape {pts.shape}")
        cols = {}
        for i, name in enumerate(self.names):
            cols[name] = pts[:, i] if i < pts.shape[1] else np.zeros(pts.shape[0])
        return self(**cols)


def compile_expression(text: str, names: Sequence[str] = ("x", "y", "z"), *,
                       kind: str | None = None) -> CompiledExpression:
    """Compile ``text`` into a :class:`CompiledExpression` of the variables ``names``.

    ``kind`` may require the result type: ``"number"`` (initial fields) or ``"boolean"``
    (regions).  Raises :class:`ExpressionError` (one-line message) for anything outside
    the whitelist described in the module docstring.
    """
    names = tuple(names)
    for n in names:
        if not isinstance(n, str) or not n.isidentifier() or n in FUNCTIONS or n in CONSTANTS:
            raise ValueError(f"invalid expression variable name {n!r}")
    if kind not in (None, NUM, BOOL):
        raise ValueError(f"kind must be None, {NUM!r} or {BOOL!r}, got {kind!r}")
    allowed = _allowed_text(names)
    if not isinstance(text, str):
        raise ExpressionError(f"expression must be a string, got {type(text).__name__}; "
                              f"{allowed}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression is too long ({len(text)} characters, at most "
                              f"{MAX_LENGTH}); {allowed}")
    if not text.strip():
        raise ExpressionError(f"expression is empty; {allowed}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        where = f" at column {exc.offset}" if exc.offset else ""
        raise ExpressionError(f"syntax error in {_quote(text)}{where}: {exc.msg}; {allowed}") from None
    except (RecursionError, MemoryError, ValueError) as exc:
        raise ExpressionError(f"expression {_quote(text)} cannot be parsed "
                              f"({type(exc).__name__}); {allowed}") from None
    _check_depth(tree.body, text, allowed)
    compiler = _Compiler(text.strip(), names, allowed)
    fn, result_kind = compiler.compile(tree.body)
    if kind is not None and result_kind != kind:
        want = "a boolean (region)" if kind == BOOL else "a numeric"
        raise ExpressionError(f"expression {_quote(text)} gives a {result_kind} but {want} "
                              f"expression is required; {allowed}")
    return CompiledExpression(text, names, result_kind, frozenset(compiler.used), fn,
                              size=sum(isinstance(n, ast.expr) for n in ast.walk(tree.body)))


def _check_depth(root: ast.AST, text: str, allowed: str) -> None:
    # Iterative, so a pathological tree cannot blow the Python stack here; the recursive
    # compiler below then only ever sees trees at most MAX_DEPTH deep.
    stack = [(root, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise ExpressionError(f"expression {_quote(text)} is nested too deeply (more than "
                                  f"{MAX_DEPTH} levels); {allowed}")
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))


def _describe(node: ast.AST) -> str:
    return {
        ast.Attribute: "attribute access",
        ast.Subscript: "subscript",
        ast.Lambda: "lambda",
        ast.ListComp: "list comprehension",
        ast.SetComp: "set comprehension",
        ast.DictComp: "dict comprehension",
        ast.GeneratorExp: "generator expression",
        ast.List: "list",
        ast.Tuple: "tuple",
        ast.Set: "set",
        ast.Dict: "dict",
        ast.IfExp: "conditional expression (use where(cond, a, b))",
        ast.NamedExpr: "assignment expression ':='",
        ast.JoinedStr: "f-string",
        ast.FormattedValue: "f-string",
        ast.Starred: "starred argument",
        ast.Await: "await",
        ast.Yield: "yield",
        ast.YieldFrom: "yield",
        ast.Slice: "slice",
    }.get(type(node), type(node).__name__)


class _Compiler:
    def __init__(self, text: str, names: tuple[str, ...], allowed: str):
        self.text = text
        self.names = names
        self.allowed = allowed
        self.used: set[str] = set()

    # -- helpers -----------------------------------------------------------------
    def _segment(self, node: ast.AST) -> str:
        seg = ast.get_source_segment(self.text, node)
        if seg is None:  # pragma: no cover - all nodes here carry positions
            seg = type(node).__name__
        if len(seg) > 60:
            seg = seg[:57] + "..."
        return seg

    def _fail(self, what: str) -> ExpressionError:
        return ExpressionError(f"{what} is not allowed in expression {_quote(self.text)}; "
                               f"{self.allowed}")

    def _need(self, node: ast.AST, kind: str, want: str, context: str) -> None:
        if kind != want:
            raise ExpressionError(
                f"{context} needs a {want} operand but {self._segment(node)!r} is a {kind} "
                f"in expression {_quote(self.text)}; {self.allowed}")

    # -- dispatcher --------------------------------------------------------------
    def compile(self, node: ast.AST) -> tuple[Evaluator, str]:
        method = _DISPATCH.get(type(node))  # the whitelist of node types
        if method is None:
            raise self._fail(f"{_describe(node)} {self._segment(node)!r}")
        fn, kind = method(self, node)
        if kind == NUM and not isinstance(node, (ast.Constant, ast.Name)) and self._constant(node):
            fn = self._fold(fn)
        return fn, kind

    def _constant(self, node: ast.AST) -> bool:
        return not any(isinstance(n, ast.Name) and n.id in self.names for n in ast.walk(node))

    def _fold(self, fn: Evaluator) -> Evaluator:
        """A sub-expression without variables, evaluated once now (the value every evaluation would
        compute: the same numpy operations on the same float64 scalars)."""
        try:
            with np.errstate(all="ignore"):
                value = fn({_N: 1})
        except _NonFinite as exc:
            raise ExpressionError(_non_finite_text(self.text, exc.segment, exc.value, None),
                                  segment=exc.segment, value=exc.value) from None
        return lambda env: value

    def _finite(self, node: ast.AST, fn: Evaluator) -> Evaluator:
        """``fn`` whose value is checked: NaN or inf anywhere raises :class:`_NonFinite`."""
        segment = self._segment(node)

        def run(env):
            r = fn(env)
            if not np.all(np.isfinite(r)):
                bad = ~np.isfinite(np.broadcast_to(r, (env[_N],)))
                i = int(np.argmax(bad))
                raise _NonFinite(segment, i, float(np.broadcast_to(r, (env[_N],))[i]))
            return r
        return run

    def _c_Constant(self, node: ast.Constant):
        value = node.value
        if isinstance(value, bool):
            const_b = np.bool_(value)
            return (lambda env: const_b), BOOL
        if isinstance(value, (int, float)):
            try:
                f = float(value)
            except OverflowError:
                raise self._fail(f"number {self._segment(node)!r} (too large)") from None
            if not math.isfinite(f):
                raise self._fail(f"number {self._segment(node)!r} (not finite)")
            const_f = np.float64(f)
            return (lambda env: const_f), NUM
        if isinstance(value, str):
            what = "string"
        elif isinstance(value, bytes):
            what = "bytes"
        elif isinstance(value, complex):
            what = "complex number"
        elif value is None:
            what = "None"
        elif value is Ellipsis:
            what = "Ellipsis"
        else:  # pragma: no cover
            what = type(value).__name__
        raise self._fail(f"{what} {self._segment(node)!r}")

    def _c_Name(self, node: ast.Name):
        name = node.id
        if name in self.names:
            self.used.add(name)
            return (lambda env: env[name]), NUM
        if name in CONSTANTS:
            c = np.float64(CONSTANTS[name])
            return (lambda env: c), NUM
        if name in FUNCTIONS:
            raise self._fail(f"bare function name {name!r} (call it, e.g. {name}(x))")
        raise self._fail(f"name {name!r}")

    def _c_BinOp(self, node: ast.BinOp):
        op = type(node.op)
        if op not in _BINOPS:
            sym = _REJECTED_OPS.get(op, op.__name__)
            raise self._fail(f"operator {sym!r}{_HINTS.get(sym, '')}")
        sym, ufunc = _BINOPS[op]
        left, lk = self.compile(node.left)
        right, rk = self.compile(node.right)
        self._need(node.left, lk, NUM, f"operator {sym!r}")
        self._need(node.right, rk, NUM, f"operator {sym!r}")
        return self._finite(node, lambda env: ufunc(left(env), right(env))), NUM

    def _c_UnaryOp(self, node: ast.UnaryOp):
        op = type(node.op)
        operand, k = self.compile(node.operand)
        if op is ast.USub:
            self._need(node.operand, k, NUM, "unary '-'")
            return (lambda env: np.negative(operand(env))), NUM
        if op is ast.UAdd:
            self._need(node.operand, k, NUM, "unary '+'")
            return operand, NUM
        if op is ast.Not:
            self._need(node.operand, k, BOOL, "'not'")
            return (lambda env: np.logical_not(operand(env))), BOOL
        sym = _REJECTED_OPS.get(op, op.__name__)
        raise self._fail(f"operator {sym!r}{_HINTS.get(sym, '')}")

    def _c_BoolOp(self, node: ast.BoolOp):
        word = "and" if isinstance(node.op, ast.And) else "or"
        ufunc = np.logical_and if word == "and" else np.logical_or
        parts = []
        for v in node.values:
            fn, k = self.compile(v)
            self._need(v, k, BOOL, f"'{word}'")
            parts.append(fn)

        def run(env):
            acc = parts[0](env)
            for p in parts[1:]:
                acc = ufunc(acc, p(env))
            return acc
        return run, BOOL

    def _c_Compare(self, node: ast.Compare):
        operands = [node.left, *node.comparators]
        fns = []
        for o in operands:
            fn, k = self.compile(o)
            self._need(o, k, NUM, "comparison")
            fns.append(fn)
        ufuncs = []
        for op in node.ops:
            t = type(op)
            if t not in _COMPARE:
                raise self._fail(f"comparison {_REJECTED_OPS.get(t, t.__name__)!r}")
            ufuncs.append(_COMPARE[t][1])

        def run(env):
            values = [f(env) for f in fns]
            acc = ufuncs[0](values[0], values[1])
            for i in range(1, len(ufuncs)):
                acc = np.logical_and(acc, ufuncs[i](values[i], values[i + 1]))
            return acc
        return run, BOOL

    def _c_Call(self, node: ast.Call):
        if not isinstance(node.func, ast.Name):
            raise self._fail(f"call of {self._segment(node.func)!r}")
        name = node.func.id
        if name not in FUNCTIONS:
            raise self._fail(f"call of {name!r}")
        if node.keywords:
            raise self._fail(f"keyword argument in {self._segment(node)!r}")
        for a in node.args:
            if isinstance(a, ast.Starred):
                raise self._fail(f"starred argument {self._segment(a)!r}")
        impl, lo, hi = FUNCTIONS[name]
        n = len(node.args)
        if n < lo or (hi is not None and n > hi):
            want = str(lo) if hi == lo else f"at least {lo}"
            raise ExpressionError(
                f"{name}() takes {want} argument{'s' if lo > 1 else ''}, got {n}, in expression "
                f"{_quote(self.text)}; {self.allowed}")
        compiled = [self.compile(a) for a in node.args]
        if name == "where":
            (c, ck), (a, ak), (b, bk) = compiled
            self._need(node.args[0], ck, BOOL, "where() condition")
            if ak != bk:
                raise ExpressionError(
                    f"where() branches must have the same type, got {ak} and {bk}, in "
                    f"expression {_quote(self.text)}; {self.allowed}")
            return _masked_where(c, a, b, ak), ak
        for arg, (_, k) in zip(node.args, compiled):
            self._need(arg, k, NUM, f"{name}()")
        fns = [fn for fn, _ in compiled]
        if len(fns) == 1:
            f0 = fns[0]
            if name == "abs":  # |finite| is finite
                return (lambda env: impl(f0(env))), NUM
            return self._finite(node, lambda env: impl(f0(env))), NUM

        def run(env):
            acc = fns[0](env)
            for f in fns[1:]:
                acc = impl(acc, f(env))
            return acc
        return run, NUM


def _masked_where(c: Evaluator, a: Evaluator, b: Evaluator, kind: str) -> Evaluator:
    """where(c, a, b) evaluating ``a`` only at the points where ``c`` holds and ``b`` only at the
    others, so a branch's values where it is not selected (1/x at x = 0) are never computed."""

    def sub(fn, env, idx):
        part = {k: (v if k == _N else v[idx]) for k, v in env.items()}
        part[_N] = idx.size
        try:
            return fn(part)
        except _NonFinite as exc:
            exc.index = int(idx[exc.index])
            raise

    def run(env):
        n = env[_N]
        cond = np.broadcast_to(np.asarray(c(env), dtype=bool), (n,))
        yes = np.flatnonzero(cond)
        if yes.size == n:
            return a(env)
        if yes.size == 0:
            return b(env)
        no = np.flatnonzero(~cond)
        out = np.empty(n, dtype=bool if kind == BOOL else np.float64)
        out[yes] = sub(a, env, yes)
        out[no] = sub(b, env, no)
        return out
    return run


_DISPATCH = {
    ast.Constant: _Compiler._c_Constant,
    ast.Name: _Compiler._c_Name,
    ast.BinOp: _Compiler._c_BinOp,
    ast.UnaryOp: _Compiler._c_UnaryOp,
    ast.BoolOp: _Compiler._c_BoolOp,
    ast.Compare: _Compiler._c_Compare,
    ast.Call: _Compiler._c_Call,
}
