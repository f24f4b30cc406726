"""`qemjax._partition.scatter`: a mesh file binned into parts on disk. Every file is written here: each
format's parts give back the input's faces and positions exactly (after welding for STL and OBJ), parts
are small and compact, borders are exactly the shared vertices, and the bytes do not depend on the
chunk size."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from qemjax import shapes
from qemjax._partition.scatter import scatter
from qemjax._partition.write import write_binary_ply


def _mesh():
    """A bumpy sphere (20,480 faces) in float32 positions, as most scanned files hold them."""
    V, F = shapes.bumpy_sphere(5)
    return V.astype(np.float32).astype(np.float64), F


def _torus_quads():
    """A torus as quads (its triangles are the quads' fans) and its triangulation."""
    V, F = shapes.torus(n_major=60, n_minor=30)
    T = F.reshape(2, -1, 3)
    Q = np.concatenate([T[0], T[1][:, 2:]], 1)  # (i0,i1,i2) + (i0,i2,i3) -> (i0,i1,i2,i3)
    return V, Q, _fans(Q)


def _fans(Q):
    """The triangles of polygons (k,n) fanned from their first corner, in order."""
    return np.stack([Q[:, [0, j, j + 1]] for j in range(1, Q.shape[1] - 1)], 1).reshape(-1, 3)


def _reference(P, F):
    """Positions welded by exact value, ids by first appearance, unused dropped: (V, F)."""
    _, first, inv = np.unique(P.view(np.uint64).reshape(-1, 3), axis=0, return_index=True, return_inverse=True)
    ids = np.empty(len(first), np.int64)
    ids[np.argsort(first, kind="stable")] = np.arange(len(first))
    return _compact(P[np.sort(first)], ids[inv.reshape(-1)][F])


def _compact(V, F):
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    return V[used], (np.cumsum(used) - 1)[F]


def _parts(scratch, manifest):
    """The parts' arrays, checked one by one, and the whole mesh they make: (parts, V, F)."""
    parts = [dict(np.load(scratch / p["file"])) for p in manifest["parts"]]
    V = np.full((manifest["n_vertices"], 3), np.nan)
    for p, entry in zip(parts, manifest["parts"]):
        gid, Vp, Fp = p["gid"], p["V"], p["F"]
        assert gid.dtype == np.int64 and Vp.dtype == np.float64 and Fp.dtype == np.int32
        assert p["border"].dtype == bool and len(p["border"]) == len(gid) == len(Vp)
        assert np.all(np.diff(gid) > 0) and len(np.unique(Fp)) == len(gid)
        assert (entry["faces"], entry["vertices"], entry["border"]) == (len(Fp), len(gid), p["border"].sum())
        seen = ~np.isnan(V[gid, 0])
        assert np.array_equal(V[gid][seen].view(np.uint64), Vp[seen].view(np.uint64))
        V[gid] = Vp
    F = np.concatenate([p["gid"][p["F"]] for p in parts])
    assert not np.isnan(V).any()
    return parts, V, F


def _rows(F):
    return F[np.lexsort(F.T[::-1])]


def _check(path, part_faces, P, F, welded, **kw):
    scratch = path.parent / (path.name + ".parts")
    manifest = scatter(path, scratch, part_faces, **kw)
    assert manifest == json.loads((scratch / "manifest.json").read_text())
    Vr, Fr = _reference(P, F) if welded else _compact(P, F)
    parts, V, Fg = _parts(scratch, manifest)
    assert manifest["welded"] == welded and manifest["n_faces"] == len(Fr) == len(Fg)
    assert manifest["n_vertices"] == len(Vr)
    assert np.array_equal(V.view(np.uint64), Vr.view(np.uint64))
    assert np.array_equal(_rows(Fg), _rows(Fr))
    assert np.allclose(manifest["bbox"], [Vr.min(0), Vr.max(0)])
    assert all(len(p["F"]) <= part_faces for p in parts)
    where = {tuple(f): k for k, f in enumerate(Fr.tolist())}
    if len(where) == len(Fr):  # faces all different: each part holds them in input order
        for p in parts:
            assert np.all(np.diff([where[tuple(f)] for f in p["gid"][p["F"]].tolist()]) > 0)
    count = np.bincount(np.concatenate([p["gid"] for p in parts]), minlength=len(V))
    for p in parts:
        assert np.array_equal(p["border"], count[p["gid"]] >= 2)
    return manifest, parts, scratch


def _write_ply_records(path, header: str, vertex_rows: np.ndarray, face_bytes: bytes):
    path.write_bytes(header.encode() + vertex_rows.tobytes() + face_bytes)


@pytest.mark.parametrize("order", ["<", ">"])
def test_binary_ply_with_other_properties(tmp_path, order):
    """Properties around x, y, z and around the index list are stepped over, in either byte order;
    unused vertices are dropped, the others keep their order."""
    V, F = _mesh()
    V = np.concatenate([V, [[9.0, 9.0, 9.0]]])  # an unused vertex, far away
    F = F[:, ::-1].copy()
    vd = np.dtype([("red", "u1"), ("z", order + "f8"), ("nx", order + "f4"), ("x", order + "f4"),
                   ("y", order + "f8")])
    v = np.zeros(len(V), vd)
    v["x"], v["y"], v["z"], v["red"] = V[:, 0], V[:, 1], V[:, 2], 7
    fd = np.dtype([("flags", "u1"), ("n", order + "i4"), ("i", order + "u4", (3,)), ("q", order + "f4")])
    f = np.zeros(len(F), fd)
    f["n"], f["i"], f["q"] = 3, F, 0.5
    kind = "little" if order == "<" else "big"
    header = (f"ply\nformat binary_{kind}_endian 1.0\ncomment made in a test\nelement vertex {len(V)}\n"
              "property uchar red\nproperty double z\nproperty float nx\nproperty float x\nproperty double y\n"
              f"element face {len(F)}\nproperty uchar flags\nproperty list int uint vertex_indices\n"
              "property float quality\nend_header\n")
    path = tmp_path / "m.ply"
    _write_ply_records(path, header, v, f.tobytes())
    P = np.stack([v["x"].astype(np.float64), v["y"], v["z"]], 1)
    manifest, parts, scratch = _check(path, 3000, P, F, welded=False, chunk_faces=5000)
    assert manifest["format"] == "ply" and manifest["n_vertices"] == len(V) - 1
    # compact: the parts' boxes fill much less than that many copies of the whole box
    volume = np.prod(np.ptp(P[:-1], 0))
    assert sum(np.prod(np.ptp(p["V"], 0)) for p in parts) < 0.3 * len(parts) * volume


def _ply_with_vertex_list(path, V, F, uv, kind: str, with_list: bool):
    """A PLY (``kind``: "<", ">" or "ascii") whose vertex element has, when ``with_list``, a list property of
    several lengths (0 to 4) between x and y; per-vertex UVs after z."""
    lengths = np.arange(len(V)) % 5
    props = ["float x", *(["list uchar int ids"] if with_list else []), "double y", "float z", "float texture_u",
             "float texture_v"]
    head = ["ply", f"format {dict(a='ascii', l='binary_little_endian', b='binary_big_endian')[kind[0]]} 1.0",
            f"element vertex {len(V)}", *(f"property {p}" for p in props), f"element face {len(F)}",
            "property list uchar int vertex_indices", "end_header", ""]
    with open(path, "wb") as f:
        f.write("\n".join(head).encode())
        if kind == "ascii":
            for (x, y, z), (u, v), n in zip(V.tolist(), uv.tolist(), lengths):
                ids = f" {n}" + "".join(f" {7 * k - 3}" for k in range(n)) if with_list else ""
                f.write(f"{x!r}{ids} {y!r} {z!r} {u!r} {v!r}\n".encode())
            f.write("".join(f"3 {a} {b} {c}\n" for a, b, c in F.tolist()).encode())
            return
        o = "<" if kind[0] == "l" else ">"
        rest = np.zeros(len(V), [("y", o + "f8"), ("z", o + "f4"), ("t", o + "f4", (2,))])
        rest["y"], rest["z"], rest["t"] = V[:, 1], V[:, 2], uv
        for k in range(len(V)):
            f.write(np.array(V[k, 0], o + "f4").tobytes())
            if with_list:
                f.write(bytes([lengths[k]]) + np.arange(lengths[k], dtype=o + "i4").tobytes())
            f.write(rest[k].tobytes())
        tris = np.zeros(len(F), [("n", "u1"), ("i", o + "i4", (3,))])
        tris["n"], tris["i"] = 3, F
        f.write(tris.tobytes())


@pytest.mark.parametrize("kind", ["little", "big", "ascii"])
def test_a_vertex_list_property_is_skipped(tmp_path, monkeypatch, kind):
    """A list property of the vertex element (rows of several lengths) is stepped over, in binary PLY of
    either byte order (its other properties streamed to fixed records, in reads that cut rows) and ASCII:
    the parts, with the UVs after it, are those of the same file without it, and the list is named as
    dropped."""
    from qemjax._partition import ply

    monkeypatch.setattr(ply, "_STREAM_BYTES", 1000)
    V, F = shapes.icosphere(3)
    V = V.astype(np.float32).astype(np.float64)
    uv = (V[:, :2] * 0.5 + 0.5).astype(np.float32)
    got = []
    for with_list in (False, True):
        path = tmp_path / f"{with_list}.ply"
        _ply_with_vertex_list(path, V, F, uv, kind, with_list)
        manifest, _, scratch = _check(path, 300, V, F, welded=False, uv=True)
        assert manifest["uv"] and (manifest["dropped"] == ["vertex properties ids"]) == with_list
        got.append([(scratch / p["file"]).read_bytes() for p in manifest["parts"]])
        assert sorted(q.name for q in scratch.iterdir()) == ["level0", "manifest.json"]
    assert got[0] == got[1] and len(got[0]) > 2


def test_polygons_are_fanned(tmp_path):
    """Binary PLY of quads and triangles (streamed, not mapped: from the start when the first face is a
    quad, else once a quad is met), ASCII PLY with an extra element."""
    V, Q, T = _torus_quads()
    quads = np.zeros(len(Q) - 100, [("n", "u1"), ("i", "<i4", (4,))])
    quads["n"], quads["i"] = 4, Q[100:]
    tris = np.zeros(200, [("n", "u1"), ("i", "<i4", (3,))])
    tris["n"], tris["i"] = 3, T[:200]  # quads 0..99 as triangles
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\nproperty double x\n"
              f"property double y\nproperty double z\nelement face {len(quads) + 200}\n"
              "property list uchar int vertex_index\nend_header\n")
    for name, data, order in (("q.ply", quads.tobytes() + tris.tobytes(), np.r_[200:len(T), :200]),
                              ("t.ply", tris.tobytes() + quads.tobytes(), np.arange(len(T)))):
        _write_ply_records(tmp_path / name, header, V, data)
        _check(tmp_path / name, 1000, V, T[order], welded=False, chunk_faces=999)

    lines = [f"{x!r} {y!r} {z!r} 1 2" for x, y, z in V.tolist()]
    faces = [f"4 {a} {b} {c} {d} 0.5" for a, b, c, d in Q.tolist()]
    text = (f"ply\nformat ascii 1.0\ncomment c\nelement vertex {len(V)}\nproperty double x\nproperty double y\n"
            "property double z\nproperty uchar u\nproperty uchar w\n"
            f"element face {len(Q)}\nproperty list uchar int vertex_indices\nproperty float q\n"
            "element extra 2\nproperty int k\nend_header\n" + "\n".join(lines) + "\n\n" + "\n".join(faces)
            + "\n1\n2\n")
    path = tmp_path / "a.ply"
    path.write_text(text)
    manifest, _, _ = _check(path, 1000, V, T, welded=False)
    assert manifest["format"] == "ply"


def test_ply_elements_in_any_order(tmp_path):
    """A list element before the faces, the faces before the vertices, an element after them."""
    V, F = shapes.icosphere(3)
    extra = b"\x02" + np.float32([1, 2]).tobytes() + b"\x00"
    rec = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,))])
    rec["n"], rec["i"] = 3, F
    header = ("ply\nformat binary_little_endian 1.0\nelement extra 2\nproperty list uchar float values\n"
              f"element face {len(F)}\nproperty list uchar int vertex_indices\nelement vertex {len(V)}\n"
              "property double x\nproperty double y\nproperty double z\nelement tail 1\nproperty int k\n"
              "end_header\n")
    path = tmp_path / "o.ply"
    path.write_bytes(header.encode() + extra + rec.tobytes() + V.tobytes() + b"\0" * 4)
    _check(path, 300, V, F, welded=False)


def test_obj_corner_forms_negative_indices_and_welding(tmp_path):
    """OBJ faces as a, a/b, a/b/c, a//c, negative, quads; repeated positions welded."""
    V, Q, T = _torus_quads()
    n = len(V)
    lines = ["# a torus", "o torus", "mtllib none.mtl"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
    lines += ["vt 0.5 0.5", "vn 0 0 1"]
    lines += [f"v {x!r} {y!r} {z!r} 1 0 0" for x, y, z in V[:50].tolist()]  # repeats, with a colour
    forms = ["{}", "{}/1", "{}/1/1", "{}//1"]
    for k, quad in enumerate(Q.tolist()):
        if k % 5 == 0:  # numbered back from the last vertex so far
            corners = [str(v - (n + 50)) for v in quad]
        elif k % 7 == 0:  # the repeated positions' numbers
            corners = [str(n + v + 1) if v < 50 else str(v + 1) for v in quad]
        else:
            corners = [forms[(k + j) % 4].format(v + 1) for j, v in enumerate(quad)]
        lines.append("f " + " ".join(corners))
    path = tmp_path / "t.obj"
    path.write_text("\r\n".join(lines[:10]) + "\r\n" + "\n".join(lines[10:]) + "\n")
    P = np.concatenate([V, V[:50]])
    manifest, _, _ = _check(path, 700, P, T, welded=True, chunk_faces=1 << 12)
    assert manifest["format"] == "obj" and manifest["n_vertices"] == n


@pytest.mark.parametrize("ascii_", [False, True])
def test_stl_soup_is_welded(tmp_path, ascii_):
    V, F = _mesh()
    path = tmp_path / "s.stl"
    tm = trimesh.Trimesh(V, F, process=False)
    tm.export(path, file_type="stl_ascii" if ascii_ else "stl")
    P = tm.triangles.reshape(-1, 3).astype(np.float32).astype(np.float64)
    if ascii_:  # the values as written in the file
        P = np.array([[float(w) for w in l.split()[1:4]] for l in path.read_text().splitlines()
                      if l.split()[:1] == ["vertex"]])
    manifest, _, _ = _check(path, 2500, P, np.arange(len(P)).reshape(-1, 3), welded=True, chunk_faces=3001)
    assert manifest["format"] == "stl" and manifest["welded"]
    assert manifest["n_vertices"] == len(trimesh.load(path).vertices)
    if ascii_:  # its keywords in capitals (as some CAD exporters write them): the same parts (it had "no facets")
        upper = tmp_path / "u.stl"
        upper.write_text(path.read_text().upper())
        again = scatter(upper, tmp_path / "u", 2500, chunk_faces=3001)
        assert [(tmp_path / "u" / p["file"]).read_bytes() for p in again["parts"]] == \
            [(tmp_path / "s.stl.parts" / p["file"]).read_bytes() for p in manifest["parts"]]


def test_same_bytes_whatever_the_chunk(tmp_path):
    V, F = _mesh()
    path = tmp_path / "m.ply"
    write_binary_ply(path, V.astype(np.float32), F)
    files = []
    for chunk in (1 << 21, 4096, 777):
        scratch = tmp_path / f"s{chunk}"
        manifest = scatter(path, scratch, 1500, chunk_faces=chunk)
        files.append([(scratch / p["file"]).read_bytes() for p in manifest["parts"]])
    assert files[0] == files[1] == files[2] and len(files[0]) > 10


def test_same_bytes_whatever_the_read_size(tmp_path, monkeypatch):
    """Text read in blocks of a few lines, a polygon PLY streamed in small reads, welds over many small
    buckets and ranges give the same parts: lines, rows and face records cut at block ends are carried
    over, and ids do not depend on how the weld splits its work."""
    from qemjax._partition import ply, text, weld

    V, Q, T = _torus_quads()
    tm = trimesh.Trimesh(V, T, process=False)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()] + ["vn 0 0 1"]
    lines += ["f " + " ".join(f"{v + 1}//1" for v in quad) for quad in Q.tolist()]
    (tmp_path / "t.obj").write_text("\n".join(lines))  # no newline at the end
    # the same, each face line continued over two (a backslash ending the first), the last one too
    cont = [w.replace(" ", " \\\n", 2).replace(" \\\n", " ", 1) if w[:2] == "f " else w for w in lines]
    (tmp_path / "c.obj").write_text("\r\n".join(cont[:9]) + "\r\n" + "\n".join(cont[9:]) + " \\\n")
    tm.export(tmp_path / "a.stl", file_type="stl_ascii")
    tm.export(tmp_path / "a.ply", encoding="ascii")
    rec = np.zeros(len(Q), [("n", "u1"), ("i", "<i4", (4,))])
    rec["n"], rec["i"] = 4, Q
    _write_ply_records(tmp_path / "q.ply", f"ply\nformat binary_little_endian 1.0\nelement vertex {len(V)}\n"
                       "property double x\nproperty double y\nproperty double z\n"
                       f"element face {len(Q)}\nproperty list uchar int vertex_indices\nend_header\n",
                       V, rec.tobytes())
    first = {}
    for name in ("t.obj", "c.obj", "a.stl", "a.ply", "q.ply"):
        seen = []
        for size in (1 << 24, 1000):
            monkeypatch.setattr(text, "BLOCK", size)
            monkeypatch.setattr(ply, "_STREAM_BYTES", size)
            monkeypatch.setattr(weld, "_BUCKET_ROWS", size)
            monkeypatch.setattr(weld, "RANGE", size + 24)
            scratch = tmp_path / f"{name}.{size}"
            manifest = scatter(tmp_path / name, scratch, 500)
            seen.append([(scratch / p["file"]).read_bytes() for p in manifest["parts"]])
            assert manifest["n_faces"] == len(T) and manifest["n_vertices"] == len(V), name
        assert seen[0] == seen[1], name
        first[name] = seen[0]
    assert first["c.obj"] == first["t.obj"]  # continued lines read as one, whatever the blocks


