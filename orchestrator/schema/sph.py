"""The SPH particle group's table of case.toml, ``[sph]`` (LAMMPS, SPH package): schema fragment,
normaliser and cross-field checks, registered in :mod:`orchestrator.schema.registry`.

Normalised layout (``case["sph"]``, present when the file has the table)::

    {dimension, spacing, smoothing_length, cfl, domain: {lower, upper},
     boundaries: {face: "open" | "periodic" | "wall"} (every face of the dimension, "open" unless
     given), gravity: [g_x, g_y(, g_z)], density_summation: bool,
     materials: {name: {model, density, sound_speed, viscosity}},
     bodies: [{name, material, region, density, velocity, fixed, spacing, hydrostatic,
               [pressure | specific_internal_energy]}],
     lammps_commands: [line, ...], particles: int}

``region`` is exactly one of ``{"box": {lower, upper}}``, ``{"sphere": {centre, radius}}``,
``{"cylinder": {base, axis, radius, length}}``, with an optional ``where`` expression
(solvers/particles.py).  ``particles`` is the number of particles the bodies give (counted here,
before anything launches).

Materials (LAMMPS pair styles, one model per case):

* ``tlsph`` (MACHDYN pair smd/tlsph, atom_style smd; adapters/lammps_tlsph.py): an elastic or
  elastic-plastic solid; keys density, youngs_modulus, poisson_ratio, strength ("linear",
  {linear_plastic = {yield_stress, hardening}}, {johnson_cook = {A, B, n, C,
  strain_rate0, room_temperature, melt_temperature, m}}), eos ("linear", "none", {shock = {c0, s,
  gamma}}), viscosity_q1, viscosity_q2, hourglass, heat_capacity.  A body may give ``clamp``, a
  region whose particles are held at rest.

Any body may give ``hold``, velocity components held at zero (e.g. ["y"]: a piston sliding along
a channel's walls, as a Lagrangian body's symmetry planes hold it; a free block under end loads
is otherwise unstable to rigid rotation).

* ``tait`` (pair sph/taitwater; the background's ``eos = "tait"`` names the same law): p = B ((rho/rho0)^7 - 1), B = c0^2 rho0 / 7; keys density
  (rho0), sound_speed (c0), viscosity (Monaghan's alpha), optional pressure_cutoff (the least
  pressure, <= 0 and > -B: a strength-free liquid or metal cavitates instead of pulling its
  neighbours back; Tait's law alone holds tension down to -B, 23 GPa for steel);
* ``ideal_gas`` (pair sph/idealgas; the background's ``eos = "ideal_gas"``): p = (gamma - 1) rho e with LAMMPS's fixed gamma = 1.4; key
  viscosity (LAMMPS's nu).  Its bodies give pressure or specific_internal_energy.
"""
from __future__ import annotations

from pathlib import Path

from solvers.expressions import BOOL

from adapters.lammps_lines import LammpsLineError, check_line, line_scales
from .parts import NAME_PATTERN, doc, integer, name, number, table, variants, vector
from .registry import register_table
from .rules import (CaseError, check_expression, check_faces, check_length, expression_refusal,
                           format_key, to_float)

MAX_PARTICLES = 20_000_000
"""More particles than this in one case is refused (memory of the SPH group and of its output)."""

MODEL_KEYS = {
    "tait": ("model", "density", "sound_speed", "viscosity", "pressure_cutoff"),
    "ideal_gas": ("model", "viscosity"),
    "tlsph": ("model", "density", "youngs_modulus", "poisson_ratio", "strength", "eos", "viscosity_q1",
              "viscosity_q2", "hourglass", "heat_capacity"),
}
MODEL_REQUIRED = {"tait": ("model", "density", "sound_speed", "viscosity"), "ideal_gas": MODEL_KEYS["ideal_gas"],
                  "tlsph": ("model", "density", "youngs_modulus", "poisson_ratio")}
PAIR_STYLE = {"tait": "taitwater", "ideal_gas": "idealgas", "tlsph": "tlsph"}
"""A case's model name (the background's EOS names where the law is the same) -> the name the
normalised case and the SPH group use: LAMMPS's pair style (the case's older spellings,
orchestrator/schema/spellings.py)."""
CASE_NAME = {v: k for k, v in PAIR_STYLE.items()}
STRENGTH_TEXT = ("\"linear\", { linear_plastic = { yield_stress, hardening } } or "
                 "{ johnson_cook = { A, B, n, C, strain_rate0, room_temperature, melt_temperature, m } }")
