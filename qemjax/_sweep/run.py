"""Parameter sweeps: meshes × a grid of `simplify` keywords × targets, one table row per cell.

A pipeline of small stages: name and load the meshes (once each), cross the grid into cells, drop the
cells already in ``out`` (resume), cut the rest into pieces (`pieces`) and run them on this process and its
helper processes (`pool`; or in batches on an executor), write the table as rows come in (table.py), keep
every finished row on Ctrl-C. A piece of cells runs through `simplify_cells`: the cells that can share rounds
(of one mesh or several) run as one disjoint union of copies, the rest alone; either way each cell's mesh is
the one `simplify` gives alone (tested), in whichever process it ran.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import itertools
import json
import math
import numbers
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .. import _costs, shapes
from .._pipeline import flat as _flat
from .._io import mesh as _io
from .._costs.base import Method
from .._pipeline.api import iter_cells, simplify
from .._options import Attributes, Schedule, Topology
from .table import (FORMATS, NOT_APPLICABLE, _check_writable, _format, _typed, as_text,  # noqa: F401
                    holding, read_table, read_text, target_column, write_table, write_text)

# a grid varies the run keywords of `simplify` and every setting by its flat or dotted name
# (`_flat.grid_keys`); not the target (that is `targets`), progress (the sweep's own) or feature edges
# (per-mesh index arrays, not a setting)


def is_grid_key(key: str) -> bool:
    """Whether a grid may vary ``key``: a run keyword, a setting's flat name or a dotted field name."""
    try:
        _flat.key_type(key)
    except KeyError:
        return False
    return True


BATCH_CELLS = 128  # a piece holds at most this many cells
PIECE_FACES = 1 << 17  # a piece's distinct runs hold at most this many faces in all (a mesh larger than that:
# a piece of its own): a few seconds of work at most, so rows reach the file and the bar as pieces finish,
# and the union of copies within the compiled rounds' size (`selection.MAX_FACES`)
PIECE_RUNS = 16  # and at most this many distinct runs: 64 configurations of the cow are 4 pieces (larger
# pieces share more of each round, but fewer of them leave cores idle: docs/sweeps.md, "Every core")
PLAN_FACES = 200_000  # meshes up to this size are planned (`pieces`); a larger one's cells run one per piece (the
# planning reads and cleans each mesh and builds its vertex states once more than the run does)
RING_COST = 4  # a run whose model prices pairs from their faces (``regularize``) costs about this many plain ones
# A default sweep's helper processes (`_helpers`), in the work of its distinct runs (`Piece.work`: faces, a ring
# model's RING_COST times; SWEPT_WORK is about a second of work in one process). A helper's start (a fresh
# Python importing JAX and loading the compiled kernels) costs a core about half of START_WORK: a sweep
# finding helpers started uses them for any work of two pieces or more; one that must start them does so
# from START_WORK on (they pay back within it), or once this process's earlier default sweeps add up to
# SWEPT_WORK (a process that sweeps again and again: the helpers join this sweep as they come up and serve
# the next ones; a script of one small sweep never starts them)
START_WORK = 1_600_000
SWEPT_WORK = 200_000
WORKERS_ENV = "QEMJAX_WORKERS"  # the default of ``workers`` when set (an integer >= 1)
HERE_TOO = True  # this process runs pieces too (beside its helpers)
_SWEPT = [0.0]  # the work of this process's default sweeps so far
SAVE_EVERY_S = 1.0  # the table is rewritten after each piece run here, and while rows come in at most this often
RETRIES = 3  # an executor task that is lost (a worker died) is submitted again this many times, then run here
EXECUTOR_BATCH = 1  # cells per task on an executor, by default: one (balances the workers best: experiments/figures/dask_speedup.py)
PEER_NAMES = ("meshoptimizer", "pymeshlab", "fast-simplification", "libigl", "pyfqmr")  # = qemjax.peers.PEERS
MESH_HASH = "mesh_sha256"  # the column of each row's input mesh fingerprint (`mesh_hash`)
METRICS_SETTINGS = "metrics_settings"  # the column of what each row's metrics were measured with
_FIRST = ("cell", "mesh")  # leading columns; then the grid keys, "target", results, metrics


@dataclasses.dataclass(frozen=True)
class Cell:
    """One configuration: a mesh (by name), ``params`` (grid key → value, in grid order) and a target (a
    ratio in (0, 1) or a face count)."""

    mesh: str
    params: tuple[tuple[str, Any], ...]
    target: float | int

    @property
    def key(self) -> str:
        """Stable identity across runs and processes: canonical JSON of mesh, sorted parameters, target."""
        return json.dumps([self.mesh, sorted((k, _plain(v)) for k, v in self.params), self.target],
                          default=_json_value)

    def kwargs(self) -> dict:
        target = {"ratio": self.target} if isinstance(self.target, float) else {"target_faces": self.target}
        return {**dict(self.params), **target}


