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
                  "items": {"type": "array", "items": name_schema(), "minItems": 2, "maxItems": 2}},
        "method": {"enum": sorted(METHODS)},
        "alpha": number(exclusiveMinimum=0.0),
        "capture": number("m", exclusiveMinimum=0.0),
        "friction": number("dimensionless", minimum=0.0),
        "return_energy": {"type": "boolean"},
    },
    required=("pairs",),
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
