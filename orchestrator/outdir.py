"""Output directories: immerse never deletes or overwrites a file it did not write.

An immerse output directory carries an ownership record::

    OUT/.immerse/owner.json   {"format", "case", "case_dir", "fingerprint", "run"}: the case it belongs
                              to; "run" names the launcher while a run is writing there (else null)
    OUT/.immerse/written      the files immerse wrote there, one path relative to OUT per line
                              ("<dir>/" for a directory immerse owns whole: .run/)

Rules for `immerse run CASE --out OUT` (the default OUT is CASE/out), checked before anything is
created or launched (:func:`plan`), each refusal one line naming --out:

* OUT does not exist, or is an empty directory: it becomes an immerse output of CASE.
* OUT is not empty and has no record, or is the output of another case: refused.
* OUT is an output of the same case (same case directory or the same fingerprint): refused unless
  --replace, which deletes the files immerse wrote there (by the record) and nothing else; or
  --restart with a checkpoint of that run, which continues it (only the step files of that run
  from the checkpoint's output index on are dropped, as they are written again).
* A file immerse did not write at a path the run would write or index (steps/<role>_<n>.h5,
  results.h5, log.txt, checkpoints/..., .run/): refused, also with --replace.
* OUT an existing file, under a file, or not writable: refused.

Files the job writes are claimed into the record when the run ends (:func:`finish_run`): before the
launch no file the record does not hold may sit at a path of the run, so whatever is there after it
was written by the run. A launcher that died without claiming (SIGKILL) leaves "run" in owner.json;
the next run claims the files of that run (modified after it started) once its launcher is gone.
Other writers (`immerse view`) record their files with :func:`record_written`.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path

FORMAT = "immerse-output-1"
MARKER_DIR = ".immerse"
OWNER = "owner.json"
RECORD = "written"
RUN_DIR = ".run"

# Paths (relative to OUT) a run writes or that the index would pick up, with the temporary names of
# their atomic writers: a file here that immerse did not write blocks the run.
_NAME = r"[A-Za-z][A-Za-z0-9_-]*"
_TMP = r"(?:\.\d+)?(?:\.tmp)?"
RUN_FILES = re.compile(
    rf"^(?:(?:log\.txt|results\.h5|results\.xdmf|summary\.json|diagnostics\.h5|probes\.csv|open_in_paraview\.py){_TMP}"
    rf"|steps/{_NAME}_(?:\d+|mesh)\.h5{_TMP}"
    rf"|checkpoints/checkpoint_\d+\.(?:h5|tmp)"
    rf"|checkpoints/step_\d+/{_NAME}\.h5{_TMP})$")
# ... and the run-control files of the job (pids, error reports), owned as a whole
_BLOCKING = re.compile(rf"{RUN_FILES.pattern}|^\.run(?:/.*)?$")
_STEP_FILE = re.compile(rf"^steps/{_NAME}_(\d+)\.h5{_TMP}$")
# directories the run writes into: they must be real directories (not links to elsewhere)
_RUN_DIRS = re.compile(r"^(?:steps|checkpoints|checkpoints/step_\d+|pictures|plots|\.run|\.immerse)$")
_CLAIM_SLACK_S = 2.0  # file times vs the launcher's clock


class OutDirError(ValueError):
    """One line: ``--out = '<dir>': <why>``."""

    def __init__(self, out, why: str):
        super().__init__(f"--out = {str(out)!r}: {why}")


# ---- the record ------------------------------------------------------------------------------------
def _marker(out: Path) -> Path:
    return Path(out) / MARKER_DIR


def read_owner(out) -> dict | None:
    """owner.json of an immerse output directory, or None."""
    p = _marker(out) / OWNER
    try:
        if p.is_symlink() or not p.is_file():
            return None
        d = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) and d.get("format") == FORMAT else None


def _safe_rel(line: str) -> str | None:
    """A record line as a clean relative path (a tampered line never reaches outside OUT)."""
    line = line.strip()
    if not line or line.startswith("/") or "\\" in line:
        return None
    parts = line.rstrip("/").split("/")
    if any(p in ("", ".", "..") for p in parts):
        return None
    return "/".join(parts) + ("/" if line.endswith("/") else "")


def read_record(out) -> set[str]:
    try:
        text = (_marker(out) / RECORD).read_text(errors="replace")
    except OSError:
        return set()
    return {r for r in map(_safe_rel, text.splitlines()) if r}


def append_lines(path: Path, rels) -> None:
    """Append ``rels`` to a record file, one a line, in one write() with O_APPEND (records of
    concurrent writers do not interleave), never through a link (also a campaign's record)."""
    data = "".join(f"{r}\n" for r in rels).encode()
    if not data:
        return
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)


