"""A distance you can ask for: ``simplify(max_distance=D)`` or ``max_distance_rel=R`` (docs/metrics.md).

The contraction costs bound no distance, so the bound is kept after the run, from its record
(`_record.history`): the run goes toward its face target (or, with none, as far as it can), then the
prefixes of its contractions are searched for the fewest faces whose mesh lies within D of the input *both
ways* at these samples (`Checker`):

* every input sample, the input's vertices and face centroids (the points the measured distance uses,
  `measure`; zero-weight ones too), to its nearest point of the output;
* every output sample, the output's vertices and face centroids, to its nearest point of the input;

each an exact point-triangle distance (`_mesh.grid_nearest`). A prefix's distance is not monotone in its
length, so the search (a bisection over the prefixes) only proposes: the level returned is the one
checked, with the number checked reported as ``stats["distance_two_way_max"]`` (<= D). With a re-fit
(the default method's), the levels are searched without it first, then re-fitted ones beyond that pick;
the returned geometry is re-fitted only when the re-fitted mesh is the one that passed. The bound is not a
continuous Hausdorff bound: points between samples may lie farther (docs/metrics.md says how far off it is).
"""
from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np

from .._record.result import Contractions
from .._schedulers import outcome

# the comparison's allowance for rounding, times the input's largest extent: the distances are found in the
# input's unit frame (`refit.unit_frame`) and scaled back, which an independent float64 recomputation in
# mesh units may differ from by a few ulps of the coordinates; a level passes when its distance plus this
# is within the bound, so the figure reported is below the bound by at least that much
SLACK = 1e-12
ABOVE_TARGET = "stopped at "  # how `stages._above_target_message` begins (replaced when the bound stopped it)


@dataclasses.dataclass(frozen=True)
class Bound:
    """The bound as given: ``value`` in mesh units (``relative`` False) or as a fraction of the input's
    bounding-box diagonal (``relative`` True)."""

    value: float
    relative: bool

    def in_mesh_units(self, diagonal: float) -> float:
        return self.value * diagonal if self.relative else self.value


def check(max_distance, max_distance_rel) -> Bound | None:
    """The bound from simplify's keywords (None: none given); ValueError naming the bad one."""
    from .stages import _real

    if max_distance is not None and max_distance_rel is not None:
        raise ValueError("give at most one of max_distance (mesh units) and max_distance_rel "
                         "(a fraction of the bounding-box diagonal)")
    for name, x, unit in (("max_distance", max_distance, "mesh units"),
                          ("max_distance_rel", max_distance_rel, "a fraction of the bounding-box diagonal")):
        if x is not None:
            v = _real(name, x)
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be a finite distance >= 0 ({unit}), got {x!r}")
            return Bound(v, name == "max_distance_rel")
    return None


def supported(job) -> None:
    """ValueError for what a bounded run cannot do: the record replays positions and faces only."""
    if job.setup.split is not None:
        raise ValueError("max_distance needs split_factor=None (CLI: --split-factor none) with this method: edge "
                         "splits come after all contractions, and the bound picks a level of the contractions")
    if job.tracker is not None:
        raise ValueError("max_distance keeps positions only (the levels it checks are replayed from the "
                         f"contractions, without attributes): pass attributes=None (CLI: --attributes none; "
                         f"kept: {', '.join(job.attrs.values)})")


def without_refit(job):
    """The job as `stages.finish` should end it for a bounded run: no re-fit and no measurement there (they
    are done on the level `apply` picks)."""
    setup = job.setup
    method = dataclasses.replace(setup.method_obj, refit=0)
    return job._replace(setup=dataclasses.replace(setup, method_obj=method, measure=False))


