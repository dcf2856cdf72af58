"""Campaign files: validation (one line naming the key), expansion into runs, case keys set by path."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from orchestrator.campaign.spec import load_campaign, parse_key, set_key
from orchestrator.campaign.toml_write import dumps
from orchestrator.case import CaseError

REPO = Path(__file__).resolve().parents[3]
SHOCK = REPO / "cases" / "campaigns" / "shock_tube_conforming_vs_immersed"


def _write(tmp_path, text: str) -> Path:
    p = tmp_path / "campaign.toml"
    p.write_text(text.replace("@SHOCK", str(SHOCK)))
    return p


BASE = '''
name = "t"
[axes.zones]
values = [100, 200]
"ale.grid.cells" = [[100, 1], [200, 1]]
[[series]]
name = "conforming"
case = "@SHOCK/conforming"
[[series]]
name = "mid"
case = "@SHOCK/immersed"
set = { "coupling.condition" = "tied" }
[series.axes.zones]
"lagrange.bodies[0].mesh.box.lower" = [[0.905, 0.0], [0.9025, 0.0]]
'''


def test_the_matrix_expands_into_series_times_levels_with_the_keys_set(tmp_path):
    camp = load_campaign(_write(tmp_path, BASE))
    assert [r.name for r in camp.runs] == ["conforming-zones100", "conforming-zones200", "mid-zones100", "mid-zones200"]
    mid = camp.runs[3]
    assert mid.levels == {"zones": 200}
    assert mid.data["ale"]["grid"]["cells"] == [200, 1]
    assert mid.data["lagrange"]["bodies"][0]["mesh"]["box"]["lower"] == [0.9025, 0.0]
    assert mid.data["coupling"]["condition"] == "tied"
    assert camp.runs[0].ranks == {"ale": 1} and mid.ranks == {"ale": 1, "lagrange": 1}
    assert camp.runs[0].data["ale"]["grid"]["cells"] == [100, 1]


def test_a_series_runs_over_the_axes_it_varies_only(tmp_path):
    text = BASE.replace('name = "mid"', 'name = "mid"\nvary = []').replace(
        '[series.axes.zones]\n"lagrange.bodies[0].mesh.box.lower" = [[0.905, 0.0], [0.9025, 0.0]]\n', "")
    camp = load_campaign(_write(tmp_path, text))
    assert [r.name for r in camp.runs] == ["conforming-zones100", "conforming-zones200", "mid"]
    assert camp.runs[2].levels == {} and camp.runs[2].data["ale"]["grid"]["cells"] == [400, 1]
    with pytest.raises(CaseError, match=r"^series\[1\]\.vary = 'cells': no such axis"):
        load_campaign(_write(tmp_path, text.replace("vary = []", 'vary = ["cells"]')))
    with pytest.raises(CaseError, match=r"^series\[1\]\.axes\.zones = <missing>: the series does not vary"):
        load_campaign(_write(tmp_path, BASE.replace('name = "mid"', 'name = "mid"\nvary = []')))


def test_a_series_can_leave_out_keys_of_its_base_case(tmp_path):
    """``unset``: the explicit series of a campaign over an implicit case drops lagrange.time_step
    (cases/campaigns/time_integrators); a key the base case does not have is one line naming it."""
    text = BASE.replace('set = { "coupling.condition" = "tied" }',
                        'set = { "coupling.condition" = "tied" }\nunset = ["coupling.condition", "ale.grid.lower"]')
    mid = load_campaign(_write(tmp_path, text), check_cases=False).runs[3]   # (a grid needs its lower)
    assert mid.data["coupling"]["condition"] == "tied"        # (set after unset)
    assert "lower" not in mid.data["ale"]["grid"] and mid.data["ale"]["grid"]["cells"] == [200, 1]
    with pytest.raises(CaseError, match=r"^series\[1\]\.unset = 'ale\.grid\.nothing': cannot unset in .*: the base "
                                        r"case has no ale\.grid\.nothing"):
        load_campaign(_write(tmp_path, text.replace('"ale.grid.lower"', '"ale.grid.nothing"')), check_cases=False)


@pytest.mark.parametrize("edit, key, allowed", [
    (lambda t: t.replace('name = "t"', 'name = "t"\nspeed = 3'), "speed", "unknown key"),
    (lambda t: t.replace('values = [100, 200]', 'values = [100, 200, 400]'), 'axes.zones."ale.grid.cells"',
     "must have 3 items"),
    (lambda t: t.replace('case = "@SHOCK/conforming"', 'case = "nowhere"'), "series[0].case", "must be a case directory"),
    (lambda t: t.replace('"coupling.condition" = "tied"', '"coupling.condition" = "glued"'),
     "run mid-zones100: coupling.condition", "must be one of"),
    (lambda t: t.replace('"ale.grid.cells" = [[100, 1], [200, 1]]', '"ale.grid.cells" = [[100, 1], [0, 1]]'),
     "run conforming-zones200: ale.grid.cells", ""),
    (lambda t: t.replace('"lagrange.bodies[0]', '"lagrange.bodies[3]'), "axes", "has 1 entries, no [3]"),
    (lambda t: t.replace('name = "mid"', 'name = "conforming"'), "series[1].name", "must differ"),
    (lambda t: t + '[report]\nresolution = "cells"\n', "report.resolution", "must name an axis"),
    (lambda t: t.replace("[axes.zones]", "[axes.zones\n"), "campaign.toml", "TOML syntax error"),
    # (issue 41: a timeout of nan or inf started runs)
    (lambda t: t.replace('name = "t"', 'name = "t"\ntimeout = nan'), "timeout", "must be a finite number"),
    (lambda t: t.replace('name = "t"', 'name = "t"\ntimeout = inf'), "timeout", "must be a finite number"),
    (lambda t: t.replace('name = "t"', 'name = "t"\ntimeout = 1e300'), "timeout", "<= 1e+09 (the physical range)"),
    # (issue 41: a 10,000-run campaign took 13 s to name its first bad run)
    (lambda t: t.replace('values = [100, 200]\n"ale.grid.cells" = [[100, 1], [200, 1]]',
                         f'values = {list(range(100, 400))}\n"ale.grid.cells" = {[[n, 1] for n in range(100, 400)]}'),
     "axes", "a campaign may have at most 500 runs"),
])
def test_a_bad_campaign_is_one_line_naming_the_key(tmp_path, edit, key, allowed):
    with pytest.raises(CaseError) as e:
        load_campaign(_write(tmp_path, edit(BASE)))
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(key), msg
    assert allowed in msg, msg


def test_bad_campaign_through_the_cli_exits_2_and_writes_nothing(tmp_path, run_immerse):
    p = _write(tmp_path, BASE.replace('"coupling.condition" = "tied"', '"coupling.condition" = "glued"'))
    out = tmp_path / "out"
    r = run_immerse("campaign", p, "--out", out)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "coupling.condition = 'glued'" in r.stderr, r.stderr
    assert not out.exists()


def test_keys_by_path_with_indices():
    assert parse_key("lagrange.bodies[0].mesh.box") == ["lagrange", "bodies", 0, "mesh", "box"]
    assert parse_key("lagrange.bodies.0.mesh") == ["lagrange", "bodies", 0, "mesh"]
    d = {"lagrange": {"bodies": [{"mesh": {}}]}}
    set_key(d, "lagrange.bodies.0.mesh.file", "m.msh")
    set_key(d, "ranks.ale", 2)  # a missing table is created
    assert d == {"lagrange": {"bodies": [{"mesh": {"file": "m.msh"}}]}, "ranks": {"ale": 2}}
    with pytest.raises(KeyError, match="no entry"):
        set_key(d, "lagrange.bodies[1]", {})


def test_every_shipped_case_survives_the_toml_writer():
    """A run's case.toml is the base case read by tomllib and written back: nothing may change."""
    files = sorted((REPO / "cases").rglob("case.toml"))
    assert len(files) > 20
    for f in files:
        data = tomllib.loads(f.read_text())
        assert tomllib.loads(dumps(data)) == data, f