def test_coincident_centroids_are_split_in_input_order(tmp_path):
    """Thousands of faces on one code (a tiny cluster beside a far triangle): refined to the last bit,
    then cut by input order."""
    rng = np.random.default_rng(1)
    V = np.concatenate([rng.normal(size=(300, 3)) * 1e-9, [[1e3, 0, 0], [1e3, 1, 0], [1e3, 0, 1]]])
    F = np.array([rng.choice(300, 3, replace=False) for _ in range(5000)])  # no face a part's clean-up drops
    F = np.concatenate([F[np.sort(np.unique(np.sort(F, 1), axis=0, return_index=True)[1])], [[300, 301, 302]]])
    path = tmp_path / "c.ply"
    write_binary_ply(path, V, F)
    calls = []
    manifest, parts, _ = _check(path, 1200, V, F, welded=False, chunk_faces=1100,
                                progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (len(F), len(F)) and calls == sorted(calls)
    first = np.concatenate([p["gid"][p["F"]] for p in parts if len(p["F"]) == 1200])
    assert np.array_equal(first, F[:len(first)])  # input order within and across the tie's parts


@pytest.mark.parametrize("name, data, words", [
    ("missing.ply", None, "no such file"),
    ("notes.ply", b"hello, this is text\n", "not a PLY file"),
    ("data.bin", bytes(range(256)) * 4, "unsupported format: a .bin file"),
    ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "unsupported format: a .off file"),
    ("nox.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n0\n", "x, y and z"),
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "line 4"),
    ("far.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "a face uses vertex 4,"),  # no "after line 0"
    ("nan.obj", b"v 0 0 0\nv 1 0 zz\nv 0 1 0\nf 1 2 3\n", "line 2"),
    ("cut.stl", b"\0" * 80 + (10).to_bytes(4, "little") + b"\0" * 60, "truncated binary STL"),
    # 34 bytes: 84 + 50 × -1, the size a header-less file's count of -1 used to match
    ("short.stl", bytes(range(1, 35)), "fewer than the 84 its header alone takes"),
    ("inf.obj", b"v 0 0 0\nv 1 0 inf\nv 0 1 0\nv nan 0 0\nf 1 2 3\n", "vertex 1 has a coordinate that is not a finite"),
    ("few.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1\n3 0 1 2\n",
     "line 12 holds too few values for a vertex row"),
])
def test_clear_errors(tmp_path, name, data, words):
    path = tmp_path / name
    if data is not None:
        path.write_bytes(data)
    with pytest.raises(ValueError) as info:
        scatter(path, tmp_path / "s", 100)
    msg = str(info.value)
    assert msg.startswith(str(path) + ": ") and "\n" not in msg and words in msg, msg


