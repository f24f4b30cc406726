"""`simplify`: the one entry point. Validates options, prepares the mesh, runs a scheduler."""
from __future__ import annotations

import functools
import math
import numbers
import time
import warnings
from typing import Any

import numpy as np

from . import _compilation
from . import _costs
from . import _io
from . import _split
from . import _topology as topo
from ._options import Options, Schedule
from . import _units
from ._arrays import face_normals
from ._record import Record
from ._result import Contractions, SimplifyResult
from ._schedulers import common, greedy, outcome, parallel

SCHEDULERS = ("parallel", "greedy")
PLACEMENTS = _costs.qem.PLACEMENTS

# Defaults, in one place (see the docstring of `simplify` for units)
BOUNDARY_WEIGHT = 100.0
FLIP_ANGLE = 90.0


def methods() -> tuple[str, ...]:
    """The cost models `simplify(method=...)` accepts (the registry in ``qemjax._costs``)."""
    return _costs.methods()


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


def _resolve_target(m: int, target_faces, ratio, max_error) -> tuple[int, float]:
    """(face target, max error) from the user's options; face target 0 means 'none'."""
    given = [x is not None for x in (target_faces, ratio)]
    if sum(given) > 1:
        raise ValueError("give at most one of target_faces and ratio")
    if not any(given) and max_error is None:
        raise ValueError("give a target: target_faces=, ratio= or max_error=")
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


