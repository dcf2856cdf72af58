"""Crash-safe HDF5 output with an HDF5 index and an XDMF 3 description for ParaView.

Layout of an output directory ``out/``::

    out/steps/<role>_mesh.h5        cells (ne, k) int64, attr cell_type ("quad" | "hexahedron")
    out/steps/<role>_<index:06d>.h5 attrs time, step, index, role; points (nn, 3) float64
                                     (zero z in 2D); /point_data/<name>, /cell_data/<name>
    out/results.h5                   /<role>/<index:06d> -> external link to the step file,
                                     /<role>/mesh -> external link to the mesh file,
                                     /<role>/times, /<role>/steps, /<role>/indices (resizable)
    out/results.xdmf                 per role one Temporal collection of Uniform grids

Step and mesh files are written under a temporary name ``<name>.<pid>.tmp`` in the same
directory, flushed, closed, fsync'ed and moved into place with ``os.replace`` (atomic on
POSIX), so a kill at any instant leaves the previous complete version. Step files are never
deleted. Stale ``*.tmp`` files left by a killed writer are ignored.

The index, and why it costs the same at every output
----------------------------------------------------
Rewriting the index from a scan of every step file made output quadratic in the number of
outputs (the 400-element bar wave: 12 outputs 1.1 s, 240 outputs 138 s). Rewriting both files
from an index held in memory was measured too and is not flat either (at 1000 steps 41 ms for
results.h5's 1000 external links and 5.6 ms for 1.5 MB of XDMF, against 2 ms at 10 steps); HDF5's
SWMR mode cannot add links, and a file a killed SWMR writer leaves needs h5clear before others
open it. :class:`OutputIndex` holds the index in memory (the coupler keeps one for the whole run;
it is built once from the files on disk, also on restart) and adds each new step by reading only
the new step file's attributes and shapes:

* results.h5 is small (about 100 bytes a step: three chunked, resizable datasets and one
  external link per step). Each output copies it in the kernel (``os.copy_file_range``) to a
  temporary file, appends the step there through HDF5 (resize the datasets, add one link) and
  moves the copy into place atomically. An HDF5 file appended in place is not safe against a
  kill (the library rewrites metadata in several writes), the copy is. The bytes copied grow
  with n (0.1 MB at 1000 steps) but not measurably the time, which opening the file dominates.
  The copy is renamed without an fsync (which cost more than the rest of the append on a busy
  disk): a kill cannot tear a rename, after a power loss ext4 gives the old or the new file
  (its replace-by-rename rule), and results.h5 holds nothing the step files (fsync'ed) do not:
  write_index rebuilds it.
* results.xdmf (about 2 kB a step, 1.5 MB at 1000 steps: copying that would not be flat) is
  appended in place, kept well formed at every instant with an XML processing instruction, which
  every XML reader skips. Each collection ends in a free room ``<?immerse-append   ...   ?>``
  (a PI whose content is spaces). A new grid G is added in three writes::

      <?immerse-append       ...spaces...      ?>            before
      <?immerse-append   G   ...spaces...      ?>            1. G written inside the PI
      <?immerse-append   G<?immerse-append ... ?>            2. a new opener after G; fdatasync
      <?immerse-append ?>G<?immerse-append ... ?>            3. "?>" closes the first PI: G is live

  Every intermediate state (also a partly written G, or a write torn at any byte) is one
  well-formed document: G never contains "?>" (ElementTree escapes ">" in text and attributes),
  "<?" inside a PI is plain content, and the target name is always followed by a space (a torn
  step 3 leaves "<?immerse-append ? G...", still one PI); a test replays every torn state. The
  fdatasync orders step 3 after steps 1-2 on disk (power loss). When the room is used up the
  whole file is rewritten atomically (temporary file + rename) with a room as large as what the
  collection holds (at least 64 kB), so rewrites get geometrically rarer and the amortised cost
  per output stays constant.
  ParaView 5.11's three XDMF readers (XDMF Reader, Xdmf3ReaderS, Xdmf3ReaderT) and
  ElementTree/meshio ignore the processing instructions (tests/orchestrator/test_paraview.py).
  XInclude of per-step files was tried and rejected: the Xdmf3 readers do not follow it.
* results.xdmf is always written before results.h5, so a results.h5 that lists a step means
  results.xdmf has it too.

Measured (``immerse bench output``, the bar wave's fields, medians): the whole output (step file
+ index append) costs 7.9 / 8.3 / 8.8 ms after 10 / 100 / 1000 outputs, the index append 4.0 /
4.2 / 4.5 ms; the mean over 1000 outputs, rewrites included, 10.6 ms. The bar wave itself runs
in 0.62 s with 12 outputs and 5.9 s with 240 (138 s before), each output added costing the same
(23 ms in the run).

:func:`write_index` is the recovery path (the launcher calls it after a run): unless the index
already lists exactly the step files on disk, it re-reads every step file and rewrites both files
atomically; it yields the same index as the appends (tests/orchestrator/test_output.py).

External links are stored relative to results.h5 ("steps/<file>"); HDF5 resolves a
relative external link in the directory of the parent file before trying the current
working directory, so results.h5 can be opened from any working directory.

Field conventions (used by the XDMF attribute types and by orchestrator.view):

* shape (n,) -> Scalar, (n, 3) -> Vector, (n, 9) -> Tensor, other (n, k) -> Matrix.
* shape (n, 6) is a symmetric tensor stored in the solvers' Voigt order
  TENSOR6_COMPONENTS = (xx, yy, zz, xy, yz, zx) (tensor shears, not engineering ones), which
  is VTK's order for symmetric tensors (XX, YY, ZZ, XY, YZ, XZ). The XDMF file describes it as
  a ``Matrix`` of Dimensions "n 1 6" (one 1 x 6 matrix per cell) pointing at the stored
  dataset: ParaView 5.11's three XDMF readers and the XDMF reader of VTK 9.7 (pyvista) then
  all give 6 components, named XX YY ZZ XY YZ XZ by ParaView, with the stored values. Measured
  alternatives (tests/orchestrator/test_paraview.py holds the matrix): ``Tensor6`` is expanded
  to 9 components "0".."8" by the legacy reader but passed through unexpanded by the Xdmf3
  readers (no data order is right in both); ``Tensor`` (n, 9) gets components named 0..8; a
  ``Matrix`` of Dimensions "n 6" is read as one tuple of 6n values by VTK 9.7's legacy reader;
  the Function/HyperSlab items used before were dropped by the Xdmf3 readers ("Skipping
  unrecognized array type"). Other (n, k) arrays are described the same way.
* boolean arrays are stored as uint8 (XDMF has no boolean type).
"""