def test_truncated_binary_ply(tmp_path):
    V, F = _mesh()
    path = tmp_path / "m.ply"
    write_binary_ply(path, V, F)
    path.write_bytes(path.read_bytes()[:-1000])
    with pytest.raises(ValueError, match="truncated binary PLY"):
        scatter(path, tmp_path / "s", 1000)
    bad = tmp_path / "far.ply"
    write_binary_ply(bad, V, F)
    data = bytearray(bad.read_bytes())
    data[-4:] = np.int32(len(V) + 5).tobytes()
    bad.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=f"uses vertex {len(V) + 5}, but the file has {len(V)} vertices"):
        scatter(bad, tmp_path / "s", 1000)


def test_write_binary_ply_in_chunks(tmp_path):
    """Chunks from generators, counts not given (written in afterwards), big-endian: trimesh and scatter
    read back the same mesh."""
    V, F = _mesh()
    path = tmp_path / "w.ply"
    counts = write_binary_ply(path, (V[i:i + 1000] for i in range(0, len(V), 1000)),
                              (F[i:i + 3000] for i in range(0, len(F), 3000)), big_endian=True)
    assert counts == (len(V), len(F))
    back = trimesh.load(path, process=False)
    assert np.array_equal(back.vertices, V) and np.array_equal(back.faces, F)
    _check(path, 5000, V, F, welded=False)
    with pytest.raises(ValueError, match="outside"):
        write_binary_ply(tmp_path / "x.ply", V, F + len(V))


