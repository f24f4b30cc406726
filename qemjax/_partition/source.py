"""A mesh on disk read in row ranges: `Source`, and the scratch arrays that text formats are converted to.

A `Source` is two blocks of fixed-size records in files: vertices (fields giving x, y, z) and triangles
(a field ``i`` of three indices, and count fields that must hold fixed values). Every read maps just the
rows asked for and lets the mapping go, so that the pages of a large file never pile up in the process's
resident memory (a mapping's touched pages count as resident while it lives).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

VERTICES, FACES = "vertices.f64", "faces.i64"  # the scratch arrays of converted formats
PACKED = "vertex_records.bin"  # a binary PLY's vertex scalars, when its vertex element also has lists
UV, CORNER_UV = "uv.f64", "corner_uv.i64"  # an OBJ's texture coordinates, and each triangle corner's
XYZ = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
UV_DTYPE = np.dtype([("u", "<f8"), ("v", "<f8")])
TRI = np.dtype([("i", "<i8", (3,))])


class Ragged(Exception):
    """A face block read as fixed triangles holds a row that is not a triangle: it must be streamed."""


class Refusal(ValueError):
    """What is wrong with an input file, in words about the file (the caller adds its name)."""


def rows(path, dtype: np.dtype, offset: int, lo: int, hi: int) -> np.ndarray:
    """Rows lo..hi of a block of records at byte ``offset`` of ``path``, copied out of a short-lived
    mapping (numpy refuses an empty one)."""
    if hi <= lo:
        return np.empty(0, dtype)
    m = np.memmap(path, dtype, "r", offset + lo * dtype.itemsize, (hi - lo,))
    out = np.array(m)
    del m
    return out


@dataclass
class Block:
    """``rows`` records of ``dtype`` at byte ``offset`` of ``path``."""

    path: Path
    offset: int
    dtype: np.dtype
    rows: int

    def read(self, lo: int, hi: int) -> np.ndarray:
        return rows(self.path, self.dtype, self.offset, lo, min(hi, self.rows))

    def gather(self, idx: np.ndarray) -> np.ndarray:
        """The records at sorted row numbers ``idx``, from one mapping dropped afterwards."""
        if len(idx) == 0:
            return np.empty(0, self.dtype)
        m = np.memmap(self.path, self.dtype, "r", self.offset, (self.rows,))
        out = m[idx]
        del m
        return out


@dataclass
class Source:
    """A triangle mesh as record blocks. ``xyz``: the vertex fields of x, y, z; ``checks``: (face field,
    value) pairs every face row must hold (a PLY's list counts), else `Ragged`."""

    format: str
    welded: bool
    vertex: Block
    face: Block
    xyz: tuple = ("x", "y", "z")
    checks: list = field(default_factory=list)
    retriangulate: object = None  # () -> Source whose faces were streamed to scratch, for `Ragged`
    dropped: tuple = ()  # what the file holds besides positions and triangles, in the file's own words
    # UVs, when the file gives every triangle corner one: their records (fields ``uv_fields``) and either
    # each corner's record number (``corner_uv``: an OBJ's vt) or the vertex's (None: a PLY's per-vertex
    # UVs), or the face records' field of 6 values (``face_uv``: a PLY's texcoord list); ``dropped_with_uv``:
    # what ``dropped`` is when they are kept
    uv: Block | None = None
    corner_uv: Block | None = None
    uv_fields: tuple = ("u", "v")
    face_uv: str | None = None
    dropped_with_uv: tuple = ()
    uv_in_file: bool = False  # the file holds UVs, asked for or not (a warning then says how to keep them)

    @property
    def n_vertices(self) -> int:
        return self.vertex.rows

    @property
    def n_faces(self) -> int:
        return self.face.rows

    def _positions(self, r: np.ndarray) -> np.ndarray:
        out = np.empty((len(r), 3), np.float64)
        for k, name in enumerate(self.xyz):
            out[:, k] = r[name]
        return out

    def vertices(self, lo: int, hi: int) -> np.ndarray:
        """Positions of vertices lo..hi as float64 (n,3)."""
        return self._positions(self.vertex.read(lo, hi))

    def gather(self, idx: np.ndarray) -> np.ndarray:
        """Positions of the vertices at sorted numbers ``idx`` as float64 (n,3)."""
        return self._positions(self.vertex.gather(idx))

    def corner_uvs(self, lo: int, hi: int, F: np.ndarray) -> np.ndarray:
        """(k,3,2) float64 UVs of the corners of triangles lo..hi (``F``: their vertices, `faces`)."""
        if self.face_uv is not None:  # (``uv``: the file's face records, the faces' own block until a weld)
            return self.uv.read(lo, hi)[self.face_uv].astype(np.float64).reshape(-1, 3, 2)
        idx = (F if self.corner_uv is None else self.corner_uv.read(lo, hi)["i"]).reshape(-1)
        used, inverse = np.unique(idx, return_inverse=True)
        r = self.uv.gather(used)
        out = np.empty((len(used), 2), np.float64)
        for k, name in enumerate(self.uv_fields):
            out[:, k] = r[name]
        return out[inverse].reshape(-1, 3, 2)

    def faces(self, lo: int, hi: int) -> np.ndarray:
        """Triangles lo..hi as int64 (n,3); `Ragged` when a row of a fixed-size face block is no triangle."""
        r = self.face.read(lo, hi)
        for name, value in self.checks:
            if np.any(r[name] != value):
                raise Ragged
        return r["i"].astype(np.int64, copy=False)


def scratch_source(scratch: Path, fmt: str, welded: bool, n_vertices: int, n_faces: int) -> Source:
    """The source over the scratch arrays a converted file was written to."""
    return Source(fmt, welded, Block(scratch / VERTICES, 0, XYZ, n_vertices), Block(scratch / FACES, 0, TRI, n_faces))


class Appender:
    """Appends arrays to a file (a scratch array written in chunks), counting rows."""

    def __init__(self, path: Path):
        self.path = path
        self.rows = 0
        self._f = open(path, "wb")

    def add(self, a: np.ndarray) -> None:
        a = np.ascontiguousarray(a)
        self._f.write(a.data if a.size else b"")
        self.rows += len(a)

    def close(self) -> None:
        self._f.close()


def remove(path) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass
