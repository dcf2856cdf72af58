"""solvers/contact/penetration.py: how far surface nodes lie behind another surface, node by node
(segments in 2-D, quadrilaterals in 3-D; self contact without the node's own facets nor the facets
that do not face it)."""
import numpy as np
import pytest

from solvers.contact.penetration import surface_penetration
from solvers.lagrange.mesh import box_mesh, concatenate, ring_mesh
from solvers.lagrange.surface import exterior_facets

T = 0.0045             # the ring's wall (cases/ring_self_contact)
COS = np.cos(np.pi / 200)


def _ring_and_plates(plate_down=0.0):
    """cases/ring_self_contact's bodies (the ring 0.1 mm from each plate): points, [facets, surface
    nodes] of ring, bottom and top; the top plate lowered by ``plate_down``."""
    meshes = [ring_mesh(0.0955, 0.1, 3, 200), box_mesh([-0.18, -0.105], [0.18, -0.1001], [90, 1]),
              box_mesh([-0.18, 0.1001], [0.18, 0.105], [90, 1])]
    mesh, body = concatenate(meshes)
    x = mesh.points.copy()
    top = np.unique(mesh.cells[body == 2])
    x[top, 1] -= plate_down
    first = np.cumsum([0] + [m.num_points for m in meshes])
    parts = []
    for k, m in enumerate(meshes):
        f, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
        parts.append((f + first[k], np.unique(f) + first[k]))
    return x, parts


def test_a_plate_lowered_onto_the_ring_measures_the_overlap():
    """The top plate 0.5 mm down: the ring's top node (0.1 mm below it before) lies 0.4 mm behind
    it (1e-12: the chord of the facet under it is level); the plate's nodes are not behind the ring
    (the ring's top facets are chords: the plate's nodes over them lie 0.4 mm - sagitta in, exactly
    what the ring's side says is the ring's node)."""
    x, (ring, bottom, top) = _ring_and_plates(plate_down=5e-4)
    pen = surface_penetration(x, top[0], ring[1], 1e-3)
    assert pen.max() == pytest.approx(4e-4, abs=1e-12)
    assert np.count_nonzero(pen) >= 1
    assert surface_penetration(x, bottom[0], ring[1], 1e-3).max() == 0.0   # the bottom: 0.1 mm away
    # in place: nothing anywhere
    x0, parts = _ring_and_plates()
    assert surface_penetration(x0, parts[2][0], parts[0][1], 1e-3).max() == 0.0


def test_a_node_beyond_the_depth_or_off_the_facets_is_not_measured():
    """A node 2 mm behind a plate's face with depth 1 mm: not measured (it sits nearer another
    face); 0.5 mm behind: 0.5 mm; beside the plate (projecting outside every facet): 0."""
    x, (ring, _, top) = _ring_and_plates()
    f = top[0]
    pts = np.concatenate([x, [[0.0, 0.1001 + 2e-3], [0.0, 0.1001 + 5e-4], [0.3, 0.1001 + 5e-4]]])
    n = len(x)
    pen = surface_penetration(pts, f, np.array([n, n + 1, n + 2]), 1e-3)
    np.testing.assert_allclose(pen, [0.0, 5e-4, 0.0], atol=1e-15)


