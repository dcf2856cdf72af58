"""Surface loads of the Lagrangian solver: the consistent nodal forces of a uniform traction on the
exterior facets in a region (``[[boundaries]] type = "traction"``).

For a traction t on a facet, node a gets t times the integral of its shape function over the facet:
L/2 on a 2-node segment (exact), and on a bilinear quad the 2 x 2 Gauss rule of N_a |x_xi x x_eta|
(exact for a flat facet: the integrand is then bilinear times bilinear at most quadratic per
direction). Vectorised over facets.

Dead loads in time (SurfaceLoads): each traction's nodal forces times its curve's factor at t, the
curve [[t, factor], ...] linear between its points and held at its end values outside (LS-DYNA's
*DEFINE_CURVE; Simo & Tarnow's hat pulses); a traction without a curve is constant.
"""
from __future__ import annotations

import numpy as np

__all__ = ["traction_loads", "SurfaceLoads"]

_G = 1.0 / np.sqrt(3.0)
_XI = np.array([[-_G, -_G], [_G, -_G], [_G, _G], [-_G, _G]])
_CORNERS = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)


def facet_weights(points: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """(nf, nodes per facet): the integral of each facet node's shape function over the facet."""
    x = np.asarray(points, dtype=np.float64)[facets]
    if facets.shape[1] == 2:
        length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
        return np.repeat(0.5 * length[:, None], 2, axis=1)
    xi, eta = _XI[:, 0, None], _XI[:, 1, None]                         # (4 gauss, 1)
    n = (1 + xi * _CORNERS[:, 0]) * (1 + eta * _CORNERS[:, 1]) / 4     # (gauss, node)
    dxi = _CORNERS[:, 0] * (1 + eta * _CORNERS[:, 1]) / 4
    deta = _CORNERS[:, 1] * (1 + xi * _CORNERS[:, 0]) / 4
    t1 = np.einsum("ga,fad->fgd", dxi, x)
    t2 = np.einsum("ga,fad->fgd", deta, x)
    da = np.linalg.norm(np.cross(t1, t2), axis=2)                      # (nf, gauss), weights 1
    return np.einsum("ga,fg->fa", n, da)


def traction_loads(points: np.ndarray, facets: np.ndarray, tractions) -> np.ndarray:
    """(n, dim) nodal forces of tractions [(node mask (n,), traction (dim,)), ...] on the facets whose
    nodes all lie in the mask."""
    x = np.asarray(points, dtype=np.float64)
    out = np.zeros_like(x)
    if not len(tractions):
        return out
    w = facet_weights(x, facets)
    for mask, t in tractions:
        sel = mask[facets].all(axis=1)
        np.add.at(out, facets[sel].ravel(), w[sel].ravel()[:, None] * np.asarray(t, float)[None, :])
    return out


class SurfaceLoads:
    """The tractions' nodal forces as a function of time: at(t) = sum_k F_k c_k(t) (module docstring)."""

    def __init__(self, points: np.ndarray, facets: np.ndarray, tractions, curves):
        self._forces = [traction_loads(points, facets, [tr]) for tr in tractions]
        self._curves = [None if c is None else np.asarray(c, dtype=np.float64) for c in curves]
        self.shape = np.asarray(points).shape

    def __bool__(self) -> bool:
        return bool(self._forces)

    def factor(self, k: int, t: float) -> float:
        c = self._curves[k]
        return 1.0 if c is None else float(np.interp(t, c[:, 0], c[:, 1]))

    def at(self, t: float) -> np.ndarray:
        """(n, dim) nodal forces at time t."""
        out = np.zeros(self.shape)
        for k, f in enumerate(self._forces):
            out += self.factor(k, t) * f
        return out
