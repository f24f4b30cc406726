"""Reading mesh files: every failure becomes one ``ValueError`` line ``could not read <path>: <reason>``,
the reason in words about the file, never a library's internals.

`read` checks what it cheaply can before trimesh reads the file (a PLY header, a binary PLY's or STL's
declared counts against its size, a GLB's magic, lengths and JSON), decodes text that is not UTF-8 itself
(trimesh's fallback for other encodings is an optional package), reads PLY triangle strips itself, and
checks what trimesh returns (faces at all, face numbers within the vertices). When trimesh fails anyway,
the file is walked line by line (`_io_text`, `_io_ply`) for a defect to name; failing that the message
says the file is damaged or truncated.
"""
from __future__ import annotations

import io
import json
import os
import re
import struct

import numpy as np

from . import ply as _io_ply, strips as _io_strips, text as _io_text, texture as _io_texture

_NAMES = {"obj": "OBJ", "ply": "PLY", "stl": "STL", "off": "OFF", "glb": "GLB", "gltf": "glTF"}
_TEXT = ("obj", "off", "gltf")  # formats that are text through and through


class BadFile(ValueError):
    """What is wrong with a file, in words about the file (`read` adds the path)."""


def _name(fmt: str) -> str:
    return _NAMES.get(fmt, fmt.upper())


def concatenated(scene):
    """A trimesh Scene's geometry as one (a Trimesh, or a PointCloud when that is all it holds)."""
    return scene.to_geometry() if hasattr(scene, "to_geometry") else scene.dump(concatenate=True)


def binary_stl_count(head: bytes, size: int) -> int | None:
    """The triangles of a binary STL of ``size`` bytes whose first bytes are ``head``: the count its header
    declares, where the file holds exactly that many records (84 bytes, then 50 per triangle); else None."""
    if len(head) < 84:
        return None
    count = int.from_bytes(head[80:84], "little")
    return count if size == 84 + 50 * count else None


def _check_stl(data: bytes) -> bytes:
    """The data to read (ASCII STL decoded as `_io_text.decode`) after checking that an STL is ASCII
    ('solid' first) or a binary one whose size matches its triangle count."""
    n = len(data)
    count = int.from_bytes(data[80:84], "little") if n >= 84 else 0
    if binary_stl_count(data, n) is not None:
        return data
    if data.lstrip()[:5].lower() == b"solid":
        return _io_text.decode(data)[0]
    if not _io_text.is_binary(data):
        raise BadFile("not an STL file (it is text, but does not begin with 'solid')")
    if n < 84:
        raise BadFile(f"truncated binary STL: {n} bytes, fewer than the 84 its header alone takes")
    if n < 84 + 50 * count:
        raise BadFile(f"truncated binary STL: header says {count} triangles, file holds {(n - 84) // 50}")
    raise BadFile(f"damaged binary STL: header says {count} triangles ({84 + 50 * count} bytes), but the "
                  f"file holds {n} bytes")


