"""`immerse` command line: check, run, view, campaign, report, bench.

  immerse check CASE [--ranks ROLE=N ...] [MACHINE]   validate only (case, meshes, expressions, resources)
  immerse run CASE [--out DIR] [--replace] [--ranks ROLE=N ...] [--restart FILE] [--engine local|slurm] [MACHINE]
      MACHINE: [--nodes N] [--memory-per-node SIZE] [--oversubscribe]
  immerse view OUT [--field NAME ...] [--step all|last|N ...] [--range fixed|step] [--movie] [--list]
  immerse plot OUT [QUANTITY ...] [--csv] [--list]    time histories (diagnostics, probes) against time
  immerse keys [TABLE] [--markdown]            every case.toml key: type, unit, range, default, meaning
  immerse campaign CAMPAIGN.toml [--out DIR] [--engine local|slurm] [--cores N] [--retry-failed] [--only AXIS=L1,L2]
      runs a matrix of cases x parameters (orchestrator/campaign), then campaign.csv/.h5 and the report
  immerse report OUT                           rebuilds a campaign's report from OUT/campaign.h5
  immerse bench NAME [--out FILE] [--quick]   NAME: lagrange, taylor, ale, sod, advect, memory, output, coupling,
                                              plate_convergence, plate_convergence_3d, penalty_sweep, sph, contact,
                                              multirate, subcycling, steel_panel_convergence, implicit, startup

Bad input: one line naming the key, the value and what is allowed; exit code 2; nothing launched,
nothing written.
"""
from __future__ import annotations

import argparse
import os
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
        # ASCII digits only: int() also takes '٢', ' 3', '1_0'
        if not (n.isascii() and n.isdigit() and len(n) <= 6) or int(n) < 1:
            return f"--ranks {role} = {n!r}: must be an integer >= 1 (ASCII digits)"
        ranks[role] = int(n)
    return ranks


def _add_machine_flags(p) -> None:
    """Flags of check and run that describe the machine the job runs on (orchestrator/resources.py)."""
    p.add_argument("--nodes", metavar="N", help="the job spans N nodes of this machine's kind "
                   "(memory and cores scale by N; default 1)")
    p.add_argument("--memory-per-node", metavar="SIZE", help="memory of a node, e.g. 64GiB, 512G, "
                   "1.5TB (default: this machine's)")
    p.add_argument("--oversubscribe", action="store_true", help="allow more than 4 processes a core")


def _admit(args, case: dict, ranks: dict, overridden) -> int:
    """What check and run verify after the case file: rank counts and memory against the machine of
    the flags, then every expression evaluated on the case's own points, then the coupled bodies'
    thickness in zones; the memory estimate. Raises CaseError."""
    from adapters.protocol import SPIN_ENV, spin_s_from
    from orchestrator.ale_states import check_states
    from orchestrator.case import CaseError
    from orchestrator.coupling.thickness import check_thin_bodies
    from orchestrator.expressions import check_expressions
    from orchestrator.resources import check_resources, this_machine

    if spin_s_from(os.environ.get(SPIN_ENV)) is None:
        raise CaseError(SPIN_ENV, os.environ[SPIN_ENV], "must be a number of seconds from 0 to 1 (unset: 200e-6)")
    cluster = None
    if getattr(args, "engine", "local") == "slurm" and (args.nodes or args.memory_per_node):
        from orchestrator.slurm_commands import cluster_size   # (the job goes to Slurm: ask it)

        cluster = cluster_size()
    machine = this_machine(args.nodes, args.memory_per_node, args.oversubscribe, cluster=cluster)
    estimate = check_resources(case, ranks, machine, overridden)
    check_expressions(case)
    check_states(case)
    check_thin_bodies(case)
    return estimate


def _notes(case: dict) -> None:
    """The case's notes (an older spelling read under its one name: orchestrator/schema/spellings.py),
    one line each, before anything runs."""
    for n in case.get("_notes", ()):
        print(f"immerse: {n}", flush=True)


def cmd_check(args) -> int:
    from orchestrator.case import CaseError, load_case, ranks_for

    try:
        case = load_case(args.case)
        overrides = _parse_ranks(args.ranks)
        if isinstance(overrides, str):
            return _fail(overrides)
        ranks = ranks_for(case, overrides)
        estimate = _admit(args, case, ranks, set(overrides))
    except CaseError as e:
        return _fail(str(e))
    from orchestrator.case import solvers_used
    from orchestrator.resources import format_bytes

    _notes(case)
    print(f"{case['name']}: ok (dimension {case['run']['dimension']}, solvers: "
          f"{', '.join(solvers_used(case))}; memory about {format_bytes(estimate)})")
    return 0


