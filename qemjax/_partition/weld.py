"""Welding positions by exact value (the bits of float64 x, y, z) in bounded memory.

Positions arrive in chunks, numbered 0, 1, … in order; a weld gives each the id of its value, ids
numbered by first appearance, so that the result does not depend on how the input was chunked:

1. each position goes, with its number, to one of B bucket files by a hash of its bits (equal values
   meet in one bucket, in number order);
2. a bucket is grouped by value (a hash table of first rows, filled in number order): a value's first
   number is its first appearance; that number is marked in a bitmap over all numbers, each position's
   (number, first) pair goes to the range file of its number, each value's (first, bits) to the range
   file of its first;
3. ranges in order: a value's id is the rank of its first appearance among all first appearances (the
   bitmap's count below it), written for every number of the range in order (the map), and the values
   first seen in the range are written out in that order (the welded vertices).

Memory: a bucket or a range (a few million rows) and the bitmap (one bit per position and a count per 64).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .._mesh.compiled import njit
from .._mesh.counting import counting_order
from .source import Appender, remove

BUCKET = np.dtype([("p", "<u8", (3,)), ("i", "<i8")])
PAIR = np.dtype([("i", "<i8"), ("g", "<i8")])
VALUE = np.dtype([("g", "<i8"), ("p", "<u8", (3,))])
RANGE = 1 << 21  # numbers per range file
_BUCKET_ROWS = 1 << 21
_MAX_FILES = 256


def _mix(h: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser: every input bit reaches every output bit (positions read from float32 have
    29 zero bits at the bottom, which a weaker mix leaves colliding)."""
    with np.errstate(over="ignore"):
        h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


def hash_rows(bits: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row of three words (a position's bits): the words mixed in one after another."""
    return _mix(_mix(_mix(bits[:, 0]) ^ bits[:, 1]) ^ bits[:, 2])


def _spread(path_of, keys: np.ndarray, rows: np.ndarray, files: dict) -> None:
    """Appends each row to the file of its key (files opened on first use, kept in ``files``), rows of
    one key keeping their order."""
    if len(keys) == 0:
        return
    order, starts = counting_order(keys.astype(np.int64), int(keys.max()) + 1)
    words = rows.view(np.uint64).reshape(len(rows), -1).take(order, axis=0)  # records are whole words
    for key in np.flatnonzero(np.diff(starts)):
        if key not in files:
            files[key] = open(path_of(key), "ab")
        files[key].write(words[starts[key]:starts[key + 1]].tobytes())


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
        bucket = (hash_rows(bits) >> np.uint64(32)) * np.uint64(self.buckets) >> np.uint64(32)
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
        num = rows["i"]
        first, is_first = _first_seen(np.ascontiguousarray(rows["p"]), num)
        new = num[is_first]
        np.bitwise_or.at(words, new >> 6, np.left_shift(np.uint64(1), (new & 63).astype(np.uint64)))
        pair = np.empty(len(rows), PAIR)
        pair["i"], pair["g"] = num, first
        _spread(lambda r: self._path("pairs", r), num // RANGE, pair, pairs)
        value = np.empty(len(new), VALUE)
        value["g"], value["p"] = new, rows["p"][is_first]
        _spread(lambda r: self._path("values", r), new // RANGE, value, values)

    def _write_range(self, r: int, words, below, ids: Appender, vertices: Appender) -> None:
        pair = np.fromfile(self._path("pairs", r), PAIR)
        remove(self._path("pairs", r))
        ids.add(_ranks(words, below, pair["i"] - r * RANGE, pair["g"]))
        path = self._path("values", r)
        if path.exists():
            value = np.fromfile(path, VALUE)
            remove(path)
            value = value[np.argsort(value["g"])]
            vertices.add(value["p"].view(np.float64))


@njit(cache=True)
def _first_seen(p, num):
    """For rows of bits p (n,3) numbered ``num`` in increasing order: the number of each row's value's
    first row, and whether the row is that first one (an open-addressing table of first rows)."""
    n = len(p)
    cap = 1
    while cap < 2 * n:
        cap *= 2
    table = np.full(cap, -1, np.int64)
    first = np.empty(n, np.int64)
    is_first = np.zeros(n, np.bool_)
    for r in range(n):
        h = p[r, 0] * np.uint64(0x9E3779B97F4A7C15) ^ p[r, 1] * np.uint64(0xC2B2AE3D27D4EB4F) \
            ^ p[r, 2] * np.uint64(0x165667B19E3779F9)
        k = np.int64((h ^ (h >> np.uint64(29))) & np.uint64(cap - 1))
        while True:
            s = table[k]
            if s < 0:
                table[k], first[r], is_first[r] = r, num[r], True
                break
            if p[s, 0] == p[r, 0] and p[s, 1] == p[r, 1] and p[s, 2] == p[r, 2]:
                first[r] = num[s]
                break
            k = (k + 1) & (cap - 1)
    return first, is_first


@njit(cache=True)
def _ranks(words, below, at, g):
    """out[at[k]] = the rank of number g[k] among the marked numbers (the bitmap ``words``, with
    ``below`` marked numbers before each word)."""
    out = np.empty(len(at), np.int64)
    one = np.uint64(1)
    for k in range(len(at)):
        w = g[k] >> 6
        mask = (one << np.uint64(g[k] & 63)) - one
        x = words[w] & mask
        c = 0
        while x:  # popcount
            x &= x - one
            c += 1
        out[at[k]] = below[w] + c
    return out
