"""Sums on the nodes of partition cuts in the order one rank adds them (Lagrangian group).

A node on a cut collects contributions (corner forces, corner masses) from elements of several ranks.
Summing each rank's partial sum (an Allreduce) rounds differently from the one-rank assembly, which
adds a node's contributions element by element in global element order: the last bits differ, and in
a coupled run (small cut zones merging or not by a threshold) a last-bit difference grows to 1e-5 of
the velocities within a few hundred steps.  Here every rank instead receives the contributions of all
elements at a cut (a few per cut node, gathered every step) and adds them into its cut nodes from
zero in (global element, corner) order -- the one-rank order -- so any partition gives the one-rank
bits.  Element kernels write the corner values of the elements at a cut into a small array
(``row``: that array's row of a local element, -1 elsewhere).
"""
from __future__ import annotations

import numpy as np


class OrderedSharedSums:
    """The cut elements of this rank, and where every gathered corner value goes."""

    def __init__(self, comm, part, nen: int):
        self.comm = comm
        nn = len(part.nodes)
        is_shared = np.zeros(nn, bool)
        is_shared[part.shared_local] = True
        cut = np.flatnonzero(is_shared[part.conn].any(axis=1))  # local elements with a cut node
        self.row = np.full(len(part.cells), -1, np.int64)
        self.row[cut] = np.arange(cut.size)
        self.ncut = int(cut.size)
        self.nen = nen
        gids = comm.allgather(part.cells[cut])
        nodes = comm.allgather(part.nodes[part.conn[cut]].reshape(-1, nen))
        self.counts = np.array([g.size for g in gids], np.int64)
        gid = np.concatenate(gids)
        gnode = np.concatenate(nodes).ravel()
        corner = np.tile(np.arange(nen), gid.size)
        egid = np.repeat(gid, nen)
        pos = np.minimum(np.searchsorted(part.nodes, gnode), nn - 1)
        mine = (part.nodes[pos] == gnode) & is_shared[pos]
        order = np.lexsort((corner, egid))  # (global element, corner): the one-rank order
        order = order[mine[order]]
        self.take = order            # rows of the gathered (element x corner) values
        self.target = pos[order]     # the local cut node each adds into
        self.shared = part.shared_local

    def buffer(self, k: int) -> np.ndarray:
        """Zeroed (ncut, nen, k) corner values of this rank's cut elements, for a kernel to fill."""
        return np.zeros((self.ncut, self.nen, k))

    def sum_into(self, local: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out[cut nodes] = the ordered sum of every rank's ``local`` (ncut, nen, k) corner values
        (out: (nn, k) or (nn,)); other nodes untouched.  Collective."""
        from mpi4py import MPI

        k = local.shape[2]
        recv = np.empty((int(self.counts.sum()) * self.nen, k))
        self.comm.Allgatherv(np.ascontiguousarray(local).reshape(-1), [recv.reshape(-1), self.counts * self.nen * k,
                                                                        MPI.DOUBLE])
        view = out.reshape(out.shape[0], -1)
        view[self.shared] = 0.0
        np.add.at(view, self.target, recv[self.take])
        return out
