"""Launch one MPMD mpiexec job for a validated case and watch it.

Only the solvers the case uses are started. The job runs with hydra's auto-cleanup off so that the
launcher, not hydra, sees which process died first: every rank records pid -> (role, rank) at start
and removes the record on a clean exit, so a record whose process is gone names a failed rank (also
one killed by SIGKILL, which leaves no message). The launcher then ends the whole job within
seconds and reports that rank; a rank that failed with a Python error has written its own message.
"""
from __future__ import annotations

import os
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from adapters import protocol as P
from adapters import registry

# outputs of a previous run that a fresh (non-restart) run replaces
RUN_OUTPUTS = ("steps", "checkpoints", "pictures", ".run", "results.h5", "results.xdmf",
               "summary.json", "log.txt", "diagnostics.h5")


def venv_bin() -> Path:
    return Path(sys.executable).parent


def build_command(case: dict, out: Path, ranks: dict[str, int], restart: str | None = None) -> list[str]:
    from orchestrator.case import solvers_used

    roles = [P.COUPLER] + solvers_used(case)
    common = ["--case", str(case["case_dir"]), "--out", str(out), "--roles", ",".join(roles)]
    if restart:
        common += ["--restart", str(restart)]
    py = sys.executable
    cmd = [str(venv_bin() / "mpiexec"), "-disable-auto-cleanup",
           "-n", "1", py, "-m", "orchestrator.coupler", *common, "--role", P.COUPLER]
    for r in roles[1:]:
        cmd += [":", "-n", str(ranks[r]), py, "-m", registry.module_of(r), *common, "--role", r]
    return cmd


def prepare_out(out: Path, restart: str | None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    names = (".run",) if restart else RUN_OUTPUTS
    for n in names:
        p = out / n
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    if restart:
        import h5py

        from orchestrator import output

        with h5py.File(restart, "r") as h:
            first_new = int(h.attrs["out_index"])
        # steps the restarted run will write again: drop the old ones so the index never mixes runs
        for f in (out / "steps").glob("*_[0-9]*.h5"):
            if int(f.stem.rsplit("_", 1)[1]) >= first_new:
                f.unlink()
        output.write_index(out)


class RankWatch:
    """Watches the job's processes through Linux pidfds: poll() wakes the moment the first one ends,
    before MPI's own error propagation takes the others down, so the first failed rank is known.
    A process whose pid record is still there when it ends has failed (clean exits remove it)."""

    def __init__(self, out: Path):
        self.dir = P.run_dir(out) / "pids"
        self.poller = select.poll()
        self.fds: dict[int, tuple[int, Path]] = {}
        self.watched: set[int] = set()
        self.failed: list[str] = []

    def _scan(self) -> None:
        if not self.dir.is_dir():
            return
        for f in self.dir.iterdir():
            if not f.name.isdigit() or int(f.name) in self.watched:
                continue
            pid = int(f.name)
            self.watched.add(pid)
            try:
                fd = os.pidfd_open(pid)
            except ProcessLookupError:  # gone before we looked
                self._ended(f)
                continue
            self.fds[fd] = (pid, f)
            self.poller.register(fd, select.POLLIN)

    def _ended(self, record: Path) -> None:
        try:
            role, rank = record.read_text().split()
        except (OSError, ValueError):
            return  # removed: a clean exit
        self.failed.append(f"{role} rank {rank}")

    def wait(self, timeout_ms: int) -> list[str]:
        """Wait up to timeout_ms; return the ranks found failed so far (first failure first)."""
        self._scan()
        for fd, _ in self.poller.poll(timeout_ms):
            pid, record = self.fds.pop(fd)
            self.poller.unregister(fd)
            os.close(fd)
            self._ended(record)
        return self.failed

    def close(self) -> None:
        for fd in self.fds:
            os.close(fd)
        self.fds.clear()


def _error_reports(out: Path) -> list[str]:
    d = P.run_dir(out)
    return [f.read_text().strip() for f in sorted(d.glob("error_*.txt"))] if d.is_dir() else []


def _stop(proc: subprocess.Popen, grace: float = 3.0) -> None:
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=grace)
            return
        except subprocess.TimeoutExpired:
            continue


def run_job(case: dict, out: Path, ranks: dict[str, int], restart: str | None = None) -> int:
    """Run the job; return 0 on success, else a non-zero code after printing which rank failed."""
    from orchestrator import output

    prepare_out(out, restart)
    cmd = build_command(case, out, ranks, restart)
    env = dict(os.environ)
    env.setdefault("NUMBA_NUM_THREADS", "1")
    env.setdefault("OMP_NUM_THREADS", "1")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env["PYTHONUNBUFFERED"] = "1"
    if sys.stderr.isatty():
        env["IMMERSE_TTY"] = "1"
    else:
        env.pop("IMMERSE_TTY", None)
    (out / "log.txt").open("a").write(f"command: {' '.join(cmd)}\n")
    proc = subprocess.Popen(cmd, env=env, start_new_session=True)
    watch = RankWatch(out)
    failed: list[str] = []
    died_first: list[str] = []  # ranks seen dead before any rank reported an error
    try:
        while proc.poll() is None:
            failed = list(watch.wait(50))
            if failed and not _error_reports(out):
                died_first = failed
            if failed or _error_reports(out):
                # let a rank that is reporting an error finish its message, then end the job
                try:
                    proc.wait(timeout=1.0)
                except subprocess.TimeoutExpired:
                    _stop(proc)
                break
        failed = failed or list(watch.wait(0))
    except KeyboardInterrupt:
        _stop(proc)
        print("immerse: interrupted", file=sys.stderr)
        return 130
    finally:
        watch.close()
    rc = proc.wait()
    if out.is_dir():
        output.write_index(out)  # every completed step file, also those the coupler had no time to index
    reports = _error_reports(out)
    if rc == 0 and not failed and not reports:
        return 0
    silent = [r for r in died_first if not any(rep.startswith(r + ":") for rep in reports)]
    if reports and silent:
        # a rank killed without a word (signal, OOM killer) is the cause; the others' reports (MPI
        # errors of a neighbour in a halo exchange, ...) are its consequences
        why = f"{silent[0]} died first (killed by a signal or exited without a message); then: " + "; ".join(reports)
    elif reports:
        why = "; ".join(reports)
    elif failed:
        why = f"{failed[0]} died first (killed by a signal or exited without a message)"
    else:
        why = f"mpiexec exited with code {rc}"
    msg = f"immerse: run failed: {why}"
    print(msg, file=sys.stderr)
    with (out / "log.txt").open("a") as f:
        f.write(msg + "\n")
    return rc if rc not in (0, None) else 1
