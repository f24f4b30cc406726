"""The first stage of partitioned simplification: a mesh file, read in chunks, binned into spatially compact
parts on disk (`scatter`).

Passes, none holding the mesh: the vertices twice (bounding box, then each vertex's cell), the faces
twice or more (a histogram of centroid codes, refined where a bin overflows, `plan`; then each chunk's
faces appended to its part's file, noting per vertex the first part that used it or that several did),
then each part once (its vertices gathered, written as ``level0/part_NNNNN.npz``; the edges between two
shared vertices noted, from which the input's boundary edges along the cuts are written once all parts
are: `borders_on_cuts`). What stays in memory across passes is per vertex: its packed cell (8 bytes), its
part or 'shared' (4 bytes), when some vertices are unused its new number (4 bytes), and in the last pass a
scratch index (4 bytes, in place of the cell) and the edges between shared vertices (the cuts' size).
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from .._io.mesh import clean_faces
from .._mesh import topology
from . import indexed
from .._mesh.compiled import njit
from .cells import Bins, Plan, codes, quantize
from .readers import open_source, texture_of
from .source import CORNER_UV, FACES, PACKED, UV, VERTICES, Ragged, Source, remove
from .write import replace_atomically, write_npz

UNSEEN, SHARED = -1, -2  # owner values besides a part number
BORDERS_ON_CUTS = "borders_on_cuts.npz"  # in level0/: `borders_on_cuts`, array ``E``


def _spans(n: int, step: int):
    for lo in range(0, n, step):
        yield lo, min(lo + step, n)


def _bounds(src: Source, step: int, keep: np.ndarray | None = None):
    """The bounding box of the vertices with finite coordinates (of those ``keep`` marks, when given):
    a non-finite vertex is refused only if a face uses it (`_write_parts`)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for a, b in _spans(src.n_vertices, step):
        V = src.vertices(a, b)
        V = V[np.isfinite(V).all(1) if keep is None else keep[a:b] & np.isfinite(V).all(1)]
        if len(V):
            lo, hi = np.minimum(lo, V.min(0)), np.maximum(hi, V.max(0))
    return lo, hi


def _cells(src: Source, lo, hi, step: int) -> np.ndarray:
    cells = np.empty(src.n_vertices, np.uint64)
    for a, b in _spans(src.n_vertices, step):
        cells[a:b] = quantize(src.vertices(a, b), lo, hi)
    return cells


def _checked(F: np.ndarray, at: int, n: int, name: str) -> np.ndarray:
    bad = (F < 0) | (F >= n)
    if bad.any():
        k = int(np.flatnonzero(bad.any(1))[0])
        raise ValueError(f"{name}: face {at + k} uses vertex {F[k][bad[k]][0]}, but the file has {n} vertices")
    return F


def _histogram(src: Source, cells, part_faces: int, step: int, name: str) -> Bins:
    bins = Bins(src.n_faces, part_faces)
    for a, b in _spans(src.n_faces, step):
        bins.add_prefix(codes(cells, _checked(src.faces(a, b), a, src.n_vertices, name)))
    while len(bins.overfull(part_faces)):
        refiner = bins.refiner(part_faces)
        for a, b in _spans(src.n_faces, step):
            refiner.add(codes(cells, src.faces(a, b)))
        refiner.apply()
    return bins


@njit(cache=True)
def _note_owner(owner, F, part):
    """Records that faces F of parts ``part`` use their vertices: a vertex's first part, or SHARED once a
    second one uses it (the same whatever the order of the records)."""
    for f in range(len(F)):
        p = part[f]
        for c in range(3):
            v = F[f, c]
            o = owner[v]
            if o == UNSEEN:
                owner[v] = p
            elif o != p:
                owner[v] = SHARED


@njit(cache=True)
def _note_uv(first, state, F, C):
    """Records the UVs C (k,3,2) of the corners of faces F: a vertex's first corner's in ``first``, and in
    ``state`` 1 once seen, 2 once a corner differs from its first (a seam vertex; a NaN differs from
    itself, as in `_wedges.seam_vertex_count`). Whether these faces hold a seam vertex."""
    seam = False
    for f in range(len(F)):
        for c in range(3):
            v = F[f, c]
            if state[v] == 0:
                state[v] = 1
                first[v, 0], first[v, 1] = C[f, c, 0], C[f, c, 1]
            if first[v, 0] != C[f, c, 0] or first[v, 1] != C[f, c, 1]:
                state[v] = 2
                seam = True
    return seam


