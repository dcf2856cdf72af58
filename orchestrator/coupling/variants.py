"""The coupling variants of the embedded-mesh method, by name: the case's `[coupling]` table picks one
with `method = "<name>"` (a registry: a new variant is one class with `@register("<name>")`).

multiplier  the method (Puso, Kokko, Settgast & Liu 2015): the stabilised multiplier solve of
            `coupling.solve`; a damping term in time, it never cuts the explicit step.
penalty     a spring per cut zone on the accumulated relative interface displacement.
nitsche     the same spring with the Nitsche stiffness γ K / h.

Every variant gives the impulses of one step on the background nodes (-Δt B^bT λ) and on the
surface nodes (+Δt BfT λ) from the predictor velocities v* (the adapter contract's `correct`), with
λ per cut zone and the condition `tied` (all components) or `slip` (normal component only).
Its state between steps (warm start, gaps) lives in a `CouplingState`, keyed by zone id and
checkpointable as plain arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from orchestrator.coupling import solve as S

if TYPE_CHECKING:
    from orchestrator.coupling.operators import Operators

METHODS: dict[str, type["CouplingMethod"]] = {}


def register(name: str):
    """Class decorator: make a coupling method available as `method = name`."""

    def deco(cls):
        cls.NAME = name
        METHODS[name] = cls
        return cls

    return deco


def _error(key: str, value: Any, allowed: str) -> ValueError:
    """The case's one-line error (`coupling.<key> = <value>: <allowed>`), a ValueError.  Imported
    late: the case schema may import this module for the variants' SCHEMA fragments."""
    from orchestrator.case import CaseError

    return CaseError(f"coupling.{key}", value, allowed)


def method_class(name: Any) -> type["CouplingMethod"]:
    if not isinstance(name, str) or name not in METHODS:
        raise _error("method", name, "must be one of: " + ", ".join(repr(n) for n in sorted(METHODS)))
    return METHODS[name]


def make(cfg: Mapping[str, Any]) -> "CouplingMethod":
    """The variant a `[coupling]` table asks for, its keys checked (`method` defaults to the
    multiplier method)."""
    cfg = dict(cfg)
    cfg.setdefault("method", "multiplier")
    return method_class(cfg["method"])(cfg)


def schema() -> dict:
    """JSON-schema fragment of the whole `[coupling]` table: one `if method = name then SCHEMA`
    branch per registered variant (the case schema's per-variant style)."""
    return {
        "type": "object",
        "properties": {"method": {"type": "string", "enum": sorted(METHODS)}},
        "allOf": [{"if": {"properties": {"method": {"const": n}}, "required": ["method"]},
                   "then": {**METHODS[n].SCHEMA, "x-when": f"method = {n!r}"}} for n in sorted(METHODS)],
    }


def _number(**bounds) -> dict:
    return {"type": "number", **bounds}


COMMON = {"method": {"type": "string"}, "condition": {"type": "string", "enum": list(S.CONDITIONS)},
          "min_fill": _number(minimum=0, exclusiveMaximum=1)}

MIN_FILL = 0.1
"""A cut zone whose open volume is less than this share material (the rest void) gets no constraint:
nothing there pushes on the surface, and a node of (nearly) empty zones has (nearly) no mass, so the
constraint would throw it at any speed (a rod's rear in void: 1e5 m/s, a zone inverted). LS-DYNA's
*CONSTRAINED_LAGRANGE_IN_SOLID has the same switch (FRCMIN, default 0.5 there)."""


