"""Domain decomposition of the ALE solver: N ranks against one rank.

Reference: the one-rank run itself (COMM_SELF, in the same test).  The `mpi` tests run on all ranks
of COMM_WORLD (decomposed under `mpiexec -n 2|4 python -m pytest -m mpi`, trivially equal on one
rank); every state array, the output and the diagnostics must agree within 1e-12 relative, and
the fields are expected bitwise (same arithmetic in the same order on every rank).  One test
launches a 4-rank run of tests/solvers/ale/mpi_compare.py in a subprocess.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from solvers.ale.boundary import Boundaries
from solvers.ale.grid import CUT, Z_IMAGE, Z_INACTIVE, Z_REAL, Block, GridError
from solvers.ale.parallel import Decomposition, split_dims, structured_cells
from solvers.ale.solver import AleSolver, SolverError
from tests.solvers.ale import mpi_compare as mc

REPO = Path(__file__).resolve().parents[3]


@pytest.mark.mpi
@pytest.mark.parametrize("name", list(mc.CASES))
def test_decomposed_run_equals_one_rank(name):
    """Sod along x / y (2D), Sedov 3D, periodic streams (2D/3D), inflow/outflow faces, in Eulerian
    and Lagrangian modes (coupling impulses on some steps), scalar and monotonic q: within 1e-12
    relative of one rank."""
    world = MPI.COMM_WORLD
    r = mc.compare(world, name)
    if world.rank != 0:
        return
    assert int(np.prod(r["dims"])) == world.size
    bad = {k: v[0] for k, v in r["diff"].items() if not v[0] <= mc.TOL}
    assert not bad, f"{name} on {world.size} ranks {r['dims']}: {bad}"


@pytest.mark.mpi
@pytest.mark.parametrize("name", ["sedov_3d_eulerian", "open_2d_lagrangian", "sedov_3d_lagrangian_mono",
                                  "periodic_2d_mono", "open_2d_lagrangian_mono", "water_air_2d", "square_2d",
                                  "square_3d"])
def test_decomposed_fields_are_bitwise(name):
    """Gathered nodal forces and masses, halo exchange at every ghost fill: the state arrays and the
    output are the one-rank bits (only the diagnostics' sums over ranks round differently)."""
    world = MPI.COMM_WORLD
    r = mc.compare(world, name)
    if world.rank == 0:
        assert not [k for k, v in r["diff"].items() if not k.startswith("diag:") and not v[1]]


@pytest.fixture
def shared_dir():
    """A directory of rank 0 known to every rank (pytest's tmp_path is per process and its
    clean-up races between ranks)."""
    world = MPI.COMM_WORLD
    d = Path(world.bcast(tempfile.mkdtemp(prefix="ale_mpi_") if world.rank == 0 else None, root=0))
    yield d
    world.Barrier()
    if world.rank == 0:
        shutil.rmtree(d, ignore_errors=True)


@pytest.mark.mpi
def test_checkpoint_restart_across_rank_counts(shared_dir):
    """A checkpoint of N ranks continues bitwise on N ranks and on one rank; one rank's checkpoint
    continues on N ranks."""
    world = MPI.COMM_WORLD
    d = shared_dir
    cfg = mc.CASES["open_3d_eulerian"][0]()
    a = mc.run(world, cfg, 6)
    a.checkpoint(d / "many.h5")
    ref = mc.snapshot(mc.run(world, cfg, 6, s=a))
    b = AleSolver(world, cfg)
    b.restart(d / "many.h5")
    same = mc.snapshot(mc.run(world, cfg, 6, s=b))
    c = AleSolver(MPI.COMM_SELF, cfg)
    c.restart(d / "many.h5")
    one = mc.snapshot(mc.run(MPI.COMM_SELF, cfg, 6, s=c))
    # one rank's checkpoint (rank 0 writes its own), restarted on all ranks
    s1 = mc.run(MPI.COMM_SELF, cfg, 6)
    if world.rank == 0:
        s1.checkpoint(d / "one.h5")
    world.Barrier()
    e = AleSolver(world, cfg)
    e.restart(d / "one.h5")
    back = mc.snapshot(mc.run(world, cfg, 6, s=e))
    if world.rank != 0:
        return
    assert b.step == a.step == 12
    for other, bitwise in ((same, True), (one, False), (back, False)):
        diff = mc.differences(ref, other)
        assert all(v[0] <= mc.TOL for v in diff.values()), {k: v for k, v in diff.items() if v[0] > mc.TOL}
        fields = [v[1] for k, v in diff.items() if not k.startswith("diag:")]
        assert all(fields)
        if bitwise:
            assert all(v[1] for v in diff.values())  # the diagnostics too (same per-rank shares)


@pytest.mark.mpi
def test_failure_on_one_rank_raises_on_every_rank():
    """An invalid state in a zone of the last rank: every rank raises SolverError (no deadlock);
    the failing rank names the zone."""
    world = MPI.COMM_WORLD
    cfg = mc.CASES["sod_x_lagrangian"][0]()
    cfg["regions"].append({"material": "gas", "region": "x > 0.97", "density": 0.125, "pressure": -0.1})
    with pytest.raises(SolverError) as err:
        AleSolver(world, cfg)
    msg = str(err.value)
    if "on rank" not in msg:  # a rank holding zones x > 0.97 (i = 62, 63): its first bad zone
        assert "ALE zone (62, " in msg and "invalid thermodynamic state" in msg and "step 0" in msg
    if world.size == 1:
        assert "ALE zone (62, 0)" in msg
    elif world.rank == 0:  # holds x < 0.5 only
        assert f"on rank {world.size - 1} of the ALE group" in msg


@pytest.mark.slow
@pytest.mark.mpi
def test_four_ranks_in_a_subprocess():
    """`mpiexec -n 4` (oversubscribed on small machines) of every comparison case."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("already running under MPI")
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [str(Path(sys.executable).parent / "mpiexec"), "-n", "4", sys.executable, "-m",
           "tests.solvers.ale.mpi_compare"]
    p = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300, env=env)
    rows = [json.loads(line) for line in p.stdout.splitlines() if line.startswith("{")]
    assert p.returncode == 0, p.stdout + p.stderr
    assert {r["case"] for r in rows} == set(mc.CASES)
    for r in rows:
        assert r["ranks"] == 4 and int(np.prod(r["dims"])) == 4
        assert r["max_rel_fields"] <= mc.TOL and r["max_rel_diagnostics"] <= mc.TOL, r


def test_split_choice():
    assert split_dims(1, [7, 3]) == [1, 1]
    assert split_dims(4, [400, 1]) == [4, 1]          # a 1-zone axis is never split
    assert split_dims(2, [1, 400]) == [1, 2]
    assert split_dims(4, [12, 12, 12]) == [2, 2, 1]   # MPI.Compute_dims
    assert split_dims(4, [3, 400]) == [1, 4]          # 3 zones: not 2 per rank on 2 ranks
    assert split_dims(8, [40, 4, 4]) == [2, 2, 2]     # 2 zones per rank are enough
    assert split_dims(9, [5, 100]) == [1, 9]          # Compute_dims' [3, 3] leaves 1 zone: smallest cut
    with pytest.raises(GridError, match="cannot be split"):
        split_dims(16, [5, 5])


def test_split_covers_the_box():
    class Comm:  # the arithmetic of the split only
        size = 1

    dec = Decomposition(Comm(), [10, 7], [False, False])
    dec.dims = [3, 2]
    off = [dec.box((i, j)) for i in range(3) for j in range(2)]
    assert sorted({int(o[0][0]) for o in off}) == [0, 4, 7] and sorted({int(o[1][0]) for o in off}) == [3, 4]
    assert sum(int(np.prod(n)) for _, n in off) == 70


@pytest.mark.parametrize("cells", [[3, 2], [2, 3, 4]])
def test_global_connectivity_is_the_one_block_connectivity(cells):
    faces = {f: "wall" for f in ("x_lower", "x_upper", "y_lower", "y_upper", "z_lower", "z_upper")}
    B = Block([0.0] * len(cells), [1.0] * len(cells), cells, faces)
    assert np.array_equal(structured_cells(cells), B.connectivity())


def test_cut_faces_of_a_block():
    """A block cut on x_upper (2 ranks along x): its upper ghosts are images, its upper node plane
    belongs to the neighbour, and no physical map touches the cut ghosts."""
    faces = {f: "wall" for f in ("x_lower", "x_upper", "y_lower", "y_upper")}
    B = Block([0.0, 0.0], [1.0, 1.0], [8, 4], faces, offset=[0, 0], local_cells=[4, 4],
              cuts=[[False, True], [False, False], [False, False]])
    assert B.face[0, 1] == CUT and B.face[0, 0] != CUT
    k = B.zkind.reshape(B.zdims)[:, :, 0]
    assert np.all(k[6:8, 2:6] == Z_IMAGE) and np.all(k[2:6, 2:6] == Z_REAL)
    assert np.all(k[6:8, 0:2] == Z_INACTIVE)  # beyond the y wall
    own = B.owned.reshape(B.ndims)[:, :, 0]
    assert own[2:6, 2:7].all() and not own[6].any()
    assert np.allclose(B.X.reshape(*B.ndims, 2)[6, 2], [0.5, 0.0])  # global coordinates
    bc = Boundaries(B)
    dst, _ = bc.zmap_zg
    i = np.unravel_index(dst, B.zdims)[0]
    j = np.unravel_index(dst, B.zdims)[1]
    assert not np.any((i >= 6) & (j >= 2) & (j < 6))  # cut ghosts: halo exchange only
    for d in range(2):
        dst, _ = bc.fmap[d]
        i, j, _k = np.unravel_index(dst, B.zdims)
        assert not np.any((i >= 6) & (j >= 2) & (j < 6))


def _steps(out: Path) -> dict:
    data = {}
    for f in sorted((out / "steps").glob("ale_*.h5")):
        with h5py.File(f) as h:
            def take(name, obj, f=f):
                if isinstance(obj, h5py.Dataset):
                    data[f"{f.name}/{name}"] = obj[...]
            h.visititems(take)
    return data


@pytest.mark.slow
@pytest.mark.mpi
def test_immerse_run_sod_on_two_ale_ranks(tmp_path, run_immerse):
    """`immerse run cases/sod --ranks ale=2` end to end: the checks pass and every output step
    equals the one-rank run bitwise."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("already running under MPI")
    runs = {}
    for n in (1, 2):
        p = run_immerse("run", REPO / "cases" / "sod", "--out", tmp_path / f"r{n}", "--ranks", f"ale={n}")
        assert p.returncode == 0, p.stdout + p.stderr
        s = json.loads((tmp_path / f"r{n}" / "summary.json").read_text())
        assert s["ranks"] == {"ale": n} and s["check"]["passed"]
        runs[n] = _steps(tmp_path / f"r{n}")
    assert len(runs[1]) >= 30 and runs[1].keys() == runs[2].keys()
    assert [k for k in runs[1] if not np.array_equal(runs[1][k], runs[2][k])] == []
