"""PLY files checked by hand, where trimesh's reader would say nothing useful.

- `parse_header`: the header, checked line by line (a `PlyError` names what is wrong);
- `check_size`: declared counts against the bytes a binary file holds, before anything is read;
- `problem`: after another reader failed, what is wrong with the data (truncated, not a number, …);
- `element_bytes`: the bytes one element of a binary file takes (for stepping over it).

Triangle strips (``element tristrips``) are read in `_io_strips`.

Host-side numpy only.
"""
from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np

from .text import quote

# PLY type name -> numpy type code (sizes follow)
TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
         "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
         "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_PLURAL = {"vertex": "vertices", "face": "faces", "edge": "edges"}


class PlyError(ValueError):
    """What is wrong with a PLY file, in words about the file (the caller adds its path)."""


class Property(NamedTuple):
    """One property: ``type`` a key of TYPES; ``count`` the list count's type, None for a scalar."""

    name: str
    type: str
    count: str | None = None


class Element(NamedTuple):
    """One element: its name, its number of rows, its properties (a list of `Property`)."""

    name: str
    rows: int
    props: list


class Header(NamedTuple):
    """A parsed header: format a key of FORMATS, elements in file order, body the data's byte offset."""

    format: str
    elements: list
    body: int

    def element(self, name: str) -> Element | None:
        return next((e for e in self.elements if e.name == name), None)

    def declares(self) -> str:
        """'162 vertices and 320 faces': the element counts, in words."""
        parts = [f"{e.rows} {rows_name(e)}" for e in self.elements]
        return " and ".join(parts) if len(parts) < 3 else ", ".join(parts[:-1]) + " and " + parts[-1]


def rows_name(e: Element) -> str:
    """What the rows of element ``e`` are called: 'vertices', 'faces', "'tristrips' rows"."""
    return _PLURAL.get(e.name, f"{e.name!r} rows")


def parse_header(data: bytes) -> Header:
    """The header of PLY bytes; PlyError when it is not a PLY header or a line in it is wrong."""
    nl = data.find(b"\n", 0, 64)
    if data[:nl if nl >= 0 else 64].strip() != b"ply":
        raise PlyError("not a PLY file (its first line is not 'ply')")
    end = re.search(rb"\nend_header[ \t\r]*\n", data)
    no_end = PlyError("the PLY header has no 'end_header' line: the file is truncated or damaged")
    # without end_header: the whole lines of the first 64 KiB, whose first wrong one is named if it is text
    head = data[:end.start()] if end else data[:data.rfind(b"\n", 0, 1 << 16)]
    fmt, elements = None, []
    for line in head.decode("latin-1").split("\n")[1:]:
        if end is None and not line.strip("\r").isprintable():
            raise no_end
        words = line.split()
        key = words[0] if words else "comment"
        if key in ("comment", "obj_info"):
            continue
        if key == "format" and len(words) == 3 and fmt is None:
            fmt = words[1]
            if fmt not in FORMATS:
                raise PlyError(f"unknown PLY format {fmt!r} (expected ascii, binary_little_endian or "
                               "binary_big_endian)")
        elif key == "element" and len(words) == 3 and words[2].isdigit():
            elements.append(Element(words[1], int(words[2]), []))
        elif key == "property" and len(words) in (3, 5) and words[1 if len(words) == 3 else 2] in TYPES \
                and (len(words) == 3 or (words[1] == "list" and words[3] in TYPES)):
            if not elements:
                raise PlyError(f"the PLY header has a property before any element: {quote(line)}")
            prop = Property(words[2], words[1]) if len(words) == 3 else Property(words[4], words[3], words[2])
            elements[-1].props.append(prop)
        else:
            raise PlyError(f"the PLY header has a line that is not valid PLY: {quote(line)}")
    if end is None:
        raise no_end
    if fmt is None:
        raise PlyError("the PLY header has no 'format' line")
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise PlyError("the PLY header declares no vertex element")
    if not {"x", "y", "z"} <= {p.name for p in vertex.props if p.count is None}:
        raise PlyError("the PLY vertex element has no x, y and z properties")
    return Header(fmt, elements, end.end())


INDEX_NAMES = ("vertex_indices", "vertex_index")  # a face's list of vertex numbers, as exporters name it


