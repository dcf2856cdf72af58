"""`immerse bench coupling`: the embedded-mesh coupling's stability and speed (DESIGN.md, "The
constraint solve"), written as bench-coupling.json (the benches' format, orchestrator/bench/__init__.py:
medians of repeated runs, params) and three charts next to it.

1. Conditioning: cond(H) of the multiplier system over grid refinement for random straight cuts,
   stabilised and not (orchestrator/coupling/conditioning.py), 2-D h = 1/8..1/64 and 3-D
   h = 1/4..1/16.  The claims: the stabilised maximum stays within a factor 2 over the sweep; the
   unstabilised one grows as h -> 0.  Chart coupling_conditioning.png.
2. Coupler cost against interface size: a regular n-gon body (n = 100 .. 10000 facets, facet length
   one zone width) through the coupler's per-step work, EmbeddedCoupling.geometry() (clip, blocked
   fractions and face coverages with the interior as runs, operators) and .solve() (the multiplier
   solve, H applied without assembly) on synthetic
   background data; time per step and per facet, split by stage.  The claim: the per-facet cost
   stays within 2x over the range.  Chart coupling_cost_per_facet.png.
3. Coupled-step share: a 2-D elastic block (~1e3 surface facets) in a gentle uniform gas flow on
   ~1e5 zones, stepped through coupling.inprocess.InProcess, against the uncoupled ALE and
   Lagrangian steps on the same meshes, timed in the same rounds (interleaved, so the load of the
   machine hits all alike); the coupler's share of the coupled step (target <= 10 %) and the coupled
   step over the sum of the uncoupled ones (target <= 1.15).  Chart coupling_step_share.png.

Timings exclude numba compilation (a warm-up call first); nothing here asserts a time.
"""
from __future__ import annotations

import contextlib
import cProfile
import json
import pstats
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from unittest import mock

import numpy as np

from orchestrator.bench.registry import bench, machine


# ---- timing helpers ------------------------------------------------------------------------------
class _Clock:
    """Accumulated wall time per key of the functions it wraps."""

    def __init__(self):
        self.t = defaultdict(float)

    def wrap(self, key: str, fn):
        def timed(*args, **kw):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                self.t[key] += time.perf_counter() - t0

        return timed

    def take(self) -> dict:
        out, self.t = dict(self.t), defaultdict(float)
        return out


def _chart(path: Path, draw) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    draw(ax)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---- 1. conditioning -----------------------------------------------------------------------------
def conditioning(quick: bool) -> tuple[list, list]:
    """Results of the cond(H) sweeps and the sweeps themselves (for the chart)."""
    from orchestrator.coupling.conditioning import conditioning_sweep

    sweeps = [conditioning_sweep(2, (1 / 8, 1 / 16, 1 / 32, 1 / 64), seeds=range(12 if quick else 32)),
              conditioning_sweep(3, (1 / 4, 1 / 8, 1 / 16), seeds=range(4 if quick else 8))]
    results = []
    for sw in sweeps:
        name = f"coupling_conditioning_{sw['dim']}d"
        seeds = len(sw["stabilised"]["all"][0])
        common = {"alpha": sw["alpha"], "beta": sw["beta"], "condition": sw["condition"], "seeds": seeds,
                  "dt": "0.5 h", "density": 1.0, "cut": "random straight cut through the unit box"}
        for series in ("stabilised", "unstabilised"):
            for i, h in enumerate(sw["h"]):
                results.append({"name": name, "metric": "cond_H_max", "value": sw[series]["max"][i], "unit": "",
                                "params": {**common, "h": h, "series": series,
                                           "median": sw[series]["median"][i], "cut_zones_mean": sw["zones"][i]}})
        stab_max = sw["stabilised"]["max"]
        ratio = max(stab_max) / min(stab_max)
        results.append({"name": name, "metric": "stabilised_max_ratio_over_sweep", "value": ratio, "unit": "x",
                        "params": {**common, "h": sw["h"], "claim": "< 2", "holds": bool(ratio < 2.0)}})
        growth = sw["unstabilised"]["median"][-1] / max(stab_max)
        results.append({"name": name, "metric": "unstabilised_median_finest_over_stabilised_max", "value": growth,
                        "unit": "x", "params": {**common, "h_finest": sw["h"][-1]}})
    return results, sweeps


