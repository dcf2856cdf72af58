"""The output bench (`output`): the cost of a step file and of the appended index per output step,
and the elastic bar's wall time as outputs are added.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, machine


def _bar_wave_fields(rng, nn: int, ne: int) -> tuple[dict, dict]:
    """The fields the Lagrange adapter writes for one output step (random values)."""
    point = {"velocity": rng.normal(size=(nn, 3)), "displacement": rng.normal(size=(nn, 3))}
    stress = rng.normal(size=(ne, 6))
    cell = {"stress": stress, "von_mises_stress": rng.random(ne), "pressure": rng.normal(size=ne),
            "plastic_strain": rng.random(ne), "temperature": rng.random(ne), "density": rng.random(ne),
            "bulk_viscosity": rng.random(ne)}
    return point, cell


def time_outputs(n_outputs: int, tmp: Path) -> dict:
    """Write ``n_outputs`` steps of the 400-element bar wave as a run does (step file, then the
    in-memory index appends); seconds per output of the step file and of the index."""
    from orchestrator import output
    from solvers.lagrange.mesh import box_mesh

    mesh = box_mesh([0.0, 0.0, 0.0], [0.1, 0.0025, 0.0025], [400, 1, 1])
    out = tmp / f"outputs_{n_outputs}"
    tmp.mkdir(parents=True, exist_ok=True)
    output.write_mesh(out, "lagrange", mesh.cells, mesh.cell_type)
    index = output.OutputIndex(out)
    rng = np.random.default_rng(0)
    point, cell = _bar_wave_fields(rng, mesh.num_points, mesh.num_cells)
    step_s, index_s = [], []
    for i in range(n_outputs):
        t0 = time.perf_counter()
        output.write_step(out, "lagrange", i, 10 * i, 1e-7 * i, mesh.points, point, cell)
        t1 = time.perf_counter()
        index.append(i, ["lagrange"])
        step_s.append(t1 - t0)
        index_s.append(time.perf_counter() - t1)
    # the appended index must equal the one rebuilt from every step file
    appended = _index_contents(out)
    output.OutputIndex(out)
    if _index_contents(out) != appended:
        raise RuntimeError(f"appended index of {n_outputs} outputs differs from the rebuilt one")
    return {"step": np.array(step_s), "index": np.array(index_s)}


def _index_contents(out: Path):
    """What a reader gets from results.h5 and results.xdmf (the append room's padding aside)."""
    import re

    import h5py

    from orchestrator import output

    xdmf = re.sub(rb"<\?immerse-append +\?>", b"<?immerse-append ?>", (out / output.INDEX_XDMF).read_bytes())
    items = []
    with h5py.File(out / output.INDEX_H5, "r") as f:
        def visit(name, link):
            if isinstance(link, h5py.ExternalLink):
                items.append((name, link.filename, link.path))
            elif isinstance(link, h5py.HardLink) and isinstance(f[name], h5py.Dataset):
                items.append((name, str(f[name].dtype), f[name][()].tolist()))
        f.visititems_links(visit)
        items += sorted((g, k, str(v)) for g in [""] + list(f) for k, v in f[g or "/"].attrs.items())
    return xdmf, items


def _bar_wave_run(n_outputs: int, tmp: Path) -> dict:
    """cases/elastic_bar_wave with output_interval = end_time / n_outputs, through the launcher."""
    from orchestrator.case import load_case, ranks_for
    from orchestrator.launch import run_job

    src = Path(__file__).resolve().parents[2] / "cases" / "elastic_bar_wave"
    text = (src / "case.toml").read_text()
    old = "output_interval = 1.0e-6"
    if old not in text:
        raise RuntimeError(f"cases/elastic_bar_wave/case.toml no longer has the line {old!r}")
    d = tmp / f"bar_wave_{n_outputs}"
    d.mkdir()
    (d / "case.toml").write_text(text.replace(old, f"output_interval = {16.0e-6 / n_outputs!r}"))
    case = load_case(d)
    t0 = time.perf_counter()
    rc = run_job(case, d / "out", ranks_for(case, {}))
    wall = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"elastic_bar_wave with {n_outputs} outputs failed (exit {rc})")
    s = json.loads((d / "out" / "summary.json").read_text())
    written = len(list((d / "out" / "steps").glob("lagrange_[0-9]*.h5")))
    return {"launcher_wall_s": wall, "coupler_wall_s": s["wall_time_s"], "steps": s["steps"],
            "output_steps": written}


