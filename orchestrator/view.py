"""Pictures of output steps (PNG): line plots for 1-D runs, off-screen pyvista renderings otherwise.

render(out_dir) writes out/pictures/<role>_<field>_<index:06d>.png, one per (role, field, step).

* A run that is one zone (element) across in every direction but one (a shock tube, a bar) is drawn
  as a line plot (matplotlib) of the field along that axis, against the case's exact solution when
  its `[check]` kind has one (orchestrator.exact_profiles); vectors are drawn by their component
  along the axis, (n, 6) tensors by their normal component along it.
* Anything else is rendered with pyvista: vectors coloured by their magnitude, tensors by the von
  Mises equivalent, scalars as they are, with a colour bar and axes that carry units
  (orchestrator.units).

Unknown fields or steps are refused before anything is drawn (ViewError, one line listing what the
output holds).  VTK's own chatter (e.g. "bad X server connection" on a machine without a display)
never reaches the terminal: rendering goes to an off-screen EGL window where libEGL exists, and
VTK's log and warning output are switched off (captured into the error if rendering fails).
"""

from __future__ import annotations

import dataclasses

import ctypes.util
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import h5py
import numpy as np

from orchestrator.output import (TENSOR6_COMPONENTS, list_roles, read_mesh_file, read_step, read_steps,
                                 step_path, von_mises)
from orchestrator.run_record import case_of_run
from orchestrator.units import with_unit

__all__ = ["render", "scalar_field", "available", "line_profile", "line_figure", "ViewError",
           "PICTURES_DIR"]

PICTURES_DIR = "pictures"
_VTK_CELL = {"quad": 9, "hexahedron": 12, "vertex": 1}  # VTK_QUAD, VTK_HEXAHEDRON, VTK_VERTEX
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")
_AXES = "xyz"


class ViewError(ValueError):
    """A request the output cannot satisfy (unknown field or step): one line naming what exists."""


# ---------------------------------------------------------------------------------------------
# what an output holds
def _field_names(out: Path, role: str, index: int) -> tuple[list[str], list[str]]:
    with h5py.File(step_path(out, role, index), "r") as f:
        return sorted(f.get("point_data", {}).keys()), sorted(f.get("cell_data", {}).keys())


def available(out_dir) -> dict[str, dict]:
    """{role: {"fields": [names], "steps": [(time, step, index)]}} of every role with output."""
    out = Path(out_dir)
    found = {}
    for r in list_roles(out):
        steps = read_steps(out, r)
        if steps:
            pd, cd = _field_names(out, r, steps[0][2])
            found[r] = {"fields": pd + cd, "steps": steps}
    return found


def listing(out_dir) -> str:
    """What `immerse view OUT --list` prints: per role its fields (with units) and its output steps
    (index, step, time)."""
    from orchestrator.units import unit_of

    lines = []
    for r, info in available(out_dir).items():
        fields = [f + (f" ({'-' if u == '1' else u})" if (u := unit_of(f)) else "") for f in info["fields"]]
        lines.append(f"{r}: fields {', '.join(fields)}")
        steps = ", ".join(f"{i}: {s}, {t:.6g} s" for t, s, i in info["steps"])
        lines.append(f"{r}: steps (index: step, time) {steps}")
    return "\n".join(lines)


def _ranges(indices: Sequence[int]) -> str:
    """[0, 1, 2, 3, 7] -> "0-3, 7"."""
    parts, i = [], 0
    while i < len(indices):
        j = i
        while j + 1 < len(indices) and indices[j + 1] == indices[j] + 1:
            j += 1
        parts.append(str(indices[i]) if i == j else f"{indices[i]}-{indices[j]}")
        i = j + 1
    return ", ".join(parts)


def _holdings(found: dict, what: str) -> str:
    if what == "fields":
        return "; ".join(f"{r}: {', '.join(v['fields'])}" for r, v in found.items())
    return "; ".join(f"{r}: {_ranges([s[2] for s in v['steps']])} (or first, last, all)"
                     for r, v in found.items())