def _draw_conditioning(sweeps):
    colours = {(2, "stabilised"): "tab:blue", (2, "unstabilised"): "tab:red",
               (3, "stabilised"): "tab:cyan", (3, "unstabilised"): "tab:orange"}

    def draw(ax):
        for sw, style in zip(sweeps, ("-o", "--s")):
            d = sw["dim"]
            for series in ("stabilised", "unstabilised"):
                colour = colours[(d, series)]
                ax.loglog(sw["h"], sw[series]["max"], style, color=colour, label=f"{d}-D {series}, max")
                ax.loglog(sw["h"], sw[series]["median"], style[:-1] + "x", color=colour, alpha=0.6,
                          label=f"{d}-D {series}, median")
        hs = sorted({h for sw in sweeps for h in sw["h"]}, reverse=True)
        ax.set_xticks(hs, [f"1/{round(1 / h)}" for h in hs])
        ax.minorticks_off()
        ax.set_xlim(hs[0] * 1.3, hs[-1] / 1.3)  # refinement to the right
        top = max(max(sw["unstabilised"]["max"]) for sw in sweeps)
        ax.set_ylim(1.0, top * 1e4)  # room for the legend above the data
        ax.set_xlabel("zone width h (m, unit box)")
        ax.set_ylabel("cond(H) = λ_max / λ_min (dimensionless)")
        ax.set_title("Multiplier system H over grid refinement, random straight cuts; max and median over seeds\n"
                     f"(stabilised: α = {sweeps[0]['alpha']:g}, β = {sweeps[0]['beta']:g}; unstabilised: "
                     "1/α = β = 0)", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=7, ncol=2, loc="upper left")

    return draw


# ---- 2. coupler cost against interface size ------------------------------------------------------
H_ZONE = 1e-2  # m, zone width of the cost study's grid


def polygon_coupling(n: int, seed: int = 0):
    """An EmbeddedCoupling holding one regular n-gon body (facets one zone width long, counter-
    clockwise: outward normals) in a square grid three zones wider than it on every side; unit
    density (node masses h^2 on both sides, as conditioning_sweep), random small velocities."""
    from orchestrator.coupling.embedded import EmbeddedCoupling

    h = H_ZONE
    radius = h / (2.0 * np.sin(np.pi / n))
    theta = 2.0 * np.pi * np.arange(n) / n
    # the centre off the grid's lattice so vertices do not sit on grid planes systematically
    centre = np.array([0.31, 0.17]) * h
    x = centre + radius * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    cells = 2 * int(np.ceil(radius / h + 3.0))
    half = 0.5 * cells * h
    case = {"ale": {"grid": {"lower": [-half, -half], "upper": [half, half], "cells": [cells, cells]}},
            "coupling": {"method": "multiplier"}}
    rng = np.random.default_rng(seed)
    surface = {"facets": np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1), "body": np.zeros(n, np.int64),
               "mass": np.full(n, h * h), "free": np.ones((n, 2)), "x": x, "v": 1e-3 * rng.standard_normal((n, 2))}
    return EmbeddedCoupling(case, surface), cells


def _background_buffer(c, rng) -> np.ndarray:
    """EmbeddedCoupling.solve's background buffer [v* (nb, dim), m (nb), R (nc, dim)]: random small
    velocities, node masses h^2, a uniform 1 Pa on the surface (R_e = p a_e)."""
    ops = c.ops
    nb = ops.bnodes.size
    R = 1.0 * ops.area[:, None] * ops.normal
    return np.concatenate([1e-3 * rng.standard_normal(nb * c.dim), np.full(nb, H_ZONE**2), R.ravel()])


