"""Signals to `immerse run`: SIGTERM or SIGINT ends the whole job (mpiexec, hydra's proxies, the
coupler, every solver rank) within seconds, as the process table shows; every completed output step
stays readable and indexed; the launcher exits 143 / 130 with one line. When mpiexec itself is
killed, the message says so."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import h5py
import pytest

from tests.conftest import REPO, immerse
from tests.orchestrator.test_faults import _ale_case, _pids, _spinning_case, assert_ended_record

# These tests look at the job's processes in /proc (below the launcher in the process table, their
# environment blocks): their processes start as plain `python -m` ones, not from the warm server
pytestmark = pytest.mark.usefixtures("plain")

CASES = {
    # a block spinning for 10^8 steps on 2 Lagrangian ranks; outputs every 0.05 s
    "lagrange": (lambda t: _spinning_case(t, **{"max_steps = 10000": "max_steps = 100000000",
                                                "output_interval = 0.2": "output_interval = 0.05"}),
                 "lagrange=2"),
    # the 2-D Sedov blast for 100 s on 2 ALE ranks; outputs every 0.01 s
    "ale": (lambda t: _ale_case(t, "sedov_2d", **{"end_time = 1.0": "end_time = 100.0",
                                                  "output_interval = 0.25": "output_interval = 0.01",
                                                  "cells = [120, 120]": "cells = [60, 60]"}),
            "ale=2"),
}


def _stat(pid):
    """(state, start time in ticks) of a process, None once it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return fields[0], int(fields[19])
    except (OSError, IndexError, ValueError):
        return None


def process_tree(root):
    """{pid: start time} of every process below ``root`` (hydra's proxies and the ranks start
    sessions of their own, so the parent links are what ties them to the launcher)."""
    children = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(name))
    found, todo = Job(), [root]
    while todo:
        for c in children.get(todo.pop(), ()):
            st = _stat(c)
            if st and c not in found:
                found[c] = st[1]
                todo.append(c)
    found.sessions = {s for p in found if (s := _session(p)) and s in found}  # sessions they lead
    return found


def _session(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[3])
    except (OSError, IndexError, ValueError):
        return None


def survivors(procs):
    """Processes of ``procs`` ({pid: start time}) still running (a zombie has ended), and any running
    process in one of their sessions (mpiexec's, each proxy's and each rank's own: started after the
    snapshot, it would be part of the job too)."""
    alive = []
    for pid, start in procs.items():
        st = _stat(pid)
        if st and st[1] == start and st[0] not in "ZX":
            alive.append(pid)
    sessions = procs.sessions if hasattr(procs, "sessions") else set()
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) not in alive and _session(int(name)) in sessions:
            st = _stat(int(name))
            if st and st[0] not in "ZX":
                alive.append(int(name))
    return alive


class Job(dict):
    """{pid: start time} of the job's processes, with the sessions they started."""
    sessions: set


