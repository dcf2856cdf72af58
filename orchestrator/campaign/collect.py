"""Collect every run's result into ``campaign.csv`` and ``campaign.h5`` (one row per run).

Columns, in this order (a column appears when any run has it):
  run, series, chart, index, status, message, returncode,
  level.<axis>            the run's level of each axis
  set.<case key>          every case key the run set
  error_metric, error     the campaign's error measure: the metric's relative error (a metric with a
                          reference) or its value (a reported value, or a metric whose reference is 0);
                          for a series `relative_to` another: error_reference (that series), value
                          (the measure's value) and error = |value / the reference run's value - 1|
  wall_time_s             the time loop (start-up excluded: summary.json's wall_time_s)
  elapsed_s               the whole `immerse run`, start-up included
  steps, dt_min, dt_max, ranks_total, end_time
  metric.<m>, metric.<m>.rel_error, metric.<m>.tolerance, metric.<m>.passed   each check metric
  reported.<m>            each further value the check computed
  conservation.<q>        the conservation residuals of summary.json

campaign.h5 holds the same table (``/table/<column>``: float64 with NaN where a run has no value, or
UTF-8 strings), the campaign's expanded spec (``/campaign`` attribute ``json``) and each run's full
result.json (``/runs/<run>`` attribute ``json``), so that ``immerse report`` rebuilds everything
from it. Both files are written to a temporary name and renamed: a reader never sees half a file.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

from orchestrator.campaign.rundir import atomic_write, read_result

FIXED = ["run", "series", "chart", "index", "status", "message", "returncode"]
COST = ["error_metric", "error_reference", "value", "error", "wall_time_s", "elapsed_s", "steps", "dt_min", "dt_max",
        "ranks_total", "end_time"]


def _metric(summary: dict | None, metric: str | None) -> tuple[dict | None, dict | None]:
    """(its check metric entry, the check's reported values) where the summary has the metric."""
    if not summary or not metric or "check" not in summary:
        return None, None
    chk = summary["check"]
    return chk.get("metrics", {}).get(metric), chk.get("reported", {})


def error_of(summary: dict | None, metric: str | None) -> float:
    """The error measure of a run: a check metric's relative error, or |a reported value|."""
    m, reported = _metric(summary, metric)
    if m is not None:
        return float(m["rel_error"])
    return abs(float(reported[metric])) if reported and metric in reported else math.nan


def value_of(summary: dict | None, metric: str | None) -> float:
    """The metric's value itself (not its error): a check metric's value or a reported value."""
    m, reported = _metric(summary, metric)
    if m is not None:
        return float(m["value"])
    return float(reported[metric]) if reported and metric in reported else math.nan


def row_of(meta: dict, res: dict | None) -> dict:
    row = {k: meta.get(k) for k in ("series", "chart", "index")}
    row["run"] = meta["name"]
    row["status"] = res["status"] if res else "not_run"
    row["message"] = res.get("message", "") if res else ""
    row["returncode"] = res.get("returncode") if res else None
    for a, v in meta.get("levels", {}).items():
        row[f"level.{a}"] = v
    for k, v in meta.get("settings", {}).items():
        row[f"set.{k}"] = json.dumps(v) if isinstance(v, (list, dict)) else v
    s = (res or {}).get("summary") or None
    row["error_metric"] = meta.get("error")
    row["error"] = error_of(s, meta.get("error"))
    row["value"] = value_of(s, meta.get("error"))
    row["elapsed_s"] = res.get("elapsed_s") if res else None
    if s:
        row["wall_time_s"] = s.get("wall_time_s")
        row["steps"] = s.get("steps")
        row["dt_min"] = (s.get("dt") or {}).get("min")
        row["dt_max"] = (s.get("dt") or {}).get("max")
        row["ranks_total"] = sum((s.get("ranks") or {}).values())
        row["end_time"] = s.get("end_time")
        chk = s.get("check") or {}
        for m, d in chk.get("metrics", {}).items():
            row[f"metric.{m}"] = d["value"]
            row[f"metric.{m}.rel_error"] = d["rel_error"]
            row[f"metric.{m}.tolerance"] = d["tolerance"]
            row[f"metric.{m}.passed"] = d["passed"]
        for m, v in chk.get("reported", {}).items():
            row[f"reported.{m}"] = v
        for q, v in (s.get("conservation") or {}).items():
            row[f"conservation.{q}"] = v
    return row


def apply_references(rows: list[dict], metas: list[dict]) -> None:
    """A series with `relative_to`: its error is |v / v_ref - 1| of its error measure's value v against
    the reference series' run at the same levels (a reference that does not vary an axis matches any
    level of it); nan without a finished reference run."""
    referenced = {m.get("relative_to") for m in metas} - {None}
    for row, meta in zip(rows, metas):
        ref_name = meta.get("relative_to")
        if not ref_name:
            if meta.get("series") in referenced:  # the reference itself: no error of its own here
                row["error_reference"] = "(the reference)"
                row["error"] = math.nan
            continue
        row["error_reference"] = ref_name
        ref = [r for r, m in zip(rows, metas) if m.get("series") == ref_name
               and all(m.get("levels", {}).get(a, v) == v for a, v in meta.get("levels", {}).items())]
        v, v0 = row.get("value"), (ref[0].get("value") if ref else None)
        ok = v is not None and v0 is not None and math.isfinite(v) and math.isfinite(v0) and v0 != 0.0
        row["error"] = abs(v / v0 - 1.0) if ok else math.nan


def gather(out: Path, names: list[str] | None = None) -> list[tuple[dict, dict | None]]:
    """(run.json, result.json or None) of the campaign's runs, in campaign order (``names``: only
    these runs, e.g. the current campaign's; default: every run directory)."""
    runs = out / "runs"
    dirs = [runs / n for n in names] if names is not None else sorted(p for p in runs.iterdir() if p.is_dir())
    found = []
    for d in dirs:
        try:
            meta = json.loads((d / "run.json").read_text())
        except (OSError, ValueError):
            continue
        found.append((meta, read_result(d)))
    found.sort(key=lambda mr: mr[0].get("index", 0))
    return found


def columns(rows: list[dict]) -> list[str]:
    seen = {}
    for r in rows:
        for k in r:
            seen.setdefault(k, None)
    rest = [k for k in seen if k not in FIXED and k not in COST]
    groups = ("level.", "set.", "metric.", "reported.", "conservation.")
    ordered = [k for g in groups[:2] for k in rest if k.startswith(g)]
    ordered += [k for k in COST if k in seen]
    ordered += [k for g in groups[2:] for k in rest if k.startswith(g)]
    ordered += [k for k in rest if k not in ordered]
    return [k for k in FIXED if k in seen] + ordered


def _csv_cell(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_csv(path: Path, rows: list[dict]) -> None:
    cols = columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_csv_cell(r.get(c)) for c in cols])
    atomic_write(path, buf.getvalue())


