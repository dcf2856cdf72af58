"""The warm process server and its stub (orchestrator/prestart): the forked process gets what the plain
`python -m` process gets (arguments, directory, environment, descriptors), ends the same way (exit
codes, Python's errors, deaths by signal), receives the signals sent to the stub, ends when the stub
is killed, and a job run through it gives the plain job's results."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator import prestart
from orchestrator.prestart import server as srv
from tests.conftest import CASES, REPO, immerse_env

PROBE = "tests.orchestrator.prestart.probe"


@pytest.fixture(scope="module")
def socket_path(tmp_path_factory):
    """A server of this test module's own (the suite's may be off), answering before the tests."""
    path = tmp_path_factory.mktemp("prestart") / "s"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator.prestart.server", str(path)], cwd=REPO,
                            env=immerse_env(), stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        ready = json.loads(proc.stdout.readline())
        assert ready["ready"] and path.exists(), ready
        yield path
    finally:
        proc.terminate()
        proc.wait(10)


def _env(socket_path: Path | None, **extra) -> dict:
    env = immerse_env()
    env.pop(prestart.ENV, None)
    if socket_path is not None:
        env[prestart.ENV] = str(socket_path)
    env.update(extra)
    return env


def _command(socket_path, args):
    if socket_path:
        return [sys.executable, "-S", str(prestart.STUB), PROBE, *args]
    return [sys.executable, "-m", PROBE, *args]


def _starter_attributes():
    """What a starter may set on its child besides arguments and environment (hydra binds cores)."""
    import resource

    os.umask(0o027)
    resource.setrlimit(resource.RLIMIT_NOFILE, (200, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))
    os.sched_setaffinity(0, {0})
    signal.signal(signal.SIGUSR1, signal.SIG_IGN)


def test_the_forked_process_gets_what_the_plain_one_gets(socket_path, tmp_path):
    """Arguments, directory, environment, stdin/stdout/stderr, an extra inherited descriptor (as hydra
    passes PMI_FD), umask, resource limits, CPU affinity and ignored signals arrive; the exit code
    comes back; only the warm start differs."""
    results = {}
    for name, path in (("warm", socket_path), ("plain", None)):
        r_fd, w_fd = os.pipe()
        env = _env(path, PROBE_VALUE="x y", PROBE_FD=str(w_fd))
        p = subprocess.run(_command(path, ["report", "3", "--out", "a b"]), env=env, cwd=tmp_path,
                           input="from stdin", capture_output=True, text=True, timeout=60, pass_fds=(w_fd,),
                           preexec_fn=_starter_attributes)
        os.close(w_fd)
        extra = os.read(r_fd, 1000)
        os.close(r_fd)
        results[name] = (p.returncode, json.loads(p.stdout), p.stderr, extra)
    warm, plain = results["warm"], results["plain"]
    assert warm[1].pop("warm") is True and plain[1].pop("warm") is False
    assert warm == plain
    assert warm[0] == 3 and warm[1] == {"argv": ["report", "3", "--out", "a b"], "cwd": str(tmp_path),
                                        "probe_env": "x y", "main": "__main__", "stdin": "from stdin",
                                        "umask": 0o027, "nofile": 200, "affinity": [0],
                                        "sigusr1_ignored": True}
    assert warm[2] == "to stderr\n" and warm[3] == b"through the extra descriptor\n"


@pytest.mark.parametrize("what, code", [("exit-message", 1), ("raise", 1), ("hooked-raise", 1),
                                        ("interrupt", -signal.SIGINT),
                                        ("kill-self", -signal.SIGTERM)])
def test_it_ends_as_the_plain_process_ends(socket_path, what, code):
    """SystemExit with a message, an uncaught error (traceback; through sys.excepthook, which a rank
    replaces with its failure report), KeyboardInterrupt (death by SIGINT, as Python ends) and a death
    by signal give the stub the plain process's status and stderr."""
    warm, plain = (subprocess.run(_command(path, [what]), env=_env(path), capture_output=True, text=True,
                                  timeout=60) for path in (socket_path, None))
    assert warm.returncode == plain.returncode == code
    last = lambda p: p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ""  # noqa: E731
    assert last(warm) == last(plain), (warm.stderr, plain.stderr)


