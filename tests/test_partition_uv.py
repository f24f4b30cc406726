"""UVs in partitioned runs (`qemjax._partition`): read from an OBJ's ``vt`` and a PLY's per-vertex texture
coordinates, carried through the parts with their corners, kept by each group's run (seams and all, a locked
border vertex with its UVs), and returned as the in-core run returns them."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import qemjax
from qemjax import Partition, shapes
from qemjax._io import attribute_files as af
from qemjax._partition import task
from qemjax._partition.readers import texture_of

from test_partition import closed_and_consistent
from test_partition_carry import open_tubes

RATIO = 0.1


def spherical(P: np.ndarray) -> np.ndarray:
    """(n,2) the longitude/latitude map of `attribute_files.spherical_uv` at points P."""
    d = P / np.linalg.norm(P, axis=1, keepdims=True)
    return np.stack([(np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)) % 1.0, np.arccos(np.clip(d[:, 2], -1, 1)) / np.pi], 1)


def deviation(res) -> np.ndarray:
    """Each wedge's UV against the map at its vertex (u across the seam: the shorter way round)."""
    e = np.abs(res.uv - spherical(res.vertices[res.wedge_vertex]))
    e[:, 0] = np.minimum(e[:, 0], np.abs(e[:, 0] - 1))
    return np.hypot(e[:, 0], e[:, 1])


@pytest.fixture(scope="module")
def sphere_obj(tmp_path_factory):
    """A bumpy sphere of 20,480 faces with a longitude/latitude map: one seam along a meridian."""
    m = shapes.bumpy_sphere(5)
    uv, corner = af.spherical_uv(m)
    path = tmp_path_factory.mktemp("uv") / "sphere.obj"
    af.write_obj(path, m, uv=uv, corner_uv=corner)
    return path


@pytest.fixture(scope="module")
def runs(sphere_obj):
    core = qemjax.simplify(str(sphere_obj), ratio=RATIO, attributes="uv")
    part = qemjax.simplify(str(sphere_obj), ratio=RATIO, attributes="uv",
                           partition=Partition(workers=1, part_faces=1000))
    return core, part


def test_uvs_are_kept_through_the_levels(runs):
    """The target, a closed mesh, and UVs as good as the in-core run's; the only vertices with several
    wedges are on the input's seam (none along the cuts: a border vertex kept its UVs in every part); the
    position quadrics are carried from level to level."""
    core, part = runs
    assert part.stats["partition"]["levels"] >= 2 and part.stats["partition"]["uv"]
    assert part.stats["partition"]["carried"]  # the position quadrics, the attributes' rebuilt per level
    assert len(part.faces) == len(core.faces) == round(RATIO * 20480) and closed_and_consistent(part.faces)
    assert np.array_equal(part.vertices[part.wedge_vertex][part.wedge_faces], part.vertices[part.faces])
    assert part.stats["dropped"] == ["record"]
    for res in (core, part):
        wedges = np.bincount(res.wedge_vertex, minlength=len(res.vertices))
        seam = np.flatnonzero(wedges > 1)
        assert len(seam) > 20 and all(np.ptp(res.uv[res.wedge_vertex == v, 0]) > 0.9 for v in seam)
    span = lambda r: np.ptp(r.uv[r.wedge_faces][:, :, 0], axis=1)  # noqa: E731
    assert np.sum(span(part) > 0.5) == np.sum(span(core) > 0.5)  # faces at the poles only, as in core
    d_part, d_core = deviation(part), deviation(core)
    assert np.median(d_part) < 1.5 * np.median(d_core) < 1e-3
    assert np.percentile(d_part, 95) < 1.5 * np.percentile(d_core, 95)


