"""Structured and file meshes of linear quadrilaterals (2D) and hexahedra (3D).

Node order is the meshio/VTK one:

* quad: 0-1-2-3 counter-clockwise (positive area in the x-y plane);
* hexahedron: 0-3 the bottom face counter-clockwise seen from above (+z-ish), 4-7 the
  nodes above 0-3 in the same order; positive volume.

Everything here is vectorised numpy (no Python loop over cells or nodes).
"""

from __future__ import annotations

import contextlib
import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = [
    "Mesh",
    "MeshError",
    "box_mesh",
    "box_axes",
    "body_mesh",
    "body_mesh_size",
    "quarter_disk_mesh",
    "quarter_cylinder_mesh",
    "ring_mesh",
    "extrude",
    "drawn_toward",
    "read_mesh",
    "concatenate",
    "boundary_faces",
    "cell_volumes",
    "QUAD_FACES",
    "HEX_FACES",
]

# Reference coordinates of the element nodes in meshio/VTK order.
_QUAD_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
_HEX_XI = np.array(
    [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]],
    dtype=np.float64,
)
# Boundary entities, ordered so that the right-hand rule gives the outward normal of a
# positively oriented cell (2D: outward normal of edge a->b is (dy, -dx)).
QUAD_FACES = np.array([[0, 1], [1, 2], [2, 3], [3, 0]], dtype=np.int64)
HEX_FACES = np.array(
    [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]],
    dtype=np.int64,
)
# Permutations that mirror a cell (turns a negative into a positive orientation).
_QUAD_FLIP = np.array([0, 3, 2, 1], dtype=np.int64)
_HEX_FLIP = np.array([0, 3, 2, 1, 4, 7, 6, 5], dtype=np.int64)


class MeshError(Exception):
    """A mesh cannot be built or read; ``str(e)`` is a one-line reason."""


@dataclass
class Mesh:
    """Unstructured mesh of one cell type.

    points: (nn, dim) float64; cells: (ne, 4) quad or (ne, 8) hexahedron, int64.
    """

    points: np.ndarray
    cells: np.ndarray

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        if self.points.ndim != 2 or self.points.shape[1] not in (2, 3):
            raise MeshError(f"points must have shape (nn, 2|3), got {self.points.shape}")
        expected = 4 if self.points.shape[1] == 2 else 8
        if self.cells.ndim != 2 or self.cells.shape[1] != expected:
            raise MeshError(
                f"cells must have shape (ne, {expected}) for {self.points.shape[1]}D points, "
                f"got {self.cells.shape}"
            )

    @property
    def dim(self) -> int:
        return int(self.points.shape[1])

    @property
    def cell_type(self) -> str:
        return "quad" if self.dim == 2 else "hexahedron"

    @property
    def num_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def num_cells(self) -> int:
        return int(self.cells.shape[0])


# ----------------------------------------------------------------------------- geometry
def _shape_gradients(xi_nodes: np.ndarray) -> np.ndarray:
    """dN_a/dxi_k at the 2^d Gauss points (+-1/sqrt 3): array (ngauss, nnodes, dim)."""
    d = xi_nodes.shape[1]
    g = 1.0 / np.sqrt(3.0)
    grids = np.meshgrid(*([[-g, g]] * d), indexing="ij")
    gauss = np.stack([c.ravel() for c in grids], axis=1)  # (ng, d)
    # factors[q, a, j] = 1 + xi_a_j * gauss_q_j
    factors = 1.0 + xi_nodes[None, :, :] * gauss[:, None, :]
    scale = 0.5 ** d
    out = np.empty((gauss.shape[0], xi_nodes.shape[0], d))
    for k in range(d):  # loop over the (2 or 3) reference directions only
        others = np.prod(np.delete(factors, k, axis=2), axis=2)
        out[:, :, k] = scale * xi_nodes[None, :, k] * others
    return out


_DN_QUAD = _shape_gradients(_QUAD_XI)
_DN_HEX = _shape_gradients(_HEX_XI)