def test_only_keeps_the_named_series_and_levels(tmp_path):
    p = _write(tmp_path, BASE)
    camp = load_campaign(p, only={"series": ["mid"], "zones": ["200"]})
    assert [r.name for r in camp.runs] == ["mid-zones200"]
    with pytest.raises(CaseError, match=r"^--only = 'series=fast': no such series; series: conforming, mid"):
        load_campaign(p, only={"series": ["fast"]})
    with pytest.raises(CaseError, match=r"^--only = 'zones=300': not a level of the axis; levels: 100, 200"):
        load_campaign(p, only={"zones": ["300"]})


def test_a_series_relative_to_another_gets_its_error_from_the_reference_run():
    from orchestrator.campaign.collect import apply_references

    metas = [{"series": "ref", "levels": {}}, {"series": "b", "levels": {"k": 1}, "relative_to": "ref"},
             {"series": "b", "levels": {"k": 2}, "relative_to": "ref"}]
    rows = [{"value": 2.0}, {"value": 2.2}, {"value": float("nan")}]
    apply_references(rows, metas)
    assert abs(rows[1]["error"] - 0.1) < 1e-15 and rows[2]["error"] != rows[2]["error"]
    assert rows[1]["error_reference"] == "ref"
    assert rows[0]["error"] != rows[0]["error"] and rows[0]["error_reference"] == "(the reference)"


@pytest.mark.parametrize("args, text", [
    (["--cores", "0"], "--cores = 0: must be an integer >= 1"),
    (["--only", "zones"], "--only 'zones': expected AXIS=LEVEL[,LEVEL...]"),
    (["--only", "zones=300"], "--only = 'zones=300': not a level of the axis"),
    (["--engine", "pbs"], "argument --engine: invalid choice: 'pbs'"),
])
def test_bad_campaign_arguments_exit_2_and_write_nothing(tmp_path, run_immerse, args, text):
    out = tmp_path / "out"
    r = run_immerse("campaign", _write(tmp_path, BASE), "--out", out, *args)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and text in r.stderr, r.stderr
    assert not out.exists()
