"""Tests for orchestrator/output.py: layout, index, XDMF, external links, kill safety."""

import os
import random
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from orchestrator import output
from orchestrator.output import (
    INDEX_H5,
    INDEX_XDMF,
    OutputError,
    OutputIndex,
    mesh_path,
    read_mesh_file,
    read_step,
    read_step_attrs,
    read_steps,
    step_path,
    pressure,
    von_mises,
    write_index,
    write_mesh,
    write_step,
)
from solvers.lagrange.mesh import box_mesh

REPO = Path(__file__).resolve().parents[2]
ROLE = "lagrange"


def fields(mesh, i):
    nn, ne = mesh.num_points, mesh.num_cells
    vel = np.full((nn, 3), float(i))
    vel[:, 0] = np.arange(nn) + i
    temp = 300.0 + i + np.zeros(nn)
    stress = np.tile(np.arange(1.0, 7.0), (ne, 1)) * (i + 1)
    return {"velocity": vel, "temperature": temp}, {"stress": stress, "plastic": np.arange(ne) % 2 == 0}


def write_series(out, mesh, n=3, role=ROLE):
    write_mesh(out, role, mesh.cells, mesh.cell_type)
    for i in range(n):
        pd, cd = fields(mesh, i)
        write_step(out, role, i, 10 * i, 0.5 * i, mesh.points, pd, cd)
    return write_index(out)


def attr_of(grid, item):
    return next(a for a in grid.findall("Attribute") if item in list(a.iter("DataItem")))


def check_xdmf(xdmf: Path, expected_times=None):
    """Every HDF DataItem must exist with the declared dimensions and number type."""
    root = ET.parse(xdmf).getroot()
    assert root.tag == "Xdmf" and root.get("Version") == "3.0"
    domain = root.find("Domain")
    colls = domain.findall("Grid")
    assert colls
    n_items = 0
    for coll in colls:
        assert coll.get("GridType") == "Collection" and coll.get("CollectionType") == "Temporal"
        times = []
        for grid in coll.findall("Grid"):
            assert grid.get("GridType") == "Uniform"
            times.append(float(grid.find("Time").get("Value")))
            topo = grid.find("Topology")
            ne = int(topo.get("NumberOfElements"))
            npe = int(topo.get("NodesPerElement"))
            assert topo.find("DataItem").get("Dimensions") == f"{ne} {npe}"
            nn = int(grid.find("Geometry/DataItem").get("Dimensions").split()[0])
            for attr in grid.findall("Attribute"):
                rows = int(attr.find("DataItem").get("Dimensions").split()[0])
                assert rows == (nn if attr.get("Center") == "Node" else ne)
                ncomp = {"Scalar": 1, "Vector": 3, "Tensor": 9}.get(attr.get("AttributeType"))
                dims = attr.find("DataItem").get("Dimensions").split()
                if ncomp is not None:
                    assert (int(dims[1]) if len(dims) > 1 else 1) == ncomp
                if attr.get("AttributeType") == "Matrix":  # e.g. symmetric tensors: one 1 x k matrix per row
                    assert len(dims) == 3 and dims[1] == "1"
            for item in grid.iter("DataItem"):
                assert item.get("ItemType") is None  # plain items only: the Xdmf3 readers drop Functions
                assert item.get("Format") == "HDF"
                fname, dset = item.text.strip().split(":")
                assert not os.path.isabs(fname)
                with h5py.File(xdmf.parent / fname, "r") as f:
                    d = f[dset]
                    dims = [int(s) for s in item.get("Dimensions").split()]
                    assert list(d.shape) == (dims[:1] + dims[2:] if len(dims) == 3 else dims)
                    assert int(item.get("Precision")) == d.dtype.itemsize
                    assert item.get("NumberType") == {"f": "Float", "i": "Int", "u": "UChar"}[d.dtype.kind] \
                        or (d.dtype.kind == "u" and item.get("NumberType") == "UInt")
                n_items += 1
        assert times == sorted(times)
        if expected_times is not None and coll.get("Name") == ROLE:
            np.testing.assert_allclose(times, expected_times)
    return n_items