# ----------------------------------------------------------------------------------------------
@dataclass
class CouplingState:
    """What a variant carries from step to step, per cut zone id (sorted):

    zones (nz,) int64; lam (nz, k) the last multipliers (warm start; k = dim tied, 1 slip);
    gap (nz, k) the accumulated relative interface displacement g_e (penalty, nitsche)."""

    zones: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    lam: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    gap: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Plain numpy arrays for a checkpoint."""
        return {"zones": self.zones.copy(), "lam": self.lam.copy(), "gap": self.gap.copy()}

    def load_state(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore from `state_arrays()` output (e.g. read back from a checkpoint)."""
        zones = np.asarray(arrays["zones"], dtype=np.int64)
        lam = np.asarray(arrays["lam"], dtype=float)
        gap = np.asarray(arrays["gap"], dtype=float)
        n = zones.size
        if lam.shape[0] != n or gap.shape[0] != n or lam.ndim != 2 or gap.ndim != 2:
            raise ValueError(f"coupling state: zones ({n},), lam {lam.shape}, gap {gap.shape}: "
                             f"lam and gap need one row per zone")
        if n > 1 and not np.all(np.diff(zones) > 0):
            raise ValueError("coupling state: zone ids must be strictly increasing")
        self.zones, self.lam, self.gap = zones, lam, gap

    def on(self, zones: np.ndarray, values: np.ndarray) -> np.ndarray:
        """`values` (lam or gap) carried over to the sorted `zones`: rows of zones kept from the last
        step, zeros for zones new to the interface (zones that left it are forgotten)."""
        out = np.zeros((zones.size, values.shape[1]))
        if self.zones.size:
            pos = np.minimum(np.searchsorted(self.zones, zones), self.zones.size - 1)
            hit = self.zones[pos] == zones
            out[hit] = values[pos[hit]]
        return out


@dataclass(frozen=True)
class StepResult:
    impulse_b: np.ndarray  # (nb, dim) on ops.bnodes
    impulse_f: np.ndarray  # (ns, dim) on the surface nodes
    diagnostics: dict


class CouplingMethod:
    """A coupling variant configured by its `[coupling]` table."""

    NAME = ""
    SCHEMA: dict = {}
    DEFAULTS: dict = {"condition": "tied"}

    def __init__(self, cfg: Mapping[str, Any]):
        cfg = {"method": self.NAME, **cfg}
        self.check(cfg)
        self.cfg = {**self.DEFAULTS, "min_fill": MIN_FILL, **cfg}
        self.condition = self.cfg["condition"]
        self.min_fill = float(self.cfg["min_fill"])

    @classmethod
    def check(cls, cfg: Mapping[str, Any]) -> None:
        """Cross-field checks of a `[coupling]` table for this method: its keys, their values.
        Raises ValueError (one line: key, value, what is allowed)."""
        if cfg.get("method", cls.NAME) != cls.NAME:
            raise _error("method", cfg.get("method"), f"this is the {cls.NAME!r} variant")
        own = cls.SCHEMA["properties"]
        for key, value in cfg.items():
            if key not in own:
                users = sorted(n for n, c in METHODS.items() if key in c.SCHEMA["properties"])
                where = (f"only with method = {' or '.join(map(repr, users))}" if users
                         else "unknown key")
                raise _error(key, value, f"{where}; method {cls.NAME!r} takes "
                             + ", ".join(sorted(own)))
        cond = cfg.get("condition", "tied")
        if cond not in S.CONDITIONS:
            raise _error("condition", cond, "must be one of: " + ", ".join(map(repr, S.CONDITIONS)))
        for key in cls.SCHEMA.get("required", ()):
            if key not in cfg:
                from orchestrator.case import MISSING

                raise _error(key, MISSING, f"required with method = {cls.NAME!r}")
        if "min_fill" in cfg:
            v = cfg["min_fill"]
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 <= v < 1.0):
                raise _error("min_fill", v, "must be a number >= 0 and < 1 (the share of a cut zone's "
                             "open volume that must be material for a constraint there)")
        cls._check_values(cfg)

    @classmethod
    def _check_values(cls, cfg):
        pass

    @staticmethod
    def _positive(cfg, key, unit="", zero_ok=False):
        if key not in cfg:
            return
        v = cfg[key]
        ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
              and (v >= 0 if zero_ok else v > 0))
        if not ok:
            raise _error(key, v, f"must be a finite number {'>=' if zero_ok else '>'} 0{unit}")

    def new_state(self) -> CouplingState:
        return CouplingState()

    def stable_dt(self, ops: Operators, m_b, m_f, modulus: float | None = None) -> float:
        """This variant's own explicit step limit (the coupler takes the minimum with the solvers')."""
        raise NotImplementedError

    def step(self, ops: Operators, v_b, m_b, v_f, m_f, dt: float, state: CouplingState,
             modulus: float | None = None) -> StepResult:
        """Impulses of one step from the predictor velocities; updates `state`."""
        raise NotImplementedError

    def condition_number(self, ops: Operators, m_b, m_f, dt: float) -> float:
        """cond(H) of the variant's system for this step, where it solves one (nan otherwise)."""
        return math.nan


