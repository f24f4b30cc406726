"""The round as compiled loops (`selection`, `contraction`): `LoopRound` runs the gate, the selection passes with
validation, the order and the contraction as compiled passes (`segments.kth`, `glue.order_fit`), between the numpy
stages' update, prices and ranking; `GlueRound` compiles the rest of that glue too (`glue`) and sends a
round's device work as one call. Both make the numpy stages'
choices (`StagedRound`), bit for bit."""
from __future__ import annotations

import time

import numpy as np

from ..._kernels.batching import CHUNKS, DTYPE
from ..._kernels.flips import host_limits
from ..._mesh.arrays import put_rows, take_rows as _take
from .. import locks as _locks
from .. import outcome, rules, segments
from . import contraction, glue, selection
from ..device import Priced, kept_fuses, start_step, step_one
from .glue import FaceArrays, Known, PairArrays
from ..select import gate_rank
from ..shape import ranking
from .stages import Round
from .state import RoundState, Run, holding


class LoopRound(Round):
    """A round whose selection passes with validation and whose contraction are compiled loops
    (`selection`, `contraction`; manifold mode with the pairs updated in place, `selection.fits`)."""

    counts_dtype = np.int32  # face counts are small: int32 halves the largest per-pair array but x

    def __init__(self, run: Run, device=None):
        super().__init__(run, device)
        n, options = run.n, run.options
        self.N0 = np.ascontiguousarray(run.normals, DTYPE)  # the input normals, for the host flip test
        # the positions alone for the host flip test: a seventh of VQ's rows to pull through the caches
        self.V3 = np.ascontiguousarray(run.VQ[:, :3])
        self.limits = selection.Limits(*host_limits(options.cos_max, options.min_quality), bool(options.keep_parts))
        self.mark = np.zeros(n, np.int32)  # scratch of `selection.select_validate`
        self._rows = self._verts = None  # more of it (`scratch`)
        self.one_copy = np.zeros(n, np.int32)  # a run alone is one copy (`passes`)
        # kept attributes: the wedge of each face corner and the seam vertices, for the seam rule
        self.seams = (selection.Seams(np.zeros((0, 3), np.int64), np.zeros(n, bool)) if run.wedges is None
                      else selection.Seams(run.wedges.C, run.wedges.multi))
        # locked vertices and the scratch of their rule (`rules.stranded_by_pass`); empty: no locks
        self.lock_rule = (selection.Locks(np.zeros(0, bool), np.zeros(0, np.int32)) if run.locks is None
                          else selection.Locks(np.ascontiguousarray(run.locks.locked, bool), np.full(n, -1, np.int32)))
        # the free cost at each vertex's part scale, as `select` takes it per pair (empty: one part)
        self.free_at = (np.zeros(0) if run.part_scale is None
                        else options.schedule.free_cost * np.asarray(run.part_scale))

    def passes(self, st: RoundState, key_of, cand, need, groups, local=None):
        """`StagedRound.passes` as one compiled call (`selection.select_validate`; ``local``: each pair's
        index within its copy, for a batch). What validation found is the accepted pairs' apexes (S,2)."""
        run = self.run
        sch = run.options.schedule
        keys, rows, verts, count = self.scratch(len(st.E))
        if groups is None:
            vcopy, needs, local = self.one_copy, np.array([need], np.int64), count[: len(st.E)]
        else:
            vcopy, needs = groups[0], np.asarray(groups[1], np.int64)
        free, active = np.ones(run.n, bool), np.zeros(run.n, bool)
        pairs = selection.Pairs(st.E, st.ecount, cand, np.ascontiguousarray(st.key, DTYPE).view(np.int32), local,
                                st.x)
        passes = selection.Passes(vcopy, needs, (run.rounds * 7919) & 0xFFFFFFFF, sch.max_passes,
                                  float(sch.pass_yield))
        acc, apex, bad, why = selection.select_validate(
            pairs, passes, rules.faces_of(run.faces), selection.Mesh(self.V3, self.N0, st.bvert, st.deg),
            self.limits, self.seams, self.lock_rule, selection.Work(free, active, self.mark, keys, rows, verts))
        return acc, bad, why, None, ~free, apex

    def select(self, st: RoundState, need: int, valid: np.ndarray):
        """`Round.select` with the gate, the order and the face target as compiled passes (`segments.kth`,
        `glue.under_gate`, `glue.order_fit`), the threshold's arithmetic as numpy does it. What validation found
        is the accepted pairs' apexes and the pool room their contraction takes."""
        run = self.run
        t0 = time.perf_counter()
        sch = run.options.schedule
        P = len(st.E)
        k = gate_rank(need, int(np.count_nonzero(valid)), P, sch)
        kth = segments.kth(st.key, valid, np.array([0, P], np.int64), np.array([k], np.int64))[0]
        thr = sch.gate * kth  # numpy's promotion of the two (kth: a float32 of the key's array)
        if not len(self.free_at):
            thr = np.maximum(thr, sch.free_cost)
        cand = glue.under_gate(st.key, valid, thr, st.E, self.free_at)
        # per pair only where the shape term reads it (the gate above takes it per vertex)
        free = np.take(self.free_at, st.E[:, 0]) if len(self.free_at) and run.options.quality_threshold else \
            sch.free_cost
        with ranking(st, run, valid, cand, free) as cand:  # (with the shape term, `shape`)
            acc, bad, why, _, locked, apex = self.passes(st, None, cand, need, None)
            n_sel = acc.size
            acc, apex, room = glue.order_fit(acc, apex, st.key, st.ecount, (run.rounds * 7919) & 0xFFFFFFFF,
                                             need, run.faces.cnt, st.E)
        self.count_rejected(why)
        run.timer.add("select_s", time.perf_counter() - t0)
        st.bad[bad] = why
        return acc, n_sel, bad.size, locked, (apex, room)

    def ordered(self, found, order):
        """A batch's accepted pairs' apexes taken in ``order`` (`batched`), as `select` gives what it found: the
        pool room left to `contract_mesh`."""
        return found[order], None

    def scratch(self, P: int):
        """`selection.select_validate`'s working arrays for P pairs, (≥ P,) int64, (2, ≥ P) int32 and (2, n)
        int64, and 0, 1, ... (≥ P): made once a run (its pairs only get fewer), so that no round maps
        megabytes afresh."""
        if self._rows is None or self._rows.shape[1] < P:
            self._keys = np.empty(P, np.int64)
            self._rows = np.empty((2, P), np.int32)
            self._verts = np.empty((2, self.run.n), np.int64)
            self._count = np.arange(P)
        return self._keys, self._rows, self._verts, self._count

    def contract_mesh(self, st: RoundState, acc, P, xs, touched, found):
        """The faces, then the pairs, after the accepted pairs P (placed at xs; ``found``: their apexes and the
        pool room their contraction takes, `select`, or None: counted here) contract, as compiled loops; the
        rejected pairs at ``touched`` get another chance."""
        run = self.run
        faces = run.faces
        a, b = P[:, 0], P[:, 1]
        apex, room = found
        contraction.clear_bad(st.E, st.bad, touched)
        if run.wedges is not None:  # the corners' wedges, before the faces are relinked
            run.wedges.contract_many(faces, run.VQ, np.stack([a, b], 1), xs)
        if room is None:
            room = faces.cnt.take(a).sum() + faces.cnt.take(b).sum()
        faces.reserve(int(room))  # the kept vertices' new runs
        faces.end, dead = contraction.contract_faces(a, b, faces.F, faces.alive, faces.cnt, faces.off, faces.pool,
                                                   faces.end)
        faces.count -= len(dead)
        run.tally.dead.append(dead)
        st.edges_next = contraction.contract_edges(st.E, st.ecount, st.deg, a, b, apex, run.label)
        put_rows(self.V3, a, xs)


