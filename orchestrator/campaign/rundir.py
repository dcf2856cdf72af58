"""A campaign's output directory and its run directories.

    OUT/.immerse-campaign.json   whose campaign this is (name, file); OUT is refused for a campaign
                                 if it is a non-empty directory without this record
    OUT/runs/RUN/RUN/            the run's case directory: the base case's files, case.toml with the
                                 run's keys set (an ordinary case: `immerse run` runs it)
    OUT/runs/RUN/out/            its `immerse run --out`
    OUT/runs/RUN/run.json        what the run is (series, levels, settings, fingerprint)
    OUT/runs/RUN/result.json     written last and atomically when the run ended: its presence, with
                                 the fingerprint of the current case, is what "done" means; a run
                                 killed midway has none and is run again
    OUT/campaign.csv, campaign.h5, report.*, figures/   collected results and the report

The fingerprint is a hash of every file of the run's case directory: a run whose case changed (the
campaign file or its base case edited) is run again; one whose case is unchanged is kept.

Ownership (the rules of orchestrator/outdir.py for a run's output, applied to a campaign's): the
marker holds the identity of the folder it was written in (device and inode), so a copy of it in
another folder is no record (a copied or moved-across-file-systems output is refused: immerse
cannot tell its files from yours); ``OUT/.immerse-campaign-written`` lists every file the campaign
wrote (paths relative to OUT, appended by each writer).  Before anything is written, a file at a
path the campaign writes (CAMPAIGN_FILES) that the list does not hold refuses the campaign, naming
it; so a run's case directory is replaced, and a file overwritten, only when immerse wrote it.
Deleting never follows a link.  Each run's ``out/`` is a run output with its own record.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path

from orchestrator.outdir import _safe_rel, append_lines, linked_on_the_way, rels_inside
from orchestrator.schema.rules import CaseError

MARKER = ".immerse-campaign.json"
RECORD = ".immerse-campaign-written"
CAMPAIGN_FILES = re.compile(
    r"^(?:campaign\.(?:csv|h5)|report\.(?:md|html)"
    r"|figures/(?:picture_[^/]*|[^/]*_(?:cost|order|stability|plot\d+))\.png"
    r"|slurm/(?:runs_\d+\.txt|campaign_\d+\.sbatch|job\.json)"
    r"|runs/[^/]+/(?:run\.json|result\.json|stdout\.txt|stderr\.txt)"
    r"|runs/([^/]+)/\1(?:/.*)?)$")
"""Paths (relative to OUT) the campaign writes, overwrites or deletes: runs/RUN/RUN/ is the run's case
directory (its whole tree); runs/RUN/out/ is left to the run's own record."""
MAX_COPY_BYTES = 256 << 20
"""Most a base case directory may hold (its outputs left out) to be copied into each run."""


def atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _folder_id(p: Path) -> list[int]:
    st = os.stat(p)
    return [st.st_dev, st.st_ino]


def read_record(out: Path) -> set[str]:
    p = Path(out) / RECORD
    try:
        if p.is_symlink():
            return set()
        text = p.read_text(errors="replace")
    except OSError:
        return set()
    return {r for r in map(_safe_rel, text.splitlines()) if r}


def record(out: Path, *paths) -> None:
    """Add files the campaign wrote in ``out`` (absolute, or relative to the working directory) to
    its record: one write() with O_APPEND (concurrent runs' records do not interleave)."""
    append_lines(Path(out) / RECORD, rels_inside(out, paths))


def _entries(out: Path):
    """(relative path, lstat) of every entry below ``out`` that the campaign may write (CAMPAIGN_FILES),
    without following links; a run's out/ is not entered."""
    for root, dirs, files in os.walk(out):
        here = Path(root)
        rel_here = here.relative_to(out).as_posix()
        parts = rel_here.split("/")
        if len(parts) == 2 and parts[0] == "runs":
            dirs[:] = [d for d in dirs if d != "out"]
        for n in dirs + files:
            rel = (here / n).relative_to(out).as_posix()
            if CAMPAIGN_FILES.match(rel):
                yield rel, (here / n).lstat()


def foreign(out: Path) -> list[str]:
    """Entries at the campaign's paths it did not record writing (a directory counts by its files;
    a link in place of one is foreign)."""
    rec = read_record(out)
    return sorted(rel for rel, st in _entries(out)
                  if not stat.S_ISDIR(st.st_mode) and rel not in rec)


