"""The host side of the greedy queue's verified batches (`batches`), compiled (numba): pops,
rules (`checks`), contractions, journal and commits on integer arrays, giving the contractions of
the one-at-a-time loop (`loop._run`) in its order.

Why: after the batching, a greedy run was Python bookkeeping spread over many small stages, none
dominant; the same steps over arrays take a small fraction of that time. What stays in Python (`batches`) is what needs the device: merging the batch's kept vertices
and pricing its stale intervals, and the history. Both modes: in manifold mode a contraction removes the
faces holding both its vertices; in non-manifold mode it also drops the faces it makes coincide
(`rules.coincident_drop`).

Layout (one `State`, every field an array so that the kernels compile once and cache):
* faces: ``T`` (m,3) corners, ``alive``; per vertex its faces and its pair partners as lists in a pool
  (``fs``/``fl`` start and length into ``fpool``, ``ns``/``nl`` into ``npool``). A list that changes is
  written anew at the pool's end, so that the journal restores a list by its (start, length).
* queue: ``heap`` of stamps (one per push, never reused); a stamp's key ``K`` (3 uint64: ordered cost bits
  << 32 | ordered squared-length bits, `queue.tie` << 32 | a, b), price ``X``, ``cost``, ``branch``,
  ``parts``. Entries order by (K, stamp), as the tuples of `queue.Queue` do. ``cur`` {pair: current stamp},
  ``blocked`` {pair: rule} and ``bat`` (blocked pairs per vertex); pairs are ints a << 32 | b, a < b.
* a batch: ``steps`` rows (kind, a, b, journal mark, rule, stamp, faces left, dead faces, where its
  removed faces start in ``rm``, dropped faces), ``rm`` the faces each step removed (its dead faces, then
  those it dropped as coincident), the stale intervals ``iv`` rows (pair, first step, end step, row of a,
  row of b), ``held`` {pair: its open interval} and ``gone`` {pair: the step that removed it}, ``ver`` (the scratch row of a vertex kept in this batch, else -1), ``orig`` (its
  row before), and the journal ``J`` rows (kind, index, old, old).
* ``ctr``: the counters (named by the C_* indices).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import types
from numba.typed import Dict

from . import wedges as gw
from ..._mesh.compiled import njit
from ..outcome import LOCKED, SEAM
from ..rules import drops_locked, has
from .checks import Step, rules_head, rules_tail

CONTRACT, BLOCK, STOP = 0, 1, 2
S_KIND, S_A, S_B, S_MARK, S_CODE, S_STAMP, S_LEFT, S_ND, S_RM, S_NDROP = range(10)  # columns of ``steps``
I_PAIR, I_START, I_END, I_RA, I_RB, I_MODE = range(6)  # columns of ``iv``
C_FACES, C_FTOP, C_NTOP, C_HSIZE, C_STAMP, C_JLEN, C_NSTEPS, C_NIV, C_DONE, C_FULL = range(10)
# a batch that stopped for room (C_FULL): the lengths the step that did not fit wanted, per array (for the
# two pools, the slots it wanted past their tops where they were short, else 0: a commit may pack them
# before the arrays grow)
C_WJ, C_WF, C_WN, C_WIV, C_WHEAP, C_WK = range(10, 16)
C_NRM, C_WRM = 16, 17  # the removed faces written to ``rm`` this batch, and the length a step wanted
NCTR = 18
J_HEAP, J_ALIVE, J_AT, J_NBR, J_TRI, J_COUNT, J_CUR, J_BLOCKED = range(8)
OPEN = 1 << 62
M32 = 0xFFFFFFFF


class Settings(NamedTuple):
    """A batch's scalars: how many steps at most, the face target, the cost limit, the mode (manifold, a
    `batches.simple` mesh, parts kept), the flip test's limits (float32), the first scratch row of VQ, and
    whether there are locks."""
    depth: int
    target: int
    max_cost: float
    manifold: bool
    simple: bool
    keep_parts: bool
    cos_max: Any
    shape: Any
    scratch: int
    has_locks: bool


class Partners(NamedTuple):
    """Each vertex's pair partners as a list in a pool (start, length into ``pool``)."""
    start: Any
    count: Any
    pool: Any


class Queue(NamedTuple):
    """The queue's arrays: the heap of stamps, each stamp's key, price, cost, branch, parts and price before
    the seam constraint (RP), and the blocked pairs per vertex (``bat``)."""
    heap: Any
    K: Any
    X: Any
    cost: Any
    branch: Any
    parts: Any
    RP: Any
    bat: Any


