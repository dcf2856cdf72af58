"""A real single-node Slurm cluster for tests: munged + slurmctld + slurmd, started as root from a
scratch directory and stopped again afterwards (stdlib only; nothing from the project).

    reason = slurm_available()          # None, or a one-line reason to skip
    with single_node_slurm(tmp_path) as env:
        run = lambda *a: subprocess.run(a, env=command_env(env), capture_output=True, text=True)
        job = run("sbatch", "--parsable", "--array=0-2", "job.sh").stdout.strip()

Tested with Debian 12's `slurm-wlm` 22.05.8 and `munge` 0.5.15, as root on a machine without
systemd (no init system that reaps quickly: killed daemons may show as <defunct> for a moment).

Where everything lives (all under `workdir`, nothing in /etc or /var):
  etc/slurm.conf            found by every Slurm daemon and command through the SLURM_CONF
                            environment variable (the compiled-in default would be
                            /etc/slurm/slurm.conf; Slurm looks for the other config files -
                            cgroup.conf, plugstack.conf, ... - in the directory of slurm.conf, and
                            none of them is needed with the plugins chosen here)
  munge/munge.key           a fresh random key (mode 0400); munged runs with its own
                            --key-file/--socket/--pid-file/--log-file/--seed-file
  munge/socket/munge.socket the socket; Slurm is pointed at it by `AuthInfo=socket=...` in
                            slurm.conf, so clients need no munge variable of their own (libmunge
                            reads none).  munged insists that every directory above its socket
                            is searchable by all (o+x) and a Unix socket path must stay below
                            108 bytes: pytest's tmp_path lies under /tmp/pytest-of-root (mode
                            0700), so there the socket goes to a private `munge-*` directory
                            (0755) in the system temp dir instead, removed again on exit.
  spool/ctld, spool/d       StateSaveLocation, SlurmdSpoolDir
  run/*.pid, log/*.log      pid files and logs of the three daemons
  log/jobcomp.txt           the job completion log (jobcomp/filetxt, see below)

The yielded dict holds what a caller must add to the environment of sbatch/squeue/sacct/scontrol/
scancel/sinfo: only SLURM_CONF (no munge variable is needed, see above).  `command_env(env)` builds
such an environment from os.environ without any SLURM_*/SBATCH_*/... variables a surrounding real
Slurm job might have set, with /usr/sbin on PATH.  Batch jobs get the submitter's environment
(sbatch's default --export=ALL), so they see SLURM_CONF too.  The ports are picked free at start, so a system Slurm (6817/6818) or a
second test cluster does not collide.

Config choices that matter in a container without systemd/cgroups (see `_slurm_conf`):
  ProctrackType=proctrack/linuxproc, TaskPlugin=task/none, JobAcctGatherType=jobacct_gather/none
      nothing touches cgroups, so no cgroup.conf is needed;
  SlurmUser=root, SlurmdUser=root; AuthType=auth/munge with AuthInfo=socket=<our socket>;
  SelectType=select/cons_tres + CR_Core: array tasks of one CPU run side by side (select/linear
      would give each task the whole node);
  SlurmctldHost=<short hostname>(127.0.0.1), NodeName=<short hostname> NodeAddr=127.0.0.1: the
      controller must be named by `hostname -s`; the address avoids any DNS;
  ReturnToService=2: the node comes up idle at its first registration;
  SlurmdParameters=config_overrides: the node is not drained if slurmd counts fewer CPUs or less
      memory than configured (CPUs = os.cpu_count(), RealMemory = 90 % of MemTotal);
  SchedulerParameters=batch_sched_delay=0: a submitted batch job starts within ~1 s instead of
      ~3 s (the first job after the start still waits ~3 s: slurmctld's first scheduling pass);
  MailProg=/bin/true: Debian has no /bin/mail, slurmctld would log an error;
  MinJobAge=3600: finished jobs stay in slurmctld's memory for an hour, so `scontrol show job`
      still knows them;
  AccountingStorageType=accounting_storage/none (no slurmdbd) but JobCompType=jobcomp/filetxt.

Reading the state and exit code of an array task (<jobid> = what `sbatch --parsable` printed,
before any ";cluster"):
  * pending/running: `squeue -h -r -j <jobid> -o "%i %T"` (-r: one line per task, ids
    <jobid>_<task>; %A gives the task's own job id).  A finished task leaves squeue's default
    output at once, a job that is no longer known at all makes squeue fail ("Invalid job id").
  * finished, method 1 - scontrol (works while slurmctld runs, for MinJobAge = 3600 s after the
    end): `scontrol -o show job <jobid>` prints one line per task record with JobId= (the task's
    own id; the last task to start takes over <jobid> itself), ArrayJobId=, ArrayTaskId=,
    JobState= (COMPLETED, FAILED, CANCELLED, TIMEOUT, OUT_OF_MEMORY, NODE_FAIL, ...), Reason=
    (NonZeroExitCode for a FAILED task) and ExitCode=<exit status>:<signal> (3:0 for `exit 3`;
    0:15 for a running job killed by scancel).  Tasks not started yet are grouped in one record
    whose ArrayTaskId is a range ("0-2", "1-2%1").  `array_task_states()` returns
    {task id: (JobState, ExitCode)} from it.
  * finished, method 2 - the job completion log (jobcomp/filetxt, JobCompLoc=log/jobcomp.txt):
    one `key=value ...` line per finished job or task, written by slurmctld when it ends, with
    JobId, ArrayJobId, ArrayTaskId, JobState, ExitCode, DerivedExitCode, Start/EndTime; it
    survives a slurmctld restart and MinJobAge.  `read_jobcomp(workdir)` parses it.
  * sacct: there is no slurmdbd, so AccountingStorageType=accounting_storage/none and plain
    `sacct` fails with "Slurm accounting storage is disabled" (exit 1).  `sacct -c` (--completion)
    reads the jobcomp/filetxt file instead and does give State and ExitCode, but in 22.05 it does
    not understand the array fields (stderr: "sacct: error: Unknown type ArrayJobId: ..."), shows
    every task under its own raw job id (JobID "7", not "5_2") and `-j <jobid>` selects only the
    record whose raw id is <jobid>.  So `sacct -c -n -P -j <raw id> -o JobID,State,ExitCode`
    works per task once the raw id is known (JobId= in scontrol, %A in squeue), but it cannot
    list the tasks of an array; use method 1 or 2 for that.
"""
from __future__ import annotations

