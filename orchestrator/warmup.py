"""Compile (or load) every numba kernel specialisation of the solvers once, at install time.

The solver kernels are `njit(cache=True)`: the first process that calls one compiles it (seconds per
kernel, ~10-25 s for a whole solver) and stores the machine code in the cache directory of this
source tree (solvers/kernel_cache.py: .numba-cache/<digest of every kernel source>); every later
process, every MPI rank included, loads it in milliseconds.  Numba keys each entry on its source
file's stamp, the argument types and the CPU, and the directory on the content of all kernel
sources, so the ranks of `immerse run` find what this module compiled as long as they import the
same source tree (the editable install of `make venv`) on the same machine, and a changed kernel
never leaves a caller running its old machine code.

`python -m orchestrator.warmup` (run by the Makefile after installing, and again whenever a solver
source changes) steps tiny cases through the solver classes (no MPI job; in two processes where
there are two cores, PARTS): 2-D
and 3-D, every material model and EOS, one and several materials per zone and void, obstacles and
moving blocked fractions, inflow/outflow/periodic/piston faces, both artificial viscosity kinds,
both ALE modes, energy sources, and writes their output and diagnostics.

`python -m orchestrator.warmup --check CASE_DIR ...` steps the given cases the same way and prints,
as JSON, the kernels that had to be compiled instead of loaded ({} after a complete warm-up).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STEPS = 3  # enough for the first-step, later-step and both sweep-order paths

# ----------------------------------------------------------------------------------------------
# the cases (case.toml text, validated by orchestrator.case like any user's case)
_RUN2 = "[run]\ndimension = 2\nend_time = 1.0\n"
_RUN3 = "[run]\ndimension = 3\nend_time = 1.0\n"
_EOS = {
    "ideal_gas": '{ eos = "ideal_gas", gamma = 1.4 }',
    "stiffened_gas": '{ eos = "stiffened_gas", gamma = 4.4, p_inf = 6.0e8 }',
    "tait": '{ eos = "tait", density = 1000.0, bulk_modulus = 2.19e9, exponent = 7.15, p0 = 1.0e5 }',
    "jwl": '{ eos = "jwl", A = 3.712e11, B = 3.231e9, R1 = 4.15, R2 = 0.95, omega = 0.3, density = 1630.0 }',
    "mie_gruneisen": '{ eos = "mie_gruneisen", density = 2700.0, c0 = 5350.0, s = 1.34, gamma0 = 2.0 }',
}
# a state each EOS accepts (density, pressure)
_STATE = {"ideal_gas": (1.0, 1.0), "stiffened_gas": (1000.0, 1.0e9), "tait": (1000.0, 1.0e5),
          "jwl": (1630.0, 1.0e9), "mie_gruneisen": (2800.0, 1.0e9)}


def _grid(dim: int) -> str:
    if dim == 2:
        return "grid = { lower = [0.0, 0.0], upper = [1.0, 0.5], cells = [6, 3] }\n"
    return "grid = { lower = [0.0, 0.0, 0.0], upper = [1.0, 0.5, 0.5], cells = [4, 3, 3] }\n"


def _single(dim: int, eos: str, mode: str, q: str, boundaries: str = "", extra: str = "") -> str:
    rho, p = _STATE[eos]
    vel = ", ".join(["1.0"] + ["0.0"] * (dim - 1))
    return ((_RUN2 if dim == 2 else _RUN3) + "[ale]\n"
            f'mode = "{mode}"\n' + _grid(dim) + boundaries
            + f'viscosity = {{ kind = "{q}" }}\n'
            + f"materials.m = {_EOS[eos]}\n"
            + f'regions = [ {{ material = "m", density = {rho}, pressure = {p} }},\n'
            + f'  {{ material = "m", region = "x > 0.5", density = {0.5 * rho}, pressure = {0.9 * p},'
            + f" velocity = [{vel}] }} ]\n" + extra)


def _mixed(dim: int, eos: tuple[str, ...], q: str, void: bool = False, boundaries: str = "", extra: str = "") -> str:
    mats = "".join(f"materials.m{i} = {_EOS[e]}\n" for i, e in enumerate(eos))
    regions = [f'{{ material = "m0", density = {_STATE[eos[0]][0]}, pressure = {_STATE[eos[0]][1]} }}']
    cuts = ["x > 0.45", "y > 0.3"]
    for i, e in enumerate(eos[1:], start=1):
        regions.append(f'{{ material = "m{i}", region = "{cuts[i - 1]}", density = {_STATE[e][0]}, '
                       f"pressure = {_STATE[e][1]} }}")
    if void:
        mats += 'materials.vacuum = { eos = "void" }\n'
        regions.append('{ material = "vacuum", region = "x > 0.6 and x < 0.8" }')
    return ((_RUN2 if dim == 2 else _RUN3) + '[ale]\nmode = "eulerian"\n' + _grid(dim) + boundaries
            + f'viscosity = {{ kind = "{q}" }}\nfraction_samples = 3\n' + extra + mats
            + "regions = [\n  " + ",\n  ".join(regions) + " ]\n")


WALL = '"wall"'


def _faces(dim: int, **kinds) -> str:
    names = [f"{a}_{s}" for a in "xyz"[:dim] for s in ("lower", "upper")]
    items = ", ".join(f"{n} = {kinds.get(n, WALL)}" for n in names)
    return f"boundaries = {{ {items} }}\n"


def _inflow(dim: int) -> str:
    vel = ", ".join(["0.5"] + ["0.0"] * (dim - 1))
    return f"{{ inflow = {{ density = 1.0, velocity = [{vel}], pressure = 1.0 }} }}"


_MAT = {
    "linear_elastic": 'model = "linear_elastic"\ndensity = 7850.0\nyoungs_modulus = 210e9\npoisson_ratio = 0.3\n',
    "neo_hookean": 'model = "neo_hookean"\ndensity = 1100.0\nyoungs_modulus = 5e6\npoisson_ratio = 0.45\n',
    "johnson_cook": ('model = "johnson_cook"\ndensity = 7830.0\nyoungs_modulus = 206.9e9\n'
                     "poisson_ratio = 0.3\nyield_stress = 806.0e6\nhardening_modulus = 614.0e6\n"
                     "hardening_exponent = 0.168\nstrain_rate_coefficient = 0.0089\n"
                     "reference_strain_rate = 1.0\nthermal_exponent = 1.1\nmelt_temperature = 1813.15\n"
                     "room_temperature = 293.15\nspecific_heat = 460.0\ntaylor_quinney = 0.9\n"),
}


def _lagrange(dim: int, mesh: str, hourglass: str = "viscous") -> str:
    """Every material model in one run (one body each) and every boundary kind; the bodies'
    hourglass_control (the assumed-strain stiffness adds its reference kernel)."""
    run = (_RUN2 if dim == 2 else _RUN3).replace("end_time = 1.0", "end_time = 1.0e-3")
    text = run + "".join(f"[materials.{m}]\n{body}" for m, body in _MAT.items())
    vel = ", ".join(["0.0"] * (dim - 1) + ["-200.0"])
    for i, m in enumerate(_MAT):
        lo = [0.0] * dim
        lo[0] = 0.01 * i
        hi = [0.01 * i + 0.008] + [0.004] * (dim - 1)
        hi[-1] = 0.02
        if mesh == "quarter_cylinder" and dim == 3 and m == "johnson_cook":
            shape = "{ quarter_cylinder = { radius = 0.004, length = 0.02, radial_cells = 2, axial_cells = 4 } }"
        else:
            cells = [2] * (dim - 1) + [4]
            shape = f"{{ box = {{ lower = {lo}, upper = {hi}, cells = {cells} }} }}"
        text += (f'[[lagrange.bodies]]\nname = "b{i}"\nmaterial = "{m}"\nmesh = {shape}\n'
                 f'initial_velocity = [{vel}]\nhourglass_control = "{hourglass}"\n')
    up = "xyz"[dim - 1]
    normal = [0.0] * dim
    normal[-1] = 1.0
    text += ('[[boundaries]]\ntype = "symmetry"\naxis = "x"\nat = 0.0\n'
             f'[[boundaries]]\ntype = "velocity"\nregion = "{up} > 0.02 - 1e-9 and x > 0.015"\n'
             f"velocity = {{ {up} = -10.0 }}\n"
             f'[[boundaries]]\ntype = "fixed"\nregion = "{up} > 0.02 - 1e-9 and x > 0.025"\n'
             f'[[boundaries]]\ntype = "rigid_wall"\npoint = {[0.0] * dim}\nnormal = {normal}\n')
    return text


def _subcycled(dim: int) -> str:
    """The explicit solver with element subcycling (its node, wall and step kernels)."""
    text = _lagrange(dim, "box", "assumed_strain")
    first = text.index("[[lagrange.bodies]]")
    return text[:first] + "[lagrange]\nsubcycling = 4\n" + text[first:]


def cases() -> dict[str, str]:
    """name -> case.toml text of every warm-up case."""
    out: dict[str, str] = {}
    for dim in (2, 3):
        out[f"lagrange_{dim}d"] = _lagrange(dim, "box")
        out[f"lagrange_{dim}d_assumed_strain"] = _lagrange(dim, "box", "assumed_strain")
        for eos in _EOS:
            out[f"ale_{dim}d_{eos}_eulerian"] = _single(dim, eos, "eulerian", "scalar")
        for q in ("scalar", "monotonic"):
            out[f"ale_{dim}d_{q}_open"] = _single(
                dim, "ideal_gas", "eulerian", q, _faces(dim, x_lower='"outflow"', x_upper='"outflow"'),
                extra="energy_sources = [ { energy = 0.1, at = %s } ]\n" % ([0.0] * dim))
            out[f"ale_{dim}d_{q}_periodic"] = _single(
                dim, "ideal_gas", "eulerian", q, _faces(dim, **{f"{a}_{s}": '"periodic"' for a in "xyz"[:dim]
                                                              for s in ("lower", "upper")}))
            out[f"ale_{dim}d_{q}_inflow_obstacle"] = _single(
                dim, "ideal_gas", "eulerian", q, _faces(dim, x_lower=_inflow(dim), x_upper='"outflow"'),
                extra='obstacles = [ { region = "x > 0.5 and x < 0.7 and y < 0.3", subsamples = 2 } ]\n')
            out[f"ale_{dim}d_{q}_obstacle_walls"] = _single(
                dim, "stiffened_gas", "eulerian", q,
                extra='obstacles = [ { region = "x > 0.75" } ]\n')
            for eos in ("ideal_gas", "tait"):
                out[f"ale_{dim}d_{q}_{eos}_lagrangian_piston"] = _single(
                    dim, eos, "lagrangian", q, _faces(dim, x_lower="{ piston = { velocity = 5.0 } }"))
            out[f"ale_{dim}d_{q}_lagrangian_walls"] = _single(dim, "stiffened_gas", "lagrangian", q)
            out[f"ale_{dim}d_{q}_mixed2"] = _mixed(dim, ("stiffened_gas", "ideal_gas"), q)
            out[f"ale_{dim}d_{q}_mixed3_void"] = _mixed(dim, ("ideal_gas", "jwl", "tait"), q, void=True,
                                                         boundaries=_faces(dim, x_upper='"outflow"'))
            out[f"ale_{dim}d_{q}_mixed2_obstacle"] = _mixed(
                dim, ("stiffened_gas", "ideal_gas"), q, extra='obstacles = [ { region = "x > 0.75", subsamples = 2 } ]\n')
            out[f"ale_{dim}d_{q}_mixed2_periodic"] = _mixed(
                dim, ("ideal_gas", "ideal_gas"), q,
                boundaries=_faces(dim, **{f"{a}_{s}": '"periodic"' for a in "xyz"[:dim] for s in ("lower", "upper")}))
    out["lagrange_3d_quarter_cylinder"] = _lagrange(3, "quarter_cylinder")
    for dim in (2, 3):   # element subcycling (solvers/lagrange/subcycling.py)
        out[f"lagrange_{dim}d_subcycled"] = _subcycled(dim)
    for dim in (2, 3):   # the implicit step's element kernel (midpoint_svk_kernel.py)
        out[f"lagrange_{dim}d_midpoint"] = _midpoint(dim)
    out["lagrange_2d_contact"] = _contact()
    out["lagrange_3d_contact"] = _contact(3)
    for dim, model in ((2, "taitwater"), (3, "idealgas")):  # the SPH group (LAMMPS)
        out[f"sph_{dim}d_{model}"] = _sph(dim, model)
    for dim in (2, 3):  # the embedded-mesh coupling: a body moving through the grid
        out[f"coupled_{dim}d"] = _coupled(dim)
        out[f"coupled_{dim}d_mixed"] = _coupled(dim, mixed=True)
        out[f"coupled_{dim}d_still"] = _coupled(dim, still=True)  # (a body at rest: blocked.py's held path)
    return out


def _midpoint(dim: int) -> str:
    """A spinning elastic block by the implicit midpoint scheme."""
    run = _RUN2 if dim == 2 else _RUN3
    vel = '["-50.0 * y", "50.0 * x"' + (', "0.0"]' if dim == 3 else "]")
    box = f"{{ lower = {[-0.05] * dim}, upper = {[0.05] * dim}, cells = {[2] * dim} }}"
    return (run + '[materials.m]\nmodel = "linear_elastic"\ndensity = 1000.0\nyoungs_modulus = 1.0e6\n'
            'poisson_ratio = 0.3\n[lagrange]\nintegrator = "midpoint"\ntime_step = 1.0e-3\n'
            f'[[lagrange.bodies]]\nname = "block"\nmaterial = "m"\nmesh = {{ box = {box} }}\n'
            f"initial_velocity = {vel}\n")


def _contact(dim: int = 2) -> str:
    """Two touching blocks, one moving into the other across it ([contact]; in 2-D with friction: the
    segment mortar and friction kernels; in 3-D frictionless: the facet mortar kernels)."""
    run = _RUN2 if dim == 2 else _RUN3
    text = run.replace("end_time = 1.0", "end_time = 1.0e-3") + f"[materials.linear_elastic]\n{_MAT['linear_elastic']}"
    extra = ", 0.0" * (dim - 2)
    for name, lo, hi, v in (("a", 0.0, 0.01, "50.0, 20.0"), ("b", 0.01, 0.02, "0.0, 0.0")):
        text += (f'[[lagrange.bodies]]\nname = "{name}"\nmaterial = "linear_elastic"\n'
                 f"mesh = {{ box = {{ lower = [{lo}, 0.0{extra}], upper = [{hi}, 0.004{', 0.004' * (dim - 2)}], "
                 f"cells = [2, 2{', 2' * (dim - 2)}] }} }}\n"
                 f"initial_velocity = [{v}{extra}]\n")
    return text + '[contact]\npairs = [["a", "b"]]\n' + ("friction = 0.2\n" if dim == 2 else "")


def _sph(dim: int, model: str) -> str:
    """A small block of particles (taitwater under gravity on fixed particles, or an ideal gas)."""
    z = [0.0] * dim
    lo, hi = [-0.1] * dim, [0.5] * dim
    mat = ('{ model = "tait", density = 1000.0, sound_speed = 20.0, viscosity = 0.3 }' if model == "taitwater"
           else '{ model = "ideal_gas", viscosity = 0.5 }')
    state = "" if model == "taitwater" else ", pressure = 1.0"
    floor = (f'  {{ material = "m", region = {{ box = {{ lower = {[-0.1] * dim}, upper = {[0.4] + [0.0] * (dim - 1)} }} }}, '
             'density = 1000.0, fixed = true },\n') if model == "taitwater" else ""
    gravity = f"gravity = {[0.0, -9.81] + [0.0] * (dim - 2)}\n" if model == "taitwater" else ""
    return ((_RUN2 if dim == 2 else _RUN3) + "[sph]\nspacing = 0.05\nsmoothing_length = 0.15\n"
            f"domain = {{ lower = {lo}, upper = {hi} }}\n" + gravity + f"materials.m = {mat}\n"
            f'bodies = [\n  {{ material = "m", region = {{ box = {{ lower = {z}, upper = {[0.2] * dim} }} }}, '
            f'density = {1000.0 if model == "taitwater" else 1.0}{state} }},\n' + floor + "]\n")


def _coupled(dim: int, mixed: bool = False, still: bool = False) -> str:
    """A small elastic block moving through gas at rest, tied by the multipliers (mixed: two gases,
    their interface through the block and the zones it cuts; still: the block at rest in a gas flow,
    so that its cut zones take the unsplit fluxes and held nodes of solvers/ale/blocked.py)."""
    if dim == 2:
        grid = "grid = { lower = [0.0, 0.0], upper = [1.0, 0.5], cells = [8, 4] }\n"
        box = "{ lower = [0.3, 0.1], upper = [0.55, 0.35], cells = [2, 2] }"
        vel = "[2.0, 0.5]"
    else:
        grid = "grid = { lower = [0.0, 0.0, 0.0], upper = [1.0, 0.5, 0.5], cells = [8, 4, 4] }\n"
        box = "{ lower = [0.3, 0.1, 0.1], upper = [0.55, 0.35, 0.35], cells = [2, 2, 2] }"
        vel = "[2.0, 0.5, 0.2]"
    gas = "density = 1.0, pressure = 1.0"
    if still:  # (the gas flows past the block, which stays at rest: its cut zones' fluxes and nodes)
        gas += ", velocity = [" + ", ".join(["0.5"] + ["0.2"] * (dim - 1)) + "]"
        vel = "[" + ", ".join(["0.0"] * dim) + "]"
    return ((_RUN2 if dim == 2 else _RUN3) + '[ale]\nmode = "eulerian"\n' + grid
            + "materials.gas = " + _EOS["ideal_gas"] + "\n"
            + ('materials.gas2 = { eos = "ideal_gas", gamma = 1.67 }\n'
               'regions = [ { material = "gas", density = 1.0, pressure = 1.0 },\n'
               '  { material = "gas2", region = "y > 0.2", density = 0.5, pressure = 1.0 } ]\n' if mixed else
               f'regions = [ {{ material = "gas", {gas} }} ]\n')
            + '[materials.solid]\nmodel = "linear_elastic"\ndensity = 2.0\nyoungs_modulus = 50.0\n'
            + "poisson_ratio = 0.3\n"
            + f'[[lagrange.bodies]]\nname = "block"\nmaterial = "solid"\nmesh = {{ box = {box} }}\n'
            + f"initial_velocity = {vel}\n"
            + ('[[boundaries]]\ntype = "fixed"\nregion = "x > -1"\n' if still else "")
            + '[coupling]\nmethod = "multiplier"\ncondition = "slip"\n')


# ----------------------------------------------------------------------------------------------
# stepping a case in this process
def _step_ale(case: dict, comm, steps: int, blocked: bool) -> None:
    from solvers.ale.solver import AleSolver

    s = AleSolver(comm, case["ale"])
    ne = int(np.prod(case["ale"]["grid"]["cells"]))
    for n in range(steps):
        dt = 0.5 * s.stable_dt()
        s.predict(dt)
        s.correct(None, step=n + 1, time=0.0)
        fractions = None
        if blocked and s.mode == "eulerian" and s.mm is None:  # a moving coupled body's fractions
            from solvers.ale.coupled import BodyGeometry
            ids = np.arange(max(1, ne // 4), dtype=np.int64)
            fractions = BodyGeometry(ids, np.full(ids.size, 0.5))
        s.remap(fractions)
        s.diagnostics()
    s.output()


def _step_lagrange(case: dict, comm, steps: int) -> None:
    from solvers.lagrange.integrators import solver_for

    s = solver_for(case)(comm, case)
    for n in range(steps):
        s.predict(0.5 * s.stable_dt())
        s.correct(None, step=n + 1, time=0.0)
        s.diagnostics()
    s.gather_nodes(s.x)
    {k: s.gather_cells(a) for k, a in s.cell_fields().items()}


def step_case(case: dict, steps: int = STEPS, blocked: bool = False) -> None:
    """A few steps of every solver the case uses, on one rank of this process (no MPI job)."""
    from mpi4py import MPI

    from orchestrator.case import solvers_used

    # the coupled step of a Lagrangian body, as the job runs it (orchestrator/coupling); particles'
    # coupling kernels are warmed by _particle_coupling, their solvers one by one below
    if case.get("coupling") and "lagrange" in case:
        from orchestrator.coupling.inprocess import InProcess

        run = InProcess(case)
        for _ in range(steps + 3):  # (a few more: the body crosses zone faces)
            run.advance(0.5 * min(run.lag.stable_dt(), run.ale.stable_dt()))
        run.ale.diagnostics()
        run.ale.output()
        return
    for role in solvers_used(case):
        if role == "ale":
            _step_ale(case, MPI.COMM_SELF, steps, blocked)
        elif role == "lagrange":
            _step_lagrange(case, MPI.COMM_SELF, steps)
        elif role == "sph":
            _step_sph(case, MPI.COMM_SELF, steps)


def _step_sph(case: dict, comm, steps: int) -> None:
    """The SPH adapter (LAMMPS) in this process: its per-step particle sums (solvers/particle_sums.py)."""
    from adapters.sph import SphAdapter

    with tempfile.TemporaryDirectory(prefix="immerse-warmup-sph-") as tmp:
        (Path(tmp) / "steps").mkdir()
        a = SphAdapter(comm, case, Path(tmp))
        a.setup()
        for i in range(min(steps, 2)):
            a.predict(0.5 * a.stable_dt(), i, 0.0)
            a.correct(None)
            a.diagnostics()
        a.close()


def _particle_coupling() -> None:
    """The coupler's particle interface (reconstruction, clipping, Shepard rows) in 2-D and 3-D."""
    from orchestrator.coupling.grid import Grid
    from orchestrator.coupling.particle_operators import particle_interface

    for dim in (2, 3):
        grid = Grid([0.0] * dim, [1.0] * dim, [6] * dim)
        ax = np.arange(0.3, 0.7, 0.05) + 0.025
        x = np.stack(np.meshgrid(*[ax] * dim, indexing="ij"), -1).reshape(-1, dim)
        particle_interface(grid, x, np.full(len(x), 0.05 ** dim), 0.1)
    # a block with a corner cut out on a coarse grid: the surface cuts across the concave corner
    # farther than h from every particle, so quadrature points take the nearest particle (the
    # kernels' second pass, particle_operators._particle_rows, called from Python)
    x = x[~np.all(x > 0.5, axis=1)]
    particle_interface(Grid([0.0] * 3, [1.0] * 3, [4] * 3), x, np.full(len(x), 0.05 ** 3), 0.1)


