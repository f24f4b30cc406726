"""The stages every round implementation shares (`Round`): the pairs' update and prices (stages 1 and 2),
the candidates and their ranking, the numpy selection around the passes (stage 3), the bookkeeping of a
contraction (stage 5), and the two ways a round's device work goes (`SeparateCalls`, `OneCall`)."""
from __future__ import annotations

import time

import numpy as np

from ..._costs import MeshView
from ..._kernels.batching import CHUNKS, DTYPE, set_rows
from ..._mesh import row_compact
from ..._mesh import topology as topo
from ..._mesh.arrays import any_at, keep_rows as _keep, put_rows, take_rows as _take
from ..._mesh.edge_lists import endpoints
from ..._mesh.fixed_order import weighted_sum
from .. import locks as _locks
from .. import outcome
from ..device import start_merge, start_price, start_step
from ..select import fits_target, gate_rank, sort_keys
from .pairs import ring_vertices, with_extra_pairs
from .state import RoundState, Run, holding
from ..shape import ranking


def one_piece(run: Run, k: int) -> int | None:
    """The shape of the one piece a round prices its k stale pairs (the first round: every pair) in, in a call
    of their own (`device.start_price`'s ``size``), or None for `chunks`' shapes. More than a smallest piece
    holds and at most a middle one: the smallest shape of a fused round's price that holds them (`STEP_PRICE`,
    `holding`), one call instead of up to eight calls of the smallest. Each pair's price is its own, whatever
    the piece: the same values. A ring model's pieces follow its ring groups (`device.start_price`)."""
    if run.model.uses_ring or not CHUNKS[0] < k <= CHUNKS[1]:
        return None
    return holding(run.price_sizes, k)


class SeparateCalls:
    """A round's device work as separate calls: the merge starts with the contraction, the kept vertices' rows
    are written once it is in, and the next round prices its stale pairs in its own stage 2. With a model that
    refreshes state, the host rows alone: `Round.contract` writes the refreshed rows of the kept vertices' rings
    to the device next, and every kept vertex is in its ring (`pairs.ring_vertices`), so a device write here
    would be overwritten before anything reads it (a device call a round for nothing)."""

    def begin(self, run: Run, P, xs):
        return start_merge(run.model, run.VQd, P, xs, run.params, size=run.merge_chunk)

    def finish(self, rnd: Round, st: RoundState, a, P, xs, merged):
        run = rnd.run
        rows = np.concatenate([xs, merged()], 1)  # the kept vertices' new [position, state]
        put_rows(run.VQ, a, rows)
        if run.model.refresh is None:
            run.VQd = set_rows(run.VQd, a, rows, size=run.merge_chunk)


class OneCall:
    """A round's device work as one call (`device.start_step`, a model that `device.fuses`): the merge, the row
    update and the next round's price of its stale pairs, started once the contraction is done."""

    def begin(self, run: Run, P, xs):
        return None

    def finish(self, rnd: Round, st: RoundState, a, P, xs, _):
        run = rnd.run
        E, stale = st.edges_next[0], st.edges_next[4]
        d = np.flatnonzero(stale)
        run.VQd, merged, priced = start_step(run.model, run.VQd, P, xs, _take(E, d), run.params, run.merge_chunk,
                                             holding(run.price_sizes, len(d)))
        rnd.started(st, a, xs, d, merged, priced)