import contextlib
import os
import pathlib
import secrets
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator

DAEMONS = ("munged", "slurmctld", "slurmd")
COMMANDS = ("sbatch", "squeue", "scontrol", "sinfo", "scancel", "sacct", "munge")
_SBIN = ("/usr/sbin", "/sbin", "/usr/local/sbin", "/usr/bin", "/usr/local/bin")
# variables a surrounding Slurm job or a user's shell may set that would change what our commands do
_FOREIGN_PREFIXES = ("SLURM_", "SBATCH_", "SALLOC_", "SRUN_", "SQUEUE_", "SACCT_", "SINFO_", "SCONTROL_",
                     "SCANCEL_", "MUNGE_")
START_TIMEOUT = 30.0
STOP_TIMEOUT = 15.0
_MAX_SOCKET_PATH = 100  # sockaddr_un.sun_path holds 108 bytes including the NUL


class SlurmClusterError(RuntimeError):
    """The cluster did not come up (the message carries the tails of the daemons' logs)."""


def _which(name: str) -> str | None:
    path = shutil.which(name)
    if path:
        return path
    for d in _SBIN:
        candidate = os.path.join(d, name)
        if os.access(candidate, os.X_OK):
            return candidate
    return None


def slurm_available() -> str | None:
    """None when `single_node_slurm` can run here, else a one-line reason (for pytest.skip)."""
    if not hasattr(os, "geteuid"):
        return "a Slurm test cluster needs a POSIX system"
    if os.geteuid() != 0:
        return "a Slurm test cluster needs root (slurmd runs jobs as their user; SlurmUser=root)"
    missing = [n for n in DAEMONS + COMMANDS if _which(n) is None]
    if missing:
        return ("Slurm/munge not installed (missing " + ", ".join(missing)
                + "; apt-get install slurm-wlm munge)")
    return None


