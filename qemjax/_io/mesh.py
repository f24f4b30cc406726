"""Input: reading meshes, validating them and cleaning them for simplification.

Everything here is numpy on the host. Cleaning is explicit and reported, never silent:
``prepare`` welds coincident vertices (Garland–Heckbert need shared corners), drops degenerate and
duplicate faces and unreferenced vertices, and says how many of each it removed. Only positions and faces
are kept: what else a mesh carries (UVs, a material, colours) is named in a warning and in the report.
"""
from __future__ import annotations

import errno
import os
import warnings
from typing import Any, NamedTuple

import numpy as np

from . import files as _io_files, ply as _io_ply, texture as _io_texture
from .._mesh import wedges as _wedges
from .._mesh.arrays import face_stats, column_bounds, nonfinite, sorted_triples


class Mesh(NamedTuple):
    """A triangle mesh as arrays: vertices (n,3) float64, faces (m,3) int64 (``V, F = mesh`` unpacks it).

    Compares and hashes by identity (``a == b`` is ``a is b``), as `qemjax.SimplifyResult` does; compare
    the arrays with ``np.array_equal``."""

    vertices: np.ndarray
    faces: np.ndarray

    # a tuple's == compares its arrays elementwise, whose result has no one truth value (it raised), and
    # its hash hashes them (unhashable): identity, as the other objects holding arrays
    def __eq__(self, other):  # False, not NotImplemented, for a plain tuple: its == would compare the arrays
        return self is other

    def __ne__(self, other):
        return self is not other

    __hash__ = object.__hash__


class MissingFileError(FileNotFoundError, ValueError):
    """A mesh or config file that does not exist: a FileNotFoundError (``errno``, ``filename``), and a
    ValueError like every other bad input. One line: ``mesh file not found: PATH``."""

    def __str__(self):
        return f"{self.strerror}: {self.filename}" if self.filename is not None else super().__str__()


def _triangulate(faces: np.ndarray) -> np.ndarray:
    """Fan-triangulate (m,k) polygons, k ≥ 3, into (m·(k−2), 3) triangles."""
    k = faces.shape[1]
    if k == 3:
        return faces
    tris = [faces[:, [0, i, i + 1]] for i in range(1, k - 1)]
    return np.stack(tris, 1).reshape(-1, 3)


def dropped_attributes(obj) -> list[str]:
    """What a `trimesh.Trimesh` carries besides positions and faces, which qemjax does not keep: any of
    ``"uv"``, ``"material"``, ``"vertex_colors"``, ``"face_colors"`` (in that order), then what its file
    held that the reader could not read (``metadata["qemjax_unread"]``: a COFF file's colours)."""
    visual = getattr(obj, "visual", None)
    kind = getattr(visual, "kind", None)
    out = []
    if kind == "texture":
        uv = getattr(visual, "uv", None)
        if uv is not None and len(uv):
            out.append("uv")
        material = getattr(visual, "material", None)
        if material is not None and not _wedges.is_placeholder(material):
            out.append("material")
        if colours_beside_uv(obj):
            out.append(_io_ply.beside_uv())
    elif kind == "vertex":
        out.append("vertex_colors")
    elif kind == "face":
        out.append("face_colors")
    unread = getattr(obj, "metadata", {}).get("qemjax_unread", [])  # what the reader could not read
    return out + [u for u in unread if u not in out]


def colours_beside_uv(obj) -> bool:
    """Whether a mesh with UVs also holds vertex colours (a glTF's COLOR_0 beside its TEXCOORD_0), which
    trimesh keeps aside (``visual.vertex_attributes["color"]``) and qemjax does not read."""
    visual = getattr(obj, "visual", None)
    extra = getattr(visual, "vertex_attributes", None)
    return getattr(visual, "kind", None) == "texture" and extra is not None and "color" in list(extra.keys())


# the dropped names that `simplify(attributes=...)` can keep, and the kind that keeps each
_KEEPS = {"uv": "uv", "vertex_colors": "color", "normals": "normal"}