EOS_TEXT = "\"linear\", \"none\" or { shock = { c0, s, gamma } } (Mie-Grueneisen, linear us-up)"
# MACHDYN's Johnson-Cook strength (LAMMPS *STRENGTH_JOHNSON_COOK; the keys have no unit in the schema)
_JC = "MACHDYN's Johnson-Cook sigma_y = (A + B eps_p^n)(1 + C ln(rate / strain_rate0))(1 - T*^m)"
_JC_KEYS = {
    "A": f"A: the initial yield stress (Pa) in {_JC}.",
    "B": f"B: the strain-hardening modulus (Pa) in {_JC}.",
    "n": f"n: the strain-hardening exponent in {_JC}.",
    "C": f"C: the strain-rate coefficient in {_JC}.",
    "strain_rate0": f"strain_rate0: the reference plastic strain rate (1/s) in {_JC}.",
    "room_temperature": "T_room (K): no thermal softening below it; T* = (T - T_room) / (T_melt - T_room).",
    "melt_temperature": "T_melt (K): the temperature at which the flow stress vanishes.",
    "m": f"m: the thermal-softening exponent in {_JC}, T* = (T - T_room) / (T_melt - T_room).",
}
STRENGTH = {
    "oneOf": [
        {"type": "string", "enum": ["linear"], "x-allowed": "must be " + STRENGTH_TEXT},
        table({"linear_plastic": table({"yield_stress": number("Pa", exclusiveMinimum=0,
                                                               description="The yield stress sigma0."),
                                        "hardening": number("Pa", minimum=0,
                                                            description="The linear hardening modulus (0: "
                                                                        "perfectly plastic).")},
                                       required=("yield_stress",),
                                       description="Elastic-plastic with linear hardening "
                                                   "(*STRENGTH_LINEAR_PLASTIC).")},
              required=("linear_plastic",)),
        table({"johnson_cook": table({k: number(None, description=text) for k, text in _JC_KEYS.items()},
                                     required=("A", "B", "n", "C", "strain_rate0", "room_temperature",
                                               "melt_temperature", "m"),
                                     description="Johnson-Cook plasticity (*STRENGTH_JOHNSON_COOK).")},
              required=("johnson_cook",)),
    ],
    "x-allowed": "must be " + STRENGTH_TEXT,
    "default": "linear",   # (adapters/lammps_tlsph.py DEFAULTS)
    "description": "tlsph: the deviatoric (shear) response. linear: elastic (*STRENGTH_LINEAR); or a table "
                   "linear_plastic or johnson_cook.",
}
EOS = {
    "oneOf": [
        {"type": "string", "enum": ["linear", "none"], "x-allowed": "must be " + EOS_TEXT},
        table({"shock": table({"c0": number("m/s", exclusiveMinimum=0,
                                            description="The bulk sound speed c0, intercept of us = c0 + s up."),
                               "s": number("dimensionless", minimum=0, description="The slope s of us = c0 + s up."),
                               "gamma": number("dimensionless", minimum=0, description="The Grueneisen gamma.")},
                              required=("c0", "s", "gamma"),
                              description="Mie-Grueneisen about the linear us = c0 + s up Hugoniot "
                                          "(*EOS_SHOCK).")},
              required=("shock",)),
    ],
    "x-allowed": "must be " + EOS_TEXT,
    "default": "linear",   # (adapters/lammps_tlsph.py DEFAULTS)
    "description": "tlsph: the pressure. linear: from the volumetric strain and the bulk modulus of E and nu "
                   "(*EOS_LINEAR); none: no pressure (*EOS_NONE); or a table shock.",
}
MATERIAL = {
    "type": "object",
    "properties": {
        "model": doc({"type": "string", "enum": list(MODEL_KEYS)},
                     "The particles' material law (one model per case; the background's EOS names where the "
                     "law is the same; LAMMPS's pair style names taitwater and idealgas are read with a note). "
                     "tait: a weakly compressible liquid, p = B ((rho/rho0)^7 - 1), B = c0^2 rho0 / 7 (pair "
                     "sph/taitwater); ideal_gas: p = (gamma - 1) rho e with LAMMPS's fixed gamma = 1.4 (pair "
                     "sph/idealgas); tlsph: an elastic or elastic-plastic solid, total-Lagrangian SPH (MACHDYN's "
                     "pair smd/tlsph)."),
        "density": number("kg/m^3", exclusiveMinimum=0,
                          description="tait: the reference density rho0 of Tait's law; tlsph: the solid's "
                                      "density."),
        "sound_speed": number("m/s", exclusiveMinimum=0, description="tait: the sound speed c0 at rho0 (sets "
                                                                     "Tait's B and the step)."),
        "viscosity": number("dimensionless", minimum=0,
                            description="The artificial viscosity: tait: Monaghan's alpha; ideal_gas: the "
                                        "viscosity nu of pair sph/idealgas."),
        "pressure_cutoff": number("Pa", maximum=0,
                                  description="tait: the least pressure (above -B): the material cavitates "
                                              "instead of holding Tait's tension (absent: none)."),
        "youngs_modulus": number("Pa", exclusiveMinimum=0, description="tlsph: Young's modulus E."),
        "poisson_ratio": number("dimensionless", minimum=0, exclusiveMaximum=0.5,
                                description="tlsph: Poisson's ratio nu."),
        "strength": STRENGTH,
        "eos": EOS,
        # (the defaults: adapters/lammps_tlsph.py DEFAULTS, MACHDYN's example values; not imported: that
        # module imports solvers.particles, which validating a case must not)
        "viscosity_q1": number("dimensionless", minimum=0, default=1.0,
                               description="tlsph: the linear artificial viscosity coefficient Q1."),
        "viscosity_q2": number("dimensionless", minimum=0, default=0.0,
                               description="tlsph: the quadratic artificial viscosity coefficient Q2."),
        "hourglass": number("dimensionless", minimum=0, default=10.0,
                            description="tlsph: the hourglass control amplitude (suppresses the zero-energy "
                                        "modes of the particle pairs)."),
        "heat_capacity": number("J/(kg K)", exclusiveMinimum=0, default=1.0,
                                description="tlsph: the heat capacity (read only by Johnson-Cook's thermal "
                                            "softening)."),
    },
    "additionalProperties": False,
    "required": ["model"],
    "allOf": variants("model", MODEL_KEYS, MODEL_REQUIRED),
    "description": "A particle material, by the name the bodies use.",
}
REGION_BOX = table({"lower": vector("m", description="The box's lower corner."),
                    "upper": vector("m", description="The box's upper corner (above lower in every component).")},
                   required=("lower", "upper"))
