"""What every bench shares: the registry of benches by name (``immerse bench NAME``), the machine
record written beside their results, and the helper that times a bench on several ranks in a job of
its own. Below every bench module of the package (they import this, the package's __init__ imports
them to register them), so that the benches form no import circle."""
from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

BENCHES = {}
"""name -> function(out: Path, quick: bool) -> Path of its JSON."""


def bench(name):
    """Register a bench function under ``name``."""
    def deco(fn):
        BENCHES[name] = fn
        return fn

    return deco


def machine() -> dict:
    return {"host": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "processor": platform.processor() or platform.machine()}


def cli_run(case_dir: Path, out: Path, **kw) -> subprocess.CompletedProcess:
    """`immerse run CASE_DIR --out OUT --replace` in a process of its own, as a user starts it (the
    launcher's start-up included, never from a warm process server: orchestrator/prestart); ``kw``
    goes to subprocess.run (env, cwd)."""
    from orchestrator.prestart import ENV

    env = {k: v for k, v in kw.pop("env", os.environ).items() if k != ENV}
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", "run", str(case_dir), "--out", str(out),
                           "--replace"], capture_output=True, text=True, env=env, **kw)


def run_worker(module: str, ranks: int, *args) -> str:
    """The last line `mpiexec -n ranks python -m module worker args...` prints (rank 0's result; one
    thread a rank): a bench's timing on several ranks, in a job of its own."""
    mpiexec = Path(sys.executable).parent / "mpiexec"
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    r = subprocess.run([str(mpiexec), "-n", str(ranks), sys.executable, "-m", module, "worker",
                        *(str(a) for a in args)], capture_output=True, text=True, env=env, check=True)
    return r.stdout.strip().splitlines()[-1]
