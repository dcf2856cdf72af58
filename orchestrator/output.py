"""Crash-safe HDF5 output with an HDF5 index and an XDMF 3 description for ParaView.

Layout of an output directory ``out/``::

    out/steps/<role>_mesh.h5        cells (ne, k) int64, attr cell_type ("quad" | "hexahedron")
    out/steps/<role>_<index:06d>.h5 attrs time, step, index, role; points (nn, 3) float64
                                     (zero z in 2D); /point_data/<name>, /cell_data/<name>
    out/results.h5                   /<role>/<index:06d> -> external link to the step file,
                                     /<role>/mesh -> external link to the mesh file,
                                     /<role>/times, /<role>/steps, /<role>/indices
    out/results.xdmf                 per role one Temporal collection of Uniform grids

Every file is written under a temporary name ``<name>.<pid>.tmp`` in the same directory,
flushed, closed, fsync'ed and moved into place with ``os.replace`` (atomic on POSIX), so a
kill at any instant leaves the previous complete version. Step files are never deleted
and results.h5 is only replaced by a complete version, so every indexed step stays
readable. Stale ``*.tmp`` files left by a killed writer are ignored.

External links are stored relative to results.h5 ("steps/<file>"); HDF5 resolves a
relative external link in the directory of the parent file before trying the current
working directory, so results.h5 can be opened from any working directory.

Field conventions (used by the XDMF attribute types and by orchestrator.view):

* shape (n,) -> Scalar, (n, 3) -> Vector, (n, 9) -> Tensor, other (n, k) -> Matrix.
* shape (n, 6) is a symmetric tensor stored in the solvers' Voigt order
  TENSOR6_COMPONENTS = (xx, yy, zz, xy, yz, zx) (tensor shears, not engineering ones).
  XDMF's Tensor6 order is (xx, xy, xz, yy, yz, zz), so the XDMF file presents it as a
  Tensor6 through a Function DataItem JOIN of the six column HyperSlabs in that order
  (read correctly by ParaView's/VTK's XDMF readers; meshio's TimeSeriesReader does not
  understand Function items).
* boolean arrays are stored as uint8 (XDMF has no boolean type).
"""

from __future__ import annotations

import contextlib
import os
import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

__all__ = [
    "STEPS_DIR",
    "INDEX_H5",
    "INDEX_XDMF",
    "TENSOR6_COMPONENTS",
    "CELL_TYPES",
    "OutputError",
    "step_path",
    "mesh_path",
    "write_mesh",
    "write_step",
    "write_index",
    "read_steps",
    "read_step",
    "read_step_attrs",
    "read_mesh_file",
    "list_roles",
    "von_mises",
]

STEPS_DIR = "steps"
INDEX_H5 = "results.h5"
INDEX_XDMF = "results.xdmf"
TENSOR6_COMPONENTS = ("xx", "yy", "zz", "xy", "yz", "zx")  # stored order of (n, 6) tensors
# stored columns in XDMF Tensor6 order (xx, xy, xz, yy, yz, zz)
_TENSOR6_TO_XDMF = (0, 3, 5, 1, 4, 2)
# meshio/VTK cell type -> (XDMF topology type, nodes per element)
CELL_TYPES = {"quad": ("Quadrilateral", 4), "hexahedron": ("Hexahedron", 8)}

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


def _link_name(index: int) -> str:
    return f"{int(index):06d}"


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


def _atomic_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_name(path)
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
        _commit(tmp, path)
    except BaseException:
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


# ----------------------------------------------------------------------------- scanning
def _scan(out_dir: Path) -> tuple[dict[str, list[tuple[int, Path]]], dict[str, Path]]:
    steps: dict[str, list[tuple[int, Path]]] = {}
    meshes: dict[str, Path] = {}
    sdir = Path(out_dir) / STEPS_DIR
    if not sdir.is_dir():
        return steps, meshes
    for entry in os.scandir(sdir):
        m = _STEP_RE.match(entry.name)
        if m:
            steps.setdefault(m["role"], []).append((int(m["index"]), Path(entry.path)))
            continue
        m = _MESH_RE.match(entry.name)
        if m:
            meshes[m["role"]] = Path(entry.path)
    for v in steps.values():
        v.sort()
    return steps, meshes


def _describe_step(path: Path) -> dict | None:
    """Attributes and dataset shapes of a step file (None if unreadable)."""
    try:
        with h5py.File(path, "r") as f:
            info = {
                "time": float(f.attrs["time"]),
                "step": int(f.attrs["step"]),
                "points": (f["points"].shape, f["points"].dtype),
                "point_data": {k: (d.shape, d.dtype) for k, d in f.get("point_data", {}).items()},
                "cell_data": {k: (d.shape, d.dtype) for k, d in f.get("cell_data", {}).items()},
            }
        return info
    except (OSError, KeyError, ValueError, TypeError) as exc:
        warnings.warn(f"skipping unreadable output step {path.name}: {exc}", stacklevel=3)
        return None


