"""The Lagrangian solver's tables of case.toml: ``[materials]``, ``[lagrange]`` (its bodies) and
``[[boundaries]]`` (their boundary conditions); schema fragments, normalisers and cross-field
checks, registered in :mod:`orchestrator.schema.registry`.

Normalised layout::

    "materials": {name: {model, density, youngs_modulus, poisson_ratio, [johnson_cook keys]}}
    "lagrange": {hourglass, bulk_viscosity_linear, bulk_viscosity_quadratic,
                 "bodies": [{name, material, mesh, size, initial_velocity, initial_temperature,
                             erosion: None | {strain, time_step}}]}
    "boundaries": [ {type, ...} ]

``materials`` and ``boundaries`` are always present (empty without bodies); ``lagrange`` when the
file has the table, or no solver table at all (the Lagrangian solver is the default).  Every body
has ``size = {"elements": int, "nodes": int}`` (Python ints, computed without building the mesh,
or counted after reading a mesh file).  ``mesh`` is exactly one of
``{"box": {lower, upper, cells}}``, ``{"quarter_cylinder": {radius, length, radial_cells,
axial_cells[, base]}}``, ``{"quarter_disk": {radius, radial_cells[, base]}}``, ``{"ring":
{inner_radius, outer_radius, radial_cells, angular_cells, centre}}`` or ``{"file": Path}``
(resolved, absolute); ``initial_velocity`` holds
``dimension`` items, each a float or an expression string in the coordinates (``x, y`` in 2D,
``x, y, z`` in 3D).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

from solvers.expressions import BOOL, NUM
from solvers.lagrange.integrators import INTEGRATORS, SUBCYCLING_RATIOS
from solvers.lagrange.mesh import body_mesh_size

from .parts import BOX, NAME_PATTERN, doc, integer, name, number, table, variants, vector
from .registry import register_table
from .rules import (MISSING, CaseError, check_expression, check_extent, check_length,
                           check_path_inside, expression_names, fmt_num, format_bytes, format_key,
                           num_or_expression, stat_regular, to_float)

MATERIAL_MODELS = ("linear_elastic", "neo_hookean", "johnson_cook")
BOUNDARY_TYPES = ("fixed", "velocity", "symmetry", "rigid_wall", "traction")

LAGRANGE_DEFAULTS = {
    "hourglass": 0.1,
    "bulk_viscosity_linear": 0.06,
    "bulk_viscosity_quadratic": 1.5,
}
DEFAULT_ROOM_TEMPERATURE = 293.15
"""Initial temperature (K) of bodies whose material has no ``room_temperature``."""

MESH_READ_FACTOR = 7
"""Reading a mesh file takes at least this many times its size in memory (tracemalloc peak of
read_mesh on 50^3 hexahedra, `immerse bench memory`: Gmsh 2.2 ASCII 7.5x, binary 14x, VTU binary 53x;
Gmsh 4 ASCII 8.2x, VTU ASCII 9.3x): a file bigger than memory / 7 cannot be read here."""


# ---- schema ---------------------------------------------------------------------------------------
_ELASTIC_KEYS = ("model", "density", "youngs_modulus", "poisson_ratio")
_JC_EXTRA = (
    "yield_stress", "hardening_modulus", "hardening_exponent", "strain_rate_coefficient",
    "reference_strain_rate", "thermal_exponent", "melt_temperature", "room_temperature",
    "specific_heat", "taylor_quinney",
)
MODEL_KEYS = {
    "linear_elastic": _ELASTIC_KEYS,
    "neo_hookean": _ELASTIC_KEYS,
    "johnson_cook": _ELASTIC_KEYS + _JC_EXTRA,
}

# Johnson-Cook flow stress (solvers/lagrange/materials.py jc_yield), the equation its keys are named in
_JC = "Johnson-Cook's sigma_y = (A + B eps_p^n)(1 + C ln(rate / rate0))(1 - T*^m)"
MATERIAL = {
    "type": "object",
    "properties": {
        "model": doc({"type": "string", "enum": list(MATERIAL_MODELS)},
                     "Constitutive model. linear_elastic: hypoelastic (Jaumann rate) Hooke's law; neo_hookean: "
                     "compressible neo-Hookean hyperelasticity from the deformation gradient; johnson_cook: J2 "
                     "plasticity with Johnson-Cook hardening, rate and adiabatic thermal softening (radial return)."),
        "density": number("kg/m^3", exclusiveMinimum=0, description="Initial (reference) mass density rho0."),
        "youngs_modulus": number("Pa", exclusiveMinimum=0, description="Young's modulus E."),
        "poisson_ratio": number("dimensionless", exclusiveMinimum=-1, exclusiveMaximum=0.5,
                                description="Poisson's ratio nu (with E: the shear and bulk moduli)."),
        "yield_stress": number("Pa", minimum=0, description=f"A: the initial yield stress in {_JC}."),
        "hardening_modulus": number("Pa", minimum=0, description=f"B: the strain-hardening modulus in {_JC}."),
        "hardening_exponent": number("dimensionless", exclusiveMinimum=0,
                                     description=f"n: the strain-hardening exponent in {_JC}."),
        "strain_rate_coefficient": number("dimensionless", minimum=0,
                                          description=f"C: the strain-rate coefficient in {_JC} (no rate term "
                                                      "below rate0)."),
        "reference_strain_rate": number("1/s", exclusiveMinimum=0,
                                        description=f"rate0: the reference plastic strain rate in {_JC}."),
        "thermal_exponent": number("dimensionless", exclusiveMinimum=0,
                                   description=f"m: the thermal-softening exponent in {_JC}, T* = (T - T_room) "
                                               "/ (T_melt - T_room)."),
        "melt_temperature": number("K", exclusiveMinimum=0,
                                   description="T_melt: the temperature at which Johnson-Cook's flow stress "
                                               "vanishes (above room_temperature)."),
        "room_temperature": number("K", exclusiveMinimum=0,
                                   description="T_room: the temperature below which Johnson-Cook has no thermal "
                                               "softening; also the bodies' initial temperature unless they give "
                                               "one."),
        "specific_heat": number("J/(kg K)", exclusiveMinimum=0,
                                description="Specific heat c_p: the temperature rise of the adiabatic plastic "
                                            "heating, dT = taylor_quinney sigma_y d(eps_p) / (rho c_p)."),
        "taylor_quinney": number("dimensionless", minimum=0, maximum=1,
                                 description="Taylor-Quinney coefficient: the share of the plastic work that "
                                             "heats the material (the rest is stored)."),
    },
    "additionalProperties": False,
    "required": ["model", "density", "youngs_modulus", "poisson_ratio"],
    "allOf": variants("model", MODEL_KEYS),
    "description": "A solid material of the Lagrangian bodies, by the name the bodies use.",
}
MATERIALS = {
    "type": "object",
    "minProperties": 1,
    "propertyNames": {"pattern": NAME_PATTERN},
    "additionalProperties": MATERIAL,
    "x-allowed": "at least one material table, e.g. [materials.steel]",
    "description": "The Lagrangian bodies' solid materials, one table each by name, e.g. [materials.steel].",
}

# (the defaults of base and centre: solvers/lagrange/mesh.py body_mesh, the origin)
QUARTER_CYLINDER = table(
    {
        "radius": number("m", exclusiveMinimum=0, description="The cylinder's radius."),
        "length": number("m", exclusiveMinimum=0, description="The cylinder's length along z."),
        "radial_cells": integer(None, minimum=2,  # butterfly grid needs >= 2
                                description="Elements across the radius (a square core and an O-grid ring)."),
        "axial_cells": integer(None, minimum=1, description="Elements along the axis."),
        # the centre of its bottom face (default the origin): a rod placed in a background grid
        "base": {**vector("m", description="The centre of the bottom face: the mesh is moved there.",
                          default=[0.0, 0.0, 0.0]), "minItems": 3},
    },
    required=("radius", "length", "radial_cells", "axial_cells"),
    description="3-D: the quarter x >= 0, y >= 0 of a cylinder along z from its bottom face, as a butterfly "
                "(O-grid) hexahedral mesh (a quarter of a rod: symmetry conditions on x = 0 and y = 0 make it "
                "whole).",
)
QUARTER_DISK = table(
    {
        "radius": number("m", exclusiveMinimum=0, description="The disk's radius."),
        "radial_cells": integer(None, minimum=2, description="Elements across the radius (a square core and "
                                                             "an O-grid ring)."),
        # the disk's centre (default the origin)
        "base": {**vector("m", description="The disk's centre: the mesh is moved there.", default=[0.0, 0.0]),
                 "minItems": 2, "maxItems": 2},
    },
    required=("radius", "radial_cells"),
    description="2-D: the quarter x >= 0, y >= 0 of a disk as a butterfly (O-grid) quadrilateral mesh.",
)
RING = table(
    {
        "inner_radius": number("m", exclusiveMinimum=0, description="The annulus's inner radius."),
        "outer_radius": number("m", exclusiveMinimum=0, description="The annulus's outer radius (above "
                                                                    "inner_radius)."),
        "radial_cells": integer(None, minimum=1, description="Elements through the wall."),
        "angular_cells": integer(None, minimum=3,  # fewer would be flat (zero area)
                                 description="Elements around the circumference."),
        # the ring's centre (default the origin)
        "centre": {**vector("m", description="The annulus's centre.", default=[0.0, 0.0]),
                   "minItems": 2, "maxItems": 2},
    },
    required=("inner_radius", "outer_radius", "radial_cells", "angular_cells"),
    description="2-D: a full annulus of quadrilaterals on a polar grid (the seam's nodes merged).",
)
MESH = table(
    {
        "box": doc(BOX, "A structured box of quadrilaterals (2-D) or hexahedra (3-D)."),
        "quarter_cylinder": QUARTER_CYLINDER,
        "quarter_disk": QUARTER_DISK,
        "ring": RING,
        "file": {"type": "string", "minLength": 1,
                 "description": "A mesh file (Gmsh .msh or .vtu, read through meshio) of quadrilaterals (2-D) or "
                                "hexahedra (3-D), relative to the case directory and inside it (or inside a "
                                "directory of $IMMERSE_ALLOW_PATH)."},
    },
    minProperties=1,
    maxProperties=1,
    description="The body's mesh: exactly one of a generated shape or a mesh file.",
)
MESH["x-allowed"] = "must have exactly one of: box, quarter_cylinder, quarter_disk, ring, file"

BODY = table(
    {
        "name": name(description="The body's name (unique): in [contact] pairs, outputs and messages."),
        "material": {"type": "string", "minLength": 1,
                     "description": "The body's material: the name of one of the [materials] tables."},
        "mesh": MESH,
        "initial_velocity": vector("m/s", {"type": ["number", "string"]},
                                   description="Initial velocity of the nodes: per component a number or an "
                                               "expression in the initial coordinates x, y (, z), e.g. \"2 - 100*y\" "
                                               "(default: at rest)."),
        "initial_temperature": number("K", exclusiveMinimum=0,
                                      description="Initial temperature of the body (Johnson-Cook's thermal "
                                                  "softening; default: the material's room_temperature, else "
                                                  f"{DEFAULT_ROOM_TEMPERATURE} K)."),
        # element erosion (LS-DYNA's MAT_ADD_EROSION, effective strain): an element whose effective
        # strain (sqrt(2/3 d':d') integrated over the steps) reaches this, or that would invert,
        # erodes: no force from then on, its nodes keep their mass, its internal energy is booked;
        # time_step: so does one whose stable step falls below this share of the solver's first one
        # (LS-DYNA's DTMIN with ERODE = 1: a crushed element stops the run by its step long before
        # it inverts)
        "erosion": table({"strain": number("dimensionless", exclusiveMinimum=0,
                                           description="An element whose effective strain (sqrt(2/3 d':d') "
                                                       "integrated over the steps) reaches this, or that would "
                                                       "invert, erodes."),
                          # (absent: 0.0 in the normalised case, i.e. off; outside the key's range, so said
                          # rather than given as a "default")
                          "time_step": number("dimensionless", exclusiveMinimum=0, exclusiveMaximum=1,
                                              description="An element whose stable step falls below this share "
                                                          "of the solver's first step erodes too (LS-DYNA's "
                                                          "DTMIN with ERODE = 1; absent: no step criterion).")},
                         required=("strain",),
                         description="Element erosion (LS-DYNA's *MAT_ADD_EROSION): an eroded element gives no "
                                     "force or stable step from then on, its nodes keep their mass and its "
                                     "internal energy is booked (absent: no erosion)."),
        # a body coupled to the background thinner than 1.5 of its zones is refused unless this is
        # true (orchestrator/coupling/thickness.py: gas on both its sides in one zone leaks through)
        "accept_thin": doc({"type": "boolean"},
                           "Coupled to a background: run the body even where it is thinner than 1.5 of the "
                           "background's zones (refused otherwise: gas on both its sides in one zone leaks "
                           "through).", default=False),
        # hourglass control of the one-point elements: the viscous Flanagan-Belytschko force (which
        # adds no bending stiffness: a body 2 elements thick bends 4/3 too softly) or the
        # assumed-strain stiffness of Belytschko & Bindeman (exact bending of rectangular quads and
        # hexahedra, no shear or volumetric locking)
        "hourglass_control": doc({"type": "string", "enum": ["viscous", "assumed_strain"]},
                                 "Hourglass control of the one-point elements. assumed_strain: Belytschko & "
                                 "Bindeman's co-rotational hourglass stiffness (the bending the bi-/trilinear "
                                 "element holds; no shear or volumetric locking); viscous: Flanagan-Belytschko's "
                                 "viscous force alone (no bending stiffness: thin walls bend too softly).",
                                 default="assumed_strain"),
    },
    required=("name", "material", "mesh"),
    description="A Lagrangian body ([[lagrange.bodies]]): its mesh, material and initial state.",
)

LAGRANGE = table(
    {
        # FB viscous hourglass damping is itself explicit: stable for coefficient <= 1/8 at dt = h/c
        "hourglass": number("dimensionless", minimum=0, maximum=0.125, default=LAGRANGE_DEFAULTS["hourglass"],
                            description="Flanagan-Belytschko viscous hourglass coefficient (bodies with "
                                        "hourglass_control = \"assumed_strain\" damp their hourglass rate at a "
                                        "tenth of it besides their stiffness)."),
        "bulk_viscosity_linear": number("dimensionless", minimum=0,
                                        default=LAGRANGE_DEFAULTS["bulk_viscosity_linear"],
                                        description="Linear coefficient of the artificial bulk viscosity that "
                                                    "spreads shocks over a few elements (LS-DYNA's Q2)."),
        "bulk_viscosity_quadratic": number("dimensionless", minimum=0,
                                           default=LAGRANGE_DEFAULTS["bulk_viscosity_quadratic"],
                                           description="Quadratic coefficient of the artificial bulk viscosity "
                                                       "(LS-DYNA's Q1)."),
        "gravity": vector("m/s^2", description="Gravitational acceleration g: the force m g on every node (its "
                                               "work: the gravity_work diagnostic; absent: none)."),
        # the time integrator (solvers/lagrange/integrators.py registers them by name);
        # quasi_static: equilibrium states, time a load parameter, load_steps of end_time / load_steps
        "integrator": doc({"enum": sorted(INTEGRATORS)},
                          "Time integration of the bodies. explicit: central differences at the stable step; "
                          "quasi_static: equilibrium states of elastic bodies, time only a load parameter; "
                          "midpoint: the implicit energy-momentum midpoint scheme; newmark: the implicit "
                          "trapezoidal rule (the comparison).", default="explicit"),
        "load_steps": integer(None, minimum=1, default=1,  # (solvers/lagrange/quasi_static.py)
                              description="quasi_static: the load steps, each end_time / load_steps, with the "
                                          "loads ramped by t / end_time."),
        # midpoint, newmark: the implicit step (s) and the energy balance a step may be off by before
        # the run stops as unstable (relative to the energy)
        "time_step": number("s", exclusiveMinimum=0,
                            description="midpoint, newmark (required there): the implicit step, the first and "
                                        "the largest (a step's Newton iterations halve or grow the next one)."),
        "time_step_min": number("s", exclusiveMinimum=0,
                                description="midpoint, newmark: the smallest step that a failed Newton iteration "
                                            "is halved down to before the run stops (default: time_step / 1024)."),
        "energy_limit": number("dimensionless", exclusiveMinimum=0, default=0.01,  # (implicit_dynamic.py)
                               description="midpoint, newmark: a step whose energy balance is off by more than "
                                           "this share of the energy stops the run as unstable."),
        # element subcycling (solvers/lagrange/subcycling.py, LS-DYNA's *CONTROL_SUBCYCLE): each element
        # and node at a power-of-two multiple of the smallest element's step, up to this ratio; 1: off
        "subcycling": doc({"enum": list(SUBCYCLING_RATIOS),
                           "x-allowed": "one of " + ", ".join(map(str, SUBCYCLING_RATIOS)) + " (1: off)"},
                          "Element subcycling (LS-DYNA's *CONTROL_SUBCYCLE): elements and nodes step at powers "
                          "of two of the smallest element's step, up to this ratio, so a small or crushed "
                          "element sets only its own step; 1: off (explicit integrator only).", default=1),
        "bodies": {"type": "array", "items": BODY,
                   "description": "The Lagrangian (finite-element) bodies, one [[lagrange.bodies]] table each."},
    },
    description="The Lagrangian solver (finite elements for solids): its options and its bodies.",
)

BOUNDARY_KEYS = {
    "fixed": ("type", "region"),
    "velocity": ("type", "region", "velocity"),
    # a uniform traction (Pa) on the exterior facets whose nodes all lie in the region (quasi-static
    # mode: ramped with the load factor t / end_time; the dynamic modes: times its curve, default 1)
    "traction": ("type", "region", "traction", "curve"),
    "symmetry": ("type", "axis", "at"),
    "rigid_wall": ("type", "point", "normal"),
}
BOUNDARY = {
    "type": "object",
    "properties": {
        "type": doc({"type": "string", "enum": list(BOUNDARY_TYPES)},
                    "The condition. fixed: every velocity component of the region's nodes held at 0; velocity: the "
                    "given components prescribed; symmetry: the axis component held at 0 on the plane axis = at; "
                    "rigid_wall: a frictionless plane wall the nodes cannot pass; traction: a surface load on the "
                    "region's exterior facets. Velocity conditions apply in file order (a later one wins)."),
        "region": {"type": "string", "minLength": 1,
                   "description": "The nodes it applies to: a boolean expression in the initial coordinates x, y "
                                  "(, z), e.g. \"x < 1e-9\" (traction: the exterior facets whose nodes all hold "
                                  "it)."},
        "velocity": table(
            {c: number("m/s", description=f"The prescribed {c} velocity.") for c in ("x", "y", "z")},
            minProperties=1,
            description="The prescribed velocity components (any subset of x, y, z; the others stay free).",
        ),
        "traction": table(
            {c: number("Pa", description=f"The traction's {c} component.") for c in ("x", "y", "z")},
            minProperties=1,
            description="A uniform traction (force per area) on the region's exterior facets, as consistent "
                        "nodal forces (components not given: 0).",
        ),
        # the traction's history: [[t (s), factor], ...], t increasing, linear between the points and
        # the end values held outside (LS-DYNA's *DEFINE_CURVE; a hat pulse: [[0, 0], [2.5, 2.5], [5, 0]])
        "curve": {"type": "array", "minItems": 2,
                  "items": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
                  "x-allowed": "must be a list of at least 2 [time (s), factor] pairs",
                  "description": "The traction's history, [[t, factor], ...] (t in s, strictly increasing; linear "
                                 "between the points, the end values held outside: LS-DYNA's *DEFINE_CURVE); "
                                 "absent: constant (quasi_static: ramped by t / end_time, no curve)."},
        "axis": doc({"type": "string", "enum": ["x", "y", "z"]}, "symmetry: the axis normal to the symmetry "
                                                                 "plane (its velocity component is held at 0)."),
        "at": number("m", description="symmetry: the plane's coordinate along axis (the nodes on it are held)."),
        "point": vector("m", description="rigid_wall: a point of the wall's plane."),
        "normal": vector(None, description="rigid_wall: the wall's normal, pointing to the bodies' side (any "
                                           "non-zero length)."),
    },
    "additionalProperties": False,
    "required": ["type"],
    "allOf": variants("type", BOUNDARY_KEYS, {**BOUNDARY_KEYS, "traction": ("type", "region", "traction")}),
    "description": "One boundary condition of the Lagrangian bodies.",
}
BOUNDARIES = {"type": "array", "items": BOUNDARY,
              "description": "Boundary conditions of the Lagrangian bodies, one [[boundaries]] table each."}


# ---- [materials] ----------------------------------------------------------------------------------
def normalise_materials(raw: dict | None, case: dict) -> dict:
    return {name: {k: (v if k == "model" else to_float(v)) for k, v in m.items()}
            for name, m in (raw or {}).items()}


def check_materials(case: dict, data: dict) -> None:
    """Wave speeds that are floats; Johnson-Cook: melt above room temperature."""
    for name, m in case["materials"].items():
        _check_wave_speed(name, m, data["materials"][name])
        if m["model"] == "johnson_cook" and not m["melt_temperature"] > m["room_temperature"]:
            raw = data["materials"][name]
            raise CaseError(format_key(["materials", name, "melt_temperature"]),
                            raw["melt_temperature"],
                            f"must be > room_temperature = {fmt_num(raw['room_temperature'])} (K)")


def _check_wave_speed(name: str, m: dict, raw: dict) -> None:
    """The elastic wave speed sqrt(M / rho), M the P-wave modulus, sets the time step: it must be a
    finite number (a huge modulus over a tiny density overflows it: dt = 0, a run that never ends)."""
    nu = m["poisson_ratio"]
    with_modulus = m["youngs_modulus"] * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))
    c2 = with_modulus / m["density"]
    if not (math.isfinite(c2) and c2 > 0.0):
        raise CaseError(format_key(["materials", name, "youngs_modulus"]), raw["youngs_modulus"],
                        f"gives an elastic wave speed that is not a finite number with density = "
                        f"{fmt_num(m['density'])} kg/m^3; allowed: moduli and densities whose "
                        "ratio is a float")


# ---- [lagrange] -----------------------------------------------------------------------------------
def normalise_lagrange(raw: dict | None, case: dict) -> dict | None:
    if raw is None:
        return None
    dim = case["run"]["dimension"]
    bodies = []
    for b in raw.get("bodies", []):
        mesh_in = b["mesh"]
        if "box" in mesh_in:
            box = mesh_in["box"]
            mesh = {"box": {"lower": [to_float(v) for v in box["lower"]],
                            "upper": [to_float(v) for v in box["upper"]],
                            "cells": [int(v) for v in box["cells"]]}}
        elif "quarter_disk" in mesh_in:
            q = mesh_in["quarter_disk"]
            mesh = {"quarter_disk": {"radius": to_float(q["radius"]), "radial_cells": int(q["radial_cells"]),
                                     **({"base": [to_float(v) for v in q["base"]]} if "base" in q else {})}}
        elif "ring" in mesh_in:
            q = mesh_in["ring"]
            mesh = {"ring": {"inner_radius": to_float(q["inner_radius"]), "outer_radius": to_float(q["outer_radius"]),
                             "radial_cells": int(q["radial_cells"]), "angular_cells": int(q["angular_cells"]),
                             "centre": [to_float(v) for v in q.get("centre", (0.0, 0.0))]}}
        elif "quarter_cylinder" in mesh_in:
            q = mesh_in["quarter_cylinder"]
            mesh = {"quarter_cylinder": {"radius": to_float(q["radius"]), "length": to_float(q["length"]),
                                         "radial_cells": int(q["radial_cells"]),
                                         "axial_cells": int(q["axial_cells"]),
                                         **({"base": [to_float(v) for v in q["base"]]} if "base" in q else {})}}
        else:
            mesh = {"file": (case["case_dir"] / mesh_in["file"]).resolve()}
        mat = case["materials"].get(b["material"], {})
        t0 = b.get("initial_temperature", mat.get("room_temperature", DEFAULT_ROOM_TEMPERATURE))
        size = body_mesh_size({"mesh": mesh})  # None for a file: counted when it is read
        bodies.append({
            "name": b["name"],
            "material": b["material"],
            "mesh": mesh,
            "size": None if size is None else {"elements": size[0], "nodes": size[1]},
            "initial_velocity": ([num_or_expression(v) for v in b["initial_velocity"]]
                                 if "initial_velocity" in b else [0.0] * dim),
            "initial_temperature": to_float(t0),
            "erosion": ({"strain": to_float(b["erosion"]["strain"]),
                         "time_step": to_float(b["erosion"].get("time_step", 0.0))} if "erosion" in b else None),
            "accept_thin": bool(b.get("accept_thin", False)),
            "hourglass_control": b.get("hourglass_control", "assumed_strain"),
        })
    lagrange = {k: to_float(raw.get(k, v)) for k, v in LAGRANGE_DEFAULTS.items()}
    if "gravity" in raw:
        lagrange["gravity"] = [to_float(v) for v in raw["gravity"]]
    lagrange["integrator"] = raw.get("integrator", "explicit")
    if "load_steps" in raw:
        lagrange["load_steps"] = int(raw["load_steps"])
    for key in ("time_step", "time_step_min", "energy_limit"):
        if key in raw:
            lagrange[key] = to_float(raw[key])
    lagrange["subcycling"] = int(raw.get("subcycling", 1))
    lagrange["bodies"] = bodies
    return lagrange


def _check_subcycling(case: dict, integrator: str) -> None:
    """Element subcycling (solvers/lagrange/subcycling.py) steps the explicit solver's elements and
    nodes at their own rates; what would need the node's own times is refused in one line."""
    ratio = case["lagrange"].get("subcycling", 1)
    if ratio == 1:
        return
    why = None
    if integrator != "explicit":
        why = f"subcycles the explicit integrator's steps; lagrange.integrator = {integrator!r} takes its own"
    elif case.get("coupling"):
        why = "not with [coupling] yet (the coupler's impulses come at the group's step)"
    elif case.get("contact"):
        why = "not with [contact] yet (its multipliers are solved once per step of the whole group)"
    if why:
        raise CaseError("lagrange.subcycling", ratio, why + "; allowed here: 1 (off)")