def _contact_search() -> None:
    """The contact broad phase's binned kernel: the tiny contact cases stay below ALL_PAIRS_MAX box
    pairs, where every pair is tested, but surfaces of shipped cases go beyond it."""
    from solvers.contact.search import _binned_pairs, facet_boxes

    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    facets = np.array([[0, 1], [1, 2]])
    boxes = facet_boxes(x, facets, 0.1)
    _binned_pairs(boxes, boxes)


def dispatchers() -> dict[str, object]:
    """Every numba function of the loaded solver modules, by qualified name."""
    from numba.core.dispatcher import Dispatcher

    found = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith(("solvers.", "orchestrator.coupling.")) or mod is None:
            continue
        for attr, obj in vars(mod).items():
            if isinstance(obj, Dispatcher) and obj.py_func.__module__ == name:
                found[f"{name}.{attr}"] = obj
    return found


def compiled() -> dict[str, int]:
    """Kernels compiled in this process (not found in the cache): name -> number of signatures."""
    return {k: sum(d._cache_misses.values()) for k, d in dispatchers().items() if d._cache_misses}


def loaded() -> int:
    return sum(sum(d._cache_hits.values()) for d in dispatchers().values())


def _import_solvers() -> None:
    import solvers.elements  # noqa: F401  (the element geometry both solvers compile in)
    import solvers.ale.solver  # noqa: F401  (and their kernel modules)
    import solvers.ale.blocked  # noqa: F401
    import solvers.ale.mixed  # noqa: F401
    import solvers.lagrange.solver  # noqa: F401
    import orchestrator.coupling.geometry  # noqa: F401  (the coupler's interface geometry)
    import orchestrator.coupling.matrix_free  # noqa: F401  (its multiplier solve)
    import orchestrator.coupling.operator_rows  # noqa: F401  (its operators)
    import orchestrator.coupling.particle_surface  # noqa: F401  (particle bodies' surfaces)
    import solvers.particle_sums  # noqa: F401  (the SPH adapter's per-step sums)
    import solvers.contact.mortar_segments  # noqa: F401  (contact between Lagrangian bodies)
    import solvers.contact.friction  # noqa: F401  (its Coulomb friction)
    import solvers.contact.search  # noqa: F401  (its broad phase)


