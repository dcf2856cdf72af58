"""The [sph] table (orchestrator/schema/sph.py): each bad value is one CaseError naming its key and
what is allowed (through the command line, with exit 2 and nothing launched: test_bad_inputs.py)."""
from __future__ import annotations

import pytest

from orchestrator.case import load_case
from orchestrator.schema.rules import CaseError
from tests.orchestrator.test_bad_inputs import SPH, edit

SOLID = edit(SPH, 'materials.water = { model = "tait", density = 1000.0, sound_speed = 20.0, viscosity = 0.1 }',
             'materials.water = { model = "tlsph", density = 1000.0, youngs_modulus = 1e9, poisson_ratio = 0.3 }')
GAS = edit(SPH, 'materials.water = { model = "tait", density = 1000.0, sound_speed = 20.0, viscosity = 0.1 }',
           'materials.water = { model = "ideal_gas", viscosity = 0.5 }')
REGION = "region = { box = { lower = [0.0, 0.0], upper = [0.1, 0.1] } }"  # the water body's, in SPH
FROM_FILE = edit(SPH, REGION, 'data_file = "water.data"')  # the same body from a LAMMPS data file

BAD = [
    # (name, text, key, fragment of what is allowed)
    ("cfl_above_one", edit(SPH, "smoothing_length = 0.03", "smoothing_length = 0.03\ncfl = 1.5"), "sph.cfl", "<= 1"),
    ("substeps_zero", edit(SPH, "smoothing_length = 0.03", "smoothing_length = 0.03\nsubsteps = 0"), "sph.substeps", ">= 1"),
    ("face_unknown", edit(SPH, 'x_lower = "wall"', 'x_lower = "sticky"'), "sph.boundaries.x_lower", "'open', 'periodic', 'wall'"),
    ("periodic_one_side", edit(SPH, 'x_lower = "wall"', 'x_lower = "periodic"'), "sph.boundaries.x_lower",
     "periodic must be set on both"),
    ("z_face_in_2d", edit(SPH, 'y_upper = "wall" }', 'y_upper = "wall", z_lower = "wall" }'), "sph.boundaries.z_lower",
     "dimension mismatch"),
    ("gravity_length", edit(SPH, "smoothing_length = 0.03", "smoothing_length = 0.03\ngravity = [0.0, -9.81, 0.0]"),
     "sph.gravity", "dimension mismatch"),
    ("hydrostatic_without_gravity", edit(SPH, "density = 1000.0 } ]", "density = 1000.0, hydrostatic = true } ]"),
     "sph.bodies[0].hydrostatic", "non-zero sph.gravity"),
    ("undefined_material", edit(SPH, '{ material = "water"', '{ material = "oil"'), "sph.bodies[0].material",
     "undefined material"),
    ("gas_without_state", GAS.replace("density = 1000.0 } ]", "density = 1.0 } ]"), "sph.bodies[0]",
     "exactly one of pressure, specific_internal_energy"),
    ("gas_key_of_water", edit(GAS, 'viscosity = 0.5 }', 'viscosity = 0.5, sound_speed = 3.0 }'),
     "sph.materials.water.sound_speed", "unknown key for model = 'ideal_gas'"),
    ("tension_cutoff_positive", edit(SPH, 'viscosity = 0.1 }', 'viscosity = 0.1, pressure_cutoff = 1.0 }'),
     "sph.materials.water.pressure_cutoff", "<= 0"),
    ("tension_cutoff_beyond_tait", edit(SPH, 'viscosity = 0.1 }', 'viscosity = 0.1, pressure_cutoff = -6.0e4 }'),
     "sph.materials.water.pressure_cutoff", "must be > -B = -c0^2 rho0 / 7 = -57142.9 Pa"),
    ("two_models", edit(SPH, 'viscosity = 0.1 }', 'viscosity = 0.1 }\nmaterials.air = { model = "ideal_gas", viscosity = 0.5 }'),
     "sph.materials", "one material model per case"),
    ("cylinder_in_2d", edit(SPH, REGION,
                            'region = { cylinder = { base = [0.1, 0.1], axis = "z", radius = 0.05, length = 0.1 } }'),
     "sph.bodies[0].region.cylinder", "cylinders are 3-D"),
    ("region_two_shapes", edit(SPH, REGION,
                               "region = { box = { lower = [0.0, 0.0], upper = [0.1, 0.1] }, sphere = { centre = [0.1, 0.1], radius = 0.05 } }"),
     "sph.bodies[0].region", "exactly one of box"),
    ("where_not_boolean", edit(SPH, "upper = [0.1, 0.1] } }", 'upper = [0.1, 0.1] }, where = "x + y" }'),
     "sph.bodies[0].region.where", "boolean"),
    ("region_without_particles", edit(SPH, REGION,
                                      'region = { box = { lower = [0.0, 0.0], upper = [0.1, 0.1] }, where = "x > 1" }'),
     "sph.bodies[0].region", "holds no particle"),
    ("domain_inverted", edit(SPH, "upper = [0.2, 0.2] }", "upper = [-0.2, 0.2] }"), "sph.domain.upper", "must be > lower"),
    ("solid_strength_unknown", edit(SOLID, "poisson_ratio = 0.3 }", 'poisson_ratio = 0.3, strength = "rigid" }'),
     "sph.materials.water.strength", "linear_plastic = { yield_stress, hardening }"),
    ("solid_jc_incomplete", edit(SOLID, "poisson_ratio = 0.3 }", "poisson_ratio = 0.3, strength = { johnson_cook = { A = 1e8 } } }"),
     "sph.materials.water.strength", "johnson_cook = { A, B, n, C"),
    ("solid_eos_unknown", edit(SOLID, "poisson_ratio = 0.3 }", 'poisson_ratio = 0.3, eos = "tait" }'),
     "sph.materials.water.eos", "shock = { c0, s, gamma }"),
    ("solid_poisson_half", edit(SOLID, "poisson_ratio = 0.3", "poisson_ratio = 0.5"),
     "sph.materials.water.poisson_ratio", "< 0.5"),
    ("solid_without_modulus", edit(SOLID, "youngs_modulus = 1e9, ", ""),
     "sph.materials.water.youngs_modulus", "required key missing"),
    ("solid_key_of_water", edit(SOLID, "poisson_ratio = 0.3 }", "poisson_ratio = 0.3, sound_speed = 3.0 }"),
     "sph.materials.water.sound_speed", "unknown key for model = 'tlsph'"),
    ("solid_with_pressure", edit(SOLID, "density = 1000.0 } ]", "density = 1000.0, pressure = 1.0 } ]"),
     "sph.bodies[0].pressure", "starts unstressed"),
    ("clamp_on_fluid", edit(SPH, "density = 1000.0 } ]", "density = 1000.0, clamp = { box = { lower = [0.0, 0.0], upper = [0.01, 0.1] } } } ]"),
     "sph.bodies[0].clamp", "only tlsph"),
    ("clamp_length", edit(SOLID, "density = 1000.0 } ]", "density = 1000.0, clamp = { box = { lower = [0.0, 0.0, 0.0], upper = [0.01, 0.1, 0.1] } } } ]"),
     "sph.bodies[0].clamp.box.lower", "dimension mismatch"),
    ("solid_periodic", edit(SOLID, 'x_lower = "wall", x_upper = "wall"', 'x_lower = "periodic", x_upper = "periodic"'),
     "sph.boundaries.x_lower", "does not wrap the reference distance"),
    ("solid_defgrad", edit(SOLID, "poisson_ratio = 0.3 }", 'poisson_ratio = 0.3, strength = "linear_defgrad" }'),
     "sph.materials.water.strength", "must be \"linear\""),
    ("hold_z_in_2d", edit(SPH, "density = 1000.0 } ]", 'density = 1000.0, hold = ["z"] } ]'),
     "sph.bodies[0].hold", "axes of the 2-D run"),
    ("hold_unknown_axis", edit(SPH, "density = 1000.0 } ]", 'density = 1000.0, hold = ["w"] } ]'),
     "sph.bodies[0].hold[0]", "'x', 'y', 'z'"),
    ("data_file_missing", FROM_FILE,
     "sph.bodies[0].data_file", "file not found"),
    ("data_file_outside", edit(SPH, REGION, 'data_file = "../water.data"'),
     "sph.bodies[0].data_file", "outside the case directory"),
    ("data_file_and_region", edit(SPH, REGION,
                                  REGION + ', data_file = "water.data"'),
     "sph.bodies[0]", "exactly one of region"),
    ("solid_and_fluid", edit(SOLID, "poisson_ratio = 0.3 }", 'poisson_ratio = 0.3 }\nmaterials.air = { model = "ideal_gas", viscosity = 0.5 }'),
     "sph.materials", "all tlsph"),
    ("coupled_sph_outside_grid", SPH.replace("[sph]", '[ale]\ngrid = { lower = [0.0, 0.0], upper = [0.05, 0.2], cells = [5, 20] }\n'
                                              'materials.air = { eos = "ideal_gas", gamma = 1.4 }\n'
                                              'regions = [ { material = "air", density = 1.2, pressure = 1000.0 } ]\n\n[sph]')
     + '\n[coupling]\nmethod = "multiplier"\n', "sph.bodies[0].region", "inside the background grid"),
]