class Checker:
    """The two-way distance (module docstring) of meshes from the input (V, F), mesh units."""

    def __init__(self, V: np.ndarray, F: np.ndarray):
        from .._mesh.arrays import box_diagonal
        from .._mesh.box_bounds import row_bounds
        from .refit import _sample_rows, unit_frame

        V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
        box = row_bounds(V)
        self.centre, self.unit = unit_frame(V, box)
        self.diagonal = box_diagonal(box[0], box[1])
        self.Vn, self.F = (V - self.centre) / self.unit, F
        # the measured distance's samples (`refit.samples`, the same arithmetic), zero weights kept, and only
        # the vertices a face uses (an unused vertex is no point of the surface)
        P = _sample_rows(self.Vn, F, np.zeros(len(V), np.int64))[0]
        used = np.zeros(len(P), bool)
        used[F.reshape(-1)] = True
        used[len(V):] = True
        self.P = P[used]
        self.checks = 0

    def __call__(self, X: np.ndarray, G: np.ndarray) -> float:
        """The largest of both ways' sample distances for the mesh (X, G), in mesh units (inf: no faces)."""
        from .._mesh.grid_nearest import nearest

        self.checks += 1
        if len(G) == 0:
            return math.inf
        Xn = (np.asarray(X, np.float64) - self.centre) / self.unit
        G = np.asarray(G, np.int64)
        Q = np.concatenate([Xn[np.unique(G)], ((Xn[G[:, 0]] + Xn[G[:, 1]]) + Xn[G[:, 2]]) / 3])
        into = nearest(Xn, G, self.P)[1].max()  # input samples to the output
        back = nearest(self.Vn, self.F, Q)[1].max()  # output samples to the input
        return float(max(into, back)) * self.unit

    def passes(self, d: float, limit: float) -> bool:
        return d + SLACK * self.unit <= limit


def finish(job, ran, bound: Bound, t_start: float, c0, s0, stacklevel: int, batch: dict | None = None):
    """`stages.finish` for a bounded run: the result of `without_refit(job)`, then `apply`. Warnings point
    ``stacklevel`` frames up from here, as `stages.finish`'s do from there."""
    from . import stages

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = stages.finish(without_refit(job), ran, t_start, c0, s0, stacklevel=stacklevel, batch=batch)
    return apply(res, job, bound, stacklevel + 1, caught)


