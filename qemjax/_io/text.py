"""Text mesh formats (OBJ, OFF, ASCII STL): decoding, and what is wrong with a file a reader failed on.

`decode` turns bytes into UTF-8 whatever their encoding (UTF-8, else Latin-1, which never fails), so that
trimesh, whose fallback for other encodings is an optional package, can read them; `plain_obj` writes an
OBJ's tabs and relative indices as trimesh reads them right. The ``*_problem``
functions are only called once a reader failed or read nothing: they walk the text line by line (pure
Python, slow on big files, hence not on every read) and return the first defect in words about the file
(line numbers count from 1), or None.
"""
from __future__ import annotations

import re

import numpy as np


def decode(data: bytes) -> tuple[bytes, bool]:
    """(UTF-8 bytes, whether they differ from ``data``): ``data`` itself when it is ASCII or UTF-8,
    else ``data`` read as Latin-1 and written as UTF-8."""
    if data.isascii():
        return data, False
    try:
        data.decode("utf-8")
        return data, False
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8"), True


_RELATIVE = re.compile(rb"(?m)^[ \t]*f[ \t][^\n]*?-[0-9]")  # a face line with a relative (negative) index


def plain_obj(data: bytes) -> tuple[bytes, bool]:
    """(OBJ text as trimesh reads it right, whether it differs from ``data``): tabs between words as spaces
    (trimesh reads no vertex or face of a file that separates them with tabs), and relative indices (-1:
    the last vertex so far) as the absolute ones they mean at their line (trimesh counts them from the end of
    the file). ``data`` itself when it has neither."""
    changed = b"\t" in data
    if changed:
        data = data.replace(b"\t", b" ")
    if not _RELATIVE.search(data):
        return data, changed
    lines = data.split(b"\n")
    count = {b"v": 0, b"vt": 0, b"vn": 0}
    kinds = (b"v", b"vt", b"vn")
    for no, line in enumerate(lines):
        words = line.split()
        if not words:
            continue
        if words[0] in count:
            count[words[0]] += 1
        elif words[0] == b"f" and b"-" in line:
            corners = []
            for corner in words[1:]:
                parts = corner.split(b"/")
                corners.append(b"/".join(
                    str(count[k] + 1 + int(p)).encode() if p.startswith(b"-") and p[1:].isdigit() else p
                    for k, p in zip(kinds, parts)))
            lines[no] = b"f " + b" ".join(corners)
    return b"\n".join(lines), True


_VERTEX_LINE = re.compile(rb"(?m)^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)")


def obj_vertices(data: bytes) -> np.ndarray:
    """(k,3) float64: the positions of an OBJ text's ``v`` lines, in file order (the numbering its faces,
    and a user's vertex indices, use; a reader may drop unused ones and split others at UV seams)."""
    rows = _VERTEX_LINE.findall(data)
    return np.array(rows, dtype=np.float64).reshape(-1, 3) if rows else np.zeros((0, 3))


_COLOURED_VERTEX = re.compile(rb"(?m)^[ \t]*v(?:[ \t]+\S+){6}")  # x y z r g b: a colour after the position


def obj_has_colours(data: bytes) -> bool:
    """Whether an OBJ text's ``v`` lines carry vertex colours (six or seven numbers, as trimesh reads them)."""
    return _COLOURED_VERTEX.search(data) is not None


def quote(line: str) -> str:
    """A line of a file, stripped, at most 40 characters, unprintable ones as '?', in quotes."""
    line = "".join(c if c.isprintable() else "?" for c in line.strip())
    return repr(line if len(line) <= 40 else line[:37] + "...")


def is_binary(data: bytes) -> bool:
    """True when the first KiB holds control bytes no text file has (tab, newlines and form feed apart)."""
    head = data[:1024]
    return bool(head.translate(None, bytes(range(9, 14)) + bytes(range(32, 256))))


def _number(word: str) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def _bad_line(no: int, line: str, last: bool, what: str) -> str:
    if last:
        return f"the file ends in the middle of {what} line (line {no}: {quote(line)})"
    return f"line {no} is not a valid {what.split()[-1]} line: {quote(line)}"


_OBJ_NAMES = {"v": ("vertex", "vertices"), "vt": ("texture coordinate", "texture coordinates"),
              "vn": ("normal", "normals")}


