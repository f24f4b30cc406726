"""Files written by the partition stages: `write_npz` (the same arrays always give the same bytes, written
atomically) and `write_binary_ply` (a triangle mesh written in chunks, for large test meshes)."""
from __future__ import annotations

import itertools
import zipfile
from pathlib import Path

import numpy as np

from .._io.atomic import replace_atomically

_EPOCH = (1980, 1, 1, 0, 0, 0)  # zip's earliest date: entries carry no time of writing


def write_npz(path: Path, **arrays) -> None:
    """An uncompressed .npz (np.load reads it) whose bytes depend only on the arrays."""
    def write(tmp):
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
            for name, a in arrays.items():
                with z.open(zipfile.ZipInfo(name + ".npy", _EPOCH), "w", force_zip64=True) as f:
                    np.lib.format.write_array(f, np.ascontiguousarray(a), allow_pickle=False)
    replace_atomically(path, write)


def _chunks(a):
    """A (n,3) array as one chunk, or the chunks of an iterable as they come."""
    if isinstance(a, np.ndarray) or (hasattr(a, "shape") and hasattr(a, "dtype")):
        yield np.asarray(a)
    else:
        yield from (np.asarray(c) for c in a)


_COUNT_WIDTH = 20  # digits reserved for a count patched in after streaming


def write_binary_ply(path, vertices, faces, *, n_vertices: int | None = None, n_faces: int | None = None,
                     big_endian: bool = False) -> tuple[int, int]:
    """Writes a binary PLY of triangles: x, y, z as ``float`` (float32 input) or ``double``, faces as a
    uchar count and int indices. ``vertices`` and ``faces`` are (n,3) arrays or iterables of (k,3)
    chunks (generated on the fly: nothing is held). Counts not given are reserved in the header and
    written in once known. Returns (vertices, faces) written."""
    order = ">" if big_endian else "<"
    vchunks, fchunks = _chunks(vertices), _chunks(faces)
    first = next(vchunks, np.empty((0, 3), np.float32))
    vtype = ("float", "f4") if first.dtype == np.float32 else ("double", "f8")
    fdtype = np.dtype([("n", "u1"), ("i", order + "i4", (3,))])

    def head(nv, nf, pad):
        nv, nf = (str(nv).ljust(_COUNT_WIDTH) if pad else nv), (str(nf).ljust(_COUNT_WIDTH) if pad else nf)
        return (f"ply\nformat binary_{'big' if big_endian else 'little'}_endian 1.0\nelement vertex {nv}\n"
                + "".join(f"property {vtype[0]} {c}\n" for c in "xyz")
                + f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n").encode("ascii")

    pad = n_vertices is None or n_faces is None
    nv = nf = 0
    with open(path, "wb") as f:
        f.write(head(0, 0, True) if pad else head(n_vertices, n_faces, False))
        for c in itertools.chain([first], vchunks):
            c = np.ascontiguousarray(c, order + vtype[1]).reshape(-1, 3)
            f.write(c.data)
            nv += len(c)
        for c in fchunks:
            c = np.asarray(c).reshape(-1, 3)
            if len(c) and (c.min() < 0 or c.max() >= max(nv, 1) or c.max() > np.iinfo(np.int32).max):
                raise ValueError(f"{path}: a face uses a vertex number outside 0..{nv - 1}")
            rec = np.empty(len(c), fdtype)
            rec["n"], rec["i"] = 3, c
            f.write(rec.data)
            nf += len(c)
        if pad:
            f.seek(0)
            f.write(head(nv, nf, True))
        elif (nv, nf) != (n_vertices, n_faces):
            raise ValueError(f"{path}: {nv} vertices and {nf} faces written, {n_vertices} and {n_faces} declared")
    return nv, nf
