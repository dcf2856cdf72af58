"""Progress reporting: a tqdm bar on a terminal, plain periodic log lines otherwise."""
from orchestrator.progress import Progress


def test_log_lines_when_not_a_terminal():
    lines = []
    p = Progress(end_time=1.0, start_time=0.0, tty=False, log=lines.append, every_s=0.0)
    p.update(0.25, 100)
    p.update(0.5, 200)
    p.close()
    assert len(lines) == 2
    assert lines[-1].startswith("t = 5.0000e-01 s (50.0%), step 200") and "steps/s" in lines[-1] and "ETA" in lines[-1]


def test_bar_on_a_terminal(capsys):
    lines = []
    p = Progress(end_time=1.0, start_time=0.0, tty=True, log=lines.append)
    p.update(0.5, 10)
    p.update(1.0, 20)
    p.close()
    err = capsys.readouterr().err
    assert "100%" in err and "step 20" in err and "steps/s" in err
    assert lines == []  # no duplicate log lines on a terminal
