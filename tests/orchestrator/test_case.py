"""Tests of orchestrator.case: valid cases load with the right defaults, every bad case
directory fails with a one-line CaseError on the exact dotted key."""

import os
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import (
    MISSING,
    CaseError,
    format_key,
    load_case,
    ranks_for,
    solvers_used,
)
from orchestrator.schema.case import CASE_SCHEMA, MODEL_KEYS
from solvers.expressions import compile_expression

HERE = Path(__file__).parent
VALID = HERE / "valid_cases"
BAD = HERE / "bad_cases"


def assert_one_line(err: CaseError):
    msg = str(err)
    assert "\n" not in msg and "\r" not in msg
    assert msg == f"{err.key} = {err.value!r}: {err.allowed}"
    return msg


# --------------------------------------------------------------------------- valid cases
def test_box3d_loads_with_values_and_defaults():
    case = load_case(VALID / "box3d")
    assert case["name"] == "box3d"
    assert case["case_dir"] == (VALID / "box3d").resolve()
    assert case["case_dir"].is_absolute()

    run = case["run"]
    assert run["dimension"] == 3 and isinstance(run["dimension"], int)
    assert run["end_time"] == pytest.approx(2.0e-5, rel=1e-15)
    assert run["dt_scale"] == 0.8
    assert run["output_interval"] == pytest.approx(2.0e-5 / 20, rel=1e-15)  # default
    assert run["checkpoint_interval"] == pytest.approx(1.0e-5, rel=1e-15)
    assert run["max_steps"] == 10_000_000
    assert run["diagnostics_every"] == 1

    assert case["ranks"] == {"lagrange": 2}
    assert solvers_used(case) == ["lagrange"]

    cu = case["materials"]["copper"]
    assert cu["model"] == "johnson_cook"
    assert set(cu) == set(MODEL_KEYS["johnson_cook"])
    assert cu["melt_temperature"] == 1356.0 and cu["room_temperature"] == 294.0
    rubber = case["materials"]["rubber"]
    assert rubber == {"model": "neo_hookean", "density": 1100.0, "youngs_modulus": 5e6,
                      "poisson_ratio": 0.45}
    assert all(isinstance(v, float) for v in rubber.values() if not isinstance(v, str))

    lag = case["lagrange"]
    assert lag["hourglass"] == 0.05
    assert lag["bulk_viscosity_linear"] == 0.06      # default
    assert lag["bulk_viscosity_quadratic"] == 1.5    # default
    bar, pad = lag["bodies"]
    assert bar["name"] == "bar" and bar["material"] == "copper"
    assert bar["mesh"] == {"box": {"lower": [0.0, 0.0, 0.0], "upper": [0.004, 0.004, 0.02],
                                   "cells": [2, 2, 8]}}
    assert bar["initial_velocity"][:2] == [0.0, 0.0]
    assert bar["initial_velocity"][2] == "-190.0 * where(z > 0.001, 1, 0.5)"  # kept as text
    assert bar["initial_temperature"] == 294.0       # default: material room_temperature
    assert pad["initial_velocity"] == [0.0, 0.0, 0.0]  # default zeros
    assert pad["initial_temperature"] == 300.0
    assert pad["mesh"]["box"]["lower"] == [0.0, 0.0, -0.01]

    b = case["boundaries"]
    assert [x["type"] for x in b] == ["symmetry", "fixed", "velocity", "rigid_wall"]
    assert b[0] == {"type": "symmetry", "axis": "x", "at": 0.0}
    assert b[2]["velocity"] == {"y": 0.0}
    assert b[3]["normal"] == [0.0, 0.0, 1.0]

    assert case["check"]["kind"] == "momentum"
    assert case["check"]["params"] == {}   # (momentum takes none: checks.PARAMS)
    assert case["check"]["metrics"] == {"total_momentum_z": {"reference": -1.0,
                                                             "tolerance": 0.01}}


def test_box3d_expressions_evaluate():
    case = load_case(VALID / "box3d")
    z = np.array([0.0, 0.0005, 0.002, 0.02])
    vz = compile_expression(case["lagrange"]["bodies"][0]["initial_velocity"][2])
    np.testing.assert_allclose(vz(0 * z, 0 * z, z), [-95.0, -95.0, -190.0, -190.0], rtol=1e-15)
    region = compile_expression(case["boundaries"][2]["region"], kind="boolean")
    x = np.array([0.01, 0.01, 0.0, 0.01])
    y = np.array([0.0, 0.011, 0.005, 0.01])
    np.testing.assert_array_equal(region(x, y, 0 * x), [True, False, False, True])


def test_box2d_loads_with_all_defaults():
    case = load_case(VALID / "box2d")
    assert case["name"] == "box2d"
    assert case["run"] == {"dimension": 2, "end_time": 1e-4, "dt_scale": 0.9,
                           "output_interval": pytest.approx(5e-6, rel=1e-15),
                           "checkpoint_interval": None, "max_steps": 10_000_000,
                           "diagnostics_every": 1, "dt_min": None, "multirate": None, "max_substeps": 64,
                           "group_dt_max": {}}
    assert case["ranks"] == {"lagrange": 1}
    assert case["materials"] == {"steel": {"model": "linear_elastic", "density": 7850.0,
                                           "youngs_modulus": 210e9, "poisson_ratio": 0.3}}
    lag = case["lagrange"]
    assert (lag["hourglass"], lag["bulk_viscosity_linear"], lag["bulk_viscosity_quadratic"]) \
        == (0.1, 0.06, 1.5)
    (plate,) = lag["bodies"]
    assert plate["initial_velocity"] == [0.0, 0.0]
    assert plate["initial_temperature"] == 293.15
    assert plate["mesh"]["box"] == {"lower": [0.0, 0.0], "upper": [0.1, 0.02], "cells": [5, 1]}
    assert case["boundaries"] == [{"type": "fixed", "region": "x < 1e-9"}]
    assert case["check"] is None