class Batch(NamedTuple):
    """One batch's arrays: its steps, stale intervals, the scratch row of each vertex kept in it (``ver``)
    and its row before (``orig``), the journal, the removed faces and the counters."""
    steps: Any
    iv: Any
    ver: Any
    orig: Any
    J: Any
    rm: Any
    ctr: Any


class Maps(NamedTuple):
    """The typed dicts: ``cur`` {pair: current stamp}, ``blocked`` {pair: rule}, and the batch's ``held``
    {pair: its open interval} and ``gone`` {pair: the step that removed it}. Passed apart from the arrays'
    bundles from Python: a typed dict inside a tuple takes numba's slow argument typing at each call."""
    cur: Any
    blocked: Any
    held: Any
    gone: Any


class Seams(NamedTuple):
    """Kept attributes (`wedges`): whether any (``wed``), the corners' wedges C, the wedge values, the seam
    flags, the journal's old values VJ, the model's channels m (-1: none) and the solved channels."""
    wed: bool
    C: Any
    val: Any
    multi: Any
    VJ: Any
    m: int
    m_solved: int
    solved: Any
    weights: Any


@njit(cache=True, inline="always")
def _less(K, s, t):
    """Whether entry s ranks before entry t: by key, then stamp."""
    for i in range(3):
        if K[s, i] != K[t, i]:
            return K[s, i] < K[t, i]
    return s < t


@njit(cache=True)
def heap_push(heap, ctr, K, s):
    i = ctr[C_HSIZE]
    ctr[C_HSIZE] = i + 1
    while i > 0:
        up = (i - 1) >> 1
        if not _less(K, s, heap[up]):
            break
        heap[i] = heap[up]
        i = up
    heap[i] = s


@njit(cache=True)
def heap_pop(heap, ctr, K):
    n = ctr[C_HSIZE] - 1
    ctr[C_HSIZE] = n
    top, last = heap[0], heap[n]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and _less(K, heap[c + 1], heap[c]):
            c += 1
        if not _less(K, heap[c], last):
            break
        heap[i] = heap[c]
        i = c
    if n > 0:
        heap[i] = last
    return top


@njit(cache=True)
def heapify(heap, ctr, K, stamps):
    """The heap of ``stamps`` (any order)."""
    ctr[C_HSIZE] = 0
    for s in stamps:
        heap_push(heap, ctr, K, s)


@njit(cache=True)
def rebuild(heap, ctr, K, cur, blocked):
    """The heap of the current, unblocked entries (old entries dropped)."""
    out = np.empty(len(cur), np.int64)
    k = 0
    for p, s in cur.items():
        if p not in blocked:
            out[k] = s
            k += 1
    heapify(heap, ctr, K, out[:k])


@njit(cache=True, inline="always")
def _pair(u, w):
    return (u << 32) | w if u < w else (w << 32) | u


@njit(cache=True, inline="always")
def _journal(J, ctr, kind, i, o0, o1):
    j = ctr[C_JLEN]
    J[j, 0], J[j, 1], J[j, 2], J[j, 3] = kind, i, o0, o1
    ctr[C_JLEN] = j + 1


@njit(cache=True, inline="always")
def _without(pool, start, length, x, buf):
    """pool[start:start+length] without x, into buf; returns how many."""
    m = 0
    for i in range(start, start + length):
        if pool[i] != x:
            buf[m] = pool[i]
            m += 1
    return m


@njit(cache=True)
def _set_list(start, length, pool, ctr, top, v, items, k):
    """v's list := items[:k], written at the pool's end (the old list stays where it was)."""
    t = ctr[top]
    pool[t:t + k] = items[:k]
    start[v], length[v] = t, k
    ctr[top] = t + k


@njit(cache=True)
def _unblock(p, ctr, J, heap, K, X, cost, branch, parts, RP, cur, blocked, bat, push):
    """Back in the queue at its stored price (a new stamp with the current entry's key and price; into the
    heap unless not ``push``: kept attributes price it first). Returns the stamp."""
    _journal(J, ctr, J_BLOCKED, p, blocked[p], 0)
    del blocked[p]
    bat[p >> 32] -= 1
    bat[p & M32] -= 1
    s = _restamp(p, ctr, J, K, X, cost, branch, parts, RP, cur)
    if push:
        heap_push(heap, ctr, K, s)
    return s


