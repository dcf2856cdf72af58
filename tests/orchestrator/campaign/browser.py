"""Load a local HTML page in headless Chromium and report what a person would see go wrong.

Stdlib only: Chromium is driven through its DevTools protocol over a pipe
(`--remote-debugging-pipe`): it reads commands from fd 3 and writes responses and events to
fd 4, each message a JSON object followed by a NUL byte.

    report = check_page(Path("report.html"), Path("report.png"))
    assert report.ok, (report.console_errors, report.broken_images)

`check_page` reports console.error calls, uncaught exceptions and the browser's own error log
entries (a missing image shows up there as "Failed to load resource: net::ERR_FILE_NOT_FOUND",
to which the URL is appended here), every <img> with its naturalWidth, and saves a full-page
screenshot. Chromium and all its child processes are ended before it returns, also on timeout
or error.
"""
from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

_CANDIDATES = ("chromium", "chromium-browser", "google-chrome")
_BASH = shutil.which("bash") or "/bin/bash"

# Longest screenshot taken (CSS pixels): a runaway page must not produce a gigantic PNG.
MAX_SCREENSHOT_HEIGHT = 16384

# Collects every <img> once it has settled: lazy images are made eager and awaited (bounded),
# so that an image below the fold is not reported broken just because it was never fetched.
_IMAGES_JS = """
(async () => {
  const imgs = Array.from(document.images);
  for (const i of imgs) { if (i.loading === 'lazy') i.loading = 'eager'; }
  const settle = i => i.complete ? null : new Promise(r => {
    i.addEventListener('load', r, {once: true});
    i.addEventListener('error', r, {once: true});
  });
  const pending = imgs.map(settle).filter(p => p);
  if (pending.length)
    await Promise.race([Promise.all(pending), new Promise(r => setTimeout(r, %d))]);
  return imgs.map(i => ({src: i.currentSrc || i.src, complete: i.complete,
                         naturalWidth: i.naturalWidth}));
})()
"""


@dataclass
class PageReport:
    console_errors: list[str] = field(default_factory=list)
    images: list[dict] = field(default_factory=list)
    broken_images: list[str] = field(default_factory=list)
    title: str = ""

    @property
    def ok(self) -> bool:
        """Loaded with no console error and every image resolved."""
        return not self.console_errors and not self.broken_images


class BrowserError(RuntimeError):
    """Chromium failed, answered a command with an error, or went away."""


def chromium_path() -> str | None:
    """Path of a Chromium/Chrome executable on PATH, or None."""
    for name in _CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


def _remote_text(obj: dict) -> str:
    """Readable text of a Runtime.RemoteObject (a console.error argument)."""
    if "value" in obj:
        v = obj["value"]
        return v if isinstance(v, str) else json.dumps(v)
    if "unserializableValue" in obj:
        return obj["unserializableValue"]
    return obj.get("description") or obj.get("type", "?")


def _exception_text(details: dict) -> str:
    exc = details.get("exception") or {}
    text = exc.get("description") or exc.get("value") or details.get("text") or "exception"
    where = details.get("url")
    if where and where not in str(text):   # a stack trace already names it
        text = f"{text} ({where}:{details.get('lineNumber', 0) + 1})"
    return f"Uncaught: {text}" if not str(text).startswith("Uncaught") else str(text)


