"""Meshes generated in code (no files needed): for tests, the demo, experiments and sweeps.

Every generator (`SHAPES`) returns a `Mesh` (vertices (n,3) float64, faces (m,3) int64), consistently
oriented. A sweep (or its config file) names them as text, ``"shapes.torus"`` or
``"shapes.bumpy_sphere(subdivisions=4)"`` (`parse_spec`: a name from `SHAPES` and keyword arguments with
literal values, never evaluated as code). `write_examples` writes the small example files the README and docs/ use.
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import os
from pathlib import Path
from typing import Any

import numpy as np

from ._io.mesh import Mesh
from ._mesh import fixed_order

SHAPES = ("bumpy_sphere", "icosphere", "torus", "cube", "grid")  # the generators a spec may name


# the least of each count a generator takes: fewer made an empty mesh, or faces on the same vertices
_LEAST = {"icosphere": {"subdivisions": 0}, "bumpy_sphere": {"subdivisions": 0, "seed": 0}, "cube": {"subdivisions": 0},
          "torus": {"n_major": 3, "n_minor": 3}, "grid": {"n": 1}, "double_cone": {"n": 3}}
# the lengths a generator takes, each a finite number > 0: zero made every vertex one point, a negative one
# turned the faces inside out
_LENGTHS = {"icosphere": ("radius",), "torus": ("major", "minor"), "grid": ("size",),
            "double_cone": ("radius", "height")}
# the numbers a generator takes that may be 0 or negative, each finite (NaN or inf made NaN vertices): a
# bumpy sphere's amplitude (0: a plain sphere; a negative one bumps inward)
_FINITE = {"bumpy_sphere": ("amplitude",)}


# the fewest bytes a face any generator takes while it makes its mesh: the mesh returned (three int64 indices
# a face, and about half a vertex of three float64: 36) and its faces once more as they are built (24)
MAKE_BYTES_PER_FACE = 60
# a shape that needs less is made without reading the memory available (which takes longer than making a small
# one): no machine that runs this package has less to spare
_CHECKED_FROM = 1 << 28


def _counts(shape: str, args: dict, text: str | None = None) -> None:
    """ValueError naming ``shapes.shape``'s argument (after ``text``, the spec as written, when given) unless
    each count in ``args`` is an integer at least its `_LEAST` (a grid with a hole: 3, the hole being its
    middle third) and each length (`_LENGTHS`) a finite number > 0 (a torus's minor radius under its major
    one: else its tube passes through the axis), and each of `_FINITE` a finite number. Without ``text`` (a
    generator called directly, with every argument), also one for a shape too large to make here (`_room`)."""
    hole = bool(args.get("hole", False))
    for name, least in _LEAST[shape].items():
        if name not in args:
            continue
        value, why = args[name], ""
        if hole and name == "n":
            least, why = 3, " with hole=True"
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < least:
            raise ValueError(f"{text or 'shapes.' + shape}: {name} must be an integer >= {least}{why}, got {value!r}")
    for name in _LENGTHS.get(shape, ()):
        if name not in args:
            continue
        value = args[name]
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value) or value <= 0:
            raise ValueError(f"{text or 'shapes.' + shape}: {name} must be a number > 0, got {value!r}")
    for name in _FINITE.get(shape, ()):
        if name not in args:
            continue
        value = args[name]
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value):
            raise ValueError(f"{text or 'shapes.' + shape}: {name} must be a finite number, got {value!r}")
    if shape == "torus":  # (a spec's args are those it gives: the others, the generator's defaults)
        given = {k: p.default for k, p in inspect.signature(torus).parameters.items()} | args
        if given["minor"] >= given["major"]:
            raise ValueError(f"{text or 'shapes.torus'}: minor must be less than major (the tube's radius under "
                             f"the ring's), got minor={given['minor']!r}, major={given['major']!r}")
    if text is None:
        _room(shape, args)


def _room(shape: str, args: dict) -> None:
    """ValueError, before a generator called directly makes anything, for a shape whose making would need more
    memory than this machine has available, in the words of a sweep's shape too large to run (`_fits`): the
    system would otherwise kill the process while making it, without a word."""
    n = _faces(shape, args)
    if n * MAKE_BYTES_PER_FACE < _CHECKED_FROM:
        return
    from ._pipeline import fits

    short = fits.shortfall(n, fits.available(), MAKE_BYTES_PER_FACE)
    if short is not None:
        counts = ", ".join(f"{k}={args[k]!r}" for k in _LEAST[shape] if k != "seed")  # those that set the size
        raise ValueError(f"shapes.{shape}({counts}): {short}: ask for a smaller shape")


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> Mesh:
    """Geodesic sphere of the given ``radius`` with 20·4^subdivisions faces (subdivisions >= 0)."""
    import trimesh

    _counts("icosphere", dict(subdivisions=subdivisions, radius=radius))
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return Mesh(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))


def torus(major: float = 1.0, minor: float = 0.35, n_major: int = 48, n_minor: int = 24) -> Mesh:
    """Closed genus-1 torus with 2·n_major·n_minor faces (n_major, n_minor >= 3: segments around the ring and
    around the tube)."""
    _counts("torus", dict(n_major=n_major, n_minor=n_minor, major=major, minor=minor))
    u, v = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a, b = 2 * np.pi * u / n_major, 2 * np.pi * v / n_minor
    cos, sin = fixed_order.cos, fixed_order.sin  # the C library's: the same mesh on every CPU
    V = np.stack([(major + minor * cos(b)) * cos(a), (major + minor * cos(b)) * sin(a),
                  minor * sin(b)], -1).reshape(-1, 3)
    i0 = (u * n_minor + v).reshape(-1)
    i1 = (((u + 1) % n_major) * n_minor + v).reshape(-1)
    i2 = (((u + 1) % n_major) * n_minor + (v + 1) % n_minor).reshape(-1)
    i3 = (u * n_minor + (v + 1) % n_minor).reshape(-1)
    F = np.concatenate([np.stack([i0, i1, i2], 1), np.stack([i0, i2, i3], 1)])
    return Mesh(V, F.astype(np.int64))


def grid(n: int = 20, size: float = 1.0, hole: bool = False) -> Mesh:
    """Flat open square [0,size]² in the z=0 plane, n×n cells of two triangles, normals +z.

    hole=True removes the cells of the middle third, leaving a square hole (a second boundary loop).
    n >= 1; with hole=True, n >= 3 (fewer cells have no middle third to remove with a border left).
    """
    _counts("grid", dict(n=n, hole=hole, size=size))
    x = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    V = np.stack([X.reshape(-1), Y.reshape(-1), np.zeros(X.size)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = np.ones_like(i, bool)
    if hole:
        lo, hi = n // 3, n - n // 3
        keep = ~((i >= lo) & (i < hi) & (j >= lo) & (j < hi))
    i, j = i[keep], j[keep]
    a = i * (n + 1) + j
    b, c, d = a + (n + 1), a + (n + 2), a + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return Mesh(V[used], remap[F].astype(np.int64))


def cube(subdivisions: int = 2) -> Mesh:
    """Closed unit cube (sharp creases and corners), each face split by midpoint subdivision (subdivisions
    >= 0: 12·4^subdivisions faces)."""
    import trimesh

    _counts("cube", dict(subdivisions=subdivisions))
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    for _ in range(subdivisions):
        V, F = trimesh.remesh.subdivide(V, F)
    return Mesh(np.asarray(V, float), np.asarray(F, np.int64))


def bumpy_sphere(subdivisions: int = 6, amplitude: float = 0.08, seed: int = 0) -> Mesh:
    """Icosphere whose radius varies with a few smooth random bumps: detail worth simplifying.
    subdivisions=6 gives 81,920 faces, 7 gives 327,680 (subdivisions >= 0). ``amplitude``: the bumps' height
    relative to the unit radius; ``seed``: which bumps (the same seed gives the same mesh on every CPU)."""
    _counts("bumpy_sphere", dict(subdivisions=subdivisions, amplitude=amplitude, seed=seed))
    V, F = icosphere(subdivisions)
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(12, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    # fixed-order products and the C library's exp and sin: the same mesh on every CPU (_mesh.fixed_order)
    bumps = fixed_order.exp(8.0 * (fixed_order.dot(V[:, None], dirs[None]) - 1.0)) * rng.uniform(-1, 1, 12)
    r = 1.0 + amplitude * np.sum(bumps, 1)
    r += 0.25 * amplitude * fixed_order.sin(9 * V[:, 0]) * fixed_order.sin(7 * V[:, 1]) * fixed_order.sin(8 * V[:, 2])
    return Mesh(V * r[:, None], F)


def double_cone(n: int = 500, radius: float = 1.0, height: float = 1.0) -> Mesh:
    """Closed double cone: a ring of n vertices of the given ``radius`` in the z=0 plane and two apexes at z=±height, each apex
    joined to every ring vertex (valence n), 2n faces (n >= 3). A fan-triangulated cap taken to the extreme."""
    _counts("double_cone", dict(n=n, radius=radius, height=height))
    t = 2 * np.pi * np.arange(n) / n
    V = np.concatenate([np.stack([radius * fixed_order.cos(t), radius * fixed_order.sin(t), np.zeros(n)], 1),
                        [[0.0, 0.0, height], [0.0, 0.0, -height]]])
    i, j = np.arange(n), (np.arange(n) + 1) % n
    F = np.concatenate([np.stack([i, j, np.full(n, n)], 1), np.stack([j, i, np.full(n, n + 1)], 1)])
    return Mesh(V, F.astype(np.int64))


# -- shapes named as text (sweeps, config files) ------------------------------------------------------

PREFIX = "shapes."


@dataclasses.dataclass(frozen=True)
class ShapeSpec:
    """A generator of `SHAPES` and its keyword arguments: ``build()`` makes the mesh; ``str()`` is the
    canonical text ``shapes.NAME(key=value, ...)``, which `parse_spec` reads back."""

    name: str
    kwargs: tuple[tuple[str, Any], ...] = ()

    def build(self) -> Mesh:
        return globals()[self.name](**dict(self.kwargs))

    def __str__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.kwargs)
        return f"{PREFIX}{self.name}({args})" if args else f"{PREFIX}{self.name}"


def is_spec(value) -> bool:
    """True for text that names a shape (``"shapes.…"``) and for a table with a ``shape`` key."""
    if isinstance(value, dict):
        return "shape" in value
    return isinstance(value, str) and value.strip().startswith(PREFIX)


def _literal(node, text):
    if isinstance(node, ast.Name) and node.id.lower() in ("true", "false"):  # TOML spells them lower-case
        return node.id.lower() == "true"
    try:
        return ast.literal_eval(node)
    except ValueError:
        raise ValueError(f"bad shape {text!r}: keyword values must be numbers, strings or true/false, "
                         f"got {ast.unparse(node)!r}") from None


def _unknown(name) -> ValueError:
    return ValueError(f"unknown shape {name!r}; qemjax.shapes makes {', '.join(PREFIX + n for n in SHAPES)}")


def parse_spec(value) -> ShapeSpec:
    """A `ShapeSpec` from ``"shapes.NAME"``, ``"shapes.NAME(key=value, ...)"`` (keyword arguments only,
    values as literals: numbers, strings, true/false) or a table ``{"shape": "NAME", key: value, ...}``.
    Checked against the generator's signature and default types; ValueError (one line) otherwise. Nothing
    is evaluated as code."""
    if isinstance(value, dict):
        kwargs = {k: v for k, v in value.items() if k != "shape"}
        name = value.get("shape")
        if not isinstance(name, str):
            raise ValueError(f"a shape table needs shape = one of {', '.join(SHAPES)}, got {name!r}")
        name = name.strip().removeprefix(PREFIX)
        text = f"{PREFIX}{name}"
    else:
        text = str(value).strip()
        try:
            node = ast.parse(text, mode="eval").body
        except SyntaxError:
            raise ValueError(f"bad shape {text!r}: write shapes.NAME or shapes.NAME(key=value, ...)") from None
        call = node if isinstance(node, ast.Call) else None
        func = call.func if call else node
        if not (isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name)
                and func.value.id == PREFIX[:-1]):
            raise ValueError(f"bad shape {text!r}: write shapes.NAME or shapes.NAME(key=value, ...)")
        name = func.attr
        if call and (call.args or any(k.arg is None for k in call.keywords)):
            raise ValueError(f"bad shape {text!r}: give keyword arguments, e.g. shapes.{name}(key=value)")
        kwargs = {k.arg: _literal(k.value, text) for k in call.keywords} if call else {}
    if name not in SHAPES:
        raise _unknown(text if not isinstance(value, dict) else name)
    params = inspect.signature(globals()[name]).parameters
    for k, v in kwargs.items():
        if k not in params:
            raise ValueError(f"{text}: unknown keyword {k!r}; shapes.{name} takes {', '.join(params)}")
        default = params[k].default
        ok = (isinstance(v, bool) if isinstance(default, bool) else
              isinstance(v, int) and not isinstance(v, bool) if isinstance(default, int) else
              isinstance(v, (int, float)) and not isinstance(v, bool) if isinstance(default, float) else True)
        if not ok:
            raise ValueError(f"{text}: {k} must be {type(default).__name__}, got {v!r}")
    _counts(name, kwargs, text)  # as the generator would, before a sweep starts
    _fits(name, {k: p.default for k, p in params.items()} | kwargs, text)
    return ShapeSpec(name, tuple((k, kwargs[k]) for k in params if k in kwargs))


def _faces(name: str, args: dict) -> int:
    """The faces shape ``name`` makes with ``args`` (every argument given: the spec's over the defaults); at
    most those of 64 subdivisions (more than any machine holds, and a count that still prints)."""
    if name in ("icosphere", "bumpy_sphere", "cube"):
        return (20 if name != "cube" else 12) * 4 ** min(args["subdivisions"], 64)
    if name in ("torus", "double_cone"):
        return 2 * (args["n_major"] * args["n_minor"] if name == "torus" else args["n"])
    n = args["n"]  # grid: n × n cells of two faces, less the middle third's with a hole
    return 2 * (n * n - ((n - 2 * (n // 3)) ** 2 if args["hole"] else 0))


def _fits(name: str, args: dict, text: str) -> None:
    """ValueError, before the shape is made, for one whose run would need more memory than this machine has
    available (`_pipeline.fits`): a sweep or config file naming it would otherwise be killed by the system
    while making it, without a word."""
    from ._pipeline import fits

    short = fits.shortfall(_faces(name, args), fits.available())
    if short is not None:
        raise ValueError(f"{text}: {short}: ask for a smaller shape")


# -- example files ------------------------------------------------------------------------------------

EXAMPLES = ("bumpy.obj", "bumpy.ply", "creases.txt", "textured.obj", "textured.png")


def _atlas(V: np.ndarray, F: np.ndarray):
    """A cube map of a sphere-like mesh into a 3×2 UV atlas: each face's chart is the dominant axis (and
    sign) of its normal, 6 charts with seams between them. Returns (uv (t,2), uv index per corner (m,3))."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ax = np.argmax(np.abs(n), axis=1)
    chart = 2 * ax + (n[np.arange(len(F)), ax] < 0)
    key = F * 6 + chart[:, None]  # one UV per (vertex, chart)
    uniq, inv = np.unique(key.reshape(-1), return_inverse=True)
    v, c = uniq // 6, uniq % 6
    keep = np.array([[1, 2], [1, 2], [0, 2], [0, 2], [0, 1], [0, 1]])
    proj = np.take_along_axis(V[v], keep[c], axis=1)
    proj = proj / max(float(np.abs(proj).max()), 1e-12)  # in [-1, 1]
    tile = np.stack([c % 3, c // 3], 1).astype(float)
    uv = (tile + 0.5 + 0.45 * proj) / np.array([3.0, 2.0])
    return uv, inv.reshape(-1, 3)


def _checkerboard(width: int = 384, height: int = 256, squares: int = 8) -> np.ndarray:
    """(height, width, 3) uint8: a 3×2 atlas of tiles, each a checkerboard in its own hue."""
    hues = np.array([[230, 80, 60], [60, 170, 80], [70, 110, 220], [230, 190, 50], [160, 80, 200],
                     [50, 190, 200]], float)
    y, x = np.mgrid[0:height, 0:width]
    tw, th = width // 3, height // 2
    tile = np.minimum(x // tw, 2) + 3 * np.minimum(y // th, 1)
    tile = np.where(tile < 6, tile, 5)
    check = ((x * squares // tw) + (y * squares // th)) % 2
    img = hues[tile] * np.where(check, 1.0, 0.55)[..., None]
    return np.flipud(img).astype(np.uint8)  # row 0 is the top of the image: v = 1


def _meridian(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(k,2) the edges of the shortest edge path from the highest vertex to the lowest: a feature line."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    e = np.unique(np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    w = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    g = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(V), len(V))).tocsr()
    top, bottom = int(np.argmax(V[:, 2])), int(np.argmin(V[:, 2]))
    _, pred = dijkstra(g, directed=False, indices=top, return_predecessors=True)
    path = [bottom]
    while path[-1] != top:
        path.append(int(pred[path[-1]]))
    return np.array(path[::-1])[np.arange(len(path) - 1)[:, None] + [0, 1]]


def _write(path: Path, text: str) -> Path:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


EXAMPLE_SWEEP = """\
# qemjax sweep sweep_example.toml   (written by `qemjax examples`; docs/cli.md explains every key)
# Paths are relative to this file's folder: bumpy.obj is written beside it; the torus is made in code.

meshes = ["bumpy.obj", "shapes.torus(n_major=32, n_minor=16)"]  # or [meshes] name = "path"; shapes.NAME(...)
targets = [0.1, 0.25, 200]            # ratios (floats in (0, 1)) and face counts (integers)
out = "sweep_example.csv"             # default: the config's name with .parquet (needs pyarrow); .csv needs nothing

[grid]                                # simplify keywords = lists of values, crossed
method = ["qem", "esqem"]
boundary_weight = [1.0, 100.0]
split_factor = ["none", 1.3333333]    # "none" is None (TOML has no null); an ESQEM setting: "n/a" in qem's rows

[metrics]                             # or: metrics = false (none), true (the default: all, 100 000 samples)
n_samples = 5000                      # qemjax.metrics.evaluate's keywords: n_samples, seed

[executor]                            # leave out: every core, when the work pays (docs/sweeps.md)
workers = 2                           # 2 processes: the command's and a helper (1: the command's alone) ...
# scheduler = "dask"                  # ... or a Dask LocalCluster of 2 single-threaded worker processes
# address = "tcp://scheduler:8786"    # or a running Dask cluster (instead of workers)
"""


def write_examples(folder=".", subdivisions: int = 4) -> list[Path]:
    """Write small example files made in code into ``folder`` (created if absent) and return their paths:

    - ``bumpy.obj`` and ``bumpy.ply``: `bumpy_sphere` (``subdivisions=4``: 5,120 faces), positions only;
    - ``creases.txt``: vertex-index pairs of bumpy.obj along a meridian (for ``feature_edges`` /
      ``--feature-edges``);
    - ``textured.obj``: the same sphere with ``vt`` lines and no ``mtllib`` (so give ``texture=``): a cube
      map into a 3×2 UV atlas, 6 charts with seams between them;
    - ``textured.png``: its texture, a checkerboard per chart;
    - ``sweep_example.toml``: a sweep of bumpy.obj and a torus (`EXAMPLE_SWEEP`: ``qemjax sweep
      sweep_example.toml`` in that folder writes sweep_example.csv).

    Existing files of these names are replaced."""
    from PIL import Image

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    V, F = bumpy_sphere(subdivisions)
    num = lambda a: "\n".join(" ".join(f"{x:.9g}" for x in row) for row in a)  # noqa: E731
    ints = lambda a: "\n".join(" ".join(str(int(x)) for x in row) for row in a)  # noqa: E731
    head = f"# qemjax example: shapes.bumpy_sphere(subdivisions={subdivisions}), {len(F)} faces\n"
    out = [_write(folder / "bumpy.obj", head + "\n".join(["\n".join("v " + r for r in num(V).split("\n")),
                                                          "\n".join("f " + r for r in ints(F + 1).split("\n"))])
                  + "\n")]
    ply = ["ply", "format ascii 1.0", f"comment {head[2:-1]}", f"element vertex {len(V)}", "property float64 x",
           "property float64 y", "property float64 z", f"element face {len(F)}",
           "property list uint8 int32 vertex_indices", "end_header", num(V),
           "\n".join("3 " + r for r in ints(F).split("\n"))]
    out.append(_write(folder / "bumpy.ply", "\n".join(ply) + "\n"))
    out.append(_write(folder / "creases.txt", "# vertex-index pairs of bumpy.obj along a meridian: "
                      "feature edges\n" + ints(_meridian(V, F)) + "\n"))
    uv, T = _atlas(V, F)
    faces = "\n".join(f"f {a}/{ta} {b}/{tb} {c}/{tc}" for (a, b, c), (ta, tb, tc) in zip(F + 1, T + 1))
    obj = ["# qemjax example: a bumpy sphere with a 3x2 UV atlas (6 charts, seams between them); no mtllib: "
           "its texture is textured.png (texture=)", "\n".join("v " + r for r in num(V).split("\n")),
           "\n".join("vt " + r for r in num(uv).split("\n")), faces]
    out.append(_write(folder / "textured.obj", "\n".join(obj) + "\n"))
    png = folder / "textured.png"
    tmp = png.with_name(".textured.png.tmp")
    Image.fromarray(_checkerboard()).save(tmp, format="PNG")
    os.replace(tmp, png)
    out.append(png)
    out.append(_write(folder / "sweep_example.toml", EXAMPLE_SWEEP))
    return out
