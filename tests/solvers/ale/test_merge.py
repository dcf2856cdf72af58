"""The small-zone merge's decisions (solvers/ale/merge.py) on a padded 2-D block of 7 x 7 zones (the
real ones 3 x 3 in the middle, two ghost layers): whom a donor merges into, chains through a donor,
a pocket of small zones, and the group totals a target's owner sums."""
from __future__ import annotations

import numpy as np

from solvers.ale.merge import PHI_MERGE, group_totals, merge_targets

N = 7
ZS = np.array([N, 1, 1], np.int64)  # x slow, y fast (the solver's padded layout)
ZDIMS = np.array([N, N, 1], np.int64)


def z(i, j):
    return (i + 2) * N + (j + 2)


def block(small):
    """Every zone open and empty of body (phi 1, b 0) except ``small``: {(i, j): phi} cut by a body
    (b = 1 - phi); masses rho phi V with rho = 1, V = 1."""
    phi, b = np.ones(N * N), np.zeros(N * N)
    for (i, j), f in small.items():
        phi[z(i, j)] = f
        b[z(i, j)] = 1.0 - f
    M = phi.copy()
    return phi, b, M, np.ones(N * N, np.uint8)


def targets(phi, b, M, usable, cand, opened=()):
    code = np.full(N * N, -1.0)
    flags = np.zeros(N * N, np.uint8)
    flags[[z(*c) for c in opened]] = 1
    bad = merge_targets(np.array([z(*c) for c in cand], np.int64), M, phi, b, flags, usable, ZS, 2, PHI_MERGE, code)
    return bad, code


