"""The stages of one run of `simplify`, in order, each a function of the previous one's output:

1. `setup`: check every setting that does not need the mesh (the method object, `Topology`,
   `Attributes`, the scheduler) -> `Setup`;
2. `geometry`: read and clean the mesh, and what depends on the mesh alone -> `Geometry` (shared by every
   run of one mesh in a batch);
3. `job`: the face target, the cost model's initial vertex state and the scheduler's `Options` -> `Job`;
4. `run`: the scheduler (`qemjax._schedulers`; its `Outcome`), with ESQEM's split planned first;
5. `finish`: the `SimplifyResult`: output in mesh units, splitting, re-fit, stop reason and warning,
   history, record and stats.

`qemjax._pipeline.api` drives them for one run (`simplify`) and for many (`simplify_cells`).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import os
import time
import warnings
from typing import Any, NamedTuple

import numpy as np

from .._kernels import compilation as _compilation
from .. import _costs
from . import flat as _flat
from . import locks as _locks
from .._io import mesh as _io
from . import measure as _measure
from . import refit as _refit
from .. import _schedulers
from . import split as _split
from .._mesh import topology as topo
from .._mesh import units as _units
from .._mesh import wedges as _wedges
from .._mesh.arrays import face_normals, release_free_memory
from .._options import Attributes, Options, Schedule, Topology
from .._record.history import Record, removals
from .._record.result import Contractions, SimplifyResult
from .._kernels.batching import DTYPE
from .._schedulers import outcome

_REFIT_ALONE = 1 << 17  # input faces from which a re-fit runs by itself (its nearest search is threaded)
LARGE_RUN = 1 << 20  # inputs of this many faces hand freed heap pages back between stages (`finish`)


def _real(name: str, x) -> float:
    """x as a float; ValueError naming the option unless x is a real number (bools are refused)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (numbers.Real, np.floating, np.integer)):
        raise ValueError(f"{name} must be a number, got {x!r}")
    return float(x)


