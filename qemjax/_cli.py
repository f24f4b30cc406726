"""Command line: ``qemjax simplify IN OUT (--faces N | --ratio R) [--max-error E] [--max-distance D] [options]``,
``qemjax lod IN OUT_DIR [--ratios R ...] [--format EXT] [--glb] [--record] [options]``,
``qemjax sweep CONFIG [--out PATH]``, ``qemjax demo [--out PATH]``, ``qemjax examples [FOLDER]``,
``qemjax compile`` and ``qemjax --version``.

The options are generated from `qemjax.simplify`'s run keywords and from the fields of the methods,
`Topology` and `Attributes` (`_flat.options`: names, real types, defaults), with help from their
docstrings and the presentation details in `OPTIONS`; `NOT_EXPOSED` names the keywords that reach
the command line another way. Errors are one line on stderr and exit code 2 (argparse's with one hint
line naming the --help to read); warnings are one line ``qemjax: warning: …``; Ctrl-C prints ``qemjax:
interrupted`` (a sweep adds how many rows it kept) and exits with 130, unless the command was started with
SIGINT ignored (it then stays ignored). The output format and folder are checked before simplifying, and the
file is written under a temporary name and renamed, so a failure never leaves a partial file. Below the
summary line, indented lines name what clean-up removed and the appearance attributes kept.

JAX's persistent compilation cache is on (from qemjax's first compilation: `_cache.ensure_default`); ``--no-cache``
or QEMJAX_NO_CACHE=1 turns it off.
"""
from __future__ import annotations

import argparse
import gc
import inspect
import os
import re
import signal
import sys
import threading
import typing
import warnings
import weakref
import _weakrefset

import numpy as np

from ._pipeline import api as _api, flat as _flat
from ._kernels import cache as _cache
from . import _costs, _schedulers
from ._pipeline.lod import RATIOS
from ._io import ply as _io_ply, texture as _io_texture

# How the command line shows some options (choices, metavar, help beyond the docstrings, the default as
# shown). Which options exist and their types come from `simplify`'s run keywords and from the fields of
# the methods, `Topology` and `Attributes` (`_flat.options`): a field added to a method is an option here
# with no edit. The flag is --name-with-dashes; options not given are not passed on.
OPTIONS = {
    "method": dict(choices=_api.methods,  # called: methods registered later are included
                   help="the cost model by name (qemjax.methods()); its settings are the options below "
                        "(--boundary-weight, --curvature-weight, ...): each given one replaces that field"),
    "scheduler": dict(type=lambda text: _scheduler_arg(text), metavar="{" + ",".join(_schedulers.names()) + "}",
                      help="'parallel': rounds of many non-interacting contractions; 'greedy': the "
                           "paper's priority queue, one contraction at a time",
                      partitioned="; with --partition, a Dask scheduler's ADDRESS (tcp://host:8786) runs the "
                                  "parts on its workers"),
    "partition": dict(help="read the input in chunks and simplify it in parts on every core (or a Dask "
                      "cluster: --scheduler ADDRESS), with their borders locked, level by level: for meshes "
                      "larger than one process (docs/large-meshes.md); --no-partition: in one process even "
                      "when the mesh would need more memory than this machine has available (without either, "
                      "such a mesh is refused before it is read)", shown="off"),
    "placement": dict(choices=lambda: _api.PLACEMENTS),
    "feature_edges": dict(metavar="FILE", help="vertex-index pairs (k,2) constrained like boundary edges, "
                          "read from FILE: .npy, or text with two integers per line (indices of the input "
                          "after welding and dropping unused vertices)", shown="none"),
    "preserve_topology": dict(shown="on; off with --pair-threshold > 0"),
    "measure": dict(shown="on when the method re-fits, as the default method does; else off"),
    "flip_angle": dict(metavar="DEG", help="forbid contractions that turn a face's normal by DEG "
                       "degrees or more; 'none' allows flips"),
    "min_angle": dict(metavar="DEG", help="refuse contractions that leave a face they move with a "
                      "smallest angle under about DEG degrees, unless the face was worse before; 'none': off",
                      shown="none"),
    "split_factor": dict(metavar="B", help="with --method esqem, split edges longer than B × the "
                         "mean edge length after simplifying (the face target still holds); 'none' disables",
                         shown="4/3"),
    "tol": dict(help="with --method area, the bisection's tolerance on the new vertex's place along the pair "
                "(a fraction of the pair's length)"),
    "attributes": dict(metavar="KINDS", help="appearance attributes to keep, seams held: 'auto' "
                       "(the kinds the input carries without seams; UVs too when the file names a texture image or "
                       "with --texture), 'none', or a comma "
                       "list of uv, color, normal"),
    "attribute_weights": dict(metavar="W", help="weight of the attributes in the cost: one number, "
                              "or kind=W pairs separated by commas (uv=0.1,color=0.03); 0: positions-only cost, "
                              "attributes interpolated", shown="uv=0.03,color=0,normal=0"),
    "texture": dict(metavar="IMAGE", help="the texture image of the input's UVs (for an OBJ without mtllib); "
                    "written beside an OBJ output and packed into a GLB", shown="none"),
    "preset": dict(choices=lambda: tuple(_costs.PRESETS), shown="none",
                   help="a named method configuration (the same as --method NAME)"),
}
TARGETS = {"target_faces": "--faces", "ratio": "--ratio", "max_error": "--max-error",
           "max_distance": "--max-distance", "max_distance_rel": "--max-distance-rel"}
NOT_EXPOSED = {"mesh": "the INPUT argument", "progress": "on unless --quiet",
               "topology": "its fields are options of their own (--flip-angle, --weld, ...)"}
FORMATS = ("obj", "ply", "stl", "off", "glb", "gltf")
# options of `simplify` that `qemjax lod` refuses (hidden from its --help): its levels carry positions only
LOD_REFUSED = ("attributes", "attribute_weights", "texture")


