"""Summaries bit for bit, before and after a change that must not change a result (a refactor, a
module split): ``python -m tests.summaries record DIR [CASE ...]`` runs the shipped cases (all of
``cases/*`` by default, or those named) and keeps each ``summary.json`` without its timings as
``DIR/<case>.json``; ``python -m tests.summaries compare A B`` lists every case whose summary
differs (exit 1) or says that all are equal (exit 0). Floats are compared as JSON text: bit for bit."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TIMING = {"wall_time_s", "output_time_s", "solver_time_s", "engine_time_s", "first_step_s", "coupling_time_s",
          "coupling_share", "machine", "case_dir"}


def record(out: Path, cases: list[str]) -> int:
    out.mkdir(parents=True, exist_ok=True)
    dirs = [Path(c) for c in cases] or sorted(p.parent for p in (REPO / "cases").glob("*/case.toml"))
    for d in dirs:
        run = out / "runs" / d.name
        r = subprocess.run([sys.executable, "-m", "orchestrator.cli", "run", str(d), "--out", str(run), "--replace"],
                           capture_output=True, text=True, cwd=REPO)
        summary = run / "summary.json"
        if not summary.is_file():
            print(f"{d.name}: no summary (exit {r.returncode}): {r.stderr.strip()[-200:]}")
            continue
        s = {k: v for k, v in json.loads(summary.read_text()).items() if k not in TIMING}
        (out / f"{d.name}.json").write_text(json.dumps(s, sort_keys=True, indent=1))
        print(f"{d.name}: exit {r.returncode}, {s.get('steps')} steps")
    return 0


def compare(a: Path, b: Path) -> int:
    names = sorted({p.name for p in a.glob("*.json")} | {p.name for p in b.glob("*.json")})
    differ = [n for n in names if not (a / n).is_file() or not (b / n).is_file()
              or (a / n).read_text() != (b / n).read_text()]
    for n in differ:
        print(f"differs: {n.removesuffix('.json')}")
    print(f"{len(names) - len(differ)} of {len(names)} summaries bit for bit equal")
    return 1 if differ else 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "record":
        sys.exit(record(Path(sys.argv[2]), sys.argv[3:]))
    if len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    sys.exit(__doc__)