@njit(cache=True)
def _restamp(p, ctr, J, K, X, cost, branch, parts, RP, cur):
    """A new stamp for pair p with its current entry's key and price (journaled)."""
    old = cur[p]
    s = ctr[C_STAMP] + 1
    ctr[C_STAMP] = s
    K[s] = K[old]
    X[s] = X[old]
    cost[s], branch[s] = cost[old], branch[old]
    parts[s] = parts[old]
    RP[s] = RP[old]
    _journal(J, ctr, J_CUR, p, old, 0)
    cur[p] = s
    return s


@njit(cache=True)
def speculate(settings, locked, seams, faces, partners, VQ, N0, cnt, queue, batch, cur, blocked, held, gone):
    """Pop and apply up to ``depth`` steps on the host into ``steps``; ctr[C_NSTEPS] of them. Pairs the
    steps stale are ``held`` out of the queue, pairs they remove are ``gone``. Stops early, with ctr[C_FULL] = 1, before a step that would not fit the arrays
    (the caller grows them; a shorter batch gives the same run), and the lengths that step wanted in
    ctr[C_WJ:C_WK + 1] (the pools: the slots it wanted, where short).

    ``wed``: kept attributes (`wedges`): the tracker's corners' wedges C, values val, seam flags
    multi (changed in place, journaled; VJ (depth + 1, k): old values), the model's channels m (-1: none)
    and the solved channels (m_solved, solved, weights) as `wedges.Tracker` holds them; RP: each stamp's
    price before the seam constraint (x, cost).

    The bundles: ``settings`` (`Settings`), ``seams`` (`Seams`), ``faces`` (`rules.Faces`), ``partners``
    (`Partners`), ``queue`` (`Queue`), ``batch`` (`Batch`), and the dicts of `Maps`; ``locked`` (n,) bool, VQ
    the host rows, N0 the reference normals, ``cnt`` (n,3) zeros: the link condition's scratch."""
    depth, target, max_cost, manifold, simple, keep_parts, cos_max, shape, scratch, has_locks = settings
    wed, C, val, multi, VJ, m, m_solved, solved, weights = seams
    T, alive, fs, fl, fpool = faces
    ns, nl, npool = partners
    heap, K, X, cost, branch, parts, RP, bat = queue
    steps, iv, ver, orig, J, rm, ctr = batch
    maps = Maps(cur, blocked, held, gone)
    ctr[C_NSTEPS] = ctr[C_NIV] = ctr[C_DONE] = ctr[C_FULL] = ctr[C_NRM] = 0
    ctr[C_WJ:C_WK + 1] = 0
    ctr[C_WRM] = 0
    # the heap's size can come back to where it started plus every entry pushed since (an undo pushes
    # back what the batch popped): the room check counts from there
    most = ctr[C_HSIZE]
    common, info = np.empty(2, np.int64), np.empty(5, np.int64)
    A, B, buf = np.empty(64, np.int64), np.empty(64, np.int64), np.empty(64, np.int64)
    D, R = np.empty(64, np.int64), np.empty(128, np.int64)
    TS, UB = np.empty((12, 64), np.int64), np.empty(64, np.int64)  # wedge scratch; a step's repriced stamps
    W = np.empty((4, max(m, val.shape[1], 1)))
    X64 = np.empty(3)
    while ctr[C_FACES] > target and ctr[C_NSTEPS] < depth:
        s = _next_live(heap, K, cur, blocked, held, gone, J, ctr)
        if s < 0:
            break
        k = ctr[C_NSTEPS]
        a, b = np.int64(K[s, 1] & np.uint64(M32)), np.int64(K[s, 2])
        p = a << 32 | b
        step = steps[k]
        step[S_A], step[S_B], step[S_STAMP], step[S_MARK] = a, b, s, ctr[C_JLEN]
        if cost[s] > max_cost:  # left in the queue: the stop report counts it
            step[S_KIND] = STOP
            ctr[C_NSTEPS] = k + 1
            break
        if ctr[C_JLEN] + 4 > len(J):  # the pop, a block, two seam flags
            ctr[C_FULL], ctr[C_WJ] = 1, ctr[C_JLEN] + 4
            break
        heap_pop(heap, ctr, K)
        _journal(J, ctr, J_HEAP, s, 0, 0)
        if fl[a] > len(A) or fl[b] > len(B):
            size = 2 * max(fl[a], fl[b])
            A, B, D, R = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64), \
                np.empty(2 * size, np.int64)
        code = rules_head(a, b, ctr[C_FACES], settings, locked, faces, cnt, Step(info, A, B, D, R, buf), common)
        if code < 0 and wed and (multi[a] or multi[b]):  # the seam rule, where the loop applies it
            TS = gw.fit(TS, max(fl[a], fl[b]))
            if not gw.seam_ok(T, alive, fs, fl, fpool, C, multi, VQ, a, b, X[s], TS, J, ctr, C_JLEN):
                code = SEAM
        if code < 0:
            code = rules_tail(a, b, X[s], ctr[C_FACES], settings, faces, VQ, N0, Step(info, A, B, D, R, buf),
                              common)
        if code < 0 and info[3] and settings.has_locks and drops_locked(R, info[3], T, locked):
            code = LOCKED
        if code >= 0:
            _journal(J, ctr, J_BLOCKED, p, -1, 0)
            blocked[p] = code
            bat[a] += 1
            bat[b] += 1
            step[S_KIND], step[S_CODE] = BLOCK, code
            ctr[C_NSTEPS] = k + 1
            continue
        need_j, need_f, need_n, unb, need_buf = _needs(a, b, info, D, R, T, fl, ns, nl, npool, bat)
        nst = unb
        if wed:  # the wedges' journal rows (`wedges.contract`, a flag pair per pushed pair), and
            # the blocked pairs of two locked vertices around a, priced again (a stamp each)
            need_j += fl[a] + fl[b] + 3 + 2 * (nl[a] + nl[b] + 2 * unb) + unb
            nst = 2 * unb
        nrm = info[0] + info[3]
        if (ctr[C_JLEN] + need_j > len(J) or ctr[C_FTOP] + need_f > len(fpool)
                or ctr[C_NTOP] + need_n > len(npool) or ctr[C_NIV] + nl[a] + nl[b] > len(iv)
                or most + unb > len(heap) or ctr[C_STAMP] + nst + 1 > len(K) or ctr[C_NRM] + nrm > len(rm)):
            ctr[C_JLEN] -= 1  # no room: the pop undone, and the batch ends here
            heap_push(heap, ctr, K, s)
            ctr[C_FULL] = 1
            ctr[C_WJ] = ctr[C_JLEN] + 1 + need_j
            ctr[C_WF] = need_f if ctr[C_FTOP] + need_f > len(fpool) else 0
            ctr[C_WN] = need_n if ctr[C_NTOP] + need_n > len(npool) else 0
            ctr[C_WIV], ctr[C_WHEAP], ctr[C_WK] = ctr[C_NIV] + nl[a] + nl[b], most + unb, ctr[C_STAMP] + nst + 1
            ctr[C_WRM] = ctr[C_NRM] + nrm
            break
        if need_buf > len(buf):
            buf = np.empty(2 * need_buf, np.int64)
        if wed and 2 * unb + nl[a] + nl[b] > len(UB):
            UB = np.empty(2 * (2 * unb + nl[a] + nl[b]), np.int64)
        most += unb
        r0 = ctr[C_NRM]
        rm[r0:r0 + info[0]] = D[:info[0]]
        rm[r0 + info[0]:r0 + nrm] = R[:info[3]]
        ctr[C_NRM] = r0 + nrm
        if wed:  # the corners' wedges, before the faces relink
            TS = gw.fit(TS, max(fl[a], fl[b]))
            X64[0], X64[1], X64[2] = X[s, 0], X[s, 1], X[s, 2]
            gw.contract(T, alive, fs, fl, fpool, C, val, multi, VQ, a, b, X[s], X64, m_solved, solved, weights, locked,
                        TS, W, VJ, ctr[C_DONE], J, ctr, C_JLEN)
        iv0 = ctr[C_NIV]
        nub = _contract(a, b, s, k, scratch, Step(info, A, B, D, R, buf), faces, partners, VQ, locked, queue, batch,
                        maps, wed, UB)
        if wed:
            TS = _push_modes(iv0, nub, UB, faces, seams, VQ, queue, batch, has_locks, locked, W, TS)
        step[S_KIND], step[S_LEFT], step[S_ND], step[S_RM], step[S_NDROP] = CONTRACT, ctr[C_FACES], info[0], \
            r0, info[3]
        ctr[C_NSTEPS] = k + 1