class CliError(ValueError):
    """A problem with the command's arguments or files: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with short errors: ``qemjax: error: …`` and one hint line naming the --help to read
    (``hint``: the command whose help that is; set by `main` for errors argparse reports at the top)."""

    hint: str | None = None
    subcommands: dict | None = None  # command name -> its parser (set by `_parser` on the top one)

    def error(self, message):
        print(f"qemjax: error: {' '.join(message.split())}", file=sys.stderr)
        print(f"see '{self.hint or self.prog} --help'", file=sys.stderr)
        raise SystemExit(2)

    def parse_args(self, args=None, namespace=None):
        """argparse's, with a misspelt option's close names: ``did you mean --boundary-weight?``."""
        args, extras = self.parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}{self._did_you_mean(args, extras)}")
        return args

    def _did_you_mean(self, args, extras) -> str:
        wrong = next((a.split("=", 1)[0] for a in extras if a.startswith("--")), None)
        if wrong is None:
            return ""
        if getattr(args, "cmd", None) == "lod" and wrong in TARGETS.values():  # lod_chain's refusal, not a near
            return f"; qemjax lod takes its targets from --ratios, not {wrong}"  # name (--max-shift for one)
        parser = (self.subcommands or {}).get(getattr(args, "cmd", None), self)
        options = [o for action in parser._actions if action.help is not argparse.SUPPRESS
                   for o in action.option_strings if o.startswith("--")]
        return _flat.did_you_mean(wrong, options, show=str)


def _doc_help(name: str, doc: str | None = None) -> str:
    """The first sentence of ``name``'s entry in simplify's docstring ('' if absent), %-escaped (``doc``: the
    docstrings searched, `_docs`)."""
    doc = _docs() if doc is None else doc
    m = re.search(rf"^(?:\w+ / )*{name}(?: / \w+)*: (.*?)(?=^\S|\Z)", doc, re.M | re.S)
    if not m:
        return ""
    text = " ".join(m.group(1).split()).replace("``", "")
    depth = 0
    for i, ch in enumerate(text):  # cut at the first full stop outside brackets: an interval such as
        depth += (ch in "([") - (ch in ")]")  # [0, √3/2) closes with the other kind
        if ch == "." and depth == 0 and (i + 1 == len(text) or text[i + 1] == " "):
            text = text[:i]
            break
    return text.replace("%", "%%")


def _docs() -> str:
    """The docstrings `_doc_help` searches: simplify's, then those of the settings' objects and methods."""
    return "\n".join(inspect.getdoc(x) or "" for x in (_api.simplify, *_flat.GROUPS.values(),
                                                      *_costs.REGISTRY.values(), _costs.base.Method))


def _cli_options() -> dict:
    """name → (type, default) of every option: `simplify`'s run keywords but the targets and NOT_EXPOSED,
    then every setting of `_flat.options` (the fields' real types), then ``preset``."""
    run = {name: (object if name in ("method", "scheduler", "attributes", "feature_edges") else bool, p.default)
           for name, p in inspect.signature(_api.simplify).parameters.items()
           if p.kind is p.KEYWORD_ONLY and name not in TARGETS and name not in NOT_EXPOSED}
    flat = {name: (o.type, o.default) for name, o in _flat.options().items() if name not in run}
    return {**run, **flat, "preset": (object, None)}


def _kind(hint):
    """(base type, whether None is allowed) of a field's type: ``float | None`` -> (float, True)."""
    args = typing.get_args(hint)
    if args and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return (rest[0] if len(rest) == 1 else object), True
    return hint, False


def _add_options(p: argparse.ArgumentParser, hidden=()):
    """Every option of `_cli_options`; those in ``hidden`` are parsed but left out of the help (the
    command refuses them with its reason). Booleans are --x / --no-x; numbers that may be None take 'none'."""
    docs = _docs()
    default_method = _costs.PRESETS["default"]()  # its settings differ from the fields' own defaults
    for name, (hint, default) in _cli_options().items():
        spec = dict(OPTIONS.get(name, {}))
        if callable(spec.get("choices")):
            spec["choices"] = spec["choices"]()
        kind, optional = _kind(hint)
        if kind is bool:
            spec["action"] = argparse.BooleanOptionalAction
        elif kind in (int, float) and not optional:
            spec.setdefault("type", kind)
            spec.setdefault("metavar", "N" if kind is int else "X")
        if "help" not in spec:
            spec["help"] = _doc_help(name, docs)
        partitioned = spec.pop("partitioned", "")  # what the option does with --partition, where it is offered
        spec["help"] += "" if "partition" in hidden else partitioned
        shown = spec.pop("shown", default)
        preset = getattr(default_method, name, shown)  # what the command runs without --method
        also = f"; {preset} with the default method" if preset != shown and name != "method" else ""
        if "(default)" not in spec["help"]:  # (a docstring's own "False (default): ..." says it already)
            spec["help"] += f" (default: {shown}{also})"
        if name in hidden:
            spec["help"] = argparse.SUPPRESS
        p.add_argument("--" + name.replace("_", "-"), dest=name, default=argparse.SUPPRESS, **spec)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-cache", action="store_true",
                   help="do not use the compilation cache (also: environment QEMJAX_NO_CACHE=1)")


def _parse(kind, text: str, what: str):
    """``kind(text)``, or argparse's error naming ``what`` (not the function's name)."""
    try:
        return kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def _ratio(text: str) -> float:
    r = _parse(float, text, "a ratio in (0, 1]")
    if not 0 < r <= 1:
        raise argparse.ArgumentTypeError(f"ratio must be in (0, 1] (the fraction of faces to keep), got {text}")
    return r


def _whole(what: str, least: int, most: int | None, says: str):
    """An argparse type: a whole number of ``what`` from ``least`` to ``most`` (None: no bound), else the
    one-line error ``says``."""
    def parse(text: str) -> int:
        n = _parse(int, text, f"a whole number of {what}")
        if n < least or (most is not None and n > most):
            raise argparse.ArgumentTypeError(f"{says}, got {text}")
        return n
    return parse


_faces = _whole("faces", 1, None, "the face target must be at least 1")
_workers = _whole("worker processes", 1, None, "the number of workers must be at least 1")
_jobs = _whole("processes", 0, None, "the number of processes must be 0 (one per core) or more")
# the demo's mesh: 20 × 4^N faces (10: 21 M; each one more quadruples the memory a run needs)
_subdivisions = _whole("subdivisions", 0, 10, "expected 0 to 10 subdivisions (20 × 4^N faces)")


def _max_error(text: str) -> float:
    e = _parse(float, text, "a number >= 0")
    if not e >= 0:
        raise argparse.ArgumentTypeError(f"max error must be >= 0 (in the method's error unit), got {text}")
    return e


def _distance(text: str) -> float:
    d = _parse(float, text, "a distance >= 0")
    if not (d >= 0 and np.isfinite(d)):
        raise argparse.ArgumentTypeError(f"the distance must be finite and >= 0, got {text}")
    return d


