"""Guard of numba's on-disk cache shared by the solvers' kernel modules."""
from __future__ import annotations


def flush_stale_cache(dispatchers, dependencies, stamp_name: str) -> None:
    """Drop the numba disk cache of ``dispatchers`` when one of the source files they compile in
    (``dependencies``: module files of other njit functions they call) changed.

    numba keys a cached function on its own source file only; functions of other modules are
    compiled *into* it, so an edit there would silently reuse stale machine code.  A digest of the
    dependencies is stored next to the cache index; on mismatch every index is flushed.
    """
    import hashlib
    import os

    try:
        h = hashlib.sha256()
        for path in dependencies:
            with open(path, "rb") as fh:
                h.update(fh.read())
        digest = h.hexdigest()
        stamp = os.path.join(dispatchers[0]._cache.cache_path, stamp_name)
        try:
            with open(stamp) as fh:
                if fh.read().strip() == digest:
                    return
        except OSError:
            pass
        for d in dispatchers:
            d._cache.flush()
        tmp = f"{stamp}.{os.getpid()}.tmp"
        with open(tmp, "w") as fh:
            fh.write(digest)
        os.replace(tmp, stamp)
    except Exception:  # cache handling must never break the solver (read-only trees etc.)
        pass
