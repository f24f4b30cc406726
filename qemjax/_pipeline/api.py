"""`simplify`: the one entry point, and `simplify_cells` / `simplify_batch` for many runs: they drive the
stages of a run (`stages`: setup, geometry, job, run, finish), batching the runs that can share rounds."""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import inspect
import math
import os
import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import _costs
from . import bound as _bound
from . import fits as _fits
from . import locks as _locks
from .._options import Topology
from .._record.result import SimplifyResult

if TYPE_CHECKING:  # annotations only: stages is imported where a run needs it (importing qemjax stays light)
    from .stages import Job

PLACEMENTS = _costs.qem.PLACEMENTS
# a setting only qemjax's own callers of `simplify` pass (`lod_chain`): how many of their frames stand between
# the user's call and simplify, so that the run's warnings point at the user's line
CALLER = "_caller_frames"


def methods() -> tuple[str, ...]:
    """The cost models `simplify(method=...)` accepts (the registry in ``qemjax._costs``)."""
    return _costs.methods()


def simplify(mesh: Any, *, target_faces: int | None = None, ratio: float | None = None,
             max_error: float | None = None, max_distance: float | None = None,
             max_distance_rel: float | None = None, method: Any = "default", scheduler: Any = "parallel",
             topology: Topology | None = None, attributes: Any = "auto", feature_edges=None,
             progress: bool = False, measure: bool | None = None, partition=None, **settings) -> SimplifyResult:
    """Simplify a triangle mesh by iterative pair contraction (Garland & Heckbert 1997).

    mesh: a path (any format trimesh reads), a `trimesh.Trimesh`, ``(vertices, faces)`` arrays, or an
        object with ``.vertices``/``.faces``. Polygons are triangulated.
    target_faces / ratio: stop at this many faces (ratio × the cleaned input's faces). Met exactly when
        the mesh allows it; otherwise the result has the fewest faces reachable above the target.
    max_error: stop before the cheapest contraction costs more than this, in the method's cost (its
        ``error_unit``): for the quadric methods the *quadric error* in mesh units², a sum of squared
        distances from the new vertex to the planes of the input faces merged into it (e.g.
        ``(0.01 * diagonal)**2``). It bounds each contraction's cost, not the output's distance from the
        input: a sum over many planes, its square root is often several times that distance, and later
        contractions and the re-fit move the surface again. The distance is measured in
        ``stats["distance_max"]`` (``measure``). May be combined with a face target; whichever is reached
        first stops.
    max_distance / max_distance_rel: a distance the result is guaranteed to keep, in mesh units (or as a
        fraction of the input's bounding-box diagonal; give one of the two): every input vertex and face
        centroid lies within it of the output's surface, and every output vertex and face centroid within
        it of the input's (exact point-triangle distances; not a continuous Hausdorff bound: points between
        the samples may lie a little farther). The run goes toward the face target (none: as far as it
        can), then returns the level of its record with the fewest faces found within the bound (checked,
        re-fitted only if the re-fitted level passes too); ``stop_reason`` is ``"max_distance"`` when the
        bound, not the target, stopped it, and ``stats["distance_two_way_max"]`` is the distance checked
        (docs/metrics.md, "A distance you can ask for"). May be combined with a face target and
        ``max_error``; whichever is reached first stops. Positions only (``attributes=None``; ESQEM with
        ``split_factor=None``); `simplify_batch` and sweeps take it, `lod_chain` does not.
    method: the cost model and all its settings, as an object (``qemjax.QEM(boundary_weight=10)``,
        ``qemjax.ESQEM(curvature_weight=0.1)``, ``qemjax.AreaDifference()``, ``qemjax.LineQEM()``, a
        preset such as ``qemjax.QEM.accurate()``, or a class registered with `qemjax.register_method`), or
        its name (`qemjax.methods()`: ``'qem'``, ``'esqem'``, ``'area'``, ``'line'``, ``'probabilistic'``,
        the presets ``'default'`` (`qemjax.QEM.default`: what runs when no method is given), ``'classic'``
        (``QEM()``, the default until 0.2) and ``'accurate'``), which means the object with its defaults. Each class's docstring lists its
        settings; every method also has ``regularize``, ``area_weight``, ``refit``, ``polish``, ``sliver_moves`` and
        ``quality_threshold`` (`_costs.base.Method`).
    scheduler: ``'parallel'`` (default): rounds of many non-interacting contractions chosen by an
        independent-set rule; a `qemjax.Schedule`: the parallel scheduler with those tunables;
        ``'greedy'``: the paper's priority queue, one contraction at a time.
    topology: a `qemjax.Topology`: topology preservation, pruning of small parts, aggregation of close
        pairs (``pair_threshold``), the flip angle and welding (None: its defaults).
    attributes: which appearance attributes to carry through (per-corner wedges, seams kept: docs/attributes.md;
        ``qemjax._mesh.wedges``): ``'auto'`` (each kind the input carries without
        seams: UVs and their material, vertex colours, stored normals, normalised to unit length; UVs with
        seams and their texture when the file's material names a texture image or ``texture`` is given;
        another kind with seams, which hold vertices in place, only when asked for by name: one warning
        names it), ``'uv'``, ``'color'``, ``'normal'``, a tuple of these, None
        (positions only; what is dropped is named in a warning), or a `qemjax.Attributes` that also sets
        their weights in the cost and the texture. Kept ones come back as ``res.uv`` / ``res.colors`` /
        ``res.normals``; a contraction that would move a seam vertex off its seam or merge wedges of
        different charts is refused (``stats['rejected_by']['seam']``). Only `qemjax.QEM` keeps attributes
        (others warn and drop).
    feature_edges: (k,2) vertex-index pairs (in the cleaned input) constrained like boundary edges.
    progress: show a progress bar (tqdm) of the faces removed (with splitting, ESQEM's, first those of the
        run that plans it).
    measure: measure the output's distance from the input (`_pipeline.measure`: every input
        vertex and face centroid to its nearest output point) into ``stats["distance_max"]``,
        ``["distance_rms"]`` (mesh units) and their ``_rel`` forms (over the bounding-box diagonal). None
        (default): measured when the method re-fits (the default method; the re-fit already makes the
        output depend on the input's samples), else not (``measure=True`` there costs one nearest-surface
        query over one and a half times the input's faces in points; ``experiments/figures/distance_check.py``
        times it).
    locked, vertex_weights (given by name, with the settings): per-vertex constraints, numbered as the
        vertices were given (before welding; a file's as the file has them, an OBJ's by its ``v`` lines:
        `qemjax._pipeline.locks`; docs/methods.md, "Locking vertices and weighting importance"). ``locked``: a boolean mask (n,) or integer indices of vertices that stay in the
        output, and at every level of ``res.record``, exactly where they are (bit for bit); a pair with
        one locked vertex contracts onto it, a pair of two never (nor do ESQEM's splits cut their edge).
        ``vertex_weights``: (n,) finite, >= 0, at most 1e30; each pair's cost is multiplied by the larger weight of its
        two vertices (a kept vertex takes the larger weight of the pair), so heavy regions keep more detail.
        A run the locks stop short of the target ends with ``stop_reason="locked"`` and
        ``stats["blocked_by"]["locked"]``.
    partition: a `qemjax.Partition` (or True: its defaults): a mesh too large for one process, read in chunks
        from its file, cut into parts simplified in parallel with their borders locked, regrouped level by
        level until one group meets the target (`qemjax._partition`; docs/large-meshes.md). The result holds
        the output and its stats (``stats["partition"]``), not the input, record or history; of the
        attributes, a file's UVs (``attributes="uv"``, or ``"auto"`` as in core: without seams, or when the file
        names a texture image).
        None (default): in this process, unless the mesh would need more memory than this machine has
        available (`_pipeline.fits`: a ``MemoryError`` that is also a ValueError, before the mesh is read,
        naming the way to run it partitioned); False: in this process regardless.
    settings: any field of the method, `Topology` or `Attributes` by its name (``boundary_weight=10``,
        ``flip_angle=None``, ``attribute_weights=0.1``) or dotted (``**{"method.refit": 0}``); each
        replaces that field of the object given (so ``method="accurate", refit=0`` is the preset without
        its re-fit). ``preset=NAME`` is ``method=NAME``. docs/methods.md, "Settings as objects", lists where each
        of the flat keywords of qemjax 0.1 lives.
    Returns a `SimplifyResult`; ``stop_reason`` says why it stopped (``"target"``, ``"max_error"``,
    ``"max_distance"``, ``"blocked"``, ``"locked"`` or ``"unchanged"``) and a warning is issued when it ends above the face target for any
    reason but the parity of a closed mesh. Raises ValueError for bad input or options (FileNotFoundError,
    also a ValueError, for a path that does not exist), TypeError for an unknown setting.
    """
    from .._kernels import compilation as _compilation  # the run's modules, here: importing qemjax stays light
    from . import stages

    settings = dict(settings)
    up = 3 + settings.pop(CALLER, 0)  # the warnings' stacklevel in the stages: the user's line
    if partition is not None and partition is not False:
        return _partitioned(mesh, target_faces, ratio, partition, progress, measure, attributes, settings,
                            dict(max_error=max_error, max_distance=max_distance, max_distance_rel=max_distance_rel,
                                 method=method, scheduler=scheduler, topology=topology, feature_edges=feature_edges))
    t_start = time.perf_counter()
    c0, s0 = _compilation.snapshot()
    locks = _locks.pop_settings(settings)
    seed, refit_to = settings.pop(stages.SEED, None), settings.pop(stages.REFIT_TO, None)
    setup = stages.setup(method, scheduler, topology, attributes, progress, settings, measure)
    bound = _bound.check(max_distance, max_distance_rel)
    # bad targets fail before the mesh is read, as does a mesh too large for this process (`fits`)
    stages._resolve_target(1, target_faces, ratio, max_error, bound is not None)
    if partition is None:
        _fits.check(mesh)
    geo = stages.geometry(mesh, setup, stacklevel=up)
    job = stages.job(setup, geo, feature_edges, target_faces, ratio, max_error, stacklevel=up, locks=locks,
                     bounded=bound is not None, seed=seed, refit_to=refit_to)
    if bound is None:
        job = stages.beside_rounds(job)
        return stages.finish(job, stages.run(job), t_start, c0, s0, stacklevel=up)
    _bound.supported(job)
    return _bound.finish(job, stages.run(job), bound, t_start, c0, s0, stacklevel=up)



