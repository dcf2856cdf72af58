"""Particle lattices filling the regions of a case's SPH bodies (used by the LAMMPS adapter to create
the particles and by the case checks to count them before anything launches).

A body's region is one of ``{"box": {lower, upper}}``, ``{"sphere": {centre, radius}}`` (a disc in
2-D), ``{"cylinder": {base, axis, radius, length}}`` (3-D; the axis is "x", "y" or "z") and may be
narrowed by ``where``, a boolean expression in ``x, y[, z]`` (solvers.expressions).  Particles sit
at the centres of the cells of a square / cubic lattice of spacing dx anchored at the region's
lower corner (so a box of n dx holds exactly n particles per side and its particles' volumes
dx^dim add up to the box's); each particle carries the volume dx^dim.
"""
from __future__ import annotations

import io
import re
import warnings

import numpy as np

from solvers.expressions import BOOL, compile_expression

IDEALGAS_GAMMA = 1.4
"""The ratio of specific heats LAMMPS's pair sph/idealgas hard-codes (p = 0.4 rho e): the initial
energies (adapters/lammps_model.py), the sound speed of the stable step (solvers/particle_sums.py)
and the output pressure take it from here."""


def tait_b(mat: dict) -> float:
    """Tait's stiffness B = c0^2 rho0 / 7 of a taitwater material (pair sph/taitwater:
    p = B ((rho / rho0)^7 - 1)); -B is the least pressure the law gives."""
    return mat["sound_speed"] ** 2 * mat["density"] / 7.0


def tait_density(mat: dict, p):
    """The density at which a taitwater material's pressure is p: rho0 (1 + p / B)^(1/7)."""
    return mat["density"] * (1.0 + p / tait_b(mat)) ** (1.0 / 7.0)


