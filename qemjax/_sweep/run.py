"""Parameter sweeps: meshes × a grid of `simplify` keywords × targets, one table row per cell.

A pipeline of small stages: name and load the meshes (once each), cross the grid into cells, drop the
cells already in ``out`` (resume), run the rest in batches (in process or on an executor), write the table
after each batch. A batch of cells runs through `simplify_cells`: the cells that can share rounds (of
one mesh or several) run as one disjoint union of copies, the rest alone; either way each cell's mesh is the one
`simplify` gives alone (tested).
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import itertools
import json
import numbers
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import _costs, shapes
from .._pipeline import flat as _flat
from .._io import mesh as _io
from .._costs.base import Method
from .._pipeline.api import simplify, simplify_cells
from .._options import Attributes, Schedule, Topology

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
BATCH_FACES = 4_000_000  # a batch holds at most this many faces in all (its copies' memory)
EXECUTOR_BATCH = 1  # cells per task on an executor, by default: one (balances the workers best: experiments/dask_speedup.py)
FORMATS = {".parquet": "parquet", ".pq": "parquet", ".csv": "csv"}
_PEER_NAMES = ("meshoptimizer", "pymeshlab", "fast-simplification", "libigl", "pyfqmr")  # = qemjax.peers.PEERS
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
        return json.dumps([self.mesh, sorted((k, _plain(v)) for k, v in self.params), self.target])

    def kwargs(self) -> dict:
        target = {"ratio": self.target} if isinstance(self.target, float) else {"target_faces": self.target}
        return {**dict(self.params), **target}


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
    """A mesh input as arrays (`_io.as_arrays`): a shape named as text is made in code."""
    spec = _shape(value)
    return _io.as_arrays(spec.build() if spec is not None else value)


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
            isinstance(meshes, tuple) and len(meshes) == 2 and not isinstance(meshes[0], (str, os.PathLike)))
        items = [meshes] if single else list(meshes)
        names = [_name(m, i) for i, m in enumerate(items)]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"two meshes have the same name {dup}: pass a dict name → mesh")
        named = dict(zip(names, items))
    if not named:
        raise ValueError("meshes is empty")
    return named


def expand_grid(grid: dict) -> list[tuple[tuple[str, Any], ...]]:
    """The cross product of ``grid`` (keyword → list of values; a non-list value is one value), in
    order: the last key varies fastest; a method setting is left out of the cells whose method does not
    have it (`_applicable`), and cells that are then alike are kept once. Unknown keywords raise
    ValueError naming them."""
    if not isinstance(grid, dict):
        raise ValueError(f"grid must be a dict of simplify keywords → lists of values, got {type(grid).__name__}")
    unknown = [k for k in grid if not is_grid_key(k)]
    if unknown:
        why = "; targets go in `targets`" if set(unknown) & {"target_faces", "ratio"} else ""
        raise ValueError(f"unknown grid keys {unknown}{why}; a grid may vary {list(_flat.grid_keys())} "
                         "or a field by its dotted name ('method.curvature_weight')")
    axes = []
    for k, values in grid.items():
        values = list(values) if isinstance(values, (list, tuple, range, np.ndarray)) else [values]
        if not values:
            raise ValueError(f"grid[{k!r}] is empty")
        axes.append([(k, v) for v in values])
    out, seen = [], set()
    for combo in itertools.product(*axes):
        combo = _applicable(combo)
        key = json.dumps([(k, _plain(v)) for k, v in combo], default=repr)
        if key not in seen:  # crossing a method without a setting with that setting's values: once
            seen.add(key)
            out.append(combo)
    return out


def _applicable(combo: tuple) -> tuple:
    """A cell's parameters without the method settings its method does not have (a peer: none; a grid that crosses
    ``method = ["qem", "esqem"]`` with ``split_factor`` gives the qem cells no split factor: NaN in the
    table, and one cell instead of one per value). Settings the method has, and the rest, stay."""
    params = dict(combo)
    if isinstance(params.get("method"), str) and params["method"] in _PEER_NAMES:
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
    """Ratios (floats in (0, 1)) and face counts (ints ≥ 1); a single number is one target."""
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
    return out


def result_hash(res) -> str:
    """sha256 of the output's vertices (float64) and faces (int64): equal meshes, equal hashes."""
    h = hashlib.sha256(np.ascontiguousarray(res.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(res.faces, np.int64).tobytes())
    return h.hexdigest()


def _peer(cell: Cell) -> str | None:
    """The peer a cell's ``method`` names (`qemjax.peers.PEERS`), else None."""
    method = dict(cell.params).get("method")
    return method if isinstance(method, str) and method in _PEER_NAMES else None


def _simplify_cell(mesh, cell: Cell):
    """The single dispatch point: a peer's `qemjax.peers.simplify` (the target resolved as `simplify`
    does; the cell's other grid keys do not apply: NaN in its row), else `simplify`."""
    name = _peer(cell)
    if name is None:
        return simplify(mesh, **cell.kwargs())
    from .. import peers

    m = len(mesh[1])
    target = max(1, int(round(cell.target * m))) if isinstance(cell.target, float) else cell.target
    return peers.simplify(name, mesh, target)


def run_cell(mesh, cell: Cell, metrics) -> dict:
    """One row, from `simplify` alone (see `row`). A failing `simplify` gives a row with ``error`` set."""
    t0 = time.perf_counter()
    try:
        res = _simplify_cell(mesh, cell)
    except Exception as exc:  # one bad combination must not stop a sweep: the row says why
        res = exc
    return row(mesh, cell, res, metrics, time.perf_counter() - t0)


def run_cells(items: list, metrics) -> list[dict]:
    """The rows of cells, items = [(mesh, `Cell`)], computed together by `simplify_cells` (each result
    equals `simplify`'s alone; cells of several meshes may share rounds). If the batch fails as a whole,
    each cell runs alone, so the rows say which configuration fails and why."""
    if len(items) == 1 or any(_peer(c) for _, c in items):  # peers run alone (`qemjax.peers`)
        return [run_cell(mesh, c, metrics) for mesh, c in items]
    t0 = time.perf_counter()
    try:
        results = simplify_cells([(mesh, c.kwargs()) for mesh, c in items], errors=True)
    except Exception:  # noqa: BLE001 - rerun alone: the failing cell's row will carry its error
        return [run_cell(mesh, c, metrics) for mesh, c in items]
    share = (time.perf_counter() - t0) / len(items)
    return [row(mesh, c, r, metrics, share) for (mesh, c), r in zip(items, results)]


def row(mesh, cell: Cell, res, metrics, seconds: float) -> dict:
    """A cell's row: parameters, counts, stop reason, timings, output hash, metrics (``metrics``: False, or
    a dict of `qemjax.metrics.evaluate` keywords); ``res`` is the `SimplifyResult` or the exception
    `simplify` raised (then only ``error`` is set). ``seconds``: the cell's share of the run's wall time."""
    peer = _peer(cell)  # a peer's row: the grid keys other than method do not apply (NaN)
    out = {"cell": cell.key, "mesh": cell.mesh,
           **{k: _plain(v) if peer is None or k == "method" else float("nan") for k, v in cell.params},
           "target": cell.target, "error": ""}
    if isinstance(res, Exception):
        out["error"] = f"{type(res).__name__}: {res}"
        return out
    s = res.stats
    out.update(faces_in=s["faces_in"], faces_out=s["faces_out"], target_faces=s["target_faces"],
               stop_reason=res.stop_reason, rounds=s["rounds"], compile_s=s["compile_s"],
               run_s=s["run_s"], total_s=s["total_s"], batch_size=s.get("batch", {}).get("size", 1),
               same_run=s.get("batch", {}).get("same_run", 1),
               result_sha256=result_hash(res))
    t0 = time.perf_counter()
    if metrics is not False:
        from ..metrics import evaluate

        out.update(evaluate(mesh, res, target_faces=s["target_faces"], **metrics))
    out["cell_s"] = seconds + time.perf_counter() - t0
    return out


def batches(cells: list[Cell], faces: dict, size: int | None) -> list[list[Cell]]:
    """Cells, in order, cut into batches of at most ``size`` cells (None: as many as `BATCH_FACES` faces
    allow, with ``faces`` the face count of each mesh by name; a larger mesh is a batch of one)."""
    out, cur, total = [], [], 0
    for c in cells:
        f = faces[c.mesh]
        full = len(cur) >= size if size else cur and total + f > BATCH_FACES
        if full:
            out.append(cur)
            cur, total = [], 0
        cur.append(c)
        total += f
    return out + ([cur] if cur else [])


def _format(out) -> str:
    ext = Path(out).suffix.lower()
    if ext not in FORMATS:
        raise ValueError(f"out must end in one of {sorted(FORMATS)}, got {os.fspath(out)!r}")
    return FORMATS[ext]


def _check_writable(out) -> str:
    """The format of ``out``; ValueError when it is Parquet and pyarrow is missing (before anything runs)."""
    fmt = _format(out)
    if fmt == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise ValueError(f"writing {Path(out).name} needs pyarrow (pip install 'qemjax[sweep]'), "
                             "or give a .csv out") from None
    return fmt


def target_column(values):
    """The ``target`` column as given: ints (face counts) stay ints beside floats (ratios). A target
    >= 1 is always a face count and < 1 a ratio (`check_targets`), so the type follows from the value,
    also when a file stored the column as float (Parquet: one type per column; CSV read back)."""
    import pandas as pd

    vals = [v if isinstance(v, str) else int(v) if v >= 1 else float(v) for v in values]
    kinds = {type(v) for v in vals}
    dtype = "int64" if kinds == {int} else "float64" if kinds == {float} else object
    return pd.Series(vals, dtype=dtype)


def _typed(df):
    if "target" in df and len(df):
        df = df.copy()
        df["target"] = target_column(df["target"]).to_numpy()
    return df


def read_table(out):
    """The table at ``out`` (Parquet or CSV by extension), its ``target`` column as given (`target_column`);
    an empty DataFrame when it does not exist."""
    import pandas as pd

    if not Path(out).exists():
        return pd.DataFrame()
    if _format(out) == "csv":
        return _typed(pd.read_csv(out, keep_default_na=False, na_values=[""], dtype={"error": str, "cell": str}))
    _check_writable(out)
    return _typed(pd.read_parquet(out))


def write_table(df, out) -> None:
    """Write ``df`` to a temporary file next to ``out``, then rename: an interruption never leaves a
    partial table. CSV keeps integer targets as integers ("424"); Parquet stores a column of ratios and
    face counts as float64 (`read_table` gives them back as ints)."""
    tmp = Path(out).with_name(f".{Path(out).name}.tmp")
    if _format(out) == "csv":
        _typed(df).to_csv(tmp, index=False)
    else:
        df.to_parquet(tmp, index=False)
    os.replace(tmp, out)


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


def sweep(meshes, grid: dict, targets, *, metrics=True, executor=None, out=None, progress: bool = True,
          batch_size: int | None = None):
    """Run every (mesh, grid configuration, target) cell with `qemjax.simplify`; a pandas DataFrame, one
    row per cell.

    meshes: a path, a list of paths or meshes, a dict name → mesh, or one mesh (``(V, F)``, `Mesh`);
        a mesh made in code may be named as text, ``"shapes.torus"`` or
        ``"shapes.bumpy_sphere(subdivisions=4)"`` (`qemjax.shapes.parse_spec`: keyword arguments with
        literal values, never evaluated). Paths are named by their stem, shapes by their name, other
        meshes ``mesh0``, ``mesh1``, … Each is read (or made) once.
    grid: `simplify` keywords → lists of values, crossed (e.g. ``{"method": ["qem", "esqem"],
        "regularize": [0, 0.1]}``). A ``method`` that names a peer (``"meshoptimizer"``, ``"pymeshlab"``,
        ``"fast-simplification"``, ``"libigl"``, ``"pyfqmr"``: `qemjax.peers`, ``pip install
        'qemjax[bench]'``) runs that peer for the cell, warm, alone, with the same metrics; the other grid
        keys do not apply to it (NaN in its row; one cell per peer, mesh and target, however many values
        they have), ``stop_reason`` is ``"peer"``, ``rounds`` NaN, ``compile_s`` 0,
        ``run_s`` = ``total_s`` = the peer call's time. A missing peer package: the row's ``error`` says so.
    targets: ratios (floats in (0, 1)) and/or face counts (ints).
    metrics: True: every column of `qemjax.metrics.evaluate` (original = the mesh as given); a dict:
        the same with these keywords to `evaluate` (e.g. ``{"n_samples": 10_000}``); False: none.
    executor: None (in this process, in order), a `concurrent.futures.Executor` or a
        `dask.distributed.Client`: one task per batch.
    out: a ``.parquet`` (needs pyarrow: ``pip install 'qemjax[sweep]'``) or ``.csv`` path, rewritten
        after each finished batch, in row order (the rows of other grids already in the file first).
        Cells whose key is already there without an error are not run again (an interrupted sweep
        resumes); rows of other cells in the file are kept.
    progress: a tqdm bar counting cells.
    batch_size: at most this many cells per batch (`simplify_cells`: cells that can share rounds, of one
        mesh or several, run together as one disjoint union of copies); None: in process, as many as
        `BATCH_FACES` faces allow; on an executor, `EXECUTOR_BATCH`. 1: every cell alone.

    Columns: ``cell`` (the key: JSON of mesh, sorted parameters, target), ``mesh``, one per grid key,
    ``target`` (as given: face counts stay ints beside ratios), ``error`` (empty, or why `simplify` raised), ``faces_in``, ``faces_out``,
    ``target_faces``, ``stop_reason``, ``rounds``, ``compile_s``, ``run_s``, ``total_s``,
    ``batch_size`` (the cells its run shared rounds with, itself included; 1: alone), ``same_run`` (the
    cells that got the very same run, itself included: cells whose settings make no difference on this
    mesh, such as ``boundary_weight`` on a closed one, run once),
    ``result_sha256`` (of the output vertices and faces), the metrics, ``cell_s`` (the cell's share of
    its batch's wall time, plus its metrics). A batched cell's ``total_s`` / ``run_s`` / ``compile_s``
    are its share of the batch's. Rows come in cell order (mesh, then grid, last key fastest, then target), however the
    cells finished. Raises ValueError for unknown grid keys, bad targets or a bad ``out``/``executor``.
    """
    import pandas as pd

    configs, targets = expand_grid(grid), check_targets(targets)
    if out is not None:
        _check_writable(out)
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, numbers.Integral)
                                   or batch_size < 1):
        raise ValueError(f"batch_size must be an int >= 1 or None, got {batch_size!r}")
    metrics = {} if metrics is True else dict(metrics) if isinstance(metrics, dict) else False
    submit = None if executor is None else _submitter(executor)
    named = name_meshes(meshes)
    cells = [Cell(name, params, t) for name in named for params in configs for t in targets]
    keys = [c.key for c in cells]
    if len(set(keys)) != len(keys):
        raise ValueError("the grid or targets repeat a value: two cells would be the same")

    table = read_table(out) if out is not None else pd.DataFrame()
    rows = {}
    if len(table) and "cell" not in table:
        raise ValueError(f"{os.fspath(out)} exists but is not a sweep table (no 'cell' column)")
    if len(table):
        ok = table[table["error"].fillna("") == ""] if "error" in table else table
        rows = {r["cell"]: r for r in ok.to_dict("records")}
        table = table[~table["cell"].isin(set(keys) - set(rows))]  # failed rows of this grid are re-run
    todo = [c for c in cells if c.key not in rows]
    loaded = {name: load_mesh(named[name]) for name in dict.fromkeys(c.mesh for c in todo)}
    others = table[~table["cell"].isin(set(keys))] if len(table) else table  # rows of other grids: kept

    from tqdm.auto import tqdm

    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), unit="cell", desc="sweep", disable=not progress)
    done = []

    def frame(records):
        df = pd.DataFrame(records)
        if len(df):
            df["target"] = target_column(df["target"]).to_numpy()
        return df

    def finish(batch_rows):
        for r in batch_rows:
            rows[r["cell"]] = r
        done.extend(batch_rows)
        bar.update(len(batch_rows))
        if out is not None:  # the rows of other grids first, then this grid's in cell order
            ours = frame([rows[k] for k in keys if k in rows])
            write_table(pd.concat([others, ours], ignore_index=True) if len(others) else ours, out)

    faces = {name: len(loaded[name][1]) for name in loaded}
    size = batch_size if batch_size is not None or submit is None else EXECUTOR_BATCH
    work = batches(todo, faces, size)
    try:
        if submit is None:
            for b in work:
                finish(run_cells([(loaded[c.mesh], c) for c in b], metrics))
        else:
            shipped = _ship(executor, loaded)
            futures = [submit(run_cells, [(shipped[c.mesh], c) for c in b], metrics) for b in work]
            for f in concurrent.futures.as_completed(futures):
                finish(f.result())
    finally:
        bar.close()
    df = frame([rows[k] for k in keys])
    front = [*_FIRST, *grid, "target"]
    return df[front + [c for c in df.columns if c not in front]]