def _partitioned(mesh, target_faces, ratio, partition, progress, measure, attributes, settings, named):
    """`simplify` with ``partition=``: its keywords checked and handed to `_partition.run`."""
    from .._partition.run import simplify_partitioned
    from .._options import Partition

    if partition is True:
        partition = Partition()
    if not isinstance(partition, Partition):
        raise ValueError(f"partition: expected a qemjax.Partition or True, got {type(partition).__name__}")
    if measure is not None:
        partition = dataclasses.replace(partition, measure=bool(measure))
    if attributes in ("uv", ("uv",)):
        uv = True
        if not isinstance(mesh, (str, os.PathLike)):
            raise ValueError("partition: UVs are kept from a mesh file (an OBJ's vt, a PLY's per-vertex texture "
                             "coordinates); a mesh given as arrays or an object is read for its positions only")
    elif attributes in ("auto", None):
        uv = "auto" if attributes == "auto" else False
    else:
        raise ValueError("partition: a partitioned run keeps a file's UVs and nothing else of its appearance; "
                         "attributes='uv', 'auto' (UVs without seams, or with a texture image) or None")
    kwargs = {k: v for k, v in named.items() if v is not None} | dict(settings)
    kwargs.pop("attributes", None)
    texture = kwargs.pop("texture", None)
    if texture is not None:  # as in core: the UVs kept with this texture
        if not uv:
            raise ValueError("texture= needs UVs: attributes=None does not keep them")
        uv = True
    if kwargs.get("weld") is False or getattr(kwargs.get("topology"), "weld", None) is False:
        raise ValueError("partition: weld=False is not offered: a partitioned run welds the file's coincident "
                         "vertices to find where its parts meet (and keeps UVs by welding the positions back); "
                         "run it in core (partition=False, --no-partition) to keep them apart")
    return simplify_partitioned(mesh, target_faces=target_faces, ratio=ratio, partition=partition, kwargs=kwargs,
                                progress=progress, stacklevel=4, uv=uv, texture=texture)


