"""Small cut zones of moving bodies: the conservative merge after the remap (``Blocked._merge``).

A zone a coupled body cuts to a small open fraction, or covers while it still holds material, hands
its content to a face neighbour (``PHI_MERGE``), and a zone the body uncovered within the step
(open, still empty: the remap's apertures are the start of the step's) takes its share from one
with material, as does one the step opened at once (a sliver at its start left at least twice as
open and no longer small, ``opened_zones``: a body's eroded element uncovered it): the target's
group (the target and its donors) shares one density and one specific energy, in proportion to the
open volumes.  Nodal momentum is conserved (a node keeps its velocity
when its mass falls and hands the momentum of the lost mass to the nodes that gain); groups that
share a node pool their nodes' momentum together (``group_components``: one group's zones may
release at a node what another's gain at the next), and the kinetic energy the exchange removes
becomes the internal energy of those groups (total energy conserved).

Who merges into whom is decided where the zone is real, from the zones within two of it (the
neighbours' open fractions and whether they merge themselves), and handed to the ghost layers of the
other ranks and of the periodic images as a code (the offset of its target, ``merge_targets``);
each target's group totals are summed where the target is real, over its donors (within two zones),
and handed out the same way (``group_totals``).  So every group that touches a zone or a node of a
block is seen whole with the two ghost layers the remap has, whatever the ranks and across periodic
faces (deciding in the ghost layers instead needs the zones three and four away: a group's donor
two zones out picks its target among zones the block does not hold).

The rule: a donor merges into the open, usable neighbour that does not merge itself, the most open
one (ties to the first in axis order, lower side first); if all its open neighbours merge, into the
target of the most open of them (two zones away); an empty zone only into one with material (a
void behind a body stays empty); a zone with material whose open face neighbours and their targets
all merge, or that has no open face neighbour (a body's corner closing around it: a pocket), into
the nearest zone within two per axis that does not merge, the most open of the nearest
(``_nearest_keeper``); with none, it keeps its content (or stays empty) if it is open and holds no
negative mass, and is an error otherwise (a covered zone with material and nowhere to pass it: the
caller names it).  Groups are keyed by their target's global zone id (periodic images share it),
and every sum over a group's nodes is taken by the nodes' owners and added in (group, node) order
(``_group_sums``), so any number of ranks gives the same bits.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from solvers.ale.eos import pressure
from solvers.ale.mixed import equilibrium_volumes

PHI_MERGE = 0.5
"""A zone a coupled body cuts to an open fraction below this (or a fully covered zone that still
holds material, or one the remap left with negative mass) shares its content with its most open
face neighbour after every remap (one density and specific energy for both): a small cut zone's
state would otherwise follow its explicit Lagrange step with a time step set by full zones (its
volume changes by O(1) of itself per step), the remap's face fluxes and the body's swept volume
agree only to the order of the scheme, and a body crossing a zone face within one step sweeps more
than the zone holds."""


@njit(cache=True, inline="always")
def _split(n, strides):
    """(i, j, k) of the flat padded index n (zone or node strides)."""
    i = n // strides[0]
    r = n - i * strides[0]
    j = r // strides[1]
    return i, j, r - j * strides[1]


@njit(cache=True)
def _corners(z, zs, ns, dim, out):
    i, j, k = _split(z, zs)
    n0 = i * ns[0] + j * ns[1] + k * ns[2]
    nc = 0
    for c in range(1 << dim):
        o0 = c & 1
        o1 = (c >> 1) & 1
        o2 = (c >> 2) & 1
        out[nc] = n0 + o0 * ns[0] + o1 * ns[1] + o2 * ns[2]
        nc += 1
    return nc


@njit(cache=True, inline="always")
def _zone_around(i, j, k, c, zs, dim):
    """Zone c (0 .. 2^dim - 1) of the 2^dim around node (i, j, k): offset -1 + bit d of c along d."""
    zk = k - 1 + ((c >> 2) & 1) if dim == 3 else 0
    return (i - 1 + (c & 1)) * zs[0] + (j - 1 + ((c >> 1) & 1)) * zs[1] + zk * zs[2]


@njit(cache=True)
def _node_mass(n, M, zact, zs, ns, dim):
    """The gather's nodal mass (hydro.gather_*: 2^-dim sum of the active zones' masses)."""
    i, j, k = _split(n, ns)
    s = 0.0
    for c in range(1 << dim):
        z = _zone_around(i, j, k, c, zs, dim)
        s += zact[z] * M[z]
    return s / (1 << dim)


@njit(cache=True)
def merge_velocities(un, ugr, m0, m1, v, tot, owned):
    """The nodes' new velocities from their group's totals ``tot`` (over all ranks: [pool, gain, mass
    after, kinetic energy before]): a node that gains mass takes its share of the momentum the others
    released with theirs; when no node of a group gains (its zones' mass moved between nodes of
    other groups) the pool goes to its nodes by mass; a node left without mass stops.  Returns the
    groups' kinetic energy after, over the nodes this rank owns."""
    dim = v.shape[1]
    ke1 = np.zeros(un.size)  # per node (owned ones), summed by group like merge_nodes' rows
    ng = tot.shape[0]
    # the released mass moves at its mean velocity u = pool / released into the nodes that gain it;
    # what the gains do not take (a node's change may come from a neighbouring group's zones: gains
    # and releases of one group need not balance) goes to all of the group's nodes by mass
    u = np.zeros((ng, dim))
    rest = np.zeros((ng, dim))
    for g in range(ng):
        rel, gain = tot[g, dim + 3], tot[g, dim]
        for d in range(dim):
            u[g, d] = tot[g, d] / rel if rel > 0.0 else 0.0
            rest[g, d] = tot[g, d] - (gain * u[g, d] if rel > 0.0 else 0.0)
    for a in range(un.size):
        g = ugr[a]
        n = un[a]
        if m1[a] > m0[a] and m1[a] > 0.0:  # (u = 0 when nothing was released: diluted)
            m_own = m0[a] if m0[a] > 0.0 else 0.0  # (see merge_nodes: negative masses)
            for d in range(dim):
                v[n, d] = (m_own * v[n, d] + (m1[a] - m_own) * u[g, d]) / m1[a]
        if m1[a] > 0.0 and tot[g, dim + 1] > 0.0:
            for d in range(dim):
                v[n, d] += rest[g, d] / tot[g, dim + 1]
        if not (m1[a] > 0.0):
            for d in range(dim):
                v[n, d] = 0.0
        if owned[n]:
            for d in range(dim):
                ke1[a] += 0.5 * m1[a] * v[n, d] * v[n, d]
    return ke1