def mat_model(case: dict, body: dict) -> str:
    return case["materials"][body["material"]]["model"]


def check_lagrange(case: dict, data: dict) -> None:
    """At least one body and a material table; unique body names,
    defined materials, vector lengths, box extents, 3-D-only meshes, velocity expressions, initial
    temperature below melt."""
    dim = case["run"]["dimension"]
    bodies = case["lagrange"]["bodies"]
    raw_bodies = data.get("lagrange", {}).get("bodies", [])
    if "gravity" in data.get("lagrange", {}):
        check_length("lagrange.gravity", data["lagrange"]["gravity"], dim)
    if not bodies:
        raise CaseError("lagrange.bodies", data.get("lagrange", {}).get("bodies", MISSING),
                        "at least one body is required ([[lagrange.bodies]]), or a background [ale]")
    if not case["materials"]:
        raise CaseError("materials", MISSING, "required key missing: the bodies' materials, e.g. [materials.steel]")
    integrator = case["lagrange"].get("integrator", "explicit")
    static = not INTEGRATORS[integrator].dynamic
    if static and case.get("coupling"):
        raise CaseError("lagrange.integrator", integrator, "a static solve has no inertia to couple with a flow "
                        "([coupling]); allowed with [coupling]: " + ", ".join(k for k, v in INTEGRATORS.items() if v.dynamic))
    if "load_steps" in case["lagrange"] and not static:
        raise CaseError("lagrange.load_steps", case["lagrange"]["load_steps"],
                        f"load steps are the quasi-static mode's (lagrange.integrator = {integrator!r}); allowed: "
                        "leave it out")
    implicit = INTEGRATORS[integrator].implicit
    implicit_names = ", ".join(k for k, v in INTEGRATORS.items() if v.implicit)
    for key in ("time_step", "time_step_min", "energy_limit"):
        if key in case["lagrange"] and not implicit:
            raise CaseError(f"lagrange.{key}", case["lagrange"][key],
                            f"a key of the implicit integrators ({implicit_names}), not of lagrange.integrator = "
                            f"{integrator!r}; allowed: leave it out")
    if implicit:
        if "time_step" not in case["lagrange"]:
            raise CaseError("lagrange.time_step", MISSING, f"required with lagrange.integrator = {integrator!r}: "
                            "the implicit step, s (e.g. 10 times the explicit limit)")
        tmin = case["lagrange"].get("time_step_min")
        if tmin is not None and not tmin <= case["lagrange"]["time_step"]:
            raise CaseError("lagrange.time_step_min", tmin, f"must be <= lagrange.time_step "
                            f"({fmt_num(case['lagrange']['time_step'])})")
        if case.get("coupling"):
            raise CaseError("lagrange.integrator", integrator,
                            "[coupling] with an implicit integrator is not built yet (issue 12); allowed with "
                            "[coupling]: explicit")
    _check_subcycling(case, integrator)
    seen: dict[str, int] = {}
    for i, (body, raw) in enumerate(zip(bodies, raw_bodies)):
        base = ["lagrange", "bodies", i]
        if body["name"] in seen:
            raise CaseError(format_key(base + ["name"]), body["name"],
                            f"duplicate body name (also lagrange.bodies[{seen[body['name']]}].name)")
        seen[body["name"]] = i
        if body["material"] not in case["materials"]:
            defined = ", ".join(case["materials"]) or "(none)"
            raise CaseError(format_key(base + ["material"]), body["material"],
                            f"undefined material; defined: {defined}")
        mesh = raw["mesh"]
        if "box" in mesh:
            box = mesh["box"]
            for k in ("lower", "upper", "cells"):
                check_length(format_key(base + ["mesh", "box", k]), box[k], dim)
            for j, (lo, hi) in enumerate(zip(box["lower"], box["upper"])):
                if not hi > lo:
                    raise CaseError(format_key(base + ["mesh", "box", "upper"]), box["upper"],
                                    f"must be > lower component-wise (component {j}: "
                                    f"{fmt_num(hi)} <= {fmt_num(lo)})")
            check_extent(format_key(base + ["mesh", "box"]), body["mesh"]["box"], box)
        elif "quarter_disk" in mesh:
            if dim != 2:
                raise CaseError(format_key(base + ["mesh", "quarter_disk"]), mesh["quarter_disk"],
                                f"quarter_disk meshes are 2D only (run.dimension = {dim}; in 3D: quarter_cylinder)")
        elif "ring" in mesh:
            if dim != 2:
                raise CaseError(format_key(base + ["mesh", "ring"]), mesh["ring"],
                                f"ring meshes are 2D only (run.dimension = {dim})")
            ring = body["mesh"]["ring"]
            if not ring["inner_radius"] < ring["outer_radius"]:
                raise CaseError(format_key(base + ["mesh", "ring", "outer_radius"]), mesh["ring"]["outer_radius"],
                                f"must be > inner_radius ({fmt_num(ring['inner_radius'])})")
        elif "quarter_cylinder" in mesh:
            if dim != 3:
                raise CaseError(format_key(base + ["mesh", "quarter_cylinder"]),
                                mesh["quarter_cylinder"],
                                f"quarter_cylinder meshes are 3D only (run.dimension = {dim})")
        if implicit and mat_model(case, body) not in ("linear_elastic", "neo_hookean"):
            raise CaseError(format_key(["materials", body["material"], "model"]), mat_model(case, body),
                            f"lagrange.integrator = {integrator!r} solves hyperelastic bodies (St. Venant-"
                            "Kirchhoff from a linear_elastic material's E, nu; neo_hookean); allowed: "
                            "linear_elastic, neo_hookean")
        if implicit and "erosion" in raw:
            raise CaseError(format_key(base + ["erosion"]), raw["erosion"],
                            f"not with lagrange.integrator = {integrator!r}; allowed: leave it out")
        if static and mat_model(case, body) not in ("linear_elastic", "neo_hookean"):
            raise CaseError(format_key(["materials", body["material"], "model"]), mat_model(case, body),
                            f"lagrange.integrator = {integrator!r} solves elasticity (small strain or neo-Hookean finite strain); allowed: "
                            "linear_elastic, neo_hookean")
        for key in ("initial_velocity", "erosion"):
            if static and key in raw:
                raise CaseError(format_key(base + [key]), raw[key],
                                f"not with lagrange.integrator = {integrator!r} (a static solve: no motion "
                                "of its own, no erosion); allowed: leave it out")
        if "initial_velocity" in raw:
            v = raw["initial_velocity"]
            check_length(format_key(base + ["initial_velocity"]), v, dim)
            for j, item in enumerate(v):
                if isinstance(item, str):
                    check_expression(format_key(base + ["initial_velocity", j]), item, dim, NUM)
        mat = case["materials"][body["material"]]
        if mat["model"] == "johnson_cook" and "initial_temperature" in raw:
            if not body["initial_temperature"] < mat["melt_temperature"]:
                raise CaseError(format_key(base + ["initial_temperature"]),
                                raw["initial_temperature"],
                                f"must be < melt_temperature = {fmt_num(mat['melt_temperature'])}"
                                f" of material {body['material']!r} (K)")


