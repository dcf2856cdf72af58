"""``immerse run CASE --engine slurm``: one run as one Slurm batch job.

The case and the output directory are checked here, before anything is submitted, by the same
rules as a local run (bad input: one line, exit 2, nothing written). The output directory is then
prepared (its ownership record) so that the job's own output file can live in it
(``OUT/slurm-<job>.out``: what the job printed, kept with the run), and one batch job is submitted
(the script on sbatch's standard input) whose body is the ordinary ``immerse run`` of this case into
that directory: the same outputs, the same fault handling. Its ``mpiexec`` spans the allocation
(hydra's Slurm support starts a proxy per node with srun): one task per process (the solvers' ranks
per role from the case or ``--ranks``, and the coupler), ``--nodes`` as given.

The submitting command stays and follows the job: it prints the run's log lines as they reach
``OUT/log.txt`` (progress), and ends with the job: 0 when the run succeeded, the run's own exit code
when it failed (its message is in the log), and a line naming the job and its state for a job that
Slurm ended (cancelled, timed out, node failure: exit 1). SIGINT/SIGTERM cancel the job (scancel):
the run ends its job in order, as on a local Ctrl-C.
"""
from __future__ import annotations

import shlex
import signal
import sys
import time
from pathlib import Path

from orchestrator.slurm_commands import FINAL_STATES, POLL_S, SlurmError, command, job_state, node_cpus


def batch_script(case: dict, inner: list[str], procs: int, nodes: int | None, overcommit: bool,
                 output: Path) -> str:
    from orchestrator.launch import thread_exports

    lines = ["#!/bin/bash",
             f"#SBATCH --job-name={shlex.quote('immerse-' + case['name'])}",
             f"#SBATCH --ntasks={procs}",
             f"#SBATCH --output={shlex.quote(str(output))}",
             "#SBATCH --open-mode=append"]
    if nodes:
        lines.append(f"#SBATCH --nodes={nodes}")
    if overcommit:  # more processes than the nodes have CPUs: the coupler is light, ranks share
        lines.append("#SBATCH --overcommit")
    lines += ["set -eu",
              thread_exports(),
              "exec " + " ".join(shlex.quote(a) for a in inner)]
    return "\n".join(lines) + "\n"


def _tail(path: Path, pos: int) -> int:
    """Print what was added to the log since ``pos``; return the new position."""
    try:
        with open(path, "rb") as f:
            f.seek(pos)
            data = f.read()
    except OSError:
        return pos
    end = data.rfind(b"\n") + 1  # whole lines only
    for line in data[:end].decode("utf-8", "replace").splitlines():
        if not line.startswith("command: "):
            print(line, flush=True)
    return pos + end


def submit_run(args, case: dict, ranks: dict[str, int]) -> int:
    """Submit and follow; return the exit code. Raises OutDirError/RestartError (nothing written)."""
    from orchestrator import outdir
    from orchestrator.fingerprint import case_fingerprint
    from orchestrator.restart import check_restart
    from orchestrator.resources import job_processes

    out = Path(args.out) if args.out is not None else Path(case["case_dir"]) / "out"
    out = out.absolute()
    ck = check_restart(args.restart, case) if args.restart is not None else None
    plan = outdir.plan(out, case, case_fingerprint(case), replace=args.replace, restart=ck)
    procs = job_processes(ranks)
    cpus = node_cpus()
    overcommit = cpus is not None and procs > cpus * (int(args.nodes) if args.nodes else 1)
    inner = [sys.executable, "-m", "orchestrator.cli", "run", str(case["case_dir"]), "--out", str(out)]
    # the checks above were this run's: the job continues the checkpoint or replaces what this
    # command prepared (the record and the job's output file only)
    inner += ["--restart", str(Path(args.restart).absolute())] if args.restart else ["--replace"]
    if args.ranks:
        inner += ["--ranks", *args.ranks]
    if args.nodes:
        inner += ["--nodes", str(args.nodes)]
    if args.memory_per_node:
        inner += ["--memory-per-node", args.memory_per_node]
    if args.oversubscribe or overcommit:
        inner += ["--oversubscribe"]
    started = time.time()
    outdir.prepare(plan, started)
    outdir.finish_run(out, started)  # prepared, not running: the job's own `immerse run` takes it
    try:
        output = out / "slurm-%j.out"
        script = batch_script(case, inner, procs, int(args.nodes) if args.nodes else None, overcommit, output)
        sb = command("sbatch", "--parsable", input=script, check=False)
        if sb.returncode != 0:
            print(f"immerse: sbatch refused the job: {' '.join(sb.stderr.split())[:300]}", file=sys.stderr)
            return 1
        job = sb.stdout.strip().split(";")[0]
    except SlurmError as e:
        print(f"immerse: {e}", file=sys.stderr)
        return 1
    name = f"slurm job {job} (immerse-{case['name']})"
    print(f"submitted {name}: {procs} tasks{f' on {args.nodes} nodes' if args.nodes else ''}; "
          f"output {out}", flush=True)
    try:
        return follow(job, name, out)
    finally:
        if (out / f"slurm-{job}.out").is_file():  # (after the job: its own --replace keeps it)
            outdir.record_written(out, out / f"slurm-{job}.out")


def follow(job: str, name: str, out: Path) -> int:
    log = out / "log.txt"
    pos = 0
    last_state = None

    def stop(signum, frame):
        raise KeyboardInterrupt(signum)

    old = signal.signal(signal.SIGTERM, stop)
    signum = None
    try:
        while True:
            try:
                pos = _tail(log, pos)
                st = job_state(job)
                if st is not None and st[0] != last_state and st[0] in ("PENDING", "RUNNING"):
                    print(f"{name}: {st[0].lower()}", flush=True)
                    last_state = st[0]
                if st is not None and st[0] in FINAL_STATES:
                    break
                time.sleep(POLL_S)
            except KeyboardInterrupt as e:
                if signum is not None:
                    raise
                signum = e.args[0] if e.args else int(signal.SIGINT)
                print(f"immerse: cancelling {name}", file=sys.stderr, flush=True)
                command("scancel", job, check=False)
    finally:
        signal.signal(signal.SIGTERM, old)
    time.sleep(0.2)
    _tail(log, pos)
    state, code = st
    rc_text = code.split(":")[0] if code else ""
    rc = int(rc_text) if rc_text.isdigit() else 1
    if signum is not None:
        print(f"immerse: {name} cancelled on {signal.Signals(signum).name}; completed output steps stay "
              f"readable in {out}", file=sys.stderr)
        return 128 + signum
    if state == "COMPLETED" or (state == "FAILED" and rc == 1 and _finished(out)):
        from orchestrator.run_record import summary_line

        line, passed = summary_line(out)
        print(line, flush=True)
        return 0 if state == "COMPLETED" else 1
    if state == "FAILED" and rc not in (0, 130, 143):
        print(f"immerse: {name} FAILED with exit code {rc}; the run's message is in {log}", file=sys.stderr)
        return rc
    print(f"immerse: {name} ended {state} (exit code {code}): stopped by Slurm; completed output steps "
          f"stay readable in {out}", file=sys.stderr)
    return 1


def _finished(out: Path) -> bool:
    """Whether the run's summary.json is that of a run that reached its end (its check may have failed),
    not the record a failed or interrupted run leaves (orchestrator/run_record.py)."""
    import json

    try:
        return json.loads((out / "summary.json").read_text()).get("status", "completed") in ("completed", "max_steps")
    except (OSError, ValueError):
        return False


__all__ = ["submit_run", "batch_script", "follow"]
