"""The parallel scheduler's driver: one run's state (`Run`), its round implementation picked once (`choose`),
then rounds of named stages until the face target or a stop (`rounds`), and the run's `outcome.Outcome`."""
from __future__ import annotations

import numpy as np

from .. import outcome
from . import selection
from ..device import fuses
from .compiled import GlueRound, LoopRound
from .history import history_arrays, history_columns, removal_steps
from .pairs import touched
from .staged import StagedRound
from .stages import OneCall, Round, SeparateCalls
from .state import Run


def choose(run: Run, glue: bool = True) -> Round:
    """The round implementation of a run, by what it runs on: the compiled loops where they apply
    (`selection.fits`: manifold mode, pairs updated in place, a mesh they are fast on), else the numpy
    stages; the device work as one call where the model allows it (`device.fuses`; with locks only on the
    compiled loops, so that a locked run on the numpy stages stays the reference it is for them); and with
    both, the compiled glue as well, unless ``glue`` is False (a batch: its gates and budgets are per copy)."""
    compiled = selection.fits(run.manifold, run.incremental, run.locks, run.m)
    fused = run.incremental and (run.locks is None or compiled) and fuses(run.model)
    if compiled and fused and glue:
        rnd = GlueRound(run)
    elif compiled:
        rnd = LoopRound(run, OneCall() if fused else SeparateCalls())
    else:
        rnd = StagedRound(run, OneCall() if fused else SeparateCalls())
    run.adopted()
    return rnd


def rounds(run: Run, rnd: Round):
    """Rounds until the face target, or until no pair may contract. Returns (stop reason, blocked_by)."""
    prev, stop, blocked, again = None, "target", {}, None
    while run.faces.count > run.target:
        run.tally.rounds += 1
        need = run.faces.count - run.target
        if again is None:
            st, valid = rnd.pairs(prev, need)  # stages 1 and 2: update, cost
        else:  # after a round that only rejected: its pairs and prices, without the rejected ones
            st, valid, again = prev, again, None
        rnd.rank(st, valid)
        if not valid.any():
            stop, blocked = rnd.stop(st, need)
            break
        acc, n_sel, n_bad, locked, found = rnd.select(st, need, valid)  # stages 3 and 4: select, validate
        if acc.size == 0:
            if n_bad:  # the invalid ones are out now: select again among the rest (same pairs)
                again, prev = rnd.without_rejected(st, valid), st
                continue
            stop, blocked = rnd.stop(st, need)
            break
        rnd.contract(st, acc, touched(run.faces, run.n, locked, acc, n_sel, st.E), found)  # stage 5
        prev = st
        if run.progress is not None:
            run.progress(run.faces.count)
    rnd.settle()
    return stop, blocked


def run(V, S, F, extra_pairs, target_faces, model, options, progress=None, edges=None, part_scale=None,
        wedges=None, locks=None, normals=None):
    """Simplify. V (n,3) float32 normalised positions, S (n, model.width) the model's vertex state,
    F (m,3) int64 faces, extra_pairs (k,2) non-edge pairs that may also contract (aggregation; k may be
    0); ``edges``: `topo.edges` of F when the caller has it; ``part_scale`` (n,): (extent of each vertex's
    part / the whole extent)², which scales ``Schedule.free_cost`` per pair (None: one part).
    Returns the `outcome.Outcome` (the schedulers' contract). ``wedges``: a `_wedges.Tracker`
    (attributes kept: the seam rule applies and its corners are updated), or None. ``locks``: a
    `_locks.RunLocks` (locked vertices and weights; locked vertices numbered first), or None. ``normals``
    (m,3): the flip test's reference normal of each face (None: F's normals at V; a run that continues
    another gives the input faces' normals, `late`)."""
    r = Run(V, S, F, extra_pairs, target_faces, model, options, progress, edges, part_scale, wedges=wedges,
            locks=locks, normals=normals)
    stop, blocked = rounds(r, choose(r))
    return result(r, stop, blocked)


def result(r: Run, stop, blocked) -> outcome.Outcome:
    """The run's `outcome.Outcome`; lets go of its vertex rows."""
    t = r.tally
    rounds_of, a, b, x, cost = history_columns(t.history)
    hist = history_arrays(a, b, x, cost)
    removed_at, coincident, rounds_of = removal_steps(r.faces.F, rounds_of, a, b, t.dead, t.dropped)
    n = r.n
    # the vertices' rows without the padding of the run's arrays (a quarter more rows on a large mesh)
    V, S = np.ascontiguousarray(r.VQ[:n, :3]), np.ascontiguousarray(r.VQ[:n, 3:])
    r.VQ = r.VQd = None
    return outcome.Outcome(
        V, S, r.faces.F, r.faces.alive, outcome.History(*hist), stop, blocked,
        outcome.count_reasons(np.repeat(np.arange(len(t.rejected_by)), t.rejected_by)), rejected=t.rejected,
        rounds=t.rounds, worst_cost=t.max_cost_used, branches=t.branches, stage_times=outcome.stage_times(r.timer.t),
        faces_per_round=t.faces_per_round, parts=np.concatenate(t.history_parts) if t.history_parts else None,
        reweights=t.reweights, history_rounds=rounds_of, removed_at=removed_at, coincident=coincident)
