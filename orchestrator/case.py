"""Load and validate a case directory (``<case_dir>/case.toml``).

:func:`load_case` returns a normalised plain dict (defaults filled in, numbers as
``float``/``int``, mesh file paths resolved to absolute :class:`~pathlib.Path`\\ s,
expressions kept as strings but already checked to compile) or raises :class:`CaseError`
whose message is ONE line ``"<dotted.key> = <value repr>: <what is allowed>"``.

This module owns the pipeline and the core tables (``[run]``, ``[ranks]``, ``[check]``); every
other top-level table is registered with its schema fragment, normaliser and checks by the code
that owns it (:mod:`orchestrator.schema.registry`: ``[materials]``, ``[lagrange]`` and
``[[boundaries]]`` in :mod:`orchestrator.schema.lagrange`, ``[ale]`` in
:mod:`orchestrator.schema.ale`); the loops below never name them.

Validation happens in stages, the first failure wins:

1. reading: ``case.toml`` must be a regular file (not a FIFO, device, directory; checked with
   ``stat`` and again on the opened descriptor, opened non-blocking so a FIFO cannot hang) of at
   most :data:`MAX_CASE_BYTES` (256 KiB; at most that much is ever read), UTF-8; TOML parsing
   (``tomllib``): a syntax error, or nesting beyond Python's recursion limit, is reported on the
   key ``case.toml``;
2. the JSON schema of :mod:`orchestrator.schema.case` (types, ranges, required keys,
   enums, unknown keys); the best error (``jsonschema.exceptions.best_match``) is
   translated into a :class:`CaseError` on its dotted key path; then every float of the
   file must be finite (``nan``/``inf`` pass JSON Schema's range checks), unless its key is
   listed in :data:`orchestrator.schema.case.NON_FINITE_KEYS`;
3. cross-field checks in Python: ``[run]`` (outputs against the end time), then each registered
   table's (vector lengths vs ``run.dimension``, material references, expressions (compiled;
   constant parts such as ``9**9**9`` folded and refused here), sanity of finite numbers
   (extents whose zones underflow, energy sources outside the grid, wave speeds that overflow),
   ...), then the ``[ranks]`` roles, then the ``[check]`` kind;
4. data files last (reading them may be slow), each table's ``check_files``: a mesh path must
   resolve (symlinks and ``..`` followed) inside the case directory or a directory of
   ``$IMMERSE_ALLOW_PATH``; a regular file small enough to read here; parsed by meshio into the
   right cells.

What needs the machine (rank counts, memory: :mod:`orchestrator.resources`) and the expressions
evaluated on the case's own points (:mod:`orchestrator.expressions`) are checked by the CLI after
this, before anything launches.

Normalised layout (all keys always present)::

    {"name": str, "case_dir": Path,
     "run": {dimension, end_time, dt_scale, output_interval, checkpoint_interval (None if
             unset), max_steps, diagnostics_every, dt_min (None if unset), multirate (None if
             unset: where a group can substep and it pays, multirate.DEFAULT_ON), max_substeps, group_dt_max {role: s}},
     "ranks": {role: int}  (1 for every used solver unless given),
     "check": None | {kind, params, metrics: {name: {reference, tolerance}}},
     ... and the registered tables: "materials", "boundaries" (always), "lagrange", "ale" (when
     used); their layouts are in their fragment modules' docstrings.}
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import math
import numbers
import os
import re
import stat
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from adapters import registry as _roles

from .schema import registry as schema_registry
from .schema.case import (
    CASE_SCHEMA,
    KNOWN_ROLES,
    NAME_TEXT,
    NON_FINITE_KEYS,
    RUN_DEFAULTS,
)
from .schema.rules import (  # noqa: F401  (re-exported: the names this module always offered)
    ALLOW_PATH_ENV,
    MISSING,
    CaseError,
    allowed_roots,
    check_path_inside,
    expression_names,
    format_bytes,
    format_key,
)
from .schema.rules import file_kind as _file_kind
from .schema.rules import fmt_num as _fmt_num
from .schema.rules import stat_regular as _stat_regular
from .schema.rules import to_float as _f

if TYPE_CHECKING:
    from jsonschema.exceptions import ValidationError

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


# ----------------------------------------------------------------------------------
# schema errors -> CaseError
def _relevance(err: ValidationError):
    """jsonschema's relevance without its sibling order (which prefers the LAST sibling): among
    equally relevant errors the first in the file wins."""
    from jsonschema.exceptions import relevance

    key = relevance(err)
    return key[:1] + key[2:]


_VALIDATORS: dict[int, tuple] = {}
"""id(schema) -> (schema, its Draft 2020-12 validator), built on first use (the schema is kept so
that its id is not reused)."""


class _Unsupported(Exception):
    """A schema construct :func:`_conforms` does not evaluate itself (jsonschema decides)."""


_ANNOTATIONS = frozenset({"$schema", "$id", "$comment", "title", "description", "default", "examples",
                          "deprecated", "readOnly", "writeOnly", "then", "else"})
"""Keywords that assert nothing by themselves ("then"/"else" are evaluated under "if"; "x-..." keys,
this project's annotations, are skipped too)."""


def _json_type(inst: Any, name: str) -> bool:
    """jsonschema's Draft 2020-12 type checker (bool is no number; 1.0 is an integer)."""
    if name == "object":
        return isinstance(inst, dict)
    if name == "array":
        return isinstance(inst, list)
    if name == "string":
        return isinstance(inst, str)
    if name == "boolean":
        return isinstance(inst, bool)
    if name == "null":
        return inst is None
    if name in ("number", "integer"):
        if isinstance(inst, bool):
            return False
        if not isinstance(inst, (int, float)):
            return False   # (another kind of number never gets here: _conforms leaves it to jsonschema)
        return name == "number" or isinstance(inst, int) or inst.is_integer()
    raise _Unsupported(name)


def _json_equal(one: Any, two: Any) -> bool:
    """jsonschema's equality (``jsonschema._utils.equal``: True is not 1, lists and tables by item)."""
    if one is two:
        return True
    if isinstance(one, str) or isinstance(two, str):
        return one == two
    if isinstance(one, list) and isinstance(two, list):
        return len(one) == len(two) and all(_json_equal(a, b) for a, b in zip(one, two))
    if isinstance(one, dict) and isinstance(two, dict):
        return len(one) == len(two) and all(k in two and _json_equal(v, two[k]) for k, v in one.items())
    if isinstance(one, (tuple, list, dict, bytes)) or isinstance(two, (tuple, list, dict, bytes)):
        raise _Unsupported("equal")
    if isinstance(one, bool) or isinstance(two, bool):
        return type(one) is type(two) and one == two
    return one == two


def _conforms(schema: Any, inst: Any) -> bool:
    """Whether ``inst`` is valid against ``schema`` as Draft 2020-12 (jsonschema) has it, for the
    keywords this project's schemas use; raises _Unsupported for any other.  The accepting path of
    the schema check: jsonschema (0.1 s to import, a third of `immerse check`'s and of the launcher's
    start) is imported only to name the error of a case this finds invalid, or to decide what this
    does not evaluate (tests/orchestrator/test_case.py checks both agree on every case text)."""
    if schema is True:
        return True
    if schema is False:
        return False
    if not isinstance(schema, dict):
        raise _Unsupported("schema")
    is_obj, is_arr = isinstance(inst, dict), isinstance(inst, list)
    is_num = not isinstance(inst, bool) and isinstance(inst, (int, float))
    if not is_num and not isinstance(inst, (bool, str, dict, list)) and isinstance(inst, numbers.Number):
        raise _Unsupported("number")   # another kind of number (not from TOML): jsonschema decides
    for key, value in schema.items():
        if key in _ANNOTATIONS or key.startswith("x-"):
            continue
        if key == "type":
            types = value if isinstance(value, list) else [value]
            ok = any(_json_type(inst, t) for t in types)
        elif key == "properties":
            ok = not is_obj or all(_conforms(sub, inst[k]) for k, sub in value.items() if k in inst)
        elif key == "required":
            ok = not is_obj or all(k in inst for k in value)
        elif key == "additionalProperties":
            if "patternProperties" in schema:
                raise _Unsupported(key)
            props = schema.get("properties", {})
            extras = [k for k in inst if k not in props] if is_obj else []
            ok = (all(_conforms(value, inst[k]) for k in extras) if isinstance(value, dict)
                  else bool(value) or not extras)
        elif key == "items":
            if "prefixItems" in schema or not isinstance(value, (dict, bool)):
                raise _Unsupported(key)
            ok = not is_arr or all(_conforms(value, item) for item in inst)
        elif key in ("minItems", "maxItems", "minProperties", "maxProperties", "minLength", "maxLength"):
            applies = is_arr if key.endswith("Items") else is_obj if key.endswith("Properties") else isinstance(inst, str)
            ok = not applies or (len(inst) >= value if key.startswith("min") else len(inst) <= value)
        elif key in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
            ok = not is_num or {"minimum": lambda: not inst < value, "maximum": lambda: not inst > value,
                                "exclusiveMinimum": lambda: not inst <= value,
                                "exclusiveMaximum": lambda: not inst >= value}[key]()
        elif key == "enum":
            ok = any(_json_equal(e, inst) for e in value)
        elif key == "const":
            ok = _json_equal(value, inst)
        elif key == "pattern":
            ok = not isinstance(inst, str) or re.search(value, inst) is not None
        elif key == "uniqueItems":
            ok = not (value and is_arr) or not any(
                _json_equal(a, b) for i, a in enumerate(inst) for b in inst[i + 1:])
        elif key == "propertyNames":
            ok = not is_obj or all(_conforms(value, k) for k in inst)
        elif key == "allOf":
            ok = all(_conforms(sub, inst) for sub in value)
        elif key == "anyOf":
            ok = any(_conforms(sub, inst) for sub in value)
        elif key == "oneOf":
            ok = sum(1 for sub in value if _conforms(sub, inst)) == 1
        elif key == "not":
            ok = not _conforms(value, inst)
        elif key == "if":
            branch = "then" if _conforms(value, inst) else "else"
            ok = branch not in schema or _conforms(schema[branch], inst)
        else:
            raise _Unsupported(key)
        if not ok:
            return False
    return True


def _best_schema_error(schema: Mapping | None, data: Any):
    """The most relevant of the first ``_MAX_SCHEMA_ERRORS`` errors of ``data`` against ``schema``
    (the case schema when None), or None.  jsonschema is imported here, where a schema is checked
    (the CLI), not at import (the job's processes read the case the launcher checked,
    adapters/case_file.py, without this module); and only for data that
    :func:`_conforms` does not accept (a valid case is accepted without it: 0.1 s of every
    `immerse check` and `immerse run`).  (The schema itself is validated against the metaschema by
    the tests, not here: that took 0.3-0.6 s of every `immerse` command.)"""
    schema = CASE_SCHEMA if schema is None else schema
    try:
        if _conforms(schema, data):
            return None
    except (_Unsupported, TypeError, re.error):   # (decided by jsonschema, which says what is wrong)
        pass
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import best_match

    if id(schema) not in _VALIDATORS:
        _VALIDATORS[id(schema)] = (schema, Draft202012Validator(schema))
    errors = itertools.islice(_VALIDATORS[id(schema)][1].iter_errors(data), _MAX_SCHEMA_ERRORS)
    return best_match(errors, key=_relevance)


_TYPE_WORDS = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "object": "a table",
    "array": "an array",
    "boolean": "a boolean (true/false)",
}