SPHERE = table({"centre": vector("m", description="The sphere's (2-D: the disc's) centre."),
                "radius": number("m", exclusiveMinimum=0, description="The sphere's radius.")},
               required=("centre", "radius"), description="A sphere (in 2-D a disc).")
CYLINDER = table({"base": vector("m", description="The centre of the cylinder's base."),
                  "axis": {"type": "string", "enum": ["x", "y", "z"],
                           "description": "The axis the cylinder runs along from its base."},
                  "radius": number("m", exclusiveMinimum=0, description="The cylinder's radius."),
                  "length": number("m", exclusiveMinimum=0, description="The cylinder's length along axis.")},
                 required=("base", "axis", "radius", "length"), description="3-D: a circular cylinder.")
REGION = {
    "type": "object",
    "properties": {"box": doc(REGION_BOX, "An axis-aligned box."), "sphere": SPHERE, "cylinder": CYLINDER,
                   "where": {"type": "string", "minLength": 1,
                             "description": "Optional: only the points where this boolean expression in x, y (, "
                                            "z) holds."}},
    "additionalProperties": False,
    "oneOf": [{"required": ["box"]}, {"required": ["sphere"]}, {"required": ["cylinder"]}],
    "x-allowed": "needs exactly one of box = { lower, upper }, sphere = { centre, radius }, "
                 "cylinder = { base, axis, radius, length } (and optionally where = \"expression\")",
}
BODY = table(
    {
        "name": name(description="The body's name (default: body<i>, i its place in sph.bodies from 0)."),
        "material": {"type": "string", "minLength": 1,
                     "description": "The body's material: one of sph.materials."},
        "region": doc(REGION, "Where the body's particles are: the cell centres of a square (cubic) lattice of "
                              "the body's spacing inside exactly one of box, sphere, cylinder (and where)."),
        # particle positions from a LAMMPS data file (its Atoms section), in place of a region
        "data_file": {"type": "string", "minLength": 1,
                      "description": "Instead of a region: the particle positions of a LAMMPS data file's Atoms "
                                     "section (inside the case directory), each particle of volume spacing^dim."},
        "density": number("kg/m^3", exclusiveMinimum=0,
                          description="The particles' initial density (their mass: density spacing^dim)."),
        "pressure": number("Pa", description="ideal_gas: the initial pressure (or specific_internal_energy)."),
        "specific_internal_energy": number("J/kg", minimum=0,
                                           description="ideal_gas: the initial specific internal energy (or "
                                                       "pressure)."),
        "velocity": vector("m/s", description="Initial velocity (default: at rest)."),
        "fixed": doc({"type": "boolean"}, "true: boundary particles that never move (fix sph/stationary; tlsph: "
                                          "held, still bonded).", default=False),
        "spacing": number("m", exclusiveMinimum=0, description="The body's own lattice spacing (default: "
                                                               "sph.spacing)."),
        # tait under gravity: the density of the column at rest (else a start-up pressure wave)
        "hydrostatic": doc({"type": "boolean"}, "tait under gravity: start the column at its hydrostatic "
                                                "density (at rest; else a start-up pressure wave).", default=False),
        # tlsph: the body's particles in this region are held at rest (a clamp)
        "clamp": doc(REGION, "tlsph: the body's particles in this region are held at rest (still bonded: they "
                             "carry stress)."),
        # velocity components held at zero (a body sliding between walls: ["y"])
        "hold": {"type": "array", "items": {"type": "string", "enum": ["x", "y", "z"]}, "uniqueItems": True,
                 "minItems": 1,
                 "description": "Velocity components held at zero, e.g. [\"y\"]: a piston sliding along a "
                                "channel's walls (absent: none)."},
    },
    required=("material", "density"),
    oneOf=[{"required": ["region"]}, {"required": ["data_file"]}],
    description="A body of particles ([[sph.bodies]]): where its particles are, their material and initial state.",
    **{"x-allowed": "needs exactly one of region = { ... } or data_file = \"file\" (a LAMMPS data file)"},
)
SPH_FACE = {"type": "string", "enum": ["open", "periodic", "wall"], "default": "open",   # (_normalise)
            "description": "open: the particles may leave (LAMMPS's shrink-wrapped box); periodic: wraps to the "
                           "opposite face (set both); wall: a reflecting wall (fix wall/reflect)."}
