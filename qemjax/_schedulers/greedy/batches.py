"""The greedy queue in verified batches, with its host side compiled (`speculate`): the same
contractions, in the same order, with the same outputs bit for bit, as the one-at-a-time loop of `greedy`
(tests/test_greedy_compiled.py runs both on the same meshes). Used for the models whose price reads only
the pair's two rows (`eligible`: QEM and its attribute form without memoryless, ring support, refresh or
ranking weights), in both modes (manifold, and non-manifold, where a contraction drops the faces it makes
coincide), on any mesh (the rules take shortcuts on a `simple` one), with locks, weights and kept
attributes.

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

A blocked pair that becomes a candidate again keeps its stored price, which is what re-pricing it would
give (its two vertices' rows have not changed since it was priced): hence `eligible`.

Locks and weights (`_locks`): prices go through `_locks.adjust` on each interval's rows (a kept vertex's
scratch row carries its lock and its new weight, `_locks.carry`), pairs of two locked vertices are blocked
whenever they are pushed (and take no part in the order check: they never come first), and the rules
refuse a contraction that would leave a locked vertex in no face. While a batch's prices are computed the
host rows hold the same versions as the device rows (the kept vertices' rows from before the batch, the
scratch rows merged), so that prices computed on the host (the attribute model's ``cost_at`` at a locked
vertex, the seam constraint) read each interval's rows too.

Kept attributes (`wedges`): the seam rule at the pop and the wedge updates at the contraction
run during the speculation, journaled; at each push the loop places pairs at seam vertices at an allowed
endpoint (`wedges.Tracker.constrain`), which depends on the faces and wedges of that moment: the batch
takes each pushed pair's mode then, and prices the endpoint after the merge call from the interval's
rows. A blocked pair that comes back is placed anew (the faces around it changed), from its price
before the constraint (``RP``).
"""
from __future__ import annotations

from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np

from . import speculate as jit
from . import wedges as gw
from .. import locks as _locks
from ..._mesh import seam_rule
from .. import outcome
from ..rules import Faces
from ..._kernels.flips import host_limits
from ..._kernels.batching import DTYPE, bucket, set_rows
from ..._mesh.arrays import face_normals
from ..device import start_merge, start_price
from .queue import stop_report

_M32 = 0xFFFFFFFF
FIRST_BATCH, MAX_BATCH = 16, 256  # speculation depth: doubled after a batch that stands, halved after one that fails
REBUILD, PREFETCH = 2, 64  # the heap is rebuilt from the current entries when it holds more than REBUILD
# times as many entries, plus PREFETCH
# first sizes (they grow when a batch needs more: `_Compiled.room`)
ROOM, SLACK = 2, 1024  # pools and queue arrays: ROOM times what they start with, plus SLACK
POOL_ROOM = 8  # a pool packed after a step did not fit: room for a batch of such steps, up to this many times its lists
JOURNAL_ROWS, INTERVAL_ROWS = 1 << 16, 1 << 14  # a batch's journal and stale intervals
REMOVED_ROWS = 1 << 12  # a batch's removed faces


def eligible(model) -> bool:
    """Whether a run can use this module: a pair's price reads only its two vertices' rows (whether or not
    it keeps attributes or has locks and weights: those run here too)."""
    return (model.support == "pair" and model.refresh is None and not model.uses_ring
            and model.rank_weights is None)


def simple(F: np.ndarray) -> bool:
    """No face with a repeated corner, no two faces with the same corners. In manifold mode a mesh stays
    so (a contraction removes the faces with both endpoints, and one that would make two faces coincide is
    refused), and the rules take shortcuts that rely on it."""
    Fs = np.sort(np.asarray(F).reshape(-1, 3), axis=1)
    return bool(np.all(Fs[:, 0] != Fs[:, 1]) and np.all(Fs[:, 1] != Fs[:, 2])
                and len(np.unique(Fs, axis=0)) == len(Fs))


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


