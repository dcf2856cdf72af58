"""Tests for solvers/lagrange/mesh.py against analytic geometry.

Tolerances: boxes and the polygonal area of the quarter disk are exact up to round-off
(rel. 1e-12); the quarter cylinder vs pi R^2 L / 4 differs by the chord error
eps = 1 - sin(h)/h with h = pi/(4m) (m core cells), 0 < eps < h^2/6.
"""

import numpy as np
import pytest

from solvers.lagrange.mesh import (
    HEX_FACES,
    Mesh,
    MeshError,
    boundary_faces,
    box_mesh,
    cell_volumes,
    concatenate,
    quarter_cylinder_mesh,
    quarter_disk_mesh,
    read_mesh,
)

meshio = pytest.importorskip("meshio")


# ----------------------------------------------------------------------------- helpers
def min_scaled_jacobian_2d(mesh):
    x = mesh.points[mesh.cells]
    e1 = np.roll(x, -1, axis=1) - x
    e0 = np.roll(x, 1, axis=1) - x
    cross = e1[..., 0] * e0[..., 1] - e1[..., 1] * e0[..., 0]
    return (cross / np.linalg.norm(e1, axis=2) / np.linalg.norm(e0, axis=2)).min()


def hex_corner_jacobians(mesh):
    """Triple products at the 8 corners of every hexahedron (all > 0 for valid cells)."""
    x = mesh.points[mesh.cells]
    # neighbours of each corner along xi, eta, zeta (VTK order), right-handed
    nb = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                   [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
    e = x[:, nb, :] - x[:, :, None, :]  # (ne, 8, 3, 3)
    return np.einsum("eci,eci->ec", np.cross(e[:, :, 0], e[:, :, 1]), e[:, :, 2])


def surface_checks(mesh):
    """Return (sum of area vectors, volume by the divergence theorem) of the boundary."""
    faces = boundary_faces(mesh)
    x = mesh.points[faces]
    if mesh.dim == 2:
        d = x[:, 1] - x[:, 0]
        normal_len = np.stack([d[:, 1], -d[:, 0]], axis=1)  # outward normal * length
        vol = 0.5 * np.einsum("fi,fi->", 0.5 * (x[:, 0] + x[:, 1]), normal_len)
    else:
        # planar quads: area vector = 1/2 diag1 x diag2, x.n constant on the face
        normal_len = 0.5 * np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 1])
        vol = np.einsum("fi,fi->", x[:, 0], normal_len) / 3.0
    return normal_len.sum(axis=0), vol


# ----------------------------------------------------------------------------- box
def test_box_2d_counts_volumes_order():
    m = box_mesh([0.0, -1.0], [3.0, 1.0], [3, 4])
    assert m.dim == 2 and m.cell_type == "quad"
    assert m.points.shape == (4 * 5, 2) and m.cells.shape == (12, 4)
    assert m.points.dtype == np.float64 and m.cells.dtype == np.int64
    vol = cell_volumes(m)
    np.testing.assert_allclose(vol, 3.0 * 2.0 / 12, rtol=1e-13)
    assert vol.sum() == pytest.approx(6.0, rel=1e-13)
    # first cell: CCW from the lower-left corner
    np.testing.assert_allclose(m.points[m.cells[0]], [[0, -1], [1, -1], [1, -0.5], [0, -0.5]])


def test_box_3d_counts_volumes_order():
    m = box_mesh([0, 0, 0], [1.0, 2.0, 3.0], [2, 3, 4])
    assert m.dim == 3 and m.cell_type == "hexahedron"
    assert m.points.shape == (3 * 4 * 5, 3) and m.cells.shape == (24, 8)
    vol = cell_volumes(m)
    np.testing.assert_allclose(vol, 6.0 / 24, rtol=1e-13)
    assert vol.sum() == pytest.approx(6.0, rel=1e-13)
    assert np.all(hex_corner_jacobians(m) > 0)
    c0 = m.points[m.cells[0]]
    np.testing.assert_allclose(c0[:4, 2], 0.0)
    np.testing.assert_allclose(c0[4:, :2], c0[:4, :2])  # 4-7 above 0-3
    np.testing.assert_allclose(c0[4:, 2], 0.75)


