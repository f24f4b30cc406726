"""Reading mesh files: damaged files give one line in words about the file, point clouds are named,
text in Latin-1 is read, PLY triangle strips are read. Every file is generated here, in tmp_path."""
from __future__ import annotations

import contextlib
import re
import signal
import struct
import warnings

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax._io import mesh as _io, strips as _io_strips
from qemjax._mesh import wedges as _wedges
from qemjax import shapes

INTERNALS = ("broadcast", "index", "out of bounds", "list index", "chunk", "could not be read to its end",
             "traceback", "codec", "charset", "module", "unpack", "inhomogeneous", "expecting value")


@contextlib.contextmanager
def time_limit(seconds: float):
    """TimeoutError when the block runs longer than ``seconds`` (SIGALRM; no limit where there is none)."""
    if not hasattr(signal, "setitimer"):
        yield
        return

    def stop(*_):
        raise TimeoutError(f"still reading after {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _sources(tmp_path) -> dict:
    """name -> bytes of one small mesh (icosphere(1): 42 vertices, 80 faces) in each format read."""
    V, F = shapes.icosphere(1)
    tm = trimesh.Trimesh(V, F, process=False)
    out = {}
    for name, kw in [("m.obj", {}), ("a.ply", {"encoding": "ascii"}), ("b.ply", {}), ("b.stl", {}),
                     ("a.stl", {"file_type": "stl_ascii"}), ("m.off", {}), ("m.glb", {})]:
        path = tmp_path / name
        tm.export(path, **kw)
        out[name] = path.read_bytes()
    return out


def _reason(path) -> str:
    """The reason `qemjax.load` gives for ``path``, checked to be one line ``could not read <path>: …``."""
    with pytest.raises(ValueError) as info:
        qemjax.load(path)
    msg = str(info.value)
    assert msg.startswith(f"could not read {path}: ") and "\n" not in msg, msg
    return msg[len(f"could not read {path}: "):]


def test_sources_load(tmp_path):
    for name, data in _sources(tmp_path).items():
        assert qemjax.load(tmp_path / name).faces.shape == (80, 3), name


def test_damaged_files_give_one_line_in_words(tmp_path):
    """40 files cut short, with bytes flipped, or replaced by text (fixed seed): reading each either
    gives a mesh (a cut OBJ can still be a smaller valid one) or one ValueError line in words about
    the file, without a library's internals, and never hangs."""
    rng = np.random.default_rng(7)
    sources = _sources(tmp_path)
    names = sorted(sources)
    failed = 0
    for i in range(40):
        name = names[i % len(names)]
        data = bytearray(sources[name])
        how = ("cut", "flip", "text")[i % 3]
        if how == "cut":
            data = data[: rng.integers(0, len(data))]
        elif how == "flip":
            for _ in range(rng.integers(1, 6)):
                data[rng.integers(len(data))] = rng.integers(256)
        else:
            data = b"this is a note about the model\nnot a mesh at all\n" * int(rng.integers(1, 4))
        path = tmp_path / f"{i:02d}_{how}_{name}"
        path.write_bytes(bytes(data))
        try:
            with time_limit(20):
                mesh = qemjax.load(path)
        except ValueError as exc:
            msg = str(exc)
            assert msg.startswith(f"could not read {path}: ") and "\n" not in msg, msg
            assert not [w for w in INTERNALS if w in msg.lower()], msg
            failed += 1
            continue
        assert how != "text", f"{path} read as a mesh"
        assert mesh.faces.ndim == 2 and mesh.faces.shape[1] == 3 and len(mesh.faces)
        assert mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices)
    assert failed >= 25  # most damage is found, not only the text


