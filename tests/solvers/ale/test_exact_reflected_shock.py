"""Exact reflected-shock solution (solvers.ale.exact.reflected_shock) against independent references:
the closed forms for a perfect gas in Anderson, "Modern Compressible Flow" (3rd ed., section 7.7),

    p5 / p2 = ((3 gamma - 1) M^2 - 2 (gamma - 1)) / ((gamma - 1) M^2 + 2)
    M_R / (M_R^2 - 1) = M / (M^2 - 1) sqrt(1 + 2 (gamma - 1) / (gamma + 1)^2 (M^2 - 1) (gamma + 1 / M^2)),

and the exact Riemann solver (the reflection is the symmetric Riemann problem (rho2, u2, p2) |
(rho2, -u2, p2): u* = 0, p* = p5, rho* = rho5, shocks at -/+ |W_r|), which also covers the
stiffened gas.  Literal values for M = 2, gamma = 1.4: p2 = 4.5, rho2 = 8/3, p5 = 15, rho5 = 6."""
import math

import numpy as np
import pytest

from solvers.ale.exact import RiemannSolution
from solvers.ale.exact.reflected_shock import ReflectedShock


@pytest.mark.parametrize("gamma", [1.4, 5.0 / 3.0, 1.2])
@pytest.mark.parametrize("mach", [1.05, 1.5, 2.0, 3.0, 8.0])
def test_anderson_closed_forms(mach, gamma):
    ex = ReflectedShock((1.2, 1.0e5), gamma, mach=mach)
    g, M = gamma, mach
    assert ex.p5 / ex.p2 == pytest.approx(((3 * g - 1) * M * M - 2 * (g - 1)) / ((g - 1) * M * M + 2), rel=1e-13)
    MR = ex.reflected_mach
    rhs = M / (M * M - 1) * math.sqrt(1 + 2 * (g - 1) / (g + 1) ** 2 * (M * M - 1) * (g + 1 / M ** 2))
    assert MR / (MR * MR - 1) == pytest.approx(rhs, rel=1e-12)
    assert ex.reflected_speed < 0 < ex.incident_speed


def test_mach2_literal_values():
    ex = ReflectedShock((1.0, 1.0), 1.4, mach=2.0)
    assert (ex.p2, ex.rho2) == (pytest.approx(4.5, rel=1e-14), pytest.approx(8.0 / 3.0, rel=1e-14))
    assert ex.p5 == pytest.approx(15.0, rel=1e-13)
    assert ex.rho5 == pytest.approx(6.0, rel=1e-13)
    assert ex.u2 == pytest.approx(2.0 * math.sqrt(1.4) * (1 - 3.0 / 8.0), rel=1e-14)
    # behind_pressure instead of the Mach number gives the same shock
    alt = ReflectedShock((1.0, 1.0), 1.4, behind_pressure=4.5)
    assert alt.mach == pytest.approx(2.0, rel=1e-14) and alt.p5 == pytest.approx(15.0, rel=1e-13)


@pytest.mark.parametrize("gamma, p_inf", [(1.4, 0.0), (4.4, 6.0e8), (2.0, 1.0)])
def test_symmetric_riemann_problem(gamma, p_inf):
    ahead = (1000.0, 1.0e5) if p_inf > 1e3 else (1.0, 1.0)
    ex = ReflectedShock(ahead, gamma, mach=1.7, p_inf=p_inf)
    rs = RiemannSolution(left=(ex.rho2, ex.u2, ex.p2), right=(ex.rho2, -ex.u2, ex.p2), gamma_l=gamma,
                         p_inf_l=p_inf, p_inf_r=p_inf)
    assert abs(rs.u_star) <= 1e-12 * ex.u2
    assert rs.p_star == pytest.approx(ex.p5, rel=1e-12)
    assert rs.rho_star_l == pytest.approx(ex.rho5, rel=1e-12)
    assert rs.waves(1.0, 0.0)["left_shock"] == pytest.approx(ex.reflected_speed, rel=1e-10)


def test_sample_and_positions():
    ex = ReflectedShock((1.0, 1.0), 1.4, mach=2.0)
    tr = ex.reflection_time(0.5, 0.75)
    assert tr == pytest.approx(0.25 / ex.incident_speed, rel=1e-15)
    x = np.array([0.1, 0.55, 0.7, 0.8])
    rho, u, p = ex.sample(x, 0.5 * tr, 0.5, 0.75)  # incident shock at 0.625
    assert np.allclose(rho[:2], ex.rho2) and rho[2] == 1.0 and np.isnan(rho[3])
    assert u[2] == 0.0 and p[0] == pytest.approx(4.5)
    kind, xs = ex.shock_position(tr + 0.1, 0.5, 0.75)
    assert kind == "reflected" and xs == pytest.approx(0.75 + ex.reflected_speed * 0.1)
    rho, u, p = ex.sample(np.array([xs - 1e-9, xs + 1e-9]), tr + 0.1, 0.5, 0.75)
    assert rho[0] == pytest.approx(ex.rho2) and rho[1] == pytest.approx(6.0)
    assert u[1] == 0.0 and p[1] == pytest.approx(15.0)


def test_bad_inputs():
    with pytest.raises(ValueError):
        ReflectedShock((1.0, 1.0), 1.4, mach=0.9)
    with pytest.raises(ValueError):
        ReflectedShock((1.0, 1.0), 1.0, mach=2.0)
    with pytest.raises(ValueError):
        ReflectedShock((1.0, 1.0), 1.4)
    with pytest.raises(ValueError):
        ReflectedShock((1.0, 1.0), 1.4, behind_pressure=0.5)
