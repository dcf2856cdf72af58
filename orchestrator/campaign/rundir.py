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
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

from orchestrator.schema_rules import CaseError

MARKER = ".immerse-campaign.json"
MAX_COPY_BYTES = 256 << 20
"""Most a base case directory may hold (its outputs left out) to be copied into each run."""


def atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def claim_out(out: Path, camp) -> None:
    """Make ``out`` this campaign's output directory, or raise CaseError (nothing written) if it
    holds anything else: a file, a non-empty directory without the record, another campaign's."""
    if out.exists() and not out.is_dir():
        raise CaseError("--out", str(out), "is a file; must be a directory for the campaign's output")
    marker = out / MARKER
    if out.is_dir() and any(out.iterdir()):
        if not marker.is_file():
            raise CaseError("--out", str(out), "is a non-empty directory that is not a campaign's "
                            "output; give a new or empty directory")
        try:
            owner = json.loads(marker.read_text())
        except (OSError, ValueError):
            raise CaseError("--out", str(out), f"its {MARKER} is unreadable; give a new directory") from None
        if owner.get("name") != camp.name:
            raise CaseError("--out", str(out), f"holds the output of campaign {owner.get('name')!r}, "
                            f"not {camp.name!r}")
        return
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(marker, json.dumps({"format": "immerse-campaign-1", "name": camp.name,
                                     "campaign": str(camp.path)}, indent=1) + "\n")


def _is_output(d: Path) -> bool:
    return (d / ".immerse" / "owner.json").is_file() or (d / MARKER).is_file()


def _copy_ignore(base: Path):
    def ignore(dirpath, names):
        d = Path(dirpath)
        return {n for n in names if (d / n).is_dir() and (_is_output(d / n) or (d == base and n == "out"))}

    return ignore


def _tree_size(base: Path) -> int:
    total = 0
    ignore = _copy_ignore(base)
    for dirpath, dirnames, filenames in os.walk(base):
        skip = ignore(dirpath, dirnames)
        dirnames[:] = [n for n in dirnames if n not in skip]
        total += sum(os.lstat(os.path.join(dirpath, f)).st_size for f in filenames)
    return total


def write_case(run, dest: Path) -> Path:
    """The run's case directory at ``dest`` (replaced if there): the base case's files (outputs left
    out) and its case.toml with the run's keys set."""
    from orchestrator.campaign.toml_write import dumps

    base = run.case_dir
    if _tree_size(base) > MAX_COPY_BYTES:
        raise CaseError(f"run {run.name}: case", str(base), f"holds more than {MAX_COPY_BYTES >> 20} MiB "
                        "(outputs left out); a campaign copies its case into every run")
    if dest.exists():
        shutil.rmtree(dest)
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
    staged = d / "case.new"
    write_case(run, staged)
    fp = fingerprint(staged)
    res = read_result(d)
    case = d / run.name
    if res is not None and res.get("fingerprint") == fp and case.is_dir():
        shutil.rmtree(staged)
        return d, True
    (d / "result.json").unlink(missing_ok=True)
    if case.exists():
        shutil.rmtree(case)
    os.replace(staged, case)
    atomic_write(d / "run.json", json.dumps({
        "name": run.name, "series": run.series, "chart": run.chart, "index": run.index,
        "levels": run.levels, "settings": run.settings, "base_case": str(run.case_dir),
        "error": run.error, "relative_to": run.relative_to, "fingerprint": fp}, indent=1) + "\n")
    return d, False