_COMPONENT = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _check_glb(data: bytes) -> None:
    """A GLB's magic, version, lengths, JSON chunk, and where its JSON places data in its binary chunk."""
    n = len(data)
    if data[:4] != b"glTF":
        raise BadFile("not a GLB file (it does not start with 'glTF')")
    if n < 20:
        raise BadFile(f"truncated GLB: {n} bytes, fewer than the 20 its header takes")
    version, length, jlen = struct.unpack_from("<III", data, 4)
    if version != 2:
        raise BadFile(f"a GLB of version {version}: only version 2 is read")
    if length > n:
        raise BadFile(f"truncated GLB: header says {length} bytes, file holds {n}")
    if data[16:20] != b"JSON":
        raise BadFile("damaged GLB: its first part is not the JSON that a GLB starts with")
    if 20 + jlen > n:
        raise BadFile(f"truncated GLB: its JSON part says {jlen} bytes, the file holds {n - 20} after its "
                      "header")
    try:
        gltf = json.loads(data[20:20 + jlen].decode("utf-8"))
    except ValueError:  # UnicodeDecodeError included
        raise BadFile("damaged GLB: its JSON part is not valid JSON") from None
    at, blen = 20 + jlen, 0
    if at + 8 <= n:
        blen, kind = struct.unpack_from("<I4s", data, at)
        if kind == b"BIN\0" and at + 8 + blen > n:
            raise BadFile(f"truncated GLB: its binary part says {blen} bytes, the file holds {n - at - 8}")
    try:
        accessors, views = gltf.get("accessors", []), gltf.get("bufferViews", [])
        for m in gltf.get("meshes", []):
            for prim in m["primitives"]:  # each names accessors that exist, positions among them
                named = [prim["attributes"]["POSITION"], *prim["attributes"].values()]
                named += [prim["indices"]] if "indices" in prim else []
                if not all(isinstance(k, int) and 0 <= k < len(accessors) for k in named):
                    raise BadFile("damaged GLB: a mesh in its JSON names data the file does not hold")
        for v in views:
            if v.get("buffer", 0) == 0 and v.get("byteOffset", 0) + v["byteLength"] > blen:
                raise BadFile(f"damaged GLB: its JSON places data at bytes {v.get('byteOffset', 0)} to "
                              f"{v.get('byteOffset', 0) + v['byteLength']} of a binary part of {blen} bytes")
        for a in accessors:
            if "bufferView" not in a:
                continue
            v = views[a["bufferView"]]
            item = _COMPONENT[a["componentType"]] * _WIDTH[a["type"]]
            stride = v.get("byteStride", item)
            if a["count"] and a.get("byteOffset", 0) + (a["count"] - 1) * stride + item > v["byteLength"]:
                raise BadFile(f"damaged GLB: its JSON declares {a['count']} items in a block of "
                              f"{v['byteLength']} bytes, too small for them")
    except BadFile:
        raise
    except Exception:  # a key missing or of the wrong kind
        raise BadFile("damaged GLB: its JSON part does not describe a valid glTF scene") from None


def _prepare(fmt: str, data: bytes):
    """(data for trimesh, whether it differs from the file, PLY header or None) after the cheap checks."""
    header = None
    if fmt == "ply":
        try:
            header = _io_ply.parse_header(data)
            _io_ply.check_size(header, data)
        except _io_ply.PlyError as exc:
            raise BadFile(str(exc)) from None
        if header.format == "ascii":
            text, changed = _io_text.decode(data)
        else:
            head, changed = _io_text.decode(data[:header.body])
            text = head + data[header.body:] if changed else data
        return text, changed, header
    if fmt == "stl":
        text = _check_stl(data)
        return text, text is not data, None
    if fmt == "glb":
        _check_glb(data)
        return data, False, None
    if fmt in _TEXT:
        text, changed = _io_text.decode(data)
        if fmt == "obj":
            text, plain = _io_text.plain_obj(text)
            changed = changed or plain
        if fmt == "off":
            reason = _io_text.off_header_problem(text[:4096].decode("utf-8", "replace"))
            if reason:
                raise BadFile(reason)
        return text, changed, None
    return data, False, None


def _problem(fmt: str, data: bytes, header) -> str | None:
    """A defect named by walking the file (after trimesh failed or read nothing), or None."""
    text = data.decode("utf-8", "replace")
    if fmt == "obj":
        return _io_text.obj_problem(text)
    if fmt == "off":
        return _io_text.off_problem(text)
    if fmt == "stl" and data.lstrip()[:5].lower() == b"solid":
        return _io_text.stl_problem(text)
    if fmt == "ply":
        return _io_ply.problem(header, data)
    return None


def _resolver(path: str):
    """trimesh's resolver for files beside ``path`` (an OBJ's MTL), decoding MTL text as `_io_text.decode`."""
    from trimesh.resolvers import FilePathResolver

    class _Decoding(FilePathResolver):
        def get(self, name):
            data = super().get(name)
            return _io_text.decode(data)[0] if str(name).lower().endswith(".mtl") else data

    return _Decoding(path)


