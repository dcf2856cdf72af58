"""Penalty contact as the same operators with a compliance in place of the stabilization (issue 11's
penalty variants, 2-D).

The KKT system of kkt.py already holds a penalty law: with g~ = B x + J p >= 0, p >= 0,
complementary, an active multiplier has g~ = 0, i.e. p = -(B x) / J for a diagonal J > 0: the
multiplier is the penetration times the stiffness 1 / J, and zero where the sides are apart. So a
penalty method is a constraint operator B with ``stabilization()`` returning the diagonal compliance
J = diag(1 / k_A), and kkt.solve_frictionless and explicit.py solve it unchanged.

The stiffness is set per unit area and scaled with the material and the mesh so that one factor
means the same on every mesh and in every unit system:

    k = kappa E / h     (pressure per unit interpenetration; kappa dimensionless, h a facet length)

so the interface is as compliant as a layer of the bodies' own material kappa^-1 elements thick:
with a stress sigma across it, the interpenetration is sigma / k = (sigma / E) h / kappa, the
strain of 1 / kappa elements. ``stabilization(gamma, h)`` receives the callers' gamma = alpha / E
and h (kkt/test callers: the stabilization's scale; the schema's alpha, default 1): the penalty
methods read alpha as a compliance factor, kappa = penalty / alpha, with the constructor keyword
``penalty`` (default PENALTY = 100: an interpenetration of 1 % of an element's strain, a stress error
of h / 100 per unit length of body in series; the KKT system stays well conditioned up to ~1e8).

* ``PenaltyMortar`` (``penalty``): the dual pass's weighted gaps G (dual_pass.py: row A is
  g_A = integral of phi_A times the gap, ~ area_A x gap) with B = G / 2 (both passes averaged, no side
  preferred) and no stabilization. Row A's multiplier is a pressure; to have p_A = k (-gap_A) =
  -k (G_A x) / area_A from p_A = -(B_A x) / J_AA = -(G_A x) / (2 J_AA):

      J_AA = area_A / (2 k) = (gamma h / (2 penalty)) area_A,    area_A = sum_B D_AB,

  which is the dual pass's stabilization (gamma h / 2) D n.n with D row-sum lumped, the cross-pass
  M terms dropped, divided by ``penalty``. Each pass's forces are consistent (G^T p of a uniform p
  is the exact nodal load of the pressure p on either side) and B^T p averages them, so a uniform
  penetration carries a uniform stress: the penalty mortar passes the patch test but for its
  compliance, an error (h / kappa) / (1 + h / kappa) in Crisfield's test (tests: test_penalty.py).
  Self contact (one pass of a surface on itself, B = G / 2, every pair twice) is the same formula.
  The limit kappa -> infinity is the two passes without stabilization, which over-constrain (both
  passes' weighted gaps zero make the gap field vanish: a sliding stack of beams held shut locks,
  test_method_failures.py: 0.26 of the dual pass's deflection at kappa 1e10, 0.9998 at the default);
  keep kappa well below ~1e5 on bending problems.

* ``PenaltyNodeToSurface`` (``node_to_surface_penalty``, passes=1; ``node_to_surface_double_penalty``,
  passes=2): node_to_surface.py's geometric gaps, a multiplier being a nodal force (per unit
  thickness). Node A's force is the pressure over its tributary length A_A (half of each slave
  segment at A that faces the master: n_seg . n_A < -FACING_COS, a corner's side face left out),
  f_A = k A_A (-g_A), so J_AA = 1 / (k A_A) = gamma h / (penalty A_A). The double pass halves each
  pass's stiffness (J doubled, as B = G / 2 averages the dual pass): a uniform interpenetration
  then carries the same pressure k d with one pass or two. Nothing makes the master side's
  share of the forces consistent: it fails the patch test at every kappa; the double pass keeps its
  over-constraint, now as a stiff penalty instead of a singular system (it locks as kappa grows).

Everything is vectorised numpy / scipy.sparse over multipliers and segments.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from solvers.contact.dual_pass import DualPassContact
from solvers.contact.mortar_segments import FACING_COS
from solvers.contact.node_to_surface import NodeToSurface

__all__ = ["PENALTY", "PenaltyMortar", "PenaltyNodeToSurface", "tributary_lengths"]

PENALTY = 100.0
"""Default dimensionless penalty factor kappa: k = PENALTY E / (alpha h) per unit area."""


class PenaltyMortar(DualPassContact):
    """The dual pass's operators with the penalty compliance J = (gamma h / (2 penalty)) diag(area)
    in place of its stabilization (module docstring); seg_b None: self contact."""

    def __init__(self, points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray | None, capture: float,
                 penetration: float | None = None, penalty: float = PENALTY):
        if not penalty > 0.0:
            raise ValueError(f"penalty factor must be > 0, got {penalty!r}")
        super().__init__(points, seg_a, seg_b, capture, penetration)
        self.penalty = float(penalty)

    def stabilization(self, gamma: float, h: float) -> sp.csr_matrix:
        """J (n_multipliers, n_multipliers) diagonal: area_A gamma h / (2 penalty), pressures
        p_A = (penalty / (gamma h)) (-gap_A) on the active set."""
        area = np.concatenate([p.area for p in self.passes]) if self.passes else np.zeros(0)
        return sp.diags(area * (0.5 * gamma * h / self.penalty), format="csr")


def tributary_lengths(points: np.ndarray, slave: np.ndarray, nodes: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(len(nodes),) half the summed length of the slave segments at each node (sorted unique ids)
    whose outward unit normal faces that node's master normal (normals (len(nodes), 2)): the part of
    the surface the node's force stands for."""
    x = np.asarray(points, dtype=np.float64)
    out = np.zeros(len(nodes))
    if len(nodes) == 0 or len(slave) == 0:
        return out
    d = x[slave[:, 1]] - x[slave[:, 0]]
    length = np.linalg.norm(d, axis=1)
    ns = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.maximum(length, 1e-300)[:, None]
    ends = slave.ravel()                              # both ends of every segment
    k = np.searchsorted(nodes, ends).clip(max=len(nodes) - 1)
    hit = nodes[k] == ends
    seg = np.repeat(np.arange(len(slave)), 2)
    facing = np.einsum("ij,ij->i", ns[seg], normals[k]) < -FACING_COS
    ok = hit & facing
    np.add.at(out, k[ok], 0.5 * length[seg[ok]])
    # a node whose every own segment is at a slant to its master (a sharp corner whose nodal normal
    # faced): its segments' plain half lengths rather than an infinite compliance
    none = out == 0.0
    if np.any(none):
        np.add.at(out, k[hit & none[k]], 0.5 * length[seg[hit & none[k]]])
    return out