def simplify_batch(mesh: Any, configs: list[dict], *, errors: bool = False) -> list:
    """`simplify` of one mesh under many configurations: ``[simplify(mesh, **c) for c in configs]``, with
    equal results, computed together (`simplify_cells`).

    errors: False: the first bad configuration raises its ValueError; True: its entry in the returned list
    is that exception instead."""
    if isinstance(configs, dict) or not all(isinstance(c, dict) for c in configs):
        raise ValueError("configs takes a list of dicts of simplify's keywords, one per run "
                         "([dict(ratio=0.5), ...])")
    return simplify_cells([(mesh, c) for c in configs], errors=errors)


def simplify_cells(cells: list, *, errors: bool = False) -> list:
    """`simplify` of many (mesh, configuration) cells: ``[simplify(m, **c) for m, c in cells]``, with equal
    results (vertices, faces, history, stop reason: bit for bit), computed together.

    Each mesh (by identity) is read and cleaned once per ``weld`` / ``pair_threshold``. Cells that can
    share rounds (the parallel scheduler, no aggregation, a model with per-pair kernel settings: QEM with
    any placement, boundary weight, area weighting, ``regularize`` or ``area_weight`` value; the same flip
    angle, topology mode and `Schedule`), of one mesh or of several, run as one disjoint union of copies
    (`_schedulers.batched`), each with its own target, ``max_error``, vertex state and settings; the rest
    run alone. Cells of a batch that would run exactly alike (`_same_runs`: the same mesh, vertex state,
    kernel settings, target and max error, e.g. every ``boundary_weight`` of a closed mesh) run once, and
    each gets its own copy of the result. A batch's re-fits (the default's post-pass) run side by side on
    threads (`stages.refit_all`), each as it would alone. ``progress`` is not offered here (a sweep shows
    its own bar).
    A batched result's ``stats["batch"]`` gives the batch's ``size`` (cells), ``copies`` (distinct runs in
    its rounds), ``same_run`` (the cells this cell's run served, itself included) and wall time; its
    ``total_s``, ``run_s`` and ``compile_s`` are its share (the batch's / its size), and its stage times
    are the batch's.
    errors: False: the first bad configuration raises its ValueError; True: its entry in the returned
    list is that exception instead.
    """
    if not all(isinstance(c, (tuple, list)) and len(c) == 2 and isinstance(c[1], dict) for c in cells):
        raise ValueError("cells takes a list of (mesh, dict of simplify's keywords) pairs")
    out = [None] * len(cells)
    for i, res in iter_cells(cells, errors=errors):  # its warnings point at our caller (checked: stacklevel 4)
        out[i] = res
    return out


