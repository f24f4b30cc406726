"""A partitioned run, as the client drives it: cut the input into parts (`scatter`), then level by level
plan the groups (`plan.level`), write the level's locks, run the groups (`task.run_group`) on the runner
(`execute`), until the last level; then measure the output (in the last level's task where it fitted to the
input, `task.run_group`; else against every part, `task.measure_parts`) and build the result. The client
reads only the pieces' border ids and the output, never the whole input."""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from . import execute, indexed, pieces, plan, task
from .readers import texture_of
from .source import CORNER_UV, FACES, PACKED, UV, VERTICES
from .._io import held as _held
from .._mesh.arrays import box_diagonal
from .._mesh.wedges import seamed_left_out
from .._options import Partition

UNSUPPORTED = ("max_error", "max_distance", "max_distance_rel", "feature_edges", "locked", "vertex_weights")


def _scratch(p: Partition) -> tuple[Path, bool]:
    """The scratch folder and whether to remove it at the end (a temporary one)."""
    if p.scratch is None:
        return Path(tempfile.mkdtemp(prefix="qemjax-parts-")), True
    path = Path(p.scratch)
    if path.exists() and not path.is_dir():
        raise ValueError(f"partition: the scratch folder {path} is a file")
    path.mkdir(parents=True, exist_ok=True)
    return path, False


def _arrays(mesh):
    """A path as given; anything else as (float64 vertices, int64 faces), converted once."""
    if isinstance(mesh, (str, os.PathLike)):
        return mesh
    from .._io.mesh import as_arrays

    V, F = as_arrays(mesh)[:2]
    return np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64)


def _input_key(mesh) -> str:
    """What identifies the input for a resumed run: a file by its path, size, time and a hash of its first
    and last MiB (another scan of the same size copied with its time kept, ``cp -p``, is another input), and
    the texture image it names (``attributes="auto"`` keeps UVs when one exists); arrays (`_arrays`) by a
    hash."""
    if isinstance(mesh, (str, os.PathLike)):
        path = Path(mesh)
        st = path.stat()
        h = hashlib.sha256()
        with open(path, "rb") as f:
            h.update(f.read(1 << 20))
            if st.st_size > 1 << 20:
                f.seek(max(st.st_size - (1 << 20), 1 << 20))
                h.update(f.read())
        image = texture_of(path)
        seen = f":{image}:{image.stat().st_mtime_ns}" if image is not None else ""
        return f"{path.resolve()}:{st.st_size}:{st.st_mtime_ns}:{h.hexdigest()[:16]}{seen}"
    return hashlib.sha256(mesh[0].tobytes() + mesh[1].tobytes()).hexdigest()


MEASURE_TASKS = 32  # the measured distance's tasks (fewer for fewer parts): fixed, whatever the workers
# what a run writes in its scratch folder: level folders, the reading's work folders and these files
_OWN_FOLDERS = re.compile(r"level\d+|tmp|weld")
LOCK = "run.lock"  # held by the run using the folder (`_claim`)
_OWN_FILES = {LOCK, "manifest.json", "run.json", "stats.json", "output.npz", "input.ply", VERTICES, FACES, UV, CORNER_UV,
              PACKED, "faces_raw.i64", "ids.i64", *indexed.WELDED}


def _own(entry: Path) -> bool:
    """Whether a scratch folder's entry is one a partitioned run writes (its atomic writes' temporary
    files, ``.NAME.PID.THREAD.tmp``, too)."""
    if entry.is_dir():
        return _OWN_FOLDERS.fullmatch(entry.name) is not None
    return entry.name in _OWN_FILES or (entry.name.startswith(".") and entry.name.endswith(".tmp"))