@pytest.mark.parametrize("name, text, key, fragment", BAD, ids=[b[0] for b in BAD])
def test_bad_sph_table(tmp_path, name, text, key, fragment):
    (tmp_path / "case.toml").write_text(text)
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == key, str(ei.value)
    assert fragment in ei.value.allowed, str(ei.value)
    assert "\n" not in str(ei.value)


def test_the_base_is_valid(tmp_path):
    (tmp_path / "case.toml").write_text(SPH)
    case = load_case(tmp_path)
    assert case["sph"]["particles"] == 100 and case["ranks"] == {"sph": 1}


def test_a_solid_with_its_defaults(tmp_path):
    """A tlsph material keeps what the case gives; the adapter fills MACHDYN's defaults
    (adapters/lammps_tlsph.py) into one pair_coeff line per material."""
    from adapters.lammps_tlsph import pair_commands

    (tmp_path / "case.toml").write_text(edit(SOLID, "poisson_ratio = 0.3 }",
                                             "poisson_ratio = 0.3, eos = { shock = { c0 = 5000.0, s = 1.4, gamma = 2.0 } } }"))
    case = load_case(tmp_path)
    mat = case["sph"]["materials"]["water"]
    assert mat["eos"] == {"shock": {"c0": 5000.0, "s": 1.4, "gamma": 2.0}} and "strength" not in mat
    assert pair_commands(case["sph"]) == [
        "pair_style smd/tlsph",
        "pair_coeff 1 1 *COMMON 1000.0 1000000000.0 0.3 1.0 0.0 10.0 1.0 *STRENGTH_LINEAR *EOS_SHOCK 5000.0 1.4 2.0 *END"]