@njit(cache=True, inline="always")
def _pushed_pair(i, niv, iv, iv0, UB, K):
    """`_push_modes`' i-th pair: the i-th new stale interval's, then the unblocked stamps' (``-s - 1``: s)."""
    if i < niv:
        p = iv[iv0 + i, I_PAIR]
        return p >> 32, p & M32
    t = UB[i - niv]
    t = t if t >= 0 else -t - 1
    return np.int64(K[t, 1] & np.uint64(M32)), np.int64(K[t, 2])


@njit(cache=True)
def _push_modes(iv0, nub, UB, faces, seams, VQ, queue, batch, has_locks, locked, W, TS):
    """Kept attributes: what the loop's push after a contraction does with the seam constraint
    (`wedges.Tracker.constrain`), for the pairs it pushes: the new stale intervals iv[iv0:] (their mode,
    priced after the batch) and the stamps in UB[:nub] (pairs back from blocked, priced now and into the
    heap; ``-s - 1``: a pair of two locked vertices, priced and left blocked). The seam flags are read for
    all of them first, as `constrain` does. Returns the wedge scratch (grown where needed)."""
    T, alive, fs, fl, fpool = faces
    C, multi, m = seams.C, seams.multi, seams.m
    heap, K, X, cost, RP = queue.heap, queue.K, queue.X, queue.cost, queue.RP
    iv, J, ctr = batch.iv, batch.J, batch.ctr
    niv = ctr[C_NIV] - iv0
    total = niv + nub
    seam = np.empty(total, np.bool_)
    for i in range(total):
        u, w = _pushed_pair(i, niv, iv, iv0, UB, K)
        seam[i] = multi[u] or multi[w]
    for i in range(total):
        u, w = _pushed_pair(i, niv, iv, iv0, UB, K)
        mode = gw.FREE
        if seam[i]:
            TS = gw.fit(TS, max(fl[u], fl[w]))
            mode = gw.modes(T, alive, fs, fl, fpool, C, multi, u, w, TS, J, ctr, C_JLEN)
        if i < niv:
            iv[iv0 + i, I_MODE] = mode
        else:
            t = UB[i - niv]
            t = t if t >= 0 else -t - 1
            gw.reprice(t, u, w, mode, VQ, K, X, cost, RP, has_locks, locked, m, W)
            if UB[i - niv] >= 0:
                heap_push(heap, ctr, K, t)
    return TS