def write_h5(path: Path, rows: list[dict], spec: dict, found) -> None:
    import h5py
    import numpy as np

    cols = columns(rows)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = "immerse-campaign-1"
        f.create_group("campaign").attrs["json"] = json.dumps(spec)
        t = f.create_group("table")
        t.attrs["columns"] = json.dumps(cols)
        for c in cols:
            vals = [r.get(c) for r in rows]
            numeric = all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in vals)
            if numeric:
                t[c] = np.array([np.nan if v is None else float(v) for v in vals], np.float64)
            else:
                t.create_dataset(c, data=[_csv_cell(v) for v in vals], dtype=h5py.string_dtype())
        g = f.create_group("runs")
        for meta, res in found:
            g.create_group(meta["name"]).attrs["json"] = json.dumps({"run": meta, "result": res})
        f.flush()
    os.replace(tmp, path)


def collect(out: Path, spec: dict, names: list[str] | None = None) -> list[dict]:
    """Write campaign.csv and campaign.h5 of ``out``; return the rows."""
    found = gather(out, names)
    rows = [row_of(m, r) for m, r in found]
    apply_references(rows, [m for m, _ in found])
    from orchestrator.campaign.rundir import record

    record(out, out / "campaign.csv", out / "campaign.h5")
    write_csv(out / "campaign.csv", rows)
    write_h5(out / "campaign.h5", rows, spec, found)
    return rows


def read_h5(path: Path, summaries: bool = False):
    """(campaign spec, rows) from a campaign.h5; with ``summaries``, also each row's summary.json
    (None for a run without one)."""
    import h5py

    with h5py.File(path, "r") as f:
        spec = json.loads(f["campaign"].attrs["json"])
        found = [(d["run"], d["result"]) for d in (json.loads(g.attrs["json"]) for g in f["runs"].values())]
    found.sort(key=lambda mr: mr[0].get("index", 0))
    rows = [row_of(m, r) for m, r in found]
    apply_references(rows, [m for m, _ in found])
    if summaries:
        return spec, rows, [(r or {}).get("summary") for _, r in found]
    return spec, rows