def group_components(comm, edges, gids, masses):
    """Groups that share a node act as one in the node update: the mass one group's zones release
    at a node may be what another's gain at the next, and pooled apart each would hand its nodes the
    other's momentum at the wrong velocity (a body moving with a uniform flow left it 6 % off where
    the group of a sliver along its side met the group of the zone its back uncovered).  Returns
    (component of every group id in ``edges`` / ``gids`` as a dict-like pair of sorted arrays
    (ids, component = the smallest id in it), and the component's mass from the groups' masses
    ``masses`` (of the groups ``gids`` whose target is real here), summed in group-id order: the
    same bits on every rank."""
    e = _allgather(comm, edges.astype(np.float64)).reshape(-1, 2).astype(np.int64)
    gm = _allgather(comm, np.column_stack([gids.astype(np.float64), masses])).reshape(-1, 2)
    ids = np.unique(np.concatenate([e.ravel(), gm[:, 0].astype(np.int64)]))
    a, b = np.searchsorted(ids, e[:, 0]), np.searchsorted(ids, e[:, 1])
    label = _components(ids.size, a, b)
    first = np.full(label.max() + 1 if label.size else 0, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(first, label, ids)
    comp = first[label]
    # the components' masses: each group's once, in id order
    gid_m, keep = np.unique(gm[:, 0].astype(np.int64), return_index=True)
    cm = np.zeros(first.size)
    np.add.at(cm, label[np.searchsorted(ids, gid_m)], gm[keep, 1])  # (unbuffered: in id order)
    return ids, comp, cm[label]


@njit(cache=True)
def _components(n, a, b):
    """Connected components of the undirected graph on n vertices with edges (a[t], b[t]): each
    vertex's component numbered 0, 1, ... in the order of its smallest vertex (union-find with path
    halving; a few links per step, where scipy's csgraph spent ~1 ms building its matrix)."""
    parent = np.arange(n)
    for t in range(a.size):
        x = a[t]
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        y = b[t]
        while parent[y] != y:
            parent[y] = parent[parent[y]]
            y = parent[y]
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    label = np.empty(n, np.int64)
    count = 0
    for i in range(n):  # a root is its component's smallest vertex: met before the others
        r = i
        while parent[r] != r:
            r = parent[r]
        parent[i] = r
        if r == i:
            label[i] = count
            count += 1
        else:
            label[i] = label[r]
    return label


def _allgather(comm, a) -> np.ndarray:
    """Every rank's float64 array ``a`` concatenated in rank order, flat (comm None: ``a`` itself)."""
    a = np.ascontiguousarray(a, dtype=np.float64).ravel()
    if comm is None:
        return a
    from mpi4py import MPI

    counts = np.zeros(comm.size, dtype=np.int64)
    comm.Allgather(np.array([a.size], dtype=np.int64), counts)
    out = np.empty(int(counts.sum()))
    comm.Allgatherv(a, [out, counts, np.concatenate([[0], np.cumsum(counts)[:-1]]), MPI.DOUBLE])
    return out


def _group_sums(comm, keys, row_key, row_node, rows) -> np.ndarray:
    """Per group (keys: this rank's sorted group ids) the sum of the rows (one per owned node: its
    group id, global node id, values) of every rank, added in the order of (group id, node id): the
    same numbers in the same order whatever the ranks (float64 buffers; comm None: one rank)."""
    k = rows.shape[1]
    mine = np.hstack([row_key[:, None].astype(np.float64), row_node[:, None].astype(np.float64), rows])
    mine = _allgather(comm, mine).reshape(-1, k + 2)
    order = np.lexsort((mine[:, 1], mine[:, 0]))
    return _ordered_sums(keys.astype(np.int64), mine[order, 0].astype(np.int64), mine[order, 2:].copy())


@njit(cache=True)
def _ordered_sums(keys, row_key, rows):
    """out[g] = sum of the rows whose key is keys[g], added in row order (rows sorted by key)."""
    out = np.zeros((keys.size, rows.shape[1]))
    g = 0
    for r in range(row_key.size):
        while g < keys.size and keys[g] < row_key[r]:
            g += 1
        if g < keys.size and keys[g] == row_key[r]:
            for c in range(rows.shape[1]):
                out[g, c] += rows[r, c]
    return out


@njit(cache=True)
def _gid(z, zs, gdims, goff, gper):
    """Global zone id (x fastest) of padded zone z: the same number on every rank that holds it,
    and for a periodic image (``gper``: periodic axes) its zone's number."""
    i, j, k = _split(z, zs)
    i += goff[0]
    j += goff[1]
    k += goff[2]
    if gper[0]:
        i %= gdims[0]
    if gper[1]:
        j %= gdims[1]
    if gper[2]:
        k %= gdims[2]
    return i + gdims[0] * (j + gdims[1] * k)


@njit(cache=True)
def zone_gids(zones, zs, gdims, goff, gper):
    out = np.empty(zones.size, np.int64)
    for a in range(zones.size):
        out[a] = _gid(zones[a], zs, gdims, goff, gper)
    return out


@njit(cache=True, inline="always")
def _is_donor(z, M, phi, b, opened, usable, phi_merge):
    """A zone a body covers in part that must share with a neighbour: small (phi < phi_merge) with
    material, left with negative mass, or open and empty -- uncovered by a body that moved on within
    the step: its faces were closed at the start of the step (the remap's apertures), so the gas that
    followed the body piled up in the neighbour behind it (1 + u dt / h of its density), and the
    group's one density puts it where the body left room.  So is a zone ``opened`` in the step (a
    sliver at its start that the step left at least twice as open, ``opened_zones``: a body's
    element eroded over it, and the remap brought its few grams onto the whole zone): it shares
    whatever it holds, or takes its share if empty, even where no body covers it any more."""
    if usable[z] == 0:
        return False
    if opened[z] != 0:
        return True
    if not (b[z] > 0.0):
        return False
    if M[z] == 0.0:
        return phi[z] > 0.0
    return phi[z] < phi_merge or M[z] < 0.0


@njit(cache=True)
def opened_zones(phi_old, phi_new, phi_merge, out):
    """out[z] = 1 where a zone was a sliver or covered at the start of the step (phi_old < phi_merge)
    and is open and at least twice as open after it: uncovered at once (an eroded element; a surface
    in smooth motion opens a zone by a CFL share of it per step, and one a sliver merges anyway
    while it stays below phi_merge), else 0."""
    for z in range(phi_new.size):
        out[z] = 1 if (phi_old[z] < phi_merge and phi_new[z] >= phi_merge
                       and phi_new[z] >= 2.0 * phi_old[z]) else 0


@njit(cache=True)
def _best(z, M, phi, b, opened, usable, zs, dim, phi_merge, filled=False):
    """The face neighbour zone z would merge into (module docstring), or -1: open and usable (and
    holding material if ``filled``: an empty zone takes its content from a neighbour with some);
    one that does not merge itself before one that does, then the most open; ties to the first."""
    best = -1
    bphi = 0.0
    bkeep = False
    for d in range(dim):
        for sgn in (-1, 1):
            nb = z + sgn * zs[d]
            if usable[nb] == 0 or not (phi[nb] > 0.0) or (filled and not (M[nb] > 0.0)):
                continue
            keep = not _is_donor(nb, M, phi, b, opened, usable, phi_merge)
            if best < 0 or (keep and not bkeep) or (keep == bkeep and phi[nb] > bphi):
                best = nb
                bphi = phi[nb]
                bkeep = keep
    return best


@njit(cache=True)
def _nearest_keeper(z, M, phi, b, opened, usable, zs, dim, phi_merge):
    """Where the face rule finds no target (a zone with material and no open face neighbour, or a
    pocket: all its open neighbours and their targets merge themselves -- a body's corner closing
    around a sliver): the nearest open zone within two per axis that does not merge itself, the most
    open of the nearest; -1 if none.  (A pocket left to keep its content is squeezed with its
    shrinking open fraction: the penetrator's lip sliver went to 2.8 rho0 and c = 3e4 m/s in five
    steps at phi = 1e-4, and the time step collapsed.)"""
    best = -1
    bd = 0
    bphi = 0.0
    for c in range(5 ** dim):
        o0 = c % 5 - 2
        o1 = (c // 5) % 5 - 2
        o2 = c // 25 - 2 if dim == 3 else 0
        d2 = o0 * o0 + o1 * o1 + o2 * o2
        if d2 == 0:
            continue
        nb = z + o0 * zs[0] + o1 * zs[1] + o2 * zs[2]
        if usable[nb] == 0 or not (phi[nb] > 0.0) or _is_donor(nb, M, phi, b, opened, usable, phi_merge):
            continue
        if best < 0 or d2 < bd or (d2 == bd and phi[nb] > bphi):
            best = nb
            bd = d2
            bphi = phi[nb]
    return best


@njit(cache=True, inline="always")
def _target(z, code, zs):
    """The target of donor z from its code (offsets -2..2 per axis, base 5)."""
    c = int(code[z])
    ox = c % 5 - 2
    oy = (c // 5) % 5 - 2
    oz = c // 25 - 2
    return z + ox * zs[0] + oy * zs[1] + oz * zs[2]


@njit(cache=True)
def merge_targets(cand, M, phi, b, opened, usable, zs, dim, phi_merge, code):
    """code[z] of the real candidate zones (the others stay -1): the offset of the zone each donor's
    content goes to (module docstring).  Returns -1, or a zone that must pass its content on (covered
    with material, or negative mass) and has nowhere to."""
    for t in range(cand.size):
        z = cand[t]
        if not _is_donor(z, M, phi, b, opened, usable, phi_merge):
            continue
        empty = M[z] == 0.0
        y = _best(z, M, phi, b, opened, usable, zs, dim, phi_merge, empty)
        if y < 0:
            if empty:
                continue  # open and empty, no neighbour with material (a void behind a body): stays empty
            y = _nearest_keeper(z, M, phi, b, opened, usable, zs, dim, phi_merge)
            if y < 0:
                return z
        elif _is_donor(y, M, phi, b, opened, usable, phi_merge):
            w = _best(y, M, phi, b, opened, usable, zs, dim, phi_merge, empty)
            if w < 0 or _is_donor(w, M, phi, b, opened, usable, phi_merge):
                w = -1 if empty else _nearest_keeper(z, M, phi, b, opened, usable, zs, dim, phi_merge)
                if w < 0:
                    if phi[z] > 0.0 and M[z] >= 0.0:
                        continue  # a pocket of small zones: this one keeps its content (or stays empty)
                    return z
            y = w
        zi, zj, zk = _split(z, zs)
        yi, yj, yk = _split(y, zs)
        code[z] = (yi - zi + 2) + 5 * (yj - zj + 2) + 25 * (yk - zk + 2)
    return -1


@njit(cache=True, inline="always")
def _real_target(z, code, real, zs, zdims):
    """Donor z's target if it lies in this block and is real there (its group totals are summed
    where the target is real), else -1."""
    zi, zj, zk = _split(z, zs)
    c = int(code[z])
    ti = zi + c % 5 - 2
    tj = zj + (c // 5) % 5 - 2
    tk = zk + c // 25 - 2
    if ti < 0 or ti >= zdims[0] or tj < 0 or tj >= zdims[1] or tk < 0 or tk >= zdims[2]:
        return -1
    t = ti * zs[0] + tj * zs[1] + tk * zs[2]
    return t if real[t] else -1


@njit(cache=True)
def group_totals(donors, code, M, e, phi, VE, real, zs, zdims, Mg, Eg, Vg):
    """Mass, internal energy and open volume of the group of every real target (zone-shaped, 0
    elsewhere): the target's own, then its donors' in the order given (global id)."""
    for a in range(donors.size):
        z = donors[a]
        t = _real_target(z, code, real, zs, zdims)
        if t < 0:
            continue
        if Vg[t] == 0.0:
            Mg[t] = M[t]
            Eg[t] = M[t] * e[t]
            Vg[t] = phi[t] * VE[t]
        Mg[t] += M[z]
        Eg[t] += M[z] * e[z]
        Vg[t] += phi[z] * VE[z]


@njit(cache=True)
def group_material_totals(donors, code, vol, mass, ener, real, zs, zdims, Vk, Mk, Ek):
    """Several materials per zone (mixed.py): each real target's group totals per material k (zone x
    material arrays, 0 elsewhere) of the volume, mass and internal energy, summed as group_totals."""
    nm = vol.shape[1]
    started = np.zeros(vol.shape[0], np.uint8)
    for a in range(donors.size):
        z = donors[a]
        t = _real_target(z, code, real, zs, zdims)
        if t < 0:
            continue
        if not started[t]:
            started[t] = 1
            for m in range(nm):
                Vk[t, m] = vol[t, m]
                Mk[t, m] = mass[t, m]
                Ek[t, m] = mass[t, m] * ener[t, m]
        for m in range(nm):
            Vk[t, m] += vol[z, m]
            Mk[t, m] += mass[z, m]
            Ek[t, m] += mass[z, m] * ener[z, m]


@njit(cache=True)
def member_materials(members, code, phi, VE, Vg, Vk, Mk, Ek, de, mcode, mpar, zs, vol, mass, ener):
    """Several materials per zone: every real member takes its group's composition (the volume
    fractions, densities and specific energies of the materials) on its open volume, its share
    phi VE / Vg of each material's mass; ``de``: the member's specific energy change beyond its
    group's mean (the kinetic energy the merge released, merge_velocities), added to every
    material (the zone's energy stays sum_k mass_k ener_k).  The composition is the pressure
    equilibrium of the group's masses and energies on its open volume Vg (mixed.equilibrium_volumes):
    the volumes the donors carry are not to be trusted (their open
    volume changed by O(1) of itself within the step), a stiff trace expanded with its zone would
    have no valid state.  Where that has no solution (void in the group), the carried volumes."""
    nm = vol.shape[1]
    vraw = np.empty(nm)
    mk = np.empty(nm)
    ek = np.empty(nm)
    # one composition per group (its members share it): row slot[t] of comps
    slot = np.full(vol.shape[0], -1, np.int64)
    comps = np.empty((members.size, nm))
    used = 0
    for a in range(members.size):
        z = members[a]
        t = z if code[z] < 0.0 else _target(z, code, zs)
        vz = phi[z] * VE[z]
        w = vz / Vg[t]
        if slot[t] < 0:
            slot[t] = used
            comp = comps[used]
            used += 1
            vs = 0.0
            for m in range(nm):
                vs += Vk[t, m]
                vraw[m] = Vk[t, m]
                mk[m] = Mk[t, m]
                ek[m] = Ek[t, m] / Mk[t, m] if Mk[t, m] > 0.0 else 0.0
            # (the start: the pressure of the material with the most volume, from the group's totals
            # alone, which every rank holds bit for bit, so any number of ranks gives the same bits)
            big = 0
            for m in range(nm):
                if vraw[m] > vraw[big]:
                    big = m
            p0 = pressure(mcode[big], mpar[big], mk[big] / vraw[big], ek[big]) if mk[big] > 0.0 else 0.0
            if not equilibrium_volumes(mcode, mpar, mk, ek, vraw, Vg[t], p0, comp):
                for m in range(nm):
                    comp[m] = Vk[t, m] * (Vg[t] / vs) if vs > 0.0 else 0.0
        comp = comps[slot[t]]
        for m in range(nm):
            vol[z, m] = comp[m] * w
            mass[z, m] = Mk[t, m] * w
            ener[z, m] = Ek[t, m] / Mk[t, m] + de[a] if Mk[t, m] > 0.0 else 0.0


@njit(cache=True)
def merge_members(members, code, M, phi, VE, Mg, Eg, Vg, zs, gdims, goff, gper, dM, en, mgid, mg):
    """The real members' new mass (as its change dM) and specific energy en, their group's id mgid
    (global id of the target) and mass mg.  Returns -1, or a member of a group without positive
    mass."""
    for a in range(members.size):
        z = members[a]
        t = z if code[z] < 0.0 else _target(z, code, zs)
        if not (Mg[t] > 0.0):
            return z
        dM[z] = Mg[t] * (phi[z] * VE[z]) / Vg[t] - M[z]
        en[a] = Eg[t] / Mg[t]
        mgid[a] = _gid(t, zs, gdims, goff, gper)
        mg[a] = Mg[t]
    return -1


@njit(cache=True)
def merge_nodes(near, code, Vg, M, dM, zact, v, owned, zs, ns, dim, gdims, goff, gper):
    """The owned nodes of the member zones ``near`` (real or first ghost layer): their masses before
    and after (m0, m1), their group (the lowest target id among their zones' groups), their rows
    [pool (dim), gain, mass after, kinetic energy before, mass released] to be summed by group, and
    (k, 2) pairs (a node's group, another group one of its zones belongs to) for group_components."""
    corners = np.empty(8, np.int64)
    nodes = np.empty(near.size * (1 << dim), np.int64)
    q = 0
    for a in range(near.size):
        nc = _corners(near[a], zs, ns, dim, corners)
        for c in range(nc):
            if owned[corners[c]]:
                nodes[q] = corners[c]
                q += 1
    un = np.unique(nodes[:q])
    nu = un.size
    m0 = np.empty(nu)
    m1 = np.empty(nu)
    ngid = np.empty(nu, np.int64)
    part = np.zeros((nu, dim + 4))
    edges = np.empty((nu * (1 << dim), 2), np.int64)
    ne = 0
    gz = np.empty(1 << dim, np.int64)
    for a in range(nu):
        n = un[a]
        m0[a] = _node_mass(n, M, zact, zs, ns, dim)
        i, j, k = _split(n, ns)
        dm = 0.0
        g = -1
        ng = 0
        for c in range(1 << dim):
            z = _zone_around(i, j, k, c, zs, dim)
            dm += zact[z] * dM[z]
            if code[z] >= 0.0:
                gz[ng] = _gid(_target(z, code, zs), zs, gdims, goff, gper)
            elif Vg[z] > 0.0:
                gz[ng] = _gid(z, zs, gdims, goff, gper)
            else:
                continue
            if g < 0 or gz[ng] < g:
                g = gz[ng]
            ng += 1
        for b in range(ng):
            if gz[b] != g:
                edges[ne, 0] = g
                edges[ne, 1] = gz[b]
                ne += 1
        m1[a] = m0[a] + dm / (1 << dim)
        ngid[a] = g
        for d in range(dim):
            part[a, dim + 2] += 0.5 * m0[a] * v[n, d] * v[n, d]
        if m1[a] <= m0[a] or not (m1[a] > 0.0):
            # (a node that gains only up to zero mass -- a negative zone mass filled -- can hold no
            # momentum: its own goes to the pool)
            c = (m0[a] - m1[a]) if m1[a] <= m0[a] else m0[a]
            for d in range(dim):
                part[a, d] += c * v[n, d]
            part[a, dim + 3] += c
        elif m0[a] < 0.0:
            # a node of negative mass (round-off of a zone a body empties) that ends with some: its
            # momentum goes to the pool and it gains all of its new mass from it (bounded velocity)
            for d in range(dim):
                part[a, d] += m0[a] * v[n, d]
            part[a, dim + 3] += m0[a]
            part[a, dim] += m1[a]
        else:
            part[a, dim] += m1[a] - m0[a]
        if m1[a] > 0.0:
            part[a, dim + 1] += m1[a]
    return un, m0, m1, ngid, part, edges[:ne]