def bounds(region: dict, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned box around a region (m)."""
    if "box" in region:
        return np.asarray(region["box"]["lower"], float), np.asarray(region["box"]["upper"], float)
    if "sphere" in region:
        c, r = np.asarray(region["sphere"]["centre"], float), float(region["sphere"]["radius"])
        return c - r, c + r
    cyl = region["cylinder"]
    base, r, length = np.asarray(cyl["base"], float), float(cyl["radius"]), float(cyl["length"])
    a = "xyz".index(cyl["axis"])
    lo, hi = base - r, base + r
    lo[a], hi[a] = base[a], base[a] + length
    return lo, hi


def lattice_counts(region: dict, spacing: float, dim: int) -> np.ndarray:
    lo, hi = bounds(region, dim)
    return np.maximum(np.rint((hi - lo) / spacing).astype(np.int64), 1)


def lattice_points(region: dict, spacing: float, dim: int) -> np.ndarray:
    """(n, dim) particle positions of one body (C order of the lattice: x slowest)."""
    lo, _ = bounds(region, dim)
    counts = lattice_counts(region, spacing, dim)
    axes = [lo[d] + (np.arange(counts[d]) + 0.5) * spacing for d in range(dim)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    return x[points_in(region, x, dim, box=False)]


def sample_points(body: dict, dim: int, size: int, seed: int = 0) -> np.ndarray:
    """The body's particles among ``size`` lattice points drawn uniformly at random from its region's
    box lattice (each axis index independently: no product of counts that could overflow): what a
    check can afford on a lattice too large to build."""
    region, spacing = body["region"], body["spacing"]
    lo, _ = bounds(region, dim)
    counts = lattice_counts(region, spacing, dim)
    rng = np.random.default_rng(seed)
    x = np.stack([lo[d] + (rng.integers(0, counts[d], size) + 0.5) * spacing for d in range(dim)], axis=1)
    return x[points_in(region, x, dim, box=False)]


def points_in(region: dict, x: np.ndarray, dim: int, box: bool = True) -> np.ndarray:
    """(n,) bool: which points lie in the region (its box or shape, and its ``where``); ``box``
    False skips the box test (a lattice built inside it)."""
    keep = np.ones(len(x), bool)
    if box and "box" in region:
        lo, hi = bounds(region, dim)
        keep &= np.all((x >= lo) & (x <= hi), axis=1)
    if "sphere" in region:
        c, r = np.asarray(region["sphere"]["centre"], float), float(region["sphere"]["radius"])
        keep &= np.sum((x - c) ** 2, axis=1) <= r * r
    elif "cylinder" in region:
        cyl = region["cylinder"]
        a = "xyz".index(cyl["axis"])
        off = x - np.asarray(cyl["base"], float)
        if box:
            keep &= (off[:, a] >= 0.0) & (off[:, a] <= float(cyl["length"]))
        off[:, a] = 0.0
        keep &= np.sum(off ** 2, axis=1) <= float(cyl["radius"]) ** 2
    if region.get("where"):
        names = ("x", "y", "z")[:dim]
        f = compile_expression(region["where"], names, kind=BOOL)
        keep &= np.asarray(f(*(x[:, d] for d in range(dim))), bool)
    return keep


# the Atoms lines of the LAMMPS atom styles whose data files give particle positions here: (the
# column of x, then y z; the number of columns) in LAMMPS's read_data formats (image flags may follow)
DATA_STYLES = {"atomic": (2, 5), "charge": (3, 6), "sphere": (4, 7), "sph": (5, 8), "smd": (10, 13),
               "bond": (3, 6), "molecular": (3, 6), "full": (4, 7)}


class DataFileError(ValueError):
    """A LAMMPS data file this reader cannot take (the message names the line); ``allowed``: what
    would be taken, where the file is fine but too large."""

    def __init__(self, message: str, allowed: str | None = None):
        super().__init__(message)
        self.allowed = allowed


_ATOMS_COUNT = re.compile(r"^[ \t]*(\d+)[ \t]+atoms[ \t\r]*(?:#.*)?$", re.MULTILINE)
_ATOMS_HEADER = re.compile(r"^[ \t]*Atoms[ \t\r]*(?:#(.*))?$", re.MULTILINE)


def read_data_positions(text: str, dim: int, max_atoms: int | None = None) -> np.ndarray:
    """(n, dim) particle positions from the text of a LAMMPS data file, in atom-id order: the
    header's ``N atoms`` (refused above ``max_atoms`` before anything is parsed), then the N lines of
    the ``Atoms`` section, its style from the section's comment (``Atoms # sph``; atomic when none),
    the x y z columns of that style (DATA_STYLES; image flags may follow). Parsed by numpy's text
    reader (C: 0.5 s a million lines of 46 bytes here), not line by line in Python. Only positions are read: the case
    gives each body's material, density, velocity and spacing (the particles' volume)."""
    section = _ATOMS_HEADER.search(text)
    if section is None:
        raise DataFileError("has no Atoms section")
    count = _ATOMS_COUNT.search(text, 0, section.start())
    if count is None:
        raise DataFileError("has no 'N atoms' line in its header (LAMMPS needs one)")
    n = int(count.group(1))
    if n < 1:
        raise DataFileError("declares 0 atoms")
    if max_atoms is not None and n > max_atoms:
        raise DataFileError(f"declares {n} atoms in its header", f"at most {max_atoms} atoms")
    comment = (section.group(1) or "").strip()
    style = comment.split()[0] if comment else "atomic"
    if style not in DATA_STYLES:
        line = text.count("\n", 0, section.start()) + 1
        raise DataFileError(f"line {line}: Atoms style {style!r}; allowed: " + ", ".join(DATA_STYLES))
    at, ncol = DATA_STYLES[style]
    try:
        with warnings.catch_warnings():   # (numpy notes that blank lines do not count towards max_rows: wanted)
            warnings.simplefilter("ignore", UserWarning)
            rows = np.loadtxt(io.StringIO(text[section.end():]), comments="#", usecols=range(ncol), max_rows=n,
                              ndmin=2)
    except ValueError as exc:
        raise DataFileError(f"the Atoms # {style} section ({n} lines of at least {ncol} numbers, the "
                            f"header's count): {exc}") from None
    if len(rows) < n:
        raise DataFileError(f"the Atoms section has {len(rows)} lines; the header declares {n} atoms")
    ids, x = rows[:, 0], rows[:, at:at + 3]
    if not np.all((ids == np.round(ids)) & (ids >= 1) & (ids < 2.0 ** 53)):
        raise DataFileError("has an atom id that is not a positive integer")
    order = np.argsort(ids.astype(np.int64), kind="stable")
    ids_sorted = ids[order]
    if np.any(ids_sorted[1:] == ids_sorted[:-1]):
        raise DataFileError("repeats an atom id")
    if not np.all(np.isfinite(x)):
        raise DataFileError("has a position that is not finite")
    if dim == 2 and np.any(x[:, 2] != 0.0):
        raise DataFileError("a 2-D run needs z = 0 for every atom")
    return x[order][:, :dim]


def body_points(body: dict, dim: int) -> np.ndarray:
    """A body's particle positions: its data file's (``_points``, read when the case was checked)
    or the lattice filling its region."""
    if "_points" in body:
        return np.asarray(body["_points"], float)
    return lattice_points(body["region"], body["spacing"], dim)


def cells_box(body: dict, dim: int, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The box around a body's particles' cells (x +- spacing / 2): what must lie inside the SPH
    domain and the background grid.  Not the region's box: a ``where`` may cut a region at a
    symmetry plane (a quarter of a rod whose axis lies on two wall faces).  ``x``: its particles
    when the caller has them (else built by body_points)."""
    x = body_points(body, dim) if x is None else x
    if len(x) == 0:
        return bounds(body["region"], dim)
    half = 0.5 * float(body["spacing"])
    return x.min(axis=0) - half, x.max(axis=0) + half
