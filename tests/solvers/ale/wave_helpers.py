"""Small-amplitude sound waves set directly into an ALE solver (not a test module): the
characteristic-face tests start a wave packet or pulse from point values of the exact linear
acoustic field, which case regions (piecewise-constant states) cannot express."""
from __future__ import annotations

import numpy as np

from solvers.ale import hydro
from solvers.ale.solver import AleSolver


def set_acoustic_state(s: AleSolver, rho0: float, p0: float, c0: float, field) -> None:
    """Overwrite the solver's initial state with the background (rho0, p0 at rest) plus a linear
    acoustic perturbation: ``field(x) -> (p', u')`` at points x (n, dim); rho' = p'/c0^2 at the zone
    centres, the velocity at the nodes.  Masses, ghosts and forces are rebuilt as at construction
    (the balances start from this state)."""
    B = s.block
    real = B.real_zone
    pz, _ = field(B.zone_centres()[real])
    rho = rho0 + pz / c0 ** 2
    e = np.empty(rho.size)
    if s.mm is None:
        hydro.energy_from_pressure_array(s.eos_code, s.eos_par, rho, p0 + pz, e)
        s.rho[real], s.e[real] = rho, e
        s.M[real] = rho * s.V[real]
    else:   # several materials: the perturbation in the zones the first material fills alone
        mm = s.mm
        hydro.energy_from_pressure_array(int(mm.code[0]), mm.par[0], rho, p0 + pz, e)
        z = np.flatnonzero(real)
        pure = mm.vol[z, 0] == mm.vol[z].sum(axis=1)
        z, rho, e = z[pure], rho[pure], e[pure]
        mm.mass[z, 0] = rho * mm.vol[z, 0]
        mm.ener[z, 0] = e
        mm.deh[z] = 0.0
        s.M[z] = mm.mass[z].sum(axis=1)
        s.e[z] = e
    _, un = field(s.x)
    s.v[:] = un
    s.bc.fill_nodes_vector(s.v)
    s._fill_zone_state()
    if s._char is not None:  # exterior states from the new initial state
        s._char._ready = False
    s._initialising = True
    s._dt_stable = s._forces(midstep=False, advect=s.mode == "eulerian", eos=True)
    s._initialising = False
    d0 = s._totals()
    s.mass0, s.energy0, s.momentum0 = d0["mass"], d0["total_energy"], d0["momentum"]


def plane_packet(direction, wavelength: float, x0: float, width: float, amplitude: float, z0: float):
    """A right-running packet p' = A exp(-(x - x0)^2 / (2 w^2)) cos(k n.x), u' = p' n / z0 (z0 = rho c):
    a plane wave along the unit vector ``direction`` under an envelope along x."""
    n = np.asarray(direction, np.float64)
    n = n / np.linalg.norm(n)
    k = 2.0 * np.pi / wavelength

    def field(x):
        x = np.asarray(x)
        p = amplitude * np.exp(-0.5 * ((x[:, 0] - x0) / width) ** 2) * np.cos(k * (x @ n[: x.shape[1]]))
        return p, p[:, None] * n[None, : x.shape[1]] / z0
    return field


def pulse(x0: float, width: float, amplitude: float, z0: float, dim: int):
    """A right-running Gaussian pulse along x: p' = A exp(-(x - x0)^2 / (2 w^2)), u' = (p'/z0, 0..)."""
    def field(x):
        x = np.asarray(x)
        p = amplitude * np.exp(-0.5 * ((x[:, 0] - x0) / width) ** 2)
        u = np.zeros((x.shape[0], dim))
        u[:, 0] = p / z0
        return p, u
    return field