def _dict():
    return jit.new_dict()


def queue_keys(P: np.ndarray, cost: np.ndarray, l2: np.ndarray) -> np.ndarray:
    """Queue keys (k,3) uint64 of pairs P (k,2): the fields of `queue.Queue`'s entries (cost, squared
    length, `queue.tie`, a, b) in three words (ordered cost bits << 32 | ordered length bits, tie << 32 | a,
    b), which compare as the tuples do."""
    a, b = P[:, 0].astype(np.uint64), P[:, 1].astype(np.uint64)
    K = np.empty((len(P), 3), np.uint64)
    K[:, 0] = (ordered_bits(cost) << np.uint64(32)) | ordered_bits(l2)
    K[:, 1] = (_ties(P[:, 0], P[:, 1]) << np.uint64(32)) | a
    K[:, 2] = b
    return K


def _lists(n: int, owner: np.ndarray, item: np.ndarray):
    """Per vertex lists (start, length, pool with as much room again) of ``item`` grouped by ``owner``,
    each item once per list (a face with a repeated corner is listed once there)."""
    order = np.argsort(owner, kind="stable")
    owner, item = owner[order], item[order]
    once = np.ones(len(item), bool)
    once[1:] = (owner[1:] != owner[:-1]) | (item[1:] != item[:-1])  # (items come in order within a list)
    owner, item = owner[once], item[once]
    length = np.bincount(owner, minlength=n).astype(np.int64)
    start = np.cumsum(length) - length
    pool = np.empty(ROOM * len(item) + SLACK, np.int64)
    pool[:len(item)] = item
    return start, length, pool


def _grown(a: np.ndarray, size: int) -> np.ndarray:
    out = np.zeros((size,) + a.shape[1:], a.dtype)
    out[:len(a)] = a
    return out


