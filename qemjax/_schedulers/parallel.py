"""Independent-set scheduler: many non-interacting contractions per round.

A round is five named stages over a `RoundState`:

1. **update** the candidate pairs after the last round's contractions (manifold mode: through the
   contractions, `topo.contract_edges`; otherwise rebuilt from the faces and matched by key);
2. **cost**: price the pairs whose cost is stale with the cost model's batched kernel (fixed-size
   chunks: one compilation per size); the rest keep their numbers. Which pairs go stale is the model's
   ``support``: the pairs at moved vertices, or (``"ring"``) every pair in their 1-rings;
3. **select**, in passes, pairs that are the cheapest among all candidate pairs touching their
   endpoints' closed 1-rings (ties broken by a scramble of the pair index in an int64 key), so no two
   selected pairs share a vertex, a face or a 1-ring neighbour;
4. **validate** them (flip kernel, coincident faces, link test): invalid ones leave the candidate set
   with the rule they broke, valid ones lock their 1-rings, and the next pass selects among what is
   still free;
5. **contract** the accepted set at once (the model's merge; the faces through the vertex->face lists of
   `FaceLists`: validation looks them up and the contraction reuses that look-up, so neither scans the
   whole mesh).
Kernel calls are asynchronous: the re-costing, the flip test and the merges run on JAX's threads while
the host works on the topology, and are waited for only where their results are needed. One host worker
thread runs the link test and the edge update beside the main thread's face work, half of each large
narrowing pass, and the initial face lists beside the input normals (numpy releases the GIL in large
array passes; the process otherwise used 1.2 of 2 cores). Work on fewer than `select.INLINE_ROWS` rows
runs on the main thread instead: on a small mesh, waking the worker on the other core costs more than it
overlaps.
Because accepted contractions are two edges apart, the validity computed for each stays true when all
happen together. The last round takes only as many, in cost order, as the exact face target allows.
"""
from __future__ import annotations

import dataclasses
import time

import jax.numpy as jnp
import numpy as np

from . import locks as _locks
from .._mesh import topology as topo
from .._mesh.fixed_order import weighted_sum
from .._mesh.arrays import any_at, keep_rows as _keep, put_rows, take_rows as _take
from .._kernels.batching import CHUNKS
from .._costs import MeshView
from .._mesh.edges_jit import endpoints
from .._mesh.faces_jit import first_step
from .._mesh.incidence import FaceLists
from .._mesh import rows_jit
from . import outcome, round_glue_jit, round_jit
from .._kernels.flips import SLIVER
from .common import (DTYPE, Options, Priced, Timer, bucket, face_normals, fuses, kept_fuses, on_device, pad_rows,
                     set_rows, start_flips, start_merge, start_price, start_step, step_one)
from .select import fits_target, gate_rank, independent_sets, sort_keys, submit

MERGE_CHUNK = 4096  # the piece shape of a round's merge and device row update (one compilation) ...
SMALL_CHUNK = CHUNKS[0]  # ... or, for a mesh of at most SMALL_MESH faces, this one: such a mesh's rounds
SMALL_MESH = 1 << 14  # contract ~100 pairs, and a 4096-row scatter costs ~12x a 256-row one. Chosen per run,
# from the mesh's size, so that meshes of similar size compile the same shapes whatever their rounds


# the shapes of the stale pairs priced in a round's one device call (`common.start_step`), by merge piece:
# the smallest that holds a round's stale pairs, else the largest and more calls. The cow's rounds to 10 %
# have 350 (median) to 1,113, the bunny's 6,020 to 13,592 (experiments/device_calls.py); two shapes per
# size class, so a run compiles at most two such calls
STEP_PRICE = {SMALL_CHUNK: (1024, 4096), MERGE_CHUNK: (4096, 16384)}


def _holding(sizes: tuple, k: int) -> int:
    """The smallest of ``sizes`` (ascending) that holds k rows, else the largest."""
    return next((s for s in sizes if s >= k), sizes[-1])


def merge_size(m: int) -> int:
    """The fixed piece shape of the merges and device row updates of a run on m faces."""
    return SMALL_CHUNK if m <= SMALL_MESH else MERGE_CHUNK


@dataclasses.dataclass
class RoundState:
    """What a round knows of its candidate pairs; every per-pair array is aligned with ``E``.

    E (P,2) pairs (mesh edges, plus close pairs with aggregation), ecount (P,) faces at each, deg (n,)
    edges at each vertex, bvert (n,) boundary vertices, keys (P,) sorted pair keys when E was rebuilt
    (None when it was updated in place); x (P,3), cost (P,), branch (P,) int8: the current prices;
    parts (P,p) float32: the model's cost parts (p may be 0); key (P,): what selection ranks (the cost,
    or for a model with `rank_weights` the cost plus its weighted parts);
    bad (P,) int8: the rule a pair broke when last validated (0: not known invalid); changed (n,) bool:
    vertices whose pairs need a new price next round; edges_next: `topo.contract_edges`' result when the
    pairs were updated through the contractions (manifold mode)."""

    E: np.ndarray
    ecount: np.ndarray
    deg: np.ndarray
    bvert: np.ndarray = None
    keys: np.ndarray | None = None
    x: np.ndarray = None
    cost: np.ndarray = None
    branch: np.ndarray = None
    parts: np.ndarray = None
    key: np.ndarray = None
    bad: np.ndarray = None
    changed: np.ndarray = None
    edges_next: tuple | None = None
    # (the stale rows of edges_next, a function giving their price started with the last round's merge) when it
    # is known: a `Priced` (`cost`), or on a `fast` run the kernel's raw (5 + p, ≥ K) output (`carry`)
    next_price: tuple | None = None


def _with_extra_pairs(E, ecount, extra_pairs, n):
    """Candidate pairs = mesh edges ∪ extra (non-edge) pairs, sorted by key; non-edges count 0 faces."""
    if len(extra_pairs) == 0:
        return E, ecount
    xk = np.unique(topo.edge_keys(extra_pairs[:, 0], extra_pairs[:, 1], n))
    ek = topo.edge_keys(E[:, 0], E[:, 1], n)
    xk = xk[~np.isin(xk, ek)]
    keys = np.concatenate([ek, xk])
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    E = topo.key_pairs(keys, n, E.dtype)
    return E, np.concatenate([ecount, np.zeros(len(xk), np.int64)])[order]