# ----------------------------------------------------------------------------- basic
def test_write_read_roundtrip_2d(tmp_path):
    mesh = box_mesh([0, 0], [2, 1], [4, 2])
    out = tmp_path / "out"
    h5, xdmf = write_series(out, mesh, n=3)
    assert h5 == out / INDEX_H5 and xdmf == out / INDEX_XDMF
    assert step_path(out, ROLE, 2).name == "lagrange_000002.h5"
    assert sorted(p.name for p in (out / "steps").iterdir()) == [
        "lagrange_000000.h5", "lagrange_000001.h5", "lagrange_000002.h5", "lagrange_mesh.h5"]
    assert read_steps(out, ROLE) == [(0.0, 0, 0), (0.5, 10, 1), (1.0, 20, 2)]
    cells, ctype = read_mesh_file(out, ROLE)
    assert ctype == "quad" and cells.dtype == np.int64
    np.testing.assert_array_equal(cells, mesh.cells)
    pts, pd, cd = read_step(out, ROLE, 1)
    assert pts.shape == (mesh.num_points, 3)
    np.testing.assert_array_equal(pts[:, :2], mesh.points)
    np.testing.assert_array_equal(pts[:, 2], 0.0)
    epd, ecd = fields(mesh, 1)
    for k in epd:
        np.testing.assert_array_equal(pd[k], epd[k])
    np.testing.assert_array_equal(cd["stress"], ecd["stress"])
    np.testing.assert_array_equal(cd["plastic"], ecd["plastic"].astype(np.uint8))
    assert read_step_attrs(out, ROLE, 2) == {"time": 1.0, "step": 20, "index": 2}
    with h5py.File(step_path(out, ROLE, 0), "r") as f:
        assert {"time", "step", "index"} <= set(f.attrs)
    with h5py.File(mesh_path(out, ROLE), "r") as f:
        assert f.attrs["cell_type"] == "quad"
    assert not list(out.rglob("*.tmp"))


def test_results_h5_from_other_cwd(tmp_path, monkeypatch):
    """External links are relative to results.h5, not to the working directory."""
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [2, 2, 2])
    out = tmp_path / "case" / "out"
    write_series(out, mesh, n=3)
    # a decoy tree in the cwd with the same relative paths but different content
    decoy = tmp_path / "elsewhere"
    write_series(decoy, box_mesh([0, 0, 0], [5, 5, 5], [1, 1, 1]), n=3)
    monkeypatch.chdir(decoy)
    rel = os.path.relpath(out / INDEX_H5, decoy)
    with h5py.File(rel, "r") as f:
        g = f[ROLE]
        np.testing.assert_allclose(g["times"][()], [0.0, 0.5, 1.0])
        np.testing.assert_array_equal(g["steps"][()], [0, 10, 20])
        np.testing.assert_array_equal(g["indices"][()], [0, 1, 2])
        assert g.attrs["cell_type"] == "hexahedron"
        np.testing.assert_array_equal(g["mesh/cells"][()], mesh.cells)
        for i in range(3):
            step = g[f"{i:06d}"]
            assert step.attrs["index"] == i
            assert step["points"].shape == (mesh.num_points, 3)
            np.testing.assert_array_equal(step["points"][()], mesh.points)
            np.testing.assert_array_equal(step["point_data/velocity"][()], fields(mesh, i)[0]["velocity"])
    # and the stored link is relative
    with h5py.File(rel, "r") as f:
        link = f[ROLE].get("000001", getlink=True)
        assert isinstance(link, h5py.ExternalLink)
        assert link.filename == "steps/lagrange_000001.h5"
    assert read_steps(os.path.relpath(out, decoy), ROLE)[-1] == (1.0, 20, 2)