def simplify(mesh: Any, *, target_faces: int | None = None, ratio: float | None = None,
             max_error: float | None = None, method: str = "qem", scheduler: str = "parallel",
             placement: str = "optimal", boundary_weight: float = BOUNDARY_WEIGHT,
             area_weighted: bool = True, area_power: float = 1.0, feature_edges=None, pair_threshold: float = 0.0,
             preserve_topology: bool | None = None,
             flip_angle: float | None = FLIP_ANGLE, weld: bool = True, progress: bool = False,
             prune: bool = False, regularize: float = 0.0, area_weight: float = 0.0,
             schedule: Schedule | None = None,
             curvature_weight: float = _costs.esqem.CURVATURE_WEIGHT,
             split_factor: float | None = _costs.esqem.SPLIT_FACTOR, memoryless: bool = False,
             volume_weight: float = 0.0, memory_weight: float = 0.0) -> SimplifyResult:
    """Simplify a triangle mesh by iterative pair contraction (Garland & Heckbert 1997).

    mesh: a path (any format trimesh reads), a `trimesh.Trimesh`, ``(vertices, faces)`` arrays, or an
        object with ``.vertices``/``.faces``. Polygons are triangulated.
    target_faces / ratio: stop at this many faces (ratio × the cleaned input's faces). Met exactly when
        the mesh allows it; otherwise the result has the fewest faces reachable above the target.
    max_error: stop before the cheapest contraction costs more than this: a *squared distance in the
        mesh's own units* (the quadric error, e.g. ``(0.01 * diagonal)**2``). May be combined with a
        face target; whichever is reached first stops.
    method: a registered cost model (`qemjax.methods()`): ``'qem'`` (quadric error metric),
        ``'esqem'`` (Zhang 2022: QEM ranked with a Gaussian-curvature term, then long edges split) or
        ``'area'`` (minimum surface-area difference, Qi et al.: each pair contracts to the point of its segment that
        changes the area least, cost = that |area change|; ``qemjax._costs.area``). With ``'area'``,
        costs, ``max_error`` and ``history.costs`` are areas (mesh units²), ``vertex_error`` is 0, and
        ``boundary_weight`` > 0 keeps boundary and feature vertices on their edges; ``placement`` and
        ``area_weighted`` do not apply.
    scheduler: ``'parallel'`` (default) — rounds of many non-interacting contractions chosen by an
        independent-set rule; ``'greedy'`` — the paper's priority queue, one contraction at a time.
    placement: ``'optimal'`` (solve; else best point on the segment; else best of endpoints/midpoint),
        ``'rank'`` (solve the well-determined directions only, the rest stay at the midpoint) or
        ``'endpoints'`` (the paper's fixed placement: best of v1, v2, midpoint).
    boundary_weight: penalty weight of the planes through each boundary edge perpendicular to its face
        (relative to an average face's plane; 0 disables boundary preservation).
    area_weighted: weight each face plane by its area / the mean face area (True), or by 1 (the paper).
    area_power: with area_weighted, weight by (area / mean area)^area_power (QEM and ESQEM; 1: the area
        itself; 0.5 lowers the Hausdorff distance on thin parts at some rms: README, "Placement and the
        ranking against peers").
    feature_edges: (k,2) vertex-index pairs (in the cleaned input) constrained like boundary edges.
    pair_threshold: t in mesh units; besides edges, any two vertices within distance t may contract
        (Garland–Heckbert's aggregation: separate parts can join). 0 = edge contraction only. Close pairs
        are found with a KD-tree; more than topo.MAX_PAIRS_PER_VERTEX per vertex is refused.
    preserve_topology: forbid contractions that break the link condition or make faces coincide (keeps
        a manifold's genus and boundary loops). Default: True when pair_threshold is 0, else False. With
        False, contractions may create non-manifold edges, and coincident faces are dropped (opposite
        ones cancel, so small parts can vanish), as in the paper.
    flip_angle: forbid a contraction that turns any surviving face's normal by this many degrees or
        more (90: any sign flip or collapse to zero area); None allows flips.
    weld: merge vertices with identical coordinates first (G&H need shared corners).
    prune: with preserve_topology, let small separate parts vanish (their last faces may contract away);
        by default (False) every part keeps at least one face. Without preserve_topology parts may always
        vanish (coincident faces cancel).
    regularize: λ ≥ 0, weight of a triangle-shape term added to the cost (penalises contractions that
        create slender triangles; ``qemjax._costs.regularize``). 0 (default) leaves the method's cost as
        it is. With λ > 0, costs, ``max_error`` and ``history.costs`` include the term (a squared length).
    area_weight: λ ≥ 0, with ``method='qem'``: adds λ·ΔS²/ℓ² to the cost, ΔS the surface-area change of the
        contraction at its placement and ℓ² the mean squared edge length around the pair (a squared
        length; ``qemjax._costs.area_term``). 0 (default) leaves the cost as it is.
    schedule: the parallel scheduler's tunables (`qemjax.Schedule`); None = the defaults.
    curvature_weight: a ≥ 0 (``method='esqem'`` only): contractions are ranked by Q + w·K with
        w = a·Q̄/K̄, so the mean curvature term is a times the mean quadric error (default 0.01, the paper's
        "two orders of magnitude below"; ``qemjax._costs.esqem``). Errors, ``max_error`` and
        ``history.costs`` stay the quadric error Q; K is in ``history.parts``.
    split_factor: b > 0 or None (``method='esqem'`` only): after simplifying, split every edge longer than
        b × the mean edge length at its midpoint (default 4/3, the paper's); None: no splitting. With a
        face target the result still has exactly that many faces: it simplifies further first, by as many
        faces as splitting will add (``qemjax._split``; ``stats["split"]``).
    memoryless: with ``method='qem'``, rebuild the quadrics around each contraction from the current faces
        (plus boundary planes) instead of summing the merged vertices' quadrics (Lindstrom & Turk 1998's
        memoryless quadrics; ``qemjax._costs.memoryless``). Costs then measure each contraction's change
        of the current surface: ``max_error`` bounds that; ``vertex_error`` stays the summed quadric's
        error (kept alongside, see ``memory_weight``). Not with ``feature_edges``, ``regularize`` or
        ``area_weight``. README, "Placement and the ranking against peers", has its ranks.
    volume_weight: λ ≥ 0, with ``memoryless=True``: add λ·(the contraction's volume change / the mean
        face area)² to its quadric before placing (Lindstrom & Turk's volume preservation as a penalty;
        a squared length). 0 (default) adds nothing.
    memory_weight: μ ≥ 0, with ``memoryless=True``: price each pair with the rebuilt quadrics plus μ times
        the summed (Garland–Heckbert) ones, which the run keeps alongside. 0 (default): memoryless alone.
    Returns a `SimplifyResult`; ``stop_reason`` says why it stopped (``"target"``, ``"max_error"``,
    ``"blocked"`` or ``"unchanged"``) and a warning is issued when it ends above the face target for any
    reason but the parity of a closed mesh. Raises ValueError for bad input or options.
    """
    t_start = time.perf_counter()
    c0, s0 = _compilation.snapshot()
    if scheduler not in SCHEDULERS:
        raise ValueError(f"unknown scheduler {scheduler!r}; choose from {SCHEDULERS}")
    boundary_weight = _real("boundary_weight", boundary_weight)
    pair_threshold = _real("pair_threshold", pair_threshold)
    flip_angle = None if flip_angle is None else _real("flip_angle", flip_angle)
    area_weighted, weld = _flag("area_weighted", area_weighted), _flag("weld", weld)
    memoryless = _flag("memoryless", memoryless)
    progress, prune = _flag("progress", progress), _flag("prune", prune)
    if preserve_topology is not None:
        preserve_topology = _flag("preserve_topology", preserve_topology)
    _resolve_target(1, target_faces, ratio, max_error)  # bad targets fail before the mesh is read
    if not (boundary_weight >= 0 and math.isfinite(boundary_weight)):
        raise ValueError(f"boundary_weight must be finite and >= 0, got {boundary_weight}")
    model = _costs.build(method, dict(placement=placement, area_weighted=area_weighted,
                                      area_power=_real("area_power", area_power), boundary_weight=
                                      boundary_weight, curvature_weight=_real("curvature_weight", curvature_weight),
                                      split_factor=split_factor if split_factor is None else
                                      _real("split_factor", split_factor), memoryless=memoryless,
                                      volume_weight=_real("volume_weight", volume_weight),
                                      memory_weight=_real("memory_weight", memory_weight)),
                         dict(regularize=regularize, area_weight=_real("area_weight", area_weight)))
    if (memoryless or volume_weight or memory_weight) and not getattr(model, "memoryless", False):
        raise ValueError("memoryless=True (and volume_weight, memory_weight, which need it) works with "
                         f"method='qem' only, not with {method!r} or with regularize / area_weight")
    split = getattr(model, "split_factor", None)  # None: the method does not split
    if schedule is None:
        schedule = Schedule()
    elif not isinstance(schedule, Schedule):
        raise ValueError(f"schedule must be a qemjax.Schedule, got {type(schedule).__name__}")
    if flip_angle is not None and not (0 < flip_angle <= 180):
        raise ValueError(f"flip_angle must be in (0, 180] degrees or None, got {flip_angle}")

    if not (pair_threshold >= 0 and math.isfinite(pair_threshold)):
        raise ValueError(f"pair_threshold must be a finite distance >= 0, got {pair_threshold}")
    if preserve_topology is None:
        preserve_topology = pair_threshold == 0
    elif preserve_topology and pair_threshold > 0:
        raise ValueError("pair_threshold > 0 joins separate parts, which changes topology: "
                         "use preserve_topology=False (the default when pair_threshold > 0)")

    (V, F), report = _io.prepare(mesh, weld_vertices=weld, stacklevel=2)
    feature_edges = _io.check_feature_edges(feature_edges, len(V))
    m = len(F)
    target, err = _resolve_target(m, target_faces, ratio, max_error)
    if target > m:
        warnings.warn(f"target of {target} faces is not below the mesh's {m} faces: returning it unchanged",
                      stacklevel=2)
        target = m

    extra = topo.close_pairs(V, F, pair_threshold)
    parts = topo.parts(F, len(V), extra)
    Vn, frame = _units.normalize(V, common.DTYPE, parts)

    E, ecount, be, bf = topo.edge_table(F, len(V))  # one sort for the boundary and the first edges
    area_mean, e2_mean, ext = report.pop("face_means")
    r2 = (ext / frame.scale) ** 2  # from the clean-up's unit extent to the frame's
    S = model.init_state(_costs.MeshInput(Vn, F, (be, bf), feature_edges, (area_mean * r2, e2_mean * r2)))
    options = Options(
        cos_max=-2.0 if flip_angle is None else float(np.cos(np.radians(flip_angle))),
        preserve_topology=preserve_topology, max_cost=frame.error_to_internal(err), schedule=schedule,
        keep_parts=not prune)
    nonmanifold = int(np.count_nonzero(ecount > 2))  # edges of three or more faces in the input

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=m - target, unit="face", desc="simplify")

        last = m

        def progress_cb(faces_now):
            nonlocal last
            bar.update(last - faces_now)
            last = faces_now
    else:
        progress_cb = None
    run_target, planned = target, None
    if target < m or err < math.inf:
        run = functools.partial(parallel.run, edges=(E, ecount), part_scale=frame.part_scale2()) \
            if scheduler == "parallel" else greedy.run
        if split is not None and target:  # simplify further by what splitting will add (`_split.plan`)
            run_target, planned = _split.plan(run, (Vn, S, F, extra), target, model, options, split)
        Vo, So, Fo, alive, hist, info = run(Vn, S, F, extra, max(run_target, 1), model, options, progress_cb)
    else:  # nothing to remove
        Vo, So, Fo, alive = Vn, S, F, np.ones(m, bool)
        hist = (np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0))
        info = {"contractions": 0, "rejected": 0, "rounds": 0, "max_cost": 0.0,
                "branches": np.zeros(len(model.branches), int), "stop_reason": "unchanged", "blocked_by": {},
                "rejected_by": outcome.count_reasons(np.zeros(0, np.int8))}
    if bar is not None:
        bar.close()

    Vout, Fout, ids, fids = common.compact_output(Vo, Fo, alive)
    vout = frame.positions_to_mesh(Vout, ids)
    unmoved = np.ones(len(V), bool)
    unmoved[hist[0][:, 0]] = False  # kept vertices moved; removed ones are gone
    same = np.flatnonzero(unmoved[ids])
    vout[same] = V[ids[same]]  # never contracted: the input's float64 position, exactly
    flat = np.flatnonzero(~np.any(face_normals(vout, Fout) != 0, axis=1))
    if flat.size:  # an input face with exactly collinear corners: keep the rounded positions there
        w = np.unique(Fout[flat])
        vout[w] = frame.positions_to_mesh(Vout[w], ids[w])
    verr = frame.errors_to_mesh(model.vertex_error(So[ids]))
    if split is not None:
        vout, Fout, ids, fids, verr, split_stats = _split.apply(vout, Fout, ids, fids, verr, split, target)
        split_stats.update(planned=planned, run_target=run_target if target else None,
                           run_stop_reason=info["stop_reason"])
        if target and len(Fout) <= target and info["stop_reason"] == "blocked":
            info["stop_reason"] = "target"  # splitting spent what the contractions could not reach
    stop = info["stop_reason"]
    if target and len(Fout) > target:  # a face target was asked for and not met
        closed = len(topo.boundary_edges(Fout, len(vout))[0]) == 0
        if outcome.parity_only(len(Fout), target, closed) and stop in ("target", "blocked"):
            stop = "target"  # documented: a closed mesh loses faces in pairs
        else:
            stop = "blocked" if stop == "target" else stop
            warnings.warn(_above_target_message(len(Fout), target, stop, info["blocked_by"], nonmanifold,
                                                preserve_topology), stacklevel=2)
    hp, hx, hc = hist[0], frame.positions_to_mesh(hist[1], hist[0][:, 0]), frame.errors_to_mesh(hist[2])
    hparts = {}
    if info.get("parts") is not None and len(model.part_units) == len(model.parts):  # in mesh units
        for name, unit, col in zip(model.parts + ("rank",), model.part_units + (2,), info["parts"].T):
            hparts[name] = np.asarray(col, np.float64) * frame.scale ** unit
    c1, s1 = _compilation.snapshot()
    total = time.perf_counter() - t_start
    stats = dict(report)
    stats.update(
        method=method, scheduler=scheduler, faces_in=m, faces_out=len(Fout), target_faces=target,
        vertices_in=len(V), vertices_out=len(vout), close_pairs=len(extra), contractions=info["contractions"],
        rejected=info["rejected"], rounds=info["rounds"],
        branches={name: int(c) for name, c in zip(model.branches, info["branches"])},
        rejected_by=info["rejected_by"], blocked_by=info["blocked_by"], model=model.describe(),
        compilations=c1 - c0, compile_s=min(s1 - s0, total), run_s=max(total - (s1 - s0), 0.0),
        total_s=total, scale=frame.scale, parts_in=parts[0], non_manifold_edges_in=nonmanifold,
        max_error_limit=err if math.isfinite(err) else None)
    for k, v in info.items():
        if k.endswith("_s") or k == "faces_per_round":
            stats[k] = v
    if info.get("reweights"):  # (faces, weights of the parts in mesh units) each time they were set
        stats["reweights"] = [(f, [float(x) * frame.scale ** (2 - u) for x, u in zip(w, model.part_units)])
                              for f, w in info["reweights"]]
    if split is not None:
        stats["split"] = split_stats
    history = Contractions(hp, hx, hc, hparts, info.get("history_rounds", np.zeros(0, np.int64)))
    record = Record(V, F, history, info.get("removed_at", np.full(m, -1, np.int64)),
                    info.get("coincident", np.zeros(m, bool)), frame, scheduler, run_target)
    return SimplifyResult(
        vertices=vout, faces=Fout.astype(np.int64), vertex_error=verr,
        max_error=float(frame.errors_to_mesh(info["max_cost"])), source_vertices=ids.astype(np.int64),
        source_faces=fids.astype(np.int64),
        input_vertices=V, input_faces=F, history=history, stats=stats, stop_reason=stop, record=record)


def _above_target_message(faces: int, target: int, stop: str, blocked: dict, nonmanifold: int,
                          manifold_mode: bool) -> str:
    held = ", ".join(f"{k}: {v}" for k, v in blocked.items() if v) or "no pairs left"
    why = {"max_error": "the remaining contractions cost more than max_error",
           "blocked": "no valid contraction is left"}.get(stop, stop)
    hint = ""
    if manifold_mode and stop == "blocked":
        if nonmanifold:
            hint = (f"; the input has {nonmanifold} non-manifold edges (3 or more faces), which manifold mode "
                    "never contracts: preserve_topology=False may reach the target")
        elif blocked.get("vanishing_part"):
            hint = "; separate parts keep their last faces: prune=True lets small parts vanish"
        else:
            hint = "; preserve_topology=False may reach further (genus and boundaries may then change)"
    return f"stopped at {faces} faces, above the target of {target}: {why} (pairs held back by {held}){hint}"
