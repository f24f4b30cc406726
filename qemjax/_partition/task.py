"""The two tasks of a partitioned run, as a worker runs them: simplify a group of pieces with the vertices
it shares with other groups locked (`run_group`), and measure level-0 parts' distance from the output
(`measure_parts`). Each reads its inputs from the scratch folder and writes its output there (whole or not at
all), so a task run twice (a retry, a resumed run) gives the same file. Importing this module is light (JAX
and numba are imported by the tasks)."""
from __future__ import annotations

import hashlib
import json
import os
import resource
import time
import warnings
from pathlib import Path

import numpy as np

from . import pieces
from .._mesh.arrays import row_index

# on histograms of the distances, the percentiles: log-spaced bins over the unit frame's extent
HIST_LO, HIST_HI, HIST_BINS = -13.0, 1.0, 4096


def peak_rss() -> int:
    """This process's peak resident memory so far, bytes."""
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _task_key(spec: dict) -> str:
    """What a task is (its inputs, locks, target, settings, ...), as text a resumed run compares. Not whether
    it measures (``measure``): that moves nothing, and a run resumed with another `Partition.measure` (or
    from a folder cut before the last level measured) reuses the output, measured by the parts where its
    stats have no distance (`run`)."""
    what = {k: v for k, v in spec.items() if k != "measure"}
    return hashlib.sha256(repr(sorted(what.items())).encode()).hexdigest()


def _done(out: Path, spec: dict) -> dict | None:
    """The stats of a task whose output is already written (a retry or a resumed run), else None: also when
    a file of that name is there from another task (a resumed run planned otherwise: another version)."""
    meta = out.with_suffix(".json")
    if out.exists() and meta.exists():
        stats = json.loads(meta.read_text())
        if stats.get("task") == _task_key(spec):
            return stats | {"reused": True}
    return None


def _gids_out(res, V, gid, locked) -> np.ndarray:
    """Each output vertex's global id: a locked vertex keeps its own (it is where it was, bit for bit), any
    other gets -1 (no other group holds it). A vertex an ESQEM split added takes its first endpoint's source
    vertex, locked or not: only one at that vertex's exact position is it."""
    src = np.asarray(res.source_vertices)
    if len(res.input_vertices) == len(V) and np.array_equal(res.input_vertices, V):
        return np.where(locked[src] & (np.asarray(res.vertices) == V[src]).all(1), gid[src], -1)
    # the run welded coincident vertices: find the locked ones by their position
    at = row_index(V[locked], res.vertices)
    out = np.full(len(at), -1, np.int64)
    out[at >= 0] = gid[locked][at[at >= 0]]  # (a group with nothing locked: none)
    return out