def test_xdmf_references(tmp_path):
    mesh = box_mesh([0, 0, 0], [1, 2, 1], [2, 3, 1])
    out = tmp_path / "out"
    _, xdmf = write_series(out, mesh, n=3)
    n = check_xdmf(xdmf, expected_times=[0.0, 0.5, 1.0])
    assert n == 3 * (1 + 1 + 4)  # topology, geometry, 4 fields
    root = ET.parse(xdmf).getroot()
    grid = root.find("Domain/Grid/Grid")
    types = {a.get("Name"): (a.get("AttributeType"), a.get("Center")) for a in grid.findall("Attribute")}
    assert types == {"velocity": ("Vector", "Node"), "temperature": ("Scalar", "Node"),
                     "stress": ("Matrix", "Cell"), "plastic": ("Scalar", "Cell")}
    assert grid.find("Topology").get("TopologyType") == "Hexahedron"


def test_index_two_roles_and_incremental(tmp_path):
    out = tmp_path / "out"
    a = box_mesh([0, 0], [1, 1], [2, 2])
    b = box_mesh([0, 0], [1, 1], [1, 1])
    write_series(out, a, n=2, role="lagrange")
    write_series(out, b, n=1, role="sph_2")
    pd, cd = fields(a, 2)
    write_step(out, "lagrange", 2, 20, 1.0, a.points, pd, cd)
    assert [s[2] for s in read_steps(out, "lagrange")] == [0, 1]  # not yet indexed
    write_index(out)
    assert [s[2] for s in read_steps(out, "lagrange")] == [0, 1, 2]
    assert read_steps(out, "sph_2") == [(0.0, 0, 0)]
    root = ET.parse(out / INDEX_XDMF).getroot()
    assert [g.get("Name") for g in root.findall("Domain/Grid")] == ["lagrange", "sph_2"]
    check_xdmf(out / INDEX_XDMF)


def test_read_steps_without_index(tmp_path):
    out = tmp_path / "out"
    m = box_mesh([0, 0], [1, 1], [1, 1])
    write_mesh(out, ROLE, m.cells, "quad")
    write_step(out, ROLE, 4, 7, 0.25, m.points, {}, {})
    (out / "steps" / "lagrange_000005.h5.123.tmp").write_bytes(b"partial")
    assert read_steps(out, ROLE) == [(0.25, 7, 4)]
    write_index(out)  # ignores the stale tmp file
    assert read_steps(out, ROLE) == [(0.25, 7, 4)]


def test_invalid_arguments(tmp_path):
    m = box_mesh([0, 0], [1, 1], [1, 1])
    with pytest.raises(OutputError):
        write_mesh(tmp_path, ROLE, m.cells, "triangle")
    with pytest.raises(OutputError):
        write_mesh(tmp_path, ROLE, m.cells[:, :3], "quad")
    with pytest.raises(OutputError):
        write_step(tmp_path, "bad/role", 0, 0, 0.0, m.points, {}, {})
    with pytest.raises(OutputError):
        write_step(tmp_path, ROLE, 0, 0, 0.0, m.points, {"v": np.zeros(3)}, {})
    with pytest.raises(OutputError):
        write_step(tmp_path, ROLE, 0, 0, 0.0, m.points, {"a/b": np.zeros(4)}, {})
    with pytest.raises(OutputError):
        read_step(tmp_path, ROLE, 9)
    assert not list(Path(tmp_path).rglob("*.tmp"))


