"""Where to cut the space-filling-curve order of face centroids into parts of at most ``part_faces`` faces.

Codes: each vertex quantized to 21 bits per axis in the bounding box (packed in one uint64), a face's
centroid the mean of its corners' cells, its code the cell's 63-bit Hilbert index (`codes`). Like a
Morton code, each aligned run of 8**k codes is a cube of the octree, which the histograms below rely on.

Cuts come from counts, never from sorting all codes: a histogram over a prefix of the code, then, for
each bin holding more than ``part_faces``, a histogram of its sub-bins (a further pass over the faces),
until every bin fits or is a single code. Bins are then packed greedily in code order into parts; a
single code holding more than ``part_faces`` faces (a pile of coincident centroids) is split by input
order into parts of its own (`Plan.assign`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._mesh.compiled import njit

BITS = 21
_MASK = (1 << BITS) - 1
_REFINE = 12  # sub-bin bits per refinement pass


def quantize(V: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Packed cells (x | y << 21 | z << 42) of float64 (n,3) positions in the box lo..hi."""
    span = hi - lo
    scale = np.divide(float(_MASK), span, out=np.zeros(3), where=span > 0)
    with np.errstate(invalid="ignore"):  # a non-finite vertex gets some cell: it is refused if a face uses it
        cell = np.nan_to_num((V - lo) * scale, nan=0.0, posinf=_MASK, neginf=0.0)
    q = np.clip(np.floor(cell), 0, _MASK).astype(np.uint64)
    return q[:, 0] | q[:, 1] << np.uint64(BITS) | q[:, 2] << np.uint64(2 * BITS)


@njit(cache=True, inline="always")
def _spread(v):
    """The 21 low bits of v moved to every third bit."""
    v = (v | v << np.uint64(32)) & np.uint64(0x1F00000000FFFF)
    v = (v | v << np.uint64(16)) & np.uint64(0x1F0000FF0000FF)
    v = (v | v << np.uint64(8)) & np.uint64(0x100F00F00F00F00F)
    v = (v | v << np.uint64(4)) & np.uint64(0x10C30C30C30C30C3)
    return (v | v << np.uint64(2)) & np.uint64(0x1249249249249249)


_BLOCK = 512  # faces whose codes are made together: each level's loop then runs in SIMD lanes


@njit(cache=True)
def codes(cells, F):
    """Hilbert codes (uint64 < 2**63) of the centroid cells of faces F (int (m,3)) over packed cells:
    Skilling's axes-to-transpose, branch-free, level by level over a block of faces, then interleaved.
    Hilbert rather than Morton order: a run of it is a connected chain of cells, where a Morton run
    jumps between distant ones, so parts cut from it are more compact."""
    n = len(F)
    out = np.empty(n, np.uint64)
    one, zero, three = np.uint64(1), np.uint64(0), np.uint64(3)
    mask, b1, b2 = np.uint64((1 << BITS) - 1), np.uint64(BITS), np.uint64(2 * BITS)
    x, y, z = np.empty(_BLOCK, np.uint64), np.empty(_BLOCK, np.uint64), np.empty(_BLOCK, np.uint64)
    for s in range(0, n, _BLOCK):
        m = min(_BLOCK, n - s)
        for i in range(m):
            a, b, c = cells[F[s + i, 0]], cells[F[s + i, 1]], cells[F[s + i, 2]]
            x[i] = ((a & mask) + (b & mask) + (c & mask)) // three
            y[i] = ((a >> b1 & mask) + (b >> b1 & mask) + (c >> b1 & mask)) // three
            z[i] = ((a >> b2) + (b >> b2) + (c >> b2)) // three
        for k in range(BITS - 1, 0, -1):
            q = np.uint64(k)
            p = (one << q) - one
            for i in range(m):
                xi, yi, zi = x[i], y[i], z[i]
                xi ^= p & (zero - (xi >> q & one))
                on = zero - (yi >> q & one)  # all ones where the bit is set
                xi ^= p & on
                t = (xi ^ yi) & p & ~on
                xi ^= t
                y[i] = yi ^ t
                on = zero - (zi >> q & one)
                xi ^= p & on
                t = (xi ^ zi) & p & ~on
                x[i], z[i] = xi ^ t, zi ^ t
        for i in range(m):
            yi = y[i] ^ x[i]
            zi = z[i] ^ yi
            t = zero
            for k in range(BITS - 1, 0, -1):
                q = np.uint64(k)
                t ^= ((one << q) - one) & (zero - (zi >> q & one))
            out[s + i] = _spread(x[i] ^ t) << np.uint64(2) | _spread(yi ^ t) << one | _spread(zi ^ t)
    return out