PARTS = ("ale", "bodies")
"""The warm-up's two processes (where the machine has the cores) and the order each takes the tasks
in (_order): the ALE solver's cases then the coupled ones, and the bodies' tasks (the particle
coupling, the contact search, the Lagrange, contact and SPH cases). Each task runs once, in the
process that claims it first (_claim); a process done with its own tasks takes the other's from the
far end of its list (the coupled cases first: the kernels they share with the ALE cases are mostly in
the cache by then), so the two end together whatever the machine's compile speed. Numba's cache
index is locked (solvers/kernel_cache.py), so an entry both compile is saved safely. Measured from an
empty cache on 2 cores (2026-12-04, a slow hour): with fixed parts (each process its own list only)
228 s, the ALE part the longer (239 s against the bodies' 138 s when timed alone); sharing the
tasks 183 and 187 s, the same 203 specialisations (~20 compiled twice, by both processes at once)."""

BODY_TASKS = ("particle_coupling", "contact_search")   # (not cases: kernels called directly)


def _part_of(name: str) -> str:
    return "ale" if name.startswith(("ale_", "coupled")) else "bodies"


def _order(part: str | None, names) -> list[str]:
    """The tasks in the order ``part`` takes them (None: all, one process)."""
    ale = sorted(n for n in names if n.startswith("ale_"))
    coupled = sorted(n for n in names if n.startswith("coupled"))
    bodies = list(BODY_TASKS) + sorted(n for n in names if _part_of(n) == "bodies")
    if part == "bodies":
        return bodies + coupled[::-1] + ale[::-1]
    return ale + coupled + bodies