def _append(out: Path, rels) -> None:
    append_lines(_marker(out) / RECORD, rels)


def rels_inside(out, paths) -> list[str]:
    """``paths`` (absolute, or relative to the working directory) as clean paths relative to
    ``out``; those outside it left out."""
    root = Path(out).resolve()
    rels = []
    for p in paths:
        try:
            rel = Path(os.path.abspath(p)).relative_to(root).as_posix()
        except ValueError:
            try:
                rel = Path(p).resolve().relative_to(root).as_posix()
            except ValueError:
                continue  # not inside OUT
        if _safe_rel(rel):
            rels.append(rel)
    return rels


def record_written(out_dir, *paths) -> None:
    """Record files immerse wrote into the output directory ``out_dir`` (absolute or relative to the
    working directory); --replace deletes them later. A no-op outside an immerse output directory.
    `immerse view` calls it once per picture after writing it."""
    out = Path(out_dir)
    if read_owner(out) is None:
        return
    _append(out, rels_inside(out, paths))


def may_write(out_dir, path) -> bool:
    """True if immerse may (over)write ``path`` in ``out_dir``: nothing is there, or immerse wrote it."""
    p = Path(path)
    if not os.path.lexists(p):
        return True
    try:
        rel = p.resolve().relative_to(Path(out_dir).resolve()).as_posix()
    except ValueError:
        return False
    return rel in read_record(out_dir) and not p.is_symlink()


def _write_owner(out: Path, owner: dict) -> None:
    d = _marker(out)
    d.mkdir(exist_ok=True)
    tmp = d / f".{OWNER}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(owner, indent=1) + "\n")
    os.replace(tmp, d / OWNER)


def _rewrite_record(out: Path, rels) -> None:
    d = _marker(out)
    tmp = d / f".{RECORD}.{os.getpid()}.tmp"
    tmp.write_text("".join(f"{r}\n" for r in sorted(set(rels))))
    os.replace(tmp, d / RECORD)