def _unit(schema: Mapping) -> str:
    unit = schema.get("x-unit") if isinstance(schema, Mapping) else None
    return f" ({unit})" if unit else ""


def _range_text(schema: Mapping, with_unit: bool = False) -> str:
    """"must be > 0 (kg/m^3)"; the physical range a unit adds (schema/parts.py UNIT_LIMITS) after the
    key's own bounds: "must be > 0 (kg/m^3), at most 1e+06 (the physical range)"."""
    physical = schema.get("x-physical", ())
    parts, extra = [], []
    for k, op in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<")):
        if k in schema:
            (extra if k in physical else parts).append(f"{op} {_fmt_num(schema[k])}")
    kind = "an integer " if schema.get("type") == "integer" else ""
    unit = _unit(schema) if with_unit else ""
    if not parts:
        return f"must be {kind}" + " and ".join(extra) + unit + " (the physical range)"
    text = f"must be {kind}" + " and ".join(parts) + unit
    return text + (f", and {' and '.join(extra)} (the physical range)" if extra else "")


def _type_text(schema: Mapping) -> str:
    types = schema.get("type")
    if isinstance(types, list):
        if set(types) == {"number", "string"}:
            return "must be a number or an expression string"
        return "must be " + " or ".join(_TYPE_WORDS.get(t, t) for t in types)
    text = "must be " + _TYPE_WORDS.get(types, str(types))
    if any(k in schema for k in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum")):
        text += " " + _range_text(schema).removeprefix("must be ").removeprefix("an integer ")
        return text   # (the caller adds the unit)
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


def _schema_error_to_case_error(err: ValidationError, prefix: tuple = ()) -> CaseError:
    """One line for a schema error; ``prefix``: the path of the validated instance in the case file
    (a fragment validated on its own, such as a check kind's ``[check] params``)."""
    path = list(prefix) + list(err.absolute_path)
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
        return CaseError(key, inst, _range_text(schema, with_unit=True))
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
def solvers_used(case: Mapping) -> list[str]:
    """Solver roles the case needs (the adapter registry knows which case table means which role)."""
    return [r for r in _roles.roles_used(case) if case.get(r)]


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
    """Parse and validate ``<case_dir>/case.toml``; return the normalised case dict, with
    ``case["case_sha256"]``, the SHA-256 of the bytes it was read from.

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
        data, sha = _read_toml(toml_path)
        _check_finite(data)   # (first: an inf is "not finite", not "beyond the range")
        from orchestrator.schema.spellings import respell

        notes = respell(data)   # (older spellings under their one name, before the schema sees them)
        err = _best_schema_error(None, data)
        if err is not None:
            raise _schema_error_to_case_error(err)

        case = _normalise(data, case_dir)
        _check(case, data)
    except RecursionError:  # a structure nested past Python's limit anywhere in the pipeline
        raise CaseError(CASE_FILE, str(toml_path), "nested too deeply (arrays or tables inside "
                        "each other beyond what can be read)") from None
    case["case_sha256"] = sha   # (after the tables' hooks: they see the documented layout)
    case["_notes"] = notes      # (printed by check and run; not part of the case's identity)
    return case


# ----------------------------------------------------------------------------------
# stages
_TOML_POS = re.compile(r"at line (\d+), column (\d+)")


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


def _read_toml(path: Path) -> tuple[dict, str]:
    """The parsed file and the SHA-256 (hex) of its bytes."""
    raw = _read_regular(path, CASE_FILE, str(path), MAX_CASE_BYTES, "TOML file")
    sha = hashlib.sha256(raw).hexdigest()
    try:   # (utf-8-sig: a byte-order mark, which some Windows editors write first, is not text)
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise CaseError(CASE_FILE, str(path), f"not UTF-8 text (byte {exc.start})") from None
    try:
        return tomllib.loads(text), sha
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


def _normalise(data: dict, case_dir: Path) -> dict:
    """Fill defaults and convert numbers; assumes the schema validated ``data``.  The core tables
    here, then every registered table's normaliser by order (schema/registry.py, hook 2)."""
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
        "dt_min": None if run_in.get("dt_min") is None else _f(run_in["dt_min"]),
        "multirate": run_in.get("multirate"),
        "max_substeps": int(run_in.get("max_substeps", 64)),
        "group_dt_max": {r: _f(v) for r, v in run_in.get("group_dt_max", {}).items()},
    }

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
        "check": check,
    }
    no_solver_table = not _roles.roles_used(d)
    for t in schema_registry.tables():
        raw = d.get(t.name)
        if raw is None and t.default and no_solver_table:
            raw = {}  # a case file without any solver table is one for the default solver
        value = t.normalise(raw, case)
        if value is not None:
            case[t.name] = value
    return case