def test_file_mesh_path_is_resolved(tmp_path, monkeypatch):
    case = load_case(VALID / "file3d")
    path = case["lagrange"]["bodies"][0]["mesh"]["file"]
    assert isinstance(path, Path) and path.is_absolute()
    assert path == (VALID / "file3d" / "column.msh").resolve()
    # relative to the case directory, not to the working directory
    monkeypatch.chdir(tmp_path)
    assert load_case(VALID / "file3d")["lagrange"]["bodies"][0]["mesh"]["file"] == path


def test_file_mesh_2d(tmp_path):
    (tmp_path / "sq.msh").write_text(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n"
        "4 0 1 0\n$EndNodes\n$Elements\n1\n1 3 2 0 0 1 2 3 4\n$EndElements\n")
    (tmp_path / "case.toml").write_text(
        (VALID / "box2d" / "case.toml").read_text().replace(
            "mesh = { box = { lower = [0, 0], upper = [0.1, 0.02], cells = [5, 1] } }",
            'mesh = { file = "sq.msh" }'))
    case = load_case(tmp_path)
    assert case["lagrange"]["bodies"][0]["mesh"] == {"file": (tmp_path / "sq.msh").resolve()}


def test_case_toml_path_accepted():
    assert load_case(VALID / "box2d" / "case.toml")["name"] == "box2d"


def test_missing_directory_and_missing_case_toml(tmp_path):
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path / "nope")
    assert ei.value.key == "case_dir"
    assert_one_line(ei.value)
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "case.toml" and "file not found" in str(ei.value)