def _load_error(exc: Exception, form: str) -> str:
    """numpy's reason a vertex file could not be read, in the user's terms: a file that is not text (nor a
    .npy) said so in the words of Python's decoder, and a ragged one came with advice about numpy's own
    arguments (``usecols``), which the user does not pass."""
    if isinstance(exc, UnicodeDecodeError):
        return f"it is not text: expected a .npy file or text with {form}"
    return re.sub(r";\s*use `usecols`.*$", "", str(exc), flags=re.S)


def _read_feature_edges(path: str) -> np.ndarray:
    """(k,2) int64 vertex pairs from a .npy file or a text file of two integers per line (an empty text
    file: none, without numpy's warning about it)."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            a = np.load(path) if path.endswith(".npy") else np.loadtxt(path, dtype=np.int64, ndmin=2)
    except (OSError, ValueError) as exc:
        raise CliError(f"could not read feature edges from {path}: {_load_error(exc, 'two integers per line')}") from None
    return np.zeros((0, 2), np.int64) if a.size == 0 and not path.endswith(".npy") else a


def _read_vector(path: str, kind, flag: str) -> np.ndarray:
    """(k,) values from a .npy file or a text file of one value per line (``kind``: the text's type); an
    empty text file is no values (numpy's warning about it is left out: the run's checks name the file)."""
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            a = np.load(path) if path.endswith(".npy") else np.loadtxt(path, dtype=kind, ndmin=1)
    except (OSError, ValueError) as exc:
        form = "one integer per line" if np.issubdtype(kind, np.integer) else "one number per line"
        raise CliError(f"could not read {flag} from {path}: {_load_error(exc, form)}") from None
    a = a.reshape(-1) if a.ndim == 2 and 1 in a.shape else a
    if a.ndim != 1:
        raise CliError(f"{flag} {path}: expected a flat list of values (in text, one a line), got an "
                       f"array of shape {a.shape}")
    return a


def _name_vertex_files(args, exc: ValueError) -> str:
    """``exc``'s message, a check of ``locked``, ``vertex_weights`` (`_pipeline.locks`) or ``feature_edges``
    (run once the input is read) given in the user's terms: the option and its file, not the keyword."""
    text = str(exc)
    for name in ("locked", "vertex_weights", "feature_edges"):
        path = getattr(args, name, None)
        m = re.match(rf"{name}(?::\s*|\s+)(.*)", text, re.S) if path is not None else None
        if m:
            return f"--{name.replace('_', '-')} {path}: {m.group(1)}"
    return text


def _number_or_none(flag: str, text: str):
    if text.strip().lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise CliError(f"{flag} takes a number or 'none', got {text!r}") from None


def _scheduler_arg(text: str) -> str:
    """--scheduler: a scheduler's name, or a Dask scheduler's address (checked with --partition)."""
    if text in _schedulers.names() or "://" in text or ":" in text:
        return text
    raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from "
                                     f"{', '.join(map(repr, _schedulers.names()))}, or a Dask scheduler's address)")


def _partition_kwargs(args, kw: dict) -> None:
    """--partition and its options as ``kw["partition"]`` (a `qemjax.Partition`; a Dask client for an
    address given as --scheduler)."""
    extra = [f for f, v in (("--part-faces", args.part_faces), ("--workers", args.workers),
                            ("--scratch", args.scratch)) if v is not None]
    address = kw.get("scheduler") if kw.get("scheduler") not in (None, *_schedulers.names()) else None
    if not kw.get("partition"):
        if extra or address:
            raise CliError(f"{(extra or ['--scheduler ADDRESS'])[0]} needs --partition")
        if kw.get("partition") is None:  # --no-partition stays: in one process, whatever the mesh's size
            kw.pop("partition", None)
        return
    from ._options import Partition

    if address is not None and args.workers is not None:
        raise CliError("give --workers N (local processes) or --scheduler ADDRESS (a Dask cluster), not both")
    client = None
    if address is not None:
        try:
            from dask.distributed import Client
        except ImportError:
            raise CliError("--scheduler ADDRESS needs dask.distributed: pip install 'qemjax[dask]'") from None
        try:
            client = Client(address, timeout="10s")
        except OSError as exc:
            raise CliError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        kw.pop("scheduler")
    options = {k: v for k, v in (("part_faces", args.part_faces), ("workers", args.workers),
                                 ("scratch", args.scratch)) if v is not None}
    try:
        kw["partition"] = Partition(client=client, **options)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def _simplify_kwargs(args) -> dict:
    """The options given on the command line, as keywords of `simplify` (settings by their flat names)."""
    kw = {name: getattr(args, name) for name in TARGETS if getattr(args, name, None) is not None}
    for name, (hint, _) in _cli_options().items():
        if not hasattr(args, name) or getattr(args, name) is None:
            continue
        value, (kind, optional) = getattr(args, name), _kind(hint)
        if optional and kind in (int, float):
            value = _number_or_none("--" + name.replace("_", "-"), value)
        kw[name] = value
    if "feature_edges" in kw:
        kw["feature_edges"] = _read_feature_edges(kw["feature_edges"])
    for name, kind in (("locked", np.int64), ("vertex_weights", np.float64)):
        if getattr(args, name, None) is not None:
            kw[name] = _read_vector(getattr(args, name), kind, "--" + name.replace("_", "-"))
    if "attribute_weights" in kw:
        kw["attribute_weights"] = _attribute_weights(kw["attribute_weights"])
    if "attributes" in kw:
        text = kw["attributes"].strip().lower()
        kw["attributes"] = None if text == "none" else "auto" if text == "auto" else \
            tuple(k.strip() for k in text.split(",") if k.strip())
    kw["progress"] = not args.quiet
    if hasattr(args, "part_faces"):
        _partition_kwargs(args, kw)
    elif kw.get("scheduler") not in (None, *_schedulers.names()):
        raise CliError(f"--scheduler {kw['scheduler']}: a Dask scheduler's address needs qemjax simplify --partition")
    return kw


def _attribute_weights(text: str):
    """'0.5' -> 0.5; 'uv=0.3,color=0.1' -> {'uv': 0.3, 'color': 0.1}; CliError otherwise."""
    try:
        if "=" not in text:
            return float(text)
        return {k.strip(): float(v) for k, v in (item.split("=") for item in text.split(",") if item.strip())}
    except ValueError:
        raise CliError(f"--attribute-weights: expected a number or kind=W pairs, got {text!r}") from None