def test_to_trimesh_and_the_command_line_write_the_uvs(runs, sphere_obj, tmp_path):
    from qemjax import _cli

    _, part = runs
    mesh = part.to_trimesh()
    assert len(mesh.visual.uv) == len(part.uv) and len(mesh.faces) == len(part.faces)
    out = tmp_path / "out.obj"
    assert _cli.main(["simplify", str(sphere_obj), str(out), "--ratio", str(RATIO), "--partition", "--workers", "1",
                      "--part-faces", "1000", "--attributes", "uv", "--quiet"]) == 0
    text = out.read_text()
    assert text.count("\nvt ") == len(part.uv) and text.count("\nf ") == len(part.faces)


@pytest.mark.slow  # starts worker processes
@pytest.mark.parametrize("where", ["local", "dask"])
def test_same_bits_with_two_workers(runs, sphere_obj, where):
    """Two local worker processes, or a Dask `LocalCluster` of two, give the in-process run's bytes, UVs
    and wedges included."""
    _, part = runs
    if where == "local":
        two = qemjax.simplify(str(sphere_obj), ratio=RATIO, attributes="uv",
                              partition=Partition(workers=2, part_faces=1000))
    else:
        distributed = pytest.importorskip("dask.distributed")
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cl, distributed.Client(cl) as client:
            two = qemjax.simplify(str(sphere_obj), ratio=RATIO, attributes="uv",
                                  partition=Partition(client=client, part_faces=1000))
        assert two.stats["partition"]["where"] == "dask"
    for name in ("vertices", "faces", "uv", "wedge_vertex", "wedge_faces"):
        assert np.asarray(getattr(two, name)).tobytes() == np.asarray(getattr(part, name)).tobytes(), name


def _ply(path, V, F, uv, binary: bool, names=("texture_u", "texture_v")):
    """A PLY with per-vertex UVs under ``names``."""
    props = ["float x", "float y", "float z", f"float {names[0]}", f"float {names[1]}"]
    head = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", f"element vertex {len(V)}",
            *(f"property {p}" for p in props), f"element face {len(F)}", "property list uchar int vertex_indices",
            "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        if binary:
            rows = np.zeros(len(V), [("p", "<f4", (3,)), ("t", "<f4", (2,))])
            rows["p"], rows["t"] = V, uv
            f.write(rows.tobytes())
            tris = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,))])
            tris["n"], tris["i"] = 3, F
            f.write(tris.tobytes())
        else:
            f.write("".join(f"{x!r} {y!r} {z!r} {u!r} {v!r}\n" for (x, y, z), (u, v) in
                            zip(V.tolist(), uv.tolist())).encode())
            f.write("".join(f"3 {a} {b} {c}\n" for a, b, c in F.tolist()).encode())


@pytest.mark.parametrize("binary,names", [(True, ("texture_u", "texture_v")), (False, ("s", "t"))])
def test_per_vertex_uvs_of_a_ply(tmp_path, binary, names):
    """A PLY's per-vertex UVs, here a map of the positions (u = x, v = y; no seam): the kept UVs follow the
    map at the output's vertices, partitioned as in core (each face fits the map in its own plane, so a
    vertex placed off the input's faces is a little off the map in both)."""
    m = shapes.bumpy_sphere(5)
    V = np.asarray(m.vertices, np.float32).astype(np.float64)
    F = np.asarray(m.faces)
    path = tmp_path / "planar.ply"
    _ply(path, V, F, V[:, :2], binary, names)
    res = qemjax.simplify(str(path), ratio=RATIO, attributes="uv", partition=Partition(workers=1, part_faces=1000))
    core = qemjax.simplify(str(path), ratio=RATIO, attributes="uv")
    assert res.stats["partition"]["uv"] and res.stats["dropped"] == ["record"]
    assert np.bincount(res.wedge_vertex).max() == 1  # no seam in, none out
    off = [np.linalg.norm(r.uv - r.vertices[r.wedge_vertex][:, :2], axis=1) for r in (res, core)]
    assert np.median(off[0]) < 1.5 * np.median(off[1]) < 1e-2 and off[0].max() < 2 * off[1].max()