from __future__ import annotations

import bisect
import contextlib
import os
import shutil
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import h5py
import numpy as np

__all__ = [
    "STEPS_DIR",
    "INDEX_H5",
    "INDEX_XDMF",
    "TENSOR6_COMPONENTS",
    "CELL_TYPES",
    "OutputError",
    "OutputIndex",
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
    "pressure",
]

INDEX_H5 = "results.h5"
INDEX_XDMF = "results.xdmf"

# the step files (written by the solver groups' ranks) are adapters/step_files.py's, below both the
# adapters and this index: read here under the same names
from adapters.step_files import (  # noqa: E402,F401
    _MESH_RE, _NAME_RE, _ROLE_RE, _STEP_RE, CELL_TYPES, STEPS_DIR, TENSOR6_COMPONENTS, OutputError, _as_storable,
    _atomic_h5, _check_role, _commit, _fsync, _tmp_name, mesh_path, pressure, step_path, von_mises, write_mesh,
    write_step)


def _link_name(index: int) -> str:
    return f"{int(index):06d}"


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
    def shapes(f: h5py.File, group: str) -> dict:
        # h5py's low-level objects: a third of the time of its Dataset wrappers (once per output)
        if group not in f:
            return {}
        gid = f[group].id
        return {name.decode(): (d.shape, d.dtype) for name in gid for d in [h5py.h5d.open(gid, name)]}

    try:
        with h5py.File(path, "r") as f:
            points = h5py.h5d.open(f.id, b"points")
            info = {
                "time": float(f.attrs["time"]),
                "step": int(f.attrs["step"]),
                "points": (points.shape, points.dtype),
                "point_data": shapes(f, "point_data"),
                "cell_data": shapes(f, "cell_data"),
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
    # (n, 6) symmetric tensors as Matrix: see the module docstring
    return {1: "Scalar", 3: "Vector", 9: "Tensor"}.get(shape[1], "Matrix")


def _data_item(parent: ET.Element, shape: tuple, dtype, ref: str) -> ET.Element:
    number, precision = _xdmf_number(dtype)
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(str(int(s)) for s in shape),
                         NumberType=number, Precision=precision, Format="HDF")
    item.text = ref
    return item


