"""Many runs of one mesh in the same rounds: the parallel scheduler on a disjoint union of copies.

A sweep's configurations of one mesh differ in their vertex state (quadrics built with another boundary
weight or area weighting), their numeric kernel settings (passed per pair, `device.PerCopy`: never a
new compilation), their face target and their ``max_error``. Copy c holds vertices c·n … c·n + n − 1 and
faces c·m … c·m + m − 1, so every stage of a round runs once for all copies, on arrays C times longer, and
the fixed cost of a round (kernel launches, hundreds of small numpy calls) is paid once instead of C
times.

Each copy makes exactly the choices it makes alone (`simplify_batch` results equal `simplify`'s, bit for
bit; tested): the rounds go through the round implementation a single run would take (`parallel.choose`,
without the compiled glue), and everything a round decides globally in a single run
(`parallel.driver.rounds`) is decided per copy here:

- the face budget (``need``) and ``max_error`` of the candidates;
- the gate (the k-th cheapest candidate of the copy);
- the tie-breaking scramble (a pair's index within its copy: `select.sort_keys` ``offset``);
- when a copy leaves the selection passes (`select.independent_sets` ``groups``);
- the exact face target (`select.fits_target` on the copy's accepted pairs);
- which rejected pairs get another chance (`touched`);
- when and why a copy stops (its own `outcome.classify`).

Copies never share a vertex, a face or a pair, and E stays grouped by copy (rebuilt edges are sorted by
key; updated ones only lose rows), so a copy's pairs are one slice of each round's arrays.
Not batched (run alone by `simplify_batch`): the greedy scheduler, non-edge pairs (aggregation), models
that refresh state (but for the memoryless second phases of late runs, each copy's rows rebuilt by its own
model) or rank by weighted parts, and splitting (ESQEM).
"""
from __future__ import annotations

import time

import numpy as np

from .._costs import memoryless as ml
from .._costs.qem import QEM
from .._mesh.arrays import face_normals, keep_rows as _keep
from .._kernels.batching import DTYPE
from . import outcome, segments
from .._options import Options
from .device import PerCopy
from .parallel import Round, RoundState, Run, driver
from .parallel.history import history_arrays, history_columns, removal_steps
from .parallel.pairs import ring_vertices
from .select import fits_target, gate_rank, sort_keys
from .shape import ranking


def batchable(model, own_refresh: bool = False) -> bool:
    """Whether runs of ``model`` can share rounds: its kernels take per-pair settings
    (`CostModel.per_pair_params`) and it neither ranks by weighted parts nor splits, nor refreshes state
    unless each copy's own model rebuilds that copy's rows (``own_refresh``: the second phases of late runs,
    `late.Second`, with `run`'s ``models``; a model that turns memoryless late batches its first phase as
    any other)."""
    return (model.per_pair_params and (model.refresh is None or (own_refresh and _rebuilds_rows(model)))
            and model.rank_weights is None
            and getattr(model, "split_factor", None) is None)


def _rebuilds_rows(model) -> bool:
    """Whether ``model`` refreshes state as memoryless QEM does (`memoryless.refresh_rows`): rows a batch
    rebuilds for all its copies in one pass, each vertex with its own copy's weights (`_CopyRefresh`)."""
    return isinstance(model, QEM) and model.memoryless and type(model).refresh is QEM.refresh


class _CopyRefresh:
    """A batch's model whose ``refresh`` rebuilds each copy's rows with that copy's own model's weights (its
    area power and boundary weight; the means its rows hold): the rows a copy gets alone, for every copy in
    one pass. Everything else is ``model``'s."""

    def __init__(self, model, models, vcopy):
        if not all(_rebuilds_rows(m) for m in models):
            raise ValueError("a batch refreshes the rows of memoryless QEM models only (`batchable`)")
        self._model, self._vcopy = model, vcopy
        self._weights = np.array([ml.weights(m) for m in models], np.float64).T  # (2, copies)

    def __getattr__(self, name):
        return getattr(self._model, name)

    @property
    def refresh(self):
        return self._refresh

    def _refresh(self, view, verts):
        cp = np.take(self._vcopy, np.asarray(verts, np.int64))
        return ml.refresh_rows_each(self._weights[0].take(cp), self._weights[1].take(cp), view, verts)


