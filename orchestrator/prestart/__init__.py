"""Warm process start: run `python -m MODULE` in a process forked from one that has already imported
numpy, scipy, h5py, numba and our modules and loaded every cached solver kernel.

Every process of a job (the launcher, the coupler, each solver rank) otherwise spends most of its
first second importing and loading kernels from numba's cache: a two-step coupled job used 3.7 s of
CPU before its first step, against 0.5 s for its steps. A suite of ~330 jobs (and ~700 refused
inputs) pays that ~1,000 times. `server.py` pays it once and forks; `stub.py` is what mpiexec or a
test starts in place of `python -m MODULE`: it hands over its descriptors, environment, directory and
arguments, forwards signals and returns the forked process's exit status, or becomes the plain
command when no server answers.

The server is named by IMMERSE_PRESTART (a Unix socket path); unset, empty or 0, nothing changes. The test suite
starts one per pytest worker (tests/conftest.py). The forked process runs the same code as the plain
command (the server refuses a request whose source files, kernel digest or import-time environment
differ from what it loaded), so the choice never changes a result: tests/orchestrator/prestart
compares a coupled job's summary both ways.
"""
from __future__ import annotations

import sys
from pathlib import Path

from orchestrator.prestart.stub import ENV, server_path

STUB = Path(__file__).resolve().with_name("stub.py")


def command(module: str, args: list[str], python: str | None = None) -> list[str]:
    """The command line of `python -m MODULE ARGS...`: through the stub when a server is named in the
    environment (IMMERSE_PRESTART), else the plain one."""
    py = python or sys.executable
    if server_path() is not None:
        return [py, "-S", str(STUB), module, *args]
    return [py, "-m", module, *args]


__all__ = ["ENV", "STUB", "command"]