def _trimesh(path: str, fmt: str, data: bytes, changed: bool):
    """What trimesh reads from the file (``data`` when it differs from the file): a Trimesh, a PointCloud
    or a Scene; a Scene holding one geometry placed as it is comes as that geometry."""
    import trimesh

    def load(**kw):
        if changed:
            return trimesh.load(io.BytesIO(data), file_type=fmt, resolver=_resolver(path), process=False,
                                **kw)
        return trimesh.load(path, process=False, resolver=_resolver(path) if fmt == "obj" else None, **kw)

    obj = load()
    if isinstance(obj, trimesh.Scene) and len(obj.geometry) == 1:
        # one geometry placed without a transform: itself (concatenating a scene drops stored normals)
        name = next(iter(obj.geometry))
        nodes = obj.graph.geometry_nodes.get(name, [])
        if len(nodes) == 1 and np.array_equal(obj.graph.get(nodes[0])[0], np.eye(4)):
            obj = obj.geometry[name]
    if isinstance(obj, trimesh.Scene) and obj.geometry and all(
            isinstance(g, trimesh.PointCloud) for g in obj.geometry.values()):
        obj = concatenated(obj)
    if not isinstance(obj, (trimesh.Trimesh, trimesh.PointCloud)) and not (
            isinstance(obj, trimesh.Scene) and not obj.geometry):
        obj = load(force="mesh")
    _io_texture.remember_read(obj)  # before anything loads its texture's pixels (PIL then drops the stream)
    return obj


def _checked(obj, fmt: str, data: bytes, header):
    """``obj`` when it is a triangle mesh whose faces name its vertices; else BadFile saying what the file
    holds instead."""
    import trimesh

    n = len(getattr(obj, "vertices", ()))
    faces = np.asarray(obj.faces) if isinstance(obj, trimesh.Trimesh) else np.zeros((0, 3), np.int64)
    if faces.size == 0 or faces.ndim != 2:
        declared = header is not None and any(e.name == "face" and e.rows for e in header.elements)
        if fmt in ("obj", "off", "stl") or declared:  # faces in the file, none read: find out why
            reason = _problem(fmt, data, header)
            if reason:
                raise BadFile(reason)
        if n == 0:
            raise BadFile(f"it holds no vertices and no faces (it is empty, or not an {_name(fmt)} file)")
        raise BadFile(f"it holds a point cloud ({n} points, no faces), not a triangle mesh")
    lo, hi = faces.min(), faces.max()
    if lo < 0 or hi >= n:
        bad = lo if lo < 0 else hi
        raise BadFile(f"a face refers to vertex {bad}, but the file holds {n} vertices (numbered 0 to "
                      f"{n - 1}): the file is damaged")
    return obj


def _fallback(path: str, h, text: bytes, V, F, vertices):
    """A `trimesh.Trimesh` of a PLY that trimesh cannot read itself (`_io_strips`): its positions and faces,
    and the vertex attributes trimesh reads (normals, colours, UVs: `_io_ply.read_by_trimesh`) as trimesh reads
    them from the same mesh in a plain triangle PLY (`_io_ply.triangle_ply`); what it leaves out is named
    (``metadata["qemjax_unread"]``: `dropped_attributes`). No faces, or faces that name no vertex: left to
    `_checked` to name."""
    import trimesh

    obj = trimesh.Trimesh(V, F, process=False)
    attributes = _io_ply.read_by_trimesh(h.element("vertex"), None) - {"x", "y", "z"}
    if attributes and len(F) and F.min() >= 0 and F.max() < len(V):
        obj = _trimesh(path, "ply", _io_ply.triangle_ply(h, text, V, F, vertices), True)
    obj.metadata["qemjax_unread"] = _io_ply.unread(h, fallback=True, textured=_textured(obj))
    return obj


