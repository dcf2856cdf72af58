"""The memory bench (`memory`): the traced peak per element, zone and material of the solvers'
states against orchestrator/resources.py's estimates.
"""
from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np

from orchestrator.bench.registry import bench
from orchestrator.bench.steps import ELASTIC, ball_config, lagrange_case, sedov_config


def _traced_peak(run) -> int:
    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _slope(peak, small, large) -> tuple[float, int]:
    """Bytes per unit between two sizes (fixed costs drop out): ``peak(size) -> (bytes, units)``."""
    peak(small)  # first-call allocations (caches) out of the way
    (b1, n1), (b2, n2) = peak(small), peak(large)
    return (b2 - b1) / (n2 - n1), n2


def _ale_memory_config(dim: int, n: int, materials: int, samples=None, obstacle=False) -> dict:
    cfg = ball_config(n, materials > 1)
    if dim == 2:
        cfg.update(dimension=2, grid={"lower": [0.0] * 2, "upper": [1.0] * 2, "cells": [n] * 2},
                   boundaries={f: "periodic" for f in ("x_lower", "x_upper", "y_lower", "y_upper")})
        for r in cfg["regions"]:
            r["velocity"] = [0.3, -0.2]
            if "region" in r:
                r["region"] = "(x - 0.5)**2 + (y - 0.5)**2 < 0.09"
    if materials == 3:
        cfg["materials"]["third"] = {"eos": "ideal_gas", "gamma": 1.4}
        cfg["regions"].append(dict(cfg["regions"][1], material="third", region="x < 0.2"))
    if samples:
        cfg["fraction_samples"] = samples
    if obstacle:
        cfg["boundaries"] = {f: "wall" for f in cfg["boundaries"]}
        cfg["obstacles"] = [{"region": "x > 0.9", "subsamples": 2}]
    return cfg