@njit(cache=True)
def _next_live(heap, K, cur, blocked, held, gone, J, ctr):
    """The stamp of the queue's next live entry (left in the heap), or -1: none left, or no journal room.
    Old entries are popped; those of pairs this batch holds out or removed are popped and journaled (an
    undo of their step makes them current again)."""
    while ctr[C_HSIZE] > 0:
        t = heap[0]
        p = np.int64(K[t, 1] & np.uint64(M32)) << 32 | np.int64(K[t, 2])
        if cur.get(p, -1) != t or p in blocked:  # an old entry: never current again
            heap_pop(heap, ctr, K)
            continue
        if p in held or p in gone:
            if ctr[C_JLEN] + 1 > len(J):
                ctr[C_FULL], ctr[C_WJ] = 1, ctr[C_JLEN] + 1
                return -1
            heap_pop(heap, ctr, K)
            _journal(J, ctr, J_HEAP, t, 0, 0)
            continue
        return t
    return -1


@njit(cache=True)
def _needs(a, b, info, D, R, T, fl, ns, nl, npool, bat):
    """Bounds on what contracting b into a adds (`_contract`): journal rows, face-pool and partner-pool
    slots, blocked pairs coming back (heap entries, stamps), and the scratch buffer's length."""
    nd, nka, nkb, ndrop = info[0], info[1], info[2], info[3]
    unb = 0
    for i in range(ns[a], ns[a] + nl[a]):
        unb += bat[npool[i]]
    for i in range(ns[b], ns[b] + nl[b]):
        unb += bat[npool[i]]
    need_f, need_n, need_buf = nka + nkb, nl[a] + nl[b], nka + nkb + nl[a] + nl[b]
    for i in range(nd + ndrop):  # the lists of the removed faces' corners, each written anew
        f = D[i] if i < nd else R[i - nd]
        for c in T[f]:
            need_f += fl[c]
            need_buf = max(need_buf, fl[c])
    for i in range(ns[b], ns[b] + nl[b]):
        need_n += nl[npool[i]] + 1
        need_buf = max(need_buf, nl[npool[i]] + 1)
    need_j = 16 + 4 * (nd + ndrop) + 3 * nkb + 2 * (nl[a] + nl[b]) + nl[b] + 2 * unb
    return need_j, need_f, need_n, unb, need_buf