def _check_multirate(case: dict, data: dict) -> None:
    """run.group_dt_max names roles the case uses (run.multirate's own rules are the coupling
    table's: orchestrator/schema/coupling.py)."""
    run = case["run"]
    used = _roles.roles_used(case)
    for r in run["group_dt_max"]:
        if r not in used:
            raise CaseError(f"run.group_dt_max.{r}", data["run"]["group_dt_max"][r],
                            f"the case has no {r} group; its groups: {', '.join(used)}")


def _check(case: dict, data: dict) -> None:
    """Cross-field checks; fills ``case["ranks"]``.  ``data`` is the raw TOML (for
    reporting values exactly as written); the check kind's params against their schema too.  Order:
    [run], the registered tables' checks by order,
    [ranks], [check], the registered tables' file checks (schema/registry.py, hooks 3 and 4)."""
    run = case["run"]

    # [run]
    if run["dt_min"] is not None and run["dt_min"] >= run["end_time"]:
        raise CaseError("run.dt_min", data["run"]["dt_min"],
                        f"must be < run.end_time = {_fmt_num(data['run']['end_time'])} (s)")
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

    # the registered tables (the solvers')
    for t in schema_registry.tables():
        if t.check is not None and t.name in case:
            t.check(case, data)

    _check_multirate(case, data)

    # [ranks] (roles only for the solvers this case uses)
    case["ranks"] = ranks_for({**case, "ranks": data.get("ranks", {})})

    # [check]: kind must be a registered check
    if case["check"] is not None:
        from orchestrator.checks import CHECKS  # lazy: the registry imports numpy etc.

        from orchestrator.checks import PARAMS

        kind = case["check"]["kind"]
        if kind not in CHECKS:
            raise CaseError("check.kind", kind, "unknown check kind; registered: "
                            + ", ".join(sorted(CHECKS)))
        # the kind's params: unknown keys, types, ranges, what it needs (before anything runs)
        err = _best_schema_error(PARAMS[kind], data["check"].get("params", {}))
        if err is not None:
            raise _schema_error_to_case_error(err, ("check", "params"))
        from orchestrator.checks import RULES

        bad = RULES[kind](case, case["check"].get("params", {})) if kind in RULES else None
        if bad is not None:
            raise CaseError(f"check.params.{bad[0]}", data["check"]["params"][bad[0]], bad[1])

    # data files last: reading them may be slow
    for t in schema_registry.tables():
        if t.check_files is not None and t.name in case:
            t.check_files(case, data)