def check_output(path: str) -> str:
    """Before any work: the format of ``path`` (its extension) must be one trimesh writes for a triangle
    mesh, and its folder must exist and take a new file. Returns the format; CliError otherwise."""
    import trimesh

    if os.path.isdir(path):
        raise CliError(f"output {path} is a folder; give a file name")
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if not ext:
        raise CliError(f"output {path} needs an extension naming its format ({', '.join(FORMATS)})")
    try:  # the format: one triangle written to memory
        trimesh.Trimesh(np.eye(3), [[0, 1, 2]], process=False).export(file_type=ext)
    except Exception as exc:
        raise CliError(_not_a_mesh_format(ext, exc)) from None
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CliError(f"cannot write {path}: folder {folder} does not exist")
    probe = _temp_name(path, "probe")
    try:
        with open(probe, "xb"):
            pass
        os.remove(probe)
    except OSError as exc:
        raise CliError(f"cannot write to {folder}: {exc.strerror}") from None
    return ext


def _not_a_mesh_format(ext: str, exc: Exception) -> str:
    """Why ``.ext`` cannot take a mesh, in the user's terms (``exc``: what writing one triangle raised)."""
    import trimesh

    formats = ", ".join(FORMATS)
    if isinstance(exc, ImportError):
        return f"writing .{ext} files needs a Python package that is not installed ({exc}); or use one of {formats}"
    try:  # a format for points (.xyz) takes a point cloud but no faces
        trimesh.PointCloud(np.eye(3)).export(file_type=ext)
    except Exception:
        return f"cannot write a mesh as .{ext}: not a mesh format; use one of {formats}"
    return f"cannot write a mesh as .{ext}: the format holds points only, no faces; use one of {formats}"


def _temp_name(path: str, tag: str) -> str:
    folder, name = os.path.split(os.path.abspath(path))
    return os.path.join(folder, f".{name}.qemjax-{tag}-{os.getpid()}{os.path.splitext(name)[1]}")


def _atomic(path: str, save) -> None:
    """``save(tmp)`` to a temporary file in the folder of ``path``, then rename it over ``path``, so a
    failure leaves no partial file."""
    tmp = _temp_name(path, "out")
    try:
        save(tmp)
        _check_interrupted()  # no output for an interrupted run, even if the interrupt was swallowed
        os.replace(tmp, path)
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write(res, path: str, ext: str, exact: bool = False):
    """Export ``res`` to ``path`` as ``ext`` (atomically: `_atomic`). A result with UVs written as OBJ also
    gets its material file (``<stem>.mtl``) and texture image beside it (each written atomically, the OBJ
    last); GLB packs them in. UVs that came without a material are written without one (``vt`` lines, no
    mtl, no image). ``exact``: an OBJ or PLY holds the positions bit for bit (a run with locked vertices,
    which stay exactly where they are: `_exact_obj`, doubles in a PLY), not merely as precisely as the
    result's detail needs."""
    mesh = res.to_trimesh()
    _warn_format_losses(res, mesh.vertices, ext)
    material = getattr(mesh.visual, "material", None)
    copied = _io_texture.verbatim(material)  # a JPEG texture as read, not encoded again (a copy: res untouched)
    if copied is not material:
        mesh.visual.material = copied
    if ext == "obj" and getattr(res, "uv", None) is not None:
        from trimesh.exchange.obj import export_obj

        stem = os.path.splitext(os.path.basename(path))[0]
        if copied is material:
            mesh.visual.material = mesh.visual.material.copy()
        mesh.visual.material.name = stem  # the image is written as <stem>.<its format>
        text, files = export_obj(mesh, include_texture=True, return_texture=True, mtl_name=f"{stem}.mtl",
                                 digits=_obj_digits(mesh.vertices))
        if res.material is None:  # trimesh writes vt lines only with a material: drop its mtl again
            text = "".join(line for line in text.splitlines(keepends=True)
                           if not line.startswith(("mtllib ", "usemtl ")))
            files = {}
        if exact:
            text = _exact_obj(text, mesh.vertices)
        folder = os.path.dirname(os.path.abspath(path))
        for name, data in files.items():
            target = os.path.join(folder, os.path.basename(name))

            _atomic(target, lambda tmp, data=data: _write_file(tmp, data))
        _atomic(path, lambda tmp: _write_file(tmp, text))
        return
    if ext in ("ply", "obj"):  # positions as precise as the result's (`_io.ply.with_double_positions`, `_obj_digits`)
        data = mesh.export(file_type=ext, **({"digits": _obj_digits(mesh.vertices)} if ext == "obj" else {}))
        if ext == "ply":
            data = _io_ply.with_double_positions(data, mesh.vertices, always=exact)
        elif exact:
            data = _exact_obj(data, mesh.vertices)
        _atomic(path, lambda tmp: _write_file(tmp, data))
        return
    if ext == "gltf":  # one file, its buffers embedded: trimesh would write them beside it under fixed names
        from trimesh.exchange.gltf import export_gltf

        data = export_gltf(mesh, embed_buffers=True)["model.gltf"]
        _atomic(path, lambda tmp: _write_file(tmp, data))
        return
    _atomic(path, lambda tmp: mesh.export(tmp, file_type=ext))


_FORMAT_NAMES = {"gltf": "glTF"}