def _describe_mesh(path: Path) -> tuple[tuple, np.dtype, str] | None:
    try:
        with h5py.File(path, "r") as f:
            ct = f.attrs["cell_type"]
            ct = ct.decode() if isinstance(ct, bytes) else str(ct)
            return f["cells"].shape, f["cells"].dtype, ct
    except (OSError, KeyError, ValueError, TypeError) as exc:
        warnings.warn(f"skipping unreadable mesh file {path.name}: {exc}", stacklevel=3)
        return None


# ----------------------------------------------------------------------------- XDMF
def _xdmf_number(dtype: np.dtype) -> tuple[str, str]:
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return "Float", str(dtype.itemsize)
    if dtype.kind == "i":
        return ("Char" if dtype.itemsize == 1 else "Int"), str(dtype.itemsize)
    if dtype.kind == "u":
        return ("UChar" if dtype.itemsize == 1 else "UInt"), str(dtype.itemsize)
    raise OutputError(f"unsupported dtype {dtype}")


def _attribute_type(shape: tuple) -> str | None:
    if len(shape) == 1:
        return "Scalar"
    if len(shape) != 2:
        return None
    return {1: "Scalar", 3: "Vector", 6: "Tensor6", 9: "Tensor"}.get(shape[1], "Matrix")


def _data_item(parent: ET.Element, shape: tuple, dtype, ref: str) -> ET.Element:
    number, precision = _xdmf_number(dtype)
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(str(int(s)) for s in shape),
                         NumberType=number, Precision=precision, Format="HDF")
    item.text = ref
    return item


def _tensor6_item(parent: ET.Element, shape: tuple, dtype, ref: str) -> ET.Element:
    """(n, 6) stored in TENSOR6_COMPONENTS order, presented in XDMF Tensor6 order."""
    n = int(shape[0])
    order = ", ".join(f"${k}" for k in range(6))
    func = ET.SubElement(parent, "DataItem", ItemType="Function", Dimensions=f"{n} 6",
                         Function=f"JOIN({order})")
    for col in _TENSOR6_TO_XDMF:
        slab = ET.SubElement(func, "DataItem", ItemType="HyperSlab", Type="HyperSlab",
                             Dimensions=f"{n} 1")
        sel = ET.SubElement(slab, "DataItem", Dimensions="3 2", NumberType="Int",
                            Precision="8", Format="XML")
        sel.text = f"0 {col} 1 1 {n} 1"  # start, stride, count
        _data_item(slab, shape, dtype, ref)
    return func