@njit(cache=True)
def _contract(a, b, s, k, scratch, step, faces, partners, VQ, locked, queue, batch, maps, wed, UB):
    """Contract b into a at X[s] as step k (journaled): its dead faces D and dropped faces R leave the
    mesh, b's other faces use a; its pairs at b are gone, those at a stale (a new interval each), blocked
    pairs around a back in the queue. ``step``: what `checks.rules_head` left (`Step`); its ``buf``: room for
    the longest list written (`_needs`). ``locked``: pairs of two locked vertices stay blocked (they never
    contract). ``maps``: the dicts (`Maps`). ``wed`` (kept attributes): the pairs back from blocked are not pushed here but listed in UB (with the
    pairs of two locked vertices around a, new stamps: ``-s - 1``) for `_push_modes`; returns how many."""
    info, A, B, D, R, buf = step
    T, alive, fs, fl, fpool = faces
    ns, nl, npool = partners
    heap, K, X, cost, branch, parts, RP, bat = queue
    iv, ver, orig, J, ctr = batch.iv, batch.ver, batch.orig, batch.J, batch.ctr
    cur, blocked, held, gone = maps
    nd, nka, nkb, ndrop = info[0], info[1], info[2], info[3]
    for i in range(nd):
        f = D[i]
        _journal(J, ctr, J_ALIVE, f, 1, 0)
        alive[f] = False
        for c in T[f]:
            if c != a and c != b:
                _journal(J, ctr, J_AT, c, fs[c], fl[c])
                _set_list(fs, fl, fpool, ctr, C_FTOP, c, buf, _without(fpool, fs[c], fl[c], f, buf))
    for i in range(nkb):
        f = B[i]
        for j in range(3):
            if T[f, j] == b:
                _journal(J, ctr, J_TRI, f, j, b)
                T[f, j] = a
    _journal(J, ctr, J_AT, a, fs[a], fl[a])
    m = 0
    for i in range(nka + nkb):  # a's faces: those kept at a and at b, less the dropped ones
        f = A[i] if i < nka else B[i - nka]
        if ndrop == 0 or not has(R, 0, ndrop, f):
            buf[m] = f
            m += 1
    _set_list(fs, fl, fpool, ctr, C_FTOP, a, buf, m)
    _journal(J, ctr, J_AT, b, fs[b], fl[b])
    fl[b] = 0
    for i in range(ndrop):  # dropped as coincident (non-manifold mode): out of their other corners' lists
        f = R[i]
        _journal(J, ctr, J_ALIVE, f, 1, 0)
        alive[f] = False
        for c in T[f]:
            if c != a:
                _journal(J, ctr, J_AT, c, fs[c], fl[c])
                _set_list(fs, fl, fpool, ctr, C_FTOP, c, buf, _without(fpool, fs[c], fl[c], f, buf))
    _journal(J, ctr, J_COUNT, 0, ctr[C_FACES], 0)
    ctr[C_FACES] -= nd + ndrop
    slot = ctr[C_DONE]
    orig[slot] = VQ[a]
    VQ[a, :3] = X[s]
    ver[a] = scratch + slot
    ctr[C_DONE] = slot + 1
    # pair partners: b's become a's; pairs at b are gone, each's stale interval (if any) ends here
    for i in range(ns[b], ns[b] + nl[b]):
        w = npool[i]
        if w != a:
            _journal(J, ctr, J_NBR, w, ns[w], nl[w])
            has_a = has(npool, ns[w], nl[w], a)
            m = _without(npool, ns[w], nl[w], b, buf)
            if not has_a:
                buf[m] = a
                m += 1
            _set_list(ns, nl, npool, ctr, C_NTOP, w, buf, m)
        q = _pair(w, b)
        gone[q] = k
        if q in held:
            iv[held[q], I_END] = k
            del held[q]
    _journal(J, ctr, J_NBR, a, ns[a], nl[a])
    m = _without(npool, ns[a], nl[a], b, buf)
    for i in range(ns[b], ns[b] + nl[b]):
        w = npool[i]
        if w != a and not has(buf, 0, m, w):
            buf[m] = w
            m += 1
    _set_list(ns, nl, npool, ctr, C_NTOP, a, buf, m)
    _journal(J, ctr, J_NBR, b, ns[b], nl[b])
    nl[b] = 0
    # the pairs at a need new prices: held out of the queue, a new stale interval each
    for i in range(ns[a], ns[a] + nl[a]):
        w = npool[i]
        vw = ver[w] if ver[w] >= 0 else w
        q = _pair(a, w)
        if q in held:
            iv[held[q], I_END] = k
        r = ctr[C_NIV]
        held[q] = r
        iv[r, I_PAIR], iv[r, I_START], iv[r, I_END], iv[r, I_MODE] = q, k, OPEN, gw.FREE
        iv[r, I_RA], iv[r, I_RB] = (scratch + slot, vw) if a < w else (vw, scratch + slot)
        ctr[C_NIV] = r + 1
        if q in blocked:
            _journal(J, ctr, J_BLOCKED, q, blocked[q], 0)
            del blocked[q]
            bat[a] -= 1
            bat[w] -= 1
    # blocked pairs around a may have become valid: back in the queue at their stored price
    nub = 0
    s0 = ctr[C_STAMP]
    for i in range(ns[a], ns[a] + nl[a]):
        u = npool[i]
        if bat[u] > 0:
            for jj in range(ns[u], ns[u] + nl[u]):
                q = _pair(u, npool[jj])
                if q in blocked and q not in gone:
                    if not (locked[u] and locked[npool[jj]]):
                        t = _unblock(q, ctr, J, heap, K, X, cost, branch, parts, RP, cur, blocked, bat, not wed)
                        if wed:
                            UB[nub] = t
                            nub += 1
                    elif wed and cur[q] <= s0:  # (pushed again and blocked again by the loop)
                        UB[nub] = -_restamp(q, ctr, J, K, X, cost, branch, parts, RP, cur) - 1
                        nub += 1
    return nub