FACES = ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")

DEFAULT_SUBSTEPS = 20
"""LAMMPS steps per coupler step of an uncoupled SPH group (the stable step re-evaluated between
them).  `immerse bench sph`, driver against LAMMPS alone on the dam break: 0.67 / 0.75 at 1 (5.7k /
44k particles), 0.92 / 1.01 at 10, 0.98 / 1.01 at 20; each batch costs about 1 ms of coupler
round trip, `run` re-initialisation and the t = 0 output amortised (adapters/sph.py)."""

DEFAULT_CFL = 0.1
"""dt = cfl h / max(c + |v|) (Monaghan's acoustic limit on the kernel support h).  0.1: a tait
column at rest with fixed boundary particles goes unstable at 0.2 (alpha 0.1 .. 0.3, h = 2 .. 4 dx)
and holds at 0.1 with alpha >= 0.3 (0.05 for alpha 0.1)."""

SPH = table(
    {
        "spacing": number("m", exclusiveMinimum=0,
                          description="The lattice spacing dx of the bodies' particles (each of volume dx^dim); a "
                                      "body may set its own."),
        "smoothing_length": number("m", exclusiveMinimum=0,
                                   description="h: the kernel's support (LAMMPS's cutoff), at least spacing."),
        "cfl": number("dimensionless", minimum=1e-4, maximum=1,   # (5e-324: a step of nothing)
                      default=DEFAULT_CFL,
                      description="The step's factor: dt = cfl h / max(c + |v|), and at most cfl sqrt(h / "
                                  "max|a|)."),
        "domain": doc(REGION_BOX, "The LAMMPS simulation box: every body lies inside it."),
        "boundaries": table({f: SPH_FACE for f in FACES},
                            description="The condition on each face of the domain, x_lower ... z_upper (faces not "
                                        "given: open)."),
        "gravity": vector("m/s^2", description="Gravitational acceleration on the moving particles (default: "
                                               "none)."),
        "density_summation": doc({"type": "boolean"}, "true: the density is the kernel sum over the neighbours "
                                                      "every step (sph/rhosum); false: integrated by the continuity "
                                                      "equation.", default=False),
        "materials": {
            "type": "object",
            "minProperties": 1,
            "propertyNames": {"pattern": NAME_PATTERN},
            "additionalProperties": MATERIAL,
            "description": "The particles' materials by name, e.g. materials.water = { model = \"tait\", "
                           "... }; one model for all of them.",
        },
        "bodies": {"type": "array", "minItems": 1, "items": BODY,
                   "description": "The bodies of particles, one [[sph.bodies]] table each."},
        "lammps_commands": {"type": "array", "items": {"type": "string"},
                            "description": "Extra LAMMPS input lines (groups, regions, fixes, computes, neighbour "
                                           "settings), checked against an allow-list (adapters/lammps_lines.py)."},
        "neighbor_skin": number("m", exclusiveMinimum=0,
                                description="LAMMPS's neighbour-list skin beyond h (default: 0.1 "
                                            "smoothing_length)."),
        # LAMMPS steps per coupler step when the particles are not coupled (adapters/sph.py)
        "substeps": integer(minimum=1, maximum=1000, default=DEFAULT_SUBSTEPS,
                            description="LAMMPS steps per coupler step when the particles are not coupled (with "
                                        "[coupling]: 1)."),
        # (LAMMPS's atom ids are 32-bit integers in its default build: 2^31 - 1 particles at most)
        "max_particles": integer(minimum=1, maximum=2**31 - 1, default=MAX_PARTICLES,
                                 description="A case whose bodies give more particles than this is refused before "
                                             "anything runs."),
    },
    required=("spacing", "smoothing_length", "domain", "materials", "bodies"),
    description="The SPH particles (LAMMPS's SPH and MACHDYN packages, run as their own process group).",
)


