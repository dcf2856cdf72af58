"""The headless-Chromium page check (tests/orchestrator/campaign/browser.py) on tiny local pages."""
from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest

from tests.orchestrator.campaign import browser
from tests.orchestrator.campaign.browser import check_page, chromium_path

pytestmark = [
    pytest.mark.timeout(120),
    pytest.mark.skipif(chromium_path() is None,
                       reason="no chromium on PATH (Debian: apt-get install -y "
                              "--no-install-recommends chromium)"),
]

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def write_png(path: Path, width: int = 4, height: int = 3, rgb=(200, 30, 30)) -> Path:
    """A small solid-colour RGB PNG, written by hand (zlib + struct)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    rows = b"".join(b"\0" + bytes(rgb) * width for _ in range(height))
    path.write_bytes(PNG_MAGIC + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
    return path


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


def page(tmp_path: Path, body: str, title: str = "t") -> Path:
    html = tmp_path / "page.html"
    html.write_text(f"<!doctype html><html><head><meta charset='utf-8'><title>{title}</title>"
                    f"</head><body>{body}</body></html>")
    return html


def test_valid_image_page_is_clean(tmp_path):
    write_png(tmp_path / "dot.png")
    # A tall page: the screenshot must cover all of it, not only the 1280x800 window.
    html = page(tmp_path, "<h1>Report</h1><img src='dot.png' width='40' height='30'>"
                          "<div style='height:2000px'></div><p>end</p>", title="Clean report")
    shot = tmp_path / "shot.png"
    report = check_page(html, shot)
    assert report.console_errors == []
    assert report.broken_images == []
    assert report.ok
    assert report.title == "Clean report"
    assert len(report.images) == 1
    img = report.images[0]
    assert img["src"].endswith("/dot.png") and img["complete"] and img["naturalWidth"] == 4
    assert shot.stat().st_size > 0
    width, height = png_size(shot)
    assert width >= 1000 and height >= 2000


def test_missing_image_is_broken_and_logged(tmp_path):
    write_png(tmp_path / "here.png")
    html = page(tmp_path, "<img src='here.png'><img src='figures/not_there.png'>")
    shot = tmp_path / "shot.png"
    report = check_page(html, shot)
    assert len(report.images) == 2
    assert len(report.broken_images) == 1 and report.broken_images[0].endswith(
        "/figures/not_there.png"), report.broken_images
    assert any("not_there.png" in e and "ERR_FILE_NOT_FOUND" in e for e in report.console_errors), \
        report.console_errors
    assert not report.ok
    assert png_size(shot)[0] > 0


def test_console_error_is_reported(tmp_path):
    report = check_page(page(tmp_path, "<p>x</p><script>console.error('boom')</script>"),
                        tmp_path / "shot.png")
    assert report.broken_images == []
    assert report.console_errors == ["boom"]
    assert not report.ok


def test_uncaught_exception_is_reported(tmp_path):
    html = page(tmp_path, "<p>x</p><script>throw new TypeError('kaboom in report')</script>"
                          "<script>console.log('not an error'); console.warn('nor this')</script>")
    report = check_page(html, tmp_path / "shot.png")
    assert len(report.console_errors) == 1, report.console_errors
    assert "TypeError: kaboom in report" in report.console_errors[0]
    assert not report.ok


def test_timeout_leaves_no_process(tmp_path, monkeypatch):
    """A page whose load never ends: TimeoutError, and the Chromium started is gone."""
    started = []
    real_start = browser._start

    def spy(exe, tmp, log):
        started.append((real_start(exe, tmp, log), tmp))
        return started[-1][0]
    monkeypatch.setattr(browser, "_start", spy)
    html = page(tmp_path, "<script>for (;;) {}</script>")
    with pytest.raises(TimeoutError):
        check_page(html, tmp_path / "shot.png", timeout=4)
    (proc, _, _), tmp = started[0]
    assert proc.returncode is not None
    assert browser._ours(proc.pid, tmp) == set()


def test_missing_html_raises(tmp_path):
    with pytest.raises(FileNotFoundError):
        check_page(tmp_path / "nope.html", tmp_path / "shot.png")