def index_list(face: Element) -> Property | None:
    """The list of vertex numbers of a face element: its first list named as in `INDEX_NAMES`, else its first
    list (None without one)."""
    lists = [p for p in face.props if p.count is not None]
    return next((p for p in lists if p.name in INDEX_NAMES), lists[0] if lists else None)


def named(element: str, names) -> str:
    """'vertex properties quality, confidence': how a run names the properties ``names`` of ``element`` that
    it does not keep (in core and partitioned alike, so both say the same of one file)."""
    return f"{element} properties {', '.join(names)}"


# what trimesh's PLY reader makes of a vertex besides x, y, z (the vertex properties a mesh read in core can
# carry on): normals when all three are there, the first UV pair it looks for (unless the faces hold their own
# UVs), and colours (three or four of these) when it found no UVs: a textured mesh has no vertex colours
_NORMALS = ("nx", "ny", "nz")
TRIMESH_UVS = (("texture_u", "texture_v"), ("u", "v"), ("s", "t"))  # in the order trimesh tries them
_COLOURS = ("red", "green", "blue", "alpha")


def read_by_trimesh(vertex: Element, face: Element | None) -> set:
    """The vertex properties trimesh reads (`_NORMALS`, `TRIMESH_UVS`, `_COLOURS`), x, y, z among them."""
    scalars = {p.name for p in vertex.props if p.count is None}
    used = {"x", "y", "z"} | (set(_NORMALS) if set(_NORMALS) <= scalars else set())
    face_uv = bool(_uv_lists(face))
    uv = () if face_uv else next((pair for pair in TRIMESH_UVS if set(pair) <= scalars), ())
    if not uv and not face_uv:
        used |= _colours(vertex)
    return used | set(uv)


def _colours(e: Element) -> set:
    """The properties of element ``e`` that trimesh reads as its colours: three or four of `_COLOURS`, else
    none."""
    found = {p.name for p in e.props if p.count is None} & set(_COLOURS)
    return found if len(found) >= 3 else set()


def _uv_lists(face: Element | None) -> set:
    """The face's ``texcoord`` lists (each corner's UV), which trimesh reads, by name."""
    return set() if face is None else {p.name for p in face.props if p.name == "texcoord" and p.count is not None}


def unread(h: Header, fallback: bool, textured: bool = False) -> list[str]:
    """What an in-core read of this PLY steps over, named as a partitioned run names it (``"vertex
    properties quality, ids"``, `named`; `other_element`): trimesh reads positions, normals, UVs and colours
    by their names (`read_by_trimesh`), and of the faces their vertex numbers, colours and ``texcoord``
    lists; it steps over the other properties and every other element. A file trimesh cannot read
    (``fallback``: `_io_strips`, then `triangle_ply`) also loses every face property but its vertex numbers,
    and the vertices' UVs are read even beside the faces' ``texcoord`` lists. ``textured``: trimesh read the
    file's UVs, so its colours are named once, as let go for them (`colours_beside_uv`)."""
    vertex, face = h.element("vertex"), h.element("face")
    used = read_by_trimesh(vertex, None if fallback else face)
    beside = colours_beside_uv(h) if textured else []
    names = [p.name for p in vertex.props if (p.name not in used and not (beside and p.name in _COLOURS))
             or p.count is not None]
    out = [named("vertex", names)] if names else []
    index = index_list(face) if face is not None else None
    read = set() if fallback or face is None else _read_of_face(face)
    names = [p.name for p in face.props if p is not index and p.name not in read] if face is not None else []
    if beside:
        names = [n for n in names if n not in _COLOURS]
    if names:
        out.append(named("face", names))
    elements = ("vertex", "face", "tristrips") if fallback else ("vertex", "face")  # (strips: `_io.strips`)
    return out + [other_element(e.name) for e in h.elements if e.name not in elements] + beside


def _read_of_face(face: Element) -> set:
    """The face properties trimesh reads besides the vertex numbers: colours (a mesh's face colours, which the
    cleaning names where qemjax does not keep them) and ``texcoord`` lists."""
    return _colours(face) | _uv_lists(face)


def other_element(name: str) -> str:
    """How a run names an element of a PLY besides its vertices and faces (edges, a scanner's ``range_grid``),
    which it does not read."""
    return f"the {name!r} element"


def beside_uv(element: str = "vertex") -> str:
    """How the colours of ``element`` that trimesh lets go for the UVs are named among what is dropped."""
    return f"{element} colours (beside the UVs, which are read instead)"


