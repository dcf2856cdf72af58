"""Tests of orchestrator.expressions: at check time every expression of a case is evaluated on
exactly the points its solver evaluates it on (recorded from the real solvers), and a non-finite
value, a zone no region covers or obstacles that block everything are refused with one line naming
the key, the expression and the point."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

import solvers.expressions as compiler
from orchestrator import expressions as check
from orchestrator.case import CaseError, load_case
from tests.orchestrator.case_texts import STEEL_BAR_HEAD

ALE2D = """\
[run]
dimension = 2
end_time = 0.2

[ale]
grid = { lower = [0.0, 0.0], upper = [1.0, 0.3], cells = [10, 3] }
materials.gas = { eos = "ideal_gas", gamma = 1.4 }
materials.heavy = { eos = "ideal_gas", gamma = 1.4 }
regions = [
  { material = "gas", density = 1.0, pressure = 1.0 },
  { material = "REGION_MATERIAL", region = "(x - 0.4)**2 + (y - 0.15)**2 < 0.04", density = 5.0, pressure = 1.0 },
]
"""
OBSTACLE = ALE2D.replace("REGION_MATERIAL", "gas") + 'obstacles = [ { region = "x > 0.83", subsamples = 3 } ]\n'
BODIES = STEEL_BAR_HEAD + """\
mesh = { box = { lower = [0.0, 0.0, 0.0], upper = [0.1, 0.01, 0.02], cells = [5, 2, 3] } }
initial_velocity = ["where(x > 0, 1e-3 / x, 0)", 0.0, "-190 * where(z > 0.001, 1, 0.5)"]

[[lagrange.bodies]]
name = "rod"
material = "steel"
mesh = { quarter_cylinder = { radius = 0.01, length = 0.02, radial_cells = 3, axial_cells = 2 } }
initial_velocity = [0.0, "y - 2 * z", 0.0]