def _obj(lines: str) -> bytes:
    return ("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + lines).encode()


def _ascii_ply(faces: str, n_faces: int, extra: str = "") -> bytes:
    head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    if n_faces >= 0:
        head += f"element face {n_faces}\nproperty list uchar int vertex_indices\n"
    return (head + "end_header\n0 0 0\n1 0 0\n0 1 0\n" + faces + extra).encode()


def test_reasons_name_what_is_wrong(tmp_path):
    src = _sources(tmp_path)
    glb = src["m.glb"]
    cases = {
        "cut.obj": (src["m.obj"][: src["m.obj"].index(b"\nv ", 500) + 4],
                    r"the file ends in the middle of a vertex line \(line \d+: 'v -?0?'\)"),
        "face.obj": (_obj("f 1 2"), r"the file ends in the middle of a face line \(line 4: 'f 1 2'\)"),
        "far.obj": (_obj("f 1 2 7\n"),
                    "the face on line 4 refers to vertex 7, but the file holds only 3 vertices"),
        "text.ply": (b"hello\nworld\n", r"not a PLY file \(its first line is not 'ply'\)"),
        "fmt.ply": (b"ply\nformat nonsense 1.0\nend_header\n", "unknown PLY format 'nonsense'"),
        "cut.ply": (src["b.ply"][:400],
                    r"truncated binary PLY: the header declares 42 vertices and 80 faces, which take at least "
                    r"584 bytes, but the file holds \d+ bytes of data"),
        "cut_ascii.ply": (src["a.ply"][:700], r"the header declares 42 vertices and 80 faces \(122 lines of "
                          r"data\), but the file holds \d+: it is truncated or damaged"),
        "far.ply": (_ascii_ply("3 0 1 9\n", 1), r"a face refers to vertex 9, but the file holds 3 vertices"),
        "cut.stl": (src["b.stl"][:84 + 50 * 12 + 7], "truncated binary STL: header says 80 triangles, "
                    "file holds 12"),
        "text.stl": (b"just some words\n" * 10, "not an STL file"),
        "cut_ascii.stl": (src["a.stl"][: src["a.stl"].index(b"\n", 3000) + 1],
                          "truncated ASCII STL: it ends without an 'endsolid' line"),
        "cut.glb": (glb[:1000], f"truncated GLB: header says {len(glb)} bytes, file holds 1000"),
        "text.glb": (b"{}", r"not a GLB file \(it does not start with 'glTF'\)"),
        "text.off": (b"hello\n1 2 3\n", r"not an OFF file \(its first line is not 'OFF'\)"),
        "far.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n",
                    "the face on line 6 refers to vertex 9, but the file holds only 3 vertices"),
        "cut.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n",
                    "truncated OFF: the header declares 3 vertices and 1 faces"),
        "empty.obj": (b"", "the file is empty"),
        "words.obj": (b"hello\n", r"it holds no vertices and no faces \(it is empty, or not an OBJ file\)"),
        "mesh.qqq": (b"\x00\x01", "'.qqq' is not a mesh format qemjax reads"),
    }
    for name, (data, match) in cases.items():
        (tmp_path / name).write_bytes(data)
        reason = _reason(tmp_path / name)
        assert not [w for w in INTERNALS if w in reason.lower()], reason
        assert re.match(match, reason), (name, reason)
    with pytest.raises(ValueError, match=r"^could not read .*cut\.ply: truncated binary PLY"):
        qemjax.simplify(tmp_path / "cut.ply", ratio=0.5)  # simplify reads through the same path