def _build_xdmf(index: dict) -> str:
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    for role, entry in index.items():
        mesh = entry["mesh"]
        if mesh is None:
            continue
        cshape, cdtype, ctype = mesh
        topo_type, npe = CELL_TYPES[ctype]
        ne = cshape[0]
        coll = ET.SubElement(domain, "Grid", Name=role, GridType="Collection",
                             CollectionType="Temporal")
        mesh_ref = f"{STEPS_DIR}/{entry['mesh_file']}:/cells"
        for idx, fname, info in entry["steps"]:
            grid = ET.SubElement(coll, "Grid", Name=f"{role}_{idx:06d}", GridType="Uniform")
            ET.SubElement(grid, "Time", Value=repr(info["time"]))
            topo = ET.SubElement(grid, "Topology", TopologyType=topo_type,
                                 NumberOfElements=str(ne), NodesPerElement=str(npe))
            _data_item(topo, cshape, cdtype, mesh_ref)
            geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
            pshape, pdtype = info["points"]
            _data_item(geo, pshape, pdtype, f"{STEPS_DIR}/{fname}:/points")
            nn = pshape[0]
            for center, group, rows in (("Node", "point_data", nn), ("Cell", "cell_data", ne)):
                for name, (shape, dtype) in sorted(info[group].items()):
                    atype = _attribute_type(shape)
                    if atype is None or shape[0] != rows:
                        warnings.warn(f"{fname}: {group}/{name} with shape {shape} is not "
                                      f"described in the XDMF file", stacklevel=3)
                        continue
                    attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=atype,
                                         Center=center)
                    ref = f"{STEPS_DIR}/{fname}:/{group}/{name}"
                    if atype == "Tensor6":
                        _tensor6_item(attr, shape, dtype, ref)
                    else:
                        _data_item(attr, shape, dtype, ref)
    ET.indent(root, space=" ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


# ----------------------------------------------------------------------------- index
def write_index(out_dir) -> tuple[Path, Path]:
    """Scan out/steps and (re)write out/results.h5 and out/results.xdmf atomically."""
    out_dir = Path(out_dir)
    steps, meshes = _scan(out_dir)
    index: dict[str, dict] = {}
    for role in sorted(set(steps) | set(meshes)):
        described = []
        for idx, path in steps.get(role, []):
            info = _describe_step(path)
            if info is not None:
                described.append((idx, path.name, info))
        mesh = _describe_mesh(meshes[role]) if role in meshes else None
        index[role] = {"steps": described, "mesh": mesh,
                       "mesh_file": meshes[role].name if role in meshes else None}

    h5 = out_dir / INDEX_H5
    with _atomic_h5(h5) as f:
        f.attrs["layout"] = "immerse-output-1"
        for role, entry in index.items():
            g = f.create_group(role)
            if entry["mesh"] is not None:
                g.attrs["cell_type"] = entry["mesh"][2]
                g["mesh"] = h5py.ExternalLink(f"{STEPS_DIR}/{entry['mesh_file']}", "/")
            rows = entry["steps"]
            g.create_dataset("times", data=np.array([r[2]["time"] for r in rows], dtype=np.float64))
            g.create_dataset("steps", data=np.array([r[2]["step"] for r in rows], dtype=np.int64))
            g.create_dataset("indices", data=np.array([r[0] for r in rows], dtype=np.int64))
            for idx, fname, _ in rows:
                g[_link_name(idx)] = h5py.ExternalLink(f"{STEPS_DIR}/{fname}", "/")
    xdmf = out_dir / INDEX_XDMF
    _atomic_text(xdmf, _build_xdmf(index))
    return h5, xdmf


# ----------------------------------------------------------------------------- readers
def list_roles(out_dir) -> list[str]:
    """Roles with output (from results.h5 when present, else by scanning out/steps)."""
    out_dir = Path(out_dir)
    h5 = out_dir / INDEX_H5
    if h5.is_file():
        with h5py.File(h5, "r") as f:
            return sorted(k for k in f.keys())
    steps, meshes = _scan(out_dir)
    return sorted(set(steps) | set(meshes))


def read_steps(out_dir, role: str) -> list[tuple[float, int, int]]:
    """[(time, step, index)] of ``role`` sorted by index.

    Uses results.h5 when it lists the role, else scans the step files (e.g. before the
    first write_index).
    """
    out_dir = Path(out_dir)
    _check_role(role)
    h5 = out_dir / INDEX_H5
    if h5.is_file():
        with h5py.File(h5, "r") as f:
            if role in f:
                g = f[role]
                times, steps, idx = g["times"][()], g["steps"][()], g["indices"][()]
                order = np.argsort(idx, kind="stable")
                return [(float(times[i]), int(steps[i]), int(idx[i])) for i in order]
    found, _ = _scan(out_dir)
    out = []
    for idx, path in found.get(role, []):
        info = _describe_step(path)
        if info is not None:
            out.append((info["time"], info["step"], idx))
    return out


def read_step(out_dir, role: str, index: int) -> tuple[np.ndarray, dict, dict]:
    """(points (nn, 3), point_data, cell_data) of one step file."""
    path = step_path(out_dir, role, index)
    if not path.is_file():
        raise OutputError(f"no output step {path.name} in {Path(out_dir) / STEPS_DIR}")
    with h5py.File(path, "r") as f:
        points = f["points"][()]
        point_data = {k: d[()] for k, d in f.get("point_data", {}).items()}
        cell_data = {k: d[()] for k, d in f.get("cell_data", {}).items()}
    return points, point_data, cell_data


def read_step_attrs(out_dir, role: str, index: int) -> dict:
    """{'time', 'step', 'index'} of one step file."""
    with h5py.File(step_path(out_dir, role, index), "r") as f:
        return {"time": float(f.attrs["time"]), "step": int(f.attrs["step"]),
                "index": int(f.attrs["index"])}


def read_mesh_file(out_dir, role: str) -> tuple[np.ndarray, str]:
    """(cells (ne, k) int64, cell_type) of ``role``."""
    path = mesh_path(out_dir, role)
    if not path.is_file():
        raise OutputError(f"no mesh file {path.name} in {Path(out_dir) / STEPS_DIR}")
    with h5py.File(path, "r") as f:
        ct = f.attrs["cell_type"]
        return f["cells"][()], (ct.decode() if isinstance(ct, bytes) else str(ct))


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
