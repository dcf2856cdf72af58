"""Decomposed ALE runs against one rank (helper of test_mpi.py, not a test module).

Run as ``mpiexec -n N python -m tests.solvers.ale.mpi_compare [case ...]`` from the repository root:
every case runs on COMM_SELF and on COMM_WORLD; rank 0 prints one JSON line per case (largest
relative difference and bitwise flag of every field) and the exit code is 1 if a difference exceeds
``TOL``.
"""
from __future__ import annotations

import json
import sys

import numpy as np

from solvers.ale.solver import AleSolver
from tests.solvers.ale.ale_helpers import FACES, periodic, sedov_config, sod_config, uniform_config

TOL = 1e-12


def _perturbed_stream(dim, n, faces, mode, velocity):
    cfg = uniform_config(dim, n, velocity, faces, mode=mode, pressure=1.0)
    sphere = " + ".join(f"({c} - 0.4)**2" for c in "xyz"[:dim]) + " < 0.06"
    cfg["regions"].append({"material": "gas", "region": sphere, "density": 2.0, "pressure": 3.0,
                           "velocity": list(velocity)})
    return cfg


def _open(dim, mode):
    vel = [0.5] + [0.0] * (dim - 1)
    faces = {f: "outflow" for f in FACES[: 2 * dim]}
    faces["x_lower"] = {"inflow": {"density": 1.0, "velocity": vel, "pressure": 1.0}}
    if dim == 3:
        faces["z_lower"] = faces["z_upper"] = "periodic"
    return _perturbed_stream(dim, 12 if dim == 2 else 8, faces, mode, vel)


def _sedov(mode):
    cfg = sedov_config(3, 12, 0.1)
    cfg["mode"] = mode
    return cfg


def _mono(cfg):
    cfg["viscosity"] = {"kind": "monotonic"}
    return cfg


# name: (config, steps, impulse steps)
CASES = {
    "sod_x_eulerian": (lambda: sod_config(2, 64, 0, ntrans=4), 40, ()),
    "sod_x_lagrangian": (lambda: sod_config(2, 64, 0, mode="lagrangian", ntrans=4), 40, (5, 6)),
    "sod_y_eulerian": (lambda: sod_config(2, 64, 1), 40, ()),  # 1 zone across: split along y
    "sod_y_lagrangian": (lambda: sod_config(2, 64, 1, mode="lagrangian", ntrans=4), 40, ()),
    "sedov_3d_eulerian": (lambda: _sedov("eulerian"), 20, ()),
    "sedov_3d_lagrangian": (lambda: _sedov("lagrangian"), 20, (3,)),
    "periodic_2d": (lambda: _perturbed_stream(2, 12, periodic(2), "eulerian", [0.3, -0.2]), 30, ()),
    "periodic_3d": (lambda: _perturbed_stream(3, 8, periodic(3), "eulerian", [0.3, -0.2, 0.1]), 12, ()),
    "open_2d_eulerian": (lambda: _open(2, "eulerian"), 30, ()),
    "open_2d_lagrangian": (lambda: _open(2, "lagrangian"), 30, ()),
    "open_3d_eulerian": (lambda: _open(3, "eulerian"), 12, ()),
    # monotonic q: its neighbour strain rates from the ghost nodes (walls, images, open faces, cuts)
    "sedov_3d_lagrangian_mono": (lambda: _mono(_sedov("lagrangian")), 20, (3,)),
    "periodic_2d_mono": (lambda: _mono(_perturbed_stream(2, 12, periodic(2), "eulerian", [0.3, -0.2])), 30, ()),
    "open_2d_lagrangian_mono": (lambda: _mono(_open(2, "lagrangian")), 30, ()),
    # several materials (mixed.py): interface reconstruction reads one neighbour layer of fractions
    "water_air_2d": (lambda: _water_air(), 40, ()),
    "square_2d": (lambda: _square(2, 16), 30, ()),
    "square_3d": (lambda: _square(3, 8), 12, ()),
}


def _water_air():
    from tests.solvers.ale.test_mixed import water_air_config
    cfg = water_air_config(n=64)
    cfg["grid"]["upper"][1] = 4.0 / 64
    cfg["grid"]["cells"][1] = 4
    return cfg


def _square(dim, n):
    from tests.solvers.ale.test_mixed import square_config
    cfg = square_config(n, dim)
    for r in cfg["regions"]:
        r["velocity"] = [0.3, -0.2, 0.1][:dim]
    return cfg


