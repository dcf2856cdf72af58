"""`immerse bench subcycling`: element subcycling (solvers/lagrange/subcycling.py) against the
single-rate step on a body whose refined corner sets the step.

The body: cases/cantilever_refined_corner's steel cantilever (200 x 20 mm, clamped at x = 0, an
initial transverse velocity 25 x^2 m/s), its structured mesh drawn toward the clamped corner
(solvers.lagrange.mesh.drawn_toward: the corner element about 8 times smaller than the rest), at
several sizes in 2-D (quads) and 3-D (hexahedra, 5 mm wide, drawn toward the corner edge's end).
Each is run over the same span of time single-rate and subcycled (lagrange.subcycling = 16), in this
process at 0.9 of the stable step (the case's dt_scale), three times; per run: the median wall time
of the stepping (set-up and kernel compilation excluded), the steps, the element evaluations per
major step against every element at every substep, and the largest difference of the tip's
deflection over the span, relative to its largest deflection."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.coupling_studies import _figure
from orchestrator.bench.registry import bench, machine

STEEL = {"model": "linear_elastic", "density": 7850.0, "youngs_modulus": 200e9, "poisson_ratio": 0.3}


def beam_case(mesh_file: Path, dim: int, ratio: int) -> dict:
    return {"name": "bench", "case_dir": str(mesh_file.parent), "run": {"dimension": dim, "end_time": 1.0},
            "materials": {"steel": dict(STEEL)},
            "lagrange": {"subcycling": ratio,
                         "bodies": [{"name": "beam", "material": "steel", "mesh": {"file": str(mesh_file)},
                                     "initial_velocity": [0.0, "25.0 * x * x"] + [0.0] * (dim - 2)}]},
            "boundaries": [{"type": "fixed", "region": "x < 1e-9"}]}


def write_mesh(path: Path, cells: list[int]) -> Path:
    """The cantilever's mesh, ``cells`` along x, y (and z), drawn toward the clamped corner over 3
    elements' width with power 3 (the shipped case's 80 x 8: the corner element 8.1 times smaller)."""
    import meshio

    from solvers.lagrange.mesh import box_mesh, drawn_toward

    upper = [0.2, 0.02, 0.005][: len(cells)]
    mesh = drawn_toward(box_mesh([0.0] * len(cells), upper, cells), [0.0] * len(cells), 3 * 0.2 / cells[0], 3.0)
    pts = mesh.points if mesh.dim == 3 else np.c_[mesh.points, np.zeros(len(mesh.points))]
    meshio.write(path, meshio.Mesh(pts, [(mesh.cell_type, mesh.cells)]))
    return path


def run_span(case: dict, span: float) -> dict:
    """The solver over ``span`` seconds at 0.9 of its stable step: wall time, steps, tip history."""
    from mpi4py import MPI

    from solvers.lagrange.integrators import solver_for

    s = solver_for(case)(MPI.COMM_SELF, case)
    top = s.X[:, 0] >= s.X[:, 0].max() - 1e-12
    t, n, tip, times = 0.0, 0, [], []
    t0 = time.perf_counter()
    while t < span * (1.0 - 1e-12):
        dt = min(0.9 * s.stable_dt(), span - t)
        s.predict(dt)
        t += dt
        n += 1
        s.correct(None, step=n, time=t)
        times.append(t)
        tip.append(float(np.mean(s.x[top, 1] - s.X[top, 1])))
    wall = time.perf_counter() - t0
    d = s.diagnostics()
    return {"wall": wall, "steps": n, "t": np.array(times), "tip": np.array(tip), "elements": s.n_cells_global,
            "share": d.get("subcycling_element_share", 1.0), "substeps": d.get("subcycling_substeps", 1.0),
            "energy_balance_rel": d["energy_balance_rel"], "momentum_balance_rel": d["momentum_balance_rel"]}


def measure(sizes, span: float, repeats: int, tmp: Path) -> list[dict]:
    rows = []
    for cells in sizes:
        dim = len(cells)
        mesh = write_mesh(tmp / f"beam_{'x'.join(map(str, cells))}.vtu", cells)
        runs = {}
        for ratio in (1, 16):
            case = beam_case(mesh, dim, ratio)
            run_span(case, 20 * span / 1000)   # (kernels compiled and warm)
            got = [run_span(case, span) for _ in range(repeats)]
            runs[ratio] = dict(got[0], wall=float(np.median([g["wall"] for g in got])))
        a, b = runs[1], runs[16]
        diff = np.abs(np.interp(b["t"], a["t"], a["tip"]) - b["tip"]).max() / np.abs(a["tip"]).max()
        rows.append({"cells": cells, "dim": dim, "elements": a["elements"], "single": a, "subcycled": b,
                     "tip_difference": float(diff), "speedup": a["wall"] / b["wall"]})
    return rows


def results(rows, span: float, repeats: int) -> list[dict]:
    out = []
    for r in rows:
        name = f"cantilever_{r['dim']}d_{'x'.join(map(str, r['cells']))}"
        params = {"elements": r["elements"], "span_s": span, "repeats": repeats}
        for mode in ("single", "subcycled"):
            m = r[mode]
            p = dict(params, steps=m["steps"], substeps_per_step=m["substeps"], element_share=m["share"],
                     energy_balance_rel=m["energy_balance_rel"], momentum_balance_rel=m["momentum_balance_rel"])
            out.append({"name": f"{name}_{mode}", "metric": "wall_time", "value": m["wall"], "unit": "s", "params": p})
        out.append({"name": name, "metric": "speedup_single_over_subcycled", "value": r["speedup"], "unit": "x",
                    "params": params})
        out.append({"name": name, "metric": "tip_difference_over_peak", "value": r["tip_difference"], "unit": "1",
                    "params": params})
    return out


def draw(rows, path: Path) -> None:
    plt, fig, (ax1, ax2) = _figure(2)
    for dim, style in ((2, "o-"), (3, "s-")):
        sel = [r for r in rows if r["dim"] == dim]
        if not sel:
            continue
        ne = [r["elements"] for r in sel]
        ax1.loglog(ne, [r["single"]["wall"] for r in sel], style, color="tab:red", label=f"{dim}-D single-rate")
        ax1.loglog(ne, [r["subcycled"]["wall"] for r in sel], style, color="tab:blue", label=f"{dim}-D subcycled")
        ax2.semilogx(ne, [r["speedup"] for r in sel], style, label=f"{dim}-D speed-up")
        ax2.semilogx(ne, [1.0 / r["subcycled"]["share"] for r in sel], style.replace("-", "--"), color="grey",
                     label=f"{dim}-D element evaluations saved (bound)")
    ax1.set(xlabel="elements", ylabel="wall time of the span (s)", title="refined-corner cantilever")
    ax2.set(xlabel="elements", ylabel="single-rate / subcycled", ylim=(0, None))
    ax1.legend(fontsize=8)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


@bench("subcycling")
def bench_subcycling(out: Path, quick: bool = False) -> Path:
    import tempfile

    sizes = [[80, 8], [40, 4, 1]] if quick else [[80, 8], [160, 16], [320, 32], [80, 8, 2], [160, 16, 4]]
    span = 2e-5 if quick else 1e-4
    repeats = 1 if quick else 3
    with tempfile.TemporaryDirectory() as tmp:
        rows = measure(sizes, span, repeats, Path(tmp))
    draw(rows, out.with_suffix(".png"))
    out.write_text(json.dumps({"results": results(rows, span, repeats), "machine": machine(),
                               "chart": out.with_suffix(".png").name}, indent=2))
    return out
