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
    (owner pair (k,) non-decreasing, rotated corners (k,3) int32): each pair's surviving faces, those at a
    then those at b, each in the order of its vertex's face list. ``with_dead``: the faces holding both
    endpoints too, after each pair's surviving faces, rotated to start at b. (One compiled pass:
    `face_passes.ring_rows`.)"""
    return faces.ring_rows(P, with_dead)


def gather_groups(faces, P: np.ndarray, pad: int, with_dead: bool = False):
    """Pairs P (K,2) grouped by ring size: yields (indices into P, Rings) per group, smallest rings first.
    Every pair appears in exactly one group. ``with_dead``: see `ring_faces`."""
    owner, rot = ring_faces(faces, P, with_dead)
    yield from group_rings(owner, rot, len(P), pad)


def group_rings(owner: np.ndarray, rot: np.ndarray, K: int, pad: int):
    """Rows rot (k,3) owned by items 0..K-1 (owner (k,) non-decreasing) grouped by how many rows each
    item has: yields (item indices, Rings) per ring size, smallest first; every item is in one group."""
    from .._mesh import face_passes  # compiled loops, imported on first use (the cost models import this)

    counts = np.bincount(owner, minlength=K)
    start = np.cumsum(counts) - counts
    size = np.array([bucket(int(c), lo=RING_MIN) for c in np.unique(counts)]) if K else np.zeros(0, int)
    for R in np.unique(size):
        idx = np.flatnonzero((counts <= R) & (counts > R // 2 if R > RING_MIN else counts <= R))
        if idx.size == 0:
            continue
        yield idx, Rings(*face_passes.pad_rings(rot, start, counts, idx, int(R), int(pad)))