def coupler_step_cost(n: int, repeats: int) -> dict:
    """Median wall times of EmbeddedCoupling.geometry() + .solve() for the n-gon, split by stage
    (the stages timed inside the real calls by wrapping the functions embedded.py calls)."""
    from orchestrator.coupling import embedded
    from orchestrator.coupling.operators import Operators

    c, cells = polygon_coupling(n)
    rng = np.random.default_rng(1)
    dt = 0.5 * H_ZONE  # unit wave speed, as conditioning_sweep
    clock = _Clock()
    samples = defaultdict(list)
    with contextlib.ExitStack() as stack:
        for key, attr in (("clip", "clip_surface"), ("coverage", "coverage")):
            stack.enter_context(mock.patch.object(embedded, attr, clock.wrap(key, getattr(embedded, attr))))
        stack.enter_context(mock.patch.object(embedded, "Operators",
                                              type("TimedOperators", (), {"build": staticmethod(
                                                  clock.wrap("operators", Operators.build))})))
        for r in range(repeats + 1):  # round 0 warms up (numba kernels compiled or loaded)
            clock.take()
            t0 = time.perf_counter()
            body = c.geometry()
            t1 = time.perf_counter()
            buf = _background_buffer(c, rng)
            vstar = c.v + 1e-3 * rng.standard_normal(c.v.shape)
            c.state = c.method.new_state()  # a cold start: no warm λ from an identical previous solve
            t2 = time.perf_counter()
            c.solve(dt, dt, vstar, buf)
            t3 = time.perf_counter()
            if r == 0:
                continue
            parts = clock.take()
            samples["geometry"].append(t1 - t0)
            samples["solve"].append(t3 - t2)
            samples["step"].append((t1 - t0) + (t3 - t2))
            for k, v in parts.items():
                samples[k].append(v)
            samples["iterations"].append(c.last.iterations)
    med = {k: float(np.median(v)) for k, v in samples.items()}
    return {"facets": n, "cells": [cells, cells], "cut_zones": int(c.ops.zones.size),
            "blocked_zones": int(body.zones.size),
            "pieces": int(c.pieces.zone.size), "repeats": repeats, **med}


COST_STAGES = (("clip", "clip_surface"), ("coverage", "coverage: fractions and face coverages (interior as runs)"),
               ("operators", "Operators.build"), ("solve", "multiplier solve"))


