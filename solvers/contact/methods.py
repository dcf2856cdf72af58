"""The contact methods by name, all behind one interface (constraint_operator, stabilization, forces,
gaps, n_multipliers) so that a case or a campaign sets them side by side (issue 11's comparisons):

* ``dual_pass_mortar`` (default): Puso & Solberg's stabilized dual pass (dual_pass.py);
* ``mortar``: standard single-pass mortar, side a non-mortar (biased);
* ``node_to_surface``: single pass, side a's nodes on side b (fails the patch test);
* ``node_to_surface_double``: both sides' nodes (locks).

A method is ``build(points, seg_a, seg_b, capture, penetration)``; register a new one with
``@register("name")``.
"""
from __future__ import annotations

from functools import partial
from typing import Callable

from solvers.contact.dual_pass import DualPassContact, SinglePassMortar
from solvers.contact.node_to_surface import NodeToSurface

METHODS: dict[str, Callable] = {}


def register(name: str):
    def deco(build: Callable) -> Callable:
        if name in METHODS:
            raise ValueError(f"contact method {name!r} registered twice")
        METHODS[name] = build
        return build
    return deco


register("dual_pass_mortar")(DualPassContact)
register("mortar")(SinglePassMortar)
register("node_to_surface")(partial(NodeToSurface, passes=1))
register("node_to_surface_double")(partial(NodeToSurface, passes=2))


def build(method: str, points, seg_a, seg_b, capture: float, penetration: float | None = None):
    """The operators of ``method`` (a KeyError names the registered ones)."""
    if method not in METHODS:
        raise KeyError(f"contact method {method!r}: registered: {', '.join(sorted(METHODS))}")
    return METHODS[method](points, seg_a, seg_b, capture, penetration)