def cmd_run(args) -> int:
    from orchestrator.case import CaseError, load_case, ranks_for
    from orchestrator.launch import run_job

    try:
        case = load_case(args.case)
        ranks = _parse_ranks(args.ranks)
        if isinstance(ranks, str):
            return _fail(ranks)
        overridden = set(ranks)
        ranks = ranks_for(case, ranks)
        _admit(args, case, ranks, overridden)
    except CaseError as e:
        return _fail(str(e))
    _notes(case)
    # everything is checked before anything is created or launched
    from orchestrator import outdir
    from orchestrator.restart import RestartError

    if args.engine == "slurm":
        from orchestrator.slurm_run import submit_run

        try:
            return submit_run(args, case, ranks)
        except (RestartError, outdir.OutDirError) as e:
            return _fail(str(e))

    out = Path(args.out) if args.out is not None else Path(case["case_dir"]) / "out"
    try:
        rc = run_job(case, out, ranks, args.restart, replace=args.replace)
    except (RestartError, outdir.OutDirError) as e:
        return _fail(str(e))
    if rc == 0:
        from orchestrator.run_record import summary_line

        line, passed = summary_line(out)
        print(line)
        if not passed:
            return 1
    return rc


def _damaged(out: Path, what: str, e: Exception) -> int:
    """One line for a file of OUT that could not be read (view, report)."""
    return _fail(f"OUT = {str(out)!r}: {what} damaged or not immerse's "
                 f"({type(e).__name__}: {' '.join(str(e).split())[:200]})")


def _reindex(out: Path) -> None:
    """An immerse output no run is writing gets its index rebuilt from its step files when the
    index does not list exactly them (a launcher killed by SIGKILL, a damaged results.h5): every
    completed output step readable and listed (orchestrator/output.py write_index)."""
    from orchestrator import outdir, output

    owner = outdir.read_owner(out)
    if owner is None or outdir._alive(owner.get("run")):
        return
    import warnings

    try:
        with warnings.catch_warnings():   # (its per-file warnings: one line below instead)
            warnings.simplefilter("ignore", UserWarning)
            output.write_index(out)
        outdir.record_written(out, out / output.INDEX_H5, out / output.INDEX_XDMF)
        found, _ = output._scan(out)
        bad = [path for role, steps in found.items() for index, path in steps
               if index not in {i for _, _, i in output.read_steps(out, role)}]
    except (OSError, output.OutputError, KeyError, ValueError):
        return   # (the readers below name what is wrong)
    if bad:   # a step file that cannot be read is left out of the index: say so, not in silence
        names = ", ".join(f"{output.STEPS_DIR}/{p.name}" for p in bad[:5]) + (f" and {len(bad) - 5} more" if len(bad) > 5 else "")
        print(f"immerse: warning: OUT = {str(out)!r}: {len(bad)} step file(s) damaged or unreadable, left "
              f"out of the index: {names}", file=sys.stderr)


def cmd_view(args) -> int:
    from orchestrator.output import OutputError
    from orchestrator.view import ViewError, render

    out = Path(args.out)
    _reindex(out)
    if not (out / "results.h5").is_file():
        return _fail(f"OUT = {str(out)!r}: no results.h5 there (run the case first)")
    steps = tuple(args.step) if args.step else ("last",)
    if args.list:
        from orchestrator.view import listing

        print(listing(out))
        return 0
    try:
        paths = render(out, fields=args.field or None, steps=steps, value_range=args.range, animate=args.movie)
    except (ViewError, OutputError) as e:
        return _fail(str(e))
    except (OSError, KeyError, ValueError, TypeError) as e:   # an index or step file damaged
        return _damaged(out, "its output files are", e)
    for p in paths:
        print(p)
    return 0


def cmd_plot(args) -> int:
    from orchestrator.plot import PlotError, listing, plot

    out = Path(args.out)
    if not out.is_dir():
        return _fail(f"OUT = {str(out)!r}: not a directory (a run's output directory)")
    try:
        if args.list:
            print(listing(out))
            return 0
        paths = plot(out, args.quantity, csv_too=args.csv)
    except PlotError as e:
        return _fail(str(e))
    except (OSError, KeyError, ValueError, TypeError) as e:   # a damaged diagnostics.h5
        return _damaged(out, "its diagnostics.h5 is", e)
    for p in paths:
        print(p)
    return 0