def check_mesh_files(case: dict, data: dict) -> None:
    """Every mesh path is checked to lie inside the case directory before any file is read."""
    dim = case["run"]["dimension"]
    raw_bodies = data.get("lagrange", {}).get("bodies", [])
    files = [(format_key(["lagrange", "bodies", i, "mesh", "file"]), raw_bodies[i]["mesh"]["file"], body)
             for i, body in enumerate(case["lagrange"]["bodies"]) if "file" in body["mesh"]]
    for key, raw, body in files:
        check_path_inside(key, raw, body["mesh"]["file"], case["case_dir"])
    for key, raw, body in files:
        body["size"], body["_extent"] = _check_mesh_file(key, raw, body["mesh"]["file"], dim)


_CELL_TYPE = {2: "quad", 3: "hexahedron"}


def _check_mesh_file(key: str, raw: str, path: Path, dim: int) -> tuple[dict, dict]:
    """Read and check a body's mesh file; its ``{"elements", "nodes"}`` counts and the ``{"lower",
    "upper"}`` corners of its nodes' box (for [coupling]'s check that the body lies in the grid)."""
    from orchestrator.resources import machine_memory

    memory = machine_memory()
    limit = memory // MESH_READ_FACTOR
    st = stat_regular(path, key, raw, "must be a regular mesh file",
                      not_found="file not found (paths are relative to the case directory)")
    if st.st_size > limit:
        raise CaseError(key, raw, f"is {format_bytes(st.st_size)}: reading it takes about "
                                  f"{MESH_READ_FACTOR} times that, this machine has "
                                  f"{format_bytes(memory)}; allowed: mesh files up to "
                                  f"{format_bytes(limit)} here")
    if not os.access(path, os.R_OK):
        raise CaseError(key, raw, "file is not readable (permission denied)")
    from solvers.lagrange.mesh import MeshError, read_mesh  # lazy: heavy imports

    expected = _CELL_TYPE[dim]

    try:
        mesh = read_mesh(path, dim, max_inflated=limit)
    except MeshError as exc:
        raise CaseError(key, raw, f"must be a readable {expected} mesh ({exc})") from None
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad input file
        raise CaseError(key, raw, f"must be a readable {expected} mesh "
                                  f"({type(exc).__name__}: {exc})") from None
    if getattr(mesh, "cell_type", expected) != expected or len(mesh.cells) == 0:
        raise CaseError(key, raw, f"must be a readable {expected} mesh (no {expected} cells "
                                  f"for a {dim}D case)")
    import numpy as np

    pts = np.asarray(mesh.points, dtype=np.float64)[:, :dim]
    return ({"elements": int(len(mesh.cells)), "nodes": int(len(mesh.points))},
            {"lower": pts.min(axis=0).tolist(), "upper": pts.max(axis=0).tolist()})


