"""The case as the launcher checked it, handed to the processes of its job: the normalised case dict
(orchestrator/case.py's load_case) written to OUT/.run/case.json, its SHA-256 on their command lines.

The coupler and every solver rank read it with the standard library alone: no TOML parse, no
normalising, no import of the case loader (which sits on the orchestrator's floor, above the
adapters). The hash makes a file changed after the launch a refusal, not another case. Values are
JSON, except paths (the case directory, a mesh file), tagged in the file and read back as Paths: the
case's fingerprint hashes the files its paths name (orchestrator/fingerprint.py), so every process
sees the very dict the launcher checked."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

NAME = "case.json"
PATH_TAG = "__immerse_path__"


class CaseFileError(RuntimeError):
    """The handed-over case is missing, changed since the launch, or not a case."""


def _plain(value):
    if isinstance(value, os.PathLike):
        return {PATH_TAG: os.fspath(value)}
    raise TypeError(f"a case value of type {type(value).__name__} cannot be handed to the job's processes")


def _paths(obj: dict):
    return Path(obj[PATH_TAG]) if len(obj) == 1 and PATH_TAG in obj else obj


def write(case: dict, run_dir: Path) -> tuple[Path, str]:
    """Write ``case`` to ``run_dir``/case.json (atomically: a process never reads half of it);
    returns (path, SHA-256 of its bytes)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    raw = json.dumps(case, default=_plain, allow_nan=False, separators=(",", ":")).encode()
    path = run_dir / NAME
    tmp = run_dir / f".{NAME}.{os.getpid()}.tmp"
    tmp.write_bytes(raw)
    os.replace(tmp, path)
    return path, hashlib.sha256(raw).hexdigest()


def read(path: str | os.PathLike, sha256: str) -> dict:
    """The case the launcher wrote to ``path``; CaseFileError if its bytes are not those of ``sha256``."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise CaseFileError(f"{path}: the case handed to the job cannot be read ({exc.strerror or exc})") from None
    if hashlib.sha256(raw).hexdigest() != sha256:
        raise CaseFileError(f"{path}: changed since the run was launched (the job's processes read the case "
                            "the launcher checked)")
    case = json.loads(raw, object_hook=_paths)
    if not isinstance(case, dict):
        raise CaseFileError(f"{path}: not a case (a JSON object)")
    return case
