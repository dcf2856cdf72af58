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
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

PACKAGES = ("solvers", "orchestrator", "adapters")
ENV_ROOT = "IMMERSE_NUMBA_CACHE_ROOT"  # the root this module chose (the user's NUMBA_CACHE_DIR, if any)


def source_digest(base: Path) -> str:
    """sha256 of the paths and contents of every .py file of PACKAGES that mentions numba."""
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for path in sorted((base / pkg).rglob("*.py")):
            data = path.read_bytes()
            if b"numba" in data:
                h.update(path.relative_to(base).as_posix().encode() + b"\0" + data + b"\0")
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
    return d


if __name__ == "__main__":  # the directory, for the Makefile's warm-up stamp
    print(configure())
