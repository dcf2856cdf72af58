"""The numba cache directory is named by the content of every kernel source (solvers/kernel_cache.py):
numba keys an entry on its own file's stamp only, and a kernel keeps the machine code of the kernels
of other files it calls, so a changed EOS left the hydro kernels running the old one (seen: a
penetrator run that stopped at step 723 with fresh kernels went to step 953 on stale ones)."""
from __future__ import annotations

import os
import subprocess
import sys

from solvers.kernel_cache import source_digest
from tests.conftest import REPO


def _tree(tmp_path):
    for pkg in ("solvers", "orchestrator", "adapters"):
        (tmp_path / pkg).mkdir()
    (tmp_path / "solvers" / "eos.py").write_text("from numba import njit\n@njit(cache=True)\ndef p(r): return r\n")
    (tmp_path / "solvers" / "hydro.py").write_text("from numba import njit\nfrom solvers.eos import p\n")
    (tmp_path / "orchestrator" / "cli.py").write_text("print('no kernels here')\n")
    return tmp_path


def test_the_digest_follows_the_kernel_sources_only(tmp_path):
    base = _tree(tmp_path)
    d0 = source_digest(base)
    assert d0 == source_digest(base) and len(d0) == 16
    (base / "orchestrator" / "cli.py").write_text("print('still no kernels')\n")
    assert source_digest(base) == d0  # a file without numba: the same cache
    (base / "solvers" / "eos.py").write_text("from numba import njit\n@njit(cache=True)\ndef p(r): return 2 * r\n")
    d1 = source_digest(base)
    assert d1 != d0  # the callee changed: its callers' entries are in a new directory
    os.utime(base / "solvers" / "hydro.py", (0, 0))
    assert source_digest(base) == d1  # a stamp alone does not matter
    (base / "orchestrator" / "bench.py").write_text('"""times numba\'s set-up"""\nimport numpy\n')
    assert source_digest(base) == d1  # numba named in a text only: not a kernel source
    (base / "orchestrator" / "late.py").write_text("def f():\n    from numba import njit\n")
    assert source_digest(base) != d1  # numba imported inside a function: a kernel source


def test_every_process_of_the_tree_uses_the_directory_of_its_sources(tmp_path):
    """Set on import, before numba reads it; inherited by the children (the ranks of a job); a
    NUMBA_CACHE_DIR of the user's is the root."""
    code = "import orchestrator, os, numba.core.config as c; print(os.environ['NUMBA_CACHE_DIR'], c.CACHE_DIR)"
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "IMMERSE_NUMBA_CACHE_ROOT")}
    env["PYTHONPATH"] = str(REPO)
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "root")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout.split()
    expected = str(tmp_path / "root" / source_digest(REPO))
    assert out == [expected, expected]
    child = ("import os, subprocess, sys, orchestrator; print(subprocess.run([sys.executable, '-c', "
             "'import solvers, os; print(os.environ[\"NUMBA_CACHE_DIR\"])'], capture_output=True, text=True).stdout)")
    out = subprocess.run([sys.executable, "-c", child], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == [expected]


# Two processes save different signatures of the same functions at the same instants: each round a
# fresh index (function f<i>), process A saving key "a" with data "a<i>", B key "b" with "b<i>".
_SAVER = """
import sys, time
LOCK = sys.argv[3] == "lock"
if LOCK:
    import solvers  # noqa: F401  (installs the lock before numba's caching module is imported)
import numba.core.caching as caching
who, path, rounds, start = sys.argv[1], sys.argv[2], int(sys.argv[4]), float(sys.argv[5])
while time.time() < start:
    pass
for i in range(rounds):
    caching.IndexDataCacheFile(path, f"f{i}", "stamp").save(who, who + str(i))
print(getattr(caching.IndexDataCacheFile, "_immerse_locked", False))
"""


def _saved_pairs(tmp_path, lock: str, rounds: int = 1000) -> list[tuple[str, object]]:
    """(key, data) of every entry two racing processes left, read back through numba's own load."""
    import time

    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "IMMERSE_NUMBA_CACHE_ROOT")}
    env["PYTHONPATH"] = str(REPO)
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "root")
    start = time.time() + 3.0   # (both interpreters up and numba imported by then)
    procs = [subprocess.Popen([sys.executable, "-c", _SAVER, who, str(tmp_path), lock, str(rounds), str(start)],
                              env=env, stdout=subprocess.PIPE, text=True) for who in ("a", "b")]
    locked = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert all(p.returncode == 0 for p in procs) and locked == [str(lock == "lock")] * 2
    import numba.core.caching as caching

    pairs = []
    for i in range(rounds):
        f = caching.IndexDataCacheFile(str(tmp_path), f"f{i}", "stamp")
        pairs += [(f"{who}{i}", f.load(who)) for who in ("a", "b")]
    return pairs


def test_concurrent_saves_of_one_function_keep_each_signature_with_its_own_code(tmp_path):
    """With the lock every key reads back its own data. Without it (numba as shipped: run
    _saved_pairs(tmp_path, "nolock")) the same 1,000 rounds mixed them up, a key lost or read back
    with the other process's data (7, 86, 13 and 13 of 2,000 entries in four runs): in a kernel
    cache, the machine code of another signature."""
    pairs = _saved_pairs(tmp_path, "lock")
    wrong = [(want, got) for want, got in pairs if got != want]
    assert not wrong, f"{len(wrong)} of {len(pairs)} entries lost or swapped: {wrong[:5]}"


# Two kernels that call two different functions of one name (closures of one factory): compiled in
# two processes, then loaded together from the cache in a third.
_CLOSURES = """
import numpy as np
from numba import njit


def make(c):
    @njit
    def inner(x):  # (big enough not to be inlined into its caller)
        a = np.empty(int(x) + 50)
        for i in range(a.size):
            a[i] = np.sin(i * c) + c
        s = 0.0
        for i in range(a.size):
            s += a[i] * a[(i * 7) % a.size]
        return s
    return inner


inner_1, inner_2 = make(1.0), make(2.0)


@njit(cache=True)
def f(x):
    return inner_1(x) + inner_1(x + 1.0)


@njit(cache=True)
def g(x):
    return inner_2(x) + inner_2(x + 1.0)
"""
_CALLER = """
import sys
if sys.argv[1] == "random":
    import solvers  # noqa: F401  (installs the random uids before numba is imported)
import closures
print(*[getattr(closures, name)(1.0) for name in sys.argv[2]])
"""


def _cached_closures(tmp_path, ids: str) -> tuple[list[float], list[float]]:
    """f(1), g(1) compiled in one process each, then (f, g) loaded together in a third."""
    (tmp_path / "closures.py").write_text(_CLOSURES)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "IMMERSE_NUMBA_CACHE_ROOT")}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(tmp_path)])
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "root")

    def call(names):
        r = subprocess.run([sys.executable, "-c", _CALLER, ids, names], env=env, capture_output=True, text=True,
                           timeout=300, check=True)
        return [float(v) for v in r.stdout.split()]

    alone = call("f") + call("g")
    return alone, call("fg")


def test_kernels_compiled_in_two_processes_keep_their_own_callees_when_loaded_together(tmp_path):
    """With numba's uids counted from 1 in each process (run _cached_closures(tmp_path, "counted")),
    both helpers were named inner v2 and g loaded after f ran f's helper: (106.24, 106.24) against
    (106.24, 412.43). With random uids each keeps its own."""
    alone, together = _cached_closures(tmp_path, "random")
    assert alone[0] != alone[1] and together == alone, (alone, together)