def offset(code, c):
    k = int(code[z(*c)])
    return (k % 5 - 2, (k // 5) % 5 - 2)


def test_a_sliver_merges_into_its_most_open_neighbour_that_does_not_merge():
    """(1, 1) at 0.01 beside (0, 1) at 0.3 (a donor itself), (2, 1) at 0.9 and (1, 2) fully open:
    into (1, 2), the most open; beside a donor at 0.4 and an empty void zone at 0.2 (not cut by a
    body: b = 0, so not a donor), into the void one."""
    phi, b, M, usable = block({(1, 1): 0.01, (0, 1): 0.3, (2, 1): 0.9, (1, 0): 0.0})
    bad, code = targets(phi, b, M, usable, [(1, 1), (0, 1), (2, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (0, 1)
    assert offset(code, (0, 1)) != (1, 0)  # (0, 1) does not pick the sliver
    assert code[z(2, 1)] == -1.0  # 0.9 >= PHI_MERGE: not a donor
    # (1, 2) at 0.4 with material (a donor), (2, 1) at 0.2 empty and no body there (does not merge):
    # into (2, 1)
    phi, b, M, usable = block({(1, 1): 0.01, (0, 1): 0.0, (2, 1): 0.2, (1, 0): 0.0, (1, 2): 0.4})
    M[z(2, 1)] = 0.0
    b[z(2, 1)] = 0.0
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (1, 0)


def test_a_zone_a_body_uncovered_takes_gas_from_a_neighbour_with_some():
    """(1, 1) open 0.3 by a body that moved on, still empty (M = 0): a donor, into its most open
    neighbour with material, (1, 2) at 1.0, not the empty (0, 1) at 1.0 (a void behind the body, b
    0) nor (2, 1) at 0.6 (less open); with only empty neighbours it stays empty (no code, no error);
    the same zone closed (phi 0, M = 0) is no donor."""
    phi, b, M, usable = block({(1, 1): 0.3, (2, 1): 0.6, (1, 0): 0.0})
    M[z(1, 1)] = 0.0
    M[z(0, 1)] = 0.0
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (0, 1)
    M[z(1, 2)] = 0.0
    M[z(2, 1)] = 0.0
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and code[z(1, 1)] == -1.0
    phi, b, M, usable = block({(1, 1): 0.0})
    M[z(1, 1)] = 0.0
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and code[z(1, 1)] == -1.0


def test_a_zone_opened_at_once_shares_with_a_neighbour_though_no_body_covers_it():
    """An eroded element uncovers (1, 1) within one step: the sliver it was (phi 4e-4 at the start,
    its few grams) now spread over the whole open zone (phi 1, b 0).  Flagged by opened_zones it is a
    donor, into its most open neighbour (1, 2) (1.0, not (0, 1), (1, 0), (2, 1) at 0.8, 0.9, 0.6:
    partly covered by the rest of the body); empty, it takes gas the
    same way; unflagged, it is none (no body covers it: the remap's density M / V would stay, 1e-3
    of its neighbours', and its kinetic energy exceed its total: the plate in a shock eroding at
    strain 1e-3 stopped so at step 5)."""
    from solvers.ale.merge import opened_zones

    phi, b, M, usable = block({(2, 1): 0.6, (0, 1): 0.8, (1, 0): 0.9})
    M[z(1, 1)] = 4e-4
    bad, code = targets(phi, b, M, usable, [(1, 1)], opened=[(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (0, 1)
    M[z(1, 1)] = 0.0
    bad, code = targets(phi, b, M, usable, [(1, 1)], opened=[(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (0, 1)
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and code[z(1, 1)] == -1.0
    # which zones are opened at once: a sliver or covered zone left at least twice as open and
    # at or above PHI_MERGE; not a surface's smooth motion (0.45 -> 0.55), nor a sliver that stays one
    old = np.array([4e-4, 0.0, 0.45, 0.2, 0.3, 0.6, 0.0])
    new = np.array([1.0, 0.5, 0.55, 0.45, 0.6, 1.0, 0.0])
    out = np.empty(old.size, np.uint8)
    opened_zones(old, new, PHI_MERGE, out)
    assert out.tolist() == [1, 1, 0, 0, 1, 0, 0]


def test_a_donor_whose_open_neighbours_all_merge_passes_its_content_two_zones_on():
    """(1, 1) covered with material (phi 0, M > 0), its only open neighbour (1, 2) a sliver whose own
    target is (1, 3): the covered zone's code points two zones on, at (1, 3)."""
    phi, b, M, usable = block({(1, 1): 0.0, (0, 1): 0.0, (2, 1): 0.0, (1, 0): 0.0, (1, 2): 0.05,
                               (0, 2): 0.0, (2, 2): 0.0})
    M[z(1, 1)] = 0.2
    bad, code = targets(phi, b, M, usable, [(1, 1), (1, 2)])
    assert bad == -1 and offset(code, (1, 1)) == (0, 2) and offset(code, (1, 2)) == (0, 1)


def test_a_pocket_of_small_zones_keeps_an_open_zone_and_names_a_covered_one():
    """Two slivers with only each other open and no zone within two that keeps its content: the open
    one keeps its content (no code); a covered zone with material whose only open neighbour is such
    a sliver is returned (nowhere to go)."""
    closed = {(i, j): 0.0 for i in range(-2, 5) for j in range(-2, 5)}
    phi, b, M, usable = block({**closed, (1, 1): 0.05, (1, 2): 0.04})
    bad, code = targets(phi, b, M, usable, [(1, 1), (1, 2)])
    assert bad == -1 and code[z(1, 1)] == -1.0 and code[z(1, 2)] == -1.0
    phi, b, M, usable = block({**closed, (1, 1): 0.05, (1, 2): 0.04})
    M[z(2, 1)] = 0.1  # covered, holds material; its only open neighbour is the sliver (1, 1)
    bad, code = targets(phi, b, M, usable, [(2, 1)])
    assert bad == z(2, 1)


def test_a_covered_zone_with_only_corner_neighbours_open_passes_its_content_across_the_corner():
    """(1, 1) covered with material, its four face neighbours covered too (a body's corner closing
    around it), the corner neighbour (2, 2) open: into (2, 2); with the corner a sliver too, into
    the nearest zone within two that keeps its content."""
    shut = {(0, 1): 0.0, (2, 1): 0.0, (1, 0): 0.0, (1, 2): 0.0}
    phi, b, M, usable = block({(1, 1): 0.0, **shut})
    M[z(1, 1)] = 1e-12
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) in {(1, 1), (-1, 1), (1, -1), (-1, -1)}
    closed = {(i, j): 0.0 for i in range(-2, 5) for j in range(-2, 5)}
    phi, b, M, usable = block({**closed, (1, 1): 0.0, (2, 2): 0.05, (3, 3): 0.6, (3, 2): 1.0})
    M[z(1, 1)] = 1e-12
    bad, code = targets(phi, b, M, usable, [(1, 1), (2, 2)])
    assert bad == -1 and offset(code, (1, 1)) == (2, 1)  # (3, 2): nearer than (3, 3)


def test_a_pocket_with_a_keeper_within_two_passes_its_content_there():
    """The penetrator's lip: a sliver (1, 1) whose open face neighbours (2, 1), (1, 2) are slivers
    whose own best neighbour (2, 2) is a sliver as well: the chain finds no target, and the pocket,
    left to keep its content, would be squeezed as its open fraction shrinks (2.8 rho0 in five
    steps at phi 1e-4).  It goes to the nearest zone within two that keeps its content, (2, 3)."""
    closed = {(i, j): 0.0 for i in range(-2, 5) for j in range(-2, 5)}
    phi, b, M, usable = block({**closed, (1, 1): 0.01, (2, 1): 0.02, (1, 2): 0.02, (2, 2): 0.1,
                               (2, 3): 0.6, (3, 3): 1.0})
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (1, 2)
    # with (2, 3) shut as well, (3, 3) at (2, 2) is the nearest
    phi[z(2, 3)], M[z(2, 3)], b[z(2, 3)] = 0.0, 0.0, 1.0
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    assert bad == -1 and offset(code, (1, 1)) == (2, 2)


def test_group_totals_are_the_targets_own_and_its_donors():
    """A real target's mass, energy and open volume: its own plus its donors', in the order given; a
    target outside the real zones gets nothing here (its owner sums it)."""
    phi, b, M, usable = block({(1, 1): 0.01, (1, 0): 0.0, (0, 1): 0.0, (2, 1): 0.0, (3, 1): 0.02})
    e = np.linspace(1.0, 2.0, N * N)
    bad, code = targets(phi, b, M, usable, [(1, 1)])
    code[z(3, 1)] = (1 + 2) + 5 * (0 + 2)  # a ghost-layer donor into the ghost (4, 1)
    real = np.zeros(N * N, np.uint8)
    for i in range(3):
        for j in range(3):
            real[z(i, j)] = 1
    Mg, Eg, Vg = np.zeros(N * N), np.zeros(N * N), np.zeros(N * N)
    donors = np.flatnonzero(code >= 0.0)
    group_totals(donors, code, M, e, phi, np.ones(N * N), real, ZS, ZDIMS, Mg, Eg, Vg)
    t = z(1, 2)
    assert Mg[t] == M[t] + M[z(1, 1)] and Vg[t] == phi[t] + phi[z(1, 1)]
    assert Eg[t] == M[t] * e[t] + M[z(1, 1)] * e[z(1, 1)]
    assert np.count_nonzero(Vg) == 1


def test_groups_that_share_a_node_are_one_component():
    """Edges (a node's group, another group at that node): groups 3-7 and 7-9 join, 20 stays alone;
    each group's component is its smallest id, its mass the sum of the groups' masses; one rank."""
    from solvers.ale.merge import group_components

    ids, comp, mass = group_components(None, np.array([[3, 7], [7, 9]], np.int64),
                                       np.array([3, 7, 9, 20], np.int64), np.array([1.0, 2.0, 4.0, 8.0]))
    assert ids.tolist() == [3, 7, 9, 20] and comp.tolist() == [3, 3, 3, 20]
    assert mass.tolist() == [7.0, 7.0, 7.0, 8.0]


def test_components_are_scipy_csgraph_s_partition():
    """merge._components (union-find, in place of scipy's connected_components, ~1 ms a step on a
    few links) against scipy.sparse.csgraph on 300 random graphs with repeated edges, self-loops
    and isolated vertices: the same partition, numbered in the order of each component's smallest
    vertex."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from solvers.ale.merge import _components

    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(1, 60))
        m = int(rng.integers(0, 80))
        a, b = rng.integers(0, n, m), rng.integers(0, n, m)
        label = _components(n, a, b)
        _, ref = connected_components(coo_matrix((np.ones(m), (a, b)), shape=(n, n)), directed=False)
        assert np.array_equal(label[:, None] == label[None, :], ref[:, None] == ref[None, :])
        first = [int(np.flatnonzero(label == c)[0]) for c in range(label.max() + 1)]
        assert first == sorted(first)