def cmd_keys(args) -> int:
    from orchestrator.keys import keys, markdown, select, text

    try:
        chosen = select(keys(), args.table)
    except ValueError as e:
        return _fail(str(e))
    print(markdown(chosen) if args.markdown else text(chosen), end="")
    return 0


def cmd_bench(args) -> int:
    from orchestrator import bench

    if args.name not in bench.BENCHES:
        return _fail(f"bench NAME = {args.name!r}: allowed: {', '.join(sorted(bench.BENCHES))}")
    out = Path(args.out or f"bench-{args.name}.json")
    if out.exists() and not out.is_file():
        return _fail(f"bench --out = {str(out)!r}: not a file path (a directory or special file); give "
                     f"the JSON file to write, e.g. {str(out / f'bench-{args.name}.json')!r}")
    from orchestrator.outdir import existing_ancestor

    blocked = existing_ancestor(out.parent)
    if not blocked.is_dir():
        return _fail(f"bench --out = {str(out)!r}: {str(blocked)!r} is not a directory")
    out.parent.mkdir(parents=True, exist_ok=True)  # (every bench writes its JSON and charts there)
    path = bench.BENCHES[args.name](out=out, quick=args.quick)
    print(path)
    return 0


def cmd_campaign(args) -> int:
    from orchestrator.campaign import run_campaign
    from orchestrator.case import CaseError

    only = {}
    for item in args.only or []:
        axis, sep, levels = item.partition("=")
        if not sep or not axis or not levels:
            return _fail(f"--only {item!r}: expected AXIS=LEVEL[,LEVEL...], e.g. zones=100,200")
        only[axis] = levels.split(",")
    try:
        if args.cores is not None and args.cores < 1:
            return _fail(f"--cores = {args.cores}: must be an integer >= 1")
        return run_campaign(args.campaign, args.out, engine=args.engine, retry_failed=args.retry_failed,
                            only=only or None, cores=args.cores)
    except CaseError as e:
        return _fail(str(e))


def cmd_report(args) -> int:
    from orchestrator.campaign.report import write_report

    out = Path(args.out)
    if not (out / "campaign.h5").is_file():
        return _fail(f"OUT = {str(out)!r}: no campaign.h5 there (run `immerse campaign` first)")
    from orchestrator.campaign.rundir import check_owned
    from orchestrator.case import CaseError

    try:  # the report overwrites report.* and figures/: only where the campaign wrote them
        check_owned(out, key="OUT")
        from orchestrator.campaign.collect import read_h5

        read_h5(out / "campaign.h5")
    except CaseError as e:
        return _fail(str(e))
    except (OSError, KeyError, ValueError, TypeError) as e:   # (json's errors are ValueErrors)
        return _damaged(out, "its campaign.h5 is", e)
    for p in write_report(out):
        print(p)
    return 0


def _version() -> str:
    """The installed distribution's version (pyproject.toml), else the source tree's."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("immerse")
    except PackageNotFoundError:
        import tomllib

        with open(Path(__file__).resolve().parent.parent / "pyproject.toml", "rb") as f:
            return tomllib.load(f)["project"]["version"]


class _Parser(argparse.ArgumentParser):
    """Command-line errors are bad input too: one line, exit 2 (argparse prints usage + error)."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"immerse: {' '.join(message.split())} (see {self.prog} --help)\n")