def kill_survivors(job):
    """After a failed assertion: no runaway job left on the machine."""
    for pid in survivors(job):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _cmdline(pid):
    try:
        return open(f"/proc/{pid}/cmdline", "rb").read().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def start_run(case, out, ranks, n_ranks, outputs=3, ignore=()):
    """Launch `immerse run` (with the signals ``ignore`` ignored, as `nohup` does); return (process,
    {pid: start} of the job) once ``outputs`` output steps exist and every rank has recorded itself."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("IMMERSE_TTY", None)

    def ignoring():
        for s in ignore:
            signal.signal(s, signal.SIG_IGN)

    proc = subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "run", str(case), "--out", str(out),
                             "--ranks", ranks], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, preexec_fn=ignoring if ignore else None)
    deadline = time.time() + 180
    while time.time() < deadline:
        steps = list((out / "steps").glob("*_[0-9]*.h5")) if (out / "steps").is_dir() else []
        if len(steps) >= outputs and len(_pids(out)) == 1 + n_ranks:
            break
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    else:
        proc.kill()
        raise AssertionError("the run did not produce output in time")
    job = process_tree(proc.pid)
    assert len(job.sessions) >= 2 + n_ranks  # mpiexec's, the proxy's, each rank's: process groups miss them
    recorded = {pid: _stat(pid)[1] for pid in _pids(out).values() if _stat(pid)}
    assert set(recorded) <= set(job), "every recorded rank is below the launcher"
    assert any("mpiexec" in _cmdline(p) for p in job) and any("hydra_pmi_proxy" in _cmdline(p) for p in job)
    return proc, job


def assert_outputs_readable(out, role):
    """Every step file on disk is indexed in results.h5 and readable through it."""
    on_disk = sorted(int(p.stem.rsplit("_", 1)[1]) for p in (out / "steps").glob(f"{role}_[0-9]*.h5"))
    with h5py.File(out / "results.h5", "r") as h:
        indices = list(h[f"{role}/indices"][...])
        times = list(h[f"{role}/times"][...])
        for i in indices:
            assert h[f"{role}/{i:06d}/points"].shape[1] == 3
    assert indices == on_disk and len(indices) >= 3
    return times


@pytest.mark.parametrize("role, sig", [
    ("lagrange", signal.SIGTERM), ("lagrange", signal.SIGINT), ("ale", signal.SIGTERM), ("ale", signal.SIGINT),
    ("lagrange", signal.SIGHUP),  # the terminal closed
], ids=lambda v: v.name if isinstance(v, signal.Signals) else v)
def test_signal_ends_the_whole_job(tmp_path, role, sig):
    make_case, ranks = CASES[role]
    case, out = make_case(tmp_path), tmp_path / "out"
    proc, job = start_run(case, out, ranks, 2)
    try:
        t_sig = time.monotonic()
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
        elapsed = time.monotonic() - t_sig
    finally:
        if proc.poll() is None:
            proc.kill()
        left = survivors(job)
        kill_survivors(job)
    print(f"{role} {sig.name}: launcher ended {elapsed:.2f} s after the signal; job of {len(job)} processes")
    assert left == [], [(p, _cmdline(p)) for p in left]
    assert proc.returncode == 128 + sig, (proc.returncode, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    m = re.fullmatch(rf"immerse: interrupted by {sig.name} at step (\d+), t = (\S+) s; outputs up to "
                     rf"t = (\S+) s in {re.escape(str(out))}", lines[0])
    assert m, lines[0]
    assert elapsed < 15.0  # measured ~1-2 s; margin for a loaded machine
    times = assert_outputs_readable(out, role)
    assert float(m[3]) == pytest.approx(times[-1], rel=1e-6)
    assert float(m[2]) >= float(m[3])
    assert lines[0] in (out / "log.txt").read_text()
    # the history up to the signal and where it stopped (issue 40: it was lost)
    s = assert_ended_record(out, "interrupted", f"interrupted by {sig.name}")
    assert 0 < s["steps"] <= int(m[1])   # the last recorded (diagnostics_every) before the signal's step


def test_nohup_keeps_running(tmp_path):
    """Started with SIGHUP ignored (`nohup immerse run ...`): a hang-up does not stop the run."""
    make_case, ranks = CASES["lagrange"]
    case, out = make_case(tmp_path), tmp_path / "out"
    proc, job = start_run(case, out, ranks, 2, ignore=(signal.SIGHUP,))
    try:
        proc.send_signal(signal.SIGHUP)
        n = len(list((out / "steps").glob("lagrange_[0-9]*.h5")))
        deadline = time.monotonic() + 60
        while len(list((out / "steps").glob("lagrange_[0-9]*.h5"))) < n + 2 and time.monotonic() < deadline:
            assert proc.poll() is None
            time.sleep(0.1)
        assert proc.poll() is None and set(survivors(job)) == set(job)  # all of the job still runs
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
        assert proc.returncode == 143
    finally:
        if proc.poll() is None:
            proc.kill()
        left = survivors(job)
        kill_survivors(job)
    assert left == []


def test_mpiexec_killed(tmp_path):
    """SIGKILL of mpiexec: the message names mpiexec (it named the coupler), the ranks are gone."""
    make_case, ranks = CASES["lagrange"]
    case, out = make_case(tmp_path), tmp_path / "out"
    proc, job = start_run(case, out, ranks, 2)
    try:
        mpiexec = [p for p in job if _cmdline(p).split(" ", 1)[0].endswith("mpiexec")]
        assert len(mpiexec) == 1
        t_kill = time.monotonic()
        os.kill(mpiexec[0], signal.SIGKILL)
        _, stderr = proc.communicate(timeout=30)
        elapsed = time.monotonic() - t_kill
    finally:
        if proc.poll() is None:
            proc.kill()
        left = survivors(job)
        kill_survivors(job)
    print(f"mpiexec SIGKILL: launcher ended {elapsed:.2f} s after")
    assert left == []
    assert proc.returncode not in (0, 2)
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"immerse: run failed: mpiexec (pid {mpiexec[0]}) died, killed by SIGKILL"), stderr
    assert "coupler rank" not in stderr
    assert elapsed < 30
    assert_outputs_readable(out, "lagrange")


def test_launcher_killed(tmp_path):
    """Even SIGKILL of the launcher (no handler can run) takes the job down: mpiexec dies with it
    (parent-death signal) and its proxies end the ranks."""
    make_case, ranks = CASES["ale"]
    case, out = make_case(tmp_path), tmp_path / "out"
    proc, job = start_run(case, out, ranks, 2)
    t_kill = time.monotonic()
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 30
    while survivors(job) and time.monotonic() < deadline:
        time.sleep(0.05)
    print(f"launcher SIGKILL: job gone {time.monotonic() - t_kill:.2f} s after")
    left = survivors(job)
    kill_survivors(job)
    assert left == [], left


def _environ(pid):
    with open(f"/proc/{pid}/environ", "rb") as f:
        return dict(v.split(b"=", 1) for v in f.read().split(b"\0") if b"=" in v)


def test_waiting_ranks_sleep_only_when_the_processes_outnumber_the_cores(tmp_path, monkeypatch):
    """MPICH's heavy yield (a waiting rank sleeps after its idle polls) is set for the job's ranks when
    coupler + ranks exceed the launcher's cores, never otherwise; so is our own waits' rule (no spin
    before they sleep, adapters.protocol.SPIN_ENV), unless the caller set it (make test does)."""
    from adapters.protocol import SPIN_ENV
    from orchestrator import launch, resources

    monkeypatch.delenv(SPIN_ENV, raising=False)
    make_case, ranks = CASES["lagrange"]
    case, out = make_case(tmp_path), tmp_path / "out"
    proc, job = start_run(case, out, ranks, 2)
    try:
        envs = [_environ(pid) for pid in _pids(out).values()]
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        kill_survivors(job)
    want = b"1" if 3 > resources.machine_cores() else None
    assert len(envs) == 3 and all(e.get(b"MPIR_CVAR_ENABLE_HEAVY_YIELD") == want for e in envs), want
    assert all(e.get(SPIN_ENV.encode()) == (b"0" if want else None) for e in envs)

    from orchestrator.case import load_case

    loaded = load_case(case)
    for cores, expected in ((2, True), (3, False), (64, False)):
        monkeypatch.setattr(resources, "machine_cores", lambda: cores)
        assert launch.oversubscribed(loaded, {"lagrange": 2}) is expected, cores
    monkeypatch.setattr(resources, "machine_cores", lambda: 2)
    assert launch.oversubscribed(loaded, {"lagrange": 1, "ale": 7}) is False  # ale is not in the case


def test_report_starts_its_own_line_after_a_half_forwarded_one(tmp_path, monkeypatch, capfd):
    """mpiexec ended while forwarding a rank's output leaves half a line on stderr; the launcher's
    report still begins a line of its own (a job standing in for mpiexec writes half a line and a
    coupler error report, then hangs until the launcher ends it)."""
    from orchestrator import launch
    from orchestrator.case import load_case, ranks_for

    case = load_case(_ale_case(tmp_path, "sod"))
    out = tmp_path / "out"
    script = (f"printf 'Traceback (most recent call last):\\n  File \"x\", line' >&2; "
              f"mkdir -p '{out}/.run'; echo 'coupler rank 0: RuntimeError: boom' > '{out}/.run/error_coupler_0.txt'; "
              "exec sleep 60")
    monkeypatch.setattr(launch, "build_command", lambda *a, **k: ["sh", "-c", script])
    rc = launch.run_job(case, out, ranks_for(case, {}))
    err = capfd.readouterr().err
    assert rc != 0
    assert "\nimmerse: run failed: coupler rank 0: RuntimeError: boom\n" in err, err
    assert '  File "x", line\n' in err, err


def test_a_silent_death_is_named_first_even_when_its_peers_report_raced_it():
    """A rank killed by a signal writes no report; its halo neighbour's failed MPI call does, and
    may do so before the launcher looks (CI saw ale rank 0's report win over ale rank 1's SIGKILL).
    The silent rank found dead at the first wake-up is still named as the cause; a real error
    report (not a failed MPI call) keeps the blame."""
    from adapters.protocol import GONE, MPI_ERROR
    from orchestrator.launch import silent_deaths

    mpi_report = f"ale rank 0: {MPI_ERROR}: Exception: See the MPI_ERROR field in MPI_Status"
    # the death was seen before any report
    assert silent_deaths([mpi_report], ["ale rank 1"], ["ale rank 1"]) == ["ale rank 1"]
    # the report raced the death: only failed MPI calls were reported
    assert silent_deaths([mpi_report], [], ["ale rank 1"]) == ["ale rank 1"]
    # the reporting rank itself is never the silent one
    assert silent_deaths([mpi_report], [], ["ale rank 0", "ale rank 1"]) == ["ale rank 1"]
    # the launcher woke after MPI's abort took the coupler down too (seen in CI): the report names
    # who was gone when it was written
    gone = f"ale rank 0: {MPI_ERROR} [{GONE}ale rank 1]: Exception: See the MPI_ERROR field"
    assert silent_deaths([gone], [], ["coupler rank 0", "ale rank 1"]) == ["ale rank 1"]
    # a physical failure was reported: the ranks Abort took down after it are not its cause
    physical = "ale rank 0: RuntimeError: zone 17 inverted at step 40, t=1e-3"
    assert silent_deaths([physical], [], ["ale rank 1"]) == []
    assert silent_deaths([physical, mpi_report], [], ["ale rank 1"]) == []


def test_a_failed_mpi_call_is_reported_as_one(tmp_path, monkeypatch):
    """The fault hook marks a rank's failed MPI call (mpi4py.MPI.Exception) so the launcher can
    tell a neighbour's death seen from this side from an error of the rank's own."""
    from mpi4py import MPI

    from adapters import protocol

    aborted = []
    monkeypatch.setattr(protocol, "_abort", lambda: aborted.append(1))
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)  # restored after the test
    protocol.install_fault_handler(tmp_path, "ale", 0)
    report = tmp_path / ".run" / "error_ale_0.txt"
    sys.excepthook(MPI.Exception, MPI.Exception(MPI.ERR_OTHER), None)
    assert report.read_text().startswith(f"ale rank 0: {protocol.MPI_ERROR}: Exception: "), report.read_text()
    # with the job's pid records: a process that has ended is named in the report, a live one not
    pids = tmp_path / ".run" / "pids"
    pids.mkdir()
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    (pids / str(done.pid)).write_text("ale 1\n")
    (pids / str(os.getpid())).write_text("ale 0\n")
    sys.excepthook(MPI.Exception, MPI.Exception(MPI.ERR_OTHER), None)
    assert report.read_text().startswith(f"ale rank 0: {protocol.MPI_ERROR} [{protocol.GONE}ale rank 1]: "), \
        report.read_text()
    sys.excepthook(RuntimeError, RuntimeError("zone 3 inverted"), None)
    assert report.read_text() == "ale rank 0: RuntimeError: zone 3 inverted\n"
    assert aborted == [1, 1, 1]


@pytest.mark.parametrize("value", ["abc", "-1", "nan", "inf", "1e300"])
def test_a_bad_wait_spin_is_refused_before_anything_starts(tmp_path, monkeypatch, value):
    """IMMERSE_WAIT_SPIN_S (adapters.protocol.SPIN_ENV) that is not a number of seconds >= 0: check
    and run stop with one line naming it and its value, exit 2, no output directory (the ranks used
    to fall back to 200e-6 s without a word)."""
    from adapters.protocol import SPIN_ENV

    monkeypatch.setenv(SPIN_ENV, value)
    out = tmp_path / "out"
    sod = REPO / "cases" / "sod"
    for args in (("check", sod), ("run", sod, "--out", out)):
        r = immerse(*args)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert lines[0] == f"immerse: {SPIN_ENV} = {value!r}: must be a number of seconds from 0 to 1 (unset: 200e-6)"
        assert not out.exists()
