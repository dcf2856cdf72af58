"""The coupling operators B^b and B^f of the embedded-mesh method, one multiplier per cut zone.

Multipliers are piecewise constant per cut background zone e (Puso, Kokko, Settgast & Liu,
IJNME 104 (2015) 697-720; the talk's "Mathematical Details: Lagrange Step"):

    B^b_eA = ∫_{Γ_e} φ^b_A dΓ     (background shape function of node A, over the surface in zone e)
    B^f_eA = ∫_{Γ_e} φ^f_A dΓ     (foreground shape function of surface node A, same surface)

Both are stored with the sign given here (positive): since the shape functions of either mesh are a
partition of unity on Γ_e, every row of either operator sums to the cut area A_e.  The constraint is
on the *relative* velocity, B^b v^b - B^f v^f (the talk's B^f carries that minus sign:
its `B^b v^b + B^f v^f = 0` is `B^b v^b - Bf v^f = 0` with `Bf` of this module).

Built from the interface geometry (`geometry.Pieces`: the surface clipped by the zones, with
quadrature points carrying both meshes' shape functions) by vectorised scatter-adds, no loop over
pieces.  Everything is ordered by global ids (zones, background nodes), so the operators do not
depend on the order the pieces arrive in beyond round-off of the sums.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

MIN_AREA_FRACTION = 1e-12
"""A zone whose cut area is at most this fraction of a full cut (`Operators.full_area`) gets no
multiplier: a line through a grid vertex leaves zero-length pieces in the zones it touches, and a
zone of zero area has no constraint to impose and no normal.  What it drops is at most 1e-12 of a
zone's share of the surface (below round-off of the cut geometry)."""

NORMAL_FALLBACK_RATIO = 0.1
"""Below |∫_{Γ_e} n dΓ| = 0.1 A_e the area vector of zone e is mostly cancellation (both faces of a
thin plate, the tip of a wedge of half-angle < 6°): its direction is then set by the small remainder
(an end cap, round-off), not by the surface, and is a poor slip direction; see `_fallback_normals`.
A smooth surface gives 1 - O((h/R)^2), a right-angle corner 0.71, so ordinary zones are not touched."""


@dataclass(frozen=True)
class Operators:
    """The coupling operators of one step, rows = cut zones in ascending zone id.

    zones    (nz,) int64      sorted cut zone ids (one multiplier per zone)
    bnodes   (nb,) int64      sorted background node ids: every corner of every cut zone
    Bb       (nz, nb) CSR     B^b_eA = ∫_{Γ_e} φ^b_A dΓ, columns index `bnodes`
    Bf       (nz, ns) CSR     B^f_eA = ∫_{Γ_e} φ^f_A dΓ, columns = surface node index
    area     (nz,)            A_e = ∫_{Γ_e} dΓ
    avec     (nz, dim)        ∫_{Γ_e} n dΓ (outward body normal)
    normal   (nz, dim)        unit slip direction n_e (avec/|avec|, or the fallback)
    fallback (nz,) bool       zones whose normal is the fallback direction
    pairs    (np, 2) int64    face-adjacent cut zones as row indices (i < j), sorted
    full_area                 area of a full cut of a zone: zone_volume^((d-1)/d)
    width                     zone width zone_volume^(1/d)
    """

    zones: np.ndarray
    bnodes: np.ndarray
    Bb: sp.csr_matrix
    Bf: sp.csr_matrix
    area: np.ndarray
    avec: np.ndarray
    normal: np.ndarray
    fallback: np.ndarray
    pairs: np.ndarray
    full_area: float
    width: float

    @property
    def dim(self) -> int:
        return int(self.avec.shape[1])

    @property
    def n_zones(self) -> int:
        return int(self.zones.size)

    @classmethod
    def build(cls, grid, pieces, facets, n_surface_nodes: int) -> "Operators":
        """Assemble B^b, B^f, areas, normals and zone pairs from the clipped surface.

        grid: `grid.Grid` (uses dim, cells, zone_volume, periodic; corner node ids as its zone_nodes);
        pieces: `geometry.Pieces`; facets: (n_facets, nv) surface node ids of every facet (the rows
        `pieces.facet` refers to); n_surface_nodes: number of columns of B^f."""
        dim = int(grid.dim)
        volume = float(grid.zone_volume)
        full_area = volume ** ((dim - 1) / dim)
        width = volume ** (1.0 / dim)
        facets = np.asarray(facets, dtype=np.int64)
        pzone = np.asarray(pieces.zone, dtype=np.int64)
        parea = np.asarray(pieces.area, dtype=float)
        pnormal = np.asarray(pieces.normal, dtype=float).reshape(-1, dim)

        from orchestrator.coupling.operator_rows import operator_arrays  # (numba: only when building)

        per = getattr(grid, "periodic", None)
        per = np.zeros(dim, np.uint8) if per is None else np.asarray(per, dtype=np.uint8)
        # one kernel: per zone (pieces arrive sorted by zone) the cut area, area vector, B^b row (one
        # weight per corner) and B^f row (sorted surface nodes); zones of (numerically) zero area
        # dropped; the unit normals (the fallback ones below); the background columns: every corner of
        # every cut zone, in corner order c (the ids ascend with c, x fastest, except where a periodic
        # axis wraps the last layer's upper corners to plane 0); the face-adjacent zone pairs
        zones, area, avec, bw, normal, fallback, fptr, fcol, fval, prow, bnodes, columns, pairs = operator_arrays(
            pzone, parea, pnormal, np.asarray(pieces.qpiece, dtype=np.int64), np.asarray(pieces.qw, dtype=float),
            np.ascontiguousarray(np.asarray(pieces.qb, dtype=float).reshape(-1, 2**dim)),
            np.ascontiguousarray(pieces.qf, dtype=float), np.asarray(pieces.facet, dtype=np.int64), facets,
            MIN_AREA_FRACTION * full_area, NORMAL_FALLBACK_RATIO, np.asarray(grid.cells, dtype=np.int64), per)
        nz = zones.size
        if fallback.any():
            live = prow >= 0
            _fallback_normals(normal, fallback, avec, prow[live], parea[live], pnormal[live])
        Bb = sp.csr_matrix((bw.ravel(), columns.ravel(), np.arange(nz + 1, dtype=np.int64) * 2**dim),
                           shape=(nz, bnodes.size))
        Bf = sp.csr_matrix((fval, fcol, fptr), shape=(nz, int(n_surface_nodes)))
        return cls(zones=zones, bnodes=bnodes, Bb=Bb, Bf=Bf, area=area, avec=avec, normal=normal,
                   fallback=fallback, pairs=pairs, full_area=full_area, width=width)