def test_distinct_ids_are_numpys_unique():
    from qemjax._partition.scatter import _distinct

    rng = np.random.default_rng(3)
    for dtype in (np.int32, np.int64):  # the file's index type: ids and the scratch array alike
        at = np.full(5000, 7, dtype)  # whatever an earlier part left there
        for n in (0, 1, 5, 300, 6000):
            raw = rng.integers(0, rng.integers(1, 5000), n).astype(dtype)
            used, inverse = _distinct(raw, at)
            want, want_inv = np.unique(raw, return_inverse=True)
            assert used.dtype == want.dtype and np.array_equal(used, want)
            assert np.array_equal(inverse, want_inv.ravel())


def test_the_list_walkers_stop_at_a_cut_row_and_name_a_damaged_one():
    """Both compiled walkers of binary list rows (`_walk`: faces, fanned; `_pack`: vertex scalars, lists
    skipped) read whole rows only: a row whose list runs past the bytes read is left for the next read,
    and a negative count is reported with its row."""
    from qemjax._partition import ply

    # rows of (list int8 count, int32 items; float32 scalar), little endian
    kinds, sizes = np.array([1, 0]), np.array([4, 4])
    csizes, csigned = np.array([1, 0]), np.array([1, 0])

    def row(items, scalar):
        return bytes([len(items) & 0xFF]) + np.asarray(items, "<i4").tobytes() + np.float32(scalar).tobytes()

    whole = row([0, 1, 2, 3], 1.5) + row([4, 5, 6], 2.5)
    buf = np.frombuffer(whole + row([7, 8, 9], 3.5)[:6], np.uint8)  # the third row cut in its list
    used, done, tris, bad = ply._walk(buf, 3, kinds, sizes, csizes, csigned, 0, True, False)
    assert (used, done, bad) == (len(whole), 2, -1)
    assert tris.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 6]]
    used, done, packed, bad = ply._pack(buf, 3, kinds, sizes, csizes, csigned, False, 4)
    assert (used, done, bad) == (len(whole), 2, -1)
    assert np.frombuffer(packed.tobytes(), "<f4").tolist() == [1.5, 2.5]
    damaged = np.frombuffer(whole + bytes([0xFF]) + np.float32(0).tobytes(), np.uint8)  # a count of -1
    assert ply._walk(damaged, 3, kinds, sizes, csizes, csigned, 0, True, False)[1:4:2] == (2, 2)
    assert ply._pack(damaged, 3, kinds, sizes, csizes, csigned, False, 4)[1:4:2] == (2, 2)