def _vec(v):
    return [to_float(a) for a in v]


def _region(r: dict) -> dict:
    out = {}
    if "box" in r:
        out["box"] = {"lower": _vec(r["box"]["lower"]), "upper": _vec(r["box"]["upper"])}
    elif "sphere" in r:
        out["sphere"] = {"centre": _vec(r["sphere"]["centre"]), "radius": to_float(r["sphere"]["radius"])}
    else:
        c = r["cylinder"]
        out["cylinder"] = {"base": _vec(c["base"]), "axis": c["axis"], "radius": to_float(c["radius"]),
                           "length": to_float(c["length"])}
    if "where" in r:
        out["where"] = r["where"]
    return out


def _material_value(key: str, v):
    if key == "model":
        return PAIR_STYLE[v]    # (the SPH group's name of the law: LAMMPS's pair style)
    if isinstance(v, str):
        return v
    if isinstance(v, dict):  # strength / eos tables
        return {k: _material_value(k, w) for k, w in v.items()}
    return to_float(v)


def _normalise(s: dict, dim: int, case_dir) -> dict:
    spacing = to_float(s["spacing"])
    out = {
        "dimension": dim,
        "spacing": spacing,
        "smoothing_length": to_float(s["smoothing_length"]),
        "cfl": to_float(s.get("cfl", DEFAULT_CFL)),
        "domain": {"lower": _vec(s["domain"]["lower"]), "upper": _vec(s["domain"]["upper"])},
        "boundaries": {f: s.get("boundaries", {}).get(f, "open") for f in FACES[: 2 * dim]},
        "gravity": _vec(s.get("gravity", [0.0] * dim)),
        "density_summation": bool(s.get("density_summation", False)),
        "materials": {n: {k: _material_value(k, v) for k, v in m.items()} for n, m in s["materials"].items()},
        "bodies": [],
        "lammps_commands": list(s.get("lammps_commands", [])),
        "max_particles": int(s.get("max_particles", MAX_PARTICLES)),
        "substeps": int(s.get("substeps", DEFAULT_SUBSTEPS)),
    }
    if "neighbor_skin" in s:
        out["neighbor_skin"] = to_float(s["neighbor_skin"])
    for i, b in enumerate(s["bodies"]):
        body = {
            "name": b.get("name", f"body{i}"),
            "material": b["material"],
            "region": _region(b["region"]) if "region" in b else None,
            "density": to_float(b["density"]),
            "velocity": _vec(b.get("velocity", [0.0] * dim)),
            "fixed": bool(b.get("fixed", False)),
            "spacing": to_float(b.get("spacing", spacing)),
            "hydrostatic": bool(b.get("hydrostatic", False)),
        }
        for k in ("pressure", "specific_internal_energy"):
            if k in b:
                body[k] = to_float(b[k])
        if "clamp" in b:
            body["clamp"] = _region(b["clamp"])
        if "data_file" in b:
            body["data_file"] = (Path(case_dir) / b["data_file"]).resolve()
        body["hold"] = list(b.get("hold", []))
        out["bodies"].append(body)
    return out