def _json_value(value):
    """What JSON cannot write in a grid value: numpy numbers and arrays as numbers and lists, anything else
    (a PIL image given as ``texture``) by its repr."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return repr(value)


def _plain(value):
    """A grid value as JSON/table data: a method object by its label (`_costs.label`:
    ``esqem(curvature_weight=0.1)``, ``default``), Schedules, Topology and Attributes objects (frozen
    dataclasses) by their repr."""
    if isinstance(value, Method):
        return _costs.label(value)
    if isinstance(value, (Schedule, Topology, Attributes)):
        return repr(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def _shape(value):
    """The `shapes.ShapeSpec` a mesh input names (``"shapes.torus"``, ``"shapes.bumpy_sphere(subdivisions=4)"``),
    or None for anything else (a file of that name is a file). ValueError for an unknown shape."""
    if isinstance(value, str) and shapes.is_spec(value) and not Path(value).is_file():
        return shapes.parse_spec(value)
    return None


def _name(value, i: int) -> str:
    spec = _shape(value)
    if spec is not None:
        return spec.name
    return Path(value).stem if isinstance(value, (str, os.PathLike)) else f"mesh{i}"


def load_mesh(value):
    """A mesh input as `simplify` reads it, in a form that pickles (helpers and executors get it): a shape
    named as text made in code; a file or trimesh with appearance attributes a run may keep (UVs, colours,
    stored normals) as a trimesh of them (`_io.portable`); else its arrays (`_io.as_arrays`)."""
    spec = _shape(value)
    if spec is not None:
        try:
            return _io.as_arrays(spec.build())
        except ValueError as exc:  # a shape that makes no mesh: which one
            raise ValueError(f"{value}: {exc}") from None
    mesh, _, tm = _io._as_arrays(value, keep_trimesh=True)
    kept = _io.portable(tm, *mesh) if tm is not None else None
    return mesh if kept is None else kept


def name_meshes(meshes) -> dict[str, Any]:
    """name → mesh input: a path (named by its stem), a shape made in code (``"shapes.NAME"`` or
    ``"shapes.NAME(key=value, ...)"``, named NAME), a list of these or of meshes, a dict name → mesh, or
    one mesh (``(V, F)``, `Mesh`, trimesh). Unnamed meshes are ``mesh0``, ``mesh1``, … Unknown shapes
    raise ValueError."""
    if isinstance(meshes, dict):
        named = {str(k): v for k, v in meshes.items()}
        for v in named.values():
            _shape(v)  # an unknown shape fails here, before anything runs
    else:
        single = isinstance(meshes, (str, os.PathLike)) or hasattr(meshes, "vertices") or (
            isinstance(meshes, tuple) and len(meshes) == 2 and _coordinates(meshes[0]))
        items = [meshes] if single else list(meshes)
        names = [_name(m, i) for i, m in enumerate(items)]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"two meshes have the same name {dup}: pass a dict name → mesh")
        named = dict(zip(names, items))
    if not named:
        raise ValueError("meshes is empty")
    return named


def _coordinates(value) -> bool:
    """Whether ``value`` reads as a table of numbers, the vertices of a ``(vertices, faces)`` pair; a pair of
    meshes (two `Mesh` objects, two ``(V, F)`` pairs, two paths) holds meshes there instead."""
    if isinstance(value, (str, os.PathLike)) or hasattr(value, "vertices"):
        return False
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):  # ragged: a (V, F) pair's two arrays
        return False
    return a.ndim == 2 and (a.dtype.kind in "biuf" or a.dtype == object)  # numbers held as objects: pandas' .values


def expand_grid(grid: dict, collapsed: dict | None = None) -> list[tuple[tuple[str, Any], ...]]:
    """The cross product of ``grid`` (keyword → list of values; a non-list value is one value), in
    order: the last key varies fastest; a method setting is left out of the cells whose method does not
    have it (`_applicable`: "n/a" in their rows), and cells that are then alike are kept once. Unknown
    keywords raise ValueError naming them. ``collapsed``: a dict that gets, for each reason (``"split_factor
    does not apply to method 'qem'"``), how many configurations of the full cross product it removed."""
    if not isinstance(grid, dict):
        raise ValueError(f"grid must be a dict of simplify keywords → lists of values, got {type(grid).__name__}")
    unknown = [k for k in grid if not is_grid_key(k)]
    if unknown:
        why = "; targets go in `targets`" if set(unknown) & {"target_faces", "ratio"} else ""
        hint = _flat.did_you_mean(unknown[0], _flat.grid_keys())
        raise ValueError(f"unknown grid keys {unknown}{why}{hint}; a grid may vary {list(_flat.grid_keys())} "
                         "or a field by its dotted name ('method.curvature_weight')")
    axes = []
    for k, values in grid.items():
        values = list(values) if isinstance(values, (list, tuple, range, np.ndarray)) else [values]
        if not values:
            raise ValueError(f"grid[{k!r}] is empty")
        texts = [_value_text(v) for v in values]
        if len(set(texts)) < len(texts):
            twice = next(v for v, t in zip(values, texts) if texts.count(t) > 1)
            raise ValueError(f"grid[{k!r}] repeats the value {twice!r}: two cells would be the same")
        axes.append([(k, v) for v in values])
    out, seen = [], set()
    for full in itertools.product(*axes):
        combo = _applicable(full)
        key = json.dumps([(k, _plain(v)) for k, v in combo], default=_json_value)
        if key not in seen:  # crossing a method without a setting with that setting's values: once
            seen.add(key)
            out.append(combo)
        elif collapsed is not None:
            why = _why_collapsed(full, combo)
            collapsed[why] = collapsed.get(why, 0) + 1
    return out


def _value_text(value) -> str:
    """A grid value's text for spotting a value given twice: its JSON, a number by its value (``1`` and ``1.0``
    set the same; a bool is no number here)."""
    value = _plain(value)
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        value = float(value)
    return json.dumps(value, default=_json_value)


def _why_collapsed(full: tuple, combo: tuple) -> str:
    """Why a configuration fell together with another: the keys `_applicable` left out, and for what method."""
    gone = [k for k, _ in full if k not in dict(combo)]
    method = dict(full).get("method", dict(full).get("preset") or _costs.DEFAULT)
    label = _plain(method) if not isinstance(method, str) else method
    if isinstance(method, str) and method in PEER_NAMES:
        return f"{', '.join(gone)} {'does' if len(gone) == 1 else 'do'} not apply to the peer {label!r}"
    return f"{', '.join(gone)} {'does' if len(gone) == 1 else 'do'} not apply to method {label!r}"


def _applicable(combo: tuple) -> tuple:
    """A cell's parameters without the method settings its method does not have (a peer: none; a grid that crosses
    ``method = ["qem", "esqem"]`` with ``split_factor`` gives the qem cells no split factor: "n/a" in the
    table, and one cell instead of one per value). Settings the method has, and the rest, stay."""
    params = dict(combo)
    if isinstance(params.get("method"), str) and params["method"] in PEER_NAMES:
        return (("method", params["method"]),)  # a peer: no setting of qemjax's applies
    table = _flat.options()
    try:
        method = _costs.resolve(params.get("method", params.get("preset") or _costs.DEFAULT))
    except ValueError:
        return combo  # simplify reports the bad method, per cell
    have = {f.name for f in dataclasses.fields(method)}

    def applies(key: str) -> bool:
        group, dot, field = key.partition(".")
        if dot:
            return group != "method" or field in have
        return key not in table or table[key].group != "method" or key in have

    return tuple((k, v) for k, v in combo if applies(k))


def check_targets(targets) -> list[float | int]:
    """Ratios (floats in (0, 1)) and face counts (ints ≥ 1), none twice; a single number is one target."""
    targets = list(targets) if isinstance(targets, (list, tuple, range, np.ndarray)) else [targets]
    if not targets:
        raise ValueError("targets is empty")
    out = []
    for t in targets:
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, numbers.Real):
            raise ValueError(f"bad target {t!r}: give ratios as floats in (0, 1) or face counts as ints")
        if isinstance(t, numbers.Integral):
            if t < 1:
                raise ValueError(f"bad target {t!r}: a face count must be an int >= 1")
            out.append(int(t))
        elif not (0 < t < 1):
            raise ValueError(f"bad target {t!r}: a ratio must be a float in (0, 1) (face counts are ints)")
        else:
            out.append(float(t))
        if out[-1] in out[:-1]:  # here, so that a config file's check names it (and the file) before any run
            raise ValueError(f"targets repeat the value {out[-1]!r}: two cells would be the same")
    return out


