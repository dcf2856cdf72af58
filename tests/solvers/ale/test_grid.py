"""Block layout of the ALE grid (index maps, VTK connectivity, zone kinds) and its ghost fills."""
import numpy as np
import pytest

from solvers.ale.boundary import Boundaries
from solvers.ale.grid import (GHOST, Z_IMAGE, Z_INACTIVE, Z_OPEN, Z_REAL, Block, GridError)
from solvers.elements import hex_bvectors, quad_bvectors

FACES3 = {"x_lower": "wall", "x_upper": "outflow", "y_lower": "periodic", "y_upper": "periodic",
          "z_lower": {"piston": {"density": 1.0, "velocity": [1.0, 2.0, 3.0], "pressure": 1.0}},
          "z_upper": "wall"}


def test_layout_and_vtk_connectivity():
    B = Block([0.0, -1.0, 2.0], [1.0, 1.0, 3.0], [3, 4, 5], FACES3)
    assert B.zdims == (7, 8, 9) and B.ndims == (8, 9, 10)
    assert B.connectivity().shape == (60, 8) and B.out_nodes.size == 4 * 5 * 6
    pts = B.X[B.out_nodes]
    # output numbering x fastest; cell 0 is the zone at the lower corner
    assert np.allclose(pts[0], [0.0, -1.0, 2.0]) and np.allclose(pts[1], [1.0 / 3, -1.0, 2.0])
    assert np.allclose(pts[-1], [1.0, 1.0, 3.0])
    b = np.empty((8, 3))
    vols = [hex_bvectors(pts[c], b)[0] for c in B.connectivity()]
    assert np.allclose(vols, (1 / 3) * (2 / 4) * (1 / 5), rtol=1e-13)  # positively oriented
    B2 = Block([0.0, 0.0], [2.0, 1.0], [4, 2], {f: "wall" for f in ("x_lower", "x_upper", "y_lower", "y_upper")})
    b2 = np.empty((4, 2))
    p2 = B2.X[B2.out_nodes]
    assert all(quad_bvectors(p2[c], b2)[0] == pytest.approx(0.25) for c in B2.connectivity())
    assert B2.zone_ijk(B2.out_zones[5]) == (1, 1)


def test_zone_kinds():
    B = Block([0.0, -1.0, 2.0], [1.0, 1.0, 3.0], [3, 4, 5], FACES3)
    k = B.zkind.reshape(B.zdims)
    assert k[2, 2, 2] == Z_REAL
    assert k[1, 2, 2] == Z_INACTIVE          # beyond the x_lower wall
    assert k[5, 2, 2] == Z_OPEN              # beyond the outflow
    assert k[2, 1, 2] == Z_IMAGE             # periodic image
    assert k[2, 2, 1] == Z_OPEN              # held-velocity (piston) ghost
    assert k[5, 1, 2] == Z_OPEN and k[1, 1, 2] == Z_INACTIVE
    # the upper periodic node plane is real but not owned (it is the lower plane's image)
    own = B.owned.reshape(B.ndims)
    assert own[2, 2, 2] and not own[2, 2 + 4, 2] and own[2, 2 + 3, 2]


def test_ghost_fills():
    B = Block([0.0, -1.0, 2.0], [1.0, 1.0, 3.0], [3, 4, 5], FACES3)
    bc = Boundaries(B)
    a = np.arange(B.nzones, dtype=float)
    bc.fill_zones([a], {(2, 0): (-7.0,)})
    v = B.zview(a)
    n = B.n3
    assert v[1, 3, 4] == v[2, 3, 4] and v[0, 3, 4] == v[3, 3, 4]                 # wall: mirror
    assert v[n[0] + 2, 3, 4] == v[n[0] + 1, 3, 4] == v[n[0] + 3, 3, 4]          # outflow: zero gradient
    assert v[3, 1, 4] == v[3, n[1] + 1, 4] and v[3, n[1] + 2, 4] == v[3, 2, 4]   # periodic images
    assert v[3, 3, 1] == -7.0 and v[3, 3, 0] == -7.0                              # inflow value
    # node vectors: walls mirror the normal component, inflow ghosts get the inflow velocity
    vel = np.tile([1.0, 2.0, 3.0], (B.nnodes, 1)) * np.arange(B.nnodes)[:, None]
    bc.fill_nodes_vector(vel)
    w = B.nview(vel)
    assert np.array_equal(w[1, 4, 4], w[3, 4, 4] * [-1, 1, 1])
    assert np.array_equal(w[4, 4, 1], [1.0, 2.0, 3.0])
    assert np.array_equal(w[4, 2 + n[1], 4], w[4, 2, 4])                         # periodic node plane


def test_bad_grids():
    with pytest.raises(GridError):
        Block([0.0, 0.0], [1.0, 1.0], [0, 3], {})
    with pytest.raises(GridError):
        Block([0.0, 0.0], [1.0, 1.0], [2, 3], {"x_lower": "periodic", "x_upper": "wall",
                                              "y_lower": "wall", "y_upper": "wall"})
    assert GHOST == 2
