"""The case's expressions evaluated at check time, on the points the solvers evaluate them on.

``load_case`` compiles every expression (whitelist, types, constants folded: ``9**9**9**9`` is
refused there).  What depends on the points (``0/(x-x)``, ``sqrt(-1-x*x)``, ``1/x`` at a node
with x = 0) is found here, by evaluating each expression where its solver will, before anything
launches (the CLI calls :func:`check_expressions` after the resource check):

* ``lagrange.bodies[i].initial_velocity[j]``: every node of that body (solvers/lagrange/solver.py);
* ``boundaries[i].region``: every node of every body (solvers/lagrange/boundary.py);
* ``ale.regions[i].region``: the zone centres, or with several materials the fraction_samples^dim
  sub-cell points of every zone (solvers/ale/solver.py, mixed.py); the regions must cover them all;
* ``ale.obstacles[i].region``: the subsamples^dim sub-cell points of every zone (blocked.py); the
  obstacles must leave some zone open.

The points come from the solvers' own functions (solvers/ale/points.py, solvers/lagrange/mesh.py),
one code path.  Evaluation goes chunk by chunk (memory bounded).  Its cost is points times syntax
tree nodes; past :data:`CHECK_BUDGET` node evaluations on a body or grid (a cluster-sized case, or
the longest, most expensive expressions on a large one) every n-th zone or node only is evaluated,
so the check stays within seconds (the solver still refuses a non-finite value at start-up, naming
the expression).
"""
from __future__ import annotations

import math

import numpy as np

from solvers.ale.points import fraction_samples, grid_points, several_materials
from solvers.expressions import BOOL, NUM, ExpressionError, compile_expression
from solvers.lagrange.mesh import body_mesh, box_axes

from .case import CaseError, format_key
from .schema_rules import expression_refusal

__all__ = ["check_expressions", "CHECK_BUDGET"]

CHECK_BUDGET = 1 << 28
"""Node-point evaluations per body or grid at check time: 2.7e8, at most 4-8 s for the costliest
operations (15-29 ns a node and point for sin and **, tests/solvers/test_expressions.py), well under
a second for typical regions (comparisons, arithmetic); e.g. a 10-node region on 2.7e7 points in
full."""

_CHUNK = 1 << 16


def _evaluate(key: str, text: str, fn, points: np.ndarray, where: str) -> np.ndarray:
    try:
        return fn(*points.T)
    except ExpressionError as exc:
        raise expression_refusal(key, text, exc, where) from None


# ---- Lagrangian bodies --------------------------------------------------------------------------
def _stride(work: int) -> int:
    return max(1, math.ceil(work / CHECK_BUDGET))


def _body_points(body: dict, dim: int, cost: int):
    """Chunks of the body's nodes (the solver's ``X`` of that body); a box without building it.
    ``cost``: syntax tree nodes evaluated per point."""
    size = body["size"]["nodes"]
    stride = _stride(size * cost)
    m = body["mesh"]
    if "box" in m:
        axes = box_axes(m["box"]["lower"], m["box"]["upper"], m["box"]["cells"])
        shape = tuple(a.size for a in axes)
        for start in range(0, size, _CHUNK * stride):
            ids = np.arange(start, min(start + _CHUNK * stride, size), stride, dtype=np.int64)
            ijk = np.unravel_index(ids, shape, order="F")  # node id = i + (nx+1)(j + (ny+1)k)
            yield np.stack([a[i] for a, i in zip(axes, ijk)], axis=1)
        return
    points = body_mesh(body, dim).points[::stride]
    for start in range(0, len(points), _CHUNK):
        yield points[start:start + _CHUNK]


