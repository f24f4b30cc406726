"""Welding positions by exact value (the bits of float64 x, y, z) in bounded memory.

Positions arrive in chunks, numbered 0, 1, … in order; a weld gives each the id of its value, ids
numbered by first appearance, so that the result does not depend on how the input was chunked:

1. each position goes, with its number, to one of B bucket files by a hash of its bits (equal values
   meet in one bucket, in number order);
2. a bucket is grouped by value (a stable sort): a group's first number is the value's first
   appearance; that number is marked in a bitmap over all numbers, each position's (number, first) pair
   goes to the range file of its number, each value's (first, bits) to the range file of its first;
3. ranges in order: a value's id is the rank of its first appearance among all first appearances (the
   bitmap's count below it), written for every number of the range in order (the map), and the values
   first seen in the range are written out in that order (the welded vertices).

Memory: a bucket or a range (a few million rows) and the bitmap (one bit per position and a count per 64).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .source import Appender, remove

BUCKET = np.dtype([("p", "<u8", (3,)), ("i", "<i8")])
PAIR = np.dtype([("i", "<i8"), ("g", "<i8")])
VALUE = np.dtype([("g", "<i8"), ("p", "<u8", (3,))])
RANGE = 1 << 22  # numbers per range file
_BUCKET_ROWS = 1 << 21
_MAX_FILES = 256


def _hash(bits: np.ndarray) -> np.ndarray:
    """A 64-bit mix of the three words of each row (splitmix64's finaliser over a combination)."""
    with np.errstate(over="ignore"):
        h = bits[:, 0] * np.uint64(0x9E3779B97F4A7C15) ^ bits[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F) \
            ^ bits[:, 2] * np.uint64(0x165667B19E3779F9)
        h ^= h >> np.uint64(31)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return h


def _spread(path_of, keys: np.ndarray, rows: np.ndarray, files: dict) -> None:
    """Appends each row to the file of its key (files opened on first use, kept in ``files``), rows of
    one key keeping their order."""
    if len(keys) == 0:
        return
    order = np.argsort(keys, kind="stable")
    k = keys[order]
    cuts = np.flatnonzero(np.diff(k)) + 1
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(k)]):
        key = int(k[lo])
        if key not in files:
            files[key] = open(path_of(key), "ab")
        files[key].write(rows[order[lo:hi]].tobytes())


def _close(files: dict) -> None:
    for f in files.values():
        f.close()
    files.clear()


class Welder:
    """Add chunks of float64 (n,3) positions with `add`, then `finish`."""

    def __init__(self, folder: Path, expected: int):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.buckets = int(np.clip(-(-expected // _BUCKET_ROWS), 1, _MAX_FILES))
        self.count = 0
        self._files: dict = {}

    def _path(self, kind: str, k: int) -> Path:
        return self.folder / f"{kind}_{k:05d}.bin"

    def add(self, positions: np.ndarray) -> None:
        bits = np.ascontiguousarray(positions, np.float64).view(np.uint64).reshape(-1, 3)
        rows = np.empty(len(bits), BUCKET)
        rows["p"], rows["i"] = bits, np.arange(self.count, self.count + len(bits))
        bucket = (_hash(bits) >> np.uint64(32)) * np.uint64(self.buckets) >> np.uint64(32)
        _spread(lambda b: self._path("bucket", b), bucket, rows, self._files)
        self.count += len(bits)

    def finish(self, map_out: Path, vertices_out: Path) -> int:
        """Writes the id of every position in order (int64) to ``map_out`` and the welded positions
        (float64 (n,3), ids' order) to ``vertices_out``; returns the number of ids."""
        _close(self._files)
        words = np.zeros(-(-self.count // 64), np.uint64)
        pairs: dict = {}
        values: dict = {}
        try:
            for b in range(self.buckets):
                self._group(self._path("bucket", b), words, pairs, values)
        finally:
            _close(pairs)
            _close(values)
        below = np.zeros(len(words), np.int64)
        np.cumsum(np.bitwise_count(words)[:-1].astype(np.int64), out=below[1:])
        ids, vertices = Appender(map_out), Appender(vertices_out)
        try:
            for r in range(-(-self.count // RANGE)):
                self._write_range(r, words, below, ids, vertices)
        finally:
            ids.close()
            vertices.close()
        return vertices.rows

    def _group(self, path: Path, words, pairs, values) -> None:
        if not path.exists():
            return
        rows = np.fromfile(path, BUCKET)
        remove(path)
        p = rows["p"]
        order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))  # stable: numbers ascend within a value
        p, num = p[order], rows["i"][order]
        new = np.ones(len(p), bool)
        new[1:] = np.any(p[1:] != p[:-1], axis=1)
        starts = np.flatnonzero(new)
        first = num[starts]
        np.bitwise_or.at(words, first >> 6, np.left_shift(np.uint64(1), (first & 63).astype(np.uint64)))
        pair = np.empty(len(p), PAIR)
        pair["i"], pair["g"] = num, first[np.cumsum(new) - 1]
        _spread(lambda r: self._path("pairs", r), num // RANGE, pair, pairs)
        value = np.empty(len(starts), VALUE)
        value["g"], value["p"] = first, p[starts]
        _spread(lambda r: self._path("values", r), first // RANGE, value, values)

    def _write_range(self, r: int, words, below, ids: Appender, vertices: Appender) -> None:
        pair = np.fromfile(self._path("pairs", r), PAIR)
        remove(self._path("pairs", r))
        g = pair["g"]
        w = words[g >> 6]
        mask = np.left_shift(np.uint64(1), (g & 63).astype(np.uint64)) - np.uint64(1)
        out = np.empty(len(pair), np.int64)
        out[pair["i"] - r * RANGE] = below[g >> 6] + np.bitwise_count(w & mask)
        ids.add(out)
        path = self._path("values", r)
        if path.exists():
            value = np.fromfile(path, VALUE)
            remove(path)
            value = value[np.argsort(value["g"])]
            vertices.add(value["p"].view(np.float64))
