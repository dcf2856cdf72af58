"""ParaView as its users open results.xdmf: Debian's ParaView 5.11 `pvbatch` with each of its XDMF
readers (the legacy "XDMF Reader", Xdmf3ReaderS, Xdmf3ReaderT) reads every step of real runs (a 3-D
and a 2-D Lagrangian body, an ALE background with several materials and void) and of a two-role
output; every array of every role must be there with its number of components and the component
names ParaView shows, and equal to the values in the step files.

pvbatch runs ParaView's own Python (the system's), so it gets an environment without this venv and
a script file written here. Without pvbatch the tests are skipped with the reason; `.ci/run` installs
Debian's `paraview` and `python3-paraview` where it can."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from orchestrator.output import OutputIndex, list_roles, read_step, read_steps, write_mesh, write_step
from solvers.lagrange.mesh import box_mesh
from tests.conftest import immerse

READERS = ("XDMFReader", "Xdmf3ReaderS", "Xdmf3ReaderT")
# the names ParaView (vtkPVArrayInformation) gives to unnamed components, by component count
COMPONENT_NAMES = {1: [""], 3: ["X", "Y", "Z"], 6: ["XX", "YY", "ZZ", "XY", "YZ", "XZ"]}

PVBATCH_SCRIPT = textwrap.dedent('''
    """Reads results.xdmf with each XDMF reader at every time step; writes what it got (array
    names, component counts and the names ParaView shows; values in an .npz)."""
    import json
    import sys

    import numpy as np
    from paraview import servermanager as sm
    from paraview import simple
    from vtkmodules.util.numpy_support import vtk_to_numpy

    xdmf, dest = sys.argv[1], sys.argv[2]
    meta, values = {}, {}

    def leaves(obj):
        """Datasets of a composite in order (the XDMF file's roles are sorted by name)."""
        if obj.IsA("vtkMultiBlockDataSet"):
            for i in range(obj.GetNumberOfBlocks()):
                md = obj.GetMetaData(i) if obj.HasMetaData(i) else None
                name = md.Get(obj.NAME()) if md is not None and md.Has(obj.NAME()) else None
                for leaf_name, leaf in leaves(obj.GetBlock(i)):
                    yield leaf_name or name, leaf
        elif obj.IsA("vtkMultiPieceDataSet"):
            for i in range(obj.GetNumberOfPieces()):
                yield from leaves(obj.GetPiece(i))
        elif obj is not None:
            yield None, obj

    for reader in ("XDMFReader", "Xdmf3ReaderS", "Xdmf3ReaderT"):
        if reader == "XDMFReader":
            src = simple.XDMFReader(FileNames=[xdmf])
        else:
            src = getattr(simple, reader)(FileName=[xdmf])
        src.UpdatePipelineInformation()
        times = src.TimestepValues
        times = [float(t) for t in times] if hasattr(times, "__len__") else [float(times)]
        steps = []
        for k, t in enumerate(times):
            src.UpdatePipeline(t)
            shown = {}
            for center, infos in (("point", src.PointData), ("cell", src.CellData)):
                for a in infos:
                    shown[center + "/" + a.Name] = [a.GetComponentName(c) or ""
                                                    for c in range(a.GetNumberOfComponents())]
            blocks = []
            for b, (name, ds) in enumerate(leaves(sm.Fetch(src))):
                key = f"{reader}/{k}/{b}"
                values[key + "/points"] = vtk_to_numpy(ds.GetPoints().GetData()).copy()  # (a view of VTK memory)
                arrays = {}
                for center, data in (("point", ds.GetPointData()), ("cell", ds.GetCellData())):
                    for i in range(data.GetNumberOfArrays()):
                        arr = data.GetArray(i)
                        if arr is None or arr.GetName().startswith("vtk"):  # e.g. vtkGhostType
                            continue
                        values[f"{key}/{center}/{arr.GetName()}"] = vtk_to_numpy(arr).copy()
                        arrays[f"{center}/{arr.GetName()}"] = arr.GetNumberOfComponents()
                blocks.append({"name": name, "cells": ds.GetNumberOfCells(), "arrays": arrays})
            steps.append({"time": t, "blocks": blocks, "component_names": shown})
        meta[reader] = steps
        simple.Delete(src)
    np.savez(dest + ".npz", **values)
    with open(dest + ".json", "w") as fh:
        json.dump(meta, fh)
''')


def _pvbatch_env() -> dict:
    """The environment without this venv: pvbatch runs the system's Python with ParaView's modules."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")}
    venv_bin = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if p and p != venv_bin)
    return env


def find_pvbatch() -> tuple[str | None, str]:
    """(pvbatch's path, "") or (None, why it cannot be used)."""
    exe = shutil.which("pvbatch", path=_pvbatch_env()["PATH"])
    if exe is None:
        return None, ("pvbatch not found: install Debian's paraview and python3-paraview "
                      "(apt-get install -y --no-install-recommends paraview python3-paraview; .ci/run does "
                      "where it runs as root)")
    probe = subprocess.run([exe, "-c", "from paraview import simple; print('ok')"], capture_output=True,
                           text=True, env=_pvbatch_env(), timeout=120)
    if "ok" not in probe.stdout:
        return None, (f"pvbatch cannot import paraview.simple (python3-paraview missing?): "
                      f"{(probe.stderr.strip().splitlines() or ['no output'])[-1]}")
    return exe, ""


@pytest.fixture(scope="module")
def pvbatch():
    exe, why = find_pvbatch()
    if exe is None:
        pytest.skip(why)
    return exe


def read_with_paraview(exe: str, out: Path, tmp: Path) -> tuple[dict, dict, str]:
    script = tmp / "read_xdmf.py"
    script.write_text(PVBATCH_SCRIPT)
    dest = tmp / f"paraview_{out.name}"
    r = subprocess.run([exe, str(script), str(out / "results.xdmf"), str(dest)], capture_output=True,
                       text=True, env=_pvbatch_env(), timeout=300)
    assert r.returncode == 0, r.stderr
    meta = json.loads(Path(f"{dest}.json").read_text())
    with np.load(f"{dest}.npz") as npz:
        values = {k: npz[k] for k in npz.files}
    return meta, values, r.stderr


def check_every_array(exe: str, out: Path, tmp: Path) -> dict:
    """Each reader, each step, each role: the arrays of the step file, their component counts and
    names, their values; returns {reader: number of arrays compared} for the report."""
    meta, values, stderr = read_with_paraview(exe, out, tmp)
    # the Xdmf3 readers' word for an array they drop (the stress of the Function items before)
    assert "Skipping" not in stderr, stderr
    roles = [r for r in list_roles(out) if read_steps(out, r)]
    by_time = {}
    for role in roles:
        for time, _step, index in read_steps(out, role):
            by_time.setdefault(time, {})[role] = index
    compared = {}
    for reader in READERS:
        steps = meta[reader]
        assert [s["time"] for s in steps] == sorted(by_time), reader
        compared[reader] = 0
        for k, s in enumerate(steps):
            assert [b["name"] for b in s["blocks"] if b["name"]] in ([], roles), (reader, s["blocks"])
            assert len(s["blocks"]) == len(roles), (reader, s["time"])
            for b, (role, block) in enumerate(zip(roles, s["blocks"])):
                points, point_data, cell_data = read_step(out, role, by_time[s["time"]][role])
                key = f"{reader}/{k}/{b}"
                np.testing.assert_array_equal(values[key + "/points"], points)
                expected = {**{f"point/{n}": a for n, a in point_data.items()},
                            **{f"cell/{n}": a for n, a in cell_data.items()}}
                assert sorted(block["arrays"]) == sorted(expected), (reader, role)
                for name, stored in expected.items():
                    ncomp = 1 if stored.ndim == 1 else stored.shape[1]
                    assert block["arrays"][name] == ncomp, (reader, role, name)
                    assert s["component_names"][name] == COMPONENT_NAMES.get(ncomp), (reader, role, name)
                    got = values[f"{key}/{name}"]
                    # the file's float64 reaches VTK unchanged (round-off: none)
                    np.testing.assert_array_equal(got.reshape(stored.shape), stored, err_msg=f"{reader} {role} {name}")
                    compared[reader] += 1
    return compared


LAGRANGE_3D = """
[run]
dimension = 3
end_time = 4.0e-6
output_interval = 1.0e-6

[materials.steel]
model = "johnson_cook"
density = 7830.0
youngs_modulus = 206.9e9
poisson_ratio = 0.3
yield_stress = 806.0e6
hardening_modulus = 614.0e6
hardening_exponent = 0.168
strain_rate_coefficient = 0.0089
reference_strain_rate = 1.0
thermal_exponent = 1.1
melt_temperature = 1813.15
room_temperature = 293.15
specific_heat = 460.0
taylor_quinney = 0.9

[[lagrange.bodies]]
name = "bar"
material = "steel"
mesh = { box = { lower = [0.0, 0.0, 0.0], upper = [0.01, 0.002, 0.002], cells = [10, 2, 2] } }

[[boundaries]]
type = "velocity"
region = "x < 1e-9"
velocity = { x = 200.0, y = 50.0 }
"""

LAGRANGE_2D = """
[run]
dimension = 2
end_time = 4.0e-6
output_interval = 2.0e-6

[materials.steel]
model = "linear_elastic"
density = 7850.0
youngs_modulus = 210.0e9
poisson_ratio = 0.3

[[lagrange.bodies]]
name = "plate"
material = "steel"
mesh = { box = { lower = [0.0, 0.0], upper = [0.01, 0.004], cells = [8, 3] } }

[[boundaries]]
type = "velocity"
region = "x < 1e-9"
velocity = { x = 5.0, y = 2.0 }
"""

ALE_MATERIALS = """
[run]
dimension = 2
end_time = 4.0e-4
output_interval = 2.0e-4

[ale]
mode = "eulerian"
grid = { lower = [0.0, 0.0], upper = [1.0, 0.5], cells = [12, 6] }
materials.air = { eos = "ideal_gas", gamma = 1.4 }
materials.water = { eos = "stiffened_gas", gamma = 4.4, p_inf = 6.0e8 }
materials.vacuum = { eos = "void" }
regions = [
  { material = "air", density = 1.0, pressure = 1.0e5 },
  { material = "water", region = "x > 0.55", density = 1000.0, pressure = 1.0e9 },
  { material = "vacuum", region = "y > 0.4 and x < 0.3" },
]
"""


@pytest.mark.timeout(900)
@pytest.mark.parametrize("name, text", [("lagrange_3d", LAGRANGE_3D), ("lagrange_2d", LAGRANGE_2D),
                                        ("ale_materials", ALE_MATERIALS)])
def test_every_reader_reads_every_array(pvbatch, tmp_path, name, text):
    case = tmp_path / name
    case.mkdir()
    (case / "case.toml").write_text(text)
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out, timeout=600)
    assert r.returncode == 0, r.stderr
    role = "ale" if name.startswith("ale") else "lagrange"
    points, point_data, cells = read_step(out, role, read_steps(out, role)[-1][2])
    if role == "lagrange":
        # points are deformed: Warp By Vector with displacement and scale -1 gives the reference
        # configuration (README), i.e. the points of step 0 (round-off of x - (x - X) at 1 cm: ~2e-18 m)
        reference, _, _ = read_step(out, role, read_steps(out, role)[0][2])
        assert np.max(np.abs(point_data["displacement"])) > 1e-7
        np.testing.assert_allclose(points - point_data["displacement"], reference, rtol=0, atol=1e-17)
        # the stress scalars written for ParaView users: pressure = -trace/3, von Mises, both non-trivial
        s = cells["stress"]
        np.testing.assert_allclose(cells["pressure"], -(s[:, 0] + s[:, 1] + s[:, 2]) / 3, rtol=1e-14)
        assert np.all(cells["von_mises_stress"] >= 0) and np.max(np.abs(s[:, 3])) > 0
        assert np.max(cells["von_mises_stress"]) > 0 and np.ptp(cells["pressure"]) > 0
    else:  # several materials and void: per-material fields and the void's volume fraction
        assert {"volume_fraction_air", "volume_fraction_water", "volume_fraction_vacuum",
                "density_air", "density_water", "pressure"} <= set(cells)
    compared = check_every_array(pvbatch, out, tmp_path)
    assert all(n >= len(cells) * len(read_steps(out, role)) for n in compared.values()), compared


def test_two_roles_in_one_file(pvbatch, tmp_path):
    """A coupled run's file (two Temporal collections): every reader gives each role its own block."""
    out = tmp_path / "out"
    hexes = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    quads = box_mesh([0, 0], [2, 1], [3, 2])
    write_mesh(out, "lagrange", hexes.cells, hexes.cell_type)
    write_mesh(out, "ale", quads.cells, quads.cell_type)
    index = OutputIndex(out)
    rng = np.random.default_rng(7)
    for i in range(3):
        write_step(out, "lagrange", i, 10 * i, 0.5 * i, hexes.points + 0.01 * i,
                   {"velocity": rng.normal(size=(hexes.num_points, 3))},
                   {"stress": rng.normal(size=(hexes.num_cells, 6)), "plastic": np.arange(hexes.num_cells) % 2 == 0})
        write_step(out, "ale", i, 10 * i, 0.5 * i, quads.points, {"velocity": rng.normal(size=(quads.num_points, 3))},
                   {"density": rng.random(quads.num_cells), "pressure": rng.random(quads.num_cells)})
        index.append(i, ["lagrange", "ale"])
    compared = check_every_array(pvbatch, out, tmp_path)
    assert compared == {r: 3 * (3 + 3) for r in READERS}


TRACE_CHECK = textwrap.dedent('''
    """Loads a run's open_in_paraview.py as a module (its pipeline, not its view: no display here) and
    writes what ParaView got: each block's name, cell count, and the background's pressure."""
    import importlib.util
    import json
    import sys

    import numpy as np
    from paraview import servermanager as sm
    from vtkmodules.util.numpy_support import vtk_to_numpy

    spec = importlib.util.spec_from_file_location("trace", sys.argv[1])
    trace = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(trace)
    results, blocks, times = trace.open_results()
    got = {"times": times, "roles": list(blocks), "range": list(trace.field_range(blocks["ale"], times))}

    def leaf(obj):
        while obj is not None and (obj.IsA("vtkMultiBlockDataSet") or obj.IsA("vtkMultiPieceDataSet")):
            obj = obj.GetBlock(0) if obj.IsA("vtkMultiBlockDataSet") else obj.GetPiece(0)
        return obj

    for role, block in blocks.items():
        block.UpdatePipeline(times[-1])
        data = leaf(sm.Fetch(block))
        got[role] = {"cells": data.GetNumberOfCells()}
        if role == "ale":
            p = vtk_to_numpy(data.GetCellData().GetArray("pressure"))
            bf = data.GetCellData().GetArray("blocked_fraction")
            covered = (vtk_to_numpy(bf) if bf is not None else np.zeros(p.shape)) >= 1.0 - 1e-12
            got[role].update(nan=int(np.isnan(p).sum()), min=float(np.nanmin(p)), zeros=int((p == 0).sum()),
                             covered=int(covered.sum()), covered_zeros=int((p[covered] == 0).sum()))
    root = sm.Fetch(results)
    got["names"] = [root.GetMetaData(i).Get(root.NAME()) for i in range(root.GetNumberOfBlocks())]
    json.dump(got, open(sys.argv[2], "w"))
''')


def trace_check(exe: str, out: Path, tmp: Path) -> dict:
    """What OUT/open_in_paraview.py shows under pvbatch at the last output (TRACE_CHECK)."""
    script = tmp / "trace_check.py"
    script.write_text(TRACE_CHECK)
    dest = tmp / "got.json"
    p = subprocess.run([exe, str(script), str(out / "open_in_paraview.py"), str(dest)], capture_output=True,
                       text=True, env=_pvbatch_env(), timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(dest.read_text())


@pytest.mark.timeout(900)
@pytest.mark.parametrize("name, edits, body", [
    ("plate_in_shock_2d", [("end_time = 4.0e-3", "end_time = 1.0e-3"), ("output_interval = 0.5e-3", "output_interval = 2.5e-4")],
     "lagrange"),
    ("embedded_sph_piston", [("end_time = 0.2", "end_time = 0.02"), ("output_interval = 0.05", "output_interval = 0.01")],
     "sph"),
    ("water_air_box_body", [("end_time = 4.0e-3", "end_time = 1.0e-3"), ("output_interval = 1.0e-3", "output_interval = 2.5e-4")],
     "lagrange")])
def test_the_runs_paraview_script_names_the_groups_and_blanks_covered_zones(pvbatch, tmp_path, name, edits, body):
    """A coupled run's OUT/open_in_paraview.py (orchestrator/paraview_script.py) under pvbatch: the
    blocks are named by their roles (ale and the body's group), each holds its cells, and the gas
    pressure has no zero: the zones the body fills whole are NaN (the plate: 90 of 9,600 zones at the
    start, 57 at 4 ms as it bends; the block crossing the water surface of water_air_box_body, two
    materials per zone: its covered zones too; the SPH piston fills none whole), its smallest value
    and its range over the outputs those of the fluids (the default reader's pieces read 0 there
    before, and "0" / "1" as names)."""
    from tests.cases.test_cases import case_variant

    case = case_variant(tmp_path, name, *edits)
    out = tmp_path / "out"
    r = immerse("run", case, "--out", out)
    assert r.returncode in (0, 1), r.stderr
    got = trace_check(pvbatch, out, tmp_path)
    assert got["names"] == ["ale", body] and got["roles"] == ["ale", body], got
    assert got["ale"]["cells"] > 0 and got[body]["cells"] >= 0 and len(got["times"]) >= 3
    assert got["ale"]["zeros"] == 0 and got["ale"]["min"] > 0.0 and got["range"][0] > 0.0, got
    if body == "lagrange":
        assert got["ale"]["nan"] > 0, got
