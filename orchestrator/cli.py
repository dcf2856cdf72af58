"""`immerse` command line: check, run, view, bench.

  immerse check CASE                          validate case.toml (and its meshes) only
  immerse run CASE [--out DIR] [--ranks ROLE=N ...] [--restart FILE]
  immerse view OUT [--field NAME ...] [--step all|last|N ...]
  immerse bench NAME [--out FILE] [--quick]   NAME: lagrange

Bad input: one line naming the key, the value and what is allowed; exit code 2; nothing launched,
nothing written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_BAD_INPUT = 2


def _fail(msg: str) -> int:
    print(f"immerse: {msg}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _parse_ranks(items: list[str]) -> dict[str, int] | str:
    ranks = {}
    for it in items or []:
        role, sep, n = it.partition("=")
        if not sep or not role:
            return f"--ranks {it!r}: expected ROLE=N, e.g. lagrange=2"
        try:
            ranks[role] = int(n)
        except ValueError:
            return f"--ranks {role} = {n!r}: must be an integer >= 1"
    return ranks


def cmd_check(args) -> int:
    from orchestrator.case import CaseError, load_case

    try:
        case = load_case(args.case)
    except CaseError as e:
        return _fail(str(e))
    from orchestrator.case import solvers_used

    print(f"{case['name']}: ok (dimension {case['run']['dimension']}, solvers: "
          f"{', '.join(solvers_used(case))})")
    return 0


def cmd_run(args) -> int:
    from orchestrator.case import CaseError, load_case, ranks_for
    from orchestrator.launch import run_job

    try:
        case = load_case(args.case)
        ranks = _parse_ranks(args.ranks)
        if isinstance(ranks, str):
            return _fail(ranks)
        ranks = ranks_for(case, ranks)
    except CaseError as e:
        return _fail(str(e))
    if args.restart and not Path(args.restart).is_file():
        return _fail(f"--restart = {args.restart!r}: not a readable checkpoint file")
    out = Path(args.out) if args.out else Path(case["case_dir"]) / "out"
    rc = run_job(case, out, ranks, args.restart)
    if rc == 0:
        import json

        s = json.loads((out / "summary.json").read_text())
        line = f"{s['case']}: {s['steps']} steps in {s['wall_time_s']:.2f} s -> {out}"
        if "check" in s:
            line += f"; check {'passed' if s['check']['passed'] else 'FAILED'}"
        print(line)
        if "check" in s and not s["check"]["passed"]:
            return 1
    return rc


def cmd_view(args) -> int:
    from orchestrator.output import OutputError
    from orchestrator.view import ViewError, render

    out = Path(args.out)
    if not (out / "results.h5").is_file():
        return _fail(f"OUT = {str(out)!r}: no results.h5 there (run the case first)")
    steps = tuple(args.step) if args.step else ("last",)
    try:
        paths = render(out, fields=args.field or None, steps=steps)
    except (ViewError, OutputError) as e:
        return _fail(str(e))
    for p in paths:
        print(p)
    return 0


def cmd_bench(args) -> int:
    from orchestrator import bench

    if args.name not in bench.BENCHES:
        return _fail(f"bench NAME = {args.name!r}: allowed: {', '.join(sorted(bench.BENCHES))}")
    path = bench.BENCHES[args.name](out=Path(args.out or f"bench-{args.name}.json"), quick=args.quick)
    print(path)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="immerse", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("check", help="validate a case directory")
    p.add_argument("case")
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("run", help="run a case directory")
    p.add_argument("case")
    p.add_argument("--out", help="output directory (default CASE/out)")
    p.add_argument("--ranks", nargs="*", metavar="ROLE=N", help="ranks per solver, e.g. lagrange=2")
    p.add_argument("--restart", help="checkpoint file (out/checkpoints/checkpoint_*.h5)")
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("view", help="render PNG pictures of a run's output")
    p.add_argument("out")
    p.add_argument("--field", nargs="*")
    p.add_argument("--step", nargs="*")
    p.set_defaults(func=cmd_view)
    p = sub.add_parser("bench", help="run a benchmark, write bench-NAME.json")
    p.add_argument("name")
    p.add_argument("--out")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.set_defaults(func=cmd_bench)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