# ---- [[boundaries]] -------------------------------------------------------------------------------
def normalise_boundaries(raw: list | None, case: dict) -> list:
    boundaries = []
    for bc in raw or []:
        out = {"type": bc["type"]}
        for k, v in bc.items():
            if k == "type" or k == "region" or k == "axis":
                out[k] = v
            elif k in ("velocity", "traction"):
                out[k] = {c: to_float(x) for c, x in v.items()}
            elif k == "at":
                out[k] = to_float(v)
            elif k == "curve":
                out[k] = [[to_float(t), to_float(f)] for t, f in v]
            elif k in ("point", "normal"):
                out[k] = [to_float(x) for x in v]
        boundaries.append(out)
    return boundaries


def _check_curve(key: str, raw, curve: list, static: bool, integrator: str) -> None:
    """A traction's [[t, factor], ...]: times strictly increasing, every value a finite float; not in
    the quasi-static mode (its loads follow the load factor t / end_time)."""
    if static:
        raise CaseError(key, raw, f"lagrange.integrator = {integrator!r} ramps every load with t / end_time; "
                                  "allowed: no curve (curves are for the dynamic integrators)")
    if not all(math.isfinite(v) for pair in curve for v in pair):
        raise CaseError(key, raw, "must hold finite numbers (time in s, factor)")
    if any(b[0] <= a[0] for a, b in zip(curve, curve[1:])):
        raise CaseError(key, raw, "times must increase strictly from one point to the next")


