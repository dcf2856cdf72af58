"""Several foreground solver groups in one coupled case (an SPH group and a Lagrangian FE group
immersed in the one ALE background): one :class:`~orchestrator.coupling.embedded.EmbeddedCoupling`
per foreground role, presented to the coupler and to the background as one.

The background sees one geometry per step, the union of the members' (:func:`merge_geometries`):
blocked fractions and face coverages add (the bodies are disjoint), the cut zones, the nodes the
constraint solves need and the covered runs are the union of the members', in the orders the
background expects (sorted ids).  It answers with one interface packet over those lists; each member
gets its own rows of it (:meth:`ForegroundCouplings.solve`), solves its own constraint with the same
method, and the background gets one correction: the members' node impulses at their rows (summed),
their cut zones' surface velocities at theirs.

The members' constraint solves are independent, which is exact as long as no background node is in
the stencil of two members' cut zones (bodies of different solvers more than a zone apart).  Closer
than that the two multiplier systems would share the node's mass, a coupled system this module does
not assemble: the run stops with a GeometryError naming the zone or node and the time (contact
between bodies is issue 11's dual-pass mortar method).

With one member everything passes straight through (the single-foreground case is bitwise the one
it was before this module).
"""
from __future__ import annotations

import numpy as np

from orchestrator.coupling.embedded import EmbeddedCoupling
from orchestrator.coupling.geometry import GeometryError


def _nanmax(vals):
    """The largest of the values that are numbers (nan: a member that has not measured it yet)."""
    fin = [v for v in vals if not np.isnan(v)]
    return max(fin) if fin else np.nan


def _union_sum(ids_list, vals_list):
    """Sorted union of ids with the sum of their values (clipped to 1: disjoint bodies' fractions)."""
    ids = np.concatenate(ids_list).astype(np.int64)
    vals = np.concatenate(vals_list).astype(np.float64)
    u, inv = np.unique(ids, return_inverse=True)
    return u, np.minimum(np.bincount(inv, weights=vals, minlength=u.size), 1.0)


def merge_geometries(geoms, roles, constraint_nodes=None):
    """One solvers.ale.coupled.BodyGeometry from the members' (each with sorted ``cut`` and
    ``nodes``), and per member the positions of its cut zones and nodes in the merged lists.
    ``constraint_nodes``: per member the nodes of its constraint solve (default: all its nodes),
    which no two members may share."""
    from solvers.ale.coupled import BodyGeometry

    zones, fractions = _union_sum([g.zones for g in geoms], [g.fractions for g in geoms])
    faces = tuple(_union_sum([g.faces[d][0] for g in geoms], [g.faces[d][1] for g in geoms])
                  for d in range(len(geoms[0].faces)))
    cut = np.concatenate([g.cut for g in geoms])
    order = np.argsort(cut, kind="stable")
    cut = cut[order]
    _shared("zone", cut, [g.cut for g in geoms], roles)
    nodes = np.unique(np.concatenate([g.nodes for g in geoms]))
    constraint = [g.nodes if c is None else c for g, c in zip(geoms, constraint_nodes or [None] * len(geoms))]
    if np.unique(np.concatenate(constraint)).size != sum(c.size for c in constraint):
        # (a node only tying another member's orphan particles may be shared: those impulses add)
        _shared("node", np.sort(np.concatenate(constraint)), constraint, roles)
    velocity = np.concatenate([g.velocity for g in geoms])[order]
    rs = np.concatenate([g.run_start for g in geoms])
    ro = np.argsort(rs, kind="stable")
    merged = BodyGeometry(zones, fractions, faces, cut, nodes, velocity, rs[ro],
                          np.concatenate([g.run_length for g in geoms])[ro])
    rows = [(np.searchsorted(cut, g.cut), np.searchsorted(nodes, g.nodes)) for g in geoms]
    return merged, rows


def _shared(what, ids_sorted, lists, roles):
    dup = ids_sorted[1:][ids_sorted[1:] == ids_sorted[:-1]]
    if dup.size:
        owners = [r for ids, r in zip(lists, roles) if np.isin(dup[0], ids)]
        raise GeometryError(
            f"bodies of the {' and '.join(owners)} groups share the background {what} {int(dup[0])}: bodies of "
            "two solver groups within a zone of each other need contact (issue 11), not two independent "
            "constraint solves")