def _refuse_foreign(folder: Path, source=None) -> None:
    """ValueError when ``folder`` holds anything a partitioned run does not write (a scratch folder is the
    run's, and a user's files beside it must not be removed with it), or the input ``source`` under a name
    the run writes."""
    foreign = sorted(e.name for e in folder.iterdir() if not _own(e))
    if foreign:
        raise ValueError(f"partition: the scratch folder {folder} holds files a partitioned run did not write "
                         f"({', '.join(foreign[:3])}{', ...' if len(foreign) > 3 else ''}); give a new or empty "
                         "folder (Partition.scratch, --scratch)")
    if isinstance(source, (str, os.PathLike)) and Path(source).resolve().parent == folder.resolve() \
            and _own(Path(source)):
        raise ValueError(f"partition: the input {source} is in the scratch folder under a name the run "
                         "writes there; move it, or give another scratch folder")


def _claim(folder: Path) -> int | None:
    """Hold ``folder`` for this run (`_io.held`: a lock on its `LOCK` file, until `_let_go`), or ValueError
    when another run holds it: two runs in one folder would each clear or overwrite the other's pieces and
    levels as it goes. None where files cannot be locked: the folder is then used unguarded, as before."""
    return _held.take(folder / LOCK, f"partition: the scratch folder {folder} is in use by another run; wait "
                                    "until it ends, or give another folder (Partition.scratch, --scratch)")


def _let_go(folder: Path, claim: int | None) -> None:
    _held.release(folder / LOCK, claim)


def _drop_temporaries(folder: Path) -> None:
    """Remove the temporary files of atomic writes (`_io.atomic.replace_atomically`: ``.NAME.PID.THREAD.tmp``)
    in a folder this run holds (`_claim`) and in its level folders: a process killed while writing (a worker
    stopped by Ctrl-C, or by the system for its memory) could not remove its own, and a resumed run would
    keep them."""
    for tmp in [*folder.glob(".*.tmp"), *folder.glob("level*/.*.tmp")]:
        tmp.unlink(missing_ok=True)


def _fresh(folder: Path, key: dict, source=None) -> None:
    """Remove what an earlier run with other inputs or settings left in ``folder`` (only its own files, and
    not the lock this run holds, `_claim`). A folder that holds anything else is refused (ValueError,
    `_refuse_foreign`), before anything in it is touched."""
    _refuse_foreign(folder, source)
    meta = folder / "run.json"
    if meta.exists() and json.loads(meta.read_text()) == key:
        return
    for entry in folder.iterdir():
        if entry.name == LOCK:
            continue
        if entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
    pieces.save_json(meta, key)


def _as_file(mesh, folder: Path) -> Path:
    """A path as given; arrays (`_arrays`) written to the scratch folder as a binary PLY, whole or not at all:
    a resumed run takes the file it finds, and one cut short by Ctrl-C would be its input."""
    if isinstance(mesh, (str, os.PathLike)):
        return Path(mesh)
    from .write import replace_atomically, write_binary_ply

    path = folder / "input.ply"
    if not path.exists():
        replace_atomically(path, lambda tmp: write_binary_ply(tmp, *mesh))
    return path


def _locks(level_dir: Path, groups: list, borders: list) -> Path:
    """The global ids that two or more of this level's groups hold (sorted, written as ``locks.npy``)."""
    held = [np.unique(np.concatenate([borders[i] for i in grp.members])) for grp in groups]  # once per group
    uniq, count = np.unique(np.concatenate(held) if held else np.zeros(0, np.int64), return_counts=True)
    path = level_dir / "locks.npy"
    np.save(path, uniq[count >= 2].astype(np.int64))
    return path


def _level_kwargs(kwargs: dict, p: Partition, last: bool) -> tuple[dict, dict]:
    """A level's method settings, and what they change from the run's: the run's own at the last level. A
    level before it stops far above the run's target, so it leaves out what only a run's end is for: the
    memoryless last stretch (a method's ``late_memoryless`` would switch at K × the group's share of the
    level, where summed quadrics keep the input's memory best and the last level starts again from the
    faces left; with it its volume term, as a run that stays summed drops it), the shape term (the slivers
    that count are the output's; ranking a level's contractions by their shape wore away a spike that the
    last level, seeing it through the carried quadrics, would have kept), ESQEM's edge splits and, with
    ``refit="last"``, the re-fit. A last level of several locked groups splits as the method asks: an edge
    between two locked vertices is never split (`_pipeline.split`), and a split's new vertex, away from the
    source vertex it names, takes no global id (`task._gids_out`)."""
    changed = {}
    method = _method(kwargs)
    if not last and getattr(method, "split_factor", None) is not None:
        changed["split_factor"] = None
    if not last:
        if p.refit == "last":
            changed["refit"] = 0
        if getattr(method, "switches_late", False):
            changed |= {"late_memoryless": 0, "volume_weight": 0}
        if getattr(method, "quality_threshold", 0):
            changed["quality_threshold"] = 0.0
    # a setting given by its dotted name too would be applied after the flat one: only the flat one stays
    out = {k: v for k, v in kwargs.items() if not (k.startswith("method.") and k[7:] in changed)}
    return out | changed, changed