@bench("output")
def bench_output(out: Path, quick: bool = False) -> Path:
    """Cost of one output step against the number of outputs before it: the 400-element bar wave's
    fields written 10, 100, 1000 times (step file + index append; metric: median of the last 10
    outputs of the run, so the cost of an output with n-1 before it; the mean over the run includes
    the rare full rewrites of results.xdmf); then cases/elastic_bar_wave run with 12, 60 and 240
    outputs through the launcher (each output added should cost the same: its write)."""
    import tempfile

    counts = [10, 100] if quick else [10, 100, 1000]
    runs = [12, 48] if quick else [12, 60, 240]
    rounds = 1 if quick else 5  # the counts interleaved, so that the machine's load hits them alike
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        timings = {n: [] for n in counts}
        for r in range(rounds):
            for n in counts:
                timings[n].append(time_outputs(n, Path(tmp) / f"round_{r}"))
        first = None
        for n in counts:
            def per_round(stat, part):
                return float(np.median([stat(part(t)) for t in timings[n]])) * 1e3
            tail = max(10, n // 10)
            last = lambda a: np.median(a[-tail:])  # noqa: E731
            value = per_round(last, lambda t: t["step"] + t["index"])
            first = first or value
            tenth = max(1, n // 10)
            drift = float(np.median([np.median(t["step"][-tenth:] + t["index"][-tenth:])
                                     / np.median(t["step"][:tenth] + t["index"][:tenth]) for t in timings[n]]))
            results.append({"name": "output_bar_wave_400", "metric": "time_per_output", "value": value, "unit": "ms",
                            "params": {"outputs": n, "rounds": rounds,
                                       "of": f"median over the rounds of the median of the last {tail} outputs of a "
                                             "run of n (step file + index append)",
                                       "step_file_ms": per_round(last, lambda t: t["step"]),
                                       "index_append_ms": per_round(last, lambda t: t["index"]),
                                       "last_tenth_over_first_tenth": drift,
                                       "mean_per_output_ms": per_round(np.mean, lambda t: t["step"] + t["index"]),
                                       "mean_index_append_ms": per_round(np.mean, lambda t: t["index"]),
                                       "max_index_append_ms": per_round(np.max, lambda t: t["index"]),
                                       "ratio_to_10_outputs": value / first}})
        walls = [_bar_wave_run(n, Path(tmp)) for n in runs]
    write_ms = results[-1]["value"]
    for n, w in zip(runs, walls):
        results.append({"name": "elastic_bar_wave", "metric": "wall_time", "value": w["coupler_wall_s"], "unit": "s",
                        "params": {"output_interval": f"end_time/{n}", **w}})
    # a constant cost per output: the wall time grows by the same amount for every output added
    for lo, hi in zip(walls, walls[1:]):
        extra = hi["output_steps"] - lo["output_steps"]
        results.append({"name": "elastic_bar_wave", "metric": "wall_time_per_extra_output",
                        "value": (hi["coupler_wall_s"] - lo["coupler_wall_s"]) / extra * 1e3, "unit": "ms",
                        "params": {"outputs": [lo["output_steps"], hi["output_steps"]],
                                   "write_time_per_output_ms": write_ms,
                                   "note": "coupler wall time difference over the extra output steps; compare with "
                                           "write_time_per_output_ms (step file + index alone, time_per_output at "
                                           "the largest count); the rest is the adapter's gather and the command's "
                                           "round trip"}})
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out
