"""What a case needs of the machine, estimated from its sizes before anything is built.

``immerse check`` and ``immerse run`` refuse (one line, exit 2, nothing launched) a case that

* asks for more ranks of a solver than it has zones or elements (always: a rank without work
  fails at start-up), or an ALE rank count its grid cannot be split into (every split axis keeps
  2 zones a block, solvers/ale/parallel.py);
* starts more processes (coupler + every solver rank) than 4 per core of the machine times
  ``--nodes``, unless ``--oversubscribe`` is given (a laptop run, coupler + a few ranks on 2 cores,
  stays well inside);
* needs more memory than the machine has (``--nodes N`` times this machine's or
  ``--memory-per-node SIZE``).

The memory estimate is a sum of measured costs (constants below; Python integers throughout, so a
grid of 10^15 zones is refused in microseconds, not overflowed).  The machine's memory is its
``MemTotal`` (or a smaller cgroup limit), not ``MemAvailable``: the answer must not depend on what
else happens to run at the instant of the check.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

from solvers.ale.parallel import MIN_ZONES, split_possible
from solvers.ale.points import DEFAULT_FRACTION_SAMPLES, several_materials

from .schema.rules import CaseError, format_bytes, format_key

# ---- measured costs (bytes) ---------------------------------------------------------------------
# `immerse bench memory` (orchestrator/bench/memory.py -> bench-memory.json) measures every one of these:
# tracemalloc peaks of the real solvers (set-up, steps, an output) as slopes between two sizes, so
# fixed costs drop out.  Values of its run on the reference machine (2 cores, 24 GiB, Python 3.11).
LAGRANGE_BYTES_PER_ELEMENT = {2: 660, 3: 1126}
"""Lagrangian solver on one rank, per element (box meshes: quads 150^2 -> 300^2: 660.1, hexahedra
20^3 -> 40^3: 1125.7, re-measured 2026-12-05; 514.0 and 896.1 when first measured, the solver has
gained arrays since); linear elastic and Johnson-Cook within 1 B)."""
LAGRANGE_MESH_BYTES_PER_ELEMENT = {"box": {2: 254, 3: 428}, "built": {2: 940, 3: 940},
                                   "file": {2: 1084, 3: 1084}}
"""Held by EVERY Lagrangian rank (each builds the global mesh and its partition), per element:
box meshes (253.5, 427.8); quarter cylinders (939.6: the generator's orientation pass; 2-D quarter
disks and rings are charged that figure, not measured); mesh files
(read_mesh of 50^3 hexahedra: Gmsh 2.2 ASCII 1068.0, binary 1059.5, VTU 1083.5; 2-D files are
charged the 3-D figure)."""
LAGRANGE_HOURGLASS_STIFFNESS_BYTES_PER_ELEMENT = {2: 72, 3: 320}
"""Added per element of a body with hourglass_control = "assumed_strain" (its state, 10 numbers a
quad, 41 a hexahedron, against 1: 9 and 40 doubles; with 8 and 29 the measured difference was
exactly 7 and 28 doubles, 716.1 - 660.1 and 1349.7 - 1125.7 B, 2026-12-05)."""
ALE_BYTES_PER_ZONE = {2: 483, 3: 719}
"""ALE solver, one material, per zone of the padded block (2 ghost layers a side), Eulerian, remap
arrays included (150^2 -> 300^2: 482.9; 24^3 -> 40^3: 718.6)."""
ALE_BYTES_PER_ZONE_MATERIAL = {2: 104, 3: 93}
"""Several materials per zone (or void): per zone and material (3 minus 2 materials: 103.6, 92.7;
2 materials measured 685.6 and 910.6 against 690 and 905 by the sum)."""
ALE_BYTES_PER_SAMPLE = {2: 77, 3: 110}
"""Several materials: per fraction sample point at start-up, fraction_samples^dim a zone (76.6, 109.6)."""
ALE_OBSTACLE_BYTES_PER_ZONE = {2: 78, 3: 94}
"""Static obstacles: blocked fractions, apertures, wall nodes, per zone (78.4, 94.1)."""
RANK_BYTES = 300 << 20
"""One solver rank before its data: Python, numpy, mpi4py, h5py, the JIT compiler and its loaded
kernels (VmHWM 248 MiB for the Lagrangian rank of elastic_bar_wave, 309 MiB for an ALE rank of
sedov_2d on 2 ranks, read from /proc during `immerse run`)."""
COUPLER_BYTES = 130 << 20
"""The coupler process (VmHWM 78-131 MiB, same runs)."""

PROCESSES_PER_CORE = 4
"""More processes than this per core are refused without --oversubscribe (MPI ranks busy-poll)."""


# ---- the machine -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Machine:
    """What the job may use: ``nodes`` nodes of ``memory_per_node`` bytes and ``cores_per_node``
    cores; ``memory_given``: the memory came from --memory-per-node (else this machine's)."""

    nodes: int
    memory_per_node: int
    cores_per_node: int
    oversubscribe: bool = False
    memory_given: bool = False

    @property
    def memory(self) -> int:
        return self.nodes * self.memory_per_node

    @property
    def cores(self) -> int:
        return self.nodes * self.cores_per_node


def machine_memory() -> int:
    """Bytes of memory of this machine: MemTotal, or a smaller cgroup (v2) limit of this process."""
    total = None
    try:
        text = Path("/proc/meminfo").read_text()
        m = re.search(r"^MemTotal:\s+(\d+)\s*kB", text, re.M)
        if m:
            total = int(m.group(1)) * 1024
    except OSError:
        pass
    if total is None:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    try:
        cg = Path("/proc/self/cgroup").read_text().strip().splitlines()
        rel = next(line.split(":", 2)[2] for line in cg if line.startswith("0::"))
        limit = Path("/sys/fs/cgroup", rel.lstrip("/"), "memory.max").read_text().strip()
        if limit.isdigit():
            total = min(total, int(limit))
    except (OSError, StopIteration, IndexError):
        pass
    return total


def job_processes(ranks: dict[str, int]) -> int:
    """The processes of one job: the coupler and every solver rank (``ranks``: ranks_for's, the used
    roles only)."""
    return 1 + sum(int(n) for n in ranks.values())


def machine_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


_UNITS = {"": 1, "b": 1,
          "k": 1 << 10, "kib": 1 << 10, "kb": 10**3,
          "m": 1 << 20, "mib": 1 << 20, "mb": 10**6,
          "g": 1 << 30, "gib": 1 << 30, "gb": 10**9,
          "t": 1 << 40, "tib": 1 << 40, "tb": 10**12,
          "p": 1 << 50, "pib": 1 << 50, "pb": 10**15}
_SIZE = re.compile(r"^\s*((?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d{1,2})?)\s*([A-Za-z]*)\s*$")
SIZE_TEXT = ("must be a size such as 64GiB, 512G or 1.5TB (K/M/G/T/P and KiB..PiB: powers of 1024, "
             "KB..PB: powers of 1000, no unit: bytes), more than 0")


def parse_size(text: str) -> int:
    """Bytes of a size such as ``64GiB``, ``512G`` (Slurm's convention: binary), ``1.5TB``
    (decimal); ValueError otherwise."""
    m = _SIZE.match(str(text))
    if not m or m.group(2).lower() not in _UNITS:
        raise ValueError(text)
    try:
        value = int(Decimal(m.group(1)) * _UNITS[m.group(2).lower()])
    except InvalidOperation:  # pragma: no cover - the pattern admits decimals only
        raise ValueError(text) from None
    if value < 1:
        raise ValueError(text)
    return value


def allocation() -> tuple[int, int] | None:
    """(nodes, memory a node in bytes, 0 if unknown) of the Slurm allocation this process runs in
    (SLURM_JOB_NUM_NODES, SLURM_MEM_PER_NODE in MB), or None outside one."""
    n = os.environ.get("SLURM_JOB_NUM_NODES", "")
    if not (n.isascii() and n.isdigit() and int(n) > 0):
        return None
    m = os.environ.get("SLURM_MEM_PER_NODE", "")
    return int(n), (int(m) << 20 if m.isascii() and m.isdigit() else 0)


MAX_NODES = 10_000
"""--nodes beyond this is refused wherever Slurm does not say the cluster's size (the largest
machines have about 10,000 nodes)."""
MAX_MEMORY_PER_NODE = 64 << 40
"""--memory-per-node beyond 64 TiB is refused wherever Slurm does not say the nodes' memory (the
largest shared-memory nodes have 24-32 TiB)."""


def this_machine(nodes: str | int | None = None, memory_per_node: str | None = None,
                 oversubscribe: bool = False, cluster=None) -> Machine:
    """The machine of the command line (``--nodes``, ``--memory-per-node``, ``--oversubscribe``),
    defaults from this machine; CaseError on the flag for a bad value.  The figures a flag gives
    are bounded by the batch system's (``cluster``: (nodes, largest node's memory): sinfo's for a
    job going to Slurm, orchestrator/cli.py; by default the allocation this runs in, if any) or,
    without one, by MAX_NODES and MAX_MEMORY_PER_NODE."""
    n = 1
    if cluster is None:
        cluster = allocation()
    cluster = cluster or None   # (False: none; tests)
    if nodes is not None:
        text = str(nodes).strip()
        if not re.fullmatch(r"\+?[0-9]{1,9}", text) or int(text) < 1:
            raise CaseError("--nodes", nodes, "must be an integer >= 1 (nodes of this machine's "
                                              "kind the job spans)")
        n = int(text)
        top, where = ((cluster[0], "the nodes Slurm has") if cluster
                      else (MAX_NODES, "the most immerse accepts without Slurm to ask"))
        if n > top:
            raise CaseError("--nodes", nodes, f"must be <= {top} ({where})")
    if memory_per_node is None:
        mem, given = machine_memory(), False
    else:
        try:
            mem, given = parse_size(memory_per_node), True
        except ValueError:
            raise CaseError("--memory-per-node", memory_per_node, SIZE_TEXT) from None
        top, where = ((cluster[1], "the largest node's memory Slurm has") if cluster and cluster[1]
                      else (MAX_MEMORY_PER_NODE, "the most immerse accepts without Slurm to ask"))
        if mem > top:
            raise CaseError("--memory-per-node", memory_per_node, f"must be <= {format_bytes(top)} ({where})")
    return Machine(nodes=n, memory_per_node=mem, cores_per_node=machine_cores(),
                   oversubscribe=bool(oversubscribe), memory_given=given)


# ---- the case's sizes --------------------------------------------------------------------------
def _mesh_kind(body: dict) -> str:
    m = body["mesh"]
    return "box" if "box" in m else "file" if "file" in m else "built"


def _mesh_key(i: int, body: dict) -> str:
    m = body["mesh"]
    sub = ["box", "cells"] if "box" in m else [k for k in ("quarter_cylinder", "quarter_disk", "ring", "file") if k in m][:1]
    return format_key(["lagrange", "bodies", i, "mesh", *sub])


def _mesh_value(body: dict):
    m = body["mesh"]
    if "box" in m:
        return m["box"]["cells"]
    for k in ("quarter_cylinder", "quarter_disk", "ring"):
        if k in m:
            return m[k]
    return m["file"].name


def _lagrange_memory(case: dict, nranks: int) -> list[tuple[str, object, str, int]]:
    """Per body: the distributed solver arrays once, the global mesh once per rank."""
    dim = case["run"]["dimension"]
    per_rank_base = LAGRANGE_BYTES_PER_ELEMENT[dim] - LAGRANGE_MESH_BYTES_PER_ELEMENT["box"][dim]
    parts = []
    for i, b in enumerate(case["lagrange"]["bodies"]):
        mesh = LAGRANGE_MESH_BYTES_PER_ELEMENT[_mesh_kind(b)][dim]
        hg = LAGRANGE_HOURGLASS_STIFFNESS_BYTES_PER_ELEMENT[dim] if b.get("hourglass_control") == "assumed_strain" else 0
        parts.append((_mesh_key(i, b), _mesh_value(b), f"lagrange body {b['name']!r}",
                      b["size"]["elements"] * (per_rank_base + hg + nranks * mesh)))
    return parts


def _lagrange_ranks(case: dict, n: int) -> str | None:
    """Every rank needs an element (the slab partition gives each one at least one then)."""
    ne = sum(b["size"]["elements"] for b in case["lagrange"]["bodies"])
    if n > ne:
        return f"more ranks than the {ne} elements of the Lagrangian bodies; allowed: 1 to {ne}"
    return None


def _ale_memory(case: dict, nranks: int) -> list[tuple[str, object, str, int]]:
    """The padded block (rank cuts add a little), materials, obstacles, start-up fraction samples."""
    a, dim = case["ale"], case["run"]["dimension"]
    cells = a["grid"]["cells"]
    padded = math.prod(c + 2 * MIN_ZONES for c in cells)
    per_zone = ALE_BYTES_PER_ZONE[dim]
    samples = 0
    if several_materials(a):
        per_zone += len({r["material"] for r in a["regions"]}) * ALE_BYTES_PER_ZONE_MATERIAL[dim]
        k = int(a.get("fraction_samples") or DEFAULT_FRACTION_SAMPLES[dim])
        samples = math.prod(cells) * k**dim * ALE_BYTES_PER_SAMPLE[dim]
    if a.get("obstacles"):
        per_zone += ALE_OBSTACLE_BYTES_PER_ZONE[dim]
    return [("ale.grid.cells", cells, "ale grid", padded * per_zone + samples)]


def _ale_ranks(case: dict, n: int) -> str | None:
    """The Cartesian split of solvers/ale/parallel.py must exist for n ranks."""
    cells = case["ale"]["grid"]["cells"]
    zones = math.prod(cells)
    if n > zones:
        return f"more ranks than the {zones} zones of ale.grid.cells = {cells}"
    if not split_possible(n, cells):
        return (f"ale.grid.cells = {cells} cannot be split over {n} ranks with at least {MIN_ZONES} "
                "zones a rank along every split axis; choose a count whose factors fit the grid")
    return None


SPH_BYTES_PER_PARTICLE = {2: 800, 3: 1500}
"""Memory of a LAMMPS SPH particle at h = 3 dx, set-up, one step and one output (peak RSS growth per
particle, 160k particles in 2-D: 786 B, 125k in 3-D: 1417 B); the neighbour lists, most of it in
3-D, grow as (h / dx)^dim."""


def _sph_memory(case: dict, nranks: int) -> list[tuple[str, object, str, int]]:
    s, dim = case["sph"], case["run"]["dimension"]
    reach = max(1.0, (s["smoothing_length"] / (3.0 * s["spacing"])) ** dim)
    return [("sph.bodies", f"{s['particles']} particles", "sph particles",
             int(s["particles"] * SPH_BYTES_PER_PARTICLE[dim] * reach))]


def _sph_ranks(case: dict, n: int) -> str | None:
    if n > case["sph"]["particles"]:
        return f"more ranks than the {case['sph']['particles']} particles of the SPH bodies"
    return None


ROLES = {"lagrange": (_lagrange_memory, _lagrange_ranks), "ale": (_ale_memory, _ale_ranks),
         "sph": (_sph_memory, _sph_ranks)}
"""Per solver role: (memory parts of the case for n ranks, why n ranks cannot work or None).  A role
without an entry is charged its processes only."""


def estimate(case: dict, ranks: dict[str, int], overridden=()) -> list[tuple[str, object, str, int]]:
    """Memory of the job by part: ``[(key, value, what, bytes)]`` (the key and value a refusal
    names for that part; ``overridden``: roles whose rank count came from --ranks)."""
    parts = []
    for role, n in ranks.items():
        if role in ROLES and case.get(role):
            parts += ROLES[role][0](case, int(n))
    nproc = job_processes(ranks)
    most = max(ranks, key=lambda r: ranks[r]) if ranks else None
    parts.append((_rank_key(most, overridden) if most else "ranks", ranks.get(most),
                  f"{nproc} processes", COUPLER_BYTES + (nproc - 1) * RANK_BYTES))
    return parts


def _rank_key(role: str, overridden) -> str:
    return f"--ranks {role}" if role in (overridden or ()) else format_key(["ranks", role])


def check_resources(case: dict, ranks: dict[str, int], machine: Machine, overridden=()) -> int:
    """Refuse (CaseError) rank counts the case cannot use or the machine cannot run, and memory
    beyond the machine; returns the memory estimate in bytes.  ``overridden``: roles whose count
    came from ``--ranks`` (named so in messages)."""
    # ranks per role against the work there is
    for role, n in ranks.items():
        why = ROLES[role][1](case, int(n)) if role in ROLES and case.get(role) else None
        if why:
            raise CaseError(_rank_key(role, overridden), n, why)
    # processes against cores
    nproc = job_processes(ranks)
    limit = PROCESSES_PER_CORE * machine.cores
    if nproc > limit and not machine.oversubscribe:
        role = max(ranks, key=lambda r: ranks[r])
        on = f"{machine.cores_per_node} cores" + (f" x {machine.nodes} nodes" if machine.nodes > 1 else "")
        raise CaseError(_rank_key(role, overridden), ranks[role],
                        f"{nproc} processes (coupler + solver ranks) on {on}: more than "
                        f"{PROCESSES_PER_CORE} a core ({limit}); give --oversubscribe to run them "
                        "anyway, or --nodes N for a job across N nodes")
    # memory
    parts = estimate(case, ranks, overridden)
    total = sum(p[3] for p in parts)
    if total > machine.memory:
        key, value, _, _ = max(parts, key=lambda p: p[3])
        breakdown = " + ".join(f"{what} {format_bytes(b)}" for _, _, what, b in parts if b)
        if machine.nodes == 1:
            have = f"{'a node' if machine.memory_given else 'this machine'} has {format_bytes(machine.memory)}"
        else:
            have = (f"{machine.nodes} nodes of {format_bytes(machine.memory_per_node)} have "
                    f"{format_bytes(machine.memory)}")
        raise CaseError(key, value, f"needs about {format_bytes(total)} of memory (estimate: "
                                    f"{breakdown}), {have}; on a cluster give --nodes N (and "
                                    "--memory-per-node SIZE)")
    return total