def _refit_to(manifest: dict, folder: Path, p: Partition, groups: list, last: bool, first: bool,
              refits: bool) -> list | None:
    """The level-0 parts the level's re-fit fits its output to (`stages.REFIT_TO`), or None (its own input):
    a last level of one group after other levels, when the input has at most ``refit_input_faces`` faces and
    the method re-fits (``refits``; else the parts would be read for nothing).
    Fitted to what the levels left, the polish and sliver moves keep the distance from a coarser surface
    than the input, and the partitioned run's Hausdorff distance ended above the in-core one's."""
    if not (refits and last and len(groups) == 1 and not first
            and int(manifest["n_faces"]) <= p.refit_input_faces):
        return None
    return [str(folder / part["file"]) for part in manifest["parts"]]


def _method(kwargs: dict):
    """The method ``kwargs`` name (as `simplify` takes them), with their settings applied. Resolved by
    `flat.apply` alone, not `stages.setup` (which builds the model): the client imports neither JAX nor
    numba; ``schedule`` is the one keyword `stages.setup` takes out before it."""
    from .._pipeline import flat

    settings = {k: v for k, v in kwargs.items() if k not in flat.KEYWORDS or k == "preset"}
    settings.pop("schedule", None)  # the scheduler's, not the method's (`stages.setup`)
    return flat.apply(kwargs.get("method", "default"), kwargs.get("topology"), None, settings)[0]


def _bar(progress: bool, total: int, desc: str):
    if not progress:
        return None
    from tqdm.auto import tqdm
    return tqdm(total=total, desc=desc, unit="task", leave=False)


def _run_level(runner, name, specs, progress, desc) -> list:
    out, bar = [None] * len(specs), _bar(progress, len(specs), desc)
    try:
        for i, res in runner.map(name, specs):
            out[i] = res
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return out


def _distance(results: list, diag: float, unit: float) -> dict:
    """The measured-distance stats (as `_pipeline.measure`) from the parts' maxima, sums and histograms."""
    from .._pipeline.measure import PERCENTILES

    d_max = max(r["max"] for r in results)
    d_rms = float(np.sqrt(sum(r["sum_sq"] for r in results) / sum(r["weight"] for r in results)))
    hist = np.sum([np.asarray(r["hist"]) for r in results], axis=0)
    cum = np.cumsum(hist) / hist.sum()
    # each slot's upper edge: 0 for the exact zeros (`task.measure_parts`), then the bins' edges
    edges = np.concatenate([[0.0], np.logspace(task.HIST_LO, task.HIST_HI, task.HIST_BINS + 1) * unit])
    out = dict(distance_max=d_max, distance_rms=d_rms)
    for p in PERCENTILES:  # the upper edge of the slot where the weight reaches p %: within 1 % above
        k = int(np.searchsorted(cum, p / 100 - 1e-12))
        out[f"distance_p{p}"] = float(min(edges[min(k, task.HIST_BINS + 1)], d_max))
    shared = np.unique(np.concatenate([r["shared"] for r in results]))  # a border vertex: one sample
    return _relative(out | dict(distance_samples=int(sum(r["samples"] for r in results)) + len(shared)), diag)