def result_hash(res) -> str:
    """sha256 of the output's vertices (float64) and faces (int64): equal meshes, equal hashes."""
    h = hashlib.sha256(np.ascontiguousarray(res.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(res.faces, np.int64).tobytes())
    return h.hexdigest()


def mesh_hash(mesh) -> str:
    """A mesh input's fingerprint (`result_hash` of the vertices and faces `load_mesh` gives): a table's
    ``mesh_sha256``, which a resumed sweep checks its meshes against."""
    return result_hash(mesh)


def _stored_meshes(table) -> dict[str, set]:
    """mesh name → the fingerprints (``mesh_sha256``) a sweep table's rows hold for it; tables written before
    the column existed hold none."""
    if not len(table) or MESH_HASH not in table:
        return {}
    out: dict[str, set] = {}
    for name, value in zip(table["mesh"], table[MESH_HASH]):
        if isinstance(value, str) and value:
            out.setdefault(str(name), set()).add(value)
    return out


def _peer(cell: Cell) -> str | None:
    """The peer a cell's ``method`` names (`qemjax.peers.PEERS`), else None."""
    method = dict(cell.params).get("method")
    return method if isinstance(method, str) and method in PEER_NAMES else None


def _simplify_cell(mesh, cell: Cell):
    """The single dispatch point: a peer's `qemjax.peers.simplify` of the cleaned input a qemjax cell runs on
    (welded, degenerate and duplicate faces removed; the target resolved as `simplify` does; the cell's
    other grid keys do not apply: NaN in its row), else `simplify`."""
    name = _peer(cell)
    if name is None:
        return simplify(mesh, **cell.kwargs())
    from .. import peers

    with warnings.catch_warnings():  # what the peer does not keep: its row is positions and faces
        warnings.simplefilter("ignore")
        clean, _ = _io.prepare(mesh, attributes=None)  # the input a qemjax cell runs on, cleaned alike
    m = len(clean.faces)
    target = max(1, int(round(cell.target * m))) if isinstance(cell.target, float) else cell.target
    return peers.simplify(name, clean, target)


def run_cell(mesh, cell: Cell, metrics) -> dict:
    """One row, from `simplify` alone (see `row`). A failing `simplify` gives a row with ``error`` set."""
    try:
        res = _simplify_cell(mesh, cell)
    except Exception as exc:  # one bad combination must not stop a sweep: the row says why
        res = exc
    return row(mesh, cell, res, metrics)


def iter_rows(items: list, metrics):
    """The rows of cells, items = [(mesh, `Cell`)], one at a time as each is final: computed together by
    `simplify_cells` (its `iter_cells`: each result equals `simplify`'s alone; cells of several meshes may
    share rounds; each cell or shared batch yields its rows when its run ends), then each row's metrics. If the batch fails as a whole, each cell runs alone, so the rows say which
    configuration fails and why. Peers and a batch of one run alone."""
    if len(items) == 1 or any(_peer(c) for _, c in items):  # peers run alone (`qemjax.peers`)
        for mesh, c in items:
            yield run_cell(mesh, c, metrics)
        return
    done = set()
    try:  # each cell as soon as its run ends: a cell alone when it ends, a shared batch when it ends
        for i, r in iter_cells([(mesh, c.kwargs()) for mesh, c in items], errors=True):
            done.add(i)
            yield row(items[i][0], items[i][1], r, metrics)
    except Exception:  # noqa: BLE001 - rerun alone: the failing cell's row will carry its error
        for i, (mesh, c) in enumerate(items):
            if i not in done:
                yield run_cell(mesh, c, metrics)


def run_cells(items: list, metrics) -> list[dict]:
    """`iter_rows` as a list: an executor's task (one per batch)."""
    return list(iter_rows(items, metrics))


def _measured(x) -> float:
    """A measured distance for a row (NaN: not measured)."""
    return math.nan if x is None else float(x)


def row(mesh, cell: Cell, res, metrics) -> dict:
    """A cell's row: parameters, counts, stop reason, timings, output hash, metrics (``metrics``: False, or
    a dict of `qemjax.metrics.evaluate` keywords); ``res`` is the `SimplifyResult` or the exception
    `simplify` raised (then only ``error`` is set). Timings (see `sweep`): a cell that ran alone has its own
    ``compile_s``, ``run_s``, ``total_s``; a cell that shared its rounds with others (``batch_size`` > 1)
    has them empty (not measured) and its apportioned ``share_s`` of the shared run's ``batch_wall_s``."""
    peer = _peer(cell)  # a peer's row: the grid keys other than method do not apply ("n/a", filled by `sweep`)
    out = {"cell": cell.key, "mesh": cell.mesh,
           **{k: _plain(v) if peer is None or k == "method" else NOT_APPLICABLE for k, v in cell.params},
           "target": cell.target, "error": ""}
    if isinstance(res, Exception):
        out["error"] = f"{type(res).__name__}: {res}"
        return out
    s = res.stats
    batch = s.get("batch", {})
    size = batch.get("size", 1)
    out.update(faces_in=s["faces_in"], faces_out=s["faces_out"], target_faces=s["target_faces"],
               stop_reason=res.stop_reason, rounds=s["rounds"], batch_size=size,
               same_run=batch.get("same_run", 1), result_sha256=result_hash(res),
               distance_max=_measured(s.get("distance_max")), distance_rms=_measured(s.get("distance_rms")),
               distance_two_way_max=_measured(s.get("distance_two_way_max")))
    if size > 1:  # rounds shared with size - 1 other cells: its own time was not measured
        wall = float(batch["total_s"])
        # its re-fit and distance measurement ran on their own (side by side)
        share = wall / size + float(s.get("refit_s", 0.0)) + float(s.get("distance_s") or 0.0) + \
            float(s.get("max_distance_s") or 0.0)  # a max_distance search, also its own
        out.update(compile_s=math.nan, run_s=math.nan, total_s=math.nan,
                   batch_wall_s=wall, share_s=share)
    else:
        out.update(compile_s=s["compile_s"], run_s=s["run_s"], total_s=s["total_s"], batch_wall_s=s["total_s"],
                   share_s=s["total_s"])
    metrics_s = 0.0
    if metrics is not False:
        from ..metrics import evaluate

        got = evaluate(mesh, res, target_faces=s["target_faces"], **metrics)
        metrics_s = got.pop("time_s")
        out.update(got)
        out["metrics_s"] = metrics_s
    out["cell_s"] = out["share_s"] + metrics_s
    return out


@dataclasses.dataclass
class Piece:
    """Cells that run together (one `run_cells` call: `simplify_cells`), and an estimate of their work (the
    faces of their distinct runs, a ring model's `RING_COST` times)."""

    cells: list
    work: float


def pieces(cells: list[Cell], loaded: dict, faces: dict) -> list[Piece]:
    """The cells cut into pieces, in this order: each group of cells that can share rounds (`api.plan_cells`:
    the same kernels, flip angle, topology mode and schedule, of any mesh), in the order of its first cell,
    cut into pieces of about equal work, each of at most `PIECE_FACES` faces and `PIECE_RUNS` distinct runs
    and `BATCH_CELLS` cells; the cells that would run exactly alike (a closed mesh's boundary weights) stay in
    one piece, where they run once. The cut depends on the cells alone, never on how many processes run
    them: the same pieces, the same rows (``batch_size``, ``same_run``). Peer cells, cells of meshes over
    `PLAN_FACES` faces and cells that cannot share rounds are runs of their own."""
    from .._pipeline.api import plan_cells

    planned = [i for i, c in enumerate(cells) if _peer(c) is None and faces[c.mesh] <= PLAN_FACES]
    plan = dict(zip(planned, plan_cells([(loaded[cells[i].mesh], cells[i].kwargs()) for i in planned])))
    groups: dict = {}  # group -> run -> [cell indices], each in order of first appearance
    cost: dict = {}  # (group, run) -> its work
    for i, c in enumerate(cells):
        if i in plan and plan[i][0] is not None:
            group, run, f, ring = plan[i]
            group = ("batch", group)
        elif i in plan:  # runs alone (another scheduler, a method that splits, a bad configuration)
            group, run, f, ring = ("alone", c.mesh), ("cell", i), plan[i][2], plan[i][3]
        else:
            group, run, f, ring = ("alone", c.mesh), ("cell", i), faces[c.mesh], False
        groups.setdefault(group, {}).setdefault(run, []).append(i)
        cost[group, run] = max(f, 1) * (RING_COST if ring else 1)
    out = []
    for group, runs in groups.items():
        units = []  # (cells, faces, work) per run; a run of more than BATCH_CELLS cells is split
        for run, idx in runs.items():
            f = faces[cells[idx[0]].mesh]
            for k in range(0, len(idx), BATCH_CELLS):
                units.append((idx[k:k + BATCH_CELLS], f, cost[group, run]))
        out += [Piece([cells[i] for u in part for i in u[0]], sum(u[2] for u in part)) for part in _cut(units)]
    return out


def _cut(units: list) -> list[list]:
    """Runs (cells, faces, work) in order, cut into the fewest contiguous parts of about equal work that keep
    every part within `PIECE_FACES` faces (or one run), `PIECE_RUNS` runs and `BATCH_CELLS` cells."""
    total = sum(u[2] for u in units) or 1.0
    n = max(1, math.ceil(sum(u[1] for u in units) / PIECE_FACES), math.ceil(len(units) / PIECE_RUNS))
    while True:
        parts: list = [[] for _ in range(n)]
        before = 0.0
        for u in units:  # each run to the part its work's midpoint falls in
            parts[min(n - 1, int((before + u[2] / 2) / total * n))].append(u)
            before += u[2]
        parts = [p for p in parts if p]
        if n >= len(units):
            return [[u] for u in units]
        if all(len(p) == 1 or (sum(u[1] for u in p) <= PIECE_FACES and len(p) <= PIECE_RUNS
                                                  and sum(len(u[0]) for u in p) <= BATCH_CELLS) for p in parts):
            return parts
        n += 1


def batches(cells: list[Cell], size: int) -> list[list[Cell]]:
    """Cells, in order, cut into batches of ``size`` cells (the last one fewer): ``batch_size``'s cut."""
    return [cells[k:k + size] for k in range(0, len(cells), size)]


def _submitter(executor):
    """A function (fn, *args) → concurrent.futures.Future: a `concurrent.futures.Executor` as is, a
    `dask.distributed.Client` through its executor view."""
    if isinstance(executor, concurrent.futures.Executor):
        return executor.submit
    if type(executor).__module__.startswith("distributed") and hasattr(executor, "get_executor"):
        return executor.get_executor(pure=False).submit
    raise ValueError("executor must be a concurrent.futures.Executor or a dask.distributed.Client, got "
                     f"{type(executor).__name__}")


def _ship(executor, loaded: dict) -> dict:
    """What each cell's task gets as its mesh: the arrays, or with a dask Client a future of them,
    scattered to every worker once, so a mesh crosses the network once per worker, not once per cell."""
    if type(executor).__module__.startswith("distributed") and hasattr(executor, "scatter"):
        return {name: executor.scatter([arrays], broadcast=True, hash=False)[0] for name, arrays in loaded.items()}
    return loaded


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a sweep: every finished row is in ``out``; the message says how many (``qemjax sweep``
    prints it and exits 130). A rerun with the same ``out`` resumes."""


def metrics_settings(metrics) -> str:
    """What a row's metrics were measured with, as its ``metrics_settings`` text: ``"false"`` for none, else
    the JSON of every keyword `qemjax.metrics.evaluate` took (``metrics``' own and the defaults, sorted), so
    ``True`` and ``{"n_samples": 100000}`` are alike. A resumed sweep checks its rows against it."""
    import inspect

    from ..metrics import evaluate

    if metrics is False:
        return "false"
    taken = {p.name: p.default for p in inspect.signature(evaluate).parameters.values()
             if p.kind is p.KEYWORD_ONLY and p.name != "target_faces"}
    return json.dumps({**taken, **metrics}, sort_keys=True, default=_json_value)


def _metrics_words(settings: str) -> str:
    """`metrics_settings`' text for an error line: ``none (metrics=False)``, or ``n_samples=100, seed=0``."""
    if settings == "false":
        return "none (metrics=False)"
    try:
        return ", ".join(f"{k}={v!r}" for k, v in json.loads(settings).items())
    except (ValueError, AttributeError):  # a file's text that is no JSON table: as it is
        return settings


def _check_metrics(metrics: dict) -> None:
    """ValueError for a ``metrics`` keyword `qemjax.metrics.evaluate` does not take, or a bad value of one
    (before anything runs)."""
    import inspect

    from ..metrics import evaluate

    takes = [p.name for p in inspect.signature(evaluate).parameters.values()
             if p.kind is p.KEYWORD_ONLY and p.name != "target_faces"]  # the cell's own target
    bad = [k for k in metrics if k not in takes]
    if bad:
        raise ValueError(f"metrics: unknown keyword {bad[0]!r}; metrics.evaluate takes {', '.join(takes)}")
    from ..metrics._distance import _check_samples

    for k in ("n_samples", "seed"):  # their values too: else the first cells' runs would be lost to the error
        if k in metrics:
            try:
                _check_samples(metrics[k], k)
            except ValueError as exc:
                raise ValueError(f"metrics: {exc}") from None


def sweep(meshes, grid: dict, targets, *, metrics=True, executor=None, out=None, progress: bool = True,
          batch_size: int | None = None, workers: int | None = None):
    """Run every (mesh, grid configuration, target) cell with `qemjax.simplify`; a pandas DataFrame, one
    row per cell.

    meshes: a path, a list of paths or meshes, a dict name → mesh, or one mesh (``(V, F)``, `Mesh`);
        a mesh made in code may be named as text, ``"shapes.torus"`` or
        ``"shapes.bumpy_sphere(subdivisions=4)"`` (`qemjax.shapes.parse_spec`: keyword arguments with
        literal values, never evaluated). Paths are named by their stem, shapes by their name, other
        meshes ``mesh0``, ``mesh1``, … Each is read (or made) once.
    grid: `simplify` keywords → lists of values, crossed (e.g. ``{"method": ["qem", "esqem"],
        "regularize": [0, 0.1]}``). A method setting crossed with a method that does not have it (e.g.
        ``split_factor`` with ``qem``) is "n/a" in that method's rows, and the cells that then fall together
        run once: a warning (and ``df.attrs["sweep"]["collapsed"]``) says how many and why. A ``method`` that
        names a peer (``"meshoptimizer"``, ``"pymeshlab"``, ``"fast-simplification"``, ``"libigl"``,
        ``"pyfqmr"``: `qemjax.peers`, ``pip install 'qemjax[bench]'``) runs that peer for the cell, warm,
        alone, with the same metrics; the other grid keys do not apply to it ("n/a"; one cell per peer,
        mesh and target), ``stop_reason`` is ``"peer"``, ``rounds`` NaN, ``compile_s`` 0, ``run_s`` =
        ``total_s`` = the peer call's time. A missing peer package: the row's ``error`` says so.
    targets: ratios (floats in (0, 1)) and/or face counts (ints).
    metrics: True: every column of `qemjax.metrics.evaluate` (original = the mesh as given); a dict:
        the same with these keywords to `evaluate` (e.g. ``{"n_samples": 10_000}``); False: none.
    executor: None (the cells run in pieces on this process and its helper processes: ``workers``), a
        `concurrent.futures.Executor` or a `dask.distributed.Client`: one task per batch. A task that is lost
        (its worker died) is submitted again (`RETRIES` times), then run in this process.
    workers: the processes that run the pieces, this one included: 1 runs them all here; N also starts
        N − 1 helper processes (`qemjax._sweep.pool`: fresh Pythons, never forked, started once and kept
        for the process's later sweeps); every process takes the next piece, largest first, as it is
        free, so the helpers join as they come up. None (default; ``$QEMJAX_WORKERS`` overrides it): every
        core this process may use when helpers are started already or the sweep's work is large enough to
        pay for starting them (`START_WORK`: a few seconds of work) or the process's earlier default sweeps
        add up to some work (`SWEPT_WORK`), else this process alone. The table does not depend on it
        (but for the timings): the pieces are cut from the cells alone (`pieces`). Not with ``executor``.
    out: a ``.parquet`` (needs pyarrow: ``pip install 'qemjax[sweep]'``) or ``.csv`` path, rewritten
        (temporary file, fsync, rename) as cells finish: after each piece run here (a few seconds of work at
        most: `PIECE_FACES`), while a piece yields rows and as a helper's pieces come in, at most every
        `SAVE_EVERY_S`; on an executor as tasks end, at most every `SAVE_EVERY_S` and within it of a row
        coming in. Rows in row order (the rows of other grids already in the file first). Cells whose key
        is already there without an error are not run again (an interrupted sweep resumes; a CSV's rows
        already there are written back as the same text); rows of other cells in the file are kept. One sweep
        at a time writes it: another sweep given the same ``out`` meanwhile is refused (ValueError). Ctrl-C
        writes every finished row and raises `SweepInterrupted` (a KeyboardInterrupt) saying how many.
    progress: a tqdm bar counting cells, moving as each cell's row is final; a line saying how many cells
        were already in ``out`` (skipped) and a warning about collapsed cells.
    batch_size: at most this many cells per batch, cut in cell order (`simplify_cells`: cells that can
        share rounds, of one mesh or several, run together as one disjoint union of copies); None: without
        an executor, the pieces of `pieces` (cells that can share rounds together, each piece within
        `PIECE_FACES` faces, `PIECE_RUNS` distinct runs and `BATCH_CELLS` cells, cells that run alike in one
        piece); on an executor, `EXECUTOR_BATCH`. 1: every cell alone (then every cell's timings are its
        own, measured).

    Columns: ``cell`` (the key: JSON of mesh, sorted parameters, target), ``mesh``, one per grid key ("n/a"
    where the cell's method does not have that setting; empty/NaN is None), ``target`` (as given: face
    counts stay ints beside ratios), ``error`` (empty, or why `simplify` raised), ``faces_in``,
    ``faces_out``, ``target_faces``, ``stop_reason``, ``rounds``, ``batch_size`` (the cells its run
    shared rounds with, itself included; 1: alone), ``same_run`` (the cells that got the very same run,
    itself included: cells whose settings make no difference on this mesh, such as ``boundary_weight`` on
    a closed one, run once), ``result_sha256`` (of the output vertices and faces), ``distance_max`` and
    ``distance_rms`` (the output's measured distance from the input, mesh units: `simplify`'s stats of those
    names; NaN where not measured: ``measure=True`` in the grid measures it for every method),
    ``distance_two_way_max`` (the checked two-way distance of a cell with ``max_distance`` or
    ``max_distance_rel`` in the grid, NaN otherwise); timings in seconds:
    ``compile_s``, ``run_s``, ``total_s`` (the cell's own `simplify` stats: JAX's and numba's compilation,
    the rest, all; measured when it ran alone, ``batch_size`` 1; empty when it shared its rounds:
    not measured), ``batch_wall_s`` (the wall time of the run that computed it: the shared rounds of its
    batch, or its own ``total_s``), ``share_s`` (apportioned: ``batch_wall_s / batch_size`` plus its own
    re-fit and distance measurement, or its own ``total_s``); then the metrics (`qemjax.metrics.evaluate`'s columns, its ``time_s``
    as ``metrics_s``: the evaluation's own wall time); ``cell_s`` = ``share_s`` + ``metrics_s`` (the
    cell's time in the sweep, apportioned when batched); ``mesh_sha256`` (`mesh_hash`: of the input's
    vertices and faces as read), ``metrics_settings`` (`metrics_settings`: what its metrics were measured
    with). Rows come in cell order (mesh, then grid, last key fastest, then target), however the cells
    finished. Raises ValueError for unknown grid keys, bad targets, a bad ``out``/``executor``/``workers``,
    or an ``out`` holding rows of a mesh that changed under its name or measured with other metrics.
    ``df.attrs["sweep"]``: ``requested``, ``cells``, ``skipped``, ``ran``, ``collapsed`` (reason → cells).
    """
    collapsed: dict = {}
    configs, targets = expand_grid(grid, collapsed), check_targets(targets)
    if out is not None:
        _check_writable(out)
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, numbers.Integral)
                                   or batch_size < 1):
        raise ValueError(f"batch_size must be an int >= 1 or None, got {batch_size!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, numbers.Integral)
                                or workers < 1):
        raise ValueError(f"workers must be an int >= 1 or None, got {workers!r}")
    if workers is not None and executor is not None:
        raise ValueError("give executor= or workers=, not both (an executor's workers are its own)")
    if isinstance(metrics, (bool, np.bool_)):
        metrics = {} if metrics else False
    elif isinstance(metrics, dict):
        metrics = dict(metrics)
    else:  # None, a number or a text was read as False: no metrics, without a word
        raise ValueError(f"metrics must be True, False or a dict of qemjax.metrics.evaluate's keywords "
                         f"({{'n_samples': 10_000}}), got {metrics!r}")
    if metrics:
        _check_metrics(metrics)
    submit = None if executor is None else _submitter(executor)
    if workers is None and executor is None:
        workers = default_workers()
        auto = workers is None
    else:
        auto = False
    named = name_meshes(meshes)
    cells = [Cell(name, params, t) for name in named for params in configs for t in targets]
    keys = [c.key for c in cells]
    if len(set(keys)) != len(keys):
        raise ValueError("the grid or targets repeat a value: two cells would be the same")
    per_config = len(named) * len(targets)
    collapsed = {why: n * per_config for why, n in collapsed.items()}
    requested = len(cells) + sum(collapsed.values())
    with holding(out):  # (None: no table, nothing to hold)
        return _sweep_into(out, named, grid, configs, cells, keys, collapsed, requested, metrics, executor, submit,
                           workers, auto, progress, batch_size)