def _check_lagrange(case: dict, names: tuple[str, ...]) -> None:
    dim = len(names)
    regions = [(format_key(["boundaries", i, "region"]), bc["region"],
                compile_expression(bc["region"], names, kind=BOOL))
               for i, bc in enumerate(case.get("boundaries", [])) if "region" in bc]
    for i, body in enumerate(case["lagrange"]["bodies"]):
        velocity = [(format_key(["lagrange", "bodies", i, "initial_velocity", j]), comp,
                     compile_expression(comp, names, kind=NUM))
                    for j, comp in enumerate(body["initial_velocity"]) if isinstance(comp, str)]
        todo = velocity + regions
        if not todo:
            continue
        where = f"a node of body {body['name']!r}"
        for pts in _body_points(body, dim, sum(fn.size for _, _, fn in todo)):
            for key, text, fn in todo:
                _evaluate(key, text, fn, pts, where)


# ---- ALE background -----------------------------------------------------------------------------
def _check_ale(ale: dict, names: tuple[str, ...]) -> None:
    dim = len(names)
    grid = ale["grid"]
    zones = math.prod(grid["cells"])
    k = fraction_samples(ale, dim) if several_materials(ale) else None
    regions = [(format_key(["ale", "regions", i, "region"]), r["region"],
                compile_expression(r["region"], names, kind=BOOL))
               for i, r in enumerate(ale["regions"]) if r.get("region")]
    whole = any(not r.get("region") for r in ale["regions"])
    obstacles = [(format_key(["ale", "obstacles", j, "region"]), o["region"],
                  compile_expression(o["region"], names, kind=BOOL)) for j, o in enumerate(ale["obstacles"])]
    # points a zone and syntax tree nodes of each set: the regions, then every obstacle
    sets = [(1 if k is None else k**dim, sum(fn.size for _, _, fn in regions))]
    sets += [(int(o.get("subsamples", 1)) ** dim, fn.size) for o, (_, _, fn) in zip(ale["obstacles"], obstacles)]
    most = max(n for n, _ in sets)
    stride = _stride(zones * sum(n * cost for n, cost in sets))
    zpc = max(1, _CHUNK // most)
    subs = [k] + [int(o.get("subsamples", 1)) for o in ale["obstacles"]]
    gens = [grid_points(grid["lower"], grid["upper"], grid["cells"], kk, zpc, stride) for kk in subs]
    sampled = "zone centre" if k is None else f"fraction sample point ({k}^{dim} a zone)"
    any_open = not obstacles
    for chunks in zip(*gens):
        ijk, pts = chunks[0]
        covered = np.full(len(pts), whole)
        for key, text, fn in regions:
            covered |= _evaluate(key, text, fn, pts, f"a {sampled} of the ALE grid")
        if not covered.all():
            first = int(np.argmax(~covered))
            zone = tuple(int(v) for v in ijk[first // (len(pts) // len(ijk))])
            at = ", ".join(f"{n} = {v:.9g}" for n, v in zip(names, pts[first]))
            raise CaseError("ale.regions", [r.get("region") for r in ale["regions"]],
                            f"zone {zone} is not covered by any region (at {at}); allowed: regions "
                            "covering the whole grid (a region without `region` covers all of it)")
        blocked = np.zeros(len(ijk), bool)
        for (key, text, fn), (oijk, opts) in zip(obstacles, chunks[1:]):
            inside = _evaluate(key, text, fn, opts, "a sub-cell point of the ALE grid")
            blocked |= inside.reshape(len(oijk), -1).all(axis=1)  # every sub-point inside: solid
        any_open = any_open or not blocked.all()
    if not any_open and stride == 1:  # (a subset of the zones cannot tell)
        raise CaseError("ale.obstacles", [o["region"] for o in ale["obstacles"]],
                        "block every zone of the ALE grid; allowed: obstacles that leave some zone open")


def check_expressions(case: dict) -> None:
    """Evaluate every expression of the (loaded) case on its solver's points; CaseError naming
    the key, the expression, the sub-expression and the point of the first non-finite value."""
    names = ("x", "y", "z")[: case["run"]["dimension"]]
    for role, check in ROLES.items():
        if case.get(role):
            check(case, names)


ROLES = {"lagrange": _check_lagrange, "ale": lambda case, names: _check_ale(case["ale"], names)}
"""Per solver role (its case table): the check of its expressions on its points."""
