"""PLY files whose faces are triangle strips (``element tristrips``, as Stanford-era range scans write
them; trimesh reads them as a point cloud): `read_tristrips` reads the vertices and the strips (ASCII,
binary little or big endian) and `strip_triangles` turns strips into consistently oriented triangles.
`read_polygons` reads a binary face list of several polygon sizes, which trimesh cannot either. Both give
the vertices' other properties too, for `_io_ply.triangle_ply`.

Raises `_io_ply.PlyError` with a reason in words about the file. Host-side numpy only.
"""
from __future__ import annotations

import numpy as np

from .ply import FORMATS, TYPES, Element, Header, PlyError, element_bytes, index_list, rows_name, type_dtype, type_size


def _read_ascii(h: Header, data: bytes) -> dict:
    """{element name: [row dicts]} (vertex: its records instead, when it has no list property) of ASCII
    data."""
    words = data[h.body:].split()
    out, i = {}, 0
    for e in h.elements:
        k = len(e.props)
        if all(p.count is None for p in e.props):
            block = words[i:i + e.rows * k]
            if len(block) < e.rows * k:
                raise PlyError(f"truncated ASCII PLY: the file ends inside its {rows_name(e)}")
            i += e.rows * k
            if e.name == "vertex":
                try:
                    a = np.array(block, np.float64).reshape(e.rows, k)
                except ValueError:
                    raise PlyError("the PLY vertex data holds something that is not a number") from None
                out["vertex"] = _records(e, [a[:, j] for j in range(k)])
                out["positions"] = a[:, [[p.name for p in e.props].index(c) for c in "xyz"]]  # as written
            continue
        rows = []
        for _ in range(e.rows):
            row = {}
            for p in e.props:
                n = 1 if p.count is None else None
                if n is None:
                    if i >= len(words) or not words[i].isdigit():
                        raise PlyError(f"the PLY {e.name} data is truncated or damaged (a list count is "
                                       "missing or not a whole number)")
                    n, i = int(words[i]), i + 1
                if i + n > len(words):
                    raise PlyError(f"truncated ASCII PLY: the file ends inside its {rows_name(e)}")
                row[p.name], i = words[i:i + n], i + n
            rows.append(row)
        out[e.name] = rows
    return out


def _read_binary(h: Header, data: bytes) -> dict:
    """{element name: [row dicts]} (vertex: its records instead, when it has no list property) of binary
    data."""
    order, at, out = FORMATS[h.format], h.body, {}
    for e in h.elements:
        size = element_bytes(e, data, at, order)
        if e.name == "vertex" and all(p.count is None for p in e.props):
            dt = np.dtype([(p.name, type_dtype(p.type, order)) for p in e.props])
            out["vertex"] = np.frombuffer(data, dt, e.rows, at)
        elif e.name in ("vertex", "tristrips", "face"):  # rows one by one (lists in them)
            rows, pos = [], at
            for _ in range(e.rows):
                row = {}
                for p in e.props:
                    n = 1
                    if p.count is not None:
                        n = int(np.frombuffer(data, type_dtype(p.count, order), 1, pos)[0])
                        pos += type_size(p.count)
                    row[p.name] = np.frombuffer(data, type_dtype(p.type, order), n, pos)
                    pos += n * type_size(p.type)
                rows.append(row)
            out[e.name] = rows
        at += size
    return out


def _records(e: Element, columns: list) -> np.ndarray:
    """Records of ``e``'s scalar properties under their names and declared types, from ``columns`` (one
    array of values a scalar property)."""
    scalars = [p for p in e.props if p.count is None]
    out = np.zeros(len(columns[0]), [(p.name, TYPES[p.type]) for p in scalars])
    with np.errstate(invalid="ignore", over="ignore"):  # a number its type cannot hold: as trimesh casts it
        for p, values in zip(scalars, columns):
            out[p.name] = values
    return out