def _accepted(E, found, take):
    """The pairs marked in ``take`` (len(E),) bool with what validation found for them (``found``: pair
    indices, kept faces, dead faces and, in manifold mode, the apexes per pass; `FaceLists.touched_with_dead`,
    `topo.link_ok`), renumbered as one set in pass order: pairs (S,2), the arguments ``kept`` and ``dead``
    of `FaceLists.contract_touched`, and the apexes (S,2) (None outside manifold mode).

    A kept face's position w counts endpoints (2·pair + side, side 1 at b), as `FaceLists` numbers them."""
    pairs, ws, fs, cs, ds, xs = [], [], [], [], [], []
    off = 0
    for idx, (w, f, c), (df, downer), apex in found:
        t = take[idx]
        pos = np.cumsum(t) - 1 + off  # each taken pair's place in the combined set
        pair_of, side = w >> 1, w & 1
        keep = t.take(pair_of)
        ws.append(2 * pos.take(pair_of.compress(keep)) + side.compress(keep))
        fs.append(f.compress(keep))
        cs.append(c.compress(keep))
        ds.append(df.compress(t.take(downer)))
        pairs.append(_take(E, idx.compress(t)))
        if apex is not None:
            xs.append(_keep(apex, t))
        off += int(t.sum())
    cat = np.concatenate
    return cat(pairs), (cat(ws), cat(fs), cat(cs)), cat(ds), cat(xs) if xs else None


def _ring_vertices(faces: FaceLists, verts, n):
    """(n,) bool: ``verts`` and every vertex sharing a live face with one."""
    t = np.zeros(n, bool)
    t[verts] = True
    t[_take(faces.F, faces.around(verts)[1]).reshape(-1)] = True
    return t


def _drop_coincident(faces: FaceLists, kept):
    """Resolve faces that coincide after contractions into the vertices ``kept`` (all such faces touch
    one), lower face index first (`topo.coincident_removals`). Returns the faces removed."""
    f = np.unique(faces.around(kept)[1])
    drop = f[topo.coincident_removals(_take(faces.F, f))]
    faces.remove(drop)
    return drop


def _removal_steps(F, rounds, a, b, dead, dropped):
    """Which contraction removed each face, from a run's per-round arrays (no per-contraction work):
    F (m,3) the faces at the end (a removed face keeps the row it had when it went), rounds, a, b the
    round, kept and removed vertex of each contraction in record order (`_history_columns`), dead /
    dropped the faces each round's contractions removed / its coincident faces dropped. Returns the record's ``removed_at`` (m,) int64
    (-1: survives), ``coincident`` (m,) bool and ``rounds`` (k,) int64 (see `_record.Record`).

    A face that dies in a contraction holds its removed vertex and vertices removed later or never: its
    step is the smallest removal step of its corners. A dropped face holds the kept vertex of the one
    contraction of its round that made it coincide (contractions of a round are two edges apart)."""
    m = len(F)
    removed_at, coincident = np.full(m, -1, np.int64), np.zeros(m, bool)
    if not len(a):
        return removed_at, coincident, rounds
    n = int(max(a.max(), b.max(), F.max() if m else 0)) + 1
    step_of = np.full(n, np.iinfo(np.int64).max)
    step_of[b] = np.arange(len(b))
    for di in dead:  # each dying face's smallest corner step (compiled: no (k,3) temporaries)
        first_step(F, step_of, di, removed_at)
    if dropped:
        f = np.concatenate([x for _, x in dropped]).astype(np.int64)
        r = np.repeat([r for r, _ in dropped], [len(x) for _, x in dropped]).astype(np.int64)
        key = rounds * n + a  # (round, kept vertex) -> step; unique, sorted by round
        order = np.argsort(key, kind="stable")
        ck = (r[:, None] * n + F[f]).reshape(-1)
        at = np.minimum(np.searchsorted(key[order], ck), len(key) - 1)
        hit = np.where(key[order][at] == ck, order[at], -1).reshape(-1, 3)
        removed_at[f] = hit.max(axis=1)
        coincident[f] = True
    return removed_at, coincident, rounds


class EdgeUpdate:
    """`round_jit.contract_edges` with its two passes over every pair (listing the rows at an endpoint,
    copying the rows that stay) each split between the worker thread and the calling one: the first half's
    listing starts on the worker when the update is made, the rest runs when its `result` is asked for.
    The threads write disjoint parts of the arrays; the steps and the result are `contract_edges`'
    (tests/test_round_jit.py compares them). Before, the calling thread waited for the whole update on the
    worker once its own face update was done."""

    def __init__(self, E, ecount, deg, a, b, apex, label):
        self.args = (E, ecount, deg, a, b, apex, label)
        P = len(E)
        self.h = h = P // 2
        round_jit.label_pairs(a, b, label)
        self.lists = round_jit.listing(E, ecount, P)
        self.first = submit(round_jit.list_rows, E, ecount, label, 0, h, *(x[:h] for x in self.lists), size=h)

    def result(self):
        """(E', ecount', keep, degree', stale'), as `round_jit.contract_edges` returns them."""
        E, ecount, deg, a, b, apex, label = self.args
        P, h = len(E), self.h
        n_hi = round_jit.list_rows(E, ecount, label, h, P, *(x[h:] for x in self.lists))
        n_lo = self.first.result()
        listed = []
        for x in self.lists:  # the upper half's listed rows moved down after the lower half's
            x[n_lo:n_lo + n_hi] = x[h:h + n_hi]
            listed.append(x[: n_lo + n_hi])
        rows, lab, far, nu, nv, cnt = listed
        keep, d2, m = round_jit.listed_rows(E, deg, a, b, apex, label, rows, lab, far, nu, nv, cnt)
        E3, c3 = np.empty((m, 2), E.dtype), np.empty(m, ecount.dtype)
        k0 = h - int(np.count_nonzero(~keep.take(rows[:n_lo])))  # the rows kept before h
        lower = submit(round_jit.copy_rows, E, ecount, keep, 0, h, E3, c3, 0, size=h)
        round_jit.copy_rows(E, ecount, keep, h, P, E3, c3, k0)
        lower.result()
        return E3, c3, keep, d2, round_jit.rewrite_rows(rows, keep, nu, nv, cnt, E3, c3)