@pytest.mark.parametrize("args", [
    ([0, 0], [1, 1, 1], [1, 1]),
    ([0, 0], [1, 0], [1, 1]),
    ([0, 0], [1, 1], [0, 1]),
    ([0, 0], [1, 1], [1.5, 1]),
    ([0], [1], [1]),
])
def test_box_invalid(args):
    with pytest.raises(MeshError) as exc:
        box_mesh(*args)
    assert "\n" not in str(exc.value)


def test_box_boundary_faces():
    m2 = box_mesh([0, 0], [2.0, 1.0], [4, 3])
    f2 = boundary_faces(m2)
    assert f2.shape == (2 * (4 + 3), 2)
    total, vol = surface_checks(m2)
    np.testing.assert_allclose(total, 0.0, atol=1e-13)
    assert vol == pytest.approx(2.0, rel=1e-13)

    m3 = box_mesh([0, 0, 0], [1.0, 2.0, 3.0], [2, 3, 4])
    f3, owner = boundary_faces(m3, return_cells=True)
    assert f3.shape == (2 * (2 * 3 + 3 * 4 + 4 * 2), 4)
    assert owner.shape == (len(f3),)
    # every face is one of its owner's faces
    own = m3.cells[owner][:, HEX_FACES]  # (nf, 6, 4)
    assert np.all(np.any(np.all(own == f3[:, None, :], axis=2), axis=1))
    total, vol = surface_checks(m3)
    np.testing.assert_allclose(total, 0.0, atol=1e-12)
    assert vol == pytest.approx(6.0, rel=1e-13)


# ----------------------------------------------------------------------------- quarter cylinder
def core_cells(mesh2d, radius):
    """m from the number of nodes on the arc (2m + 1)."""
    r = np.hypot(mesh2d.points[:, 0], mesh2d.points[:, 1])
    n_arc = int(np.sum(np.abs(r - radius) < 1e-12 * radius))
    assert n_arc % 2 == 1
    return (n_arc - 1) // 2


@pytest.mark.parametrize("radial", [2, 3, 4, 5, 8, 16])
def test_quarter_disk_exact_polygon_area_and_quality(radial):
    R = 2.0
    m2 = quarter_disk_mesh(R, radial)
    m = core_cells(m2, R)
    assert m == int(np.floor(radial / 2 + 0.5))
    n = radial - m
    assert m2.points.shape == ((m + 1) ** 2 + n * (2 * m + 1), 2)
    assert m2.cells.shape == (m * m + 2 * m * n, 4)
    vol = cell_volumes(m2)
    assert np.all(vol > 0)
    assert vol.sum() == pytest.approx(m * R**2 * np.sin(np.pi / (4 * m)), rel=1e-12)
    assert min_scaled_jacobian_2d(m2) > 0.8
    # axes: uniform node spacing R / radial on the x axis
    on_x = np.sort(m2.points[np.abs(m2.points[:, 1]) < 1e-14, 0])
    np.testing.assert_allclose(np.diff(on_x), R / radial, rtol=1e-12)
    assert np.all(m2.points >= -1e-14)
    assert np.all(np.hypot(*m2.points.T) <= R * (1 + 1e-12))
    # no duplicated nodes
    assert len(np.unique(np.round(m2.points, 12), axis=0)) == len(m2.points)


def test_quarter_cylinder_volume_converges():
    R, L = 0.5, 3.0
    exact = np.pi * R**2 * L / 4
    errors = []
    for radial in (2, 4, 8, 16):
        mesh = quarter_cylinder_mesh(R, L, radial, 3)
        assert mesh.cell_type == "hexahedron"
        m = core_cells(Mesh(mesh.points[mesh.points[:, 2] == 0, :2], np.zeros((0, 4))), R)
        n = radial - m
        nn2 = (m + 1) ** 2 + n * (2 * m + 1)
        assert mesh.points.shape == (nn2 * 4, 3)
        assert mesh.cells.shape == ((m * m + 2 * m * n) * 3, 8)
        vol = cell_volumes(mesh)
        assert np.all(vol > 0)
        assert np.all(hex_corner_jacobians(mesh) > 0)
        h = np.pi / (4 * m)
        assert vol.sum() == pytest.approx(L * m * R**2 * np.sin(h), rel=1e-12)
        err = 1 - vol.sum() / exact
        assert 0 < err < h**2 / 6
        errors.append(err)
        assert mesh.points[:, 2].min() == 0.0 and mesh.points[:, 2].max() == pytest.approx(L)
        total, vsurf = surface_checks(mesh)
        np.testing.assert_allclose(total, 0.0, atol=1e-12)
        assert vsurf == pytest.approx(vol.sum(), rel=1e-12)
    assert all(b < a for a, b in zip(errors, errors[1:]))
    assert errors[-1] < 2e-3


