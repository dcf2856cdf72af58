"""The output step files of a solver group (written by its ranks, read by the index and the
readers of orchestrator/output.py, whose docstring describes the whole layout of OUT/):

    out/steps/<role>_mesh.h5        cells (ne, k) int64, attr cell_type ("quad" | "hexahedron" | "vertex")
    out/steps/<role>_<index:06d>.h5 attrs time, step, index, role; points (nn, 3) float64
                                     (zero z in 2D); /point_data/<name>, /cell_data/<name>

Each is written under a temporary name ``<name>.<pid>.tmp`` in the same directory, flushed, closed,
fsync'ed and moved into place with ``os.replace`` (atomic on POSIX), so a kill at any instant leaves
the previous complete version. Here, below both the adapters and the orchestrator: the adapters
import nothing from the orchestrator above them.
"""
from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

STEPS_DIR = "steps"
TENSOR6_COMPONENTS = ("xx", "yy", "zz", "xy", "yz", "zx")  # stored order of (n, 6) tensors
# meshio/VTK cell type -> (XDMF topology type, nodes per element)
CELL_TYPES = {"quad": ("Quadrilateral", 4), "hexahedron": ("Hexahedron", 8),
              "vertex": ("Polyvertex", 1)}  # particles: a point cloud, one vertex per particle

_ROLE_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")
_STEP_RE = re.compile(r"^(?P<role>[A-Za-z][A-Za-z0-9_-]*)_(?P<index>\d{6,})\.h5$")
_MESH_RE = re.compile(r"^(?P<role>[A-Za-z][A-Za-z0-9_-]*)_mesh\.h5$")
_NAME_RE = re.compile(r"^[^/.\s][^/]*$")


class OutputError(Exception):
    """Invalid arguments to the output writers or an unreadable output directory."""


# ----------------------------------------------------------------------------- paths
def _check_role(role: str) -> str:
    if not isinstance(role, str) or not _ROLE_RE.match(role):
        raise OutputError(f"role must match {_ROLE_RE.pattern}, got {role!r}")
    return role


def step_path(out_dir, role: str, index: int) -> Path:
    return Path(out_dir) / STEPS_DIR / f"{_check_role(role)}_{int(index):06d}.h5"


def mesh_path(out_dir, role: str) -> Path:
    return Path(out_dir) / STEPS_DIR / f"{_check_role(role)}_mesh.h5"


# ----------------------------------------------------------------------------- atomic files
def _fsync(path: Path, directory: bool = False) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _tmp_name(path: Path) -> Path:
    return path.with_name(f"{path.name}.{os.getpid()}.tmp")


def _commit(tmp: Path, path: Path) -> None:
    _fsync(tmp)
    os.replace(tmp, path)
    _fsync(path.parent, directory=True)


@contextlib.contextmanager
def _atomic_h5(path: Path) -> Iterator[h5py.File]:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_name(path)
    # default (earliest) file format: readable by the older HDF5 inside ParaView/VisIt
    f = h5py.File(tmp, "w")
    try:
        yield f
        f.flush()
        f.close()
        _commit(tmp, path)
    except BaseException:
        with contextlib.suppress(Exception):
            f.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


# ----------------------------------------------------------------------------- writers
def write_mesh(out_dir, role: str, cells, cell_type: str) -> Path:
    """Write the topology of ``role`` once: steps/<role>_mesh.h5."""
    if cell_type not in CELL_TYPES:
        raise OutputError(f"cell_type must be one of {sorted(CELL_TYPES)}, got {cell_type!r}")
    cells = np.asarray(cells)
    k = CELL_TYPES[cell_type][1]
    if cells.ndim != 2 or cells.shape[1] != k or not np.issubdtype(cells.dtype, np.integer):
        raise OutputError(f"{cell_type} cells must be an integer array (ne, {k}), got "
                          f"{cells.dtype} {cells.shape}")
    path = mesh_path(out_dir, role)
    with _atomic_h5(path) as f:
        f.create_dataset("cells", data=cells.astype(np.int64))
        f.attrs["cell_type"] = cell_type
        f.attrs["role"] = role
    return path


def _as_storable(name: str, value) -> np.ndarray:
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise OutputError(f"invalid field name {name!r} (no '/', not empty)")
    arr = np.asarray(value)
    if arr.dtype == bool:
        arr = arr.astype(np.uint8)
    if arr.dtype.kind not in "fiu" or arr.ndim < 1:
        raise OutputError(f"field {name!r} must be a numeric array (n, ...), got {arr.dtype} "
                          f"{arr.shape}")
    return np.ascontiguousarray(arr)


def write_step(out_dir, role: str, index: int, step: int, time: float, points,
               point_data: dict | None = None, cell_data: dict | None = None) -> Path:
    """Write one output step of ``role`` atomically: steps/<role>_<index:06d>.h5.

    points (nn, 2|3) are stored as (nn, 3) float64 (zero z in 2D); point_data arrays
    must have nn rows, cell_data arrays one row per cell (all the same count).
    """
    index, step, time = int(index), int(step), float(time)
    if index < 0:
        raise OutputError(f"index must be >= 0, got {index}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise OutputError(f"points must have shape (nn, 2|3), got {pts.shape}")
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    pdata = {k: _as_storable(k, v) for k, v in (point_data or {}).items()}
    cdata = {k: _as_storable(k, v) for k, v in (cell_data or {}).items()}
    for k, v in pdata.items():
        if v.shape[0] != len(pts):
            raise OutputError(f"point_data {k!r} has {v.shape[0]} rows, expected {len(pts)}")
    if len({v.shape[0] for v in cdata.values()}) > 1:
        raise OutputError("cell_data arrays have different numbers of rows: "
                          + ", ".join(f"{k}={v.shape[0]}" for k, v in cdata.items()))
    path = step_path(out_dir, role, index)
    with _atomic_h5(path) as f:
        f.attrs["time"] = time
        f.attrs["step"] = step
        f.attrs["index"] = index
        f.attrs["role"] = role
        f.create_dataset("points", data=pts)
        gp = f.create_group("point_data")
        for k, v in pdata.items():
            gp.create_dataset(k, data=v)
        gc = f.create_group("cell_data")
        for k, v in cdata.items():
            gc.create_dataset(k, data=v)
    return path


# ----------------------------------------------------------------------------- tensors
def von_mises(t6) -> np.ndarray:
    """Von Mises equivalent of symmetric tensors (n, 6) in TENSOR6_COMPONENTS order.

    Only the split normals (columns 0-2) / shears (columns 3-5) matters, so any Voigt
    order with the normal components first gives the same result.
    """
    s = np.asarray(t6, dtype=np.float64)
    xx, yy, zz = s[..., 0], s[..., 1], s[..., 2]
    shear2 = np.sum(s[..., 3:6] ** 2, axis=-1)
    return np.sqrt(0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) + 3.0 * shear2)


def pressure(t6) -> np.ndarray:
    """Pressure -trace/3 of symmetric tensors (n, 6) (normal components in columns 0-2)."""
    s = np.asarray(t6, dtype=np.float64)
    return -(s[..., 0] + s[..., 1] + s[..., 2]) / 3.0
