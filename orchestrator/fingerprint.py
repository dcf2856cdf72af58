"""The fingerprint of a case: what a checkpoint and an output directory record to know which case
they belong to.

It is the SHA-256 of a canonical JSON form of the validated, normalised case
(:func:`orchestrator.case.load_case`) in which every file the case reads (mesh files) is replaced
by the SHA-256 of its bytes, so a case whose mesh file was edited is another case, while the same
case copied or moved elsewhere (another case directory, the mesh under another name) is the same.

Left out, because a restart may legitimately change them (as LS-DYNA's and ALE3D's restarts let
an analyst extend a run): where the case lives and what it is called (``name``, ``case_dir``), the
hash of its file's bytes (``case_sha256``: an edited comment is not another case), how
far and how often the run goes and writes (``run.end_time``, ``run.max_steps``,
``run.output_interval``, ``run.checkpoint_interval``, ``run.diagnostics_every``), the rank counts
(``ranks``: both solvers restart on another rank count) and the case's own check (``check``: it
only reads the results). Everything else (dimension, dt_scale, materials, meshes, initial state,
boundaries, solver options) makes another case.  Keys that start with ``_`` hold what the checks
derived from the case's files (a mesh file's bounding box): left out, the files' digests stand for
them.
"""
from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

FORMAT = "immerse-case-1"

# keys that may change between a checkpoint and its restart (paths into the normalised case)
RESTART_MAY_CHANGE = (
    ("name",), ("case_dir",), ("case_sha256",), ("ranks",), ("check",),
    ("run", "end_time"), ("run", "max_steps"), ("run", "output_interval"),
    ("run", "checkpoint_interval"), ("run", "diagnostics_every"), ("run", "dt_min"),
)

_CHUNK = 1 << 20


def file_digest(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def _canonical(value: Any) -> Any:
    """Plain JSON values; a Path (a file the case reads) becomes the digest of its bytes."""
    if isinstance(value, Path):
        return {"file_sha256": file_digest(value)} if value.is_file() else {"missing_file": value.name}
    if isinstance(value, Mapping):  # ("_" keys: what the checks derived from the files: their digests count)
        return {str(k): _canonical(v) for k, v in value.items() if not str(k).startswith("_")}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, float):
        return repr(value) if value != value or value in (float("inf"), float("-inf")) else value
    return value


def case_identity(case: Mapping) -> dict:
    """The part of the normalised case that makes it this case (plain JSON, files as digests)."""
    ident = _canonical(case)
    for path in RESTART_MAY_CHANGE:
        d = ident
        for k in path[:-1]:
            d = d.get(k, {}) if isinstance(d, dict) else {}
        if isinstance(d, dict):
            d.pop(path[-1], None)
    return ident


def canonical_json(identity: Mapping) -> str:
    return json.dumps(identity, sort_keys=True, separators=(",", ":"), allow_nan=False)


def fingerprint_of(canonical: str) -> str:
    """The fingerprint of a case identity's canonical JSON."""
    return "sha256:" + hashlib.sha256(canonical.encode()).hexdigest()


def case_fingerprint(case: Mapping) -> str:
    return fingerprint_of(canonical_json(case_identity(case)))


def first_difference(a: Any, b: Any, path: str = "") -> tuple[str, Any, Any] | None:
    """The first key path (dotted, sorted order) where two case identities differ, with both values
    (``None`` if equal); what a refused restart names."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            sub = f"{path}.{k}" if path else k
            if k not in a or k not in b:
                return sub, a.get(k, "<absent>"), b.get(k, "<absent>")
            d = first_difference(a[k], b[k], sub)
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return path, f"{len(a)} items", f"{len(b)} items"
        for i, (x, y) in enumerate(zip(a, b)):
            d = first_difference(x, y, f"{path}[{i}]")
            if d:
                return d
        return None
    return None if a == b else (path, a, b)
