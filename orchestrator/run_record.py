"""What a run leaves for its reader besides the output steps: ``OUT/diagnostics.h5`` (the history of
every recorded step: time, step and each solver group's diagnostics as ``<role>.<name>``) and
``OUT/summary.json`` (the one format tests, campaigns and reviewers read, DESIGN.md "Conventions").

A run that reaches its end gets both from the coupler (``status`` "completed"; "max_steps" when
run.max_steps stopped it first). A run that fails or is interrupted gets both from the launcher
(:func:`record_ended_run`), from the history the coupler spooled while it ran
(orchestrator/history_spool.py): ``status`` "failed" or "interrupted", the one-line message, the last
recorded step and time, and the balances so far; no check (its figures describe a finished run).
"""
from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

import h5py
import numpy as np

from orchestrator.history_spool import each_step_once


def conservation_residuals(hist: dict[str, np.ndarray], roles) -> dict[str, float]:
    """summary.json's `conservation`: for each balanced quantity Q (mass, energy, momentum, ...)
    `Q_rel` = the largest |Q_balance_rel| over the run and over the solver roles, where every solver
    defines Q_balance_rel = (Q(t) - Q(0) - what crossed the boundary up to t) / scale (the solver's
    own diagnostic of that name, the same figure the case checks report as `Q_balance_rel`).
    A solver whose mass cannot cross its boundary (Lagrangian bodies) reports no mass balance:
    its residual is then (M(t) - M(0)) / M(0) from its mass history: the same definition with
    nothing crossing."""
    rel: dict[str, float] = {}

    def put(name: str, a) -> None:
        rel[name] = max(rel.get(name, 0.0), float(np.max(np.abs(a))))

    for r in roles:
        prefix = f"{r}."
        for k, a in hist.items():
            if k.startswith(prefix) and k.endswith("_balance_rel") and len(a):
                put(k[len(prefix):].replace("_balance_rel", "_rel"), a)
        m = hist.get(f"{r}.mass")
        if f"{r}.mass_balance_rel" not in hist and m is not None and len(m) and m[0] != 0:
            put("mass_rel", m / m[0] - 1.0)
    return rel


def contact_balances(hist: dict[str, np.ndarray], roles) -> dict[str, dict[str, float]]:
    """summary.json's `contact`, per solver role that has contact: the work the contact did on the
    bodies over the run (`work`, J; <= 0: the energy it took, booked in the energy balance), that work
    over the role's initial kinetic energy (`dissipated_rel`, when it had any), the largest contact
    force (`force_max`, the norm of the contact_force components: N, per unit thickness in 2-D) and
    the most multipliers active at once (`active_max`)."""
    out: dict[str, dict[str, float]] = {}
    for r in roles:
        comps = [hist[f"{r}.contact_force_{c}"] for c in "xyz" if f"{r}.contact_force_{c}" in hist]
        if not comps or not len(comps[0]):
            continue
        d = {"force_max": float(np.sqrt(sum(a**2 for a in comps)).max())}
        if f"{r}.contact_active" in hist:
            d["active_max"] = float(hist[f"{r}.contact_active"].max())
        w = hist.get(f"{r}.contact_work")
        if w is not None and len(w):
            d["work"] = float(w[-1])
            ke0 = hist.get(f"{r}.kinetic_energy")
            if ke0 is not None and len(ke0) and ke0[0] > 0:
                d["dissipated_rel"] = float(-w[-1] / ke0[0])
        out[r] = d
    return out


def write_diagnostics(out: Path, hist: dict[str, np.ndarray]) -> None:
    """diagnostics.h5, written whole beside and renamed over (readable if killed at any instant);
    the case's probes also as probes.csv (write_probes)."""
    tmp = Path(out) / "diagnostics.h5.tmp"
    with h5py.File(tmp, "w") as h:
        for k, a in hist.items():
            h.create_dataset(k, data=a)
    os.replace(tmp, Path(out) / "diagnostics.h5")
    write_probes(out, hist)


def case_of_run(out: Path) -> dict | None:
    """The validated case of the run in ``out`` (its summary.json names the case directory), or None:
    no summary yet, the case moved or it no longer validates (readers then draw without it)."""
    try:
        case_dir = json.loads((Path(out) / "summary.json").read_text())["case_dir"]
        from orchestrator.case import load_case

        return load_case(case_dir)
    except Exception:
        return None


