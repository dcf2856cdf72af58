"""One run of a campaign: ``python -m orchestrator.campaign.task RUN_DIR [--timeout S]``.

Runs ``immerse run RUN_DIR/<run> --out RUN_DIR/out --replace`` (the ordinary command: no second
code path), then writes ``RUN_DIR/result.json`` atomically, last. Both engines run this: the local
engine as a child process, the Slurm engine as the body of an array task.

result.json: ``status`` (see STATUSES), ``returncode``, ``message`` (the run's own one-line failure
message, or ''), ``elapsed_s`` (the whole command, start-up included), ``fingerprint`` (of the case
that ran), ``summary`` (the run's summary.json, when it wrote one) and ``engine``.

A task killed or stopped by a signal writes no result: the run is not done and runs again.
"""
from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from orchestrator import prestart

STATUSES = {
    "passed": "ran to its end time; its check passed (or it has none)",
    "warned": "ran to its end time, but a detector warned of a known failure (an ill-conditioned "
              "multiplier system, steps beyond the stable limit): the warning is the message",
    "check_failed": "ran to its end time; a check metric is outside its tolerance",
    "unstable": "stopped by a detector that names an instability (coupling beyond its stable limit, "
                "Courant limit, energy growth, inverted elements, non-finite or non-positive state)",
    "failed": "stopped by any other error",
    "timeout": "ended by the campaign's per-run timeout",
}
INSTABILITY = re.compile(
    r"unstable|instabilit|beyond (?:its|the) stable|stable (?:time )?step|courant|energy grow|"
    r"invert|negative (?:internal )?(?:volume|jacobian|density|energy)|non-positive|non-finite|vacuum|"
    r"cavitat|tangled",
    re.IGNORECASE)
"""Words of the detectors' messages that name an instability (the map's 'unstable detected')."""


def classify(rc: int, message: str, summary: dict | None, warnings: list[str] | None = None) -> str:
    if summary is not None and summary.get("status", "completed") not in ("completed", "max_steps"):
        summary = None   # a failed or interrupted run's record (run_record.py): no result of a finished run
    if rc in (0, 1) and warnings and summary is not None:
        return "warned"
    if rc == 0:
        return "passed"
    if summary is not None and rc == 1 and "check" in summary and not summary["check"]["passed"]:
        return "check_failed"
    return "unstable" if INSTABILITY.search(message or "") else "failed"


def failed_metrics(summary: dict) -> str:
    """A check_failed run's message: each metric outside its tolerance, with why where it is NaN."""
    out = []
    for name, m in summary["check"]["metrics"].items():
        if not m["passed"]:
            text = (f"{name}: {m['value']:.6g} vs {m['reference']:.6g} (rel. error {m['rel_error']:.3g}, "
                    f"tolerance {m['tolerance']:g})")
            out.append(text + (f": {m['note']}" if m.get("note") else ""))
    return "; ".join(out)[:2000]


def _message(stderr: str) -> str:
    """The run's one-line failure message: its last line that starts with 'immerse:'."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    own = [ln for ln in lines if ln.startswith("immerse:")]
    text = own[-1] if own else (lines[-1] if lines else "")
    return text.removeprefix("immerse:").strip()[:2000]


def _warnings(log: Path) -> list[str]:
    """The run's own warnings (log lines 'warning: ...', time stamp dropped)."""
    try:
        lines = log.read_text(errors="replace").splitlines()
    except OSError:
        return []
    return [ln.split("] ", 1)[-1].removeprefix("warning: ").strip() for ln in lines if "] warning: " in ln]


def _wait_for_previous(out: Path, limit: float = 30.0) -> None:
    """A launcher of this run killed with its campaign may still be ending its job: wait for it."""
    from orchestrator import outdir

    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        owner = outdir.read_owner(out) if out.is_dir() else None
        if not owner or not outdir._alive(owner.get("run")):
            return
        time.sleep(0.2)


def run_task(d: Path, timeout: float | None = None, engine: str = "local") -> int:
    from orchestrator.campaign.rundir import atomic_write, record, remove_recorded
    from orchestrator.launch import dies_with_parent

    meta = json.loads((d / "run.json").read_text())
    camp_out = d.parent.parent
    remove_recorded(camp_out, f"runs/{d.name}/result.json")
    record(camp_out, d / "stdout.txt", d / "stderr.txt", d / "result.json")
    out = d / "out"
    _wait_for_previous(out)
    cmd = prestart.command("orchestrator.cli", ["run", str(d / meta["name"]), "--out", str(out), "--replace"])
    started = time.monotonic()
    started_at = time.time()
    with open(d / "stdout.txt", "w") as so, open(d / "stderr.txt", "w+") as se:
        proc = subprocess.Popen(cmd, stdout=so, stderr=se, stdin=subprocess.DEVNULL,
                                preexec_fn=dies_with_parent(signal.SIGTERM))
        stopped: list[int] = []

        def forward(signum, frame):  # SIGTERM/SIGINT: the run ends its job in order; no result
            stopped.append(signum)
            proc.send_signal(signal.SIGTERM)

        signal.signal(signal.SIGTERM, forward)
        signal.signal(signal.SIGINT, forward)
        timed_out = False
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            proc.send_signal(signal.SIGTERM)  # `immerse run` ends its job in order
            try:
                rc = proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                rc = proc.wait()
        se.seek(0)
        stderr = se.read()
    elapsed = time.monotonic() - started
    if stopped:
        return 128 + stopped[0]
    if not timed_out and (rc < 0 or rc in (130, 143)):
        # killed, or stopped by SIGINT/SIGTERM from outside: not a result of the run; it runs again
        return 128 - rc if rc < 0 else rc
    summary = None
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        pass
    message = _message(stderr) if rc != 0 else ""
    warnings = _warnings(out / "log.txt")
    status = "timeout" if timed_out else classify(rc, message, summary, warnings)
    if status == "warned":
        message = "; ".join(warnings)[:2000]
    if status == "check_failed" and not message:
        message = failed_metrics(summary)
    if timed_out:
        message = f"timed out after {timeout:g} s (the campaign's timeout); ended"
    result = {"name": meta["name"], "status": status, "returncode": rc, "message": message,
              "warnings": warnings,
              "elapsed_s": elapsed, "started_at": started_at, "ended_at": time.time(),
              "fingerprint": meta["fingerprint"], "engine": engine,
              "summary": summary}
    atomic_write(d / "result.json", json.dumps(result, indent=1) + "\n")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m orchestrator.campaign.task")
    ap.add_argument("run_dir")
    ap.add_argument("--timeout", type=float)
    ap.add_argument("--engine", default="local")
    args = ap.parse_args(argv)
    return run_task(Path(args.run_dir), args.timeout, args.engine)


if __name__ == "__main__":
    sys.exit(main())
