"""Progress reporting: a tqdm bar on a terminal, plain periodic log lines otherwise; the ETA comes
from the rate measured after the first step, and only once it has been measured."""
import re

import pytest

from orchestrator.progress import Progress


class FakeClock:
    def __init__(self, t: float = 100.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_log_lines_when_not_a_terminal():
    lines = []
    clock = FakeClock()
    p = Progress(end_time=1.0, start_time=0.0, tty=False, log=lines.append, every_s=0.0,
                 eta_after_s=3.0, clock=clock)
    clock.t += 1.0
    p.update(0.25, 100)
    clock.t += 4.0
    p.update(0.5, 200)
    p.close()
    assert len(lines) == 2
    assert lines[0] == "t = 2.5000e-01 s (25.0%), step 100, 0 steps/s, ETA --"
    # 100 steps and 0.25 s of simulated time in 4 s: 25 steps/s, 0.5 s left -> 8 s
    assert lines[1] == "t = 5.0000e-01 s (50.0%), step 200, 25 steps/s, ETA 8 s"


def test_an_implicit_solvers_step_and_iterations_join_the_line():
    lines = []
    clock = FakeClock()
    p = Progress(end_time=1.0, start_time=0.0, tty=False, log=lines.append, every_s=0.0, clock=clock)
    clock.t += 1.0
    p.update(0.25, 100, "lagrange: dt 0.00025 s, 4 Newton iterations")
    assert lines == ["t = 2.5000e-01 s (25.0%), step 100, 0 steps/s, ETA --; lagrange: dt 0.00025 s, 4 Newton iterations"]
    # a function is asked only when a line is written
    asked = []
    p.every = 10.0
    p.update(0.3, 120, lambda: asked.append(1) or "x")
    clock.t += 11.0
    p.update(0.35, 140, lambda: asked.append(1) or "lagrange: dt 0.0005 s, 3 Newton iterations")
    assert len(asked) == 1 and lines[-1].endswith("; lagrange: dt 0.0005 s, 3 Newton iterations")


def test_no_eta_from_a_slow_start():
    """The case of issue 7: 18 s of start-up (kernels compiled before step 1), then the run ends a
    second later. The old rate, (steps done) / (wall since start), predicted an ETA of ~1787 s; no
    line may show an ETA until the rate is measured, and none may be far above the real rest."""
    lines = []
    clock = FakeClock()
    end, steps = 1.0, 100
    p = Progress(end_time=end, start_time=0.0, tty=False, log=lines.append, every_s=0.0, clock=clock)
    clock.t += 18.0  # start-up, then step 1
    for k in range(1, steps + 1):
        p.update(end * k / steps, k)
        clock.t += 1.0 / steps
    p.close()
    assert len(lines) == steps
    assert all(line.endswith("ETA --") for line in lines)


def test_eta_tracks_the_measured_rate_after_a_slow_start():
    lines = []
    clock = FakeClock()
    p = Progress(end_time=10.0, start_time=0.0, tty=False, log=lines.append, every_s=0.0,
                 eta_after_s=3.0, clock=clock)
    clock.t += 18.0  # start-up
    wall_per_sim_s = 2.0  # steady: 1 s of simulated time per 2 s of wall time
    etas = []
    for k in range(1, 11):
        p.update(float(k), k)
        m = re.search(r"ETA (\d+) s", lines[-1])
        etas.append(int(m.group(1)) if m else None)
        clock.t += wall_per_sim_s
    assert etas[:2] == [None, None]  # 0 and 2 s of stepping measured
    for k, eta in enumerate(etas[2:], start=3):
        assert eta == pytest.approx((10.0 - k) * wall_per_sim_s, abs=0.5)


def test_restart_measures_from_its_own_start():
    """A run restarted at t = 5 of 10: the ETA is the rest at the rate of this run."""
    lines = []
    clock = FakeClock()
    p = Progress(end_time=10.0, start_time=5.0, tty=False, log=lines.append, every_s=0.0,
                 eta_after_s=1.0, clock=clock)
    clock.t += 3.0
    p.update(5.5, 1001)
    clock.t += 1.0
    p.update(6.0, 1002)
    assert lines[-1].endswith("ETA 8 s")  # 0.5 s per wall second, 4 s left
    assert "(60.0%)" in lines[-1]


def test_log_lines_are_spaced():
    lines = []
    clock = FakeClock()
    p = Progress(end_time=1.0, start_time=0.0, tty=False, log=lines.append, every_s=10.0, clock=clock)
    for k in range(1, 101):
        clock.t += 0.5
        p.update(k / 100, k)
    assert len(lines) == 5  # every 10 s of 50


def test_bar_on_a_terminal(capsys):
    lines = []
    clock = FakeClock()
    p = Progress(end_time=1.0, start_time=0.0, tty=True, log=lines.append, eta_after_s=3.0, clock=clock)
    clock.t += 18.0
    p.update(0.5, 10)
    assert "ETA --" in p.bar.postfix
    clock.t += 4.0
    p.update(0.75, 20)
    assert p.bar.postfix.endswith("ETA 4 s")  # 0.25 s of sim time in 4 s, 0.25 left
    p.update(1.0, 30)
    p.close()
    err = capsys.readouterr().err
    assert "100%" in err and "step 30" in err and "steps/s" in err
    assert lines == []  # no duplicate log lines on a terminal