def corner_wedges(F: np.ndarray, UV: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wedges of triangles F (m,3) whose corners have UVs UV (m,3,2): (each wedge's vertex (w,), its UV
    (w,2), each corner's wedge (m,3)); corners with the same vertex and equal UVs share a wedge, in the
    order of (vertex, u, v) (`_wedges._unique_rows`, as an in-core run orders its wedges): the same for
    the same corners, whatever their order."""
    from .._mesh.wedges import _unique_rows

    key = np.concatenate([F.reshape(-1, 1).astype(np.float64), np.asarray(UV, np.float64).reshape(-1, 2) + 0.0], 1)
    rows, inverse = _unique_rows(key)
    return rows[:, 0].astype(np.int64), rows[:, 1:], inverse.reshape(F.shape)


def _local_edges(E: np.ndarray, gid: np.ndarray) -> np.ndarray:
    """The rows of ``E`` (k,2), global ids, whose two ends this piece holds, as its vertex indices."""
    if not len(gid):
        return np.zeros((0, 2), np.int64)
    order = np.argsort(gid, kind="stable")
    ids = gid[order]
    at = np.minimum(np.searchsorted(ids, E), len(ids) - 1)
    return order[at[(ids[at] == E).all(1)]]


def _with_uv(V: np.ndarray, F: np.ndarray, UV: np.ndarray, locked: np.ndarray, Q: np.ndarray | None):
    """The mesh a group with UVs runs on, as OBJ files store it (a vertex per wedge, `TextureVisuals`; the
    run welds the positions back and keeps the wedges), its locked mask, its vertices and their carried
    quadrics (each vertex's on its first copy, zero on the others: the run's weld adds them up) and each
    vertex's first copy."""
    import trimesh

    vertex, uv, corners = corner_wedges(F, UV)
    mesh = trimesh.Trimesh(V[vertex], corners, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    used, at = np.unique(vertex, return_index=True)
    first = np.full(len(V), -1, np.int64)
    first[used] = at
    if Q is not None:
        Q = np.where((first[vertex] == np.arange(len(vertex)))[:, None], Q[vertex], 0.0)
    return mesh, locked[vertex], V[vertex], Q, first


def run_group(spec: dict) -> dict:
    """Simplify the pieces ``spec["inputs"]`` stitched into one mesh to ``spec["target"]`` faces, locking the
    vertices whose global ids are in ``spec["locks"]`` (a sorted ``.npy`` of this level) or, on the first
    level, those marked ``border``, starting from the quadrics the pieces carry (`carry`); write
    ``spec["out"]`` (with its vertices' quadrics when ``spec["carry_out"]``: a level before the last) and its
    stats beside it (``.json``). ``spec["measure"]``: a last level that fits its output to the input's parts
    (``spec["refit_to"]``) also measures the output's distance from them, with the samples and nearest faces
    its re-fit found (``stats["distance"]``): the client then reads the parts no second time
    (`measure_parts`)."""
    out = Path(spec["out"])
    done = _done(out, spec)
    if done is not None:
        return done
    t0 = time.perf_counter()
    from .._pipeline.api import simplify  # JAX and numba: only in the worker
    from .._pipeline.refit import InputSide
    from .._pipeline.stages import REFIT_TO, SEED
    from .carry import Carry

    side = None
    if spec.get("refit_to"):  # the last level fits its output to the input's parts (`run._refit_to`): they
        # are read, with what the re-fit makes of them alone, on a thread beside this level's own work (its
        # rounds keep one core busy)
        parts = spec["refit_to"]
        side = InputSide(lambda: pieces.stitch(parts)[:2], moves=spec.get("refit_moves", True), thread=True)
    V, F, gid, border, Q = pieces.stitch(spec["inputs"], carried=True)
    UV = pieces.stitch_uv(spec["inputs"]) if spec.get("uv") else None
    keep_edges = None
    if spec["locks"] == "border":
        locked = border
        if spec.get("borders_on_cuts"):
            with np.load(spec["borders_on_cuts"]) as z:
                keep_edges = _local_edges(z["E"], gid)
    elif spec["locks"] is None:
        locked = np.zeros(len(V), bool)
    else:
        locks = np.load(spec["locks"])  # sorted, the whole level's: a binary search per vertex, no hashing
        at = np.minimum(np.searchsorted(locks, gid), max(len(locks) - 1, 0))
        locked = (gid >= 0) & (locks[at] == gid) if len(locks) else np.zeros(len(V), bool)
    kw = dict(spec["kwargs"])
    mesh, mask, Vc = (V, F), locked, V
    if UV is not None:  # kept UVs: the run keeps the wedges, seams and all, and a locked vertex its UVs
        mesh, mask, Vc, Q, first = _with_uv(V, F, UV, locked, Q)
        if keep_edges is not None:
            keep_edges = first[keep_edges]
    if mask.any():
        kw["locked"] = mask
    carry = kw[SEED] = Carry(Vc, Q, spec["unit"], exports=bool(spec.get("carry_out")), boundary=keep_edges)
    if side is not None:
        kw[REFIT_TO] = side
    Q = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = simplify(mesh, target_faces=int(spec["target"]), measure=bool(spec.get("measure")), progress=False,
                       attributes=None if UV is None else "uv", **kw)
    g = _gids_out(res, V, gid, locked)
    held = np.unique(g[g >= 0])
    Q = carry.export(res)
    extra = {} if Q is None else dict(Q=Q)
    if res.uv is not None:
        extra["UV"] = res.uv[res.wedge_faces]
    pieces.save(out, V=res.vertices, F=res.faces.astype(np.int32), gid=g, borders=held, **extra)
    stats = dict(faces_in=int(len(F)), faces_out=int(len(res.faces)), target=int(spec["target"]),
                 locked=int(locked.sum()), vertices_in=int(len(V)), stop_reason=res.stop_reason,
                 carried=carry.carried,
                 max_error=float(res.max_error),
                 seconds=time.perf_counter() - t0, compile_s=float(res.stats.get("compile_s") or 0.0),
                 peak_rss=peak_rss(), pid=os.getpid(),
                 warnings=sorted({str(w.message) for w in caught}), task=_task_key(spec))
    if res.stats.get("late_memoryless_off"):  # why the run stayed summed (the run's stats say it, `run._result`)
        stats["late_memoryless_off"] = res.stats["late_memoryless_off"]
    if spec.get("measure"):  # measured against the surface the re-fit fitted to: the input's parts
        from .._pipeline.measure import KEYS
        stats["distance"] = {k: res.stats[k] for k in KEYS if not k.endswith("_rel")}  # the client's diagonal: `run`
    pieces.save_json(out.with_suffix(".json"), stats)
    return stats


def measure_parts(spec: dict) -> dict:
    """The distances of level-0 parts' samples (every vertex, a third of its faces' area each, and every face
    centroid, its area: `_pipeline.refit.samples` before scaling, so that the weights of a vertex two parts
    hold add up to its weight in the whole) from the output ``spec["final"]``, exactly: for each part the
    output is cropped to the part's box grown by a margin, and searched whole where a distance exceeds the
    margin. Returns, over the parts ``spec["parts"]``, the maximum, the weighted sum of squares, the total
    weight, a weighted histogram, the samples counted and the global ids of the vertex samples on parts'
    borders (``shared``, not counted: the client counts each once)."""
    from .._mesh.grid_nearest import nearest
    from .._pipeline.refit import _sample_rows

    with np.load(spec["final"]) as z:
        X, G = z["V"], z["F"].astype(np.int64)
    centre, unit = np.asarray(spec["centre"]), float(spec["unit"])
    Xu = (X - centre) / unit
    T = Xu[G]
    flo, fhi = T.min(1), T.max(1)  # each output face's box, once for all the parts
    del T
    edges = np.logspace(HIST_LO, HIST_HI, HIST_BINS + 1)
    # hist[0]: the weight at distance 0 exactly (an unchanged surface), hist[1 + i]: in bin i of ``edges``
    out = dict(max=0.0, sum_sq=0.0, weight=0.0, hist=np.zeros(HIST_BINS + 2), samples=0)
    shared = []  # the global ids of the sampled vertices other parts also hold: counted once, by the client
    for part in spec["parts"]:
        V, F, gid, border = pieces.load(part)
        P, w, _ = _sample_rows((V - centre) / unit, F, np.zeros(len(V), np.int64))
        keep = w > 0
        if border is not None:
            held = keep[:len(V)] & border
            shared.append(gid[held])
            out["samples"] -= int(np.count_nonzero(held))
        P, w = P[keep], w[keep]
        if not len(P):
            continue
        lo, hi = P.min(0), P.max(0)
        margin = 0.02
        while True:  # exact when every distance is within the margin the crop was grown by
            sel = np.flatnonzero(np.all(flo <= hi + margin, axis=1) & np.all(fhi >= lo - margin, axis=1))
            d = nearest(Xu, G[sel], P)[1] if len(sel) else None
            if len(sel) == len(G) or (d is not None and d.max() <= margin):
                break
            margin = max(2 * float(d.max()), 4 * margin) if d is not None else 4 * margin
        out["max"] = max(out["max"], float(d.max()) * unit)
        out["sum_sq"] += float(np.sum(w * d * d)) * unit * unit
        out["weight"] += float(w.sum())
        out["hist"] += np.bincount(np.where(d > 0, np.clip(np.searchsorted(edges, d), 0, HIST_BINS) + 1, 0),
                                   weights=w, minlength=HIST_BINS + 2)
        out["samples"] += int(len(P))
    out["hist"] = out["hist"].tolist()
    return out | dict(shared=np.unique(np.concatenate(shared)) if shared else np.zeros(0, np.int64),
                      peak_rss=peak_rss())