@pytest.mark.parametrize("present", [("u", "s"), ("texture_u", "u", "s"), ("s",), ("texture_s", "s")])
def test_a_ply_with_several_uv_pairs_gives_the_uvs_an_in_core_read_takes(tmp_path, present):
    """A PLY whose vertices hold more than one pair of UV names (u, v beside s, t) gave a partitioned run one
    pair and an in-core run (trimesh's reader) another: the partitioned reader now tries them in trimesh's
    order, so a file gives the same UVs either way."""
    import trimesh

    from qemjax._io import ply as io_ply
    from qemjax._partition import ply as part_ply

    pairs = {"u": ("u", "v"), "s": ("s", "t"), "texture_u": ("texture_u", "texture_v"),
             "texture_s": ("texture_s", "texture_t")}
    V, F = shapes.icosphere(1)
    names = [n for key in present for n in pairs[key]]
    columns = {n: V[:, 0] + k for k, n in enumerate(names)}  # each name its own values
    head = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property double x", "property double y",
            "property double z", *[f"property double {n}" for n in names], f"element face {len(F)}",
            "property list uchar int vertex_indices", "end_header"]
    rows = np.c_[V, np.stack([columns[n] for n in names], 1)]
    path = tmp_path / "uv.ply"
    path.write_text("\n".join(head + [" ".join(map(repr, r)) for r in rows.tolist()]
                              + [f"3 {a} {b} {c}" for a, b, c in F.tolist()] + [""]))
    uv = trimesh.load(path, process=False).visual.uv
    taken = next(pair for pair in pairs.values() if pair[0] in names and np.array_equal(uv[:, 0], columns[pair[0]]))
    header = io_ply.parse_header(path.read_bytes())
    assert part_ply.uv_names(header.element("vertex")) == taken


def test_per_corner_uvs_of_a_binary_ply(tmp_path):
    """A binary PLY's face list ``texcoord`` (u, v of each corner, as MeshLab writes them, seams and all):
    kept as an OBJ's vt are, the only vertices with several UVs on the input's seam."""
    m = shapes.bumpy_sphere(5)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    uv, corner = af.spherical_uv(m)
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(V)}", "property float x",
            "property float y", "property float z", f"element face {len(F)}",
            "property list uchar int vertex_indices", "property list uchar float texcoord", "end_header"]
    rows = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,)), ("k", "u1"), ("t", "<f4", (6,))])
    rows["n"], rows["i"], rows["k"], rows["t"] = 3, F, 6, uv[corner].reshape(-1, 6)
    path = tmp_path / "seamed.ply"
    path.write_bytes(("\n".join(head) + "\n").encode() + V.astype("<f4").tobytes() + rows.tobytes())
    res = qemjax.simplify(str(path), ratio=RATIO, attributes="uv", partition=Partition(workers=1, part_faces=1000))
    assert res.stats["partition"]["uv"] and res.stats["dropped"] == ["record"]
    seam = np.flatnonzero(np.bincount(res.wedge_vertex, minlength=len(res.vertices)) > 1)
    assert len(seam) > 20 and all(np.ptp(res.uv[res.wedge_vertex == v, 0]) > 0.9 for v in seam)
    assert np.median(deviation(res)) < 1e-3


def test_the_texture_image_is_the_used_materials(tmp_path):
    """texture_of took the first map_Kd of any material whose file exists, though the faces use another
    (a wrong image came back), and the last word of a map_Kd with options or a name with spaces."""
    from PIL import Image

    obj = tmp_path / "m.obj"
    obj.write_text("mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl mat\nf 1/1 2/2 3/3\n")
    (tmp_path / "lib.mtl").write_text("newmtl other\nmap_Kd other.png\n\nnewmtl mat\nmap_Kd -s 1 1 1 my tex.png\n")
    Image.new("RGB", (4, 4)).save(tmp_path / "other.png")
    assert texture_of(obj) is None  # the used material's image does not exist: none, not another's
    Image.new("RGB", (4, 4)).save(tmp_path / "my tex.png")
    assert texture_of(obj) == tmp_path / "my tex.png"