[[boundaries]]
type = "fixed"
region = "x < 1e-9 and z > 0.005"
"""


def _case(tmp_path, text, name="c"):
    d = tmp_path / name
    d.mkdir()
    (d / "case.toml").write_text(text)
    return load_case(d)


class _Recorder:
    """Wraps compile_expression where a module imported it: records (text, points) of every call."""

    def __init__(self):
        self.calls = []

    def wrap(self, original):
        def compile_and_record(text, names=("x", "y", "z"), **kw):
            fn = original(text, names, **kw)

            def call(*args, **kwargs):
                self.calls.append((text, np.column_stack([np.broadcast_to(a, np.shape(args[0])) for a in args])))
                return fn(*args, **kwargs)
            return call
        return compile_and_record

    def points(self, text):
        return _rows(np.concatenate([p for t, p in self.calls if t == text]))


def _rows(a):
    """The set of rows (sorted, duplicates dropped): the points as a set, bitwise."""
    return np.unique(np.asarray(a, dtype=np.float64), axis=0)


def _checked_points(monkeypatch, case):
    seen = _Recorder()
    original = check._evaluate

    def record(key, text, fn, points, where):
        seen.calls.append((text, np.array(points)))
        return original(key, text, fn, points, where)
    monkeypatch.setattr(check, "_evaluate", record)
    check.check_expressions(case)
    return seen


# ---- the same points as the solvers -------------------------------------------------------------
@pytest.mark.parametrize("material", ["gas", "heavy"], ids=["one_material_centres", "two_materials_samples"])
def test_ale_regions_on_the_solver_points(tmp_path, monkeypatch, material):
    from solvers.ale import solver as ale_solver
    from solvers import expressions as shared

    text = ALE2D.replace("REGION_MATERIAL", material)
    if material == "heavy":
        text = text.replace("[ale]\n", "[ale]\nfraction_samples = 3\n")
    case = _case(tmp_path, text)
    solver_seen = _Recorder()
    monkeypatch.setattr(ale_solver, "compile_expression", solver_seen.wrap(shared.compile_expression))
    monkeypatch.setattr(shared, "compile_expression", solver_seen.wrap(shared.compile_expression))  # mixed.py
    ale_solver.AleSolver(MPI.COMM_SELF, case["ale"])
    monkeypatch.undo()
    region = case["ale"]["regions"][1]["region"]
    got = _checked_points(monkeypatch, case).points(region)
    want = solver_seen.points(region)
    assert len(want) == (30 if material == "gas" else 30 * 9)
    np.testing.assert_array_equal(got, want)


def test_obstacle_on_the_solver_points(tmp_path, monkeypatch):
    from solvers.ale import blocked

    case = _case(tmp_path, OBSTACLE)
    seen = _Recorder()
    monkeypatch.setattr(blocked, "compile_expression", seen.wrap(blocked.compile_expression))
    blocked.obstacle_fractions(__import__("solvers.ale.grid", fromlist=["Block"]).Block(
        case["ale"]["grid"]["lower"], case["ale"]["grid"]["upper"], case["ale"]["grid"]["cells"],
        {f: "wall" for f in ("x_lower", "x_upper", "y_lower", "y_upper")}), case["ale"]["obstacles"])
    monkeypatch.undo()
    text = case["ale"]["obstacles"][0]["region"]
    want = seen.points(text)
    assert len(want) == 30 * 9
    np.testing.assert_array_equal(_checked_points(monkeypatch, case).points(text), want)


def test_lagrange_expressions_on_the_solver_nodes(tmp_path, monkeypatch):
    from solvers.lagrange import boundary, solver

    case = _case(tmp_path, BODIES)
    seen = _Recorder()
    monkeypatch.setattr(solver, "compile_expression", seen.wrap(solver.compile_expression))
    monkeypatch.setattr(boundary, "compile_expression", seen.wrap(boundary.compile_expression))
    solver.LagrangeSolver(MPI.COMM_SELF, case)
    monkeypatch.undo()
    checked = _checked_points(monkeypatch, case)
    texts = [case["lagrange"]["bodies"][0]["initial_velocity"][0], case["lagrange"]["bodies"][0]["initial_velocity"][2],
             case["lagrange"]["bodies"][1]["initial_velocity"][1], case["boundaries"][0]["region"]]
    for text in texts:
        np.testing.assert_array_equal(checked.points(text), seen.points(text))
    assert len(seen.points(texts[0])) == 6 * 3 * 4                   # the box's nodes (built without the mesh)
    np.testing.assert_array_equal(seen.points(texts[3]),   # regions: the nodes of every body
                                  _rows(np.concatenate([seen.points(texts[0]), seen.points(texts[2])])))


# ---- refusals -----------------------------------------------------------------------------------
@pytest.mark.parametrize("old, new, key, fragment", [
    ('"where(x > 0, 1e-3 / x, 0)"', '"1e-3 / x"', "lagrange.bodies[0].initial_velocity[0]",
     "gives inf at x = 0 (a node of body 'bar')"),
    ('"y - 2 * z"', '"sqrt(y - 2 * z)"', "lagrange.bodies[1].initial_velocity[1]", "gives nan at y = 0, z = 0.01"),
    ('region = "x < 1e-9 and z > 0.005"', 'region = "log(x) < -20"', "boundaries[0].region",
     "(sub-expression 'log(x)' = -inf) at x = 0"),
])
def test_lagrange_refusals_name_key_point_and_sub_expression(tmp_path, old, new, key, fragment):
    case = _case(tmp_path, BODIES.replace(old, new))
    with pytest.raises(CaseError) as ei:
        check.check_expressions(case)
    msg = str(ei.value)
    assert ei.value.key == key and fragment in msg and "\n" not in msg, msg


def test_ale_refusals(tmp_path):
    bad = ALE2D.replace("REGION_MATERIAL", "gas").replace("< 0.04", "< 0.04 + log(x - 0.5)")
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, bad, "log"))
    assert ei.value.key == "ale.regions[1].region" and "at x = 0.05, y = 0.05 (a zone centre" in str(ei.value)
    gap = ALE2D.replace("REGION_MATERIAL", "gas").replace(
        '{ material = "gas", density = 1.0, pressure = 1.0 }', '{ material = "gas", region = "y > 0.1", density = 1.0, pressure = 1.0 }')
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, gap, "gap"))
    assert ei.value.key == "ale.regions" and "zone (0, 0) is not covered by any region (at x = 0.05, y = 0.05)" in str(ei.value)
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, OBSTACLE.replace('"x > 0.83"', '"x > -1"'), "solid"))
    assert ei.value.key == "ale.obstacles" and "block every zone" in str(ei.value)
    # an obstacle covering all but a sliver of one zone (one sub-point out) leaves it open
    check.check_expressions(_case(tmp_path, OBSTACLE.replace('"x > 0.83"', '"x > 0.02 or y > 0.02"'), "sliver"))


def test_past_the_budget_a_grid_is_bounded_by_boxes_not_sampled(tmp_path, monkeypatch):
    """Past the budget (3000 here) the grid of 100 x 30 zones is walked by boxes of zones: the disc
    region bounds finite over the whole grid at once (no point evaluated); a pole at one zone centre
    (57, 13) that every-n-th-zone sampling skipped (stride 196 visited 16 zones) is found and named;
    a finite expression the bounds cannot follow (sin^2 + cos^2 holds 0 in its interval) is refused
    on its key once the leaves it must evaluate pass the budget; and two materials' sample points
    (8^2 a zone) are bounded the same way."""
    monkeypatch.setattr(check, "CHECK_BUDGET", 3000)
    monkeypatch.setattr(check, "LEAF", 16)
    text = ALE2D.replace("REGION_MATERIAL", "gas").replace("cells = [10, 3]", "cells = [100, 30]")
    seen = _checked_points(monkeypatch, _case(tmp_path, text, "big"))
    assert sum(len(p) for _, p in seen.calls) == 0
    x0, y0 = 0.0 + (57 + 0.5) * 0.01, 0.0 + (13 + 0.5) * 0.01      # (the solver's centre arithmetic)
    pole = text.replace("< 0.04", f"< 0.04 + 1 / ((x - {x0!r})**2 + (y - {y0!r})**2)")
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, pole, "pole"))
    assert ei.value.key == "ale.regions[1].region" and f"x = {x0:.9g}, y = {y0:.9g}" in str(ei.value), str(ei.value)
    odd = text.replace("< 0.04", "< 0.04 / (sin(x)**2 + cos(x)**2)")
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, odd, "odd"))
    assert ei.value.key == "ale.regions[1].region" and "cannot be checked on all 3000 zones" in str(ei.value)
    seen = _checked_points(monkeypatch, _case(tmp_path, ALE2D.replace("REGION_MATERIAL", "heavy").replace(
        "cells = [10, 3]", "cells = [100, 30]"), "heavy"))
    assert sum(len(p) for _, p in seen.calls) == 0


def test_past_the_budget_a_box_body_is_bounded_by_boxes(tmp_path, monkeypatch):
    """A box body past the budget: where(x > 0, 1e-3 / x, 0) bounds finite away from x = 0 and is
    evaluated at the nodes near it (finite there: the guard holds); 1e-3 / (x - 0.04) has a node at
    x = 0.04 and is refused naming it."""
    monkeypatch.setattr(check, "CHECK_BUDGET", 600)
    monkeypatch.setattr(check, "LEAF", 8)
    big = BODIES.replace("cells = [5, 2, 3]", "cells = [50, 2, 3]")
    seen = _checked_points(monkeypatch, _case(tmp_path, big, "guarded"))
    n = sum(len(p) for t, p in seen.calls if "1e-3" in t)
    assert 0 < n < 51 * 3 * 4, n                  # (the nodes near x = 0 only, of 612)
    with pytest.raises(CaseError) as ei:
        check.check_expressions(_case(tmp_path, big.replace("where(x > 0, 1e-3 / x, 0)", "1e-3 / (x - 0.04)"), "pole"))
    assert ei.value.key == "lagrange.bodies[0].initial_velocity[0]" and "x = 0.04" in str(ei.value), str(ei.value)


def test_guarded_expressions_pass(tmp_path):
    check.check_expressions(_case(tmp_path, BODIES))  # where(x > 0, 1e-3 / x, 0) at x = 0 is 0
    assert compiler.compile_expression("where(x > 0, 1e-3 / x, 0)")(np.zeros(3), 0.0, 0.0).tolist() == [0.0] * 3


def test_shipped_cases_pass():
    repo = Path(__file__).resolve().parents[2]
    for d in sorted((repo / "cases").iterdir()):
        if (d / "case.toml").is_file():
            check.check_expressions(load_case(d))