# ---- looking at a directory ------------------------------------------------------------------------
def _start_ticks(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def _alive(run: dict | None) -> bool:
    """Is the launcher named in owner.json still running (the same process, not a reused pid)?"""
    if not isinstance(run, dict):
        return False
    try:
        return _start_ticks(int(run["pid"])) == int(run["pid_start"])
    except (KeyError, TypeError, ValueError):
        return False


def _walk(out: Path):
    """(relative path, lstat) of every entry below out, without following links."""
    for root, dirs, files in os.walk(out):
        for n in dirs + files:
            p = Path(root) / n
            yield p.relative_to(out).as_posix(), p.lstat()


def _owned(rel: str, st: os.stat_result, record: set[str]) -> bool:
    if rel == MARKER_DIR or rel.startswith(MARKER_DIR + "/"):
        return True
    top = rel.split("/", 1)[0]
    if f"{top}/" in record:  # a directory immerse owns whole (.run/)
        return True
    return rel in record and stat.S_ISREG(st.st_mode)


def existing_ancestor(path) -> Path:
    """The nearest of ``path`` (made absolute) and its parents that exists, a link counted as existing
    (a path under it cannot be created unless it is a directory)."""
    anc = Path(path).absolute()
    while not os.path.lexists(anc):
        anc = anc.parent
    return anc


def _writable(p: Path) -> str | None:
    if not os.access(p, os.W_OK | os.X_OK):
        return "not writable (permission denied)"
    try:
        if os.statvfs(p).f_flag & os.ST_RDONLY:
            return "on a read-only file system"
    except OSError:
        pass
    return None


def _claimable(out: Path, record: set[str], since: float):
    """Unrecorded files at run paths modified since ``since``: written by a run that started then."""
    for rel, st in _walk(out):
        if stat.S_ISREG(st.st_mode) and RUN_FILES.match(rel) and rel not in record \
                and st.st_mtime >= since - _CLAIM_SLACK_S:
            yield rel


# ---- the plan --------------------------------------------------------------------------------------
@dataclass
class Plan:
    out: Path
    create: bool  # OUT does not exist yet
    owner: dict  # owner.json to write
    delete: list[str] = field(default_factory=list)  # recorded files (relative) this run removes
    keep: set[str] = field(default_factory=set)  # record entries that stay
    adopt: set[str] = field(default_factory=set)  # files of an unfinished earlier run, claimed now


def plan(out, case: dict, fingerprint: str, *, replace: bool = False, restart=None) -> Plan:
    """Decide what preparing ``out`` for a run of ``case`` does, or raise OutDirError; touches
    nothing. ``restart`` is the :class:`orchestrator.restart.Checkpoint` of --restart, if any."""
    out = Path(out)
    owner = {"format": FORMAT, "case": case["name"], "case_dir": str(case["case_dir"]),
             "fingerprint": fingerprint, "run": None}
    if os.path.lexists(out) and (out.is_symlink() and not out.is_dir()):
        raise OutDirError(out, "is a dangling link; expected a directory")
    if out.exists() and not out.is_dir():
        raise OutDirError(out, "is an existing file; expected a directory (new, empty, or an earlier "
                               "immerse output of this case)")
    if not out.exists():
        anc = existing_ancestor(out)
        if not anc.is_dir():
            raise OutDirError(out, f"cannot be created: {str(anc)!r} is not a directory")
        why = _writable(anc)
        if why:
            raise OutDirError(out, f"cannot be created: {str(anc)!r} is {why}")
        return Plan(out, create=True, owner=owner)
    why = _writable(out)
    if why:
        raise OutDirError(out, f"is {why}")
    with os.scandir(out) as it:
        empty = next(it, None) is None
    if empty:
        return Plan(out, create=False, owner=owner)

    prev = read_owner(out)
    if prev is None:
        if (out / "results.h5").is_file() and (out / "steps").is_dir():
            raise OutDirError(out, "holds an output of an older immerse without an ownership record "
                                   f"({MARKER_DIR}/{OWNER}): immerse cannot tell its files from yours; "
                                   "move or delete it yourself, or choose another --out")
        raise OutDirError(out, "is not empty and not an immerse output; choose a new or empty "
                               "directory (immerse never deletes files it did not write)")
    same_case = prev.get("case_dir") == owner["case_dir"] or prev.get("fingerprint") == fingerprint
    if not same_case:
        raise OutDirError(out, f"is the output of another case ({prev.get('case')!r} in "
                               f"{prev.get('case_dir')}); choose another --out")
    if _alive(prev.get("run")):
        raise OutDirError(out, f"is in use by a running immerse (pid {prev['run']['pid']})")

    record = read_record(out)
    adopt: set[str] = set()
    if isinstance(prev.get("run"), dict):  # an earlier launcher died before claiming its files
        adopt = set(_claimable(out, record, float(prev["run"].get("started", time.time()))))
        record |= adopt

    foreign = []
    for rel, st in _walk(out):
        if _RUN_DIRS.match(rel) and not stat.S_ISDIR(st.st_mode):
            raise OutDirError(out, f"{rel} is not a directory immerse made (a link or a file); "
                                   "immerse writes there")
        if not _owned(rel, st, record) and _BLOCKING.match(rel):
            foreign.append((stat.S_ISDIR(st.st_mode), rel))
    foreign = [rel for _, rel in sorted(foreign)]  # name a file before a directory
    if foreign:
        raise OutDirError(out, f"{foreign[0]} was not written by immerse, and this run would write "
                               f"or index it{f' (and {len(foreign) - 1} more)' if len(foreign) > 1 else ''}; "
                               "move it away or choose another --out")

    files = {r for r in record if not r.endswith("/")}
    existing = {r for r in files if os.path.lexists(out / r)}
    own_checkpoint = False
    if restart is not None:
        try:
            rel = Path(restart.path).relative_to(out.resolve()).as_posix()
            own_checkpoint = rel in existing
        except ValueError:
            pass
    if own_checkpoint:
        if replace:
            raise OutDirError(out, "--replace would delete the checkpoint --restart continues from; "
                                   "continuing a run in its own output needs no --replace")
        drop = sorted(r for r in existing if (m := _STEP_FILE.match(r)) and int(m[1]) >= restart.out_index)
        keep = (existing - set(drop)) | {f"{RUN_DIR}/"}
        return Plan(out, create=False, owner=owner, delete=drop, keep=keep, adopt=adopt)
    if not replace:
        raise OutDirError(out, f"holds an earlier run of this case ({prev.get('case')!r}); pass "
                               "--replace to replace what immerse wrote there (your own files stay), "
                               "or choose another --out")
    return Plan(out, create=False, owner=owner, delete=sorted(existing), keep=set(), adopt=adopt)


# ---- acting on it ----------------------------------------------------------------------------------
def _is_real_dir(p: Path) -> bool:
    return p.is_dir() and not p.is_symlink()


def linked_on_the_way(out: Path, rel: str) -> str | None:
    """The first folder on the way from ``out`` to ``out/rel`` that is there but not a real
    directory (a link, a file), relative to out, or None (a missing one leads nowhere): a record
    line ``foo/x.txt`` with ``foo`` a link to the user's folder names the user's file."""
    parts = Path(rel).parts
    for i in range(1, len(parts)):
        try:
            mode = os.lstat(out.joinpath(*parts[:i])).st_mode
        except FileNotFoundError:
            return None
        if not stat.S_ISDIR(mode):
            return Path(*parts[:i]).as_posix()
    return None


def _plain_file(out: Path, rel: str) -> bool:
    """``out/rel`` is a regular file reached through real directories only."""
    try:
        return linked_on_the_way(out, rel) is None and stat.S_ISREG(os.lstat(out / rel).st_mode)
    except OSError:
        return False


def prepare(p: Plan, started: float | None = None) -> None:
    """Carry out a plan: create OUT, delete the files it names, write the ownership record with the
    launcher as the running writer. OutDirError (one line) if the file system refuses; a directory
    this call created is removed again."""
    out = p.out
    created: list[Path] = []
    try:
        if p.create:
            missing = []
            a = out.absolute()
            while not os.path.lexists(a):
                missing.append(a)
                a = a.parent
            for d in reversed(missing):
                d.mkdir()
                created.append(d)
        run_dir = out / RUN_DIR
        if _is_real_dir(run_dir):
            shutil.rmtree(run_dir)
        parents = set()
        for rel in p.delete:
            if not _plain_file(out, rel):
                continue  # never through a link (the file's or a folder's on the way), never a directory
            (out / rel).unlink()
            parents.update(Path(rel).parents)
        for rel in sorted((str(d) for d in parents if str(d) != "."), key=lambda s: -s.count("/")):
            d = out / rel
            if _is_real_dir(d) and not any(d.iterdir()):
                d.rmdir()
        owner = dict(p.owner)
        owner["run"] = {"pid": os.getpid(), "pid_start": _start_ticks(os.getpid()),
                        "started": time.time() if started is None else started}
        _write_owner(out, owner)
        _rewrite_record(out, (p.keep | p.adopt | {f"{RUN_DIR}/", "log.txt"}) - set(p.delete))
    except OSError as e:
        for d in reversed(created):
            shutil.rmtree(d, ignore_errors=True)
        raise OutDirError(out, f"cannot be prepared: {e.strerror or e}"
                               f"{f' ({e.filename})' if getattr(e, 'filename', None) else ''}") from None


def finish_run(out, started: float) -> None:
    """Claim the files the run wrote (run paths modified since it started) and mark OUT idle."""
    out = Path(out)
    owner = read_owner(out)
    if owner is None:
        return
    record = read_record(out)
    _append(out, sorted(_claimable(out, record, started)))
    owner["run"] = None
    _write_owner(out, owner)