def check_boundaries(case: dict, data: dict) -> None:
    """Region expressions, components and axes of the case's dimension, wall normals."""
    dim = case["run"]["dimension"]
    comps = expression_names(dim)
    for i, (bc, raw) in enumerate(zip(case["boundaries"], data.get("boundaries", []))):
        base = ["boundaries", i]
        if "region" in raw:
            check_expression(format_key(base + ["region"]), raw["region"], dim, BOOL)
        for key in ("velocity", "traction"):
            for c in raw.get(key, {}):
                if c not in comps:
                    raise CaseError(format_key(base + [key, c]), raw[key][c],
                                    f"dimension mismatch: no {c} component in a {dim}D case; "
                                    f"allowed: {', '.join(comps)}")
        integrator = (case.get("lagrange") or {}).get("integrator", "explicit")
        static = integrator in INTEGRATORS and not INTEGRATORS[integrator].dynamic
        if "curve" in raw:
            _check_curve(format_key(base + ["curve"]), raw["curve"], bc["curve"], static, integrator)
        if bc["type"] == "rigid_wall" and integrator in INTEGRATORS and INTEGRATORS[integrator].implicit:
            raise CaseError(format_key(base + ["type"]), raw["type"],
                            f"rigid walls are not built into lagrange.integrator = {integrator!r}; allowed: "
                            "fixed, velocity, symmetry")
        if bc["type"] == "rigid_wall" and static:
            raise CaseError(format_key(base + ["type"]), raw["type"],
                            f"rigid_wall boundaries are velocity conditions; allowed with lagrange.integrator = "
                            f"{integrator!r}: fixed, velocity (a displacement rate), symmetry, traction "
                            "(a wall: a held body in contact)")
        if "axis" in raw and raw["axis"] not in comps:
            raise CaseError(format_key(base + ["axis"]), raw["axis"],
                            f"dimension mismatch: must be one of {', '.join(comps)} in a "
                            f"{dim}D case")
        for k in ("point", "normal"):
            if k in raw:
                check_length(format_key(base + [k]), raw[k], dim)
        if "normal" in raw:  # its length squared is taken: it must neither vanish nor overflow
            n2 = math.fsum(float(c) * float(c) for c in raw["normal"])
            if not (n2 > 0.0 and math.isfinite(n2)):
                raise CaseError(format_key(base + ["normal"]), raw["normal"],
                                "must be a non-zero vector whose squared length is a finite "
                                "float (e.g. a unit vector)")


# ---- registration (places: after [run], [ranks]; [ale] is 40) ----------------------------------------
register_table("materials", MATERIALS, normalise_materials, check_materials, order=20)
register_table("lagrange", LAGRANGE, normalise_lagrange, check_lagrange, order=30,
               check_files=check_mesh_files, default=True)
register_table("boundaries", BOUNDARIES, normalise_boundaries, check_boundaries, order=50)