def test_quarter_cylinder_invalid():
    for args in [(1.0, 1.0, 1, 1), (-1.0, 1.0, 4, 1), (1.0, 0.0, 4, 1), (1.0, 1.0, 4, 0)]:
        with pytest.raises(MeshError):
            quarter_cylinder_mesh(*args)


# ----------------------------------------------------------------------------- concatenate
def test_concatenate():
    a = box_mesh([0, 0], [1, 1], [2, 2])
    b = box_mesh([2, 0], [3, 1], [1, 3])
    m, body = concatenate([a, b])
    assert m.points.shape == (9 + 8, 2) and m.cells.shape == (4 + 3, 4)
    np.testing.assert_array_equal(body, [0, 0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(m.cells[4:], b.cells + 9)
    assert cell_volumes(m).sum() == pytest.approx(2.0)
    with pytest.raises(MeshError):
        concatenate([a, box_mesh([0, 0, 0], [1, 1, 1], [1, 1, 1])])


# ----------------------------------------------------------------------------- read_mesh
def _points3(mesh):
    if mesh.dim == 3:
        return mesh.points
    return np.column_stack([mesh.points, np.zeros(mesh.num_points)])


@pytest.mark.parametrize("fmt,suffix", [("vtu", ".vtu"), ("gmsh22", ".msh"), ("gmsh", ".msh")])
@pytest.mark.parametrize("dim", [2, 3])
def test_read_mesh_roundtrip(tmp_path, fmt, suffix, dim):
    orig = box_mesh([0, 0], [2, 1], [3, 2]) if dim == 2 else quarter_cylinder_mesh(1.0, 2.0, 3, 2)
    path = tmp_path / f"m{suffix}"
    ctype = orig.cell_type
    meshio.write(path, meshio.Mesh(_points3(orig), [(ctype, orig.cells)]), file_format=fmt,
                 **({"binary": False} if fmt.startswith("gmsh") else {}))
    back = read_mesh(path, dim)
    assert back.cell_type == ctype
    np.testing.assert_allclose(back.points, orig.points, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.cells, orig.cells)


def test_read_mesh_filters_flips_and_compacts(tmp_path):
    orig = box_mesh([0, 0], [1, 1], [2, 2])
    pts = np.vstack([[[5.0, 5.0], [6.0, 6.0], [7.0, 5.0]], orig.points])  # 3 unused-by-quads
    pts3 = np.column_stack([pts, np.full(len(pts), 0.25)])  # constant z != 0
    quads = orig.cells + 3
    quads[1] = quads[1][[0, 3, 2, 1]]  # inverted
    tri = np.array([[0, 1, 2]])
    path = tmp_path / "mixed.vtu"
    meshio.write(path, meshio.Mesh(pts3, [("triangle", tri), ("quad", quads)]))
    back = read_mesh(path, 2)
    assert back.points.shape == (9, 2)
    np.testing.assert_allclose(back.points, orig.points)
    assert np.all(cell_volumes(back) > 0)
    np.testing.assert_array_equal(np.sort(back.cells, axis=1), np.sort(orig.cells, axis=1))

    hexm = box_mesh([0, 0, 0], [1, 1, 1], [2, 1, 1])
    cells = hexm.cells.copy()
    cells[0] = cells[0][[4, 5, 6, 7, 0, 1, 2, 3]]  # upside down
    p = tmp_path / "hex.msh"
    meshio.write(p, meshio.Mesh(hexm.points, [("hexahedron", cells)]), file_format="gmsh22",
                 binary=False)
    back3 = read_mesh(p, 3)
    assert np.all(cell_volumes(back3) > 0)
    assert np.all(hex_corner_jacobians(back3) > 0)


def _one_line_error(path, dim):
    with pytest.raises(MeshError) as exc:
        read_mesh(path, dim)
    msg = str(exc.value)
    assert msg and "\n" not in msg
    return msg


def test_read_mesh_errors(tmp_path):
    assert "no such file" in _one_line_error(tmp_path / "missing.msh", 2)

    bad = tmp_path / "corrupt.msh"
    bad.write_bytes(b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0\ngarbage\x00\xff")
    assert "corrupt.msh" in _one_line_error(bad, 2)

    junk = tmp_path / "junk.vtu"
    junk.write_text("<VTKFile><not closed")
    _one_line_error(junk, 3)

    quad = box_mesh([0, 0], [1, 1], [1, 1])
    q = tmp_path / "quad.vtu"
    meshio.write(q, meshio.Mesh(_points3(quad), [("quad", quad.cells)]))
    assert "hexahedron" in _one_line_error(q, 3)

    warped = _points3(quad).copy()
    warped[0, 2] = 0.5
    w = tmp_path / "warped.vtu"
    meshio.write(w, meshio.Mesh(warped, [("quad", quad.cells)]))
    assert "planar" in _one_line_error(w, 2)

    tri = tmp_path / "tri.vtu"
    meshio.write(tri, meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]))
    assert "triangle" in _one_line_error(tri, 2)

    degenerate = _points3(quad).copy()
    degenerate[2] = degenerate[1]
    degenerate[3] = degenerate[0]
    d = tmp_path / "flat.vtu"
    meshio.write(d, meshio.Mesh(degenerate, [("quad", quad.cells)]))
    assert "degenerate" in _one_line_error(d, 2)


def test_a_quarter_cylinder_with_a_base_is_the_one_at_the_origin_moved_there():
    """``quarter_cylinder.base`` (the centre of its bottom face; a rod placed in a background grid,
    cases/penetrator_tate_fe): the same cells, every point moved by base; without it, at the origin.
    The coupled case's bounding box (schema/coupling.py _body_box) moves with it."""
    from orchestrator.schema.coupling import _body_box
    from solvers.lagrange.mesh import body_mesh

    q = {"radius": 1e-3, "length": 0.01, "radial_cells": 4, "axial_cells": 5}
    at0 = body_mesh({"mesh": {"quarter_cylinder": q}}, 3)
    moved = body_mesh({"mesh": {"quarter_cylinder": {**q, "base": [0.5, 0.25, 0.02506]}}}, 3)
    assert np.array_equal(moved.cells, at0.cells)
    assert np.array_equal(moved.points, at0.points + np.array([0.5, 0.25, 0.02506]))
    lo, hi = _body_box({"quarter_cylinder": {**q, "base": [0.5, 0.25, 0.02506]}}, 3)
    assert lo == [0.5, 0.25, 0.02506] and hi == [0.501, 0.251, 0.02506 + 0.01]


# ----------------------------------------------------------------------------- ring
@pytest.mark.parametrize("radial, angular", [(1, 3), (2, 7), (3, 200), (5, 64)])
def test_ring_polygon_area_counts_orientation_and_two_loops(radial, angular):
    """The annulus: area of its two inscribed polygons exactly, n/2 sin(2 pi/n) (ro^2 - ri^2) (it tends
    to pi (ro^2 - ri^2)); the counts of body_mesh_size; every Jacobian positive; the seam merged (no
    node twice); the exterior facets two closed loops, the outer one outward, the inner one pointing
    into the hole (towards the centre)."""
    from solvers.lagrange.mesh import _jacobian_dets, body_mesh, body_mesh_size, ring_mesh
    from solvers.lagrange.surface import exterior_facets

    ri, ro, c = 0.7, 1.3, np.array([0.25, -2.0])
    spec = {"mesh": {"ring": {"inner_radius": ri, "outer_radius": ro, "radial_cells": radial,
                              "angular_cells": angular, "centre": list(c)}}}
    m = body_mesh(spec, 2)
    assert np.array_equal(m.points, ring_mesh(ri, ro, radial, angular, c).points)
    assert body_mesh_size(spec) == (m.num_cells, m.num_points) == (radial * angular, (radial + 1) * angular)
    area = angular / 2 * np.sin(2 * np.pi / angular) * (ro**2 - ri**2)
    assert cell_volumes(m).sum() == pytest.approx(area, rel=1e-13)
    if angular >= 64:
        assert cell_volumes(m).sum() == pytest.approx(np.pi * (ro**2 - ri**2), rel=(2 * np.pi / angular) ** 2 / 6)
    assert np.all(_jacobian_dets(m.points, m.cells) > 0)
    assert len(np.unique(np.round(m.points, 12), axis=0)) == m.num_points
    r = np.hypot(*(m.points - c).T)
    assert r.min() == pytest.approx(ri, rel=1e-14) and r.max() == pytest.approx(ro, rel=1e-14)

    facets, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
    assert len(facets) == 2 * angular
    # every boundary node starts one facet and ends one: the facets chain into closed loops
    assert np.array_equal(np.sort(facets[:, 0]), np.sort(facets[:, 1]))
    nxt = dict(zip(facets[:, 0].tolist(), facets[:, 1].tolist()))
    loops, left = [], set(nxt)
    while left:
        a = start = left.pop()
        loop = [a]
        while (a := nxt[a]) != start:
            loop.append(a)
            left.discard(a)
        loops.append(loop)
    assert sorted(len(lp) for lp in loops) == [angular, angular]
    x = m.points[facets]
    d = x[:, 1] - x[:, 0]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1)          # outward of the cells
    radial_dir = 0.5 * (x[:, 0] + x[:, 1]) - c
    outer = np.hypot(*(x[:, 0] - c).T) > 0.5 * (ri + ro)   # (its nodes on the outer circle)
    assert outer.sum() == angular
    dots = np.einsum("fi,fi->f", normal, radial_dir)
    assert np.all(dots[outer] > 0) and np.all(dots[~outer] < 0)  # the inner loop points into the hole


