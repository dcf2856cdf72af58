"""Given states of the ALE background checked against their materials' equations of state
(`immerse check` and `immerse run` before anything starts; orchestrator/cli.py _admit): a region's
or a face's density and pressure that are no state of the material's EOS (an ideal gas at negative
pressure) get one line naming the key.  Not in the schema's checks: those stay light (no numba; the
EOS functions are the solvers' compiled ones)."""
from __future__ import annotations

from orchestrator.schema.rules import CaseError, format_key


def _valid_state(key: str, value, material: str, props: dict, rho: float, p: float) -> None:
    from solvers.ale import eos as _eos

    code, par = _eos.eos_params(props["eos"], props)
    e = float(_eos.energy_from_pressure(code, par, float(rho), float(p)))
    p2, c, ok = _eos.state(code, par, float(rho), e)
    if not ok:
        raise CaseError(key, value, f"must be a valid state of material {material!r} ({_eos.describe(code, par)}): "
                        f"density {rho:g} kg/m^3 and pressure {p:g} Pa give e = {e:.6g} J/kg, p = {p2:.6g} Pa, "
                        f"sound speed {c:.6g} m/s")


def check_states(case: dict) -> None:
    """The regions' and the faces' given states against their materials' equations of state."""
    ale = case.get("ale")
    if not ale:
        return
    mats = ale["materials"]
    for i, reg in enumerate(ale["regions"]):
        props = mats.get(reg["material"], {})
        if props.get("eos") not in (None, "void") and "density" in reg and "pressure" in reg:
            _valid_state(format_key(["ale", "regions", i]), reg, reg["material"], props, reg["density"],
                         reg["pressure"])
    solid = [m for m, v in mats.items() if v["eos"] != "void"]
    for f, face in ale["boundaries"].items():
        if not isinstance(face, dict):
            continue
        (kind, body), = face.items()
        name = body.get("material", solid[0] if len(solid) == 1 else None)
        if "density" in body and "pressure" in body and name is not None:
            _valid_state(format_key(["ale", "boundaries", f, kind]), body, name, mats[name], body["density"],
                         body["pressure"])
