"""Characteristic (non-reflecting) open faces of the ALE grid: inflow, outflow and far field.

The fluid beyond an open face is an *exterior state* ``(rho_e, u_e, p_e, c_e)`` per face zone:
the state a case gives (``inflow``, ``far_field`` tables), or the initial state of the zone next to
the face (``"outflow"``, ``"far_field"`` strings: the face then holds the incoming characteristic
it starts with and lets every wave leave).  The face's ghost zones use the zero-gradient maps of
boundary.py for everything except what this module sets: their pressure (every step), and the
density and energy the remap takes in (the donors).

Face pressure (the exterior's wave curve)
-----------------------------------------
A face moving with normal velocity ``u_b`` (``n`` the outward normal) pushes the exterior with
``du = (u_b - u_e) . n``; the exterior answers with the pressure of its own wave curve::

    p_b(du) = p_e + rho_e W(du) du,      W(du) = A du + sqrt(A^2 du^2 + c_e^2)         (1)

the Rankine-Hugoniot pressure behind a shock whose speed grows linearly with the particle-velocity
jump, slope ``A = G/2`` (``G = 1 + (rho/c) (dc/drho)_s``, the fundamental derivative of the
exterior's EOS, evaluated once per face zone).  For an ideal or stiffened gas (1) is exact on the
shock branch (``A = (gamma + 1)/4``); for a Mie-Grueneisen solid it is the ``us = c0 + s up`` law
near its reference state; on the expansion branch (``du < 0``, a rarefaction leaving the domain) it
agrees with the isentrope to second order in ``du`` (a shock's entropy jump is of third order).
For small ``du`` it is the impedance condition ``p_b - p_e = rho_e c_e du``: the incoming
characteristic ``p - rho c u.n`` is held, and a plane wave at normal incidence leaves without
reflection (Thompson 1987, J. Comput. Phys. 68; Lysmer & Kuhlemeyer 1969's viscous boundary).  A
shock leaving through a face whose exterior state it was made from (the reflection of an incident
shock from a wall, running back out through the inflow face that feeds the incident state) leaves
exactly: ``p_b`` at ``u_b = 0`` is the reflected pressure.

On the staggered grid the exterior acts through the ghost zones of the face: their pressure is
``p_b`` at the face zone's mean normal velocity ``v^{n-1/2}`` (plus the correction of (2)), and the
face nodes' normal velocity gets the rest of the dashpot implicitly in the node constraint
(trapezoidal, unconditionally stable whatever ``rho c dt / dx``)::

    m (v^{n+1/2} - v*) . n = -dt_avg C_n (v^{n+1/2} - v^{n-1/2}) . n / 2,     C_n = sum_z Z_z a_zn

(``Z_z = dp_b/d(du)`` of each face zone at its lagged ``du``, ``a_zn`` the node's share of the
zone's face: a quarter in 3-D, a half in 2-D), so that the face pressure is (1) at the mean
velocity ``(v^{n-1/2} + v^{n+1/2})/2`` of the step, the velocity the compatible energy update works
with.  The reaction ``m (v^{n+1/2} - v*)`` and its work on that mean velocity are boundary terms of
the balances (as a wall's), the ghost zones' corner forces are booked by the solver as on every
open face, and so are the mass, momentum and energy the remap carries through the face.

Oblique waves (transverse terms)
--------------------------------
(1) alone reflects a plane wave arriving at incidence ``theta`` with ``R = (cos theta - 1)/(cos
theta + 1)``: -7 % at 30 degrees, -17 % at 45.  The second-order absorbing condition of Engquist &
Majda (1977, Math. Comp. 31), written as the incoming characteristic's transverse term (Thompson
1990; Lodato, Domingo & Vervisch 2008, J. Comput. Phys. 227), ``d/dt (p - rho c u.n) = -beta rho c^2
div_t u_t``, corrects it: the exterior pressure carries a correction ``delta`` per face zone with::

    d delta / dt = -beta rho_e c_e^2 div_t(u_t) - K (delta  or  p_b - p_target)            (2)

(``div_t`` the tangential divergence of the face nodes' velocity over the face zone).  A plane wave
then reflects with ``R = (beta s^2 - (1 - cos))/((1 + cos) - beta s^2)`` (``s = sin theta``);
``beta = 1/2`` (Engquist-Majda's Pade choice) gives -0.5 % at 30 degrees, -2.9 % at 45 and -11 % at
60; ``beta = 0.64`` (the default, chosen to minimise the largest reflection over 0-60 degrees as
Trefethen & Halpern 1986 choose their absorbing conditions' coefficients) at most 2.0 % over
0-60 degrees (+1.5 % at 30, +1.9 % at 45, -2.0 % at 60).

(2) is an acoustic condition; two guards keep it to that in a flow. Its tangential divergence is
clipped to the face zone's dilatation ``|div u|`` (an acoustic wave's is ``sin^2 theta`` of it, so
the clip leaves sound alone; a vortex crossing the face has a tangential divergence but no
dilatation). And the gas flowing through the face carries the correction out with it, at
``|u_n| / h`` (``h`` the zone's width normal to the face; nil at rest). A Mach 1.2 shock diffracted
by an obstacle in a 160 mm channel, the outflow face 107 mm behind it: its load against a channel
four times as long, RMS error over 2 ms 2.0 kPa of a 122 kPa peak with both (without them 4.9 kPa
and the face correction past 1e5 Pa; beta = 0: 2.8 kPa).

Relaxation (Poinsot & Lele 1992, J. Comput. Phys. 101; Rudy & Strikwerda 1980)
-----------------------------------------------------------------------------
``K = relax c_e (1 - M^2) / L`` (``L`` the grid's length normal to the face, ``M`` the exterior's
normal Mach number, clipped to 1): on a face with a given state the correction ``delta`` decays to
zero (the face returns to its given state after an oblique wave passed, and a steady flow with a
transverse divergence at the face cannot drift); on an outflow face with a ``pressure`` the face
pressure relaxes to it.  ``relax = 0`` keeps whatever the waves leave (perfectly non-reflecting, may
drift); larger values hold the target more firmly and reflect more of the slow (long) waves.  The
default is 0.25 (Poinsot & Lele's).  An ``"outflow"`` or ``"far_field"`` face without a given state
relaxes its correction to the state it started with; the exterior state itself is held, so a
plane wave's normal part always leaves.

Subsonic inflow: the tangential velocity
---------------------------------------
Where the exterior flows in (its normal Mach number above 1e-3), the vorticity characteristic is
incoming too and the face sets it: the face nodes hold the exterior's tangential velocity (a
constraint as the dashpot's, its reaction and work booked the same way), the flow direction of a
subsonic inflow (Poinsot & Lele's SI-1 sets u, v and T). So do the nodes of any open face that gas
flows in through at the moment (inward normal velocity above 1e-3 of the exterior's sound speed:
backflow through an outflow face, as a vortex crossing it draws in gas; OpenFOAM's inletOutlet
switches the same way), with the exterior's tangential velocity (an outflow face's: the state it
started with). (1) and (2) keep the acoustic part; (2) is
then idle there (no tangential divergence). Left free (zero-gradient), the tangential velocity was
underspecified, and with (2) it grew into a standing odd-even wave along the face: unstable in
about 1 ms at Mach 0.29 and beta = 0.64, 7 ms at Mach 0.08 (with beta = 0 neutral). At rest and
where gas leaves, the tangential velocity stays free and (2) works as above.

Remap donors
------------
Every characteristic face gives its ghost zones, for the remap, the exterior state the face's
motion makes (``rho* = rho_e W / (W - du)``, ``e* = e_e + (p* + p_e)/2 (1/rho_e - 1/rho*)``, the
jump conditions of (1)): gas entering carries the exterior's entropy, also gas flowing back in
through an outflow face.  (Zero-gradient donors there, the state next to the face, let a shock
leaving against the inflow reflect more: at Mach 3, 8 % of the jump against 2 %.)  Ghost node
velocities stay zero-gradient copies of the face nodes.

With several materials per zone (mixed.py) each face zone's exterior is one material: a given
state's (``material`` of the inflow or far-field table; default the material that fills most of the
face), or, for a face without one, the material that fills most of the face zone at the start (its
state there).  (1) and (2) use that material's equation of state, and the remap's donors are that
material alone (the gas that enters is the exterior's; what leaves is the face zone's own, the
upwind donor).  A face zone that holds only void at the start stays zero-gradient: no exterior,
no dashpot, no donors.

The face pressure is not let below the exterior's pressure cutoff (a Mie-Grueneisen material that
gives way in tension, ``pressure_cutoff``): the expansion branch of (1) pulls on the face zone as
if the exterior could; where the cutoff holds it the dashpot is off.  (Unbounded, the outflow faces
of a penetrator's target, aluminium at p = 0 with cutoff 0, pulled its corner edge apart: a zone
inverted at 5.7 us; bounded, penetrator_tate_fe runs its first 6 us with energy closing to 5.7e-12.)
A case with a void material keeps zero-gradient faces (solver.py), a measured choice: on the Tate
penetrators, whose targets are 6 rod radii wide, the far faces move the result by a few per cent
either way.  SPH rod (cases/penetrator_tate, 32 us): depth at Tate's time 17.15 mm (+0.6 %) and
penetration velocity 595.5 m/s (+3.7 %) with zero-gradient faces, 17.69 mm (+3.8 %) and 606.2 m/s
(+5.6 %, over the case's 5 %) with characteristic ones, 16.97 mm with rigid walls; FE rod
(cases/penetrator_tate_fe): 14.86 mm (-12.8 %), 546 m/s zero-gradient, 15.31 mm (-10.2 %), 556 m/s
characteristic (energy 5.7e-12 either way).  The characteristic outflow holds the exterior at its
given pressure (0 here), which lets the target flow out more freely than the zero-gradient face, and
the SPH rod then overshoots Tate's limit.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from solvers.ale import eos as _eos
from solvers.ale.grid import CUT, FACE_NAMES, PERIODIC, Block

DEFAULT_BETA = 0.64      # minimax reflection over 0-60 degrees (module docstring)
DEFAULT_RELAX = 0.25     # Poinsot & Lele 1992's sigma
INFLOW_MACH = 1e-3       # an exterior flowing in faster than this (normal Mach) makes a subsonic inflow


def fundamental_half(code: int, par: np.ndarray, rho: float, e: float) -> float:
    """A = G/2 with G = 1 + (rho/c)(dc/drho)_s by a central difference along the isentrope
    (de = p/rho^2 drho); 0.6 (an ideal diatomic gas) if the EOS gives no finite value."""
    p, c, ok = _eos.state(code, par, rho, e)
    if not ok:
        return 0.6
    h = 1e-4 * rho
    cs = []
    for s in (-1.0, 1.0):
        r = rho + s * h
        # second-order isentrope step: e(rho + dr) = e + p/rho^2 dr + d(p/rho^2)/drho dr^2 / 2 ~ mid-point
        pm, _, _ = _eos.state(code, par, rho + 0.5 * s * h, e + 0.5 * s * h * p / (rho * rho))
        em = e + s * h * pm / ((rho + 0.5 * s * h) ** 2)
        _, cc, okc = _eos.state(code, par, r, em)
        if not okc:
            return 0.6
        cs.append(cc)
    g = 1.0 + rho / c * (cs[1] - cs[0]) / (2.0 * h)
    return 0.5 * g if math.isfinite(g) and g > 0.0 else 0.6


@njit(cache=True, inline="always")
def wave_curve(du, rho_e, c_e, a):
    """(p_b - p_e, dp_b/d(du), W) of (1) at the normal velocity difference du."""
    r = math.sqrt(a * a * du * du + c_e * c_e)
    if not r > 0.0:  # void beyond the face (no sound speed): no pressure, no impedance
        return 0.0, 0.0, 0.0
    w = a * du + r
    dw = a + a * a * du / r
    return rho_e * w * du, rho_e * (w + du * dw), w


@njit(cache=True, inline="always")
def _pushed(v, nodes, so, d, u_ed):
    """du = (u_b - u_e) . n of a face zone: its face nodes' mean outward normal velocity u_b."""
    nf = nodes.shape[0]
    u = 0.0
    for a in range(nf):
        u += v[nodes[a], d]
    return so * (u / nf - u_ed)