# --------------------------------------------------------------------------- bad cases
BAD_CASES = [
    # (directory, expected key, fragment of the "allowed" text)
    ("missing_required_key", "run.end_time", "required key missing"),
    ("unknown_top_level_key", "solver", "unknown key; allowed: run, ranks, materials"),
    ("unknown_nested_key", "lagrange.bodies[0].velocity", "unknown key; allowed: name"),
    ("key_of_other_model", "materials.steel.yield_stress", "model = 'linear_elastic'"),
    ("negative_density", "materials.steel.density", "must be > 0 (kg/m^3)"),
    ("poisson_ratio_half", "materials.steel.poisson_ratio", "must be > -1 and < 0.5"),
    ("unknown_material_model", "materials.steel.model", "'johnson_cook'"),
    ("undefined_material", "lagrange.bodies[0].material", "undefined material; defined: steel"),
    ("missing_mesh_file", "lagrange.bodies[0].mesh.file", "file not found"),
    ("corrupt_mesh_file", "lagrange.bodies[0].mesh.file", "readable hexahedron mesh"),
    ("wrong_cell_type_mesh", "lagrange.bodies[0].mesh.file", "hexahedron"),
    ("end_time_zero", "run.end_time", "must be > 0 (s)"),
    ("end_time_negative", "run.end_time", "must be > 0 (s)"),
    ("dimension_mismatch", "lagrange.bodies[0].initial_velocity", "dimension mismatch"),
    ("box_dimension_mismatch", "lagrange.bodies[0].mesh.box.cells", "dimension mismatch"),
    ("ranks_zero", "ranks.lagrange", ">= 1"),
    ("unknown_rank_role", "ranks.fluid", "unknown role; allowed: lagrange"),
    ("bad_region_expression", "boundaries[0].region", "is not allowed"),
    ("region_not_boolean", "boundaries[0].region", "boolean"),
    ("bad_velocity_expression", "lagrange.bodies[0].initial_velocity[1]", "name 'z'"),
    ("toml_syntax_error", "case.toml", "TOML syntax error"),
    ("wrong_type", "materials.steel.density", "must be a number"),
    ("jc_missing_yield_stress", "materials.copper.yield_stress", "required key missing"),
    ("jc_melt_below_room", "materials.copper.melt_temperature", "room_temperature"),
    ("quarter_cylinder_2d", "lagrange.bodies[0].mesh.quarter_cylinder", "3D only"),
    ("two_mesh_kinds", "lagrange.bodies[0].mesh", "exactly one of: box, quarter_cylinder, quarter_disk, ring, file"),
    ("no_bodies", "lagrange.bodies", "at least one body"),
    ("ale_periodic_one_side", "ale.boundaries.x_lower", "periodic must be set on both"),
    ("ale_piston_eulerian", "ale.boundaries.x_lower.piston", "is a moving wall and needs ale.mode = \"lagrangian\""),
    ("ale_undefined_material", "ale.regions[1].material", "undefined material"),
    ("ale_unknown_eos", "ale.materials.air.eos", "must be one of"),
    ("ale_gamma_one", "ale.materials.air.gamma", "must be > 1"),
    ("ale_positive_pressure_cutoff", "ale.materials.al.pressure_cutoff", "must be <= 0 (Pa)"),
    ("ale_viscosity_kind", "ale.viscosity.kind", "one of: 'scalar', 'monotonic'"),
    ("ale_void_with_density", "ale.regions[1].density", "is void"),
    ("ale_mixed_lagrangian", "ale.mode", "need mode = \"eulerian\""),
    ("ale_region_without_density", "ale.regions[1]", "needs material, density"),
    ("ale_mixed_piston", "ale.boundaries.x_lower", "not supported yet"),
    ("ale_inflow_unknown_material", "ale.boundaries.x_lower.inflow.material", "with an equation of state"),
    ("ale_void_inflow", "ale.boundaries.x_lower", "with a void material"),
    ("multirate_with_contact", "run.multirate", "the lagrange group cannot take substeps: contact"),
    ("multirate_penalty", "run.multirate", "needs coupling.method = 'multiplier'"),
    ("group_dt_max_unknown_role", "run.group_dt_max.sph", "the case has no sph group"),
    ("multirate_max_substeps_zero", "run.max_substeps", "must be an integer >= 1 and <= 1024"),
    ("output_interval_too_long", "run.output_interval", "<= run.end_time"),
    ("dimension_four", "run.dimension", "one of: 2, 3"),
    ("symmetry_axis_z_2d", "boundaries[0].axis", "dimension mismatch"),
    ("boundary_key_of_other_type", "boundaries[0].velocity", "type = 'fixed'"),
    ("duplicate_body_name", "lagrange.bodies[1].name", "duplicate body name"),
    ("contact_unknown_body", "contact.pairs[0][1]", "not a body; bodies: left, right"),
    ("contact_self_node_to_surface", "contact.pairs[0]", "self contact needs a method that handles it"),
    ("contact_unknown_method", "contact.method", "must be one of: 'dual_pass_mortar'"),
    ("contact_3d_method", "contact.method", "not in 3-D (run.dimension = 3); allowed: dual_pass_mortar"),
    ("contact_friction_static", "contact.friction", "'quasi_static' is frictionless"),
    ("lagrange_traction_curve_static", "boundaries[1].curve", "ramps every load with t / end_time"),
    ("lagrange_traction_curve_unordered", "boundaries[0].curve", "times must increase strictly"),
    ("contact_return_energy_explicit", "contact.return_energy", "a step of the midpoint scheme's contact update"),
    ("check_free_flight_after_end", "check.params.after", "must be <= run.end_time (1 s)"),
    ("lagrange_static_rigid_wall", "boundaries[0].type", "rigid_wall boundaries are velocity conditions"),
    ("lagrange_load_steps_explicit", "lagrange.load_steps", "load steps are the quasi-static mode's"),
    ("lagrange_static_johnson_cook", "materials.steel.model", "allowed: linear_elastic, neo_hookean"),
    ("lagrange_quarter_disk_3d", "lagrange.bodies[0].mesh.quarter_disk", "quarter_disk meshes are 2D only"),
    ("contact_friction_node_to_surface", "contact.friction", "friction needs a mortar method"),
    ("lagrange_gravity_length", "lagrange.gravity", "dimension mismatch"),
    ("lagrange_ring_inner_beyond_outer", "lagrange.bodies[0].mesh.ring.outer_radius", "must be > inner_radius (0.1)"),
    ("lagrange_ring_3d", "lagrange.bodies[0].mesh.ring", "ring meshes are 2D only"),
    ("lagrange_implicit_no_time_step", "lagrange.time_step", "required with lagrange.integrator = 'midpoint'"),
    ("lagrange_time_step_explicit", "lagrange.time_step", "a key of the implicit integrators (midpoint, newmark)"),
    ("lagrange_implicit_johnson_cook", "materials.steel.model", "allowed: linear_elastic, neo_hookean"),
    ("lagrange_time_step_min_above", "lagrange.time_step_min", "must be <= lagrange.time_step (0.001)"),
    ("lagrange_subcycling_three", "lagrange.subcycling", "one of 1, 2, 4, 8, 16, 32, 64 (1: off)"),
    ("lagrange_subcycling_contact", "lagrange.subcycling", "not with [contact] yet"),
    ("lagrange_subcycling_midpoint", "lagrange.subcycling", "lagrange.integrator = 'midpoint' takes its own"),
]


def test_bad_case_table_covers_every_directory():
    dirs = {p.name for p in BAD.iterdir() if p.is_dir()}
    assert dirs == {name for name, _, _ in BAD_CASES}
    assert len(dirs) >= 14
    for d in dirs:  # each bad case documents its expected key
        head = (BAD / d / "case.toml").read_text().splitlines()[:2]
        key = dict((n, k) for n, k, _ in BAD_CASES)[d]
        assert head[1] == f"# Expected CaseError key: {key}"


