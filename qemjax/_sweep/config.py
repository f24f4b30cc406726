"""``qemjax sweep CONFIG``: a sweep described in a TOML file (or YAML, with pyyaml installed).

Everything is checked before any mesh is simplified or any worker started: unknown keys, missing files,
unknown shapes, wrong types and bad targets raise ValueError with one line naming the file and the key
(a missing file `MissingFileError`: a FileNotFoundError too).
Relative paths (meshes, out, the texture images a grid names) are relative to the config file's folder; a
mesh may also be a shape made in code (``"shapes.torus"``, ``"shapes.bumpy_sphere(subdivisions=4)"`` or ``{shape = "torus", n_major = 32}``). See docs/cli.md, "Sweep config files".
"""
from __future__ import annotations

import contextlib
import dataclasses
import errno
import numbers
import os
import typing
from pathlib import Path
from typing import Any

from .._io.mesh import MissingFileError
from .._pipeline import api as _api, flat as _flat
from .. import _costs, _schedulers, shapes
from . import run as _sweep, table as _table

KEYS = ("meshes", "grid", "targets", "out", "metrics", "executor")
EXECUTOR_KEYS = ("workers", "scheduler", "address")
SCHEDULERS = ("process", "dask")  # a local process pool, or a Dask cluster (local, or at `address`)
METRICS_KEYS = ("n_samples", "seed")  # keywords of qemjax.metrics.evaluate a config may set


@dataclasses.dataclass(frozen=True)
class SweepConfig:
    meshes: dict[str, str]  # name → path, or a shape's text ("shapes.torus(n_major=32)")
    grid: dict[str, list]
    targets: list
    out: str
    metrics: bool | dict
    executor: dict  # a subset of EXECUTOR_KEYS; empty: in this process


