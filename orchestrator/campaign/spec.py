"""Read and validate a campaign file (``CAMPAIGN.toml``) and expand it into runs.

A campaign is series x the product of its axes. Each series names a case directory (relative to
the campaign file) and the keys it sets; each axis names its levels (``values``) and, per level,
the value of one or more case keys (keys of one axis vary together). A series may add keys to an
axis (``[series.axes.NAME]``: e.g. the wall position that has to follow the resolution). A key is a
case.toml key by its dotted path, ``lagrange.bodies[0].mesh.box.lower`` (or ``...bodies.0...``).

Every expanded run is an ordinary case directory: its case.toml is the base case's with the keys
set, checked by :func:`orchestrator.case.load_case` and the machine check of ``immerse check``
before anything starts. A problem is one line naming the key (a campaign key, or ``run NAME:``
followed by the case key), the value and what is allowed (:class:`~orchestrator.case.CaseError`).

Layout of :class:`Campaign`: ``name``, ``path`` (the file), ``description``, ``timeout_s`` (per run,
None: none), ``report`` (dict, see SCHEMA), ``series`` (list of dicts), ``axes`` ({name: values}),
``runs`` (list of :class:`RunSpec`, series-major, axes in file order, last axis fastest).
"""
from __future__ import annotations

import copy
import itertools
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from orchestrator.schema.parts import number
from orchestrator.schema.rules import CaseError, MISSING, format_key

CAMPAIGN_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*(\[\d+\]|\.[A-Za-z0-9_-]+)*$")
_SEGMENT = re.compile(r"([^.\[\]]+)|\[(\d+)\]")
MAX_RUNS = 500
"""Most runs a campaign may expand into (a typo such as a 1000-level axis is refused, not queued).
Every run's case is checked before anything starts, 7.7 ms a run here (its case copied and loaded:
2000 runs took 15.5 s to name a bad last one): 500 keep that check within the 5 s of any refusal."""

_SCALAR = {"type": ["number", "string", "boolean"]}
_VALUE = {}  # any TOML value a case key may take (checked by the case's own schema afterwards)
_KEYS = {"type": "object", "propertyNames": {"pattern": CAMPAIGN_KEY.pattern},
         "additionalProperties": _VALUE, "x-allowed": "a table of dotted case keys"}
_AXIS = {"type": "object", "required": ["values"],
         "properties": {"values": {"type": "array", "minItems": 1, "items": _SCALAR,
                                   "x-allowed": "must be an array of the axis's levels (numbers or names)"}},
         "propertyNames": {"pattern": CAMPAIGN_KEY.pattern},
         "additionalProperties": {"type": "array", "minItems": 1}}
_SERIES_AXIS = {"type": "object", "propertyNames": {"pattern": CAMPAIGN_KEY.pattern},
                "additionalProperties": {"type": "array", "minItems": 1}}
_NAME = {"type": "string", "minLength": 1, "maxLength": 80, "pattern": r"^[^\n\r\t/\\]+$"}