@njit(cache=True)
def undo(mark, T, alive, fs, fl, ns, nl, heap, K, cur, blocked, bat, J, ctr, C, val, multi, VJ):
    """Every change journaled since ``mark``, undone (last first); C, val, multi, VJ: the wedges'
    (`wedges`)."""
    for j in range(ctr[C_JLEN] - 1, mark - 1, -1):
        kind, i, o0, o1 = J[j, 0], J[j, 1], J[j, 2], J[j, 3]
        if kind == J_HEAP:
            heap_push(heap, ctr, K, i)
        elif kind == J_ALIVE:
            alive[i] = True
        elif kind == J_AT:
            fs[i], fl[i] = o0, o1
        elif kind == J_NBR:
            ns[i], nl[i] = o0, o1
        elif kind == J_TRI:
            T[i, o0] = o1
        elif kind == J_COUNT:
            ctr[C_FACES] = o0
        elif kind == J_CUR:
            cur[i] = o0
        elif kind >= gw.J_MULTI:
            gw.undo_one(kind, i, o0, o1, C, val, multi, VJ)
        elif o0 < 0:  # J_BLOCKED: was not blocked
            del blocked[i]
            bat[i >> 32] -= 1
            bat[i & M32] -= 1
        else:
            if i not in blocked:
                bat[i >> 32] += 1
                bat[i & M32] += 1
            blocked[i] = o0
    ctr[C_JLEN] = mark


@njit(cache=True)
def first_wrong(steps, K, iv, ikeys, n):
    """The first of the ``n`` steps that a stale interval open at
    it (begun before it, not ended before it) ranks before; ``ikeys`` (niv,3) the intervals' keys."""
    niv = len(ikeys)
    h = np.empty(niv, np.int64)  # a heap of interval indices by key (`heap_push`'s, its size in hc)
    hc = np.zeros(C_FULL + 1, np.int64)
    i = 0
    for k in range(n):
        while i < niv and iv[i, I_START] < k:
            heap_push(h, hc, ikeys, i)
            i += 1
        # ended intervals leave when they reach the top: the top is then an open one of the smallest key
        # (whichever of equal keys it is: only its key is compared)
        while hc[C_HSIZE] > 0 and iv[h[0], I_END] < k:
            heap_pop(h, hc, ikeys)
        if hc[C_HSIZE] > 0:
            s, top = steps[k, S_STAMP], h[0]
            for c in range(3):
                if ikeys[top, c] != K[s, c]:
                    if ikeys[top, c] < K[s, c]:
                        return k
                    break
    return n