# ----------------------------------------------------------------------------------------------
@register("multiplier")
class Multiplier(CouplingMethod):
    """The stabilised multiplier method (`coupling.solve`).  No step limit of its own: the
    constraint enters the equations of motion as the damping term C = B^T C̄ B (the talk's
    `M a_n + C v_{n+1/2} + K d_n = 0`), and the central-difference recursion is bounded when
    A = M + Δt/2 C - Δt²/4 K > 0 (slide "Stability in Time"); C >= 0 only adds to A, so Δt <= 2/ω_c
    of the uncoupled solvers stays the limit."""

    SCHEMA = {
        "type": "object",
        "properties": {**COMMON, "alpha": _number(exclusiveMinimum=0), "beta": _number(minimum=0),
                       # multi-rate's passes (orchestrator/coupling/multirate.py): a pass is accepted
                       # when the solve after it would move the substeps' mean velocity by at most this
                       # share of its scale; at most this many passes
                       "substep_tolerance": _number(exclusiveMinimum=0, maximum=0.1),
                       "substep_passes": {"type": "integer", "minimum": 2, "maximum": 100}},
        "required": ["method"],
        "additionalProperties": False,
    }
    DEFAULTS = {"condition": "tied", "alpha": S.ALPHA, "beta": S.BETA}

    @classmethod
    def _check_values(cls, cfg):
        cls._positive(cfg, "alpha")
        cls._positive(cfg, "beta", zero_ok=True)

    def stable_dt(self, ops, m_b, m_f, modulus=None) -> float:
        return math.inf

    def _stabilisation(self, stab_scale: float) -> tuple[float, float]:
        """(alpha, beta) of a step whose stabilisation keeps the size it has at ``stab_scale`` times
        the step: C̄^-1 ~ s_e ~ Δt, so alpha / scale, beta x scale (multi-rate: the substeps' step,
        orchestrator/coupling/multirate.py)."""
        return float(self.cfg["alpha"]) / stab_scale, float(self.cfg["beta"]) * stab_scale

    def condition_number(self, ops, m_b, m_f, dt, stab_scale: float = 1.0) -> float:
        """λ_max/λ_min of the assembled H (S.assemble: the same system the matrix-free solve applies)."""
        if ops.n_zones == 0:
            return 1.0
        alpha, beta = self._stabilisation(stab_scale)
        sysm = S.assemble(ops, m_b, m_f, dt, self.condition, alpha=alpha, beta=beta)
        return S.condition_number(sysm.H)

    def step(self, ops, v_b, m_b, v_f, m_f, dt, state, modulus=None, stab_scale: float = 1.0) -> StepResult:
        # (matrix_free: the same solve as S.solve in one numba kernel -- the step's hot path; imported
        # here: validating a case imports this module and no numba)
        from orchestrator.coupling import matrix_free

        alpha, beta = self._stabilisation(stab_scale)
        sol = matrix_free.solve(ops, m_b, m_f, v_b, v_f, dt, self.condition, alpha=alpha, beta=beta,
                                warm=(state.zones, state.lam))
        lam = sol.lam.reshape(ops.n_zones, -1)
        # (consistent by construction: set directly, load_state's checks are for arrays read back)
        state.zones, state.lam, state.gap = ops.zones, lam, np.zeros((ops.n_zones, lam.shape[1]))
        return StepResult(sol.impulse_b, sol.impulse_f,
                          {"iterations": sol.iterations, "residual": sol.residual,
                           "interface_dissipation": sol.dissipation})


