"""The compiled loops of `pieces.stitch` (numba; imported by it when it runs, so that importing `pieces` stays
light): each vertex's first holder of its global id, read from a table indexed by the id instead of a sort
of the ids, and the faces renumbered in one pass. Integers and copies only: the same arrays as the numpy
expressions they stand for."""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit


@njit(cache=True, nogil=True)
def first_holders(gid, size):
    """(n,) int64: for each vertex, the first vertex (lowest index) with its global id (``gid``: ids in
    [0, size), -1: held by no other, its own), as ``held[first][inverse]`` of ``np.unique(gid[held],
    return_index=True, return_inverse=True)`` gives it."""
    first = np.full(size, -1, np.int64)
    to = np.empty(len(gid), np.int64)
    for i in range(len(gid)):
        g = gid[i]
        if g < 0:
            to[i] = i
            continue
        if first[g] < 0:
            first[g] = i
        to[i] = first[g]
    return to


@njit(cache=True, nogil=True)
def same_positions(V, to, gid):
    """Whether every vertex with a global id (``gid`` >= 0) is where its first holder (``to``) is, bit for
    bit, as ``np.array_equal(V[to[held]], V[held])`` answers (a NaN is not equal, not even to itself)."""
    for i in range(len(to)):
        if gid[i] < 0:
            continue
        j = to[i]
        for k in range(V.shape[1]):
            if not V[j, k] == V[i, k]:
                return False
    return True


@njit(cache=True, nogil=True)
def renumbered(F, to, new):
    """``new[to][F]``: each face's corners as the first holders' new numbers."""
    out = np.empty(F.shape, np.int64)
    for f in range(F.shape[0]):
        for k in range(F.shape[1]):
            out[f, k] = new[to[F[f, k]]]
    return out