def _bin(src: Source, cells, plan: Plan, tmp: Path, index_type, step: int, progress, uv: bool,
         seams: bool = False) -> tuple[np.ndarray, int, bool]:
    """Appends each face to its part's file (input order kept within a part), and with ``uv`` its corners'
    UVs to the part's ``.uv`` file; returns the owners, with ``seams`` how many vertices have corners of
    different UVs (else 0: with ``seams``, the UVs are written only while none is found, as a seam leaves
    them out), and whether every UV read is a finite number."""
    owner = np.full(src.n_vertices, UNSEEN, np.int32)
    finite, write_uv = True, uv
    if seams:
        first, state = np.empty((src.n_vertices, 2), np.float64), np.zeros(src.n_vertices, np.int8)
    for a, b in _spans(src.n_faces, step):
        F = src.faces(a, b)
        C = src.corner_uvs(a, b, F) if uv else None
        if seams and _note_uv(first, state, F, C) and write_uv:  # a seam: the parts will not take the UVs
            write_uv = False  # (still read, to count the seam vertices)
            for written in tmp.glob("*.uv"):
                remove(written)
        finite = finite and (C is None or bool(np.isfinite(C).all()))
        part = plan.assign(codes(cells, F)).astype(np.int32)
        _note_owner(owner, F, part)
        order = np.argsort(part, kind="stable")
        sorted_part = part[order]
        cuts = np.flatnonzero(np.diff(sorted_part)) + 1
        F = F.astype(index_type)
        for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(order)]):
            with open(tmp / f"{sorted_part[lo]}.bin", "ab") as f:
                f.write(F[order[lo:hi]].tobytes())
            if write_uv:
                with open(tmp / f"{sorted_part[lo]}.uv", "ab") as f:
                    f.write(C[order[lo:hi]].tobytes())
        if progress is not None:
            progress(b, src.n_faces)
    return owner, int(np.count_nonzero(state == 2)) if seams else 0, finite