@bench("memory")
def bench_memory(out: Path, quick: bool = False) -> Path:
    """The memory costs orchestrator/resources.py estimates a case from (tracemalloc peaks of the real
    solvers: set-up, two steps and an output; slopes between two sizes)."""
    from mpi4py import MPI

    from solvers.ale.solver import AleSolver
    from solvers.lagrange.mesh import body_mesh, concatenate, read_mesh
    from solvers.lagrange.partition import partition
    from solvers.lagrange.solver import LagrangeSolver

    results = []

    def row(name, metric, value, params):
        results.append({"name": name, "metric": metric, "value": round(float(value), 1), "unit": "B",
                        "params": params})

    def lagrange_peak(dim):
        def peak(n):
            case = lagrange_case(n, ELASTIC, 1.0)
            if dim == 2:
                case["run"]["dimension"] = 2
                case["lagrange"]["bodies"][0].update(
                    mesh={"box": {"lower": [0, 0], "upper": [0.01, 0.01], "cells": [n, n]}},
                    initial_velocity=["-1*y/0.01", 0.0])
            holder = {}

            def run():
                s = holder["s"] = LagrangeSolver(MPI.COMM_SELF, case)
                s.predict(0.5 * s.stable_dt())
                s.correct(None)
            return _traced_peak(run), holder["s"].n_cells_global
        return peak

    sizes = {2: (40, 80) if quick else (150, 300), 3: (8, 16) if quick else (20, 40)}
    for dim in (2, 3):
        v, ne = _slope(lagrange_peak(dim), *sizes[dim])
        row("lagrange", "memory_per_element", v, {"dimension": dim, "elements": ne, "ranks": 1})

    def mesh_peak(spec, dim):
        def peak(scale):
            def run():
                m, _ = concatenate([body_mesh(spec(scale), dim)])
                partition(m.points.astype(np.float64), m.cells.astype(np.int64), 2, 0)
            return _traced_peak(run), body_mesh(spec(scale), dim).num_cells
        return peak
    box = {2: lambda n: {"mesh": {"box": {"lower": [0, 0], "upper": [1, 1], "cells": [n, n]}}},
           3: lambda n: {"mesh": {"box": {"lower": [0] * 3, "upper": [1] * 3, "cells": [n] * 3}}}}
    for dim in (2, 3):
        v, ne = _slope(mesh_peak(box[dim], dim), *sizes[dim])
        row("lagrange_global_mesh_box", "memory_per_element_per_rank", v, {"dimension": dim, "elements": ne})
    qc = lambda n: {"mesh": {"quarter_cylinder": {"radius": 1.0, "length": 3.0, "radial_cells": n, "axial_cells": 2 * n}}}
    v, ne = _slope(mesh_peak(qc, 3), *((6, 12) if quick else (15, 30)))
    row("lagrange_global_mesh_quarter_cylinder", "memory_per_element_per_rank", v, {"dimension": 3, "elements": ne})

    import tempfile

    import meshio

    from solvers.lagrange.mesh import box_mesh
    with tempfile.TemporaryDirectory() as tmp:
        m = box_mesh([0, 0, 0], [1, 1, 1], [20 if quick else 50] * 3)
        for fmt, kw, suffix in (("gmsh22", {"binary": False}, ".msh"), ("gmsh22", {"binary": True}, ".msh"),
                                ("vtu", {"binary": True}, ".vtu")):
            path = Path(tmp) / f"m_{kw['binary']}{suffix}"
            meshio.write(str(path), meshio.Mesh(m.points, [("hexahedron", m.cells)]), file_format=fmt, **kw)
            peak = _traced_peak(lambda: read_mesh(path, 3))
            row(f"read_mesh_{fmt}_{'binary' if kw['binary'] else 'ascii'}", "memory_per_element", peak / m.num_cells,
                {"elements": m.num_cells, "file_bytes": path.stat().st_size,
                 "peak_over_file_size": round(peak / path.stat().st_size, 2)})

    def ale_peak(dim, materials, samples=None, obstacle=False):
        def peak(n):
            cfg = (sedov_config(n, "eulerian") if (dim, materials, obstacle) == (3, 1, False)
                   else _ale_memory_config(dim, n, materials, samples, obstacle))
            holder = {}

            def run():
                s = holder["s"] = AleSolver(MPI.COMM_SELF, cfg)
                for k in range(2):
                    dt = 0.5 * s.stable_dt()
                    s.predict(dt)
                    s.correct(None, step=k + 1, time=dt)
                    s.remap(None)
                s.output()
            return _traced_peak(run), holder["s"].block.nzones  # per zone of the padded block
        return peak

    asz = {2: (40, 80) if quick else (150, 300), 3: (8, 14) if quick else (24, 40)}
    per_zone = {}
    for dim in (2, 3):
        for materials in (1, 2, 3):
            v, nz = _slope(ale_peak(dim, materials, samples=1), *asz[dim])
            per_zone[dim, materials] = v
            row("ale", "memory_per_zone", v, {"dimension": dim, "materials": materials, "padded_zones": nz,
                                              "fraction_samples": 1 if materials > 1 else None})
        row("ale", "memory_per_zone_and_material", (per_zone[dim, 3] - per_zone[dim, 2]),
            {"dimension": dim, "note": "several materials: 3 minus 2 materials"})
        k = 4
        v, nz = _slope(ale_peak(dim, 2, samples=k), *asz[dim])
        real = nz / np.prod([c + 4 for c in [asz[dim][1]] * dim]) * asz[dim][1] ** dim
        row("ale", "memory_per_fraction_sample", (v - per_zone[dim, 2]) * nz / real / k**dim,
            {"dimension": dim, "fraction_samples": k})
        v, nz = _slope(ale_peak(dim, 1, obstacle=True), *asz[dim])
        row("ale", "memory_per_zone_obstacles", v - per_zone[dim, 1], {"dimension": dim, "subsamples": 2})