def write_probes(out: Path, hist: dict[str, np.ndarray]) -> None:
    """OUT/probes.csv when the run has probes (``<role>.probe_<name>``): time (s), step, then one
    column per probe named ``<role>.<name>``, every diagnostics step once (a step recorded at its
    diagnostics and again at its output keeps its first record); written beside and renamed over."""
    keys = [k for k in hist if ".probe_" in k]
    if not keys or not len(hist.get("time", ())):
        return
    first = each_step_once(hist)
    cols = [hist["time"][first], hist["step"][first]] + [np.asarray(hist[k])[first] for k in keys]
    tmp = Path(out) / "probes.csv.tmp"
    with open(tmp, "w") as f:
        f.write(",".join(["time", "step"] + [k.replace(".probe_", ".") for k in keys]) + "\n")
        for row in zip(*cols):
            f.write(f"{float(row[0])!r},{int(row[1])}," + ",".join(repr(float(v)) for v in row[2:]) + "\n")
    os.replace(tmp, Path(out) / "probes.csv")


def final_units(final: dict, probes: dict | None) -> dict:
    """summary.json's "units": the SI unit of each of "final"'s histories ("1": dimensionless; a name
    without a known unit is left out), orchestrator/units.py history_unit.  The other keys carry
    their unit in their names (wall_time_s, end_time and dt in s, conservation's *_rel relative)."""
    from orchestrator.units import history_unit

    return {k: u for k in final if (u := history_unit(k, probes)) is not None}


def write_summary(out: Path, s: dict) -> None:
    tmp = Path(out) / "summary.json.tmp"
    tmp.write_text(json.dumps(s, indent=2))
    os.replace(tmp, Path(out) / "summary.json")


def roles_of(hist: dict[str, np.ndarray]) -> list[str]:
    """The roles of a history's columns ("<role>.<name>"), in their first order."""
    return list(dict.fromkeys(k.split(".", 1)[0] for k in hist if "." in k))


def ended_summary(case: dict, hist: dict[str, np.ndarray] | None, status: str, message: str,
                  wall: float, ranks: dict[str, int]) -> dict:
    """summary.json of a run that did not reach its end: where it stopped and its balances so far."""
    hist = hist or {}
    n = len(hist.get("time", ()))
    roles = roles_of(hist)
    s = {
        "case": case["name"],
        "case_dir": str(case["case_dir"]),
        "status": status,
        "message": message,
        "wall_time_s": wall,
        "steps": int(hist["step"][-1]) if n else 0,
        "end_time": float(hist["time"][-1]) if n else 0.0,
        "requested_end_time": float(case["run"]["end_time"]),
        "ranks": ranks,
        "conservation": conservation_residuals(hist, roles) if n else {},
        "final": {k: float(a[-1]) for k, a in hist.items() if k not in ("time", "step")} if n else {},
        "machine": {"host": socket.gethostname(), "cores": os.cpu_count()},
    }
    s["units"] = final_units(s["final"], case.get("probes"))
    if n and (contact := contact_balances(hist, roles)):
        s["contact"] = contact
    return s


def record_ended_run(case: dict, out: Path, status: str, message: str, started: float,
                     ranks: dict[str, int]) -> None:
    """After a failed or interrupted job: diagnostics.h5 and summary.json from the spooled history,
    unless the coupler's own summary of this run says it completed (a failure after its end)."""
    from orchestrator.history_spool import read_history, remove_spool

    out = Path(out)
    try:
        s = json.loads((out / "summary.json").read_text())
        if s.get("status") in ("completed", "max_steps") and (out / "summary.json").stat().st_mtime >= started - 2.0:
            return
    except (OSError, ValueError):
        pass
    hist = read_history(out)
    if hist is not None and len(hist["time"]):
        hist["step"] = hist["step"].astype(np.int64)
        write_diagnostics(out, hist)
    write_summary(out, ended_summary(case, hist, status, message, time.time() - started, ranks))
    remove_spool(out)


def summary_line(out: Path) -> tuple[str, bool]:
    """The line a finished run ends with (``immerse run``, a Slurm run), and whether its check (if
    any) passed."""
    s = json.loads((out / "summary.json").read_text())
    line = f"{s['case']}: {s['steps']} steps in {s['wall_time_s']:.2f} s -> {out}"
    if s.get("status") == "max_steps":   # a check of a run cut short measures the part it ran
        line += f"; stopped by run.max_steps at t = {s['end_time']:.6g} s, before the case's end_time"
    if "check" in s:
        line += f"; check {'passed' if s['check']['passed'] else 'FAILED'}"
    return line, s.get("check", {}).get("passed", True)
