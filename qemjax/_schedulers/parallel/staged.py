"""The round as numpy stages (`StagedRound`): selection passes of whole-array steps (`select.independent_sets`),
validation with the link test on the worker thread and the flip test on the device, and the contraction
through `FaceLists`. It serves every mode: meshes too large for the compiled loops, pairs rebuilt each round
(non-manifold mode, non-edge pairs), and it is the reference the compiled rounds are tested against."""
from __future__ import annotations

import time

import numpy as np

from ..._mesh import topology as topo
from ..._mesh.arrays import any_at, take_rows as _take
from .. import locks as _locks
from .. import outcome
from ..device import start_flips
from ..select import independent_sets, submit
from .pairs import EdgeUpdate, accepted, drop_coincident
from .stages import Round
from .state import RoundState


class StagedRound(Round):
    """A round's selection, validation and contraction as numpy stages."""

    def passes(self, st: RoundState, key_of, cand, need, groups, local=None):
        """The selection passes with validation (`select.independent_sets`; ``groups``: a batched run's
        (vcopy, need per copy, pair copies); ``local`` is read by the compiled loops only). Returns
        (accepted pairs in pass order, rejected pairs, their rules, the extra faces each accepted pair
        removes (None: none), the locked vertices, what validation found: the list `validate` fills)."""
        found = []
        acc, bad, why, extra, locked = independent_sets(
            st.E, key_of, cand, need, self.run.n, lambda *a: self.validate(st, found, *a), self.run.options.schedule,
            groups=groups)
        return acc, bad, why, extra, locked, found

    def ordered(self, found, order):
        """What validation found, for the accepted pairs taken in ``order``: kept in pass order (the
        contraction renumbers it, `pairs.accepted`)."""
        return found

    def validate(self, st: RoundState, found: list, P, idx, Efree):
        """(rule broken per pair (0: valid), faces made coincident) for vertex-disjoint pairs P (indices
        idx into this round's pairs). Efree (rows of this round's pairs) holds every pair at them; the faces
        come from `FaceLists`. In manifold mode the link test runs on the worker thread. What the contraction
        will need again (the faces' look-up and, in manifold mode, the apexes that the link test found, for
        the edge update) is appended to ``found``."""
        run = self.run
        tv = time.perf_counter()
        if run.manifold:
            link = submit(topo.link_ok, P, st.ecount[idx], Efree, run.n, st.bvert, st.deg, apexes=True,
                          size=len(Efree))
        (fids, before, corner, owner, G), kept, dead = run.faces.touched_with_dead(P)
        flipped = start_flips(run.VQd, run.N0d, before, fids, corner, owner, _take(st.x, idx), len(P),
                              run.cos_max, run.min_quality)  # runs while the host tests the rest
        dropped = topo.coincident_rows(G)  # the faces each pair would drop as coincident (non-manifold mode)
        gone = np.bincount(owner[dropped], minlength=len(P))
        why = np.zeros(len(P), np.int8)
        apex = None
        if run.manifold:  # link condition, no coincident faces
            linked, apex = link.result()
            why[gone > 0] = outcome.COINCIDENT
            if run.options.keep_parts:  # the pair's faces are all its part has left
                why[np.bincount(owner, minlength=len(P)) == 0] = outcome.PART
            why[~linked] = outcome.TOPOLOGY
        if run.locks is not None:  # a locked vertex never leaves the mesh (its part's or its own last faces)
            gone_locked = _locks.vanishing(run.locks, P, np.bincount(owner, minlength=len(P))) | \
                _locks.strands(run.locks, run.faces, P, dead) | _locks.drops(run.locks, G, owner, dropped, len(P))
            why[(why == 0) & gone_locked] = outcome.LOCKED
        if run.wedges is not None:  # the seam rule, for the pairs still valid
            why[run.wedges.refused(run.faces, run.VQ, P, _take(st.x, idx), why == 0)] = outcome.SEAM
        found.append((idx, kept, dead, apex))
        flip = flipped()
        why[(why == 0) & flip] = outcome.FLIP
        run.timer.add("validity_s", time.perf_counter() - tv)
        return why, gone

    def contract_mesh(self, st: RoundState, acc, P, xs, touched, found):
        """The faces and, in manifold mode, the pairs after the accepted pairs ``acc`` (P, placed at xs)
        contract, from what validation ``found``; the rejected pairs at ``touched`` get another chance. The
        pairs' update runs on the worker thread while this thread relinks the faces."""
        run = self.run
        n, faces = run.n, run.faces
        a, b = P[:, 0], P[:, 1]
        r = np.flatnonzero(st.bad)
        if r.size:
            st.bad[r[any_at(touched, _take(st.E, r))]] = 0
        taken = np.zeros(len(st.E), bool)
        taken[acc] = True
        pairs, kept, dead, apex = accepted(st.E, found, taken)  # in pass order, not acc's
        edges_next = None
        if run.incremental:
            edges_next = EdgeUpdate(st.E, st.ecount, st.deg, pairs[:, 0], pairs[:, 1], np.asarray(apex, np.int64),
                                    run.label)
        if run.wedges is not None:  # the corners' wedges, before the faces are relinked
            run.wedges.contract_many(faces, run.VQ, P, xs)
        faces.contract_touched(pairs, kept, dead)
        run.tally.dead.append(dead)
        if not run.manifold:
            run.tally.dropped.append((run.tally.rounds - 1, drop_coincident(faces, a)))
        if len(run.extra_pairs):
            rep = np.arange(n, dtype=np.int32)
            rep[b] = a
            ep = rep[run.extra_pairs]
            run.extra_pairs = ep[ep[:, 0] != ep[:, 1]]
        if edges_next is not None:
            st.edges_next = edges_next.result()
