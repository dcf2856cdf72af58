"""The ``[probes]`` table (orchestrator/schema/probes.py): what it accepts, fills in and refuses."""
from __future__ import annotations

import pytest

from orchestrator.case import load_case
from orchestrator.schema.rules import CaseError
from tests.orchestrator.test_case import VALID, assert_one_line

PROBE = '[probes]\ntip = { role = "lagrange", quantity = "displacement", component = "x", box = { lower = [0.09, 0.0], upper = [0.1, 0.02] } }\n'


def _case(tmp_path, probes: str):
    d = tmp_path / "case"
    d.mkdir(parents=True)
    (d / "case.toml").write_text((VALID / "box2d" / "case.toml").read_text() + "\n" + probes)
    return d


def test_a_probe_is_normalised(tmp_path):
    p = load_case(_case(tmp_path, PROBE))["probes"]
    assert p == {"tip": {"role": "lagrange", "quantity": "displacement", "component": "x", "reduce": "mean",
                         "box": {"lower": [0.09, 0.0], "upper": [0.1, 0.02]}}}


@pytest.mark.parametrize("old, new, key, fragment", [
    ('role = "lagrange"', 'role = "sph"', "probes.tip.role", "the case has no [sph] table; allowed: a "
     "solver the case runs (lagrange)"),
    ('role = "lagrange"', 'role = "ale"', "probes.tip.role", "the case has no [ale] table"),
    ('role = "lagrange"', 'role = "nodes"', "probes.tip.role", "must be one of: 'lagrange', 'sph', 'ale'"),
    ('quantity = "displacement"', 'quantity = "stress"', "probes.tip.quantity", "one of: 'density', 'displacement'"),
    ('quantity = "displacement"', 'quantity = "pressure"', "probes.tip.quantity",
     "allowed for role = 'lagrange': displacement, velocity, position"),
    ('component = "x"', 'component = "z"', "probes.tip.component", "allowed in 2-D: x, y, magnitude"),
    ('component = "x"', 'component = "x", reduce = "median"', "probes.tip.reduce", "one of: 'mean', 'max', 'min'"),
    ("lower = [0.09, 0.0]", "lower = [0.09, 0.0, 0.0]", "probes.tip.box.lower", "dimension mismatch"),
    ("upper = [0.1, 0.02]", "upper = [0.08, 0.02]", "probes.tip.box.upper", "must be >= box.lower"),
    ("tip = {", '"the tip" = {', 'probes."the tip"', "invalid name"),
    ('component = "x"', 'component = "x", node = 3', "probes.tip.node", "unknown key"),
])
def test_a_bad_probe_is_named(tmp_path, old, new, key, fragment):
    assert old in PROBE
    with pytest.raises(CaseError) as ei:
        load_case(_case(tmp_path, PROBE.replace(old, new, 1)))
    assert_one_line(ei.value)
    assert ei.value.key == key
    assert fragment in ei.value.allowed


def test_a_check_names_a_probe_the_case_has(tmp_path):
    check = ('\n[check]\nkind = "free_end"\nparams = { role = "lagrange", axis = "x", length = 0.1, speed = 1.0, '
             'wave_speed = 5000.0, probe = "PROBE" }\n')
    load_case(_case(tmp_path / "a", PROBE + check.replace("PROBE", "tip")))
    with pytest.raises(CaseError) as ei:
        load_case(_case(tmp_path / "b", PROBE + check.replace("PROBE", "top")))
    assert_one_line(ei.value)
    assert ei.value.key == "check.params.probe" and "allowed: tip" in ei.value.allowed