def _warn_dropped(dropped: list[str], what: str, stacklevel: int, kept=None, hint: bool = True):
    """One warning naming what is not kept. ``kept``: for a run (`prepare`), the kinds it keeps; the warning
    then says which `attributes=` would keep the rest (``hint``: not for a run given attributes=None, which
    asked for positions alone: `lod_chain`'s levels, a peer's input). None: a reader of positions only
    (`load`)."""
    if kept is None:
        warnings.warn(f"{what} carries {', '.join(dropped)}, which qemjax does not keep: the result has "
                      "positions and faces only (stats['dropped'] lists them)", stacklevel=stacklevel + 1)
        return
    has = f"positions, faces and {', '.join(kept)}" if kept else "positions and faces only"
    could = [d for d in dropped if d in _KEEPS or (d == "material" and "uv" in dropped)]  # a material with its UVs
    cannot = [d for d in dropped if d not in could]
    said = ([f"{', '.join(cannot)}, which qemjax does not keep"] if cannot else []) + (
        [f"{', '.join(could)}, which this run does not keep"] if could else [])
    kinds = tuple(kept) + tuple(_KEEPS[d] for d in could if d in _KEEPS)
    how = ""
    if hint and len(kinds) > len(kept):
        arg = repr(kinds[0]) if len(kinds) == 1 else repr(kinds)
        how = f"; attributes={arg} (CLI: --attributes {','.join(kinds)}) keeps them"
    warnings.warn(f"{what} carries {' and '.join(said)}: the result has {has} (stats['dropped'] lists them){how}",
                  stacklevel=stacklevel + 1)


def _as_trimesh(obj):
    """A `trimesh.Trimesh`, or a `trimesh.Scene` concatenated into one; ValueError for anything else
    (a point cloud named as one, with its number of points)."""
    import trimesh

    if isinstance(obj, trimesh.Scene):
        beside = any(colours_beside_uv(g) for g in obj.geometry.values())
        obj = _io_files.concatenated(obj)
        if beside and isinstance(obj, trimesh.Trimesh):  # joining the parts lets them go: named as dropped
            obj.metadata.setdefault("qemjax_unread", []).append(_io_ply.beside_uv())
    if isinstance(obj, trimesh.PointCloud):
        raise ValueError(f"expected a triangle mesh, got a point cloud ({len(obj.vertices)} points)")
    if not isinstance(obj, trimesh.Trimesh):
        raise ValueError(f"expected a triangle mesh, got {type(obj).__name__}")
    return obj


def _from_trimesh(obj) -> tuple[Mesh, list[str]]:
    """(Mesh, `dropped_attributes`) of a `trimesh.Trimesh`, or of a `trimesh.Scene` concatenated."""
    obj = _as_trimesh(obj)
    return Mesh(np.asarray(obj.vertices), np.asarray(obj.faces)), dropped_attributes(obj)


