"""What the coupler and the solver groups share: how processes find their role, the command and
reply buffers exchanged every step (numpy float64, never pickles), and how a failing rank reports.

Process layout: one MPMD job `mpiexec -n 1 coupler : -n Na role_a : -n Nb role_b ...`. Every process
is told its role and the ordered role list; COMM_WORLD is split by role and the coupler holds one
intercommunicator per solver group (group root = rank 0 of that group).
"""
from __future__ import annotations

import math
import os
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

COUPLER = "coupler"

# Commands the coupler broadcasts to a solver group: float64[CMD_LEN]
CMD_STEP, CMD_WRITE, CMD_CHECKPOINT, CMD_STOP = 1.0, 2.0, 3.0, 4.0
CMD_LIMITER = 5.0  # no step: the group root sends what sets its stable step (TAG_LIMITER), then replies
CMD_LEN = 7  # [command, dt, step (after the step), time (after the step), output index, diagnostics flag,
#              substeps (a foreground's, multi-rate: orchestrator/coupling/multirate.py; 1 otherwise)]

# Reply of a group root to the coupler after every command: float64[REPLY_HEAD + n_diagnostics]
REPLY_HEAD = 2  # [status (0 ok), stable dt for the next step]


@dataclass
class Placement:
    role: str
    roles: list[str]  # coupler first, then the solver roles of this job
    world: object
    comm: object  # this role's own communicator
    inter: dict  # coupler: {solver role: intercomm}; solver: {"coupler": intercomm}


def join(role: str, roles: list[str]) -> Placement:
    """Split COMM_WORLD by role and connect every solver group to the coupler."""
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    comm = world.Split(roles.index(role), world.rank)
    placed = world.allgather((role, comm.rank))
    leader = {r: i for i, (r, sub_rank) in enumerate(placed) if sub_rank == 0}
    inter = {}
    if role == COUPLER:
        for r in roles[1:]:
            inter[r] = comm.Create_intercomm(0, world, leader[r], tag=100 + roles.index(r))
    else:
        inter[COUPLER] = comm.Create_intercomm(0, world, leader[COUPLER], tag=100 + roles.index(role))
    return Placement(role, roles, world, comm, inter)


LAUNCH_HOST_ENV = "IMMERSE_LAUNCH_HOST"
"""The host of the launcher (set by orchestrator.launch for every rank)."""


def run_dir(out_dir: Path) -> Path:
    """Run-control files (pids, error reports) that `immerse run` watches."""
    return Path(out_dir) / ".run"


def register_process(out_dir: Path, role: str, rank: int) -> None:
    """Record pid -> (role, rank) so the launcher can name a rank that dies without a word (SIGKILL).
    Only a process on the launcher's host records itself: a pid names a process on one host only
    (a rank on another node of a Slurm allocation is watched by mpiexec)."""
    import socket

    if os.environ.get(LAUNCH_HOST_ENV, socket.gethostname()) != socket.gethostname():
        return
    d = run_dir(out_dir) / "pids"
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / f".{os.getpid()}.tmp"
    tmp.write_text(f"{role} {rank} {start_ticks(os.getpid())}\n")
    os.replace(tmp, d / str(os.getpid()))


