"""Validation campaigns: ``immerse campaign CAMPAIGN.toml`` and ``immerse report OUT``.

The order of things (each step a module of this package):

1. :mod:`.spec` reads the campaign file and expands it into runs; every run's case is checked like
   ``immerse check`` before anything is written (one line, exit 2).
2. :mod:`.rundir` claims the output directory and writes each run's case directory; a run whose
   result is stored for the same case (same fingerprint) is done and skipped.
3. an engine runs the rest, each run through :mod:`.task` (``immerse run``, then result.json):
   :mod:`.local` (a pool of child processes, default) or :mod:`.slurm` (one sbatch job array).
4. :mod:`.collect` gathers every result into campaign.csv and campaign.h5.
5. :mod:`.report` draws the charts and writes report.md and report.html.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ENGINES = ("local", "slurm")


def spec_dict(camp) -> dict:
    """What the report needs of the campaign, stored in campaign.h5 (rebuilt without the file)."""
    return {"name": camp.name, "file": str(camp.path), "description": camp.description,
            "report": camp.report, "axes": camp.axes,
            "series": [{"name": s["name"], "chart": s.get("chart", camp.name),
                        "error": s.get("error", camp.report.get("error"))} for s in camp.series],
            "runs": [r.name for r in camp.runs]}


def _line(i: int, n: int, run, res: dict | None, note: str | None = None) -> str:
    if res is None:
        return f"[{i}/{n}] {run.name}: {note or 'ended without a result (interrupted)'}; runs again next time"
    s = res.get("summary") or {}
    text = f"[{i}/{n}] {run.name}: {res['status']}"
    if s:
        text += f", {s.get('steps')} steps, {s.get('wall_time_s', float('nan')):.3g} s"
    from orchestrator.campaign.collect import error_of

    err = error_of(s, run.error)
    if err == err:
        text += f", {run.error} {err:.4g}"
    if res.get("message"):
        text += f" -- {res['message']}"
    return text


def run_campaign(path, out=None, engine: str = "local", retry_failed: bool = False,
                 report: bool = True, only: dict | None = None, cores: int | None = None) -> int:
    """The whole command; returns its exit code (0: every run ended with a result; 1: some run has
    none; 130/143 interrupted). Raises CaseError (nothing written) for bad input."""
    from orchestrator.campaign import collect, rundir
    from orchestrator.campaign.spec import load_campaign

    camp = load_campaign(path, only=only)
    out = Path(out) if out is not None else camp.path.parent / "out"
    rundir.claim_out(out, camp)
    pending, done = [], 0
    for run in camp.runs:
        d, is_done = rundir.prepare_run(out, run)
        res = rundir.read_result(d) if is_done else None
        if is_done and retry_failed and res and res["status"] not in ("passed", "check_failed", "warned"):
            rundir.remove_recorded(out, f"runs/{d.name}/result.json")
            is_done = False
        if is_done:
            done += 1
        else:
            pending.append((run, d))
    n = len(camp.runs)
    print(f"campaign {camp.name}: {n} runs, {done} done before, {len(pending)} to run "
          f"(engine {engine}) -> {out}", flush=True)
    count = [done]

    def on_done(run, d, note=None):
        count[0] += 1
        print(_line(count[0], n, run, rundir.read_result(d), note), flush=True)

    started = time.monotonic()
    rc = 0
    try:
        if engine == "local":
            from orchestrator.campaign.local import cores_here, run_local

            run_local(pending, camp.timeout_s, cores or cores_here(), on_done)
        else:
            from orchestrator.campaign.slurm import SlurmError, run_slurm

            try:
                run_slurm(camp, out, pending, on_done)
            except SlurmError as e:
                print(f"immerse: campaign {camp.name}: {e}", file=sys.stderr)
                rc = 1
    except KeyboardInterrupt as e:
        signum = e.args[0] if e.args else 2
        print(f"immerse: campaign interrupted ({'SIGTERM' if signum == 15 else 'SIGINT'}); finished "
              f"runs are kept, `immerse campaign` again runs the rest", file=sys.stderr)
        rc = 128 + signum
    rows = collect.collect(out, spec_dict(camp), [r.name for r in camp.runs])
    missing = [r["run"] for r in rows if r["status"] == "not_run"]
    if rc == 0 and missing:
        print(f"immerse: {len(missing)} runs have no result ({', '.join(missing[:5])}"
              f"{', ...' if len(missing) > 5 else ''})", file=sys.stderr)
        rc = 1
    if report and rc == 0:
        from orchestrator.campaign.report import write_report

        write_report(out)
    by = {}
    for r in rows:
        by[r["status"]] = by.get(r["status"], 0) + 1
    print(f"campaign {camp.name}: " + ", ".join(f"{v} {k}" for k, v in by.items())
          + f" in {time.monotonic() - started:.1f} s -> {out / 'campaign.csv'}", flush=True)
    return rc

