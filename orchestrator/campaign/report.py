"""The campaign report: ``report.md`` and ``report.html`` with PNG charts in ``figures/``, built from
``campaign.h5`` alone (``immerse report OUT`` rebuilds it without rerunning anything).

Per chart group (the series sharing a ``chart`` name, e.g. one case):
  * error against wall time (log-log), one series per method, the Pareto front (runs no other run
    beats in both error and time) drawn as a step line and ringed;
  * error against the resolution axis (log-log) with the observed order fitted per series
    (least squares of log error on log resolution over the series' finished runs);
  * the stability map: series x the map axis, each cell the run's status (stable: passed or check
    outside tolerance; unstable detected; failed; timeout), the messages listed under it;
  * pictures (pyvista, :mod:`orchestrator.view`) of the finest run of each series.
Every chart names its axes with units, has a legend and a caption naming the reference.
"""
from __future__ import annotations

import html
import math
import shutil
from pathlib import Path

import numpy as np

STATUS_COLOURS = {"passed": "#2e9e44", "check_failed": "#a6d96a", "warned": "#ffd92f", "unstable": "#f28e2b",
                  "failed": "#d62728", "timeout": "#7f7f7f", "not_run": "#ffffff"}
STATUS_TEXT = {"passed": "stable, check passed", "check_failed": "stable, check outside tolerance",
               "warned": "ran, a detector warned (ill-conditioned, beyond a limit)",
               "unstable": "unstable (detected)", "failed": "failed", "timeout": "timed out",
               "not_run": "not run"}
_MARKERS = "osD^vP*Xh<>"