def _warn_format_losses(res, V, ext: str) -> None:
    """Warn when the format cannot hold what the result has: positions as precise as the result's (STL,
    GLB and glTF store float32, OFF as trimesh writes it 10 decimals; PLY and OBJ widen, `write`), or its
    kept attributes (STL and OFF store positions and faces only; PLY, UVs without their texture image; OBJ,
    colours without their alpha)."""
    V = np.asarray(V, np.float64)
    rounded = {"stl": lambda X: X.astype(np.float32), "glb": lambda X: X.astype(np.float32),
               "gltf": lambda X: X.astype(np.float32), "off": lambda X: np.round(X, 10)}.get(ext)
    if rounded is not None and len(V):
        diagonal = float(np.linalg.norm(V.max(0) - V.min(0)))
        moved = float(np.max(np.linalg.norm(rounded(V).astype(np.float64) - V, axis=1)))
        if moved > _io_ply.WIDEN_AT * diagonal:
            warnings.warn(f"{_FORMAT_NAMES.get(ext, ext.upper())} cannot hold the result's positions exactly: written, they move by up "
                          f"to {moved:.3g} ({100 * moved / diagonal:.2g} % of the diagonal); .ply or .obj keep them",
                          stacklevel=3)
    kept = [k for k in ("uv", "colors", "normals") if getattr(res, k, None) is not None]
    if kept and ext in ("stl", "off"):
        warnings.warn(f"{_FORMAT_NAMES.get(ext, ext.upper())} stores positions and faces only: the kept {', '.join(kept)} not written "
                      "(.obj, .ply, .glb and .gltf hold them)", stacklevel=3)
    colors = getattr(res, "colors", None)
    if ext == "obj" and colors is not None and len(colors) and (colors[:, 3] < 1).any():
        warnings.warn(f"OBJ stores vertex colours as RGB: their alpha (below 1 at {int((colors[:, 3] < 1).sum())} "
                      "vertices) is not written (.ply, .glb and .gltf hold it)", stacklevel=3)
    if ext == "ply" and getattr(res, "uv", None) is not None:
        from ._mesh.wedges import names_texture

        if names_texture(getattr(res, "material", None)):
            warnings.warn("PLY holds the UVs (as s, t) but not their texture image: the image is not written "
                          "(.obj writes it beside the file, .glb and .gltf pack it in)", stacklevel=3)


def _write_file(path: str, data) -> None:
    """Write ``data`` (bytes, or text as UTF-8) to ``path``."""
    with open(path, "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


def _exact_obj(text: str, V) -> str:
    """OBJ text whose ``v`` lines give x, y, z as the shortest decimals that read back as ``V``'s float64
    values (trimesh writes a fixed count of decimals, which rounds); the rest of each line (colours) kept.
    The text as it is where its ``v`` lines are not one per row of V."""
    lines = text.split("\n")
    at = [i for i, line in enumerate(lines) if line.startswith("v ")]
    if len(at) != len(V):
        return text
    for i, row in zip(at, np.asarray(V, np.float64).tolist()):
        lines[i] = " ".join(["v", *map(repr, row), *lines[i].split()[4:]])
    return "\n".join(lines)


def _obj_digits(V) -> int:
    """Decimals an OBJ's positions need so that rounding moves none by more than `_io.ply.WIDEN_AT` of the
    diagonal: trimesh's 8, more for a small mesh (a model in metres of a part a micrometre wide)."""
    V = np.asarray(V, np.float64)
    diagonal = float(np.linalg.norm(V.max(0) - V.min(0))) if len(V) else 0.0
    if not diagonal > 0:
        return 8
    return int(min(max(8, np.ceil(-np.log10(2 * _io_ply.WIDEN_AT * diagonal))), 17))


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"qemjax: warning: {message}", file=sys.stderr)


class _Version(argparse.Action):
    """--version, its text made when it is given (`qemjax._version_line`: no JAX imported)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show program's version number and exit"):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from . import _version_line

        print(_version_line())
        parser.exit()


def _add_partition_settings(p: argparse.ArgumentParser) -> None:
    """--part-faces, --workers and --scratch: `Partition`'s settings, for a command that offers --partition."""
    p.add_argument("--part-faces", dest="part_faces", type=_faces, metavar="K", help="with --partition: the most "
                   "faces one task reads (default 100000)")
    p.add_argument("--workers", type=_workers, metavar="N", help="with --partition: local worker processes (default: "
                   "every core)")
    p.add_argument("--scratch", metavar="DIR", help="with --partition: the folder for the parts (new, empty, or "
                   "one a partitioned run wrote; kept; a run of the same input and options resumes from it); "
                   "default: a temporary folder, removed at the end")


def _add_vertex_files(p: argparse.ArgumentParser) -> None:
    """--locked and --vertex-weights: per-vertex files (`_simplify_kwargs` reads them)."""
    p.add_argument("--locked", metavar="FILE", help="vertices that stay exactly where they are: indices of the "
                   "input's vertices as the file has them (.npy of indices or a boolean mask, or text with one "
                   "integer per line)")
    p.add_argument("--vertex-weights", dest="vertex_weights", metavar="FILE", help="one weight (finite, >= 0, at most 1e30) "
                   "per input vertex (.npy or text, one number per line): each pair's cost is multiplied by "
                   "the larger weight of its vertices, so heavy regions keep more detail")


