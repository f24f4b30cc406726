"""The greedy queue in verified batches: the same contractions, in the same order, as one at a time.

One contraction at a time costs a device round trip (merge, then re-price the pairs at the kept vertex)
per contraction, and the pairs it re-prices are rarely the next cheapest: on the cow, 3 % of the pops
take a pair priced by the contraction just before. So the queue runs ahead (*speculates*): it keeps
popping and contracting on the host, with the pairs whose price is out of date (*stale*) held out of the
queue, then merges and re-prices all of them in one device call each, and checks the order: a step
stands if no stale pair held out before it ranks before it (with the queue's own keys, ties included).
The first step that fails and all after it are undone (a journal of every host change) and run again
from the queue with the new prices in it. A step that would change a vertex whose state a stale pair
reads waits for the next batch, so each stale pair has one price per batch, computed from the rows the
step that staled it left. (A pair's price and merge do not depend on which other pairs share their
kernel call: the kernels are elementwise over pairs, and the outputs match bit for bit.)

Queue entries are fetched a few dozen ahead and their flip tests run in one numpy pass; a test is used
when its pair comes up unless a contraction since has moved or removed a vertex it read.

For models with pair support, no refresh, no wedges and no ranking weights (`eligible`): a blocked pair
that becomes a candidate again keeps its stored price, which is what re-pricing it would give (its two
vertices' rows have not changed since it was priced). The checks are those of `greedy` (link condition,
vanishing parts, flips with `flips.flips_host`, coincident faces) on Python sets of the faces around
each vertex.
"""
from __future__ import annotations

import heapq
from collections import deque
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._mesh import topology as topo
from .._mesh.incidence import FaceLists
from .._kernels import flips
from . import outcome
from .common import DTYPE, bucket, face_normals, set_rows, start_merge, start_price
from .outcome import BUDGET
from .queue import Queue as _Queue, stop_report as _stop, tie as _tie

CONTRACT, BLOCK, STOP = "contract", "block", "stop"
FIRST_BATCH, MAX_BATCH = 16, 256  # speculation depth: doubled after a batch that stands, halved after one that fails
PREFETCH = 32  # queue entries fetched ahead at a time, their flip tests done together
BLOCKED_SCAN = 64  # up to this many blocked pairs, find those around a vertex among them (else among its pairs)
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


class _Journal:
    """Undo log of host changes during a batch: (container, key, old value) per change."""

    def __init__(self, heap):
        self.log, self.heap = [], heap

    def put(self, c: list, k: int, v):
        """c[k] = v, remembering the old value."""
        self.log.append((c, k, c[k]))
        c[k] = v

    def put_d(self, d: dict, k, v):
        """d[k] = v, remembering the old value (or its absence)."""
        self.log.append((d, k, d.get(k, _MISSING)))
        d[k] = v

    def drop(self, d: dict, k):
        if k in d:
            self.log.append((d, k, d.pop(k)))

    def row(self, A: np.ndarray, i: int):
        self.log.append((A, i, A[i].copy()))

    def popped(self, entry):
        self.log.append((_HEAP, None, entry))

    def undo(self, mark: int):
        for c, k, old in reversed(self.log[mark:]):
            if c is _HEAP:
                heapq.heappush(self.heap, old)
            elif old is _MISSING:
                del c[k]
            else:
                c[k] = old
        del self.log[mark:]


class _Step(NamedTuple):
    """One pop of a batch: its queue tuple (key, l2, tie, a, b), kind, journal mark, what it changed."""

    order: tuple
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

    def corners(self, faces) -> set:
        out = set()
        for f in faces:
            out.update(self.tri[f])
        return out

    def on_boundary(self, v: int) -> bool:
        """Whether v has an edge with one face: a neighbour seen in only one of v's faces."""
        once, twice = set(), set()
        for f in self.at[v]:
            for c in self.tri[f]:
                if c != v:
                    (twice if c in once else once).add(c)
        return len(once) > len(twice)

    def link_ok(self, a: int, b: int, nshared: int) -> bool:
        """`greedy._link_ok` on these sets (same rule, same answers)."""
        if not 1 <= nshared <= 2:
            return False
        common = (self.corners(self.at[a]) & self.corners(self.at[b])) - {a, b}
        if len(common) != nshared:
            return False
        if nshared == 2:
            if self.on_boundary(a) and self.on_boundary(b):
                return False
            for c in common:
                if len(self.corners(self.at[c])) - 1 <= 3:
                    return False
        return True

    def output(self, n: int) -> FaceLists:
        """The faces as a `FaceLists` (what the run returns and `queue.stop_report` reads)."""
        faces = FaceLists(np.array(self.tri, np.int32).reshape(-1, 3), n)
        faces.alive = np.array(self.alive, bool)
        faces.count = self.count["faces"]
        return faces


