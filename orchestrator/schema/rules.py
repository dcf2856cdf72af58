"""What every table of case.toml is checked with: the one-line :class:`CaseError`, dotted key paths,
and the rules the table fragments share (vector lengths against ``run.dimension``, expressions,
box extents, data files: paths inside the case directory, regular files).

Used by :mod:`orchestrator.case` (the core tables and the load pipeline) and by the fragment
modules of the solvers' tables (:mod:`orchestrator.schema.registry`); light on purpose: no solver
module is imported here.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from solvers.expressions import ExpressionError, compile_expression

__all__ = [
    "CaseError", "MISSING", "ALLOW_PATH_ENV", "format_key", "fmt_num", "expression_names",
    "to_float", "num_or_expression", "check_length", "check_expression", "check_extent",
    "allowed_roots", "check_path_inside", "format_bytes", "file_kind", "stat_regular",
]


_MAX_VALUE_REPR = 160
"""Longest repr of a value in a message; a longer one is abbreviated."""

ALLOW_PATH_ENV = "IMMERSE_ALLOW_PATH"
"""Directories (``os.pathsep``-separated) besides the case directory that mesh and data paths may
resolve into, e.g. a shared mesh library; inherited by the launched ranks."""


class _Missing:
    """Value of a required key that is absent (repr ``<missing>``)."""

    _instance = None

    def __new__(cls):
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "<missing>"

    def __reduce__(self):
        return (_Missing, ())


MISSING = _Missing()


class _Abbreviated:
    """Stand-in for a value whose repr is too long / multi-line for a one-line message."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return self.text

    def __eq__(self, other):
        return isinstance(other, _Abbreviated) and other.text == self.text

    def __hash__(self):
        return hash(self.text)


def _one_line(text: Any) -> str:
    return " ".join(str(text).split())


class CaseError(ValueError):
    """Invalid case: ``str(e) == f"{e.key} = {e.value!r}: {e.allowed}"``, always one line.

    ``key`` is the dotted TOML path (``"materials.steel.poisson_ratio"``,
    ``"lagrange.bodies[0].mesh.file"``), ``value`` the offending value (:data:`MISSING`
    for an absent required key; replaced by an abbreviation when its repr would be longer
    than 160 characters or span lines) and ``allowed`` a human description of what is
    accepted.
    """

    def __init__(self, key: str, value: Any, allowed: str):
        self.key = _one_line(key)
        text = repr(value)
        if len(text) > _MAX_VALUE_REPR or "\n" in text or "\r" in text:
            text = _one_line(text)
            if len(text) > _MAX_VALUE_REPR:
                text = text[: _MAX_VALUE_REPR - 3] + "..."
            value = _Abbreviated(text)
        self.value = value
        self.allowed = _one_line(allowed)
        super().__init__(f"{self.key} = {self.value!r}: {self.allowed}")

    def __str__(self) -> str:
        return self.args[0]

    def __reduce__(self):
        return (CaseError, (self.key, self.value, self.allowed))


