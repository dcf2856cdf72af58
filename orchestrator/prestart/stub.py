"""The small process that stands in for `python -m MODULE ARGS...` when a warm process server runs.

    python -S orchestrator/prestart/stub.py MODULE ARGS...

Standard library only, started without site (about 15 ms): it hands its inherited descriptors (stdin,
stdout, stderr and whatever its starter passed, such as hydra's PMI_FD), its environment, working
directory and arguments to the server named by IMMERSE_PRESTART (server.py), which forks a process
that already holds numpy, scipy, h5py, numba and the solver kernels and runs MODULE there. The stub
then stands for that process: signals sent to it are forwarded, its exit status is the process's
(a death by signal is repeated on itself), and its own death (SIGKILL included) ends the process
within a poll of the server's watcher. Without a server, or when the server refuses (another source
tree, an import-time environment it was not started with), it becomes the plain command (execv), so
the stub never changes what runs, only how fast it starts.
"""
import json
import os
import signal
import socket
import struct
import sys

ENV = "IMMERSE_PRESTART"
FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2)


def server_path() -> str | None:
    """The server's socket IMMERSE_PRESTART names; None when it is unset, empty or 0 (off)."""
    path = os.environ.get(ENV)
    return None if path in (None, "", "0") else path


def plain(module: str, args: list[str]) -> None:
    """Become `python -m MODULE ARGS...` (the same interpreter, with its site this time)."""
    os.execv(sys.executable, [sys.executable, "-m", module, *args])


def inherited_fds() -> list[int]:
    """Every descriptor this process holds now (the directory listing's own is closed again)."""
    listed = [int(n) for n in os.listdir("/proc/self/fd")]
    held = []
    for fd in listed:
        try:
            os.fstat(fd)
        except OSError:
            continue
        held.append(fd)
    return held


def attributes() -> dict:
    """What else a process inherits from its starter: ignored signals, umask, CPU affinity (hydra may
    bind ranks to cores), resource limits."""
    import resource

    mask = os.umask(0)
    os.umask(mask)
    limits = {name: resource.getrlimit(getattr(resource, name)) for name in dir(resource)
              if name.startswith("RLIMIT_")}
    return {"ignored": [int(s) for s in FORWARDED if signal.getsignal(s) == signal.SIG_IGN], "umask": mask,
            "affinity": sorted(os.sched_getaffinity(0)), "limits": limits}


def _line(sock: socket.socket, buf: bytearray) -> bytes | None:
    """The next newline-ended message from the server, None at end of stream."""
    while b"\n" not in buf:
        chunk = sock.recv(4096)
        if not chunk:
            return None
        buf += chunk
    i = buf.index(b"\n")
    line = bytes(buf[:i])
    del buf[:i + 1]
    return line


def main() -> None:
    module, args = sys.argv[1], sys.argv[2:]
    path = server_path()
    if path is None:
        plain(module, args)
    fds = inherited_fds()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    buf = bytearray()
    try:
        sock.connect(path)
        header = json.dumps({"module": module, "args": args, "cwd": os.getcwd(), "env": dict(os.environ),
                             "fds": fds, **attributes()}).encode()
        socket.send_fds(sock, [struct.pack("!Q", len(header))], fds)
        sock.sendall(header)
        reply = _line(sock, buf)
    except OSError:
        reply = None
    if reply is None or not reply.startswith(b"R "):
        sock.close()
        plain(module, args)

    def forward(signum, _frame):
        try:
            sock.send(bytes([signum]))
        except OSError:
            pass

    for s in FORWARDED:
        signal.signal(s, forward)
    while True:
        try:
            line = _line(sock, buf)
        except OSError:
            line = None
        if line is None:  # the watcher is gone without a word: the process's fate is unknown
            print(f"immerse prestart: lost the watcher of `python -m {module}` (pid {reply[2:].decode()})",
                  file=sys.stderr, flush=True)
            os._exit(1)
        kind, _, value = line.partition(b" ")
        if kind == b"X":
            os._exit(int(value))
        if kind == b"S":
            sig = int(value)
            signal.signal(sig, signal.SIG_DFL)
            os.kill(os.getpid(), sig)
            os._exit(128 + sig)  # a signal that does not end a process by default


if __name__ == "__main__":
    main()
