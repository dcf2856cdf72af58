"""The LAMMPS input lines a case may add to its SPH group (``sph.lammps_commands``), checked against an
allow-list before anything launches (and again by the adapter, before LAMMPS sees them).

Case files are data: a line may adjust what the schema does not cover (an extra fix that adds a
force, a group, a compute, neighbour settings), never run a program, load code, read or write a
file, or take the time loop from the coupler.  A line is accepted when

* it is one line of printable text (no newline, no ``&`` continuation, no quotes, which LAMMPS
  would use to join or span lines), without ``$`` substitutions (an immediate ``$(...)`` or
  ``${...}`` is expanded by LAMMPS before the command is parsed, so what it runs is not the line
  checked here);
* its command is in :data:`COMMANDS`; ``fix``, ``compute`` and ``variable`` also need their style
  in :data:`FIX_STYLES`, :data:`COMPUTE_STYLES`, :data:`VARIABLE_STYLES`;
* no word of it is a keyword that names a file or a stream (:data:`FILE_KEYWORDS`: ``file``,
  ``append``, ``screen``, ``out``, ...), whatever the command;
* its fix and compute IDs do not start with ``immerse`` (the adapter's own).

Everything else (``shell``, ``python``, ``include``, ``write_*``, ``dump``, ``log``, ``fix print``,
``print``, ``plugin``, ``run``, ``timestep``, ``read_*``, ``jump``, ``label``, ...) is refused with
the reason.
"""
from __future__ import annotations

import re

COMMANDS = frozenset({
    "atom_modify", "comm_modify", "compute", "compute_modify", "displace_atoms",
    "fix", "fix_modify", "group", "neigh_modify", "neighbor", "pair_modify", "region", "set",
    "thermo", "thermo_modify", "thermo_style", "uncompute", "unfix", "variable", "velocity",
})
"""Commands that change the model in memory only (not the number of particles: the output and the
coupling follow particles by id for the whole run, so ``delete_atoms`` and ``create_atoms`` are out)."""

FIX_STYLES = frozenset({
    "addforce", "aveforce", "enforce2d", "gravity", "lineforce", "momentum", "move", "planeforce",
    "recenter", "setforce", "smd/setvel", "spring", "sph/stationary", "viscous", "wall/reflect",
    "wall/region",
})
"""Fixes that add forces, constraints or walls (none writes a file or runs a command)."""

COMPUTE_STYLES = frozenset({
    "com", "count/type", "erotate/sphere", "group/group", "ke", "ke/atom", "pe", "pressure",
    "property/atom", "reduce", "reduce/region", "smd/contact/radius", "smd/damage",
    "smd/internal/energy", "smd/plastic/strain", "smd/plastic/strain/rate", "smd/rho",
    "smd/tlsph/defgrad", "smd/tlsph/dt", "smd/tlsph/num/neighs", "smd/tlsph/shape",
    "smd/tlsph/strain", "smd/tlsph/strain/rate", "smd/tlsph/stress", "smd/vol", "sph/e/atom",
    "sph/rho/atom", "sph/t/atom", "stress/atom", "temp", "vcm",
})

VARIABLE_STYLES = frozenset({"equal", "atom", "vector", "index", "internal", "loop", "string"})
"""Formula and list variables (not ``python``, ``file``, ``atomfile``, ``getenv``, ``shell`` ...)."""

FILE_KEYWORDS = frozenset({
    "append", "file", "fileper", "log", "nfile", "out", "overwrite", "screen", "universe",
    "write",
})

OWN_PREFIX = "immerse"
"""IDs of the adapter's own fixes and computes (a case line may not replace or remove them)."""

_PRINTABLE = re.compile(r"^[\x20-\x7e]*$")


class LammpsLineError(ValueError):
    """A refused line: str() says why."""


def check_line(line: str) -> None:
    """Raise :class:`LammpsLineError` naming why ``line`` may not run; return for an allowed line."""
    if not isinstance(line, str):
        raise LammpsLineError("must be a string")
    if not _PRINTABLE.match(line):
        raise LammpsLineError("must be one line of printable ASCII (no newlines or control characters)")
    body = line.split("#", 1)[0].strip()
    if not body:
        return
    for ch, why in (("$", "variable substitution ($) is not allowed (it is expanded before the command is checked)"),
                    ("&", "line continuation (&) is not allowed"),
                    ('"', "quotes are not allowed"), ("'", "quotes are not allowed")):
        if ch in body:
            raise LammpsLineError(why)
    words = body.split()
    cmd = words[0]
    if cmd not in COMMANDS:
        raise LammpsLineError(f"command {cmd!r} is not allowed; allowed: {', '.join(sorted(COMMANDS))}")
    for w in words[1:]:
        if w.lower() in FILE_KEYWORDS:
            raise LammpsLineError(f"keyword {w!r} (files and output streams) is not allowed")
    if cmd in ("fix", "compute"):
        if len(words) < 4:
            raise LammpsLineError(f"{cmd} needs an ID, a group and a style")
        styles = FIX_STYLES if cmd == "fix" else COMPUTE_STYLES
        style = words[3]
        if style not in styles:
            raise LammpsLineError(f"{cmd} style {style!r} is not allowed; allowed: {', '.join(sorted(styles))}")
    if cmd in ("fix", "compute", "unfix", "uncompute", "fix_modify", "compute_modify"):
        if len(words) > 1 and words[1].lower().startswith(OWN_PREFIX):
            raise LammpsLineError(f"IDs starting with {OWN_PREFIX!r} belong to immerse")
    if cmd == "variable":
        if len(words) < 3:
            raise LammpsLineError("variable needs a name and a style")
        if words[2] not in VARIABLE_STYLES:
            raise LammpsLineError(f"variable style {words[2]!r} is not allowed; allowed: "
                                  + ", ".join(sorted(VARIABLE_STYLES)))
