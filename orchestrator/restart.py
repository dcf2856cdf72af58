"""What `immerse run --restart FILE` accepts: a checkpoint manifest written by the coupler
(``OUT/checkpoints/checkpoint_<step>.h5``) of this very case (see :mod:`orchestrator.fingerprint`),
with the state file of every solver the case uses beside it. Anything else is refused with one line
naming --restart before anything is created or launched.

The manifest's attributes written by :meth:`orchestrator.coupler.Coupler.checkpoint`:
``format`` (FORMAT), ``case_name``, ``case_fingerprint``, ``case_identity`` (the canonical JSON the
fingerprint hashes, so a refusal can name the key that differs), ``ranks_<role>``, ``file_<role>``
(the solver's state, relative to the manifest), and the coupler's own state (t, step, out_index, ...).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import math
import os

FORMAT = "immerse-checkpoint-1"
MAX_IDENTITY_BYTES = 1 << 20
"""The case identity a manifest carries (canonical JSON of the case: ~10 KB) may not be longer."""
MAX_RANKS = 1 << 20
EXPECTED = "expected a checkpoint manifest OUT/checkpoints/checkpoint_<step>.h5"
COUPLER_STATE = ("t", "step", "out_index", "dt_min", "dt_max")


class RestartError(ValueError):
    """One line: ``--restart = '<path>': <why>``."""

    def __init__(self, path, why: str):
        super().__init__(f"--restart = {str(path)!r}: {why}")


@dataclass
class Checkpoint:
    path: Path  # resolved
    step: int
    t: float
    out_index: int
    case_name: str
    fingerprint: str
    identity: dict
    ranks: dict[str, int]
    files: dict[str, Path]  # role -> solver state file


def _text(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _what_else(h) -> str:
    """Name the kinds of immerse files that are not a checkpoint manifest."""
    a = h.attrs
    if _text(a.get("layout", "")).startswith("immerse-output"):
        return "is a results index (results.h5), not a checkpoint; " + EXPECTED
    if "role" in a and "index" in a:
        return "is an output step file, not a checkpoint; " + EXPECTED
    if "cells" in h and "cell_type" in a:
        return "is an output mesh file, not a checkpoint; " + EXPECTED
    if "ranks" in a and "step" in a:
        return "is the state of one solver group; pass the checkpoint_<step>.h5 that names it"
    if all(k in a for k in COUPLER_STATE) and "case_fingerprint" not in a:
        return ("is a checkpoint without a case fingerprint (written by an older immerse): it cannot "
                "be matched to this case")
    return "is an HDF5 file but not an immerse checkpoint; " + EXPECTED


def read_checkpoint(path) -> Checkpoint:
    """Read and check a checkpoint manifest (not the case): RestartError if it is not one."""
    import h5py

    p = Path(path)
    if not p.exists():
        raise RestartError(path, "no such file; " + EXPECTED)
    if p.is_dir():
        raise RestartError(path, "is a directory; " + EXPECTED)
    if not p.is_file():
        raise RestartError(path, "not a regular file; " + EXPECTED)
    try:
        with open(p, "rb"):
            pass
    except OSError as e:
        raise RestartError(path, f"cannot read: {e.strerror or e}") from None
    if not h5py.is_hdf5(p):
        raise RestartError(path, "not an HDF5 file; " + EXPECTED)
    try:
        with h5py.File(p, "r") as h:
            a = h.attrs
            if _text(a.get("format", "")) != FORMAT:
                raise RestartError(path, _what_else(h))
            missing = [k for k in COUPLER_STATE if k not in a]
            if missing:
                raise RestartError(path, f"damaged checkpoint: no attribute {missing[0]!r}")
            files = {k[5:]: _state_file(path, p, k, a[k]) for k in a if k.startswith("file_")}
            ranks = {k[6:]: _whole(path, k, a[k], 1, MAX_RANKS) for k in a if k.startswith("ranks_")}
            text = _text(a["case_identity"])
            if len(text) > MAX_IDENTITY_BYTES:
                raise RestartError(path, f"damaged checkpoint: case_identity of {len(text)} characters "
                                         f"(at most {MAX_IDENTITY_BYTES})")
            identity = json.loads(text)
            if not isinstance(identity, dict):
                raise RestartError(path, "damaged checkpoint: case_identity is not a table")
            ck = Checkpoint(path=p.resolve(), step=_whole(path, "step", a["step"], 0, 10**15),
                            t=_time(path, "t", a["t"]),
                            out_index=_whole(path, "out_index", a["out_index"], 0, 10**9),
                            case_name=_text(a["case_name"]), fingerprint=_text(a["case_fingerprint"]),
                            identity=identity, ranks=ranks, files=files)
            for k in ("dt_min", "dt_max"):
                v = float(_py(a[k]))
                if math.isnan(v) or v < 0.0:
                    raise RestartError(path, f"damaged checkpoint: {k} = {v!r}, allowed: a step >= 0 s")
    except RestartError:
        raise
    except RecursionError:
        raise RestartError(path, "damaged checkpoint: case_identity nested too deeply") from None
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise RestartError(path, f"unreadable checkpoint ({type(e).__name__}: {e})".replace("\n", " ")) from None
    return ck


def _py(v):
    """An HDF5 attribute as a Python value (numpy scalars print as np.int64(...) in messages)."""
    return v.item() if hasattr(v, "item") else v


def _whole(path, key: str, v, lo: int, hi: int) -> int:
    """An integer attribute within [lo, hi] (a float that is a whole number passes)."""
    v = _py(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise RestartError(path, f"damaged checkpoint: {key} = {v!r}, allowed: an integer") from None
    if not (math.isfinite(f) and f == int(f) and lo <= f <= hi):
        raise RestartError(path, f"damaged checkpoint: {key} = {v!r}, allowed: an integer from {lo} to {hi}")
    return int(f)


def _time(path, key: str, v) -> float:
    v = _py(v)
    f = float(v)
    if not (math.isfinite(f) and f >= 0.0):
        raise RestartError(path, f"damaged checkpoint: {key} = {v!r}, allowed: a finite time >= 0 s")
    return f


def _state_file(path, p: Path, key: str, v) -> Path:
    """A solver's state file the manifest names: a relative path of plain names (no '..', not
    absolute) that resolves, links followed, to a regular file inside the manifest's folder."""
    rel = _text(v)
    parts = rel.split("/")
    if not rel or rel.startswith("/") or "\\" in rel or any(q in ("", ".", "..") for q in parts):
        raise RestartError(path, f"damaged checkpoint: {key} = {rel!r}, allowed: a path inside the "
                                 "checkpoint's folder")
    f = p.parent / rel
    root = p.parent.resolve()
    try:
        real = f.resolve(strict=True)
        real.relative_to(root)
    except (OSError, ValueError):
        if not os.path.lexists(f):
            raise RestartError(path, f"the {key[5:]} state it names is missing: {f}") from None
        raise RestartError(path, f"damaged checkpoint: {key} = {rel!r} leads outside the checkpoint's "
                                 "folder") from None
    if not real.is_file():
        raise RestartError(path, f"damaged checkpoint: {key} = {rel!r} is not a regular file")
    return f


