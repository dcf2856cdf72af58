"""J2 plasticity at a plane-strain shell strip's through-thickness points (solvers/lagrange/
strip_plasticity.py) and the plastic hinge it gives beam2d.py's element, against closed forms: the
plane-strain yield stress 2 sigma_y / sqrt 3 with sigma_yy = sigma_xx / 2, the consistency
sigma_vm = sigma_y + H alpha, and the fully plastic moment M_p = (2 / sqrt 3) sigma_y h^2 / 4."""
from __future__ import annotations

import numpy as np

from solvers.lagrange import beam2d
from solvers.lagrange.strip_plasticity import plane_strain_yield, strip_return

E, NU, SY = 2.0e11, 0.3, 2.5e8
E_PLANE = E / (1 - NU ** 2)


def _pull(hardening: float, strain: float = 0.02, steps: int = 400):
    ep, al = np.zeros((1, 2)), np.zeros(1)
    for e in np.linspace(0.0, strain, steps + 1)[1:]:   # (a loading path, increment by increment)
        sx, sy, ep, al = strip_return(np.array([e]), ep, al, E, NU, SY, hardening)
    return sx[0], sy[0], al[0]


def test_uniaxial_plane_strain_reaches_the_plane_strain_yield_stress():
    """Pulled to 2 % (100 times the yield strain) without hardening: sigma_xx = 2 sigma_y / sqrt 3
    (measured to 2e-16), sigma_yy / sigma_xx = 1/2 (1.0e-8: the elastic strain's share), the von
    Mises stress on the yield surface (1.1e-16 of sigma_y). With hardening H = 2e9 Pa the von Mises
    stress is sigma_y + H alpha (2.4e-16)."""
    sx, sy, al = _pull(0.0)
    assert abs(sx / plane_strain_yield(SY) - 1) < 1e-12
    assert abs(sy / sx - 0.5) < 1e-7
    assert abs(np.sqrt(sx * sx - sx * sy + sy * sy) / SY - 1) < 1e-12
    sx, sy, al = _pull(2.0e9)
    assert abs(np.sqrt(sx * sx - sx * sy + sy * sy) - (SY + 2.0e9 * al)) < 1e-12 * SY
    assert sx > 1.1 * plane_strain_yield(SY)


def test_below_yield_the_points_are_elastic():
    """At 0.9 of the first yield the stress is E' eps, sigma_yy nu sigma_xx, no plastic strain (exact)."""
    e_yield = SY / np.sqrt(1 - NU + NU ** 2) / E_PLANE
    sx, sy, ep, al = strip_return(np.array([0.9 * e_yield]), np.zeros((1, 2)), np.zeros(1), E, NU, SY)
    assert np.isclose(sx[0], E_PLANE * 0.9 * e_yield, rtol=1e-14, atol=0) and np.isclose(sy[0], NU * sx[0], rtol=1e-14)
    assert not ep.any() and not al.any()


def _hinge(points: int, factor: float = 40.0, steps: int = 400, unload: float = 0.0):
    """One element bent uniformly (nodal rotations -+ kappa L0 / 2, no stretch, no shear) to `factor`
    times the curvature of first yield, then back by `unload` of it: (M / M_p at the end, the
    unloading slope dM / dkappa over E' h^3 / 12)."""
    h, L0 = 0.01, 0.1
    X, el = np.array([[0.0, 0.0], [L0, 0.0]]), np.array([[0, 1]])
    sec = beam2d.BeamSection(E, NU, 7800.0, np.full(1, h), points=points, yield_stress=SY)
    state = beam2d.plastic_state(1, sec)
    k_yield = SY / np.sqrt(1 - NU + NU ** 2) / E_PLANE / (h / 2)
    path = list(np.linspace(0.0, factor * k_yield, steps + 1)[1:])
    if unload:
        path += [factor * k_yield - unload * k_yield]
    moments = []
    for k in path:   # (the loading path)
        _, _, res, state = beam2d.internal_forces(X, X, np.array([-0.5, 0.5]) * k * L0, el, sec, plastic=state)
        moments.append(res[0, 1])
    m_p = plane_strain_yield(SY) * h * h / 4
    slope = (moments[-1] - moments[-2]) / (path[-1] - path[-2]) / (E_PLANE * h ** 3 / 12)
    return moments[-1] / m_p, slope


def test_plastic_hinge_reaches_the_fully_plastic_moment():
    """At 40 times the first yield's curvature the moment is the fully plastic one of the points'
    quadrature, M_p 4 sum w_k |z_k| / h (5 Gauss points: 0.94485; measured equal to round-off: every
    point but the middle one, whose stress is zero, is on the plane-strain yield stress), and with 21
    points within 0.5 % of the closed-form M_p (measured -0.36 %; 51 points -0.063 %). Unloading is
    elastic: the slope dM / dkappa is E' h^3 / 12 (measured to 1e-15)."""
    import numpy.polynomial.legendre as leg

    xi, w = leg.leggauss(5)
    quad = 4 * np.sum(0.5 * w * np.abs(0.5 * xi))
    m5, slope = _hinge(5, unload=0.5)
    m5_loaded, _ = _hinge(5)
    assert abs(m5_loaded / quad - 1) < 1e-12, m5_loaded / quad - 1
    assert abs(_hinge(21)[0] - 1) < 5e-3
    assert abs(slope - 1) < 1e-12, slope
