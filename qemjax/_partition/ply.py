"""Binary PLY as a `Source`: the vertex block and, when every face is a triangle, the face block mapped as
fixed-size records; other face blocks are streamed once (`_walk`, compiled) into scratch triangles.

The header is parsed by `qemjax._io.ply.parse_header`; ASCII PLY is read by `text.read_ascii_ply`.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._io import ply as _ply
from .._mesh.compiled import njit
from .scan import _grow
from .source import FACES, PACKED, TRI, Appender, Block, Refusal, Source

_INTS = {"i1", "u1", "i2", "u2", "i4", "u4"}
_STREAM_BYTES = 1 << 24


def header(path: Path) -> _ply.Header:
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    try:
        return _ply.parse_header(head)
    except _ply.PlyError as exc:
        raise Refusal(str(exc)) from None


def _code(t: str) -> str:
    return _ply.TYPES[t]


def _index_prop(face: _ply.Element) -> int:
    for j, p in enumerate(face.props):
        if p.name in _ply.INDEX_NAMES and p.count is not None:
            if _code(p.count) not in _INTS or _code(p.type) not in _INTS:
                raise Refusal(f"the PLY face list {p.name!r} is not made of integers ({p.count} {p.type})")
            return j
    raise Refusal("the PLY face element has no vertex_indices list")


def _layout(e: _ply.Element, order: str, index: int = -1):
    """Arrays describing a list element's properties to `_walk`: kind (0 scalar, 1 list), item size,
    count size, count signed; ``index``: the list of vertex indices (its items' signedness last)."""
    kinds, sizes, csizes, csigned = (np.zeros(len(e.props), np.int64) for _ in range(4))
    for j, p in enumerate(e.props):
        sizes[j] = _ply.type_size(p.type)
        if p.count is not None:
            if _code(p.count) not in _INTS:
                raise Refusal(f"the PLY {e.name} list {p.name!r} has a count of type {p.count}")
            kinds[j], csizes[j], csigned[j] = 1, _ply.type_size(p.count), _code(p.count)[0] == "i"
    isigned = index >= 0 and _code(e.props[index].type)[0] == "i"
    return kinds, sizes, csizes, csigned, index, isigned, order == ">"


@njit(cache=True)
def _int(buf, p, size, signed, big):
    v = 0
    for k in range(size):
        v = (v << 8) | np.int64(buf[p + k] if big else buf[p + size - 1 - k])
    if signed and v >= np.int64(1) << (8 * size - 1):
        v -= np.int64(1) << (8 * size)
    return v


CUT, DAMAGED = -1, -2  # `_list_at`'s counts for a list that runs past the read, and a negative count


@njit(cache=True)
def _list_at(buf, p, csize, csigned, size, big):
    """The list property at byte ``p`` of ``buf``: (its first item's byte, its count), or the count CUT where
    its count or items run past the end of ``buf`` (the row goes on in the next read), DAMAGED where the
    count is negative."""
    if p + csize > len(buf):
        return p, CUT
    c = _int(buf, p, csize, csigned, big)
    p += csize
    if c < 0:
        return p, DAMAGED
    if p + c * size > len(buf):
        return p, CUT
    return p, c


@njit(cache=True)
def _walk(buf, rows, kinds, sizes, csizes, csigned, index, isigned, big):
    """Whole rows of a list element from the start of ``buf`` (at most ``rows``): (bytes used, rows
    read, triangles fanned from the ``index`` list, a negative count's row or -1)."""
    n = len(buf)
    tris = np.empty((max(16, n // 8), 3), np.int64)
    nt, pos, done = 0, 0, 0
    while done < rows:
        p, nt0, fits = pos, nt, True
        for j in range(len(kinds)):
            if kinds[j] == 0:
                p += sizes[j]
                continue
            p, c = _list_at(buf, p, csizes[j], csigned[j], sizes[j], big)
            if c == DAMAGED:
                return pos, done, tris[:nt], done
            if c == CUT:
                fits = False
                break
            if j == index and c >= 3:
                tris = _grow(tris, nt, c)
                first = _int(buf, p, sizes[j], isigned, big)
                prev = _int(buf, p + sizes[j], sizes[j], isigned, big)
                for k in range(2, c):
                    cur = _int(buf, p + k * sizes[j], sizes[j], isigned, big)
                    tris[nt, 0], tris[nt, 1], tris[nt, 2] = first, prev, cur
                    nt += 1
                    prev = cur
            p += c * sizes[j]
        if not fits or p > n:
            nt = nt0
            break
        pos, done = p, done + 1
    return pos, done, tris[:nt], -1


@njit(cache=True)
def _pack(buf, rows, kinds, sizes, csizes, csigned, big, width):
    """Whole rows of an element with list properties from the start of ``buf`` (at most ``rows``): (bytes
    used, rows read, the bytes of each row's scalar properties, ``width`` a row, a negative count's row or
    -1). The lists are skipped."""
    n = len(buf)
    least = 0  # the shortest row: its scalars and its lists' counts
    for j in range(len(kinds)):
        least += sizes[j] if kinds[j] == 0 else csizes[j]
    out = np.empty(min(rows, n // max(least, 1) + 1) * width, np.uint8)
    pos, done = 0, 0
    while done < rows:
        p, o, fits = pos, done * width, True
        for j in range(len(kinds)):
            if kinds[j] == 0:
                if p + sizes[j] > n:
                    fits = False
                    break
                for k in range(sizes[j]):
                    out[o + k] = buf[p + k]
                o += sizes[j]
                p += sizes[j]
                continue
            p, c = _list_at(buf, p, csizes[j], csigned[j], sizes[j], big)
            if c == DAMAGED:
                return pos, done, out[:done * width], done
            if c == CUT:
                fits = False
                break
            p += c * sizes[j]
        if not fits:
            break
        pos, done = p, done + 1
    return pos, done, out[:done * width], -1


def _stream(path: Path, at: int, e: _ply.Element, layout, out: Appender | None, walk=_walk) -> int:
    """Reads element ``e``'s rows from byte ``at`` (what ``walk`` makes of them, `_walk`'s triangles or
    `_pack`'s records, to ``out`` when given); its end offset."""
    left, big_row = e.rows, 0
    with open(path, "rb") as f:
        f.seek(at)
        carry = b""
        while left:
            data = f.read(max(_STREAM_BYTES, 2 * big_row))
            buf = np.frombuffer(carry + data, np.uint8)
            used, done, tris, bad = walk(buf, left, *layout)
            if bad >= 0:
                raise Refusal(f"the PLY {e.name} data holds a list with a negative count: the file is damaged")
            if done == 0 and not data:
                raise Refusal(f"truncated binary PLY: the file ends inside its {_ply.rows_name(e)} (the "
                              f"header declares {e.rows} of them)")
            if out is not None:
                out.add(tris)
            big_row = len(buf) if done == 0 else 0  # a row longer than a read: read more at once
            left -= done
            at += used
            carry = buf[used:].tobytes()
    return at


def _offsets(path: Path, h: _ply.Header, order: str, size: int) -> dict:
    """Byte offsets of the elements up to the later of vertex and face (list elements before it
    streamed over)."""
    at, where = h.body, {}
    for e in h.elements:
        where[e.name] = at
        if "vertex" in where and "face" in where:
            break
        if all(p.count is None for p in e.props):
            at += e.rows * sum(_ply.type_size(p.type) for p in e.props)
        else:
            at = _stream(path, at, e, _layout(e, order), None)
        if at > size:
            raise Refusal(f"truncated binary PLY: the file ends inside its {_ply.rows_name(e)} (the header "
                          f"declares {e.rows} of them)")
    return where


def _fixed_dtype(path: Path, at: int, face: _ply.Element, order: str, index: int):
    """The record dtype of face rows that all look like the first one (lists of its lengths), and the
    (count field, length) checks; None when the first row is not a triangle."""
    fields, checks, pos = [], [], at
    with open(path, "rb") as f:
        f.seek(at)
        first = f.read(1 << 16)
    for j, p in enumerate(face.props):
        if p.count is None:
            fields.append((f"p{j}", order + _code(p.type)))
            pos += _ply.type_size(p.type)
            continue
        cs, off = _ply.type_size(p.count), pos - at
        if off + cs > len(first):
            return None
        c = int(np.frombuffer(first, order + _code(p.count), 1, off)[0])
        if c < 0 or (j == index and c != 3):
            return None
        fields.append((f"c{j}", order + _code(p.count)))
        checks.append((f"c{j}", c))
        if c:
            fields.append(("i" if j == index else f"p{j}", order + _code(p.type), (c,)))
        pos += cs + c * _ply.type_size(p.type)
    return np.dtype(fields), checks


# per vertex: those an in-core read takes, in its order (so a file gives the same UVs either way), then one
# more pair trimesh does not read (an in-core run names it among what it drops)
UV_NAMES = (*_ply.TRIMESH_UVS, ("texture_s", "texture_t"))


def uv_names(vertex: _ply.Element) -> tuple | None:
    """The names of the vertex properties that hold UVs (the first pair of `UV_NAMES` present), or None."""
    names = {p.name for p in vertex.props if p.count is None}
    return next((pair for pair in UV_NAMES if set(pair) <= names), None)


FACE_UV = "texcoord"  # a face list of each corner's u, v (as MeshLab writes them)


def _face_uv_field(face: _ply.Element, fixed) -> str | None:
    """The record field of the faces' ``texcoord`` list when every face holds 6 float values, else None."""
    for j, p in enumerate(face.props):
        if p.name == FACE_UV and p.count is not None and _code(p.type)[0] == "f" and (f"c{j}", 6) in fixed[1]:
            return f"p{j}"
    return None


def dropped(h: _ply.Header, kept: tuple = ()) -> tuple:
    """What a partitioned run does not carry over from this PLY: every property but x, y, z, the face
    indices and the vertex properties ``kept``, and every element but vertices and faces, named as the
    header names them."""
    out = []
    for e in h.elements:
        if e.name not in ("vertex", "face"):
            out.append(_ply.other_element(e.name))
            continue
        skip = {"x", "y", "z", *kept} if e.name == "vertex" else {e.props[_index_prop(e)].name, *kept}
        names = [p.name for p in e.props if p.name not in skip]
        if names:
            out.append(_ply.named(e.name, names))
    return tuple(out)


def read_binary(path: Path, h: _ply.Header, scratch: Path, uv_wanted: bool = False) -> Source:
    """The binary PLY as a `Source`; with ``uv_wanted``, its UVs (per vertex, or the faces' ``texcoord``
    lists when every face has one of 6 values and all are triangles)."""
    order, size = _ply.FORMATS[h.format], os.path.getsize(path)
    vertex, face = h.element("vertex"), h.element("face")
    if face is None:
        raise Refusal("the PLY header declares no face element")
    index = _index_prop(face)
    at = _offsets(path, h, order, size)
    names = [p.name if p.count is None else None for p in vertex.props]  # a list is no x, y, z or UV
    vdtype = np.dtype([(f"p{j}", order + _code(p.type)) for j, p in enumerate(vertex.props) if p.count is None])
    xyz = tuple(f"p{names.index(c)}" for c in "xyz")
    uv = uv_names(vertex)
    uv_fields = None if uv is None else tuple(f"p{names.index(c)}" for c in uv)
    if len(vdtype) < len(vertex.props):  # rows of several lengths: their scalars streamed to fixed records
        kinds, sizes, csizes, csigned = _layout(vertex, order)[:4]
        out = Appender(scratch / PACKED)
        try:
            _stream(path, at["vertex"], vertex, (kinds, sizes, csizes, csigned, order == ">", vdtype.itemsize),
                    out, _pack)
        finally:
            out.close()
        vblock = Block(scratch / PACKED, 0, vdtype, vertex.rows)
    else:
        if at["vertex"] + vertex.rows * vdtype.itemsize > size:
            raise Refusal(f"truncated binary PLY: the file ends inside its vertices (the header declares "
                          f"{vertex.rows} of them)")
        vblock = Block(path, at["vertex"], vdtype, vertex.rows)

    def with_uv(src: Source, corner_field: str | None = None) -> Source:
        src.dropped = dropped(h)
        src.uv_in_file = uv is not None or corner_field is not None
        if uv_wanted and uv is not None:  # per-vertex UVs: read from the vertex records
            src.uv, src.uv_fields, src.dropped_with_uv = vblock, uv_fields, dropped(h, uv)
        elif uv_wanted and corner_field is not None:  # a face list of 6 (u, v per corner), read from the face records
            src.uv, src.face_uv, src.dropped_with_uv = src.face, corner_field, dropped(h, (FACE_UV,))
        return src

    def retriangulate() -> Source:
        out = Appender(scratch / FACES)
        try:
            _stream(path, at["face"], face, _layout(face, order, index), out)
        finally:
            out.close()
        return with_uv(Source("ply", False, vblock, Block(scratch / FACES, 0, TRI, out.rows), xyz))

    fixed = _fixed_dtype(path, at["face"], face, order, index) if face.rows else (np.dtype(TRI), [])
    if fixed is not None:
        later = h.elements[h.elements.index(face) + 1:]
        least = sum(e.rows * sum(_ply.type_size(p.count or p.type) for p in e.props) for e in later)
        if at["face"] + face.rows * fixed[0].itemsize + least <= size:
            return with_uv(Source("ply", False, vblock, Block(path, at["face"], fixed[0], face.rows), xyz,
                                  fixed[1], retriangulate), _face_uv_field(face, fixed))
    return retriangulate()