class _Batch:
    """C copies (of one mesh or of several) in one `parallel.Run`, whose rounds go through a round
    implementation (`parallel.choose` without the compiled glue: ``rnd``) with the per-copy decisions of the
    module docstring. Copy c holds vertices voff[c] … voff[c+1] − 1 and faces foff[c] … foff[c+1] − 1."""

    def __init__(self, Vs, states, Fs, targets, max_costs, model, params, options: Options, edges, part_scales,
                 normals=None, models=None):
        C = len(states)
        self.C = C
        self.voff = np.concatenate([[0], np.cumsum([len(V) for V in Vs])]).astype(np.int64)
        self.foff = np.concatenate([[0], np.cumsum([len(F) for F in Fs])]).astype(np.int64)
        Fu = np.concatenate([F + o for F, o in zip(Fs, self.voff)])
        Eu = np.concatenate([(E.astype(np.int64) + o).astype(E.dtype) for (E, _), o in zip(edges, self.voff)])
        # Schedule.free_cost per vertex, as each copy compares it alone: at its parts' scale, or (one part)
        # as float32 (a Python float against the float32 gate)
        free = options.schedule.free_cost
        self.free_v = None
        if any(ps is not None for ps in part_scales):
            self.free_v = np.concatenate([np.full(len(V), float(np.float32(free))) if ps is None else free * ps
                                          for V, ps in zip(Vs, part_scales)])
        self.vcopy = np.repeat(np.arange(C), np.diff(self.voff)).astype(np.int32)
        stacked = {k: np.stack([np.asarray(p[k]) for p in params]) for k in params[0]}
        if normals is None:
            seen = {}  # the input normals of each mesh once (copies of one mesh share V and F)
            for V, F in zip(Vs, Fs):
                if (id(V), id(F)) not in seen:
                    seen[id(V), id(F)] = face_normals(np.asarray(V, DTYPE), F)
            normals = [seen[id(V), id(F)] for V, F in zip(Vs, Fs)]
        if model.refresh is not None:  # each copy's state rebuilt by its own model (its settings, its means)
            if models is None or len(models) != C:
                raise ValueError("a batch of a model that refreshes state needs each copy's model (models=)")
            model = _CopyRefresh(model, models, self.vcopy)
        self.run = Run(np.concatenate(Vs), np.concatenate(states), Fu, np.zeros((0, 2), np.int32),
                       int(np.sum(targets)), model, options, None, (Eu, np.concatenate([ec for _, ec in edges])),
                       None, PerCopy(stacked, self.vcopy), normals=np.concatenate(normals))
        # its copies' gates, budgets and targets are their own (`select_batch`): no compiled glue
        self.rnd: Round = driver.choose(self.run, glue=False)
        self.targets = np.asarray(targets, np.int64)
        self.max_costs = np.asarray(max_costs, np.float64)
        self.active = np.ones(C, bool)
        self.n_in_rounds = C  # copies whose pairs the rounds still carry (`_without_stopped`)
        self.stops = [None] * C  # (stop reason, blocked_by) per copy
        self.copy_rounds = np.zeros(C, np.int64)
        self.copy_branches = np.zeros((C, len(model.branches)), np.int64)
        self.copy_rejected = np.zeros((C, len(outcome.REJECT) + 1), np.int64)
        self.copy_max_cost = np.zeros(C)
        self.copy_faces = []  # per round that contracted: (which copies contracted, every copy's face count)

    # -- per-copy views ----------------------------------------------------------------------------
    def counts(self) -> np.ndarray:
        """(C,) live faces of each copy."""
        return np.add.reduceat(self.run.faces.alive[: self.foff[-1]], self.foff[:-1], dtype=np.int64)

    def pair_copies(self, st: RoundState):
        """(each pair's copy (P,), each copy's first pair (C + 1,)): E is grouped by copy."""
        cp = np.take(self.vcopy, st.E[:, 0])
        starts = np.searchsorted(cp, np.arange(self.C + 1))
        return cp, starts

    def _end(self, c: int, st: RoundState, s: slice, need: int):
        """Copy c stops in this round (no valid pair, or nothing it selected was valid); s: its pairs."""
        ok = ((st.ecount[s] >= 1) & (st.ecount[s] <= 2)) if self.run.manifold else np.ones(s.stop - s.start, bool)
        self.stops[c] = outcome.classify(need + int(self.targets[c]), int(self.targets[c]), st.bad[s],
                                         st.ecount[s], st.cost[s] > self.max_costs[c], ok)
        self.active[c] = False
        self.copy_rounds[c] = self.run.rounds

    def _without_stopped(self, edges_next):
        """The next round's pairs (`contraction.contract_edges`' (E', ecount', keep, degree', stale')) without
        those of copies that have stopped: they are never candidates again, and every per-pair pass of
        the rounds left would carry them. Order is kept, so each copy's pairs and their indices within
        it are unchanged."""
        E, ecount, keep, deg, stale = edges_next
        mine = np.take(self.active, np.take(self.vcopy, E[:, 0]))
        rows = np.flatnonzero(keep)
        keep = np.zeros(len(keep), bool)
        keep[np.compress(mine, rows)] = True
        return _keep(E, mine), np.compress(mine, ecount), keep, deg, np.compress(mine, stale)

    # -- stages ------------------------------------------------------------------------------------
    def select_batch(self, st: RoundState, need: np.ndarray, valid: np.ndarray, n_valid: np.ndarray, cp, starts):
        """`parallel.Round.select` per copy: the gate, the passes and the face target of each copy its own (n_valid:
        each copy's valid pairs). Returns (accepted indices, per copy: selected, rejected; the locked
        vertices, what validation found)."""
        t0 = time.perf_counter()
        sch = self.run.options.schedule
        ks = np.zeros(self.C, np.int64)  # each active copy's gate rank among its own valid pairs
        for c in np.flatnonzero(self.active):
            ks[c] = gate_rank(int(need[c]), int(n_valid[c]), int(starts[c + 1] - starts[c]), sch)
        thresh = np.where(ks > 0, segments.kth(np.ascontiguousarray(st.key),
                                               np.ascontiguousarray(valid, bool), starts, ks), 0).astype(np.float32)
        salt = self.run.rounds * 7919
        offset = np.take(starts, cp)

        def key_of(idx):
            return sort_keys(st.key, idx, salt, offset)
        free = sch.free_cost if self.free_v is None else np.take(self.free_v, st.E[:, 0])
        cand = valid & (st.key <= np.maximum(sch.gate * np.take(thresh, cp), free))
        with ranking(st, self.run, valid, cand, free, starts) as cand:  # (the shape term per copy, `shape`)
            acc, bad, why, extra, locked, found = self.rnd.passes(st, key_of, cand, 0, (self.vcopy, need, cp),
                                                              np.arange(len(st.E)) - offset)
            order = np.argsort(key_of(acc), kind="stable")
        self.copy_rejected += np.bincount(np.take(cp, bad).astype(np.int64) * self.copy_rejected.shape[1] + why,
                                          minlength=self.copy_rejected.size).reshape(self.copy_rejected.shape)
        n_bad = np.bincount(np.take(cp, bad), minlength=self.C)
        acc = acc[order]
        ca = np.take(cp, acc)
        n_sel = np.bincount(ca, minlength=self.C)
        fit = _fits_targets(ca, st.ecount[acc] + (0 if extra is None else extra[acc]), need, self.C)
        acc = acc[fit]
        found = self.rnd.ordered(found, order[fit])
        self.run.timer.add("select_s", time.perf_counter() - t0)
        st.bad[bad] = why
        return acc, n_sel, n_bad, locked, found

    def touched(self, locked, acc, n_sel, P):
        """Per copy (`parallel.pairs.touched`): the locked 1-rings, or the rings of what contracted (P, rows
        ``acc`` of the round's pairs) where the target cut it short."""
        cut = np.bincount(np.take(self.vcopy, P[:, 0]), minlength=self.C) != n_sel
        if not cut.any():
            return locked
        mine = np.take(cut, np.take(self.vcopy, P[:, 0]))
        return (locked & ~np.take(cut, self.vcopy)) | ring_vertices(self.run.faces, P[mine].reshape(-1), self.run.n)

    def contract_batch(self, st: RoundState, acc, n_sel, locked, found, cp):
        ca = np.take(cp, acc)
        nb = self.copy_branches.shape[1]
        self.copy_branches += np.bincount(ca.astype(np.int64) * nb + st.branch[acc],
                                          minlength=self.copy_branches.size).reshape(self.copy_branches.shape)
        np.maximum.at(self.copy_max_cost, ca, st.cost[acc].astype(np.float64))
        self.rnd.contract(st, acc, self.touched(locked, acc, n_sel, np.take(st.E, acc, axis=0)), found)

    def candidates_batch(self, st: RoundState, need: np.ndarray, cp) -> np.ndarray:
        """`parallel.Round.candidates` with each copy's face budget and max_error, among the active copies. A
        setting that is the same for every active copy (or, for the budget, above every pair's face
        count) is passed as one number: the same test without a per-pair gather."""
        act = self.active
        big = st.ecount.max(initial=0)
        budget = int(need[act].min()) if np.all(need[act] >= big) else np.take(need, cp)
        mc = self.max_costs[act]
        limit = mc[0] if np.all(mc == mc[0]) else np.take(self.max_costs, cp)
        valid = self.rnd.candidates(st, budget, limit)
        return valid if act.all() else valid & np.take(act, cp)

    # -- the loop ----------------------------------------------------------------------------------
    def rounds(self):
        """Rounds until every copy has stopped (`parallel.driver.rounds` per copy)."""
        prev = None
        while True:
            counts = self.counts()
            reached = self.active & (counts <= self.targets)
            for c in np.flatnonzero(reached):
                self.stops[c] = ("target", {})
                self.copy_rounds[c] = self.run.rounds
            self.active &= ~reached
            if not self.active.any():
                break
            self.run.tally.rounds += 1
            t0 = time.perf_counter()
            if prev is not None and prev.edges_next is not None and self.active.sum() < self.n_in_rounds:
                prev.edges_next = self._without_stopped(prev.edges_next)
                prev.next_price = None  # started for the pairs before: priced again, without the stopped copies
                self.n_in_rounds = int(self.active.sum())
            st, follow, stale, same = self.rnd.update(prev)
            self.run.timer.add("topology_s", time.perf_counter() - t0)
            self.rnd.cost(st, prev, follow, stale, same)
            cp, starts = self.pair_copies(st)
            need = counts - self.targets
            valid = self.candidates_batch(st, need, cp)
            st.key = st.cost
            n_valid = segments.sums(valid, starts)
            for c in np.flatnonzero(self.active & (n_valid == 0)):
                self._end(c, st, slice(starts[c], starts[c + 1]), int(need[c]))
            if not self.active.any():
                break
            acc, n_sel, n_bad, locked, found = self.select_batch(st, need, valid, n_valid, cp, starts)
            n_acc = np.bincount(np.take(cp, acc), minlength=self.C)
            for c in np.flatnonzero(self.active & (n_acc == 0) & (n_bad == 0)):
                self._end(c, st, slice(starts[c], starts[c + 1]), int(need[c]))
            if acc.size == 0:  # the invalid ones are out now: select again among the rest (same pairs)
                self.rnd.retry(st)
                prev = st
                if not self.active.any():
                    break
                continue
            self.contract_batch(st, acc, n_sel, locked, found, cp)
            self.copy_faces.append((n_acc > 0, self.counts()))
            prev = st
        self.rnd.settle()

    # -- per-copy outputs --------------------------------------------------------------------------
    def outputs(self):
        """Each copy's `outcome.Outcome`."""
        voff, foff, C = self.voff, self.foff, self.C
        # every contraction once, then each copy's rows (record order within a copy is kept)
        t = self.run.tally
        rounds, a, b, x, cost = history_columns(t.history)
        order, bounds = _grouped(np.take(self.vcopy, a), C)
        parts = [None] * C
        if t.history_parts:
            allp = np.concatenate(t.history_parts)
            parts = [np.take(allp, order[bounds[c]:bounds[c + 1]], axis=0) for c in range(C)]
        dead = np.concatenate(t.dead) if t.dead else np.zeros(0, np.int64)
        dead = np.sort(dead)
        dead_c = np.split(dead, np.searchsorted(dead, foff[1:-1]))
        dropped = _by_copy(t.dropped, foff, lambda d: d)
        out = []
        for c in range(C):
            lo, hi, f0, f1 = voff[c], voff[c + 1], foff[c], foff[c + 1]
            mine = order[bounds[c]:bounds[c + 1]]
            ac, bc = np.take(a, mine) - lo, np.take(b, mine) - lo
            F = self.run.faces.F[f0:f1] - lo
            removed_at, coincident, rc = removal_steps(F, np.take(rounds, mine), ac, bc, [dead_c[c] - f0],
                                                        [(r, d - f0) for r, d in dropped[c]])
            stop, blocked = self.stops[c]
            out.append(outcome.Outcome(
                self.run.VQ[lo:hi, :3], self.run.VQ[lo:hi, 3:], F, self.run.faces.alive[f0:f1],
                outcome.History(*history_arrays(ac, bc, np.take(x, mine, axis=0), np.take(cost, mine))),
                stop, blocked, outcome.count_reasons(np.repeat(np.arange(self.copy_rejected.shape[1]),
                                                               self.copy_rejected[c])),
                rejected=int(self.copy_rejected[c, 1:].sum()), rounds=int(self.copy_rounds[c]),
                worst_cost=float(self.copy_max_cost[c]), branches=self.copy_branches[c].copy(),
                stage_times=outcome.stage_times(self.run.timer.t),
                faces_per_round=[int(f[c]) for took, f in self.copy_faces if took[c]],
                parts=parts[c] if parts[c] is not None and len(parts[c]) else None,
                history_rounds=rc, removed_at=removed_at, coincident=coincident))
        return out