SCHEMA = {
    "type": "object",
    "required": ["name", "series"],
    "additionalProperties": False,
    "properties": {
        "name": _NAME,
        "description": {"type": "string"},
        "timeout": number("s", exclusiveMinimum=0),   # (<= 1e9 s: orchestrator/schema/parts.py)
        "axes": {"type": "object", "propertyNames": {"pattern": r"^[A-Za-z_][A-Za-z0-9_-]*$"},
                 "additionalProperties": _AXIS},
        "series": {
            "type": "array", "minItems": 1,
            "items": {
                "type": "object", "required": ["name", "case"], "additionalProperties": False,
                "properties": {
                    "name": _NAME,
                    "case": {"type": "string", "minLength": 1},
                    "chart": _NAME,
                    "error": {"type": "string", "minLength": 1},
                    "relative_to": _NAME,
                    "vary": {"type": "array", "items": {"type": "string"}, "uniqueItems": True,
                             "x-allowed": "must be an array of axis names (the axes this series runs over)"},
                    "set": _KEYS,
                    # keys of the base case this series leaves out (e.g. an implicit case's
                    # lagrange.time_step when the series runs it explicitly)
                    "unset": {"type": "array", "items": {"type": "string", "minLength": 1}, "uniqueItems": True,
                              "x-allowed": "must be an array of dotted case keys"},
                    "axes": {"type": "object", "additionalProperties": _SERIES_AXIS},
                },
            },
        },
        "report": {
            "type": "object", "additionalProperties": False,
            "properties": {
                "error": {"type": "string", "minLength": 1},
                "error_label": {"type": "string", "minLength": 1},
                "reference": {"type": "string", "minLength": 1},
                "resolution": {"type": "string", "minLength": 1},
                "resolution_label": {"type": "string", "minLength": 1},
                "map": {"type": "string", "minLength": 1},
                "map_label": {"type": "string", "minLength": 1},
                "charts": {"type": "object", "additionalProperties": {
                    "type": "object", "additionalProperties": False,
                    "properties": {"error_label": {"type": "string", "minLength": 1},
                                   "reference": {"type": "string", "minLength": 1},
                                   # the chart's own x axis (its series vary another axis)
                                   "resolution": {"type": "string", "minLength": 1},
                                   "resolution_label": {"type": "string", "minLength": 1}}},
                    "x-allowed": "must be a table of chart names, each { error_label, reference, resolution, "
                                 "resolution_label }"},
                "plots": {"type": "array", "items": {
                    "type": "object", "required": ["value", "label"], "additionalProperties": False,
                    "properties": {"value": {"type": "string", "minLength": 1},
                                   "label": {"type": "string", "minLength": 1}}},
                    "x-allowed": "must be an array of { value = <check metric or reported value>, label = <axis label with unit> }"},
                "picture": {"type": "string", "minLength": 1,
                            "x-allowed": "must be the name of an output field (density, pressure, ...)"},
            },
        },
    },
}


@dataclass
class RunSpec:
    name: str  # directory name: series and levels, e.g. "conforming-zones100"
    series: str  # the series' name
    case_dir: Path  # the base case directory
    levels: dict[str, Any]  # axis name -> level value
    settings: dict[str, Any]  # dotted case key -> value (series' set, then the axes')
    chart: str
    error: str | None
    relative_to: str | None = None  # series whose run (at the same levels) is this one's reference
    index: int = 0  # position in the campaign (array task id)
    ranks: dict = field(default_factory=dict)  # role -> ranks (filled by check_runs)
    data: dict = field(default_factory=dict, repr=False)  # the run's case.toml content


@dataclass
class Campaign:
    name: str
    path: Path
    description: str
    timeout_s: float | None
    report: dict
    series: list[dict]
    axes: dict[str, list]
    runs: list[RunSpec]


def parse_key(key: str) -> list[str | int]:
    """``"lagrange.bodies[0].mesh"`` or ``"lagrange.bodies.0.mesh"`` -> ["lagrange", "bodies", 0, "mesh"]."""
    out: list[str | int] = []
    for name, index in _SEGMENT.findall(key):
        if index:
            out.append(int(index))
        elif name.isdigit():
            out.append(int(name))
        else:
            out.append(name)
    return out