def main(argv=None) -> int:
    ap = _Parser(prog="immerse", description=__doc__.split("\n")[0])
    ap.add_argument("--version", action="version", version=f"immerse {_version()}")
    sub = ap.add_subparsers(dest="verb", required=True)
    p = sub.add_parser("check", help="validate a case directory")
    p.add_argument("case")
    p.add_argument("--ranks", nargs="*", metavar="ROLE=N", help="ranks per solver, as for run")
    _add_machine_flags(p)
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("run", help="run a case directory")
    p.add_argument("case")
    p.add_argument("--out", help="output directory (default CASE/out)")
    p.add_argument("--ranks", nargs="*", metavar="ROLE=N", help="ranks per solver, e.g. lagrange=2")
    p.add_argument("--restart", help="checkpoint file (OUT/checkpoints/checkpoint_*.h5) of this case; "
                                     "continues its run in its own output directory")
    p.add_argument("--replace", action="store_true",
                   help="replace an earlier output of this case in OUT: deletes only the files immerse "
                        "wrote there")
    p.add_argument("--engine", choices=("local", "slurm"), default="local",
                   help="local: run here (default); slurm: submit one batch job whose mpiexec spans its "
                        "allocation, and follow it")
    _add_machine_flags(p)
    p.set_defaults(func=cmd_run)
    p = sub.add_parser("view", help="render PNG pictures of a run's output",
                       description="Render PNG pictures of a run's output steps to OUT/pictures/ (1-D runs as "
                       "line plots against the exact solution where the case's check has one).")
    p.add_argument("out")
    p.add_argument("--field", nargs="*", help="fields to draw (default: all the output holds; an unknown "
                   "one is refused with the list of those it has)")
    p.add_argument("--step", nargs="*", help="output steps: first, last (default), all, or indices")
    p.add_argument("--range", choices=("fixed", "step"), default=None,
                   help="fixed: one colour (value) range for all steps drawn (default for several "
                        "steps); step: each step's own")
    p.add_argument("--movie", action="store_true", help="also an animated GIF per field of the steps "
                   "drawn (OUT/pictures/<role>_<field>.gif)")
    p.add_argument("--list", action="store_true", help="list the output's fields (with units) and steps, "
                   "draw nothing")
    p.set_defaults(func=cmd_view)
    p = sub.add_parser("plot", help="draw a run's time histories (diagnostics, probes) against time",
                       description="Draw time histories of a run (OUT/diagnostics.h5) against time, with the "
                       "case's check's reference curve where it has one, to OUT/plots/.")
    p.add_argument("out")
    p.add_argument("quantity", nargs="*", help="<role>.<name> as diagnostics.h5 holds it, a pattern "
                   "('*.total_energy') or a probe's name; none: the probes, else the total energies")
    p.add_argument("--csv", action="store_true", help="also write the histories as CSV")
    p.add_argument("--list", action="store_true", help="list the run's histories with their units")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("keys", help="the reference of every case.toml key (from the case schema)",
                       description="Print every case.toml key the case schema knows: its type or allowed "
                       "values, unit, range, default and meaning (the README's reference is this, --markdown).")
    p.add_argument("table", nargs="?", help="only the keys under this table or key, e.g. run, "
                   "ale.materials, lagrange.bodies")
    p.add_argument("--markdown", action="store_true", help="as Markdown tables (the README's reference)")
    p.set_defaults(func=cmd_keys)
    p = sub.add_parser("campaign", help="run a validation campaign (cases x parameters) and its report")
    p.add_argument("campaign", help="the campaign file (or a directory holding campaign.toml)")
    p.add_argument("--out", help="output directory (default: CAMPAIGN_DIR/out); an interrupted "
                                 "campaign continues there")
    p.add_argument("--engine", choices=("local", "slurm"), default="local",
                   help="local: child processes on this machine (default); slurm: one sbatch job array")
    p.add_argument("--retry-failed", action="store_true",
                   help="run again the runs that failed, were unstable or timed out")
    p.add_argument("--cores", type=int, metavar="N", help="cores the local engine may use (default: all "
                   "of this machine's); a run takes as many as its solvers have ranks")
    p.add_argument("--only", nargs="*", metavar="AXIS=LEVELS",
                   help="run only these levels of an axis, e.g. zones=100,200, or these series, "
                        "series=NAME,NAME (a reduced matrix)")
    p.set_defaults(func=cmd_campaign)
    p = sub.add_parser("report", help="rebuild a campaign's report from its stored results")
    p.add_argument("out")
    p.set_defaults(func=cmd_report)
    p = sub.add_parser("bench", help="run a benchmark, write bench-NAME.json")
    p.add_argument("name", help="the benchmark (listed below)")
    plain_help = p.format_help

    def bench_help():   # (the benches' registry takes ~2 s to import: only for --help)
        from orchestrator import bench

        return plain_help() + "\nbenchmarks: " + ", ".join(sorted(bench.BENCHES)) + "\n"

    p.format_help = bench_help
    p.add_argument("--out")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.set_defaults(func=cmd_bench)
    args = ap.parse_args(argv)
    try:
        rc = args.func(args)
    except KeyboardInterrupt:
        # Ctrl-C before a job runs (checking the case, rendering): nothing was launched; while a job
        # runs, launch.py handles the signal itself and ends the job in order
        print("immerse: interrupted (SIGINT)", file=sys.stderr)
        return 130
    if argv is None and args.verb in ("run", "check"):
        _exit_program(rc)
    return rc


def _exit_program(rc: int) -> None:
    """The `immerse` program's end after check and run (main() called without arguments, as the
    console script does): its output flushed, exit at once instead of the interpreter's teardown
    (freeing numpy's and h5py's modules took 50-60 ms of every run and check; the job's processes
    are gone and every file is closed by then). A flush that fails (a closed pipe) leaves the
    ordinary exit to report it."""
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):
        return
    os._exit(rc)


if __name__ == "__main__":
    sys.exit(main())