def test_point_clouds_are_named(tmp_path):
    """A file of points without faces, and a trimesh PointCloud object, are called point clouds."""
    cases = {"p.ply": _ascii_ply("", -1), "p0.ply": _ascii_ply("", 0), "p.obj": _obj(""),
             "p.off": b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n"}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        assert _reason(tmp_path / name) == "it holds a point cloud (3 points, no faces), not a triangle mesh"
        with pytest.raises(ValueError, match="could not read .*point cloud"):
            qemjax.simplify(tmp_path / name, ratio=0.5)
    cloud = trimesh.PointCloud(np.random.default_rng(0).random((5, 3)))
    for call in (lambda: qemjax.simplify(cloud, ratio=0.5), lambda: _io.as_arrays(cloud),
                 lambda: qemjax.simplify(trimesh.Scene([cloud]), ratio=0.5)):
        with pytest.raises(ValueError, match=r"^expected a triangle mesh, got a point cloud \(5 points\)$"):
            call()


LATIN_OBJ = """# mod\u00e8le export\u00e9
mtllib m.mtl
o mod\u00e8le
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 2 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0 1
vn 0 0 1
g t\u00eate
usemtl mat\u00e9riau
f 1/1/1 2/2/1 3/3/1
f 1/1/1 3/3/1 4/4/1
f 4/4/1 3/3/1 5/5/1
"""


def test_latin1_obj_is_read_with_its_uvs_normals_and_material(tmp_path):
    """One non-UTF-8 byte used to stop the read (trimesh's fallback needs an optional package)."""
    path = tmp_path / "latin.obj"
    path.write_bytes(LATIN_OBJ.encode("latin-1"))
    (tmp_path / "m.mtl").write_bytes("newmtl mat\u00e9riau\nKd 0.2 0.4 0.6\n".encode("latin-1"))
    tm = _io._read_trimesh(path)
    assert tm.vertices.shape == (5, 3) and tm.faces.shape == (3, 3)
    values, material = _wedges.from_trimesh(tm)
    assert sorted(values) == ["normal", "uv"]
    assert np.allclose(values["normal"], [0, 0, 1])
    assert material is not None and np.array_equal(material.diffuse, [51, 102, 153, 255])
    with pytest.warns(UserWarning, match="carries uv, material"):
        assert qemjax.load(path).faces.shape == (3, 3)


def test_latin1_comments_in_other_text_formats(tmp_path):
    src = _sources(tmp_path)
    word = "mod\u00e8le".encode("latin-1")
    edits = {"a.ply": src["a.ply"].replace(b"1.0\n", b"1.0\ncomment " + word + b"\n", 1),
             "b.ply": src["b.ply"].replace(b"1.0\n", b"1.0\ncomment " + word + b"\n", 1),
             "m.off": src["m.off"].replace(b"OFF\n", b"OFF\n# " + word + b"\n", 1),
             "a.stl": b"solid " + word + src["a.stl"][src["a.stl"].index(b"\n"):]}
    for name, data in edits.items():
        assert data != src[name]
        (tmp_path / ("latin_" + name)).write_bytes(data)
        assert qemjax.load(tmp_path / ("latin_" + name)).faces.shape == (80, 3), name


# ---- triangle strips ----------------------------------------------------------------------------------

def _stripify(F: np.ndarray) -> list:
    """Greedy strips covering the oriented triangles F: triangle i of a strip s is (s[i], s[i+1], s[i+2]),
    first two swapped for odd i (the convention the reader follows)."""
    by_edge = {}
    for f, (a, b, c) in enumerate(F):
        for e in ((a, b), (b, c), (c, a)):
            by_edge[e] = (f, (set((a, b, c)) - set(e)).pop())
    used, strips = np.zeros(len(F), bool), []
    for f in range(len(F)):
        if used[f]:
            continue
        used[f] = True
        s = [int(v) for v in F[f]]
        while True:
            i = len(s) - 2  # the number of the triangle to add
            edge = (s[-2], s[-1]) if i % 2 == 0 else (s[-1], s[-2])
            nxt = by_edge.get(edge)
            if nxt is None or used[nxt[0]]:
                break
            used[nxt[0]] = True
            s.append(int(nxt[1]))
        strips.append(s)
    return strips


def _joined(strips: list) -> list:
    """One sequence: strips joined alternately by a -1 restart and by degenerate triangles (repeating the
    last vertex of one strip and the first of the next, once or twice to keep the next one's parity)."""
    out, start = list(strips[0]), 0  # start: where the current strip sequence began
    for k, s in enumerate(strips[1:]):
        if k % 2 == 0:
            out += [-1]
            start = len(out)
            out += s
        else:
            pad = 1 if (len(out) - start) % 2 == 0 else 2
            out += [out[-1]] + [s[0]] * pad + s
    return out


def _strip_ply(V: np.ndarray, rows: list, fmt: str, count: str, item: str) -> bytes:
    """A PLY with vertices (x, y, z and two extra properties to step over) and an element tristrips."""
    head = (f"ply\nformat {fmt} 1.0\ncomment strips\nelement vertex {len(V)}\nproperty float x\n"
            f"property float y\nproperty float z\nproperty uchar flag\nproperty double confidence\n"
            f"element tristrips {len(rows)}\nproperty list {count} {item} vertex_indices\nend_header\n")
    if fmt == "ascii":
        body = "".join(f"{x} {y} {z} 7 0.5\n" for x, y, z in V)
        body += "".join(f"{len(r)} " + " ".join(str(v) for v in r) + "\n" for r in rows)
        return (head + body).encode()
    o = "<" if fmt == "binary_little_endian" else ">"
    code = {"uchar": "B", "int": "i", "uint": "I"}
    vdt = np.dtype([("x", o + "f4"), ("y", o + "f4"), ("z", o + "f4"), ("flag", "u1"), ("c", o + "f8")])
    verts = np.zeros(len(V), vdt)
    verts["x"], verts["y"], verts["z"], verts["flag"], verts["c"] = V[:, 0], V[:, 1], V[:, 2], 7, 0.5
    body = verts.tobytes()
    for r in rows:
        r = [v % 2 ** 32 if item == "uint" else v for v in r]
        body += struct.pack(o + code[count], len(r)) + struct.pack(o + code[item] * len(r), *r)
    return head.encode() + body


def _oriented(F) -> set:
    """Triangles as a set, each rotated to start at its smallest vertex (orientation kept)."""
    out = set()
    for t in np.asarray(F).tolist():
        k = t.index(min(t))
        out.add(tuple(t[k:] + t[:k]))
    return out


def test_strip_triangles_by_hand():
    got = _io_strips.strip_triangles(np.array([0, 1, 2, 3, 4, -1, 5, 6, 7, 7, 8, 8, 9, 10]))
    # 5 6 7 7 8 8 9 10: the joins (7 7, 8 8) are dropped; (8, 9, 10) is the strip's sixth triangle: swapped
    assert got.tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4], [5, 6, 7], [9, 8, 10]]


