"""The greedy queue in verified batches: the same contractions, in the same order, as one at a time.

One contraction at a time costs a device round trip (merge, then re-price the pairs at the kept vertex)
per contraction, and the pairs it re-prices are rarely the next cheapest: on the cow, 3 % of the pops
take a pair priced by the contraction just before. So the queue runs ahead (*speculates*): it keeps
popping and contracting on the host, with the pairs whose price is out of date (*stale*) held out of the
queue, then merges and re-prices all of them in one device call each, and checks the order: a step
stands if no stale pair held out before it ranks before it (with the queue's own keys, ties included).
The first step that fails and all after it are undone (a journal of every host change) and run again
from the queue with the new prices in it.

A pair is stale over an *interval* of steps: from the step that changed one of its vertices to the next
step that changes one again (or removes the pair), or to the end of the batch. Each interval has its own
price, from the rows as they were then: a kept vertex's new row goes to a scratch row of its own (past
the mesh's rows), so one price call reads each interval's versions of its two rows, and the order check
compares each step with the intervals open at it. A popped pair never has a vertex merged earlier in the
batch (every pair at a kept vertex is stale), so all of a batch's merges read the rows the batch started
from: one merge call. (A pair's price and merge do not depend on which rows or pairs share their kernel
call: the kernels gather rows and are elementwise over pairs, and the outputs match bit for bit.)

The queue is a heap of Python ints, one per entry, that order as the keys (cost, squared length, tie,
a, b) then a stamp (`_entries`): an int compares in one step where a tuple compares field by field.
Pairs are ints a << 32 | b in every dict.

Queue entries are fetched a few dozen ahead and their flip tests run in one numpy pass; a test is used
when its pair comes up unless a contraction since has moved or removed a vertex it read.

For models with pair support, no refresh, no wedges and no ranking weights (`eligible`): a blocked pair
that becomes a candidate again keeps its stored price, which is what re-pricing it would give (its two
vertices' rows have not changed since it was priced). The checks are those of `greedy` (link condition,
vanishing parts, flips with `flips.flips_host`, coincident faces) on Python sets of the faces around
each vertex.
"""
from __future__ import annotations

import bisect
import heapq
from collections import deque
from itertools import chain, repeat
from types import SimpleNamespace
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._mesh import topology as topo
from .._mesh.incidence import FaceLists
from .._kernels import flips
from . import outcome
from .common import DTYPE, bucket, face_normals, set_rows, start_merge, start_price
from .outcome import BUDGET
from .queue import stop_report as _stop

try:  # the C loop behind Counter (CPython); the same counts in Python elsewhere
    from collections import _count_elements
except ImportError:  # pragma: no cover
    def _count_elements(counts, items):
        for x in items:
            counts[x] = counts.get(x, 0) + 1

CONTRACT, BLOCK, STOP = "contract", "block", "stop"
FIRST_BATCH, MAX_BATCH = 16, 256  # speculation depth: doubled after a batch that stands, halved after one that fails
PREFETCH = 64  # queue entries fetched ahead at a time, their flip tests done together
STAMP_BITS = 40  # an entry's lowest bits: its stamp (unique per push, never reused)
_STAMP = (1 << STAMP_BITS) - 1
_PAIR = (1 << 64) - 1
_M32 = 0xFFFFFFFF
REBUILD = 2  # the queue is rebuilt from its current entries when it holds this many times as many entries
OPEN = 1 << 62  # the end of a stale interval still open when the batch ends
_MISSING = object()
_HEAP = object()


def eligible(model, wedges) -> bool:
    """Whether a run can use this module: a pair's price reads only its two vertices' rows."""
    return (wedges is None and model.support == "pair" and model.refresh is None and not model.uses_ring
            and model.rank_weights is None)


