"""Element partition of one mesh over the ranks of the Lagrangian group.

Every rank builds the same global mesh and computes the same partition, so no mesh is sent around.
Cells are ordered along the longest axis of the bounding box (recursive coordinate bisection would
give smaller interfaces; a slab cut is enough for bar- and block-like bodies) and cut into equal
contiguous slabs. Nodes on a cut are shared: their force and mass contributions are summed over the
ranks that touch them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Partition:
    cells: np.ndarray          # global ids of my cells (sorted)
    nodes: np.ndarray          # global ids of my nodes (sorted)
    conn: np.ndarray           # my cells' connectivity in local node numbering
    shared_global: np.ndarray  # global ids of all nodes on a cut (same on every rank, sorted)
    shared_local: np.ndarray   # local index of each shared node I hold
    shared_slot: np.ndarray    # its position in shared_global
    owned: np.ndarray          # bool per local node: I am the lowest rank holding it (for output)


def partition(points: np.ndarray, cells: np.ndarray, nranks: int, rank: int) -> Partition:
    ne = len(cells)
    centroid = points[cells].mean(axis=1)
    axis = int(np.argmax(np.ptp(points, axis=0))) if len(points) else 0
    order = np.argsort(centroid[:, axis], kind="stable")
    owner = np.empty(ne, dtype=np.int64)
    owner[order] = (np.arange(ne) * nranks) // max(ne, 1)

    # lowest rank touching each node, and how many ranks touch it
    nn = len(points)
    node_rank = np.repeat(owner, cells.shape[1])
    flat = cells.ravel()
    pairs = np.unique(flat * nranks + node_rank)
    pair_node = pairs // nranks
    pair_rank = pairs % nranks
    touch_count = np.bincount(pair_node, minlength=nn)
    first_rank = np.full(nn, nranks, dtype=np.int64)
    np.minimum.at(first_rank, pair_node, pair_rank)

    mine = np.flatnonzero(owner == rank)
    my_nodes = np.unique(cells[mine])
    conn = np.searchsorted(my_nodes, cells[mine])
    shared_global = np.flatnonzero(touch_count > 1)
    is_shared = touch_count[my_nodes] > 1
    shared_local = np.flatnonzero(is_shared)
    shared_slot = np.searchsorted(shared_global, my_nodes[shared_local])
    return Partition(
        cells=mine,
        nodes=my_nodes,
        conn=conn.astype(np.int64),
        shared_global=shared_global,
        shared_local=shared_local,
        shared_slot=shared_slot,
        owned=first_rank[my_nodes] == rank,
    )
