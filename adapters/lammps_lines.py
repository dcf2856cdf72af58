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
* its fix and compute IDs do not start with ``immerse`` (the adapter's own);
* its memory and distance settings are bounded (:data:`LIMITS`): neighbour pages and the most
  neighbours of a particle (``neigh_modify page/one``), bin sizes no finer than a quarter of the
  smoothing length, ghost cutoffs and skins no longer than the domain (a cutoff of 1e6 m ghosts
  every particle thousands of times over a periodic face).

Everything else (``shell``, ``python``, ``include``, ``write_*``, ``dump``, ``log``, ``fix print``,
``print``, ``plugin``, ``run``, ``timestep``, ``read_*``, ``jump``, ``label``, ...) is refused with
the reason.

Here, below both of its users (the [sph] table's schema, orchestrator/schema/sph.py, and the SPH
adapter, adapters/sph.py): the adapters import nothing from the orchestrator above them.
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


ONE_MAX = 100_000
"""neigh_modify one: the most neighbours of one particle (LAMMPS's default 2000; a 3-D particle at
h = 3 dx has about 500 inside 2 h)."""
PAGE_MAX = 10_000_000
"""neigh_modify page: neighbour-list entries a page (LAMMPS's default 100000, 0.4 MB a page)."""

LIMITS = {
    # command: {keyword: (kind, what it bounds)}; kinds: "int:<max>", "length" (0 .. the domain's
    # extent), "bin" (0, or h / 4 .. the domain's extent)
    "neigh_modify": {"one": f"int:{ONE_MAX}", "page": f"int:{PAGE_MAX}", "binsize": "bin"},
    "comm_modify": {"cutoff": "length"},
    "atom_modify": {"sort": "sort"},
}


class LammpsLineError(ValueError):
    """A refused line: str() says why."""


def _number(word: str, what: str) -> float:
    try:
        v = float(word)
    except ValueError:
        raise LammpsLineError(f"{what} must be a number, not {word!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise LammpsLineError(f"{what} must be a finite number, not {word!r}")
    return v


def _check_bounds(words: list[str], extent: float | None, h: float | None) -> None:
    """The memory and distance settings of ``words`` (a command and its arguments) within LIMITS."""
    cmd = words[0]
    far = extent if extent is not None else float("inf")
    fine = h / 4.0 if h is not None else 0.0

    def length(word, what, lo=0.0):
        v = _number(word, what)
        if v < lo or v > far:
            raise LammpsLineError(f"{what} = {word} must be >= {lo:g} and <= the domain's extent "
                                  f"({far:g} m)")
        return v

    def binsize(word, what):
        v = _number(word, what)
        if v != 0.0 and (v < fine or v > far):
            raise LammpsLineError(f"{what} = {word} must be 0 (LAMMPS's choice) or between a quarter of "
                                  f"the smoothing length ({fine:g} m) and the domain's extent ({far:g} m)")

    if cmd == "neighbor" and len(words) > 1:
        length(words[1], "neighbor skin")
    limits = LIMITS.get(cmd, {})
    one = 2000
    for i, w in enumerate(words[1:], start=1):
        kind = limits.get(w)
        if kind is None:
            continue
        arg = words[i + 1] if i + 1 < len(words) else None
        if arg is None:
            raise LammpsLineError(f"{cmd} {w} needs a value")
        what = f"{cmd} {w}"
        if kind.startswith("int:"):
            top = int(kind[4:])
            if not re.fullmatch(r"\d{1,12}", arg) or not 1 <= int(arg) <= top:
                raise LammpsLineError(f"{what} = {arg} must be an integer from 1 to {top}")
            if w == "one":
                one = int(arg)
            elif int(arg) < 10 * one and "one" not in words[i + 2:]:
                raise LammpsLineError(f"{what} = {arg} must be >= 10 x neigh_modify one ({10 * one})")
        elif kind == "length":
            length(arg, what)
        elif kind == "bin":
            binsize(arg, what)
        elif kind == "sort":  # sort Nfreq binsize
            if not re.fullmatch(r"\d{1,9}", arg):
                raise LammpsLineError(f"{what} = {arg}: Nfreq must be an integer >= 0")
            binsize(words[i + 2] if i + 2 < len(words) else "", f"{what} binsize")


def check_line(line: str, extent: float | None = None, h: float | None = None) -> None:
    """Raise :class:`LammpsLineError` naming why ``line`` may not run; return for an allowed line.
    ``extent``, ``h``: the SPH domain's largest extent and the smoothing length (m), which bound
    the line's distances (LIMITS); without them only the absolute limits apply."""
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
    _check_bounds(words, extent, h)
    if cmd == "variable":
        if len(words) < 3:
            raise LammpsLineError("variable needs a name and a style")
        if words[2] not in VARIABLE_STYLES:
            raise LammpsLineError(f"variable style {words[2]!r} is not allowed; allowed: "
                                  + ", ".join(sorted(VARIABLE_STYLES)))


def line_scales(sph: dict) -> tuple[float, float]:
    """(the domain's largest extent, the smoothing length) in m of a normalised [sph] table: what
    bounds the distances of a ``lammps_commands`` line."""
    d = sph["domain"]
    return (max(hi - lo for lo, hi in zip(d["lower"], d["upper"])), float(sph["smoothing_length"]))