def apply(res, job, bound: Bound, stacklevel: int, caught: list) -> object:
    """The bounded result: ``res`` (from `stages.finish` of `without_refit(job)`) cut back to the level of
    its record that the search picks, re-fitted when that passes, measured; its stop reason, stats and
    warnings. ``caught``: the warnings `finish` issued (re-issued here, but for its above-target one when the
    bound stopped the run). ``job``: the run's own (with its re-fit)."""
    from . import measure as _measure
    from .refit import refit as _refit

    t0 = time.perf_counter()
    rec, setup = res.record, job.setup
    g = job.locks.geo if job.locks is not None else job.geo
    V, F = rec.input_vertices, rec.input_faces
    chk = Checker(V, F)
    limit = bound.in_mesh_units(chk.diagonal)
    J = len(rec.history)

    def level(j):
        lv = rec.replay(contractions=j)
        return lv, (0.0 if j == 0 else chk(lv.vertices, lv.faces))

    def refitted(lv):
        fixed = None if rec.locked is None else rec.locked[lv.source_vertices]
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            X = _refit(V, F, lv.vertices, lv.faces, setup.refit, setup.cos_max, g.parts[1], lv.source_faces,
                       fixed=fixed, min_quality=setup.min_quality, polish=setup.polish,
                       sliver_moves=setup.sliver_moves)
        return X, chk(X, lv.faces), w

    # 1. bisection over the prefixes, without the re-fit: lo passes (0, the input, always), hi does not
    best, d_best = level(J)
    lo, hi = (J, J + 1) if chk.passes(d_best, limit) else (0, J)
    if lo == 0:
        best, d_best = level(0)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lv, d = level(mid)
        if chk.passes(d, limit):
            lo, best, d_best = mid, lv, d
        else:
            hi = mid
    X, refit_rounds, refit_note, refit_warnings = best.vertices, 0, None, []
    # 2. the re-fit: on the pick, then (if it passes) on the prefixes beyond it, by bisection again
    if setup.refit and lo > 0:
        Xr, dr, w = refitted(best)
        if chk.passes(dr, limit):
            X, d_best, refit_rounds, refit_warnings = Xr, dr, setup.refit, w
            a, b = lo, J + 1
            while b - a > 1:
                mid = (a + b) // 2
                lv = rec.replay(contractions=mid)
                Xm, dm, wm = refitted(lv)
                if chk.passes(dm, limit):
                    a, best, X, d_best, refit_warnings = mid, lv, Xm, dm, wm
                else:
                    b = mid
            lo = a
        else:
            refit_note = "the re-fitted level lay beyond max_distance"
    elif setup.refit:
        refit_note = "max_distance returned the input itself"
    j = lo
    counts = rec.face_counts()
    bound_stopped = j < J and counts[j] > counts[J]
    for w in refit_warnings:
        warnings.warn(w.message, w.category, stacklevel=stacklevel)
    for w in caught:  # the run's own warnings; its above-target one only when the bound did not stop it
        if not (bound_stopped and str(w.message).startswith(ABOVE_TARGET)):
            warnings.warn(w.message, w.category, stacklevel=stacklevel)
    target = res.stats["target_faces"]
    if bound_stopped and target and len(best.faces) > target:
        warnings.warn(f"stopped at {len(best.faces)} faces, above the target of {target}: a further contraction "
                      f"would put the output more than max_distance ({limit:.3g} mesh units) from the input",
                      stacklevel=stacklevel)
    _cut(res, rec, best, X, j, J)
    s = res.stats
    if bound_stopped:
        res.stop_reason = "max_distance"
    rounds = rec.history.rounds
    if j < J and rounds is not None and len(rounds) == J:
        s["rounds"] = int(rounds[j - 1]) + 1 if j else 0
        s["rounds_contracting"] = outcome.contracting_rounds(rounds[:j])
        if isinstance(s.get("faces_per_round"), list):
            # one entry per round that contracted something (rounds that contracted nothing have none, so
            # the rounds run are no count of them), from the record: the count after each such round's last
            # contraction in the prefix, the level's own for a round the cut ends inside
            last = np.flatnonzero(np.diff(rounds[:j]) != 0).tolist() + [j - 1] if j else []
            s["faces_per_round"] = [int(counts[k + 1]) for k in last]
    s.update(faces_out=len(best.faces), vertices_out=len(X), contractions=j, refit=refit_rounds,
             max_distance=limit, max_distance_rel=(limit / chk.diagonal if chk.diagonal > 0 else None),
             distance_two_way_max=d_best,
             distance_two_way_max_rel=(d_best / chk.diagonal if chk.diagonal > 0 else None),
             max_distance_checks=chk.checks)
    if refit_note:
        s["refit_skipped"] = refit_note
    s.update(_measure.distance(V, F, X, best.faces))
    if j == 0:  # the input itself: every sample lies on it
        s["distance_two_way_max"] = s["distance_two_way_max_rel"] = 0.0
    s["max_distance_s"] = time.perf_counter() - t0
    s["total_s"] += s["max_distance_s"]
    s["run_s"] += s["max_distance_s"]
    return res


def _cut(res, rec, lv, X, j: int, J: int) -> None:
    """``res`` becomes the level ``lv`` (after ``j`` of the ``J`` contractions) at positions X."""
    same = j == J and np.array_equal(lv.source_vertices, res.source_vertices)
    res.vertex_error = res.vertex_error if same else np.full(len(X), np.nan)
    res.vertices, res.faces = np.asarray(X, np.float64), lv.faces.astype(np.int64)
    res.source_vertices, res.source_faces = lv.source_vertices, lv.source_faces
    res.max_error = lv.max_error
    if j < J:
        h = rec.history
        res.history = Contractions(h.pairs[:j], h.positions[:j], h.costs[:j], {k: v[:j] for k, v in h.parts.items()},
                                   None if h.rounds is None else h.rounds[:j])
        removed = np.where(rec.removed_at >= j, -1, rec.removed_at)
        res.record = dataclasses.replace(rec, history=res.history, removed_at=removed,
                                         coincident=rec.coincident & (rec.removed_at >= 0) & (rec.removed_at < j),
                                         target_faces=0)