def start_ticks(pid: int) -> int | None:
    """When process ``pid`` started (clock ticks since boot, /proc field 22), None if it is gone: with
    the pid, the identity of a process (a pid alone may be reused once it has ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def read_record(path: Path) -> tuple[str, int, int | None] | None:
    """(role, rank, start ticks) of a process record (register_process), None once removed."""
    try:
        fields = Path(path).read_text().split()
        return fields[0], int(fields[1]), (int(fields[2]) if len(fields) > 2 and fields[2].isdigit() else None)
    except (OSError, IndexError, ValueError):
        return None


def is_recorded_process(path: Path) -> bool:
    """Is the process a record names (by its pid, the record's file name) still the one that wrote it
    (the same start time)? A process started from a warm server (orchestrator/prestart) has the
    server's command line, so its start time, not its command line, says who it is."""
    rec = read_record(path)
    return rec is not None and rec[2] is not None and start_ticks(int(Path(path).name)) == rec[2]


def write_stop_state(out_dir: Path, **state) -> None:
    """What the coupler was doing when it was told to stop (step, t): the launcher's interruption
    message reads it. Written atomically; small."""
    import json

    d = run_dir(out_dir)
    tmp = d / f".stop_state.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(state))
    os.replace(tmp, d / "stop_state.json")


def read_stop_state(out_dir: Path) -> dict | None:
    import json

    try:
        return json.loads((run_dir(out_dir) / "stop_state.json").read_text())
    except (OSError, ValueError):
        return None


def report_failure(out_dir: Path, role: str, rank: int, message: str) -> None:
    line = f"{role} rank {rank}: {message}".replace("\n", " ")
    try:
        d = run_dir(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        tmp = d / f".error_{role}_{rank}.tmp"  # atomic: the launcher polls for these and reads them
        tmp.write_text(line + "\n")
        os.replace(tmp, d / f"error_{role}_{rank}.txt")
    finally:
        print(f"immerse: {line}", file=sys.stderr, flush=True)


UNSTABLE_COUPLING = "coupling_beyond_limit.txt"
"""While a coupling method's step is beyond its own explicit stable-step limit, the coupler keeps a
one-line note of it here: a solver that then fails (a zone inverted by the growing oscillation,
before the coupler's energy check sees it) failed because of the coupling, and the launcher says so."""


def note_unstable_coupling(out_dir: Path, line: str | None) -> None:
    """Write (``line``) or remove (None) the coupler's note that its step is beyond the coupling's
    stable-step limit; atomic, so the launcher never reads half a line."""
    d = run_dir(out_dir)
    path = d / UNSTABLE_COUPLING
    if line is None:
        path.unlink(missing_ok=True)
        return
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / f".{UNSTABLE_COUPLING}.tmp"
    tmp.write_text(line.replace("\n", " ") + "\n")
    os.replace(tmp, path)


def unstable_coupling_note(out_dir: Path) -> str | None:
    try:
        return (run_dir(out_dir) / UNSTABLE_COUPLING).read_text().strip() or None
    except OSError:
        return None


MPI_ERROR = "MPI error (a rank it exchanges with may be gone)"
"""Starts the report of a rank whose MPI call failed: most often a consequence (a neighbour in a
halo exchange was killed), so the launcher names a rank that died silently before it as the cause."""


GONE = "gone at this report: "
"""In a failed MPI call's report, before the names of the job's processes (this host's pid records)
that had already ended when the rank reported: the neighbour whose death failed the call, named
while the others still run (the launcher may wake after MPI's abort took them all down)."""


def proc_stat(pid: int) -> tuple[int, str] | None:
    """(parent pid, state letter) of a process from /proc, None if it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return int(fields[1]), fields[0]
    except (OSError, IndexError, ValueError):
        return None


def is_running(pid: int) -> bool:
    """Alive and not a zombie (a zombie has ended; only its exit status waits to be collected)."""
    st = proc_stat(pid)
    return st is not None and st[1] not in "ZX"


def gone_processes(out_dir: Path) -> list[str]:
    """'role rank N' of every recorded process of the job on this host that has ended (or is a
    zombie its parent has not reaped yet); records removed by a clean exit are not listed."""
    d = run_dir(out_dir) / "pids"
    gone = []
    try:
        records = sorted(d.iterdir(), key=lambda f: f.name)
    except OSError:
        return gone
    for f in records:
        if f.name.isdigit() and not is_running(int(f.name)):
            rec = read_record(f)
            if rec is None:
                continue   # removed meanwhile: a clean exit
            role, rank = rec[0], rec[1]
            gone.append(f"{role} rank {rank}")
    return gone


def _is_mpi_error(exc: BaseException) -> bool:
    mpi = sys.modules.get("mpi4py.MPI")
    return mpi is not None and isinstance(exc, mpi.Exception)


def _abort() -> None:
    from mpi4py import MPI

    MPI.COMM_WORLD.Abort(1)


def exit_after_clean_end() -> None:
    """End a process of the job that has finished its work (its pid record removed): flush its
    output, finalize MPI, and exit at once, skipping the interpreter's teardown. That teardown
    freed the modules one by one after the job was done: the JIT compiler's objects took 0.35-0.45 s
    of CPU in a solver rank (sod), and MPI_Finalize, which every rank of the job waits in, came
    only after it. Only the `python -m` entry points call this (never a caller in-process):
    every file is closed by then, and nothing is written after MPI_Finalize (hydra may drop a
    process's last output written after the job's final barrier)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    try:  # and C's stdio buffers (a library's printf, e.g. LAMMPS): exit() flushes them, _exit() not
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is not None and mpi.Is_initialized() and not mpi.Is_finalized():
        mpi.Finalize()
    os._exit(0)


def install_fault_handler(out_dir: Path, role: str, rank: int) -> None:
    """An uncaught exception on any rank: report it by role and rank, then bring the whole job down."""

    def hook(exc_type, exc, tb):
        traceback.print_exception(exc_type, exc, tb, file=sys.stderr)
        prefix = ""
        if _is_mpi_error(exc):
            gone = gone_processes(out_dir)
            prefix = f"{MPI_ERROR}" + (f" [{GONE}{', '.join(gone)}]" if gone else "") + ": "
        report_failure(out_dir, role, rank, f"{prefix}{exc_type.__name__}: {exc}")
        _abort()

    sys.excepthook = hook


# ---- coupled steps (embedded-mesh coupling): group root <-> coupler, float64 buffers ---------------
# tags of the messages of a coupled run (README/DESIGN "the coupled step"), in the order they flow
TAG_SURFACE = 10    # foreground -> coupler, at start-up: its surface (ids, facets, masses, x, v)
TAG_GEOMETRY = 11   # coupler -> background: the bodies' geometry in the grid (start-up, every remap)
TAG_PREDICT = 19    # coupler -> foreground in substeps, at the step's start: the predicted surface impulses
TAG_VSTAR = 20      # foreground -> coupler, after predict: v* of the surface nodes (in substeps: their mean)
TAG_INTERFACE = 21  # background -> coupler, after predict: v*, m of the nodes asked for, cut-zone forces
TAG_IMPULSE = 22    # coupler -> foreground: surface impulses
TAG_STATE = 23      # foreground -> coupler, after correct: x^{n+1}, v^{n+1/2} of the surface nodes, then a flag (1: a new surface follows, TAG_SURFACE)
TAG_CORRECT = 24    # coupler -> background: node impulses, the surface's v^{n+1/2} and mean velocity
TAG_TIMING = 30     # solver -> coupler, after its stop reply: [seconds in its own step work, seconds in its engine (LAMMPS runs) or nan]
TAG_LIMITER = 31    # solver -> coupler, on CMD_LIMITER: its step_limiter() (pickled dict or None; rare, not a hot path)


SPIN_ENV = "IMMERSE_WAIT_SPIN_S"
"""How long a wait polls MPI at full speed before it sleeps between polls (seconds; default 200e-6).
With a core per process a reply due within a LAMMPS step or two is then taken at once (sleeping from
the first polls cost the SPH driver 10 % at one LAMMPS step per coupler step) and a long wait (a
rank's start-up, the coupler's solve or output) still leaves the core.  With more processes than
cores every poll takes a working process's core: the launcher sets 0 then, and so does the test
suite (two jobs at once on 2 cores)."""


SPIN_MAX_S = 1.0
"""The longest a wait may spin before it sleeps (s): beyond, every waiting rank holds a core."""


def spin_s_from(text: str | None) -> float | None:
    """SPIN_ENV's value in seconds (default 200e-6 when unset), or None if it is not a finite number
    from 0 to SPIN_MAX_S (immerse check and run refuse it, orchestrator/cli.py, before anything starts)."""
    if text is None:
        return 200e-6
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) and 0.0 <= v <= SPIN_MAX_S else None


def _spin_s() -> float:
    v = spin_s_from(os.environ.get(SPIN_ENV))
    return 200e-6 if v is None else v


SPIN_S = _spin_s()
SLEEP_S = 50e-6  # the sleep between polls after SPIN_S: the latency a short wait adds
SLEEP_SHARE = 0.02
"""A long wait sleeps up to this share of the time it has waited so far between polls (from SLEEP_S
up to SLEEP_MAX_S): the latency it adds stays within 2 % of the wait.  A wait of a step (ms) polls
every SLEEP_S as before; a wait of a second (the coupler's for the ranks' start-up) no longer wakes
~8500 times a second (a sleep of 50 us takes ~110 us): its CPU 0.09-0.10 -> 0.016-0.021 s, CPU that
it took from the ranks it waits for when they share its core."""
SLEEP_MAX_S = 2e-3


def poll(done) -> None:
    """Call ``done()`` until it is true, spinning for SPIN_S and then sleeping between calls: SLEEP_S,
    or SLEEP_SHARE of the time waited so far in a long wait (at most SLEEP_MAX_S).
    MPI's blocking calls busy-poll for as long as they wait, and the ranks often share the cores
    (more processes than cores in small jobs and in the test suite)."""
    import time as _t

    if done():
        return
    t0 = _t.perf_counter()
    polls = 0
    while not done():
        polls += 1  # (at least 50 quick polls: a message already on its way)
        if polls > 50:
            waited = _t.perf_counter() - t0
            if waited > SPIN_S:
                _t.sleep(min(max(SLEEP_S, SLEEP_SHARE * waited), SLEEP_MAX_S))


def wait(req) -> None:
    """Wait for a request without spinning a core for long (see poll)."""
    poll(req.Test)


def send(comm, buf, dest: int, tag: int) -> None:
    comm.Send(np.ascontiguousarray(buf, dtype=np.float64), dest=dest, tag=tag)


def recv(comm, source: int, tag: int) -> np.ndarray:
    """A float64 buffer of any length (probed first), waited for without spinning."""
    from mpi4py import MPI

    status = MPI.Status()
    poll(lambda: comm.Iprobe(source=source, tag=tag, status=status))
    buf = np.empty(status.Get_count(MPI.DOUBLE))
    comm.Recv(buf, source=source, tag=tag)
    return buf


def recv_object(comm, source: int, tag: int):
    """A pickled object, waited for without spinning: the coupler waits for the solver ranks' start-up
    (imports, the kernels loaded from their cache: a second or more), and a blocking receive would
    busy-poll a core through all of it (sod, profiled: 1.3 s of the coupler's 2.2 s)."""
    poll(lambda: comm.Iprobe(source=source, tag=tag))
    return comm.recv(source=source, tag=tag)


def share(comm, buf) -> np.ndarray:
    """The group root's buffer on every rank of the group (length first, then the data)."""
    if comm.size == 1:
        return buf
    n = np.array([0 if buf is None else len(buf)], dtype=np.int64)
    wait(comm.Ibcast(n, root=0))  # the other ranks wait while the root receives from the coupler
    if comm.rank != 0:
        buf = np.empty(int(n[0]))
    comm.Bcast(buf, root=0)
    return buf


def command(cmd: float, dt: float = 0.0, step: int = 0, time: float = 0.0, index: int = -1) -> np.ndarray:
    return np.array([cmd, dt, step, time, index, 0.0, 1.0], dtype=np.float64)