def test_von_mises():
    # stored order xx yy zz xy yz zx. Uniaxial: |sigma|; pure shear tau: sqrt(3) tau;
    # hydrostatic: 0; general case against the deviatoric definition sqrt(3/2 s:s)
    assert von_mises([[-5.0, 0, 0, 0, 0, 0]])[0] == pytest.approx(5.0)
    for col in (3, 4, 5):
        t = np.zeros((1, 6))
        t[0, col] = 2.0
        assert von_mises(t)[0] == pytest.approx(2.0 * np.sqrt(3.0))
    assert von_mises([[7.0, 7.0, 7.0, 0, 0, 0]])[0] == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(1)
    v = rng.normal(size=(5, 6))
    full = np.empty((5, 3, 3))
    full[:, [0, 1, 2], [0, 1, 2]] = v[:, :3]
    full[:, 0, 1] = full[:, 1, 0] = v[:, 3]
    full[:, 1, 2] = full[:, 2, 1] = v[:, 4]
    full[:, 2, 0] = full[:, 0, 2] = v[:, 5]
    dev = full - np.trace(full, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    np.testing.assert_allclose(von_mises(v), np.sqrt(1.5 * np.sum(dev**2, axis=(1, 2))), rtol=1e-12)


# ----------------------------------------------------------------------------- readers
def test_meshio_time_series_reader(tmp_path):
    meshio = pytest.importorskip("meshio")
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    out = tmp_path / "out"
    _, xdmf = write_series(out, mesh, n=3)
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        points, cells = reader.read_points_cells()
        np.testing.assert_array_equal(points, mesh.points)
        assert cells[0].type == "hexahedron"
        np.testing.assert_array_equal(cells[0].data, mesh.cells)
        assert reader.num_steps == 3
        for k in range(3):
            t, pd, cd = reader.read_data(k)
            assert t == 0.5 * k
            np.testing.assert_array_equal(pd["velocity"], fields(mesh, k)[0]["velocity"])
            np.testing.assert_array_equal(cd["plastic"][0], fields(mesh, k)[1]["plastic"])
            np.testing.assert_array_equal(cd["stress"][0], fields(mesh, k)[1]["stress"])


def test_vtk_xdmf_reader(tmp_path):
    """ParaView's legacy XDMF reader (vtkXdmfReader, in the vtk wheel) reads the series."""
    try:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
        from vtkmodules.vtkIOXdmf2 import vtkXdmfReader
    except ImportError:
        pytest.skip("vtkXdmfReader not available in this vtk build")
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [2, 2, 1])
    out = tmp_path / "out"
    _, xdmf = write_series(out, mesh, n=3)
    reader = vtkXdmfReader()
    reader.SetFileName(str(xdmf))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    np.testing.assert_allclose(times, [0.0, 0.5, 1.0])
    reader.UpdateTimeStep(1.0)
    grid = reader.GetOutputDataObject(0)
    assert grid.GetNumberOfPoints() == mesh.num_points
    assert grid.GetNumberOfCells() == mesh.num_cells
    assert grid.GetCellType(0) == 12  # VTK_HEXAHEDRON
    vel = vtk_to_numpy(grid.GetPointData().GetArray("velocity"))
    np.testing.assert_array_equal(vel, fields(mesh, 2)[0]["velocity"])
    # stored (xx yy zz xy yz zx) = (1..6)*3 reaches VTK 9.7's reader as stored: VTK's symmetric
    # tensor order (XX YY ZZ XY YZ XZ), so ParaView names the components right (test_paraview.py)
    stress = vtk_to_numpy(grid.GetCellData().GetArray("stress"))
    assert stress.shape == (mesh.num_cells, 6)
    np.testing.assert_array_equal(stress, fields(mesh, 2)[1]["stress"])


# ----------------------------------------------------------------------------- kill safety
CHILD = textwrap.dedent("""
    import sys
    import numpy as np
    from orchestrator.output import OutputIndex, write_mesh, write_step
    from solvers.lagrange.mesh import box_mesh

    out, start = sys.argv[1], int(sys.argv[2])
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [4, 4, 4])
    write_mesh(out, "lagrange", mesh.cells, mesh.cell_type)
    index = OutputIndex(out)  # rebuilt from the steps of the killed runs before, as on a restart
    nn, ne = mesh.num_points, mesh.num_cells
    print("ready", flush=True)
    i = start
    while True:
        vel = np.full((nn, 3), float(i))
        write_step(out, "lagrange", i, 100 * i, 0.01 * i, mesh.points,
                   {"velocity": vel, "temperature": np.full(nn, 300.0 + i)},
                   {"stress": np.full((ne, 6), float(i))})
        index.append(i, ["lagrange"])
        i += 1
""")


