"""orchestrator/schema/spellings.py: the reference density is `density` in every table; the
background's older `rho0` is read under it with a one-line note (check and run print it), the same
case either way; both at once refused in one line."""
from __future__ import annotations

import pytest

from orchestrator.case import CaseError, load_case
from tests.conftest import CASES, immerse


def _water(tmp_path, spelling: str):
    text = (CASES / "water_piston_column" / "case.toml").read_text()
    assert 'eos = "tait", density = 1000.0' in text
    d = tmp_path / spelling.replace(" ", "_").replace("=", "").replace(",", "")
    d.mkdir()
    (d / "case.toml").write_text(text.replace("density = 1000.0, bulk_modulus", f"{spelling}, bulk_modulus", 1))
    return d


def test_the_older_spelling_is_the_same_case_with_a_note(tmp_path):
    new, old = load_case(_water(tmp_path, "density = 1000.0")), load_case(_water(tmp_path, "rho0 = 1000.0"))
    assert new["_notes"] == [] and old["_notes"] == [
        "note: ale.materials.water.rho0 is read as density: the reference density's one name in every table "
        "([materials], [sph] materials, [ale.materials])"]
    assert old["ale"]["materials"] == new["ale"]["materials"] and new["ale"]["materials"]["water"]["rho0"] == 1000.0
    from orchestrator.fingerprint import canonical_json, case_identity

    ident = [case_identity({k: v for k, v in c.items() if k not in ("case_dir", "case_sha256")}) for c in (old, new)]
    assert canonical_json(ident[0]) == canonical_json(ident[1])
    (tmp_path / "cli").mkdir()
    r = immerse("check", _water(tmp_path / "cli", "rho0 = 1000.0"))
    assert r.returncode == 0 and r.stdout.splitlines()[0].startswith("immerse: note: ale.materials.water.rho0 is read "
                                                                      "as density"), r.stdout


def test_both_spellings_at_once_are_refused(tmp_path):
    with pytest.raises(CaseError) as ei:
        load_case(_water(tmp_path, "rho0 = 1000.0, density = 1000.0"))
    assert ei.value.key == "ale.materials.water.rho0" and "give only density" in str(ei.value)


@pytest.mark.parametrize("name, new, old", [("dam_break", "tait", "taitwater"), ("sph_shock_tube", "ideal_gas", "idealgas")])
def test_the_particles_older_model_names_are_the_same_case_with_a_note(tmp_path, name, new, old):
    """sph.materials' model takes the background's EOS names (tait, ideal_gas); LAMMPS's pair-style
    names (taitwater, idealgas) are read under them with a note, the normalised case equal (its
    model the pair style the SPH group runs) and an unknown name refused naming the allowed ones."""
    text = (CASES / name / "case.toml").read_text()
    assert f'model = "{new}"' in text
    cases = {}
    for spelling in (new, old, "water"):
        d = tmp_path / spelling
        d.mkdir()
        (d / "case.toml").write_text(text.replace(f'model = "{new}"', f'model = "{spelling}"', 1))
        if spelling == "water":
            with pytest.raises(CaseError) as ei:
                load_case(d)
            assert ei.value.key.endswith(".model") and "'tait', 'ideal_gas', 'tlsph'" in str(ei.value), str(ei.value)
        else:
            cases[spelling] = load_case(d)
    material = next(iter(cases[new]["sph"]["materials"]))
    assert cases[new]["_notes"] == [] and cases[old]["_notes"] == [
        f"note: sph.materials.{material}.model = '{old}' is read as '{new}': the background's EOS name for the same "
        "law (sph.materials model names LAMMPS's pair style before)"]
    assert cases[old]["sph"] == cases[new]["sph"] and cases[new]["sph"]["materials"][material]["model"] == old