def iter_cells(cells: list, *, errors: bool = False, stacklevel: int = 4):
    """`simplify_cells`, as (index, result) pairs as each is final: the bad configurations first, then each
    cell that runs alone when it ends, each batch's cells when the batch (and its re-fits) ends. A sweep
    writes each row as soon as it can. ``stacklevel``: where warnings point (4: at `simplify_cells`'s caller)."""
    from .._kernels import compilation as _compilation  # the run's modules, here: importing qemjax stays light
    from .. import _schedulers
    from .._schedulers import batched
    from . import stages

    parallel_run = _schedulers.get("parallel")
    t_start = time.perf_counter()
    jobs, out, bounds = _jobs(cells, errors, stacklevel + 1)
    for i, exc in enumerate(out):
        if exc is not None:
            yield i, exc
    groups: dict = {}
    for i, job in jobs:
        groups.setdefault(_batch_key(job), []).append((i, job))
    prep = (time.perf_counter() - t_start) / max(len(jobs), 1)  # reading and cleaning, per run
    for key, members in groups.items():
        if key is None or len(members) == 1:
            for i, job in members:
                t0, (c1, s1) = time.perf_counter(), _compilation.snapshot()
                if i in bounds:
                    yield i, _bound.finish(job, stages.run(job), bounds[i], t0 - prep, c1, s1,
                                           stacklevel=stacklevel)
                else:
                    yield i, stages.finish(job, stages.run(job), t0 - prep, c1, s1, stacklevel=stacklevel)
            continue
        t0, (c1, s1) = time.perf_counter(), _compilation.snapshot()
        which, firsts = _same_runs([j for _, j in members])
        js = [members[k][1] for k in firsts]  # one copy per distinct run
        ran = batched.run([j.geo.Vn for j in js], [j.S for j in js], [j.geo.F for j in js],
                          [_first_target(j) for j in js], [j.options.max_cost for j in js], js[0].model,
                          [j.model.kernel_params() for j in js], js[0].options, [j.geo.edges[:2] for j in js],
                          [j.geo.frame.part_scale2() for j in js])
        # each cell's own copy of its first phase (cells of one run share it), then its second phase
        ran = _second_phases(parallel_run, [job for _, job in members], [
            ran[which[k]] if k == firsts[which[k]] else copy.deepcopy(ran[which[k]]) for k in range(len(members))])
        wall = time.perf_counter() - t0 + prep * len(members)
        c2, s2 = _compilation.snapshot()
        share, comp = wall / len(members), min(s2 - s1, wall) / len(members)
        served = np.bincount(which, minlength=len(js))
        later: list = []  # the batch's re-fits, run side by side below
        for k, (i, job) in enumerate(members):
            r = ran[k]
            info = {"size": len(members), "copies": len(js), "same_run": int(served[which[k]]), "total_s": wall,
                    "compilations": c2 - c1}
            if i in bounds:  # its re-fit and check run here, on the level the bound picks
                res = _bound.finish(job, (r, job.target, None), bounds[i], time.perf_counter(), c2, s2,
                                    stacklevel=stacklevel, batch=info)
            else:
                res = stages.finish(job, (r, job.target, None), time.perf_counter(), c2, s2, stacklevel=stacklevel,
                                    batch=info, later=later)
            res.stats.update(total_s=share, compile_s=comp, run_s=max(share - comp, 0.0))
            out[i] = res
        stages.refit_all(later)
        for i, _ in members:
            yield i, out[i]


