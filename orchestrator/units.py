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