def _distinct(raw: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(raw, return_inverse=True)`` for vertex ids ``raw`` into ``at`` (one scratch entry per
    vertex of the file, any values): only the distinct ids are sorted, about a sixth of a part's corners,
    and no pass runs over every vertex of the file (a part is small, the file is not)."""
    at[raw] = np.arange(len(raw), dtype=at.dtype)  # the last corner of each id wins
    used = np.sort(raw[at[raw] == np.arange(len(raw), dtype=at.dtype)])
    at[used] = np.arange(len(used), dtype=at.dtype)
    return used, at[raw]


def _shared_edges(F: np.ndarray, gid: np.ndarray, border: np.ndarray) -> np.ndarray:
    """(k,2) the global ids of the edges of a part's faces F whose two ends other parts also use, one row
    per face that has the edge, smaller id first."""
    on = border[F]
    out = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        both = on[:, i] & on[:, j]
        a, b = gid[F[both, i]], gid[F[both, j]]
        out.append(np.stack([np.minimum(a, b), np.maximum(a, b)], 1))
    return np.concatenate(out)


def borders_on_cuts(shared: list, n: int) -> np.ndarray:
    """(k,2) sorted rows of the global ids (below ``n``) of the input's boundary edges whose two ends lie on
    cuts, from the parts' `_shared_edges`: the edges one face of the whole input has. A part's run cannot
    tell them from the cuts, which are its boundary too (`carry`)."""
    rows = np.concatenate(shared) if shared else np.zeros((0, 2), np.int64)
    if n > 3_000_000_000:  # a * n + b would not fit in 63 bits
        uniq, count = np.unique(rows, axis=0, return_counts=True)
        return uniq[count == 1].astype(np.int64)
    key, count = topology.unique_counts(topology.edge_keys(rows[:, 0], rows[:, 1], n))  # a fast sort
    return topology.key_pairs(key[count == 1], n, np.int64)


def _write_parts(src: Source, plan: Plan, owner, new_id, tmp: Path, level: Path, index_type, name: str,
                 uv: bool) -> tuple[list, np.ndarray]:
    """The parts, written (`scatter`), and `borders_on_cuts`."""
    parts, shared = [], []
    at = np.empty(src.n_vertices, index_type)  # holds a corner's place in its part
    for p in range(plan.parts):
        raw = np.fromfile(tmp / f"{p}.bin", index_type)
        remove(tmp / f"{p}.bin")
        if len(raw) > np.iinfo(at.dtype).max:  # a part of more than 2^31 corners
            at = at.astype(np.int64)
        used, inverse = _distinct(raw, at)
        # the in-core clean-up's face rules (`_io.mesh.clean_faces`): a face with a repeated vertex, and a
        # face on the same three vertices as an earlier one of its part (a repeat lies at the same place, so
        # in the same part), go; the counts, and the ratio's faces, are then an in-core run's
        F, degenerate, duplicate, rows = clean_faces(inverse.reshape(-1, 3), np.arange(len(raw) // 3))
        if degenerate or duplicate:  # a vertex only they used goes too
            ref = np.zeros(len(used), bool)
            ref[F.reshape(-1)] = True
            used, F = used[ref], (np.cumsum(ref) - 1)[F]
        gid = (used if new_id is None else new_id[used]).astype(np.int64)
        border = owner[used] == SHARED
        shared.append(_shared_edges(F, gid, border))
        V = src.gather(used)
        bad = ~np.isfinite(V).all(1)
        if bad.any():
            raise ValueError(f"{name}: vertex {used[bad][0]} has a coordinate that is not a finite number")
        file = f"part_{p:05d}.npz"
        extra = {}
        if uv:
            extra["UV"] = np.fromfile(tmp / f"{p}.uv", np.float64).reshape(-1, 3, 2)[rows]
            remove(tmp / f"{p}.uv")
            if not np.isfinite(extra["UV"]).all():
                raise ValueError(f"{name}: a texture coordinate is not a finite number")
        write_npz(level / file, gid=gid, V=V, F=F.astype(np.int32), border=border, **extra)
        parts.append({"file": f"level0/{file}", "faces": len(F), "vertices": len(used),
                      "border": int(border.sum()), "degenerate_removed": degenerate, "duplicate_removed": duplicate})
    return parts, borders_on_cuts(shared, src.n_vertices)


def _prepare(scratch: Path) -> tuple[Path, Path]:
    level, tmp = scratch / "level0", scratch / "tmp"
    remove(scratch / "manifest.json")  # a failed run leaves no manifest of an earlier one's parts
    for old in level.glob("part_*.npz") if level.exists() else ():
        old.unlink()
    remove(level / BORDERS_ON_CUTS)
    shutil.rmtree(tmp, ignore_errors=True)
    level.mkdir(parents=True, exist_ok=True)
    tmp.mkdir()
    return level, tmp


def _read(path, scratch: Path, part_faces: int, step: int, name: str, uv: bool):
    """The source (with its UVs when ``uv`` and it has them), its vertex cells and its code histogram; a
    face block that turns out to hold other polygons than triangles is streamed into scratch triangles and
    counted again."""
    src = open_source(path, scratch, uv)
    if src.n_faces == 0:
        raise ValueError(f"{name}: the mesh has no faces")
    if not src.welded and indexed.repeats(src, step):  # a PLY that repeats positions: welded, as in core
        src = indexed.weld(src, scratch, step)
    box = _bounds(src, step)
    cells = _cells(src, *box, step)
    try:
        return src, box, cells, _histogram(src, cells, part_faces, step, name)
    except Ragged:
        dropped, src = src.dropped, src.retriangulate()
        src.dropped = dropped
        return src, box, cells, _histogram(src, cells, part_faces, step, name)


def scatter(path, scratch, part_faces: int, *, chunk_faces: int = 1 << 21, progress=None, uv=False) -> dict:
    """Reads the mesh file ``path`` (PLY, OBJ or STL) in chunks of ``chunk_faces`` faces and bins its
    triangles into spatially compact parts of at most ``part_faces`` faces, written to
    ``scratch/level0/part_NNNNN.npz`` (arrays ``gid``: sorted global vertex ids, ``V``: their float64
    positions, ``F``: int32 triangles over them in input order, ``border``: whether another part also
    uses the vertex), and returns the manifest (also written to ``scratch/manifest.json``): format,
    n_vertices, n_faces (after the clean-up: faces with a repeated vertex, and repeats of a face within its
    part, removed; their numbers as degenerate_removed and duplicate_removed), bbox, welded, parts (file,
    faces, vertices, border and those two numbers for each), dropped (what the file holds besides positions
    and triangles, which the parts do not carry), borders_on_cuts (the file, in level0/, of the input's
    boundary edges whose two ends other parts also use, as global id pairs ``E``: `borders_on_cuts`).

    With ``uv`` True (asked for by name) or "auto" (as `simplify`'s ``attributes="auto"`` keeps them: when
    the file names a texture image, or else when no vertex has corners of different UVs, a seam), each part
    also holds ``UV`` (m,3,2) float64, its triangles' corners' UVs (an OBJ's ``vt``, a PLY's per-vertex
    ``texture_u``/``s``/``u`` and their pairs, a binary PLY's ``texcoord`` lists), and the manifest says
    ``uv`` and names the ``texture`` image the file names; UVs left out by "auto" for their seams, how many
    vertices are on them (``uv_seam_vertices``). Finding the seams holds each vertex's first UV in the
    binning pass (17 bytes a vertex), only when the corners' UVs can differ at a vertex (an OBJ's, a
    ``texcoord`` list's, or per-vertex UVs at repeated positions).

    Positions are welded by exact value (a PLY's only when some repeat: `indexed`). Unused vertices are
    dropped, the others keep their order. ``progress(done_faces, total_faces)`` is called after each
    chunk of the binning pass. The same file gives the same bytes whatever ``chunk_faces``.
    """
    if int(part_faces) < 1 or int(chunk_faces) < 1:
        raise ValueError(f"part_faces and chunk_faces must be at least 1 (got {part_faces} and {chunk_faces})")
    part_faces, step, name = int(part_faces), int(chunk_faces), os.fspath(path)
    scratch = Path(scratch)
    scratch.mkdir(parents=True, exist_ok=True)
    level, tmp = _prepare(scratch)
    try:
        texture = texture_of(path) if uv else None
        auto = uv == "auto" and texture is None  # kept when they have no seam, as in core
        src, (lo, hi), cells, bins = _read(path, scratch, part_faces, step, name, bool(uv))
        plan = Plan.from_bins(bins, part_faces)
        index_type = np.int32 if src.n_vertices < 2**31 else np.int64
        uv = src.uv is not None  # asked for, and every triangle corner has one
        # a vertex's corners can have different UVs only where they are not read from the vertex itself
        seams = auto and uv and (src.corner_uv is not None or src.face_uv is not None)
        owner, seam_vertices, finite = _bin(src, cells, plan, tmp, index_type, step, progress, uv, seams)
        # UVs found only by "auto" that are not numbers are left out, as they were before it looked for
        # them; asked for, they are refused (`_write_parts`)
        uv = uv and not seam_vertices and (finite or not auto)
        del cells, bins
        kept = owner != UNSEEN
        n_kept = int(np.count_nonzero(kept))
        new_id = None
        if n_kept < src.n_vertices:  # unused vertices: the others renumbered in order
            new_id = np.cumsum(kept, dtype=index_type) - 1
            lo, hi = _bounds(src, step, kept)
        del kept
        parts, on_cuts = _write_parts(src, plan, owner, new_id, tmp, level, index_type, name, uv)
        write_npz(level / BORDERS_ON_CUTS, E=on_cuts)
        manifest = {"format": src.format, "n_vertices": n_kept, "n_faces": sum(p["faces"] for p in parts),
                    "degenerate_removed": sum(p["degenerate_removed"] for p in parts),
                    "duplicate_removed": sum(p["duplicate_removed"] for p in parts),
                    "bbox": [lo.tolist(), hi.tolist()], "welded": src.welded, "parts": parts,
                    "dropped": list(src.dropped_with_uv if uv else src.dropped), "uv": uv,
                    "uv_in_file": bool(src.uv_in_file), "uv_seam_vertices": seam_vertices,
                    "texture": None if texture is None or not uv else str(texture),
                    "borders_on_cuts": f"level0/{BORDERS_ON_CUTS}"}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(scratch / "weld", ignore_errors=True)
        for leftover in (VERTICES, FACES, UV, CORNER_UV, PACKED, "faces_raw.i64", "ids.i64", *indexed.WELDED):
            remove(scratch / leftover)

    def write(p):
        p.write_text(json.dumps(manifest, indent=1) + "\n")
    replace_atomically(scratch / "manifest.json", write)
    return manifest