class _Compiled:
    """The run's state (arrays and typed dicts, as `speculate` describes) and its batch loop."""

    def __init__(self, V, S, F, pairs, target, model, options, progress, locks=None, wedges=None, normals=None):
        n, m = len(V), len(F)
        self.n, self.target, self.model, self.options, self.progress = n, target, model, options, progress
        self.params = model.kernel_params()
        self.scratch = n + 1  # a batch's merged rows go to rows scratch.. (row n stays zero)
        self.VQ = np.zeros((bucket(n + 1 + MAX_BATCH), 3 + model.width), DTYPE)
        self.VQ[:n, :3], self.VQ[:n, 3:] = V, S
        self.VQd = jnp.asarray(self.VQ)
        # locks (`_locks`): locked vertices, and the weights carried through contractions, per row (a batch's
        # kept vertices' new weights in their scratch rows, as their merged rows)
        self.locks, rows = locks, len(self.VQ)
        self.locked = np.zeros(n, bool) if locks is None else np.asarray(locks.locked, bool)
        self.row_locks = None if locks is None else _locks.RunLocks(_grown(self.locked, rows))
        self.weights = None if locks is None or locks.weights is None else _grown(
            np.array(locks.weights, np.float64), rows)
        self.N0 = (face_normals(np.asarray(V, DTYPE), F) if normals is None else normals).astype(DTYPE)
        # kept attributes: the tracker's arrays, changed in place (`wedges`); none: empty ones
        self.wedges = wedges
        if wedges is None:
            self.wed = (False, np.zeros((0, 3), np.int64), np.zeros((0, 1)), np.zeros(n, bool), np.zeros((1, 1)),
                        -1, -1, np.zeros(1, bool), np.ones(1))
        else:
            self.wed = (True, wedges.C, wedges.val, wedges.multi,
                        np.zeros((MAX_BATCH + 1, wedges.val.shape[1])), int(wedges.m), int(wedges.m_solved),
                        np.ascontiguousarray(wedges.solved, bool), np.ascontiguousarray(wedges.weights, np.float64))
        self.T = np.array(F, np.int64).reshape(-1, 3)
        self.manifold, self.simple = bool(options.preserve_topology), simple(self.T)
        self.alive = np.ones(m, bool)
        self.pool_room = {"fpool": 0, "npool": 0}  # free slots a packed pool keeps (`room`)
        self.fs, self.fl, self.fpool = _lists(n, self.T.reshape(-1), np.repeat(np.arange(m, dtype=np.int64), 3))
        P = np.unique(np.asarray(pairs, np.int64).reshape(-1, 2), axis=0)
        self.P0 = P = P[P[:, 0] != P[:, 1]]
        self.ns, self.nl, self.npool = _lists(n, P[:, ::-1].reshape(-1), P.reshape(-1))
        self.cnt = np.zeros((n, 3), np.int64)
        cap = ROOM * len(P) + SLACK
        self.heap = np.zeros(cap, np.int64)
        self.K = np.zeros((cap, 3), np.uint64)
        self.X = np.zeros((cap, 3), DTYPE)
        self.cost = np.zeros(cap, DTYPE)
        self.branch = np.zeros(cap, np.int64)
        self.parts = np.zeros((cap, len(model.parts)), DTYPE)
        self.RP = np.zeros((cap, 4), DTYPE)  # each stamp's position and cost before the seam constraint
        self.cur, self.blocked = _dict(), _dict()
        self.bat = np.zeros(n, np.int64)
        self.steps = np.zeros((MAX_BATCH + 1, 10), np.int64)
        self.iv = np.zeros((INTERVAL_ROWS, 6), np.int64)
        self.J = np.zeros((JOURNAL_ROWS, 4), np.int64)
        self.rm = np.zeros(REMOVED_ROWS, np.int64)
        self.ver = np.full(n, -1, np.int64)
        self.orig = np.zeros((MAX_BATCH + 1, self.VQ.shape[1]), DTYPE)
        self.ctr = np.zeros(jit.NCTR, np.int64)
        self.ctr[jit.C_FACES] = m
        self.ctr[jit.C_FTOP], self.ctr[jit.C_NTOP] = 3 * m, 2 * len(P)  # the pools' ends
        self.cos_max, self.shape = host_limits(options.cos_max, options.min_quality)
        self.history, self.history_parts = [], []
        self.removed_at = np.full(m, -1, np.int64)
        self.coincident = np.zeros(m, bool)
        self.rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
        self.branches = np.zeros(len(model.branches), np.int64)
        self.max_cost_used = 0.0
        self.stop = None
        self.depth = FIRST_BATCH
        self.batches = self.failed = 0

    def push_all(self):
        """Every pair into the queue, stamps in row order (pairs sorted)."""
        P = self.P0
        if not len(P):
            return
        d = self.VQ[P[:, 0], :3] - self.VQ[P[:, 1], :3]
        raw = self.adjust(self.VQd, P, start_price(self.model, self.VQd, P, self.params, None, self.n)())
        w = self.wedges  # pairs at seam vertices: placed at an allowed endpoint (as the loop)
        priced = self.seamed(raw, P, lambda x, cost: seam_rule.constrain(
            self.T, self.alive, self.fl, self.fs, self.fpool, w.C, w.multi, self.VQ, P, x, cost, w.m))
        self.push(P, priced, np.einsum("ij,ij->i", d, d), raw=raw)

    def seamed(self, raw, rows, place):
        """With kept attributes, the prices ``raw`` of pairs whose two rows are ``rows`` (k,2) with those at
        seam vertices placed at an allowed endpoint (``place(x, cost)``, in place, on copies) and, with locks,
        a locked first vertex pinned (`_locks.pin`); else ``raw`` itself."""
        if self.wedges is None:
            return raw
        priced = raw._replace(x=raw.x.copy(), cost=raw.cost.copy())
        place(priced.x, priced.cost)
        if self.locks is not None:
            _locks.pin(self.row_locks, self.VQ, rows, priced.x)
        return priced

    def adjust(self, VQd, rows, priced, kept=None):
        """With locks, `_locks.adjust` of the prices of pairs whose two rows are ``rows`` (k,2): pairs with a
        locked kept vertex priced there (the attribute values it holds: those of its vertex, ``kept`` (k,)
        where its row is a scratch row, else the row's own), costs and parts times the larger weight of the
        two rows."""
        if self.locks is None:
            return priced
        held = None
        if self.wedges is not None:
            vertex = dict(zip(rows[:, 0].tolist(), (rows[:, 0] if kept is None else kept).tolist()))
            held = lambda row: self.wedges.held(vertex[row])  # noqa: E731
        return _locks.adjust(self.row_locks, self.weights, self.model, self.VQ, VQd, rows, priced, self.params,
                             None, self.n, held=held)

    def push(self, P, priced, l2, keys=None, raw=None):
        """Pairs P (k,2) into the queue at ``priced`` (``raw``: before the seam constraint; None: the same)."""
        keys = queue_keys(P, priced.cost, l2) if keys is None else keys
        raw = priced if raw is None else raw
        self.room(stamps=len(P))
        jit.push((P[:, 0] << 32) | P[:, 1], keys, priced.x, priced.cost, priced.branch.astype(np.int64),
                 np.ascontiguousarray(priced.parts.T), np.concatenate([raw.x, raw.cost[:, None]], 1).astype(DTYPE),
                 self.heap, self.K, self.X, self.cost, self.branch, self.parts, self.RP, self.cur, self.blocked,
                 self.bat, self.ctr, self.locks is not None, self.locked)

    def room(self, stamps=0, full=False):
        """Grow the arrays for ``stamps`` more pushes; with ``full`` (a batch stopped for room), grow each
        array the step that did not fit wanted more of (`speculate.speculate` leaves the lengths), so that
        the step fits from an empty batch. Memory stays O(input) whatever the valence: the journal and the
        stale intervals, a batch's own, grow only when a batch could not take its first step (a batch that
        took some runs on in the next one); the pools are packed with room for the step; the stamp arrays
        stay as long as the queue (`renumber`)."""
        ctr = self.ctr
        if full:
            want = lambda c, length: ctr[c] > length  # noqa: E731
            if want(jit.C_WK, len(self.K)):
                stamps = max(stamps, int(ctr[jit.C_WK] - ctr[jit.C_STAMP]))
            if want(jit.C_WHEAP, len(self.heap)):
                self.heap = _grown(self.heap, int(max(2 * len(self.heap), ctr[jit.C_WHEAP])))
            if ctr[jit.C_NSTEPS] == 0:  # not one step fitted: room for it, from an empty batch
                if want(jit.C_WJ, len(self.J)):
                    self.J = _grown(self.J, int(max(2 * len(self.J), ctr[jit.C_WJ])))
                if want(jit.C_WIV, len(self.iv)):
                    self.iv = _grown(self.iv, int(max(2 * len(self.iv), ctr[jit.C_WIV])))
                if want(jit.C_WRM, len(self.rm)):
                    self.rm = _grown(self.rm, int(max(2 * len(self.rm), ctr[jit.C_WRM])))
        need = ctr[jit.C_STAMP] + stamps + 1
        if need > len(self.K):
            size = 2 * max(need, len(self.K))
            self.K, self.X, self.cost = _grown(self.K, size), _grown(self.X, size), _grown(self.cost, size)
            self.branch, self.parts = _grown(self.branch, size), _grown(self.parts, size)
            self.RP = _grown(self.RP, size)
        if ctr[jit.C_HSIZE] + stamps > len(self.heap):
            self.heap = _grown(self.heap, 2 * (len(self.heap) + stamps))
        for top, w, s, ln, pool in ((jit.C_FTOP, jit.C_WF, self.fs, self.fl, "fpool"),
                                    (jit.C_NTOP, jit.C_WN, self.ns, self.nl, "npool")):
            arr = getattr(self, pool)
            short = full and ctr[w] > 0  # (this pool stopped the batch)
            if short or ctr[top] > 3 * len(arr) // 4:  # packed, with room for as much again (or the steps)
                live = int(ln.sum())
                if short:  # room for a batch of such steps, at most POOL_ROOM times the lists
                    self.pool_room[pool] = max(2 * int(ctr[w]), min(self.depth * int(ctr[w]), POOL_ROOM * (live + SLACK)))
                new, ctr[top] = jit.compact(s, ln, arr, max(live, SLACK, self.pool_room[pool]))
                setattr(self, pool, new)

    def renumber(self):
        """`speculate.renumber` when the stamps used pass twice the queue's pairs (and SLACK): old stamps'
        rows are reused, so the stamp arrays do not grow with the run's pushes (a vertex of valence d
        re-prices d pairs per contraction at it: d² pushes where it absorbs its neighbours)."""
        if self.ctr[jit.C_STAMP] > 2 * jit.size(self.cur) + SLACK:
            jit.renumber(self.heap, self.ctr, self.K, self.X, self.cost, self.branch, self.parts, self.RP, self.cur,
                         self.blocked)

    # a batch ---------------------------------------------------------------------------------------

    def batch(self):
        ctr = self.ctr
        self.renumber()
        if ctr[jit.C_HSIZE] > REBUILD * jit.size(self.cur) + PREFETCH:  # mostly old entries: keep the current ones
            jit.rebuild(self.heap, ctr, self.K, self.cur, self.blocked)
        held, gone = _dict(), _dict()
        opt = self.options  # (scalars of fixed types: one compiled specialisation)
        settings = jit.Settings(int(self.depth), int(self.target), float(opt.max_cost), self.manifold, self.simple,
                                bool(opt.keep_parts), self.cos_max, self.shape, int(self.scratch),
                                self.locks is not None)
        faces = Faces(self.T, self.alive, self.fs, self.fl, self.fpool)
        queue = jit.Queue(self.heap, self.K, self.X, self.cost, self.branch, self.parts, self.RP, self.bat)
        batch = jit.Batch(self.steps, self.iv, self.ver, self.orig, self.J, self.rm, ctr)
        jit.speculate(settings, self.locked, jit.Seams(*self.wed), faces, jit.Partners(self.ns, self.nl, self.npool),
                      self.VQ, self.N0, self.cnt, queue, batch, self.cur, self.blocked, held, gone)
        ns = int(ctr[jit.C_NSTEPS])
        steps = self.steps[:ns].copy()
        contracted = steps[steps[:, jit.S_KIND] == jit.CONTRACT]
        rows = np.zeros((0, self.VQ.shape[1]), DTYPE)
        if len(contracted):
            P = contracted[:, [jit.S_A, jit.S_B]]
            X = self.X[contracted[:, jit.S_STAMP]]
            rows = np.concatenate([X, start_merge(self.model, self.VQd, P, X, self.params)()], 1)
            if self.locks is not None:
                # the kept vertices' scratch rows: locked as they are, with the larger weight of the pair
                # (`_locks.carry`; a popped pair's vertices were not merged earlier in the batch, so their
                # weights are those the batch started with)
                slots = self.scratch + np.arange(len(P))
                self.row_locks.locked[slots] = self.locked[P[:, 0]]
                if self.weights is not None:
                    self.weights[slots] = np.maximum(self.weights[P[:, 0]], self.weights[P[:, 1]])
        niv = int(ctr[jit.C_NIV])
        VQd, priced, raw, keys = self.VQd, None, None, np.zeros((0, 3), np.uint64)
        iv = self.iv[:niv].copy()
        if niv:
            VQd, priced, raw, keys = self.price_intervals(iv, rows, contracted[:, jit.S_A])
        ok = int(jit.first_wrong(steps, self.K, iv, self.order_keys(iv, keys), ns))
        self.batches += 1
        if ok < ns:
            self.failed += 1
            self.depth = max(1, self.depth // 2)
            w = self.wed
            jit.undo(int(steps[ok, jit.S_MARK]), self.T, self.alive, self.fs, self.fl, self.ns, self.nl, self.heap,
                     self.K, self.cur, self.blocked, self.bat, self.J, ctr, w[1], w[2], w[3], w[4])
            m = int(np.sum(steps[:ok, jit.S_KIND] == jit.CONTRACT))
            self.VQ[contracted[m:, jit.S_A]] = self.orig[m:len(contracted)]  # their rows from before
        elif ns == self.depth:
            self.depth = min(MAX_BATCH, 2 * self.depth)
        ctr[jit.C_JLEN] = 0
        self.ver[contracted[:, jit.S_A]] = -1
        m = int(np.sum(steps[:ok, jit.S_KIND] == jit.CONTRACT))  # the merged rows of the steps that stand
        if m:
            kept = contracted[:m, jit.S_A]
            self.VQ[kept, 3:] = rows[:m, 3:]
            if self.weights is not None:
                self.weights[kept] = self.weights[self.scratch + np.arange(m)]
            VQd = set_rows(VQd, kept, rows[:m], size=MAX_BATCH)
        self.VQd = VQd
        jit.forget_gone(gone, ok, self.cur, self.blocked, self.bat)
        if niv:
            sel = jit.last_intervals(iv, int(niv), ok, gone)
            if len(sel):
                pk = iv[sel, jit.I_PAIR]
                sub = priced._replace(x=priced.x[sel], cost=priced.cost[sel], branch=priced.branch[sel],
                                      parts=priced.parts[:, sel])
                self.push(np.stack([pk >> 32, pk & _M32], 1), sub, None, keys[sel],
                          raw._replace(x=raw.x[sel], cost=raw.cost[sel]))
        self.record(steps[:ok][steps[:ok, jit.S_KIND] == jit.CONTRACT])
        for code in steps[:ok][steps[:ok, jit.S_KIND] == jit.BLOCK, jit.S_CODE].tolist():
            if code != outcome.BUDGET:
                self.rejected_by[code] += 1
        if np.any(steps[:ok, jit.S_KIND] == jit.STOP):
            self.stop = "max_error"
        self.room(full=bool(ctr[jit.C_FULL]))  # (a batch stopped for room: rare)

    def price_intervals(self, iv, rows, kept):
        """Prices (after the seam constraint, and before it) and queue keys of the stale intervals, each from
        its own versions of its two rows: the device rows with the batch's merged ``rows`` in the scratch
        rows. The host rows are the same versions meanwhile (``kept``, the batch's kept vertices: their rows
        from before the batch; the scratch rows: the merged ones), for the prices computed on the host (a
        host ``cost_at`` with locks, the seam constraint)."""
        ids = iv[:, [jit.I_RA, jit.I_RB]]
        VQd = set_rows(self.VQd, self.scratch + np.arange(len(rows)), rows, size=MAX_BATCH) if len(rows) \
            else self.VQd
        self.VQ[self.scratch:self.scratch + len(rows)] = rows
        moved = self.VQ[kept, :3].copy()
        self.VQ[kept] = self.orig[:len(kept)]
        raw = self.adjust(VQd, ids, start_price(self.model, VQd, ids, self.params, None, self.n)(),
                          iv[:, jit.I_PAIR] >> 32)
        priced = self.seamed(raw, ids, lambda x, cost: gw.constrain_rows(  # by the modes taken at their pushes
            self.VQ, ids, iv[:, jit.I_MODE], x, cost, int(self.wedges.m)))
        pos = self.VQ[ids.reshape(-1), :3].reshape(-1, 2, 3)
        self.VQ[kept, :3] = moved
        d = np.ascontiguousarray(pos[:, 0]) - np.ascontiguousarray(pos[:, 1])
        l2 = np.einsum("ij,ij->i", d, d)
        pk = iv[:, jit.I_PAIR]
        return VQd, priced, raw, queue_keys(np.stack([pk >> 32, pk & _M32], 1), priced.cost, l2)

    def order_keys(self, iv, keys):
        """The intervals' keys as the order check takes them: a pair of two locked vertices is blocked as
        soon as it is pushed, so it precedes nothing (its key: the largest)."""
        if self.locks is None or not len(keys):
            return keys
        pk = iv[:, jit.I_PAIR]
        both = self.locked[pk >> 32] & self.locked[pk & _M32]
        if not both.any():
            return keys
        keys = keys.copy()
        keys[both] = np.iinfo(np.uint64).max
        return keys

    def record(self, steps):
        """The history of the contraction steps that stand, in order."""
        history, parts = self.history, len(self.model.parts)
        for a, b, s, left, nd, r0, ndrop in steps[:, [jit.S_A, jit.S_B, jit.S_STAMP, jit.S_LEFT, jit.S_ND, jit.S_RM,
                                                      jit.S_NDROP]].tolist():
            step = len(history)
            cost = float(self.cost[s])
            history.append((a, b, self.X[s].copy(), cost))
            self.branches[self.branch[s]] += 1
            if cost > self.max_cost_used:
                self.max_cost_used = cost
            if parts:
                self.history_parts.append(np.append(self.parts[s], cost))
            self.removed_at[self.rm[r0:r0 + nd + ndrop]] = step
            if ndrop:
                self.coincident[self.rm[r0 + nd:r0 + nd + ndrop]] = True
            if self.progress is not None:
                self.progress(left)

    def loop(self):
        while self.stop is None and self.ctr[jit.C_FACES] > self.target and self.ctr[jit.C_HSIZE]:
            self.batch()

    def output(self):
        """The faces as a `FaceLists`, and the queue as `queue.stop_report` reads it."""
        from ..._mesh.incidence import FaceLists
        faces = FaceLists(self.T.astype(np.int32), self.n)
        faces.alive = self.alive.copy()
        faces.count = int(self.ctr[jit.C_FACES])
        pairs, stamps = jit.export(self.cur)
        bp, codes = jit.export(self.blocked)
        pair = lambda p: (p >> 32, p & _M32)  # noqa: E731
        q = SimpleNamespace(placed={pair(p): (None, None, c) for p, c in zip(pairs.tolist(), self.cost[stamps].tolist())},
                            blocked={pair(p): c for p, c in zip(bp.tolist(), codes.tolist())})
        return faces, q


def run(V, S, F, pairs, target_faces, model, options, progress, locks=None, wedges=None, normals=None):
    """`greedy.run` for an `eligible` model; pairs (k,2): the candidate pairs (edges and extra pairs, each
    row sorted). Same return."""
    r = _Compiled(V, S, F, pairs, target_faces, model, options, progress, locks, wedges, normals)
    r.push_all()
    r.loop()
    faces, q = r.output()
    stop, blocked = r.stop, {}
    if faces.count > target_faces:
        stop, blocked = stop_report(faces, q, options, target_faces, stop)
    nparts = len(model.parts)
    return outcome.Outcome(
        r.VQ[:len(V), :3], r.VQ[:len(V), 3:], faces.F, faces.alive, outcome.History.of(r.history),
        stop or "target", blocked,
        outcome.count_reasons(np.repeat(np.arange(len(r.rejected_by)), r.rejected_by)),
        rejected=int(r.rejected_by.sum()), rounds=len(r.history), worst_cost=r.max_cost_used,
        branches=r.branches, parts=np.array(r.history_parts, np.float64).reshape(-1, nparts + 1) if nparts else None,
        history_rounds=np.arange(len(r.history), dtype=np.int64), removed_at=r.removed_at,
        coincident=r.coincident)
