"""Older spellings of case keys, read under their one name with a one-line note (``immerse check``
and ``immerse run`` print it): one vocabulary for a quantity across the solvers' tables.

The reference density of a material is ``density`` in every table ([materials] of the bodies,
[sph] materials and bodies, [ale.materials]); the background's equations of state (tait, jwl,
mie_gruneisen) used to call it ``rho0``.  A case that gives both for one material is refused (one
line): which one it means is not ours to guess.

The particles' material laws take the background's EOS names where the law is the same
(``sph.materials.<name>.model = "tait"`` / ``"ideal_gas"``); LAMMPS's pair-style names
``taitwater`` / ``idealgas`` are read under them with a note (VALUE_SPELLINGS).
"""
from __future__ import annotations

from .rules import CaseError, format_key

_DENSITY = "the reference density's one name in every table ([materials], [sph] materials, [ale.materials])"
SPELLINGS = (
    # (the path of keys to a {name: material} table, or to one material table (named=False); old; new; why)
    (("ale", "materials"), True, "rho0", "density", _DENSITY),
    (("check", "params", "eos_left"), False, "rho0", "density", _DENSITY),    # (EOS tables of a check)
    (("check", "params", "eos_right"), False, "rho0", "density", _DENSITY),
)


_SPH_MODEL = ("the background's EOS name for the same law (sph.materials model names LAMMPS's pair style "
              "before)")
VALUE_SPELLINGS = (
    # (the path of keys to a {name: material} table; key; old value; new value; why)
    (("sph", "materials"), "model", "taitwater", "tait", _SPH_MODEL),
    (("sph", "materials"), "model", "idealgas", "ideal_gas", _SPH_MODEL),
)


def _table_at(data: dict, path: tuple) -> dict | None:
    """The table at ``path`` in the raw case, or None where it is absent or not a table."""
    table = data
    for k in path:
        table = table.get(k) if isinstance(table, dict) else None
    return table if isinstance(table, dict) else None


def respell(data: dict) -> list[str]:
    """Rename every older spelling in the raw case ``data`` in place (before the schema sees it);
    returns the notes, one line each."""
    notes = []
    for path, named, old, new, why in SPELLINGS:
        if (table := _table_at(data, path)) is None:
            continue
        for name, m in (table.items() if named else [(None, table)]):
            if not isinstance(m, dict) or old not in m:
                continue
            key = format_key([*path, name] if named else list(path))
            if new in m:
                raise CaseError(f"{key}.{old}", m[old], f"give only {new} (its one spelling; {old} is the older "
                                f"one and {key}.{new} is given too)")
            m[new] = m.pop(old)
            notes.append(f"note: {key}.{old} is read as {new}: {why}")
    for path, key, old, new, why in VALUE_SPELLINGS:
        if (table := _table_at(data, path)) is None:
            continue
        for name, m in table.items():
            if isinstance(m, dict) and m.get(key) == old:
                m[key] = new
                notes.append(f"note: {format_key([*path, name, key])} = {old!r} is read as {new!r}: {why}")
    return notes
