"""Contact surfaces for the tests: the facing faces of two blocks, outward segments (dy, -dx)."""
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