def read(path) -> dict:
    """The raw table of a .toml, .yaml or .yml file."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(errno.ENOENT, "config file not found", os.fspath(path))
    ext = path.suffix.lower()
    if ext == ".toml":
        import tomllib

        try:
            return tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path.name}: not valid TOML: {exc}") from None
    if ext in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise ValueError(f"{path.name}: reading a YAML config needs pyyaml (pip install pyyaml); "
                             "or write it as .toml") from None
        try:
            raw = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ValueError(f"{path.name}: not valid YAML: {' '.join(str(exc).split())}") from None
        if not isinstance(raw, dict):
            raise ValueError(f"{path.name}: the file must be a mapping of {', '.join(KEYS)}")
        bad = _non_text_key(raw)
        if bad is not None:
            raise ValueError(f"{path.name}: {bad!r} is not a key a sweep config has: keys are names (text)")
        return raw
    raise ValueError(f"{path.name}: a config must be .toml, .yaml or .yml, got {ext or 'no extension'!r}")


def _non_text_key(table: dict):
    """The first key of ``table`` or of a table in it (``grid``, ``meshes``, ...) that is not text (YAML
    reads ``3:`` as a number), or None."""
    for k, v in table.items():
        if not isinstance(k, str):
            return k
        if isinstance(v, dict) and (inner := _non_text_key(v)) is not None:
            return inner
    return None


def load(path, out: str | None = None) -> SweepConfig:
    """Read and check the config at ``path``; ``out`` (e.g. from the command line) overrides its ``out``."""
    path = Path(path)
    raw = read(path)
    where = path.name

    def fail(msg, missing=None):
        if missing is not None:  # a file the config names: FileNotFoundError too
            raise MissingFileError(errno.ENOENT, f"{where}: {msg}", missing)
        raise ValueError(f"{where}: {msg}")

    unknown = [k for k in raw if k not in KEYS]
    if unknown:
        fail(f"unknown key {unknown[0]!r}{_flat.did_you_mean(unknown[0], KEYS)}; a sweep config has "
             f"{', '.join(KEYS)}")
    for key in ("meshes", "targets"):
        if key not in raw:
            fail(f"'{key}' is missing")
    folder = path.resolve().parent
    meshes = _meshes(raw["meshes"], folder, fail)
    grid = _grid_paths(_grid(raw.get("grid", {}), fail), folder, fail)
    try:
        _sweep.expand_grid(grid)
        targets = _sweep.check_targets(raw["targets"])
    except ValueError as exc:
        fail(str(exc))
    if out is None:  # the config's own out is relative to its folder; --out to the shell's
        out = raw.get("out", path.with_suffix(".parquet").name)
        if not isinstance(out, str):
            fail(f"out must be a file name (string), got {out!r}")
        out = os.fspath(folder / out)
    _check_out(out, fail)
    return SweepConfig(meshes, grid, targets, out, _metrics(raw.get("metrics", True), fail),
                       _executor(raw.get("executor", {}), fail))


def _mesh(value, folder: Path, fail) -> str:
    """One mesh entry: a path (relative to the config's folder) or a shape made in code, as text
    (``"shapes.bumpy_sphere(subdivisions=4)"``) or a table (``{shape = "bumpy_sphere", subdivisions = 4}``);
    returns the absolute path or the shape's canonical text."""
    if shapes.is_spec(value) and not (isinstance(value, str) and (folder / value).is_file()):
        try:
            return str(shapes.parse_spec(value))
        except ValueError as exc:
            fail(f"meshes: {exc}")
    if not isinstance(value, str):
        fail(f"meshes must be file paths or shapes (strings such as \"shapes.torus\"), got {value!r}")
    path = os.fspath(folder / value)
    if not Path(path).is_file():
        fail("mesh file not found", missing=path)
    return path


def _meshes(value, folder: Path, fail) -> dict[str, str]:
    if isinstance(value, str):
        value = [value]
    if isinstance(value, list):
        paths = [_mesh(v, folder, fail) for v in value]  # its errors name the config already (`fail`)
        names = [_sweep._name(p, i) for i, p in enumerate(paths)]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:  # named by stem or shape: a config names them in a table (the Python API: a dict)
            fail(f"meshes: two meshes have the same name {twice[0]!r}: name each in a table, "
                 f"[meshes] {twice[0]}_a = \"...\", {twice[0]}_b = \"...\"")
        try:
            named = _sweep.name_meshes(paths)
        except ValueError as exc:
            fail(str(exc))
    elif isinstance(value, dict):
        named = {str(k): _mesh(v, folder, fail) for k, v in value.items()}
    else:
        fail(f"meshes must be a path, a list of paths or a table name = path, got {type(value).__name__}")
    if not named:
        fail("meshes is empty")
    return named


# a method names qemjax's cost models or a peer simplifier (`qemjax.peers`: the cell runs that peer); a
# preset, one of the named method configurations
_CHOICES = {"method": lambda: [*_api.methods(), *_sweep.PEER_NAMES], "scheduler": _schedulers.names,
            "placement": lambda: _api.PLACEMENTS, "preset": lambda: list(_costs.PRESETS)}


def _allowed(key: str) -> set[str]:
    """The type names a grid key takes, from the real type of what it sets (`_flat.key_type`: e.g.
    {'float', 'None'}); {'any'} for a key whose values simplify checks itself (``attributes``)."""
    hint = _flat.key_type(key)
    if hint is Any or hint is object:
        return {"any"}
    args = typing.get_args(hint) or (hint,)
    return {"None" if a is type(None) else "any" if a in (Any, object) else getattr(a, "__name__", str(a))
            for a in args}


def _check_value(key: str, v, fail):
    """One grid value, checked against the real type of what it sets; the string 'none' is None where allowed."""
    allowed = _allowed(key)
    if allowed == {"any"}:  # as written; 'none' is None, a list a tuple (attributes=["uv", "color"])
        if isinstance(v, str) and v.strip().lower() == "none":
            return None
        return tuple(v) if isinstance(v, list) else v
    if (v is None or isinstance(v, str) and v.strip().lower() == "none") and "None" in allowed:
        return None  # YAML's null, or "none" (TOML has no null)
    if "Schedule" in allowed:  # its fields are no grid keys either
        fail(f"grid.{key}: a Schedule cannot be given in a config file; use qemjax.sweep from Python "
             f"(grid={{\"{key}\": [qemjax.Schedule(...), ...]}})")
    if "Topology" in allowed:
        fail(f"grid.{key}: a {key} object cannot be given in a config file; vary its fields by name "
             f"(grid.flip_angle, grid.\"topology.weld\") or use qemjax.sweep from Python")
    if "any" in allowed:
        if isinstance(v, str) and v.strip().lower() == "none":
            return None
        return tuple(v) if isinstance(v, list) else v
    if "bool" in allowed and isinstance(v, bool):
        return v
    if "int" in allowed and isinstance(v, numbers.Integral) and not isinstance(v, bool):
        return int(v)
    if "float" in allowed and isinstance(v, numbers.Real) and not isinstance(v, bool):
        return float(v)
    if "str" in allowed and isinstance(v, str):
        if key in _CHOICES and v not in _CHOICES[key]():
            fail(f"grid.{key}: unknown value {v!r}; one of {', '.join(_CHOICES[key]())}")
        return v
    kinds = " or ".join(sorted(t.replace("None", "'none'").replace("float", "a number")
                               .replace("bool", "true/false").replace("str", "a string")
                               .replace("int", "a whole number") for t in allowed))
    fail(f"grid.{key}: expected {kinds}, got {v!r}")


def _grid(value, fail) -> dict[str, list]:
    if not isinstance(value, dict):
        fail(f"grid must be a table of simplify keywords = lists of values, got {type(value).__name__}")
    unknown = [k for k in value if not _sweep.is_grid_key(k)]
    if unknown:
        fail(f"unknown grid key {unknown[0]!r}{_flat.did_you_mean(unknown[0], _flat.grid_keys())}; "
             f"a grid may vary {', '.join(_flat.grid_keys())} "
             "(or a field by its dotted name: \"method.curvature_weight\")"
             + ("; targets go in 'targets'" if unknown[0] in ("ratio", "target_faces") else ""))
    grid = {}
    for key, values in value.items():
        values = values if isinstance(values, list) else [values]
        if not values:
            fail(f"grid.{key} is empty")
        grid[key] = [_check_value(key, v, fail) for v in values]
    return grid


PATH_KEYS = ("texture", "attributes.texture")  # grid keys whose text values name files


def _grid_paths(grid: dict, folder: Path, fail) -> dict:
    """The grid with the texture images it names as paths relative to the config's folder, as its meshes are
    (a missing one fails before anything runs, as a missing mesh does)."""
    for key in PATH_KEYS:
        if key not in grid:
            continue
        values = []
        for v in grid[key]:
            if isinstance(v, str):
                path = os.fspath(folder / v)
                if not Path(path).is_file():
                    fail(f"grid.{key}: texture image not found", missing=path)
                v = path
            values.append(v)
        grid[key] = values
    return grid


def _metrics(value, fail) -> bool | dict:
    if isinstance(value, bool):
        return value
    if not isinstance(value, dict):
        fail(f"metrics must be true, false or a table of {', '.join(METRICS_KEYS)}, got {value!r}")
    for k, v in value.items():
        if k not in METRICS_KEYS:
            fail(f"unknown metrics key {k!r}{_flat.did_you_mean(k, METRICS_KEYS)}; metrics may set "
                 f"{', '.join(METRICS_KEYS)}")
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:  # n_samples = 0: distances at the vertices
            fail(f"metrics.{k} must be an integer >= 0, got {v!r}")  # alone, as qemjax.sweep and evaluate take it
    return dict(value)


def _executor(value, fail) -> dict:
    if not isinstance(value, dict):
        fail(f"executor must be a table of {', '.join(EXECUTOR_KEYS)}, got {type(value).__name__}")
    for k in value:
        if k not in EXECUTOR_KEYS:
            fail(f"unknown executor key {k!r}{_flat.did_you_mean(k, EXECUTOR_KEYS)}; executor may set "
                 f"{', '.join(EXECUTOR_KEYS)}")
    workers, scheduler, address = value.get("workers"), value.get("scheduler"), value.get("address")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        fail(f"executor.workers must be an integer >= 1, got {workers!r}")
    if scheduler is not None and scheduler not in SCHEDULERS:
        fail(f"executor.scheduler must be one of {', '.join(SCHEDULERS)}, got {scheduler!r}")
    if address is not None:
        if not isinstance(address, str):
            fail(f"executor.address must be a string such as 'tcp://scheduler:8786', got {address!r}")
        if workers is not None or scheduler == "process":
            fail("executor.address connects to a running Dask cluster: it takes no workers or "
                 "scheduler = 'process'")
    elif value and workers is None:
        fail("executor needs workers (a local pool) or address (a Dask cluster)")
    if scheduler == "dask" or address is not None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            fail("executor: a Dask scheduler needs dask.distributed (pip install 'qemjax[dask]')")
    return dict(value)


def _check_out(out: str, fail):
    """The sweep's own checks of ``out`` (`table._check_writable`: its format, its folder, pyarrow for
    Parquet), named with the config file."""
    try:
        _table._check_writable(out)
    except ValueError as exc:
        fail(str(exc))


def local(settings: dict) -> bool:
    """Whether the executor settings ask for a local process pool (``workers`` without Dask): the sweep's
    own helper processes run the cells then (``sweep(workers=N)``: this process and N - 1 helpers)."""
    return bool(settings) and "address" not in settings and settings.get("scheduler", "process") == "process"


@contextlib.contextmanager
def executor(settings: dict):
    """The executor the settings describe, shut down on exit: a Dask client; None in this process and for a
    local pool (`local`: the sweep's own helpers, ``workers=``)."""
    if not settings or local(settings):
        yield None
    elif "address" in settings:
        from distributed import Client

        try:
            client = Client(settings["address"], timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise ValueError(f"executor.address: could not reach a Dask scheduler at {settings['address']} "
                             f"({type(exc).__name__}: {' '.join(str(exc).split())[:160]})") from None
        with client:
            yield client
    else:
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=settings["workers"], threads_per_worker=1, processes=True) as cluster, \
                Client(cluster) as client:
            yield client


def run(config: SweepConfig, progress: bool = True) -> Any:
    """Run the sweep the config describes; the DataFrame (also written to ``config.out``)."""
    workers = config.executor["workers"] if local(config.executor) else None
    with executor(config.executor) as ex:
        return _sweep.sweep(config.meshes, config.grid, config.targets, metrics=config.metrics, executor=ex,
                            workers=workers, out=config.out, progress=progress)
