"""Launch one MPMD mpiexec job for a validated case and watch it.

Only the solvers the case uses are started. The job runs with hydra's auto-cleanup off so that the
launcher, not hydra, sees which process died first: every rank records pid -> (role, rank) at start
and removes the record on a clean exit, so a record whose process is gone names a failed rank (also
one killed by SIGKILL, which leaves no message). The launcher then ends the whole job within
seconds and reports that rank; a rank that failed with a Python error has written its own message.

SIGINT and SIGTERM to the launcher end the job the same way (stop_on_signals, end_job) and name the
step it was at; if mpiexec itself dies, the message says so. execute() runs one job and reacts to a
stop request without printing, so a campaign can run many; run_job() is what `immerse run` calls.
"""
from __future__ import annotations

import contextlib
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from adapters import case_file
from adapters import protocol as P
from adapters import registry
from orchestrator import outdir, prestart

def venv_bin() -> Path:
    return Path(sys.executable).parent


def build_command(case: dict, out: Path, ranks: dict[str, int], restart: str | None,
                  handed: tuple[Path, str]) -> list[str]:
    """The mpiexec command of the job; ``handed``: (path, SHA-256) of the case file the processes read
    (case_file.write)."""
    from orchestrator.case import solvers_used

    roles = [P.COUPLER] + solvers_used(case)
    path, sha = handed
    common = ["--case", str(path), "--case-sha256", sha, "--out", str(out), "--roles", ",".join(roles)]
    if restart:
        common += ["--restart", str(restart)]
    cmd = [str(venv_bin() / "mpiexec"), "-disable-auto-cleanup",
           "-n", "1", *prestart.command("orchestrator.coupler", [*common, "--role", P.COUPLER])]
    for r in roles[1:]:
        cmd += [":", "-n", str(ranks[r]), *prestart.command(registry.module_of(r), [*common, "--role", r])]
    return cmd


class StderrRelay:
    """Copies the job's stderr (mpiexec forwards every rank's there) to the launcher's own, and knows
    whether the last byte ended a line. mpiexec killed while forwarding a rank's traceback leaves half
    a line; the launcher's one-line report must not be glued to it, so close() ends such a line."""

    def __init__(self, pipe):
        self.pipe = pipe
        self.at_line_start = True
        self.thread = threading.Thread(target=self._copy, name="immerse-stderr-relay", daemon=True)
        self.thread.start()

    @staticmethod
    def _write(data: bytes) -> None:
        sys.stderr.flush()
        try:
            fd = sys.stderr.fileno()
        except (AttributeError, OSError, ValueError):  # a stream without a descriptor (in-process use)
            sys.stderr.write(data.decode(errors="replace"))
            sys.stderr.flush()
            return
        while data:
            data = data[os.write(fd, data):]

    def _copy(self) -> None:
        fd = self.pipe.fileno()
        while chunk := os.read(fd, 65536):
            self._write(chunk)
            self.at_line_start = chunk.endswith(b"\n")

    def close(self, timeout: float = 5.0) -> None:
        """After the job has ended: copy what is left, then end a half-written line."""
        self.thread.join(timeout)  # EOF once no process of the job holds the pipe
        if not self.at_line_start:
            self._write(b"\n")
            self.at_line_start = True
        if not self.thread.is_alive():
            self.pipe.close()


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
        self.waker: int | None = None  # a pidfd of mpiexec: poll() also wakes when the job ends

    def wake_on_exit_of(self, proc: subprocess.Popen) -> None:
        """Make wait() return as soon as ``proc`` (mpiexec) ends, not at the end of its timeout: the
        launcher then reports and exits within milliseconds of the job (the 50 ms polls added 25 ms
        on average to every job)."""
        try:
            self.waker = os.pidfd_open(proc.pid)
        except OSError:  # (already reaped, or no pidfds: the timeout alone ends the wait)
            return
        self.poller.register(self.waker, select.POLLIN)

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
        rec = P.read_record(record)
        if rec is None:
            return  # removed: a clean exit
        self.failed.append(f"{rec[0]} rank {rec[1]}")

    def wait(self, timeout_ms: int) -> list[str]:
        """Wait up to timeout_ms; return the ranks found failed so far (first failure first)."""
        self._scan()
        for fd, _ in self.poller.poll(timeout_ms):
            if fd == self.waker:
                continue
            pid, record = self.fds.pop(fd)
            self.poller.unregister(fd)
            os.close(fd)
            self._ended(record)
        return self.failed

    def find(self, role: str, rank: int) -> tuple[int, int] | None:
        """(pid, pidfd) of a live, recorded process of the job."""
        self._scan()
        for fd, (pid, record) in self.fds.items():
            rec = P.read_record(record)
            if rec is not None and rec[:2] == (role, rank):
                return pid, fd
        return None

    def close(self) -> None:
        for fd in self.fds:
            os.close(fd)
        self.fds.clear()
        if self.waker is not None:
            os.close(self.waker)
            self.waker = None