def _check_indexed(out: Path, other_cwd: Path) -> int:
    h5 = out / INDEX_H5
    if not h5.exists():
        return 0
    prev = os.getcwd()
    os.chdir(other_cwd)
    try:
        rel = os.path.relpath(h5, other_cwd)
        with h5py.File(rel, "r") as f:
            g = f[ROLE]
            idx = g["indices"][()]
            times = g["times"][()]
            for i, t in zip(idx, times):
                step = g[f"{i:06d}"]
                assert step.attrs["time"] == t == pytest.approx(0.01 * i)
                v = step["point_data/velocity"][()]
                assert v.shape[1] == 3 and np.all(v == float(i))
                assert np.all(step["cell_data/stress"][()] == float(i))
    finally:
        os.chdir(prev)
    steps = read_steps(out, ROLE)
    for _t, _s, i in steps:
        _pts, pd, _cd = read_step(out, ROLE, i)
        assert np.all(pd["temperature"] == 300.0 + i)
    check_xdmf(out / INDEX_XDMF)
    return len(steps)


@pytest.mark.timeout(180)
def test_sigkill_leaves_readable_index(tmp_path):
    """A writer appending to the index is killed at random instants, 12 times: results.h5 and
    results.xdmf always read, list only complete steps, and never lose one."""
    out = tmp_path / "out"
    other = tmp_path / "cwd"
    other.mkdir()
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    seed = int(os.environ.get("IMMERSE_TEST_SEED", time.time_ns() % 100_000))
    rng = random.Random(seed)
    indexed = 0
    for trial in range(12):
        existing = list((out / "steps").glob("lagrange_[0-9]*.h5")) if out.exists() else []
        start = 1 + max((int(p.stem.split("_")[-1]) for p in existing), default=-1)
        proc = subprocess.Popen([sys.executable, str(script), str(out), str(start)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
        try:
            line = proc.stdout.readline()
            assert line.strip() == "ready", f"child failed to start: {proc.stderr.read()}"
            # the first kill comes late enough for some steps to be indexed
            time.sleep(rng.uniform(0.3 if trial == 0 else 0.0, 0.4))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
        assert proc.returncode == -signal.SIGKILL, f"seed {seed}: child exited early: {proc.stderr.read()}"
        n = _check_indexed(out, other)
        assert n >= indexed, f"seed {seed}: index lost steps"
        indexed = n
    # the survivors' state can always be re-indexed, stale *.tmp files are ignored
    write_index(out)
    assert _check_indexed(out, other) >= indexed
    assert indexed > 0


# ----------------------------------------------------------------------------- appending
def index_contents(out: Path) -> tuple[bytes, list]:
    """What a reader gets from results.xdmf (the append room's padding aside) and results.h5."""
    xdmf = re.sub(rb"<\?immerse-append +\?>", b"<?immerse-append ?>", (out / INDEX_XDMF).read_bytes())
    items = []
    with h5py.File(out / INDEX_H5, "r") as f:
        def visit(name, link):
            if isinstance(link, h5py.ExternalLink):
                items.append((name, link.filename, link.path))
            elif isinstance(f[name], h5py.Dataset):
                items.append((name, f[name].dtype.str, f[name][()].tolist()))
            else:
                items.append((name, sorted((k, str(v)) for k, v in f[name].attrs.items())))
        f.visititems_links(visit)
        items.append(("/", sorted((k, str(v)) for k, v in f.attrs.items())))
    return xdmf, sorted(items)


def test_append_equals_rebuild(tmp_path):
    """Appending (two roles, 3-D and 2-D; a role whose mesh comes with its first step, as the ALE
    writes it; a step written again, one out of order) gives the index the full rescan gives."""
    out = tmp_path / "out"
    hexes = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    quads = box_mesh([0, 0], [1, 1], [2, 2])
    write_mesh(out, "lagrange", hexes.cells, hexes.cell_type)
    index = OutputIndex(out)
    rebuilt = tmp_path / "rebuilt"
    for i in [0, 1, 2, 3, 2, 5, 4, 6]:  # 2 written again, 4 after 5
        pd, cd = fields(hexes, i)
        write_step(out, "lagrange", i, 10 * i, 0.5 * i, hexes.points, pd, cd)
        if i >= 1:
            if i == 1:
                write_mesh(out, "ale", quads.cells, quads.cell_type)
            qd = {"density": np.full(quads.num_cells, 1.0 + i), "stress": np.full((quads.num_cells, 6), float(i))}
            write_step(out, "ale", i, 10 * i, 0.5 * i, quads.points, {"velocity": np.zeros((quads.num_points, 3))}, qd)
        assert index.append(i, ["lagrange", "ale", "sph"]) == ["lagrange", "ale"][: 1 + (i >= 1)]
        appended = index_contents(out)
        shutil.rmtree(rebuilt, ignore_errors=True)
        shutil.copytree(out, rebuilt)
        OutputIndex(rebuilt)  # the full rescan (write_index would find the index complete)
        assert index_contents(rebuilt) == appended, f"after output {i}"
    assert [s[2] for s in read_steps(out, "lagrange")] == [0, 1, 2, 3, 4, 5, 6]
    assert [s[2] for s in read_steps(out, "ale")] == [1, 2, 3, 4, 5, 6]
    check_xdmf(out / INDEX_XDMF)
    # and a restart: built again from disk, then appending
    index = OutputIndex(out)
    pd, cd = fields(hexes, 7)
    write_step(out, "lagrange", 7, 70, 3.5, hexes.points, pd, cd)
    index.append(7, ["lagrange", "ale"])
    appended = index_contents(out)
    OutputIndex(out)
    assert index_contents(out) == appended
    assert read_steps(out, "lagrange")[-1] == (3.5, 70, 7)


def test_write_index_rebuilds_only_what_is_not_indexed(tmp_path, monkeypatch):
    """The recovery path leaves a complete index alone (a successful run: no step file re-read),
    and rebuilds it when a step file is not indexed, is gone, or was written after the index."""
    out = tmp_path / "out"
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    write_mesh(out, ROLE, mesh.cells, mesh.cell_type)
    index = OutputIndex(out)
    for i in range(4):
        pd, cd = fields(mesh, i)
        write_step(out, ROLE, i, 10 * i, 0.5 * i, mesh.points, pd, cd)
        index.append(i, [ROLE])
    described = []
    describe = output._describe_step
    monkeypatch.setattr(output, "_describe_step", lambda path: described.append(path.name) or describe(path))
    before = index_contents(out)
    write_index(out)
    assert described == [] and index_contents(out) == before
    # a step the coupler had no time to index (killed between the step file and the append)
    pd, cd = fields(mesh, 4)
    write_step(out, ROLE, 4, 40, 2.0, mesh.points, pd, cd)
    write_index(out)
    assert len(described) == 5 and [s[2] for s in read_steps(out, ROLE)] == [0, 1, 2, 3, 4]
    # a step file gone (a restart drops the steps it writes again)
    step_path(out, ROLE, 4).unlink()
    write_index(out)
    assert [s[2] for s in read_steps(out, ROLE)] == [0, 1, 2, 3]
    # a step file written again after the index (a later modification time)
    time.sleep(0.01)
    write_step(out, ROLE, 3, 31, 1.55, mesh.points, pd, cd)
    write_index(out)
    assert read_steps(out, ROLE)[-1] == (1.55, 31, 3)
    check_xdmf(out / INDEX_XDMF, expected_times=[0.0, 0.5, 1.0, 1.55])
    # an unreadable results.h5 is rebuilt too
    (out / INDEX_H5).write_bytes(b"not hdf5")
    write_index(out)
    assert read_steps(out, ROLE)[-1] == (1.55, 31, 3)


def test_append_reads_only_the_new_step(tmp_path, monkeypatch):
    """The cost of an append does not grow with the steps before it: each reads one step file, and
    results.xdmf is rewritten whole only when its free room is used up (geometrically rarer)."""
    out = tmp_path / "out"
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    write_mesh(out, ROLE, mesh.cells, mesh.cell_type)
    index = OutputIndex(out)
    described, rewrites = [], []
    describe, rewrite = output._describe_step, OutputIndex._write_xdmf
    monkeypatch.setattr(output, "_describe_step", lambda path: described.append(path.name) or describe(path))
    monkeypatch.setattr(OutputIndex, "_write_xdmf", lambda self: rewrites.append(len(described)) or rewrite(self))
    pd, cd = fields(mesh, 1)
    n = 400
    for i in range(n):
        write_step(out, ROLE, i, i, 0.1 * i, mesh.points, pd, cd)
        index.append(i, [ROLE])
    assert described == [f"{ROLE}_{i:06d}.h5" for i in range(n)]
    # a grid here is ~1.6 kB: room for 40 in the first 64 kB, then the room doubles with the file
    assert 2 <= len(rewrites) <= 6, rewrites
    assert all(b >= 1.8 * a for a, b in zip(rewrites[1:], rewrites[2:])), rewrites
    assert len(ET.parse(out / INDEX_XDMF).getroot().findall("Domain/Grid/Grid")) == n


def test_every_instant_of_an_append_is_readable(tmp_path, monkeypatch):
    """Replays the in-place writes of one XDMF append cut at every byte (a kill tears a write at
    any point): every intermediate file is well-formed XML and lists the old steps, plus the new
    one only once complete."""
    out = tmp_path / "out"
    mesh = box_mesh([0, 0, 0], [1, 1, 1], [1, 1, 1])
    write_series(out, mesh, n=0)
    index = OutputIndex(out)
    for i in range(3):
        pd, cd = fields(mesh, i)
        write_step(out, ROLE, i, i, 0.1 * i, mesh.points, pd, cd)
        index.append(i, [ROLE])
    before = (out / INDEX_XDMF).read_bytes()
    writes, pwrite = [], output._pwrite_all
    monkeypatch.setattr(output, "_pwrite_all", lambda fd, data, off: writes.append((off, bytes(data))) or pwrite(fd, data, off))
    pd, cd = fields(mesh, 3)
    write_step(out, ROLE, 3, 3, 0.3, mesh.points, pd, cd)
    index.append(3, [ROLE])
    after = (out / INDEX_XDMF).read_bytes()
    assert len(writes) == 3 and writes[2][1] == b"?>"  # grid, next opener, then the commit

    def grids(text: bytearray) -> list[str]:
        return [g.get("Name") for g in ET.fromstring(bytes(text)).findall("Domain/Grid/Grid")]

    old = grids(bytearray(before))
    assert old == [f"{ROLE}_{i:06d}" for i in range(3)]
    state = bytearray(before)
    for k, (off, data) in enumerate(writes):
        for cut in range(len(data) + 1):
            torn = bytearray(state)
            torn[off:off + cut] = data[:cut]
            complete = k == 2 and cut == len(data)
            try:
                ok = grids(torn) == old + [f"{ROLE}_000003"] * complete
            except ET.ParseError as exc:
                raise AssertionError(f"write {k} cut at {cut}: {exc}: {bytes(torn[off - 20:off + cut + 20])!r}") from None
            assert ok, (k, cut)
        state[off:off + len(data)] = data
    assert state == after


def test_pressure_and_von_mises_of_the_stored_order():
    # pressure = -trace/3; a stress state sigma = -p I + deviator has the pressure p for any deviator
    assert pressure([[-3.0, -6.0, -9.0, 1.0, 2.0, 3.0]])[0] == pytest.approx(6.0)
    assert von_mises([[1.0, 1.0, 1.0, 0, 0, 0]])[0] == pytest.approx(0.0, abs=1e-15)
