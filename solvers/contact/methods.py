"""The contact methods by name, all behind one interface (constraint_operator, stabilization, forces,
gaps, n_multipliers) so that a case or a campaign sets them side by side (issue 11's comparisons):

* ``dual_pass_mortar`` (default): Puso & Solberg's stabilized dual pass (dual_pass.py);
* ``mortar``: standard single-pass mortar, side a non-mortar (biased);
* ``node_to_surface``: single pass, side a's nodes on side b (fails the patch test);
* ``node_to_surface_double``: both sides' nodes (over-constrained: locks);
* ``penalty``: the dual pass's mortar gaps with a penalty law instead of the stabilization
  (penalty.py: J is the compliance h / (kappa E), kappa = 100 / alpha);
* ``node_to_surface_penalty``, ``node_to_surface_double_penalty``: node-to-surface, single and
  double pass, with the same penalty law per tributary length (the double pass's locking as a
  stiff penalty rather than a singular system).

A method is ``build(points, seg_a, seg_b, capture, penetration)``, registered by name with the
module and class that build it (imported on first use: the case schema reads the names without
loading the kernels) and whether it handles self contact.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field

__all__ = ["METHODS", "Method", "register", "build"]


@dataclass(frozen=True)
class Method:
    module: str
    attr: str
    kwargs: dict = field(default_factory=dict)
    self_contact: bool = False
    three_d: bool = False   # has quadrilateral facets (mortar_facets.py); tested in 3-D


METHODS: dict[str, Method] = {}


def register(name: str, method: Method) -> None:
    if name in METHODS:
        raise ValueError(f"contact method {name!r} registered twice")
    METHODS[name] = method


register("dual_pass_mortar", Method("solvers.contact.dual_pass", "DualPassContact", self_contact=True, three_d=True))
register("mortar", Method("solvers.contact.dual_pass", "SinglePassMortar"))
register("node_to_surface", Method("solvers.contact.node_to_surface", "NodeToSurface", {"passes": 1}))
register("node_to_surface_double", Method("solvers.contact.node_to_surface", "NodeToSurface", {"passes": 2}))
register("penalty", Method("solvers.contact.penalty", "PenaltyMortar", self_contact=True))
register("node_to_surface_penalty", Method("solvers.contact.penalty", "PenaltyNodeToSurface", {"passes": 1}))
register("node_to_surface_double_penalty", Method("solvers.contact.penalty", "PenaltyNodeToSurface", {"passes": 2}))


def build(method: str, points, seg_a, seg_b, capture: float, penetration: float | None = None):
    """The operators of ``method`` (a KeyError names the registered ones); seg_b None: self contact."""
    if method not in METHODS:
        raise KeyError(f"contact method {method!r}: registered: {', '.join(sorted(METHODS))}")
    m = METHODS[method]
    if seg_b is None and not m.self_contact:
        raise NotImplementedError(f"self contact with {method!r}: only "
                                  f"{', '.join(k for k, v in METHODS.items() if v.self_contact)}")
    cls = getattr(importlib.import_module(m.module), m.attr)
    return cls(points, seg_a, seg_b, capture, penetration, **m.kwargs)
