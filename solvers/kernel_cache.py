"""Where numba keeps the compiled kernels: a directory named by the content of every source file
that uses numba, set as NUMBA_CACHE_DIR before numba is imported.

Numba's own cache (``njit(cache=True)``) is keyed by each source file's modification time and size,
and a kernel that calls a kernel of another file keeps the callee's machine code in its own cache
entry: a changed callee (an EOS in solvers/ale/eos.py, called by the hydro kernels of hydro.py)
leaves its callers' entries valid, and they go on running the old code. Keyed by the content of
all kernel sources together, any change starts a fresh cache (``make venv`` compiles it again),
and a checkout of an earlier version finds its own.

The root is ``.numba-cache`` beside the packages when writable (an editable install), else the
user's cache directory; a NUMBA_CACHE_DIR set by the user is taken as the root. The directory is
set in the environment, so the ranks of a job (children of the launcher) use the same one.

Numba's index of a function's entries (one per signature) is read, extended and written back
without a lock: two processes saving different signatures of one function at the same time both
took data file 1, and the index kept one's signature over the other's machine code. A kernel then
ran another signature's code on its arrays: the suite's ALE tests segfaulted, or lost 2e-5 of their
energy, on a cache that two pytest workers and their ranks had filled. Every save (and load) of an
index and its data file is therefore done under a file lock (lock_cache_index, installed as numba's
caching module is imported).

Numba names the machine code of every function it compiles by its qualified name, argument types and
a per-process counter (FunctionIdentity's uid). Two processes that each compiled a kernel calling
a different function of the same name (closures of one factory, numba's own generic helpers) gave
the helpers the same symbol; a process that then loaded both kernels from the cache linked the
second kernel to the first one's helper (LLVM merges the two weak definitions: numba issue 10486),
and a kernel compiled there after loading the first was saved with the wrong helper in it. Seen: a
coupled ALE step lost 2e-5 of its energy on a cache the suite had filled (orchestrator/coupling's
operator_arrays, 35 kB larger than its fresh compile). The uids are therefore drawn at random
(random_function_ids, installed as numba's bytecode module is imported): 63 bits, so two processes
give two functions the same one with a chance of about n^2 / 2^64.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.abc
import importlib.util
import os
import sys
from pathlib import Path

PACKAGES = ("solvers", "orchestrator", "adapters")
ENV_ROOT = "IMMERSE_NUMBA_CACHE_ROOT"  # the root this module chose (the user's NUMBA_CACHE_DIR, if any)


def _imports_numba(data: bytes) -> bool:
    """A line ``from numba ...`` or ``import numba ...`` (at any indentation). Each mention of numba
    is checked on its own line: a regular expression over every line of every file cost each process
    start ~2 ms more than the old substring test (this runs as every process of a job starts)."""
    i = data.find(b"numba")
    while i >= 0:
        head = data[data.rfind(b"\n", 0, i) + 1:i]
        if head.strip() in (b"from", b"import") and head[-1:] in (b" ", b"\t") \
                and data[i + 5:i + 6] in (b"", b" ", b"\t", b".", b"\n", b"\r", b",", b";"):
            return True
        i = data.find(b"numba", i + 5)
    return False


CACHE_MACHINERY = ("solvers/kernel_cache.py", "solvers/numba_cache.py")
"""Sources that change what the cache holds without importing numba at their top (this file patches
numba's caching and function ids; numba_cache.py drops stale entries)."""


def is_kernel_source(rel: str, data: bytes) -> bool:
    """A file whose change can change compiled machine code: one that imports numba (at any
    indentation: kernels compiled in a function too), or the cache machinery. A file that only names
    numba in its text (a docstring, a bench that times numba's set-up) is not one: editing it no
    longer starts a fresh cache and a 3-minute warm-up. (Numba freezes the globals a kernel reads
    into its machine code: a constant read that way lives in a kernel source; constants passed to a
    kernel as arguments, e.g. operators.MIN_AREA_FRACTION, may live anywhere.)"""
    return rel in CACHE_MACHINERY or _imports_numba(data)


def source_digest(base: Path) -> str:
    """sha256 of the paths and contents of every kernel source (is_kernel_source) of PACKAGES."""
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for path in sorted((base / pkg).rglob("*.py")):
            data = path.read_bytes()
            rel = path.relative_to(base).as_posix()
            if is_kernel_source(rel, data):
                h.update(rel.encode() + b"\0" + data + b"\0")
    return h.hexdigest()[:16]


def _writable(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
        return os.access(d, os.W_OK)
    except OSError:
        return False


def configure() -> Path:
    """Set NUMBA_CACHE_DIR to <root>/<digest> (once per process tree) and return it."""
    if os.environ.get(ENV_ROOT) is not None and os.environ.get("NUMBA_CACHE_DIR"):
        _patch_on_import()
        return Path(os.environ["NUMBA_CACHE_DIR"])
    base = Path(__file__).resolve().parent.parent
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        root = Path(root)
    else:
        root = base / ".numba-cache"
        if not _writable(root):
            root = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "immerse" / "numba"
    d = root / source_digest(base)
    os.environ[ENV_ROOT] = str(root)
    os.environ["NUMBA_CACHE_DIR"] = str(d)
    _patch_on_import()
    return d


def random_function_ids(bytecode) -> None:
    """Make numba's FunctionIdentity (module ``bytecode``: numba.core.bytecode) take its uids at
    random instead of counting from 1 in every process (the module docstring)."""
    import secrets

    cls = bytecode.FunctionIdentity
    if not getattr(cls, "_immerse_random_ids", False):
        cls._unique_ids = iter(lambda: secrets.randbits(63), None)
        cls._immerse_random_ids = True


def lock_cache_index(caching) -> None:
    """Make numba's IndexDataCacheFile (module ``caching``: numba.core.caching) save, load and flush
    under an flock of ``<index>.lock``: exclusive to save (read the index, pick a data file, write
    both), shared to load (never an index whose data file is not written yet)."""
    import fcntl

    cls = caching.IndexDataCacheFile
    if getattr(cls, "_immerse_locked", False):
        return
    save, load, flush = cls.save, cls.load, cls.flush

    @contextlib.contextmanager
    def locked(self, kind):
        try:
            fd = os.open(self._index_path + ".lock", os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:   # (no cache directory, or a read-only one: numba saves nothing there)
            yield
            return
        try:
            fcntl.flock(fd, kind)
            yield
        finally:
            os.close(fd)   # (releases the lock)

    def locked_save(self, key, data):
        with locked(self, fcntl.LOCK_EX):
            save(self, key, data)

    def locked_load(self, key):
        with locked(self, fcntl.LOCK_SH):
            return load(self, key)

    def locked_flush(self):
        with locked(self, fcntl.LOCK_EX):
            flush(self)

    cls.save, cls.load, cls.flush = locked_save, locked_load, locked_flush
    cls._immerse_locked = True


PATCHES = {"numba.core.caching": lock_cache_index, "numba.core.bytecode": random_function_ids}
"""What is changed in which numba module, as soon as it is imported."""


class _PatchWhenImported(importlib.abc.MetaPathFinder):
    """Finds the modules of PATCHES like the rest of the path, and patches each once executed."""

    def __init__(self, names):
        self.names = set(names)

    def find_spec(self, name, path, target=None):
        if name not in self.names:
            return None
        self.names.discard(name)
        if not self.names:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                PATCHES[name](module)

            spec.loader.exec_module = exec_module
        return spec


def _patch_on_import() -> None:
    waiting = []
    for name, patch in PATCHES.items():
        if name in sys.modules:
            patch(sys.modules[name])
        else:
            waiting.append(name)
    if waiting and not any(isinstance(f, _PatchWhenImported) for f in sys.meta_path):
        sys.meta_path.insert(0, _PatchWhenImported(waiting))


if __name__ == "__main__":  # the directory, for the Makefile's warm-up stamp
    print(configure())