def test_a_resumed_run_sees_the_texture_image_that_appeared(tmp_path):
    """attributes="auto" keeps a file's UVs with seams when the image it names exists: a run resumed from one
    made before the image existed reused its parts without UVs (the key held "auto", not what it found)."""
    from PIL import Image

    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    uv, corner = af.spherical_uv(m)
    wv = np.zeros(len(uv), np.int64)
    wv[corner] = F
    path = tmp_path / "tex.ply"
    _ply(path, V[wv], corner, uv, True)  # a vertex per (position, UV): the seam's positions twice
    data = path.read_bytes()
    path.write_bytes(data.replace(b"format binary_little_endian 1.0\n",
                                  b"format binary_little_endian 1.0\ncomment TextureFile t.png\n", 1))
    settings = Partition(workers=1, part_faces=2000, scratch=tmp_path / "scratch")
    assert qemjax.simplify(str(path), ratio=0.1, partition=settings).uv is None  # no image yet
    Image.new("RGB", (8, 8), (200, 30, 30)).save(tmp_path / "t.png")
    resumed = qemjax.simplify(str(path), ratio=0.1, partition=settings)
    assert resumed.uv is not None and resumed.stats["partition"]["reused"] == 0


@pytest.mark.parametrize("kind", ["soup", "seams", "texcoord soup"])
def test_a_ply_that_repeats_positions_is_welded_as_in_core(tmp_path, kind):
    """A PLY whose vertices repeat positions (a triangle soup; a mesh split at its UV seams, per-vertex UVs;
    a soup whose corners' UVs are texcoord lists): in core the copies are welded; partitioned they were
    vertices of different numbers, neither shared by two parts, which the parts moved apart (a crack; the
    last level failed). Now welded as in core: closed in, closed out, the UVs kept with their seams."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    uv, corner = af.spherical_uv(m)
    path = tmp_path / "repeats.ply"
    if kind == "soup":
        _ply(path, V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3), np.zeros((3 * len(F), 2)), True)
    elif kind == "seams":  # a vertex per (position, UV): the seam's positions twice
        wv = np.zeros(len(uv), np.int64)
        wv[corner] = F
        _ply(path, V[wv], corner, uv, True)
    else:
        head = ["ply", "format binary_little_endian 1.0", f"element vertex {3 * len(F)}", "property float x",
                "property float y", "property float z", f"element face {len(F)}",
                "property list uchar int vertex_indices", "property list uchar float texcoord", "end_header"]
        rows = np.zeros(len(F), [("n", "u1"), ("i", "<i4", (3,)), ("k", "u1"), ("t", "<f4", (6,))])
        rows["n"], rows["i"], rows["k"], rows["t"] = 3, np.arange(3 * len(F)).reshape(-1, 3), 6, uv[corner].reshape(-1, 6)
        path.write_bytes(("\n".join(head) + "\n").encode() + V[F].reshape(-1, 3).astype("<f4").tobytes() + rows.tobytes())
    attributes = None if kind == "soup" else "uv"
    core = qemjax.simplify(str(path), ratio=0.1, attributes=attributes)
    res = qemjax.simplify(str(path), ratio=0.1, attributes=attributes, partition=Partition(workers=1, part_faces=1000))
    assert res.stats["partition"]["welded"] and len(res.stats["partition"]["groups_per_level"]) > 1
    assert len(res.faces) == len(core.faces) == round(0.1 * len(F)) and closed_and_consistent(res.faces)
    assert len(res.vertices) == len(core.vertices)
    if attributes:
        assert res.uv is not None
        seam = np.bincount(res.wedge_vertex, minlength=len(res.vertices)) > 1
        assert 20 < seam.sum() < 0.2 * len(res.vertices)  # the seam, kept, and only there


def test_auto_keeps_uvs_that_come_with_a_texture(sphere_obj, tmp_path):
    """``attributes="auto"`` (the default) keeps a file's UVs with seams when its material names a texture
    image that exists, and the result carries that image; without one they are dropped, and named. Kept, they
    turn off the default's memoryless last stretch in the last level's runs: said once, as in core, in a
    warning and the stats (a worker's warning, it was in neither)."""
    from PIL import Image

    path = tmp_path / "textured.obj"
    path.write_text("mtllib tex.mtl\nusemtl tex\n" + sphere_obj.read_text())
    settings = Partition(workers=1, part_faces=4000)
    (tmp_path / "tex.mtl").write_text("newmtl tex\nKd 1 1 1\nmap_Kd t.png\n")
    with pytest.warns(UserWarning, match=r"texture coordinates \(vt\); uv not kept by default \(uv: \d+ seam "
                      r"vertices\): seams hold .*; attributes='uv' \(CLI: --attributes uv\) keeps them$"):
        plain = qemjax.simplify(str(path), ratio=RATIO, partition=settings)  # the image is missing
    assert plain.uv is None and "texture coordinates (vt)" in plain.stats["dropped"]
    Image.new("RGB", (8, 8), (200, 30, 30)).save(tmp_path / "t.png")
    assert texture_of(path) == tmp_path / "t.png"
    with pytest.warns(UserWarning) as said:
        res = qemjax.simplify(str(path), ratio=RATIO, partition=settings)
    assert [str(w.message).split(" turns off")[0] for w in said] == ["keeping uv"]
    assert "attributes are kept" in res.stats["late_memoryless_off"]
    assert res.uv is not None and np.asarray(res.material.image).shape[:2] == (8, 8)
    assert res.stats["dropped"] == ["record"] and res.stats["attributes"] == ["uv"]
    Image.new("RGB", (4, 2)).save(tmp_path / "other.png")  # texture= names the image itself, as in core
    given = qemjax.simplify(str(sphere_obj), ratio=RATIO, texture=tmp_path / "other.png", partition=settings)
    assert given.uv is not None and np.asarray(given.material.image).shape[:2] == (2, 4)


@pytest.mark.parametrize("binary", [True, False])
def test_a_ply_s_uvs_without_seams_are_kept_by_default(tmp_path, binary):
    """A PLY's per-vertex UVs without a texture image and without seams are kept by default, as in core
    (they were left out without an image); with ``attributes=None`` they are named as dropped, without the
    way to keep them; columns under names that are not UVs are not read as UVs."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    path = tmp_path / "planar.ply"
    _ply(path, V, F, V[:, :2], binary)
    settings = Partition(workers=1, part_faces=1000)

    def warned(source, **kw):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = qemjax.simplify(str(source), ratio=RATIO, partition=settings, **kw)
        return res, [str(w.message) for w in caught if "not carried over" in str(w.message)]

    res, said = warned(path)
    assert res.uv is not None and not said and res.stats["dropped"] == ["record"]
    assert qemjax.simplify(str(path), ratio=RATIO).uv is not None  # in core
    res, said = warned(path, attributes=None)
    assert res.uv is None and len(said) == 1 and "keeps the UVs" not in said[0]
    assert said[0].endswith("vertex properties texture_u, texture_v")
    other = tmp_path / "other.ply"  # the same columns under names that are not UVs
    _ply(other, V, F, V[:, :2], binary, names=("quality", "confidence"))
    res, said = warned(other)
    assert res.uv is None and len(said) == 1 and said[0].endswith("vertex properties quality, confidence")


def _core_seams(path) -> int:
    """How many seam vertices an in-core run with ``attributes="auto"`` names for the file's UVs (0: kept)."""
    import re

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = qemjax.simplify(str(path), ratio=RATIO)
    found = [re.search(r"uv: (\d+) seam vertices", str(w.message)) for w in caught]
    counts = [int(f.group(1)) for f in found if f]
    assert (res.uv is None) == bool(counts)
    return counts[0] if counts else 0


def test_auto_decides_on_an_obj_s_uvs_as_in_core(tmp_path, sphere_obj):
    """``attributes="auto"`` on an OBJ with UVs and no texture image keeps them when they have no seam (each
    ``v`` its own ``vt``) and leaves them out when they have one (the sphere's meridian), as an in-core run
    does: the same seam vertices counted, named in the warning and in ``stats["not_kept_seams"]``."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    seamless = tmp_path / "planar.obj"
    seamless.write_text("".join(f"v {x!r} {y!r} {z!r}\nvt {x!r} {y!r}\n" for x, y, z in V.tolist())
                        + "".join(f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in (F + 1).tolist()))
    settings = Partition(workers=1, part_faces=1000)
    with pytest.warns(UserWarning) as said:
        res = qemjax.simplify(str(seamless), ratio=RATIO, partition=settings)
    assert [str(w.message).split(" turns off")[0] for w in said] == ["keeping uv"]  # kept: only the stretch's
    assert _core_seams(seamless) == 0
    assert res.uv is not None and res.stats["dropped"] == ["record"] and res.stats["attributes"] == ["uv"]
    assert len(res.stats["partition"]["groups_per_level"]) > 1 and "not_kept_seams" not in res.stats
    assert np.abs(res.uv - res.vertices[res.wedge_vertex][:, :2]).max() < 0.05  # the map, u = x, v = y
    seams = _core_seams(sphere_obj)
    assert seams > 20
    with pytest.warns(UserWarning) as said:
        res = qemjax.simplify(str(sphere_obj), ratio=RATIO, partition=settings)
    with pytest.warns(UserWarning) as in_core:  # the same sentence, from one place (`_wedges.seamed_left_out`)
        qemjax.simplify(str(sphere_obj), ratio=RATIO)
    core = [str(w.message) for w in in_core if "not kept by default" in str(w.message)]
    assert core == [f"{sphere_obj}: uv not kept by default (uv: {seams} seam vertices): seams hold their vertices "
                    "in place, which costs geometry and time (docs/attributes.md); attributes='uv' (CLI: "
                    "--attributes uv) keeps them"]
    assert [str(w.message) for w in said if "not kept by default" in str(w.message)] == [
        "partition: the output keeps positions only; not carried over from the input: texture coordinates (vt); "
        + core[0].split(": ", 1)[1]]
    assert res.uv is None and res.stats["not_kept_seams"] == ["uv"]
    assert res.stats["dropped"] == ["record", "texture coordinates (vt)"]


def test_auto_writes_no_uvs_to_the_parts_once_it_found_a_seam(tmp_path, sphere_obj, monkeypatch):
    """``attributes="auto"`` without a texture leaves seamed UVs out, which it knows only when the binning
    pass meets a seam: it wrote every chunk's UVs to the parts' scratch files all the same, to discard them.
    It writes none from the chunk where it finds the first seam on; the parts and the manifest are the same
    bits as without the UVs (but for the seam count) and whatever the chunks."""
    from qemjax._partition import scatter

    m = shapes.bumpy_sphere(5)
    uv, corner = af.spherical_uv(m)
    C = uv[corner].reshape(-1, 2)  # each corner's UV, in face order
    flat = np.asarray(m.faces).reshape(-1)
    _, first = np.unique(flat, return_index=True)
    seam_chunk = int(np.flatnonzero((C != C[first[flat]]).any(1))[0]) // 3 // 2000  # where the first seam is
    chunks = -(-len(m.faces) // 2000)
    assert seam_chunk < chunks - 1  # chunks after it: UVs that were written to be dropped
    real_open, at, written = open, [0], []

    def spy(path, *args, **kwargs):
        if str(path).endswith(".uv"):
            written.append(at[0])
        return real_open(path, *args, **kwargs)

    def progress(done, total):
        at[0] += 1

    monkeypatch.setattr(scatter, "open", spy, raising=False)
    manifest = scatter.scatter(sphere_obj, tmp_path / "auto", 1000, chunk_faces=2000, progress=progress, uv="auto")
    monkeypatch.undo()
    assert at[0] == chunks and not manifest["uv"] and manifest["uv_seam_vertices"] > 20
    assert written and max(written) < seam_chunk  # before the seam's chunk only (none when it is the first)
    plain = scatter.scatter(sphere_obj, tmp_path / "plain", 1000, chunk_faces=2000)
    whole = scatter.scatter(sphere_obj, tmp_path / "whole", 1000, uv="auto")
    assert whole == manifest == {**plain, "uv_seam_vertices": manifest["uv_seam_vertices"]}
    for part in manifest["parts"]:
        got = [np.load(tmp_path / run / part["file"]) for run in ("auto", "plain", "whole")]
        assert sorted(got[0].files) == ["F", "V", "border", "gid"]
        assert all(sorted(g.files) == sorted(got[0].files) for g in got)
        assert all(np.array_equal(g[k], got[0][k]) for g in got for k in got[0].files)


def test_a_folder_cut_when_auto_needed_a_texture_is_not_resumed(tmp_path):
    """A scratch folder an earlier version cut under ``attributes="auto"`` (which kept UVs only with a texture
    image) holds parts without the UVs "auto" now keeps: its key differs, so the run starts afresh."""
    import json

    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    path = tmp_path / "planar.ply"
    _ply(path, V, F, V[:, :2], True)
    settings = Partition(workers=1, part_faces=2000, scratch=tmp_path / "scratch")
    assert qemjax.simplify(str(path), ratio=RATIO, partition=settings).uv is not None
    meta, manifest = tmp_path / "scratch" / "run.json", tmp_path / "scratch" / "manifest.json"
    meta.write_text(json.dumps(json.loads(meta.read_text()) | {"uv": "auto"}))  # as the earlier version wrote
    manifest.write_text(json.dumps(json.loads(manifest.read_text()) | {"uv": False}))  # and what it decided
    res = qemjax.simplify(str(path), ratio=RATIO, partition=settings)
    assert res.uv is not None and res.stats["partition"]["reused"] == 0


def test_texture_file_of_a_ply(tmp_path):
    path = tmp_path / "m.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\ncomment TextureFile skin.png\nelement vertex 0\nend_header\n")
    assert texture_of(path) is None  # named, not there
    (tmp_path / "skin.png").write_bytes(b"")
    assert texture_of(path) == tmp_path / "skin.png"


def test_a_border_along_the_cuts_is_kept_with_uvs(tmp_path):
    """With kept UVs a group runs on a vertex per wedge: the input's boundary edges along the cuts keep their
    planes there too (named by their vertices' first wedges), and the partitioned run's Hausdorff distance
    stays near the in-core one's (`test_partition_carry.test_a_border_along_the_cuts_is_kept_as_in_core`)."""
    around, rings = 48, 11
    V, F = open_tubes(around=around, along=rings - 1)
    j, ring = np.arange(len(V)) % around, np.arange(len(V)) // around % rings
    u = j[F].astype(float)
    u[(u.max(1) - u.min(1) > around / 2)[:, None] & (u < around / 2)] += around  # across the seam: u > 1
    uv = np.stack([u / around, ring[F] / (rings - 1)], -1).reshape(-1, 2)
    path = tmp_path / "tubes.obj"
    af.write_obj(path, (V, F), uv=uv, corner_uv=np.arange(3 * len(F)).reshape(-1, 3))
    core = qemjax.simplify(str(path), ratio=RATIO, attributes="uv", progress=False)
    part = qemjax.simplify(str(path), ratio=RATIO, attributes="uv", progress=False,
                           partition=Partition(workers=1, part_faces=1000))
    assert part.stats["partition"]["uv"] and part.stats["partition"]["levels"] >= 2
    h_core, h_part = core.stats["distance_max_rel"], part.stats["distance_max_rel"]
    assert h_part < 1.5 * h_core, (h_part, h_core)


def test_corner_wedges_split_a_vertex_by_its_uvs():
    F = np.array([[0, 1, 2], [0, 2, 3]])
    UV = np.array([[[0, 0], [1, 0], [1, 1]], [[0.5, 0], [1, 1], [0, 1]]], float)
    vertex, uv, corners = task.corner_wedges(F, UV)
    assert vertex.tolist() == [0, 0, 1, 2, 3] and corners.tolist() == [[0, 2, 3], [1, 3, 4]]
    assert np.array_equal(uv[corners], UV)


def test_uv_input_errors(tmp_path, sphere_obj):
    m = shapes.bumpy_sphere(3)
    with pytest.raises(ValueError, match="from a mesh file"):
        qemjax.simplify((m.vertices, m.faces), ratio=0.5, attributes="uv", partition=True)
    with pytest.raises(ValueError, match="UVs and nothing else"):
        qemjax.simplify(str(sphere_obj), ratio=0.5, attributes="color", partition=True)
    half = tmp_path / "half.obj"  # a face without texture coordinates: the UVs are not kept
    lines = sphere_obj.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("f "))
    lines[k] = "f " + " ".join(c.split("/")[0] for c in lines[k].split()[1:])
    half.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="does not give every triangle corner a UV"):  # as in core
        qemjax.simplify(str(half), ratio=RATIO, attributes="uv", partition=Partition(workers=1, part_faces=4000))
    with pytest.raises(ValueError, match="carries no uv"):
        qemjax.simplify(str(half), ratio=RATIO, attributes="uv")
    # texture coordinates that are not u and v numbers: the file is read as before, its UVs are not kept
    quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\n"
    faces = "f 1/1/1 2/2/1 5/3/1\nf 2/2/1 3/3/1 5/1/1\nf 3/1 4/2 5/3\nf 4/1 1/2 5/3\nf 1/1 3/3 2/2\nf 1/1 4/2 3/3\n"
    odd = tmp_path / "odd.obj"
    odd.write_text(quad + "vt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n" + faces)
    assert qemjax.simplify(str(odd), target_faces=4, attributes="uv", partition=Partition(workers=1)).uv is not None
    # and corners naming texture coordinates the file does not have (none, the fourth, 0, before the first)
    for vt, fix in [("", ""), ("vt 0 0\nvt 1 0\nvt 1 1\n", "f 1/4 4/2 3/3"), ("vt 0 0\nvt 1 0\nvt 1 1\n", "f 1/0 4/2 3/3"),
                    ("vt 0 0\nvt 1 0\nvt 1 1\n", "f 1/-4 4/2 3/3"), ("vt 0.5\nvt 0.2\nvt 0.1\n", ""),
                    ("vt 0 0\nvt a b\nvt 1 1\n", "")]:
        odd.write_text(quad + vt + "vn 0 0 1\n" + (faces.replace("f 1/1 4/2 3/3", fix) if fix else faces))
        with pytest.raises(ValueError, match="does not give every triangle corner a UV"):
            qemjax.simplify(str(odd), target_faces=4, attributes="uv", partition=Partition(workers=1))
        assert qemjax.simplify(str(odd), target_faces=4, partition=Partition(workers=1)).uv is None  # auto: none
    ply = tmp_path / "odd.ply"  # an ASCII PLY whose UV column is not numbers: its positions, as before
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
                   "property float s\nproperty float t\nelement face 6\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 x\n0 1 0 0 1\n0.5 0.5 1 0.5 0.5\n"
                   "3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n3 0 2 1\n3 0 3 2\n")
    with pytest.raises(ValueError, match="does not give every triangle corner a UV"):
        qemjax.simplify(str(ply), target_faces=4, attributes="uv", partition=Partition(workers=1))
    res = qemjax.simplify(str(ply), target_faces=4, partition=Partition(workers=1))
    assert res.uv is None and len(res.faces) == 4
    with pytest.raises(ValueError, match="weld=False is not offered"):
        qemjax.simplify(str(sphere_obj), ratio=0.5, attributes="uv", weld=False, partition=True)
    with pytest.raises(ValueError, match="texture= needs UVs"):
        qemjax.simplify(str(sphere_obj), ratio=0.5, attributes=None, texture="t.png", partition=True)
