"""The embedded-mesh coupling's table of case.toml, ``[coupling]``: bodies of the Lagrangian solver
immersed in the ALE background, tied by the method the table names (orchestrator/coupling/variants.py:
each variant registers itself with its schema fragment and its cross-field check).

Normalised layout (``case["coupling"]``, present when the file has the table): the variant's keys
with its defaults filled in, e.g. ``{method: "multiplier", condition: "tied" | "slip", alpha, beta}``.
Lagrangian bodies and SPH particles may be immersed together (each group its own constraint solve
with the one method: orchestrator/coupling/foregrounds.py).

Cross-field rules: a coupled case needs the background (``[ale]``, Eulerian mode: the bodies move
through the fixed grid) and bodies (``[[lagrange.bodies]]``); every body made from a box or a
quarter cylinder lies inside the grid's box, and every mesh file's nodes (read by [lagrange]'s file
check), by the coupler's own rule (``Grid.snap``, ``Grid.beyond``);
several materials (or void) in the background beside the bodies (mixed.py with blocked.py).
"""
from __future__ import annotations

from orchestrator.coupling import multirate, variants

from .registry import register_table
from .rules import MISSING, CaseError, format_key

KEYS = {
    "method": "The coupling method. multiplier: stabilised Lagrange multipliers, one per cut zone (Puso, Kokko, "
              "Settgast & Liu 2015; never cuts the step); penalty: a spring per cut zone on the accumulated "
              "relative interface displacement; nitsche: that spring with the stiffness gamma K / h.",
    "condition": "What the interface ties: tied, every velocity component (no slip); slip, the normal "
                 "component only (an inviscid gas slides along the surface).",
    "min_fill": "A cut zone whose open volume holds less than this share of material (the rest void) gets no "
                "constraint (LS-DYNA's FRCMIN).",
    "alpha": "multiplier: the stabilisation's weight, the compliance C^-1 = J + I / alpha of each multiplier.",
    "beta": "multiplier: the weight of the jump term J between neighbouring cut zones.",
    "substep_tolerance": "multirate: a pass of a group's substeps is accepted when the solve after it would move "
                         "their mean velocity by at most this share of its scale.",
    "substep_passes": "multirate: the most passes of a coupling step's substeps (the last is accepted and "
                      "reported).",
    "gamma": "nitsche: the factor gamma of the interface stiffness gamma K / h (K the coupled material's "
             "modulus, h the zone width).",
    "stiffness": "penalty: the spring's stiffness, traction per metre of relative interface displacement.",
}
"""What each key of the coupling variants means (orchestrator/coupling/variants.py holds their schemas)."""


def _defaults(method: str) -> dict:
    """The values a variant takes for its keys left out (CouplingMethod.__init__; the multi-rate passes:
    orchestrator/coupler.py).  Not ``method``: within a variant's branch it is given; left out, it is
    the multiplier method's (variants.make), said at the table's own ``method``."""
    return {"min_fill": variants.MIN_FILL, **variants.METHODS[method].DEFAULTS,
            "substep_tolerance": multirate.PASS_TOLERANCE, "substep_passes": multirate.MAX_PASSES}


def _described(properties: dict, method: str) -> dict:
    """Copies of a variant's key schemas with their meanings and defaults (the variants' own stay bare)."""
    defaults = _defaults(method)
    return {k: {**v, **({"description": KEYS[k]} if k in KEYS else {}),
                **({"default": defaults[k]} if k in defaults else {})}
            for k, v in properties.items()}


def _schema() -> dict:
    """The variants' branches (variants.schema()) under a closed table of all their keys: a key of
    another variant gets the variant's own message, an unknown key the schema's."""
    s = variants.schema()
    branches = []
    props = {}
    for branch in s["allOf"]:
        method = branch["if"]["properties"]["method"]["const"]
        then = {**branch["then"], "properties": _described(branch["then"]["properties"], method)}
        branches.append({**branch, "then": then})
        props.update(then["properties"])
    # (method left out: the multiplier method, variants.make)
    props["method"] = {**s["properties"]["method"], "description": KEYS["method"], "default": "multiplier"}
    return {**s, "allOf": branches, "properties": props, "additionalProperties": False,
            "description": "Lagrangian bodies and SPH particles immersed in the ALE background (Eulerian), tied "
                           "to it by the method this table names."}


COUPLING = _schema()


def normalise(raw: dict | None, case: dict) -> dict | None:
    """The registry's hook: the variant's keys with its defaults (checked by the variant)."""
    if raw is None:
        return None
    return dict(variants.make(raw).cfg)


def _body_box(mesh: dict, dim: int):
    """(lower, upper) of a generated body mesh, or None (a mesh file: checked at start-up)."""
    if "box" in mesh:
        return list(mesh["box"]["lower"])[:dim], list(mesh["box"]["upper"])[:dim]
    if "quarter_cylinder" in mesh:
        q = mesh["quarter_cylinder"]
        r, length = float(q["radius"]), float(q["length"])
        b = [float(v) for v in q.get("base", (0.0, 0.0, 0.0))]
        return b[:dim], [b[0] + r, b[1] + r, b[2] + length][:dim]
    if "ring" in mesh:
        q = mesh["ring"]
        r, c = float(q["outer_radius"]), [float(v) for v in q["centre"]]
        return [c[0] - r, c[1] - r], [c[0] + r, c[1] + r]
    return None