def silent_deaths(reports: list[str], died_first: list[str], first_dead: list[str]) -> list[str]:
    """The ranks that died without a report of their own and so caused the others' reports:
    those seen dead before any report (``died_first``), or, when every report is a failed MPI call
    (a neighbour's death seen from this side), those the first wake-up found dead: a rank's peer
    may write its report microseconds after the death, before the launcher looks (seen in CI).
    Those reports name the processes already gone when they were written (protocol.GONE): when the
    launcher woke only after MPI's abort had taken every rank down, that list is the only record
    of who died first."""
    if not died_first and reports and all(P.MPI_ERROR in rep for rep in reports):
        named = [name for rep in reports if P.GONE in rep
                 for name in rep.split(P.GONE, 1)[1].split("]", 1)[0].split(", ")]
        died_first = list(dict.fromkeys(named)) or first_dead
    return [r for r in died_first if not any(rep.startswith(r + ":") for rep in reports)]


def _error_reports(out: Path) -> list[str]:
    d = P.run_dir(out)
    return [f.read_text().strip() for f in sorted(d.glob("error_*.txt"))] if d.is_dir() else []



# ---- the process table -----------------------------------------------------------------------------
def descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` in the process table. hydra's proxies and the ranks each
    start a session of their own (setsid), so a process group or session signal from the launcher
    reaches mpiexec alone; the parent links still tie them to it."""
    children: dict[int, list[int]] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = P.proc_stat(int(name))
            if st:
                children.setdefault(st[0], []).append(int(name))
    found, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), ()):
            if c not in found:
                found.add(c)
                todo.append(c)
    return found


def end_job(proc: subprocess.Popen, out: Path, grace: float = 3.0) -> None:
    """End every process of the job: mpiexec, hydra's proxies, the coupler and every solver rank
    (those below mpiexec in the process table and those recorded in OUT/.run/pids, which also finds
    a rank whose proxy already died). SIGTERM, then SIGKILL after ``grace`` seconds; returns when
    none is running. pidfds make sure a recycled pid is never signalled."""
    # below mpiexec only while it is not reaped (a reaped pid may already belong to another process)
    pids = descendants(proc.pid) if proc.returncode is None else set()
    d = P.run_dir(out) / "pids"
    if d.is_dir():
        # (only a process still the one that wrote its record: a pid may have been reused)
        pids |= {int(f.name) for f in d.iterdir() if f.name.isdigit() and P.is_recorded_process(f)}
    fds = {}
    for pid in pids:
        try:
            fds[pid] = os.pidfd_open(pid)
        except OSError:
            pass
    try:
        # mpiexec first and without a word: a SIGTERM'd mpiexec prints banners about its ranks
        if proc.poll() is None:
            proc.kill()
        for sig, wait_s in ((signal.SIGTERM, grace), (signal.SIGKILL, 5.0)):
            for pid, fd in fds.items():
                try:
                    signal.pidfd_send_signal(fd, sig)
                except OSError:
                    pass
            deadline = time.monotonic() + wait_s
            while any(P.is_running(p) for p in fds) and time.monotonic() < deadline:
                time.sleep(0.02)
            if not any(P.is_running(p) for p in fds):
                break
    finally:
        for fd in fds.values():
            os.close(fd)
    proc.wait()


def dies_with_parent(sig: int = signal.SIGKILL):
    """preexec_fn for mpiexec: the kernel sends it ``sig`` (SIGKILL) when the launcher dies, even by
    SIGKILL, and its proxies then end the ranks (mpiexec's death ends the job, see end_job). Linux
    only; the signal follows the launcher *thread* that started the job, which waits for the job's
    end. A campaign uses it with SIGTERM for its `immerse run`s, which then end their jobs in order."""
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    launcher = os.getpid()
    pr_set_pdeathsig = 1

    def arm() -> None:  # in the child, between fork and exec: one libc call, no Python locks
        prctl(pr_set_pdeathsig, int(sig), 0, 0, 0)
        if os.getppid() != launcher:  # the launcher died before the line above
            os._exit(1)

    return arm


# ---- signals ---------------------------------------------------------------------------------------
class StopRequest:
    """Why running jobs must end: set by a signal handler (:func:`stop_on_signals`), or by a campaign
    that runs jobs in threads and owns the signals itself."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def request(self, signum: int) -> None:
        if self.signum is None:
            self.signum = signum


@contextlib.contextmanager
def stop_on_signals(stop: StopRequest | None = None,
                    signals=(signal.SIGINT, signal.SIGTERM, signal.SIGHUP)):
    """While inside, SIGINT, SIGTERM and SIGHUP (the terminal closed) to this process only set
    ``stop`` (no KeyboardInterrupt at a random place): the job loop sees it within 50 ms and ends the
    job in order. A signal the launcher was started ignoring (`nohup`, `&` in a script) stays ignored."""
    stop = stop or StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {s: signal.signal(s, lambda signum, frame: stop.request(signum))
                for s in signals if signal.getsignal(s) is not signal.SIG_IGN}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


# ---- one job ---------------------------------------------------------------------------------------
@dataclass
class JobResult:
    returncode: int  # 0 ok; 128 + signal number when interrupted; else the job's failure code
    message: str = ""  # one line (empty on success)
    signal: int | None = None  # the signal that interrupted it


def _last_output_time(out: Path) -> float | None:
    """Time of the last output step every role has on disk (after re-indexing)."""
    from orchestrator import output

    try:
        lasts = [steps[-1][0] for r in output.list_roles(out) if (steps := output.read_steps(out, r))]
    except (OSError, KeyError, ValueError):
        return None
    return min(lasts) if lasts else None


def _interrupted(out: Path, signum: int) -> str:
    name = signal.Signals(signum).name
    state = P.read_stop_state(out)
    where = (f"at step {state['step']}, t = {state['t']:.6e} s" if state
             else "during start-up (before the time loop)")
    last = _last_output_time(out)
    outputs = f"outputs up to t = {last:.6e} s" if last is not None else "no output step written"
    return f"interrupted by {name} {where}; {outputs} in {out}"


def _ask_coupler_where(watch: RankWatch, timeout: float = 1.0) -> None:
    """SIGTERM to the coupler alone first: it records its step and time, then exits."""
    found = watch.find(P.COUPLER, 0)
    if found is None:
        return
    pid, fd = found
    try:
        signal.pidfd_send_signal(fd, signal.SIGTERM)
    except OSError:
        return
    deadline = time.monotonic() + timeout
    while P.is_running(pid) and time.monotonic() < deadline:
        time.sleep(0.01)


def oversubscribed(case: dict, ranks: dict[str, int]) -> bool:
    """More processes (the coupler and every solver rank) than cores this launcher may run on."""
    from orchestrator.case import solvers_used
    from orchestrator.resources import job_processes, machine_cores

    return job_processes({r: ranks[r] for r in solvers_used(case)}) > machine_cores()


THREAD_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""What every process of a job gets where the environment does not set it: one thread each (the
job's parallelism is its ranks; a rank's BLAS or numba threads would take its neighbours' cores).
The launcher's default, the Slurm scripts' exports and bench startup's environment."""


def thread_exports() -> str:
    """THREAD_ENV as a shell line of a batch script."""
    return "export " + " ".join(f"{k}={v}" for k, v in THREAD_ENV.items())


PREFETCH_AFTER_S = 0.5
"""When execute() imports what it needs after the job (the output index), the job running."""


def execute(case: dict, out: Path, ranks: dict[str, int], restart: str | None = None,
            stop: StopRequest | None = None) -> JobResult:
    """Launch the job into a prepared ``out``, watch it, and end all of it on a failure or when
    ``stop`` is set (a signal); every completed output step is indexed afterwards. Prints nothing."""
    stop = stop or StopRequest()
    # the case checked here, as the processes read it (adapters/case_file.py: no TOML, no loader);
    # theirs alone: removed when the job ends, so a finished run leaves OUT/.run/ as it always did
    # (outdir.py's record of what a run wrote)
    handed = case_file.write(case, P.run_dir(out))
    cmd = build_command(case, out, ranks, restart, handed)
    env = dict(os.environ)
    for k, v in THREAD_ENV.items():
        env.setdefault(k, v)
    if oversubscribed(case, ranks):
        # MPICH's ranks busy-poll while they wait (for the coupler, a halo, a reduction); with more
        # processes than cores the pollers take the waited-for rank's core.  Its heavy yield sleeps
        # after POLLS_BEFORE_YIELD idle polls instead: two 3-process jobs on 2 cores 15.6 -> 9.5 s
        # (one alone 5.7 s, unchanged).  Not with a core per process: the sleep would add latency.
        env.setdefault("MPIR_CVAR_ENABLE_HEAVY_YIELD", "1")
        env.setdefault(P.SPIN_ENV, "0")  # and our own waits sleep after their first polls
    env["PYTHONUNBUFFERED"] = "1"
    env[P.LAUNCH_HOST_ENV] = socket.gethostname()  # only ranks on this host record their pids
    if sys.stderr.isatty():
        env["IMMERSE_TTY"] = "1"
    else:
        env.pop("IMMERSE_TTY", None)
    with (out / "log.txt").open("a") as f:
        f.write(f"command: {' '.join(cmd)}\n")
    if stop.signum is not None:
        handed[0].unlink(missing_ok=True)
        return JobResult(128 + stop.signum, f"interrupted by {signal.Signals(stop.signum).name} before "
                                            "the job started", stop.signum)
    proc = subprocess.Popen(cmd, env=env, start_new_session=True, preexec_fn=dies_with_parent(),
                            stderr=subprocess.PIPE)
    relay = StderrRelay(proc.stderr)
    watch = RankWatch(out)
    watch.wake_on_exit_of(proc)
    failed: list[str] = []
    died_first: list[str] = []  # ranks seen dead before any rank reported an error
    first_dead: list[str] = []  # the ranks the first wake-up found dead (a report may race them)
    ended_by_us = False
    # the index's writer (h5py: 50 ms), imported while the job runs, its processes past their own
    # imports, rather than on the way to the job's start or after its end
    prefetch_at = time.monotonic() + PREFETCH_AFTER_S
    try:
        while proc.poll() is None and stop.signum is None:
            failed = list(watch.wait(50))
            if prefetch_at is not None and time.monotonic() >= prefetch_at:
                prefetch_at = None
                from orchestrator import output  # noqa: F401
            if failed and not first_dead:
                first_dead = failed
            if failed and not _error_reports(out):
                died_first = failed
            if failed or _error_reports(out):
                # let a rank that is reporting an error finish its message, then end the job
                try:
                    proc.wait(timeout=1.0)
                except subprocess.TimeoutExpired:
                    ended_by_us = True
                break
        if stop.signum is not None:
            _ask_coupler_where(watch)
            ended_by_us = True
        failed = failed or list(watch.wait(0))
        first_dead = first_dead or failed
    finally:
        watch.close()
        # also after mpiexec's own end: no process of the job may outlive it
        end_job(proc, out)
        relay.close()
        handed[0].unlink(missing_ok=True)
    rc = proc.returncode
    from orchestrator import output

    if out.is_dir():
        output.write_index(out)  # every completed step file, also those the coupler had no time to index
    if stop.signum is not None:
        return JobResult(128 + stop.signum, _interrupted(out, stop.signum), stop.signum)
    reports = _error_reports(out)
    if rc == 0 and not failed and not reports:
        return JobResult(0)
    silent = silent_deaths(reports, died_first, first_dead)
    if rc < 0 and not ended_by_us:
        # mpiexec itself was killed: its proxies take the ranks down, which is not their failure
        why = (f"mpiexec (pid {proc.pid}) died, killed by {signal.Signals(-rc).name}; the job was "
               "ended with it")
    elif reports and silent:
        # a rank killed without a word (signal, OOM killer) is the cause; the others' reports (MPI
        # errors of a neighbour in a halo exchange, ...) are its consequences
        why = f"{silent[0]} died first (killed by a signal or exited without a message); then: " + "; ".join(reports)
    elif reports:
        why = "; ".join(reports)
        unstable = P.unstable_coupling_note(out)
        if unstable and not any(rep.startswith("coupler rank") for rep in reports):
            # a solver failed while the coupling's step was beyond its own limit: that is the cause
            why = f"{unstable}; then: {why}"
        elif case["run"].get("dt_scale", 0.9) > 1.0:
            # the case asked for steps beyond the solvers' own stable limit (a stability study)
            why = (f"unstable: run.dt_scale = {case['run']['dt_scale']:g} > 1 took steps beyond the "
                   f"solvers' stable (Courant) limit; then: {why}")
    elif failed:
        why = f"{failed[0]} died first (killed by a signal or exited without a message)"
    else:
        why = f"mpiexec exited with code {rc}"
    return JobResult(rc if rc not in (0, None) and rc > 0 else 1, f"run failed: {why}")


def run_job(case: dict, out: Path, ranks: dict[str, int], restart: str | None = None, *,
            replace: bool = False) -> int:
    """Check ``restart`` and ``out`` (the ownership rules of orchestrator.outdir) before anything
    is created, prepare ``out``, run the job with SIGINT/SIGTERM ending it in order, claim the files
    it wrote; print one line unless it succeeded; return the exit code (0, 1.., 130 on SIGINT, 143
    on SIGTERM). RestartError or OutDirError (nothing touched) if either is refused."""
    from orchestrator.fingerprint import case_fingerprint
    from orchestrator.restart import check_restart

    out = Path(out)
    ck = check_restart(restart, case) if restart is not None else None
    plan = outdir.plan(out, case, case_fingerprint(case), replace=replace, restart=ck)
    started = time.time()
    with stop_on_signals() as stop:
        outdir.prepare(plan, started)
        if restart and plan.delete:  # step files past the checkpoint dropped: no index entry may dangle
            from orchestrator import output

            output.write_index(out)
        try:
            result = execute(case, out, ranks, restart, stop)
            if result.returncode != 0 and out.is_dir():
                # the history so far and where it stopped (run_record.py), claimed with the run's files
                from orchestrator.case import solvers_used
                from orchestrator.run_record import record_ended_run

                try:
                    record_ended_run(case, out, "interrupted" if result.signal is not None else "failed",
                                     result.message, started, {r: ranks[r] for r in solvers_used(case)})
                except (OSError, ValueError, KeyError) as e:   # the run's own message comes first
                    with (out / "log.txt").open("a") as f:
                        f.write(f"immerse: the ended run's summary.json and diagnostics.h5 were not written: {e}\n")
        finally:
            outdir.finish_run(out, started)
    if result.message:
        if result.signal is not None and sys.stderr.isatty():
            print(file=sys.stderr)  # past the progress bar
        msg = f"immerse: {result.message}"
        print(msg, file=sys.stderr)
        with (out / "log.txt").open("a") as f:
            f.write(msg + "\n")
    return result.returncode