def _second_phases(parallel_run, js: list, ran: list) -> list:
    """The outcomes ``ran`` of the jobs ``js`` (a batch's first phases, one per job) with the second phase of
    each late run (`_schedulers.late`: its memoryless stretch) joined: those whose phases can share rounds
    together (`batched.run`, one batch per model's kernels), the rest alone."""
    from .._mesh import topology as topo
    from .._schedulers import batched, late

    out = list(ran)
    nxt = {}
    for j, job in enumerate(js):
        if getattr(job.model, "switches_late", False):
            p = late.prepare(ran[j], job.geo.Vn, job.geo.F, job.geo.extra, max(job.target, 1), job.model,
                             part_scale=job.geo.frame.part_scale2())
            if p is not None:
                nxt[j] = p
    groups: dict = {}  # (the batch's jobs have no locks and no extra pairs: `_batch_key`)
    for j, p in nxt.items():
        key = _kernels_key(p.model) if batched.batchable(p.model, own_refresh=True) else ("alone", j)
        groups.setdefault(key, []).append(j)
    for key, members in groups.items():
        if len(members) == 1:
            j = members[0]
            out[j] = late.join(ran[j], nxt[j].run(parallel_run, js[j].options), nxt[j].faces, nxt[j].keep)
            continue
        ps = [nxt[j] for j in members]
        seconds = batched.run([p.V for p in ps], [p.S for p in ps], [p.F for p in ps], [p.target for p in ps],
                              [js[j].options.max_cost for j in members], ps[0].model,
                              [p.model.kernel_params() for p in ps], js[members[0]].options,
                              [topo.edges(p.F, len(p.V)) for p in ps], [p.part_scale for p in ps],
                              normals=[p.normals for p in ps], models=[p.model for p in ps])
        for j, p, o in zip(members, ps, seconds):
            out[j] = late.join(ran[j], o, p.faces, p.keep)
    return out