@njit(cache=True)
def push(P, ikeys, x, cst, br, prt, raw, heap, K, X, cost, branch, parts, RP, cur, blocked, bat, ctr, has_locks,
         locked):
    """Into the queue: pairs P (k,) with keys (k,3) and prices (``raw`` (k,4): position and cost before the
    seam constraint), a new stamp each, in order; pairs of two ``locked`` vertices blocked (rule LOCKED:
    they never contract)."""
    for r in range(len(P)):
        p = P[r]
        s = ctr[C_STAMP] + 1
        ctr[C_STAMP] = s
        K[s] = ikeys[r]
        X[s] = x[r]
        cost[s], branch[s] = cst[r], br[r]
        parts[s] = prt[r]
        RP[s] = raw[r]
        cur[p] = s
        if p in blocked:
            del blocked[p]
            bat[p >> 32] -= 1
            bat[p & M32] -= 1
        heap_push(heap, ctr, K, s)
        if has_locks and locked[p >> 32] and locked[p & M32]:
            blocked[p] = LOCKED
            bat[p >> 32] += 1
            bat[p & M32] += 1


@njit(cache=True)
def forget_gone(gone, ok, cur, blocked, bat):
    """Commit: the pairs the steps before ``ok`` removed leave the queue."""
    for p, k in gone.items():
        if k < ok:
            cur.pop(p, 0)
            if p in blocked:
                del blocked[p]
                bat[p >> 32] -= 1
                bat[p & M32] -= 1


@njit(cache=True)
def last_intervals(iv, niv, ok, gone):
    """Commit: each pair's last interval that began in a step before ``ok``, pairs the steps before ``ok``
    removed left out; interval indices in order of the pairs' first interval."""
    last = dict()
    order = []
    for r in range(niv):
        if iv[r, I_START] >= ok:
            break
        p = iv[r, I_PAIR]
        if p not in last:
            order.append(p)
        last[p] = r
    out = np.empty(len(order), np.int64)
    k = 0
    for p in order:
        if gone.get(p, ok) >= ok:
            out[k] = last[p]
            k += 1
    return out[:k]


@njit(cache=True)
def renumber(heap, ctr, K, X, cost, branch, parts, RP, cur, blocked):
    """The current entries' stamps renumbered 1, 2, ... in their order (a stamp's rows moved with it), and
    the heap rebuilt from them: entries order as before, and old stamps no longer hold rows, so that the
    stamp arrays stay as long as the queue, not as the run's pushes (between batches only: the journal
    and a batch's steps hold stamps)."""
    ks, vs = export(cur)
    order = np.argsort(vs)
    for r in range(len(order)):
        i = order[r]
        old, s = vs[i], r + 1  # s <= old (distinct stamps from 1, in order): rows move down, in place
        if s != old:
            K[s] = K[old]
            X[s] = X[old]
            cost[s], branch[s] = cost[old], branch[old]
            parts[s] = parts[old]
            RP[s] = RP[old]
        cur[ks[i]] = s
    ctr[C_STAMP] = len(order)
    rebuild(heap, ctr, K, cur, blocked)


@njit(cache=True)
def compact(start, length, pool, extra):
    """The lists moved to a new pool, packed (``extra`` free slots after)."""
    total = 0
    for v in range(len(start)):
        total += length[v]
    new = np.empty(total + extra, np.int64)
    t = 0
    for v in range(len(start)):
        k = length[v]
        new[t:t + k] = pool[start[v]:start[v] + k]
        start[v] = t
        t += k
    return new, t


@njit(cache=True)
def fill_cur(P, stamps, cur):
    for r in range(len(P)):
        cur[P[r]] = stamps[r]


@njit(cache=True)
def new_dict():
    """An empty int64 -> int64 typed dict, made in compiled code: made from Python, numba compiles its
    constructor afresh in every process (it cannot cache it)."""
    return Dict.empty(key_type=types.int64, value_type=types.int64)


@njit(cache=True)
def size(d):
    """len(d) of a typed dict, compiled and cached (from Python, numba compiles len afresh per process)."""
    return len(d)


@njit(cache=True)
def export(d):
    """A typed dict's keys and values as arrays."""
    ks = np.empty(len(d), np.int64)
    vs = np.empty(len(d), np.int64)
    k = 0
    for p, v in d.items():
        ks[k], vs[k] = p, v
        k += 1
    return ks, vs