def test_a_sitecustomize_on_the_path_runs_before_the_module(socket_path, tmp_path):
    """As `python -m` runs site's sitecustomize from PYTHONPATH first (the suite's audit hook that
    sees every process a refused input would launch is one), so does the forked process."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text("import os\nos.environ['PROBE_VALUE'] = 'set by sitecustomize'\n")
    outs = []
    for path in (socket_path, None):
        env = _env(path)
        env["PYTHONPATH"] = f"{site}{os.pathsep}{env['PYTHONPATH']}"
        p = subprocess.run(_command(path, ["report", "0"]), env=env, capture_output=True, text=True, timeout=60,
                           input="")
        assert p.returncode == 0, p.stderr
        outs.append(json.loads(p.stdout))
    assert outs[0]["warm"] is True and outs[1]["warm"] is False
    assert outs[0]["probe_env"] == outs[1]["probe_env"] == "set by sitecustomize"


def _started(socket_path, tmp_path):
    pidfile = tmp_path / "pid"
    stub = subprocess.Popen(_command(socket_path, ["wait", str(pidfile)]), env=_env(socket_path),
                            stdout=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not (pidfile.exists() and pidfile.read_text()):
        assert time.monotonic() < deadline and stub.poll() is None
        time.sleep(0.01)
    return stub, int(pidfile.read_text())


def test_signals_to_the_stub_reach_the_process(socket_path, tmp_path):
    stub, pid = _started(socket_path, tmp_path)
    assert pid != stub.pid  # forked from the server, not the stub itself
    stub.send_signal(signal.SIGTERM)
    out, _ = stub.communicate(timeout=30)
    assert stub.returncode == 7 and out == "got SIGTERM\n"


def test_the_process_ends_within_a_second_of_a_killed_stub(socket_path, tmp_path):
    """SIGKILL leaves the stub no word to say: its watcher sees the socket close (measured: ~10 ms)."""
    stub, pid = _started(socket_path, tmp_path)
    fd = os.pidfd_open(pid)
    t0 = time.monotonic()
    stub.kill()
    stub.wait()
    import select

    assert select.select([fd], [], [], 1.0)[0], "the forked process outlived its stub by 1 s"
    os.close(fd)
    assert time.monotonic() - t0 < 1.0


def test_without_an_answer_the_stub_runs_the_plain_command(socket_path, tmp_path):
    """No server at the path, or a refusal (an import-time setting the server was not started with):
    the plain command runs, with the same result."""
    for env in (_env(tmp_path / "no-server"), _env(socket_path, OPENBLAS_NUM_THREADS="2")):
        p = subprocess.run([sys.executable, "-S", str(prestart.STUB), PROBE, "report", "0"], env=env,
                           capture_output=True, text=True, timeout=60, input="")
        assert p.returncode == 0 and json.loads(p.stdout)["warm"] is False, p.stderr


def test_the_server_refuses_what_it_did_not_load(tmp_path, monkeypatch):
    """A changed source file, another package in the directory (`-m` looks there first), an
    import-time environment variable or another kernel cache: refused, with the reason."""
    held = srv.Loaded.__new__(srv.Loaded)
    src = tmp_path / "mod.py"
    src.write_text("x = 1\n")
    st = src.stat()
    held.stamps = {str(src): (st.st_mtime_ns, st.st_size)}
    from solvers import kernel_cache

    held.digest = kernel_cache.source_digest(REPO)
    import json as json_module  # a top-level module of the standard library, imported by the server

    held.tops = {"orchestrator": str(REPO / "orchestrator" / "__init__.py"), "json": json_module.__file__}
    held.customize = {"sitecustomize": None, "usercustomize": None}
    held.rest = [p for p in sys.path[1:] if p != str(REPO)]
    held.path = [str(REPO), str(REPO), *held.rest]
    monkeypatch.setattr(srv, "_START_ENV", {"NUMBA_OPT": "3", "LD_LIBRARY_PATH": "/lib/a"})
    req = {"env": {"NUMBA_OPT": "3", "PYTHONPATH": str(REPO), "LD_LIBRARY_PATH": "/lib/a:/lib/a"}, "cwd": str(tmp_path)}
    assert srv.refusal(req, held) is None  # (a repeated directory changes no search)
    for other in ("", "/lib/a:/lib/b", "/lib/b:/lib/a"):
        assert srv.refusal({**req, "env": {**req["env"], "LD_LIBRARY_PATH": other}}, held) \
            == "environment LD_LIBRARY_PATH differs"
    assert srv.refusal({**req, "env": {**req["env"], "NUMBA_OPT": "2"}}, held) == "environment NUMBA_OPT differs"
    # (adapters.protocol reads its wait's spin as it is imported)
    assert srv.refusal({**req, "env": {**req["env"], "IMMERSE_WAIT_SPIN_S": "0"}}, held) \
        == "environment IMMERSE_WAIT_SPIN_S differs"
    assert srv.refusal({**req, "env": {**req["env"], "NUMBA_CACHE_DIR": "/elsewhere"}}, held) \
        == "environment NUMBA_CACHE_DIR differs"
    # `python -m` looks in its directory first, then PYTHONPATH (an empty entry: the directory again)
    (tmp_path / "orchestrator").mkdir()
    (tmp_path / "orchestrator" / "__init__.py").write_text("")
    assert srv.refusal(req, held) == "the directory and PYTHONPATH find another orchestrator"
    (tmp_path / "orchestrator" / "__init__.py").unlink()
    (tmp_path / "orchestrator").rmdir()
    elsewhere = tmp_path / "lib"
    elsewhere.mkdir()
    (elsewhere / "json.py").write_text("")
    assert srv.refusal({**req, "env": {**req["env"], "PYTHONPATH": f"{REPO}:{elsewhere}"}}, held) \
        == "the directory and PYTHONPATH find another json"
    assert srv.refusal({**req, "env": {**req["env"], "PYTHONPATH": f"{REPO}::"}}, held) is None
    # a sitecustomize the server has not run is run by the forked process before its module
    (elsewhere / "json.py").unlink()
    (elsewhere / "sitecustomize.py").write_text("")
    asked = {**req, "env": {**req["env"], "PYTHONPATH": f"{elsewhere}:{REPO}"}}
    assert srv.refusal(asked, held) is None
    assert asked["customize"] == {"sitecustomize": str(elsewhere / "sitecustomize.py")}
    assert asked["path"][:3] == [str(tmp_path), str(elsewhere), str(REPO)]
    src.write_text("x = 22\n")
    assert srv.refusal(req, held) == f"{src} changed"


def _summary_without_times(out: Path) -> dict:
    s = json.loads((out / "summary.json").read_text())
    for k in ("wall_time_s", "output_time_s", "solver_time_s", "first_step_s", "coupling_time_s",
              "coupling_share"):
        s.pop(k, None)
    return s


def test_a_coupled_job_gives_the_plain_jobs_results(socket_path, tmp_path):
    """The plate in the shock tube (ALE + Lagrange + coupler), 3 steps, both ways: every field of
    summary.json but the times equal, and the step files' arrays bit for bit."""
    import h5py
    import numpy as np

    case = tmp_path / "case"
    case.mkdir()
    text = (CASES / "plate_in_shock_2d" / "case.toml").read_text()
    assert "end_time = 4.0e-3" in text and "output_interval = 0.5e-3" in text
    (case / "case.toml").write_text(text.replace("end_time = 4.0e-3", "end_time = 2.5e-5")
                                    .replace("output_interval = 0.5e-3", "output_interval = 1.0e-5"))
    outs = {}
    for name, path in (("warm", socket_path), ("plain", None)):
        out = tmp_path / name
        p = subprocess.run([*_command_cli(path), "run", str(case), "--out", str(out)], env=_env(path), cwd=REPO,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        outs[name] = out
    assert _summary_without_times(outs["warm"]) == _summary_without_times(outs["plain"])
    files = sorted(f.name for f in (outs["plain"] / "steps").iterdir())
    assert files == sorted(f.name for f in (outs["warm"] / "steps").iterdir()) and len(files) >= 4
    for f in files:
        with h5py.File(outs["warm"] / "steps" / f) as a, h5py.File(outs["plain"] / "steps" / f) as b:
            names = []
            a.visit(names.append)
            for n in names:
                if isinstance(a[n], h5py.Dataset):
                    assert np.array_equal(a[n][()], b[n][()], equal_nan=True), (f, n)


def test_the_suites_jobs_start_warm(tmp_path):
    """Every process of a coupled job that a test starts through tests.conftest.immerse (the CLI, the
    coupler, the ALE and Lagrange ranks) is forked by the suite's warm server, none refused: a value
    the launcher gives its ranks that the server was started without (OPENBLAS_NUM_THREADS, when the
    suite ran as `pytest` rather than `make test`) had every solver rank start cold, each importing
    and loading its kernels (tests/cases/test_coupled_cases.py 202 s against 75 s)."""
    from tests.conftest import immerse

    path = os.environ.get(prestart.ENV)
    if not path or path == "0":
        pytest.skip("the suite's warm process server is off (IMMERSE_PRESTART unset or 0)")
    deadline = time.monotonic() + 120   # the server answers once it has loaded (seconds)
    while not Path(path).exists():
        assert time.monotonic() < deadline, f"the suite's server {path} never answered"
        time.sleep(0.2)
    out = tmp_path / "out"
    r = immerse("run", CASES / "embedded_piston_sod", "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr

    def rows():   # this job's processes (the server is shared by the suite's workers)
        lines = Path(f"{path}.log").read_text().splitlines()
        return [x for x in map(json.loads, lines) if str(out) in " ".join(x.get("args") or [])]

    deadline = time.monotonic() + 10   # (the CLI's row is written as it ends, after immerse returns)
    while len(rows()) < 4 and time.monotonic() < deadline:
        time.sleep(0.1)
    mine = rows()
    assert not [x for x in mine if "refused" in x], mine
    assert sorted(x["module"] for x in mine) == ["adapters.ale", "adapters.lagrange", "orchestrator.cli",
                                                 "orchestrator.coupler"], mine


def _command_cli(socket_path):
    if socket_path:
        return [sys.executable, "-S", str(prestart.STUB), "orchestrator.cli"]
    return [sys.executable, "-m", "orchestrator.cli"]