def _ties(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """`queue.tie` of many pairs (exact in uint64: the products stay below 2**64 for any vertex index
    below 2**32)."""
    a, b = a.astype(np.uint64), b.astype(np.uint64)
    return ((a * np.uint64(0x9E3779B1)) ^ (b * np.uint64(0x85EBCA77))) & np.uint64(0xFFFFFFFF)


def ordered_bits(v: np.ndarray) -> np.ndarray:
    """float32 values -> uint64 in the same order (-0.0 as 0.0, equal floats equal ints; a NaN ranks
    after +inf, where a tuple of floats has no order at all)."""
    u = (np.asarray(v, np.float32) + np.float32(0.0)).view(np.uint32).astype(np.uint64)
    return np.where(u >> np.uint64(31), ~u & np.uint64(_M32), u | np.uint64(0x80000000))


def _entries(P: np.ndarray, cost: np.ndarray, l2: np.ndarray) -> list:
    """Queue keys of pairs P (K,2) as ints without stamps: (cost, squared length, `queue.tie`, a, b) from
    the highest bits down, the stamp's bits left zero. Ints compare as the tuples of `queue.Queue` do."""
    hi = (ordered_bits(cost) << np.uint64(32)) | ordered_bits(l2)
    pk = (P[:, 0].astype(np.uint64) << np.uint64(32)) | P[:, 1].astype(np.uint64)
    s = STAMP_BITS
    return [(h << (s + 96)) | (t << (s + 64)) | (p << s)
            for h, t, p in zip(hi.tolist(), _ties(P[:, 0], P[:, 1]).tolist(), pk.tolist())]


def entry_pair(e: int) -> tuple[int, int]:
    """(a, b) of a queue entry."""
    return (e >> (STAMP_BITS + 32)) & _M32, (e >> STAMP_BITS) & _M32


class _Step(NamedTuple):
    """One pop of a batch: its queue order (the entry without its stamp), pair, kind, journal mark, what
    it changed."""

    order: int
    a: int
    b: int
    kind: str
    mark: int
    code: int = 0  # BLOCK: the rule it broke
    x: np.ndarray | None = None
    branch: int = 0
    cost: float = 0.0
    parts: np.ndarray | None = None
    faces_left: int = 0
    dead: tuple = ()
    drop: tuple = ()


def simple(F: np.ndarray) -> bool:
    """No face with a repeated corner, no two faces with the same corners. In manifold mode a mesh stays
    so (a contraction removes the faces with both endpoints, and one that would make two faces coincide is
    refused), and the rules take shortcuts that rely on it."""
    Fs = np.sort(np.asarray(F).reshape(-1, 3), axis=1)
    return bool(np.all(Fs[:, 0] != Fs[:, 1]) and np.all(Fs[:, 1] != Fs[:, 2])
                and len(np.unique(Fs, axis=0)) == len(Fs))


class _Mesh:
    """Faces on the host as Python objects, cheap to test and change one contraction at a time: tri[f]
    the corners of face f, at[v] the set of live faces at v, alive[f], and nbr[v] v's pair partners. Sets
    are replaced, never changed in place, so that the journal can keep the old ones."""

    def __init__(self, F: np.ndarray, n: int, pairs: np.ndarray):
        self.tri = [tuple(t) for t in F.tolist()]
        self.alive = [True] * len(F)
        self.count = {"faces": len(F)}
        at = [[] for _ in range(n)]
        for f, (i, j, k) in enumerate(self.tri):
            at[i].append(f)
            at[j].append(f)
            at[k].append(f)
        self.at = [frozenset(s) for s in at]
        nbr = [set() for _ in range(n)]
        for a, b in pairs.tolist():
            nbr[a].add(b)
            nbr[b].add(a)
        self.nbr = [frozenset(s) for s in nbr]
        self.simple = simple(F)

    def corners(self, faces) -> set:
        return set(chain.from_iterable(map(self.tri.__getitem__, faces)))

    def link_ok(self, a: int, b: int, nshared: int) -> bool:
        """`greedy._link_ok` on these sets (same rule, same answers)."""
        return self.link_common(a, b, nshared) is not None

    def link_common(self, a: int, b: int, nshared: int):
        """`link_ok`, giving the common neighbours of a and b (the apexes of their faces) when it holds,
        else None. The corners of a's faces are counted (one C loop), which gives both its neighbours and
        whether it is on a boundary (a neighbour counted once)."""
        if not 1 <= nshared <= 2:
            return None
        tri, at = self.tri, self.at
        ca, cb = {}, {}
        _count_elements(ca, chain.from_iterable(map(tri.__getitem__, at[a])))
        _count_elements(cb, chain.from_iterable(map(tri.__getitem__, at[b])))
        common = (ca.keys() & cb.keys()) - {a, b}
        if len(common) != nshared:
            return None
        if nshared == 2:
            del ca[a], cb[b]
            if 1 in ca.values() and 1 in cb.values():  # both on a boundary
                return None
            for c in common:
                # k distinct faces at c need k <= C(d, 2) of its d neighbours: 4 faces or more, 4 or more
                if (len(at[c]) <= 3 or not self.simple) and len(self.corners(at[c])) - 1 <= 3:
                    return None
        return common

    def coincident_drop(self, a, b, ka, kb) -> list:
        """Faces the contraction would make coincide and drop (`topo.coincident_removals`, faces in index
        order): none unless two faces around the pair end with the same three corners."""
        tri = self.tri
        seen = {tuple(sorted(tri[f])) for f in ka}
        seen.update(tuple(sorted(_moved(tri[f], b, a))) for f in kb)
        if len(seen) == len(ka) + len(kb):
            return []
        fids = sorted(ka | kb)
        after = [tri[f] if f in ka else _moved(tri[f], b, a) for f in fids]
        gone = topo.coincident_removals(np.array(after, np.int64).reshape(-1, 3))
        return [f for f, g in zip(fids, gone) if g]

    def coincide(self, a, b, ka, kb, common) -> bool:
        """Whether contracting b into a would make two faces coincide (`coincident_drop` is not empty),
        on a `simple` mesh where the link rule holds (``common``: its common neighbours): only faces
        (a, u, w) and (b, u, w) can, u and w then both common neighbours."""
        if len(common) != 2:
            return False
        u, w = common
        uw = self.at[u] & self.at[w]
        return not uw.isdisjoint(ka) and not uw.isdisjoint(kb)

    def output(self, n: int) -> FaceLists:
        """The faces as a `FaceLists` (what the run returns and `queue.stop_report` reads)."""
        faces = FaceLists(np.array(self.tri, np.int32).reshape(-1, 3), n)
        faces.alive = np.array(self.alive, bool)
        faces.count = self.count["faces"]
        return faces


def _moved(t: tuple, b: int, a: int) -> tuple:
    return (a if t[0] == b else t[0], a if t[1] == b else t[1], a if t[2] == b else t[2])


class _Blocked(dict):
    """{pair: rule} of the blocked pairs, and ``at`` {vertex: how many blocked pairs it is in}, kept
    through every change (the journal's undo included), so that finding the blocked pairs around a vertex
    looks only at vertices that have some."""

    def __init__(self):
        super().__init__()
        self.at = {}

    def _count(self, p, d):
        at = self.at
        for v in (p >> 32, p & _M32):
            c = at.get(v, 0) + d
            if c:
                at[v] = c
            else:
                del at[v]

    def __setitem__(self, p, code):
        if p not in self:
            self._count(p, 1)
        super().__setitem__(p, code)

    def __delitem__(self, p):
        super().__delitem__(p)
        self._count(p, -1)

    def pop(self, p, *default):
        if p in self:
            self._count(p, -1)
            return super().pop(p)
        if default:
            return default[0]
        raise KeyError(p)


class _Prices:
    """One push's prices, kept as arrays and lists (a pair's entry in ``placed`` is (this, its index)):
    x (K,3) float32, branch, cost and queue keys (without stamps) as lists, parts (p,K)."""

    __slots__ = ("x", "branch", "cost", "parts", "keys")

    def __init__(self, priced, keys):
        self.x, self.branch, self.cost, self.parts = priced.x, priced.branch.tolist(), priced.cost.tolist(), priced.parts
        self.keys = keys


class _Batches:
    """The run's state and its batch loop (`run`). Queue: ``heap`` of int entries, ``cur`` {pair: its
    current entry}, ``placed`` {pair: (x, branch, cost, parts, entry without stamp)}, ``blocked``
    {pair: rule}; pairs are ints a << 32 | b."""  # placed: {pair: (_Prices, index)}

    def __init__(self, V, S, F, pairs, target, model, options, progress):
        n = len(V)
        self.n, self.target, self.model, self.options, self.progress = n, target, model, options, progress
        self.params = model.kernel_params()
        self.scratch = n + 1  # a batch's merged rows go to rows scratch.. (row n stays zero)
        self.VQ = np.zeros((bucket(n + 1 + MAX_BATCH), 3 + model.width), DTYPE)
        self.VQ[:n, :3], self.VQ[:n, 3:] = V, S
        self.VQd = jnp.asarray(self.VQ)
        self.N0 = face_normals(np.asarray(V, DTYPE), F).astype(DTYPE)  # each input face's normal
        self.mesh = _Mesh(F, n, pairs)
        self.heap, self.cur, self.placed, self.blocked = [], {}, {}, _Blocked()
        self.stamp = 0
        self.log = []  # the journal: (container, key, old value or _MISSING); (_HEAP, None, entry) per pop
        self.history, self.history_parts = [], []
        self.removed_at = np.full(len(F), -1, np.int64)
        self.coincident = np.zeros(len(F), bool)
        self.rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
        self.branches = np.zeros(len(model.branches), np.int64)
        self.max_cost_used = 0.0
        self.stop = None
        self.depth = FIRST_BATCH
        self.batches = self.failed = 0

    @property
    def q(self):
        """The queue as `queue.stop_report` reads it: placed and blocked keyed by (a, b)."""
        pair = lambda p: (p >> 32, p & _M32)  # noqa: E731
        return SimpleNamespace(placed={pair(p): (None, None, blk.cost[k]) for p, (blk, k) in self.placed.items()},
                               blocked={pair(p): c for p, c in self.blocked.items()})

    # pricing ---------------------------------------------------------------------------------------

    def push_all(self, pairs):
        P = np.unique(np.asarray(pairs, np.int64).reshape(-1, 2), axis=0)  # rows in order, as sorted tuples
        P = P[P[:, 0] != P[:, 1]]
        if len(P):
            d = self.VQ[P[:, 0], :3] - self.VQ[P[:, 1], :3]
            priced = start_price(self.model, self.VQd, P, self.params, None, self.n)()
            self.push(P, priced, np.einsum("ij,ij->i", d, d))

    def push(self, P, priced, l2, keys=None):
        """Into the queue: pairs P (K,2) with their prices (stamps in order, as `queue.Queue.push`),
        heapifying when it adds more entries than the queue holds (the first push: every pair).
        ``keys``: their `_entries`, when known."""
        keys = _entries(P, priced.cost, l2) if keys is None else keys
        s0 = self.stamp
        self.stamp += len(keys)
        entries = [k | s for k, s in zip(keys, range(s0 + 1, s0 + 1 + len(keys)))]
        pks = ((P[:, 0] << 32) | P[:, 1]).tolist()
        self.cur.update(zip(pks, entries))
        blk = _Prices(priced, keys)
        self.placed.update(zip(pks, zip(repeat(blk), range(len(keys)))))
        blocked = self.blocked
        if blocked:
            for p in pks:
                if p in blocked:
                    blocked.pop(p)
        heap = self.heap
        if len(entries) > len(heap):
            heap.extend(entries)
            heapq.heapify(heap)
        else:
            push = heapq.heappush
            for e in entries:
                push(heap, e)

    # one pop ---------------------------------------------------------------------------------------

    def check(self, a: int, b: int, x, flipped=None):
        """The first rule contracting b into a at x breaks (or None), and the faces it would change:
        (code, (dead, kept at a, kept at b, drop)). ``flipped``: the flip test's answer when known."""
        mesh, opt = self.mesh, self.options
        manifold = opt.preserve_topology
        A, B = mesh.at[a], mesh.at[b]
        dead = A & B
        nshared = len(dead)
        left = mesh.count["faces"] - nshared
        if left < self.target:
            return BUDGET, None
        if manifold:
            common = mesh.link_common(a, b, nshared)
            if common is None:
                return outcome.TOPOLOGY, None
        ka, kb = A - dead, B - dead
        if manifold and opt.keep_parts and not (ka or kb):  # its faces are all its part has left
            return outcome.PART, None
        if ka or kb:
            if flipped is None:
                flipped = self.flip_tests([(a, b, x, ka, kb)])[0]
            if flipped:
                return outcome.FLIP, None
        if manifold and mesh.simple:
            if mesh.coincide(a, b, ka, kb, common):
                return outcome.COINCIDENT, None
            return None, (dead, ka, kb, [])
        drop = mesh.coincident_drop(a, b, ka, kb)
        if drop and (manifold or left - len(drop) < self.target):
            return (outcome.COINCIDENT if manifold else BUDGET), None
        return None, (dead, ka, kb, drop)

    def flip_tests(self, tests) -> list[bool]:
        """`flips.flips_host` for several contractions at once, one numpy pass over all their faces:
        tests = [(a, b, x, faces kept at a, faces kept at b)]. Returns one bool per test."""
        tri, rows, verts, counts, X = self.mesh.tri, [], [], [], []
        for a, b, x, ka, kb in tests:
            rows.extend(ka)
            rows.extend(kb)
            verts += (a, b)
            counts += (len(ka), len(kb))
            X.append(x)
        if not rows:
            return [False] * len(tests)
        G = np.fromiter(chain.from_iterable(map(tri.__getitem__, rows)), np.int64, 3 * len(rows)).reshape(-1, 3)
        counts = np.array(counts).reshape(-1, 2)
        per_test = counts.sum(1)
        corner = np.argmax(G == np.repeat(np.array(verts), counts.reshape(-1))[:, None], axis=1)
        owner = np.repeat(np.arange(len(tests)), per_test)
        bad = flips.flips_host_faces(self.VQ, self.N0, G, np.array(rows), corner,
                                     np.repeat(np.array(X, DTYPE), per_test, axis=0), self.options.cos_max)
        return np.bincount(owner, weights=bad, minlength=len(tests)).astype(bool).tolist()

    def contract(self, a: int, b: int, x, faces):
        """Contract b into a at x on the host (journaled); its pairs at b are gone, those at a stale."""
        mesh, log, step = self.mesh, self.log, len(self.steps)
        at, tri, alive, nbr = mesh.at, mesh.tri, mesh.alive, mesh.nbr
        dead, ka, kb, drop = faces
        for f in dead:
            log.append((alive, f, True))
            alive[f] = False
            for c in tri[f]:
                if c != a and c != b:
                    log.append((at, c, at[c]))
                    at[c] = at[c] - {f}
        for f in kb:
            t = tri[f]
            log.append((tri, f, t))
            tri[f] = (a if t[0] == b else t[0], a if t[1] == b else t[1], a if t[2] == b else t[2])
        log.append((at, a, at[a]))
        at[a] = ka | kb
        log.append((at, b, at[b]))
        at[b] = frozenset()
        for f in drop:
            log.append((alive, f, True))
            alive[f] = False
            for c in tri[f]:
                log.append((at, c, at[c]))
                at[c] = at[c] - {f}
        count = mesh.count
        log.append((count, "faces", count["faces"]))
        count["faces"] -= len(dead) + len(drop)
        VQ = self.VQ
        old = VQ[a].copy()
        log.append((VQ, a, old))
        self.orig[a] = old
        VQ[a, :3] = x
        slot = self.scratch + self.contracted  # a's row from now on (this batch): its scratch row
        VQ[slot, :3] = x
        ver = self.ver
        ver[a] = slot
        # pair partners: b's become a's; pairs at b are gone, each's stale interval (if any) ends here
        held, gone, iv = self.held, self.gone, self.iv
        nb = nbr[b]
        B, just_b, a_for_b = b, frozenset((b,)), frozenset((a, b))
        for w in nb:
            if w != a:
                nw = nbr[w]
                log.append((nbr, w, nw))
                nbr[w] = nw - just_b if a in nw else nw ^ a_for_b  # (b is one of w's partners)
            p = (w << 32 | B) if w < B else (B << 32 | w)
            gone[p] = step
            i = held.pop(p, None)
            if i is not None:
                iv.end[i] = step
        log.append((nbr, a, nbr[a]))
        ring = nbr[a] = (nbr[a] | nb) - {a, b}
        log.append((nbr, b, nb))
        nbr[b] = frozenset()
        # the pairs at a need new prices: held out of the queue, a new stale interval each
        blocked = self.blocked
        for w in ring:
            if a < w:
                p, va, vb = a << 32 | w, slot, ver.get(w, w)
            else:
                p, va, vb = w << 32 | a, ver.get(w, w), slot
            i = held.get(p)
            if i is not None:
                iv.end[i] = step
            held[p] = len(iv.pair)
            iv.pair.append(p)
            iv.start.append(step)
            iv.end.append(OPEN)
            iv.rows += (va, vb)
            if p in blocked:
                log.append((blocked, p, blocked.pop(p)))
        # blocked pairs around a may have become valid: back in the queue at their stored price
        bat = blocked.at
        if bat:
            for u in ring:
                if u in bat:
                    for w in nbr[u]:
                        p = (u << 32 | w) if u < w else (w << 32 | u)
                        if p in blocked and p not in gone:
                            self.unblock(p)

    def unblock(self, p):
        """Back in the queue at its stored price (its vertices' rows are those it was priced with)."""
        log = self.log
        log.append((self.blocked, p, self.blocked.pop(p)))
        self.stamp += 1
        blk, k = self.placed[p]
        e = blk.keys[k] | self.stamp
        cur = self.cur
        log.append((cur, p, cur.get(p, _MISSING)))
        cur[p] = e
        heapq.heappush(self.heap, e)

    # a batch ---------------------------------------------------------------------------------------

    def live(self, e) -> bool:
        """Whether a queue entry is current; pops and forgets one that is not (journaled when undoing
        this batch's steps could make it current again)."""
        p = (e >> STAMP_BITS) & _PAIR
        if self.cur.get(p) != e or p in self.blocked:  # an old entry: never current again
            return False
        if p in self.held or p in self.gone:  # current again if this batch's step is undone
            self.log.append((_HEAP, None, e))
            return False
        return True

    def prefetch(self, want: int):
        """Move the queue's next ``want`` live entries to ``ahead``, with their flip tests from one numpy
        pass, the vertices those read, and the contraction count then (a test stays right while no
        contraction since has moved or removed one of those vertices)."""
        heap, cur, mesh, new = self.heap, self.cur, self.mesh, []
        pop, live = heapq.heappop, self.live
        while heap and len(new) < want:
            e = pop(heap)
            if cur.get((e >> STAMP_BITS) & _PAIR) == e and live(e):  # (most are old: cheap test first)
                new.append(e)
        tests, reads = [], []
        at, placed, nbr = mesh.at, self.placed, mesh.nbr
        for e in new:
            p = (e >> STAMP_BITS) & _PAIR
            a, b = p >> 32, p & _M32
            A, B = at[a], at[b]
            dead = A & B
            blk, k = placed[p]
            tests.append((a, b, blk.x[k], A - dead, B - dead))
            reads.append(nbr[a] | nbr[b])  # the corners of a's and b's faces, and perhaps more
        self.moved = set()  # vertices moved or removed since (ahead is empty when this runs)
        for e, flipped, r in zip(new, self.flip_tests(tests), reads):
            self.ahead.append((e, flipped, r))

    def next_entry(self):
        """The next live entry, from ``ahead`` or the queue, whichever ranks first (an unblocked pair can
        enter the queue before what was fetched ahead), and its flip test if known; (None, None) if none.
        Not removed yet."""
        heap, cur, ahead, live = self.heap, self.cur, self.ahead, self.live
        while True:
            while heap:
                e = heap[0]
                if cur.get((e >> STAMP_BITS) & _PAIR) == e and live(e):
                    break
                heapq.heappop(heap)
            if not ahead:
                if not heap:
                    return None, None
                self.prefetch(min(PREFETCH, max(1, self.depth - len(self.steps))))
                continue
            entry, flipped, reads = ahead[0]
            if not live(entry):
                ahead.popleft()
                continue
            if heap and heap[0] < entry:
                return heap[0], None
            if not reads.isdisjoint(self.moved):
                flipped = None  # a contraction since changed what the test read
            return entry, flipped

    def speculate(self):
        """Pop and apply up to ``depth`` steps on the host (into ``steps``). Pairs the steps stale are
        ``held`` out of the queue, pairs they remove are ``gone``: {pair: step index} each."""
        mesh, log, opt, placed, steps = self.mesh, self.log, self.options, self.placed, self.steps
        count, ahead = mesh.count, self.ahead
        while count["faces"] > self.target and len(steps) < self.depth:
            e, flipped = self.next_entry()
            if e is None:
                break
            order = e >> STAMP_BITS
            p = order & _PAIR
            a, b = p >> 32, p & _M32
            blk, k = placed[p]
            cost = blk.cost[k]
            if cost > opt.max_cost:  # left in the queue: the stop report counts it
                steps.append(_Step(order, a, b, STOP, len(log)))
                break
            mark = len(log)
            if ahead and ahead[0][0] is e:
                ahead.popleft()
            else:
                heapq.heappop(self.heap)
            log.append((_HEAP, None, e))
            x = blk.x[k]
            code, faces = self.check(a, b, x, flipped)
            if code is not None:
                log.append((self.blocked, p, _MISSING))
                self.blocked[p] = code
                steps.append(_Step(order, a, b, BLOCK, mark, code=code))
                continue
            self.contract(a, b, x, faces)
            self.contracted += 1
            self.moved.update((a, b))
            steps.append(_Step(order, a, b, CONTRACT, mark, x=x, branch=blk.branch[k], cost=cost, parts=blk.parts[:, k],
                               faces_left=count["faces"], dead=faces[0], drop=faces[3]))
        for entry, *_ in ahead:  # fetched but not taken: back in the queue (never journaled)
            heapq.heappush(self.heap, entry)
        ahead.clear()

    def price_intervals(self, rows):
        """Prices and queue keys of the stale intervals, each from its own versions of its two rows:
        the device rows with the batch's merged ``rows`` in the scratch rows."""
        iv = self.iv
        ids = np.array(iv.rows, np.int64).reshape(-1, 2)
        VQd = set_rows(self.VQd, self.scratch + np.arange(len(rows)), rows, size=MAX_BATCH) if len(rows) \
            else self.VQd
        priced = start_price(self.model, VQd, ids, self.params, None, self.n)()
        pos = self.VQ[ids.reshape(-1), :3]  # host scratch rows hold the merged positions
        if self.orig:  # rows a later step of the batch changed: the positions from before
            first = ids.reshape(-1)
            for k in np.flatnonzero(np.isin(first, np.fromiter(self.orig, np.int64, len(self.orig)))).tolist():
                pos[k] = self.orig[int(first[k])][:3]
        pos = pos.reshape(-1, 2, 3)
        d = np.ascontiguousarray(pos[:, 0]) - np.ascontiguousarray(pos[:, 1])
        l2 = np.einsum("ij,ij->i", d, d)
        pk = np.array(iv.pair, np.int64)
        P = np.stack([pk >> 32, pk & _M32], 1)
        return VQd, priced, l2, P, _entries(P, priced.cost, l2)

    def first_wrong(self, orders, keys) -> int:
        """Index of the first step that a stale interval open at it (begun before it, not ended before
        it) would have preceded."""
        start, end, h, i = self.iv.start, self.iv.end, [], 0
        for k, o in enumerate(orders):
            while i < len(start) and start[i] < k:
                heapq.heappush(h, (keys[i], end[i]))
                i += 1
            while h and h[0][1] < k:
                heapq.heappop(h)
            if h and h[0][0] < o:
                return k
        return len(orders)

    def batch(self):
        if len(self.heap) > REBUILD * len(self.cur) + PREFETCH:  # mostly old entries: keep the current ones
            blocked = self.blocked
            self.heap = [e for p, e in self.cur.items() if p not in blocked]
            heapq.heapify(self.heap)
        self.steps, self.held, self.gone, self.iv = [], {}, {}, SimpleNamespace(pair=[], start=[], end=[], rows=[])
        self.ahead, self.moved, self.contracted, self.ver, self.orig = deque(), set(), 0, {}, {}
        self.speculate()
        steps = self.steps
        contracted = [s for s in steps if s.kind == CONTRACT]
        rows = np.zeros((0, self.VQ.shape[1]), DTYPE)
        if contracted:
            P = np.array([(s.a, s.b) for s in contracted], np.int64)
            X = np.array([s.x for s in contracted], DTYPE)
            merged = start_merge(self.model, self.VQd, P, X, self.params)()
            rows = np.concatenate([X, merged], 1)
        VQd, priced, l2, P, keys = self.VQd, None, None, None, []
        if self.iv.pair:
            VQd, priced, l2, P, keys = self.price_intervals(rows)
        ok = self.first_wrong([s.order for s in steps], [k >> STAMP_BITS for k in keys])
        self.batches += 1
        if ok < len(steps):
            self.failed += 1
            self.depth = max(1, self.depth // 2)
            self.undo(steps[ok].mark)
        elif len(steps) == self.depth:
            self.depth = min(MAX_BATCH, 2 * self.depth)
        self.log.clear()
        m = sum(1 for s in steps[:ok] if s.kind == CONTRACT)  # the merged rows of the steps that stand
        if m:
            kept = np.array([s.a for s in contracted[:m]], np.int64)
            self.VQ[kept, 3:] = rows[:m, 3:]
            VQd = set_rows(VQd, kept, rows[:m], size=MAX_BATCH)
        self.VQd = VQd
        self.commit(steps[:ok], ok, priced, l2, P, keys)

    def undo(self, mark: int):
        heap, push = self.heap, heapq.heappush
        for c, k, old in reversed(self.log[mark:]):
            if c is _HEAP:
                push(heap, old)
            elif old is _MISSING:
                del c[k]
            else:
                c[k] = old
        del self.log[mark:]

    def commit(self, steps, ok, priced, l2, P, keys):
        cur, placed, blocked = self.cur, self.placed, self.blocked
        gone = self.gone.keys() if ok == len(self.steps) else {p for p, i in self.gone.items() if i < ok}
        for p in gone:
            cur.pop(p, None)
            placed.pop(p, None)
            if p in blocked:
                del blocked[p]
        # each pair's last interval that began in a step that stands (intervals are in order of start)
        cut = bisect.bisect_left(self.iv.start, ok)
        last = dict(zip(self.iv.pair[:cut], range(cut)))
        for p in gone:
            last.pop(p, None)
        if last:
            keep = np.fromiter(last.values(), np.int64, len(last))
            sub = priced._replace(x=priced.x[keep], cost=priced.cost[keep], branch=priced.branch[keep],
                                  parts=priced.parts[:, keep])
            self.push(P[keep], sub, l2[keep], [keys[k] for k in last.values()])
        self.record([s for s in steps if s.kind == CONTRACT])
        for s in steps:
            if s.kind == BLOCK:
                if s.code != BUDGET:
                    self.rejected_by[s.code] += 1
            elif s.kind == STOP:
                self.stop = "max_error"

    def record(self, steps):
        """The history of contraction steps that stand, in order."""
        history, progress, parts = self.history, self.progress, len(self.model.parts)
        faces, at, drops, drop_at, branches = [], [], [], [], []
        for s in steps:
            step = len(history)
            history.append((s.a, s.b, s.x, s.cost))  # (x: a row of its price block; History copies it)
            branches.append(s.branch)
            if s.cost > self.max_cost_used:
                self.max_cost_used = s.cost
            if parts:  # with the rank it was taken at (with no ranking weights: its cost)
                self.history_parts.append(np.append(s.parts, s.cost))
            faces.extend(s.dead)
            at.extend([step] * len(s.dead))
            if s.drop:
                drops.extend(s.drop)
                drop_at.extend([step] * len(s.drop))
            if progress is not None:
                progress(s.faces_left)
        if steps:
            self.removed_at[faces] = at
            self.branches += np.bincount(np.array(branches, np.int64), minlength=len(self.branches))
        if drops:
            self.removed_at[drops] = drop_at
            self.coincident[drops] = True

    def loop(self):
        while self.stop is None and self.mesh.count["faces"] > self.target and self.heap:
            self.batch()


def run(V, S, F, pairs, target_faces, model, options, progress):
    """`greedy.run` for an `eligible` model; pairs (k,2): the candidate pairs (edges and extra pairs,
    each row sorted). Same return."""
    r = _Batches(V, S, F, pairs, target_faces, model, options, progress)
    r.push_all(pairs)
    r.loop()
    faces = r.mesh.output(len(V))
    stop, blocked = r.stop, {}
    if faces.count > target_faces:
        stop, blocked = _stop(faces, r.q, options, target_faces, stop)
    nparts = len(model.parts)
    return outcome.Outcome(
        r.VQ[:len(V), :3], r.VQ[:len(V), 3:], faces.F, faces.alive, outcome.History.of(r.history),
        stop or "target", blocked,
        outcome.count_reasons(np.repeat(np.arange(len(r.rejected_by)), r.rejected_by)),
        rejected=int(r.rejected_by.sum()), rounds=len(r.history), worst_cost=r.max_cost_used,
        branches=r.branches, parts=np.array(r.history_parts, np.float64).reshape(-1, nparts + 1) if nparts else None,
        history_rounds=np.arange(len(r.history), dtype=np.int64), removed_at=r.removed_at,
        coincident=r.coincident)

