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
tree nodes; past :data:`CHECK_BUDGET` node evaluations on a grid or box body (a cluster-sized case,
or the longest, most expensive expressions on a large one) the check bounds the expressions over
boxes of zones or nodes instead (orchestrator/expression_bounds.py: interval arithmetic), splits the
boxes it cannot decide and evaluates the small ones point by point (:data:`LEAF`), still within the
budget: what it then says holds for every point. A case it cannot decide within the budget (an
expression the bounds cannot follow, e.g. ``1/(x - x + 1)``, undecided over most of a huge grid) is
refused naming the key, not sampled.
"""
from __future__ import annotations

import math

import numpy as np

from solvers.ale.points import (axis_centres, box_points, fraction_samples, grid_points, several_materials, spacing,
                                subcell_offsets)
from solvers.expressions import BOOL, NUM, ExpressionError, compile_expression
from solvers.lagrange.mesh import body_mesh, box_axes

from .schema.rules import CaseError, format_key
from .expression_bounds import Unproven, bounds
from .schema.rules import expression_refusal

__all__ = ["check_expressions", "CHECK_BUDGET"]

CHECK_BUDGET = 1 << 28
"""Node-point evaluations per body or grid at check time: 2.7e8, at most 4-8 s for the costliest
operations (15-29 ns a node and point for sin and **, tests/solvers/test_expressions.py), well under
a second for typical regions (comparisons, arithmetic); e.g. a 10-node region on 2.7e7 points in
full."""

_CHUNK = 1 << 16

LEAF = 1 << 12
"""Zones (or nodes) of a box the bounded check evaluates point by point instead of splitting it."""


def _evaluate(key: str, text: str, fn, points: np.ndarray, where: str) -> np.ndarray:
    try:
        return fn(*points.T)
    except ExpressionError as exc:
        raise expression_refusal(key, text, exc, where) from None


# ---- boxes of a tensor grid, past the budget -----------------------------------------------------
def _walk_boxes(shape, decide, evaluate, cost: int, blame: list, what: str) -> bool:
    """Visit index boxes of a grid of ``shape`` (zones or nodes): ``decide(box)`` settles a box from
    its bounds (True) or not (False, or Unproven); an undecided box is halved along its longest axis,
    and one of at most LEAF entries is ``evaluate``d point by point, ``cost`` node-point evaluations
    an entry, at most CHECK_BUDGET in all (else a CaseError on the key and value in ``blame``, which
    ``decide`` sets to what it could not settle). Returns whether every entry was evaluated (nothing
    settled by bounds alone). box: ((lo, hi), ...) index ranges."""
    stack = [tuple((0, int(n)) for n in shape)]
    spent, bounded = 0, False
    while stack:
        box = stack.pop()
        try:
            if decide(box):
                bounded = True
                continue
        except Unproven:
            pass
        size = math.prod(hi - lo for lo, hi in box)
        if size <= LEAF:
            spent += size * cost
            if spent > CHECK_BUDGET:
                raise CaseError(blame[0], blame[1], f"cannot be checked on all {math.prod(shape):.4g} {what} "
                                          f"within the check's {CHECK_BUDGET:.3g} node-point evaluations "
                                          "(its interval bounds leave too many undecided); allowed: "
                                          "an expression the bounds can follow (no x - x), or a smaller grid")
            evaluate(box)
            continue
        d = max(range(len(box)), key=lambda k: box[k][1] - box[k][0])
        lo, hi = box[d]
        mid = (lo + hi) // 2
        stack.append(box[:d] + ((mid, hi),) + box[d + 1:])
        stack.append(box[:d] + ((lo, mid),) + box[d + 1:])
    return not bounded


def _widened(a: float, b: float) -> tuple[float, float]:
    return math.nextafter(float(a), -math.inf), math.nextafter(float(b), math.inf)


# ---- Lagrangian bodies --------------------------------------------------------------------------
def _body_points(body: dict, dim: int):
    """Chunks of the body's nodes (the solver's ``X`` of that body); a box without building it (a box
    past the budget goes to _bounded_box_body instead; other meshes are built here anyway, and every
    node is evaluated)."""
    size = body["size"]["nodes"]
    m = body["mesh"]
    if "box" in m:
        axes = box_axes(m["box"]["lower"], m["box"]["upper"], m["box"]["cells"])
        shape = tuple(a.size for a in axes)
        for start in range(0, size, _CHUNK):
            ids = np.arange(start, min(start + _CHUNK, size), dtype=np.int64)
            ijk = np.unravel_index(ids, shape, order="F")  # node id = i + (nx+1)(j + (ny+1)k)
            yield np.stack([a[i] for a, i in zip(axes, ijk)], axis=1)
        return
    points = body_mesh(body, dim).points
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
        cost = sum(fn.size for _, _, fn in todo)
        if "box" in body["mesh"] and body["size"]["nodes"] * cost > CHECK_BUDGET:
            _bounded_box_body(body["mesh"]["box"], todo, names, cost, where)
            continue
        for pts in _body_points(body, dim):
            for key, text, fn in todo:
                _evaluate(key, text, fn, pts, where)


def _bounded_box_body(box: dict, todo, names, cost: int, where: str) -> None:
    """A box body past the budget: its node grid walked by boxes (_walk_boxes), every expression
    bounded finite over a box's nodes or evaluated on them."""
    axes = box_axes(box["lower"], box["upper"], box["cells"])

    blame = list(todo[0][:2])

    def decide(b):
        span = {n: _widened(a[lo], a[hi - 1]) for n, a, (lo, hi) in zip(names, axes, b)}
        for key, text, _ in todo:
            blame[:] = key, text
            bounds(text, span)
        return True

    def evaluate(b):
        grids = np.meshgrid(*(a[lo:hi] for a, (lo, hi) in zip(axes, b)), indexing="ij")
        pts = np.stack([g.ravel() for g in grids], axis=1)
        for start in range(0, len(pts), _CHUNK):
            for key, text, fn in todo:
                _evaluate(key, text, fn, pts[start:start + _CHUNK], where)

    _walk_boxes([len(a) for a in axes], decide, evaluate, cost, blame, "nodes")


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
    cost = sum(n * c for n, c in sets)
    zpc = max(1, _CHUNK // most)
    subs = [k] + [int(o.get("subsamples", 1)) for o in ale["obstacles"]]
    sampled = "zone centre" if k is None else f"fraction sample point ({k}^{dim} a zone)"
    state = {"open": not obstacles}

    def chunk(chunks):
        """The regions' coverage and the obstacles' points of a chunk of zones (grid_points')."""
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
        state["open"] = state["open"] or not blocked.all()

    if zones * cost <= CHECK_BUDGET:
        for chunks in zip(*(grid_points(grid["lower"], grid["upper"], grid["cells"], kk, zpc) for kk in subs)):
            chunk(chunks)
        everywhere = True
    else:
        everywhere = _bounded_ale(grid, subs, regions, whole, obstacles, names, cost, chunk, state)
    if not state["open"] and everywhere:  # (zones settled by bounds alone cannot tell)
        raise CaseError("ale.obstacles", [o["region"] for o in ale["obstacles"]],
                        "block every zone of the ALE grid; allowed: obstacles that leave some zone open")


def _bounded_ale(grid, subs, regions, whole, obstacles, names, cost, chunk, state) -> bool:
    """A grid past the budget: walked by boxes of zones (_walk_boxes). A box is settled when every
    expression is bounded finite over its points (each set's own: the regions' sample points, each
    obstacle's sub-cell points) and some region certainly holds on all of it (or one covers the
    grid); a box where every obstacle certainly does not hold has open zones."""
    lo = np.asarray(grid["lower"], dtype=np.float64)
    h = spacing(grid["lower"], grid["upper"], grid["cells"])
    offsets = [np.zeros(1) if kk is None else subcell_offsets(kk, np.ones(1))[:, 0] for kk in subs]
    blame = ["ale.regions", [text for _, text, _ in regions]]

    def span(box, off):
        """{name: (lo, hi)} of the points with sub-cell offsets ``off`` (fractions of h) of the zones
        in ``box``: the same arithmetic as grid_points', widened a float step each side."""
        return {n: _widened(axis_centres(lo[d], h[d], b0) + off[0] * h[d], axis_centres(lo[d], h[d], b1 - 1) + off[-1] * h[d])
                for d, (n, (b0, b1)) in enumerate(zip(names, box))}

    def decide(box):
        at = span(box, offsets[0])
        certain = whole
        for key, text, _ in regions:
            blame[:] = key, text
            may_false, may_true = bounds(text, at)
            certain = certain or not may_false
        if not certain:
            blame[:] = "ale.regions", [text for _, text, _ in regions]
            return False
        none = True
        for (key, text, _), off in zip(obstacles, offsets[1:]):
            blame[:] = key, text
            none = none and not bounds(text, span(box, off))[1]
        state["open"] = state["open"] or (none and bool(obstacles))
        return True

    def evaluate(box):
        chunk([box_points(grid["lower"], grid["upper"], grid["cells"], box, kk) for kk in subs])

    return _walk_boxes(grid["cells"], decide, evaluate, cost, blame, "zones")


def check_expressions(case: dict) -> None:
    """Evaluate every expression of the (loaded) case on its solver's points; CaseError naming
    the key, the expression, the sub-expression and the point of the first non-finite value."""
    names = ("x", "y", "z")[: case["run"]["dimension"]]
    for role, check in ROLES.items():
        if case.get(role):
            check(case, names)


ROLES = {"lagrange": _check_lagrange, "ale": lambda case, names: _check_ale(case["ale"], names)}
"""Per solver role (its case table): the check of its expressions on its points."""