def restrict(ops: Operators, keep: np.ndarray) -> Operators:
    """The operators of the rows ``keep`` (bool per cut zone) only: the same background columns and
    surface nodes (a node of no kept row gets no impulse), the face pairs between kept rows."""
    rows = np.flatnonzero(keep)
    new = np.full(keep.size, -1, np.int64)
    new[rows] = np.arange(rows.size)
    pairs = new[ops.pairs] if len(ops.pairs) else ops.pairs
    if len(pairs):
        pairs = np.ascontiguousarray(pairs[(pairs >= 0).all(axis=1)])
    return dataclasses.replace(ops, zones=ops.zones[rows], Bb=ops.Bb[rows], Bf=ops.Bf[rows], area=ops.area[rows],
                               avec=ops.avec[rows], normal=ops.normal[rows], fallback=ops.fallback[rows],
                               pairs=pairs)


def _fallback_normals(normal, fallback, avec, prow, parea, pnormal):
    """Set ``normal`` of the zones flagged in ``fallback`` (|avec_e| < NORMAL_FALLBACK_RATIO A_e; the
    others hold n_e = avec_e/|avec_e| from ``operator_rows.kept_rows``).

    The fallback is the area-weighted mean of the piece normals taken as *directions* (axes, sign
    ignored): the eigenvector of the largest eigenvalue of T_e = Σ_p a_p n_p n_p^T.  The plain
    area-weighted mean of the signed normals is avec_e/A_e again, the cancelled vector we are
    avoiding; the axis mean of the two faces of a thin plate is the plate normal, across which the
    fluid must not flow on either side.  Its sign follows avec_e (or, if that is exactly
    perpendicular, makes the largest component positive) so it is deterministic."""
    nz, dim = avec.shape
    rows_fb = np.flatnonzero(fallback)
    sel = fallback[prow]
    T = np.zeros((nz, dim, dim))
    np.add.at(T, prow[sel], parea[sel, None, None] * pnormal[sel, :, None] * pnormal[sel, None, :])
    _, vecs = np.linalg.eigh(T[rows_fb])
    axis = vecs[:, :, -1]  # eigh sorts eigenvalues ascending: last = largest
    s = (axis * avec[rows_fb]).sum(axis=1)
    big = axis[np.arange(rows_fb.size), np.abs(axis).argmax(axis=1)]
    sign = np.where(s != 0.0, np.sign(s), np.sign(big))
    normal[rows_fb] = axis * sign[:, None]
