"""Off-screen pictures of output steps (PNG) with pyvista.

render(out_dir) writes out/pictures/<role>_<field>_<index:06d>.png, one per (role, field,
step): vector fields are coloured by their magnitude, (n, 6) symmetric tensors
(Voigt order xx yy zz xy yz zx, see orchestrator.output) by the von Mises equivalent,
scalars as they are.
Each picture has a scalar bar and a title with the role, field, time and step number.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from orchestrator.output import list_roles, read_mesh_file, read_step, read_steps, von_mises

__all__ = ["render", "scalar_field", "PICTURES_DIR"]

PICTURES_DIR = "pictures"
_VTK_CELL = {"quad": 9, "hexahedron": 12}  # VTK_QUAD, VTK_HEXAHEDRON
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def scalar_field(name: str, values) -> tuple[str, np.ndarray]:
    """(label, one value per row) used to colour a field."""
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 1:
        return name, a
    a = a.reshape(len(a), -1)
    if a.shape[1] == 1:
        return name, a[:, 0]
    if a.shape[1] == 6:
        return f"{name} (von Mises)", von_mises(a)
    return f"{name} magnitude", np.linalg.norm(a, axis=1)


def _select_steps(available: list[tuple[float, int, int]], wanted: Iterable) -> list[tuple[float, int, int]]:
    by_index = {s[2]: s for s in available}
    chosen: list[tuple[float, int, int]] = []
    for w in wanted:
        if isinstance(w, str) and w.strip().lstrip("-").isdigit():
            w = int(w)  # e.g. from the command line
        if w == "last":
            picks = available[-1:]
        elif w == "first":
            picks = available[:1]
        elif w == "all":
            picks = available
        elif isinstance(w, (int, np.integer)) and not isinstance(w, bool):
            if int(w) not in by_index:
                raise ValueError(f"no output step with index {w} (available: "
                                 f"{[s[2] for s in available]})")
            picks = [by_index[int(w)]]
        else:
            raise ValueError(f"steps entries must be 'first', 'last', 'all' or an output index, "
                             f"got {w!r}")
        chosen.extend(p for p in picks if p not in chosen)
    return chosen


def _grid(pv, points: np.ndarray, cells: np.ndarray, cell_type: str):
    ne, k = cells.shape
    conn = np.hstack([np.full((ne, 1), k, dtype=np.int64), cells.astype(np.int64)]).ravel()
    types = np.full(ne, _VTK_CELL[cell_type], dtype=np.uint8)
    return pv.UnstructuredGrid(conn, types, np.asarray(points, dtype=np.float64))


def render(out_dir, fields: Sequence[str] | None = None, steps: Sequence = ("last",),
           role: str | None = None, *, window_size: tuple[int, int] = (1024, 768),
           show_edges: bool | None = None) -> list[Path]:
    """Render PNGs into out_dir/pictures; returns the written paths.

    fields: names of point or cell data (None: all of them); steps: 'first', 'last',
    'all' or output indices; role: one role (None: every role with output).
    """
    import pyvista

    pyvista.OFF_SCREEN = True
    out_dir = Path(out_dir)
    if isinstance(steps, (str, int, np.integer)):
        steps = (steps,)
    if isinstance(fields, str):
        fields = (fields,)
    roles = [role] if role is not None else list_roles(out_dir)
    pictures = out_dir / PICTURES_DIR
    written: list[Path] = []
    rendered_fields: set[str] = set()
    for r in roles:
        available = read_steps(out_dir, r)
        if not available:
            continue
        cells, cell_type = read_mesh_file(out_dir, r)
        planar = None
        for time, step, index in _select_steps(available, steps):
            points, point_data, cell_data = read_step(out_dir, r, index)
            if planar is None:
                planar = bool(np.all(points[:, 2] == points[0, 2]))
            names = list(fields) if fields is not None else sorted(point_data) + sorted(cell_data)
            grid = _grid(pyvista, points, cells, cell_type)
            for name in names:
                if name in point_data:
                    label, values = scalar_field(name, point_data[name])
                    grid.point_data[label] = values
                    preference = "point"
                elif name in cell_data:
                    label, values = scalar_field(name, cell_data[name])
                    grid.cell_data[label] = values
                    preference = "cell"
                else:
                    continue
                rendered_fields.add(name)
                pictures.mkdir(parents=True, exist_ok=True)
                path = pictures / f"{_SAFE.sub('_', r)}_{_SAFE.sub('_', name)}_{index:06d}.png"
                lo, hi = float(np.min(values)), float(np.max(values))
                if not hi > lo:  # constant field: give the colour map a finite range
                    pad = max(abs(lo), 1.0) * 1e-6
                    lo, hi = lo - pad, hi + pad
                font = max(6, round(window_size[0] / 70))
                small = window_size[0] < 600
                edges = grid.n_cells <= 20_000 if show_edges is None else show_edges
                plotter = pyvista.Plotter(off_screen=True, window_size=list(window_size))
                try:
                    plotter.set_background("white")
                    plotter.add_mesh(grid, scalars=label, preference=preference, cmap="viridis",
                                     clim=(lo, hi), show_edges=edges, edge_color="grey",
                                     scalar_bar_args={"title": label, "color": "black",
                                                      "fmt": "%.3g", "n_labels": 3 if small else 5,
                                                      "title_font_size": font,
                                                      "label_font_size": font,
                                                      "position_x": 0.2, "width": 0.6})
                    plotter.add_text(f"{r}: {label}\nt = {time:.6g} s (step {step})",
                                     position="upper_left", font_size=font, color="black")
                    if planar:
                        plotter.view_xy()
                    else:
                        plotter.view_isometric()
                    plotter.screenshot(str(path))
                finally:
                    plotter.close()
                written.append(path)
    if fields is not None:
        missing = [f for f in fields if f not in rendered_fields]
        if missing:
            raise ValueError(f"field(s) {missing} not found in the output of "
                             f"{roles if role is None else role}")
    return written
