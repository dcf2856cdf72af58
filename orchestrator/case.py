"""Load and validate a case directory (``<case_dir>/case.toml``).

:func:`load_case` returns a normalised plain dict (defaults filled in, numbers as
``float``/``int``, mesh file paths resolved to absolute :class:`~pathlib.Path`\\ s,
expressions kept as strings but already checked to compile) or raises :class:`CaseError`
whose message is ONE line ``"<dotted.key> = <value repr>: <what is allowed>"``.

Validation happens in stages, the first failure wins:

1. reading: ``case.toml`` must be a regular file (not a FIFO, device, directory; checked with
   ``stat`` and again on the opened descriptor, opened non-blocking so a FIFO cannot hang) of at
   most :data:`MAX_CASE_BYTES` (256 KiB; at most that much is ever read), UTF-8; TOML parsing
   (``tomllib``): a syntax error, or nesting beyond Python's recursion limit, is reported on the
   key ``case.toml``;
2. the JSON schema of :mod:`orchestrator.case_schema` (types, ranges, required keys,
   enums, unknown keys); the best error (``jsonschema.exceptions.best_match``) is
   translated into a :class:`CaseError` on its dotted key path; then every float of the
   file must be finite (``nan``/``inf`` pass JSON Schema's range checks), unless its key is
   listed in :data:`orchestrator.case_schema.NON_FINITE_KEYS`;
3. cross-field checks in Python: vector lengths vs ``run.dimension``, material references,
   expressions (compiled; constant parts such as ``9**9**9`` folded and refused here), ranks
   roles, sanity of finite numbers (extents whose zones underflow, more outputs than steps,
   energy sources outside the grid, wave speeds that overflow), ...;
4. mesh files last (reading them may be slow): the path must resolve (symlinks and ``..``
   followed) inside the case directory or a directory of ``$IMMERSE_ALLOW_PATH``; a regular
   file small enough to read here; parsed by meshio into the right cells.

What needs the machine (rank counts, memory: :mod:`orchestrator.resources`) and the expressions
evaluated on the case's own points (:mod:`orchestrator.expressions`) are checked by the CLI after
this, before anything launches.

Normalised layout (all keys always present)::

    {"name": str, "case_dir": Path,
     "run": {dimension, end_time, dt_scale, output_interval, checkpoint_interval (None if
             unset), max_steps, diagnostics_every},
     "ranks": {role: int}  (1 for every used solver unless given),
     "materials": {name: {model, density, youngs_modulus, poisson_ratio, [johnson_cook keys]}},
     "lagrange": {hourglass, bulk_viscosity_linear, bulk_viscosity_quadratic,
                  "bodies": [{name, material, mesh, initial_velocity, initial_temperature}]},
     "boundaries": [ {type, ...} ],
     "check": None | {kind, params, metrics: {name: {reference, tolerance}}}}

Every body also has ``size = {"elements": int, "nodes": int}`` (Python ints, computed without
building the mesh, or counted after reading a mesh file).

``mesh`` is exactly one of ``{"box": {lower, upper, cells}}``,
``{"quarter_cylinder": {radius, length, radial_cells, axial_cells}}`` or
``{"file": Path}``; ``initial_velocity`` holds ``dimension`` items, each a float or an
expression string in the coordinates (``x, y`` in 2D, ``x, y, z`` in 3D).
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import os
import re
import stat
import sys
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import jsonschema
from jsonschema.exceptions import ValidationError, best_match, relevance

from .case_schema import (
    CASE_SCHEMA,
    DEFAULT_ROOM_TEMPERATURE,
    KNOWN_ROLES,
    LAGRANGE_DEFAULTS,
    NAME_TEXT,
    NON_FINITE_KEYS,
    RUN_DEFAULTS,
)
from solvers.expressions import BOOL, NUM, ExpressionError, compile_expression
from solvers.lagrange.mesh import body_mesh_size

__all__ = [
    "CaseError",
    "MISSING",
    "CASE_FILE",
    "load_case",
    "solvers_used",
    "ranks_for",
    "format_key",
    "expression_names",
]

CASE_FILE = "case.toml"
_MAX_VALUE_REPR = 160
MAX_OUTPUTS = 1_000_000
"""Most output steps (and checkpoints) a case may ask for over its end time."""

MAX_CASE_BYTES = 256 << 10
"""Largest accepted case.toml (256 KiB: 60 times the largest shipped case, about 1900 bodies; the
check of a file this size takes about a second, of 1 MiB already 4-9 s on a loaded 2-core machine).
A bigger file is refused before it is read, and no more than this is ever read (a /proc file
claims size 0)."""

_MAX_SCHEMA_ERRORS = 100
"""best_match picks among the first errors only: a file full of mistakes costs no more to refuse
than a valid one costs to accept."""

ALLOW_PATH_ENV = "IMMERSE_ALLOW_PATH"
"""Directories (``os.pathsep``-separated) besides the case directory that mesh and data paths may
resolve into, e.g. a shared mesh library; inherited by the launched ranks."""

MESH_READ_FACTOR = 7
"""Reading a mesh file takes at least this many times its size in memory (tracemalloc peak of
read_mesh on 50^3 hexahedra, `immerse bench memory`: Gmsh 2.2 ASCII 7.5x, binary 14x, VTU binary 53x;
Gmsh 4 ASCII 8.2x, VTU ASCII 9.3x): a file bigger than memory / 7 cannot be read here."""


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
# schema errors -> CaseError
def _relevance(err: ValidationError):
    """jsonschema's relevance without its sibling order (which prefers the LAST sibling): among
    equally relevant errors the first in the file wins."""
    key = relevance(err)
    return key[:1] + key[2:]


_VALIDATOR = jsonschema.Draft202012Validator
# (the schema itself is validated against the metaschema by the tests, not at every import: that
# took 0.3-0.6 s of every `immerse` command and every rank's start)
_SCHEMA_VALIDATOR = _VALIDATOR(CASE_SCHEMA)

_TYPE_WORDS = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "object": "a table",
    "array": "an array",
    "boolean": "a boolean (true/false)",
}


def _fmt_num(v: float) -> str:
    return repr(v) if isinstance(v, float) and not float(v).is_integer() else f"{v:g}"


def _unit(schema: Mapping) -> str:
    unit = schema.get("x-unit") if isinstance(schema, Mapping) else None
    return f" ({unit})" if unit else ""


def _range_text(schema: Mapping) -> str:
    parts = []
    if "minimum" in schema:
        parts.append(f">= {_fmt_num(schema['minimum'])}")
    if "exclusiveMinimum" in schema:
        parts.append(f"> {_fmt_num(schema['exclusiveMinimum'])}")
    if "maximum" in schema:
        parts.append(f"<= {_fmt_num(schema['maximum'])}")
    if "exclusiveMaximum" in schema:
        parts.append(f"< {_fmt_num(schema['exclusiveMaximum'])}")
    kind = "an integer " if schema.get("type") == "integer" else ""
    return f"must be {kind}" + " and ".join(parts)


def _type_text(schema: Mapping) -> str:
    types = schema.get("type")
    if isinstance(types, list):
        if set(types) == {"number", "string"}:
            return "must be a number or an expression string"
        return "must be " + " or ".join(_TYPE_WORDS.get(t, t) for t in types)
    text = "must be " + _TYPE_WORDS.get(types, str(types))
    if any(k in schema for k in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum")):
        text += " " + _range_text(schema).removeprefix("must be ").removeprefix("an integer ")
    elif "enum" in schema:
        text += ", one of: " + ", ".join(repr(v) for v in schema["enum"])
    return text


def _items_text(schema: Mapping) -> str:
    lo, hi = schema.get("minItems"), schema.get("maxItems")
    if lo is not None and hi is not None:
        if lo == hi:
            return f"must have {lo} items"
        return f"must have {lo} or {hi} items" if hi == lo + 1 else f"must have {lo} to {hi} items"
    if lo is not None:
        return f"must have at least {lo} item{'s' if lo != 1 else ''}"
    return f"must have at most {hi} item{'s' if hi != 1 else ''}"


def _schema_error_to_case_error(err: ValidationError) -> CaseError:
    path = list(err.absolute_path)
    schema = err.schema if isinstance(err.schema, Mapping) else {}
    when = schema.get("x-when")
    suffix = f" ({when})" if when else ""
    v = err.validator
    inst = err.instance

    if v == "additionalProperties" and isinstance(inst, Mapping):
        props = list(schema.get("properties", {}))
        extras = [k for k in inst if k not in props]
        if extras:
            bad = extras[0]
            allowed = ", ".join(props) if props else "(none)"
            where = f" for {when}" if when else ""
            return CaseError(format_key(path + [bad]), inst[bad],
                             f"unknown key{where}; allowed: {allowed}")
    if v == "required" and isinstance(inst, Mapping):
        missing = [k for k in err.validator_value if k not in inst]
        if missing:
            return CaseError(format_key(path + [missing[0]]), MISSING,
                             f"required key missing{suffix}")
    if "propertyNames" in err.absolute_schema_path:
        # a table key failed the name rule: jsonschema reports the inner validator
        # ("pattern") with err.instance = the key itself and err.path = the enclosing table
        return CaseError(format_key(path + [str(inst)]), inst, f"invalid name: {NAME_TEXT}")

    key = format_key(path) or CASE_FILE
    if "x-allowed" in schema and v not in ("type",):
        return CaseError(key, inst, schema["x-allowed"] + _unit(schema))
    if v == "type":
        return CaseError(key, inst, _type_text(schema) + _unit(schema))
    if v in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return CaseError(key, inst, _range_text(schema) + _unit(schema))
    if v == "enum":
        return CaseError(key, inst, "must be one of: " + ", ".join(repr(x) for x in err.validator_value))
    if v == "const":
        return CaseError(key, inst, f"must be {err.validator_value!r}")
    if v in ("minItems", "maxItems"):
        return CaseError(key, inst, _items_text(schema))
    if v == "minLength":
        return CaseError(key, inst, "must not be empty")
    if v == "minProperties":
        return CaseError(key, inst, f"must have at least {err.validator_value} entr"
                                    f"{'y' if err.validator_value == 1 else 'ies'}")
    if v == "maxProperties":
        return CaseError(key, inst, f"must have at most {err.validator_value} entr"
                                    f"{'y' if err.validator_value == 1 else 'ies'}")
    return CaseError(key, inst, err.message)  # pragma: no cover - all validators above


# ----------------------------------------------------------------------------------
# public API
def expression_names(dimension: int) -> tuple[str, ...]:
    """Coordinate names usable in expressions of a ``dimension``-D case."""
    return ("x", "y", "z")[:dimension]


def solvers_used(case: Mapping) -> list[str]:
    """Solver roles the case needs (the adapter registry knows which case table means which role)."""
    from adapters import registry

    return [r for r in registry.roles_used(case) if case.get(r)]


def _rank_count(key: str, value: Any) -> int:
    allowed = "must be an integer >= 1 (MPI ranks)"
    if isinstance(value, bool):
        raise CaseError(key, value, allowed)
    if isinstance(value, str):
        try:
            value = int(value.strip(), 10)
        except ValueError:
            raise CaseError(key, value, allowed) from None
    elif isinstance(value, float):
        if not value.is_integer():
            raise CaseError(key, value, allowed)
        value = int(value)
    elif not isinstance(value, int):
        raise CaseError(key, value, allowed)
    if value < 1:
        raise CaseError(key, value, allowed)
    return int(value)


def _role_check(key: str, role: Any, n: Any, used: list[str]) -> None:
    if role not in used:
        if role in KNOWN_ROLES:
            allowed = f"solver {role!r} is not used by this case; allowed: {', '.join(used)}"
        else:
            allowed = f"unknown role; allowed: {', '.join(used) or '(none)'}"
        raise CaseError(key, n, allowed)


def ranks_for(case: Mapping, overrides: Mapping[str, Any] | Iterable[str] | None = None
              ) -> dict[str, int]:
    """MPI ranks per used solver role: 1 each, then ``[ranks]`` of the case, then
    ``overrides`` (from the CLI ``--ranks ROLE=N``; a mapping role -> N, or an iterable of
    ``"ROLE=N"`` strings).  Overrides are validated like the case file, on the key
    ``"--ranks ROLE"``; the result is ordered like :func:`solvers_used`."""
    used = solvers_used(case)
    result = {role: 1 for role in used}
    for role, n in (case.get("ranks") or {}).items():
        key = format_key(["ranks", role])
        _role_check(key, role, n, used)
        result[role] = _rank_count(key, n)
    if overrides is None:
        return result
    if isinstance(overrides, Mapping):
        items = list(overrides.items())
    else:
        items = []
        for spec in overrides:
            role, sep, n = str(spec).partition("=")
            if not sep or not role.strip():
                raise CaseError("--ranks", spec, "must be ROLE=N, e.g. lagrange=2; roles: "
                                + ", ".join(used))
            items.append((role.strip(), n))
    for role, n in items:
        key = f"--ranks {role}"
        _role_check(key, role, n, used)
        result[role] = _rank_count(key, n)
    return result


def load_case(case_dir: str | os.PathLike) -> dict:
    """Parse and validate ``<case_dir>/case.toml``; return the normalised case dict.

    ``case_dir`` may also be the path of the ``case.toml`` file itself.
    Raises :class:`CaseError` (one-line message) for any problem.
    """
    given = Path(case_dir).expanduser()
    if given.suffix == ".toml" and given.exists() and not given.is_dir():
        toml_path = given.resolve()
        case_dir = toml_path.parent
    else:
        if not given.is_dir():
            raise CaseError("case_dir", str(given), "directory not found")
        case_dir = given.resolve()
        toml_path = case_dir / CASE_FILE
    try:
        data = _read_toml(toml_path)

        errors = itertools.islice(_SCHEMA_VALIDATOR.iter_errors(data), _MAX_SCHEMA_ERRORS)
        err = best_match(errors, key=_relevance)
        if err is not None:
            raise _schema_error_to_case_error(err)
        _check_finite(data)

        case = _normalise(data, case_dir)
        _check(case, data)
    except RecursionError:  # a structure nested past Python's limit anywhere in the pipeline
        raise CaseError(CASE_FILE, str(toml_path), "nested too deeply (arrays or tables inside "
                        "each other beyond what can be read)") from None
    return case


# ----------------------------------------------------------------------------------
# stages
_TOML_POS = re.compile(r"at line (\d+), column (\d+)")
_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
               (stat.S_ISSOCK, "a socket"))


def _file_kind(mode: int) -> str:
    return next((name for test, name in _FILE_KINDS if test(mode)), "not a regular file")


def format_bytes(n: int) -> str:
    """``2.9 TiB``, ``23.4 GiB``, ``256 KiB``, ``512 B`` (binary units)."""
    n = int(n)
    for unit, shift in (("EiB", 60), ("PiB", 50), ("TiB", 40), ("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{n} B"


def _stat_regular(path: Path, key: str, value: Any, allowed: str,
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
        raise CaseError(key, value, f"is {_file_kind(st.st_mode)}; {allowed}")
    return st


def _read_regular(path: Path, key: str, value: Any, limit: int, what: str) -> bytes:
    """At most ``limit`` bytes of a regular file, refused (CaseError on ``key``) if it is anything
    else (FIFO, device, directory: checked before opening and on the opened descriptor, opened
    non-blocking so that neither the open nor the check can hang) or larger than ``limit``."""
    allowed = f"must be a regular {what} of at most {format_bytes(limit)}"
    st = _stat_regular(path, key, value, allowed)
    if st.st_size > limit:
        raise CaseError(key, value, f"is {format_bytes(st.st_size)}; {allowed}")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise CaseError(key, value, f"cannot read: {exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)  # the file opened, not the name: it may have been swapped meanwhile
        if not stat.S_ISREG(st.st_mode):
            raise CaseError(key, value, f"is {_file_kind(st.st_mode)}; {allowed}")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 16, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise CaseError(key, value, f"cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > limit:
        raise CaseError(key, value, f"is more than {format_bytes(limit)}; {allowed}")
    return b"".join(chunks)


def _read_toml(path: Path) -> dict:
    raw = _read_regular(path, CASE_FILE, str(path), MAX_CASE_BYTES, "TOML file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CaseError(CASE_FILE, str(path), f"not UTF-8 text (byte {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _TOML_POS.search(msg)
        value: Any = path.name
        if m:
            lines = text.splitlines()
            lineno = int(m.group(1))
            if 1 <= lineno <= len(lines):
                value = lines[lineno - 1].strip()
        raise CaseError(CASE_FILE, value, f"TOML syntax error: {msg}") from None


def _check_finite(data: dict) -> None:
    """Every float of the file is finite (``nan``, ``inf`` pass JSON Schema's ranges: nan > 0 is
    false, so is nan <= 0), unless its key matches a pattern of NON_FINITE_KEYS.  Iterative, so
    nesting depth costs no stack."""
    stack: list[tuple[list, Any]] = [([], data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, dict):
            stack.extend((path + [k], v) for k, v in reversed(list(value.items())))
        elif isinstance(value, list):
            stack.extend((path + [i], v) for i, v in reversed(list(enumerate(value))))
        elif isinstance(value, float) and not math.isfinite(value):
            key = format_key(path)
            if not any(_key_matches(key, pattern) for pattern in NON_FINITE_KEYS):
                raise CaseError(key, value, "must be a finite number (not nan or inf)")


def _key_matches(key: str, pattern: str) -> bool:
    """``pattern``: a dotted key where ``*`` stands for any one table key and ``[]`` for any index,
    e.g. ``check.metrics.*.reference``, ``ale.energy_sources[].energy``."""
    rx = re.escape(pattern).replace(r"\*", r"[^.\[]+").replace(r"\[\]", r"\[\d+\]")
    return re.fullmatch(rx, key) is not None


def _f(v):
    return float(v)


def _num_or_expr(v):
    return v if isinstance(v, str) else float(v)


def _normalise(data: dict, case_dir: Path) -> dict:
    """Fill defaults and convert numbers; assumes the schema validated ``data``."""
    d = copy.deepcopy(data)
    run_in = d["run"]
    dim = int(run_in["dimension"])
    end_time = _f(run_in["end_time"])
    run = {
        "dimension": dim,
        "end_time": end_time,
        "dt_scale": _f(run_in.get("dt_scale", RUN_DEFAULTS["dt_scale"])),
        "output_interval": _f(run_in.get("output_interval", end_time / 20.0)),
        "checkpoint_interval": (None if run_in.get("checkpoint_interval") is None
                                else _f(run_in["checkpoint_interval"])),
        "max_steps": int(run_in.get("max_steps", RUN_DEFAULTS["max_steps"])),
        "diagnostics_every": int(run_in.get("diagnostics_every",
                                            RUN_DEFAULTS["diagnostics_every"])),
    }

    materials = {}
    for name, m in d.get("materials", {}).items():
        materials[name] = {k: (v if k == "model" else _f(v)) for k, v in m.items()}

    lag_in = d.get("lagrange", {})
    bodies = []
    for b in lag_in.get("bodies", []):
        mesh_in = b["mesh"]
        if "box" in mesh_in:
            box = mesh_in["box"]
            mesh = {"box": {"lower": [_f(v) for v in box["lower"]],
                            "upper": [_f(v) for v in box["upper"]],
                            "cells": [int(v) for v in box["cells"]]}}
        elif "quarter_cylinder" in mesh_in:
            q = mesh_in["quarter_cylinder"]
            mesh = {"quarter_cylinder": {"radius": _f(q["radius"]), "length": _f(q["length"]),
                                         "radial_cells": int(q["radial_cells"]),
                                         "axial_cells": int(q["axial_cells"])}}
        else:
            mesh = {"file": (case_dir / mesh_in["file"]).resolve()}
        mat = materials.get(b["material"], {})
        t0 = b.get("initial_temperature", mat.get("room_temperature", DEFAULT_ROOM_TEMPERATURE))
        size = body_mesh_size({"mesh": mesh})  # None for a file: counted when it is read
        bodies.append({
            "name": b["name"],
            "material": b["material"],
            "mesh": mesh,
            "size": None if size is None else {"elements": size[0], "nodes": size[1]},
            "initial_velocity": ([_num_or_expr(v) for v in b["initial_velocity"]]
                                 if "initial_velocity" in b else [0.0] * dim),
            "initial_temperature": _f(t0),
        })
    lagrange = {k: _f(lag_in.get(k, v)) for k, v in LAGRANGE_DEFAULTS.items()}
    lagrange["bodies"] = bodies

    boundaries = []
    for bc in d.get("boundaries", []):
        out = {"type": bc["type"]}
        for k, v in bc.items():
            if k == "type" or k == "region" or k == "axis":
                out[k] = v
            elif k == "velocity":
                out[k] = {c: _f(x) for c, x in v.items()}
            elif k == "at":
                out[k] = _f(v)
            elif k in ("point", "normal"):
                out[k] = [_f(x) for x in v]
        boundaries.append(out)

    check = None
    if "check" in d:
        c = d["check"]
        check = {
            "kind": c["kind"],
            "params": c.get("params", {}),
            "metrics": {n: {"reference": _f(m["reference"]), "tolerance": _f(m["tolerance"])}
                        for n, m in c.get("metrics", {}).items()},
        }

    case = {
        "name": case_dir.name,
        "case_dir": case_dir,
        "run": run,
        "ranks": {},
        "materials": materials,
        "boundaries": boundaries,
        "check": check,
    }
    if "lagrange" in d or "ale" not in d:
        case["lagrange"] = lagrange
    if "ale" in d:
        case["ale"] = _normalise_ale(d["ale"], dim)
    return case


def _normalise_ale(a: dict, dim: int) -> dict:
    """The [ale] table with numbers as floats; solver defaults (viscosity, hourglass) left to the
    solver unless given."""
    grid = a["grid"]
    out = {
        "dimension": dim,
        "mode": a.get("mode", "eulerian"),
        "grid": {"lower": [_f(v) for v in grid["lower"]], "upper": [_f(v) for v in grid["upper"]],
                 "cells": [int(v) for v in grid["cells"]]},
        "boundaries": {},
        "materials": {n: {k: (v if k == "eos" else _f(v)) for k, v in m.items()}
                      for n, m in a["materials"].items()},
        "regions": [],
        "energy_sources": [{"energy": _f(e["energy"]), "at": [_f(v) for v in e["at"]]}
                           for e in a.get("energy_sources", [])],
        "obstacles": [{"region": o["region"], "subsamples": int(o.get("subsamples", 1))}
                      for o in a.get("obstacles", [])],
    }
    if "fraction_samples" in a:
        out["fraction_samples"] = int(a["fraction_samples"])
    if "hourglass" in a:
        out["hourglass"] = _f(a["hourglass"])
    if "viscosity" in a:
        out["viscosity"] = {k: (v if k == "kind" else _f(v)) for k, v in a["viscosity"].items()}
    faces = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")[: 2 * dim]
    for f in faces:
        face = a.get("boundaries", {}).get(f, "wall")
        if isinstance(face, dict) and "piston" in face:
            face = {"piston": {"velocity": _f(face["piston"]["velocity"])}}
        elif isinstance(face, dict):
            inflow = face["inflow"]
            face = {"inflow": {"density": _f(inflow["density"]), "pressure": _f(inflow["pressure"]),
                               "velocity": [_f(v) for v in inflow["velocity"]]}}
        out["boundaries"][f] = face
    for r in a["regions"]:
        reg = {k: (v if k in ("material", "region") else _f(v)) for k, v in r.items() if k != "velocity"}
        reg["velocity"] = [_f(v) for v in r.get("velocity", [0.0] * dim)]
        out["regions"].append(reg)
    return out


def _vec_len(key: str, value: list, dim: int) -> None:
    if len(value) != dim:
        raise CaseError(key, value, f"dimension mismatch: must have {dim} items "
                                    f"(run.dimension = {dim})")


def _expr(key: str, text: str, dim: int, kind: str) -> None:
    try:
        compile_expression(text, expression_names(dim), kind=kind)
    except ExpressionError as exc:
        raise CaseError(key, text, str(exc)) from None


def _check(case: dict, data: dict) -> None:
    """Cross-field checks; fills ``case["ranks"]``.  ``data`` is the raw TOML (for
    reporting values exactly as written)."""
    run = case["run"]
    dim = run["dimension"]

    # [run]
    if run["output_interval"] > run["end_time"]:
        raise CaseError("run.output_interval", data["run"]["output_interval"],
                        f"must be <= run.end_time = {_fmt_num(data['run']['end_time'])} (s)")
    # every output writes one file per solver role and every checkpoint one directory: an interval
    # like 1e-300 s asks for a run that never ends and a directory no file system holds. (Not bounded
    # by run.max_steps: a short trial run with a small max_steps is legitimate.)
    for k in ("output_interval", "checkpoint_interval"):
        if run[k] is not None and run["end_time"] / run[k] > MAX_OUTPUTS:
            raise CaseError(f"run.{k}", data["run"].get(k, run[k]),
                            f"gives {run['end_time'] / run[k]:.3g} {k.split('_')[0]}s over run.end_time "
                            f"= {_fmt_num(run['end_time'])} s, more than {MAX_OUTPUTS:,} "
                            f"(each writes files)")

    # at least one solver: Lagrangian bodies and/or a background
    if "ale" in case:
        _check_ale(case["ale"], data["ale"], dim)
    if "lagrange" in case and not case["lagrange"]["bodies"]:
        raw = data.get("lagrange", {}).get("bodies", MISSING)
        raise CaseError("lagrange.bodies", raw,
                        "at least one body is required ([[lagrange.bodies]]), or a background [ale]")
    if "lagrange" in case and not case["materials"]:
        raise CaseError("materials", MISSING, "required key missing: the bodies' materials, e.g. [materials.steel]")

    # [ranks] (roles only for the solvers this case uses)
    case["ranks"] = ranks_for({**{r: case[r] for r in ("lagrange", "ale") if r in case},
                               "ranks": data.get("ranks", {})})

    # [materials]
    for name, m in case["materials"].items():
        _check_wave_speed(name, m, data["materials"][name])
        if m["model"] == "johnson_cook" and not m["melt_temperature"] > m["room_temperature"]:
            raw = data["materials"][name]
            raise CaseError(format_key(["materials", name, "melt_temperature"]),
                            raw["melt_temperature"],
                            f"must be > room_temperature = {_fmt_num(raw['room_temperature'])} (K)")

    # [lagrange]
    bodies = case.get("lagrange", {}).get("bodies", [])
    raw_bodies = data.get("lagrange", {}).get("bodies", [])
    seen: dict[str, int] = {}
    for i, (body, raw) in enumerate(zip(bodies, raw_bodies)):
        base = ["lagrange", "bodies", i]
        if body["name"] in seen:
            raise CaseError(format_key(base + ["name"]), body["name"],
                            f"duplicate body name (also lagrange.bodies[{seen[body['name']]}].name)")
        seen[body["name"]] = i
        if body["material"] not in case["materials"]:
            defined = ", ".join(case["materials"]) or "(none)"
            raise CaseError(format_key(base + ["material"]), body["material"],
                            f"undefined material; defined: {defined}")
        mesh = raw["mesh"]
        if "box" in mesh:
            box = mesh["box"]
            for k in ("lower", "upper", "cells"):
                _vec_len(format_key(base + ["mesh", "box", k]), box[k], dim)
            for j, (lo, hi) in enumerate(zip(box["lower"], box["upper"])):
                if not hi > lo:
                    raise CaseError(format_key(base + ["mesh", "box", "upper"]), box["upper"],
                                    f"must be > lower component-wise (component {j}: "
                                    f"{_fmt_num(hi)} <= {_fmt_num(lo)})")
            _check_extent(format_key(base + ["mesh", "box"]), body["mesh"]["box"], box)
        elif "quarter_cylinder" in mesh:
            if dim != 3:
                raise CaseError(format_key(base + ["mesh", "quarter_cylinder"]),
                                mesh["quarter_cylinder"],
                                f"quarter_cylinder meshes are 3D only (run.dimension = {dim})")
        if "initial_velocity" in raw:
            v = raw["initial_velocity"]
            _vec_len(format_key(base + ["initial_velocity"]), v, dim)
            for j, item in enumerate(v):
                if isinstance(item, str):
                    _expr(format_key(base + ["initial_velocity", j]), item, dim, NUM)
        mat = case["materials"][body["material"]]
        if mat["model"] == "johnson_cook" and "initial_temperature" in raw:
            if not body["initial_temperature"] < mat["melt_temperature"]:
                raise CaseError(format_key(base + ["initial_temperature"]),
                                raw["initial_temperature"],
                                f"must be < melt_temperature = {_fmt_num(mat['melt_temperature'])}"
                                f" of material {body['material']!r} (K)")

    # [[boundaries]]
    comps = expression_names(dim)
    for i, (bc, raw) in enumerate(zip(case["boundaries"], data.get("boundaries", []))):
        base = ["boundaries", i]
        if "region" in raw:
            _expr(format_key(base + ["region"]), raw["region"], dim, BOOL)
        if "velocity" in raw:
            for c in raw["velocity"]:
                if c not in comps:
                    raise CaseError(format_key(base + ["velocity", c]), raw["velocity"][c],
                                    f"dimension mismatch: no {c} component in a {dim}D case; "
                                    f"allowed: {', '.join(comps)}")
        if "axis" in raw and raw["axis"] not in comps:
            raise CaseError(format_key(base + ["axis"]), raw["axis"],
                            f"dimension mismatch: must be one of {', '.join(comps)} in a "
                            f"{dim}D case")
        for k in ("point", "normal"):
            if k in raw:
                _vec_len(format_key(base + [k]), raw[k], dim)
        if "normal" in raw:  # its length squared is taken: it must neither vanish nor overflow
            n2 = math.fsum(float(c) * float(c) for c in raw["normal"])
            if not (n2 > 0.0 and math.isfinite(n2)):
                raise CaseError(format_key(base + ["normal"]), raw["normal"],
                                "must be a non-zero vector whose squared length is a finite "
                                "float (e.g. a unit vector)")

    # [check]: kind must be a registered check
    if case["check"] is not None:
        from orchestrator.checks import CHECKS  # lazy: the registry imports numpy etc.

        kind = case["check"]["kind"]
        if kind not in CHECKS:
            raise CaseError("check.kind", kind, "unknown check kind; registered: "
                            + ", ".join(sorted(CHECKS)))

    # mesh files last: reading them may be slow; every path is checked before any file is read
    files = [(format_key(["lagrange", "bodies", i, "mesh", "file"]), raw_bodies[i]["mesh"]["file"], body)
             for i, body in enumerate(bodies) if "file" in body["mesh"]]
    for key, raw, body in files:
        check_path_inside(key, raw, body["mesh"]["file"], case["case_dir"])
    for key, raw, body in files:
        body["size"] = _check_mesh_file(key, raw, body["mesh"]["file"], dim)


def _check_ale(ale: dict, raw: dict, dim: int) -> None:
    """Cross-field rules of [ale]: vector lengths, grid extent, periodic pairs, material references,
    region and obstacle expressions (obstacles in Eulerian mode only)."""
    for k in ("lower", "upper", "cells"):
        _vec_len(format_key(["ale", "grid", k]), raw["grid"][k], dim)
    for j, (lo, hi) in enumerate(zip(ale["grid"]["lower"], ale["grid"]["upper"])):
        if not hi > lo:
            raise CaseError("ale.grid.upper", raw["grid"]["upper"],
                            f"must be > lower component-wise (component {j})")
    _check_extent("ale.grid", ale["grid"], raw["grid"])
    axes = ("x", "y", "z")[:dim]
    raw_faces = raw.get("boundaries", {})
    for f in raw_faces:
        if f[0] not in axes:
            raise CaseError(format_key(["ale", "boundaries", f]), raw_faces[f],
                            f"dimension mismatch: no {f[0]} faces in a {dim}D case")
    for a in axes:
        lo, hi = ale["boundaries"][f"{a}_lower"], ale["boundaries"][f"{a}_upper"]
        if (lo == "periodic") != (hi == "periodic"):
            raise CaseError(format_key(["ale", "boundaries", f"{a}_lower" if lo == "periodic" else f"{a}_upper"]),
                            "periodic", f"periodic must be set on both {a}_lower and {a}_upper")
        for f in (f"{a}_lower", f"{a}_upper"):
            face = ale["boundaries"][f]
            if isinstance(face, dict) and "piston" in face:
                if ale["mode"] != "lagrangian":
                    raise CaseError(format_key(["ale", "boundaries", f, "piston"]), raw_faces[f]["piston"],
                                    "piston faces need ale.mode = \"lagrangian\" (the face nodes move with the piston)")
            elif isinstance(face, dict):
                _vec_len(format_key(["ale", "boundaries", f, "inflow", "velocity"]),
                         raw_faces[f]["inflow"]["velocity"], dim)
    for i, (reg, r) in enumerate(zip(ale["regions"], raw["regions"])):
        base = ["ale", "regions", i]
        if reg["material"] not in ale["materials"]:
            raise CaseError(format_key(base + ["material"]), reg["material"],
                            "undefined material; defined in [ale.materials]: " + ", ".join(ale["materials"]))
        void = ale["materials"][reg["material"]]["eos"] == "void"
        if void and "density" in r:
            raise CaseError(format_key(base + ["density"]), r["density"],
                            f"material {reg['material']!r} is void: a void region has no density, "
                            "pressure or specific_internal_energy")
        if not void and "density" not in r:
            raise CaseError(format_key(base), r, "needs material, density and exactly one of pressure, "
                            "specific_internal_energy (a void material: none of them)")
        if "velocity" in r:
            _vec_len(format_key(base + ["velocity"]), r["velocity"], dim)
        if "region" in r:
            _expr(format_key(base + ["region"]), r["region"], dim, BOOL)
    _check_ale_mixed(ale, raw)
    lo, hi = ale["grid"]["lower"], ale["grid"]["upper"]
    for i, e in enumerate(raw.get("energy_sources", [])):
        _vec_len(format_key(["ale", "energy_sources", i, "at"]), e["at"], dim)
        if not all(a <= float(x) <= b for a, x, b in zip(lo, e["at"], hi)):
            raise CaseError(format_key(["ale", "energy_sources", i, "at"]), e["at"],
                            f"must lie in the grid, from ale.grid.lower = {raw['grid']['lower']} to "
                            f"ale.grid.upper = {raw['grid']['upper']} (m)")
    for i, o in enumerate(raw.get("obstacles", [])):
        _expr(format_key(["ale", "obstacles", i, "region"]), o["region"], dim, BOOL)
        if ale["mode"] != "eulerian":
            raise CaseError(format_key(["ale", "obstacles"]), raw["obstacles"],
                            "obstacles need ale.mode = \"eulerian\" (the remap keeps material out of them)")


def _check_ale_mixed(ale: dict, raw: dict) -> None:
    """Several materials per zone (or void): Eulerian mode, no obstacles or inflow faces yet."""
    used = list(dict.fromkeys(r["material"] for r in ale["regions"]))
    voids = [m for m in used if ale["materials"][m]["eos"] == "void"]
    if len(used) == 1 and not voids:
        return
    if len(voids) == len(used):
        raise CaseError("ale.regions", [r["material"] for r in raw["regions"]],
                        "void only: at least one region needs a material with an equation of state")
    what = "several materials" if len(used) > 1 else "a void material"
    if ale["mode"] != "eulerian":
        raise CaseError("ale.mode", raw.get("mode"), f"{what} in ale.regions need mode = \"eulerian\"")
    if raw.get("obstacles"):
        raise CaseError("ale.obstacles", raw["obstacles"], f"not supported yet with {what} in ale.regions")
    for f, face in ale["boundaries"].items():
        if isinstance(face, dict) and "inflow" in face:
            raise CaseError(format_key(["ale", "boundaries", f]), raw["boundaries"][f],
                            f"inflow faces are not supported yet with {what} in ale.regions")


def _check_extent(key: str, box: dict, raw: dict) -> None:
    """Finite numbers whose differences are not: an extent upper - lower that overflows, zones so
    small that their volume underflows (the solvers divide by it)."""
    widths = [hi - lo for lo, hi in zip(box["lower"], box["upper"])]
    if not all(math.isfinite(w) for w in widths):
        raise CaseError(f"{key}.upper", raw["upper"], "upper - lower must be a finite number "
                        "(it overflows); allowed: extents below 1e308 m")
    volume = math.prod(w / c for w, c in zip(widths, box["cells"]))
    if not volume >= sys.float_info.min:
        raise CaseError(f"{key}.cells", raw["cells"], f"zones of {_fmt_num(volume)} m^{len(widths)} "
                        "are too small to compute with (their volume underflows a float); allowed: "
                        "fewer cells or a larger extent")


def _check_wave_speed(name: str, m: dict, raw: dict) -> None:
    """The elastic wave speed sqrt(M / rho), M the P-wave modulus, sets the time step: it must be a
    finite number (a huge modulus over a tiny density overflows it: dt = 0, a run that never ends)."""
    nu = m["poisson_ratio"]
    with_modulus = m["youngs_modulus"] * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))
    c2 = with_modulus / m["density"]
    if not (math.isfinite(c2) and c2 > 0.0):
        raise CaseError(format_key(["materials", name, "youngs_modulus"]), raw["youngs_modulus"],
                        f"gives an elastic wave speed that is not a finite number with density = "
                        f"{_fmt_num(m['density'])} kg/m^3; allowed: moduli and densities whose "
                        "ratio is a float")


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


_CELL_TYPE = {2: "quad", 3: "hexahedron"}


def _check_mesh_file(key: str, raw: str, path: Path, dim: int) -> dict:
    """Read and check a body's mesh file; its ``{"elements", "nodes"}`` counts."""
    from orchestrator.resources import machine_memory

    memory = machine_memory()
    limit = memory // MESH_READ_FACTOR
    st = _stat_regular(path, key, raw, "must be a regular mesh file",
                       not_found="file not found (paths are relative to the case directory)")
    if st.st_size > limit:
        raise CaseError(key, raw, f"is {format_bytes(st.st_size)}: reading it takes about "
                                  f"{MESH_READ_FACTOR} times that, this machine has "
                                  f"{format_bytes(memory)}; allowed: mesh files up to "
                                  f"{format_bytes(limit)} here")
    if not os.access(path, os.R_OK):
        raise CaseError(key, raw, "file is not readable (permission denied)")
    from solvers.lagrange.mesh import MeshError, read_mesh  # lazy: heavy imports

    expected = _CELL_TYPE[dim]

    try:
        mesh = read_mesh(path, dim)
    except MeshError as exc:
        raise CaseError(key, raw, f"must be a readable {expected} mesh ({exc})") from None
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad input file
        raise CaseError(key, raw, f"must be a readable {expected} mesh "
                                  f"({type(exc).__name__}: {exc})") from None
    if getattr(mesh, "cell_type", expected) != expected or len(mesh.cells) == 0:
        raise CaseError(key, raw, f"must be a readable {expected} mesh (no {expected} cells "
                                  f"for a {dim}D case)")
    return {"elements": int(len(mesh.cells)), "nodes": int(len(mesh.points))}
