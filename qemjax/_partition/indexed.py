"""Welding an indexed file (PLY) whose vertices repeat positions, as an in-core run welds them.

A PLY lists its vertices once each, usually; a triangle soup, or a mesh split at its UV seams, repeats a
position under several numbers. In core the copies are one vertex (``weld=True``); across parts they
would be vertices of different numbers, neither marked as shared, so the parts' runs would move them
apart: a crack. So the positions are first checked for repeats, 8 bytes a vertex (their hashes, the
Welder's `weld.hash_rows`, sorted),
and only a file that has some is welded (`weld.Welder`, bounded memory) and its faces renumbered.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .source import TRI, XYZ, Appender, Block, Ragged, Source, remove, rows
from .weld import Welder, hash_rows

# the welded positions and renumbered triangles (a text file's own scratch arrays may be the ones read here)
WELDED = ("vertices_welded.f64", "faces_welded.i64")


def repeats(src: Source, step: int) -> bool:
    """Whether two of the vertices have the same position (the same bits): their hashes, sorted (8 bytes a
    vertex), and the vertices of any hash seen twice compared."""
    n = src.n_vertices
    h = np.empty(n, np.uint64)
    for lo in range(0, n, step):
        bits = np.ascontiguousarray(src.vertices(lo, lo + step)).view(np.uint64).reshape(-1, 3)
        h[lo:lo + len(bits)] = hash_rows(bits)
    s = np.sort(h)
    twice = np.unique(s[1:][s[1:] == s[:-1]])
    if not len(twice):
        return False
    idx = np.flatnonzero(np.isin(h, twice))  # a few: hashes seen twice are rare unless positions repeat
    bits = np.ascontiguousarray(src.gather(idx)).view(np.uint64).reshape(-1, 3)
    return len(np.unique(bits, axis=0)) < len(bits)


def weld(src: Source, scratch: Path, step: int) -> Source:
    """``src`` with its repeated positions welded (ids by first appearance, as `Welder`) and its faces
    renumbered; ``src`` itself when no two positions are equal. UVs are read as before: a corner's from its
    file vertex (``corner_uv``: the file's face records) or from its face record (a texcoord list)."""
    try:
        for lo in range(0, src.n_faces, step):  # a face block of other polygons: streamed first
            src.faces(lo, lo + step)
    except Ragged:
        dropped, src = src.dropped, src.retriangulate()
        src.dropped = dropped
    welder = Welder(scratch / "weld", src.n_vertices)
    for lo in range(0, src.n_vertices, step):
        welder.add(src.vertices(lo, lo + step))
    ids = scratch / "ids.i64"
    n = welder.finish(ids, scratch / WELDED[0])
    if n == src.n_vertices:
        remove(ids)
        remove(scratch / WELDED[0])
        return src
    mapping = rows(ids, np.dtype(np.int64), 0, 0, src.n_vertices)
    out = Appender(scratch / WELDED[1])
    try:
        for lo in range(0, src.n_faces, step):
            out.add(mapping[src.faces(lo, lo + step)].reshape(-1, 3))
    finally:
        out.close()
    del mapping
    remove(ids)
    corner_uv = src.corner_uv
    if src.uv is not None and src.face_uv is None and corner_uv is None:
        corner_uv = src.face  # per-vertex UVs: each corner's from its vertex as the file numbers it
    return dataclasses.replace(src, welded=True, vertex=Block(scratch / WELDED[0], 0, XYZ, n),
                               face=Block(scratch / WELDED[1], 0, TRI, out.rows), xyz=("x", "y", "z"),
                               checks=[], retriangulate=None, corner_uv=corner_uv)