def claim_out(out: Path, camp) -> None:
    """Make ``out`` this campaign's output directory, or raise CaseError (nothing written) if it
    holds anything else: a file, a non-empty directory without the record, another campaign's, a
    marker copied from another folder, or a file the campaign did not write at one of its paths."""
    if out.exists() and not out.is_dir():
        raise CaseError("--out", str(out), "is a file; must be a directory for the campaign's output")
    marker = out / MARKER
    if out.is_dir() and any(out.iterdir()):
        check_owned(out, camp.name)
        return
    made = []
    try:
        a = out.absolute()
        while not os.path.lexists(a):
            made.append(a)
            a = a.parent
        if not a.is_dir():
            raise CaseError("--out", str(out), f"cannot be created: {str(a)!r} is not a directory")
        for d in reversed(made):
            d.mkdir()
        atomic_write(marker, json.dumps({"format": "immerse-campaign-1", "name": camp.name,
                                         "campaign": str(camp.path), "folder": _folder_id(out)},
                                        indent=1) + "\n")
    except OSError as e:   # (under /proc, read-only, no permission: nothing left behind)
        for d in made:
            shutil.rmtree(d, ignore_errors=True)
        raise CaseError("--out", str(out), f"cannot be created: {e.strerror or e}") from None


def check_owned(out: Path, name: str | None = None, key: str = "--out") -> None:
    """``out`` is a campaign output this campaign (``name``; None: any) may write into: its marker
    is a real file written in this folder, and no file at the campaign's paths is unrecorded.
    Else CaseError naming ``key``."""
    marker = out / MARKER
    if marker.is_symlink() or not marker.is_file():
        raise CaseError(key, str(out), "is a non-empty directory that is not a campaign's "
                        "output; give a new or empty directory")
    try:
        owner = json.loads(marker.read_text())
    except (OSError, ValueError):
        raise CaseError(key, str(out), f"its {MARKER} is unreadable; give a new directory") from None
    if not isinstance(owner, dict) or (name is not None and owner.get("name") != name):
        other = owner.get("name") if isinstance(owner, dict) else None
        raise CaseError(key, str(out), f"holds the output of campaign {other!r}, not {name!r}")
    if owner.get("folder") != _folder_id(out):
        raise CaseError(key, str(out), f"its {MARKER} was written in another folder (a copy, or an "
                        "output of an older immerse): immerse cannot tell its files from yours; "
                        "give a new or empty directory")
    bad = foreign(out)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise CaseError(key, str(out), f"{bad[0]} was not written by this campaign, which would "
                        f"write or delete it{more}; move it away or give another directory")


def remove_recorded(out: Path, rel: str) -> None:
    """Delete ``out/rel`` (a file, or a directory tree) if the campaign recorded writing it: every
    file and link in the tree recorded (unlinked, never followed), every directory real; else
    CaseError naming the first foreign entry (claim_out refused those before: a race)."""
    rec = read_record(out)
    top = out / rel
    on_the_way = linked_on_the_way(out, rel)
    if on_the_way is not None:
        raise CaseError("--out", str(out), f"{on_the_way} is not a directory the campaign made "
                        "(a link or a file)")
    try:
        st = os.lstat(top)
    except FileNotFoundError:
        return
    if not stat.S_ISDIR(st.st_mode):
        if rel not in rec:
            raise CaseError("--out", str(out), f"{rel} was not written by this campaign; move it away")
        top.unlink()
        return
    tree = [(Path(r).relative_to(out).as_posix(), ds, fs) for r, ds, fs in os.walk(top)]
    for r, _, fs in tree:
        for f in fs:
            if f"{r}/{f}" not in rec:
                raise CaseError("--out", str(out), f"{r}/{f} was not written by this campaign; move it away")
    for r, ds, fs in reversed(tree):  # the deepest first
        for f in fs:
            (out / r / f).unlink()
        for d in ds:
            p = out / r / d
            if p.is_symlink():
                if f"{r}/{d}" not in rec:
                    raise CaseError("--out", str(out), f"{r}/{d} was not written by this campaign; move it away")
                p.unlink()
            else:
                p.rmdir()
    top.rmdir()