def plan_cells(cells: list) -> list:
    """How `simplify_cells` would run each (mesh, configuration) cell, without running it: per cell,
    (group, run, faces, ring), where cells of one group (a hashable key; None: the cell runs alone, as a
    bad configuration does) can share rounds, cells of one run (a hashable key, within the group) would run
    exactly alike (`_same_runs`' key; the run is computed once), ``faces`` are the cleaned mesh's and
    ``ring`` says whether its model prices pairs from their faces (``uses_ring``: a round costs several
    times more). A sweep cuts its cells into pieces with it (`qemjax._sweep.run.pieces`). Reads and
    cleans each mesh and builds each vertex state, as the run will (the run builds them again)."""
    plan = [(None, ("error", i), 0, False) for i in range(len(cells))]
    geos: dict = {}

    def each(i, job):  # its keys only: the job (and its vertex state) is let go
        group = _batch_key(job)
        if group is None:
            plan[i] = (None, ("alone", i), len(job.geo.F), bool(job.model.uses_ring))
            return
        geo = geos.setdefault(id(job.geo), (len(geos), job.geo))[0]  # (each geometry held, so its id stays its own)
        plan[i] = (group, _run_key(job, geo), len(job.geo.F), bool(job.model.uses_ring))

    with warnings.catch_warnings():  # the run says them again (clean-up, targets), where they belong
        warnings.simplefilter("ignore")
        _jobs(cells, True, 3, each=each, states=_Held())
    return plan


class _Held(dict):
    """Vertex states by key (`stages.job`'s cache) for planning: all let go once they would hold more than
    `PLAN_BYTES` (a state is then built again for a later cell that needs it)."""

    def __setitem__(self, key, value):
        if sum(v.nbytes for v in self.values()) + np.asarray(value).nbytes > PLAN_BYTES:
            self.clear()
        super().__setitem__(key, value)


PLAN_BYTES = 1 << 28  # 256 MiB


def _jobs(cells: list, errors: bool, stacklevel: int, each=None, states=None):
    """Each cell's `stages.Job` (its setup, geometry and vertex state; geometries shared per mesh and
    cleaning settings, states per model state): ([(index, job)], per cell None or its ValueError (with
    ``errors``; else raised), {index: its max_distance bound}). ``each(index, job)``: called for each
    instead of keeping the jobs (the list is then empty); ``states``: the vertex states' cache."""
    from . import stages

    geos, jobs, out, bounds = {}, [], [None] * len(cells), {}
    states = {} if states is None else states
    for i, (mesh, cfg) in enumerate(cells):
        try:
            if "progress" in cfg:
                raise ValueError("simplify_batch: progress is not offered here (a sweep shows its own bar)")
            kw = {**_RUN_DEFAULTS, **{k: v for k, v in cfg.items() if k in _RUN_DEFAULTS}}
            rest = {k: v for k, v in cfg.items() if k not in _RUN_DEFAULTS}
            locks = _locks.pop_settings(rest)
            try:
                setup = stages.setup(kw["method"], kw["scheduler"], kw["topology"], kw["attributes"], False, rest,
                                     kw["measure"])
            except TypeError as exc:
                raise ValueError(f"simplify_batch: {exc}") from None
            bound = _bound.check(kw["max_distance"], kw["max_distance_rel"])
            stages._resolve_target(1, kw["target_faces"], kw["ratio"], kw["max_error"], bound is not None)
            base = (id(mesh), setup.weld, setup.pair_threshold, repr(setup.attributes), id(setup.texture))
            gk = base + (setup.keeps_attributes,)  # (what the cleaning's warning says the result has)
            if gk not in geos:
                other = geos.get(base + (not setup.keeps_attributes,))
                # a mesh that carries no attributes is cleaned alike whether its method keeps them or not
                plain = other is not None and other.attrs is None and not other.report.get("dropped")
                geos[gk] = other if plain else stages.geometry(mesh, setup, stacklevel=stacklevel)
            job = stages.job(setup, geos[gk], kw["feature_edges"], kw["target_faces"], kw["ratio"],
                             kw["max_error"], stacklevel=stacklevel, states=states, locks=locks,
                             bounded=bound is not None)
            if bound is not None:
                _bound.supported(job)
                bounds[i] = bound
            if each is None:
                jobs.append((i, job))
            else:
                each(i, job)
        except (ValueError, TypeError) as exc:  # a value of the wrong type: that cell's error too
            if not errors:
                raise
            out[i] = exc
    return jobs, out, bounds


