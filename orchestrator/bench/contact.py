"""`immerse bench contact`: the cost of the contact library's geometry (solvers/contact) against the
number of contact facets, 10^2 ... 10^5 per side (2-D segments).

Two facing wavy faces with non-matching meshes (side b has 0.7 the segments of side a, so nodes never
line up), a gap of a tenth of a segment. Timed, medians of repeats:

* search: the binned broad phase of both passes (search.candidate_pairs);
* operators: both passes' integrals assembled, the gap operator G and the stabilization J (what a
  step needs before its multiplier solve);
* solve: the multipliers' system of an explicit step, S p = -g0 with S = B M^-1 B^T + J (unit
  masses, J weighed as explicit.py does) by the primal-dual active set (kkt.solve_schur_complement,
  SuperLU), every row's gap closed (g0 < 0: the whole interface pressed, the largest system; the
  set releases the faces' 4 end rows and settles in 2 iterations);
* all pairs: the O(n^2) test the broad phase replaces, up to 10^3 facets (beyond, its n^2 memory).

Reported per facet (µs) and the log-log slopes against the facet count (1: linear) of the operators
and of a step's whole contact work, search + operators + solve.

And the contact's share of an explicit impact step (``contact_share``): two steel blocks of 5 x 10^4
plane-strain quads each (5000 x 10), meeting along their long sides at 10 m/s (10^4 contact
facets, both sides), stepped in this process with and without [contact]: the share is 1 - (step
without) / (step with), medians of the steps after the first (which builds the surface).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench, machine


def wavy_faces(n: int):
    """points, seg_a, seg_b: side a y = 0.02 sin(2 pi x) on [0, 1] in n segments (outward +y), side
    b the same curve raised by a tenth of a segment in int(0.7 n) + 1 segments (outward -y)."""
    nb = int(0.7 * n) + 1
    xa, xb = np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, nb + 1)
    pa = np.stack([xa, 0.02 * np.sin(2 * np.pi * xa)], axis=1)
    pb = np.stack([xb, 0.02 * np.sin(2 * np.pi * xb) + 0.1 / n], axis=1)
    seg_a = np.stack([np.arange(1, n + 1), np.arange(n)], axis=1)
    seg_b = np.stack([np.arange(nb), np.arange(1, nb + 1)], axis=1) + n + 1
    return np.concatenate([pa, pb]), seg_a, seg_b


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


@bench("contact")
def bench_contact(out: Path, quick: bool = False) -> Path:
    from solvers.contact.dual_pass import DualPassContact
    from solvers.contact.kkt import solve_schur_complement
    from solvers.contact.search import candidate_pairs, facet_boxes

    sizes = [100, 1000] if quick else [100, 1000, 10000, 100000]
    repeats = 3 if quick else 7
    DualPassContact(*wavy_faces(10), capture=0.1)  # compile the kernel outside the timings
    results, totals, steps = [], [], []
    for n in sizes:
        pts, sa, sb = wavy_faces(n)
        capture = 0.5 / n
        ba, bb = facet_boxes(pts, sa, capture), facet_boxes(pts, sb, capture)
        t_search = _median_time(lambda: (candidate_pairs(ba, bb), candidate_pairs(bb, ba)), repeats)

        def operators():
            c = DualPassContact(pts, sa, sb, capture=capture)
            c.gap_operator()
            c.stabilization(1e-3, 1.0 / n)
            return c

        t_ops = _median_time(operators, repeats)
        c = operators()
        B = c.constraint_operator()
        bbt = (B @ B.T).tocsc()
        j1 = c.stabilization(1.0, 1.0)
        S = (bbt + np.median(bbt.diagonal()) / np.median(j1.diagonal()) * j1).tocsc()
        g0 = -np.abs(B @ pts.ravel()) - 1e-3 / n     # every row's gap closed
        t_solve = _median_time(lambda: solve_schur_complement(S, g0, active=g0 < 0.0), repeats)
        sol = solve_schur_complement(S, g0, active=g0 < 0.0)
        pairs = len(candidate_pairs(ba, bb))
        params = {"facets_a": n, "facets_b": len(sb), "candidate_pairs": pairs,
                  "multipliers": c.n_multipliers, "repeats": repeats,
                  "solve_active": int(sol.active.sum()), "solve_iterations": sol.iterations}
        if n <= 1000:
            def all_pairs():
                return np.argwhere(np.all((ba[:, None, 0] <= bb[None, :, 1]) & (bb[None, :, 0] <= ba[:, None, 1]), axis=2))
            params["all_pairs_s"] = _median_time(all_pairs, repeats)
        results += [
            {"name": "contact_search", "metric": "time_per_facet", "value": t_search / (n + len(sb)) * 1e6,
             "unit": "us", "params": {**params, "seconds": t_search}},
            {"name": "contact_operators", "metric": "time_per_facet", "value": t_ops / (n + len(sb)) * 1e6,
             "unit": "us", "params": {**params, "seconds": t_ops}},
            {"name": "contact_solve", "metric": "time_per_facet", "value": t_solve / (n + len(sb)) * 1e6,
             "unit": "us", "params": {**params, "seconds": t_solve}},
            {"name": "contact_search_operators_solve", "metric": "time_per_facet",
             "value": (t_search + t_ops + t_solve) / (n + len(sb)) * 1e6, "unit": "us",
             "params": {**params, "seconds": t_search + t_ops + t_solve}},
        ]
        totals.append(t_ops)
        steps.append(t_search + t_ops + t_solve)
    for name, t in (("contact_operators", totals), ("contact_search_operators_solve", steps)):
        slope = float(np.polyfit(np.log(sizes[1:]), np.log(t[1:]), 1)[0]) if len(sizes) > 2 else None
        results.append({"name": name, "metric": "loglog_slope_vs_facets", "value": slope, "unit": "",
                        "params": {"sizes": sizes[1:], "target": "~1 (linear)"}})
    results.append(contact_share(quick))
    doc = {"results": results, "machine": machine()}
    out.write_text(json.dumps(doc, indent=2))
    return out


def _blocks(nx: int, ny: int, contact: bool) -> dict:
    steel = {"model": "linear_elastic", "density": 7800.0, "youngs_modulus": 200e9, "poisson_ratio": 0.3}
    length, h = 1.0, 1.0 / nx
    bodies = [{"name": "lower", "material": "m", "mesh": {"box": {"lower": [0.0, -ny * h], "upper": [length, 0.0],
                                                                  "cells": [nx, ny]}},
               "initial_velocity": [0.0, 10.0]},
              {"name": "upper", "material": "m", "mesh": {"box": {"lower": [0.0, 0.0], "upper": [length, ny * h],
                                                                  "cells": [nx - 1, ny]}},
               "initial_velocity": [0.0, 0.0]}]
    case = {"name": "bench", "case_dir": ".", "run": {"dimension": 2, "end_time": 1.0},
            "materials": {"m": steel}, "lagrange": {"bodies": bodies}, "boundaries": []}
    if contact:
        case["contact"] = {"pairs": [["lower", "upper"]], "method": "dual_pass_mortar", "alpha": 1.0, "friction": 0.0}
    return case


def contact_share(quick: bool) -> dict:
    """The contact's share of the explicit step (module docstring)."""
    from mpi4py import MPI

    from solvers.lagrange.solver import LagrangeSolver

    nx, ny, steps = (500, 10, 4) if quick else (5000, 10, 6)
    times = {}
    for contact in (False, True):
        s = LagrangeSolver(MPI.COMM_SELF, _blocks(nx, ny, contact))
        dt = 0.5 * s.stable_dt()
        per = []
        for n in range(steps):
            t0 = time.perf_counter()
            s.predict(dt)
            s.correct(None, step=n + 1, time=(n + 1) * dt)
            per.append(time.perf_counter() - t0)
        times[contact] = float(np.median(per[1:]))
        active = s.contact.last_active if contact else 0
    return {"name": "contact_step", "metric": "contact_share", "value": 1.0 - times[False] / times[True], "unit": "",
            "params": {"elements": nx * ny + (nx - 1) * ny, "contact_facets": 2 * nx - 1, "steps": steps,
                       "step_without_s": times[False], "step_with_s": times[True], "active_multipliers": active}}