@pytest.mark.parametrize("name, key, fragment", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_case(name, key, fragment):
    with pytest.raises(CaseError) as ei:
        load_case(BAD / name)
    err = ei.value
    msg = assert_one_line(err)
    assert err.key == key
    assert msg.startswith(f"{key} = ")
    assert fragment in err.allowed
    assert isinstance(err, ValueError)


def test_bad_case_values_are_reported():
    def err(name):
        with pytest.raises(CaseError) as ei:
            load_case(BAD / name)
        return ei.value
    assert err("negative_density").value == -7850
    assert err("poisson_ratio_half").value == 0.5
    assert err("wrong_type").value == "7850"
    assert err("missing_required_key").value is MISSING
    assert str(err("missing_required_key")) == "run.end_time = <missing>: required key missing"
    assert err("undefined_material").value == "stell"
    assert err("bad_region_expression").value == "__import__('os').system('x')"
    assert err("toml_syntax_error").value == "end_time 1e-5"   # the offending line
    assert err("ranks_zero").value == 0


# --------------------------------------------------------------------------- edits of a valid case
def _edited(tmp_path, old, new, base="box3d"):
    src = VALID / base
    dst = tmp_path / base
    shutil.copytree(src, dst)
    text = (dst / "case.toml").read_text()
    assert old in text, old
    (dst / "case.toml").write_text(text.replace(old, new, 1))
    return dst


@pytest.mark.parametrize("old, new, key, fragment", [
    ("[lagrange]\n", "[lagrange]\nhourglas = 0.1\n", "lagrange.hourglas", "unknown key"),
    ("hourglass = 0.05", "hourglass = 0.2", "lagrange.hourglass", "must be >= 0 and <= 0.125"),
    ("dt_scale = 0.8", "dt_scale = 0", "run.dt_scale", "must be > 0 and <= 4"),
    ("dt_scale = 0.8", "dt_scale = 4.5", "run.dt_scale", "must be > 0 and <= 4"),
    ("dimension = 3", "dimension = 3.5", "run.dimension", "integer"),
    ("dimension = 3", 'dimension = "3"', "run.dimension", "must be an integer"),
    ("[materials.rubber]", '[materials."my rubber"]', 'materials."my rubber"', "invalid name"),
    ("taylor_quinney = 0.9", "taylor_quinney = 1.1", "materials.copper.taylor_quinney",
     "must be >= 0 and <= 1"),
    ("taylor_quinney = 0.9", "taylor_quinney = 0.9\nwater = 1", "materials.copper.water",
     "unknown key"),
    ("poisson_ratio = 0.45", "poisson_ratio = -1.0", "materials.rubber.poisson_ratio", "> -1"),
    ("cells = [2, 2, 8]", "cells = [2, 0, 8]", "lagrange.bodies[0].mesh.box.cells[1]", ">= 1"),
    ("cells = [2, 2, 8]", "cells = [2, 2]", "lagrange.bodies[0].mesh.box.cells",
     "dimension mismatch"),
    ("upper = [0.004, 0.004, 0.02]", "upper = [0.004, 0.0, 0.02]",
     "lagrange.bodies[0].mesh.box.upper", "must be > lower"),
    ('initial_velocity = [0.0, 0.0, "-190.0 * where(z > 0.001, 1, 0.5)"]',
     'initial_velocity = [0.0, 0.0, "open(\'/etc/passwd\')"]',
     "lagrange.bodies[0].initial_velocity[2]", "call of 'open'"),
    ('initial_velocity = [0.0, 0.0, "-190.0 * where(z > 0.001, 1, 0.5)"]',
     'initial_velocity = [0.0, 0.0, "z > 1"]',
     "lagrange.bodies[0].initial_velocity[2]", "numeric"),
    ('initial_velocity = [0.0, 0.0, "-190.0 * where(z > 0.001, 1, 0.5)"]',
     'initial_velocity = [0.0, 0.0, true]',
     "lagrange.bodies[0].initial_velocity[2]", "a number or an expression string"),
    ("initial_temperature = 300", "initial_temperature = 0", "lagrange.bodies[1].initial_temperature",
     "> 0 (K)"),
    ('name = "bar"\nmaterial = "copper"\n', 'name = "bar"\nmaterial = "copper"\n'
     "initial_temperature = 2000\n", "lagrange.bodies[0].initial_temperature",
     "< melt_temperature"),
    ('type = "symmetry"', 'type = "mirror"', "boundaries[0].type", "one of: 'fixed'"),
    ('axis = "x"\n', "", "boundaries[0].axis", "required key missing (type = 'symmetry')"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 0.0]", "boundaries[3].normal", "non-zero"),
    ("point = [0.0, 0.0, -0.02]", "point = [0.0, -0.02]", "boundaries[3].point",
     "dimension mismatch"),
    ("velocity = { y = 0.0 }", "velocity = {}", "boundaries[2].velocity", "at least 1"),
    ("velocity = { y = 0.0 }", "velocity = { w = 0.0 }", "boundaries[2].velocity.w", "unknown key"),
    ('kind = "momentum"\n', "", "check.kind", "required key missing"),
    ('kind = "momentum"', 'kind = "momentun"', "check.kind", "unknown check kind; registered:"),
    ('name = "bar"', 'name = "the bar"', "lagrange.bodies[0].name", "must start with a letter"),
    ("tolerance = 0.01", "tolerance = 0", "check.metrics.total_momentum_z.tolerance", "> 0"),
    ("lagrange = 2", 'lagrange = "2"', "ranks.lagrange", "integer"),
    ("end_time = 2.0e-5", "end_time = 2.0e-5\nend_time = 3.0e-5", "case.toml",
     "TOML syntax error"),
    ('mesh.box = { lower = [0.0, 0.0, -0.01], upper = [0.01, 0.01, -0.005], cells = [2, 2, 1] }',
     "mesh.quarter_cylinder = { radius = 0.01, length = 0.02, radial_cells = 1, axial_cells = 2 }",
     "lagrange.bodies[1].mesh.quarter_cylinder.radial_cells", ">= 2"),
])
def test_edited_case(tmp_path, old, new, key, fragment):
    case_dir = _edited(tmp_path, old, new)
    with pytest.raises(CaseError) as ei:
        load_case(case_dir)
    assert_one_line(ei.value)
    assert ei.value.key == key
    assert fragment in ei.value.allowed


def test_quarter_cylinder_in_3d_is_valid(tmp_path):
    case_dir = _edited(
        tmp_path,
        'mesh.box = { lower = [0.0, 0.0, -0.01], upper = [0.01, 0.01, -0.005], cells = [2, 2, 1] }',
        "mesh.quarter_cylinder = { radius = 0.01, length = 0.02, radial_cells = 3, axial_cells = 2 }")
    mesh = load_case(case_dir)["lagrange"]["bodies"][1]["mesh"]
    assert mesh == {"quarter_cylinder": {"radius": 0.01, "length": 0.02, "radial_cells": 3,
                                         "axial_cells": 2}}


def test_not_utf8(tmp_path):
    (tmp_path / "case.toml").write_bytes(b"[run]\ndimension = 3\n\xff\xfe\n")
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "case.toml" and "UTF-8" in ei.value.allowed


# --------------------------------------------------------------------------- ranks
def test_ranks_for_defaults_file_and_overrides():
    case3 = load_case(VALID / "box3d")
    case2 = load_case(VALID / "box2d")
    assert ranks_for(case2, {}) == {"lagrange": 1}
    assert ranks_for(case2, None) == {"lagrange": 1}
    assert ranks_for(case3, {}) == {"lagrange": 2}          # from [ranks]
    assert ranks_for(case3, {"lagrange": 4}) == {"lagrange": 4}
    assert ranks_for(case3, {"lagrange": "3"}) == {"lagrange": 3}  # CLI strings
    assert ranks_for(case3, ["lagrange=5"]) == {"lagrange": 5}


@pytest.mark.parametrize("overrides, key, fragment", [
    ({"dem": 2}, "--ranks dem", "unknown role; allowed: lagrange"),
    ({"sph": 2}, "--ranks sph", "solver 'sph' is not used by this case; allowed: lagrange"),
    ({"lagrange": 0}, "--ranks lagrange", ">= 1"),
    ({"lagrange": -3}, "--ranks lagrange", ">= 1"),
    ({"lagrange": "two"}, "--ranks lagrange", "integer"),
    ({"lagrange": 1.5}, "--ranks lagrange", "integer"),
    ({"lagrange": True}, "--ranks lagrange", "integer"),
    (["lagrange"], "--ranks", "ROLE=N"),
    (["fluid=2"], "--ranks fluid", "unknown role"),
])
def test_ranks_for_bad_overrides(overrides, key, fragment):
    case = load_case(VALID / "box2d")
    with pytest.raises(CaseError) as ei:
        ranks_for(case, overrides)
    assert_one_line(ei.value)
    assert ei.value.key == key
    assert fragment in ei.value.allowed


# --------------------------------------------------------------------------- CaseError & schema
def test_case_error_format_and_pickle():
    e = CaseError("materials.steel.density", -1.0, "must be > 0 (kg/m^3)")
    assert str(e) == "materials.steel.density = -1.0: must be > 0 (kg/m^3)"
    assert (e.key, e.value, e.allowed) == ("materials.steel.density", -1.0, "must be > 0 (kg/m^3)")
    assert isinstance(e, ValueError)
    e2 = pickle.loads(pickle.dumps(e))
    assert type(e2) is CaseError and str(e2) == str(e)
    # multi-line "allowed" and very long values still give one line
    e3 = CaseError("a.b", "x" * 1000, "first line\nsecond line")
    assert str(e3) == f"{e3.key} = {e3.value!r}: {e3.allowed}"
    assert "\n" not in str(e3) and len(str(e3)) < 300
    assert e3.allowed == "first line second line"


def test_format_key():
    assert format_key(["lagrange", "bodies", 0, "mesh", "file"]) == "lagrange.bodies[0].mesh.file"
    assert format_key(["materials", "my steel", "density"]) == 'materials."my steel".density'
    assert format_key(["boundaries", 2]) == "boundaries[2]"


def _walk(schema, path="#"):
    if isinstance(schema, dict):
        yield path, schema
        for k, v in schema.items():
            yield from _walk(v, f"{path}/{k}")
    elif isinstance(schema, list):
        for i, v in enumerate(schema):
            yield from _walk(v, f"{path}/{i}")


def test_schema_is_draft_2020_12_and_closed():
    import jsonschema
    jsonschema.Draft202012Validator.check_schema(CASE_SCHEMA)
    assert CASE_SCHEMA["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    tables = 0
    for path, node in _walk(CASE_SCHEMA):
        if "properties" in node and isinstance(node["properties"], dict) \
                and "/if" not in path:  # `if` conditions only test a discriminator
            tables += 1
            assert node.get("additionalProperties") is False, path
    assert tables >= 10


# --------------------------------------------------------------------------- issue 7: hostile input
@pytest.mark.parametrize("old, new, key", [
    ("end_time = 2.0e-5", "end_time = nan", "run.end_time"),
    ("end_time = 2.0e-5", "end_time = inf", "run.end_time"),
    ("dt_scale = 0.8", "dt_scale = nan", "run.dt_scale"),                    # nan <= 1 is false too
    ("hourglass = 0.05", "hourglass = -nan", "lagrange.hourglass"),
    ("youngs_modulus = 5e6", "youngs_modulus = inf", "materials.rubber.youngs_modulus"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, nan, 1.0]", "boundaries[3].normal[1]"),
    ("velocity = { y = 0.0 }", "velocity = { y = -inf }", "boundaries[2].velocity.y"),
    ("tolerance = 0.01", "tolerance = inf", "check.metrics.total_momentum_z.tolerance"),
    ("reference = -1.0", "reference = nan", "check.metrics.total_momentum_z.reference"),
])
def test_non_finite_numbers_are_refused_anywhere(tmp_path, old, new, key):
    with pytest.raises(CaseError) as ei:
        load_case(_edited(tmp_path, old, new))
    assert ei.value.key == key and ei.value.allowed == "must be a finite number (not nan or inf)"
    assert_one_line(ei.value)


def test_a_key_may_allow_non_finite_numbers(tmp_path, monkeypatch):
    import orchestrator.case as C

    d = _edited(tmp_path, "tolerance = 0.01", "tolerance = 0.01\nreference_max = inf")
    with pytest.raises(CaseError):
        load_case(d)  # unknown key first (the schema runs before the finite rule)
    d = _edited(tmp_path / "b", "reference = -1.0", "reference = inf")
    monkeypatch.setattr(C, "NON_FINITE_KEYS", ("check.metrics.*.reference",))
    assert load_case(d)["check"]["metrics"]["total_momentum_z"]["reference"] == float("inf")
    monkeypatch.setattr(C, "NON_FINITE_KEYS", ("check.*.reference",))
    with pytest.raises(CaseError):  # '*' is one table key, not a path
        load_case(d)
    d = _edited(tmp_path / "c", "normal = [0.0, 0.0, 1.0]", "normal = [0.0, inf, 1.0]")
    monkeypatch.setattr(C, "NON_FINITE_KEYS", ("boundaries[].normal",))
    with pytest.raises(CaseError):  # '[]' is an index only where it is written
        load_case(d)


@pytest.mark.parametrize("old, new, key, fragment", [
    ("end_time = 2.0e-5", "end_time = 2.0e-5\noutput_interval = 1e-300", "run.output_interval",
     "more than 1,000,000"),
    ("checkpoint_interval = 1.0e-5", "checkpoint_interval = 1e-14", "run.checkpoint_interval",
     "2e+09 checkpoints"),
    # (an extent that overflows, upper - lower = 2e308, once refused by its difference: now each
    # coordinate by the physical range of a length, schema/parts.py UNIT_LIMITS)
    ("lower = [0.0, 0.0, 0.0], upper = [0.004, 0.004, 0.02]", "lower = [-1e308, 0.0, 0.0], upper = [1e308, 0.004, 0.02]",
     "lagrange.bodies[0].mesh.box.lower[0]", "<= 1e+06 (m) (the physical range)"),
    ("lower = [0.0, 0.0, 0.0], upper = [0.004, 0.004, 0.02]", "lower = [0.0, 0.0, 0.0], upper = [1e-110, 1e-110, 1e-110]",
     "lagrange.bodies[0].mesh.box.cells", "underflows"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 1e200]", "boundaries[3].normal", "finite float"),
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 1e-200]", "boundaries[3].normal", "non-zero"),
    ("density = 1100", "density = 1e-305", "materials.rubber.youngs_modulus", "wave speed"),
    ('initial_velocity = [0.0, 0.0, "-190.0 * where(z > 0.001, 1, 0.5)"]',
     'initial_velocity = [0.0, 0.0, "9**9**9**9"]', "lagrange.bodies[0].initial_velocity[2]", "'9**9**9' = inf"),
])
def test_finite_but_absurd_numbers(tmp_path, old, new, key, fragment):
    with pytest.raises(CaseError) as ei:
        load_case(_edited(tmp_path, old, new))
    assert ei.value.key == key and fragment in ei.value.allowed, str(ei.value)
    assert_one_line(ei.value)


def test_case_file_that_is_not_a_regular_file_or_too_big(tmp_path):
    import os

    from orchestrator.case import MAX_CASE_BYTES

    fifo = tmp_path / "fifo"
    fifo.mkdir()
    os.mkfifo(fifo / "case.toml")                 # no writer: a blocking open would hang
    with pytest.raises(CaseError, match="is a FIFO"):
        load_case(fifo)
    with pytest.raises(CaseError, match="is a FIFO"):
        load_case(fifo / "case.toml")
    dev = tmp_path / "dev"
    dev.mkdir()
    (dev / "case.toml").symlink_to("/dev/zero")
    with pytest.raises(CaseError, match="is a character device"):
        load_case(dev)
    big = tmp_path / "big"
    big.mkdir()
    text = (VALID / "box2d" / "case.toml").read_text()
    (big / "case.toml").write_text(text + "#" * (MAX_CASE_BYTES - len(text) - 1) + "\n")
    assert load_case(big)["name"] == "big"        # exactly the limit: read
    with open(big / "case.toml", "a") as f:
        f.write("#")
    with pytest.raises(CaseError) as ei:
        load_case(big)
    assert "must be a regular TOML file of at most 256 KiB" in ei.value.allowed


def test_nesting_beyond_the_recursion_limit(tmp_path):
    (tmp_path / "case.toml").write_text("[run]\ndimension = 2\nx = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "case.toml" and "nested too deeply" in ei.value.allowed


def test_first_schema_error_in_file_order(tmp_path):
    text = (VALID / "box2d" / "case.toml").read_text()
    (tmp_path / "case.toml").write_text(text.replace("[run]\n", "[run]\nbogus1 = 1\nbogus2 = 2\n"))
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "run.bogus1"


def _file_case(tmp_path, mesh_path, name="case"):
    d = tmp_path / name
    d.mkdir()
    (d / "case.toml").write_text((VALID / "file3d" / "case.toml").read_text().replace(
        'file = "column.msh"', f"file = {str(mesh_path)!r}"))
    return d


def test_mesh_paths_stay_inside_the_case_directory(tmp_path, monkeypatch):
    from orchestrator.case import ALLOW_PATH_ENV

    monkeypatch.delenv(ALLOW_PATH_ENV, raising=False)
    library = tmp_path / "library"
    library.mkdir()
    shutil.copy(VALID / "file3d" / "column.msh", library / "column.msh")
    for name, path in [("up", "../library/column.msh"), ("abs", library / "column.msh"),
                       ("etc", "../../../../../../../../etc/passwd")]:
        d = _file_case(tmp_path, path, name)
        with pytest.raises(CaseError) as ei:
            load_case(d)
        assert ei.value.key == "lagrange.bodies[0].mesh.file" and "outside the case directory" in ei.value.allowed
    link = _file_case(tmp_path, "column.msh", "link")
    (link / "column.msh").symlink_to(library / "column.msh")     # a symlink is followed first
    with pytest.raises(CaseError, match="outside the case directory"):
        load_case(link)
    inside = _file_case(tmp_path, "meshes/../sub/column.msh", "inside")   # '..' that stays inside
    (inside / "sub").mkdir()
    shutil.copy(library / "column.msh", inside / "sub" / "column.msh")
    assert load_case(inside)["lagrange"]["bodies"][0]["size"] == {"elements": 2, "nodes": 12}
    # an explicit allowed root: $IMMERSE_ALLOW_PATH (inherited by the ranks)
    monkeypatch.setenv(ALLOW_PATH_ENV, f"{tmp_path / 'nowhere'}{os.pathsep}{library}")
    for name in ("up", "abs", "link"):
        assert load_case(tmp_path / name)["lagrange"]["bodies"][0]["mesh"]["file"] == (library / "column.msh").resolve()
    with pytest.raises(CaseError, match=f"or {tmp_path / 'nowhere'}, {library}"):
        load_case(tmp_path / "etc")


def test_mesh_files_that_are_not_regular_or_too_big(tmp_path, monkeypatch):
    import orchestrator.resources as R

    d = _file_case(tmp_path, "column.msh")
    os.mkfifo(d / "column.msh")
    with pytest.raises(CaseError, match="is a FIFO"):
        load_case(d)
    (d / "column.msh").unlink()
    shutil.copy(VALID / "file3d" / "column.msh", d / "column.msh")    # 990 bytes
    assert load_case(d)["lagrange"]["bodies"][0]["size"] == {"elements": 2, "nodes": 12}
    monkeypatch.setattr(R, "machine_memory", lambda: 7 * 900)          # reading needs ~7x the size
    with pytest.raises(CaseError) as ei:
        load_case(d)
    assert "reading it takes about 7 times that, this machine has 6.15 KiB" in ei.value.allowed


def test_body_sizes(tmp_path):
    case = load_case(VALID / "box3d")
    assert [b["size"] for b in case["lagrange"]["bodies"]] == [{"elements": 32, "nodes": 3 * 3 * 9},
                                                               {"elements": 4, "nodes": 3 * 3 * 2}]



def _mutations(data, rng, n):
    """``n`` seeded variants of a TOML document: a value replaced by another type or a number out of
    range, a key dropped or an unknown one added, an array grown or shortened."""
    import copy

    values = [0, 1, -1, 2, 0.5, -0.5, 1.0, 1e300, -1e-300, True, False, "", "x", "wall", "x > 0.5",
              "ideal_gas", [], {}, [1.0, 2.0], [1, 2, 3], {"a": 1}, float("inf")]
    out = []
    for _ in range(n):
        d = copy.deepcopy(data)
        node, path = d, []
        for _ in range(rng.randint(1, 6)):
            if isinstance(node, dict) and node:
                k = rng.choice(list(node))
            elif isinstance(node, list) and node:
                k = rng.randrange(len(node))
            else:
                break
            path.append((node, k))
            node = node[k]
        if path:
            parent, k = path[-1]
            op, v = rng.random(), parent[k]
            if op < 0.5:
                parent[k] = copy.deepcopy(rng.choice(values))
            elif op < 0.65 and isinstance(parent, dict):
                del parent[k]
            elif op < 0.8 and isinstance(parent, dict):
                parent[rng.choice(["extra", f"{k}_", "Bad Name"])] = rng.choice(values)
            elif op < 0.9 and isinstance(parent, list):
                parent.append(copy.deepcopy(v))
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                parent[k] = rng.choice([-v, v * 1e10, v + 0.5, -v - 1, 0, v * 1e-10])
            else:
                parent[k] = v[:-1] if isinstance(v, list) and v else rng.choice(values)
        out.append(d)
    return out


def test_the_schema_check_accepts_exactly_what_jsonschema_accepts():
    """A case is accepted without importing jsonschema (orchestrator.case._conforms: 0.1 s of every
    check and run); jsonschema names the error of one that is not. The two agree on every case,
    campaign and [check] params document of the repository and on seeded mutations of each (a
    disagreement would let a bad case through, or refuse a good one without a message)."""
    import random
    import tomllib

    from jsonschema import Draft202012Validator

    from orchestrator import case as case_mod
    from orchestrator.campaign.spec import SCHEMA as CAMPAIGN_SCHEMA
    from orchestrator.checks import PARAMS

    root = Path(__file__).resolve().parents[2]
    rng = random.Random(20261203)
    validators, compared, accepted = {}, 0, 0
    for toml in sorted([*root.glob("cases/**/*.toml"), *root.glob("tests/**/*.toml")]):
        try:
            data = tomllib.loads(toml.read_text(encoding="utf-8-sig"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError):
            continue
        docs = [(CASE_SCHEMA, data)]
        if "campaign" in toml.name or "axes" in data or "series" in data:
            docs.append((CAMPAIGN_SCHEMA, data))
        check = data.get("check")
        if isinstance(check, dict) and check.get("kind") in PARAMS and isinstance(check.get("params", {}), dict):
            docs.append((PARAMS[check["kind"]], check.get("params", {})))
        for schema, doc in docs:
            v = validators.setdefault(id(schema), Draft202012Validator(schema))
            for variant in [doc, *_mutations(doc, rng, 12)]:
                ok = case_mod._conforms(schema, variant)
                assert ok == v.is_valid(variant), (toml, variant)
                compared += 1
                accepted += ok
    assert compared > 1000 and 0.1 < accepted / compared < 0.9, (compared, accepted)


def test_a_valid_case_is_checked_without_importing_jsonschema():
    import subprocess
    import sys

    probe = ("import sys; from orchestrator.case import load_case; "
             f"load_case({str(VALID / 'box3d')!r}); print('jsonschema' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[2], timeout=120)
    assert r.returncode == 0 and r.stdout.split() == ["False"], r.stdout + r.stderr

def test_every_check_kind_has_a_closed_params_schema():
    """[check] params are each kind's own table (orchestrator.checks.PARAMS): valid Draft 2020-12,
    closed (unknown keys refused), and every shipped case's params pass it."""
    import tomllib

    import jsonschema

    from orchestrator.checks import CHECKS, PARAMS

    assert set(PARAMS) == set(CHECKS)
    for kind, schema in PARAMS.items():
        jsonschema.Draft202012Validator.check_schema(schema)
        assert schema["additionalProperties"] is False, kind
    root = Path(__file__).resolve().parents[2] / "cases"
    seen = set()
    for toml in sorted(root.glob("*/case.toml")):
        check = tomllib.loads(toml.read_text()).get("check")
        if check:
            jsonschema.validate(check.get("params", {}), PARAMS[check["kind"]])
            seen.add(check["kind"])
    assert len(seen) >= 10   # the shipped cases use most kinds (measured: 13)


def test_a_mesh_file_whose_compressed_data_inflate_past_their_counts_is_one_line(tmp_path):
    """A VTU of one hexahedron whose points' zlib blocks inflate to 8 GiB (tests/solvers/lagrange's
    bomb): refused on its key, one line, without inflating it."""
    from tests.solvers.lagrange.test_mesh import _vtu_bomb

    d = _file_case(tmp_path, "bomb.vtu")
    _vtu_bomb(d / "bomb.vtu")
    with pytest.raises(CaseError) as ei:
        load_case(d)
    assert ei.value.key == "lagrange.bodies[0].mesh.file" and "inflate to more than" in str(ei.value)
    assert "\n" not in str(ei.value)


def test_a_case_file_with_a_byte_order_mark_reads_as_without(tmp_path):
    """Windows editors may write a UTF-8 byte-order mark first: the case reads as without it (tomllib
    alone refuses it: 'Invalid statement' at line 1, column 1); Windows line ends read too."""
    text = (VALID / "box3d" / "case.toml").read_text()
    plain, bom, crlf = (tmp_path / n for n in ("plain", "bom", "crlf"))
    for d, data in ((plain, text.encode()), (bom, b"\xef\xbb\xbf" + text.encode()),
                    (crlf, b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode())):
        d.mkdir()
        (d / "case.toml").write_bytes(data)
    ref = load_case(plain)
    for d in (bom, crlf):
        got = load_case(d)
        skip = ("case_dir", "name", "case_sha256")   # (the folder, and the hash of the bytes as written)
        assert {k: v for k, v in got.items() if k not in skip} == {k: v for k, v in ref.items() if k not in skip}