def _same_runs(jobs: list) -> tuple[np.ndarray, list[int]]:
    """Which jobs of one batch would run exactly alike: the same geometry, vertex state (by value: on a
    closed mesh every ``boundary_weight`` gives the same quadrics, without area weighting every
    ``area_power``), kernel settings, face target and max error. Returns (each job's run (k,) int, the first
    job of each run); such jobs run once (`simplify_cells`)."""
    which, firsts, seen = np.zeros(len(jobs), np.int64), [], {}
    for k, job in enumerate(jobs):
        key = _run_key(job, id(job.geo))
        run = seen.get(key)
        if run is not None and not np.array_equal(jobs[firsts[run]].S, job.S):
            run = None  # equal digests of different states: a run of its own
        if run is None:
            run = len(firsts)
            seen.setdefault(key, run)
            firsts.append(k)
        which[k] = run
    return which, firsts


def _run_key(job: "Job", geo) -> tuple:
    """What makes two jobs of one batch run exactly alike (`_same_runs`): ``geo`` (their geometry's
    identity), a digest of the vertex state, the kernel settings, the (first phase's) face target, the max
    error and the shape term's threshold."""
    S = np.ascontiguousarray(job.S)
    params = sorted((name, np.asarray(v).dtype.str, np.asarray(v).tobytes())
                    for name, v in job.model.kernel_params().items())
    return (geo, S.shape, S.dtype.str, hashlib.blake2b(S.tobytes(), digest_size=16).digest(), tuple(params),
            _first_target(job), job.options.max_cost, job.options.quality_threshold)


def _first_target(job: "Job") -> int:
    """The face target of a batch copy's run: the job's, or for a model that turns memoryless late in the run
    the first phase's (`_schedulers.late`; the second phases run after the batch's first, `_second_phases`)."""
    from .._schedulers import late

    return late.first_target(job.model, max(job.target, 1))


def _batch_key(job: "Job"):
    """Jobs with equal keys can run as copies of one batch (`_schedulers.batched`); None: run alone."""
    from .._schedulers import batched

    s, model = job.setup, job.model
    if s.scheduler != "parallel" or len(job.geo.extra) or job.tracker is not None or job.locks is not None or \
            not batched.batchable(model) or not (
            job.target < len(job.geo.F) or job.err < math.inf):
        return None
    return (_kernels_key(model), s.cos_max, s.min_quality, s.preserve_topology, s.prune, s.schedule,
            job.options.quality_threshold)


def _kernels_key(model):
    """What runs of a model share in one batch: its compiled kernels and the names of their settings (the
    values may differ per copy)."""
    return _model_key(model), tuple(sorted(model.kernel_params()))


def _model_key(model):
    """What decides a model's compiled kernels: its class (and a term's base), and the price function."""
    base = getattr(model, "base", None)
    return (type(model), getattr(model, "price_kernel", None), None if base is None else _model_key(base))


_RUN_DEFAULTS = {k: p.default for k, p in inspect.signature(simplify).parameters.items()
                 if p.kind is p.KEYWORD_ONLY and k != "progress"}