class GlueRound(LoopRound):
    """`LoopRound` with its glue compiled too (`glue`) and a round's device work as one call: a
    round after one that contracted takes the device's prices straight into its pairs (`carry`); a round
    without them (the first) takes the numpy stages' `fresh`."""

    def __init__(self, run: Run):
        super().__init__(run)
        self.at_kept = None  # (`contract`) the next round's price at locked kept vertices, started
        self.kept_fuses = run.locks is not None and kept_fuses(run.model)  # ... in the round's device call
        self.limit = glue.bound(run.options.max_cost, DTYPE)  # as `candidates` compares it

    def pairs(self, prev: RoundState | None, need: int):
        if prev is not None and prev.next_price is not None:
            return self.carry(prev, need)
        return self.fresh(prev, need)

    def carry(self, prev: RoundState, need: int):
        """Stages 1 and 2 and the candidates (`update`, `cost`, `candidates`) in one compiled pass once the
        device's prices are in (`glue.carry`). Returns the new state and its candidates."""
        run = self.run
        t0 = time.perf_counter()
        E, ecount, kept, deg, stale = prev.edges_next
        d, raw = prev.next_price
        prev.next_price = None
        self.settle()
        out = raw()
        t1 = time.perf_counter()
        st = RoundState(E, ecount, deg)
        if run.locks is not None:  # locked kept vertices and the weights, as `cost` applies them
            out = self.locked_raw(out, _take(E, d), self.at_kept)
            self.at_kept = None
        last = Known(prev.x, prev.cost, prev.branch, prev.parts, prev.bad)
        st.x, st.cost, st.branch, st.parts, st.bad, st.bvert, valid, _ = glue.carry(
            kept, d, out, tuple(last), E, ecount, run.n, (self.limit, need, run.manifold), self.lock_rule[0])
        if run.wedges is not None:  # stale pairs at seam vertices: placed at an allowed endpoint (as `cost`)
            self.place_at_seams(st, d)
            if run.locks is not None:  # as `cost`: two locked vertices stay LOCKED, a locked kept one pinned
                Pd = _take(E, d)
                st.bad[d[_locks.both_locked(run.locks, Pd)]] = outcome.LOCKED
                xd = _take(st.x, d)
                _locks.pin(run.locks, run.VQ, Pd, xd)
                put_rows(st.x, d, xd)
            valid[d] = self.candidates_of(st.cost[d], st.bad[d], ecount[d], need)  # their candidate test again
        run.timer.add("kernels_s", t1 - t0)
        run.timer.add("topology_s", time.perf_counter() - t1)
        return st, valid

    def locked_raw(self, out, P, at=None):
        """The device's raw price ``out`` (5 + p, ≥ K) of pairs P (K,2) (`device.step_one`) with locked kept
        vertices and the weights applied (`_locks.adjust`, on the `Priced` that `cost` would make of it;
        ``at``: its price at the kept vertices, started with the device call, or None): (5 + p, K), the same
        values in the same dtypes."""
        run = self.run
        K = len(P)
        pr = Priced(out[:3, :K].T, out[3, :K], out[4, :K].astype(np.int8), out[5:, :K])
        at = _locks.adjust(run.locks, run.weights, run.model, run.VQ, run.VQd, P, pr, run.params, run.faces,
                           run.pad, at=at, held=None if run.wedges is None else run.wedges.held)
        res = np.empty((out.shape[0], K), out.dtype)
        res[:3], res[3], res[4], res[5:] = at.x.T, at.cost, at.branch, at.parts
        return res

    def contract(self, st: RoundState, acc, touched, found):
        """`Round.contract` as one compiled pass (`glue.contract`), then the device call (one
        piece: `device.step_one`; else `device.start_step`)."""
        run, t = self.run, self.run.tally
        t0 = time.perf_counter()
        faces = run.faces
        apex, room = found
        P = _take(st.E, acc)
        if run.wedges is not None:  # the corners' wedges, before the faces are relinked
            run.wedges.contract_many(faces, run.VQ, P, _take(st.x, acc))
        faces.reserve(int(room))  # the kept vertices' new runs
        pairs = PairArrays(st.E, st.ecount, st.deg, st.bad, st.x, st.cost, st.branch)
        lists = FaceArrays(faces.F, faces.alive, faces.cnt, faces.off, faces.pool)
        a, b, xs, costs, top, faces.end, dead, st.edges_next, d, one = glue.contract(
            tuple(pairs), tuple(lists), faces.end, (self.V3, run.VQ), (touched, acc, apex), t.branches, run.label,
            (len(run.VQd), run.merge_chunk, run.price_sizes[0]))
        faces.count -= len(dead)
        t.dead.append(dead)
        t.max_cost_used = max(t.max_cost_used, top)
        _locks.carry(run.weights, a, b)
        self.record(st, acc, a, b, xs, costs)
        Pd = one[3][: len(d)] if len(one[0]) else _take(st.edges_next[0], d)  # the stale pairs
        # with locks, those at a locked kept vertex are priced there too, in the same device call (a small share
        # of the stale pairs: the smallest shape holds them, else they go beside it)
        kept = _locks.at_kept_pairs(run.locks, Pd) if self.kept_fuses else None
        if kept is not None and not 0 < len(kept) <= CHUNKS[1]:
            kept = None
        if len(one[0]):
            run.VQd, merged, priced, *at = step_one(run.model, run.VQd, *one, run.params, len(acc), kept=kept)
        else:
            run.VQd, merged, priced, *at = start_step(run.model, run.VQd, P, xs, Pd, run.params, run.merge_chunk,
                                                      holding(run.price_sizes, len(d)), raw=True, kept=kept)
        self.started(st, a, xs, d, merged, priced, moved=True)
        if run.locks is not None:
            self.at_kept = at[0] if at else _locks.start_at_kept(run.locks, run.model, run.VQd, Pd, run.params,
                                                                 faces, run.pad)
        t.faces_per_round.append(faces.count)
        run.timer.add("contract_s", time.perf_counter() - t0)