def _sweep_into(out, named, grid, configs, cells, keys, collapsed, requested, metrics, executor, submit, workers,
                auto, progress, batch_size):
    """`sweep`, its arguments checked, from reading ``out`` on: while this sweep holds it (`table.holding`),
    so that no other sweep reads it or writes it meanwhile."""
    import pandas as pd

    table = read_table(out) if out is not None else pd.DataFrame()
    rows = {}
    if len(table) and "cell" not in table:
        raise ValueError(f"{os.fspath(out)} exists but is not a sweep table (no 'cell' column)")
    header, texts = read_text(out) if out is not None else ([], {})
    if len(table):
        ok = table[table["error"].fillna("") == ""] if "error" in table else table
        rows = {r["cell"]: r for r in ok.to_dict("records")}
        table = table[~table["cell"].isin(set(keys) - set(rows))]  # failed rows of this grid are re-run
    texts = {k: t for k, t in texts.items() if k in rows or k not in set(keys)}
    todo = [c for c in cells if c.key not in rows]
    skipped = len(cells) - len(todo)
    stored = _stored_meshes(table)
    # the meshes to run, and those whose rows the file holds: a mesh changed under its name must not have
    # its old rows kept beside (or instead of) new ones
    loaded = {name: load_mesh(named[name]) for name in dict.fromkeys(
        [*(c.mesh for c in todo), *(name for name in named if name in stored)])}
    fingerprints = {name: mesh_hash(mesh) for name, mesh in loaded.items()}
    for name in named:
        if name in stored and stored[name] != {fingerprints[name]}:
            raise ValueError(f"{os.fspath(out)} holds rows of mesh {name!r} computed from another mesh (its "
                             f"vertices or faces differ from the {name!r} given now): give another out=, or "
                             "remove the file to start again")
    measured = metrics_settings(metrics)
    stored_metrics = {v for r in rows.values() if isinstance(v := r.get(METRICS_SETTINGS), str) and v}
    if stored_metrics - {measured}:  # the rows kept would have been measured otherwise than the new ones
        raise ValueError(f"{os.fspath(out)} holds rows measured with metrics "
                         f"{_metrics_words(sorted(stored_metrics - {measured})[0])}, where this sweep asks for "
                         f"{_metrics_words(measured)}: give another out=, or the same metrics")
    others = table[~table["cell"].isin(set(keys))] if len(table) else table  # rows of other grids: kept
    other_keys = list(others["cell"]) if len(others) else []

    if collapsed:
        why = "; ".join(f"{n} cells: {reason}" for reason, n in collapsed.items())
        warnings.warn(f"sweep: {requested} requested cells are {len(cells)} ({why}; \"n/a\" in their rows)",
                      stacklevel=2)
    from tqdm.auto import tqdm

    if progress and skipped:
        tqdm.write(f"sweep: {skipped} of {len(cells)} cells already in {os.fspath(out)}: skipped", file=sys.stderr)
    bar = tqdm(total=len(cells), initial=skipped, unit="cell", desc="sweep", disable=not progress)
    ran = []
    front = [*_FIRST, *grid, "target"]  # the table's leading columns, in the DataFrame and the file alike

    def frame(records):
        df = pd.DataFrame(records)
        if len(df):
            df["target"] = target_column(df["target"]).to_numpy()
            df = df[front + [c for c in df.columns if c not in front]]
        return df

    def complete(r):
        for k in grid:  # a grid key the cell does not have: its method has no such setting
            r.setdefault(k, NOT_APPLICABLE)
        r[MESH_HASH] = fingerprints[r["mesh"]]  # what a resume checks the mesh against
        r[METRICS_SETTINGS] = measured  # and the metrics
        return r

    def finish(batch_rows):
        for r in batch_rows:
            rows[r["cell"]] = complete(r)
            if out is not None and _format(out) == "csv":
                texts[r["cell"]] = {k: as_text(v) for k, v in r.items()}
        ran.extend(batch_rows)
        bar.update(len(batch_rows))

    saved = [time.perf_counter(), 0]  # when the table was last written, and with how many new rows

    def save(force: bool = True) -> float | None:
        """Write the table if rows are waiting (unless not ``force`` and the last write was under
        `SAVE_EVERY_S` ago); the seconds until a write is due, or None when no row is waiting."""
        if out is None or saved[1] == len(ran):
            return None
        wait = SAVE_EVERY_S - (time.perf_counter() - saved[0])
        if not force and wait > 0:
            return wait
        now, n = time.perf_counter(), len(ran)
        if _format(out) == "csv":  # rows already in the file: as they were, byte for byte
            order = other_keys + [k for k in keys if k in rows]
            # the DataFrame's leading columns first (a grid key the first rows lack would otherwise come
            # last); a file's own header stays as it is, so the rows already there keep their text
            cols = list(dict.fromkeys([*header, *front, *(c for k in order for c in texts[k])]))
            write_text(cols, [texts[k] for k in order], out)
        else:
            ours = frame([rows[k] for k in keys if k in rows])
            write_table(pd.concat([others, ours], ignore_index=True) if len(others) else ours, out)
        # marked written only once written: a Ctrl-C during the write leaves them waiting, for the last save
        saved[:] = now, n

    faces = {name: len(loaded[name].faces) for name in loaded}
    stopped = False
    try:
        if submit is None:
            work = pieces(todo, loaded, faces) if batch_size is None else [
                Piece(b, float(sum(faces[c.mesh] for c in b))) for b in batches(todo, batch_size)]
            _run_pieces(work, _helpers(workers, work, configs), loaded, metrics, finish, save)
            if auto:  # this process's default sweeps so far (`_helpers`)
                _SWEPT[0] += sum(p.work for p in work)
        else:
            work = batches(todo, batch_size if batch_size is not None else EXECUTOR_BATCH)
            _run_on(executor, submit, work, loaded, metrics, finish, save)
    except KeyboardInterrupt:
        stopped = True
    finally:
        bar.close()
        save()  # nothing when every finished row is written already
    if stopped:
        where = f" in {os.fspath(out)}" if out is not None else " (no out= given: not written)"
        raise SweepInterrupted(f"{len(ran)} of {len(todo)} cells finished this run, kept{where}; "
                               f"{len(rows)} of {len(cells)} done in all (a rerun resumes)")
    df = frame([rows[k] for k in keys])
    df.attrs["sweep"] = {"requested": requested, "cells": len(cells), "skipped": skipped, "ran": len(ran),
                         "collapsed": collapsed}
    return df