def _jacobian_dets(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """det J at the Gauss points, shape (ne, ngauss)."""
    dn = _DN_QUAD if cells.shape[1] == 4 else _DN_HEX
    x = points[cells]  # (ne, nnodes, dim)
    jac = np.einsum("eai,gak->egik", x, dn)
    return np.linalg.det(jac)


def cell_volumes(mesh_or_points, cells: np.ndarray | None = None) -> np.ndarray:
    """Signed area (2D) / volume (3D) of every cell.

    Exact for bilinear quads and trilinear hexahedra (2x2(x2) Gauss quadrature of det J,
    which is a polynomial of degree <= 2 in each reference coordinate).
    """
    if cells is None:
        points, cells = mesh_or_points.points, mesh_or_points.cells
    else:
        points = mesh_or_points
    if len(cells) == 0:
        return np.zeros(0)
    return _jacobian_dets(np.asarray(points, float), np.asarray(cells)).sum(axis=1)


def _orient(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flip cells with negative volume; returns (cells, volumes after flipping)."""
    vol = cell_volumes(points, cells)
    neg = vol < 0
    if np.any(neg):
        flip = _QUAD_FLIP if cells.shape[1] == 4 else _HEX_FLIP
        cells = cells.copy()
        cells[neg] = cells[neg][:, flip]
        vol = np.abs(vol)
    return cells, vol


# ----------------------------------------------------------------------------- generators
def box_axes(lower, upper, cells) -> list[np.ndarray]:
    """Node coordinates along each axis of a box mesh: node (i, j[, k]) of box_mesh is
    (axes[0][i], axes[1][j][, axes[2][k]]) exactly."""
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    return [np.linspace(lo[k], hi[k], int(cells[k]) + 1) for k in range(lo.size)]


def box_mesh(lower: Sequence[float], upper: Sequence[float], cells: Sequence[int]) -> Mesh:
    """Structured box [lower, upper] with ``cells`` cells per direction (2D if len(lower)==2).

    Node numbering: id = i + (nx+1) * (j + (ny+1) * k), x fastest.
    """
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    nc = np.asarray(cells)
    d = lo.size
    if d not in (2, 3) or hi.size != d or nc.size != d:
        raise MeshError(f"box_mesh needs lower, upper, cells of equal length 2 or 3, got "
                        f"{lo.size}, {hi.size}, {nc.size}")
    if not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) or np.any(hi <= lo):
        raise MeshError(f"box_mesh needs upper > lower in every direction, got {lower} {upper}")
    if not np.issubdtype(nc.dtype, np.integer) or np.any(nc < 1):
        raise MeshError(f"box_mesh cells must be integers >= 1, got {list(cells)}")
    nc = nc.astype(np.int64)
    n1 = nc + 1
    axes = box_axes(lo, hi, nc)
    grids = np.meshgrid(*axes, indexing="ij")
    points = np.stack([g.ravel(order="F") for g in grids], axis=1)

    strides = np.cumprod(np.concatenate([[1], n1[:-1]]))  # (1, nx1[, nx1*ny1])
    base_grids = np.meshgrid(*[np.arange(c) for c in nc], indexing="ij")
    base = sum(g.ravel(order="F") * s for g, s in zip(base_grids, strides))
    sx, sy = strides[0], strides[1]
    quad = np.array([0, sx, sx + sy, sy], dtype=np.int64)
    offsets = quad if d == 2 else np.concatenate([quad, quad + strides[2]])
    conn = base[:, None] + offsets[None, :]
    return Mesh(points, conn)


def quarter_disk_mesh(radius: float, radial_cells: int, *, core_fraction: float = 0.5,
                      bulge: float = 0.5) -> Mesh:
    """Quarter disk x>=0, y>=0, |x| <= radius as a butterfly (O-grid) quad mesh.

    A core square with m x m cells (m = floor(core_fraction * radial_cells + 1/2), clipped to
    1..radial_cells-1) whose outer
    edges bulge towards a circle (``bulge`` in [0, 1): 0 = straight square edges) is
    surrounded by a ring of n = radial_cells - m layers of 2m cells each. Along both axes
    the node spacing is uniform (radius / radial_cells). All outer nodes lie exactly on
    the circle, so the area is that of the inscribed polygon with 2m equal segments:
    m * radius**2 * sin(pi / (4 m)).

    Quality with the defaults (core_fraction 0.5, bulge 0.5), for any radial_cells:
    every corner angle is within about 55..125 degrees (scaled Jacobian >= 0.81) and the
    edge-length ratio inside a cell is below 2.
    """
    radial_cells = int(radial_cells)
    if radial_cells < 2:
        raise MeshError(f"quarter disk needs radial_cells >= 2, got {radial_cells}")
    if not (np.isfinite(radius) and radius > 0):
        raise MeshError(f"quarter disk needs radius > 0, got {radius}")
    N = radial_cells
    m = int(min(max(np.floor(core_fraction * N + 0.5), 1), N - 1))
    n = N - m
    R = float(radius)
    a = R * m / N  # half side of the core square on the axes

    # --- core nodes (i, j), i, j = 0..m ; id = i + (m+1) j
    u = np.arange(m + 1) / m
    U, V = np.meshgrid(u, u, indexing="ij")  # [i, j]
    U, V = U.ravel(order="F"), V.ravel(order="F")
    sq = a * np.stack([U, V], axis=1)
    linf = np.maximum(U, V)
    l2 = np.hypot(U, V)
    with np.errstate(invalid="ignore", divide="ignore"):
        circ = np.where(l2[:, None] > 0, sq * (linf / np.where(l2 > 0, l2, 1.0))[:, None], 0.0)
    w = bulge * linf  # blend grows from the centre to the core boundary
    core_pts = (1.0 - w)[:, None] * sq + w[:, None] * circ
    nc = (m + 1) ** 2

    def core_id(i, j):
        return i + (m + 1) * j

    # --- ring: 2m+1 "spokes" s = 0..2m from angle 0 to pi/2; layers k = 0..n
    s = np.arange(2 * m + 1)
    # inner end of each spoke: core boundary node (m, s) for s <= m, (2m - s, m) beyond
    inner_ids = np.where(s <= m, core_id(m, np.minimum(s, m)), core_id(2 * m - np.maximum(s, m), m))
    theta = s * (0.5 * np.pi) / (2 * m)
    outer = R * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    k = np.arange(1, n + 1) / n
    inner = core_pts[inner_ids]
    ring_pts = (1.0 - k)[:, None, None] * inner[None] + k[:, None, None] * outer[None]  # [k, s]
    ring_pts = ring_pts.reshape(-1, 2)
    points = np.concatenate([core_pts, ring_pts])
    # ids of the ring grid [layer 0..n, spoke 0..2m]
    ring_ids = np.empty((n + 1, 2 * m + 1), dtype=np.int64)
    ring_ids[0] = inner_ids
    ring_ids[1:] = nc + np.arange(n * (2 * m + 1)).reshape(n, 2 * m + 1)

    # --- cells
    ci, cj = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    ci, cj = ci.ravel(), cj.ravel()
    core_cells = np.stack([core_id(ci, cj), core_id(ci + 1, cj), core_id(ci + 1, cj + 1),
                           core_id(ci, cj + 1)], axis=1)
    rk, rs = np.meshgrid(np.arange(n), np.arange(2 * m), indexing="ij")
    rk, rs = rk.ravel(), rs.ravel()
    ring_cells = np.stack([ring_ids[rk, rs], ring_ids[rk + 1, rs], ring_ids[rk + 1, rs + 1],
                           ring_ids[rk, rs + 1]], axis=1)
    cells = np.concatenate([core_cells, ring_cells])
    cells, vol = _orient(points, cells)
    if np.any(vol <= 0):
        raise MeshError("quarter disk: degenerate cells (check core_fraction/bulge)")
    return Mesh(points, cells)


def ring_mesh(inner_radius: float, outer_radius: float, radial_cells: int, angular_cells: int,
              centre: Sequence[float] = (0.0, 0.0)) -> Mesh:
    """Full annulus inner_radius <= |x - centre| <= outer_radius as a polar grid of quads.

    Nodes (k, j) at radius r_k = inner + k (outer - inner) / radial_cells, k = 0..radial_cells, and
    angle 2 pi j / angular_cells, j = 0..angular_cells-1 (the seam at angle 0 is one column of nodes:
    the last cells close onto j = 0), id = j + angular_cells k (angle fastest). Cell (k, j) is
    (k, j), (k+1, j), (k+1, j+1), (k, j+1): counter-clockwise, as (r, theta) -> (x, y) has Jacobian r
    > 0. Every boundary node lies on its circle, so the area is that of the two inscribed polygons:
    angular_cells / 2 sin(2 pi / angular_cells) (outer^2 - inner^2).
    """
    radial_cells, angular_cells = int(radial_cells), int(angular_cells)
    ri, ro = float(inner_radius), float(outer_radius)
    if radial_cells < 1:
        raise MeshError(f"ring needs radial_cells >= 1, got {radial_cells}")
    if angular_cells < 3:  # (two cells around would be flat: zero area)
        raise MeshError(f"ring needs angular_cells >= 3, got {angular_cells}")
    if not (np.isfinite(ri) and np.isfinite(ro) and 0.0 < ri < ro):
        raise MeshError(f"ring needs 0 < inner_radius < outer_radius, got {ri}, {ro}")
    c = np.asarray(centre, dtype=np.float64)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise MeshError(f"ring needs a centre of 2 finite coordinates, got {list(np.ravel(centre))}")
    na = angular_cells
    r = np.linspace(ri, ro, radial_cells + 1)
    r[-1] = ro  # (exactly on the outer circle)
    theta = 2.0 * np.pi * np.arange(na) / na
    points = c + (r[:, None, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)[None]).reshape(-1, 2)
    k, j = np.meshgrid(np.arange(radial_cells), np.arange(na), indexing="ij")
    k, j = k.ravel(), j.ravel()
    j1 = (j + 1) % na  # the seam: the last column of cells closes onto the first column of nodes
    cells = np.stack([j + na * k, j + na * (k + 1), j1 + na * (k + 1), j1 + na * k], axis=1)
    vol = cell_volumes(points, cells)
    if np.any(vol <= 0):  # (not for any valid input: the guard of the orientation claimed above)
        raise MeshError("ring: a cell is not counter-clockwise")
    return Mesh(points, cells)


def drawn_toward(mesh: Mesh, point, radius: float, power: float) -> Mesh:
    """The mesh with its nodes within ``radius`` of ``point`` drawn toward it: a node at distance r
    moves to radius (r / radius)^power along its ray (power > 1: elements shrink toward the point,
    the one at it about (h / radius)^(power - 1) times its size; nodes on a line through the point
    stay on it, so a box's faces through a corner or an edge point stay where they were).  A locally
    refined corner or notch on a structured mesh (element subcycling's test body)."""
    p = np.asarray(point, np.float64)
    if not (np.isfinite(radius) and radius > 0.0 and power >= 1.0) or p.shape != (mesh.dim,):
        raise MeshError(f"drawn_toward needs a point of {mesh.dim} coordinates, radius > 0 and power >= 1")
    d = mesh.points - p
    r = np.linalg.norm(d, axis=1)
    near = (r > 0.0) & (r < radius)
    points = mesh.points.copy()
    points[near] = p + d[near] * ((r[near] / radius) ** (power - 1.0))[:, None]
    return Mesh(points, mesh.cells.copy())


def extrude(mesh2d: Mesh, length: float, layers: int, z0: float = 0.0) -> Mesh:
    """Extrude a 2D quad mesh along +z into hexahedra (z0 .. z0 + length, ``layers`` cells)."""
    if mesh2d.dim != 2:
        raise MeshError("extrude needs a 2D quad mesh")
    layers = int(layers)
    if layers < 1 or not (np.isfinite(length) and length > 0):
        raise MeshError(f"extrude needs length > 0 and layers >= 1, got {length}, {layers}")
    nn = mesh2d.num_points
    z = z0 + np.linspace(0.0, float(length), layers + 1)
    xy = np.tile(mesh2d.points, (layers + 1, 1))
    points = np.column_stack([xy, np.repeat(z, nn)])
    q = mesh2d.cells
    lay = np.arange(layers)[:, None, None] * nn
    hexes = np.concatenate([q[None] + lay, q[None] + lay + nn], axis=2).reshape(-1, 8)
    cells, vol = _orient(points, hexes)
    return Mesh(points, cells)


def quarter_cylinder_mesh(radius: float, length: float, radial_cells: int,
                          axial_cells: int) -> Mesh:
    """Quarter cylinder x>=0, y>=0, 0<=z<=length, axis z, butterfly cross-section.

    ``radial_cells`` cells across the radius (>= 2), ``axial_cells`` along z. The volume
    is exactly length * m * radius**2 * sin(pi/(4m)) with m = floor(radial_cells/2 + 1/2)
    core cells, i.e. pi radius**2 length / 4 * (1 - eps), 0 < eps < (pi/(4m))**2 / 6.
    """
    if not (np.isfinite(length) and length > 0):
        raise MeshError(f"quarter cylinder needs length > 0, got {length}")
    if int(axial_cells) < 1:
        raise MeshError(f"quarter cylinder needs axial_cells >= 1, got {axial_cells}")
    return extrude(quarter_disk_mesh(radius, radial_cells), length, axial_cells)


# ----------------------------------------------------------------------------- file input
class _Inflated(Exception):
    """The compressed blocks of a file inflate past the budget."""


class _BoundedInflate:
    """zlib or lzma as meshio's VTU reader calls them (``decompress(block)``), each block inflated
    only up to what is left of a budget shared by all: a few kilobytes of compressed zeros can claim
    gigabytes, which the file's size (all that is checked before reading) does not show."""

    def __init__(self, module, left: list):
        self.module, self.left = module, left

    def decompress(self, data):
        import zlib

        d = self.module.decompressobj() if self.module is zlib else self.module.LZMADecompressor()
        out = d.decompress(data, self.left[0] + 1)
        if len(out) > self.left[0]:
            raise _Inflated
        self.left[0] -= len(out)
        return out


@contextlib.contextmanager
def _bounded_vtu_inflate(budget: int | None):
    """meshio's VTU reader with its decompressors bounded to ``budget`` bytes in all (None: as is)."""
    import lzma
    import zlib

    from meshio.vtu import _vtu

    if budget is None:
        yield
        return
    left = [int(budget)]
    saved = _vtu.zlib, getattr(_vtu, "lzma", None)
    _vtu.zlib, _vtu.lzma = _BoundedInflate(zlib, left), _BoundedInflate(lzma, left)
    try:
        yield
    finally:
        _vtu.zlib, _vtu.lzma = saved


VTU_BYTES_PER_ENTITY = 1200
"""What a VTU's compressed data may inflate to, per point and cell its Pieces declare (plus 1 MiB):
the coordinates (24 bytes a point), a hexahedron's connectivity, offset and type (73 bytes a cell)
and some 140 more doubles of point and cell data each; a file claiming more holds something else."""


def _vtu_declared_budget(path: Path) -> int:
    """The inflation budget of a VTU from the counts its Pieces declare (VTU_BYTES_PER_ENTITY)."""
    import re

    with open(path, "rb") as f:
        raw = f.read()
    counts = [int(v) for v in re.findall(rb'Number(?:OfPoints|OfCells)\s*=\s*"\s*(\d+)\s*"', raw)]
    return (1 << 20) + VTU_BYTES_PER_ENTITY * sum(counts)


def read_mesh(path, dim: int, max_inflated: int | None = None) -> Mesh:
    """Read a quad (dim 2) or hexahedron (dim 3) mesh with meshio (.msh, .vtu, ...).

    Keeps only quad/hexahedron cells, drops unused points, flips inverted cells, drops
    a constant z coordinate for dim 2. Raises MeshError with a one-line reason.
    ``max_inflated``: the most bytes a compressed file's blocks may inflate to (VTU's zlib and
    lzma; refused past it, before it is all in memory); a VTU's own points and cells bound it
    further (_vtu_declared_budget: a small file of compressed zeros is refused within a megabyte).
    """
    import meshio

    path = Path(path)
    if dim not in (2, 3):
        raise MeshError(f"{path.name}: dimension must be 2 or 3, got {dim}")
    if not path.is_file():
        raise MeshError(f"{path}: no such file")
    if max_inflated is not None and path.suffix.lower() == ".vtu":
        max_inflated = min(max_inflated, _vtu_declared_budget(path))
    # meshio prints diagnostics and may even call sys.exit() on unreadable files.
    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink), _bounded_vtu_inflate(max_inflated):
            raw = meshio.read(str(path))
    except _Inflated:
        raise MeshError(f"{path.name}: its compressed data inflate to more than {max_inflated} bytes "
                        "(allowed: what its declared points and cells need, within this machine's memory)") from None
    except (Exception, SystemExit) as exc:  # many error types on bad input
        text = str(exc) if not isinstance(exc, SystemExit) else sink.getvalue()
        reason = " ".join(text.replace(str(path), path.name).split()) or type(exc).__name__
        raise MeshError(f"{path.name}: cannot read mesh ({reason[:200]})") from None

    wanted = "quad" if dim == 2 else "hexahedron"
    blocks = [np.asarray(b.data) for b in raw.cells if b.type == wanted]
    found = sorted({b.type for b in raw.cells})
    if not blocks or sum(len(b) for b in blocks) == 0:
        raise MeshError(f"{path.name}: no {wanted} cells for a {dim}D mesh "
                        f"(found: {', '.join(found) or 'none'})")
    cells = np.concatenate(blocks).astype(np.int64)
    points = np.asarray(raw.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3) or len(points) == 0:
        raise MeshError(f"{path.name}: invalid point array of shape {points.shape}")
    if cells.min() < 0 or cells.max() >= len(points):
        raise MeshError(f"{path.name}: cell node index out of range (0..{len(points) - 1})")

    used, inverse = np.unique(cells, return_inverse=True)
    cells = inverse.reshape(cells.shape).astype(np.int64)
    points = points[used]
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{path.name}: non-finite point coordinates")

    if dim == 2:
        if points.shape[1] == 3:
            z = points[:, 2]
            scale = max(float(np.ptp(points[:, :2], axis=0).max()), 1e-300)
            if np.ptp(z) > 1e-12 * scale:
                raise MeshError(f"{path.name}: quad mesh is not planar in z "
                                f"(z spans {np.ptp(z):.3g}); cannot use it as a 2D mesh")
            points = points[:, :2]
    elif points.shape[1] != 3:
        raise MeshError(f"{path.name}: hexahedra need 3D points, got {points.shape[1]}D")

    cells, vol = _orient(points, cells)
    bad = ~(vol > 0)
    if np.any(bad):
        raise MeshError(f"{path.name}: {int(bad.sum())} degenerate {wanted} cell(s) "
                        f"(zero volume), e.g. cell {int(np.argmax(bad))}")
    return Mesh(points, cells)


def body_mesh(spec: dict, dim: int) -> Mesh:
    """The mesh of one body of the case (``spec``: an entry of ``lagrange.bodies``): the solver's
    nodes, and the points ``immerse check`` evaluates the body's expressions on."""
    m = spec["mesh"]
    if "box" in m:
        b = m["box"]
        return box_mesh(b["lower"], b["upper"], b["cells"])
    if "quarter_disk" in m:
        q = m["quarter_disk"]
        mesh = quarter_disk_mesh(q["radius"], q["radial_cells"])
        if any(q.get("base", ())):
            mesh.points += np.asarray(q["base"], np.float64)
        return mesh
    if "quarter_cylinder" in m:
        q = m["quarter_cylinder"]
        mesh = quarter_cylinder_mesh(q["radius"], q["length"], q["radial_cells"], q["axial_cells"])
        if any(q.get("base", ())):
            mesh.points += np.asarray(q["base"], np.float64)
        return mesh
    if "ring" in m:
        q = m["ring"]
        return ring_mesh(q["inner_radius"], q["outer_radius"], q["radial_cells"], q["angular_cells"],
                         q.get("centre", (0.0, 0.0)))
    return read_mesh(m["file"], dim)


def _core_cells(radial_cells: int, core_fraction: float = 0.5) -> int:
    """m of quarter_disk_mesh: core cells per side (Python ints: exact for any size)."""
    n = int(radial_cells)
    m = (n + 1) // 2 if core_fraction == 0.5 else int(math.floor(core_fraction * n + 0.5))
    return min(max(m, 1), n - 1)


def body_mesh_size(spec: dict) -> tuple[int, int] | None:
    """(cells, nodes) of the generated mesh of a body (box, quarter_disk, quarter_cylinder or ring)
    without building it, in Python integers (no overflow however large); None for a mesh file (known after reading).
    The counts follow box_mesh, quarter_disk_mesh/extrude and ring_mesh exactly (tests compare them)."""
    m = spec["mesh"]
    if "box" in m:
        cells = [int(c) for c in m["box"]["cells"]]
        return math.prod(cells), math.prod(c + 1 for c in cells)
    if "quarter_disk" in m:
        n = int(m["quarter_disk"]["radial_cells"])
        core = _core_cells(n)
        return core * core + (n - core) * 2 * core, (core + 1) ** 2 + (n - core) * (2 * core + 1)
    if "quarter_cylinder" in m:
        q = m["quarter_cylinder"]
        n, layers = int(q["radial_cells"]), int(q["axial_cells"])
        core = _core_cells(n)
        ring = n - core
        cells2d = core * core + ring * 2 * core
        nodes2d = (core + 1) ** 2 + ring * (2 * core + 1)
        return cells2d * layers, nodes2d * (layers + 1)
    if "ring" in m:
        n, na = int(m["ring"]["radial_cells"]), int(m["ring"]["angular_cells"])
        return n * na, (n + 1) * na  # (the seam merged: angular_cells columns of nodes)
    return None


# ----------------------------------------------------------------------------- utilities
def concatenate(meshes: Sequence[Mesh]) -> tuple[Mesh, np.ndarray]:
    """Join meshes (no node merging); returns (mesh, body_id per cell)."""
    meshes = list(meshes)
    if not meshes:
        raise MeshError("concatenate needs at least one mesh")
    dims = {m.dim for m in meshes}
    if len(dims) != 1:
        raise MeshError(f"concatenate: meshes of mixed dimension {sorted(dims)}")
    counts = np.array([m.num_points for m in meshes], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    points = np.concatenate([m.points for m in meshes])
    cells = np.concatenate([m.cells + off for m, off in zip(meshes, offsets)])
    body = np.repeat(np.arange(len(meshes), dtype=np.int64), [m.num_cells for m in meshes])
    return Mesh(points, cells), body


def boundary_faces(mesh: Mesh, return_cells: bool = False):
    """Outer faces (hexahedra: (nf, 4) quads; quads: (nf, 2) edges) as node indices.

    A face is outer when exactly one cell has it. Faces keep the node order of their
    cell (QUAD_FACES / HEX_FACES), so for positively oriented cells they are oriented
    with the outward normal (2D: (dy, -dx) of the edge a->b). With ``return_cells``
    also returns the owning cell of each face.
    """
    local = QUAD_FACES if mesh.cells.shape[1] == 4 else HEX_FACES
    nlf = local.shape[0]
    faces = mesh.cells[:, local].reshape(-1, local.shape[1])  # (ne * nlf, k)
    key = np.sort(faces, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    sel = np.sort(first[counts == 1])
    if return_cells:
        return faces[sel], sel // nlf
    return faces[sel]
