"""The diagnostics history on disk while a run goes on: what explains a slow or failing run survives
the run's end by any means (a solver's error, SIGTERM, a rank killed, the coupler killed).

The coupler appends every recorded row (time, step, each solver group's diagnostics, the coupler's
own) to ``OUT/.run/history.bin`` as raw float64 and flushes it to the operating system at once: an
append of fixed-size records, so a kill at any instant leaves every earlier row whole and at most one
partial row at the end, which the reader drops. ``OUT/.run/history.json`` names the columns. A
restarted coupler writes the history it loaded from its checkpoint first.

When a job ends without the coupler's own summary (orchestrator/run_record.py), the launcher reads
the rows back into the form of diagnostics.h5. Once diagnostics.h5 is written (by the coupler at the
end, or by the launcher) the spool is removed.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

ROWS = "history.bin"
COLUMNS = "history.json"


def _paths(out: Path) -> tuple[Path, Path]:
    d = Path(out) / ".run"
    return d / ROWS, d / COLUMNS


class HistorySpool:
    """Appends the coupler's recorded rows; ``names``: role -> its diagnostics' names, in row order."""

    def __init__(self, out: Path, names: dict[str, list[str]]):
        rows, columns = _paths(out)
        rows.parent.mkdir(parents=True, exist_ok=True)
        tmp = columns.with_suffix(".tmp")
        tmp.write_text(json.dumps({"roles": [[r, list(n)] for r, n in names.items()]}))
        os.replace(tmp, columns)
        self.width = 2 + sum(len(n) for n in names.values())
        self.fd = os.open(rows, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)

    def append(self, t: float, step: int, rows: list[np.ndarray]) -> None:
        """One record: [t, step, *rows] (the roles in the order of ``names``); one write(2)."""
        rec = np.concatenate([[t, float(step)], *rows]).astype(np.float64)
        if rec.size != self.width:
            raise ValueError(f"history record of {rec.size} values, expected {self.width}")
        os.write(self.fd, rec.tobytes())

    def close(self) -> None:
        os.close(self.fd)


def remove_spool(out: Path) -> None:
    """The spooled history once diagnostics.h5 holds it."""
    for p in _paths(out):
        p.unlink(missing_ok=True)


def each_step_once(hist: dict[str, np.ndarray]) -> np.ndarray:
    """Indices of a history's rows with each step once, in step order: a step recorded at its
    diagnostics and again at its output keeps its first record."""
    return np.unique(hist["step"], return_index=True)[1]


def read_history(out: Path) -> dict[str, np.ndarray] | None:
    """The spooled history as diagnostics.h5 holds it ({"time", "step", "<role>.<name>"}), a partial
    last record dropped; None when the run spooled nothing."""
    rows, columns = _paths(out)
    try:
        roles = json.loads(columns.read_text())["roles"]
        data = rows.read_bytes()
    except (OSError, ValueError, KeyError):
        return None
    width = 2 + sum(len(n) for _, n in roles)
    n = len(data) // (8 * width)
    a = np.frombuffer(data[: n * 8 * width], dtype=np.float64).reshape(n, width)
    hist = {"time": a[:, 0].copy(), "step": a[:, 1].copy()}
    col = 2
    for role, names in roles:
        for name in names:
            hist[f"{role}.{name}"] = a[:, col].copy()
            col += 1
    return hist