def _stored_bytes(path, f: Path) -> int:
    """Bytes the datasets of an HDF5 file declare (what reading them would allocate)."""
    import h5py

    total = 0

    def add(name, obj):
        nonlocal total
        if isinstance(obj, h5py.Dataset):
            total += int(obj.size) * obj.dtype.itemsize

    try:
        with h5py.File(f, "r") as h:
            h.visititems(add)
    except (OSError, ValueError, RecursionError) as e:
        raise RestartError(path, f"unreadable state file {f.name} ({type(e).__name__})") from None
    return total


def _short(v) -> str:
    text = json.dumps(v) if not isinstance(v, str) else v
    return text if len(text) <= 60 else text[:57] + "..."


def check_restart(path, case: dict) -> Checkpoint:
    """The checkpoint at ``path`` if it belongs to ``case`` (same fingerprint and solvers), else
    RestartError naming the first key that differs. Any rank counts are accepted: both solvers
    restart on another rank count (ALE bitwise, Lagrangian to round-off)."""
    from orchestrator.case import solvers_used
    from orchestrator.fingerprint import case_fingerprint, case_identity, first_difference

    ck = read_checkpoint(path)
    if ck.fingerprint != case_fingerprint(case):
        here = case_identity(case)
        d = first_difference(ck.identity, here)
        where = (f"{d[0]} = {_short(d[1])} in the checkpoint, {_short(d[2])} in this case" if d
                 else "fingerprints differ")
        raise RestartError(path, f"checkpoint of another case ({ck.case_name!r}): {where}; only "
                                 "end_time, max_steps, output/checkpoint intervals, "
                                 "diagnostics_every, ranks and [check] may change on restart")
    roles = solvers_used(case)
    if sorted(ck.files) != sorted(roles):
        raise RestartError(path, f"holds solvers {', '.join(sorted(ck.files)) or '(none)'}, the case "
                                 f"uses {', '.join(roles)}")
    # what reading the state would allocate, against the machine (a dataset may declare 8 TiB)
    from orchestrator.resources import format_bytes, machine_memory

    have = machine_memory()
    for f in [ck.path, *ck.files.values()]:
        n = _stored_bytes(path, f)
        if n > have:
            raise RestartError(path, f"damaged checkpoint: {f.name} declares {format_bytes(n)} of data, "
                                     f"more than this machine's {format_bytes(have)}")
    return ck