@pytest.mark.parametrize("fmt,count,item", [("ascii", "int", "int"), ("binary_little_endian", "int", "int"),
                                            ("binary_little_endian", "uchar", "uint"),
                                            ("binary_big_endian", "int", "uint"), ("ascii", "uchar", "int")])
def test_tristrip_ply_is_read(tmp_path, fmt, count, item):
    V, F = shapes.grid(4)
    strips = _stripify(F)
    assert len(strips) > 2 and max(len(s) for s in strips) > 4  # odd triangles and joins both happen
    seq = _joined(strips)
    rows = [seq] if count == "int" else [s for s in strips]  # uchar counts: one strip per row
    path = tmp_path / "strips.ply"
    path.write_bytes(_strip_ply(V, rows, fmt, count, item))
    m = qemjax.load(path)
    assert np.allclose(m.vertices, V.astype(np.float32))
    assert len(m.faces) == len(F) and _oriented(m.faces) == _oriented(F)
    r = qemjax.simplify(path, ratio=0.5)
    assert 0 < len(r.faces) < len(F)


def test_bad_tristrips_are_named(tmp_path):
    V, F = shapes.grid(2)
    path = tmp_path / "bad.ply"
    path.write_bytes(_strip_ply(V, [[0, 1, 99]], "ascii", "int", "int"))
    assert _reason(path).startswith("the PLY tristrips refer to vertex 99, but the file holds 9 vertices")
    path.write_bytes(_strip_ply(V, [[0, 1, 2, 3]], "binary_little_endian", "int", "int")[:-6])
    assert _reason(path).startswith("truncated binary PLY")


def test_relative_indices_and_tabs_in_an_obj_are_read_as_the_format_means_them(tmp_path):
    """An OBJ face's negative index counts back from the vertices before its line (trimesh counts from the
    file's end: here both faces became the second triangle, one then dropped as a duplicate); words split by
    tabs are words (trimesh read no vertex and no face). Read as the same file written plainly is."""
    rel = tmp_path / "rel.obj"
    rel.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf -3/-3 -2/-2 -1/-1\n"
                   "v 5 0 0\nv 6 0 0\nv 5 1 0\nf -3 -2 -1\nf 1 -2 6\n")
    plain = tmp_path / "plain.obj"
    plain.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
                     "v 5 0 0\nv 6 0 0\nv 5 1 0\nf 4 5 6\nf 1 5 6\n")
    tab = tmp_path / "tab.obj"
    tab.write_text(plain.read_text().replace(" ", "\t"))
    want = qemjax.load(str(plain))
    for path in (rel, tab):
        got = qemjax.load(str(path))
        assert np.array_equal(got.vertices, want.vertices) and np.array_equal(got.faces, want.faces)
    assert len(want.faces) == 3
    r = qemjax.simplify(str(rel), ratio=1.0)
    assert len(r.faces) == 3 and r.stats["duplicate_removed"] == 0


