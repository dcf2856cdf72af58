"""Contact surfaces for the tests: the facing faces of two blocks, outward segments (dy, -dx) in 2-D,
flat grids of outward quadrilaterals in 3-D."""
import numpy as np


def facing_faces(xa, xb, gap, ya=0.0, tilt=0.0):
    """Side a: the top face y = ya of a block below, nodes at xa (segments run right to left: normal
    +y); side b: the bottom face y = ya + gap + tilt * x of a block above, nodes at xb (left to right:
    normal -y). Returns points, seg_a, seg_b (node ids into points: a's first)."""
    xa, xb = np.asarray(xa, float), np.asarray(xb, float)
    pa = np.stack([xa, np.full_like(xa, ya)], axis=1)
    pb = np.stack([xb, ya + gap + tilt * xb], axis=1)
    na = len(xa)
    seg_a = np.stack([np.arange(1, na), np.arange(0, na - 1)], axis=1)
    seg_b = np.stack([np.arange(0, len(xb) - 1), np.arange(1, len(xb))], axis=1) + na
    return np.concatenate([pa, pb]), seg_a, seg_b


def hat_integrals(x):
    """Integral of each node's hat function over a 1-D mesh with nodes x (sorted)."""
    h = np.diff(x)
    out = np.zeros(len(x))
    out[:-1] += h / 2
    out[1:] += h / 2
    return out


def rotation(t):
    """The 2 x 2 rotation by the angle t (counter-clockwise)."""
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def grid_face(n, z, turn=0.0, up=True):
    """A flat n x n grid of quadrilaterals on [0, 1]^2 at height z; turn: its interior nodes turned
    about the centre (the boundary nodes stay on the square's edges). up: facets with normal +z
    (else -z). Returns points (nn, 3), facets (n^2, 4)."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t, indexing="xy")
    p = np.c_[x.ravel(), y.ravel()]
    inner = (p > 1e-12).all(axis=1) & (p < 1 - 1e-12).all(axis=1)
    p[inner] = 0.5 + (p[inner] - 0.5) @ rotation(turn).T
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    base = (j * (n + 1) + i).ravel()
    quads = np.stack([base, base + 1, base + n + 2, base + n + 1], axis=1)
    return np.c_[p, np.full(len(p), z)], (quads if up else quads[:, ::-1])