def _read_trimesh(path):
    """The `trimesh.Trimesh` in a file (no processing); ValueError naming the file and, for a file that
    cannot be read, what is wrong with it in words about the file (`_io_files.read`)."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise MissingFileError(errno.ENOENT, "mesh file not found", path)
    if os.path.isdir(path):
        raise ValueError(f"expected a mesh file, got a folder: {path}")
    return _as_trimesh(_io_files.read(path))


def portable(tm, V: np.ndarray, F: np.ndarray):
    """A `trimesh.Trimesh` of ``V``, ``F`` (``tm``'s, checked) with what `prepare` may keep of ``tm``: its
    UVs and material, vertex colours, the normals its file stored. It pickles, where a mesh trimesh read
    does not (it keeps its file's resolver), so a sweep's helpers get what a lone `simplify` of ``tm`` reads.
    None when ``tm`` carries none of these (its arrays are all a run reads)."""
    import trimesh

    vals, material = _wedges.from_trimesh(tm)
    if not vals and material is None:
        return None
    if "uv" in vals or material is not None:
        visual = trimesh.visual.TextureVisuals(uv=np.asarray(tm.visual.uv) if "uv" in vals else None,
                                               material=material)
    elif "color" in vals:
        visual = trimesh.visual.ColorVisuals(vertex_colors=np.asarray(tm.visual.vertex_colors))
    else:
        visual = None
    normals = tm._cache.cache.get("vertex_normals") if "normal" in vals else None  # as `from_trimesh` finds them
    return trimesh.Trimesh(V, F, visual=visual, vertex_normals=normals, process=False)


def _read(path) -> tuple[Mesh, list[str]]:
    """`load` without the warning: (Mesh, `dropped_attributes`)."""
    return _from_trimesh(_read_trimesh(path))


def load(path: str | os.PathLike) -> Mesh:
    """Read any file trimesh reads (OBJ, PLY, STL, OFF, GLB, …) as a `Mesh`.

    Polygons are triangulated; vertices are not merged (welding is a separate, explicit step of
    `simplify`) and keep the file's order, except an OBJ's: trimesh drops its unused ``v`` lines and splits
    a vertex at a UV seam, so its numbering is not the file's (``simplify(path, locked=...)`` numbers an
    OBJ's vertices by its ``v`` lines). Only positions and faces are read: UVs, a material or colours in the
    file are dropped, with one warning naming them.
    """
    mesh, dropped = _read(path)
    if dropped:
        _warn_dropped(dropped, os.fspath(path), stacklevel=2)
    return mesh


def _array(name: str, x) -> np.ndarray:
    """np.asarray(x); a ValueError naming ``name`` for a ragged nested list. An array of Python numbers
    (dtype object, as pandas' ``.values`` of mixed columns gives) is read as the numbers it holds."""
    try:
        a = np.asarray(x)
    except (ValueError, TypeError):
        a = None
    if a is not None and a.dtype == object:
        try:
            a = np.array(a.tolist())  # rows of numbers: a numeric array; rows of other lengths: still object
        except (ValueError, TypeError):
            a = None
    if a is None or a.dtype == object:
        try:
            lengths = sorted({len(row) for row in x})
        except TypeError:
            lengths = "of different lengths"
        if isinstance(lengths, list) and len(lengths) == 1:
            raise ValueError(f"{name} must be an array of numbers, got values that are not numbers (dtype object)")
        raise ValueError(f"{name} must be a rectangular array, got a ragged list (rows of lengths {lengths}); "
                         "give faces as an (m, 3) array, or polygons with the same number of corners")
    return a


def _as_arrays(mesh: Any, keep_trimesh: bool = False):
    """`as_arrays`, also returning `dropped_attributes` (empty for arrays); with ``keep_trimesh`` also the
    `trimesh.Trimesh` read (None for arrays), whose attributes `prepare` may keep."""
    dropped, tm, source = [], None, None
    if isinstance(mesh, (str, os.PathLike)):
        source = os.fspath(mesh)
        tm = _read_trimesh(mesh)
    elif type(mesh).__module__.startswith("trimesh"):
        tm = _as_trimesh(mesh)
    if tm is not None:
        mesh, dropped = _from_trimesh(tm)
    if isinstance(mesh, tuple) and len(mesh) == 2:
        V, F = mesh
    elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        V, F = mesh.vertices, mesh.faces
    else:
        raise ValueError("mesh must be a path, a trimesh.Trimesh, a (vertices, faces) pair "
                         f"or have .vertices and .faces; got {type(mesh).__name__}")
    try:
        V, F = _checked(V, F)
    except ValueError as exc:
        if source is None:
            raise
        raise ValueError(f"{source}: {exc}") from None  # which file, when the mesh came from one
    if keep_trimesh:
        return Mesh(V, F), dropped, tm
    return Mesh(V, F), dropped


def _checked(V, F) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n,3) float64 and triangles (m,3) int64 of arrays-like ``V``, ``F``, polygons fan-triangulated;
    ValueError naming the problem."""
    V = _array("vertices", V)
    F = _array("faces", F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must have shape (n, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] < 3:
        raise ValueError(f"faces must have shape (m, 3) (or (m, k≥3) polygons), got {F.shape}")
    if V.shape[0] == 0 or F.shape[0] == 0:
        raise ValueError(f"empty mesh: {V.shape[0]} vertices, {F.shape[0]} faces")
    if not np.issubdtype(V.dtype, np.number) or np.iscomplexobj(V):
        raise ValueError(f"vertices must be real numbers, got dtype {V.dtype}")
    V = np.ascontiguousarray(V, np.float64)
    if not np.issubdtype(F.dtype, np.integer):
        if np.issubdtype(F.dtype, np.floating) and np.all(np.isfinite(F)) and np.all(F == np.round(F)):
            F = F.astype(np.int64)
        else:
            raise ValueError(f"face indices must be integers, got dtype {F.dtype}")
    if F.dtype == np.uint64 and F.max() > np.iinfo(np.int64).max:
        raise ValueError(f"face indices out of range: found {F.max()} for {V.shape[0]} vertices")
    # int64 faces are used as given, not copied (nothing writes into them; 127 MiB on a 5.5 M-face mesh)
    F = np.ascontiguousarray(_triangulate(F.astype(np.int64, copy=False)))
    lo, hi = F.min(), F.max()
    if lo < 0 or hi >= V.shape[0]:
        raise ValueError(f"face indices out of range: found [{lo}, {hi}] for {V.shape[0]} vertices")
    bad = nonfinite(V, F)[1]  # (unused ones are dropped by `prepare`)
    if bad.size:
        raise ValueError(f"vertices contain NaN or inf coordinates ({bad.size} vertices, first: {bad[0]})")
    return V, F


def as_arrays(mesh: Any) -> Mesh:
    """Accept a path, a `trimesh.Trimesh`, a ``(vertices, faces)`` pair or an object with ``.vertices``
    and ``.faces``; validate and return float64 / int64 arrays. Raises ValueError naming the problem."""
    return _as_arrays(mesh)[0]


def check_feature_edges(feature_edges, n: int) -> np.ndarray | None:
    """Validate ``feature_edges`` for a cleaned mesh of n vertices: None, or a (k,2) array (or nested
    list) of integer vertex indices in [0, n). Returns None or (k,2) int64; ValueError names the problem."""
    if feature_edges is None:
        return None
    fe = _array("feature_edges", feature_edges)
    if fe.size == 0:
        return np.zeros((0, 2), np.int64)
    if fe.ndim != 2 or fe.shape[1] != 2:
        raise ValueError(f"feature_edges must have shape (k, 2) (pairs of vertex indices), got {fe.shape}")
    if not np.issubdtype(fe.dtype, np.integer):
        raise ValueError(f"feature_edges must be integer vertex indices, got dtype {fe.dtype}")
    lo, hi = fe.min(), fe.max()
    if lo < 0 or hi >= n:
        raise ValueError(f"feature_edges indices out of range: found [{lo}, {hi}] for {n} vertices "
                         "(indices refer to the cleaned input: after welding and dropping unused vertices)")
    return fe.astype(np.int64)


def _row_hash(U: np.ndarray) -> np.ndarray:
    """(k,) uint64 hash of the rows of a (k,c) uint64 array (equal rows, equal hashes)."""
    h = np.zeros(len(U), np.uint64)
    for j, mult in enumerate((0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9)[: U.shape[1]]):
        h ^= U[:, j] * np.uint64(mult) + (h >> np.uint64(29))
    return h


def _maybe_repeated(h: np.ndarray) -> bool:
    """False when the hashes are all different, which proves the hashed rows are (a cheap test: one
    pass through a hash table, `face_passes.repeated`; equal hashes need an exact check)."""
    from .._mesh.face_passes import repeated  # numba: imported when first used

    return len(repeated(np.ascontiguousarray(h, np.uint64))) > 0


def weld(V: np.ndarray, F: np.ndarray, with_map: bool = False):
    """Merge vertices with identical coordinates. Returns (V', F', number merged), and with ``with_map``
    also each input vertex's index in V' (n,) int64.

    Kept vertices stay in first-occurrence order, so a mesh without duplicates is returned unchanged.
    """
    if not _maybe_repeated(_row_hash((V + 0.0).view(np.uint64))):  # + 0.0: -0.0 becomes 0.0
        return (V, F, 0, np.arange(len(V))) if with_map else (V, F, 0)
    order = np.lexsort(V.T[::-1])
    Vs = V[order]
    new = np.ones(len(V), bool)
    new[1:] = np.any(Vs[1:] != Vs[:-1], axis=1)
    group = np.cumsum(new) - 1
    first = np.full(group[-1] + 1, len(V), np.int64)
    np.minimum.at(first, group, order)  # representative = smallest original index
    rep = np.empty(len(V), np.int64)
    rep[order] = first[group]
    keep = rep == np.arange(len(V))
    if keep.all():
        return (V, F, 0, np.arange(len(V))) if with_map else (V, F, 0)
    newidx = np.cumsum(keep) - 1
    out = V[keep], newidx[rep][F], int((~keep).sum())
    return (*out, newidx[rep]) if with_map else out


def unique_face_mask(F: np.ndarray) -> np.ndarray:
    """(m,) bool: True for the first face of each set of faces with the same three vertices (any order)."""
    s = sorted_triples(F)
    if not _maybe_repeated(_row_hash(s.astype(np.uint64))):
        return np.ones(len(F), bool)
    order = np.lexsort(s.T[::-1])  # stable: within equal keys, lower face index first
    ss = s[order]
    dup_sorted = np.zeros(len(F), bool)
    dup_sorted[1:] = np.all(ss[1:] == ss[:-1], axis=1)
    keep = np.ones(len(F), bool)
    keep[order[dup_sorted]] = False
    return keep


def clean_faces(F: np.ndarray, rows: np.ndarray | None = None):
    """Drop faces with a repeated index, then duplicates (same three vertices, any order; the first
    one is kept). Returns (F', degenerate removed, duplicates removed); given ``rows`` (m,…) aligned with
    F, also those rows of the kept faces (a fourth value)."""
    deg = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    n_deg = int(np.count_nonzero(deg))
    if n_deg:
        F = F[~deg]
        rows = None if rows is None else rows[~deg]
    keep = unique_face_mask(F)
    n_dup = len(F) - int(np.count_nonzero(keep))
    if rows is not None:
        return (F[keep] if n_dup else F), n_deg, n_dup, (rows[keep] if n_dup else rows)
    return (F[keep] if n_dup else F), n_deg, n_dup


def drop_unreferenced(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Remove vertices no face uses, renumbering faces. Returns (V', F', number removed)."""
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    if used.all():
        return V, F, 0
    newidx = np.cumsum(used) - 1
    return V[used], newidx[F], int((~used).sum())


_KEPT_NAMES = {"uv": ("uv",), "color": ("vertex_colors",)}


def _kept_names(kept: dict, material) -> set:
    """The names `dropped_attributes` gives to what the kinds ``kept`` keep (the material with the UVs)."""
    names = {n for k in kept for n in _KEPT_NAMES.get(k, ())}
    if "uv" in kept and material is not None:
        names.add("material")
    return names


def prepare(mesh: Any, *, weld_vertices: bool = True, stacklevel: int = 1, attributes=None,
            texture=None, keeps: bool = True) -> tuple[Mesh, dict]:
    """Validate and clean a mesh for simplification; returns (Mesh, report) where report counts
    ``welded``, ``degenerate_removed``, ``duplicate_removed``, ``zero_area_removed`` (exactly collinear
    corners), ``unreferenced_removed``, gives ``vertex_map`` (each given vertex's index in the cleaned
    mesh, -1 for one no face uses) and lists the attributes not kept in ``dropped`` (`dropped_attributes`; also one warning, attributed to the
    caller ``stacklevel`` - 1 frames above prepare's caller).

    attributes: which appearance attributes to keep (`_wedges.select`: 'auto', None, a kind or a tuple);
    kept ones come as ``report["attributes"]``, an `_wedges.Attributes` aligned with the cleaned faces
    (None when nothing is kept). texture: a path or PIL image to use as the material's texture. ``keeps``:
    False when the run's method drops every attribute (its caller warns of the kept ones): the warning of
    what else is dropped then says the result has positions and faces only, and names no way to keep it."""

    (V, F), dropped, tm = _as_arrays(mesh, keep_trimesh=True)
    notes = {}
    available, material = _wedges.from_trimesh(tm, notes) if tm is not None else ({}, None)
    kept, _ = _wedges.select(available, attributes, dropped)
    if "normal" in available and "normal" not in kept:  # stored normals: named as the other kinds are
        dropped = dropped + ["normals"]
    if texture is not None:
        if "uv" not in kept:
            raise ValueError("texture= needs UVs: the mesh carries none (or attributes= does not keep them)")
        material = _io_texture.load(texture)  # a file's bytes kept: written back as they are
    report = {"welded": 0}
    F0 = F
    vmap = np.arange(len(V))  # each input vertex's index in the cleaned mesh (-1: dropped)
    if weld_vertices:
        V, F, report["welded"], vmap = weld(V, F, with_map=True)
    name = os.fspath(mesh) if isinstance(mesh, (str, os.PathLike)) else "the mesh"
    if attributes == "auto" and kept:  # kinds with seams are kept only when asked for, or UVs with a
        # texture image (`_wedges.AUTO_RULE`)
        textured = texture is not None or _wedges.names_texture(material)
        seamed = {k: c for k in kept if (c := _wedges.seam_vertex_count(kept[k], F, F0))
                  and not (k == "uv" and textured)}
        if seamed:
            kept = {k: v for k, v in kept.items() if k not in seamed}
            extra = ["material"] if "uv" in seamed and material is not None else []
            names = [_wedges.DROPPED_NAME[k] for k in seamed] + extra
            # the kinds still kept (and their material) are not among the others the warning names
            others = [d for d in dropped if d not in names and d not in _kept_names(kept, material)]
            dropped = others + names
            if keeps:  # (a method that keeps none drops them for that, not for their seams)
                _wedges.warn_seamed(seamed, others, name, stacklevel=stacklevel + 1)
                report["not_kept_seams"] = list(seamed)
    if kept:
        names = _kept_names(kept, material)
        dropped = [d for d in dropped if d not in names]
    if dropped and not report.get("not_kept_seams"):
        _warn_dropped(dropped, name, stacklevel=stacklevel + 1, kept=list(kept) if keeps else [],
                      hint=attributes is not None and keeps)
    report["dropped"] = dropped
    if "normal" in kept:
        report["normals_recomputed"] = notes.get("normals_recomputed", 0)
    src = np.arange(len(F) * 3, dtype=np.int64).reshape(-1, 3) if kept else None  # corner ids
    if kept:
        F, report["degenerate_removed"], report["duplicate_removed"], src = clean_faces(F, src)
    else:
        F, report["degenerate_removed"], report["duplicate_removed"] = clean_faces(F)
    if len(F) == 0:
        a, b, c = F0.T  # the faces as given: with three distinct vertices, welding made them degenerate
        whole = int(np.count_nonzero((a != b) & (b != c) & (a != c)))
        why = (f"; {whole} faces had three distinct vertices before the vertices at the same position were welded: "
               "the coordinates lack the precision for the detail (float32, as STL stores them, keeps about 7 "
               "digits, so detail far from the origin falls on one point)" if whole and report["welded"] else "")
        where = f"{name}: " if name != "the mesh" else ""
        raise ValueError(f"{where}empty mesh: every face is degenerate (a corner repeated){why}")
    # faces with exactly collinear corners would survive untouched into the output: drop them; the same
    # pass gives the means that scale the quadric weights, at unit extent (divided by the bounding box's
    # largest side, so no scale underflows; an overflowing extent is refused by name in `_units`)
    lo, hi = column_bounds(V)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):  # unused non-finite vertices (`_checked`): the
        lo, hi = column_bounds(V[np.isfinite(V).all(axis=1)])  # box of the others, as if they were not given
    with np.errstate(over="ignore"):
        ext = float(np.max(hi - lo))
    scaled = np.isfinite(ext) and ext > 0
    with np.errstate(over="ignore", invalid="ignore"):
        nz, area_mean, e2_mean = face_stats((V - lo) / ext if scaled else V, F)
    if not nz.any():
        raise ValueError(f"the mesh has no surface: all {len(F)} faces have zero area (collinear corners)")
    report["zero_area_removed"] = int(len(F) - np.count_nonzero(nz))
    if report["zero_area_removed"]:
        F = F[nz]
        src = None if src is None else src[nz]
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    V, F, report["unreferenced_removed"] = drop_unreferenced(V, F)
    report["vertex_map"] = np.where(used, np.cumsum(used) - 1, -1)[vmap]  # for `simplify`, popped there
    report["attributes"] = None
    if kept:  # wedges: the source vertex of each kept corner, split by value at each welded vertex
        a = _wedges.build(kept, F, F0.reshape(-1)[src])
        a.material = material if "uv" in kept else None
        report["attributes"] = a
    report["face_means"] = (area_mean, e2_mean, ext if scaled else 1.0)  # for `simplify`, popped there
    return Mesh(V, F), report