def _parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="qemjax", description="Quadric-error mesh simplification with JAX.",
                 epilog="Errors (--max-error, the reported max error) are squared distances in the mesh's "
                 "units (mesh units²); with --method area, surface-area changes (also mesh units²). The "
                 "summary names the unit of each run.")
    ap.add_argument("--version", action=_Version)
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("simplify", help="simplify a mesh file")
    s.add_argument("input", help="any format trimesh reads (.obj, .ply, .stl, .off, .glb, ...)")
    s.add_argument("output", help=f"written as its extension says: {', '.join(FORMATS)}")
    g = s.add_mutually_exclusive_group()
    g.add_argument(TARGETS["ratio"], dest="ratio", type=_ratio, help="keep this fraction of the faces, in (0, 1]")
    g.add_argument(TARGETS["target_faces"], dest="target_faces", type=_faces, metavar="N",
                   help="target face count")
    s.add_argument(TARGETS["max_error"], dest="max_error", type=_max_error, metavar="E",
                   help="stop before a contraction costs more than E (the quadric error, a sum of squared distances to "
                   "planes, mesh units²: not the output's distance, which the summary measures; --method area: "
                   "surface-area change, mesh units²); alone or with --faces/--ratio")
    d = s.add_mutually_exclusive_group()
    d.add_argument(TARGETS["max_distance"], dest="max_distance", type=_distance, metavar="D",
                   help="keep the output within D mesh units of the input, both ways, at the input's and the "
                   "output's vertices and face centroids (stops early if needed; alone or with --faces/--ratio)")
    d.add_argument(TARGETS["max_distance_rel"], dest="max_distance_rel", type=_distance, metavar="R",
                   help="as --max-distance, with D = R × the input's bounding-box diagonal (0.005: 0.5 %%)")
    _add_options(s)
    _add_vertex_files(s)
    _add_partition_settings(s)
    lod = sub.add_parser("lod", help="levels of detail from one run: one file per level (and a .glb, a record)")
    lod.add_argument("input", help="any format trimesh reads (.obj, .ply, .stl, .off, .glb, ...)")
    lod.add_argument("out_dir", help="folder for the levels, NAME-lod0.EXT ..., one per ratio in the order of "
                     "--ratios (created if absent)")
    lod.add_argument("--ratios", type=_ratio, nargs="+", default=list(RATIOS), metavar="R",
                     help="fractions of the faces to keep, one level each "
                     f"(default: {' '.join(map(str, RATIOS))})")
    lod.add_argument("--format", dest="fmt", default="obj", choices=FORMATS, help="format of the level files "
                     "(default: obj)")
    lod.add_argument("--glb", action="store_true", help="also write NAME-lods.glb, one node per level, side "
                     "by side along x (1.2 × the mesh's x-extent apart, level 0 at the origin)")
    lod.add_argument("--record", action="store_true", help="also write NAME-record.npz, the progressive "
                     "record every level can be replayed from (qemjax.load_record)")
    _add_options(lod, hidden=LOD_REFUSED + ("partition",))
    _add_vertex_files(lod)
    sw = sub.add_parser("sweep", help="a parameter sweep described in a TOML (or YAML) file; writes its table",
                        description="Run qemjax.sweep as CONFIG describes: meshes, grid, targets, out (default: "
                        "CONFIG's name with .parquet), metrics, executor. See docs/cli.md, 'Sweep config files'.")
    sw.add_argument("config", help="a .toml file (.yaml/.yml with pyyaml installed)")
    sw.add_argument("--out", help="write the table here instead of the config's out (.parquet or .csv; a "
                    "table already there is resumed)")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.add_argument("--no-cache", action="store_true",
                    help="do not use the compilation cache (also: environment QEMJAX_NO_CACHE=1)")
    d = sub.add_parser("demo", help="simplify a bumpy sphere made in code (writes a file only with --out)")
    d.add_argument("--out", "--output", dest="out", metavar="PATH", help="write the result here")
    d.add_argument("--subdivisions", type=_subdivisions, default=7, metavar="N",
                   help="0 to 10: 20 × 4^N faces (7: 327,680; 10: 20,971,520) (default: 7)")
    d.add_argument("--ratio", type=_ratio, default=0.02, help="keep this fraction of the faces (default: 0.02)")
    _add_options(d)
    _add_partition_settings(d)
    ex = sub.add_parser("examples", help="write small example files made in code (bumpy.obj, bumpy.ply, "
                        "creases.txt, textured.obj, textured.png, sweep_example.toml)",
                        description="Write the example files the README uses, made in code: a bumpy sphere "
                        "(bumpy.obj, bumpy.ply), feature edges on it (creases.txt), a UV-mapped copy with "
                        "6 charts (textured.obj, no mtllib) and its texture (textured.png), and a sweep of "
                        "bumpy.obj and a torus (sweep_example.toml: qemjax sweep sweep_example.toml).")
    ex.add_argument("folder", nargs="?", default=".", help="where to write them (created if absent; default: .)")
    co = sub.add_parser("compile", help="compile the host loops ahead into numba's cache (an install from a "
                        "wheel or `pip install .` has them already)",
                        description="Compile every host loop that qemjax's common runs use into numba's cache, "
                        "so that no later run spends time compiling them: for an editable install, a "
                        "NUMBA_CACHE_DIR of your own, or a container image. `pip install .` does this already.")
    co.add_argument("--jobs", type=_jobs, default=0, help="processes to compile in (default: one per core)")
    ap.commands = tuple(sub.choices)
    ap.subcommands = dict(sub.choices)
    return ap


_INTERRUPTED: list = []  # non-empty once Ctrl-C arrived during `main` (`_on_sigint`)
_RAISED: list = []  # non-empty once that interrupt was raised: the run is on its way out
_SETTLING: list = []  # non-empty while `main` hands a last pending Ctrl-C to its handler before restoring
_ACTIVE: list = []  # non-empty while `main` runs with `_on_sigint` installed
_LOCK = threading.Lock()  # `_resend` against `main` leaving
_SAID: list = []  # non-empty once `main` printed 'qemjax: interrupted' (`leave`)


def _resend() -> None:
    """Send a deferred Ctrl-C again, while `main` still runs with its handler and has not raised one. A
    real signal, so that a main thread waiting on a lock or a future wakes up; sent to the process, so its
    C-level handler has run when ``os.kill`` returns. Under the lock `main` takes to leave: never after
    `main` returned, when the interpreter, exiting, has reset SIGINT to its default action (exit -2)."""
    with _LOCK:
        if _ACTIVE and not _RAISED:
            os.kill(os.getpid(), signal.SIGINT)


def _settle() -> None:
    """Nothing: calling a Python function lets the interpreter run a pending signal's handler."""


def _drops_exceptions(frame) -> bool:
    """Whether an exception raised at ``frame`` would be dropped on its way out: the stack holds a frame
    that Python runs as a callback and whose exceptions it prints as ignored and goes on (a garbage
    collector callback, as JAX has; a destructor, ``__del__``, as dask's futures have; a weak reference's
    callback, as `weakref.finalize`, the weak dictionaries and the weak sets run), or numba's own Python
    code, which its compiled loops call back into (to build their constants) and which drops an exception
    raised there."""
    callbacks = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    numba = sys.modules.get("numba")
    numba_dir = os.path.dirname(numba.__file__) + os.sep if getattr(numba, "__file__", None) else None
    weak = (weakref.__file__, _weakrefset.__file__)
    f = frame
    while f is not None:
        code = f.f_code
        if (code in callbacks or code.co_name == "__del__" or code.co_filename in weak
                or (numba_dir and code.co_filename.startswith(numba_dir))):
            return True
        f = f.f_back
    return False


def _on_sigint(signum, frame):
    """Ctrl-C: remembered, then raised as Python does, except where the exception would be dropped
    (`_drops_exceptions`): there the signal is sent again a moment later, once that callback has returned.
    `_atomic` and `main` also check the flag, so a run whose interrupt was lost all the same writes nothing
    and ends with exit code 130."""
    _INTERRUPTED.append(True)
    if _RAISED or _SETTLING:  # one interrupt is enough: the first is unwinding the run already
        return
    if _drops_exceptions(frame):
        timer = threading.Timer(0.05, _resend)
        timer.daemon = True
        timer.start()
        return
    _RAISED.append(True)
    raise KeyboardInterrupt