def _vertices(h: Header, got: dict) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n,3) float64, records of the vertices' scalar properties) of what `_read_ascii` or
    `_read_binary` read. An ASCII file's positions are its numbers as written, whatever their declared type."""
    rows = got["vertex"]
    if isinstance(rows, np.ndarray):
        V = got["positions"] if "positions" in got else np.stack([rows[c].astype(np.float64) for c in "xyz"], 1)
        return V, rows
    e = h.element("vertex")  # rows read one by one (a vertex element with a list property)
    V = np.array([[float(r[c][0]) for c in "xyz"] for r in rows], np.float64)
    return V, _records(e, [np.array([float(r[p.name][0]) for r in rows]) for p in e.props if p.count is None])


def strip_triangles(strips: np.ndarray) -> np.ndarray:
    """(m,3) int64 triangles of (k,) strip indices with -1 restarts: triangle i of a strip s is
    (s[i], s[i+1], s[i+2]), with the first two swapped for odd i so that all keep one orientation;
    triangles with a repeated vertex (strip joins) are dropped."""
    s = np.asarray(strips, np.int64).ravel()
    if len(s) < 3:
        return np.zeros((0, 3), np.int64)
    pos = np.arange(len(s))
    start = np.maximum.accumulate(np.where(s < 0, pos + 1, 0))  # where each element's strip starts
    i = pos[:-2]
    a, b, c = s[:-2], s[1:-1], s[2:]
    ok = (a >= 0) & (b >= 0) & (c >= 0) & (a != b) & (b != c) & (a != c)
    odd = (i - start[:-2]) % 2 == 1
    tris = np.stack([np.where(odd, b, a), np.where(odd, a, b), c], 1)
    return tris[ok]


def read_polygons(h: Header, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n,3) float64, faces (m,3) int64, the vertices' records: `_vertices`) of a binary PLY file
    whose faces are polygons of any sizes in one list (triangles beside quads, which trimesh cannot read),
    each fanned from its first corner; rows of fewer than 3 corners are left out. Row by row: for the files
    trimesh refuses."""
    el = h.element("face")
    index = index_list(el) if el is not None else None
    if index is None:
        raise PlyError("the PLY face element has no list of vertex numbers")
    name = index.name
    got = _read_binary(h, data)
    tris = [np.stack([np.full(len(r[name]) - 2, r[name][0]), r[name][1:-1], r[name][2:]], 1)
            for r in got["face"] if len(r[name]) >= 3]
    F = np.concatenate(tris).astype(np.int64) if tris else np.zeros((0, 3), np.int64)
    V, vertices = _vertices(h, got)
    return V, F, vertices


def read_tristrips(h: Header, data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n,3) float64, faces (m,3) int64, the vertices' records: `_vertices`) of a PLY file with an
    ``element tristrips`` (its first list property holds vertex numbers; each row is a strip sequence; -1,
    or an unsigned type's largest value, restarts a strip)."""
    el = h.element("tristrips")
    lists = [p for p in el.props if p.count is not None]
    if not lists:
        raise PlyError("the PLY tristrips element has no list of vertex numbers")
    got = _read_ascii(h, data) if h.format == "ascii" else _read_binary(h, data)
    V, vertices = _vertices(h, got)
    n = len(V)
    parts = []
    try:
        for row in got["tristrips"]:
            parts += [np.asarray(row[lists[0].name], np.float64), np.array([-1.0])]
    except ValueError:
        raise PlyError("the PLY tristrips hold something that is not a number") from None
    s = np.concatenate(parts) if parts else np.zeros(0)
    if not np.all(s == np.round(s)):
        raise PlyError("the PLY tristrips hold a vertex number that is not a whole number")
    s = s.astype(np.int64)
    if TYPES[lists[0].type][0] == "u":  # unsigned numbers write the restart -1 as their largest value
        s[s == 2 ** (8 * type_size(lists[0].type)) - 1] = -1
    bad = s[(s < -1) | (s >= n)]
    if len(bad):
        raise PlyError(f"the PLY tristrips refer to vertex {bad[0]}, but the file holds {n} vertices "
                       f"(numbered 0 to {n - 1}; -1 restarts a strip)")
    return V, strip_triangles(s), vertices