def pareto(times: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats in both time and error, by increasing time."""
    order = np.lexsort((errors, times))
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(i)
            best = errors[i]
    return np.array(front, dtype=int)


def fit_order(res: np.ndarray, err: np.ndarray) -> float:
    """Observed order p of err ~ res^-p (least squares in log-log); nan with fewer than 2 points."""
    ok = np.isfinite(res) & np.isfinite(err) & (res > 0) & (err > 0)
    if ok.sum() < 2:
        return math.nan
    return float(-np.polyfit(np.log(res[ok]), np.log(err[ok]), 1)[0])


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _groups(spec: dict, rows: list[dict]) -> dict[str, list[str]]:
    charts: dict[str, list[str]] = {}
    for s in spec["series"]:
        charts.setdefault(s["chart"], []).append(s["name"])
    return charts


def _slug(text: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_") or "chart"


def _chart_cost(spec, chart, names, rows, path: Path) -> list[dict]:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    table = []
    pts_t, pts_e = [], []
    for k, name in enumerate(names):
        rs = [r for r in rows if r["series"] == name and r["status"] in ("passed", "check_failed", "warned")]
        t = np.array([_float(r.get("wall_time_s")) for r in rs])
        e = np.array([_float(r.get("error")) for r in rs])
        ok = np.isfinite(t) & np.isfinite(e) & (t > 0) & (e > 0)
        ax.loglog(t[ok], e[ok], marker=_MARKERS[k % len(_MARKERS)], linestyle="-", label=name)
        pts_t += list(t[ok])
        pts_e += list(e[ok])
        table += [{"series": name, "run": r["run"], "wall_time_s": ti, "error": ei}
                  for r, ti, ei, o in zip(rs, t, e, ok) if o]
    if pts_t:
        t, e = np.array(pts_t), np.array(pts_e)
        f = pareto(t, e)
        ax.step(t[f], e[f], where="post", color="k", linewidth=0.8, alpha=0.6)
        ax.scatter(t[f], e[f], s=140, facecolors="none", edgecolors="k", label="Pareto front")
    _finish(fig, ax, "wall time of the time loop (s)",
            spec["report"].get("error_label") or spec["report"].get("error", "error"),
            f"{chart}: error against cost", path)
    return table


def _finish(fig, ax, xlabel: str, ylabel: str, title: str, path: Path) -> None:
    """Axes labels (with units), title, grid, legend; saved and closed."""
    import matplotlib.pyplot as plt

    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _chart_vs_resolution(spec, chart, names, rows, values, ylabel: str, title: str, path: Path,
                         fit: bool) -> dict[str, float] | None:
    """Per series, ``values(row)`` of its finished runs against the resolution axis (log-log); with
    ``fit`` the observed order of each series in its legend (returned). None without a resolution,
    or when no run has a positive finite value to chart (a value this chart's runs do not report: an
    empty figure says nothing)."""
    import matplotlib.pyplot as plt

    axis = spec["report"].get("resolution")
    if not axis:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    orders = {}
    points = 0
    for k, name in enumerate(names):
        rs = [r for r in rows if r["series"] == name and r["status"] in ("passed", "check_failed", "warned")]
        n = np.array([_float(r.get(f"level.{axis}")) for r in rs])
        v = np.array([_float(values(r)) for r in rs])
        p = fit_order(n, v) if fit else math.nan
        orders[name] = p
        ok = np.isfinite(n) & np.isfinite(v) & (v > 0) & (n > 0)
        points += int(ok.sum())
        ax.loglog(n[ok], v[ok], marker=_MARKERS[k % len(_MARKERS)], linestyle="-",
                  label=f"{name} (order {p:.2f})" if p == p else name)
    if not points:
        plt.close(fig)
        return None
    _finish(fig, ax, spec["report"].get("resolution_label") or f"{axis} (resolution)", ylabel,
            f"{chart}: {title}", path)
    return orders


_WORST = ["not_run", "passed", "check_failed", "warned", "timeout", "unstable", "failed"]


def _chart_map(spec, chart, names, rows, path: Path) -> list[dict]:
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    axis = spec["report"].get("map") or spec["report"].get("resolution")
    levels = spec["axes"].get(axis, [None]) if axis else [None]
    grid = np.zeros((len(names), len(levels)), dtype=int)
    notes = []
    for i, name in enumerate(names):
        for j, lv in enumerate(levels):
            # (a series that does not vary the map's axis: its runs fill the whole row)
            rs = [r for r in rows if r["series"] == name
                  and (axis is None or r.get(f"level.{axis}") in (lv, None))]
            worst = max((_WORST.index(r["status"]) for r in rs), default=0)
            grid[i, j] = worst
            notes += [{"series": name, "level": lv, "run": r["run"], "status": r["status"],
                       "message": r.get("message", "")} for r in rs
                      if r["status"] not in ("passed",) and all(n["run"] != r["run"] for n in notes)]
    cmap = ListedColormap([STATUS_COLOURS[s] for s in _WORST])
    fig, ax = plt.subplots(figsize=(max(4.5, 1.0 + 0.9 * len(levels)), 1.6 + 0.45 * len(names)))
    ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(_WORST) - 0.5, aspect="auto")
    ax.set_xticks(range(len(levels)), [f"{v:g}" if isinstance(v, float) else str(v) for v in levels])
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel(spec["report"].get("map_label") or (f"{axis}" if axis else ""))
    ax.set_title(f"{chart}: stability map")
    for i in range(len(names)):
        for j in range(len(levels)):
            ax.text(j, i, _WORST[grid[i, j]].replace("_", " "), ha="center", va="center", fontsize=7)
    used = sorted(set(grid.ravel()))
    ax.legend(handles=[Patch(facecolor=STATUS_COLOURS[_WORST[u]], edgecolor="k",
                             label=STATUS_TEXT[_WORST[u]]) for u in used],
              loc="upper center", bbox_to_anchor=(0.5, -0.5 if len(names) < 3 else -0.32),
              ncol=min(3, len(used)), fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return notes


def _pictures(out: Path, spec, names, rows, figdir: Path) -> list[tuple[str, str, str]]:
    """A picture of the last step of each series' finest finished run (the last level of the
    resolution axis that ran): the report's `picture` field, default density. (series, caption,
    figure name) each; a picture that cannot be drawn (a damaged or missing results.h5) has the
    reason as its caption and no name: the report lists it, it does not cost the report."""
    field = spec["report"].get("picture", "density")
    axis = spec["report"].get("resolution")
    pics = []
    for name in names:
        rs = [r for r in rows if r["series"] == name and r["status"] in ("passed", "check_failed", "warned")]
        if not rs:
            continue
        best = max(rs, key=lambda r: _float(r.get(f"level.{axis}")) if axis else r["index"])
        run_out = out / "runs" / best["run"] / "out"
        if not (run_out / "results.h5").is_file():
            pics.append((name, f"{best['run']}: no results.h5 in its output", ""))
            continue
        try:
            from orchestrator.view import render

            paths = render(run_out, fields=[field], steps=("last",))
        except Exception as e:  # noqa: BLE001 - a picture that cannot be drawn must not cost the report
            pics.append((name, f"{best['run']}: {type(e).__name__}: {' '.join(str(e).split())[:200]}", ""))
            continue
        for p in paths[:1]:
            dest = figdir / f"picture_{_slug(best['run'])}.png"  # (recorded: _Figures)
            shutil.copyfile(p, dest)
            pics.append((name, f"{name}, finest run {best['run']}: {field} at the end time", dest.name))  # (orchestrator.view)
    return pics


class _Figures:
    """OUT/figures/: each path asked for is in the campaign's record before it is written
    (orchestrator/campaign/rundir.py: a campaign overwrites only what it wrote)."""

    def __init__(self, out: Path):
        self.out, self.path = out, out / "figures"
        self.path.mkdir(exist_ok=True)

    def __truediv__(self, name: str) -> Path:
        from orchestrator.campaign.rundir import record

        p = self.path / name
        record(self.out, p)
        return p


def write_report(out: Path) -> list[Path]:
    """Build report.md, report.html and figures/ of a campaign output from its campaign.h5."""
    import matplotlib

    matplotlib.use("Agg")
    from orchestrator.campaign.collect import error_of, read_h5

    out = Path(out)
    spec, rows, summaries = read_h5(out / "campaign.h5", summaries=True)
    figdir = _Figures(out)
    ref = spec["report"].get("reference", "the cases' own check references")
    metric = spec["report"].get("error_label") or spec["report"].get("error", "error")
    sections = []
    spec_all, ref_all = spec, ref
    for chart, names in _groups(spec_all, rows).items():
        # a chart's own labels (report.charts."NAME": error_label, reference) over the campaign's
        spec = {**spec_all, "report": {**spec_all["report"], **spec_all["report"].get("charts", {}).get(chart, {})}}
        ref = spec["report"].get("reference", ref_all)
        metric = spec["report"].get("error_label") or spec["report"].get("error", "error")
        base = _slug(chart)
        sec = {"chart": chart, "figures": [], "tables": []}
        f1 = figdir / f"{base}_cost.png"
        _chart_cost(spec, chart, names, rows, f1)
        sec["figures"].append((f1.name, f"Error against wall time, {chart}: {metric} against the "
                               f"time loop's wall time on this machine, one series per method; the "
                               f"ringed points are the Pareto front. Reference: {ref}."))
        f2 = figdir / f"{base}_order.png"
        orders = _chart_vs_resolution(spec, chart, names, rows, lambda r: r.get("error"), metric,
                                      "observed convergence", f2, fit=True)
        if orders is not None:
            sec["figures"].append((f2.name, f"Observed convergence, {chart}: {metric} against "
                                   f"{spec['report'].get('resolution')}; order fitted per series "
                                   f"(least squares, log-log). Reference: {ref}."))
            sec["tables"].append(("Observed order per series", ["series", "order"],
                                  [[k, f"{v:.3f}" if v == v else "-"] for k, v in orders.items()]))
        for j, plot in enumerate(spec["report"].get("plots", [])):
            f = figdir / f"{base}_plot{j}.png"
            by_run = dict(zip((r["run"] for r in rows), summaries))
            if _chart_vs_resolution(spec, chart, names, rows,
                                    lambda r, v=plot["value"]: error_of(by_run[r["run"]], v),
                                    plot["label"], plot["value"], f, fit=False) is not None:
                sec["figures"].append((f.name, f"{plot['label']} against {spec['report'].get('resolution')}, "
                                       f"{chart}, one series per method ({plot['value']} of each run). "
                                       f"Reference: {ref}."))
        f3 = figdir / f"{base}_stability.png"
        notes = _chart_map(spec, chart, names, rows, f3)
        sec["figures"].append((f3.name, f"Stability map, {chart}: each run's outcome (method x "
                               f"{spec['report'].get('map') or spec['report'].get('resolution') or 'run'}); "
                               f"stable runs are checked against {ref}."))
        sec["tables"].append(("Runs", ["series", "run", "status", "wall time (s)", metric],
                              [[r["series"], r["run"], r["status"], _fmt(r.get("wall_time_s")),
                                _fmt(r.get("error"))] for r in rows if r["series"] in names]))
        if notes:
            sec["tables"].append(("Runs that did not pass, with their messages",
                                  ["series", "run", "status", "message"],
                                  [[n["series"], n["run"], n["status"], n["message"]] for n in notes]))
        pics = _pictures(out, spec, names, rows, figdir)
        sec["figures"] += [(name, f"{caption} (immerse view).") for _, caption, name in pics if name]
        if any(not name for _, _, name in pics):
            sec["tables"].append(("Pictures not drawn", ["series", "why"],
                                  [[series, caption] for series, caption, name in pics if not name]))
        sections.append(sec)
    md, page = _markdown(spec_all, sections), _html(spec_all, sections)
    from orchestrator.campaign.rundir import atomic_write, record

    record(out, out / "report.md", out / "report.html")
    atomic_write(out / "report.md", md)
    atomic_write(out / "report.html", page)
    return [out / "report.md", out / "report.html"]


def _fmt(v) -> str:
    x = _float(v)
    return "-" if x != x else f"{x:.4g}"


def _markdown(spec, sections) -> str:
    lines = [f"# Campaign {spec['name']}", ""]
    if spec.get("description"):
        lines += [spec["description"].strip(), ""]
    for sec in sections:
        lines += [f"## {sec['chart']}", ""]
        for name, caption in sec["figures"]:
            lines += [f"![{caption}](figures/{name})", "", f"*{caption}*", ""]
        for title, head, body in sec["tables"]:
            lines += [f"**{title}**", "", "| " + " | ".join(head) + " |",
                      "|" + "---|" * len(head)]
            lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in body]
            lines.append("")
    return "\n".join(lines) + "\n"


def _html(spec, sections) -> str:
    e = html.escape
    parts = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
             f"<title>Campaign {e(spec['name'])}</title>",
             "<style>body{font-family:sans-serif;max-width:1000px;margin:2em auto;padding:0 1em}"
             "figure{margin:1.5em 0}img{max-width:100%}figcaption{font-size:90%;color:#333}"
             "table{border-collapse:collapse;font-size:85%;margin:1em 0}"
             "td,th{border:1px solid #bbb;padding:2px 6px;text-align:left}"
             "figure.pic{display:inline-block;width:47%;vertical-align:top;margin:0.5em 1%}</style></head><body>",
             f"<h1>Campaign {e(spec['name'])}</h1>"]
    if spec.get("description"):
        parts.append(f"<p>{e(spec['description'].strip())}</p>")
    for sec in sections:
        parts.append(f"<h2>{e(sec['chart'])}</h2>")
        for name, caption in sec["figures"]:
            cls = " class=\"pic\"" if name.startswith("picture_") else ""  # pictures two a row
            parts.append(f"<figure{cls}><img src=\"figures/{e(name)}\" alt=\"{e(caption)}\">"
                         f"<figcaption>{e(caption)}</figcaption></figure>")
        for title, head, body in sec["tables"]:
            parts.append(f"<h3>{e(title)}</h3><table><tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr>")
            parts += ["<tr>" + "".join(f"<td>{e(str(c))}</td>" for c in row) + "</tr>" for row in body]
            parts.append("</table>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"