def set_key(data: dict, key: str, value: Any) -> None:
    """Set a dotted case key in raw case data. Tables on the way are created where missing; an
    array index must exist. Raises KeyError(reason)."""
    path = parse_key(key)
    node: Any = data
    for i, part in enumerate(path[:-1]):
        nxt = path[i + 1]
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                have = len(node) if isinstance(node, list) else 0
                raise KeyError(f"{format_key(path[:i])} has {have} entries, no [{part}]")
            node = node[part]
        else:
            if not isinstance(node, dict):
                raise KeyError(f"{format_key(path[:i])} is not a table")
            if part not in node:
                if isinstance(nxt, int):
                    raise KeyError(f"the base case has no {format_key(path[:i + 1])}")
                node[part] = {}
            node = node[part]
    last = path[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise KeyError(f"{format_key(path[:-1])} has no entry [{last}]")
        node[last] = copy.deepcopy(value)
    else:
        if not isinstance(node, dict):
            raise KeyError(f"{format_key(path[:-1])} is not a table")
        node[last] = copy.deepcopy(value)


def unset_key(data: dict, key: str) -> None:
    """Remove a dotted case key from raw case data. Raises KeyError(reason) if it is not there."""
    path = parse_key(key)
    node: Any = data
    for i, part in enumerate(path[:-1]):
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            raise KeyError(f"the base case has no {format_key(path[:i + 1])}") from None
    if not isinstance(node, dict) or path[-1] not in node:
        raise KeyError(f"the base case has no {format_key(path)}")
    del node[path[-1]]


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", str(text)).strip("_") or "x"


def _level_text(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def read_campaign(path: str | Path) -> dict:
    from orchestrator import case as case_mod

    p = Path(path).expanduser()
    if p.is_dir():
        p = p / "campaign.toml"
    if not p.exists():
        raise CaseError("CAMPAIGN", str(path), "campaign file not found (a CAMPAIGN.toml, or a "
                        "directory holding campaign.toml)")
    try:
        data, _ = case_mod._read_toml(p.resolve())
    except CaseError as e:  # the reader names case.toml: this is the campaign file
        raise CaseError(p.name, e.value, e.allowed) from None
    case_mod._check_finite(data)   # (nan and inf pass the schema's ranges: a timeout of nan ran)
    err = case_mod._best_schema_error(SCHEMA, data)   # (the case file's rule: first 100 errors, best match)
    if err is not None:
        raise case_mod._schema_error_to_case_error(err)
    return data


def load_campaign(path: str | Path, *, check_cases: bool = True,
                  only: dict[str, list[str]] | None = None) -> Campaign:
    """Read, validate and expand a campaign file. ``check_cases``: also load every run's case (the
    full case validation) -- what `immerse campaign` does before it starts anything. ``only``: axis
    -> the levels (as written, e.g. "100") to keep (`immerse campaign --only zones=100,200`), and
    "series" -> the series (by name) to keep."""
    p = Path(path).expanduser()
    p = (p / "campaign.toml") if p.is_dir() else p
    data = read_campaign(p)
    p = p.resolve()
    base = p.parent
    axes = {name: list(a["values"]) for name, a in data.get("axes", {}).items()}
    for name, a in data.get("axes", {}).items():
        n = len(a["values"])
        if len({json.dumps(v) for v in a["values"]}) != n:
            raise CaseError(format_key(["axes", name, "values"]), a["values"], "levels must differ")
        for key, vals in a.items():
            if key != "values" and len(vals) != n:
                raise CaseError(format_key(["axes", name, key]), vals,
                                f"must have {n} items, one per level of axes.{name}.values")
    report = dict(data.get("report", {}))
    for k in ("resolution", "map"):
        if k in report and report[k] not in axes:
            raise CaseError(format_key(["report", k]), report[k],
                            f"must name an axis; axes: {', '.join(axes) or '(none)'}")
    only = dict(only or {})
    keep_series = only.pop("series", None)  # --only series=NAME,...: those series only
    if keep_series is not None:
        names0 = [s["name"] for s in data["series"]]
        for n in keep_series:
            if n not in names0:
                raise CaseError("--only", f"series={n}", "no such series; series: " + ", ".join(names0))
    for a, keep in only.items():
        if a not in axes:
            raise CaseError("--only", a, f"no such axis; axes: {', '.join(axes) or '(none)'}")
        bad = [v for v in keep if v not in {_level_text(x) for x in axes[a]}]
        if bad:
            raise CaseError("--only", f"{a}={bad[0]}", "not a level of the axis; levels: "
                            + ", ".join(_level_text(x) for x in axes[a]))
    names = [s["name"] for s in data["series"]]
    for i, s in enumerate(data["series"]):
        if names.index(s["name"]) != i:
            raise CaseError(format_key(["series", i, "name"]), s["name"], "series names must differ")
        if "relative_to" in s and s["relative_to"] not in names:
            raise CaseError(format_key(["series", i, "relative_to"]), s["relative_to"],
                            "must name another series (the reference whose value this one is compared with)")
    n_runs = sum(_product(len(axes[a]) for a in s.get("vary", axes) if a in axes) for s in data["series"])
    if n_runs > MAX_RUNS:
        raise CaseError("axes", f"{n_runs} runs", f"a campaign may have at most {MAX_RUNS} runs")

    from orchestrator.case import CASE_FILE, _read_toml

    runs: list[RunSpec] = []
    for si, s in enumerate(data["series"]):
        if keep_series is not None and s["name"] not in keep_series:
            continue
        case_dir = (base / s["case"]).resolve()
        if not (case_dir / CASE_FILE).is_file():
            raise CaseError(format_key(["series", si, "case"]), s["case"],
                            f"must be a case directory (holding {CASE_FILE}) relative to the campaign file")
        raw, _ = _read_toml(case_dir / CASE_FILE)
        extra = s.get("axes", {})
        for aname, keys in extra.items():
            if aname not in axes:
                raise CaseError(format_key(["series", si, "axes", aname]), MISSING,
                                f"no such axis; axes: {', '.join(axes) or '(none)'}")
            for key, vals in keys.items():
                if len(vals) != len(axes[aname]):
                    raise CaseError(format_key(["series", si, "axes", aname, key]), vals,
                                    f"must have {len(axes[aname])} items, one per level of axes.{aname}.values")
        vary = s.get("vary", list(axes))
        for a in vary:
            if a not in axes:
                raise CaseError(format_key(["series", si, "vary"]), a,
                                f"no such axis; axes: {', '.join(axes) or '(none)'}")
        for aname in extra:
            if aname not in vary:
                raise CaseError(format_key(["series", si, "axes", aname]), MISSING,
                                f"the series does not vary axis {aname!r} (vary = {vary})")
        used = {a: t for a, t in data.get("axes", {}).items() if a in vary}
        for combo in itertools.product(*(range(len(axes[a])) for a in used)):
            levels = {a: axes[a][k] for a, k in zip(used, combo)}
            if only and any(a in only and _level_text(v) not in only[a] for a, v in levels.items()):
                continue
            settings = dict(s.get("set", {}))
            for (aname, a), k in zip(used.items(), combo):
                for key, vals in a.items():
                    if key != "values":
                        settings[key] = vals[k]
                for key, vals in extra.get(aname, {}).items():
                    settings[key] = vals[k]
            name = "-".join([slug(s["name"])] + [f"{slug(a)}{slug(_level_text(v))}" for a, v in levels.items()])
            run_data = copy.deepcopy(raw)
            for key in s.get("unset", []):
                try:
                    unset_key(run_data, key)
                except KeyError as e:
                    raise CaseError(format_key(["series", si, "unset"]), key,
                                    f"cannot unset in {s['case']}: {e.args[0]}") from None
            for key, value in settings.items():
                try:
                    set_key(run_data, key, value)
                except KeyError as e:
                    where = (["series", si, "set", key] if key in s.get("set", {}) else ["axes", key])
                    raise CaseError(format_key(where), value, f"cannot set in {s['case']}: {e.args[0]}") from None
            runs.append(RunSpec(name=name, series=s["name"], case_dir=case_dir, levels=levels,
                                settings=settings, chart=s.get("chart", data["name"]),
                                error=s.get("error", report.get("error")), relative_to=s.get("relative_to"),
                                index=len(runs), data=run_data))
    if len({r.name for r in runs}) != len(runs):
        raise CaseError("series", names, "two runs get the same directory name: give the series or "
                        "levels names that differ in letters or digits")
    timeout = data.get("timeout")
    camp = Campaign(name=data["name"], path=p, description=data.get("description", ""),
                    timeout_s=float(timeout) if timeout is not None else None, report=report,
                    series=data["series"], axes=axes, runs=runs)
    if check_cases:
        check_runs(camp)
    return camp


def _product(it) -> int:
    n = 1
    for k in it:
        n *= k
    return n


def check_runs(camp: Campaign) -> None:
    """Every run's case through the full case validation and the machine check, in a scratch
    directory (nothing of the campaign's output is written). CaseError prefixed ``run NAME:``."""
    import tempfile

    from orchestrator.campaign.rundir import write_case

    with tempfile.TemporaryDirectory(prefix="immerse-campaign-check-") as tmp:
        for run in camp.runs:
            d = write_case(run, Path(tmp) / run.name)
            try:
                case = _check_case(d)
                from orchestrator.case import ranks_for

                run.ranks = dict(ranks_for(case, {}))
            except CaseError as e:
                raise CaseError(f"run {run.name}: {e.key}", e.value, e.allowed) from None


def _check_case(case_dir: Path) -> dict:
    from orchestrator.case import load_case, ranks_for
    from orchestrator.expressions import check_expressions
    from orchestrator.resources import check_resources, this_machine

    case = load_case(case_dir)
    ranks = ranks_for(case, {})
    check_resources(case, ranks, this_machine(None, None, True), set())
    check_expressions(case)
    return case