def test_a_binary_ply_of_triangles_and_quads_is_read(tmp_path):
    """Faces of several sizes in one binary list: trimesh cannot read them (it called the file damaged); the
    same faces as the ASCII file, which it reads, fanned from each polygon's first corner."""
    import struct

    n = 6
    V = np.array([[x, y, 0.1 * x * y] for y in range(n) for x in range(n)], np.float64)
    polys = []
    for y in range(n - 1):
        for x in range(n - 1):
            a, b, c, d = y * n + x, y * n + x + 1, (y + 1) * n + x + 1, (y + 1) * n + x
            polys += [[a, b, c, d]] if (x + y) % 2 else [[a, b, c], [a, c, d]]
    head = (f"ply\nformat {{}} 1.0\nelement vertex {len(V)}\nproperty double x\nproperty double y\n"
            f"property double z\nelement face {len(polys)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = V.astype("<f8").tobytes() + b"".join(struct.pack(f"<B{len(p)}i", len(p), *p) for p in polys)
    (tmp_path / "b.ply").write_bytes(head.format("binary_little_endian").encode() + body)
    (tmp_path / "a.ply").write_text(head.format("ascii") + "".join(" ".join(map(repr, v)) + "\n" for v in V.tolist())
                                    + "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys))
    got, want = qemjax.load(str(tmp_path / "b.ply")), qemjax.load(str(tmp_path / "a.ply"))

    def triangles(F):  # each rotated to start at its smallest corner (orientation kept), in sorted order
        F = np.asarray(F)
        r = F.argmin(1)
        F = np.stack([F[np.arange(len(F)), (r + k) % 3] for k in range(3)], 1)
        return F[np.lexsort(F.T[::-1])]
    assert np.array_equal(got.vertices, want.vertices)
    assert np.array_equal(triangles(got.faces), triangles(want.faces)) and len(got.faces) == 2 * (n - 1) ** 2


def test_coff_colours_that_are_not_read_are_named(tmp_path):
    """trimesh reads an OFF file's positions but not a COFF file's colours: the run says it dropped them."""
    path = tmp_path / "c.off"
    path.write_text("COFF\n4 4 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n0 0 1 255 255 0 255\n"
                    "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
    with pytest.warns(UserWarning, match=r"carries vertex colours \(COFF\), which qemjax does not keep"):
        r = qemjax.simplify(str(path), ratio=1.0)
    assert r.stats["dropped"] == ["vertex colours (COFF)"]
    path.write_text(path.read_text().replace("COFF", "OFF").replace(" 255 0 0 255", "").replace(" 0 255 0 255", "")
                    .replace(" 0 0 255 255", "").replace(" 255 255 0 255", ""))
    assert qemjax.simplify(str(path), ratio=1.0).stats["dropped"] == []


def test_ply_colours_beside_uvs_are_named(tmp_path):
    """trimesh reads a PLY with UVs (s, t) and colours (red, green, blue) as UVs alone: the colours were
    dropped without a word (stats["dropped"] empty). They are named among what is dropped, with the
    warning; the same file without the UVs keeps its colours as before."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])

    def write(path, uv):
        props = ["x", "y", "z"] + (["s", "t"] if uv else []) + ["red", "green", "blue"]
        rows = [" ".join(f"{x:g}" for x in v) + (f" {v[0]:g} {v[1]:g}" if uv else "") + f" {40 * i} 9 200"
                for i, v in enumerate(V)]
        head = (["ply", "format ascii 1.0", f"element vertex {len(V)}"]
                + [f"property {'uchar' if p in ('red', 'green', 'blue') else 'float'} {p}" for p in props]
                + [f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"])
        path.write_text("\n".join(head + rows + [f"3 {a} {b} {c}" for a, b, c in F]) + "\n")

    path = tmp_path / "uvc.ply"
    write(path, uv=True)
    with pytest.warns(UserWarning, match=r"carries vertex colours \(beside the UVs, which are read instead\)"):
        res = qemjax.simplify(str(path), ratio=1.0)
    assert res.uv is not None and res.colors is None
    assert res.stats["dropped"] == ["vertex colours (beside the UVs, which are read instead)"]
    write(path, uv=False)
    res = qemjax.simplify(str(path), ratio=1.0)
    assert res.colors is not None and res.stats["dropped"] == []


def test_obj_colours_beside_uvs_are_named(tmp_path):
    """trimesh reads an OBJ whose v lines carry colours (x y z r g b) and whose faces name vt lines as UVs
    alone: the colours went without a word. They are named among what is dropped, with the warning; the
    same file without the vt lines keeps its colours."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]) + 1
    coloured = [f"v {x:g} {y:g} {z:g} {i / 4:g} 0.5 0.2" for i, (x, y, z) in enumerate(V)]
    path = tmp_path / "uvc.obj"
    path.write_text("\n".join(coloured + [f"vt {x:g} {y:g}" for x, y, _ in V]
                              + ["f " + " ".join(f"{a}/{a}" for a in f) for f in F]) + "\n")
    with pytest.warns(UserWarning, match=r"carries vertex colours \(beside the UVs, which are read instead\)"):
        res = qemjax.simplify(str(path), ratio=1.0)
    assert res.uv is not None and res.colors is None
    assert res.stats["dropped"] == ["vertex colours (beside the UVs, which are read instead)"]
    path.write_text("\n".join(coloured + ["f " + " ".join(map(str, f)) for f in F]) + "\n")
    res = qemjax.simplify(str(path), ratio=1.0)
    assert res.colors is not None and res.stats["dropped"] == []


def test_gltf_colours_beside_uvs_are_named(tmp_path):
    """A GLB with COLOR_0 beside TEXCOORD_0: trimesh keeps the colours aside (visual.vertex_attributes) and
    joining the scene's parts lets them go, so they went without a word. They are named among what is
    dropped, for the file, its scene and its mesh alike."""
    m = shapes.bumpy_sphere(1)
    V = np.asarray(m.vertices)
    mesh = trimesh.Trimesh(V, m.faces, process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=V[:, :2] * 0.5 + 0.5)
    mesh.visual.vertex_attributes["color"] = (np.c_[V * 0.5 + 0.5, np.ones(len(V))] * 255).astype(np.uint8)
    path = tmp_path / "uvc.glb"
    mesh.export(path)
    scene = trimesh.load(path, process=False)
    for given in (str(path), scene, next(iter(scene.geometry.values()))):
        with pytest.warns(UserWarning, match=r"carries vertex colours \(beside the UVs, which are read instead\)"):
            res = qemjax.simplify(given, ratio=1.0)
        assert res.uv is not None
        assert res.stats["dropped"] == ["vertex colours (beside the UVs, which are read instead)"]


@pytest.mark.parametrize("kind", ["little", "big", "ascii"])
def test_a_vertex_list_property_is_named_in_core(tmp_path, kind):
    """An in-core run of a PLY whose vertex element has a list property dropped it without a word
    (stats["dropped"] empty) while a partitioned run names it: it is named as there, with the warning of
    what a run does not keep. trimesh reads an ASCII file's other properties (its UVs are kept); a binary
    file with lists of several lengths, which trimesh refuses, is read without the lists as trimesh reads
    the plain file (its UVs are kept too): the same result as without the list."""
    from test_partition_scatter import _ply_with_vertex_list

    m = qemjax.shapes.bumpy_sphere(2)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    uv = (V[:, :2] * 0.5 + 0.5).astype(np.float32)
    out = []
    for with_list in (False, True):
        path = tmp_path / f"{with_list}.ply"
        _ply_with_vertex_list(path, V, F, uv, kind, with_list)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            res = qemjax.simplify(str(path), ratio=0.5)
        said = [str(w.message) for w in seen if "memoryless" not in str(w.message)]
        assert res.stats["dropped"] == (["vertex properties ids"] if with_list else [])
        assert said == ([f"{path} carries vertex properties ids, which qemjax does not keep: the result has "
                         "positions, faces and uv (stats['dropped'] lists them)"] if with_list else []), said
        out.append((res.vertices.tobytes(), res.faces.tobytes(), res.uv.tobytes()))
    assert out[0] == out[1]


def _ply_with_columns(path, V, F, columns: dict, fmt: str):
    """A PLY of ``fmt`` ("ascii" or "binary_little_endian") whose vertices hold x, y, z and then ``columns``
    ({name: (n,) values}, written as floats)."""
    cols = {"x": V[:, 0], "y": V[:, 1], "z": V[:, 2], **columns}
    head = ["ply", f"format {fmt} 1.0", f"element vertex {len(V)}", *(f"property float {c}" for c in cols),
            f"element face {len(F)}", "property list uchar int vertex_indices", "end_header", ""]
    rows = np.zeros(len(V), [(c, "<f4") for c in cols])
    for c, values in cols.items():
        rows[c] = values
    with open(path, "wb") as f:
        f.write("\n".join(head).encode())
        if fmt == "ascii":
            f.write("".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows.tolist()).encode())
            f.write("".join(f"3 {a} {b} {c}\n" for a, b, c in F.tolist()).encode())
            return
        tris = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,))])
        tris["n"], tris["i"] = 3, F
        f.write(rows.tobytes() + tris.tobytes())


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_unread_vertex_properties_are_named_in_core_as_a_partitioned_run_names_them(tmp_path, fmt):
    """trimesh steps over a PLY's vertex properties it has no use for (a scanner's quality, confidence) and
    an in-core run said nothing of them, where a partitioned run names them: one warning names them, in the
    partitioned run's words, and not what the in-core reader does read (normals, colours, UVs under the
    names it reads them by). Colours beside UVs are not read (a textured mesh has no vertex colours): named.
    A file of positions alone gives no warning."""
    V, F = shapes.icosphere(2)
    V = V.astype(np.float32).astype(np.float64)
    n = len(V)
    normals = {"nx": V[:, 0], "ny": V[:, 1], "nz": V[:, 2]}
    colours = {"red": np.full(n, 200.0), "green": np.full(n, 100.0), "blue": np.full(n, 50.0)}
    scanner = {"quality": np.arange(n, dtype=np.float64), "confidence": np.ones(n)}

    def run(columns, **kw):
        path = tmp_path / f"{len(columns)}.ply"
        _ply_with_columns(path, V, F, columns, fmt)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            res = qemjax.simplify(str(path), ratio=0.5, **kw)
            qemjax.load(path)
        said = [str(w.message) for w in seen if "memoryless" not in str(w.message)]
        return res, said, str(path)

    res, said, path = run({**normals, **colours, **scanner})
    assert res.stats["dropped"] == ["vertex properties quality, confidence"]
    assert res.normals is not None and res.colors is not None
    assert said == [f"{path} carries vertex properties quality, confidence, which qemjax does not keep: the "
                    "result has positions, faces and color, normal (stats['dropped'] lists them)",
                    f"{path} carries vertex_colors, vertex properties quality, confidence, which qemjax does not "
                    "keep: the result has positions and faces only (stats['dropped'] lists them)"], said  # load
    res, said, path = run({"s": V[:, 0], "t": V[:, 1], **colours, "quality": V[:, 2]})
    assert res.uv is not None and res.stats["dropped"] == [  # the colours named once, as let go for the UVs
        "vertex properties quality", "vertex colours (beside the UVs, which are read instead)"]
    res, said, path = run({"u": V[:, 0], "v": V[:, 1], "texture_s": V[:, 0], "texture_t": V[:, 1]})
    assert res.uv is not None and res.stats["dropped"] == ["vertex properties texture_s, texture_t"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        path = tmp_path / "plain.ply"
        _ply_with_columns(path, V, F, {}, fmt)
        assert qemjax.simplify(str(path), ratio=0.5).stats["dropped"] == []
        qemjax.load(path)
    res, said, path = run(scanner)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        parted = qemjax.simplify(path, ratio=0.5, partition=qemjax.Partition(part_faces=1000, workers=1))
    item = "vertex properties quality, confidence"
    assert res.stats["dropped"] == [item] and parted.stats["dropped"] == ["record", item]
    assert [s.endswith(f"input: {item}") for s in (str(w.message) for w in seen)].count(True) == 1


def test_unread_face_properties_and_elements_are_named_in_core_as_a_partitioned_run_names_them(tmp_path):
    """trimesh reads a face's vertex numbers, colours and UV lists and steps over its other properties (a
    scanner's per-face quality, flags) and every element besides vertices and faces (edges): an in-core run
    dropped them without a word, where a partitioned run names them. Both name them now, in the same words."""
    V, F = shapes.icosphere(2)
    head = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property double x", "property double y",
            "property double z", f"element face {len(F)}", "property list uchar int vertex_indices",
            "property float quality", "property uchar flags", "element edge 1", "property int vertex1",
            "property int vertex2", "end_header"]
    path = tmp_path / "faces.ply"
    path.write_text("\n".join(head + [" ".join(map(repr, v)) for v in V.tolist()]
                              + [f"3 {a} {b} {c} {i * 0.5} 1" for i, (a, b, c) in enumerate(F.tolist())] + ["0 1", ""]))
    items = ["face properties quality, flags", "the 'edge' element"]
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        res = qemjax.simplify(str(path), ratio=0.5)
    assert res.stats["dropped"] == items
    assert [str(w.message) for w in seen if "carries" in str(w.message)] == [
        f"{path} carries {', '.join(items)}, which qemjax does not keep: the result has positions and faces only "
        "(stats['dropped'] lists them)"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parted = qemjax.simplify(str(path), ratio=0.5, partition=qemjax.Partition(part_faces=1000, workers=1))
    assert parted.stats["dropped"] == ["record", *items]


def test_the_names_of_a_face_list_of_vertex_numbers_have_one_home():
    """The names a face's list of vertex numbers goes by (vertex_indices, vertex_index) were written in the
    in-core reader (twice: `unread`, `read_polygons`) and the partitioned one: they live in `_io.ply`
    (`INDEX_NAMES`, `index_list`), which the others use, and no other module names them both."""
    from pathlib import Path

    from qemjax._io import ply
    from qemjax._partition import ply as parted

    def face(*props):
        return ply.Element("face", 1, [ply.Property(*p) for p in props])

    for name in ply.INDEX_NAMES:
        f = face(("flags", "uchar"), ("texcoord", "float", "uchar"), (name, "int", "uchar"))
        assert ply.index_list(f).name == name and parted._index_prop(f) == 2
    assert ply.index_list(face(("flags", "uchar"), ("corners", "int", "uchar"))).name == "corners"  # the one list
    assert ply.index_list(face(("flags", "uchar"))) is None
    package = Path(qemjax.__file__).parent
    both = [str(p.relative_to(package)) for p in package.rglob("*.py")
            if "vertex_index\"" in p.read_text() and "\"vertex_indices\"" in p.read_text()]
    assert both == ["_io/ply.py"], both


def _attribute_ply(V, columns: dict, faces: list, element: str = "face", fmt: str = "binary_little_endian") -> bytes:
    """A PLY whose vertices hold x, y, z (float) and ``columns`` ({name: (n,) values}: uchar for colours,
    float otherwise), with ``faces`` (rows of vertex numbers, any lengths) as element ``element``."""
    types = {c: "u1" if c in ("red", "green", "blue", "alpha") else "<f4" for c in columns}
    rows = np.zeros(len(V), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), *types.items()])
    rows["x"], rows["y"], rows["z"] = V.T
    for c, values in columns.items():
        rows[c] = values
    head = ["ply", f"format {fmt} 1.0", f"element vertex {len(V)}",
            *(f"property {'uchar' if types.get(c) == 'u1' else 'float'} {c}" for c in rows.dtype.names),
            f"element {element} {len(faces)}", "property list int int vertex_indices", "end_header", ""]
    if fmt == "ascii":
        body = "".join(" ".join(repr(v) for v in row) + "\n" for row in rows.tolist())
        body += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in faces)
        return "\n".join(head).encode() + body.encode()
    return "\n".join(head).encode() + rows.tobytes() + b"".join(struct.pack(f"<i{len(f)}i", len(f), *f) for f in faces)