def _textured(obj) -> bool:
    """Whether trimesh read UVs into the mesh (its one visual: colours beside them are let go)."""
    return getattr(getattr(obj, "visual", None), "kind", None) == "texture"


def _read(path: str, fmt: str, data: bytes):
    """`read` of the file's bytes ``data``; BadFile with a reason."""
    if not data:
        raise BadFile("the file is empty")
    text, changed, header = _prepare(fmt, data)
    if header is not None and header.element("tristrips") and not header.element("face"):
        try:
            V, F, vertices = _io_strips.read_tristrips(header, data)
        except _io_ply.PlyError as exc:
            raise BadFile(str(exc)) from None
        return _checked(_fallback(path, header, text, V, F, vertices), fmt, data, header)
    try:
        obj = _trimesh(path, fmt, text, changed)
    except ImportError as exc:  # an optional package trimesh needs for this format
        if exc.name is None:
            raise BadFile(f"not a valid {_name(fmt)} file: the file is damaged or truncated") from exc
        raise BadFile(f"reading {_name(fmt)} files needs the Python package {exc.name!r}, which is not "
                      "installed") from exc
    except Exception as exc:  # trimesh raises many kinds, whose words are about its code: find our own
        reason = _problem(fmt, data, header)
        if reason is None and header is not None and header.format != "ascii" and header.element("face"):
            try:  # polygons of several sizes in one binary list, which trimesh cannot read
                V, F, vertices = _io_strips.read_polygons(header, data)
                return _checked(_fallback(path, header, text, V, F, vertices), fmt, data, header)
            except (_io_ply.PlyError, ValueError, IndexError):
                pass
        raise BadFile(reason or f"not a valid {_name(fmt)} file: the file is damaged or truncated") from exc
    return _checked(obj, fmt, data, header)


def read(path) -> object:
    """The `trimesh.Trimesh` in the mesh file at ``path`` (a file of several meshes concatenated), read
    without processing (vertices as stored). ValueError ``could not read <path>: <reason>`` otherwise."""
    import trimesh

    path = os.fspath(path)
    fmt = os.path.splitext(path)[1].lower().lstrip(".")
    try:
        if not fmt:
            raise BadFile("its name has no extension to tell its format (.obj, .ply, .stl, .off, .glb, ...)")
        if fmt not in trimesh.available_formats():
            raise BadFile(f"'.{fmt}' is not a mesh format qemjax reads (OBJ, PLY, STL, OFF, GLB and the "
                          "other formats trimesh reads)")
        with open(path, "rb") as f:
            data = f.read()
        obj = _read(path, fmt, data)
        if fmt == "off" and re.match(rb"\s*[A-Z]*C[A-Z]*OFF", data) and getattr(obj, "visual", None) is not None \
                and obj.visual.kind is None:  # trimesh reads no COFF colour: named among what is dropped
            obj.metadata["qemjax_unread"] = ["vertex colours (COFF)"]
        if fmt == "obj" and _textured(obj) and _io_text.obj_has_colours(data):  # trimesh lets them go for the UVs
            obj.metadata.setdefault("qemjax_unread", []).append(_io_ply.beside_uv())
        if fmt == "ply" and "qemjax_unread" not in obj.metadata:  # what trimesh steps over without a word
            obj.metadata["qemjax_unread"] = _io_ply.unread(_io_ply.parse_header(data), fallback=False,
                                                           textured=_textured(obj))
        return obj
    except OSError as exc:
        raise ValueError(f"could not read {path}: {exc.strerror or 'the file cannot be opened'}") from exc
    except BadFile as exc:
        raise ValueError(f"could not read {path}: {exc}") from exc.__cause__
    except Exception as exc:  # a check of ours tripped on damage it did not foresee: still words
        raise ValueError(f"could not read {path}: not a valid {_name(fmt)} file: the file is damaged or "
                         "truncated") from exc