def _grouped(copy: np.ndarray, C: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows grouped by their copy (k,): (order (k,), a stable sort by copy, so rows keep their order
    within a copy; bounds (C + 1,): copy c's rows are order[bounds[c]:bounds[c + 1]])."""
    order = np.argsort(copy, kind="stable")
    return order, np.searchsorted(np.take(copy, order), np.arange(C + 1))


def _fits_targets(ca: np.ndarray, removes: np.ndarray, need: np.ndarray, C: int) -> np.ndarray:
    """`select.fits_target` per copy: mask over accepted pairs in cost order (``ca`` their copies,
    ``removes`` the faces each removes) taking, in each copy, what fits its ``need``. A copy whose
    accepted pairs all fit takes them all (the common case: one cumulative sum for every copy); the
    others go through `fits_target`."""
    order, bounds = _grouped(ca, C)
    r = np.take(removes, order)
    total = segments.sums(r, bounds)
    take = np.ones(len(ca), bool)
    for c in np.flatnonzero(total > need):
        idx = order[bounds[c]:bounds[c + 1]]
        take[idx] = fits_target(r[bounds[c]:bounds[c + 1]], int(need[c]))
    return take


def _by_copy(entries, offsets: np.ndarray, first) -> list:
    """Per-round entries [(round, arrays)] (``first(arrays)``: ids, in copy c when offsets[c] <= id <
    offsets[c+1]; every array of an entry is indexed alike) -> for each copy its own [(round, arrays)],
    rounds in order, rows in their order, entries it has no rows in left out."""
    C = len(offsets) - 1
    out = [[] for _ in range(C)]
    for r, arrs in entries:
        ids = first(arrs)
        if not len(ids):
            continue
        order, bounds = _grouped(np.searchsorted(offsets, ids, "right") - 1, C)
        for c in np.flatnonzero(np.diff(bounds)):
            sel = order[bounds[c]:bounds[c + 1]]
            out[c].append((r, tuple(a[sel] for a in arrs) if isinstance(arrs, tuple) else arrs[sel]))
    return out


def run(Vs, states, Fs, targets, max_costs, model, params, options: Options, edges, part_scales, *, normals=None,
        models=None):
    """Simplify C meshes (copies of one, or several) together. Per copy: Vs (n_c,3) float32 normalised
    positions, states (n_c, width) vertex states, Fs (m_c,3) faces, targets face targets, max_costs
    internal max errors, params its `CostModel.kernel_params` (the numbers; the kernels are ``model``'s),
    edges `topo.edges` of its faces, part_scales as `parallel.run`'s ``part_scale`` (None: one part),
    normals as its ``normals`` (None: each copy's faces' at its V). ``options`` are shared by every copy (its
    ``max_cost`` unused). A ``model`` that refreshes state (a late run's memoryless phase, `late.Second`)
    needs ``models``, each copy's own (`batchable` with ``own_refresh``). Returns C tuples in `parallel.run`'s
    form."""
    if not len(states):
        return []
    b = _Batch(Vs, states, Fs, targets, max_costs, model, params, options, edges, part_scales, normals, models)
    b.rounds()
    return b.outputs()
