"""The local engine: the campaign's runs as child processes on this machine, as many at once as
the cores allow.

A run takes as many cores as its solvers have ranks (the coupler, mostly waiting, is not counted),
at most all of them: runs start in campaign order while their cores are free, and a run larger than
the machine runs alone. Each run is ``python -m orchestrator.campaign.task`` (which runs ``immerse run``); every
child dies with the campaign (SIGTERM by the kernel, even when the campaign is killed by SIGKILL),
so no job outlives it and an unfinished run leaves no result: the next ``immerse campaign`` runs it
again.
"""
from __future__ import annotations

import os
import signal
import subprocess
import time
from collections import deque

from orchestrator import prestart


def run_weight(run, cores: int) -> int:
    """Cores a run takes: its solvers' ranks (at most all cores). The coupler rank is not counted: it
    waits on the solvers most of the step (measured 28 % of a core in a coupled 1-D run, less
    uncoupled), so two 1-rank runs share two cores."""
    return max(1, min(cores, sum(run.ranks.values()) if run.ranks else cores))


class _Stop(Exception):
    pass


def run_local(pending: list, timeout: float | None, cores: int, on_done) -> None:
    """Run ``pending`` [(RunSpec, run directory)]; ``on_done(run, directory)`` after each. SIGINT /
    SIGTERM end the running children (their runs stay not done) and re-raise as KeyboardInterrupt."""
    from orchestrator.launch import dies_with_parent

    queue = deque(pending)
    running: dict[subprocess.Popen, tuple] = {}
    free = cores

    def stop(signum, frame):
        raise _Stop(signum)

    old = signal.signal(signal.SIGTERM, stop)
    try:
        while queue or running:
            while queue:
                run, d = queue[0]
                w = run_weight(run, cores)
                if running and w > free:
                    break
                queue.popleft()
                cmd = prestart.command("orchestrator.campaign.task", [str(d), "--engine", "local"])
                if timeout is not None:
                    cmd += ["--timeout", str(timeout)]
                proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                                        preexec_fn=dies_with_parent(signal.SIGTERM))
                running[proc] = (run, d, w)
                free -= w
            time.sleep(0.05)
            for proc in [p for p in running if p.poll() is not None]:
                run, d, w = running.pop(proc)
                free += w
                on_done(run, d)
    except (KeyboardInterrupt, _Stop) as e:
        for proc in running:
            proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 30
        for proc in running:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
        signum = e.args[0] if isinstance(e, _Stop) else signal.SIGINT
        raise KeyboardInterrupt(int(signum)) from None
    finally:
        signal.signal(signal.SIGTERM, old)


def cores_here() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1