def default_workers() -> int | None:
    """``workers`` when a sweep gives none: $QEMJAX_WORKERS (an integer >= 1), else None (automatic)."""
    value = os.environ.get(WORKERS_ENV, "").strip()
    if not value or value == "auto":
        return None
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"${WORKERS_ENV} must be an integer >= 1 or 'auto', got {value!r}")
    return n


def _helpers(workers: int | None, work: list[Piece], configs: list) -> int:
    """How many helper processes run a sweep's pieces beside this process: ``workers`` − 1; None: the
    cores this process may use, less one, when helpers are started already (`pool.HELPERS`), the distinct
    runs' work reaches `START_WORK` or this process's earlier default sweeps reach `SWEPT_WORK`, else none;
    none either when the grid's values or this process's registered methods come from the caller's script
    (``__main__``: a helper cannot import them; ``workers=N`` tries, and runs here what they cannot). No
    more than there are pieces to share."""
    share = len(work) - 1 if HERE_TOO else len(work)
    if workers is None:
        from .pool import HELPERS, cores, from_main, shippable

        want = cores() - 1
        if HELPERS.size() == 0 and sum(p.work for p in work) < START_WORK and _SWEPT[0] < SWEPT_WORK:
            want = 0
        if not shippable() or any(from_main(v) for params in configs for _, v in params):
            want = 0
    else:
        want = workers - 1
    return max(0, min(want, share))