def test_a_ply_trimesh_cannot_read_keeps_its_vertex_attributes(tmp_path):
    """A binary PLY whose face list mixes triangles and quads, or whose faces are triangle strips, was read
    for positions and faces alone (its normals, colours and UVs named as dropped): it is read as trimesh
    reads the same mesh written as a plain triangle PLY (the polygons fanned, the strips cut, in the same
    order), with the same attributes and the same simplified result; a property it does not read (quality) is
    still named."""
    m = shapes.bumpy_sphere(2)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces).tolist()
    n = len(V)
    normals = {f"n{c}": V[:, k] / np.linalg.norm(V, axis=1) for k, c in enumerate("xyz")}
    colours = {"red": np.full(n, 200), "green": np.arange(n) % 256, "blue": np.full(n, 50)}
    uv = {"texture_u": V[:, 0] * 0.5 + 0.5, "texture_v": V[:, 1] * 0.5 + 0.5}
    quality = {"quality": np.arange(n, dtype=np.float64)}
    a, b, c = F[0]  # faces 0 and the one across its edge (c, a) as one quad, fanned back into both
    k = next(k for k, t in enumerate(F) if k and any((t[r], t[(r + 1) % 3]) == (a, c) for r in range(3)))
    d = next(x for x in F[k] if x not in (a, c))
    polygons = [[a, b, c, d], *F[1:k], *F[k + 1:]]
    fanned = [[a, b, c], [a, c, d], *F[1:k], *F[k + 1:]]
    grid_V, grid_F = shapes.grid(5)
    strips = _stripify(grid_F)
    seq = _joined(strips)
    cut = _io_strips.strip_triangles(np.array(seq)).tolist()
    gn = len(grid_V)
    grid = {"nx": np.zeros(gn), "ny": np.zeros(gn), "nz": np.ones(gn), "red": np.arange(gn) * 9 % 256,
            "green": np.full(gn, 7), "blue": np.full(gn, 9), "confidence": np.ones(gn)}
    cases = [(V, {**normals, **colours, **quality}, polygons, fanned, "face", "binary_little_endian"),
             (V, {**uv, **colours, **quality}, polygons, fanned, "face", "binary_little_endian"),
             (grid_V, grid, [seq], cut, "tristrips", "binary_little_endian"),
             (grid_V, grid, [seq], cut, "tristrips", "ascii")]
    for i, (P, columns, faces, triangles, element, fmt) in enumerate(cases):
        odd, plain = tmp_path / f"odd{i}.ply", tmp_path / f"plain{i}.ply"
        odd.write_bytes(_attribute_ply(P, columns, faces, element, fmt))
        plain.write_bytes(_attribute_ply(P, columns, triangles, "face", fmt))
        runs = []
        for path in (odd, plain):
            with warnings.catch_warnings(record=True) as seen:
                warnings.simplefilter("always")
                got = qemjax.load(path)
                res = qemjax.simplify(str(path), ratio=0.5)
            said = sorted(str(w.message).replace(str(path), "PATH") for w in seen)
            runs.append((got, res, said))
        (got, res, said), (want, wanted, told) = runs
        assert np.array_equal(got.vertices, want.vertices) and np.array_equal(got.faces, want.faces)
        assert said == told and any("vertex properties" in s for s in said), (said, told)
        assert res.stats["dropped"] == wanted.stats["dropped"]
        assert res.stats["dropped"][-1] in ("vertex properties quality", "vertex properties confidence",
                                            "vertex colours (beside the UVs, which are read instead)")
        for name in ("vertices", "faces", "uv", "colors", "normals"):
            x, y = getattr(res, name), getattr(wanted, name)
            assert (x is None) == (y is None) and (x is None or np.array_equal(x, y)), (i, name)
        kept = [k for k in ("uv", "colors", "normals") if getattr(res, k) is not None]
        assert kept == (["uv"] if i == 1 else ["colors", "normals"]), (i, kept)