def obj_problem(text: str) -> str | None:
    """The first defect of OBJ text: a vertex or face line cut short or not made of numbers, a face
    with fewer than 3 corners, a corner naming a vertex (UV, normal) the file does not hold."""
    if is_binary(text[:1024].encode("utf-8", "replace")):
        return "it holds binary data, not OBJ text: the file is damaged or not an OBJ file"
    lines = text.split("\n")  # only newlines end lines (trimesh's view; splitlines splits at more)
    cut = not text.endswith("\n")
    count = {"v": 0, "vt": 0, "vn": 0}
    need = {"v": 3, "vt": 1, "vn": 3}
    highest = {}  # kind -> (largest positive number used, its line)
    faces = 0
    for no, line in enumerate(lines, 1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        last = cut and no == len(lines)
        if words[0] in count:
            if len(words) <= need[words[0]] or not all(_number(w) for w in words[1:]):
                return _bad_line(no, line, last, f"a {_OBJ_NAMES[words[0]][0]}")
            count[words[0]] += 1
        elif words[0] == "f":
            if len(words) < 4:
                return _bad_line(no, line, last, "a face")
            for corner in words[1:]:
                parts = corner.split("/")
                if len(parts) > 3 or not all(p.lstrip("-").isdigit() for p in parts if p) or not parts[0] \
                        or (len(parts) == 2 and not parts[1]) or (len(parts) == 3 and not parts[2]):
                    return _bad_line(no, line, last, "a face")
                for kind, p in zip(("v", "vt", "vn"), parts):
                    k = int(p) if p else None
                    if k == 0:
                        return f"the face on line {no} refers to {_OBJ_NAMES[kind][0]} 0 (OBJ numbers from 1)"
                    if k is not None and k < 0 and -k > count[kind]:
                        return (f"the face on line {no} refers to {_OBJ_NAMES[kind][0]} {k}, but only "
                                f"{count[kind]} {_OBJ_NAMES[kind][1]} come before it")
                    if k is not None and k > highest.get(kind, (0, 0))[0]:
                        highest[kind] = (k, no)
            faces += 1
        elif words[0][0] in "fv" and words[0] not in ("vp", "fo"):  # trimesh would take it for one
            return f"line {no} is not a valid OBJ line: {quote(line)}"
    for kind, (k, no) in highest.items():
        if k > count[kind]:
            return (f"the face on line {no} refers to {_OBJ_NAMES[kind][0]} {k}, but the file holds only "
                    f"{count[kind]} {_OBJ_NAMES[kind][1]}")
    return None


def _data_lines(text: str) -> list:
    """(line number, words) of the lines of text with something on them besides a '#' comment."""
    out = []
    for no, line in enumerate(text.split("\n"), 1):
        words = line.split("#", 1)[0].split()
        if words:
            out.append((no, words))
    return out


def _off_rows(text: str) -> tuple[list, list]:
    """(count words, data rows) of OFF text: the counts may follow 'OFF' on its line or have their own."""
    rows = _data_lines(text)
    if len(rows[0][1]) > 1:
        return rows[0][1][1:], rows[1:]
    return (rows[1][1] if len(rows) > 1 else []), rows[2:]


def off_header_problem(text: str) -> str | None:
    """What is wrong with the first lines of OFF text ('OFF' and the counts), or None."""
    rows = _data_lines(text[:4096])
    if not rows or not rows[0][1][0].endswith("OFF"):
        return "not an OFF file (its first line is not 'OFF')"
    counts = _off_rows(text[:4096])[0]
    if len(counts) < 2 or not all(w.isdigit() for w in counts[:3]):
        return "the OFF header has no valid counts line (vertices, faces and edges, as whole numbers)"
    return None


def off_problem(text: str) -> str | None:
    """The first defect of OFF text: its header, fewer lines than its counts declare, a vertex line not
    made of numbers, a face line cut short or naming a vertex the file does not hold."""
    head = off_header_problem(text)
    if head:
        return head
    counts, rows = _off_rows(text)
    nv, nf = int(counts[0]), int(counts[1])
    if len(rows) < nv + nf:
        return (f"truncated OFF: the header declares {nv} vertices and {nf} faces ({nv + nf} lines of data), "
                f"but the file holds {len(rows)}")
    for no, words in rows[:nv]:
        if len(words) < 3 or not all(_number(w) for w in words[:3]):
            return f"line {no} is not a valid vertex line: {quote(' '.join(words))}"
    for no, words in rows[nv:nv + nf]:
        k = int(words[0]) if words[0].isdigit() else 0
        if k < 3 or len(words) < 1 + k or not all(w.isdigit() for w in words[1:1 + k]):
            return f"line {no} is not a valid face line: {quote(' '.join(words))}"
        big = max(int(w) for w in words[1:1 + k])
        if big >= nv:
            return (f"the face on line {no} refers to vertex {big}, but the file holds only {nv} vertices "
                    f"(numbered 0 to {nv - 1})")
    return None


_STL_WORDS = {"solid": 0, "facet": 5, "outer": 1, "vertex": 4, "endloop": 0, "endfacet": 0, "endsolid": 0}


def stl_problem(text: str) -> str | None:
    """The first defect of ASCII STL text: a line that is not STL (or whose numbers are not numbers),
    or its end before 'endsolid'."""
    rows = _data_lines(text)
    facets = 0
    for no, words in rows:
        key = words[0].lower()
        if key not in _STL_WORDS or len(words) < _STL_WORDS[key] \
                or (key in ("facet", "vertex") and not all(_number(w) for w in words[-3:])):
            return f"line {no} is not a valid ASCII STL line: {quote(' '.join(words))}"
        facets += key == "endfacet"
    if not rows or rows[-1][1][0].lower() != "endsolid":
        return f"truncated ASCII STL: it ends without an 'endsolid' line (after {facets} complete facets)"
    return None