# ----------------------------------------------------------------------------------------------
class _Spring(CouplingMethod):
    """A spring per cut zone on the accumulated relative interface displacement

        g_e^{n+1} = g_e^n + Δt (B^b v_b^{n+1/2} - Bf v_f^{n+1/2})_e / A_e        (m; slip: · n_e)

    (the zone mean of u^b - u^f on Γ_e), kept in the state by zone id: a zone that stays cut keeps
    its gap, a zone new to the interface starts at 0, a zone the surface left forgets its gap (and
    the spring energy k A_e g_e²/2 in it -- small when k is large enough for the gaps to be small).
    The multiplier is the spring's traction, λ_e = k_e g_e (Pa; force k_e A_e g_e on the zone),
    explicit: computed from g^n, applied as the impulses -Δt B^bT λ, +Δt BfT λ, then the gap advances
    with the corrected velocities (central differences: d^{n+1} = d^n + Δt v^{n+1/2}).

    Step limit.  The zone's energy k_e A_e g_e²/2 = (k_e/A_e)(b_e·u)²/2 with b_e = [B^b_e, -Bf_e]
    is a rank-one stiffness K_e = (k_e/A_e) b_e b_e^T.  Split each node's mass between the zones in
    proportion to its weight, M_e,A = m_A B_eA / S_A with S_A = Σ_e' B_e'A: then Σ_e M_e = M and the
    element bound λ_max(K, M) <= max_e λ_max(K_e, M_e) holds (Irons), with
    λ_max(K_e, M_e) = b_e^T M_e^-1 b_e, so

        ω² <= max_e (k_e / A_e) Σ_A B_eA S_A / m_A      (both meshes),   Δt <= 2/ω.

    For an isolated zone (S_A = B_eA) this is ω² = k_e Σ_A B_eA²/(A_e m_A), two masses M_1, M_2 on
    a spring k A: ω² = k A (1/M_1 + 1/M_2) exactly.  Slip: the same bound (the stiffness acts
    along n_e only).  The coupler adds this limit to the solvers' own (it is the interface springs'
    alone; a stiff penalty spring is what cuts the step)."""

    def stiffness(self, ops: Operators, modulus: float | None) -> np.ndarray:
        """k_e per zone of ops (Pa/m)."""
        raise NotImplementedError

    def stable_dt(self, ops, m_b, m_f, modulus=None) -> float:
        mat = S.material_operators(ops, m_b, m_f)
        if mat.rows.size == 0:
            return math.inf
        k = self.stiffness(ops, modulus)[mat.rows]
        s_b = np.asarray(mat.Bb.sum(axis=0)).ravel()  # S_A: column sums
        s_f = np.asarray(mat.Bf.sum(axis=0)).ravel()
        per_zone = mat.Bb @ (s_b * mat.inv_mb) + mat.Bf @ (s_f * mat.inv_mf)  # Σ_A B_eA S_A / m_A
        omega2 = float(np.max(k / ops.area[mat.rows] * per_zone))
        return 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf

    def step(self, ops, v_b, m_b, v_f, m_f, dt, state, modulus=None) -> StepResult:
        dim = ops.dim
        v_b = np.asarray(v_b, dtype=float).reshape(-1, dim)
        v_f = np.asarray(v_f, dtype=float).reshape(-1, dim)
        mat = S.material_operators(ops, m_b, m_f)
        slip = self.condition == "slip"
        ncomp = 1 if slip else dim
        gap_all = state.on(ops.zones, state.gap) if state.gap.shape[1] == ncomp else np.zeros((ops.n_zones, ncomp))
        rows = mat.rows
        normal = ops.normal[rows]
        area = ops.area[rows]
        k = self.stiffness(ops, modulus)[rows]
        gap = gap_all[rows]

        lam = k[:, None] * gap  # traction per zone (scalar normal component for slip)
        vec = lam * normal if slip else lam
        impulse_b = -dt * np.asarray(mat.Bb.T @ vec)
        impulse_f = dt * np.asarray(mat.Bf.T @ vec)

        # advance the gaps with the corrected velocities v^{n+1/2} = v* + M^-1 impulse
        rel = S.relative_velocity(mat, v_b + mat.inv_mb[:, None] * impulse_b,
                                  v_f + mat.inv_mf[:, None] * impulse_f)
        if slip:
            rel = (rel * normal).sum(axis=1, keepdims=True)
        gap_new = gap + dt * rel / area[:, None]
        full_gap = np.zeros((ops.n_zones, ncomp))
        full_gap[rows] = gap_new
        full_lam = np.zeros((ops.n_zones, ncomp))
        full_lam[rows] = lam
        state.load_state({"zones": ops.zones, "lam": full_lam, "gap": full_gap})
        energy = 0.5 * float((k * area * (gap_new**2).sum(axis=1)).sum())
        return StepResult(impulse_b, impulse_f, {"interface_energy": energy})