def command_env(cluster_env: dict[str, str], base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment for a Slurm command against the test cluster: `base` (default os.environ)
    without Slurm/munge variables from outside, plus `cluster_env` (what single_node_slurm yielded)."""
    env = {k: v for k, v in (os.environ if base is None else base).items()
           if not k.startswith(_FOREIGN_PREFIXES)}
    path = env.get("PATH", "")
    for d in ("/usr/sbin", "/sbin"):  # slurmd/slurmctld live in sbin, not always on a test's PATH
        if d not in path.split(os.pathsep):
            path = path + os.pathsep + d if path else d
    env["PATH"] = path
    env.update(cluster_env)
    return env


def _free_ports(n: int) -> list[int]:
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind(("", 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _real_memory_mb() -> int:
    """A bit (10 %, at least 256 MB) below the machine's memory as slurmd sees it (MemTotal)."""
    total_kb = 0
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    total_kb = int(line.split()[1])
                    break
    total_mb = total_kb // 1024
    if total_mb <= 0:
        return 1000
    return max(1, min(int(total_mb * 0.9), total_mb - 256))


def _slurm_conf(*, host: str, ctld_port: int, slurmd_port: int, socket_path: pathlib.Path,
                wd: pathlib.Path, cpus: int, memory_mb: int) -> str:
    return f"""\
# written by tests/orchestrator/campaign/slurm_cluster.py for one test cluster
ClusterName=immersetest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket_path}
SlurmUser=root
SlurmdUser=root
StateSaveLocation={wd / 'spool' / 'ctld'}
SlurmdSpoolDir={wd / 'spool' / 'd'}
SlurmctldPidFile={wd / 'run' / 'slurmctld.pid'}
SlurmdPidFile={wd / 'run' / 'slurmd.pid'}
SlurmctldLogFile={wd / 'log' / 'slurmctld.log'}
SlurmdLogFile={wd / 'log' / 'slurmd.log'}
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc={wd / 'log' / 'jobcomp.txt'}
SwitchType=switch/none
MpiDefault=none
MailProg=/bin/true
SchedulerType=sched/builtin
SchedulerParameters=batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmdParameters=config_overrides
MinJobAge=3600
KillWait=5
InactiveLimit=0
Waittime=0
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={memory_mb} State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def _tail(path: pathlib.Path, lines: int = 15) -> str:
    try:
        text = path.read_text(errors="replace").splitlines()
    except OSError:
        return f"  ({path.name}: none)"
    return "\n".join(f"  {path.name}: {line}" for line in text[-lines:])


def _searchable_by_all(path: pathlib.Path) -> bool:
    for d in (path, *path.parents):
        try:
            if not os.stat(d).st_mode & 0o001:
                return False
        except OSError:
            return False
    return True


def _read_pid(pid_file: pathlib.Path) -> int | None:
    try:
        return int(pid_file.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _alive(pid: int) -> bool:
    """True while `pid` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            state = f.read().rsplit(")", 1)[1].split()[0]
        return state not in ("Z", "X")
    except (OSError, IndexError):
        return False


def _job_processes(conf: str) -> list[int]:
    """Pids of the job side of the cluster whose slurm.conf is `conf`: slurmstepd (started by our
    slurmd, so its environment has our SLURM_CONF) and the job processes (SLURM_JOB_ID set by
    slurmstepd, SLURM_CONF ours).  The caller's own processes with our SLURM_CONF are not among
    them; neither is this process."""
    needle = f"SLURM_CONF={conf}".encode()
    found = []
    me = os.getpid()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == me:
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                environ = f.read().split(b"\0")
            if needle not in environ:
                continue
            with open(f"/proc/{entry}/comm", "rb") as f:
                comm = f.read().strip()
        except OSError:
            continue
        if comm == b"slurmstepd" or any(v.startswith(b"SLURM_JOB_ID=") for v in environ):
            found.append(int(entry))
    return found


def cluster_processes(cluster_env: dict[str, str]) -> list[int]:
    """Pids of the live slurmstepd and job processes of the cluster of `cluster_env` - none
    once `single_node_slurm` has exited."""
    return [p for p in _job_processes(cluster_env["SLURM_CONF"]) if _alive(p)]


def _stop_pids(pids: list[int], timeout: float) -> None:
    """SIGTERM, wait up to `timeout`, then SIGKILL what is left and wait for it to be gone."""
    pids = [p for p in pids if _alive(p)]
    for p in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(p, signal.SIGTERM)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    for p in pids:
        if _alive(p):
            with contextlib.suppress(ProcessLookupError):
                os.kill(p, signal.SIGKILL)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.05)