def _run_pieces(work: list[Piece], helpers: int, loaded, metrics, finish, save) -> None:
    """The pieces in this process and on ``helpers`` helper processes (`pool`), rows to ``finish`` as they
    come, the table written at most every `SAVE_EVERY_S` while they do and after each piece run here. The
    helpers and this process take the pieces, largest first, from one queue, each as it is free; this one
    starts at once, the helpers once started (a few seconds, the first time: `pool`). A piece whose helper
    died is run again (`RETRIES` times), then here. Ctrl-C (or an error) stops the helpers: their pieces in
    flight are dropped."""
    if helpers == 0:
        for piece in work:
            for r in iter_rows([(loaded[c.mesh], c) for c in piece.cells], metrics):
                finish([r])
                save(force=False)
            save()
        return
    import collections
    import queue
    import threading

    from . import pool as _pool

    if not _pool.HELPERS.busy.acquire(blocking=False):  # another thread's sweep has them: here alone
        return _run_pieces(work, 0, loaded, metrics, finish, save)
    try:
        _pool.HELPERS.grow(helpers)
        todo = collections.deque(sorted(work, key=lambda p: -p.work))
        lock = threading.Lock()
        ids = {id(p): k for k, p in enumerate(work)}
        dispatch = _pool.Dispatch(_pool.HELPERS, todo, lock, lambda p: (ids[id(p)], run_cells, (
            [(loaded[c.mesh], c) for c in p.cells], metrics)), RETRIES, helpers)
        dispatch.start()
        here, done = [], False

        def handle(msg) -> bool:
            if msg[0] == "rows":
                _pool.warn_again(msg[3])
                finish(msg[2])
                save(force=False)
            elif msg[0] == "here":
                here.append(msg[1])
            return msg[0] == "done"

        def drain() -> bool:
            got = False
            while True:
                try:
                    got = handle(dispatch.results.get_nowait()) or got
                except queue.Empty:
                    return got

        try:
            while True:
                done = drain() or done
                piece = here.pop(0) if here else None
                if piece is None and (HERE_TOO or dispatch.error is not None or not dispatch.is_alive()):
                    with lock:
                        piece = todo.popleft() if todo else None
                if piece is not None:
                    for r in iter_rows([(loaded[c.mesh], c) for c in piece.cells], metrics):
                        finish([r])
                        save(force=False)
                        done = drain() or done
                    save()
                    continue
                if done:
                    break
                try:
                    done = handle(dispatch.results.get(timeout=_pool.POLL_S)) or done
                except queue.Empty:
                    save(force=False)
        except BaseException:
            dispatch.stop()
            _pool.HELPERS.shutdown()  # the pieces in flight are dropped
            drain()  # rows that came in meanwhile are finished rows: kept
            raise
        if dispatch.error is not None:
            raise dispatch.error
    finally:
        _pool.HELPERS.busy.release()


