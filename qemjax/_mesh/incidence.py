"""Vertex -> face incidence on the host (numpy), kept up to date through contractions.

The parallel scheduler asks, every pass, for the faces around a few thousand pairs, and after every round
re-links the faces of the removed vertices. Scanning all faces for that costs a pass over the whole mesh
each time; these lists make both cost what they touch.

Layout: each vertex's faces are one run in a pool (CSR with lazy deletion). A contraction writes the kept
vertex's merged run at the end of the pool and abandons the old runs; a face that dies stays listed at
its other corners, and readers skip it. When the pool is full, the live entries are compacted.
"""
from __future__ import annotations

import numpy as np


def _jit():
    """The compiled loops (`face_passes`), imported on first use: importing the cost models stays light."""
    from . import face_passes

    return face_passes


def _exclusive_cumsum(c: np.ndarray) -> np.ndarray:
    out = np.cumsum(c)
    out -= c
    return out


class FaceLists:
    """The faces F (m,3) of a mesh with n vertices, which of them are alive, and each vertex's faces.

    Face rows never move: a face keeps its index (the input face it continues) until it dies. F must not
    repeat a vertex within a face."""

    def __init__(self, F: np.ndarray, n: int):
        self.F = np.array(F, np.int32)
        m = len(self.F)
        self.alive = np.ones(m, bool)
        self.count = m
        # grouping corners by vertex: a counting sort, compiled
        self.cnt, self.off, self.pool, self.end = _jit().vertex_runs(self.F, n)

    def live(self) -> np.ndarray:
        """(count,3) the live faces, in face order."""
        return self.F.compress(self.alive, axis=0)

    def around(self, verts: np.ndarray):
        """Every live face at each of ``verts`` (k,): (positions into verts, face ids), grouped by
        position in order (a face at two of the vertices appears twice)."""
        return _jit().around(self.alive, self.cnt, self.off, self.pool, np.asarray(verts))

    def remove(self, faces: np.ndarray):
        """Mark faces dead (they stay listed at their corners until those runs are rewritten)."""
        faces = faces[self.alive[faces]]
        self.alive[faces] = False
        self.count -= len(np.unique(faces))

    def contract(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Contract b into a for vertex-disjoint pairs whose faces are disjoint (no face holds endpoints
        of two pairs): faces holding both endpoints die, b's other faces now use a. Returns the faces
        that died."""
        pairs = np.stack([a, b], 1)
        _, kept, (dead, _) = self.touched_with_dead(pairs)
        self.contract_touched(pairs, kept, dead)
        return dead

    def _write(self, verts, w1, f1, w2, f2):
        """New runs for ``verts``: faces f1 then f2, each grouped by their position w1 / w2 in verts
        (non-decreasing), appended at the end of the pool."""
        S = len(verts)
        c1, c2 = np.bincount(w1, minlength=S), np.bincount(w2, minlength=S)
        total = c1 + c2
        k = int(total.sum())
        self.reserve(k)
        start = self.end + _exclusive_cumsum(total)
        p1 = np.arange(len(w1), dtype=np.int64) + (start - _exclusive_cumsum(c1)).take(w1)
        p2 = np.arange(len(w2), dtype=np.int64) + (start + c1 - _exclusive_cumsum(c2)).take(w2)
        self.pool[p1] = f1
        self.pool[p2] = f2
        self.off[verts] = start
        self.cnt[verts] = total
        self.end += k

    def reserve(self, k: int) -> None:
        """Room for k more entries at the pool's end (compacting it first when they would not fit)."""
        if self.end + k > len(self.pool):
            self._compact(k)

    def _compact(self, extra: int):
        """Rewrite every run without its dead faces at the start of the pool, with room for ``extra``
        more entries (the pool grows if the live entries and those do not fit)."""
        verts = np.flatnonzero(self.cnt)
        w, f = self.around(verts)
        counts = np.bincount(w, minlength=len(verts))
        need = len(f) + extra
        if need > len(self.pool) // 2:  # keep room for the runs to come
            self.pool = np.empty(max(2 * need, len(self.pool)), np.int32)
        self.pool[: len(f)] = f
        self.off[verts] = _exclusive_cumsum(counts)
        self.cnt[verts] = counts
        self.end = len(f)

    def touched(self, pairs: np.ndarray):
        """The faces around pairs (S,2) as contracting each b into its a would leave them; the pairs must
        be vertex-disjoint and no face may hold endpoints of two pairs. Faces holding both endpoints of
        their pair (they die) are left out. Returns face ids (k,), the faces before (k,3), the corner
        that moves (k,), the owner pair (k,) and the faces after (k,3), b replaced by a."""
        return self.touched_with_dead(pairs)[0]

    def touched_with_dead(self, pairs: np.ndarray):
        """`touched`, plus what `contract_touched` needs to apply the contractions without looking the
        faces up again: (positions w into pairs.reshape(-1), faces, moving corners) of the surviving
        faces, and (faces, owner pairs) of the faces that die (seen from b's side)."""
        ends = np.ascontiguousarray(pairs).reshape(-1)
        return _jit().touched(self.F, self.alive, self.cnt, self.off, self.pool, ends)

    def ring_rows(self, pairs: np.ndarray, with_dead: bool = False):
        """The ring rows of pairs (K,2) (any pairs, not necessarily disjoint): `face_passes.ring_rows`."""
        ends = np.ascontiguousarray(pairs).reshape(-1)
        return _jit().ring_rows(self.F, self.alive, self.cnt, self.off, self.pool, ends, bool(with_dead))

    def contract_touched(self, pairs: np.ndarray, kept, dead) -> None:
        """`contract` for pairs (S,2) whose faces `touched_with_dead` found (and have not changed since),
        without looking them up again: ``kept`` = (w, f, corner) of the surviving faces, w non-decreasing
        positions into pairs.reshape(-1); ``dead`` = the faces that die."""
        w, f, corner = kept
        a, b = pairs[:, 0], pairs[:, 1]
        self.alive[dead] = False
        self.count -= len(dead)
        at_b = (w & 1).astype(bool)
        wa, wb = w.compress(~at_b) >> 1, w.compress(at_b) >> 1
        mv = f.compress(at_b)
        self.F[mv, corner.compress(at_b)] = a.take(wb).astype(np.int32)
        self._write(a, wa, f.compress(~at_b), wb, mv)
        self.cnt[b] = 0