def _claim(claims: Path | None, task: str) -> bool:
    """True for the one process that claims ``task`` first (an exclusive create in ``claims``)."""
    if claims is None:
        return True
    import os

    try:
        os.close(os.open(claims / task, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        return True
    except FileExistsError:
        return False


def _warm_part(part: str | None, claims: Path | None = None) -> dict:
    """Step the warm-up tasks in ``part``'s order (None: all), those this process claims; its counts."""
    from orchestrator.case import load_case

    t0 = time.perf_counter()
    _import_solvers()
    table = cases()
    ran = 0
    with tempfile.TemporaryDirectory(prefix="immerse-warmup-") as tmp:
        for name in _order(part, table):
            if not _claim(claims, name):
                continue
            if name == "particle_coupling":
                _particle_coupling()
            elif name == "contact_search":
                _contact_search()
            else:
                d = Path(tmp) / name
                d.mkdir()
                (d / "case.toml").write_text(table[name])
                step_case(load_case(d), blocked="obstacle" in name or "walls" in name)
                ran += 1
    return {"cases": ran, "compiled": sum(compiled().values()), "loaded_from_cache": loaded(),
            "seconds": round(time.perf_counter() - t0, 2)}


def warm(log=print, jobs: int | None = None) -> dict:
    """Step every warm-up task, in two processes sharing the tasks (PARTS) when ``jobs`` (default: the
    cores this process may use) allows; return the summed counts and the wall time (measured: 283 s in
    one process on 2 cores, 190 specialisations)."""
    import os
    import subprocess

    t0 = time.perf_counter()
    jobs = len(os.sched_getaffinity(0)) if jobs is None else jobs
    if jobs < 2:
        parts = [_warm_part(None)]
    else:
        claims = Path(tempfile.mkdtemp(prefix="immerse-warmup-claims-"))
        child = subprocess.Popen([sys.executable, "-m", "orchestrator.warmup", "--part", PARTS[1],
                                  "--claims", str(claims)], stdout=subprocess.PIPE, text=True)
        import shutil

        try:
            parts = [_warm_part(PARTS[0], claims)]
            out = child.communicate()[0]   # (it may still claim: the directory stays until it ends)
        except BaseException:   # (the other part must not go on compiling alone)
            child.kill()
            child.wait()
            raise
        finally:
            shutil.rmtree(claims, ignore_errors=True)
        if child.returncode != 0:
            raise RuntimeError(f"the warm-up of the {PARTS[1]} cases failed (exit code {child.returncode})")
        parts.append(json.loads(out.strip().splitlines()[-1]))
    report = {k: sum(p[k] for p in parts) for k in ("cases", "compiled", "loaded_from_cache")}
    report["seconds"] = round(time.perf_counter() - t0, 2)
    log(f"numba kernels warm: {report['cases']} tiny cases, {report['compiled']} specialisations "
        f"compiled, {report['loaded_from_cache']} loaded from the cache, {report['seconds']} s "
        f"({len(parts)} process{'es' if len(parts) > 1 else ''})")
    return report


def check(case_dirs) -> dict[str, int]:
    """Step each case a few steps; return the kernels that had to be compiled (empty: all cached)."""
    from orchestrator.case import load_case

    _import_solvers()
    for d in case_dirs:
        step_case(load_case(d), steps=2)
    return compiled()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m orchestrator.warmup", description=__doc__.split("\n")[0])
    ap.add_argument("--check", nargs="+", metavar="CASE_DIR",
                    help="step these cases and print the kernels compiled instead of loaded (JSON)")
    ap.add_argument("--part", choices=PARTS, help="warm in this part's order and print the counts (JSON)")
    ap.add_argument("--claims", type=Path, help="with --part: the directory where the processes claim their tasks")
    args = ap.parse_args(argv)
    if args.part:
        print(json.dumps(_warm_part(args.part, args.claims)))
    elif args.check:
        print(json.dumps(check(args.check)))
    else:
        warm()
    return 0


if __name__ == "__main__":
    sys.exit(main())
