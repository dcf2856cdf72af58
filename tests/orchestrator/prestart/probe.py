"""A module the prestart tests run both through the stub and as `python -m`: it reports what it was
given and does what its first argument says."""
import json
import os
import signal
import sys
import time

WARM = "numba" in sys.modules  # imported before this module ran: the process came from the server


def main(argv: list[str]) -> None:
    what = argv[0]
    if what == "report":
        fd_env = os.environ.get("PROBE_FD")
        if fd_env:  # an extra descriptor handed down by the starter (as hydra hands PMI_FD)
            os.write(int(fd_env), b"through the extra descriptor\n")
        import resource

        mask = os.umask(0)
        print(json.dumps({"argv": argv, "cwd": os.getcwd(), "probe_env": os.environ.get("PROBE_VALUE"),
                          "main": __name__, "warm": WARM, "stdin": sys.stdin.read(), "umask": mask,
                          "nofile": resource.getrlimit(resource.RLIMIT_NOFILE)[0],
                          "affinity": sorted(os.sched_getaffinity(0)),
                          "sigusr1_ignored": signal.getsignal(signal.SIGUSR1) == signal.SIG_IGN}))
        print("to stderr", file=sys.stderr)
        sys.exit(int(argv[1]))
    if what == "exit-message":
        sys.exit("a message for stderr")
    if what == "raise":
        raise RuntimeError("raised by the probe")
    if what == "hooked-raise":  # as a rank's fault handler does (adapters/protocol.py)
        sys.excepthook = lambda kind, value, tb: print(f"hooked: {kind.__name__}: {value}", file=sys.stderr)
        raise RuntimeError("raised past a hook")
    if what == "interrupt":
        raise KeyboardInterrupt
    if what == "kill-self":
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)
    if what == "wait":  # write the pid, then wait for a signal (SIGTERM handled: exit 7)
        signal.signal(signal.SIGTERM, lambda *_: (print("got SIGTERM", flush=True), os._exit(7)))
        with open(argv[1], "w") as f:
            f.write(str(os.getpid()))
        time.sleep(60)
        sys.exit(9)


if __name__ == "__main__":
    main(sys.argv[1:])