def _flag(name: str, x) -> bool:
    """x as a bool; ValueError naming the option unless x is True or False."""
    if not isinstance(x, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {x!r}")
    return bool(x)


def _resolve_target(m: int, target_faces, ratio, max_error, bounded: bool = False) -> tuple[int, float]:
    """(face target, max error) from the user's options; face target 0 means 'none'. ``bounded``: a
    ``max_distance`` is given, a target of its own (`bound`)."""
    given = [x is not None for x in (target_faces, ratio)]
    if sum(given) > 1:
        raise ValueError("give at most one of target_faces and ratio")
    if not any(given) and max_error is None and not bounded:
        raise ValueError("give a target: target_faces=, ratio=, max_error=, max_distance= or max_distance_rel=")
    err = math.inf
    if max_error is not None:
        err = _real("max_error", max_error)
        if not err >= 0:
            raise ValueError(f"max_error must be a non-negative squared distance, got {max_error}")
    target = 0
    if target_faces is not None:
        t = _real("target_faces", target_faces)
        if not (math.isfinite(t) and t == int(t)):
            raise ValueError(f"target_faces must be an integer, got {target_faces!r}")
        target = int(t)
        if target <= 0:
            raise ValueError(f"target_faces must be at least 1, got {target}")
    if ratio is not None:
        r = _real("ratio", ratio)
        if not 0 < r <= 1:
            raise ValueError(f"ratio must be in (0, 1] (the fraction of faces to keep), got {ratio}")
        target = max(1, int(round(r * m)))
    return target, err


# a setting only a partitioned run's tasks pass (`_partition.carry`): a callable, (the Job without its vertex
# state, the MeshInput the model would start from) -> the vertex state the run starts from in place of the
# model's own (the quadrics carried from the level before); the model's own is not built beside it
SEED = "_seed"
# a setting only a partitioned run's last level passes (`_partition.task`): the surface the re-fit, its polish
# and sliver moves fit the output to in place of the run's own input (which is the levels' output there), as
# (V, F) or as a `refit.InputSide` (made on a thread beside the rounds)
REFIT_TO = "_refit_to"


@dataclasses.dataclass(frozen=True)
class Setup:
    """A run's settings, checked and resolved before the mesh is read (`setup`): the method object and
    its name as shown (`_costs.shown_name`: ``"default"`` when the call named none), the scheduler and its
    `Schedule`, the model it prices with (`_costs.build`), `Topology`, `Attributes` (with the checked weights
    per kind) and whether to show progress."""

    method_obj: Any
    method: str
    scheduler: str
    schedule: Schedule
    model: Any
    topology: Topology
    attribute_options: Attributes
    kind_weights: Any
    progress: bool
    measure: bool | None = None  # measure the output's distance from the input (`measure`); None: with a re-fit
    late_asked: bool = False  # the call set late_memoryless itself (then a run that cannot apply it warns)
    shape_asked: bool = False  # the call set quality_threshold itself (likewise)

    cos_max = property(lambda self: self.topology.cos_max)
    min_quality = property(lambda self: self.topology.min_quality)
    pair_threshold = property(lambda self: float(self.topology.pair_threshold))
    preserve_topology = property(lambda self: self.topology.manifold)
    weld = property(lambda self: self.topology.weld)
    prune = property(lambda self: self.topology.prune)
    attributes = property(lambda self: self.attribute_options.attributes)
    texture = property(lambda self: self.attribute_options.texture)
    refit = property(lambda self: int(self.method_obj.refit))
    polish = property(lambda self: int(self.method_obj.polish))
    sliver_moves = property(lambda self: int(self.method_obj.sliver_moves))

    @property
    def measures(self) -> bool:
        """Whether the run measures its distance from the input: ``measure``, or (None) when it re-fits."""
        return self.refit > 0 if self.measure is None else self.measure

    @property
    def split(self):
        return getattr(self.model, "split_factor", None)  # None: the method does not split

    @property
    def keeps_attributes(self) -> bool:
        """Whether the run's method carries appearance attributes (QEM, without splits or memoryless
        quadrics); another drops them (`job`: one warning)."""
        return (_costs.name_of(self.method_obj) == "qem" and self.split is None
                and not getattr(self.model, "memoryless", False))


class Geometry(NamedTuple):
    """The cleaned mesh and what depends on it alone (shared by every run of one mesh with the same
    ``weld``, ``pair_threshold``, ``attributes`` and ``texture``): V (n,3) float64, F (m,3), the clean-up
    report (without ``face_means`` and ``attributes``), the face means, close pairs, parts, normalised
    positions and their frame, the edge table (E, ecount, boundary edges, their faces), the count of
    non-manifold edges and the kept attributes (`_wedges`, or None)."""

    V: np.ndarray
    F: np.ndarray
    report: dict
    face_means: tuple
    extra: np.ndarray
    parts: tuple
    Vn: np.ndarray
    frame: _units.Frame
    edges: tuple
    nonmanifold: int
    attrs: Any = None
    vertex_map: Any = None  # (given vertices,) int64: each given vertex's index here (-1: dropped)
    source: Any = None  # the file read (a path), or None: `_locks.given_map` numbers an OBJ's vertices as it does
    given: Any = None  # `_locks.given_map`'s own dict: an OBJ's numbering, read from the file once for all runs


class Job(NamedTuple):
    """One run, ready: its `Setup` and `Geometry`, the face target and max error, the model's vertex
    state S and the scheduler's `Options`; the model (the setup's, or the attribute model), the report
    (the geometry's, plus what this run drops), the attributes it keeps and their seam `Tracker`."""

    setup: Setup
    geo: Geometry
    target: int
    err: float
    S: np.ndarray
    options: Options
    model: Any
    report: dict
    attrs: Any = None
    tracker: Any = None
    locks: Any = None  # `_locks.Locks` (geo is then the run's renumbered geometry), or None
    refit_to: Any = None  # the surface the re-fit fits the output to instead of geo's (`REFIT_TO`): (V, F) or
    # a `refit.InputSide`; or None
    side: Any = None  # geo's own `refit.InputSide`, made on a thread beside the rounds (`beside_rounds`), or None


def setup(method, scheduler, topology, attributes, progress, settings: dict, measure=None) -> Setup:
    """Check every setting that does not need the mesh (`_flat.apply` folds settings given by name into
    the objects); ValueError naming the bad one, TypeError for an unknown name."""
    settings = dict(settings)
    sched_name, schedule = _flat.scheduler_of(scheduler, settings.pop("schedule", None))
    named = settings.get("preset") or method  # what the call named ("default" when it named none)
    method_obj, topology, attrs = _flat.apply(method, topology, attributes, settings)
    model = _costs.build(method_obj)
    kind_weights = _wedges.check_weights(attrs.attribute_weights)
    return Setup(method_obj, _costs.shown_name(method_obj, named), sched_name, schedule, model, topology, attrs,
                 kind_weights, _flag("progress", progress), None if measure is None else _flag("measure", measure),
                 *(name in settings or (not isinstance(method, str) and bool(getattr(method_obj, name, 0)))
                   for name in ("late_memoryless", "quality_threshold")))


def geometry(mesh, setup: Setup, stacklevel: int) -> Geometry:
    """Read and clean ``mesh`` and compute what depends on the mesh alone (`Geometry`)."""
    (V, F), report = _io.prepare(mesh, weld_vertices=setup.weld, stacklevel=stacklevel,
                                 attributes=setup.attributes, texture=setup.texture, keeps=setup.keeps_attributes)
    face_means = report.pop("face_means")
    attrs = report.pop("attributes")
    vertex_map = report.pop("vertex_map")
    extra = topo.close_pairs(V, F, setup.pair_threshold)
    parts = topo.parts(F, len(V), extra)
    Vn, frame = _units.normalize(V, DTYPE, parts)
    E, ecount, be, bf = topo.edge_table(F, len(V))  # one sort for the boundary and the first edges
    if len(V) < 2**31:  # held for the whole call (and a batch's): half the memory, as the scheduler uses it
        E, ecount = E.astype(np.int32), ecount.astype(np.int32)
    nonmanifold = int(np.count_nonzero(ecount > 2))  # edges of three or more faces in the input
    return Geometry(V, F, report, face_means, extra, parts, Vn, frame, (E, ecount, be, bf), nonmanifold, attrs,
                    vertex_map, os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else None, {})


def job(setup: Setup, geo: Geometry, feature_edges, target_faces, ratio, max_error, stacklevel: int,
         states: dict | None = None, locks: tuple = (None, None), bounded: bool = False, seed=None,
         refit_to=None) -> Job:
    """The face target, the model's initial vertex state and the scheduler's options for one run.
    ``states``: a cache of vertex states by (geometry, model `state_key`, feature edges), for a batch.
    ``locks``: the user's (locked, vertex_weights) (`_locks`); with any, the run works on the geometry
    renumbered with the locked vertices first (`_locks.Locks.geometry`). ``seed``: `SEED`'s callable, the
    state's maker in place of the model's own; ``refit_to``: `REFIT_TO`'s surface."""
    lock_stats = {}  # also when every locked vertex is unreferenced (the run is then without locks)
    lk = _locks.resolve(*locks, geo, stacklevel=stacklevel + 1, stats=lock_stats)
    if lk is not None and not _takes_locks(setup.scheduler):  # before it runs, in the call's words
        raise ValueError(f"scheduler={setup.scheduler!r} takes no locks (its run has no locks= keyword), so "
                         "locked= and vertex_weights= cannot run on it: use scheduler='parallel' or 'greedy', "
                         "or give its run a locks= keyword (docs/design.md, 'The scheduler contract')")
    if lk is not None:  # a numbering of its own: no vertex state shared with a batch's other runs
        geo, states = lk.geometry(), None
    model, report, attrs = setup.model, dict(geo.report), geo.attrs
    memoryless = getattr(model, "memoryless", False)
    if attrs is not None and not setup.keeps_attributes:
        warn = list(attrs.values) + (["material"] if attrs.material is not None else [])
        what = "memoryless=True" if memoryless else f"method={setup.method!r}"
        _wedges.warn_unsupported(warn, what, stacklevel=stacklevel)
        # named in stats["dropped"] as the cleaning names what it drops ("vertex_colors", "normals")
        report["dropped"] = report["dropped"] + [_wedges.DROPPED_NAME.get(k, k) for k in warn]
        attrs = None
    method_obj = setup.method_obj
    feature_edges = _io.check_feature_edges(feature_edges, len(geo.V))
    off = _late_off(method_obj, attrs, feature_edges, setup.scheduler,
                    target_faces is not None or ratio is not None or bounded)
    if off:  # the whole run on the summed quadrics, and the stats say so
        why, said = off
        method_obj = dataclasses.replace(method_obj, late_memoryless=0.0, volume_weight=0.0)
        model = _costs.build(method_obj)
        report["late_memoryless_off"] = why
        if setup.late_asked:
            warnings.warn(f"late_memoryless is not applied: {why}; the run uses the summed quadrics throughout",
                          stacklevel=stacklevel)
        elif said and (not bounded or why == FEATURES_GIVEN):  # a setting or an input alone changes the
            # default's geometry: said, not silent. A bounded run says it in the stats alone (it refuses kept
            # attributes, `bound.supported`, and returns the level its distance picks), feature edges aside
            warnings.warn(said, stacklevel=stacklevel)
    corner_values = channel_weights = None
    if attrs is not None:
        channel_weights = _wedges.channel_weights(attrs, setup.kind_weights)
        if np.any(channel_weights > 0):  # the cost model over positions and attributes (`_costs.attributes`)
            model = _costs.build(method_obj, weights=np.maximum(channel_weights, 1e-30))
            corner_values = attrs.matrix()[attrs.corners] * (channel_weights > 0)
    if lk is not None and feature_edges is not None:
        feature_edges = lk.feature_edges(feature_edges)
    if attrs is not None and attrs.has_seams():  # seams are constrained like boundaries: feature-edge planes
        seams = _wedges.seam_edges(geo.F, attrs.corners)
        if len(seams):
            feature_edges = seams if feature_edges is None else np.concatenate([feature_edges, seams])
        report.update(seams_in=_wedges.seam_count(seams), seam_edges_in=len(seams))
    elif attrs is not None:
        report.update(seams_in=0, seam_edges_in=0)
    m = len(geo.F)
    target, err = _resolve_target(m, target_faces, ratio, max_error, bounded)
    if target > m:
        warnings.warn(f"target of {target} faces is not below the mesh's {m} faces: returning it unchanged",
                      stacklevel=stacklevel)
        target = m
    E, ecount, be, bf = geo.edges
    start = _costs.MeshInput(geo.Vn, geo.F, (be, bf), feature_edges, frame_means(geo), corner_values)
    key = None if states is None or attrs is not None or seed is not None else (
        id(geo), model.state_key(), None if feature_edges is None else feature_edges.tobytes())
    S = None if key is None else states.get(key)
    if S is None and seed is None:
        S = model.init_state(start)
        if key is not None:
            states[key] = S
    shape = float(np.float32(getattr(method_obj, "quality_threshold", 0.0)))  # as the rounds compare it
    if shape and setup.scheduler != "parallel":  # said, not silently dropped
        why = ("the greedy queue ranks by cost alone" if setup.scheduler == "greedy" else
               f"the scheduler {setup.scheduler!r} is not the parallel one, whose rounds it ranks")
        report["quality_threshold_off"] = why
        if setup.shape_asked:
            warnings.warn(f"quality_threshold is not applied: {why}", stacklevel=stacklevel)
        shape = 0.0
    options = Options(cos_max=setup.cos_max, preserve_topology=setup.preserve_topology,
                      max_cost=geo.frame.error_to_internal(err), schedule=setup.schedule,
                      keep_parts=not setup.prune, min_quality=setup.min_quality, quality_threshold=shape)
    tracker = None if attrs is None else _wedges.Tracker(attrs.corners, attrs.matrix(), len(geo.V), geo.F, model,
                                                         None if corner_values is None else channel_weights > 0,
                                                         None if lk is None else lk.run().locked)
    report.update(lock_stats)
    job = Job(setup, geo, target, err, S, options, model, report, attrs, tracker, lk, refit_to)
    return job if seed is None else job._replace(S=seed(job, start))


def frame_means(geo: Geometry) -> tuple:
    """(mean face area, mean squared edge length) of the cleaned mesh in the run's frame (what the models
    scale their weights by: `_costs.MeshInput`)."""
    area_mean, e2_mean, ext = geo.face_means
    r2 = (ext / geo.frame.scale) ** 2  # from the clean-up's unit extent to the frame's
    return area_mean * r2, e2_mean * r2


ATTRIBUTES_KEPT = "attributes are kept (the memoryless quadrics have no attribute terms)"  # `_late_off` reasons
FEATURES_GIVEN = "feature edges are given (the memoryless quadrics do not track them)"  # that come with the input
STRETCH_OFF = "turns off the default method's memoryless last stretch"  # in the warning `job` gives for it
LESS_ACCURATE = "the geometry may be less accurate than with"  # that warning's way back to the default's


def _late_off(method_obj, attrs, feature_edges, scheduler: str, face_target: bool) -> tuple | None:
    """Why a method that turns memoryless late (`_schedulers.late`) stays summed in this run, and the
    warning that says so to a call that did not set ``late_memoryless`` itself (what the call set or gave,
    `STRETCH_OFF`, why, and how to get the default's geometry back; None: no warning); None when it switches.
    ``face_target``: the run has one (a ratio, target_faces, or max_distance's targets)."""
    if not getattr(method_obj, "switches_late", False):
        return None

    def said(what: str, why: str, back: str) -> str:
        return f"{what} {STRETCH_OFF} (late_memoryless: {why}): {back}"

    if not face_target:
        return "there is no face target (max_error alone), and the switch comes at a multiple of it", None
    if scheduler not in _schedulers.BUILT_IN:
        built_in = " or ".join(map(repr, _schedulers.BUILT_IN))
        return (f"the scheduler {scheduler!r} is not a built-in one (the switch runs the scheduler a second time)",
                said(f"scheduler={scheduler!r}", "it runs a built-in scheduler a second time",
                     f"the default's geometry needs scheduler={built_in}"))
    term = "regularize" if method_obj.regularize else "area_weight" if method_obj.area_weight else None
    if term:  # (the two are never set together: `_costs.area_term`)
        return (f"{term} is set (its term prices the summed quadrics' placement)",
                said(f"setting {term}", "its term prices the summed quadrics' placement",
                     f"{LESS_ACCURATE} {term}=0 (CLI: --{term.replace('_', '-')} 0)"))
    if attrs is not None:
        return ATTRIBUTES_KEPT, said(f"keeping {', '.join(attrs.values)}", "it does not carry attributes",
                                     f"{LESS_ACCURATE} attributes=None (CLI: --attributes none)")
    if feature_edges is not None and len(feature_edges):
        return FEATURES_GIVEN, said("giving feature edges", "it does not track them",
                                    "the run stays on the summed quadrics throughout")
    return None


def _takes_locks(name: str) -> bool:
    """Whether the scheduler ``name`` takes the run's locks (a ``locks=`` keyword, or ``**kwargs``): the
    built-in ones do; one registered from outside may keep the contract without them."""
    import inspect

    if name in _schedulers.BUILT_IN:
        return True
    try:
        params = inspect.signature(_schedulers.get(name)).parameters.values()
    except (TypeError, ValueError):  # no signature to read: let the call say what it takes
        return True
    return any(p.name == "locks" or p.kind is p.VAR_KEYWORD for p in params)


def beside_rounds(job: Job) -> Job:
    """``job`` with what its re-fit makes of the input alone (`refit.InputSide`: the samples, and for the
    moves after the fit their search structure) made on a thread of its own from now on, for a run that
    re-fits to its own input: its rounds keep one core busy and seldom two, so the re-fit finds them made.
    The same values as made by the re-fit. Not for a batch (its runs share one side, `refit_all`), a run
    with locks (its re-fit sees the input in the user's numbering, `_locks.back`), nor an input of
    `LARGE_RUN` faces or more (its rounds' stages take the cores, and the samples would be held beside the
    rounds' arrays)."""
    setup, g = job.setup, job.geo
    if not (setup.refit and job.refit_to is None and job.locks is None and job.target < len(g.F) < LARGE_RUN):
        return job
    side = _refit.InputSide(lambda: (g.V, g.F), part=g.parts[1], moves=bool(setup.polish or setup.sliver_moves),
                            thread=True)
    return job._replace(side=side)


def unchanged(job: Job):
    """A run's outputs when there is nothing to remove (`run`'s form)."""
    g = job.geo
    return outcome.Outcome.unchanged(g.Vn, job.S, g.F, len(job.model.branches)), None, None


def faces_to_remove(m: int, target: int, closed: bool) -> int:
    """The faces a run from ``m`` faces down to ``target`` removes, its progress bar's total: a closed
    manifold loses faces in pairs, so it stops one above an odd target (`outcome.parity_only`)."""
    n = m - max(target, 1)
    return n - n % 2 if closed else n


def run(job: Job):
    """Run the scheduler. Returns (its `outcome.Outcome`, the face target the run aimed at, the faces
    splitting was planned to add (None without splitting))."""
    setup, g, model, options, target = job.setup, job.geo, job.model, job.options, job.target
    m = len(g.F)
    if not (target < m or job.err < math.inf):
        return unchanged(job)
    bar, progress_cb = None, None
    closed = len(g.edges[2]) == 0 and g.nonmanifold == 0
    if setup.progress:
        from tqdm.auto import tqdm

        splits = setup.split is not None and target
        bar = tqdm(total=faces_to_remove(m, target, closed), unit="face",
                   desc="simplify (planning the splits)" if splits else "simplify")
        last = m

        def progress_cb(faces_now):
            nonlocal last
            bar.update(last - faces_now)
            last = faces_now
    run_target, planned = target, None
    try:  # from the bar's first line on: an interrupt anywhere below still ends its line
        scheduler = _schedulers.get(setup.scheduler)
        if getattr(model, "switches_late", False):  # two phases
            from .._schedulers import late

            scheduler = functools.partial(late.run, scheduler)
        lock_settings = _locks.scheduler_settings(job.locks)
        run = functools.partial(scheduler, edges=g.edges[:2], part_scale=g.frame.part_scale2(), wedges=job.tracker,
                                **lock_settings)
        if setup.split is not None and target:  # simplify further by what splitting will add (`_split.plan`)
            fixed = lock_settings["locks"].locked if lock_settings else None

            def new_bar(lower):  # the run itself goes past the target, by the faces splitting adds back
                nonlocal last
                if bar is not None:
                    last = m
                    bar.reset(total=faces_to_remove(m, lower, closed))
                    bar.set_description("simplify")

            out, run_target, planned, first = _split.plan(run, (g.Vn, job.S, g.F, g.extra), target, model, options,
                                                          setup.split, progress_cb, fixed, setup.min_quality, new_bar)
        else:
            out = run(g.Vn, job.S, g.F, g.extra, max(run_target, 1), model, options, progress_cb)
        if planned is not None and not _split.fills(out, target, setup.split, fixed, setup.min_quality):
            out, run_target = first, target  # blocked where splitting cannot refill: the run to the target
        if bar is not None and bar.n != bar.total and (out.stop_reason == "target" or (
                out.stop_reason == "max_error" and not target)):
            # its goal reached (a face target, or the error bound alone, whose faces no count foresees):
            # the bar ends full; one that stopped short of its target stays short, as the run did
            bar.total = bar.n
            bar.refresh()
    finally:  # an interrupted run also ends its bar's line
        if bar is not None:
            bar.close()
    return out, run_target, planned


def finish(job: Job, ran, t_start: float, c0, s0, stacklevel: int, batch: dict | None = None,
           later: list | None = None) -> SimplifyResult:
    """The `SimplifyResult` of a run: compact output in mesh units, splitting, re-fit, the stop reason (and
    a warning when it ends above the target), history, record and stats. ``batch``: for a run that went
    through `simplify_batch`, what stats say of the batch. ``later``: a list to which the re-fit is
    appended as ``(result, RefitTask)`` instead of running here (the result then holds the contractions'
    positions until `refit_all` runs the list: a batch's re-fits run side by side).

    The steps, in order: the outcome in the cleaned input's numbering (`_locks.back`), the output mesh
    (`_output`), its attributes (`_appearance`), splitting (`_split_faces`), the re-fit and the measured
    distance (`_refit_and_measure`), the stop reason (`_stop_reason`), the history (`_history`) and the stats
    (`_stats`)."""
    out, run_target, planned = ran
    run_target = job.target if run_target is None else run_target
    if len(job.geo.F) >= LARGE_RUN:  # the rounds' freed arrays, back to the system before the re-fit's
        release_free_memory()
    out, g, locked = _locks.back(job.locks, out, job.geo)
    if out.removed_at is None and out.contractions:  # a scheduler that does not say which contraction removed
        # each face (the contract lets it): found from its contractions, so that its record replays its output
        removed_at, coincident = removals(g.F, out.history.pairs, out.alive)
        out = dataclasses.replace(out, removed_at=removed_at, coincident=coincident)
    mesh = _output(out, g, job.model, locked)
    appearance = _appearance(job, mesh)
    split_stats = None
    if job.setup.split is not None:
        mesh, out, split_stats = _split_faces(job, out, mesh, run_target, planned)
    mesh, refit = _refit_and_measure(job, g, mesh, appearance, later)
    stop = _stop_reason(job, out, mesh, g.nonmanifold, stacklevel + 1)
    history = _history(out, g, job.model, locked)
    stats = _stats(job, out, g, mesh, refit, _times(t_start, c0, s0), dict(split=split_stats, batch=batch))
    m = len(g.F)
    record = Record(g.V, g.F, history, np.full(m, -1, np.int64) if out.removed_at is None else out.removed_at,
                    np.zeros(m, bool) if out.coincident is None else out.coincident, g.frame, job.setup.scheduler,
                    run_target, locked=locked)
    res = SimplifyResult(
        vertices=mesh.vertices, faces=mesh.faces.astype(np.int64), vertex_error=mesh.vertex_error,
        max_error=float(g.frame.errors_to_mesh(out.worst_cost)),
        source_vertices=mesh.source_vertices.astype(np.int64), source_faces=mesh.source_faces.astype(np.int64),
        input_vertices=g.V, input_faces=g.F, history=history, stats=stats, stop_reason=stop, record=record,
        **appearance)
    if later is not None and refit.task is not None:
        later.append((res, refit.task))
    return res


class _Mesh(NamedTuple):
    """The output while `finish` builds it: positions (k,3) float64 in mesh units, faces (f,3), each vertex's
    and face's source in the cleaned input, each vertex's error (mesh units²) and the vertices that keep
    their input position exactly (locked ones; None: no locks)."""

    vertices: np.ndarray
    faces: np.ndarray
    source_vertices: np.ndarray
    source_faces: np.ndarray
    vertex_error: np.ndarray
    fixed: np.ndarray | None


def _output(out: outcome.Outcome, g: Geometry, model, locked) -> _Mesh:
    """The run's surviving mesh (`Outcome.output`) in mesh units. A vertex never contracted keeps the
    input's float64 position exactly, a locked one always (`_locks.keep_exact`)."""
    o, frame = out.output(), g.frame
    ids = o.source_vertices
    vout = frame.positions_to_mesh(o.positions, ids)
    unmoved = np.ones(len(g.V), bool)
    unmoved[out.history.pairs[:, 0]] = False  # kept vertices moved; removed ones are gone
    same = np.flatnonzero(unmoved[ids])
    vout[same] = g.V[ids[same]]
    flat = np.flatnonzero(~np.any(face_normals(vout, o.faces) != 0, axis=1))
    if flat.size:  # an input face with exactly collinear corners: keep the rounded positions there
        w = np.unique(o.faces[flat])
        vout[w] = frame.positions_to_mesh(o.positions[w], ids[w])
    fixed = _locks.keep_exact(locked, vout, ids, g.V)
    verr = frame.errors_to_mesh(model.vertex_error(out.states[ids]))
    return _Mesh(vout, o.faces, ids, o.source_faces, verr, fixed)


def _appearance(job: Job, mesh: _Mesh) -> dict:
    """The kept attributes on the output (the `SimplifyResult`'s uv, colors, normals and wedges), or {}."""
    if job.tracker is None:
        return {}
    attrs = job.attrs
    wf, wv, wval = _wedges.output(job.tracker.C, job.tracker.val, mesh.faces, mesh.source_faces,
                                  mesh.source_vertices)
    vals = attrs.split(wval)
    if "normal" in vals:
        nn = np.linalg.norm(vals["normal"], axis=1, keepdims=True)
        vals["normal"] = vals["normal"] / np.where(nn > 0, nn, 1.0)
    if "color" in vals:  # a quadric's optimum may lie just outside the colour cube, as a position outside its ring
        vals["color"] = np.clip(vals["color"], 0.0, 1.0)
    return dict(uv=vals.get("uv"), colors=vals.get("color"), normals=vals.get("normal"), wedge_faces=wf,
                wedge_vertex=wv, material=attrs.material, input_wedge_faces=attrs.corners)


def _split_faces(job: Job, out: outcome.Outcome, mesh: _Mesh, run_target: int, planned):
    """The output split (`_split.apply`): (the mesh, the outcome, the split's stats). Splitting that reached
    the target the contractions could not makes the run's stop reason ``"target"``; short of it (edges
    between locked vertices are not split), the run's own reason stays, and `_stop_reason` warns."""
    target = job.target
    fixed = mesh.fixed
    vout, Fout, ids, fids, verr, stats = _split.apply(mesh.vertices, mesh.faces, mesh.source_vertices,
                                                      mesh.source_faces, mesh.vertex_error, job.setup.split, target,
                                                      fixed, job.setup.min_quality)
    if fixed is not None:  # the midpoints it adds are free
        fixed = np.concatenate([fixed, np.zeros(len(vout) - len(fixed), bool)])
    stats.update(planned=planned, run_target=run_target if target else None, run_stop_reason=out.stop_reason)
    if target and abs(len(Fout) - target) <= 1 and out.stop_reason == "blocked":  # one off: the splits' parity
        out = dataclasses.replace(out, stop_reason="target")
    return _Mesh(vout, Fout, ids, fids, verr, fixed), out, stats


class _Refit(NamedTuple):
    """What `_refit_and_measure` did: its rounds (0: none), its seconds, the measured distance's stats and the
    `RefitTask` (None: nothing to re-fit or measure)."""

    rounds: int
    seconds: float
    distance: dict
    task: Any


def _refit_and_measure(job: Job, g: Geometry, mesh: _Mesh, appearance: dict, later: list | None) -> tuple[_Mesh, _Refit]:
    """The re-fit of the output's positions and the measure of its distance from the input (`RefitTask`):
    run here, or left to ``later`` (`finish`). Locked vertices, and with attributes the seam vertices, keep
    their positions."""
    setup = job.setup
    rounds, seconds, task = setup.refit, 0.0, None
    refits = bool(rounds and len(mesh.faces) < len(g.F))
    distance = _measure.not_measured()
    if refits or setup.measures:
        held, wedges = mesh.fixed, None
        if refits and appearance:  # seam vertices (two or more wedges) stay on the input's seams
            seam = np.bincount(appearance["wedge_vertex"], minlength=len(mesh.vertices)) > 1
            held = seam if held is None else (held | seam)
            if appearance.get("uv") is not None:  # the UVs follow the moves (`refit.carry_uv`)
                wedges = (appearance["wedge_faces"], appearance["wedge_vertex"], appearance["uv"])
        # the surface fitted to: the run's input, its parts and the input face each output face continues;
        # or another one (`REFIT_TO`), whole
        side = job.refit_to if isinstance(job.refit_to, _refit.InputSide) else None
        if job.refit_to is None:
            V, F, part, source, side = g.V, g.F, g.parts[1], mesh.source_faces, job.side
        else:
            V, F = job.refit_to if side is None else side.get()[:2]
            part = source = None
        task = RefitTask(V, F, mesh.vertices, mesh.faces, rounds if refits else 0, setup.cos_max, part, source,
                         held, setup.measures, setup.min_quality, wedges, setup.polish, setup.sliver_moves, side)
        if later is None:
            vout, seconds, distance, uv = task()
            mesh = mesh._replace(vertices=vout)
            if uv is not None:
                appearance["uv"] = uv
    return mesh, _Refit(rounds, seconds, distance, task)


def _stop_reason(job: Job, out: outcome.Outcome, mesh: _Mesh, nonmanifold: int, stacklevel: int) -> str:
    """The result's stop reason: the run's, or where the output ends above the face target asked for,
    `Outcome.stop_above`'s, with a warning that says why (none for the parity case, whose reason is
    ``"target"``; ``stacklevel`` as this function's caller sees it)."""
    target, faces = job.target, len(mesh.faces)
    if target and faces < target - 1 and job.setup.split is not None:  # the splits could not add faces back
        warnings.warn(f"ESQEM's edge splits ended at {faces} faces, below the target of {target}: the "
                      f"contractions stopped there ({out.stop_reason}), and the edges left join locked "
                      "vertices, which are not split", stacklevel=stacklevel)
    if not (target and faces > target):
        return out.stop_reason
    closed = len(topo.boundary_edges(mesh.faces, len(mesh.vertices))[0]) == 0
    stop = out.stop_above(faces, target, closed)
    if stop != "target":
        warnings.warn(_above_target_message(faces, target, stop, out.blocked_by, nonmanifold,
                                            job.setup.preserve_topology), stacklevel=stacklevel)
    return stop


def _history(out: outcome.Outcome, g: Geometry, model, locked) -> Contractions:
    """The contractions in mesh units (a contraction onto a locked vertex: its input position, exactly), with
    their cost parts where the model gives the parts' units."""
    h, frame = out.history, g.frame
    hx = frame.positions_to_mesh(h.positions, h.pairs[:, 0])
    _locks.keep_exact(locked, hx, h.pairs[:, 0], g.V)
    hparts = {}
    if out.parts is not None and len(model.part_units) == len(model.parts):
        for name, unit, col in zip(model.parts + ("rank",), model.part_units + (2,), out.parts.T):
            hparts[name] = np.asarray(col, np.float64) * frame.scale ** unit
    return Contractions(h.pairs, hx, frame.errors_to_mesh(h.costs), hparts,
                        np.zeros(0, np.int64) if out.history_rounds is None else out.history_rounds)


def _times(t_start: float, c0, s0) -> dict:
    """The run's compilations and seconds since ``t_start`` (compiling, running, in all), for its stats."""
    c1, s1 = _compilation.snapshot()
    total = time.perf_counter() - t_start
    return dict(compilations=c1 - c0, compile_s=min(s1 - s0, total), run_s=max(total - (s1 - s0), 0.0),
                total_s=total)


def _stats(job: Job, out: outcome.Outcome, g: Geometry, mesh: _Mesh, refit: _Refit, times: dict,
           extra: dict) -> dict:
    """The result's stats (`SimplifyResult`): the clean-up's report, the run's counts, sizes, times and
    settings; ``extra``'s entries where they are not None."""
    setup, model, frame, err = job.setup, job.model, g.frame, job.err
    stats = dict(job.report)
    stats.update(
        method=setup.method, scheduler=setup.scheduler, faces_in=len(g.F), faces_out=len(mesh.faces),
        target_faces=job.target, vertices_in=len(g.V), vertices_out=len(mesh.vertices), close_pairs=len(g.extra),
        **out.counts(model.branches), model=model.describe(), **times, scale=frame.scale, parts_in=g.parts[0],
        non_manifold_edges_in=g.nonmanifold, max_error_limit=err if math.isfinite(err) else None,
        refit=refit.rounds, refit_s=refit.seconds, error_unit=model.error_unit, **refit.distance)
    if job.tracker is not None:
        stats.update(attributes=list(job.attrs.values), seam_vertices_in=job.tracker.seam_in)
    stats.update(out.stage_times)
    if getattr(model, "switches_late", False):  # the faces left when the run turned memoryless (None: it did not)
        stats["memoryless_from_faces"] = out.switched_at
    if out.faces_per_round is not None:
        stats["faces_per_round"] = out.faces_per_round
    if out.reweights:  # (faces, weights of the parts in mesh units) each time they were set
        stats["reweights"] = [(f, [_times_power(x, frame.scale, 2 - u) for x, u in zip(w, model.part_units)])
                              for f, w in out.reweights]
    stats.update({k: v for k, v in extra.items() if v is not None})
    return stats


def _times_power(x: float, base: float, power: int) -> float:
    """x × base**power as a float: inf where it lies past float64's range (a power that overflows raises in
    Python, where the product would give inf), 0 for x = 0."""
    try:
        factor = base ** power
    except OverflowError:
        factor = math.inf
    return float(x) * factor if x else 0.0


class RefitTask(NamedTuple):
    """One result's re-fit (`_pipeline.refit.refit`'s arguments); calling it returns (positions, seconds)."""
    V: np.ndarray
    F: np.ndarray
    X: np.ndarray
    G: np.ndarray
    rounds: int
    cos_max: float
    part: np.ndarray
    source_faces: np.ndarray
    fixed: np.ndarray | None
    measure: bool = False  # then measure the output's distance from the input (`_pipeline.measure`)
    min_quality: float = 0.0  # the quality guard (`Topology.min_angle`)
    wedges: tuple | None = None  # kept UVs: (wedge_faces, wedge_vertex, uv), moved with the positions
    polish: int = 0  # moves of the minimax polish after the re-fit at most (`_pipeline.polish`)
    sliver_moves: int = 0  # moves of slivers' corners after the polish at most (`_pipeline.slivers`)
    side: Any = None  # V and F's `refit.InputSide`, made beforehand (None: `refit` makes what it needs)

    def __call__(self) -> tuple[np.ndarray, float, dict, np.ndarray | None]:
        """(positions, re-fit seconds, the distance stats: `measure.distance`, or all None, the UVs moved
        with the positions: `refit.carry_uv`, or None without ``wedges``)."""
        t = time.perf_counter()
        X, uv = self.X, None
        sampled = []  # the input's samples, made once for the re-fit and the measured distance
        report = {}  # the polish's and the sliver moves' counts
        if self.rounds:
            X = _refit.refit(self.V, self.F, self.X, self.G, self.rounds, self.cos_max, self.part,
                             self.source_faces, fixed=self.fixed, sampled=sampled if self.measure else None,
                             min_quality=self.min_quality, polish=self.polish,
                             sliver_moves=self.sliver_moves, report=report, side=self.side)
            if self.wedges is not None:
                uv = _refit.carry_uv(self.X, X, self.G, *self.wedges)
        refit_s = time.perf_counter() - t
        if not self.measure:
            return X, refit_s, _measure.not_measured() | report, uv
        return X, refit_s, _measure.distance(self.V, self.F, X, self.G, sampled[0] if sampled else None,
                                             sampled[1] if len(sampled) > 1 else None) | report, uv


def refit_all(later: list) -> None:
    """Run the re-fits `finish` left in ``later`` and put their positions and ``refit_s`` into their results.
    Each is independent of the others (the same arithmetic as alone, bit for bit), so they run side by side
    on threads (`_mesh.threads.each`: one per core up to four): their compiled nearest-face search,
    assembly (`refit_system`) and solver release the GIL, as numpy does (a batch of 64 cow re-fits: `experiments/figures/sweep_bench.py
    --grid distinct`). A
    re-fit of a large input (``_REFIT_ALONE`` faces or more) runs by itself: its nearest search already
    uses the cores, and side by side the large ones would hold their memory at once. Re-fits to the same
    input (a batch's cells of one mesh share its geometry) share what is made of the input alone
    (`refit.InputSide`: its samples and search structure, made once; the first to ask counts its seconds)."""
    from .._mesh import threads

    later = _shared_sides(later)

    def run(item):
        res, task = item
        res.vertices, res.stats["refit_s"], distance, uv = task()
        res.stats.update(distance)
        if uv is not None:
            res.uv = uv

    threads.each(run, [item for item in later if len(item[1].F) < _REFIT_ALONE])
    for item in later:
        if len(item[1].F) >= _REFIT_ALONE:
            run(item)


def _shared_sides(later: list) -> list:
    """``later``'s (result, `RefitTask`) items, those that re-fit to the same input (V, F and part labels, the
    same arrays) given one `refit.InputSide` between them."""
    groups: dict = {}
    for k, (_, task) in enumerate(later):
        if task.rounds and task.side is None:
            groups.setdefault((id(task.V), id(task.F), id(task.part)), []).append(k)
    out = list(later)
    for ks in groups.values():
        if len(ks) < 2:
            continue
        first = later[ks[0]][1]
        side = _refit.InputSide(lambda V=first.V, F=first.F: (V, F), part=first.part,
                                moves=any(later[k][1].polish or later[k][1].sliver_moves for k in ks))
        for k in ks:
            res, task = later[k]
            out[k] = (res, task._replace(side=side))
    return out


def _above_target_message(faces: int, target: int, stop: str, blocked: dict, nonmanifold: int,
                          manifold_mode: bool) -> str:
    held = ", ".join(f"{k}: {v}" for k, v in blocked.items() if v) or "no pairs left"
    why = {"max_error": "the remaining contractions cost more than max_error",
           "blocked": "no valid contraction is left",
           "locked": "the locked vertices hold back the contractions left"}.get(stop, stop)
    hint = ""
    if manifold_mode and stop == "blocked":
        if nonmanifold:
            hint = (f"; the input has {nonmanifold} non-manifold edges (3 or more faces), which manifold mode "
                    "never contracts: preserve_topology=False may reach the target")
        elif blocked.get("vanishing_part"):
            hint = "; separate parts keep their last faces: prune=True lets small parts vanish"
        elif blocked.get("topology") or blocked.get("coincident"):  # the rules that mode lifts, and only those
            hint = "; preserve_topology=False may reach further (genus and boundaries may then change)"
    if blocked.get("locked"):
        hint += ("; locked vertices hold pairs back (pairs of two locked vertices never contract): lock fewer "
                 "vertices to reach further")
    if blocked.get("seam"):
        hint += ("; UV seams / colour discontinuities are kept where they are and hold pairs back: "
                 "attributes=None (positions only) may reach further")
    return f"stopped at {faces} faces, above the target of {target}: {why} (pairs held back by {held}){hint}"