def _history_columns(history):
    """A run's per-round [(round, (kept, removed, positions, costs))] -> each contraction's round, kept
    and removed vertex (k,) int64, position (k,3) and cost (k,), in record order."""
    if not history:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                np.zeros(0))
    rounds = np.repeat([r for r, _ in history], [len(h[0]) for _, h in history]).astype(np.int64)
    cols = [np.concatenate([h[i] for _, h in history]) for i in range(4)]
    return rounds, cols[0].astype(np.int64), cols[1].astype(np.int64), cols[2], cols[3]


def _history_arrays(a, b, x, cost):
    """The record's history: pairs (k,2) int64, positions (k,3), costs (k,) (float64 empties when k = 0)."""
    if not len(a):
        return np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0)
    return np.stack([a, b], 1), x, cost


class _Run:
    """One simplification: the mesh state that lives across rounds, and the stages of a round."""

    def __init__(self, V, S, F, extra_pairs, target_faces, model, options: Options, progress, edges,
                 part_scale=None, params=None, wedges=None, normals=None, locks=None):
        self.n, m = len(V), len(F)
        self.merge_chunk = merge_size(m)
        self.price_sizes = STEP_PRICE[self.merge_chunk]
        self.wedges = wedges  # a `_wedges.Tracker` when attributes are kept (else None)
        self.locks = locks  # a `_locks.RunLocks` (else None); the weights are carried in a copy
        self.weights = None if locks is None or locks.weights is None else np.array(locks.weights, np.float64)
        self.part_scale = part_scale
        self.model, self.options, self.progress = model, options, progress
        self.params = model.kernel_params() if params is None else params
        if isinstance(self.params, dict):  # the settings cross to the device once, not with every kernel call
            self.params = on_device(self.params)
        self.cos_max = jnp.asarray(np.asarray(options.cos_max, DTYPE))  # the flip threshold, likewise
        self.target = target_faces
        self.manifold = options.preserve_topology
        self.extra_pairs = np.asarray(extra_pairs, np.int32).reshape(-1, 2)
        # manifold mode: the pairs are updated through each round's contractions instead of rebuilt
        self.incremental = self.manifold and len(self.extra_pairs) == 0
        n_cap = bucket(self.n + 1)
        self.pad = self.n  # a zero row past the last vertex: padding for ring gathers
        self.VQ = np.zeros((n_cap, 3 + model.width), DTYPE)  # rows [position, model state]
        self.VQ[: self.n, :3], self.VQ[: self.n, 3:] = V, S
        self.VQd = jnp.asarray(self.VQ)  # device copy, updated row by row
        # the first costing of the given edges runs while the host sets up the faces (unless the model
        # needs the faces for it)
        self.first = None
        if edges is not None and len(self.extra_pairs) == 0 and not model.uses_ring:
            self.first = start_price(model, self.VQd, edges[0], self.params)
        self.edges = edges
        # int32 rows (n < 2**31) keep their index: face i continues input face i; built on the worker
        # while this thread computes the input normals
        lists = submit(FaceLists, F, self.n, size=m)
        N0 = face_normals(np.asarray(V, DTYPE), F) if normals is None else normals  # input normals
        self.N0d = jnp.asarray(pad_rows(N0, bucket(m)))  # padded: one compilation per size class
        # the common case's rounds run as compiled loops (`round_jit`), with the flip test on the host
        self.compiled = round_jit.fits(self.manifold, self.incremental, locks, m)
        # a round's merge, row update and the next round's price in one device call (`start_step`); with locks
        # only on the compiled path (`carry` applies the locks to the device's price there), so that a locked run
        # on the numpy stages stays the reference it is for the compiled one
        self.fused = self.incremental and (locks is None or self.compiled) and fuses(model)
        self.merged = None  # (kept vertices, their merged states) not yet in VQ: `settle`
        if self.incremental:
            self.label = np.full(self.n, -1, np.int32)  # scratch of `round_jit.contract_edges`
        if self.compiled:
            self.N0 = np.ascontiguousarray(N0, DTYPE)
            # the positions alone for the host flip test: a seventh of VQ's rows to pull through the caches
            self.V3 = np.ascontiguousarray(self.VQ[:, :3])
            self.flip_limits = (np.float32(options.cos_max), np.float32(SLIVER))
            self.mark = np.zeros(self.n, np.int32)  # scratch of `round_jit.select_validate`
            self._rows = self._verts = None  # more of it (`scratch`)
            self.one_copy = np.zeros(self.n, np.int32)  # a run alone is one copy (`passes`)
            # kept attributes: the wedge of each face corner and the seam vertices, for the seam rule
            self.seams = ((np.zeros((0, 3), np.int64), np.zeros(self.n, bool)) if wedges is None
                          else (wedges.C, wedges.multi))
            # locked vertices and the scratch of their rule (`round_jit._all_dying`); empty: no locks
            self.lock_rule = ((np.zeros(0, bool), np.zeros(0, np.int32)) if locks is None
                              else (np.ascontiguousarray(locks.locked, bool), np.full(self.n, -1, np.int32)))
        # and the glue between those loops and the device call compiled too (`round_glue_jit`): one run
        # whose rounds are the compiled loops with the fused device call (a batch sets it False: its gates
        # and budgets are per copy)
        self.fast = self.compiled and self.fused
        if self.fast:
            self.at_kept = None  # (`contract_fast`) the next round's price at locked kept vertices, started
            self.kept_fuses = locks is not None and kept_fuses(model)  # ... in the round's device call
            self.limit = round_glue_jit.bound(options.max_cost, DTYPE)  # as `candidates` compares it
            # the free cost at each vertex's part scale, as `select` takes it per pair (empty: one part)
            self.free_at = (np.zeros(0) if part_scale is None
                           else options.schedule.free_cost * np.asarray(part_scale))
        self.faces = lists.result()
        self.timer = Timer()
        self.history = []  # per round: (round, (kept, removed, positions, costs)) in record order
        self.dead, self.dropped = [], []  # per round: faces its contractions removed; (round, coincident drops)
        self.branches = np.zeros(len(model.branches), np.int64)
        self.rounds = self.rejected = 0
        self.rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
        self.max_cost_used = 0.0
        self.faces_per_round = []
        self.rank_w, self.weighed_at, self.reweights = None, 0, []  # ranking weights (`rank`)
        self.history_parts = []

    # -- stage 1: update ---------------------------------------------------------------------------
    def update(self, prev: RoundState | None):
        """This round's pairs. Returns the new state (prices not yet filled), the function that carries
        the last round's per-pair arrays over to the new pairs, which of them are stale (P,) bool, and
        on a rebuild which of them existed before (P,) bool (else None). On the first round the last
        three are None."""
        n = self.n
        if prev is None or prev.edges_next is None:
            if self.edges is not None:
                # the caller's arrays as they are when int32 (read only here: every round makes new ones)
                E, ecount = np.asarray(self.edges[0], np.int32), self.edges[1]
                self.edges = None
            else:
                E, ecount = topo.edges(self.faces.live(), n)
            E, ecount = _with_extra_pairs(E, ecount, self.extra_pairs, n)
            if self.compiled:  # face counts are small: int32 halves the largest per-pair array but x
                ecount = np.asarray(ecount, np.int32)
            deg = topo.vertex_degree(E if self.incremental else _keep(E, ecount > 0), n)
            keys = None if self.incremental else topo.edge_keys(E[:, 0], E[:, 1], n)  # sorted, as E is
            st = RoundState(E, ecount, deg, keys=keys)
            if prev is None:
                return st, None, None, None
            # rebuilt (never incremental here): find each pair's predecessor by key
            src = np.minimum(np.searchsorted(prev.keys, keys), len(prev.keys) - 1)
            same = prev.keys[src] == keys
            return st, (lambda a: _take(a, src)), any_at(prev.changed, E) | ~same, same
        E, ecount, kept, deg, stale = prev.edges_next
        st = RoundState(E, ecount, deg)
        if self.model.support == "ring":
            stale = stale | any_at(prev.changed, E)
        # several arrays follow, each moved down in place (the last round's arrays are not read again)
        idx = np.flatnonzero(kept)
        return st, (lambda a: rows_jit.compact(a, idx)), stale, None

    def carry(self, prev: RoundState, need: int):
        """Stages 1 and 2 and the candidates (`update`, `cost`, `candidates`) of a `fast` run's round after
        the first, in one compiled pass once the device's prices are in (`round_glue_jit.carry`). Returns
        the new state and its candidates."""
        t0 = time.perf_counter()
        E, ecount, kept, deg, stale = prev.edges_next
        d, raw = prev.next_price
        prev.next_price = None
        self.settle()
        out = raw()
        t1 = time.perf_counter()
        st = RoundState(E, ecount, deg)
        if self.locks is not None:  # locked kept vertices and the weights, as `cost` applies them
            out = self.locked_raw(out, _take(E, d), self.at_kept)
            self.at_kept = None
        st.x, st.cost, st.branch, st.parts, st.bad, st.bvert, valid, _ = round_glue_jit.carry(
            kept, d, out, prev.x, prev.cost, prev.branch, prev.parts, prev.bad, E, ecount, self.n, self.limit,
            need, self.manifold, self.lock_rule[0])
        if self.wedges is not None:  # stale pairs at seam vertices: placed at an allowed endpoint (as `cost`)
            self.place_at_seams(st, d)
            if self.locks is not None:  # as `cost`: two locked vertices stay LOCKED, a locked kept one pinned
                Pd = _take(E, d)
                st.bad[d[_locks.both_locked(self.locks, Pd)]] = outcome.LOCKED
                xd = _take(st.x, d)
                _locks.pin(self.locks, self.VQ, Pd, xd)
                put_rows(st.x, d, xd)
            valid[d] = self.candidates_of(st.cost[d], st.bad[d], ecount[d], need)  # their candidate test again
        self.timer.add("kernels_s", t1 - t0)
        self.timer.add("topology_s", time.perf_counter() - t1)
        return st, valid

    # -- stage 2: cost -----------------------------------------------------------------------------
    def cost(self, st: RoundState, prev, follow, stale, same):
        """Fill the prices of ``st``: new ones for the stale pairs (the kernel runs while the host works
        on), the last round's for the rest, and what is known to be invalid."""
        t0 = time.perf_counter()
        model, VQd = self.model, self.VQd
        if prev is None:
            pending = self.first or start_price(model, VQd, st.E, self.params, self.faces, self.pad)
            self.first = None
            st.bad = np.zeros(len(st.E), np.int8)
            if self.locks is not None:
                pending = self.locked_prices(pending, st.E)
        else:
            if prev.next_price is not None:  # started with the last round's merge (`contract`)
                d, pending = prev.next_price
                prev.next_price = None
            else:
                d = np.flatnonzero(stale)
                pending = start_price(model, VQd, _take(st.E, d), self.params, self.faces, self.pad)
            if self.locks is not None:
                pending = self.locked_prices(pending, _take(st.E, d))
            st.bad = follow(prev.bad)  # found invalid, and their neighbourhood has not changed since
            if same is not None:
                st.bad = st.bad * same
        st.bvert = endpoints(st.E, st.ecount == 1, self.n)
        self.timer.add("topology_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        self.settle()
        if prev is None:
            st.x, st.cost, st.branch, parts = pending()
            st.parts = np.ascontiguousarray(parts.T)
        else:
            # separate arrays, each under 32 MB at 2 M edges: glibc maps larger ones afresh every time
            # (page faults on every round; one (E,5) array was slower to gather here)
            st.x, st.cost, st.branch = follow(prev.x), follow(prev.cost), follow(prev.branch)
            xd, st.cost[d], st.branch[d], parts = pending()
            put_rows(st.x, d, xd)
            # (a model without cost parts: no take of P empty rows, which numpy still spends P checks on)
            st.parts = follow(prev.parts) if prev.parts.shape[1] else prev.parts[:0].reshape(len(st.E), 0)
            if len(parts):  # a model with cost parts
                put_rows(st.parts, d, np.ascontiguousarray(parts.T))
        if self.wedges is not None:  # pairs at seam vertices: placed at an allowed endpoint
            self.place_at_seams(st, np.arange(len(st.E)) if prev is None else d)
        if self.locks is not None:  # pairs of two locked vertices never contract
            st.bad[_locks.both_locked(self.locks, st.E)] = outcome.LOCKED
            if self.wedges is not None:  # a seam placement never moves a locked vertex
                _locks.pin(self.locks, self.VQ, st.E, st.x)
        self.timer.add("kernels_s", time.perf_counter() - t0)

    def place_at_seams(self, st: RoundState, d):
        """Newly priced pairs d at seam vertices (kept attributes): placed at an allowed endpoint, and marked
        `outcome.SEAM` where none is (`wedges.Tracker.constrain`)."""
        self.wedges.constrain_rows(self.faces, self.VQ, st.E, d, st.x, st.cost, st.bad, outcome.SEAM)

    def settle(self):
        """The last round's merged vertex states into the host rows VQ (`contract` leaves them on the device
        while the host works on): before anything reads VQ's states, and at the end of the run."""
        if self.merged is not None:
            a, merged = self.merged
            self.merged = None
            self.VQ[a, 3:] = merged()

    def locked_raw(self, out, P, at=None):
        """The device's raw price ``out`` (5 + p, ≥ K) of pairs P (K,2) (`common.step_one`) with locked kept
        vertices and the weights applied (`_locks.adjust`, on the `Priced` that `cost` would make of it;
        ``at``: its price at the kept vertices, started with the device call, or None): (5 + p, K), the same
        values in the same dtypes."""
        K = len(P)
        pr = Priced(out[:3, :K].T, out[3, :K], out[4, :K].astype(np.int8), out[5:, :K])
        at = _locks.adjust(self.locks, self.weights, self.model, self.VQ, self.VQd, P, pr, self.params, self.faces,
                           self.pad, at=at)
        res = np.empty((out.shape[0], K), out.dtype)
        res[:3], res[3], res[4], res[5:] = at.x.T, at.cost, at.branch, at.parts
        return res

    def locked_prices(self, pending, P):
        """``pending`` (a price of pairs P) with locked kept vertices and the weights applied (`_locks.adjust`)."""
        return lambda: _locks.adjust(self.locks, self.weights, self.model, self.VQ, self.VQd, P, pending(),
                                     self.params, self.faces, self.pad)

    def rank(self, st: RoundState, valid: np.ndarray):
        """Set ``st.key``: the cost, or for a model with `rank_weights` the cost plus its weighted parts,
        with weights taken from the candidate pairs (``valid``) at the start and again whenever the face
        count has fallen by the model's ``reweight_step`` since (then recorded in ``reweights``)."""
        if self.model.rank_weights is None:
            st.key = st.cost
            return
        count = self.faces.count
        if self.rank_w is None or count <= (1.0 - self.model.reweight_step) * self.weighed_at:
            self.rank_w = self.model.rank_weights(st.parts.compress(valid, axis=0))
            self.weighed_at = count
            self.reweights.append((count, self.rank_w))
        st.key = (st.cost + weighted_sum(st.parts, self.rank_w)).astype(DTYPE)

    # -- stages 3 and 4: select and validate -------------------------------------------------------
    def candidates(self, st: RoundState, need, max_cost=None) -> np.ndarray:
        """(P,) bool: the pairs that may contract this round (not known invalid, within max_error and
        the face budget; manifold mode: edges with one or two faces). ``need`` and ``max_cost`` may be
        given per pair (a batch's copies); max_cost None: the options'."""
        return self.candidates_of(st.cost, st.bad, st.ecount, need, max_cost)

    def candidates_of(self, cost, bad, ecount, need, max_cost=None) -> np.ndarray:
        """`candidates` of pairs given by their costs, known rules and face counts."""
        limit = self.options.max_cost if max_cost is None else max_cost
        valid = (cost <= limit) & (bad == 0) & (ecount <= need)
        if self.manifold:
            valid &= (ecount >= 1) & (ecount <= 2)
        return valid

    def select(self, st: RoundState, need: int, valid: np.ndarray):
        """The accepted pairs in cost order, cut to the face target; records the rejected ones in
        ``st.bad``. Returns (accepted indices, how many were selected, how many were rejected, the
        locked vertices, what validation found for them)."""
        if self.fast:
            return self.select_fast(st, need, valid)
        t0 = time.perf_counter()
        sch = self.options.schedule
        k = gate_rank(need, int(valid.sum()), len(st.E), sch)
        kth = np.partition(st.key.compress(valid), k - 1)[k - 1]
        salt = self.rounds * 7919

        def key_of(idx):
            return sort_keys(st.key, idx, salt)
        free = sch.free_cost if self.part_scale is None else sch.free_cost * self.part_scale[st.E[:, 0]]
        cand = valid & (st.key <= np.maximum(sch.gate * kth, free))
        acc, bad, why, extra, locked, found = self.passes(st, key_of, cand, need, None)
        self.rejected += bad.size
        self.rejected_by += np.bincount(why, minlength=len(self.rejected_by))
        n_sel = acc.size
        order = np.argsort(key_of(acc), kind="stable")
        fit = fits_target(st.ecount[acc[order]] + (0 if extra is None else extra[acc[order]]), need)
        acc = acc[order[fit]]
        if self.compiled:  # the apexes of the accepted pairs, in the same order
            found = found[order[fit]]
        self.timer.add("select_s", time.perf_counter() - t0)
        st.bad[bad] = why
        return acc, n_sel, bad.size, locked, found

    def select_fast(self, st: RoundState, need: int, valid: np.ndarray):
        """`select` for a `fast` run: the gate, the order and the face target as compiled passes
        (`round_glue_jit`), the threshold's arithmetic as numpy does it. Returns what `select` returns, the
        pool room the contraction takes last."""
        t0 = time.perf_counter()
        sch = self.options.schedule
        k = gate_rank(need, int(np.count_nonzero(valid)), len(st.E), sch)
        thr = sch.gate * np.partition(st.key.compress(valid), k - 1)[k - 1]
        if not len(self.free_at):
            thr = np.maximum(thr, sch.free_cost)
        cand = round_glue_jit.under_gate(st.key, valid, thr, st.E, self.free_at)
        acc, bad, why, _, locked, apex = self.passes(st, None, cand, need, None)
        self.rejected += bad.size
        self.rejected_by += np.bincount(why, minlength=len(self.rejected_by))
        n_sel = acc.size
        acc, apex, room = round_glue_jit.order_fit(acc, apex, st.key, st.ecount, (self.rounds * 7919) & 0xFFFFFFFF,
                                                   need, self.faces.cnt, st.E)
        self.timer.add("select_s", time.perf_counter() - t0)
        st.bad[bad] = why
        return acc, n_sel, bad.size, locked, (apex, room)

    def passes(self, st: RoundState, key_of, cand, need, groups, local=None):
        """The selection passes with validation (`select.independent_sets`; ``groups``: a batched run's
        (vcopy, need per copy, pair copies), ``local``: each pair's index within its copy). Returns
        (accepted pairs in pass order, rejected pairs, their rules, the extra faces each accepted pair
        removes (None: none), the locked vertices, what validation found: for the compiled loops the
        accepted pairs' apexes (S,2), else the list `validate` fills)."""
        sch = self.options.schedule
        if not self.compiled:
            found = []
            acc, bad, why, extra, locked = independent_sets(
                st.E, key_of, cand, need, self.n, lambda *a: self.validate(st, found, *a), sch, groups=groups)
            return acc, bad, why, extra, locked, found
        keys, rows, verts, count = self.scratch(len(st.E))
        if groups is None:
            vcopy, needs, local = self.one_copy, np.array([need], np.int64), count[: len(st.E)]
        else:
            vcopy, needs = groups[0], np.asarray(groups[1], np.int64)
        free, active = np.ones(self.n, bool), np.zeros(self.n, bool)
        faces = self.faces
        acc, apex, bad, why = round_jit.select_validate(
            st.E, st.ecount, cand, np.ascontiguousarray(st.key, DTYPE).view(np.int32), local,
            (self.rounds * 7919) & 0xFFFFFFFF, vcopy, needs, sch.max_passes, float(sch.pass_yield),
            bool(self.options.keep_parts), faces.F, faces.alive, faces.cnt, faces.off, faces.pool, self.V3,
            self.N0, st.x, st.bvert, st.deg, *self.flip_limits, free, active, self.mark, keys, rows, verts,
            *self.seams, *self.lock_rule)
        return acc, bad, why, None, ~free, apex

    def scratch(self, P: int):
        """`round_jit.select_validate`'s working arrays for P pairs, (≥ P,) int64, (2, ≥ P) int32 and (2, n)
        int64, and 0, 1, ... (≥ P): made once a run (its pairs only get fewer), so that no round maps
        megabytes afresh."""
        if self._rows is None or self._rows.shape[1] < P:
            self._keys = np.empty(P, np.int64)
            self._rows = np.empty((2, P), np.int32)
            self._verts = np.empty((2, self.n), np.int64)
            self._count = np.arange(P)
        return self._keys, self._rows, self._verts, self._count

    def validate(self, st: RoundState, found: list, P, idx, Efree):
        """(rule broken per pair (0: valid), faces made coincident) for vertex-disjoint pairs P (indices
        idx into this round's pairs). Efree (rows of this round's pairs) holds every pair at them; the faces
        come from `FaceLists`. In manifold mode the link test runs on the worker thread. What the contraction
        will need again (the faces' look-up and, in manifold mode, the apexes that the link test found, for
        `round_jit.contract_edges`) is appended to ``found``."""
        tv = time.perf_counter()
        if self.manifold:
            link = submit(topo.link_ok, P, st.ecount[idx], Efree, self.n, st.bvert, st.deg, apexes=True,
                          size=len(Efree))
        (fids, before, corner, owner, G), kept, dead = self.faces.touched_with_dead(P)
        flipped = start_flips(self.VQd, self.N0d, before, fids, corner, owner, _take(st.x, idx), len(P),
                            self.cos_max)  # runs while the host tests the rest
        gone = topo.coincidence_count(G, owner, len(P))
        why = np.zeros(len(P), np.int8)
        apex = None
        if self.manifold:  # link condition, no coincident faces
            linked, apex = link.result()
            why[gone > 0] = outcome.COINCIDENT
            if self.options.keep_parts:  # the pair's faces are all its part has left
                why[np.bincount(owner, minlength=len(P)) == 0] = outcome.PART
            why[~linked] = outcome.TOPOLOGY
        if self.locks is not None:  # a locked vertex never leaves the mesh (its part's or its own last faces)
            gone_locked = _locks.vanishing(self.locks, P, np.bincount(owner, minlength=len(P))) | \
                _locks.strands(self.locks, self.faces, P, dead)
            why[(why == 0) & gone_locked] = outcome.LOCKED
        if self.wedges is not None:  # the seam rule, for the pairs still valid
            why[self.wedges.refused(self.faces, self.VQ, P, _take(st.x, idx), why == 0)] = outcome.SEAM
        found.append((idx, kept, dead, apex))
        flip = flipped()
        why[(why == 0) & flip] = outcome.FLIP
        self.timer.add("validity_s", time.perf_counter() - tv)
        return why, gone

    # -- stage 5: contract -------------------------------------------------------------------------
    def contract(self, st: RoundState, acc, n_sel, locked, found):
        """Contract the accepted pairs together; leaves in ``st`` what the next round's update needs."""
        if self.fast:
            return self.contract_fast(st, acc, n_sel, locked, *found)
        t0 = time.perf_counter()
        n, faces = self.n, self.faces
        P = _take(st.E, acc)
        a, b = P[:, 0], P[:, 1]
        xs = _take(st.x, acc)
        if not self.fused:
            merged = start_merge(self.model, self.VQd, P, xs, self.params, size=self.merge_chunk)  # runs meanwhile
        st.changed = np.zeros(n, bool)
        st.changed[a] = True
        self.branches += np.bincount(st.branch[acc], minlength=len(self.branches))
        _locks.carry(self.weights, a, b)
        self.max_cost_used = max(self.max_cost_used, float(st.cost[acc].max()))
        self.record(st, acc, a.copy(), b.copy(), xs, st.cost[acc].astype(np.float64))
        # pairs whose faces change get another chance: those at the 1-rings that selection locked, unless
        # the target cut the set short
        if self.compiled:
            round_jit.clear_bad(st.E, st.bad, self.touched(locked, acc, n_sel, P))
            self.contract_compiled(st, a, b, xs, found)
        else:
            r = np.flatnonzero(st.bad)
            if r.size:
                st.bad[r[any_at(self.touched(locked, acc, n_sel, P), _take(st.E, r))]] = 0
            edges_next = self.contract_numpy(st, acc, xs, found)
        if not self.manifold:
            self.dropped.append((self.rounds - 1, _drop_coincident(faces, a)))
        if len(self.extra_pairs):
            rep = np.arange(n, dtype=np.int32)
            rep[b] = a
            ep = rep[self.extra_pairs]
            self.extra_pairs = ep[ep[:, 0] != ep[:, 1]]
        if self.incremental and not self.compiled:
            st.edges_next = edges_next.result()
        if self.compiled:
            put_rows(self.V3, a, xs)
        if self.fused:  # the merge, the row update and the next round's price: one device call
            E, stale = st.edges_next[0], st.edges_next[4]
            d = np.flatnonzero(stale)
            self.VQd, merged, priced = start_step(self.model, self.VQd, P, xs, _take(E, d), self.params,
                                                  self.merge_chunk, _holding(self.price_sizes, len(d)))
            self.started(st, a, xs, d, merged, priced)
        else:
            rows = np.concatenate([xs, merged()], 1)  # the kept vertices' new [position, state]
            put_rows(self.VQ, a, rows)
            self.VQd = set_rows(self.VQd, a, rows, size=self.merge_chunk)
        if self.model.support == "ring" or self.model.refresh is not None:
            ring = _ring_vertices(faces, a, n)
            if self.model.support == "ring":
                st.changed = ring
            if self.model.refresh is not None:
                self.refresh(np.flatnonzero(ring))
        self.faces_per_round.append(faces.count)
        self.timer.add("contract_s", time.perf_counter() - t0)

    def contract_fast(self, st: RoundState, acc, n_sel, locked, apex, room):
        """`contract` for a `fast` run: one compiled pass (`round_glue_jit.contract`), then the device call
        (one piece: `step_one`; else `start_step`)."""
        t0 = time.perf_counter()
        faces = self.faces
        P = _take(st.E, acc)
        touched = self.touched(locked, acc, n_sel, P)
        if self.wedges is not None:  # the corners' wedges, before the faces are relinked
            self.wedges.contract_many(faces, self.VQ, P, _take(st.x, acc))
        faces.reserve(int(room))  # the kept vertices' new runs
        a, b, xs, costs, top, faces.end, dead, st.edges_next, d, one = round_glue_jit.contract(
            st.E, st.ecount, st.deg, st.bad, touched, acc, apex, st.x, st.cost, st.branch, self.branches, self.V3,
            self.VQ, faces.F, faces.alive, faces.cnt, faces.off, faces.pool, faces.end, self.label, len(self.VQd),
            self.merge_chunk, self.price_sizes[0])
        faces.count -= len(dead)
        self.dead.append(dead)
        self.max_cost_used = max(self.max_cost_used, top)
        _locks.carry(self.weights, a, b)
        self.record(st, acc, a, b, xs, costs)
        Pd = one[3][: len(d)] if len(one[0]) else _take(st.edges_next[0], d)  # the stale pairs
        # with locks, those at a locked kept vertex are priced there too, in the same device call (a small share
        # of the stale pairs: the smallest shape holds them, else they go beside it)
        kept = _locks.at_kept_pairs(self.locks, Pd) if self.kept_fuses else None
        if kept is not None and not 0 < len(kept) <= CHUNKS[1]:
            kept = None
        if len(one[0]):
            self.VQd, merged, priced, *at = step_one(self.model, self.VQd, *one, self.params, len(acc), kept=kept)
        else:
            self.VQd, merged, priced, *at = start_step(self.model, self.VQd, P, xs, Pd, self.params, self.merge_chunk,
                                                       _holding(self.price_sizes, len(d)), raw=True, kept=kept)
        self.started(st, a, xs, d, merged, priced, moved=True)
        if self.locks is not None:
            self.at_kept = at[0] if at else _locks.start_at_kept(self.locks, self.model, self.VQd, Pd, self.params,
                                                                 faces, self.pad)
        self.faces_per_round.append(faces.count)
        self.timer.add("contract_s", time.perf_counter() - t0)

    def record(self, st: RoundState, acc, a, b, xs, costs):
        """The round's contractions ``acc`` (kept a, removed b, at xs, costs float64) into the history, with
        their cost parts and keys for a model with parts."""
        self.history.append((self.rounds - 1, (a, b, xs, costs)))
        if st.parts.shape[1]:
            self.history_parts.append(np.concatenate([_take(st.parts, acc), _take(st.key, acc)[:, None]], 1))

    def started(self, st: RoundState, a, xs, d, merged, priced, moved: bool = False):
        """After a round's one device call (fused): the kept vertices' positions into VQ (unless ``moved``:
        the compiled contraction wrote them), their merged states pending until `settle`, and the next
        round's price of its stale rows d pending in ``st``."""
        st.next_price = (d, priced)
        if not moved:
            self.VQ[a, :3] = xs
        self.merged = (a, merged)  # the states reach VQ when the price is waited for (`settle`)

    def contract_numpy(self, st: RoundState, acc, xs, found):
        """The faces after the accepted pairs ``acc`` (placed at xs) contract, from what validation
        ``found`` (`_accepted`). In manifold mode the pairs' update starts on the worker thread: returns
        its future (else None)."""
        n, faces = self.n, self.faces
        P = _take(st.E, acc)
        taken = np.zeros(len(st.E), bool)
        taken[acc] = True
        pairs, kept, dead, apex = _accepted(st.E, found, taken)  # in pass order, not acc's
        edges_next = None
        if self.incremental:  # the edge update (compiled) starts on the worker while this thread relinks the faces
            edges_next = EdgeUpdate(st.E, st.ecount, st.deg, pairs[:, 0], pairs[:, 1], np.asarray(apex, np.int64),
                                    self.label)
        if self.wedges is not None:  # the corners' wedges, before the faces are relinked
            self.wedges.contract_many(faces, self.VQ, P, xs)
        faces.contract_touched(pairs, kept, dead)
        self.dead.append(dead)
        return edges_next

    def contract_compiled(self, st: RoundState, a, b, xs, apex):
        """`contract_numpy` as compiled loops (`round_jit`): the faces, then the pairs."""
        faces = self.faces
        if self.wedges is not None:  # the corners' wedges, before the faces are relinked
            self.wedges.contract_many(faces, self.VQ, np.stack([a, b], 1), xs)
        faces.reserve(int(faces.cnt.take(a).sum() + faces.cnt.take(b).sum()))  # the kept vertices' new runs
        faces.end, dead = round_jit.contract_faces(a, b, faces.F, faces.alive, faces.cnt, faces.off, faces.pool,
                                                   faces.end)
        faces.count -= len(dead)
        self.dead.append(dead)
        st.edges_next = round_jit.contract_edges(st.E, st.ecount, st.deg, a, b, apex, self.label)

    def touched(self, locked, acc, n_sel, P):
        """(n,) bool: the vertices around this round's contractions P (rows ``acc``): the 1-rings that
        selection locked, unless the target cut the set short (then the rings of what contracted)."""
        return locked if acc.size == n_sel else _ring_vertices(self.faces, P.reshape(-1), self.n)

    def refresh(self, verts):
        """Recompute the model's derived state at ``verts`` (after their neighbourhood changed)."""
        state = np.asarray(self.model.refresh(MeshView(self.faces, self.VQ[: self.n]), verts), DTYPE)
        self.VQ[verts, 3:] = state
        self.VQd = set_rows(self.VQd, verts, self.VQ[verts], size=self.merge_chunk)

    # -- the loop ----------------------------------------------------------------------------------
    def run(self):
        prev, stop, blocked = None, "target", {}
        while self.faces.count > self.target:
            self.rounds += 1
            need = self.faces.count - self.target
            if self.fast and prev is not None and prev.next_price is not None:
                st, valid = self.carry(prev, need)
            else:
                t0 = time.perf_counter()
                st, follow, stale, same = self.update(prev)
                self.timer.add("topology_s", time.perf_counter() - t0)
                self.cost(st, prev, follow, stale, same)
                valid = self.candidates(st, need)
            self.rank(st, valid)
            if not valid.any():
                stop, blocked = self.stop(st, need)
                break
            acc, n_sel, n_bad, locked, found = self.select(st, need, valid)
            if acc.size == 0:
                if n_bad:  # the invalid ones are out now: select again among the rest (same pairs)
                    st.changed = np.zeros(self.n, bool)
                    if self.incremental:
                        st.edges_next = (st.E, st.ecount, np.ones(len(st.E), bool), st.deg,
                                         np.zeros(len(st.E), bool))
                    prev = st
                    continue
                stop, blocked = self.stop(st, need)
                break
            self.contract(st, acc, n_sel, locked, found)
            prev = st
            if self.progress is not None:
                self.progress(self.faces.count)
        self.settle()
        return stop, blocked

    def stop(self, st: RoundState, need: int):
        """The stop reason and what blocked the remaining pairs (`outcome.classify`)."""
        ok = ((st.ecount >= 1) & (st.ecount <= 2)) if self.manifold else np.ones(len(st.E), bool)
        return outcome.classify(self.faces.count, self.target, st.bad, st.ecount,
                                st.cost > self.options.max_cost, ok)


def run(V, S, F, extra_pairs, target_faces, model, options: Options, progress=None, edges=None,
        part_scale=None, wedges=None, locks=None):
    """Simplify. V (n,3) float32 normalised positions, S (n, model.width) the model's vertex state,
    F (m,3) int64 faces, extra_pairs (k,2) non-edge pairs that may also contract (aggregation; k may be
    0); ``edges``: `topo.edges` of F when the caller has it; ``part_scale`` (n,): (extent of each vertex's
    part / the whole extent)², which scales ``Schedule.free_cost`` per pair (None: one part).
    Returns the `outcome.Outcome` (the schedulers' contract). ``wedges``: a `_wedges.Tracker`
    (attributes kept: the seam rule applies and its corners are updated), or None. ``locks``: a
    `_locks.RunLocks` (locked vertices and weights; locked vertices numbered first), or None."""
    r = _Run(V, S, F, extra_pairs, target_faces, model, options, progress, edges, part_scale, wedges=wedges,
             locks=locks)
    stop, blocked = r.run()
    rounds, a, b, x, cost = _history_columns(r.history)
    hist = _history_arrays(a, b, x, cost)
    removed_at, coincident, rounds = _removal_steps(r.faces.F, rounds, a, b, r.dead, r.dropped)
    n = r.n
    # the vertices' rows without the padding of the run's arrays (a quarter more rows on a large mesh)
    V, S = np.ascontiguousarray(r.VQ[:n, :3]), np.ascontiguousarray(r.VQ[:n, 3:])
    r.VQ = r.VQd = None
    return outcome.Outcome(
        V, S, r.faces.F, r.faces.alive, outcome.History(*hist), stop, blocked,
        outcome.count_reasons(np.repeat(np.arange(len(r.rejected_by)), r.rejected_by)), rejected=r.rejected,
        rounds=r.rounds, worst_cost=r.max_cost_used, branches=r.branches, stage_times=outcome.stage_times(r.timer.t),
        faces_per_round=r.faces_per_round, parts=np.concatenate(r.history_parts) if r.history_parts else None,
        reweights=r.reweights, history_rounds=rounds, removed_at=removed_at, coincident=coincident)