@njit(cache=True)
def face_pressure(v, x_nodes, so, d_n, rho_e, u_e, p_e, c_e, a_e, delta, pmin, zt, pb):
    """Per face zone k: the face pressure pb[k] = p_e + (1)(du) + delta at its face nodes' velocity
    and the dashpot coefficient zt[k] = dp_b/d(du); not below the exterior's pressure cutoff pmin[k]
    (a material that gives way in tension pulls no harder: there the dashpot is off)."""
    for k in range(x_nodes.shape[0]):
        d = d_n[k]
        du = _pushed(v, x_nodes[k], so[k], d, u_e[k, d])
        dp, z, _ = wave_curve(du, rho_e[k], c_e[k], a_e[k])
        pb[k] = p_e[k] + dp + delta[k]
        zt[k] = z
        if pb[k] < pmin[k]:
            pb[k] = pmin[k]
            zt[k] = 0.0


@njit(cache=True)
def star_state(v, x_nodes, so, d_n, rho_e, u_e, p_e, e_e, c_e, a_e, delta, rho_d, e_d):
    """The exterior state behind the wave the face's motion sends out (jump conditions of (1)):
    rho* = rho_e W / (W - du), e* = e_e + (p* + p_e)/2 (1/rho_e - 1/rho*) (the remap donors)."""
    for k in range(x_nodes.shape[0]):
        d = d_n[k]
        du = _pushed(v, x_nodes[k], so[k], d, u_e[k, d])
        dp, _, w = wave_curve(du, rho_e[k], c_e[k], a_e[k])
        pe = p_e[k] + delta[k]
        if not w > 0.0:  # (void beyond the face)
            rho_d[k] = rho_e[k]
            e_d[k] = e_e[k]
            continue
        rho = rho_e[k] * w / max(w - du, 1e-12 * w)
        rho_d[k] = rho
        e_d[k] = e_e[k] + 0.5 * (pe + dp + pe) * (1.0 / rho_e[k] - 1.0 / rho)