_XDMF_HEAD = b'<?xml version="1.0" encoding="utf-8"?>\n<Xdmf Version="3.0">\n <Domain>\n'
_XDMF_TAIL = b" </Domain>\n</Xdmf>\n"
_COLLECTION_CLOSE = b"  </Grid>\n"
_MARK = b"<?immerse-append"  # opens the free room at the end of a collection (a processing instruction)
_MIN_ROOM = 64 * 1024        # bytes of free room after a rewrite, at least


def _collection_open(role: str) -> bytes:
    return f'  <Grid Name="{role}" GridType="Collection" CollectionType="Temporal">\n'.encode()


def _grid_xml(role: str, mesh: tuple, mesh_file: str, idx: int, fname: str, info: dict) -> bytes:
    """One Uniform grid of a role's Temporal collection (indented for its place in the file)."""
    cshape, cdtype, ctype = mesh
    topo_type, npe = CELL_TYPES[ctype]
    ne = cshape[0]
    grid = ET.Element("Grid", Name=f"{role}_{idx:06d}", GridType="Uniform")
    ET.SubElement(grid, "Time", Value=repr(info["time"]))
    topo = ET.SubElement(grid, "Topology", TopologyType=topo_type, NumberOfElements=str(ne),
                         NodesPerElement=str(npe))
    _data_item(topo, cshape, cdtype, f"{STEPS_DIR}/{mesh_file}:/cells")
    geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    pshape, pdtype = info["points"]
    _data_item(geo, pshape, pdtype, f"{STEPS_DIR}/{fname}:/points")
    nn = pshape[0]
    for center, group, rows in (("Node", "point_data", nn), ("Cell", "cell_data", ne)):
        for name, (shape, dtype) in sorted(info[group].items()):
            atype = _attribute_type(shape)
            if atype is None or shape[0] != rows:
                warnings.warn(f"{fname}: {group}/{name} with shape {shape} is not described in "
                              f"the XDMF file", stacklevel=4)
                continue
            attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=atype, Center=center)
            # a Matrix is one 1 x k matrix per row (see the module docstring)
            item_shape = (shape[0], 1, shape[1]) if atype == "Matrix" else shape
            _data_item(attr, item_shape, dtype, f"{STEPS_DIR}/{fname}:/{group}/{name}")
    ET.indent(grid, space=" ", level=3)
    text = ("   " + ET.tostring(grid, encoding="unicode") + "\n").encode()
    if b"?>" in text:  # cannot happen: ElementTree escapes '>' (the append scheme relies on it)
        raise OutputError(f"grid {role}_{idx:06d} would end the XDMF append room early")
    return text


def _pwrite_all(fd: int, data: bytes, offset: int) -> None:
    view = memoryview(data)
    while view:
        n = os.pwrite(fd, view, offset)
        view, offset = view[n:], offset + n


def _copy_file(src: Path, dst: Path) -> None:
    """Copy in the kernel where it can (no pass through user space)."""
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        size = os.fstat(fin.fileno()).st_size
        copied = 0
        try:
            while copied < size:
                n = os.copy_file_range(fin.fileno(), fout.fileno(), size - copied, copied, copied)
                if n == 0:
                    break
                copied += n
        except (AttributeError, OSError):
            copied = 0
        if copied < size:
            fin.seek(0)
            fout.seek(0)
            fout.truncate()
            shutil.copyfileobj(fin, fout)


# ----------------------------------------------------------------------------- index
@dataclass
class _RoleIndex:
    steps: list = field(default_factory=list)  # [(index, step file name, _describe_step)] sorted
    mesh: tuple | None = None                   # _describe_mesh of the role's mesh file
    mesh_file: str | None = None
    room: tuple[int, int] | None = None          # results.xdmf offsets: free-room PI start, its "?>"