def _is_output(d: Path) -> bool:
    return (d / ".immerse" / "owner.json").is_file() or (d / MARKER).is_file()


def _copy_ignore(base: Path):
    def ignore(dirpath, names):
        d = Path(dirpath)
        return {n for n in names if (d / n).is_dir() and (_is_output(d / n) or (d == base and n == "out"))}

    return ignore


def _tree_size(base: Path, key: str = "case") -> int:
    """Bytes the base case's files hold (a link counts its target's), walking without following
    links; CaseError (``key``) for an entry that is not a regular file, a directory or a link to a
    regular file: a FIFO would block the copy, a socket or a device cannot be copied."""
    total = 0
    ignore = _copy_ignore(base)
    for dirpath, dirnames, filenames in os.walk(base):
        skip = ignore(dirpath, dirnames)
        dirnames[:] = [n for n in dirnames if n not in skip]
        for f in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            p = os.path.join(dirpath, f)
            try:
                st = os.stat(p)   # (through a link: what the copy and the fingerprint read)
            except OSError:
                raise CaseError(key, p, "is a dangling link; allowed in a campaign's base case: "
                                "regular files and directories") from None
            if not stat.S_ISREG(st.st_mode):
                from orchestrator.schema.rules import file_kind

                kind = file_kind(st.st_mode) if not stat.S_ISDIR(st.st_mode) else "a link to a directory"
                raise CaseError(key, p, f"is {kind}; allowed in a campaign's base case: regular "
                                "files and directories")
            total += st.st_size
            if total > MAX_COPY_BYTES:
                return total
    return total


def write_case(run, dest: Path) -> Path:
    """The run's case directory at ``dest`` (replaced if there): the base case's files (outputs left
    out) and its case.toml with the run's keys set."""
    from orchestrator.campaign.toml_write import dumps

    base = run.case_dir
    if _tree_size(base, f"run {run.name}: case") > MAX_COPY_BYTES:
        raise CaseError(f"run {run.name}: case", str(base), f"holds more than {MAX_COPY_BYTES >> 20} MiB "
                        "(outputs left out); a campaign copies its case into every run")
    shutil.copytree(base, dest, ignore=_copy_ignore(base), symlinks=True)
    header = (f"# written by `immerse campaign` from {base.name}/case.toml with:\n"
              + "".join(f"#   {k} = {json.dumps(v)}\n" for k, v in run.settings.items()))
    atomic_write(dest / "case.toml", header + dumps(run.data))
    return dest


def fingerprint(case_dir: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(case_dir.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(case_dir)).encode() + b"\0")
            h.update(p.read_bytes())
    return h.hexdigest()[:20]


def run_dir(out: Path, run) -> Path:
    return out / "runs" / run.name


def read_result(d: Path) -> dict | None:
    try:
        return json.loads((d / "result.json").read_text())
    except (OSError, ValueError):
        return None


def prepare_run(out: Path, run) -> tuple[Path, bool]:
    """Write the run's case into a scratch place, compare its fingerprint with a stored result: return
    (run directory, done). A run not done gets its case directory (re)written and its result removed."""
    d = run_dir(out, run)
    d.mkdir(parents=True, exist_ok=True)
    # staged in a folder of its own (made here: nobody else's files are in it)
    staged = Path(tempfile.mkdtemp(prefix=".case-", dir=d)) / run.name
    write_case(run, staged)
    fp = fingerprint(staged)
    res = read_result(d)
    case = d / run.name
    if res is not None and res.get("fingerprint") == fp and case.is_dir() and not case.is_symlink():
        shutil.rmtree(staged.parent)
        return d, True
    remove_recorded(out, f"runs/{run.name}/result.json")
    remove_recorded(out, f"runs/{run.name}/{run.name}")
    # recorded before it is in place (a kill between leaves a record of nothing, never a file unrecorded)
    record(out, *(case / p.relative_to(staged) for p in staged.rglob("*")))
    os.replace(staged, case)
    staged.parent.rmdir()
    record(out, d / "run.json")
    atomic_write(d / "run.json", json.dumps({
        "name": run.name, "series": run.series, "chart": run.chart, "index": run.index,
        "levels": run.levels, "settings": run.settings, "base_case": str(run.case_dir),
        "error": run.error, "relative_to": run.relative_to, "fingerprint": fp}, indent=1) + "\n")
    return d, False