@register("penalty")
class Penalty(_Spring):
    """Penalty coupling: k_e = `stiffness` (Pa/m: traction per metre of relative displacement),
    the same in every zone."""

    SCHEMA = {
        "type": "object",
        "properties": {**COMMON, "stiffness": _number(exclusiveMinimum=0, **{"x-unit": "Pa/m"})},
        "required": ["method", "stiffness"],
        "additionalProperties": False,
    }

    @classmethod
    def _check_values(cls, cfg):
        cls._positive(cfg, "stiffness", " (Pa/m)")

    def stiffness(self, ops, modulus):
        return np.full(ops.n_zones, float(self.cfg["stiffness"]))


@register("nitsche")
class Nitsche(_Spring):
    """Nitsche coupling, as implemented here: its stabilisation (penalty) part, k_e = γ K / h with
    K the bulk/elastic modulus the coupler passes (`modulus`, Pa) and h the zone width
    (V_zone^{1/d}) -- the mesh-dependent stiffness that makes the penalty consistent as h -> 0.
    The consistency (flux) part of Nitsche's method, the traction σ·n of the adjoining material
    on the interface, is the fluid pressure load the coupler already transfers to the foreground
    for every method; it is not added again here."""

    SCHEMA = {
        "type": "object",
        "properties": {**COMMON, "gamma": _number(exclusiveMinimum=0)},
        "required": ["method"],
        "additionalProperties": False,
    }
    DEFAULTS = {"condition": "tied", "gamma": 1.0}
    """γ = 1: for a full cut between materials of similar density ρ and wave speed c = sqrt(K/ρ),
    the step limit below is then ω ~ c/h, Δt ~ 2h/c -- the solvers' own CFL scale; a larger γ
    enforces the tie more tightly (gap ~ traction h / (γ K)) at a proportionally smaller Δt²."""

    @classmethod
    def _check_values(cls, cfg):
        cls._positive(cfg, "gamma")

    def stiffness(self, ops, modulus):
        if modulus is None or not (modulus > 0.0 and math.isfinite(modulus)):
            raise ValueError(f"nitsche coupling needs the modulus K > 0 (Pa) of the coupled material, "
                             f"got {modulus!r}")
        return np.full(ops.n_zones, float(self.cfg["gamma"]) * float(modulus) / ops.width)
