"""The contact table of case.toml, ``[contact]``: which Lagrangian bodies touch which, by what method
(solvers/contact/methods.py: the methods register themselves by name), enforced by impulses from a
multiplier solve every step (solvers/contact/explicit.py).

    [contact]
    pairs = [["striker", "target"], ["ring", "ring"]]   # a body twice: self contact
    method = "dual_pass_mortar"                        # default; or mortar, node_to_surface, penalty, ...
    alpha = 1.0                                        # stabilization weight (> 0); penalty methods:
                                                       # compliance factor, k = 100 E / (alpha h)
    capture = 1e-3                                     # search distance, m (default: median element edge)
    friction = 0.2                                     # Coulomb's mu (default 0: frictionless)
    return_energy = true                               # midpoint only: step 3 of the three-step update
                                                       # (give back on release what the contact took)

Normalised layout (``case["contact"]``): the same keys with the defaults filled in (capture only when
given). Cross-field rules: the bodies are [[lagrange.bodies]] names, a pair names two bodies (or one
twice), no pair twice; self contact only with a method that handles it; 2-D only so far (the 3-D
facet mortar is to come).
"""
from __future__ import annotations

from solvers.contact.methods import METHODS

from .parts import number, table
from .parts import name as name_schema
from .registry import register_table
from .rules import CaseError, format_key

CONTACT = table(
    {
        "pairs": {"type": "array", "minItems": 1,
                  "items": {"type": "array", "items": name_schema(), "minItems": 2, "maxItems": 2},
                  "description": "The pairs of [[lagrange.bodies]] names that may touch, e.g. [[\"striker\", "
                                 "\"target\"]]; a body twice is self contact."},
        "method": {"enum": sorted(METHODS), "default": "dual_pass_mortar",
                   "description": "How the gaps are measured and enforced. dual_pass_mortar: Puso & Solberg's "
                                  "stabilized dual-pass mortar (2-D and 3-D, self contact); mortar: single-pass "
                                  "mortar (biased); node_to_surface(_double): one side's nodes (both sides') on "
                                  "the other's facets; penalty, node_to_surface(_double)_penalty: the same gaps with "
                                  "a penalty law (2-D comparisons)."},
        "alpha": number(exclusiveMinimum=0.0, default=1.0,
                        description="Weight of the stabilization term J of the multiplier solve; penalty methods: "
                                    "the compliance factor, stiffness k = 100 E / (alpha h)."),
        "capture": number("m", exclusiveMinimum=0.0,
                          description="Search distance: facets and nodes closer than this are tested for contact "
                                      "(default: the median element edge)."),
        "friction": number("dimensionless", minimum=0.0, default=0.0,
                           description="Coulomb friction coefficient mu: tangential impulses bounded by mu times "
                                       "the normal ones (0: frictionless; mortar methods, explicit integrator)."),
        "return_energy": {"type": "boolean", "default": True,  # (solvers/lagrange/implicit_dynamic.py)
                          "description": "midpoint integrator: when a pair's contact ends, give back along its last "
                                         "force the energy the contact took (false: it stays lost, "
                                         "contact_lost_energy)."},
    },
    required=("pairs",),
    description="Contact between Lagrangian bodies, enforced every step by impulses from a multiplier solve.",
)


def normalise(raw: dict | None, case: dict) -> dict | None:
    if raw is None:
        return None
    out = {"pairs": [list(p) for p in raw["pairs"]], "method": raw.get("method", "dual_pass_mortar"),
           "alpha": float(raw.get("alpha", 1.0)), "friction": float(raw.get("friction", 0.0))}
    if "capture" in raw:
        out["capture"] = float(raw["capture"])
    if "return_energy" in raw:
        out["return_energy"] = bool(raw["return_energy"])
    return out


def check(case: dict, data: dict) -> None:
    c = case["contact"]
    dim = case["run"]["dimension"]
    if dim == 3 and not METHODS[c["method"]].three_d:
        ok = ", ".join(k for k, m in METHODS.items() if m.three_d)
        raise CaseError("contact.method", c["method"], f"not in 3-D (run.dimension = 3); allowed: {ok}")
    names = [b["name"] for b in case.get("lagrange", {}).get("bodies", [])]
    if not names:
        raise CaseError("contact", data.get("contact"), "contact is between Lagrangian bodies: [[lagrange.bodies]] has none")
    integrator = (case.get("lagrange") or {}).get("integrator", "explicit")
    if "return_energy" in c and integrator != "midpoint":
        raise CaseError("contact.return_energy", data["contact"]["return_energy"],
                        f"a step of the midpoint scheme's contact update; lagrange.integrator = {integrator!r}: "
                        "allowed: leave it out")
    seen = {}
    for i, pair in enumerate(c["pairs"]):
        for j, n in enumerate(pair):
            if n not in names:
                raise CaseError(format_key(["contact", "pairs", i, j]), n,
                                f"not a body; bodies: {', '.join(names)}")
        key = tuple(sorted(pair))
        if key in seen:
            raise CaseError(format_key(["contact", "pairs", i]), pair, f"the same pair as contact.pairs[{seen[key]}]")
        seen[key] = i
        if c["friction"] > 0.0 and integrator != "explicit":
            raise CaseError("contact.friction", c["friction"], f"friction is enforced by the explicit step's "
                            f"impulses; lagrange.integrator = {integrator!r} is frictionless: allowed 0")
        if c["friction"] > 0.0 and c["method"] not in ("dual_pass_mortar", "mortar"):
            raise CaseError("contact.friction", c["friction"], f"friction needs a mortar method (dual_pass_mortar, "
                            f"mortar); method = {c['method']!r}")
        if pair[0] == pair[1] and not METHODS[c["method"]].self_contact:
            ok = ", ".join(k for k, m in METHODS.items() if m.self_contact)
            raise CaseError(format_key(["contact", "pairs", i]), pair,
                            f"self contact needs a method that handles it ({ok}); method = {c['method']!r}")


register_table("contact", CONTACT, normalise, check, order=35)