def colours_beside_uv(h: Header) -> list[str]:
    """The colours of a PLY that trimesh reads as UVs: its mesh holds one visual, the UVs, and lets the
    vertex and face colours (``red``, ``green``, ``blue``: what it reads as colours) go."""
    out = []
    for name in ("vertex", "face"):
        e = h.element(name)
        if e is not None and len({"red", "green", "blue"} & {p.name for p in e.props}) == 3:
            out.append(beside_uv(name))
    return out


def type_size(t: str) -> int:
    return int(TYPES[t][1])


def type_dtype(t: str, order: str) -> np.dtype:
    return np.dtype(order + TYPES[t])


def check_size(h: Header, data: bytes) -> None:
    """PlyError when a binary file holds fewer bytes than its declared counts need (lists counted as
    empty: the least they can take). ASCII files pass."""
    if h.format == "ascii":
        return
    least = sum(e.rows * sum(type_size(p.count or p.type) for p in e.props) for e in h.elements)
    held = len(data) - h.body
    if held < least:
        raise PlyError(f"truncated binary PLY: the header declares {h.declares()}, which take at least "
                       f"{least} bytes, but the file holds {held} bytes of data")


def element_bytes(e: Element, data: bytes, at: int, order: str) -> int:
    """The bytes element ``e`` takes when it starts at offset ``at`` of binary data; PlyError when it
    runs past the end. Rows with one list whose counts are all equal are measured at once."""
    fixed = [p for p in e.props if p.count is None]
    lists = [p for p in e.props if p.count is not None]
    if not lists:
        return e.rows * sum(type_size(p.type) for p in fixed)
    if e.rows == 0:
        return 0
    past = PlyError(f"truncated binary PLY: the file ends inside its {rows_name(e)} "
                    f"(the header declares {e.rows} of them)")
    if len(lists) == 1:  # all rows alike: a strided look at every count field at once
        p = lists[0]
        lead = sum(type_size(q.type) for q in e.props[: e.props.index(p)])
        if at + lead + type_size(p.count) > len(data):
            raise past
        n = int(np.frombuffer(data, type_dtype(p.count, order), 1, at + lead)[0])
        row = sum(type_size(q.type) for q in fixed) + type_size(p.count) + n * type_size(p.type)
        if at + e.rows * row <= len(data):
            rows = np.frombuffer(data, np.uint8, e.rows * row, at).reshape(e.rows, row)
            counts = rows[:, lead:lead + type_size(p.count)].copy().view(type_dtype(p.count, order)).ravel()
            if np.all(counts == n):
                return e.rows * row
    pos = at
    for _ in range(e.rows):  # rows of different lengths: step through them
        for p in e.props:
            if p.count is None:
                pos += type_size(p.type)
                continue
            if pos + type_size(p.count) > len(data):
                raise past
            n = int(np.frombuffer(data, type_dtype(p.count, order), 1, pos)[0])
            if n < 0:
                raise PlyError(f"the PLY {e.name} data holds a list of {n} items: the file is damaged")
            pos += type_size(p.count) + n * type_size(p.type)
        if pos > len(data):
            raise past
    return pos - at


def _ascii_rows(h: Header, text: str) -> list:
    """(line number, line) of the ASCII data rows: non-empty lines after the header."""
    skip = text[: h.body].count("\n")
    return [(skip + i + 1, s) for i, s in enumerate(text[h.body:].split("\n")) if s.strip()]


def _row_length(e: Element, values: list) -> int:
    """How many values an ASCII row of ``e`` starting with ``values`` needs (lists by their counts;
    more than len(values) when a count is missing, negative or not whole)."""
    pos = 0
    for p in e.props:
        if p.count is not None:
            n = values[pos] if pos < len(values) else -1
            if n < 0 or n != int(n):
                return len(values) + 1
            pos += int(n)
        pos += 1
    return pos