def _select_steps(available_steps: list[tuple[float, int, int]], wanted: Iterable) -> list[tuple[float, int, int]]:
    """The output steps named by `wanted` ('first', 'last', 'all' or output indices).
    Raises ViewError naming the first entry that names no step (with the role's caller context)."""
    by_index = {s[2]: s for s in available_steps}
    chosen: list[tuple[float, int, int]] = []
    for w in wanted:
        if isinstance(w, str) and w.strip().lstrip("-").isdigit():
            w = int(w)  # e.g. from the command line
        if w == "last":
            picks = available_steps[-1:]
        elif w == "first":
            picks = available_steps[:1]
        elif w == "all":
            picks = available_steps
        elif isinstance(w, (int, np.integer)) and not isinstance(w, bool):
            if int(w) not in by_index:
                raise ViewError(f"--step {w}: no output step with that index")
            picks = [by_index[int(w)]]
        else:
            raise ViewError(f"--step {w!r}: must be first, last, all or an output index")
        chosen.extend(p for p in picks if p not in chosen)
    return chosen


# ---------------------------------------------------------------------------------------------
# values to draw
def _tensor_von_mises(a: np.ndarray) -> np.ndarray:
    if a.shape[1] == 6:
        return von_mises(a)
    t = a.reshape(len(a), 3, 3)
    s = t - np.trace(t, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3.0
    return np.sqrt(1.5 * np.einsum("nij,nij->n", s, s))


def scalar_field(name: str, values) -> tuple[str, np.ndarray]:
    """(label, one value per row) used to colour a field."""
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 1:
        return name, a
    a = a.reshape(len(a), -1)
    if a.shape[1] == 1:
        return name, a[:, 0]
    if a.shape[1] in (6, 9):
        return f"{name}, von Mises", _tensor_von_mises(a)
    return f"{name} magnitude", np.linalg.norm(a, axis=1)


def _axial(name: str, values, axis: int) -> tuple[str, np.ndarray]:
    """(label, one value per row) of a field along `axis`: vectors by that component, tensors by
    their normal component along it, scalars as they are."""
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 1:
        return name, a
    a = a.reshape(len(a), -1)
    if a.shape[1] == 1:
        return name, a[:, 0]
    c = _AXES[axis]
    if a.shape[1] == 6:
        return f"{name} {c}{c}", a[:, TENSOR6_COMPONENTS.index(c + c)]
    if a.shape[1] == 9:
        return f"{name} {c}{c}", a[:, 4 * axis]
    return f"{name} {c}", a[:, axis]


TUBE_CELLS_ACROSS = 4
TUBE_ASPECT = 20.0


def one_d_axis(points: np.ndarray, cells: np.ndarray) -> int | None:
    """The axis of a mesh that is one cell across in every other direction, or a tube (at most
    TUBE_CELLS_ACROSS cells across and TUBE_ASPECT times longer than wide: a shock tube with a few
    rows, whose field picture is a line), else None."""
    centres = points[cells].mean(axis=1)
    span = float(np.max(np.ptp(points, axis=0))) or 1.0
    across = [len(np.unique(np.round(centres[:, d] / span, 9))) for d in range(3)]
    varying = [d for d in range(3) if across[d] > 1]
    if len(varying) == 1 and len(cells) > 1:
        return varying[0]
    extent = np.ptp(points, axis=0)
    long = int(np.argmax(extent))
    others = [d for d in varying if d != long]
    if (others and all(across[d] <= TUBE_CELLS_ACROSS for d in others)
            and extent[long] >= TUBE_ASPECT * max(extent[d] for d in others)):
        return long
    return None


@dataclass
class LineProfile:
    """A 1-D picture's data: the computed values along the axis and, if the case has one, the
    exact solution at the same time."""
    role: str
    field: str
    axis: int
    time: float
    step: int
    x: np.ndarray
    values: np.ndarray
    label: str  # e.g. "velocity x"
    exact_x: np.ndarray | None = None
    exact_values: np.ndarray | None = None
    exact_label: str | None = None
    bodies: list = dataclasses.field(default_factory=list)  # [(role, lo, hi)] along the axis

    @property
    def xlabel(self) -> str:
        return f"{_AXES[self.axis]} (m)"

    @property
    def ylabel(self) -> str:
        return with_unit(self.label, self.field)


def _stations(coord0: np.ndarray, coord: np.ndarray, values: np.ndarray):
    """Average rows that share a station (same initial coordinate along the axis)."""
    span = float(np.ptp(coord0)) or 1.0
    keys, inv = np.unique(np.round(coord0 / span, 9), return_inverse=True)
    n = np.bincount(inv)
    x = np.bincount(inv, weights=coord) / n
    v = np.bincount(inv, weights=values) / n
    order = np.argsort(x)
    return x[order], v[order]


def line_profile(out_dir, role: str, field: str, index: int, axis: int, case=None) -> LineProfile:
    """The profile of `field` along `axis` at output step `index` (see LineProfile)."""
    out = Path(out_dir)
    steps = {s[2]: s for s in read_steps(out, role)}
    time, step, _ = steps[index]
    cells, _ = read_mesh_file(out, role)
    first = min(steps)
    points0 = read_step(out, role, first)[0]
    points, pd, cd = read_step(out, role, index)
    if field in pd:
        label, v = _axial(field, pd[field], axis)
        x, vals = _stations(points0[:, axis], points[:, axis], v)
    else:
        label, v = _axial(field, cd[field], axis)
        x, vals = _stations(points0[cells].mean(axis=1)[:, axis], points[cells].mean(axis=1)[:, axis], v)
    prof = LineProfile(role, field, axis, time, step, x, vals, label)
    c = _AXES[axis]
    if case is not None and label in (field, f"{field} {c}", f"{field} {c}{c}"):
        from orchestrator.exact_profiles import exact_profile

        try:
            ex = exact_profile(case, time)
        except (KeyError, ValueError, TypeError):
            ex = None  # the check's parameters do not describe a profile at this time
        if ex is not None and ex.axis == axis:
            xs = np.linspace(float(points[:, axis].min()), float(points[:, axis].max()), 2001)
            sampled = ex.sample(xs)
            if field in sampled:
                prof.exact_x, prof.exact_values, prof.exact_label = xs, np.asarray(sampled[field]), ex.label
    return prof


def line_figure(prof: LineProfile, size: tuple[int, int] = (1024, 768), ylim=None):
    """A matplotlib Figure of a LineProfile (computed: markers and line; exact: black line);
    ``ylim``: the value axis's range (one range for every frame of a sequence), None: its own."""
    from matplotlib.figure import Figure

    dpi = 100
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    ax = fig.add_subplot()
    if prof.exact_x is not None:
        ax.plot(prof.exact_x, prof.exact_values, color="black", linewidth=1.2, label=prof.exact_label,
                zorder=3)
    ax.plot(prof.x, prof.values, color="tab:blue", marker="o", markersize=2.5, linewidth=0.8,
            label=f"{prof.role} ({len(prof.x)} stations)", zorder=2)
    shades = {}
    for role, lo, hi in prof.bodies:  # coupled bodies in the background: one shade and legend entry a role
        first = role not in shades
        shades.setdefault(role, ("tab:grey", "tab:brown", "tab:olive", "tab:pink")[len(shades) % 4])
        ax.axvspan(lo, hi, color=shades[role], alpha=0.35, zorder=1, label=f"{role} body" if first else None)
    if ylim is not None:
        ax.set_ylim(*ylim)
    ax.set_xlabel(prof.xlabel)
    ax.set_ylabel(prof.ylabel)
    ax.set_title(f"{prof.role}: {prof.label}, t = {prof.time:.6g} s (step {prof.step})")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------------
# pyvista
def _quiet_vtk():
    """Import pyvista with VTK's terminal output off and an off-screen window that needs no X."""
    if ctypes.util.find_library("EGL"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    os.environ.setdefault("EGL_LOG_LEVEL", "fatal")
    from vtkmodules.vtkCommonCore import vtkLogger, vtkObject, vtkOutputWindow, vtkStringOutputWindow

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)
    vtkObject.GlobalWarningDisplayOff()
    sink = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(sink)
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista, sink


def _grid(pv, points: np.ndarray, cells: np.ndarray, cell_type: str):
    ne, k = cells.shape
    conn = np.hstack([np.full((ne, 1), k, dtype=np.int64), cells.astype(np.int64)]).ravel()
    types = np.full(ne, _VTK_CELL[cell_type], dtype=np.uint8)
    return pv.UnstructuredGrid(conn, types, np.asarray(points, dtype=np.float64))


def _render_pyvista(pv, sink, path: Path, grid, label: str, field: str, values, preference: str,
                    title: str, planar: bool, window_size, show_edges, overlays=(), clim=None):
    lo, hi = (float(np.nanmin(values)), float(np.nanmax(values))) if clim is None else clim
    if not hi > lo:  # constant field: give the colour map a finite range
        pad = max(abs(lo), 1.0) * 1e-6
        lo, hi = lo - pad, hi + pad
    font = max(6, round(window_size[0] / 70))
    small = window_size[0] < 600
    edges = grid.n_cells <= 5_000 if show_edges is None else show_edges  # denser: edges hide the colours
    bar_title = with_unit(label, field)
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        plotter.set_background("white")
        plotter.add_mesh(grid, scalars=label, preference=preference, cmap="viridis",
                         clim=(lo, hi), show_edges=edges, edge_color="grey",
                         # unlit: a colour reads as the bar's value (on every face of a 3-D view)
                         lighting=False,
                         scalar_bar_args={"title": bar_title, "color": "black",
                                          "fmt": "%.3g", "n_labels": 3 if small else 5,
                                          "title_font_size": font, "label_font_size": font,
                                          "position_x": 0.2, "position_y": 0.07, "width": 0.6,
                                          "height": 0.05})
        for body in overlays:  # coupled bodies over the background (solid grey, their element edges)
            plotter.add_mesh(body, color="lightgrey", show_edges=True, edge_color="black",
                             show_scalar_bar=False)
        # tick labels below the bar, the title above it: they overlapped on the same side
        plotter.scalar_bar.SetTextPositionToPrecedeScalarBar()
        if planar:
            plotter.add_text(title, position="upper_left", font_size=font, color="black")
            # coordinate axes with units along the bounds: two labels each (ends) keep them readable
            plotter.show_bounds(xtitle="x (m)", ytitle="y (m)", color="black", font_size=font, fmt="%.3g",
                                grid=False, location="outer", ticks="outside", n_xlabels=2, n_ylabels=2,
                                show_zaxis=False, show_zlabels=False)
            plotter.view_xy()
        else:
            # a 3-D box's axis labels meet at its corners and run together (and a slender body's
            # short axes label round-off): its extent is written under the title instead, and an
            # orientation triad clear of the colour bar says which way is which
            plotter.add_text(f"{title}\n{_extent_text([grid, *overlays])}", position="upper_left",
                             font_size=font, color="black")
            plotter.add_axes(color="black", viewport=(0.0, 0.14, 0.14, 0.28))
            plotter.add_mesh(grid.outline(), color="black", line_width=1)  # the unlit box's edges
            plotter.view_isometric()
        _frame(plotter, [grid, *overlays], window_size, FRAME if planar else FRAME_3D)
        plotter.screenshot(str(path))
    except Exception as e:
        raise RuntimeError(f"rendering {path.name} failed: {e}; VTK said: {sink.GetOutput().strip()}") from e
    finally:
        plotter.close()


FRAME = (0.10, 0.92, 0.27, 0.87)
"""Where a planar domain is drawn in the picture (fractions of its width and height: left, right,
bottom, top): the title above, the axis labels and the colour bar below it, clear of each other."""

FRAME_3D = (0.12, 0.90, 0.22, 0.85)
"""Where a 3-D view's projected domain is drawn: no axis labels below it, a title of three lines
above it, the orientation triad at the lower left."""


def _extent_text(grids) -> str:
    """'x 0 to 1.03 m, y ...' of the drawn domain (a coordinate within 1e-9 of the largest span
    of zero written as 0, not as round-off)."""
    b = _bounds(grids)
    tiny = 1e-9 * float(np.max(b[1::2] - b[0::2]) or 1.0)
    b = np.where(np.abs(b) < tiny, 0.0, b)
    return ", ".join(f"{a} {b[2 * k]:.3g} to {b[2 * k + 1]:.3g}" for k, a in enumerate("xyz")) + " m"


def _bounds(grids) -> np.ndarray:
    b = np.array(grids[0].bounds, dtype=float)
    for o in grids[1:]:
        ob = np.array(o.bounds, dtype=float)
        b[0::2], b[1::2] = np.minimum(b[0::2], ob[0::2]), np.maximum(b[1::2], ob[1::2])
    return b


def _frame(plotter, grids, window_size, frame) -> None:
    """A picture framed to its domain (the grid and the bodies drawn on it): a parallel projection
    along the camera's present direction whose centre and scale put the domain's projected
    bounding box into ``frame`` (fractions: left, right, bottom, top), whatever its aspect (a
    slender body or a long tube no longer shrinks to a strip in the middle of a square view)."""
    b = _bounds(grids)
    corners = np.array([[b[i], b[2 + j], b[4 + k]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    cam = plotter.camera
    pos, focal = np.array(cam.position, dtype=float), np.array(cam.focal_point, dtype=float)
    look = (focal - pos) / np.linalg.norm(focal - pos)
    up = np.array(cam.up, dtype=float)
    up = up - (up @ look) * look
    up /= np.linalg.norm(up)
    right = np.cross(look, up)
    u, v = corners @ right, corners @ up                 # screen axes, world units
    w, h = max(np.ptp(u), 1e-300), max(np.ptp(v), 1e-300)
    left, rgt, bottom, top = frame
    aspect = window_size[0] / window_size[1]
    # parallel scale = half the visible height (world units)
    scale = max(h / (top - bottom), w / ((rgt - left) * aspect)) / 2.0
    cu = 0.5 * (u.min() + u.max()) - ((left + rgt) / 2.0 - 0.5) * 2.0 * scale * aspect
    cv = 0.5 * (v.min() + v.max()) - ((bottom + top) / 2.0 - 0.5) * 2.0 * scale
    centre = corners.mean(axis=0)
    centre = centre + (cu - centre @ right) * right + (cv - centre @ up) * up
    distance = np.linalg.norm(focal - pos)
    plotter.enable_parallel_projection()
    cam.focal_point = tuple(centre)
    cam.position = tuple(centre - distance * look)
    cam.parallel_scale = scale
    plotter.renderer.ResetCameraClippingRange()


def _particle_axis(case, role: str) -> int | None:
    """A particle run drawn as a line plot: when the case's check compares this role's profile along
    an axis with an exact one (e.g. the SPH shock tube's riemann check), that axis; the particles
    that start at one coordinate along it are one station (their mean)."""
    if not case:
        return None
    from orchestrator.exact_profiles import exact_profile

    params = (case.get("check") or {}).get("params") or {}
    if params.get("role", role) != role:
        return None
    try:
        ex = exact_profile(case, 0.0)
    except (KeyError, ValueError, TypeError):
        return None
    return None if ex is None else ex.axis


def _is_background(role: str) -> bool:
    from adapters.registry import coupling_side

    return coupling_side(role) == "background"


def _foreground_roles(found: dict) -> list[str]:
    """Roles with bodies in the output, when the output also has a background (a coupled run)."""
    from adapters.registry import coupling_side

    if not any(coupling_side(r) == "background" for r in found):
        return []
    return [r for r in found if coupling_side(r) == "foreground"]


def _intervals(out_dir: Path, role: str, index: int, axis: int) -> list[tuple[float, float]]:
    """Where a role's bodies lie along the axis: the union of its cells' spans (particles: of
    their positions, neighbours closer than 3 median spacings joined), one interval a body."""
    x = read_step(out_dir, role, index)[0][:, axis]
    cells, _ = read_mesh_file(out_dir, role)
    lo, hi = x[cells].min(axis=1), x[cells].max(axis=1)
    order = np.argsort(lo)
    lo, hi = lo[order], np.maximum.accumulate(hi[order])
    gap = 0.0
    if cells.shape[1] == 1 and len(lo) > 1:   # particles: no cell spans, join at the spacing
        steps = np.diff(np.unique(lo))
        gap = 3.0 * float(np.median(steps)) if steps.size else 0.0
    new = np.nonzero(lo[1:] > hi[:-1] + gap)[0] + 1   # a body starts where the last one ended
    starts, ends = np.r_[0, new], np.r_[new - 1, len(lo) - 1]
    return [(float(lo[a]), float(hi[b])) for a, b in zip(starts, ends)]


def _picture_path(pictures: Path, role: str, name: str, index: int) -> Path:
    return pictures / f"{_SAFE.sub('_', role)}_{_SAFE.sub('_', name)}_{index:06d}.png"


# ---------------------------------------------------------------------------------------------
RANGES = ("fixed", "step")
"""--range: one colour (or value-axis) range for all the steps drawn of a field (``fixed``, the
default for several steps: frames compare and animate), or each step's own (``step``)."""


def _colour_values(name: str, point_data: dict, cell_data: dict, coupled: bool):
    """(label, values, "point" | "cell") a picture colours for field ``name`` of a step; in a coupled
    background the zones a body fills whole are NaN (no gas: drawn under the body, out of the range)."""
    if name in point_data:
        label, values = scalar_field(name, point_data[name])
        return label, values, "point"
    label, values = scalar_field(name, cell_data[name])
    if coupled and "blocked_fraction" in cell_data and name != "blocked_fraction":
        values = np.where(cell_data["blocked_fraction"] >= 1.0 - 1e-12, np.nan, values)
    return label, values, "cell"


def _span(arrays, margin: float = 0.0):
    """(lo, hi) over the finite values of ``arrays`` (None entries skipped), widened by ``margin`` of
    its width (line plots); a constant field gets a finite range; None when nothing is finite."""
    lo, hi = np.inf, -np.inf
    for a in arrays:
        a = None if a is None else np.asarray(a, dtype=float)
        if a is not None and np.isfinite(a).any():
            lo, hi = min(lo, float(np.nanmin(a))), max(hi, float(np.nanmax(a)))
    if not np.isfinite(lo):
        return None
    if not hi > lo:
        pad = max(abs(lo), 1.0) * 1e-6
        lo, hi = lo - pad, hi + pad
    m = margin * (hi - lo)
    return lo - m, hi + m


def movie(frames: Sequence[Path], path: Path, seconds_per_frame: float = 0.4) -> Path:
    """An animated GIF of the frames (Pillow, matplotlib's own image library), looping."""
    from PIL import Image

    images = [Image.open(f).convert("RGB") for f in frames]
    # one palette for all frames (the first's adaptive one): colours keep their values frame to frame
    first = images[0].quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    rest = [im.quantize(palette=first, dither=Image.Dither.NONE) for im in images[1:]]
    tmp = path.with_name(path.name + ".tmp")
    first.save(tmp, format="GIF", save_all=True, append_images=rest, duration=int(1000 * seconds_per_frame),
               loop=0)
    tmp.replace(path)
    return path


def render(out_dir, fields: Sequence[str] | None = None, steps: Sequence = ("last",),
           role: str | None = None, *, window_size: tuple[int, int] = (1024, 768),
           show_edges: bool | None = None, value_range: str | None = None,
           animate: bool = False) -> list[Path]:
    """Render PNGs into out_dir/pictures; returns the written paths.

    fields: names of point or cell data (None: all of them); steps: 'first', 'last',
    'all' or output indices; role: one role (None: every role with output); value_range: RANGES
    (None: fixed for several steps); animate: also one GIF per role and field of its frames
    (pictures/<role>_<field>.gif).
    Raises ViewError (nothing written) for a field or step the output does not hold.
    """
    if value_range is not None and value_range not in RANGES:
        raise ViewError(f"--range {value_range!r}: allowed: {', '.join(RANGES)}")
    out_dir = Path(out_dir)
    if isinstance(steps, (str, int, np.integer)):
        steps = (steps,)
    if isinstance(fields, str):
        fields = (fields,)
    found = available(out_dir)
    if role is not None:
        if role not in found:
            raise ViewError(f"role {role!r}: no output of that role; roles: {', '.join(found) or 'none'}")
        found = {role: found[role]}
    if not found:
        raise ViewError(f"{out_dir}: no output steps yet")
    # check the whole request before drawing anything
    if fields is not None:
        missing = [f for f in fields if not any(f in v["fields"] for v in found.values())]
        if missing:
            raise ViewError(f"--field {' '.join(missing)}: not in this output; fields: "
                            f"{_holdings(found, 'fields')}")
    plan = []
    for r, info in found.items():
        try:
            chosen = _select_steps(info["steps"], steps)
        except ViewError as e:
            raise ViewError(f"{e} in {r}; steps: {_holdings(found, 'steps')}") from None
        names = [f for f in (fields or info["fields"]) if f in info["fields"]]
        plan.append((r, chosen, names))

    pictures = out_dir / PICTURES_DIR
    # immerse never overwrites a file it did not write (orchestrator/outdir.py): a picture path
    # taken by a file of the user's refuses the request before anything is drawn
    from orchestrator import outdir

    for r, chosen, names in plan:
        paths = [_picture_path(pictures, r, name, index) for _, _, index in chosen for name in names]
        if animate:
            paths += [pictures / f"{_SAFE.sub('_', r)}_{_SAFE.sub('_', name)}.gif" for name in names]
        for path in paths:
            if not outdir.may_write(out_dir, path):
                raise ViewError(f"{path}: a file immerse did not write is there; move it away "
                                "(immerse never overwrites a file it did not write)")
    written: list[Path] = []
    pv = sink = None
    case = None
    bodies = _foreground_roles(found)  # coupled bodies: drawn in the background's pictures
    for r, chosen, names in plan:
        cells, cell_type = read_mesh_file(out_dir, r)
        first_points = read_step(out_dir, r, min(s[2] for s in found[r]["steps"]))[0]
        axis = one_d_axis(first_points, cells)
        if case is None and (axis is not None or cell_type == "vertex"):
            case = case_of_run(out_dir) or False
        if axis is None and cell_type == "vertex":   # particles: 1-D where the case's check has an exact
            axis = _particle_axis(case, r)           # profile of this role
        planar = bool(np.all(first_points[:, 2] == first_points[0, 2]))
        coupled = bool(bodies) and _is_background(r)
        fixed = (value_range or ("fixed" if len(chosen) > 1 else "step")) == "fixed"
        ranges, profiles = {}, {}
        if axis is not None:   # line plots: each profile once (the range, with the exact curves, then the frame)
            profiles = {(name, i): line_profile(out_dir, r, name, i, axis, case or None)
                        for _, _, i in chosen for name in names}
            if fixed:
                ranges = {name: _span([a for _, _, i in chosen for a in (profiles[name, i].values,
                                                                          profiles[name, i].exact_values)], 0.05)
                          for name in names}
        elif fixed:   # each step read once, only its extremes kept (a 3-D run's fields do not all fit)
            extremes = {name: [] for name in names}
            for _, _, i in chosen:
                _, pd, cd = read_step(out_dir, r, i)
                for name in names:
                    v = _colour_values(name, pd, cd, coupled)[1]
                    extremes[name].append(np.array([np.nanmin(v), np.nanmax(v)]) if np.isfinite(v).any() else None)
            ranges = {name: _span(extremes[name]) for name in names}
        frames = {name: [] for name in names}
        for time, step, index in chosen:
            pictures.mkdir(parents=True, exist_ok=True)
            if axis is not None:
                # the bodies in the background along the axis at this step: read once for all its fields
                spans = ([(b, lo, hi) for b in bodies for lo, hi in _intervals(out_dir, b, index, axis)]
                         if _is_background(r) else [])
                for name in names:
                    path = _picture_path(pictures, r, name, index)
                    prof = profiles[name, index]
                    prof.bodies = spans
                    fig = line_figure(prof, window_size, ranges.get(name))
                    fig.savefig(path)
                    outdir.record_written(out_dir, path)
                    written.append(path)
                    frames[name].append(path)
                continue
            if pv is None:
                pv, sink = _quiet_vtk()
            points, point_data, cell_data = read_step(out_dir, r, index)
            grid = _grid(pv, points, cells, cell_type)
            overlays = []
            if _is_background(r):  # the bodies at the same output step, drawn over the gas
                for b in bodies:
                    bcells, btype = read_mesh_file(out_dir, b)
                    overlays.append(_grid(pv, read_step(out_dir, b, index)[0], bcells, btype))
            for name in names:
                label, values, preference = _colour_values(name, point_data, cell_data, coupled)
                (grid.point_data if preference == "point" else grid.cell_data)[label] = values
                path = _picture_path(pictures, r, name, index)
                title = f"{r}: {label}" + (f" with {', '.join(bodies)} bodies (grey)" if overlays else "")
                if np.isfinite(values).any() and np.nanmin(values) == np.nanmax(values):
                    # the same everywhere at this step (e.g. a contact pressure after the contact): said,
                    # so that a blank picture is not taken for a failed one
                    title += f" (uniform: {float(np.nanmin(values)):.6g} at this step)"
                _render_pyvista(pv, sink, path, grid, label, name, values, preference,
                                f"{title}\nt = {time:.6g} s (step {step})", planar,
                                window_size, show_edges, overlays, ranges.get(name))
                outdir.record_written(out_dir, path)
                written.append(path)
                frames[name].append(path)
        if animate:
            for name in names:
                gif = pictures / f"{_SAFE.sub('_', r)}_{_SAFE.sub('_', name)}.gif"
                movie(frames[name], gif)
                outdir.record_written(out_dir, gif)
                written.append(gif)
    return written