@pytest.mark.parametrize("content, fragment", [
    ("no atoms here\n", "has no Atoms section"),
    ("2 atoms\n\nAtoms # atomic\n\n1 1 0.05 0.05 0.0\n2 1 0.5 0.5 0.0\n", "must lie inside sph.domain"),
    ("1 atoms\n\nAtoms # atomic\n\n1 1 0.05 0.05\n", "with 4 columns"),
    ("Atoms # atomic\n\n1 1 0.05 0.05 0.0\n", "no 'N atoms' line in its header"),
    # the header's count against sph.max_particles, before the section (here not numbers) is parsed
    ("3000000000 atoms\n\nAtoms # atomic\n\nx y z\n",
     "declares 3000000000 atoms in its header; allowed: at most 20000000 atoms (sph.max_particles"),
    (b"1 atoms\n\nAtoms\n\n1 1 0.05 \xff 0.0\n", "not UTF-8 text"),
])
def test_a_bad_data_file_is_one_line_naming_the_key(tmp_path, content, fragment):
    """A body's data file is read while the case is checked: what is wrong with it, on its key."""
    (tmp_path / "case.toml").write_text(FROM_FILE)
    (tmp_path / "water.data").write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "sph.bodies[0].data_file" and fragment in str(ei.value), str(ei.value)
    assert "\n" not in str(ei.value)


def test_a_data_file_body_counts_its_particles(tmp_path):
    (tmp_path / "case.toml").write_text(FROM_FILE)
    (tmp_path / "water.data").write_text("2 atoms\n\nAtoms # atomic\n\n1 1 0.05 0.05 0.0\n2 1 0.06 0.05 0.0\n")
    case = load_case(tmp_path)
    assert case["sph"]["particles"] == 2
    box = case["sph"]["bodies"][0]["region"]["box"]  # half a spacing (0.01) around the particles
    assert box["lower"] == pytest.approx([0.045, 0.045], abs=1e-15) and box["upper"] == pytest.approx([0.065, 0.055], abs=1e-15)


