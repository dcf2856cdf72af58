"""The embedded-mesh coupling's table of case.toml, ``[coupling]``: bodies of the Lagrangian solver
immersed in the ALE background, tied by the method the table names (orchestrator/coupling/variants.py:
each variant registers itself with its schema fragment and its cross-field check).

Normalised layout (``case["coupling"]``, present when the file has the table): the variant's keys
with its defaults filled in, e.g. ``{method: "multiplier", condition: "tied" | "slip", alpha, beta}``.

Cross-field rules: a coupled case needs the background (``[ale]``, Eulerian mode: the bodies move
through the fixed grid) and bodies (``[[lagrange.bodies]]``); every body made from a box or a
quarter cylinder lies inside the grid's box (a mesh file's nodes are checked when the run starts);
one gas material in the background (several materials or void beside coupled bodies: not yet).
"""
from __future__ import annotations

from orchestrator.coupling import variants

from .schema_registry import register_table
from .schema_rules import MISSING, CaseError, format_key

def _schema() -> dict:
    """The variants' branches (variants.schema()) under a closed table of all their keys: a key of
    another variant gets the variant's own message, an unknown key the schema's."""
    s = variants.schema()
    props = {}
    for branch in s["allOf"]:
        props.update(branch["then"]["properties"])
    props["method"] = s["properties"]["method"]
    return {**s, "properties": props, "additionalProperties": False}


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
        return [0.0, 0.0, 0.0][:dim], ([r, r, length] if dim == 3 else [r, length])
    return None


def check(case: dict, data: dict) -> None:
    """The registry's hook."""
    raw = data["coupling"]
    if "ale" not in case:
        raise CaseError("ale", MISSING, "a [coupling] case needs the background grid [ale] its bodies move through")
    bodies = case.get("lagrange", {}).get("bodies", [])
    if not bodies:
        raise CaseError("lagrange.bodies", MISSING, "a [coupling] case needs at least one body ([[lagrange.bodies]])")
    from solvers.ale.points import several_materials

    if several_materials(case["ale"]):
        raise CaseError("ale.regions", data["ale"]["regions"],
                        "one gas material with [coupling] (several materials or void beside coupled "
                        "bodies are not supported yet)")
    mode = case["ale"].get("mode", "eulerian")
    if mode != "eulerian":
        raise CaseError("ale.mode", data["ale"].get("mode", mode),
                        "must be 'eulerian' with [coupling] (the bodies move through the fixed grid)")
    dim = int(case["run"]["dimension"])
    g = case["ale"]["grid"]
    lo, hi = [float(v) for v in g["lower"]], [float(v) for v in g["upper"]]
    for i, body in enumerate(bodies):
        box = _body_box(body["mesh"], dim)
        if box is None:
            continue
        blo, bhi = box
        for d in range(dim):
            tol = 1e-9 * (hi[d] - lo[d])
            if blo[d] < lo[d] - tol or bhi[d] > hi[d] + tol:
                kind = next(iter(body["mesh"]))
                raise CaseError(format_key(["lagrange", "bodies", i, "mesh", kind]),
                                data["lagrange"]["bodies"][i]["mesh"][kind],
                                f"body {body['name']!r} must lie inside the background grid "
                                f"[{lo}, {hi}] ([coupling]); along {'xyz'[d]} it spans "
                                f"[{blo[d]:g}, {bhi[d]:g}]")
    del raw


# ---- registration (after [[boundaries]] 50) -----------------------------------------------------------
register_table("coupling", COUPLING, normalise, check, order=60)