class Round:
    """The stages a round implementation shares, over the run's state ``run`` (`Run`). An implementation
    adds the selection passes (`passes`, with `ordered`) and the contraction of the mesh (`contract_mesh`),
    or replaces whole stages; ``device`` is how its device work goes (`SeparateCalls`, `OneCall`)."""

    counts_dtype = None  # the dtype of the pairs' face counts when rebuilt (None: as `topo.edges` gives them)

    def __init__(self, run: Run, device=None):
        self.run, self.device = run, device

    # -- stages 1 and 2 and the candidates -----------------------------------------------------------
    def pairs(self, prev: RoundState | None, need: int):
        """This round's priced pairs and its candidates (P,) bool."""
        return self.fresh(prev, need)

    def fresh(self, prev: RoundState | None, need: int):
        """`pairs` through `update`, `cost` and `candidates`."""
        t0 = time.perf_counter()
        st, follow, stale, same = self.update(prev)
        self.run.timer.add("topology_s", time.perf_counter() - t0)
        self.cost(st, prev, follow, stale, same)
        return st, self.candidates(st, need)

    def update(self, prev: RoundState | None):
        """This round's pairs. Returns the new state (prices not yet filled), the function that carries
        the last round's per-pair arrays over to the new pairs, which of them are stale (P,) bool, and
        on a rebuild which of them existed before (P,) bool (else None). On the first round the last
        three are None."""
        run = self.run
        n = run.n
        if prev is None or prev.edges_next is None:
            if run.edges is not None:
                # the caller's arrays as they are when int32 (read only here: every round makes new ones)
                E, ecount = np.asarray(run.edges[0], np.int32), run.edges[1]
                run.edges = None
            else:
                E, ecount = topo.edges(run.faces.live(), n)
            E, ecount = with_extra_pairs(E, ecount, run.extra_pairs, n)
            if self.counts_dtype is not None:  # face counts are small: int32 halves the largest per-pair array
                ecount = np.asarray(ecount, self.counts_dtype)
            deg = topo.vertex_degree(E if run.incremental else _keep(E, ecount > 0), n)
            keys = None if run.incremental else topo.edge_keys(E[:, 0], E[:, 1], n)  # sorted, as E is
            st = RoundState(E, ecount, deg, keys=keys)
            if prev is None:
                return st, None, None, None
            # rebuilt (never incremental here): find each pair's predecessor by key
            src = np.minimum(np.searchsorted(prev.keys, keys), len(prev.keys) - 1)
            same = prev.keys[src] == keys
            return st, (lambda a: _take(a, src)), any_at(prev.changed, E) | ~same, same
        E, ecount, kept, deg, stale = prev.edges_next
        st = RoundState(E, ecount, deg)
        if run.model.support == "ring":
            stale = stale | any_at(prev.changed, E)
        # several arrays follow, each moved down in place (the last round's arrays are not read again)
        idx = np.flatnonzero(kept)
        return st, (lambda a: row_compact.compact(a, idx)), stale, None

    def cost(self, st: RoundState, prev, follow, stale, same):
        """Fill the prices of ``st``: new ones for the stale pairs (the kernel runs while the host works
        on), the last round's for the rest, and what is known to be invalid."""
        run = self.run
        t0 = time.perf_counter()
        d, pending = self.start_prices(st, prev, follow, stale, same)
        run.timer.add("topology_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        self.settle()
        self.fill_prices(st, prev, follow, d, pending)
        if run.wedges is not None:  # pairs at seam vertices: placed at an allowed endpoint
            self.place_at_seams(st, np.arange(len(st.E)) if prev is None else d)
        if run.locks is not None:  # pairs of two locked vertices never contract
            st.bad[_locks.both_locked(run.locks, st.E)] = outcome.LOCKED
            if run.wedges is not None:  # a seam placement never moves a locked vertex
                _locks.pin(run.locks, run.VQ, st.E, st.x)
        run.timer.add("kernels_s", time.perf_counter() - t0)

    def start_prices(self, st: RoundState, prev, follow, stale, same):
        """The new prices of `cost`, started: (the stale rows d (None on the first round: every pair), a function
        giving their `Priced`). Meanwhile the rules known to be broken are carried over, and the boundary
        vertices marked."""
        run = self.run
        if prev is None:
            d, pending = None, run.first or start_price(run.model, run.VQd, st.E, run.params, run.faces, run.pad,
                                                        size=one_piece(run, len(st.E)))
            run.first = None
            st.bad = np.zeros(len(st.E), np.int8)
            if run.locks is not None:
                pending = self.locked_prices(pending, st.E)
        else:
            if prev.next_price is not None:  # started with the last round's device call (`OneCall`)
                d, pending = prev.next_price
                prev.next_price = None
            else:
                d = np.flatnonzero(stale)
                pending = start_price(run.model, run.VQd, _take(st.E, d), run.params, run.faces, run.pad,
                                      size=one_piece(run, len(d)))
            if run.locks is not None:
                pending = self.locked_prices(pending, _take(st.E, d))
            st.bad = follow(prev.bad)  # found invalid, and their neighbourhood has not changed since
            if same is not None:
                st.bad = st.bad * same
        st.bvert = endpoints(st.E, st.ecount == 1, run.n)
        return d, pending

    def fill_prices(self, st: RoundState, prev, follow, d, pending):
        """The prices into ``st``: every pair's from ``pending`` on the first round; else the last round's,
        carried over by ``follow``, with the stale rows d from ``pending``."""
        if prev is None:
            st.x, st.cost, st.branch, parts = pending()
            st.parts = np.ascontiguousarray(parts.T)
            return
        # separate arrays, each under 32 MB at 2 M edges: glibc maps larger ones afresh every time
        # (page faults on every round; one (E,5) array was slower to gather here)
        st.x, st.cost, st.branch = follow(prev.x), follow(prev.cost), follow(prev.branch)
        xd, st.cost[d], st.branch[d], parts = pending()
        put_rows(st.x, d, xd)
        # (a model without cost parts: no take of P empty rows, which numpy still spends P checks on)
        st.parts = follow(prev.parts) if prev.parts.shape[1] else prev.parts[:0].reshape(len(st.E), 0)
        if len(parts):  # a model with cost parts
            put_rows(st.parts, d, np.ascontiguousarray(parts.T))

    def place_at_seams(self, st: RoundState, d):
        """Newly priced pairs d at seam vertices (kept attributes): placed at an allowed endpoint, and marked
        `outcome.SEAM` where none is (`wedges.Tracker.constrain`)."""
        run = self.run
        run.wedges.constrain_rows(run.faces, run.VQ, st.E, d, st.x, st.cost, st.bad, outcome.SEAM)

    def settle(self):
        """The last round's merged vertex states into the host rows VQ (the device call leaves them on the
        device while the host works on): before anything reads VQ's states, and at the end of the run."""
        run = self.run
        if run.merged is not None:
            a, merged = run.merged
            run.merged = None
            run.VQ[a, 3:] = merged()

    def locked_prices(self, pending, P):
        """``pending`` (a price of pairs P) with locked kept vertices and the weights applied (`_locks.adjust`)."""
        run = self.run
        held = None if run.wedges is None else run.wedges.held
        return lambda: _locks.adjust(run.locks, run.weights, run.model, run.VQ, run.VQd, P, pending(),
                                     run.params, run.faces, run.pad, held=held)

    def candidates(self, st: RoundState, need, max_cost=None) -> np.ndarray:
        """(P,) bool: the pairs that may contract this round (not known invalid, within max_error and
        the face budget; manifold mode: edges with one or two faces). ``need`` and ``max_cost`` may be
        given per pair (a batch's copies); max_cost None: the options'."""
        return self.candidates_of(st.cost, st.bad, st.ecount, need, max_cost)

    def candidates_of(self, cost, bad, ecount, need, max_cost=None) -> np.ndarray:
        """`candidates` of pairs given by their costs, known rules and face counts."""
        limit = self.run.options.max_cost if max_cost is None else max_cost
        valid = (cost <= limit) & (bad == 0) & (ecount <= need)
        if self.run.manifold:
            valid &= (ecount >= 1) & (ecount <= 2)
        return valid

    def rank(self, st: RoundState, valid: np.ndarray):
        """Set ``st.key``: the cost, or for a model with `rank_weights` the cost plus its weighted parts,
        with weights taken from the candidate pairs (``valid``) at the start and again whenever the face
        count has fallen by the model's ``reweight_step`` since (then recorded in ``reweights``)."""
        run, t = self.run, self.run.tally
        if run.model.rank_weights is None:
            st.key = st.cost
            return
        count = run.faces.count
        if t.rank_w is None or count <= (1.0 - run.model.reweight_step) * t.weighed_at:
            t.rank_w = run.model.rank_weights(st.parts.compress(valid, axis=0))
            t.weighed_at = count
            t.reweights.append((count, t.rank_w))
        st.key = (st.cost + weighted_sum(st.parts, t.rank_w)).astype(DTYPE)

    # -- stages 3 and 4: select and validate ----------------------------------------------------------
    def select(self, st: RoundState, need: int, valid: np.ndarray):
        """The accepted pairs in cost order, cut to the face target; records the rejected ones in
        ``st.bad``. Returns (accepted indices, how many were selected, how many were rejected, the
        locked vertices, what validation found for them)."""
        run, t = self.run, self.run.tally
        t0 = time.perf_counter()
        sch = run.options.schedule
        k = gate_rank(need, int(valid.sum()), len(st.E), sch)
        kth = np.partition(st.key.compress(valid), k - 1)[k - 1]
        salt = t.rounds * 7919

        def key_of(idx):
            return sort_keys(st.key, idx, salt)
        free = sch.free_cost if run.part_scale is None else sch.free_cost * run.part_scale[st.E[:, 0]]
        cand = valid & (st.key <= np.maximum(sch.gate * kth, free))
        with ranking(st, run, valid, cand, free) as cand:  # (with the shape term, `shape`)
            acc, bad, why, extra, locked, found = self.passes(st, key_of, cand, need, None)
            order = np.argsort(key_of(acc), kind="stable")
        self.count_rejected(why)
        n_sel = acc.size
        fit = fits_target(st.ecount[acc[order]] + (0 if extra is None else extra[acc[order]]), need)
        acc = acc[order[fit]]
        found = self.ordered(found, order[fit])
        run.timer.add("select_s", time.perf_counter() - t0)
        st.bad[bad] = why
        return acc, n_sel, bad.size, locked, found

    def count_rejected(self, why):
        """The rules of the pairs a round's passes rejected, into the tally."""
        t = self.run.tally
        t.rejected += why.size
        t.rejected_by += np.bincount(why, minlength=len(t.rejected_by))

    def retry(self, st: RoundState):
        """A batch's round that only rejected: the same pairs updated and priced again next round, the
        rejected ones out (a single run takes `without_rejected`)."""
        st.changed = np.zeros(self.run.n, bool)
        if self.run.incremental:
            st.edges_next = (st.E, st.ecount, np.ones(len(st.E), bool), st.deg, np.zeros(len(st.E), bool))

    def without_rejected(self, st: RoundState, valid: np.ndarray) -> np.ndarray:
        """The candidates of a round after one that only rejected: its own without those it rejected. Nothing
        contracted, so the pairs, their prices, the rules known and the face budget are as they were, and
        `pairs` would make the same state again (update, prices, candidates)."""
        return valid & (st.bad == 0)

    def stop(self, st: RoundState, need: int):
        """The stop reason and what blocked the remaining pairs (`outcome.classify`)."""
        run = self.run
        ok = ((st.ecount >= 1) & (st.ecount <= 2)) if run.manifold else np.ones(len(st.E), bool)
        return outcome.classify(run.faces.count, run.target, st.bad, st.ecount, st.cost > run.options.max_cost, ok)

    # -- stage 5: contract ----------------------------------------------------------------------------
    def contract(self, st: RoundState, acc, touched, found):
        """Contract the accepted pairs ``acc`` together (``touched``: the vertices whose rejected pairs get
        another chance, `pairs.touched`; ``found``: what validation found for them); leaves in ``st`` what the
        next round's update needs."""
        run, t = self.run, self.run.tally
        t0 = time.perf_counter()
        P = _take(st.E, acc)
        a, b = P[:, 0], P[:, 1]
        xs = _take(st.x, acc)
        merged = self.device.begin(run, P, xs)  # runs meanwhile
        st.changed = np.zeros(run.n, bool)
        st.changed[a] = True
        t.branches += np.bincount(st.branch[acc], minlength=len(t.branches))
        _locks.carry(run.weights, a, b)
        t.max_cost_used = max(t.max_cost_used, float(st.cost[acc].max()))
        self.record(st, acc, a.copy(), b.copy(), xs, st.cost[acc].astype(np.float64))
        self.contract_mesh(st, acc, P, xs, touched, found)
        self.device.finish(self, st, a, P, xs, merged)
        if run.model.support == "ring" or run.model.refresh is not None:
            ring = ring_vertices(run.faces, a, run.n)
            if run.model.support == "ring":
                st.changed = ring
            if run.model.refresh is not None:
                self.refresh(np.flatnonzero(ring))
        t.faces_per_round.append(run.faces.count)
        run.timer.add("contract_s", time.perf_counter() - t0)

    def record(self, st: RoundState, acc, a, b, xs, costs):
        """The round's contractions ``acc`` (kept a, removed b, at xs, costs float64) into the history, with
        their cost parts and keys for a model with parts."""
        t = self.run.tally
        t.history.append((t.rounds - 1, (a, b, xs, costs)))
        if st.parts.shape[1]:
            t.history_parts.append(np.concatenate([_take(st.parts, acc), _take(st.key, acc)[:, None]], 1))

    def started(self, st: RoundState, a, xs, d, merged, priced, moved: bool = False):
        """After a round's one device call: the kept vertices' positions into VQ (unless ``moved``: the
        compiled contraction wrote them), their merged states pending until `settle`, and the next round's
        price of its stale rows d pending in ``st``."""
        st.next_price = (d, priced)
        if not moved:
            self.run.VQ[a, :3] = xs
        self.run.merged = (a, merged)  # the states reach VQ when the price is waited for (`settle`)

    def refresh(self, verts):
        """Recompute the model's derived state at ``verts`` (after their neighbourhood changed)."""
        run = self.run
        state = np.asarray(run.model.refresh(MeshView(run.faces, run.VQ[: run.n]), verts), DTYPE)
        run.VQ[verts, 3:] = state
        run.VQd = set_rows(run.VQd, verts, run.VQ[verts], size=run.merge_chunk)