@njit(cache=True)
def transverse_divergence(v, x_nodes, tan, htan, out):
    """div_t u_t of each face zone from its face nodes (2-D: nodes 0, 1 along the tangent; 3-D: the
    quad (a, b), (a+1, b), (a+1, b+1), (a, b+1) in the tangential axes tan[k, 0], tan[k, 1])."""
    nk, nf = x_nodes.shape
    for k in range(nk):
        n = x_nodes[k]
        if nf == 2:
            t = tan[k, 0]
            out[k] = (v[n[1], t] - v[n[0], t]) / htan[k, 0]
        else:
            t1 = tan[k, 0]
            t2 = tan[k, 1]
            out[k] = (((v[n[1], t1] + v[n[2], t1]) - (v[n[0], t1] + v[n[3], t1])) / (2.0 * htan[k, 0])
                      + ((v[n[2], t2] + v[n[3], t2]) - (v[n[0], t2] + v[n[1], t2])) / (2.0 * htan[k, 1]))


@njit(cache=True)
def damp(v, v_old, m, owned, nodes, d_n, cn, dt_avg, acc):
    """Implicit part of the dashpot on the face nodes' normal component (module docstring); the
    reaction m (v_new - v*) of owned nodes into acc[0:dim], its work on (v_old + v_new)/2 into acc[3]."""
    for t in range(nodes.shape[0]):
        n = nodes[t]
        d = d_n[t]
        if not m[n] > 0.0 or cn[t] == 0.0:
            continue
        vs = v[n, d]
        vn = v_old[n, d] + m[n] * (vs - v_old[n, d]) / (m[n] + 0.5 * dt_avg * cn[t])
        r = m[n] * (vn - vs)
        v[n, d] = vn
        if owned[n]:
            acc[d] += r
            acc[3] += r * 0.5 * (v_old[n, d] + vn)