def test_self_contact_counts_the_far_wall_not_the_nodes_own_facets():
    """The ring in place, against itself with depth 4 mm (< the 4.5 mm wall): 0 everywhere (every
    node is a corner of the facets at it; the wall's far face is 4.5 mm away). The top inner node
    (id 50) moved to the centre of a cell of the bottom wall's outer layer: behind the bottom's
    inner face by r_c - 0.0955 cos(pi / 200) (the chord under it), 3.75 mm; the outer face 0.75 mm
    under it does not face it (both normals down) and does not count (with it: 0.75 mm, fails).
    With depth 5 mm, more than the wall: a node in place is behind its own wall's far face (facing
    it) by the thickness: depth must stay below it (the contact's capture does)."""
    x, (ring, _, _) = _ring_and_plates()
    f, nodes = ring
    assert surface_penetration(x, f, nodes, 4e-3, own=True).max() == 0.0
    cell = ring_mesh(0.0955, 0.1, 3, 200).cells[150 + 400]
    centre = x[cell].mean(axis=0)
    moved = x.copy()
    moved[50] = centre
    pen = surface_penetration(moved, f, nodes, 4e-3, own=True)
    r_c = np.hypot(*centre)
    assert pen.max() == pytest.approx(r_c - 0.0955 * COS, rel=1e-9)
    assert nodes[np.argmax(pen)] == 50 and np.count_nonzero(pen) == 1
    # the far face is facing (opposite normals) 4.5 mm behind: within depth 5 mm it is measured
    assert surface_penetration(x, f, nodes, 5e-3, own=True).max() == pytest.approx(T * COS, rel=1e-3)


def test_three_dimensional_faces():
    """A 2 x 2 x 1 block's top face (quadrilaterals, normal +z) and points above and below it:
    0.3 mm below -> 0.3 mm; above or outside the face's square -> 0; 0.3 mm below with depth 0.2 mm -> 0."""
    m = box_mesh([0.0, 0.0, 0.0], [1.0, 1.0, 0.5], [2, 2, 1])
    f, _ = exterior_facets(m.cells, m.cell_type, m.num_points, m.points)
    topf = f[np.all(m.points[f][:, :, 2] > 0.49, axis=1)]
    probe = np.array([[0.3, 0.6, 0.5 - 3e-4], [0.3, 0.6, 0.5 + 3e-4], [1.2, 0.6, 0.5 - 3e-4]])
    pts = np.concatenate([m.points, probe])
    ids = np.arange(m.num_points, m.num_points + 3)
    np.testing.assert_allclose(surface_penetration(pts, topf, ids, 1e-3), [3e-4, 0.0, 0.0], atol=1e-15)
    assert surface_penetration(pts, topf, ids, 2e-4).max() == 0.0


def _brute_force(points, facets, nodes, depth):
    """Every node against every facet (no bins): the nearest facet whose plane the node projects
    into the inside of within depth (2-D segments), its depth behind it."""
    out = np.zeros(len(nodes))
    for m, node in enumerate(nodes):
        best = np.inf
        for a, b in facets:
            t = points[b] - points[a]
            n = np.array([t[1], -t[0]]) / np.linalg.norm(t)
            d = (points[node] - 0.5 * (points[a] + points[b])) @ n
            q = points[node] - d * n
            xi = (q - points[a]) @ t / (t @ t)
            if abs(d) <= depth and -1e-9 <= xi <= 1 + 1e-9 and abs(d) < best:
                best, out[m] = abs(d), max(-d, 0.0)
    return out


def test_the_binned_search_finds_what_every_pair_does():
    """A wavy surface of 60 segments and 300 random points within 3 segment lengths of it, depths
    from a tenth of a segment to 4 (one bin holds many facets, or a box spans two bins): the
    binned kernel finds the same nodes behind, at the all-pairs depths to the last bit (2e-16
    relative measured where the compiled kernel fuses multiply-adds and numpy does not)."""
    rng = np.random.default_rng(7)
    s = np.linspace(0.0, 6.0, 61)
    surf = np.stack([s, 0.2 * np.sin(2.0 * s)], axis=1)
    pts = np.concatenate([surf, surf[rng.integers(0, 61, 300)] + rng.uniform(-0.3, 0.3, (300, 2))])
    facets = np.stack([np.arange(1, 61), np.arange(0, 60)], axis=1)      # normal +y: the top face
    nodes = np.arange(61, 361)
    for depth, behind in ((0.01, 1), (0.1, 43), (0.4, 130)):     # (nodes found behind: measured)
        got = surface_penetration(pts, facets, nodes, depth)
        want = _brute_force(pts, facets, nodes, depth)
        np.testing.assert_array_equal(got > 0, want > 0)
        np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
        assert np.count_nonzero(got) == behind