DATA_FILE_LIMIT = 1 << 30
"""A particle data file larger than this is refused (1 GiB: ~20 M particles of a text data file)."""


def _read_body_file(body: dict, key: str, raw: str, case_dir, dim: int, max_atoms: int) -> None:
    """A body's LAMMPS data file: inside the case directory, a regular file, its Atoms positions
    (solvers/particles.py: a header declaring more than ``max_atoms`` is refused before the atoms
    are parsed) kept as ``_points``; the body's region becomes the box of its particles (half a
    spacing around them) for the domain and grid checks."""
    from solvers.particles import DataFileError, read_data_positions

    from .rules import check_path_inside, stat_regular

    path = body["data_file"]
    check_path_inside(key, raw, path, case_dir)
    stat_regular(path, key, raw, "a LAMMPS data file (text)")
    try:
        with open(path, "rb") as f:
            data = f.read(DATA_FILE_LIMIT + 1)
    except OSError as exc:
        raise CaseError(key, raw, f"cannot read: {exc.strerror or exc}") from None
    if len(data) > DATA_FILE_LIMIT:
        raise CaseError(key, raw, "is more than 1 GiB; allowed: a LAMMPS data file up to 1 GiB")
    try:
        x = read_data_positions(data.decode("utf-8"), dim, max_atoms)
    except UnicodeDecodeError as exc:
        raise CaseError(key, raw, f"not UTF-8 text (byte {exc.start}); allowed: a LAMMPS data file") from None
    except DataFileError as exc:
        raise CaseError(key, raw, f"{exc}; allowed: " + (f"{exc.allowed} (sph.max_particles less the other bodies')"
                                                         if exc.allowed else "a LAMMPS data file with an Atoms section")) from None
    body["_points"] = x
    half = 0.5 * body["spacing"]
    body["region"] = {"box": {"lower": [float(v) for v in x.min(axis=0) - half],
                              "upper": [float(v) for v in x.max(axis=0) + half]}}


def _check_region(reg: dict, rreg: dict, base: list, dim: int) -> None:
    """A region's vector lengths, shape for the dimension, box order and where expression."""
    for kind, keys in (("box", ("lower", "upper")), ("sphere", ("centre",)), ("cylinder", ("base",))):
        if kind in reg:
            for k in keys:
                check_length(format_key(base + ["region", kind, k]), rreg[kind][k], dim)
    if "cylinder" in reg and dim != 3:
        raise CaseError(format_key(base + ["region", "cylinder"]), rreg["cylinder"],
                        "cylinders are 3-D; in 2-D a disc is a sphere = { centre, radius }")
    if "box" in reg and not all(u > v for u, v in zip(reg["box"]["upper"], reg["box"]["lower"])):
        raise CaseError(format_key(base + ["region", "box", "upper"]), rreg["box"]["upper"],
                        "must be > lower component-wise")
    if "where" in reg:
        check_expression(format_key(base + ["region", "where"]), reg["where"], dim, BOOL)


