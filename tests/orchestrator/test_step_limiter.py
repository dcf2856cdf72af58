"""What sets the step, said by name (issue 40): each group's step_limiter() (adapters/base.py) through
the coupler's CMD_LIMITER query, in the progress line and the run's last line; a step more than 100
times below its early median said once; run.dt_min stops the run by name."""
from __future__ import annotations

import re
import shutil
from types import SimpleNamespace

import pytest

from orchestrator.coupler import EARLY_STEPS, FALL_WARN, Coupler, describe_limiter
from tests.conftest import CASES, immerse


def _variant(tmp_path, name, *edits, check=True):
    """cases/<name> with its texts replaced; without its [check] (the last table) when ``check`` is
    False (a run of a few steps is no result)."""
    case = tmp_path / name
    shutil.copytree(CASES / name, case, ignore=shutil.ignore_patterns("out"))
    text = (case / "case.toml").read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    if not check and "[check]" in text:
        text = text[: text.index("[check]")]
    (case / "case.toml").write_text(text)
    return case


def _last_line(tmp_path, case):
    r = immerse("run", case, "--out", tmp_path / "out", timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return next(ln for ln in (tmp_path / "out" / "log.txt").read_text().splitlines() if "finished:" in ln)


def _few_steps(end_time, n=3):
    return (f"end_time = {end_time}", f"end_time = {end_time}\nmax_steps = {n}")


# (case, edits, the phrase the run's last line must hold): one case limited by each kind
KINDS = {
    "element": ("elastic_bar_wave", [_few_steps("16.0e-6")],
                r"set by lagrange: sound speed limit in element \d+ of body 'bar' at \(\S+, \S+, \S+\) m \(volume 1 of"),
    "zone": ("sod", [_few_steps("0.2")],
             r"set by ale: sound speed limit in zone \(\d+, 0\) at \(\S+, \S+\) m \(c = \S+ m/s, rho ="),
    # the piston's face 0.96 of a zone into it, driven at 3: the cut zone ahead of it, squeezed, in
    # the first step (the next ones, the face a zone on, the open zone beyond)
    "cut zone": ("piston_into_gas", [_few_steps("0.25", 1), ("upper = [0.05, 0.005]", "upper = [0.0524, 0.005]"),
                                     ("initial_velocity = [1.0, 0.0]", "initial_velocity = [3.0, 0.0]"),
                                     ("velocity = { x = 1.0 }", "velocity = { x = 3.0 }")],
                 r"set by ale: cut zone limit in zone \(21, 0\) at \(0\.05375, \S+\) m \(.*open fraction 0\.\d+\)"),
    "particle": ("sph_shock_tube", [_few_steps("0.2")],
                 r"set by sph: (signal speed|acceleration) limit in particle \d+ at \(\S+, \S+\) m \((c \+ \|v\||\|a\|) ="),
    # the implicit and quasi-static integrators: no element limits their step, their control chose it
    "step control": ("l_block_free_flight", [_few_steps("30.0")],
                     r"set by lagrange: step control limit in the midpoint step's Newton control "
                     r"\(time_step 0\.1 s, \d+ iterations last step\)$"),
    "load step": ("contact_patch_2d", [],
                  r"set by lagrange: load step limit in lagrange\.load_steps = 1 over the end time$"),
}


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_last_line_names_what_set_the_step(kind, tmp_path):
    name, edits, phrase = KINDS[kind]
    case = _variant(tmp_path, name, *edits, check=False)
    line = _last_line(tmp_path, case)
    assert re.search(r"finished: [13] steps?, .*; the last step \S+ s " + phrase, line), line


def test_describe_limiter():
    lim = {"dt": 1e-9, "kind": "sound speed", "what": "zone (35, 8)", "at": [0.08875, 0.02125],
           "detail": "c = 3.2e+06 m/s"}
    assert describe_limiter("ale", lim) == "ale: sound speed limit in zone (35, 8) at (0.08875, 0.02125) m (c = 3.2e+06 m/s)"
    assert describe_limiter("lagrange", None) == "the lagrange solver"


def _watching(dt_min=None):
    logged = []
    c = SimpleNamespace(early=[], _fall_said=False, dt_floor=dt_min, step=0, t=0.0, log=logged.append,
                        step_limit_text=lambda: "ale: sound speed limit in zone (1, 2)")
    return c, logged


def test_a_step_falling_100_times_below_its_early_median_is_said_once():
    c, logged = _watching()
    for k in range(EARLY_STEPS):
        Coupler._watch_step(c, 1e-6)
        c.step += 1
    Coupler._watch_step(c, 1.01e-6 / FALL_WARN)   # not yet: 99 times below
    assert logged == []
    for dt in (0.99e-6 / FALL_WARN, 1e-9, 1e-10):
        Coupler._watch_step(c, dt)
        c.step += 1
    assert len(logged) == 1, logged
    assert logged[0].startswith("warning: the step fell to 9.9e-09 s at step ")
    assert "101 times below its early median 1e-06 s (steps 1-50): set by ale: sound speed limit in zone (1, 2)" in logged[0]


def test_run_dt_min_stops_the_run_naming_what_set_the_step(tmp_path):
    """The bar's stable step is 4.7e-8 s: run.dt_min = 1e-7 stops it before its first step, exit 1, one
    line naming run.dt_min and the element."""
    case = _variant(tmp_path, "elastic_bar_wave", ("end_time = 16.0e-6", "end_time = 16.0e-6\ndt_min = 1e-7"))
    r = immerse("run", case, "--out", tmp_path / "out", timeout=300)
    assert r.returncode == 1, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert re.fullmatch(r"immerse: run failed: coupler rank 0: RuntimeError: time step \S+ s below run.dt_min = 1e-07 s "
                        r"at step 1, t = 0 s; set by lagrange: sound speed limit in element \d+ of body 'bar' .*", last), last


def test_a_run_cut_short_by_max_steps_writes_its_last_state_and_says_so(tmp_path):
    """run.max_steps = 3 in Sod's tube (outputs every 0.01 s, 0.2 s to go): the third step's state is
    written (outputs held only step 0 before: the run's last state was lost), no checkpoint is taken
    at it, and the run's last line says it stopped before its end time (its check measures the part
    it ran)."""
    from orchestrator.view import available

    case = _variant(tmp_path, "sod", _few_steps("0.2"))
    r = immerse("run", case, "--out", tmp_path / "out", timeout=300)
    assert r.returncode in (0, 1), r.stdout + r.stderr
    assert [s[1] for s in available(tmp_path / "out")["ale"]["steps"]] == [0, 3]
    last = r.stdout.strip().splitlines()[-1]
    assert re.search(r"sod: 3 steps in \S+ s -> .*; stopped by run\.max_steps at t = \S+ s, before the case's "
                     r"end_time; check (passed|FAILED)$", last), last
