"""orchestrator/keys.py (`immerse keys`): every key of the case schema, with its meaning, unit,
range and default, read from the schema; the README's reference is its Markdown (test_readme)."""
from __future__ import annotations

from orchestrator.keys import keys, markdown, select, text
from orchestrator.schema.case import case_schema
from tests.conftest import immerse


def _property_names(node, found: set) -> set:
    """Every key name the schema defines anywhere (an independent walk: any dict's "properties")."""
    if isinstance(node, dict):
        for k, v in node.get("properties", {}).items():
            if v is not True:
                found.add(k)
        for v in node.values():
            _property_names(v, found)
    elif isinstance(node, list):
        for v in node:
            _property_names(v, found)
    return found


def test_every_key_of_the_schema_is_listed_with_its_meaning():
    ks = keys()
    names = {k.path.rsplit(".", 1)[-1].removesuffix("[]") for k in ks}
    faces = {f"{a}_{s}" for a in "xyz" for s in ("lower", "upper")}   # (listed once as <face>)
    assert _property_names(case_schema(), set()) - faces <= names
    missing = [k.path for k in ks if not k.meaning]
    assert not missing, missing
    assert len({k.path for k in ks}) == len(ks)


def test_types_units_ranges_defaults_and_variants():
    by = {k.path: k for k in keys()}
    dt = by["run.dt_scale"]
    assert (dt.kind, dt.allowed, dt.default, dt.has_default) == ("number", "> 0, <= 4", 0.9, True)
    p_inf = by["ale.materials.<name>.p_inf"]
    assert p_inf.unit == "Pa" and p_inf.when == ["eos = 'stiffened_gas'"] and "stiffened" in p_inf.meaning.lower()
    assert by["ale.materials.<name>.eos"].when == []           # (every variant has it)
    assert by["lagrange.bodies[].mesh.box.cells"].kind.startswith("list of integers")
    assert "ale.boundaries.<face>.inflow.density" in by and not any(".x_lower" in p for p in by)
    assert by["materials.<name>.youngs_modulus"].unit == "Pa"


def test_the_cli_prints_a_table_or_refuses_in_one_line():
    r = immerse("keys", "run")
    assert r.returncode == 0 and r.stdout == text(select(keys(), "run"))
    assert r.stdout.splitlines()[0] == "run  [table]" and "run.dt_scale  [number]  > 0, <= 4  default 0.9" in r.stdout
    r = immerse("keys", "nope")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "TABLE = 'nope': no such key or table; tables: run" in r.stderr
    md = immerse("keys", "probes", "--markdown").stdout
    assert md == markdown(select(keys(), "probes")) and md.startswith("#### `[probes]`\n\n| key | type |")


def test_the_readmes_key_reference_is_the_generated_one():
    """README.md's "Key reference (generated)" between its markers ends with `immerse keys --markdown`
    (regenerate: the section's text after its introduction)."""
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("<!-- keys:begin -->", 1)[1].split("<!-- keys:end -->", 1)[0]
    generated = markdown(keys())
    assert section.endswith(generated), "README's key reference is stale: paste `immerse keys --markdown` into it"