class ForegroundCouplings:
    """The coupler's view of the embedded-mesh coupling: the members (one per foreground role, in
    the order of ``roles``) behind the interface of one EmbeddedCoupling."""

    # how a diagnostic of the members combines into the coupling's one (EmbeddedCoupling.DIAGNOSTICS)
    _COMBINE = {"iterations": max, "residual": max, "dissipation": sum, "foreground_work": sum,
                "stable_dt_limit": min, "cond_H": _nanmax, "lambda_oscillation": max,
                "lambda_oscillation_max": max, "void_zones": sum, "tied_orphans": sum,
                "substeps": max, "substep_passes": max, "substep_residual": max,
                "momentum_in_transit": sum, "energy_in_transit": sum}

    def __init__(self, case: dict, surfaces: list[dict], roles: list[str]):
        self.roles = list(roles)
        self.members = [EmbeddedCoupling(case, s) for s in surfaces]
        first = self.members[0]
        self.dim, self.method = first.dim, first.method
        self._rows = None
        self._nb = self._nc = 0

    # (what the coupler reads: the smallest limit, the worst conditioning, the sums of the exchange)
    @property
    def stable_limit(self) -> float:
        return min(m.stable_limit for m in self.members)

    @property
    def cond_H(self) -> float:
        return _nanmax([m.cond_H for m in self.members])

    @property
    def momentum_f(self) -> np.ndarray:
        return sum(m.momentum_f for m in self.members)

    @property
    def momentum_scale(self) -> float:
        """The scale of the momentum balance: the members' impulses in size (two pistons driven
        apart give each other's opposite momentum: their sum alone would measure round-off against
        round-off), and the largest step's impulses node by node (a block ringing in a box takes
        impulses that cancel over its surface: measured 0.46 of round-off against its net's
        round-off before)."""
        return float(sum(max(np.linalg.norm(m.momentum_f), m.impulse_size) for m in self.members))

    @property
    def work_f(self) -> float:
        return sum(m.work_f for m in self.members)

    def geometry(self):
        geoms = [m.geometry() for m in self.members]
        if len(geoms) == 1:
            return geoms[0]
        merged, self._rows = merge_geometries(geoms, self.roles, [m.ops.bnodes for m in self.members])
        # the sizes of the merged lists the background's packet spans: not the sums of the members'
        # (a node tying only orphan particles may be in two members' lists, merge_geometries)
        self._nb, self._nc = merged.nodes.size, merged.cut.size
        return merged

    def load_kernels(self) -> None:
        for m in self.members:
            m.load_kernels()

    def solve(self, dt: float, dt_avg: float, vstars: list, background: np.ndarray, substeps=None,
              predicted=None, mobility=None) -> list:
        """Each member's surface impulses from its rows of the background's interface packet
        (v_b, m_b of the merged nodes, R and the fill of the merged cut zones); ``substeps``,
        ``predicted``: per member, its substeps and its predictor pass's impulses (EmbeddedCoupling.solve)."""
        substeps = substeps or [1] * len(self.members)
        predicted = predicted or [None] * len(self.members)
        mobility = mobility or [1.0] * len(self.members)
        return [self.solve_member(i, dt, dt_avg, vs, background, k, pred, c)
                for i, (vs, k, pred, c) in enumerate(zip(vstars, substeps, predicted, mobility))]

    def solve_member(self, i: int, dt: float, dt_avg: float, vstar, background: np.ndarray, substeps: int = 1,
                     predicted=None, mobility: float = 1.0) -> np.ndarray:
        """Member i's solve on its rows of the background's packet (again: a substeps' pass)."""
        extra = (substeps, predicted, mobility) if substeps > 1 else ()   # (multi-rate's, multirate.py)
        if len(self.members) == 1:
            return self.members[0].solve(dt, dt_avg, vstar, background, *extra)
        dim = self.dim
        nb, nc = self._nb, self._nc
        v_b = background[: nb * dim].reshape(nb, dim)
        m_b = background[nb * dim: nb * (dim + 1)]
        a = nb * (dim + 1)
        R = background[a: a + nc * dim].reshape(nc, dim)
        fill = background[a + nc * dim:]
        ic, inode = self._rows[i]
        part = [v_b[inode].ravel(), m_b[inode], R[ic].ravel()] + ([fill[ic]] if fill.size else [])
        return self.members[i].solve(dt, dt_avg, vstar, np.concatenate(part), *extra)

    def replace_surface(self, i: int, surface: dict) -> None:
        """Member i's foreground surface changed (elements eroded): the next geometry() is on it."""
        self.members[i].replace_surface(surface)

    def take_state(self, states: list) -> np.ndarray:
        """The background's correction: [node impulses (nb, dim), v^{n+1/2}_e (nc, dim), mean
        velocity_e (nc, dim)] over the merged lists."""
        if len(self.members) == 1:
            return self.members[0].take_state(states[0])
        dim = self.dim
        nb, nc = self._nb, self._nc
        imp = np.zeros((nb, dim))
        vh, vb = np.zeros((nc, dim)), np.zeros((nc, dim))
        for m, (ic, inode), st in zip(self.members, self._rows, states):
            c = m.take_state(st)
            k, n = inode.size * dim, ic.size * dim
            np.add.at(imp, inode, c[:k].reshape(-1, dim))
            vh[ic] = c[k: k + n].reshape(-1, dim)
            vb[ic] = c[k + n: k + 2 * n].reshape(-1, dim)
        return np.concatenate([imp.ravel(), vh.ravel(), vb.ravel()])

    # ---- diagnostics and checkpoints ---------------------------------------------------------------
    def diagnostic_names(self) -> list[str]:
        return self.members[0].diagnostic_names()

    def diagnostics(self) -> list[float]:
        if len(self.members) == 1:
            return self.members[0].diagnostics()
        rows = [m.diagnostics() for m in self.members]
        names = self.diagnostic_names()
        out = []
        for j, name in enumerate(names):
            vals = [r[j] for r in rows]
            out.append(sum(vals) if name.startswith(("foreground_momentum_", "interface_force_"))
                       else self._COMBINE[name](vals))
        return out

    def state_arrays(self) -> dict[str, np.ndarray]:
        if len(self.members) == 1:
            return self.members[0].state_arrays()
        return {f"{r}__{k}": a for r, m in zip(self.roles, self.members) for k, a in m.state_arrays().items()}

    def load_state(self, arrays: dict) -> None:
        if len(self.members) == 1:
            self.members[0].load_state(arrays)
            return
        for r, m in zip(self.roles, self.members):
            p = f"{r}__"
            m.load_state({k[len(p):]: a for k, a in arrays.items() if k.startswith(p)})
