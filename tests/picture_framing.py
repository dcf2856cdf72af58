"""How a picture of `immerse view` is framed, measured from its pixels (field pictures, pyvista) or
from its figure's bounding boxes (line plots, matplotlib): the domain fills most of the frame, the
title, the axis labels and the colour bar with its labels are clear of each other, and nothing is
cut at the picture's edges. Used by tests/cases/test_pictures.py on every shipped case and by
tests/orchestrator/test_view.py on synthetic outputs."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INK = 0.85           # a pixel darker than this in any channel is drawn (the background is white)
SATURATED = 0.15     # viridis is saturated (max - min channel); black text, white and grey are not


@dataclass
class Framing:
    """Fractions of the picture (rows from its top, columns from its left)."""
    domain: tuple[float, float, float, float]   # top, bottom, left, right of the coloured domain
    bar: tuple[float, float]                    # top, bottom of the colour bar
    title_bottom: float                         # first blank row under the title's text
    bar_labels: int                             # separate label groups under the bar
    edge_ink: bool                              # something drawn on the picture's outermost pixels

    @property
    def width(self) -> float:
        return self.domain[3] - self.domain[2]

    @property
    def height(self) -> float:
        return self.domain[1] - self.domain[0]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the runs of True in a 1-D mask."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def field_picture_framing(png) -> Framing:
    """Measures a field picture (pyvista): the colour bar is the band of saturated rows in the
    picture's lowest quarter that spans more than a quarter of its width; the domain, the
    saturated pixels above it."""
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"), dtype=float) / 255.0
    h, w = img.shape[:2]
    ink = img.min(axis=2) < INK
    sat = img.max(axis=2) - img.min(axis=2) > SATURATED
    wide = sat.sum(axis=1) > 0.25 * w
    wide[: int(0.75 * h)] = False
    bands = _runs(wide)
    assert bands, f"{png}: no colour bar in the lowest quarter"
    bar_top, bar_bottom = bands[-1]
    rows, cols = np.nonzero(sat[: bar_top - 1])
    assert rows.size, f"{png}: no coloured domain above the colour bar"
    blank = ~ink.any(axis=1)
    title_bottom = int(np.argmax(blank[1:])) + 1     # the first blank row after the title's text
    # the bar's tick labels: the first band of text under the bar, split where 4+ blank columns part it
    under = _runs(ink[bar_bottom:].any(axis=1))
    labels = 0
    if under:
        r0, r1 = under[0]
        text_cols = ink[bar_bottom + r0: bar_bottom + r1].any(axis=0)
        # a label's characters stand a few pixels apart, two labels tens of pixels
        inner = sum(1 for a, b in _runs(~text_cols) if b - a < 0.01 * w and a > 0 and b < w)
        labels = len(_runs(text_cols)) - inner
    edge = ink[0].any() or ink[-1].any() or ink[:, 0].any() or ink[:, -1].any()
    return Framing((rows.min() / h, rows.max() / h, cols.min() / w, cols.max() / w),
                   (bar_top / h, bar_bottom / h), title_bottom / h, labels, bool(edge))


def assert_field_picture_framed(png, planar: bool, n_labels: int = 5) -> Framing:
    """A planar domain fills at least 75 % of the width or 55 % of the height (view.FRAME spans 82 %
    and 60 %); a 3-D view at least 45 % of either (isometric, zoomed out for its axis titles); the
    domain lies under the title and ends at least 5 % of the height above the colour bar (room for
    its axis labels); the bar's tick labels are ``n_labels`` separate groups (not run together);
    nothing is drawn on the picture's outermost pixels (nothing cut)."""
    f = field_picture_framing(png)
    fill_w, fill_h = (0.75, 0.55) if planar else (0.45, 0.45)
    assert f.width >= fill_w or f.height >= fill_h, f"{png}: domain fills {f.width:.2f} x {f.height:.2f}"
    assert f.domain[0] > f.title_bottom, f"{png}: domain top {f.domain[0]:.3f} under title {f.title_bottom:.3f}"
    assert f.bar[0] - f.domain[1] > 0.05, f"{png}: domain bottom {f.domain[1]:.3f}, colour bar {f.bar[0]:.3f}"
    assert f.bar_labels == n_labels, f"{png}: {f.bar_labels} colour-bar label groups, {n_labels} labels"
    assert not f.edge_ink, f"{png}: drawn up to the picture's edge (cut)"
    return f


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def assert_line_figure_framed(fig) -> None:
    """A line plot's texts (title, axis labels, tick labels) and its legend lie inside the figure
    and clear of each other (their display bounding boxes); the axes fill most of the figure."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)   # as savefig draws it
    canvas.draw()
    renderer = canvas.get_renderer()
    frame = fig.bbox
    ax = fig.axes[0]
    boxes = [("title", ax.title.get_window_extent(renderer)),
             ("xlabel", ax.xaxis.label.get_window_extent(renderer)),
             ("ylabel", ax.yaxis.label.get_window_extent(renderer))]
    for name, axis, (lo, hi) in (("xtick", ax.xaxis, ax.get_xlim()), ("ytick", ax.yaxis, ax.get_ylim())):
        lo, hi = min(lo, hi), max(lo, hi)
        boxes += [(f"{name} {t.label1.get_text()}", t.label1.get_window_extent(renderer))
                  for t in axis.get_major_ticks()   # those drawn: inside the axis's limits
                  if lo <= t.get_loc() <= hi and t.label1.get_visible() and t.label1.get_text()]
    legend = ax.get_legend()
    for name, b in boxes:
        assert frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1, \
            f"{name} {b} outside the figure {frame}"
    for i, (n1, b1) in enumerate(boxes):
        for n2, b2 in boxes[i + 1:]:
            assert not _overlap(b1, b2), f"{n1} overlaps {n2}"
    if legend is not None:
        lb = legend.get_window_extent(renderer)
        for name, b in boxes:
            assert not _overlap(lb, b), f"legend overlaps {name}"
    a = ax.get_window_extent(renderer)
    assert a.width > 0.6 * frame.width and a.height > 0.6 * frame.height, (a, frame)
