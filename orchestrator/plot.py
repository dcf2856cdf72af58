"""`immerse plot OUT [QUANTITY ...]`: time histories of a run (diagnostics.h5) drawn against time,
as LS-DYNA users read glstat/nodout curves or OpenFOAM users run foamMonitor.

A QUANTITY is a history of the run: ``<role>.<name>`` as diagnostics.h5 holds it (every solver's
energies, momenta, balances, the coupling's works), a shell-style pattern of them
(``'*.total_energy'``), or a probe by its name (``tip`` for ``lagrange.probe_tip``, case
``[probes]``).  Without one, the case's probes are drawn, or else each group's total energy.
Each quantity is one panel (shared time axis, units from orchestrator/units.py); where the case's
check compares that history with a reference curve (checks.reference_curve: e.g. tip_history on a
probe, free_end's triangle wave), the reference is drawn with it.  Written to OUT/plots/:
``<name>.png`` and, with ``--csv``, ``<name>.csv`` (time, then one column per quantity, every
diagnostics step once).  A history is read while the run goes on too (its spool).

An unknown quantity is refused before anything is drawn: one line naming it and what the run has.
"""
from __future__ import annotations

import csv
import fnmatch
import re
from pathlib import Path

import numpy as np

from orchestrator.history_spool import each_step_once
from orchestrator.run_record import case_of_run
from orchestrator.units import DIMENSIONLESS, history_unit

PLOTS_DIR = "plots"
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


class PlotError(ValueError):
    """A request the run's history cannot satisfy: one line naming what it holds."""


def read_history(out: Path) -> dict[str, np.ndarray]:
    """The run's history {"time", "step", "<role>.<name>"}: diagnostics.h5, or while the run goes on
    (or after it was killed) its spool; each step once (a step recorded at its diagnostics and again
    at its output keeps its first record)."""
    import h5py

    from orchestrator.history_spool import read_history as spooled

    path = Path(out) / "diagnostics.h5"
    hist = None
    if path.is_file():
        with h5py.File(path, "r") as h:
            hist = {k: h[k][...] for k in h if h[k].ndim == 1}
    else:
        hist = spooled(Path(out))
    if not hist or "time" not in hist or len(hist["time"]) == 0:
        raise PlotError(f"OUT = {str(out)!r}: no history there yet (diagnostics.h5 or a running job's spool)")
    first = each_step_once(hist)
    return {k: np.asarray(v)[first] for k, v in hist.items()}


def select(hist: dict, wanted, case) -> list[str]:
    """The history keys of the quantities asked for (module docstring), in the order asked."""
    keys = [k for k in hist if k not in ("time", "step")]
    if not wanted:
        probes = [k for k in keys if k.split(".", 1)[-1].startswith("probe_")]
        return probes or [k for k in keys if k.endswith(".total_energy")] or keys[:1]
    chosen = []
    for q in wanted:
        found = [k for k in keys if fnmatch.fnmatchcase(k, q)] if any(c in q for c in "*?[") else (
            [q] if q in keys else [k for k in keys if k.split(".", 1)[-1] in (q, f"probe_{q}")]
            or [k for k in keys if re.fullmatch(rf"[^.]+\.probe_{re.escape(q)}_\d+", k)])   # (a line's points)
        if not found:
            near = sorted({k for k in keys if q.lower() in k.lower()})[:8]
            probes = sorted(k.split("probe_", 1)[1] for k in keys if ".probe_" in k)
            hint = (f"; did you mean {', '.join(near)}" if near else "") + (
                f"; probes: {', '.join(probes)}" if probes else "")
            raise PlotError(f"QUANTITY = {q!r}: not a history of this run (run `immerse plot OUT --list` "
                            f"for the {len(keys)} it has{hint})")
        chosen += [k for k in found if k not in chosen]
    return chosen


def _label(key: str, probes) -> str:
    u = history_unit(key, probes)
    return key if u is None else f"{key} ({'-' if u == DIMENSIONLESS else u})"


def figure(out_dir, wanted=()):
    """(matplotlib Figure, the history keys drawn) for the quantities asked (module docstring)."""
    return _draw(out_dir, wanted)[:2]


def _draw(out_dir, wanted):
    """(Figure, keys, the history, the case's probes)."""
    from matplotlib.figure import Figure

    out = Path(out_dir)
    hist = read_history(out)
    case = case_of_run(out)
    keys = select(hist, list(wanted or ()), case)
    probes = (case or {}).get("probes")
    ref = None
    if case is not None:
        from orchestrator.checks import reference_curve

        ref = reference_curve(case)
    t = hist["time"]
    fig = Figure(figsize=(10.24, max(3.2, 2.6 * len(keys) + 0.8)), dpi=100)
    axes = fig.subplots(len(keys), 1, sharex=True, squeeze=False)[:, 0]
    for ax, k in zip(axes, keys):
        ax.plot(t, hist[k], color="tab:blue", linewidth=1.2, label=f"{k} ({len(t)} steps)")
        if ref is not None and ref[0] == k:
            ax.plot(ref[1], ref[2], color="black", linestyle="--", marker="o", markersize=3, linewidth=1.0,
                    label=ref[3])
        ax.set_ylabel(_label(k, probes))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    title = (case or {}).get("name") or out.resolve().name
    axes[0].set_title(f"{title}: {', '.join(keys) if len(keys) <= 3 else f'{len(keys)} histories'}")
    fig.tight_layout()
    return fig, keys, hist, probes


def plot(out_dir, wanted=(), csv_too: bool = False, name: str | None = None) -> list[Path]:
    """Draw the quantities (module docstring) of the run in ``out_dir`` to OUT/plots/; returns the
    files written."""
    out = Path(out_dir)
    fig, keys, hist, probes = _draw(out, wanted)
    t = hist["time"]
    stem = name or _SAFE.sub("_", "+".join(k.replace("probe_", "") for k in keys))[:120]
    dest = out / PLOTS_DIR
    dest.mkdir(exist_ok=True)
    written = [dest / f"{stem}.png"]
    fig.savefig(written[0])
    if csv_too:
        path = dest / f"{stem}.csv"
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time (s)"] + [_label(k, probes) for k in keys])
            w.writerows(zip(*([repr(float(v)) for v in t], *[[repr(float(v)) for v in hist[k]] for k in keys])))
        written.append(path)
    return written


def listing(out_dir) -> str:
    """The run's histories, one per line with its unit, for ``--list``."""
    out = Path(out_dir)
    hist = read_history(out)
    case = case_of_run(out)
    probes = (case or {}).get("probes")
    return "\n".join(_label(k, probes) for k in hist if k not in ("time", "step"))