@pytest.mark.parametrize("args, match", [((1.0, 1.0, 2, 8), "inner_radius < outer_radius"),
                                         ((0.0, 1.0, 2, 8), "inner_radius < outer_radius"),
                                         ((0.5, 1.0, 0, 8), "radial_cells >= 1"),
                                         ((0.5, 1.0, 2, 2), "angular_cells >= 3")])
def test_ring_refuses_bad_input(args, match):
    from solvers.lagrange.mesh import ring_mesh

    with pytest.raises(MeshError, match=match):
        ring_mesh(*args)


def _vtu_bomb(path, blocks=128):
    """A valid compressed VTU of one hexahedron whose points' zlib blocks are replaced by ``blocks``
    copies of 64 MiB of compressed zeros (8 GiB inflated for 128; the file ~11 MB)."""
    import base64
    import zlib

    m = box_mesh([0, 0, 0], [1, 1, 1], [1, 1, 1])
    meshio.write(path, meshio.Mesh(m.points, [("hexahedron", m.cells)]), compression="zlib")
    text = path.read_text()
    block = zlib.compress(bytes(64 << 20), 9)
    header = np.array([blocks, 64 << 20, 64 << 20] + [len(block)] * blocks, dtype=np.uint32).tobytes()
    bomb = base64.b64encode(header).decode() + base64.b64encode(block * blocks).decode()
    start = text.index(">", text.index('<DataArray type="Float64" Name="Points"')) + 1
    end = text.index("</DataArray>", start)
    path.write_text(text[:start] + "\n" + bomb + "\n" + text[end:])


def test_a_vtu_whose_blocks_inflate_past_what_it_declares_is_refused(tmp_path):
    """A VTU declaring 8 points and 1 cell whose points inflate to 8 GiB: refused by the budget its
    counts give (1 MiB + 1200 bytes each) in 0.16 s, not inflated (the read's peak memory: measured
    43 MiB, the 11 MB file and its base64 decoding); the same file's genuine points read."""
    import tracemalloc

    path = tmp_path / "bomb.vtu"
    _vtu_bomb(path)
    tracemalloc.start()
    with pytest.raises(MeshError, match="inflate to more than 1059376 bytes"):
        read_mesh(path, 3, max_inflated=1 << 40)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 100 << 20, peak
    m = box_mesh([0, 0, 0], [1, 1, 1], [1, 1, 1])
    meshio.write(tmp_path / "ok.vtu", meshio.Mesh(m.points, [("hexahedron", m.cells)]), compression="zlib")
    assert read_mesh(tmp_path / "ok.vtu", 3, max_inflated=1 << 40).cells.shape == (1, 8)