def _check_interrupted() -> None:
    if _INTERRUPTED:
        _RAISED.append(True)
        raise KeyboardInterrupt


def main(argv=None) -> int:
    """Run the command; returns the exit code (0 ok, 2 bad arguments, input or output, 130 interrupted:
    one line, and no partial output, since files are written under a temporary name and renamed)."""
    _INTERRUPTED.clear()
    _RAISED.clear()
    _SAID.clear()
    previous = None
    try:
        # started with Ctrl-C ignored (`nohup`, `cmd &` in a script, some CI runners): it stays ignored, as
        # the one who started us asked; else our handler
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
            previous = signal.signal(signal.SIGINT, _on_sigint)
            _ACTIVE.append(True)
    except ValueError:  # not the main thread: Python's own handling
        previous = None
    try:
        code = _main(sys.argv[1:] if argv is None else list(argv))
        _check_interrupted()  # a Ctrl-C that was swallowed on the way
        return code
    except KeyboardInterrupt as exc:  # a sweep's says how many rows it kept (`SweepInterrupted`)
        print(f"qemjax: interrupted{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        _SAID.append(True)
        return 130
    finally:
        if previous is not None:
            with _LOCK:  # no re-send from here on
                _ACTIVE.clear()
            _SETTLING.append(True)
            _settle()  # one sent just before reaches `_on_sigint`, which only records it now
            signal.signal(signal.SIGINT, previous)
            _SETTLING.clear()
        _RAISED.clear()


def _main(argv: list) -> int:
    if argv == ["--version"]:  # without building the parser (its options read every method's fields)
        from . import _version_line

        print(_version_line())
        return 0
    ap = _parser()
    cmd = next((a for a in argv if not a.startswith("-")), None)
    ap.hint = f"qemjax {cmd}" if cmd in ap.commands else None  # argparse reports stray options at the top
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a usage error _Parser has printed
        return exc.code if isinstance(exc.code, int) else 2
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        try:
            return _run(args)
        except ValueError as exc:
            print(f"qemjax: error: {_name_vertex_files(args, exc)}", file=sys.stderr)
            return 2


def _lod_run(args, kwargs, folder: str, lod_chain):
    """`_lod`'s run, in its output folder: (the chain, the level files' paths, the input's stem)."""
    stem = os.path.splitext(os.path.basename(args.input))[0]
    paths = [os.path.join(folder, f"{stem}-lod{i}.{args.fmt}") for i in range(len(args.ratios))]
    check_output(paths[0])
    if args.no_cache:  # else on from the first compilation (unless QEMJAX_NO_CACHE)
        _cache.disable()
    return lod_chain(args.input, ratios=args.ratios, **kwargs), paths, stem


def _lod(args, kwargs) -> int:
    """``qemjax lod``: one run, every level written (each file under a temporary name, then renamed)."""
    from ._pipeline.lod import lod_chain

    partition = kwargs.pop("partition", None)
    if partition:
        raise CliError("qemjax lod: --partition is offered by qemjax simplify only (a partitioned run keeps no "
                       "record to replay the levels from)")
    if partition is False:  # --no-partition: in one process even when the mesh would not fit (`_pipeline.fits`)
        kwargs["partition"] = False
    refused = ["--" + name.replace("_", "-") for name in LOD_REFUSED if kwargs.get(name) is not None]
    if refused:
        raise CliError(f"qemjax lod keeps positions only: its levels are replayed from contractions "
                       f"({', '.join(refused)} given); use qemjax simplify --texture for a textured result")
    moved = ["--" + name.replace("_", "-") for name in ("refit", "polish", "sliver_moves") if kwargs.get(name)]
    if moved:  # they move a run's result, which no level file holds
        raise CliError(f"qemjax lod writes the levels as replayed from the run's contractions, which "
                       f"{', '.join(moved)} would not change (they move one result: qemjax simplify)")
    folder = os.path.abspath(args.out_dir)
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"output {args.out_dir} is a file; give a folder")
    if not os.path.isdir(os.path.dirname(folder)):
        raise CliError(f"cannot create {args.out_dir}: folder {os.path.dirname(folder)} does not exist")
    made = not os.path.exists(folder)
    os.makedirs(folder, exist_ok=True)
    try:
        chain, paths, stem = _lod_run(args, kwargs, folder, lod_chain)
    except BaseException:
        if made and not os.listdir(folder):  # a failed run leaves no empty folder it made
            os.rmdir(folder)
        raise
    for path, level, r in zip(paths, chain.levels, chain.ratios):
        write(level, path, args.fmt, exact=kwargs.get("locked") is not None)
        print(f"{path}: ratio {r:g}, {len(level.faces)} faces, max error {level.max_error:.3g}")
    extra = []
    if args.glb:
        extra.append((os.path.join(folder, f"{stem}-lods.glb"), chain.export))
    if args.record:
        extra.append((os.path.join(folder, f"{stem}-record.npz"), chain.result.record.save))
    for path, save in extra:
        _atomic(path, save)
        print(path)
    print(f"{args.input}: {chain.result.summary()}")
    _print_details(chain.result, "the ratios")
    return 0


def _sweep(args) -> int:
    """``qemjax sweep CONFIG``: the whole config is checked before anything runs."""
    from ._sweep import config as _sweep_config

    config = _sweep_config.load(args.config, out=args.out)
    if args.no_cache:  # else on from the first compilation (unless QEMJAX_NO_CACHE)
        _cache.disable()
    df = _sweep_config.run(config, progress=not args.quiet)
    failed = int((df["error"].fillna("") != "").sum())
    info = df.attrs.get("sweep", {})
    extra = f"; {info['skipped']} were already there (skipped)" if info.get("skipped") else ""
    if info.get("collapsed"):
        extra += (f"; {info['requested']} requested cells collapsed to {info['cells']} ("
                  + "; ".join(f"{n}: {why}" for why, n in info["collapsed"].items()) + ")")
    print(f"{args.config}: {len(df)} cells ({failed} failed) -> {config.out}{extra}")
    return 0


def _examples(args) -> int:
    """``qemjax examples [FOLDER]``: the README's example files, made in code."""
    from .shapes import write_examples

    if os.path.exists(args.folder) and not os.path.isdir(args.folder):
        raise CliError(f"{args.folder} is a file; give a folder")
    for path in write_examples(args.folder):
        print(path)
    return 0