def coupler_cost(quick: bool) -> tuple[list, list]:
    sizes = (100, 300, 1000) if quick else (100, 300, 1000, 3000, 10000)
    # the same measuring time per size (~2e4 facet-steps): a small surface's step takes well under a
    # millisecond, and the median of five of them is mostly the machine's noise
    rows = [coupler_step_cost(n, repeats=max(3, (2000 if quick else 20000) // n)) for n in sizes]
    results = []
    for row in rows:
        n = row["facets"]
        params = {"facets": n, "grid_cells": row["cells"], "cut_zones": row["cut_zones"], "pieces": row["pieces"],
                  "blocked_zones": row["blocked_zones"],
                  "repeats": row["repeats"], "cg_iterations": row["iterations"], "zone_width_m": H_ZONE,
                  "facet_length_zones": 1.0,
                  "stages_ms": {k: row[k] * 1e3 for k, _ in COST_STAGES},
                  "geometry_ms": row["geometry"] * 1e3,
                  "note": "EmbeddedCoupling.geometry() + .solve() (cold CG start) on a regular n-gon"}
        results.append({"name": "coupler_step_2d_polygon", "metric": "time_per_step", "value": row["step"] * 1e3,
                        "unit": "ms", "params": params})
        results.append({"name": "coupler_step_2d_polygon", "metric": "time_per_facet_step",
                        "value": row["step"] / n * 1e6, "unit": "us", "params": {"facets": n}})
    per = [r["step"] / r["facets"] for r in rows]
    results.append({"name": "coupler_step_2d_polygon", "metric": "per_facet_cost_max_over_min",
                    "value": max(per) / min(per), "unit": "x",
                    "params": {"facets": list(sizes), "claim": "within 2x", "holds": bool(max(per) / min(per) <= 2.0)}})
    return results, rows


def _draw_cost(rows):
    def draw(ax):
        n = np.array([r["facets"] for r in rows], dtype=float)
        ax.loglog(n, [r["step"] / r["facets"] * 1e6 for r in rows], "ko-", lw=2, label="whole coupler step")
        for (key, label), marker in zip(COST_STAGES, "sv^Dx"):
            ax.loglog(n, [max(r[key], 1e-9) / r["facets"] * 1e6 for r in rows], marker + "--", label=label)
        ax.set_xlabel("surface facets (regular polygon, facet length = zone width)")
        ax.set_ylabel("wall time per facet per step (µs)")
        ax.set_title("Coupler cost per facet against interface size, 2-D polygon, 1 core (medians, no compilation)\n"
                     "(a body's interior goes to the background as runs of zones: no stage lists it zone by zone)",
                     fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)

    return draw


# ---- 3. coupled-step share -----------------------------------------------------------------------
SCENE = """# immerse bench coupling: an elastic block in a gentle uniform gas flow (Mach 0.085), periodic box
[run]
dimension = 2
end_time = 1.0

[ale]
mode = "eulerian"
grid = {{ lower = [0.0, 0.0], upper = [1.0, 1.0], cells = [{zones}, {zones}] }}
boundaries = {{ x_lower = "periodic", x_upper = "periodic", y_lower = "periodic", y_upper = "periodic" }}
materials.gas = {{ eos = "ideal_gas", gamma = 1.4 }}
regions = [ {{ material = "gas", density = 1.0, pressure = 1.0, velocity = [0.1, 0.0] }} ]

# wave speed 1 m/s (the gas's 1.18): steps alike; p / E = 1 %: the block is squeezed gently
[materials.block]
model = "linear_elastic"
density = 100.0
youngs_modulus = 100.0
poisson_ratio = 0.3

# edges off the grid planes; elements about one zone wide
[[lagrange.bodies]]
name = "block"
material = "block"
mesh = {{ box = {{ lower = [0.103, 0.103], upper = [0.897, 0.897], cells = [{elements}, {elements}] }} }}

[coupling]
method = "multiplier"
condition = "slip"
"""


def step_share(quick: bool) -> tuple[list, dict]:
    from mpi4py import MPI

    from orchestrator.case import load_case
    from orchestrator.coupling.inprocess import InProcess
    from solvers.ale.solver import AleSolver
    from solvers.lagrange.solver import LagrangeSolver

    zones, elements, warm, rounds = (100, 80, 2, 6) if quick else (316, 250, 3, 30)
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "case.toml").write_text(SCENE.format(zones=zones, elements=elements))
        case = load_case(tmp)
    comm = MPI.COMM_SELF
    coupled = InProcess(case)
    ale = AleSolver(comm, case["ale"])  # the same grid and gas, no bodies
    lag = LagrangeSolver(comm, case)  # the same block, no gas
    clock = _Clock()
    c = coupled.coupling
    for key in ("geometry", "solve", "background_correction"):  # instance attributes shadow the methods
        setattr(c, key, clock.wrap(key, getattr(c, key)))
    t_ale = t_lag = 0.0
    samples = defaultdict(list)
    for r in range(warm + rounds):
        dt = coupled.dt_scale * min(coupled.lag.stable_dt(), coupled.ale.stable_dt())
        clock.take()
        t0 = time.perf_counter()
        coupled.advance(dt)
        t1 = time.perf_counter()
        parts = clock.take()
        t_ale += dt
        ale.predict(dt)
        ale.correct(None, step=r + 1, time=t_ale)
        ale.remap(None)
        t2 = time.perf_counter()
        t_lag += dt
        lag.predict(dt)
        lag.correct(None, step=r + 1, time=t_lag)
        t3 = time.perf_counter()
        if r < warm:  # compilation (or cache loads) and first touches
            continue
        samples["coupled"].append(t1 - t0)
        samples["ale"].append(t2 - t1)
        samples["lagrange"].append(t3 - t2)
        samples["coupler"].append(sum(parts.values()))
        for k, v in parts.items():
            samples["coupler_" + k].append(v)
        samples["cg_iterations"].append(c.last.iterations)
    med = {k: float(np.median(v)) for k, v in samples.items()}
    # the profile of a few more coupled steps: where the time goes (cumulative names for the report)
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(3 if quick else 5):
        coupled.advance(coupled.dt_scale * min(coupled.lag.stable_dt(), coupled.ale.stable_dt()))
    prof.disable()
    top = sorted(pstats.Stats(prof).stats.items(), key=lambda kv: -kv[1][2])[:10]
    profile = [(fn if f == "~" else f"{Path(f).parent.name}/{Path(f).name}:{fn}") + f" {tt * 1e3:.1f} ms"
               for (f, _, fn), (_, _, tt, _, _) in top]  # ("~": numpy's and Python's builtins)
    geo = c.geometry()  # zones with a blocked fraction: listed (cut) and in runs (covered whole)
    covered = int(geo.zones.size + geo.run_length.sum())
    share = med["coupler"] / med["coupled"]
    over = med["coupled"] / (med["ale"] + med["lagrange"])
    params = {"zones": zones**2, "elements": elements**2, "surface_facets": int(c.facets.shape[0]),
              "cut_zones": int(c.ops.zones.size), "covered_zones": covered, "listed_zones": int(geo.zones.size),
              "runs": int(geo.run_length.size), "rounds": rounds, "warm_up_rounds": warm,
              "dt_s": float(coupled.dt_prev), "condition": "slip", "method": "multiplier",
              "ms": {k: v * 1e3 for k, v in med.items() if k != "cg_iterations"},
              "cg_iterations_median": med["cg_iterations"]}
    results = [
        {"name": "coupled_step_2d_block", "metric": "time_per_step", "value": med["coupled"] * 1e3, "unit": "ms",
         "params": params},
        {"name": "uncoupled_ale_step_2d", "metric": "time_per_step", "value": med["ale"] * 1e3, "unit": "ms",
         "params": {"zones": zones**2, "rounds": rounds, "note": "predict, correct, remap; no bodies"}},
        {"name": "uncoupled_lagrange_step_2d", "metric": "time_per_step", "value": med["lagrange"] * 1e3,
         "unit": "ms", "params": {"elements": elements**2, "rounds": rounds, "note": "predict, correct; no gas"}},
        {"name": "coupled_step_2d_block", "metric": "coupler_share", "value": share, "unit": "",
         "params": {"target": "<= 0.10", "holds": bool(share <= 0.10),
                    "coupler": "EmbeddedCoupling.geometry + solve + background_correction",
                    "profile_top_tottime": profile}},
        {"name": "coupled_step_2d_block", "metric": "coupled_over_uncoupled_sum", "value": over, "unit": "x",
         "params": {"target": "<= 1.15", "holds": bool(over <= 1.15),
                    # the solvers' own extra work with the body (cut cells, blocked zones, exchanges)
                    "coupled_without_coupler_over_uncoupled_sum":
                        (med["coupled"] - med["coupler"]) / (med["ale"] + med["lagrange"])}},
    ]
    return results, med


def _draw_share(med):
    def draw(ax):
        labels = ["ALE alone", "Lagrange alone", "ALE + Lagrange", "coupled step"]
        ms = {k: v * 1e3 for k, v in med.items()}
        ax.bar(labels[:2], [ms["ale"], ms["lagrange"]], color=["tab:blue", "tab:green"])
        ax.bar(labels[2], ms["ale"], color="tab:blue", label="ALE step")
        ax.bar(labels[2], ms["lagrange"], bottom=ms["ale"], color="tab:green", label="Lagrange step")
        rest = ms["coupled"] - ms["coupler"]
        ax.bar(labels[3], rest, color="tab:gray", label="coupled solvers (with cut cells)")
        bottom = rest
        for key, colour in (("coupler_geometry", "tab:orange"), ("coupler_solve", "tab:red"),
                            ("coupler_background_correction", "tab:purple")):
            ax.bar(labels[3], ms.get(key, 0.0), bottom=bottom, color=colour, label="coupler: " + key[8:])
            bottom += ms.get(key, 0.0)
        ax.set_ylabel("wall time per step (ms), median")
        ax.set_title(f"Coupled step against the uncoupled solvers, 2-D block in gas, 1 core\n"
                     f"(coupler share {ms['coupler'] / ms['coupled']:.1%}, coupled / (ALE + Lagrange) = "
                     f"{ms['coupled'] / (ms['ale'] + ms['lagrange']):.2f})", fontsize=9)
        ax.legend(fontsize=7)

    return draw


# ---- the bench -----------------------------------------------------------------------------------
@bench("coupling")
def bench_coupling(out: Path, quick: bool = False) -> Path:
    out = Path(out)
    cond, sweeps = conditioning(quick)
    cost, rows = coupler_cost(quick)
    share, med = step_share(quick)
    doc = {"results": cond + cost + share, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    _chart(out.parent / "coupling_conditioning.png", _draw_conditioning(sweeps))
    _chart(out.parent / "coupling_cost_per_facet.png", _draw_cost(rows))
    _chart(out.parent / "coupling_step_share.png", _draw_share(med))
    return out