class _Cluster:
    def __init__(self, workdir: pathlib.Path):
        self.wd = workdir.resolve()
        self.pids: dict[str, int] = {}
        self.socket_dir: pathlib.Path | None = None
        self.env: dict[str, str] = {}

    # -- helpers
    def run(self, *args: str, timeout: float = 10) -> subprocess.CompletedProcess:
        return subprocess.run([_which(args[0]) or args[0], *args[1:]], env=self.env, capture_output=True,
                              text=True, timeout=timeout, stdin=subprocess.DEVNULL)

    def logs(self) -> str:
        log = self.wd / "log"
        return "\n".join(_tail(log / n) for n in ("munged.log", "munged.out", "slurmctld.log",
                                                   "slurmctld.out", "slurmd.log", "slurmd.out"))

    def fail(self, what: str) -> SlurmClusterError:
        return SlurmClusterError(f"{what}\n{self.logs()}")

    def start_daemon(self, name: str, args: list[str], pid_file: pathlib.Path, deadline: float) -> None:
        out = self.wd / "log" / f"{name}.out"
        with open(out, "ab") as f:
            proc = subprocess.Popen([_which(name) or name, *args], env=self.env, stdin=subprocess.DEVNULL,
                                    stdout=f, stderr=subprocess.STDOUT, start_new_session=True, cwd=self.wd)
        # the daemon forks away from `proc`; `proc` exits non-zero when the start failed
        try:
            rc = proc.wait(timeout=max(1.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            raise self.fail(f"{name} did not daemonize in time") from None
        if rc != 0:
            raise self.fail(f"{name} exited with {rc} at start")
        while time.monotonic() < deadline:
            pid = _read_pid(pid_file)
            if pid and _alive(pid) and name in _cmdline(pid):
                self.pids[name] = pid
                return
            time.sleep(0.05)
        raise self.fail(f"{name} wrote no pid file {pid_file}")

    # -- start
    def start(self) -> dict[str, str]:
        wd = self.wd
        for sub in ("etc", "munge", "munge/socket", "spool/ctld", "spool/d", "run", "log"):
            (wd / sub).mkdir(parents=True, exist_ok=True)
        # munged refuses group/other-writable directories on the way to its files, and wants the
        # socket's directory and all above it searchable by everyone
        for d in ("munge", "run", "log"):
            os.chmod(wd / d, 0o700 if d != "munge" else 0o711)
        os.chmod(wd / "munge" / "socket", 0o755)
        socket_path = wd / "munge" / "socket" / "munge.socket"
        if len(os.fsencode(str(socket_path))) > _MAX_SOCKET_PATH or not _searchable_by_all(wd):
            # e.g. pytest's tmp_path lies under /tmp/pytest-of-root (mode 0700)
            self.socket_dir = pathlib.Path(tempfile.mkdtemp(prefix="munge-"))
            os.chmod(self.socket_dir, 0o755)
            socket_path = self.socket_dir / "munge.socket"
        key = wd / "munge" / "munge.key"
        if key.exists():
            key.unlink()
        fd = os.open(key, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o400)
        with os.fdopen(fd, "wb") as f:
            f.write(secrets.token_bytes(1024))

        host = socket.gethostname().split(".")[0]  # slurmctld accepts only its `hostname -s`
        ctld_port, slurmd_port = _free_ports(2)
        conf = wd / "etc" / "slurm.conf"
        conf.write_text(_slurm_conf(host=host, ctld_port=ctld_port, slurmd_port=slurmd_port,
                                    socket_path=socket_path, wd=wd, cpus=os.cpu_count() or 1,
                                    memory_mb=_real_memory_mb()))
        cluster_env = {"SLURM_CONF": str(conf)}
        self.env = command_env(cluster_env)

        deadline = time.monotonic() + START_TIMEOUT
        self.start_daemon("munged", ["--key-file", str(key), "--socket", str(socket_path),
                                     "--pid-file", str(wd / "run" / "munged.pid"),
                                     "--log-file", str(wd / "log" / "munged.log"),
                                     "--seed-file", str(wd / "munge" / "munged.seed"),
                                     "--num-threads", "2"],
                          wd / "run" / "munged.pid", deadline)
        while True:  # munged answers
            enc = subprocess.run([_which("munge"), "-n", "-S", str(socket_path)], capture_output=True,
                                 env=self.env, timeout=10)
            if enc.returncode == 0:
                break
            if time.monotonic() > deadline:
                raise self.fail("munged does not answer: " + enc.stderr.decode(errors="replace").strip())
            time.sleep(0.1)

        self.start_daemon("slurmctld", [], wd / "run" / "slurmctld.pid", deadline)
        while True:  # slurmctld answers
            r = self.run("scontrol", "ping")
            if r.returncode == 0 and "UP" in r.stdout:
                break
            if time.monotonic() > deadline:
                raise self.fail("slurmctld does not answer scontrol ping: " + (r.stdout + r.stderr).strip())
            time.sleep(0.2)

        self.start_daemon("slurmd", ["-N", host], wd / "run" / "slurmd.pid", deadline)
        state = ""
        while True:  # the node registered and is idle
            r = self.run("sinfo", "-h", "-N", "-o", "%T")
            state = r.stdout.strip()
            if r.returncode == 0 and state == "idle":
                break
            if time.monotonic() > deadline:
                raise self.fail(f"node not idle after {START_TIMEOUT:.0f} s (sinfo: {state!r} {r.stderr.strip()})")
            time.sleep(0.2)
        return cluster_env

    # -- stop
    def stop_daemon(self, name: str) -> None:
        pid = self.pids.get(name)
        if pid and name in _cmdline(pid):  # still ours (not a reused pid)
            _stop_pids([pid], STOP_TIMEOUT)

    def stop(self) -> None:
        conf = self.env.get("SLURM_CONF")
        if "slurmctld" in self.pids and _alive(self.pids["slurmctld"]):
            # end the jobs first so that slurmstepd and the job scripts go with them
            with contextlib.suppress(subprocess.SubprocessError, OSError):
                jobs = self.run("squeue", "-h", "-o", "%A", timeout=10).stdout.split()
                if jobs:
                    self.run("scancel", *sorted(set(jobs)), timeout=10)
                    deadline = time.monotonic() + 10
                    while time.monotonic() < deadline and self.run("squeue", "-h", "-o", "%A").stdout.strip():
                        time.sleep(0.2)
        for name in ("slurmd", "slurmctld"):
            self.stop_daemon(name)
        if conf:  # slurmstepd and job processes that outlived slurmd
            _stop_pids(_job_processes(conf), 3)
        self.stop_daemon("munged")
        if self.socket_dir is not None:
            shutil.rmtree(self.socket_dir, ignore_errors=True)


@contextlib.contextmanager
def single_node_slurm(workdir: pathlib.Path) -> Iterator[dict[str, str]]:
    """Start munged, slurmctld and slurmd configured from files in `workdir`; wait (at most
    START_TIMEOUT s) until the node is idle; yield the variables to add to the environment of
    Slurm commands (SLURM_CONF, ...; use `command_env(env)`).  On exit, also after an exception
    in the body or a failed start: cancel the jobs left, stop the daemons by their pids and wait
    until they are gone."""
    reason = slurm_available()
    if reason:
        raise SlurmClusterError(reason)
    cluster = _Cluster(pathlib.Path(workdir))
    try:
        yield cluster.start()
    finally:
        cluster.stop()


def parse_scontrol_jobs(text: str) -> list[dict[str, str]]:
    """The records of `scontrol -o show job ...` (one line each) as dicts of their key=value pairs.
    (Values with spaces, e.g. Command= or Comment=, are cut at the first space; the keys used to
    read states - JobId, ArrayJobId, ArrayTaskId, JobState, ExitCode, Reason - have none.)"""
    records = []
    for line in text.splitlines():
        fields = {}
        for token in line.split():
            key, sep, value = token.partition("=")
            if sep and key not in fields:
                fields[key] = value
        if fields:
            records.append(fields)
    return records


def array_task_states(env: dict[str, str], job_id: str) -> dict[str, tuple[str, str]]:
    """{task id: (JobState, ExitCode)} of one array job from `scontrol -o show job <job_id>`, e.g.
    {"0": ("COMPLETED", "0:0"), "2": ("FAILED", "3:0")}; tasks not started yet come as one range
    key such as "1-2"; a job that is no array gives {<job id>: (...)}.  `env` is what
    single_node_slurm yielded."""
    r = subprocess.run([_which("scontrol") or "scontrol", "-o", "show", "job", job_id], env=command_env(env),
                       capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        raise SlurmClusterError(f"scontrol show job {job_id}: {r.stderr.strip()}")
    return {rec.get("ArrayTaskId", rec.get("JobId", "")): (rec.get("JobState", ""), rec.get("ExitCode", ""))
            for rec in parse_scontrol_jobs(r.stdout)}


def read_jobcomp(workdir: pathlib.Path) -> list[dict[str, str]]:
    """The job completion records (jobcomp/filetxt, log/jobcomp.txt under the cluster's workdir),
    one dict per finished job or array task, in the order they finished: JobId (the task's own
    id), ArrayJobId and ArrayTaskId (array tasks only), JobState, ExitCode, DerivedExitCode,
    StartTime, EndTime, NodeList, WorkDir, ..."""
    path = pathlib.Path(workdir).resolve() / "log" / "jobcomp.txt"
    try:
        text = path.read_text(errors="replace")
    except FileNotFoundError:
        return []
    return parse_scontrol_jobs(text)