def _run(args) -> int:
    if args.cmd == "examples":
        return _examples(args)
    if args.cmd == "compile":
        from ._ahead import compile_ahead

        r = compile_ahead(args.jobs)
        print(f"qemjax: {r['compiled']} host loops compiled, {r['loaded']} already in numba's cache "
              f"({r['signatures']} listed) in {r['seconds']:.1f} s" + (f"; {len(r['failed'])} failed (they "
              f"compile on first use): " + "; ".join(r["failed"]) if r["failed"] else ""))
        return 0
    if args.cmd == "sweep":
        return _sweep(args)
    if args.cmd == "lod":
        return _lod(args, _simplify_kwargs(args))
    if args.cmd == "simplify" and all(getattr(args, k) is None for k in TARGETS):
        raise CliError("give a target: --faces N, --ratio R, --max-error E, --max-distance D or --max-distance-rel R")
    out = args.output if args.cmd == "simplify" else args.out
    ext = check_output(out) if out is not None else None
    kwargs = _simplify_kwargs(args)
    if args.no_cache:  # else on from the first compilation (unless QEMJAX_NO_CACHE)
        _cache.disable()
    if args.cmd == "simplify":
        res = _api.simplify(args.input, **kwargs)
        name = args.input
    else:
        from .shapes import bumpy_sphere

        mesh = bumpy_sphere(args.subdivisions)
        res = _api.simplify(mesh, **kwargs)
        name = f"bumpy sphere ({len(mesh.faces)} faces)"
    if out is not None:
        write(res, out, ext, exact=kwargs.get("locked") is not None)
    where = f" -> {out}" if out is not None else " (not written; --out PATH saves it)"
    print(f"{name}: {res.summary()}{where}")
    _print_details(res, "the ratio" if getattr(args, "ratio", None) else None)
    return 0


def _print_details(res, target: str | None) -> None:
    """Below the summary, indented: what clean-up removed (`cleanup_note`) and the attributes kept
    (`attributes_note`), each when there is something to say."""
    for line in (cleanup_note(res.stats, target), attributes_note(res.stats)):
        if line:
            print(f"  {line}")


def _count(n: int, one: str, many: str | None = None) -> str:
    return f"{n} {one}" if n == 1 else f"{n} {many or one + 's'}"


def cleanup_note(stats: dict, target: str | None = "the ratio") -> str:
    """What the input's clean-up (`qemjax._io.mesh.prepare`) removed, and that ``target`` (a ratio's name, or
    None) counted from the faces left: 'clean-up: 724 duplicate faces removed; the ratio applied to the
    1510 faces left (of 2234 read)'. '' when it removed nothing."""
    faces = {"duplicate": stats.get("duplicate_removed", 0), "degenerate": stats.get("degenerate_removed", 0),
             "zero-area": stats.get("zero_area_removed", 0)}
    parts = [_count(n, f"{what} face") + " removed" for what, n in faces.items() if n]
    welded = " welded" + (" (their attribute values kept as wedges)" if stats.get("attributes") else "")
    for key, what, done in (("welded", "coincident", welded), ("unreferenced_removed", "unused", " removed")):
        if stats.get(key):
            parts.append(_count(stats[key], what + " vertex", what + " vertices") + done)
    if not parts:
        return ""
    note = "clean-up: " + ", ".join(parts)
    if any(faces.values()):
        read = stats["faces_in"] + sum(faces.values())
        left = f"{stats['faces_in']} faces left (of {read} read)"
        note += f"; {target} applied to the {left}" if target else f"; {left}"
    return note


def attributes_note(stats: dict) -> str:
    """The appearance attributes kept and the seams they hold, or those dropped: 'kept uv: 13 seams (412
    seam edges, 380 seam vertices) constrained like boundaries, 1203 contractions refused there'. ''
    when the input carried none."""
    parts = []
    if stats.get("attributes"):
        seams = stats.get("seams_in")  # None: not counted (a partitioned run's parts are not seen whole)
        note = f"kept {', '.join(stats['attributes'])}" + ("" if seams is None else ": " + (
            _count(seams, "seam") if seams else "no seams"))
        if seams:
            note += (f" ({stats.get('seam_edges_in', 0)} seam edges, {stats.get('seam_vertices_in', 0)} seam "
                     "vertices) constrained like boundaries")
        refused = stats.get("rejected_by", {}).get("seam", 0)
        if refused:
            note += f", {_count(refused, 'contraction')} refused there"
        parts.append(note)
    if stats.get("normals_recomputed"):
        parts.append(f"{_count(stats['normals_recomputed'], 'stored normal')} of zero length recomputed from the "
                     "faces")
    if stats.get("not_kept_seams"):
        kinds = stats["not_kept_seams"]
        parts.append(f"not kept by default, for their seams: {', '.join(kinds)} (--attributes {','.join(kinds)} "
                     "keeps them)")
    dropped = [d for d in stats.get("dropped", []) if d not in
               {"uv", "vertex_colors", "normals", "material"} & set(_not_kept_names(stats))]
    if dropped:
        parts.append(f"dropped {', '.join(dropped)}")
    return "; ".join(parts)


def _not_kept_names(stats: dict) -> list[str]:
    """The names in stats['dropped'] that `attributes_note` already gives as not kept for their seams."""
    from ._mesh.wedges import DROPPED_NAME

    names = [DROPPED_NAME[k] for k in stats.get("not_kept_seams", [])]
    return names + (["material"] if "uv" in stats.get("not_kept_seams", []) else [])


def leave(run) -> int:
    """``run()``'s exit code, also when a Ctrl-C is handled only after `main` gave Python its own handler
    back (one re-sent by `_resend` can arrive there): the run was interrupted, so 130, said once."""
    try:
        return run()
    except KeyboardInterrupt:
        if not _SAID:
            print("qemjax: interrupted", file=sys.stderr)
        return 130


def exit_soon() -> None:
    """The command's last step, in either entry point run as the program (``qemjax``, ``python -m qemjax``,
    ``python -m qemjax._cli``): the objects the process holds are moved out of the garbage collector's reach
    (`gc.freeze`). Python's shutdown collects garbage once more, and after JAX, numba and a run that
    collection walks a large graph of objects for nothing: most of the time between a command's last line
    and its exit (docs/benchmarks.md, "A command's exit"). Memory is still freed, by reference counts and
    by the process's end."""
    gc.freeze()


if __name__ == "__main__":
    code = leave(main)
    exit_soon()
    sys.exit(code)
