"""Text formats (OBJ, ASCII STL, ASCII PLY) and binary STL, converted in one streaming pass into the
scratch arrays (`source.VERTICES`, `source.FACES`): blocks of whole lines go through the compiled
scanners (`scan`), their coordinates through numpy's parser (correctly rounded float64).

OBJ and STL positions are welded by exact value (`weld`); STL is always a soup, and OBJ files repeat
positions (at UV seams, or written per face).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._io import ply as _ply
from .._io.text import is_binary, quote
from . import scan
from .ply import _index_prop, dropped as _ply_dropped, uv_names
from .source import (Appender, Block, CORNER_UV, FACES, Refusal, TRI, UV, UV_DTYPE, VERTICES, remove, rows,
                     scratch_source)
from .weld import Welder

BLOCK = 1 << 24  # bytes of text scanned at once
_STL_RECORD = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
_MESSAGES = {
    scan.BAD_VERTEX: "is a vertex line without x, y and z",
    scan.BAD_CORNER: "has a face corner that is not a vertex number",
    scan.ZERO_INDEX: "has a face corner numbered 0 (OBJ numbers vertices from 1)",
    scan.BEFORE_FIRST: "has a face corner counting back past the first vertex",
    scan.FEW_CORNERS: "has a face with fewer than 3 corners",
    scan.BAD_FACET: "ends a facet that does not have 3 vertices",
    scan.FEW_VALUES: "holds too few values for a {what} row",
    scan.BAD_INT: "holds a list count or vertex number that is not a whole number",
}
UV_NAME = "texture coordinates (vt)"  # how a warning names an OBJ's UVs


def blocks(path: Path, start: int = 0, continued: bool = False):
    """Blocks of whole lines (bytes ending with a newline) from byte ``start``; ``continued``: a line ending
    with a backslash goes on in the next line (OBJ), so a block never ends after one."""
    with open(path, "rb") as f:
        f.seek(start)
        carry = b""
        while True:
            data = f.read(BLOCK)
            if not data:
                if carry:
                    yield carry + b"\n"
                return
            data = carry + data
            cut = data.rfind(b"\n") + 1
            while continued and cut and data.endswith((b"\\\n", b"\\\r\n"), 0, cut):
                cut = data.rfind(b"\n", 0, cut - 1) + 1
            carry = data[cut:]
            if cut:
                yield data[:cut]


def _line(block: bytes, k: int) -> str:
    return block.split(b"\n")[k - 1].decode("latin-1")


def _refuse(code: int, block: bytes, k: int, line0: int, what: str = "") -> Refusal:
    return Refusal(f"line {line0 + k} {_MESSAGES[code].format(what=what)}: {quote(_line(block, k))}")


def _floats(coords: np.ndarray, count: int, block: bytes, line0: int, pick, width: int = 3) -> np.ndarray:
    """The (count,width) float64 coordinates in ``coords``; else a refusal naming the first line whose
    coordinate words (``pick(line number in block, words)``, None for other lines) are not numbers."""
    try:
        v = np.fromstring(coords.tobytes(), np.float64, sep=" ")
        if len(v) == width * count:
            return v.reshape(count, width)
    except ValueError:
        pass
    for k, line in enumerate(block.split(b"\n"), 1):
        try:
            [float(w) for w in pick(k, line.split()) or ()]
        except ValueError:
            raise Refusal(f"line {line0 + k} holds a coordinate that is not a number: "
                          f"{quote(line.decode('latin-1'))}") from None
    raise Refusal(f"after line {line0} a coordinate is not a number")


def _finish_weld(welder: Welder, scratch: Path, fmt: str, raw: Appender | None, n_raw: int) -> object:
    """The welded source: STL's ids are its faces; OBJ's faces are mapped through the ids."""
    if raw is None:
        n = welder.finish(scratch / FACES, scratch / VERTICES)
        return scratch_source(scratch, fmt, True, n, welder.count // 3)
    ids = scratch / "ids.i64"
    n = welder.finish(ids, scratch / VERTICES)
    if n == n_raw:  # no position repeats: the ids are 0, 1, …
        os.replace(raw.path, scratch / FACES)
    else:
        mapping = np.fromfile(ids, np.int64).astype(np.int32 if n < 2**31 else np.int64)
        out = Appender(scratch / FACES)
        step = BLOCK // 24
        for lo in range(0, raw.rows, step):
            flat = rows(raw.path, np.dtype(np.int64), 0, 3 * lo, 3 * min(lo + step, raw.rows))
            out.add(mapping[flat].astype(np.int64).reshape(-1, 3))
        out.close()
        remove(raw.path)
    remove(ids)
    return scratch_source(scratch, fmt, True, n, raw.rows)


_CONTINUED = re.compile(rb"\\\r?\n")  # a backslash ending a line: it goes on in the next
# a `v` line with more than three values: its vertex colour (x y z r g b), which a partitioned run drops
_COLOURED = re.compile(rb"(?m)^v[ \t]+\S+[ \t]+\S+[ \t]+\S+[ \t]+[^\s#]")


def read_obj(path: Path, scratch: Path, uv_wanted: bool = False):
    """The OBJ file as a welded `Source`; with ``uv_wanted``, its UVs (`source.UV`, each triangle corner's
    ``vt``) when every corner names one (written to scratch only then)."""
    welder = Welder(scratch / "weld", os.path.getsize(path) // 16)
    raw = Appender(scratch / "faces_raw.i64")
    uv, corner_uv = Appender(scratch / UV), Appender(scratch / CORNER_UV)
    nv = nvt = line0 = 0
    top = (-1, 0)  # the largest vertex number a face uses, and its block's first line
    top_t = -1  # the largest texture coordinate number a face uses
    bare = False  # a corner names no texture coordinate, or a vt line is not a u and a v
    seen_vn = seen_colour = False
    try:
        for block in blocks(path, continued=True):
            lines = block.count(b"\n")
            if b"\\\n" in block or b"\\\r\n" in block:  # continued lines, joined as trimesh joins them (in
                # core); a refusal's line number in such a block counts the joined lines as one
                block = _CONTINUED.sub(b" ", block)
                block += b"" if block.endswith(b"\n") else b"\n"  # the file's last line was continued
            seen_vn = seen_vn or block.startswith(b"vn ") or b"\nvn " in block
            seen_colour = seen_colour or _COLOURED.search(block) is not None
            if line0 == 0 and is_binary(block[:1024]):
                raise Refusal("it holds binary data, not OBJ text: the file is damaged or not an OBJ file")
            coords, k, tris, err, at, uv_words, kt, tuv, short = scan.obj(np.frombuffer(block, np.uint8), nv, nvt)
            if err:
                raise _refuse(err, block, at, line0)
            welder.add(_floats(coords, k, block, line0, lambda _, w: w[1:4] if w[:1] == [b"v"] else None))
            bare = bare or short or not uv_wanted
            if kt and not bare:  # UVs that cannot be read are not kept (as before, the file is read)
                try:
                    uv.add(_floats(uv_words, kt, block, line0, lambda _, w: w[1:3] if w[:1] == [b"vt"] else None, 2))
                except Refusal:
                    bare = True
            raw.add(tris)
            if not bare:
                corner_uv.add(tuv)
            if len(tris) and tris.max() > top[0]:
                top = (int(tris.max()), line0)
            if len(tuv):
                top_t = max(top_t, int(tuv.max()))
            bare = bare or bool(len(tuv) and tuv.min() < 0)  # NO_UV, BAD_UV
            nv += k
            nvt += kt
            line0 += lines
    finally:
        raw.close()
        uv.close()
        corner_uv.close()
    if top[0] >= nv:
        where = f" (below line {top[1]})" if top[1] else ""  # the block it is in: lines are not counted per face
        raise Refusal(f"a face{where} uses vertex {top[0] + 1}, but the file has {nv} vertices")
    if raw.rows == 0:
        raise Refusal("the OBJ file has no faces (no 'f' lines)")
    src = _finish_weld(welder, scratch, "obj", raw, nv)
    src.dropped = tuple(k for k, seen in ((UV_NAME, nvt > 0), ("normals (vn)", seen_vn),
                                          ("vertex colours (v x y z r g b)", seen_colour)) if seen)
    src.uv_in_file = nvt > 0
    bare = bare or top_t >= nvt  # a corner names a texture coordinate the file does not have
    if nvt and not bare:
        src.uv = Block(scratch / UV, 0, UV_DTYPE, nvt)
        src.corner_uv = Block(scratch / CORNER_UV, 0, TRI, raw.rows)
        src.dropped_with_uv = tuple(k for k in src.dropped if k != UV_NAME)
    else:
        remove(scratch / UV)
        remove(scratch / CORNER_UV)
    return src


def read_ascii_stl(path: Path, scratch: Path):
    welder = Welder(scratch / "weld", os.path.getsize(path) // 40)
    pending = line0 = 0
    for block in blocks(path):
        block = block.lower()  # keywords in any case (some exporters write SOLID, FACET, VERTEX), as in core
        coords, k, _, pending, err, at = scan.stl(np.frombuffer(block, np.uint8), pending)
        if err:
            raise _refuse(err, block, at, line0)
        welder.add(_floats(coords, k, block, line0, lambda _, w: w[1:4] if w[:1] == [b"vertex"] else None))
        line0 += block.count(b"\n")
    if welder.count % 3:
        raise Refusal("the file ends in the middle of a facet: it is truncated")
    if welder.count == 0:
        raise Refusal("the STL file has no facets")
    return _finish_weld(welder, scratch, "stl", None, 0)


def read_binary_stl(path: Path, scratch: Path, n: int):
    welder = Welder(scratch / "weld", 3 * n)
    step = BLOCK // _STL_RECORD.itemsize
    for lo in range(0, n, step):
        welder.add(rows(path, _STL_RECORD, 84, lo, min(lo + step, n))["v"].reshape(-1, 3))
    if n == 0:
        raise Refusal("the STL file has no facets")
    return _finish_weld(welder, scratch, "stl", None, 0)


def _element_args(h: _ply.Header, e: _ply.Element, uv: bool = False):
    """(mode, x y z (and with ``uv`` the UVs') columns, property kinds, index list) of an ASCII element for
    `scan.ply_rows`."""
    kinds = np.array([p.count is not None for p in e.props], np.int64)
    if e.name == "vertex":
        names = [p.name if p.count is None else None for p in e.props]  # a list is no x, y, z or UV
        extra = (uv_names(e) or ()) if uv else ()
        return 1, np.array([names.index(c) for c in ("x", "y", "z", *extra)], np.int64), kinds, -1
    if e.name == "face":
        return 2, np.zeros(3, np.int64), kinds, _index_prop(e)
    return 0, np.zeros(3, np.int64), kinds, -1


def _scalar_words(words: list, kinds: np.ndarray, cols) -> list:
    """Where the properties ``cols`` of an ASCII PLY row are among its ``words`` (a list property is its
    count and that many words); those past the row's end or behind a count that is not one, left out."""
    at, w = [], 0
    for kind in kinds:
        at.append(w)
        if kind:
            try:
                w += int(words[w])
            except (IndexError, ValueError):
                break
        w += 1
    return [at[c] for c in cols if c < len(at) and at[c] < len(words)]


def read_ascii_ply(path: Path, h: _ply.Header, scratch: Path, uv_wanted: bool = False):
    """The ASCII PLY as a `Source`; with ``uv_wanted``, its per-vertex UVs when the vertex element has them
    and they are numbers (else the file is read without them)."""
    vertex = h.element("vertex")
    uv_wanted = bool(uv_wanted and vertex is not None and uv_names(vertex))
    if h.element("face") is None:
        raise Refusal("the PLY header declares no face element")
    with open(path, "rb") as f:
        line0 = f.read(h.body).count(b"\n")
    vertices, faces, uv = Appender(scratch / VERTICES), Appender(scratch / FACES), Appender(scratch / UV)
    todo = [(e, e.rows) for e in h.elements if e.rows]
    try:
        for block in blocks(path, h.body):
            buf, pos = np.frombuffer(block, np.uint8), 0
            while todo and pos < len(buf):
                e, left = todo[0]
                mode, cols, kinds, index = _element_args(h, e, uv_wanted)
                start = pos
                pos, done, coords, tris, lines, err, at = scan.ply_rows(buf, pos, left, mode, cols, kinds, index)
                if err:
                    k = block[:pos].count(b"\n") + 1
                    raise _refuse(err, block, k, line0, e.name)
                if mode == 1:
                    first = block[:pos].count(b"\n") - lines  # lines before this call in the block
                    last = first + lines
                    def pick(k, w, cols):
                        return [w[c] for c in _scalar_words(w, kinds, cols)] if first < k <= last and w else None

                    try:
                        rows_read = _floats(coords, done, block, line0, lambda k, w: pick(k, w, cols), len(cols))
                    except Refusal:
                        if len(cols) == 3:
                            raise
                        uv_wanted = False  # UVs that are not numbers: the positions alone, as before
                        xyz = cols[:3]
                        coords = scan.ply_rows(buf, start, left, mode, xyz, kinds, index)[2]
                        rows_read = _floats(coords, done, block, line0, lambda k, w: pick(k, w, xyz), 3)
                    vertices.add(rows_read[:, :3])
                    uv.add(rows_read[:, 3:])
                faces.add(tris)
                todo[0] = (e, left - done)
                if left == done:
                    todo.pop(0)
            line0 += block.count(b"\n")
    finally:
        vertices.close()
        faces.close()
        uv.close()
    if todo:
        e, left = todo[0]
        raise Refusal(f"the header declares {h.declares()}, but the file ends {left} {_ply.rows_name(e)} "
                      "short: it is truncated")
    src = scratch_source(scratch, "ply", False, vertices.rows, faces.rows)
    src.dropped = _ply_dropped(h)
    src.uv_in_file = uv_names(h.element("vertex")) is not None
    if not uv_wanted:
        remove(scratch / UV)
    else:  # per-vertex UVs, converted beside the positions
        kept = uv_names(h.element("vertex"))
        src.uv, src.dropped_with_uv = Block(scratch / UV, 0, UV_DTYPE, vertices.rows), _ply_dropped(h, kept)
    return src
