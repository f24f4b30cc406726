"""A run in two phases (``QEM(late_memoryless=K)``): the model's summed quadrics until the faces fall to K × the
target, then memoryless quadrics (`QEM.late_model`) to the target, on any scheduler.

Why: summed quadrics keep the memory of the input, which is what holds the rms down; memoryless ones price a
contraction by the surface as it is now, which holds the farthest point (the Hausdorff distance) down. Most of
what the memoryless quadrics gain comes in the last stretch of a run (docs/benchmarks.md, "Quality"), where
they cost little: the rounds there are few and the mesh small.

The second phase is a run of its own, by the same scheduler, on the first phase's mesh: its faces alive (in
input order) and the vertices they use (renumbered in order, with their locks and per-part scales), the
summed quadrics as the memoryless rows' history (``late_memory_weight`` weighs them), the input faces'
normals as the flip test's reference (as if one run), the lock weights as the first phase carried them, and
the extra pairs whose ends are still there. The two outcomes are joined into one (`join`): one history, the faces
numbered as the input's, the states back to the summed quadrics' columns (what the rest of the pipeline reads).
"""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .._costs import memoryless as ml
from .._kernels.batching import DTYPE
from .._mesh import topology as topo
from .._mesh.arrays import face_normals, face_stats
from .._mesh.incidence import FaceLists
from . import outcome
from .locks import RunLocks


def switch_faces(model, target_faces: int) -> int | None:
    """The face count at which a run of ``model`` turns memoryless (None: it does not)."""
    if not getattr(model, "switches_late", False):
        return None
    return int(model.late_memoryless * target_faces)


def first_target(model, target_faces: int) -> int:
    """The face target of a run's first phase: K × the target (the target itself without a switch)."""
    return max(switch_faces(model, target_faces) or 0, target_faces)


def run(scheduler, V, S, F, extra_pairs, target_faces, model, options, progress=None, *, edges=None,
        part_scale=None, wedges=None, locks=None):
    """`scheduler` (a scheduler's ``run``) in two phases; the scheduler contract's arguments and return.
    Kept attributes (``wedges``) are refused: the memoryless rows carry no attribute terms."""
    if wedges is not None:
        raise ValueError("late_memoryless keeps no attributes (the memoryless quadrics have no attribute terms)")
    kw = {} if locks is None else {"locks": locks}
    first = scheduler(V, S, F, extra_pairs, first_target(model, target_faces), model, options, progress,
                      edges=edges, part_scale=part_scale, **kw)
    return second(scheduler, first, V, F, extra_pairs, target_faces, model, options, progress,
                  part_scale=part_scale, locks=locks)


class Second(NamedTuple):
    """The second phase's run (`prepare`): its arguments to a scheduler (positions V, states S, faces F, extra
    pairs, target, the memoryless model, per-vertex part scales, the flip test's reference normals, locks) and
    where its mesh sits in the first's (``faces``: the first phase's faces alive, ``keep``: its vertices)."""
    V: np.ndarray
    S: np.ndarray
    F: np.ndarray
    extra: np.ndarray
    target: int
    model: object
    part_scale: np.ndarray | None
    normals: np.ndarray
    locks: RunLocks | None
    faces: np.ndarray
    keep: np.ndarray

    def run(self, scheduler, options, progress=None) -> outcome.Outcome:
        """The second phase on ``scheduler`` (a scheduler's ``run``)."""
        kw = {} if self.locks is None else {"locks": self.locks}
        return scheduler(self.V, self.S, self.F, self.extra, self.target, self.model, options, progress,
                         part_scale=self.part_scale, normals=self.normals, **kw)


def second(scheduler, first: outcome.Outcome, V, F, extra_pairs, target_faces, model, options, progress=None,
           *, part_scale=None, locks=None) -> outcome.Outcome:
    """The second phase after ``first`` (the first phase's outcome on the run's V, F: `run`), joined to it;
    ``first`` itself when it has none (`prepare`)."""
    nxt = prepare(first, V, F, extra_pairs, target_faces, model, part_scale=part_scale, locks=locks)
    if nxt is None:
        return first
    return join(first, nxt.run(scheduler, options, progress), nxt.faces, nxt.keep)