def _moved(t: tuple, b: int, a: int) -> tuple:
    return (a if t[0] == b else t[0], a if t[1] == b else t[1], a if t[2] == b else t[2])


class _Batches:
    """The run's state and its batch loop (`run`)."""

    def __init__(self, V, S, F, pairs, target, model, options, progress):
        n = len(V)
        self.n, self.target, self.model, self.options, self.progress = n, target, model, options, progress
        self.params = model.kernel_params()
        self.VQ = np.zeros((bucket(n + 1), 3 + model.width), DTYPE)
        self.VQ[:n, :3], self.VQ[:n, 3:] = V, S
        self.VQd = jnp.asarray(self.VQ)
        self.N0 = face_normals(np.asarray(V, DTYPE), F).astype(DTYPE)  # each input face's normal
        self.mesh = _Mesh(F, n, pairs)
        self.q = _Queue()
        self.journal = _Journal(self.q.heap)
        self.history, self.history_parts = [], []
        self.removed_at = np.full(len(F), -1, np.int64)
        self.coincident = np.zeros(len(F), bool)
        self.rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
        self.branches = np.zeros(len(model.branches), np.int64)
        self.max_cost_used = 0.0
        self.stop = None
        self.depth = FIRST_BATCH
        self.batches = self.failed = 0

    # pricing ---------------------------------------------------------------------------------------

    def price(self, plist):
        """Prices of pairs ``plist`` (list of (a, b)) from the device rows, with their squared lengths."""
        pa = np.array(plist, np.int64).reshape(-1, 2)
        d = self.VQ[pa[:, 0], :3] - self.VQ[pa[:, 1], :3]
        priced = start_price(self.model, self.VQd, pa, self.params, None, self.n)()
        return priced, np.einsum("ij,ij->i", d, d)

    def push_all(self, pairs):
        plist = sorted({tuple(p) for p in pairs.tolist() if p[0] != p[1]})
        if plist:
            self.push(plist, *self.price(plist))

    def keys(self, plist, priced, l2):
        """The queue keys of priced pairs: lists (rank, squared length, tie, a, b)."""
        q = self.q
        costs = priced.cost.tolist()
        P = np.array(plist, np.int64).reshape(-1, 2)
        keys = costs if q.weights is None else [q._key(c, w) for c, w in zip(costs, priced.parts.T)]
        return keys, l2.tolist(), _ties(P[:, 0], P[:, 1]).tolist(), P[:, 0].tolist(), P[:, 1].tolist()

    def push(self, plist, priced, l2):
        """`queue.Queue.push` (same entries, same stamps in order), heapifying when it adds more entries
        than the queue holds (the first push: every pair)."""
        q = self.q
        keys, l2s, ties, a, b = self.keys(plist, priced, l2)
        stamps = [next(q.stamps) for _ in plist]
        q.stamp.update(zip(plist, stamps))
        q.placed.update(zip(plist, zip(list(priced.x), priced.branch.tolist(), priced.cost.tolist(),
                                       list(priced.parts.T), l2s)))
        if q.blocked:
            for p in plist:
                q.blocked.pop(p, None)
        entries = list(zip(keys, l2s, ties, a, b, stamps))
        if len(entries) > len(q.heap):
            q.heap.extend(entries)
            heapq.heapify(q.heap)
        else:
            for e in entries:
                heapq.heappush(q.heap, e)

    # one pop ---------------------------------------------------------------------------------------

    def check(self, a: int, b: int, x, flipped=None):
        """The first rule contracting b into a at x breaks (or None), and the faces it would change:
        (code, (dead, kept at a, kept at b, drop)). ``flipped``: the flip test's answer when known."""
        mesh, opt, manifold = self.mesh, self.options, self.options.preserve_topology
        A, B = mesh.at[a], mesh.at[b]
        dead = A & B
        nshared = len(dead)
        left = mesh.count["faces"] - nshared
        if left < self.target:
            return BUDGET, None
        if manifold and not mesh.link_ok(a, b, nshared):
            return outcome.TOPOLOGY, None
        ka, kb = sorted(A - dead), sorted(B - dead)
        if manifold and opt.keep_parts and not (ka or kb):  # its faces are all its part has left
            return outcome.PART, None
        if ka or kb:
            if flipped is None:
                flipped = self.flip_tests([(a, b, x, ka, kb)])[0]
            if flipped:
                return outcome.FLIP, None
        drop = self.coincident_drop(a, b, ka, kb)
        if drop and (manifold or left - len(drop) < self.target):
            return (outcome.COINCIDENT if manifold else BUDGET), None
        return None, (sorted(dead), ka, kb, drop)

    def flip_tests(self, tests) -> list[bool]:
        """`flips.flips_host` for several contractions at once, one numpy pass over all their faces:
        tests = [(a, b, x, faces kept at a, faces kept at b)]. Returns one bool per test."""
        tri, rows, corner, X, owner = self.mesh.tri, [], [], [], []
        for i, (a, b, x, ka, kb) in enumerate(tests):
            for v, kept in ((a, ka), (b, kb)):
                for f in kept:
                    rows.append(f)
                    corner.append(tri[f].index(v))
                    X.append(x)
                    owner.append(i)
        if not rows:
            return [False] * len(tests)
        G = np.array([tri[f] for f in rows], np.int64)
        bad = flips.flips_host_faces(self.VQ, self.N0, G, np.array(rows), np.array(corner), np.array(X),
                                     self.options.cos_max)
        return np.bincount(np.array(owner), weights=bad, minlength=len(tests)).astype(bool).tolist()

    def coincident_drop(self, a, b, ka, kb) -> list:
        """Faces the contraction would make coincide and drop (`topo.coincident_removals`, faces in index
        order): none unless two faces around the pair end with the same three corners."""
        fids = sorted(ka + kb)
        after = [self.mesh.tri[f] if f in ka else _moved(self.mesh.tri[f], b, a) for f in fids]
        if len({tuple(sorted(t)) for t in after}) == len(after):
            return []
        gone = topo.coincident_removals(np.array(after, np.int64).reshape(-1, 3))
        return [f for f, g in zip(fids, gone) if g]

    def contract(self, a: int, b: int, x, faces) -> tuple[set, set]:
        """Contract b into a at x on the host (journaled). Returns (pairs to re-price, their vertices)."""
        mesh, j, q = self.mesh, self.journal, self.q
        dead, ka, kb, drop = faces
        for f in dead:
            j.put(mesh.alive, f, False)
            for c in mesh.tri[f]:
                if c != a and c != b:
                    j.put(mesh.at, c, mesh.at[c] - {f})
        for f in kb:
            j.put(mesh.tri, f, _moved(mesh.tri[f], b, a))
        j.put(mesh.at, a, frozenset(ka) | frozenset(kb))
        j.put(mesh.at, b, frozenset())
        for f in drop:
            j.put(mesh.alive, f, False)
            for c in mesh.tri[f]:
                j.put(mesh.at, c, mesh.at[c] - {f})
        j.put_d(mesh.count, "faces", mesh.count["faces"] - len(dead) - len(drop))
        j.row(self.VQ, a)
        self.VQ[a, :3] = x
        # pair partners: b's become a's; pairs at b are gone (forgotten by the queue when the step stands)
        step, nb = len(self.steps), mesh.nbr[b]
        nbr, put = mesh.nbr, j.put
        for w in nb:
            if w != a:
                put(nbr, w, (nbr[w] - {b}) | {a})
            self.gone[(w, b) if w < b else (b, w)] = step
        j.put(mesh.nbr, a, (mesh.nbr[a] | nb) - {a, b})
        j.put(mesh.nbr, b, frozenset())
        # the pairs at a need new prices: held out of the queue until the batch's device call
        ring = mesh.nbr[a]
        at_a = sorted((a, w) if a < w else (w, a) for w in ring)
        for p in at_a:
            self.held[p] = step
            if p in q.blocked:
                j.drop(q.blocked, p)
        # blocked pairs around a may have become valid: back in the queue at their stored price
        if q.blocked:
            if len(q.blocked) <= BLOCKED_SCAN:
                back = [p for p in q.blocked if p[0] in ring or p[1] in ring]
            else:
                back = {(u, w) if u < w else (w, u) for u in ring for w in mesh.nbr[u]}
                back = [p for p in back if p in q.blocked]
            for p in back:
                if p not in self.gone:
                    self.unblock(p)
        self.stale_verts |= ring
        self.stale_verts.add(a)
        return at_a

    def unblock(self, p):
        """Back in the queue at its stored price (its vertices' rows are those it was priced with)."""
        q = self.q
        _, _, c, parts, l2 = q.placed[p]
        self.journal.drop(q.blocked, p)
        s = next(q.stamps)
        self.journal.put_d(q.stamp, p, s)
        heapq.heappush(q.heap, (q._key(c, parts), l2, _tie(*p), p[0], p[1], s))

    # a batch ---------------------------------------------------------------------------------------

    def live(self, entry) -> bool:
        """Whether a queue entry is current; pops and forgets one that is not (journaled when undoing
        this batch's steps could make it current again)."""
        key, l2, tie, a, b, s = entry
        p = (a, b)
        q = self.q
        if q.stamp.get(p) != s or p in q.blocked:  # an old entry: never current again
            return False
        if p in self.held or p in self.gone:  # current again if this batch's step is undone
            self.journal.popped(entry)
            return False
        return True

    def prefetch(self, want: int):
        """Move the queue's next ``want`` live entries to ``ahead``, with their flip tests from one numpy
        pass, the vertices those read, and the contraction count then (a test stays right while no
        contraction since has moved or removed one of those vertices)."""
        heap, stamp, mesh, new = self.q.heap, self.q.stamp, self.mesh, []
        while heap and len(new) < want:
            entry = heapq.heappop(heap)
            if stamp.get((entry[3], entry[4])) == entry[5] and self.live(entry):  # (most are old: cheap test first)
                new.append(entry)
        tests, reads = [], []
        for entry in new:
            a, b = entry[3], entry[4]
            A, B = mesh.at[a], mesh.at[b]
            dead = A & B
            tests.append((a, b, self.q.placed[(a, b)][0], sorted(A - dead), sorted(B - dead)))
            reads.append(mesh.corners(A | B) | {a, b})
        for entry, flipped, r in zip(new, self.flip_tests(tests), reads):
            self.ahead.append((entry, flipped, r, self.contracted))

    def next_entry(self):
        """The next live entry, from ``ahead`` or the queue, whichever ranks first (an unblocked pair can
        enter the queue before what was fetched ahead), and its flip test if known; (None, None) if none.
        Not removed yet."""
        heap, stamp, ahead = self.q.heap, self.q.stamp, self.ahead
        while True:
            while heap and not (stamp.get((heap[0][3], heap[0][4])) == heap[0][5] and self.live(heap[0])):
                heapq.heappop(heap)
            if not ahead:
                if not heap:
                    return None, None
                self.prefetch(min(PREFETCH, max(1, self.depth - len(self.steps))))
                continue
            entry, flipped, reads, since = ahead[0]
            if not self.live(entry):
                ahead.popleft()
                continue
            if heap and heap[0] < entry:
                return heap[0], None
            moved = self.moved
            if any(moved.get(v, -1) >= since for v in reads):
                flipped = None  # a contraction since changed what the test read
            return entry, flipped

    def take(self, entry):
        """Remove ``entry`` (the one `next_entry` gave) from where it is, journaled."""
        if self.ahead and self.ahead[0][0] is entry:
            self.ahead.popleft()
        else:
            heapq.heappop(self.q.heap)
        self.journal.popped(entry)

    def speculate(self):
        """Pop and apply up to ``depth`` steps on the host (into ``steps``). Pairs the steps stale are
        ``held`` out of the queue, pairs they remove are ``gone``: {pair: step index} each."""
        q, mesh, j, opt = self.q, self.mesh, self.journal, self.options
        steps, stale_verts = self.steps, self.stale_verts
        while mesh.count["faces"] > self.target and len(steps) < self.depth:
            entry, flipped = self.next_entry()
            if entry is None:
                break
            a, b = entry[3], entry[4]
            p = (a, b)
            x, br, cost, parts, _ = q.placed[p]
            if cost > opt.max_cost:  # left in the queue: the stop report counts it
                steps.append(_Step(entry[:5], STOP, len(j.log)))
                break
            if a in stale_verts or b in stale_verts:  # reads or changes a row this batch changes
                break
            mark = len(j.log)
            self.take(entry)
            code, faces = self.check(a, b, x, flipped)
            if code is not None:
                j.put_d(q.blocked, p, code)
                steps.append(_Step(entry[:5], BLOCK, mark, code=code))
                continue
            self.contract(a, b, x, faces)
            self.contracted += 1
            self.moved[a] = self.moved[b] = self.contracted
            steps.append(_Step(entry[:5], CONTRACT, mark, x=x, branch=br, cost=cost, parts=parts,
                               faces_left=mesh.count["faces"], dead=faces[0], drop=faces[3]))
        for entry, *_ in self.ahead:  # fetched but not taken: back in the queue (never journaled)
            heapq.heappush(q.heap, entry)
        self.ahead.clear()

    def merge(self, steps):
        """The kept vertices' new states (one device call), on the host and device rows."""
        P = np.array([s.order[3:5] for s in steps], np.int64)
        X = np.array([s.x for s in steps], DTYPE)
        merged = start_merge(self.model, self.VQd, P, X, self.params)()
        self.VQ[P[:, 0], 3:] = merged
        self.VQd = set_rows(self.VQd, P[:, 0], self.VQ[P[:, 0]], size=256)

    def first_wrong(self, steps, stale, order) -> int:
        """Index of the first step that a stale pair held out before it would have preceded."""
        best, i = None, 0
        for k, step in enumerate(steps):
            while i < len(stale) and stale[i][1] < k:
                if best is None or order[i] < best:
                    best = order[i]
                i += 1
            if best is not None and best < step.order:
                return k
        return len(steps)

    def batch(self):
        self.steps, self.held, self.gone, self.stale_verts = [], {}, {}, set()
        self.ahead, self.moved, self.contracted = deque(), {}, 0
        self.speculate()
        steps, stale = self.steps, list(self.held.items())
        contracted = [s for s in steps if s.kind == CONTRACT]
        if contracted:
            self.merge(contracted)
        priced = l2 = None
        order = []
        if stale:
            priced, l2 = self.price([p for p, _ in stale])
            order = list(zip(*self.keys([p for p, _ in stale], priced, l2)))
        ok = self.first_wrong(steps, stale, order)
        self.batches += 1
        if ok < len(steps):
            self.failed += 1
            self.depth = max(1, self.depth // 2)
            self.undo(steps[ok:])
        elif len(steps) == self.depth:
            self.depth = min(MAX_BATCH, 2 * self.depth)
        self.journal.log.clear()
        self.commit(steps[:ok], stale, priced, l2)

    def undo(self, steps):
        self.journal.undo(steps[0].mark)
        back = np.array([s.order[3] for s in steps if s.kind == CONTRACT], np.int64)
        if len(back):  # the device rows of the kept vertices, as the journal restored the host's
            self.VQd = set_rows(self.VQd, back, self.VQ[back], size=256)

    def commit(self, steps, stale, priced, l2):
        q = self.q
        for p, i in self.gone.items():
            if i < len(steps):
                q.forget(p)
        keep = [k for k, (_, i) in enumerate(stale) if i < len(steps)]
        if keep:
            sub = priced._replace(x=priced.x[keep], cost=priced.cost[keep], branch=priced.branch[keep],
                                  parts=priced.parts[:, keep])
            self.push([stale[k][0] for k in keep], sub, l2[keep])
        for s in steps:
            if s.kind == BLOCK:
                if s.code != BUDGET:
                    self.rejected_by[s.code] += 1
            elif s.kind == STOP:
                self.stop = "max_error"
            else:
                self.record(s)

    def record(self, s: _Step):
        a, b = s.order[3:5]
        self.branches[s.branch] += 1
        self.max_cost_used = max(self.max_cost_used, float(s.cost))
        self.history.append((a, b, np.array(s.x), float(s.cost)))
        if len(self.model.parts):
            self.history_parts.append(np.append(s.parts, s.order[0]))
        step = len(self.history) - 1
        self.removed_at[list(s.dead)] = step
        if s.drop:
            self.removed_at[list(s.drop)] = step
            self.coincident[list(s.drop)] = True
        if self.progress is not None:
            self.progress(s.faces_left)

    def loop(self):
        while self.stop is None and self.mesh.count["faces"] > self.target and self.q.heap:
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