def _check(sph: dict, raw: dict, dim: int, case_dir) -> None:
    """Cross-field rules: vector lengths, the domain, periodic pairs, one material model, each body's
    material and thermodynamic state, regions inside the domain, the extra LAMMPS lines, the
    particle count."""
    import numpy as np

    from solvers.expressions import ExpressionError
    from solvers.particles import bounds, body_points, cells_box, lattice_counts, points_in, sample_points, tait_b

    for k in ("lower", "upper"):
        check_length(format_key(["sph", "domain", k]), raw["domain"][k], dim)
    lo, hi = sph["domain"]["lower"], sph["domain"]["upper"]
    for j in range(dim):
        if not hi[j] > lo[j]:
            raise CaseError("sph.domain.upper", raw["domain"]["upper"], f"must be > lower component-wise (component {j})")
    if "gravity" in raw:
        check_length("sph.gravity", raw["gravity"], dim)
    check_faces("sph", sph["boundaries"], raw.get("boundaries", {}), dim)
    h = sph["smoothing_length"]
    extent = line_scales(sph)[0]
    for key in ("smoothing_length", "neighbor_skin"):  # a longer reach ghosts the domain many times over
        if key in sph and sph[key] > extent:
            raise CaseError(f"sph.{key}", raw[key], f"must be <= the domain's largest extent ({extent:g} m)")
    if h < sph["spacing"]:
        raise CaseError("sph.smoothing_length", raw["smoothing_length"],
                        f"must be >= sph.spacing = {raw['spacing']} m (the kernel must reach the neighbours)")
    models = {m["model"] for m in sph["materials"].values()}
    if len(models) > 1:
        raise CaseError("sph.materials", sorted(CASE_NAME[m] for m in models), "one material model per case "
                        "(LAMMPS runs one pair style); allowed: all tait, all ideal_gas or all tlsph")
    for mname, m in sph["materials"].items():
        if "pressure_cutoff" in m:
            b = tait_b(m)
            if not m["pressure_cutoff"] > -b:
                raise CaseError(format_key(["sph", "materials", mname, "pressure_cutoff"]),
                                raw["materials"][mname]["pressure_cutoff"],
                                f"must be > -B = -c0^2 rho0 / 7 = {-b:.6g} Pa (Tait's least pressure)")
    total = 0
    for i, (body, rb) in enumerate(zip(sph["bodies"], raw["bodies"])):
        base = ["sph", "bodies", i]
        if body["material"] not in sph["materials"]:
            raise CaseError(format_key(base + ["material"]), body["material"],
                            "undefined material; defined in [sph.materials]: " + ", ".join(sph["materials"]))
        model = sph["materials"][body["material"]]["model"]
        state = [k for k in ("pressure", "specific_internal_energy") if k in rb]
        if model == "idealgas" and len(state) != 1:
            raise CaseError(format_key(base), {k: rb[k] for k in state} or "no state",
                            "an ideal_gas body needs exactly one of pressure, specific_internal_energy")
        if model == "taitwater" and state:
            raise CaseError(format_key(base + [state[0]]), rb[state[0]],
                            "a tait body's pressure follows from its density (Tait's equation); remove it")
        if body["hydrostatic"] and (model != "taitwater" or not any(sph["gravity"])):
            raise CaseError(format_key(base + ["hydrostatic"]), True,
                            "needs a tait body and a non-zero sph.gravity")
        if model == "tlsph" and state:
            raise CaseError(format_key(base + [state[0]]), rb[state[0]],
                            "a tlsph body starts unstressed at its density; remove it")
        if model == "tlsph" and "periodic" in sph["boundaries"].values():
            face = next(f for f, v in sph["boundaries"].items() if v == "periodic")
            raise CaseError(format_key(["sph", "boundaries", face]), "periodic",
                            "tlsph solids need open or wall faces: LAMMPS's PairTlsph::ComputeForces does not "
                            "wrap the reference distance of a pair across a periodic face")
        if "clamp" in body and model != "tlsph":
            raise CaseError(format_key(base + ["clamp"]), rb["clamp"],
                            "only tlsph (solid) bodies are clamped; a fluid's boundary is a fixed body")
        if "clamp" in body:
            for kind, keys in (("box", ("lower", "upper")), ("sphere", ("centre",)), ("cylinder", ("base",))):
                if kind in body["clamp"]:
                    for k in keys:
                        check_length(format_key(base + ["clamp", kind, k]), rb["clamp"][kind][k], dim)
            if "where" in body["clamp"]:
                check_expression(format_key(base + ["clamp", "where"]), body["clamp"]["where"], dim, BOOL)
        for a in body["hold"]:
            if "xyz".index(a) >= dim:
                raise CaseError(format_key(base + ["hold"]), rb["hold"], f"axes of the {dim}-D run: x, y" + (", z" if dim == 3 else ""))
        if "pressure" in body and body["pressure"] < 0:
            raise CaseError(format_key(base + ["pressure"]), rb["pressure"], "must be >= 0 for an ideal gas (Pa)")
        if "velocity" in rb:
            check_length(format_key(base + ["velocity"]), rb["velocity"], dim)
        if "data_file" in body:  # its region: the box around its particles (for the checks below)
            _read_body_file(body, format_key(base + ["data_file"]), rb["data_file"], case_dir, dim,
                            sph["max_particles"] - total)
            where, rreg = "data_file", rb["data_file"]
        else:
            where, rreg = "region", rb["region"]
            _check_region(body["region"], rreg, base, dim)
        reg = body["region"]
        # the where expressions on the points the adapter evaluates them on: the lattice of the
        # region's box, the clamp's on the body's particles (adapters/lammps_tlsph.py); a lattice too
        # large to build here (EXACT_LATTICE) is sampled, and only what the sample proves is claimed
        lattice = float(np.prod(lattice_counts(reg, body["spacing"], dim), dtype=np.float64))
        sampled = "_points" not in body and lattice > EXACT_LATTICE
        try:
            x = sample_points(body, dim, SAMPLE, seed=i) if sampled else body_points(body, dim)
        except ExpressionError as exc:
            raise expression_refusal(format_key(base + ["region", "where"]), reg["where"], exc,
                                     f"a lattice point of the region of sph.bodies[{i}]") from None
        if "clamp" in body and body["clamp"].get("where"):
            try:
                points_in(body["clamp"], x, dim)
            except ExpressionError as exc:
                raise expression_refusal(format_key(base + ["clamp", "where"]), body["clamp"]["where"], exc,
                                         f"a particle of sph.bodies[{i}]") from None
        if sampled:
            n, low = _estimate(len(x), SAMPLE, lattice)
            if n == 0:
                raise CaseError(format_key(base + [where]), rreg,
                                f"its lattice of {lattice:.3g} points is too large to count here and a "
                                f"sample of {SAMPLE} found none inside; allowed: a region whose box is "
                                f"closer to the body (at most {EXACT_LATTICE} lattice points are built "
                                "to check it exactly)")
            if total + low > sph["max_particles"]:
                raise CaseError(format_key(base + [where]), rreg,
                                f"the bodies give more than sph.max_particles = {sph['max_particles']} "
                                f"particles (this one about {n:.3g}, from a sample of {SAMPLE} of its "
                                f"{lattice:.3g} lattice points)")
            # (the domain: the region's box, which holds the particles whatever the where cuts)
            blo, bhi = bounds(reg, dim)
            x = np.stack([blo + 0.5 * body["spacing"], bhi - 0.5 * body["spacing"]])
        else:
            n = len(x)
        clo, chi = cells_box(body, dim, x)  # the particles' cells: a where may cut the region at a face
        slack = 1e-9 * body["spacing"]
        if n and (np.any(clo < np.asarray(lo) - slack) or np.any(chi > np.asarray(hi) + slack)):
            raise CaseError(format_key(base + [where]), rreg,
                            f"must lie inside sph.domain (lower {raw['domain']['lower']}, upper {raw['domain']['upper']}; "
                            "its particles' cells, x +- spacing / 2)")
        if n == 0:
            raise CaseError(format_key(base + [where]), rreg,
                            f"holds no particle at spacing {body['spacing']:g} m")
        n = int(n)
        total += n
        if total > sph["max_particles"]:
            raise CaseError(format_key(base + [where]), rreg,
                            f"the bodies give more than sph.max_particles = {sph['max_particles']} particles")
    sph["particles"] = total
    for i, line in enumerate(sph["lammps_commands"]):
        try:
            check_line(line, *line_scales(sph))
        except LammpsLineError as exc:
            raise CaseError(format_key(["sph", "lammps_commands", i]), line, str(exc)) from None


EXACT_LATTICE = 4_000_000
"""Lattice points of a body built and run through its region (and where) at check time: about 3 s
(0.7 us a point, a 79M-point lattice took 57 s).  Beyond, a sample of SAMPLE points estimates the
count; the check claims only what the sample proves (a body over max_particles: its count's lower
bound beyond it) and the adapter builds the exact lattice at set-up."""
SAMPLE = 200_000


def _estimate(hits: int, sample: int, lattice: float) -> tuple[float, float]:
    """(estimate, lower bound) of a body's particles from ``hits`` of ``sample`` lattice points
    drawn at random: the binomial fraction and 5 standard deviations below it."""
    f = hits / sample
    sd = (f * (1.0 - f) / sample) ** 0.5
    return f * lattice, max(0.0, f - 5.0 * sd - 1.0 / sample) * lattice


def normalise(raw: dict | None, case: dict) -> dict | None:
    return None if raw is None else _normalise(raw, case["run"]["dimension"], case["case_dir"])


def check(case: dict, data: dict) -> None:
    _check(case["sph"], data["sph"], case["run"]["dimension"], case["case_dir"])


# ---- registration (after [[boundaries]] 50, before [coupling] 60) ----------------------------------
register_table("sph", SPH, normalise, check, order=55)