class _Pipe:
    """One DevTools connection over Chromium's debugging pipe."""

    def __init__(self, write_fd: int, read_fd: int, deadline: float):
        self._w, self._r = write_fd, read_fd
        self.deadline = deadline
        self._buf = b""
        self._next_id = 0
        self.events: list[dict] = []   # every event received, in order
        self._replies: dict[int, dict] = {}

    def _remaining(self, what: str) -> float:
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError(f"headless Chromium: timed out waiting for {what}")
        return left

    def _pump(self, wait: float) -> bool:
        """Read what Chromium has written, waiting at most `wait` s; False if nothing came."""
        ready, _, _ = select.select([self._r], [], [], max(wait, 0.0))
        if not ready:
            return False
        chunk = os.read(self._r, 1 << 20)
        if not chunk:
            raise BrowserError("headless Chromium closed its DevTools pipe (did it crash?)")
        self._buf += chunk
        *messages, self._buf = self._buf.split(b"\0")
        for raw in messages:
            if not raw:
                continue
            msg = json.loads(raw)
            if "id" in msg:
                self._replies[msg["id"]] = msg
            else:
                self.events.append(msg)
        return True

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        self._next_id += 1
        msg: dict = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        data = json.dumps(msg).encode() + b"\0"
        while data:
            _, ready, _ = select.select([], [self._w], [], self._remaining(f"{method} to be sent"))
            if ready:
                data = data[os.write(self._w, data):]
        return self._next_id

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send a command and wait for its reply; events meanwhile go to self.events."""
        cid = self.send(method, params, session)
        while cid not in self._replies:
            self._pump(self._remaining(f"the reply to {method}"))
        reply = self._replies.pop(cid)
        if "error" in reply:
            err = reply["error"]
            raise BrowserError(f"{method}: {err.get('message')} {err.get('data', '')}".strip())
        return reply.get("result", {})

    def wait_event(self, accept, what: str, start: int = 0) -> int:
        """Index of the first event from events[start:] that `accept`s, reading until it comes."""
        i = start
        while True:
            while i < len(self.events):
                if accept(self.events[i]):
                    return i
                i += 1
            self._pump(self._remaining(what))

    def drain(self, quiet: float = 0.05) -> None:
        """Read events until Chromium has been quiet for `quiet` s (bounded by the deadline)."""
        while time.monotonic() < self.deadline and self._pump(quiet):
            pass


def _high_fd(fd: int) -> int:
    """Move `fd` to a free descriptor >= 10 (close-on-exec; pass_fds lifts that in the child)."""
    try:
        return fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10)
    finally:
        os.close(fd)


def _start(exe: str, tmp: str, log) -> tuple[subprocess.Popen, int, int]:
    """Start Chromium with the command pipe on its fd 3 and the reply pipe on its fd 4.

    Everything it writes (profile, crashpad database, cache) goes under `tmp`.
    Returns (process, fd we write commands to, fd we read replies from)."""
    cmd_r, cmd_w = os.pipe()
    rep_r, rep_w = os.pipe()
    # Chromium's ends go to fds >= 10 first, so that placing them on 3 and 4 cannot collide.
    cmd_r, rep_w = _high_fd(cmd_r), _high_fd(rep_w)
    args = [
        exe, "--headless=new", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
        f"--user-data-dir={tmp}/profile", "--no-first-run", "--no-default-browser-check",
        "--disable-extensions", "--disable-background-networking", "--disable-sync",
        "--disable-component-update", "--disable-default-apps", "--disable-breakpad",
        "--mute-audio", "--hide-scrollbars", "--window-size=1280,800",
        "--force-device-scale-factor=1", "about:blank",
    ]
    env = dict(os.environ, XDG_CONFIG_HOME=f"{tmp}/config", XDG_CACHE_HOME=f"{tmp}/cache")
    # A bash trampoline puts the two pipe ends on fds 3 and 4 and closes the originals before
    # exec'ing Chromium (subprocess cannot place inherited fds at given numbers by itself; dash
    # cannot redirect fds above 9).
    trampoline = f'exec 3<&{cmd_r} 4>&{rep_w} {cmd_r}<&- {rep_w}>&-; exec "$@"'
    try:
        proc = subprocess.Popen(
            [_BASH, "-c", trampoline, "bash", *args], stdin=subprocess.DEVNULL, stdout=log,
            stderr=subprocess.STDOUT, pass_fds=(cmd_r, rep_w), start_new_session=True, env=env)
    except BaseException:
        for fd in (cmd_r, cmd_w, rep_r, rep_w):
            os.close(fd)
        raise
    os.close(cmd_r)
    os.close(rep_w)
    return proc, cmd_w, rep_r


def _stop(proc: subprocess.Popen, pipe: _Pipe | None, tmp: str, grace: float = 5.0) -> None:
    """Browser.close, wait, kill whatever of this Chromium lingers, and reap the browser.

    "This Chromium" is its process group (it leads a session of its own, so the group id is its
    pid), plus any process whose command line names `tmp`: the crashpad handlers leave the
    group (setsid) but carry --database=<tmp>/config/...; zombies are left to init.
    The browser is reaped last: while it is an unreaped zombie its pid (the group id) cannot be
    reused, so signalling the group cannot hit a stranger."""
    if not _exited(proc) and pipe is not None:
        try:
            pipe.deadline = time.monotonic() + grace
            pipe.send("Browser.close")
        except (OSError, TimeoutError):
            pass
    end = time.monotonic() + grace
    while not _exited(proc) and time.monotonic() < end:
        time.sleep(0.02)
    # Its children normally exit by themselves once the browser is gone: give them a moment,
    # then SIGKILL what is left (the browser too, if it ignored Browser.close) and wait again.
    if not (_exited(proc) and _wait_gone(proc, tmp, 1.0)):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        for pid in _ours(proc.pid, tmp) - {proc.pid}:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        _wait_gone(proc, tmp, grace)
    proc.wait()


def _exited(proc: subprocess.Popen) -> bool:
    """Has the browser exited? (Does not reap it.)"""
    if proc.returncode is not None:
        return True
    try:
        return os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
    except ChildProcessError:
        return True


def _wait_gone(proc: subprocess.Popen, tmp: str, seconds: float) -> bool:
    """Wait up to `seconds` until no live process of this Chromium but the browser remains."""
    end = time.monotonic() + seconds
    while _ours(proc.pid, tmp) - {proc.pid}:
        if time.monotonic() > end:
            return False
        time.sleep(0.02)
    return True


def _ours(pgid: int, tmp: str) -> set[int]:
    """Live (not zombie) pids in process group `pgid` or whose command line contains `tmp`.

    Linux /proc; an empty set elsewhere."""
    found = set()
    needle = tmp.encode()
    try:
        entries = os.listdir("/proc")
    except OSError:
        return found
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                stat = f.read()
            fields = stat[stat.rfind(b")") + 2:].split()   # state, ppid, pgrp, ...
            if fields[0] in (b"Z", b"X"):
                continue
            if int(fields[2]) == pgid:
                found.add(int(entry))
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                if needle in f.read():
                    found.add(int(entry))
        except (OSError, IndexError, ValueError):
            continue
    return found


def check_page(html: Path, screenshot: Path, timeout: float = 30.0) -> PageReport:
    """Load `html` in headless Chromium; report console errors and images; save a screenshot.

    Raises FileNotFoundError if `html` does not exist, RuntimeError when no Chromium is found
    or it fails (BrowserError), TimeoutError past `timeout` seconds in all."""
    html = Path(html).resolve()
    screenshot = Path(screenshot)
    if not html.is_file():
        raise FileNotFoundError(html)
    exe = chromium_path()
    if exe is None:
        raise RuntimeError("no chromium / chromium-browser / google-chrome on PATH")
    deadline = time.monotonic() + timeout
    report = PageReport()

    with tempfile.TemporaryDirectory(prefix="immerse-chromium-") as tmp:
        log_path = os.path.join(tmp, "chromium.log")
        with open(log_path, "wb") as log:
            proc, cmd_w, rep_r = _start(exe, tmp, log)
        pipe = None
        try:
            pipe = _Pipe(cmd_w, rep_r, deadline)
            try:
                _drive(pipe, html, screenshot, report)
            except (BrowserError, TimeoutError) as exc:
                tail = Path(log_path).read_text(errors="replace")[-2000:]
                raise type(exc)(f"{exc}\n--- chromium output (tail) ---\n{tail}") from exc
        finally:
            try:
                _stop(proc, pipe, tmp)
            finally:
                os.close(cmd_w)
                os.close(rep_r)
    return report


def _drive(pipe: _Pipe, html: Path, screenshot: Path, report: PageReport) -> None:
    target = pipe.call("Target.createTarget", {"url": "about:blank"})["targetId"]
    sid = pipe.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for domain in ("Runtime", "Log", "Page"):
        pipe.call(f"{domain}.enable", session=sid)

    mark = len(pipe.events)
    nav = pipe.call("Page.navigate", {"url": html.as_uri()}, session=sid)
    if nav.get("errorText"):
        raise BrowserError(f"navigating to {html.as_uri()}: {nav['errorText']}")

    def ours(e):
        return e.get("sessionId") == sid

    # The load event that counts is the one after the main frame committed our file:// URL
    # (not the about:blank one the new target may still be firing).
    committed = pipe.wait_event(
        lambda e: ours(e) and e["method"] == "Page.frameNavigated"
        and not e["params"]["frame"].get("parentId")
        and e["params"]["frame"].get("url", "").startswith("file:"),
        "the page to be committed", mark)
    pipe.wait_event(lambda e: ours(e) and e["method"] == "Page.loadEventFired",
                    "Page.loadEventFired", committed + 1)

    settle_ms = int(max(0.0, min(5.0, (pipe.deadline - time.monotonic()) / 3)) * 1000)
    res = pipe.call("Runtime.evaluate", {"expression": _IMAGES_JS % settle_ms,
                                         "awaitPromise": True, "returnByValue": True},
                    session=sid)
    if "exceptionDetails" in res:
        raise BrowserError(f"collecting images: {_exception_text(res['exceptionDetails'])}")
    report.images = res["result"].get("value") or []
    report.broken_images = [i["src"] for i in report.images if not i.get("naturalWidth")]
    report.title = pipe.call("Runtime.evaluate", {"expression": "document.title",
                                                  "returnByValue": True},
                             session=sid)["result"].get("value") or ""

    metrics = pipe.call("Page.getLayoutMetrics", session=sid)
    size = metrics.get("cssContentSize") or metrics.get("contentSize") or {}
    width = max(1, int(size.get("width") or 1280))
    height = max(1, min(MAX_SCREENSHOT_HEIGHT, int(size.get("height") or 800)))
    shot = pipe.call("Page.captureScreenshot", {
        "format": "png", "captureBeyondViewport": True,
        "clip": {"x": 0, "y": 0, "width": width, "height": height, "scale": 1}}, session=sid)
    screenshot.parent.mkdir(parents=True, exist_ok=True)
    screenshot.write_bytes(base64.b64decode(shot["data"]))

    pipe.drain()
    report.console_errors = _errors(e for e in pipe.events if ours(e))


def _errors(events) -> list[str]:
    out: list[str] = []
    for e in events:
        method, p = e.get("method"), e.get("params", {})
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            out.append(" ".join(_remote_text(a) for a in p.get("args", [])) or p["type"])
        elif method == "Runtime.exceptionThrown":
            out.append(_exception_text(p.get("exceptionDetails", {})))
        elif method == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            entry = p["entry"]
            text, url = entry.get("text", ""), entry.get("url")
            out.append(f"{text} ({url})" if url and url not in text else text)
    return out