class OutputIndex:
    """The index (results.h5 and results.xdmf) of an output directory, held in memory.

    Built once from the files on disk (a scan that reads every step file's attributes); then
    :meth:`append` adds the steps of one output index at a cost that does not grow with the number
    of steps before it (see the module docstring). Both files stay readable at every instant.
    """

    def __init__(self, out_dir):
        self.out = Path(out_dir)
        self.roles: dict[str, _RoleIndex] = {}
        self._xdmf_id: tuple[int, int] | None = None  # (inode, size) of the results.xdmf we wrote
        steps, meshes = _scan(self.out)
        for role in sorted(set(steps) | set(meshes)):
            entry = self.roles[role] = _RoleIndex()
            for idx, path in steps.get(role, []):
                info = _describe_step(path)
                if info is not None:
                    entry.steps.append((idx, path.name, info))
            if role in meshes:
                entry.mesh = _describe_mesh(meshes[role])
                entry.mesh_file = meshes[role].name if entry.mesh is not None else None
        self._write_xdmf()
        self._write_h5()  # second: a results.h5 that lists a step means results.xdmf has it

    @property
    def paths(self) -> tuple[Path, Path]:
        return self.out / INDEX_H5, self.out / INDEX_XDMF

    # ---- appending ------------------------------------------------------------------------------
    def append(self, index: int, roles: Iterable[str]) -> list[str]:
        """Add the step files ``steps/<role>_<index>.h5`` that exist for ``roles``; the roles added.

        Steps in increasing index order are appended; a step written again or out of order, and
        the first mesh of a role, rewrite both files from memory (atomically; rare)."""
        index = int(index)
        added: list[str] = []
        rewrite = False
        for role in roles:
            _check_role(role)
            entry = self.roles.get(role)
            if entry is None or entry.mesh is None:
                mpath = mesh_path(self.out, role)
                described = _describe_mesh(mpath) if mpath.is_file() else None
                if described is not None:
                    entry = self.roles.setdefault(role, _RoleIndex())
                    entry.mesh, entry.mesh_file = described, mpath.name
                    rewrite = True  # a new collection in the XDMF file, a mesh link in results.h5
            path = step_path(self.out, role, index)
            info = _describe_step(path) if path.is_file() else None
            if info is None:
                continue
            entry = self.roles.setdefault(role, _RoleIndex())
            row = (index, path.name, info)
            if entry.steps and entry.steps[-1][0] >= index:
                entry.steps = [s for s in entry.steps if s[0] != index]
                bisect.insort(entry.steps, row, key=lambda s: s[0])
                rewrite = True
            else:
                entry.steps.append(row)
            added.append(role)
        if rewrite or (added and not (self.out / INDEX_H5).is_file()):
            self._write_xdmf()
            self._write_h5()
        elif added:
            self._append_xdmf(added)
            self._append_h5(added)  # second, as in __init__
        return added

    # ---- results.h5 -----------------------------------------------------------------------------
    _H5_COLUMNS = (("times", np.float64), ("steps", np.int64), ("indices", np.int64))

    def _h5_group(self, f: h5py.File, role: str) -> h5py.Group:
        if role in f:
            return f[role]
        entry = self.roles[role]
        g = f.create_group(role)
        if entry.mesh is not None:
            g.attrs["cell_type"] = entry.mesh[2]
            g["mesh"] = h5py.ExternalLink(f"{STEPS_DIR}/{entry.mesh_file}", "/")
        for name, dtype in self._H5_COLUMNS:
            g.create_dataset(name, shape=(0,), maxshape=(None,), chunks=(1024,), dtype=dtype)
        return g

    @staticmethod
    def _h5_add(g: h5py.Group, rows: list) -> None:
        if not rows:
            return
        columns = ([r[2]["time"] for r in rows], [r[2]["step"] for r in rows], [r[0] for r in rows])
        for (name, _), values in zip(OutputIndex._H5_COLUMNS, columns):
            ds = g[name]
            n = ds.shape[0]
            ds.resize((n + len(rows),))
            ds[n:] = values
        for idx, fname, _ in rows:
            g[_link_name(idx)] = h5py.ExternalLink(f"{STEPS_DIR}/{fname}", "/")

    def _write_h5(self) -> None:
        with _atomic_h5(self.out / INDEX_H5) as f:
            f.attrs["layout"] = "immerse-output-1"
            for role, entry in sorted(self.roles.items()):
                self._h5_add(self._h5_group(f, role), entry.steps)

    def _append_h5(self, roles: list[str]) -> None:
        path = self.out / INDEX_H5
        tmp = _tmp_name(path)
        try:
            _copy_file(path, tmp)
            with h5py.File(tmp, "r+") as f:
                for role in roles:
                    self._h5_add(self._h5_group(f, role), self.roles[role].steps[-1:])
            # no fsync here (the module docstring says why): a rename is atomic against a kill
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise

    # ---- results.xdmf ---------------------------------------------------------------------------
    def _grid(self, role: str, row: tuple) -> bytes:
        entry = self.roles[role]
        return _grid_xml(role, entry.mesh, entry.mesh_file, *row)

    def _write_xdmf(self) -> None:
        """The whole file, atomically, with a free room at the end of each collection."""
        parts = [_XDMF_HEAD]
        size = len(_XDMF_HEAD)
        rooms = {}
        for role, entry in sorted(self.roles.items()):
            if entry.mesh is None:
                continue  # no topology to describe (yet)
            grids = [_MARK + b" ?>" + self._grid(role, row) for row in entry.steps]
            live = sum(map(len, grids))
            room = _MARK + b" " * max(_MIN_ROOM, live) + b"?>\n"
            opener = _collection_open(role)
            parts += [opener, *grids, room, _COLLECTION_CLOSE]
            start = size + len(opener) + live
            rooms[role] = (start, start + len(room) - 3)
            size = start + len(room) + len(_COLLECTION_CLOSE)
        parts.append(_XDMF_TAIL)
        path = self.out / INDEX_XDMF
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = _tmp_name(path)
        try:
            with open(tmp, "wb") as fh:
                fh.write(b"".join(parts))
            st = os.stat(tmp)
            _commit(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        for role, entry in self.roles.items():
            entry.room = rooms.get(role)
        self._xdmf_id = (st.st_ino, st.st_size)

    def _append_xdmf(self, roles: list[str]) -> None:
        """The new grids written into the free rooms in place (module docstring, steps 1-3)."""
        path = self.out / INDEX_XDMF
        try:
            fd = os.open(path, os.O_RDWR)
        except OSError:
            return self._write_xdmf()
        try:
            st = os.fstat(fd)
            plans = []
            for role in roles:
                entry = self.roles[role]
                if entry.mesh is None:
                    continue
                grid = self._grid(role, entry.steps[-1])
                start, end = entry.room
                body = start + len(_MARK) + 3  # " ?>" of step 3 goes before the grid
                fits = body + len(grid) + len(_MARK) + 1 <= end
                # the file must still be the one we wrote (nobody rewrote it behind our back)
                ours = ((st.st_ino, st.st_size) == self._xdmf_id
                        and os.pread(fd, len(_MARK), start) == _MARK and os.pread(fd, 2, end) == b"?>")
                if not (fits and ours):
                    plans = None
                    break
                plans.append((entry, start, body, grid))
            if plans:
                for entry, start, body, grid in plans:
                    _pwrite_all(fd, grid, body)                   # 1. inside the room's PI
                    _pwrite_all(fd, _MARK, body + len(grid))      # 2. the next room's opener
                os.fdatasync(fd)
                for entry, start, body, grid in plans:
                    _pwrite_all(fd, b"?>", start + len(_MARK) + 1)  # 3. close the PI before G
                    entry.room = (body + len(grid), entry.room[1])
        finally:
            os.close(fd)
        if plans is None:
            self._write_xdmf()


def write_index(out_dir) -> tuple[Path, Path]:
    """Make out/results.h5 and out/results.xdmf index the step files on disk: the recovery path
    (the launcher calls it after a run; a running job appends with an :class:`OutputIndex`).

    An index the appends completed is left as it is: results.h5 lists exactly the step and mesh
    files on disk and none of them is newer than it (checked from the directory listing, without
    reading the step files; results.h5 is written after results.xdmf, so that one is complete
    too). Otherwise both files are rebuilt atomically from every step file."""
    out_dir = Path(out_dir)
    if not _index_is_current(out_dir):
        OutputIndex(out_dir)
    return out_dir / INDEX_H5, out_dir / INDEX_XDMF


def _index_is_current(out_dir: Path) -> bool:
    h5, xdmf = out_dir / INDEX_H5, out_dir / INDEX_XDMF
    try:
        written = h5.stat().st_mtime_ns
        if not xdmf.is_file():
            return False
        listed = {}
        with h5py.File(h5, "r") as f:
            for role in f:
                g = f[role]
                listed[role] = (sorted(int(i) for i in g["indices"][()]), "mesh" in g)
    except (OSError, KeyError, ValueError, TypeError):
        return False
    steps, meshes = {}, set()
    sdir = out_dir / STEPS_DIR
    entries = list(os.scandir(sdir)) if sdir.is_dir() else []
    for entry in entries:
        m = _STEP_RE.match(entry.name)
        if m:
            steps.setdefault(m["role"], []).append(int(m["index"]))
        elif _MESH_RE.match(entry.name):
            meshes.add(entry.name[: -len("_mesh.h5")])
        else:
            continue
        if entry.stat().st_mtime_ns > written:
            return False
    on_disk = {r: (sorted(steps.get(r, [])), r in meshes) for r in set(steps) | meshes}
    return on_disk == listed


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