class Bins:
    """Disjoint aligned code intervals [start, start + 2**shift) in order, with their face counts."""

    def __init__(self, n_faces: int, part_faces: int):
        # about a thousand bins per part, so that parts come out nearly full and refining is rare
        self.prefix = int(np.clip(np.ceil(np.log2(max(1.0, 1024.0 * n_faces / part_faces))), 3, BITS))
        self.start = np.arange(1 << self.prefix, dtype=np.uint64) << np.uint64(3 * BITS - self.prefix)
        self.shift = np.full(1 << self.prefix, 3 * BITS - self.prefix, np.int64)
        self.count = np.zeros(1 << self.prefix, np.int64)

    def add_prefix(self, c: np.ndarray) -> None:
        """Counts a chunk's codes into the first histogram."""
        self.count += np.bincount((c >> np.uint64(3 * BITS - self.prefix)).astype(np.int64),
                                  minlength=len(self.count))

    def overfull(self, part_faces: int) -> np.ndarray:
        return np.flatnonzero((self.count > part_faces) & (self.shift > 0))

    def refiner(self, part_faces: int) -> "Refiner":
        return Refiner(self, self.overfull(part_faces))


class Refiner:
    """One refinement pass: the sub-bin counts of the overfull bins ``over``."""

    def __init__(self, bins: Bins, over: np.ndarray):
        self.bins, self.over = bins, over
        self.start, self.shift = bins.start[over], bins.shift[over]
        self.sub = np.minimum(self.shift, _REFINE)
        self.offset = np.concatenate([[0], np.cumsum(1 << self.sub)])
        self.count = np.zeros(self.offset[-1], np.int64)

    def add(self, c: np.ndarray) -> None:
        j = np.searchsorted(self.start, c, "right") - 1
        jj = np.maximum(j, 0)
        d = c - self.start[jj]
        inside = (j >= 0) & (d >> self.shift[jj].astype(np.uint64) == 0)
        jj, d = jj[inside], d[inside]
        sub = (d >> (self.shift[jj] - self.sub[jj]).astype(np.uint64)).astype(np.int64)
        self.count += np.bincount(self.offset[jj] + sub, minlength=len(self.count))

    def apply(self) -> None:
        """Replaces the overfull bins by their sub-bins."""
        b, k = self.bins, np.repeat(np.arange(len(self.over)), 1 << self.sub)
        child_shift = (self.shift - self.sub)[k]
        local = np.arange(len(k)) - self.offset[k]
        child_start = self.start[k] + (local.astype(np.uint64) << child_shift.astype(np.uint64))
        keep = np.ones(len(b.start), bool)
        keep[self.over] = False
        start = np.concatenate([b.start[keep], child_start])
        order = np.argsort(start, kind="stable")
        b.start = start[order]
        b.shift = np.concatenate([b.shift[keep], child_shift])[order]
        b.count = np.concatenate([b.count[keep], self.count])[order]


@njit(cache=True)
def _pack(start, shift, count, part_faces):
    """Greedy packing of bins in order: the start code of each part; for each single code holding more
    than part_faces faces, the code and its first part. (Ending parts at coarse cell boundaries instead,
    at the price of fuller parts, gave no fewer border vertices.)"""
    starts = np.empty(len(count) + count.sum() // part_faces + 1, np.uint64)
    ties = np.empty((len(count), 2), np.uint64)
    n, nt, fill = 0, 0, part_faces + 1
    for b in range(len(count)):
        c = count[b]
        if c == 0:
            continue
        if shift[b] == 0 and c > part_faces:
            ties[nt, 0], ties[nt, 1] = start[b], n
            nt += 1
            for _ in range((c + part_faces - 1) // part_faces):
                starts[n] = start[b]
                n += 1
            fill = part_faces + 1  # what follows starts a part of its own
        elif fill + c > part_faces:
            starts[n] = start[b]
            n += 1
            fill = c
        else:
            fill += c
    return starts[:n], ties[:nt]


@dataclass
class Plan:
    """Parts as runs of codes: part p holds the codes from ``starts[p]`` on; a tie code's faces go, in
    input order, ``part_faces`` at a time to its parts from ``tie_part`` on."""

    starts: np.ndarray
    tie_code: np.ndarray
    tie_part: np.ndarray
    part_faces: int

    @classmethod
    def from_bins(cls, bins: Bins, part_faces: int) -> "Plan":
        starts, ties = _pack(bins.start, bins.shift, bins.count, part_faces)
        plan = cls(starts, ties[:, 0].copy(), ties[:, 1].astype(np.int64), part_faces)
        plan.seen = np.zeros(len(ties), np.int64)
        return plan

    @property
    def parts(self) -> int:
        return len(self.starts)

    def assign(self, c: np.ndarray) -> np.ndarray:
        """Parts of a chunk's codes; call with the chunks in input order (tie codes count their faces)."""
        part = np.searchsorted(self.starts, c, "right") - 1
        if len(self.tie_code):
            t = np.minimum(np.searchsorted(self.tie_code, c), len(self.tie_code) - 1)
            at = np.flatnonzero(self.tie_code[t] == c)
            if len(at):
                tid = t[at]
                order = np.argsort(tid, kind="stable")
                ids, first, n = np.unique(tid[order], return_index=True, return_counts=True)
                rank = np.arange(len(at)) - np.repeat(first, n) + np.repeat(self.seen[ids], n)
                part[at[order]] = self.tie_part[tid[order]] + rank // self.part_faces
                self.seen[ids] += n
        return part
