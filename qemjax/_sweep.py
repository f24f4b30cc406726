"""Parameter sweeps: meshes × a grid of `simplify` keywords × targets, one table row per cell.

A pipeline of small stages: name and load the meshes (once each), cross the grid into cells, drop the
cells already in ``out`` (resume), run the rest in process or on an executor, write the table after each
cell. Every cell is one plain `simplify` call, so its mesh is the one `simplify` gives alone.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import inspect
import itertools
import json
import math
import numbers
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from . import _io
from ._api import simplify
from ._options import Schedule

# keywords a grid may not vary: the target is `targets`, progress is the sweep's own, feature edges are
# per-mesh index arrays (not a scalar setting)
_NOT_IN_GRID = ("mesh", "target_faces", "ratio", "progress", "feature_edges")
GRID_KEYS = tuple(k for k in inspect.signature(simplify).parameters if k not in _NOT_IN_GRID)
FORMATS = {".parquet": "parquet", ".pq": "parquet", ".csv": "csv"}
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
    """A grid value as JSON/table data: Schedules (frozen dataclasses) by their repr."""
    if isinstance(value, Schedule):
        return repr(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def name_meshes(meshes) -> dict[str, Any]:
    """name → mesh input: a path (named by its stem), a list of paths or meshes, a dict name → mesh, or
    one mesh (``(V, F)``, `Mesh`, trimesh). Unnamed meshes are ``mesh0``, ``mesh1``, …"""
    if isinstance(meshes, dict):
        named = {str(k): v for k, v in meshes.items()}
    else:
        single = isinstance(meshes, (str, os.PathLike)) or hasattr(meshes, "vertices") or (
            isinstance(meshes, tuple) and len(meshes) == 2 and not isinstance(meshes[0], (str, os.PathLike)))
        items = [meshes] if single else list(meshes)
        names = [Path(m).stem if isinstance(m, (str, os.PathLike)) else f"mesh{i}" for i, m in enumerate(items)]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"two meshes have the same name {dup}: pass a dict name → mesh")
        named = dict(zip(names, items))
    if not named:
        raise ValueError("meshes is empty")
    return named


def expand_grid(grid: dict) -> list[tuple[tuple[str, Any], ...]]:
    """The cross product of ``grid`` (keyword → list of values; a non-list value is one value), in
    order: the last key varies fastest. Unknown keywords raise ValueError naming them."""
    if not isinstance(grid, dict):
        raise ValueError(f"grid must be a dict of simplify keywords → lists of values, got {type(grid).__name__}")
    unknown = [k for k in grid if k not in GRID_KEYS]
    if unknown:
        why = "; targets go in `targets`" if set(unknown) & {"target_faces", "ratio"} else ""
        raise ValueError(f"unknown grid keys {unknown}{why}; a grid may vary {list(GRID_KEYS)}")
    axes = []
    for k, values in grid.items():
        values = list(values) if isinstance(values, (list, tuple, range, np.ndarray)) else [values]
        if not values:
            raise ValueError(f"grid[{k!r}] is empty")
        axes.append([(k, v) for v in values])
    return [tuple(combo) for combo in itertools.product(*axes)]


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


def run_cell(mesh, cell: Cell, metrics) -> dict:
    """One row: parameters, counts, stop reason, timings, output hash, metrics (``metrics``: False, or a
    dict of `qemjax.metrics.evaluate` keywords). A failing `simplify` gives a row with ``error`` set."""
    row = {"cell": cell.key, "mesh": cell.mesh, **{k: _plain(v) for k, v in cell.params},
           "target": cell.target, "error": ""}
    t0 = time.perf_counter()
    try:
        res = simplify(mesh, **cell.kwargs())
    except Exception as exc:  # one bad combination must not stop a sweep: the row says why
        row["error"] = f"{type(exc).__name__}: {exc}"
        return row
    s = res.stats
    row.update(faces_in=s["faces_in"], faces_out=s["faces_out"], target_faces=s["target_faces"],
               stop_reason=res.stop_reason, rounds=s["rounds"], compile_s=s["compile_s"],
               run_s=s["run_s"], total_s=s["total_s"], result_sha256=result_hash(res))
    if metrics is not False:
        from .metrics import evaluate

        row.update(evaluate(mesh, res, target_faces=s["target_faces"], **metrics))
    row["cell_s"] = time.perf_counter() - t0
    return row


def _format(out) -> str:
    ext = Path(out).suffix.lower()
    if ext not in FORMATS:
        raise ValueError(f"out must end in one of {sorted(FORMATS)}, got {os.fspath(out)!r}")
    return FORMATS[ext]


def read_table(out):
    """The table at ``out`` (Parquet or CSV by extension); an empty DataFrame when it does not exist."""
    import pandas as pd

    if not Path(out).exists():
        return pd.DataFrame()
    if _format(out) == "csv":
        return pd.read_csv(out, keep_default_na=False, na_values=[""], dtype={"error": str, "cell": str})
    return pd.read_parquet(out)


def write_table(df, out) -> None:
    """Write ``df`` to a temporary file next to ``out``, then rename: an interruption never leaves a
    partial table."""
    tmp = Path(out).with_name(f".{Path(out).name}.tmp")
    if _format(out) == "csv":
        df.to_csv(tmp, index=False)
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


def sweep(meshes, grid: dict, targets, *, metrics=True, executor=None, out=None, progress: bool = True):
    """Run every (mesh, grid configuration, target) cell with `qemjax.simplify`; a pandas DataFrame, one
    row per cell.

    meshes: a path, a list of paths or meshes, a dict name → mesh, or one mesh (``(V, F)``, `Mesh`);
        paths are named by their stem, other meshes ``mesh0``, ``mesh1``, … Each is read once.
    grid: `simplify` keywords → lists of values, crossed (e.g. ``{"method": ["qem", "esqem"],
        "regularize": [0, 0.1]}``).
    targets: ratios (floats in (0, 1)) and/or face counts (ints).
    metrics: True: every column of `qemjax.metrics.evaluate` (original = the mesh as given); a dict:
        the same with these keywords to `evaluate` (e.g. ``{"n_samples": 10_000}``); False: none.
    executor: None (in this process, in order), a `concurrent.futures.Executor` or a
        `dask.distributed.Client`: one task per cell.
    out: a ``.parquet`` or ``.csv`` path, rewritten after each finished cell. Cells whose key is already
        there without an error are not run again (an interrupted sweep resumes); rows of other cells in
        the file are kept.
    progress: a tqdm bar counting cells.

    Columns: ``cell`` (the key: JSON of mesh, sorted parameters, target), ``mesh``, one per grid key,
    ``target`` (as given), ``error`` (empty, or why `simplify` raised), ``faces_in``, ``faces_out``,
    ``target_faces``, ``stop_reason``, ``rounds``, ``compile_s``, ``run_s``, ``total_s``,
    ``result_sha256`` (of the output vertices and faces), the metrics, ``cell_s`` (wall time of the
    cell). Rows come in cell order (mesh, then grid, last key fastest, then target), however the
    cells finished. Raises ValueError for unknown grid keys, bad targets or a bad ``out``/``executor``.
    """
    import pandas as pd

    configs, targets = expand_grid(grid), check_targets(targets)
    if out is not None:
        _format(out)
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
    loaded = {name: _io.as_arrays(named[name]) for name in dict.fromkeys(c.mesh for c in todo)}

    from tqdm.auto import tqdm

    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), unit="cell", desc="sweep", disable=not progress)
    done = []

    def finish(row):
        nonlocal table
        rows[row["cell"]] = row
        done.append(row)
        bar.update(1)
        if out is not None:
            new = pd.DataFrame([row])
            table = pd.concat([table, new], ignore_index=True) if len(table) else new
            write_table(table, out)

    try:
        if submit is None:
            for c in todo:
                finish(run_cell(loaded[c.mesh], c, metrics))
        else:
            shipped = _ship(executor, loaded)
            futures = [submit(run_cell, shipped[c.mesh], c, metrics) for c in todo]
            for f in concurrent.futures.as_completed(futures):
                finish(f.result())
    finally:
        bar.close()
    df = pd.DataFrame([rows[k] for k in keys])
    front = [*_FIRST, *grid, "target"]
    return df[front + [c for c in df.columns if c not in front]]
