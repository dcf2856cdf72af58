"""SI units of the output fields (everything immerse writes is SI), for labels of pictures and charts.

Per-material fields carry the material's name as a suffix (``density_water``,
``volume_fraction_air``): they have the unit of their stem.  A field not in the table has no unit
in its label rather than a guessed one.
"""
from __future__ import annotations

DIMENSIONLESS = "1"

FIELD_UNITS: dict[str, str] = {
    # nodes
    "velocity": "m/s",
    "displacement": "m",
    "coordinates": "m",
    # Lagrangian elements
    "stress": "Pa",
    "von_mises": "Pa",
    "von_mises_stress": "Pa",
    "pressure": "Pa",
    "plastic_strain": DIMENSIONLESS,
    "temperature": "K",
    "density": "kg/m^3",
    "bulk_viscosity": "Pa",
    "contact_pressure": "Pa",
    "contact_gap": "m",
    "contact_slip": "m",
    # ALE zones
    "specific_internal_energy": "J/kg",
    "sound_speed": "m/s",
    "artificial_viscosity": "Pa",
    "blocked_fraction": DIMENSIONLESS,
    "volume_fraction": DIMENSIONLESS,
}
# stems of per-material fields: <stem>_<material>
_PER_MATERIAL = ("volume_fraction", "density", "specific_internal_energy", "pressure")


def unit_of(field: str) -> str | None:
    """The SI unit of an output field ("1" for dimensionless), None if unknown."""
    if field in FIELD_UNITS:
        return FIELD_UNITS[field]
    for stem in _PER_MATERIAL:
        if field.startswith(stem + "_"):
            return FIELD_UNITS[stem]
    return None


def with_unit(label: str, field: str) -> str:
    """``label (unit)``, e.g. "density (kg/m^3)"; dimensionless: "(-)"; unknown: the label alone."""
    u = unit_of(field)
    if u is None:
        return label
    return f"{label} ({'-' if u == DIMENSIONLESS else u})"


# Histories (diagnostics.h5, summary.json's "final"): <role>.<name>, the unit from the name's stem or
# ending.  Why by pattern: every solver adds its own names (energies, works, momenta, balances) and
# keeps to these endings.
_HISTORY_EXACT = {
    "mass": "kg", "time": "s", "step": DIMENSIONLESS, "particles": DIMENSIONLESS, "dissipation": "J",
    "iterations": DIMENSIONLESS, "residual": DIMENSIONLESS, "cond_H": DIMENSIONLESS, "stable_dt_limit": "s",
    "substeps": DIMENSIONLESS, "substep_passes": DIMENSIONLESS, "substep_residual": DIMENSIONLESS,
    "energy_in_transit": "J",
    "void_zones": DIMENSIONLESS, "tied_orphans": DIMENSIONLESS, "momentum_in_transit": "kg m/s",
    "lambda_oscillation": DIMENSIONLESS, "lambda_oscillation_max": DIMENSIONLESS,
    "newton_iterations": DIMENSIONLESS, "contact_force_x": "N", "contact_force_y": "N", "contact_force_z": "N",
}
_HISTORY_ENDINGS = (("_rel", DIMENSIONLESS), ("_energy", "J"), ("_work", "J"), ("energy", "J"), ("work", "J"),
                    ("_impulse", "N s"), ("_force", "N"), ("_count", DIMENSIONLESS), ("_dt", "s"),
                    ("_time_s", "s"), ("_mass", "kg"), ("_share", DIMENSIONLESS))
_HISTORY_PREFIXES = (("momentum_", "kg m/s"), ("angular_momentum", "kg m^2/s"), ("contact_force", "N"),
                     ("interface_momentum_", "kg m/s"), ("interface_force_", "N"), ("foreground_momentum_", "kg m/s"),
                     ("impulse_", "N s"), ("force_", "N"), ("substeps_", DIMENSIONLESS))
PROBE_UNITS = {"displacement": "m", "velocity": "m/s", "position": "m"}


def history_unit(key: str, probes: dict | None = None) -> str | None:
    """The SI unit of a history ``<role>.<name>`` ("1" dimensionless), None if unknown; a probe's
    (``<role>.probe_<name>``) from its quantity in ``probes`` (the case's normalised [probes])."""
    name = key.split(".", 1)[-1]
    if name.startswith("probe_"):
        stem = name[len("probe_"):]
        p = (probes or {}).get(stem) or (probes or {}).get(stem.rsplit("_", 1)[0])   # (a line's <name>_<k>)
        return PROBE_UNITS.get(p["quantity"], FIELD_UNITS.get(p["quantity"])) if p else None
    if name in _HISTORY_EXACT:
        return _HISTORY_EXACT[name]
    for stem, unit in _HISTORY_PREFIXES:
        if name.startswith(stem):
            return unit
    for end, unit in _HISTORY_ENDINGS:
        if name.endswith(end):
            return unit
    return None