def _run_on(executor, submit, work, loaded, metrics, finish, save) -> None:
    """The batches as tasks on an executor; rows written as tasks end (at most every `SAVE_EVERY_S`, and
    never later than that after a row came in). A task whose future fails (not a cell: a cell's error is
    its row) was lost, e.g. its worker died: submitted again with the mesh arrays
    themselves, up to `RETRIES` times, then run here. Ctrl-C cancels the tasks not started."""
    shipped = _ship(executor, {c.mesh: loaded[c.mesh] for b in work for c in b})  # not the meshes loaded only
    # to check a resumed table's rows against
    pending = {submit(run_cells, [(shipped[c.mesh], c) for c in b], metrics): (b, 0) for b in work}
    due = None  # seconds until waiting rows must be written; None: none waiting
    try:
        while pending:
            done, _ = concurrent.futures.wait(list(pending), timeout=due,
                                              return_when=concurrent.futures.FIRST_COMPLETED)
            for f in done:
                b, tries = pending.pop(f)
                try:
                    got = f.result()
                except Exception:  # noqa: BLE001 - lost, not failed: run_cells catches the cells' errors
                    items = [(loaded[c.mesh], c) for c in b]
                    again = None
                    if tries < RETRIES:
                        try:
                            again = submit(run_cells, items, metrics)
                        except Exception:  # noqa: BLE001 - a broken pool takes no more tasks
                            again = None
                    if again is not None:
                        pending[again] = (b, tries + 1)
                        continue
                    got = run_cells(items, metrics)
                finish(got)
            due = save(force=False)
    except BaseException:
        for f in pending:
            f.cancel()
        raise