QUARTER = 'region = { sphere = { centre = [0.0, 0.0], radius = 0.1 }, where = "x > 0 and y > 0" }'


def test_a_where_may_cut_a_region_at_the_domain_faces(tmp_path):
    """A quarter of a disc centred on the domain's corner (its two wall faces the symmetry planes of
    a quarter model): what must lie inside the domain is the particles' cells (x +- spacing / 2),
    not the region's box; the same disc without the where pokes out and is refused on its key."""
    (tmp_path / "case.toml").write_text(edit(SPH, REGION, QUARTER))
    case = load_case(tmp_path)
    # the lattice of 0.01 anchored at (-0.1, -0.1): cell centres at (i + 1/2) 0.01, i >= 0, in the disc
    c = (__import__("numpy").arange(10) + 0.5) * 0.01
    expected = int(((c[:, None] ** 2 + c[None, :] ** 2) <= 0.01).sum())
    assert case["sph"]["particles"] == expected == 79
    (tmp_path / "case.toml").write_text(edit(SPH, REGION, QUARTER.replace(', where = "x > 0 and y > 0"', "")))
    with pytest.raises(CaseError) as ei:
        load_case(tmp_path)
    assert ei.value.key == "sph.bodies[0].region" and "must lie inside sph.domain" in str(ei.value)


def _big(tmp_path, spacing: str, where: str = "", extra: str = ""):
    text = edit(edit(SPH, "spacing = 0.01", f"spacing = {spacing}"), "smoothing_length = 0.03",
                f"smoothing_length = {float(spacing) * 3}{extra}")
    if where:
        text = edit(text, "upper = [0.1, 0.1] } }", f'upper = [0.1, 0.1] }}, where = "{where}" }}')
    d = tmp_path / "big"
    d.mkdir(exist_ok=True)
    (d / "case.toml").write_text(text)
    return d


def test_a_lattice_too_large_to_build_is_counted_from_a_sample(tmp_path):
    """Issue 41: a lattice of 79M points was built (57 s) before its refusal.  Beyond EXACT_LATTICE
    a sample counts the body: 5e7 lattice points over max_particles refused, and the same box cut
    by a where to a quarter disc of radius 0.01 m (pi/4 1e-4 m^2 of 1e-2: 3.9e5 particles)
    estimated within its sampling error, each check in under 5 s."""
    import time

    t0 = time.perf_counter()
    with pytest.raises(CaseError) as e:
        load_case(_big(tmp_path, "1.4142e-05"))
    assert e.value.key == "sph.bodies[0].region" and "more than sph.max_particles = 20000000" in e.value.allowed
    assert "from a sample of 200000" in e.value.allowed
    assert time.perf_counter() - t0 < 5.0
    t0 = time.perf_counter()
    case = load_case(_big(tmp_path, "1.4142e-05", where="x*x + y*y < 1e-4"))
    exact = 3.14159265 / 4 * (0.01 / 1.4142e-05) ** 2
    # a binomial sample: 1571 of 200,000 points inside, one standard deviation 2.5 % (measured 2.6 %)
    assert case["sph"]["particles"] == pytest.approx(exact, rel=0.1)
    assert time.perf_counter() - t0 < 5.0


def test_a_max_particles_of_1e15_meets_the_machine(tmp_path, run_immerse):
    """max_particles lifted to 1e15 (it allocated 50.7 GiB for a 1e10-particle body: a MemoryError
    traceback): refused at the key (LAMMPS's ids are 32-bit); at its most, a 1e9-particle body is
    counted from a sample and refused by the memory it needs, one line, in under 5 s."""
    import time

    with pytest.raises(CaseError) as e:
        load_case(_big(tmp_path, "1e-06", extra="\nmax_particles = 1000000000000000"))
    assert e.value.key == "sph.max_particles" and "<= 2.14748e+09" in e.value.allowed
    t0 = time.perf_counter()
    r = run_immerse("check", _big(tmp_path, "3.1623e-06", extra="\nmax_particles = 2147483647"), timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "needs about" in r.stderr and "of memory" in r.stderr, r.stderr
    assert time.perf_counter() - t0 < 5.0