def prepare(first: outcome.Outcome, V, F, extra_pairs, target_faces, model, *, part_scale=None,
            locks=None) -> Second | None:
    """The second phase's run after ``first`` (the first phase's outcome on the run's V, F: `run`, or a batch's
    copy: `_schedulers.batched` runs such phases side by side), to `join` to it; None when the cost limit
    stopped the first or it has no faces to remove. A first phase held back short of its target still
    switches (a closed mesh stops one face above an odd target, and one with a lone part may end two above
    it): the memoryless prices may place where the summed ones could not, and the second phase reports its
    own stop."""
    faces = np.flatnonzero(first.alive)
    if switch_faces(model, target_faces) is None or first.stop_reason == "max_error" or len(faces) <= target_faces:
        return None
    late = model.late_model()
    n = len(V)
    # the second run holds the vertices the faces left use, renumbered in order (locked ones, numbered first,
    # stay first): a run's per-round work and arrays grow with its vertices, and after a large first phase
    # most of them are gone
    keep = np.unique(first.faces[faces])
    at = np.full(n, -1, np.int64)
    at[keep] = np.arange(len(keep))
    F2 = at[first.faces[faces]]
    # the memoryless rows: the summed quadrics as history, the current ones from the faces left, and the
    # input's means (the memoryless model's normalisation)
    means = face_stats(np.asarray(V, np.float64), np.asarray(F, np.int64))[1:]
    S2 = ml.state_rows(late, np.asarray(first.positions, np.float64)[keep], FaceLists(F2, len(keep)),
                       np.arange(len(keep)), means, history=first.states[keep])
    kept = topo.contraction_roots(first.history.pairs, n)
    extra = np.asarray(extra_pairs, np.int64).reshape(-1, 2)
    if len(extra):
        extra = at[kept[extra]]
        extra = np.unique(np.sort(extra[(extra >= 0).all(1)], axis=1), axis=0)
        extra = extra[extra[:, 0] != extra[:, 1]]
    run_locks = None
    if locks is not None:  # the weights as the first phase carried them (`locks.carry`: the largest)
        w = None if locks.weights is None else np.array(locks.weights, np.float64)
        if w is not None:
            np.maximum.at(w, kept, np.asarray(locks.weights, np.float64))
            w = w[keep]
        run_locks = RunLocks(np.asarray(locks.locked)[keep], w)
    normals = face_normals(np.asarray(V, DTYPE), np.asarray(F, np.int64)[faces])
    return Second(np.ascontiguousarray(first.positions[keep]), S2, F2, extra, target_faces, late,
                  None if part_scale is None else np.asarray(part_scale)[keep], normals, run_locks, faces, keep)


def join(first: outcome.Outcome, second: outcome.Outcome, faces: np.ndarray, keep: np.ndarray) -> outcome.Outcome:
    """One outcome of the two phases: ``second`` ran on ``first``'s faces ``faces`` (input numbers, in order)
    over its vertices ``keep`` (second's vertex i is first's keep[i]). Faces and vertices keep their input
    numbers; the second phase's contractions follow the first's in the history (their rounds after the
    first's); the states are the summed quadrics."""
    k1 = first.contractions
    F = first.faces.copy()
    F[faces] = keep[second.faces]
    positions, states = first.positions.copy(), first.states.copy()
    positions[keep] = second.positions
    states[keep] = second.states[:, :ml.CCOLS - 3]  # the summed quadrics' columns (the rows' history)
    alive = np.zeros_like(first.alive)
    alive[faces] = second.alive
    removed_at = first.removed_at.copy()
    removed_at[faces] = np.where(second.removed_at >= 0, second.removed_at + k1, -1)
    coincident = first.coincident.copy()
    coincident[faces] = second.coincident
    h1, h2 = first.history, second.history._replace(pairs=keep[second.history.pairs])
    history = outcome.History(*(np.concatenate([a, b]) for a, b in zip(h1, h2)))
    rounds = np.concatenate([first.history_rounds, second.history_rounds + first.rounds])
    times = {k: first.stage_times.get(k, 0.0) + second.stage_times.get(k, 0.0)
             for k in {**first.stage_times, **second.stage_times}}
    per_round = None if first.faces_per_round is None else list(first.faces_per_round) + list(
        second.faces_per_round or [])
    return dataclasses.replace(
        second, positions=positions, states=states, faces=F, alive=alive, history=history,
        rejected_by={k: first.rejected_by.get(k, 0) + v for k, v in second.rejected_by.items()},
        rejected=first.rejected + second.rejected, rounds=first.rounds + second.rounds,
        worst_cost=max(first.worst_cost, second.worst_cost), branches=first.branches + second.branches,
        stage_times=times, faces_per_round=per_round, parts=None if first.parts is None else np.concatenate(
            [first.parts, second.parts]), reweights=first.reweights + second.reweights, history_rounds=rounds,
        removed_at=removed_at, coincident=coincident, switched_at=len(faces))