def _check_multirate(case: dict) -> None:
    """run.multirate = true: every foreground group must be able to substep (multi-rate,
    orchestrator/coupling/multirate.py), tied by the multipliers."""
    if case["run"].get("multirate") is not True:
        return
    from adapters import registry as roles

    method = case["coupling"].get("method", "multiplier")
    if method != "multiplier":
        raise CaseError("run.multirate", True, f"needs coupling.method = 'multiplier' (not {method!r}): "
                        "the substeps are tied by its multipliers")
    for r in roles.roles_used(case):
        if roles.coupling_side(r) == "foreground":
            why = roles.substep_refusal(r, case)
            if why:
                raise CaseError("run.multirate", True, f"the {r} group cannot take substeps: {why} "
                                "(false or unset: no group substeps)")


def check(case: dict, data: dict) -> None:
    """The registry's hook."""
    _check_multirate(case)
    if "ale" not in case:
        raise CaseError("ale", MISSING, "a [coupling] case needs the background grid [ale] its bodies move through")
    bodies = case.get("lagrange", {}).get("bodies", [])
    if not bodies and "sph" not in case:
        raise CaseError("lagrange.bodies", MISSING, "a [coupling] case needs at least one body "
                        "([[lagrange.bodies]] or the particles of [sph])")
    if "sph" in case:
        _sph_inside_grid(case, data)
    mode = case["ale"].get("mode", "eulerian")
    if mode != "eulerian":
        raise CaseError("ale.mode", data["ale"].get("mode", mode),
                        "must be 'eulerian' with [coupling] (the bodies move through the fixed grid)")
    dim = int(case["run"]["dimension"])
    for i, body in enumerate(bodies):
        box = _body_box(body["mesh"], dim)
        if box is not None:
            kind = next(iter(body["mesh"]))
            _inside_grid(case, data, i, kind, box, dim)


def _sph_inside_grid(case: dict, data: dict) -> None:
    """Every SPH body's particles (their cells) lie in the background grid (the coupler reconstructs
    the particles' surface on its nodes)."""
    from solvers.particles import cells_box

    dim = case["run"]["dimension"]
    g = case["ale"]["grid"]
    for i, body in enumerate(case["sph"]["bodies"]):
        lo, hi = cells_box(body, dim)
        if any(a < b - 1e-12 * (u - b) for a, b, u in zip(lo, g["lower"], g["upper"])) or \
                any(a > u + 1e-12 * (u - b) for a, b, u in zip(hi, g["lower"], g["upper"])):
            raise CaseError(format_key(["sph", "bodies", i, "region"]), data["sph"]["bodies"][i]["region"],
                            f"must lie inside the background grid, from ale.grid.lower = {data['ale']['grid']['lower']} "
                            f"to ale.grid.upper = {data['ale']['grid']['upper']} (m)")


def check_files(case: dict, data: dict) -> None:
    """The registry's file hook (after [lagrange]'s has read the mesh files): a mesh file's nodes
    inside the grid's box."""
    if "ale" not in case:
        return
    dim = int(case["run"]["dimension"])
    for i, body in enumerate(case.get("lagrange", {}).get("bodies", [])):
        ext = body.get("_extent")
        if "file" in body["mesh"] and ext is not None:
            _inside_grid(case, data, i, "file", (ext["lower"], ext["upper"]), dim)


def _inside_grid(case, data, i, kind, box, dim) -> None:
    """Body i's box (lower, upper) inside the grid's box by the coupler's rule (Grid.snap, Grid.beyond:
    the coordinates within a few ulps of a grid plane lie on it), or one line naming the body's mesh."""
    import numpy as np

    from orchestrator.coupling.grid import Grid

    g = case["ale"]["grid"]
    grid = Grid(g["lower"], g["upper"], g["cells"])
    corners = np.array([box[0][:dim], box[1][:dim]], dtype=np.float64)
    bad = grid.beyond(grid.snap(corners)).any(axis=0)
    if bad.any():
        d = int(np.flatnonzero(bad)[0])
        body = case["lagrange"]["bodies"][i]
        raise CaseError(format_key(["lagrange", "bodies", i, "mesh", kind]),
                        data["lagrange"]["bodies"][i]["mesh"][kind],
                        f"body {body['name']!r} must lie inside the background grid "
                        f"[{grid.lower.tolist()}, {grid.upper.tolist()}] ([coupling]); along {'xyz'[d]} its "
                        f"nodes span [{corners[0, d]!r}, {corners[1, d]!r}]")


# ---- registration (after [[boundaries]] 50) -----------------------------------------------------------
register_table("coupling", COUPLING, normalise, check, order=60, check_files=check_files)