def problem(h: Header, data: bytes) -> str | None:
    """What is wrong with the data of a file whose header parsed (after a reader failed on it), or
    None when nothing is found."""
    if h.format != "ascii":
        at, order = h.body, FORMATS[h.format]
        try:
            for e in h.elements:
                at += element_bytes(e, data, at, order)
        except PlyError as exc:
            return str(exc)
        return None
    rows = _ascii_rows(h, data.decode("latin-1"))
    need = sum(e.rows for e in h.elements)
    if len(rows) < need:
        return (f"the header declares {h.declares()} ({need} lines of data), but the file holds "
                f"{len(rows)}: it is truncated or damaged")
    k = 0
    for e in h.elements:
        for line_no, line in rows[k:k + e.rows]:
            try:
                if not line.rstrip("\r").replace("\t", " ").isprintable():  # \r, \v, …: trimesh splits
                    raise ValueError
                values = [float(w) for w in line.split()]
            except ValueError:
                return f"line {line_no} holds something that is not a number: {quote(line)}"
            if _row_length(e, values) > len(values):
                return f"line {line_no} holds too few values for a {e.name} row: {quote(line)}"
        k += e.rows
    return None


_TYPE_NAMES = {code: name for name, code in reversed(TYPES.items())}  # the first name of each: "char", "float"


def triangle_ply(h: Header, text: bytes, V: np.ndarray, F: np.ndarray, vertices: np.ndarray) -> bytes:
    """A binary PLY of triangles ``F`` (m,3) whose vertices hold positions ``V`` (n,3) as doubles and the
    other scalar properties of ``vertices`` (records, `_io_strips`) as the file ``text`` declares them, with
    its comments (a ``TextureFile``): a file trimesh cannot read (polygons of several sizes, triangle strips)
    as the plain one whose attributes it reads."""
    head = text[:text.find(b"\nend_header")].split(b"\n")
    comments = [line.rstrip(b"\r") for line in head if line.split()[:1] == [b"comment"]]
    vertex = h.element("vertex")
    props = [(p.name, "<f8" if p.name in ("x", "y", "z") else "<" + TYPES[p.type]) for p in vertex.props
             if p.count is None]
    rows = np.zeros(len(V), props)
    for name in rows.dtype.names:
        rows[name] = vertices[name]
    rows["x"], rows["y"], rows["z"] = V[:, 0], V[:, 1], V[:, 2]
    tris = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,))])
    tris["n"], tris["i"] = 3, F
    lines = [b"ply", b"format binary_little_endian 1.0", *comments, f"element vertex {len(V)}".encode(),
            *(f"property {_TYPE_NAMES[t[1:]]} {name}".encode() for name, t in props),
            f"element face {len(F)}".encode(), b"property list uchar int vertex_indices", b"end_header", b""]
    return b"\n".join(lines) + rows.tobytes() + tris.tobytes()


# a position written as float32 may move by up to half a float32 step of its coordinate: far from the origin
# (a georeferenced scan) that exceeds what simplifying changed; past this share of the diagonal, doubles
WIDEN_AT = 1e-6


def with_double_positions(data: bytes, V: np.ndarray, always: bool = False) -> bytes:
    """Binary little-endian PLY bytes (trimesh's export: the vertex element first, scalar properties) with
    its x, y, z written as doubles from ``V`` (n,3) float64, when writing them as float32 would move a vertex
    by more than `WIDEN_AT` of the bounding-box diagonal, or would move any at all with ``always`` (positions
    that must stay exactly as they are: locked vertices); ``data`` itself otherwise."""
    V = np.asarray(V, np.float64)
    if not len(V):
        return data
    diagonal = float(np.linalg.norm(V.max(0) - V.min(0)))
    moved = np.max(np.abs(V.astype(np.float32).astype(np.float64) - V))
    if moved <= (0.0 if always else WIDEN_AT * diagonal):
        return data
    h = parse_header(data)
    vertex = h.elements[0]
    if h.format != "binary_little_endian" or vertex.name != "vertex" or any(p.count for p in vertex.props):
        return data  # not the layout trimesh writes: left as it is
    old = np.dtype([(p.name, "<" + TYPES[p.type]) for p in vertex.props])
    new = np.dtype([(p.name, "<f8" if p.name in ("x", "y", "z") else "<" + TYPES[p.type]) for p in vertex.props])
    rows = np.frombuffer(data, old, vertex.rows, h.body)
    out = np.empty(vertex.rows, new)
    for name in old.names:
        out[name] = rows[name]
    out["x"], out["y"], out["z"] = V[:, 0], V[:, 1], V[:, 2]
    head = data[:h.body].decode("ascii")
    for axis in "xyz":
        head = re.sub(rf"(?m)^property (float|float32) {axis}\s*$", f"property double {axis}", head)
    return head.encode("ascii") + out.tobytes() + data[h.body + old.itemsize * vertex.rows:]