def impulse(cfg, step):
    """A deterministic global impulse (output node order), small against the nodal momenta."""
    cells = np.asarray(cfg["grid"]["cells"])
    nn, dim = int(np.prod(cells + 1)), len(cells)
    k = np.arange(nn * dim, dtype=np.float64).reshape(nn, dim)
    # (the coupler sends ids and values of the nodes it touches; here: every node)
    return {"nodes": np.arange(nn, dtype=np.int64), "impulse": 1e-6 * np.sin(0.37 * k + step) / nn}


def run(comm, cfg, steps, impulses=(), s=None):
    """``steps`` coupler cycles (dt = half the stable step) from the solver's own step and time."""
    s = AleSolver(comm, cfg) if s is None else s
    for _ in range(steps):
        dt = 0.5 * s.stable_dt()
        k, t = s.step + 1, s.time + dt
        s.predict(dt)
        s.correct(impulse(cfg, k) if k in impulses else None, k, t)
        s.remap()
    return s


def snapshot(s):
    """Collective. Rank 0: every state array over the real zones/nodes in output order, the output
    (points, cells, data) and the diagnostics; None elsewhere."""
    out = {}
    for k in AleSolver.ARRAYS:
        a = getattr(s, k)
        nodes = a.shape[0] == s.block.nnodes
        out[k] = s._gather_real(a, nodes) if s.dec.parallel else (s.node_field if nodes else s.zone_field)(a)
    if s.mm is not None:
        for k in ("vol", "mass", "ener"):
            a = getattr(s.mm, k)
            out[f"material_{k}"] = s._gather_real(a, False) if s.dec.parallel else s.zone_field(a)
    res = s.output()
    diag = s.diagnostics()
    if s.dec.rank != 0:
        return None
    pts, cells, pdata, cdata = res
    out.update({"points": pts, "cells": cells, "out_velocity": pdata["velocity"]})
    out.update({f"out_{k}": v for k, v in cdata.items()})
    return {"fields": out, "diag": diag}


def differences(one, many) -> dict:
    """field -> (largest relative difference, bitwise equal); diagnostics relative to their scale
    (momenta: the momentum scale sqrt(2 M K); balance numbers, already relative: absolute)."""
    res = {}
    for k, a in one["fields"].items():
        b = many["fields"][k]
        if a.shape != b.shape:
            res[k] = (np.inf, False)
            continue
        scale = max(float(np.abs(a).max()), 1e-300)
        res[k] = (float(np.abs(a - b).max()) / scale, bool(np.array_equal(a, b)))
    d1, d2 = one["diag"], many["diag"]
    pscale = np.sqrt(2.0 * d1["mass"] * max(d1["kinetic_energy"], 1e-300))
    for k, a in d1.items():
        b = d2[k]
        if k.endswith("_rel"):
            scale = 1.0
        elif k.startswith("momentum"):
            scale = max(abs(a), pscale)
        elif k == "boundary_work":
            scale = max(abs(a), abs(d1["total_energy"]))
        else:
            scale = max(abs(a), 1e-300)
        res[f"diag:{k}"] = (abs(a - b) / scale, a == b)
    return res


def compare(world, name):
    from mpi4py import MPI

    make, steps, imp = CASES[name]
    cfg = make()
    one = snapshot(run(MPI.COMM_SELF, cfg, steps, imp))
    s = run(world, cfg, steps, imp)
    many = snapshot(s)
    dims = list(s.dec.dims)
    s.dec.free()
    if world.rank != 0:
        return None
    return {"dims": dims, "diff": differences(one, many)}


def main(argv) -> int:
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    worst = 0.0
    for name in argv or list(CASES):
        r = compare(world, name)
        if world.rank == 0:
            fields = {k: v for k, v in r["diff"].items() if not k.startswith("diag:")}
            diags = {k: v for k, v in r["diff"].items() if k.startswith("diag:")}
            m = max(v[0] for v in r["diff"].values())
            worst = max(worst, m)
            print(json.dumps({"case": name, "ranks": world.size, "dims": r["dims"],
                              "max_rel_fields": max(v[0] for v in fields.values()),
                              "fields_bitwise": all(v[1] for v in fields.values()),
                              "not_bitwise": sorted(k for k, v in fields.items() if not v[1]),
                              "max_rel_diagnostics": max(v[0] for v in diags.values())}), flush=True)
    bad = np.array([1 if worst > TOL else 0], np.int64)
    world.Bcast(bad, root=0)
    return int(bad[0])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
