"""Gonzalez's discrete gradient for neo-Hookean bodies (solvers/lagrange/discrete_gradient_nh.py):
the step's internal force does exactly the stored energy's change as work (any step, 2-D and 3-D),
sums to zero with zero moment about the midpoint configuration, and is the static force (its Newton
matrix half the static tangent) when the step does not move."""
import numpy as np
import pytest

from solvers.lagrange import discrete_gradient_nh as dg
from solvers.lagrange import finite_strain
from solvers.lagrange.mesh import body_mesh

MU, LAM = finite_strain.lame(1.0e6, 0.3)


def _mesh(dim):
    box = ({"lower": [0, 0], "upper": [1, 0.5], "cells": [4, 2]} if dim == 2
           else {"lower": [0, 0, 0], "upper": [1, 0.5, 0.5], "cells": [3, 2, 2]})
    m = body_mesh({"mesh": {"box": box}}, dim)
    return m.points, m.cells


def _cross(x, f):
    if x.shape[1] == 2:
        return np.sum(x[:, 0] * f[:, 1] - x[:, 1] * f[:, 0])
    return np.cross(x, f).sum(axis=0)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_force_does_the_energys_change_and_keeps_the_momenta(dim):
    """(u1 - u0) . f = U1 - U0 (measured 5.6e-16 / 2.2e-16 relative) for a large random step (2 %
    strains and 4 % more); sum f = 0 and sum x_{n+1/2} x f = 0 to 1e-15 of |f| |x|."""
    P, C = _mesh(dim)
    rng = np.random.default_rng(0)
    u0 = 0.01 * rng.standard_normal(P.shape)
    u1 = u0 + 0.02 * rng.standard_normal(P.shape)
    f = dg.dg_force(P, C, u0, u1, MU, LAM)
    du = dg.nh_energy(P, C, u1, MU, LAM) - dg.nh_energy(P, C, u0, MU, LAM)
    assert (u1 - u0).ravel() @ f == pytest.approx(du, rel=5e-15)
    ff = f.reshape(P.shape)
    scale = np.abs(ff).max()
    assert np.abs(ff.sum(axis=0)).max() < 1e-15 * scale * len(P)
    xm = P + 0.5 * (u0 + u1)
    assert np.abs(_cross(xm, ff)).max() < 1e-15 * scale * len(P)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_step_that_does_not_move_is_the_static_force(dim):
    """u0 = u1: f is finite_strain's internal force and the Newton matrix half its tangent (the
    midpoint's dF = dF_{n+1} / 2), to round-off (measured 5.8e-16 / 9.8e-16, 2e-16)."""
    P, C = _mesh(dim)
    u = 0.01 * np.random.default_rng(1).standard_normal(P.shape)
    k, f = dg.dg_tangent(P, C, u, u, MU, LAM)
    ks, fs = finite_strain.tangent(P, C, u, MU, LAM)
    assert np.abs(f - fs).max() < 1e-14 * np.abs(fs).max()
    assert abs(2.0 * k - ks).max() < 1e-14 * abs(ks).max()