def _relative(dist: dict, diag: float) -> dict:
    """The measured-distance stats with their ``_rel`` forms: each distance over the input's diagonal (the
    manifest's box, however the distances were measured)."""
    rel = {f"{k}_rel": (v / diag if diag > 0 else None) for k, v in dist.items()
           if k.startswith("distance_") and k not in ("distance_samples", "distance_s")}
    return dist | rel


def _common_cost(runner, specs: list, p: Partition, progress, label: str):
    """``Partition(share="cost")``: the pilot groups (`plan.pilots`) run in proportion first; every group of
    the level then stops at their common cost (`plan.common_cost`), or at a quarter of its proportional
    share, whichever comes first. Returns (the cost, the level's specs)."""
    chosen = plan.pilots(len(specs))
    pilot_specs = [specs[i] | dict(out=specs[i]["out"].replace("group_", "pilot_")) for i in chosen]
    cost = plan.common_cost([s["max_error"] for s in _run_level(runner, "run_group", pilot_specs, progress, label)])
    return cost, [s | dict(target=max(1, s["target"] // 4), kwargs=s["kwargs"] | {"max_error": cost})
                  for s in specs]


def simplify_partitioned(mesh, *, target_faces, ratio, partition: Partition, kwargs: dict, progress: bool,
                         stacklevel: int = 3, uv=False, texture=None):
    """`simplify` with ``partition=``: the module docstring. ``kwargs``: the method and its settings, as
    `simplify` takes them; ``uv``: keep a file's UVs (True, "auto": as in core, when it names a texture
    image or they have no seams, False: `scatter.scatter`); ``texture``: the image of the UVs kept (a path
    or a PIL image; None: the one the file names)."""
    from .._pipeline import stages
    from .scatter import scatter

    bad = [k for k in UNSUPPORTED if kwargs.get(k) is not None]
    if bad:
        raise ValueError(f"partition: {', '.join(bad)} cannot be combined with a partitioned run")
    stages._resolve_target(1, target_faces, ratio, None, False)
    p = partition
    t0 = time.perf_counter()
    if isinstance(mesh, (str, os.PathLike)) and not Path(mesh).exists():  # before a scratch folder is made
        from .._io.mesh import MissingFileError
        raise MissingFileError(f"no such file: {mesh}")
    folder, temporary = _scratch(p)
    runner = claim = None
    try:  # the scratch folder is held (`_claim`) until the workers are stopped and the stats written
        try:
            mesh = _arrays(mesh)
            key = dict(input=_input_key(mesh), part_faces=p.part_faces, budget=p.budget, reduction=p.reduction,
                       final_faces=p.final_faces, refit_input_faces=p.refit_input_faces, refit=p.refit, share=p.share,
                       target=[target_faces, ratio],
                       kwargs=repr(sorted(kwargs.items())), levels="summed before the last", quadrics="carried, in the input's extent",
                       borders="the input's kept along the cuts",
                       uv="auto: without seams, or with a texture image" if uv == "auto" else uv)
            if not temporary:  # (a temporary folder is this run's alone)
                _refuse_foreign(folder, mesh)  # before a lock file is made in a user's folder
                claim = _claim(folder)
            _fresh(folder, key, mesh)
            if claim is not None:
                _drop_temporaries(folder)
            source = _as_file(mesh, folder)
            runner = execute.open_runner(p)
            manifest_path = folder / "manifest.json"
            if manifest_path.exists():
                manifest = json.loads(manifest_path.read_text())
            else:
                manifest = scatter(source, folder, p.part_faces, uv=uv)
            t_scatter = time.perf_counter() - t0
            if uv is True and not manifest.get("uv"):  # refused, as in core, before any level runs
                raise ValueError("attributes='uv': the file does not give every triangle corner a UV (an OBJ's vt, a "
                                 "PLY's per-vertex texture_u/texture_v, s/t or u/v, a binary PLY's texcoord lists)")
            n_faces = int(manifest["n_faces"])
            target = int(target_faces) if target_faces is not None else max(int(round(ratio * n_faces)), 1)
            if target > n_faces:  # as an in-core run says it
                warnings.warn(f"target of {target} faces is not below the mesh's {n_faces} faces: returning it "
                              "unchanged", stacklevel=stacklevel)
            target = min(target, n_faces)
            paths = [str(folder / part["file"]) for part in manifest["parts"]]
            unit = float(np.max(np.subtract(manifest["bbox"][1], manifest["bbox"][0]))) or 1.0  # `carry`'s unit
            faces = np.array([part["faces"] for part in manifest["parts"]], np.int64)
            borders = None
            levels, first = [], True
            method = _method(kwargs)
            refits = bool(getattr(method, "refit", 0))
            moves = bool(getattr(method, "polish", 0) or getattr(method, "sliver_moves", 0))  # after the re-fit
            while True:
                t_level = time.perf_counter()
                stalled = bool(levels) and levels[-1]["faces_out"] > 0.9 * levels[-1]["faces_in"]
                groups, last = plan.level(faces, target, p, first, stalled, levels[-1]["target"] if levels else None)
                level_dir = folder / f"level{len(levels) + 1}"
                level_dir.mkdir(exist_ok=True)
                if len(groups) == 1:
                    locks = None
                elif first:
                    locks = "border"
                else:
                    locks = str(_locks(level_dir, groups, borders))
                level_kw, changed = _level_kwargs(kwargs, p, last)
                specs = [dict(inputs=[paths[i] for i in g.members], locks=locks, target=g.target, kwargs=level_kw,
                              out=str(level_dir / f"group_{k:05d}.npz"), carry_out=not last, unit=unit,
                              uv=bool(manifest.get("uv")))
                         for k, g in enumerate(groups)]
                if locks == "border" and manifest.get("borders_on_cuts"):  # they keep their planes (`carry`)
                    for spec in specs:
                        spec["borders_on_cuts"] = str(folder / manifest["borders_on_cuts"])
                refit_to = _refit_to(manifest, folder, p, groups, last, first, refits)
                if refit_to is not None:  # (measured there too, with the re-fit's samples: `task.run_group`)
                    specs[0] |= dict(refit_to=refit_to, refit_moves=moves, measure=p.measure)
                cost = None
                if p.share == "cost" and not last and len(groups) > 1:
                    cost, specs = _common_cost(runner, specs, p, progress, f"level {len(levels) + 1} pilots")
                stats = _run_level(runner, "run_group", specs, progress, f"level {len(levels) + 1}")
                paths = [s["out"] for s in specs]
                faces = np.array([s["faces_out"] for s in stats], np.int64)
                levels.append(dict(groups=len(groups), faces_in=int(sum(g.faces for g in groups)),
                                   faces_out=int(faces.sum()), target=int(sum(g.target for g in groups)),
                                   locked=int(sum(s["locked"] for s in stats)), seconds=time.perf_counter() - t_level,
                                   cost=cost, stats=stats,
                                   settings=changed, refit_to="level input" if refit_to is None else "input"))
                if last:
                    break
                borders = [pieces.borders(path) for path in paths]
                first = False
            V, F, gid, _ = pieces.stitch(paths)
            UV = pieces.stitch_uv(paths) if manifest.get("uv") else None
            locked_share = float(np.mean(gid >= 0)) if len(paths) > 1 and len(gid) else 0.0
            dist, t_measure = {}, time.perf_counter()
            lo, hi = np.array(manifest["bbox"][0]), np.array(manifest["bbox"][1])
            # the last level's own measure, where it fitted to the input (`task.run_group`): taken as it is
            measured = levels[-1]["stats"][0].get("distance") if len(levels[-1]["stats"]) == 1 else None
            if not (p.measure and len(F)):
                pass
            elif measured is not None and measured["distance_max"] is not None:
                dist = _relative(measured, box_diagonal(lo, hi))
            else:
                final = folder / "output.npz"
                pieces.save(final, V=V, F=F.astype(np.int32), gid=gid)
                centre, unit = 0.5 * (lo + hi), float(np.max(hi - lo))
                files = [str(folder / part["file"]) for part in manifest["parts"]]
                # as many tasks whatever the workers: each sums its parts in order, the client the tasks in order,
                # so the sums (the rms, the histogram) are the same bits on 1 worker or 64
                batches = np.array_split(np.arange(len(files)), min(len(files), MEASURE_TASKS))
                mspecs = [dict(parts=[files[i] for i in b], final=str(final), centre=centre.tolist(), unit=unit)
                          for b in batches]
                dist = _distance(_run_level(runner, "measure_parts", mspecs, progress, "distance"),
                                 box_diagonal(lo, hi), unit)
                dist["distance_s"] = time.perf_counter() - t_measure
            t_measure = dist.get("distance_s", 0.0)
        except BaseException:
            if runner is not None:
                runner.close(cancel=True)
                runner = None
            raise
        finally:
            try:
                if runner is not None:
                    runner.close()
            finally:  # a Ctrl-C while the workers leave still removes the temporary folder
                if temporary:
                    shutil.rmtree(folder, ignore_errors=True)
        if manifest.get("dropped"):
            # the way to keep UVs left out by default: for their seams in the in-core run's words (`_wedges`), else
            # the option alone
            left_out = uv == "auto" and manifest.get("uv_in_file") and not manifest.get("uv")
            seams = manifest.get("uv_seam_vertices", 0)
            how = "" if not left_out else f"; {seamed_left_out({'uv': seams})}" if seams else \
                "; attributes='uv' (CLI: --attributes uv) keeps the UVs"
            warnings.warn(f"partition: the output keeps positions{' and UVs' if UV is not None else ''} only; not "
                          f"carried over from the input: {'; '.join(manifest['dropped'])}{how}", stacklevel=stacklevel)
        return _result(V, F, target, n_faces, manifest, levels, dist, locked_share, runner_name(p), t0, t_scatter,
                       t_measure, folder if not temporary else None, kwargs, stacklevel + 1, UV, texture)
    finally:
        if claim is not None:
            _let_go(folder, claim)


def runner_name(p: Partition) -> str:
    return "dask" if p.client is not None else ("this process" if p.n_workers <= 1 else f"{p.n_workers} local processes")


def _wedges(F, UV, manifest, stacklevel, texture=None) -> dict:
    """The result's wedge fields for the output's corners' UVs ``UV`` (None: none), with the material of
    ``texture`` or else of the texture the file names."""
    if UV is None:
        return {}
    from .._io.texture import load as load_texture  # the file's bytes kept, written back as they are

    vertex, uv, corners = task.corner_wedges(F, UV)
    material = None
    if texture is not None:
        material = load_texture(texture)
    elif manifest.get("texture"):
        try:
            material = load_texture(manifest["texture"])
        except ValueError as exc:
            warnings.warn(f"partition: the UVs are kept without their texture: {exc}", stacklevel=stacklevel)
    return dict(uv=uv, wedge_vertex=vertex, wedge_faces=corners, material=material)


def _result(V, F, target, n_faces, manifest, levels, dist, locked_share, where, t0, t_scatter, t_measure, folder,
            kwargs, stacklevel, UV=None, texture=None):
    from .._pipeline.measure import not_measured
    from .._record.result import Contractions, SimplifyResult

    all_stats = [s for lv in levels for s in lv["stats"]]
    per_worker = {}
    for s in all_stats:
        per_worker[s["pid"]] = per_worker.get(s["pid"], 0.0) + s["compile_s"]
    compile_s = max(per_worker.values(), default=0.0)
    total = time.perf_counter() - t0
    final = levels[-1]["stats"]
    if len(final) == 1:  # one group, nothing locked: its own reason (the parity of a closed mesh is "target")
        stop = final[0]["stop_reason"]
    else:
        stop = "target" if len(F) <= target else "locked"
    # the last level's runs that kept UVs (or were given a setting that does) turned off the default's memoryless
    # last stretch (`stages.job`): said once, as an in-core run says it, and not as a reason for stopping; the
    # reason is the runs' own (a task kept before they gave it: its UVs, the one reason such a run then warned)
    from .._pipeline.stages import ATTRIBUTES_KEPT, STRETCH_OFF

    stretch = sorted({m for s in final for m in s["warnings"] if STRETCH_OFF in m})
    off = next((s["late_memoryless_off"] for s in final if s.get("late_memoryless_off")), ATTRIBUTES_KEPT)
    # the groups' reasons, without their own "stopped at N faces, above the target of T: " (the run's warning says it)
    msgs = sorted({re.sub(r"^stopped at \d+ faces, above the target of \d+: ", "", m) for s in final
                   for m in s["warnings"] if STRETCH_OFF not in m})
    part = dict(parts=len(manifest["parts"]), levels=len(levels), where=where,
                faces_per_level=[lv["faces_out"] for lv in levels], groups_per_level=[lv["groups"] for lv in levels],
                locked_per_level=[lv["locked"] for lv in levels], seconds_per_level=[lv["seconds"] for lv in levels],
                cost_per_level=[lv["cost"] for lv in levels], settings_per_level=[lv["settings"] for lv in levels],
                refit_to=levels[-1]["refit_to"],
                locked_share=locked_share, scatter_s=t_scatter, measure_s=t_measure,
                peak_rss_workers=max((s["peak_rss"] for s in all_stats), default=0), peak_rss_client=task.peak_rss(),
                reused=sum(1 for s in all_stats if s.get("reused")), scratch=None if folder is None else str(folder),
                format=manifest.get("format"), welded=manifest.get("welded"),
                carried=all(s.get("carried", False) for s in all_stats), uv=UV is not None)
    stats = dict(faces_in=n_faces, faces_out=int(len(F)), vertices_in=int(manifest["n_vertices"]),
                 degenerate_removed=int(manifest.get("degenerate_removed", 0)),
                 duplicate_removed=int(manifest.get("duplicate_removed", 0)),
                 vertices_out=int(len(V)), target_faces=target, max_error_limit=None, rounds=0, rounds_contracting=0,
                 method=str(kwargs.get("method", "default")), scheduler=str(kwargs.get("scheduler", "parallel")),
                 total_s=total, compile_s=compile_s, run_s=total - compile_s, partition=part,
                 dropped=["record", *manifest.get("dropped", [])], attributes=["uv"] if UV is not None else [],
                 **({"late_memoryless_off": off} if stretch else {}),
                 **({"not_kept_seams": ["uv"]} if manifest.get("uv_seam_vertices") else {}),
                 **(not_measured() | dist))
    if manifest.get("uv") and UV is None:  # the file's UVs were read, a group's run did not keep them
        why = sorted({m for s in all_stats for m in s["warnings"] if "uv" in m.lower()})
        warnings.warn(f"partition: the UVs were read but not kept by the runs: {'; '.join(why) or 'no reason given'}",
                      stacklevel=stacklevel)
    if stretch:
        warnings.warn(stretch[0], stacklevel=stacklevel)
    if locked_share > 0:
        warnings.warn(f"partition: the output is too large for one process (Partition.final_faces), so "
                      f"{100 * locked_share:.2g} % of its vertices stayed locked at part borders", stacklevel=stacklevel)
    if stop not in ("target", "unchanged"):  # "unchanged": nothing to remove (a target at the input's faces)
        warnings.warn(f"partition: stopped at {len(F)} faces, above the target {target} ({stop}: "
                      f"{'; '.join(msgs) or 'the last level could not go further'})", stacklevel=stacklevel)
    if folder is not None:  # a kept scratch folder also keeps what the run did
        pieces.save_json(folder / "stats.json", stats)
    empty = np.zeros(0, np.int64)
    return SimplifyResult(vertices=V, faces=np.asarray(F, np.int64), vertex_error=np.full(len(V), np.nan),
                          max_error=float("nan"), source_vertices=empty, source_faces=empty,
                          input_vertices=np.zeros((0, 3)), input_faces=np.zeros((0, 3), np.int64),
                          history=Contractions(np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0)),
                          stats=stats, stop_reason=stop,
                          **_wedges(np.asarray(F, np.int64), UV, manifest, stacklevel + 1, texture))