# ----------------------------------------------------------------------------------
# key paths
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def format_key(path: Iterable[str | int]) -> str:
    """Dotted TOML key for a path: ``["lagrange", "bodies", 0, "mesh"]`` ->
    ``lagrange.bodies[0].mesh``; non-bare keys are quoted as in TOML."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            part = str(part)
            piece = part if _BARE_KEY.match(part) else json.dumps(part, ensure_ascii=False)
            out = f"{out}.{piece}" if out else piece
    return out


# ----------------------------------------------------------------------------------
# rules the tables share
def fmt_num(v: float) -> str:
    """A number as a message shows it: ``0.5``, ``1e+09``, ``3``."""
    return repr(v) if isinstance(v, float) and not float(v).is_integer() else f"{v:g}"


def expression_names(dimension: int) -> tuple[str, ...]:
    """Coordinate names usable in expressions of a ``dimension``-D case."""
    return ("x", "y", "z")[:dimension]


def to_float(v):
    return float(v)


def num_or_expression(v):
    """A value that may be a number or an expression string (kept as the string)."""
    return v if isinstance(v, str) else float(v)


def expression_refusal(key: str, text: str, exc: ExpressionError, where: str) -> CaseError:
    """The CaseError of an expression that gave a non-finite value at a point (``where``: which
    kind of point, e.g. "a node of body 'bar'"): the key, the sub-expression and the point."""
    if exc.segment is None:  # pragma: no cover - compile errors are load_case's
        return CaseError(key, text, str(exc))
    sub = "" if exc.segment == text.strip() else f" (sub-expression {exc.segment!r} = {exc.value})"
    what = f"{exc.value}" if not sub else "a non-finite value"
    at = ", ".join(f"{k} = {v:.9g}" for k, v in (exc.point or {}).items())
    return CaseError(key, text, f"gives {what}{sub} at {at or 'every point'} ({where}); allowed: "
                                "finite values at every point (guard divisions and roots with "
                                "where(cond, a, b))")


def check_length(key: str, value: list, dim: int) -> None:
    """A vector of the case has run.dimension components."""
    if len(value) != dim:
        raise CaseError(key, value, f"dimension mismatch: must have {dim} items "
                                    f"(run.dimension = {dim})")


def check_faces(table: str, faces: dict, raw_faces: dict, dim: int) -> None:
    """A solver's ``boundaries`` faces (``[ale]``, ``[sph]``): no face of an axis the dimension lacks,
    and ``periodic`` on both faces of an axis or on neither.  ``faces``: the normalised faces (every
    face of the dimension), ``raw_faces``: as written."""
    axes = "xyz"[:dim]
    for f in raw_faces:
        if f[0] not in axes:
            raise CaseError(format_key([table, "boundaries", f]), raw_faces[f],
                            f"dimension mismatch: no {f[0]} faces in a {dim}D case")
    for a in axes:
        lo, hi = faces[f"{a}_lower"], faces[f"{a}_upper"]
        if (lo == "periodic") != (hi == "periodic"):
            raise CaseError(format_key([table, "boundaries", f"{a}_lower" if lo == "periodic" else f"{a}_upper"]),
                            "periodic", f"periodic must be set on both {a}_lower and {a}_upper")


def check_expression(key: str, text: str, dim: int, kind: str) -> None:
    """An expression compiles (whitelist, ``kind`` NUM or BOOL, constant parts folded)."""
    try:
        compile_expression(text, expression_names(dim), kind=kind)
    except ExpressionError as exc:
        raise CaseError(key, text, str(exc)) from None


def check_extent(key: str, box: dict, raw: dict) -> None:
    """Finite numbers whose differences are not: an extent upper - lower that overflows, zones so
    small that their volume underflows (the solvers divide by it)."""
    widths = [hi - lo for lo, hi in zip(box["lower"], box["upper"])]
    if not all(math.isfinite(w) for w in widths):
        raise CaseError(f"{key}.upper", raw["upper"], "upper - lower must be a finite number "
                        "(it overflows); allowed: extents below 1e308 m")
    volume = math.prod(w / c for w, c in zip(widths, box["cells"]))
    if not volume >= sys.float_info.min:
        raise CaseError(f"{key}.cells", raw["cells"], f"zones of {fmt_num(volume)} m^{len(widths)} "
                        "are too small to compute with (their volume underflows a float); allowed: "
                        "fewer cells or a larger extent")


# ----------------------------------------------------------------------------------
# files the case reads
_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
               (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    return next((name for test, name in _FILE_KINDS if test(mode)), "not a regular file")


def format_bytes(n: int) -> str:
    """``2.9 TiB``, ``23.4 GiB``, ``256 KiB``, ``512 B`` (binary units)."""
    n = int(n)
    for unit, shift in (("EiB", 60), ("PiB", 50), ("TiB", 40), ("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{n} B"


def stat_regular(path: Path, key: str, value: Any, allowed: str,
                 not_found: str = "file not found") -> os.stat_result:
    """os.stat of a file that must be a regular file (a FIFO, device or directory is refused on
    ``key`` before anything opens it: opening a FIFO blocks)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise CaseError(key, value, not_found) from None
    except OSError as exc:
        raise CaseError(key, value, f"cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise CaseError(key, value, f"is {file_kind(st.st_mode)}; {allowed}")
    return st


def allowed_roots(case_dir: Path) -> list[Path]:
    """The case directory and the directories of $IMMERSE_ALLOW_PATH, symlinks resolved."""
    roots = [Path(case_dir).resolve()]
    for d in os.environ.get(ALLOW_PATH_ENV, "").split(os.pathsep):
        if d.strip():
            roots.append(Path(d.strip()).expanduser().resolve())
    return roots


def check_path_inside(key: str, raw: str, path: Path, case_dir: Path) -> None:
    """A data path of the case (already resolved: symlinks and '..' followed) must lie inside the
    case directory or an allowed root, so a case file cannot make the run read elsewhere."""
    roots = allowed_roots(case_dir)
    if not any(Path(path).resolve().is_relative_to(r) for r in roots):
        extra = "" if len(roots) == 1 else " or " + ", ".join(str(r) for r in roots[1:])
        raise CaseError(key, raw, f"resolves to {str(path)!r}, outside the case directory{extra}; "
                                  f"allowed: paths inside the case directory (symlinks and '..' "
                                  f"followed), or inside a directory listed in ${ALLOW_PATH_ENV}")