class PenaltyNodeToSurface(NodeToSurface):
    """node_to_surface.py's constraints (single or double pass) with the penalty compliance
    J_AA = passes gamma h / (penalty A_A), A_A the node's tributary length (module docstring)."""

    def __init__(self, points: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, capture: float,
                 penetration: float | None = None, passes: int = 1, penalty: float = PENALTY):
        if not penalty > 0.0:
            raise ValueError(f"penalty factor must be > 0, got {penalty!r}")
        super().__init__(points, seg_a, seg_b, capture, penetration, passes)
        self.penalty = float(penalty)
        self.n_passes = passes
        slaves = [np.asarray(seg_a, np.int64)] + ([np.asarray(seg_b, np.int64)] if passes == 2 else [])
        # rows' nodes come out of a unique/lexsort, sorted: the searchsorted lookup holds
        self.tributary = np.concatenate([tributary_lengths(self.points, s, r[0], r[3])
                                         for s, r in zip(slaves, self.rows)])

    def stabilization(self, gamma: float, h: float) -> sp.csr_matrix:
        """J diagonal: passes gamma h / (penalty A_A); nodal forces f_A = k A_A (-g_A) / passes."""
        return sp.diags(self.n_passes * gamma * h / (self.penalty * self.tributary), format="csr")