@njit(cache=True)
def hold_tangential(v, v_old, m, owned, nodes, d_n, so, hold, ue, c_in, free, acc):
    """Subsonic inflow: the face nodes of an exterior flowing in (hold) and those gas enters through
    now (inward normal velocity above c_in) take the exterior's tangential velocity (module
    docstring) in their free components (free[t, k]: not a wall's normal); the reaction
    m (v_new - v*) of owned nodes into acc[0:dim], its work on (v_old + v_new)/2 into acc[3], as
    damp's."""
    dim = v.shape[1]
    for t in range(nodes.shape[0]):
        n = nodes[t]
        if not m[n] > 0.0 or not (hold[t] or -so[t] * v[n, d_n[t]] > c_in[t]):
            continue
        for k in range(dim):
            if k == d_n[t] or not free[t, k]:
                continue
            r = m[n] * (ue[t, k] - v[n, k])
            v[n, k] = ue[t, k]
            if owned[n]:
                acc[k] += r
                acc[3] += r * 0.5 * (v_old[n, k] + ue[t, k])


class CharacteristicFaces:
    """The characteristic faces of a block (see the module docstring): their face zones, exterior
    states, corrections, and the pressure, dashpot and donor passes the solver calls."""

    def __init__(self, solver, specs: dict):
        B: Block = solver.block
        self.s = solver
        dim = B.dim
        self.dim = dim
        zs, ns = B.zs, B.ns
        self.faces = []
        rows = []            # per face: (face index, ghost 1, ghost 2, zone inside, face nodes...)
        gz, gsrc = [], []    # ghost zones of the face planes and the face zone each takes its pressure from
        nodes, nd, nso, w_rows, w_cols, w_vals = [], [], [], [], [], []
        base = 0             # the first face zone of the face
        for f, ((d, s), spec) in enumerate(sorted(specs.items())):
            n = int(B.n3[d])
            g1, g2, zi, nplane = (1, 0, 2, 2) if s == 0 else (n + 2, n + 3, n + 1, n + 2)
            tans = [t for t in range(dim) if t != d]
            # face zones: the real ones, and one layer more along a tangential axis whose side is
            # an image (periodic, rank cut): every rank then computes the same numbers for the
            # zones around its edge nodes as the rank (or the image) that owns them
            lo = np.array([int(B.zreal[0][t]) for t in range(3)])
            hi = np.array([int(B.zreal[1][t]) for t in range(3)])
            for t in tans:
                lo[t] -= B.face[t, 0] in (PERIODIC, CUT)
                hi[t] += B.face[t, 1] in (PERIODIC, CUT)
            lo[d], hi[d] = 0, 1
            ijk = np.stack([a.ravel() for a in np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)],
                                                            indexing="ij")], axis=1)   # (face zones, 3), C order
            tz = ijk @ zs                             # the zone's flat index without its d part (ijk_d = 0)
            offs = [(0,), (1,)] if dim == 2 else [(0, 0), (1, 0), (1, 1), (0, 1)]
            tn = ijk @ ns + nplane * ns[d]
            corner = [tn + sum(o_t * ns[t] for o_t, t in zip(o, tans)) for o in offs]
            rows.append(np.column_stack([np.full(tz.size, f), tz + g1 * zs[d], tz + g2 * zs[d], tz + zi * zs[d]]
                                        + corner))
            shape = hi - lo

            def source(q):  # face zone (global row) of the clamped tangential position q (m, 3)
                c = np.clip(q, lo, hi - 1)
                c[:, d] = 0
                return base + np.ravel_multi_index((c - lo).T, shape)

            # ghost zones over the padded tangential extent (corners, cuts), both planes
            full = [np.arange(B.zdims[t]) if t in tans else np.array([0]) for t in range(3)]
            q = np.stack([a.ravel() for a in np.meshgrid(*full, indexing="ij")], axis=1)
            qz = q @ zs
            for pl in (g1, g2):
                gz.append(qz + pl * zs[d])
                gsrc.append(source(q))
            # face nodes and their dashpot weights: C_n = sum over the active ghost-plane-1 zones z
            # around the node of Z(z's face zone) * area / 2^(dim-1)
            fn = B.face_nodes(d, s)
            qn = np.stack(np.unravel_index(fn, B.ndims), axis=1)
            row0 = sum(a.size for a in nodes)
            nodes.append(fn)
            nd.append(np.full(fn.size, d))
            nso.append(np.full(fn.size, 1.0 if s == 1 else -1.0))
            area = float(np.prod([B.h[t] for t in tans]))
            for o in ([(0,), (-1,)] if dim == 2 else [(0, 0), (-1, 0), (0, -1), (-1, -1)]):
                z = qn.copy()
                z[:, d] = g1
                for o_t, t in zip(o, tans):
                    z[:, t] += o_t
                ok = np.all((z >= 0) & (z < np.array(B.zdims)), axis=1)
                ok[ok] = B.zact[z[ok] @ zs] > 0.0
                w_rows.append(row0 + np.flatnonzero(ok))
                w_cols.append(source(z[ok]))
                w_vals.append(np.full(int(ok.sum()), area / 2 ** (dim - 1)))
            self.faces.append({"d": d, "s": s, "spec": spec, "kind": spec["kind"], "L": float(B.cells[d] * B.h[d])})
            base += tz.size
        R = np.concatenate(rows).astype(np.int64)
        self.face_of = R[:, 0].copy()
        self.g2, self.zin = R[:, 2].copy(), R[:, 3].copy()
        self.x_nodes = np.ascontiguousarray(R[:, 4:])
        nk = R.shape[0]
        self.nk = nk
        fd = np.array([fc["d"] for fc in self.faces], np.int64)
        fs = np.array([fc["s"] for fc in self.faces], np.int64)
        self.d_n = fd[self.face_of]
        self.hn = np.array([B.h[d] for d in self.d_n], np.float64)
        self.so = np.where(fs[self.face_of] == 1, 1.0, -1.0)
        # the layer of nodes inside the face nodes (the face zones' other side)
        self.x_inner = self.x_nodes - (np.where(fs[self.face_of] == 1, 1, -1)
                                       * np.asarray(B.ns, np.int64)[self.d_n])[:, None]
        self.tan = np.zeros((nk, 2), np.int64)
        self.htan = np.ones((nk, 2))
        for f, fc in enumerate(self.faces):
            sel = self.face_of == f
            for a, t in enumerate(t for t in range(dim) if t != fc["d"]):
                self.tan[sel, a] = t
                self.htan[sel, a] = B.h[t]
        self.gz = np.ascontiguousarray(np.concatenate(gz), dtype=np.int64)
        self.gsrc = np.ascontiguousarray(np.concatenate(gsrc), dtype=np.int64)
        nodes, nd, nso = (np.concatenate(a) for a in (nodes, nd, nso))
        w_rows, w_cols, w_vals = (np.concatenate(a) for a in (w_rows, w_cols, w_vals))
        from scipy.sparse import csr_matrix

        self.nodes = nodes.astype(np.int64)
        self.nodes_d = nd.astype(np.int64)
        self.nodes_so = nso.astype(np.float64)
        self.fn = np.zeros(len(nodes))
        self.W = csr_matrix((w_vals, (w_rows, w_cols)), shape=(len(nodes), nk))
        self.cn = np.zeros(len(nodes))
        # state per face zone
        self.rho_e = np.zeros(nk)
        self.e_e = np.zeros(nk)
        self.u_e = np.zeros((nk, dim))
        self.p_e = np.zeros(nk)
        self.c_e = np.zeros(nk)
        self.a_e = np.zeros(nk)
        self.delta = np.zeros(nk)
        self.zt = np.zeros(nk)
        self.pb = np.zeros(nk)
        self.divt = np.zeros(nk)
        self.K = np.zeros(nk)
        self.beta = np.zeros(nk)
        self.target = np.full(nk, np.nan)      # outflow: the pressure the face relaxes to
        self.rho_d = np.zeros(nk)
        self.e_d = np.zeros(nk)
        # several materials: the exterior's material per face zone (-1: one material, or a void face
        # zone), and the face zones with an exterior (a void face zone has none: zero-gradient)
        self.mat = np.full(nk, -1.0)
        self.pmin = np.full(nk, -np.inf)   # the exterior's pressure cutoff (Mie-Grueneisen), -inf: none
        self.act = np.ones(nk)
        self._ready = False

    # ------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Exterior states from the case or the initial face zones (called once the initial state
        is in place)."""
        s = self.s
        mm = s.mm
        for f, fc in enumerate(self.faces):
            sel = np.flatnonzero(self.face_of == f)
            spec = fc["spec"]
            zin = self.zin[sel]
            if mm is not None:
                self.mat[sel] = self._exterior_materials(spec, zin)
                self.act[sel] = self.mat[sel] >= 0
            if spec.get("state") is not None:
                rho, u, p = spec["state"]
                code, par = self._eos_of(sel)
                name = s.material if mm is None else mm.names[int(self.mat[sel[0]])]
                e = float(_eos.energy_from_pressure(code[0], par[0], rho, p))
                p2, c, ok = _eos.state(code[0], par[0], rho, e)
                if not ok:
                    raise ValueError(f"{fc['kind']} state on {FACE_NAMES[2 * fc['d'] + fc['s']]} "
                                     f"(density {rho}, pressure {p}) is not a valid state of material "
                                     f"{name!r}")
                self.rho_e[sel], self.e_e[sel], self.p_e[sel], self.c_e[sel] = rho, e, p2, c
                self.u_e[sel] = np.asarray(u, np.float64)
            else:
                if mm is None:
                    self.rho_e[sel] = s.rho[zin]
                    self.e_e[sel] = s.e[zin]
                    self.p_e[sel] = s.p[zin]
                    self.c_e[sel] = s.c[zin]
                else:   # the exterior material's own state in the face zone (from its EOS: the face
                    # zones include images in the ghost layers, whose material states are not
                    # evaluated; void zones: inert values)
                    code, par = self._eos_of(sel)
                    k = self.mat[sel].astype(np.int64)
                    for i, z, kk, cd, pr in zip(sel, zin, k, code, par):
                        if kk < 0:
                            self.rho_e[i], self.e_e[i], self.p_e[i], self.c_e[i] = 1.0, 0.0, 0.0, 1.0
                            continue
                        r = mm.mass[z, kk] / mm.vol[z, kk]
                        e = mm.ener[z, kk] + mm.deh[z, kk]
                        p, c, _ = _eos.state(cd, pr, r, e)
                        self.rho_e[i], self.e_e[i], self.p_e[i], self.c_e[i] = r, e, p, c
                # the face nodes' mean velocity (the zone's is not stored)
                self.u_e[sel] = s.v[self.x_nodes[sel]].mean(axis=1)
            code, par = self._eos_of(sel)
            self.pmin[sel] = [pr[_eos.MG_PC] if cd == _eos.MIE_GRUNEISEN else -np.inf for cd, pr in zip(code, par)]
            self.a_e[sel] = [fundamental_half(cd, pr, r, e) for cd, pr, r, e in
                             zip(code, par, self.rho_e[sel], self.e_e[sel])]
        self._derive()

    def _derive(self) -> None:
        """Relaxation rates, transverse coefficients, targets and donor flags from the exterior
        states and the specs."""
        s = self.s
        for f, fc in enumerate(self.faces):
            sel = np.flatnonzero(self.face_of == f)
            spec = fc["spec"]
            mach = np.minimum(np.abs(self.u_e[sel, fc["d"]]) / self.c_e[sel], 1.0)
            relax = float(spec.get("relax", DEFAULT_RELAX))
            self.K[sel] = relax * self.c_e[sel] * (1.0 - mach ** 2) / fc["L"]
            self.beta[sel] = float(spec.get("beta", DEFAULT_BETA))
            if fc["kind"] == "outflow" and "pressure" in spec:
                self.target[sel] = float(spec["pressure"])
        # subsonic inflow (the exterior flows in, faster than 1e-3 of its sound speed): the face
        # nodes hold the exterior's tangential velocity (the mean over the node's face zones)
        # (over the face zones with an exterior: void ones have none)
        from scipy.sparse import diags

        Wa = self.W @ diags(self.act)
        wsum = np.asarray(Wa.sum(axis=1)).ravel()
        wn = np.where(wsum > 0.0, wsum, 1.0)
        self.node_ue = np.ascontiguousarray(np.asarray(Wa @ self.u_e) / wn[:, None])
        self.node_c_in = np.where(wsum > 0.0, INFLOW_MACH * np.asarray(Wa @ self.c_e).ravel() / wn, np.inf)
        u_in = -self.nodes_so * self.node_ue[np.arange(self.nodes.size), self.nodes_d]
        self.node_hold = (wsum > 0.0) & (u_in > self.node_c_in)
        # (a face node on a wall keeps the wall's normal component, one on an edge of two open faces
        # each face's normal component (its dashpot's): the reactions' work is booked at the final
        # velocity of each component, so each component has one constraint)
        bc = s.bc
        taken = np.zeros((s.v.shape[0], self.dim), bool)
        taken[bc.wall_nodes, bc.wall_comp] = True
        taken[self.nodes, self.nodes_d] = True
        self.node_free = np.ascontiguousarray(~taken[self.nodes])
        self.zone_in = (-self.so * self.u_e[np.arange(self.nk), self.d_n] > INFLOW_MACH * self.c_e) & (self.act > 0)
        self.inert = np.flatnonzero(self.act == 0)   # (void face zones: zero-gradient)
        on = self.act[self.gsrc] > 0                  # (the ghosts that take donors: _donor_ghosts)
        self._dgz, self._dsrc = self.gz[on], self.gsrc[on]
        self._ready = True

    # checkpoint: the per-face-zone state in a zone-shaped array, each face zone's row at its
    # outer ghost zone (unique per face; written and read like every padded array of the solver)
    STATE = ("rho_e", "e_e", "p_e", "c_e", "a_e", "delta", "zt", "pb", "mat", "act", "pmin")

    def state_array(self) -> np.ndarray:
        a = np.zeros((self.s.block.nzones, len(self.STATE) + self.dim + 1))
        if self._ready:
            for i, k in enumerate(self.STATE):
                a[self.g2, i] = getattr(self, k)
            a[self.g2, len(self.STATE): -1] = self.u_e
            a[self.g2, -1] = 1.0
        return a

    def set_state_array(self, a: np.ndarray) -> None:
        if not np.all(a[self.g2, -1] == 1.0):
            raise ValueError("the checkpoint holds no state of the open faces' exteriors")
        for i, k in enumerate(self.STATE):
            getattr(self, k)[:] = a[self.g2, i]
        self.u_e[:] = a[self.g2, len(self.STATE): -1]
        self._derive()
        self._dashpot()  # (the pressures p are restored already: the arrays come first)

    def _eos_of(self, sel):
        """EOS (code, parameters) of the face zones sel: the solver's, or with several materials
        their exterior material's (an ideal gas's for a void face zone: inert values, never used)."""
        s = self.s
        if s.mm is None:
            return [s.eos_code] * sel.size, [s.eos_par] * sel.size
        mm = s.mm
        k = self.mat[sel].astype(np.int64)
        gas = (int(_eos.IDEAL_GAS), np.ascontiguousarray(_eos.eos_params("ideal_gas", {"gamma": 1.4})[1]))
        return ([int(mm.code[i]) if i >= 0 else gas[0] for i in k],
                [np.ascontiguousarray(mm.par[i], np.float64) if i >= 0 else gas[1] for i in k])

    def _exterior_materials(self, spec, zin):
        """The exterior's material per face zone (several materials; see the module docstring): a
        given state's (``material``, or the one that fills most of the face), else the one that fills
        most of each face zone, -1 where only void does."""
        mm = self.s.mm
        vol = np.where(mm.code[None, :] != _eos.VOID, mm.vol[zin], 0.0)
        if spec.get("state") is not None:
            if spec.get("material") is not None:
                return np.full(zin.size, float(mm.names.index(spec["material"])))
            return np.full(zin.size, float(np.argmax(vol.sum(axis=0))))
        return np.where(vol.max(axis=1) > 0.0, np.argmax(vol, axis=1), -1).astype(np.float64)

    # ------------------------------------------------------------------------------------------
    def advance(self, dt: float) -> None:
        """Step (2) over dt (the step just taken) with the face velocities it ended with."""
        if dt <= 0.0 or not self._ready:
            return
        transverse_divergence(self.s.v, self.x_nodes, self.tan, self.htan, self.divt)
        # the acoustic part: an acoustic wave's tangential divergence is sin^2(theta) of its
        # dilatation, a vortex's has none (div u = 0): |div_t u_t| is clipped to the face zone's
        # |div u| (face and inner layer of nodes)
        v = self.s.v
        vn = v[self.x_nodes, self.d_n[:, None]]   # the face nodes' normal velocity, per face zone
        un_f = vn.mean(axis=1)
        un_i = v[self.x_inner, self.d_n[:, None]].mean(axis=1)
        dil = np.abs(self.divt + self.so * (un_f - un_i) / self.hn)
        np.clip(self.divt, -dil, dil, out=self.divt)
        rate = -self.beta * self.rho_e * self.c_e ** 2 * self.divt
        # (none where gas enters through a face node: the tangential velocity is held there)
        rate[self.zone_in | np.any(-self.so[:, None] * vn > INFLOW_MACH * self.c_e[:, None], axis=1)] = 0.0
        has_t = np.isfinite(self.target)
        resid = np.where(has_t, self.pb - np.where(has_t, self.target, 0.0), self.delta)
        # the gas flowing through the face carries the correction out at |u_n| / h (implicit)
        self.delta = (self.delta + dt * (rate - self.K * resid)) / (1.0 + dt * np.abs(un_f) / self.hn)
        self.delta[self.inert] = 0.0

    def ghost_pressure(self) -> None:
        """Face pressure (1) + delta into the ghost zones of the faces (both layers; corners and
        cut-side ghosts from the nearest face zone, the latter then by the halo exchange) and the
        dashpot coefficients of the face nodes."""
        s = self.s
        if not self._ready:
            self.start()
        face_pressure(s.v, self.x_nodes, self.so, self.d_n, self.rho_e, self.u_e, self.p_e, self.c_e, self.a_e,
                      self.delta, self.pmin, self.zt, self.pb)
        if self.inert.size:  # (void face zones: the zone's own pressure, no dashpot)
            self.pb[self.inert] = s.p[self.zin[self.inert]]
            self.zt[self.inert] = 0.0
        # the face node's dual cell reaches half a zone beyond the face, where the ghost zone's
        # centre lies: in the normal direction the ghost acts as the linear extrapolation through
        # the face pressure, 2 p_b - p_1 (p_1: the zone inside), so that the node sees the face's
        # pressure difference to p_1 over the half zone between them.  Its pressure is p_b (the
        # tangential forces on the face nodes come from the face pressure), the normal remainder
        # (p_b - p_1) a_zn is a nodal force (normal_force; booked as boundary work) and the dashpot
        # slope doubles.  (As the ghost pressure, 2 p_b - p_1 also doubled the tangential coupling of
        # the face nodes to the zones inside: unstable for waves at 60 degrees.)
        s.p[self.gz] = self.pb[self.gsrc]
        self._dashpot()
        s.q[self.gz] = 0.0

    def _dashpot(self) -> None:
        """The face nodes' normal force and dashpot coefficient from the face zones' p_b and Z."""
        self.fn = self.W @ (self.pb - self.s.p[self.zin])
        self.cn = 2.0 * (self.W @ self.zt)

    def add_normal_force(self, f) -> None:
        """The normal remainder of the ghost's extrapolated pressure (ghost_pressure) on the face
        nodes (pushing inward where p_b > p_1)."""
        f[self.nodes, self.nodes_d] -= self.nodes_so * self.fn

    def normal_force_terms(self, v, v_old, owned, dt_avg):
        """(impulse (dim,), work) of that force over the step on the owned face nodes, with the
        mean velocity (v_old + v)/2 of the compatible energy update."""
        fo = -self.nodes_so * self.fn * owned[self.nodes]
        imp = np.zeros(self.dim)
        np.add.at(imp, self.nodes_d, dt_avg * fo)
        vb = 0.5 * (v[self.nodes, self.nodes_d] + v_old[self.nodes, self.nodes_d])
        return imp, float(dt_avg * np.sum(fo * vb))

    def constrain(self, v, v_old, m, owned, dt_avg, acc) -> None:
        damp(v, v_old, m, owned, self.nodes, self.nodes_d, self.cn, dt_avg, acc)
        hold_tangential(v, v_old, m, owned, self.nodes, self.nodes_d, self.nodes_so, self.node_hold, self.node_ue,
                        self.node_c_in, self.node_free, acc)

    def donors(self) -> None:
        """The exterior state the face's current motion makes into the ghost zones' rho and e
        (remap donors; star_state)."""
        star_state(self.s.v, self.x_nodes, self.so, self.d_n, self.rho_e, self.u_e, self.p_e, self.e_e,
                   self.c_e, self.a_e, self.delta, self.rho_d, self.e_d)
        self.apply_donors()

    def apply_donors(self, energy_only: bool = False) -> None:
        s = self.s
        if s.mm is None:
            if not energy_only:
                s.rho[self.gz] = self.rho_d[self.gsrc]
            s.e[self.gz] = self.e_d[self.gsrc]
            return
        g, r = self._donor_ghosts()
        if not energy_only:
            s.rho[g] = self.rho_d[r]
        s.e[g] = self.e_d[r]
        k = self.mat[r].astype(np.int64)
        s.mm.ener[g, k] = self.e_d[r]

    def _donor_ghosts(self):
        """(ghost zones, their face zones) of the face zones with an exterior (several materials;
        set by _derive)."""
        return self._dgz, self._dsrc

    def apply_material_donors(self) -> None:
        """Several materials: the ghost zones of the face zones with an exterior hold that material
        alone at the donor state (after the materials' zero-gradient fill, mixed.fill)."""
        mm = self.s.mm
        g, r = self._donor_ghosts()
        k = self.mat[r].astype(np.int64)
        vz = mm.vol[g].sum(axis=1)
        for a in (mm.vol, mm.mass, mm.ener, mm.deh):
            a[g] = 0.0
        mm.vol[g, k] = vz
        mm.mass[g, k] = self.rho_d[r] * vz
        mm.ener[g, k] = self.e_d[r]
