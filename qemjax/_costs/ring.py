"""Padded 1-rings of pairs, for cost models that read the faces around a pair (``uses_ring``).

For a pair (a, b), its ring is every live face at a or b that does not hold both: exactly the faces that
survive the contraction, each with one corner moved to the new position. A face is given as its three
vertex ids rotated so that the moving corner comes first, ``[v, c1, c2]``: before the contraction it is
(v, c1, c2), after it (x, c1, c2), with the orientation kept.

Ring sizes vary (about 10 on a regular mesh, hundreds at a high-valence vertex), so pairs are grouped by
the power of two that holds their ring (RING_MIN at least): each group is padded only to its own size,
padding at most doubles a ring, and a run compiles one kernel per (batch shape, ring size) it meets.

With ``with_dead=True`` (models whose ``ring_dead`` is set) the ring also holds the faces that hold both
a and b, which the contraction removes, as rows ``[b, ·, ·]`` (rotated to start at b): a kernel that
replaces both endpoints by x sees them collapse to zero area.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._kernels.batching import bucket

RING_MIN = 16


class Rings(NamedTuple):
    """corners (K,R,3) int32 ``[v, c1, c2]`` per face (padding rows point at vertex ``pad``), mask (K,R)
    bool: which rows are faces."""

    corners: np.ndarray
    mask: np.ndarray


def ring_faces(faces, P: np.ndarray, with_dead: bool = False):
    """The ring faces of pairs P (K,2) (any pairs, not necessarily disjoint) from `FaceLists` ``faces``:
    (owner pair (k,) non-decreasing, rotated corners (k,3) int32). ``with_dead``: the faces holding both
    endpoints too, after each pair's surviving faces, rotated to start at b."""
    (_, G, corner, owner, _), _, (dead, downer) = faces.touched_with_dead(P)
    rows = np.arange(len(G))
    rot = np.stack([G[rows, corner], G[rows, (corner + 1) % 3], G[rows, (corner + 2) % 3]], 1)
    if with_dead and len(dead):
        D = np.take(faces.F, dead, axis=0)
        c = np.argmax(D == np.take(P[:, 1], downer)[:, None], axis=1)
        r = np.arange(len(D))
        D = np.stack([D[r, c], D[r, (c + 1) % 3], D[r, (c + 2) % 3]], 1)
        order = np.argsort(np.concatenate([owner, downer]), kind="stable")
        return np.concatenate([owner, downer])[order], np.concatenate([rot, D])[order].astype(np.int32)
    return owner, rot.astype(np.int32)


def gather_groups(faces, P: np.ndarray, pad: int, with_dead: bool = False):
    """Pairs P (K,2) grouped by ring size: yields (indices into P, Rings) per group, smallest rings first.
    Every pair appears in exactly one group. ``with_dead``: see `ring_faces`."""
    owner, rot = ring_faces(faces, P, with_dead)
    yield from group_rings(owner, rot, len(P), pad)


def group_rings(owner: np.ndarray, rot: np.ndarray, K: int, pad: int):
    """Rows rot (k,3) owned by items 0..K-1 (owner (k,) non-decreasing) grouped by how many rows each
    item has: yields (item indices, Rings) per ring size, smallest first; every item is in one group."""
    counts = np.bincount(owner, minlength=K)
    start = np.cumsum(counts) - counts
    size = np.array([bucket(int(c), lo=RING_MIN) for c in np.unique(counts)]) if K else np.zeros(0, int)
    for R in np.unique(size):
        idx = np.flatnonzero((counts <= R) & (counts > R // 2 if R > RING_MIN else counts <= R))
        if idx.size == 0:
            continue
        corners = np.full((len(idx), R, 3), pad, np.int32)
        mask = np.zeros((len(idx), R), bool)
        c = counts[idx]
        which = np.repeat(np.arange(len(idx)), c)
        slot = np.arange(len(which)) - np.repeat(np.cumsum(c) - c, c)
        src = np.repeat(start[idx], c) + slot
        corners[which, slot] = rot[src]
        mask[which, slot] = True
        yield idx, Rings(corners, mask)
