"""Which reader a mesh file goes to (by its name's extension, else by its first bytes), and the errors
it raises: one-line ``ValueError`` messages that start with the file's path."""
from __future__ import annotations

import os
from pathlib import Path

from .._io.files import binary_stl_count
from .._io.text import is_binary
from . import ply, text
from .source import Refusal, Source

FORMATS = ("ply", "obj", "stl")


def _sniff(head: bytes) -> str | None:
    if head.startswith(b"ply") and head[3:4] in (b"\n", b"\r"):
        return "ply"
    if head.lstrip()[:5].lower() == b"solid":
        return "stl"
    if not is_binary(head) and any(line.split()[:1] in ([b"v"], [b"f"]) for line in head.split(b"\n")):
        return "obj"
    return None


def _stl(path: Path, scratch: Path) -> Source:
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        head = f.read(84)
    count = int.from_bytes(head[80:84], "little") if len(head) == 84 else -1
    if binary_stl_count(head, size) is not None:
        return text.read_binary_stl(path, scratch, count)
    if head.lstrip()[:5].lower() == b"solid" and not is_binary(head[:80]):
        return text.read_ascii_stl(path, scratch)
    if count < 0:
        raise Refusal(f"truncated binary STL: {size} bytes, fewer than the 84 its header alone takes")
    if size < 84 + 50 * count:
        raise Refusal(f"truncated binary STL: its header says {count} triangles, the file holds "
                      f"{(size - 84) // 50}")
    raise Refusal(f"damaged binary STL: its header says {count} triangles ({84 + 50 * count} bytes), but "
                  f"the file holds {size} bytes")


def open_source(path, scratch: Path, uv: bool = False) -> Source:
    """The mesh in ``path`` as a `Source` (text formats converted into ``scratch``), with its UVs when
    ``uv`` and every triangle corner has one (``Source.uv``); ValueError naming the file and what is wrong
    with it."""
    name = os.fspath(path)
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{name}: no such file" if not path.exists() else f"{name}: not a file")
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        with open(path, "rb") as f:
            fmt = _sniff(f.read(1 << 12))
        if fmt is None:
            kind = f"a {path.suffix} file" if path.suffix else "a file"
            raise ValueError(f"{name}: unsupported format: {kind} that is not PLY, OBJ or STL (what is read here)")
    try:
        if fmt == "ply":
            h = ply.header(path)
            return text.read_ascii_ply(path, h, scratch, uv) if h.format == "ascii" else ply.read_binary(path, h, scratch, uv)
        if fmt == "stl":
            return _stl(path, scratch)
        return text.read_obj(path, scratch, uv)
    except Refusal as exc:
        raise ValueError(f"{name}: {exc}") from None


def texture_of(path) -> Path | None:
    """The texture image a mesh file names, when it exists: the ``map_Kd`` of the material an OBJ's faces use
    (its first ``usemtl``; without one, the first ``map_Kd``) in its material libraries (``mtllib`` and
    ``usemtl`` lines in its first MiB; one image, as the UVs of a partitioned run keep one material), or a
    PLY header's ``comment TextureFile``; else None."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    lines = head.split(b"\n")
    if head.startswith(b"ply"):
        for line in lines[:head[:head.find(b"end_header")].count(b"\n") + 1]:
            words = line.split(None, 2)
            if words[:2] == [b"comment", b"TextureFile"] and len(words) == 3:
                image = path.parent / words[2].strip().decode("utf-8", "replace")
                return image if image.is_file() else None
        return None
    libs, used = [], None
    for line in lines:
        words = line.split(None, 1)
        if words[:1] == [b"mtllib"] and len(words) == 2:  # a name with spaces, or several names
            whole = words[1].strip().decode("utf-8", "replace")
            libs += [whole] + ([] if (path.parent / whole).is_file() else whole.split())
        elif words[:1] == [b"usemtl"] and len(words) == 2 and used is None:  # the material the faces use
            used = words[1].strip()
    for name in libs:
        lib = path.parent / name
        if not lib.is_file():
            continue
        current = None
        for entry in lib.read_bytes().split(b"\n"):
            parts = entry.split()
            if parts[:1] == [b"newmtl"]:
                current = b" ".join(parts[1:])
            elif parts[:1] == [b"map_Kd"] and len(parts) > 1 and (used is None or current == used):
                image = lib.parent / _map_file(parts[1:]).decode("utf-8", "replace")
                return image if image.is_file() else None  # the used material's image, or none (as in core)
    return None


# a texture map's options and how many values each takes (the MTL format's), before its file's name
_MAP_OPTIONS = {b"-blendu": 1, b"-blendv": 1, b"-bm": 1, b"-boost": 1, b"-cc": 1, b"-clamp": 1, b"-imfchan": 1,
                b"-mm": 2, b"-o": 3, b"-s": 3, b"-t": 3, b"-texres": 1, b"-type": 1}


def _map_file(words: list) -> bytes:
    """The file a ``map_Kd`` line names: its words after the options (a name may hold spaces)."""
    i = 0
    while i < len(words) and words[i] in _MAP_OPTIONS:
        i += 1 + _MAP_OPTIONS[words[i]]
    return b" ".join(words[i:])
