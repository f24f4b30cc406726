"""Loading, welding and cleaning."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import shared_mesh

import qemjax
from qemjax._io import mesh as _io
from qemjax import shapes


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "off", "glb"])
def test_load_formats(tmp_path, ext):
    V, F = shapes.icosphere(2)
    path = tmp_path / f"m.{ext}"
    trimesh.Trimesh(V, F, process=False).export(path)
    m = qemjax.load(path)
    assert m.faces.shape == (320, 3)
    r = qemjax.simplify(path, target_faces=100)
    assert len(r.faces) == 100


def test_weld_merges_coincident_vertices_and_reports():
    V, F = shapes.icosphere(2)
    Vs = V[F].reshape(-1, 3)  # triangle soup: every corner its own vertex
    Fs = np.arange(len(Vs)).reshape(-1, 3)
    (V2, F2), rep = _io.prepare((Vs, Fs))
    assert rep["welded"] == len(Vs) - len(V)
    assert len(V2) == len(V)
    (V3, F3), rep3 = _io.prepare((Vs, Fs), weld_vertices=False)
    assert rep3["welded"] == 0 and len(V3) == len(Vs)
    r = qemjax.simplify((Vs, Fs), target_faces=100)
    assert r.stats["welded"] == len(Vs) - len(V) and len(r.faces) == 100


def test_weld_treats_negative_zero_as_zero():
    """The hash fast path compares bits: -0.0 and 0.0 must still count as the same coordinate."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-0.0, 0, -0.0], [0, 0, 1]])
    F = np.array([[0, 1, 2], [3, 2, 4]])
    V2, F2, merged = _io.weld(V, F)
    assert merged == 1 and len(V2) == 4 and F2.tolist() == [[0, 1, 2], [0, 2, 3]]
    V3, F3, none = _io.weld(V[:3], F[:1])  # nothing to merge: returned unchanged
    assert none == 0 and np.array_equal(V3, V[:3]) and np.array_equal(F3, F[:1])


def test_degenerate_and_duplicate_faces_are_removed_and_counted():
    V, F = shapes.icosphere(1)
    Fbad = np.concatenate([F, [[0, 0, 1]], F[:3], F[:1, ::-1]])
    (_, F2), rep = _io.prepare((V, Fbad))
    assert rep["degenerate_removed"] == 1 and rep["duplicate_removed"] == 4
    assert np.array_equal(F2, F)


def test_polygons_are_triangulated():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    m = _io.as_arrays((V, np.array([[0, 1, 2, 3]])))
    assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_unreferenced_vertices_dropped():
    V, F = shapes.icosphere(1)
    V2 = np.concatenate([V, [[5.0, 5, 5]]])
    (V3, _), rep = _io.prepare((V2, F))
    assert rep["unreferenced_removed"] == 1 and len(V3) == len(V)


def test_non_finite_unreferenced_vertices_dropped_as_others():
    """NaN or inf in a vertex no face uses is accepted and dropped; the clean-up's face means (taken at unit
    extent) are those of the mesh without it, not of a box made NaN or infinite by it."""
    V, F = shapes.icosphere(1)
    V = np.asarray(V) * 3.1 + 0.7
    (V3, F3), rep = _io.prepare((np.concatenate([[[np.nan, 0, 0], [0, np.inf, 0]], V]), F + 2))
    (_, _), alone = _io.prepare((V, F))
    assert rep["unreferenced_removed"] == 2 and np.array_equal(V3, V) and np.array_equal(F3, F)
    assert rep["vertex_map"].tolist() == [-1, -1, *range(len(V))]
    assert rep["face_means"] == alone["face_means"]
    assert np.isnan(_io.as_arrays((np.concatenate([V, [[np.nan, 0, 0]]]), F)).vertices[-1, 0])


def test_meshes_compare_by_identity():
    """A `Mesh` is a named tuple of arrays: its tuple `==` compared the arrays elementwise and raised ("truth
    value of an array is ambiguous"), and it could not be hashed. It compares and hashes by identity, and still
    unpacks as a tuple."""
    a, b = shapes.icosphere(1), shapes.icosphere(1)
    assert a == a and a != b and not a == b and not a != a
    assert a != (a.vertices, a.faces) and (a.vertices, a.faces) != a  # not a plain tuple, whatever its arrays
    assert len({a, b, a}) == 2 and hash(a) == hash(a)
    V, F = a
    assert V is a.vertices and F is a.faces and a[1] is F


def test_accepts_trimesh_and_objects():
    V, F = shapes.icosphere(2)
    tm = trimesh.Trimesh(V, F, process=False)
    a = qemjax.simplify(tm, target_faces=50)
    b = qemjax.simplify(qemjax.Mesh(V, F), target_faces=50)
    c = qemjax.simplify(a, target_faces=20)  # a result is a mesh too
    assert np.array_equal(a.faces, b.faces) and len(c.faces) == 20


def _colored(kind):
    V, F = shapes.icosphere(1)
    if kind == "vertex":
        return trimesh.Trimesh(V, F, vertex_colors=np.tile([255, 0, 0, 255], (len(V), 1)), process=False)
    if kind == "face":
        return trimesh.Trimesh(V, F, face_colors=np.tile([0, 255, 0, 255], (len(F), 1)), process=False)
    uv = np.c_[V[:, 0] * 0.5 + 0.5, V[:, 1] * 0.5 + 0.5]
    material = trimesh.visual.material.SimpleMaterial(diffuse=[200, 10, 10, 255])
    return trimesh.Trimesh(V, F, visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False)


@pytest.mark.parametrize("kind,dropped,who", [("vertex", ["vertex_colors"], "this run"),
                                              ("face", ["face_colors"], "qemjax"),
                                              ("texture", ["uv", "material"], "this run"),
                                              ("normals", ["normals"], "this run")])
def test_dropped_attributes_warn_once_and_are_recorded(kind, dropped, who):
    """attributes=None keeps positions only: what the mesh carried is named once, stored normals too (they
    went without a word); a kind another `attributes=` keeps is not kept by "this run", face colours by
    qemjax at all (and asking for colours says they are per face)."""
    mesh = _colored(kind) if kind != "normals" else trimesh.Trimesh(
        *shapes.icosphere(1), vertex_normals=shapes.icosphere(1)[0], process=False)
    with pytest.warns(UserWarning, match=f"{', '.join(dropped)}, which {who} does not keep") as record:
        r = qemjax.simplify(mesh, target_faces=40, attributes=None)
    assert len(record) == 1 and "keeps them" not in str(record[0].message)  # attributes=None: no hint
    assert r.stats["dropped"] == dropped and r.uv is None and r.colors is None and r.normals is None
    if kind == "normals":  # asked for other kinds: the hint names the one that keeps it
        with pytest.warns(UserWarning, match=r"has positions and faces only .*attributes='normal' .*keeps them"):
            assert qemjax.simplify(mesh, target_faces=40, attributes=()).stats["dropped"] == ["normals"]
    if kind == "face":
        with pytest.raises(ValueError, match="its colours are per face"):
            qemjax.simplify(mesh, target_faces=40, attributes="color")


@pytest.mark.parametrize("kind,kept", [("vertex", "colors"), ("texture", "uv")])
def test_attributes_kept_by_default(kind, kept):
    """By default UVs (with their material) and vertex colours are kept, with one warning: the one saying that
    they turn off the default's memoryless last stretch; face colours are still dropped with one."""
    with pytest.warns(UserWarning) as said:
        r = qemjax.simplify(_colored(kind), target_faces=40)
    assert [str(w.message).split(" turns off")[0] for w in said] == [f"keeping {kept.rstrip('s')}"]
    assert getattr(r, kept) is not None and r.stats["dropped"] == []
    if kind == "texture":
        assert np.array_equal(r.material.diffuse, [200, 10, 10, 255])
        assert r.to_trimesh().visual.kind == "texture"
    with pytest.warns(UserWarning, match="face_colors"):
        qemjax.simplify(_colored("face"), target_faces=40)


def test_dropped_attributes_from_files(tmp_path):
    """A textured GLB (UVs and a material) and a PLY with vertex colours: named in the warning when not
    kept (attributes=None, and `load`, which reads positions and faces only); kept by default."""
    glb, ply = tmp_path / "t.glb", tmp_path / "c.ply"
    _colored("texture").export(glb)
    _colored("vertex").export(ply)
    with pytest.warns(UserWarning, match=r"t\.glb carries uv, material"):
        r = qemjax.simplify(glb, target_faces=40, attributes=None)
    assert r.stats["dropped"] == ["uv", "material"]
    with pytest.warns(UserWarning, match=r"c\.ply carries vertex_colors"):
        m = qemjax.load(ply)
    assert m.faces.shape == (80, 3)
    assert qemjax.simplify(glb, target_faces=40).uv is not None
    assert qemjax.simplify(ply, target_faces=40).colors is not None


def test_plain_meshes_warn_nothing(tmp_path):
    V, F = shapes.icosphere(1)
    path = tmp_path / "plain.obj"
    trimesh.Trimesh(V, F, process=False).export(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for mesh in [(V, F), trimesh.Trimesh(V, F, process=False), path]:
            assert qemjax.simplify(mesh, target_faces=40).stats["dropped"] == []


def test_spot_uvs_are_reported():
    """spot.obj has vt lines (UVs, 13 charts) and no mtllib: trimesh's placeholder material is not
    reported; the UVs are named in the warning with attributes=None, left out by default for their seams
    (one warning saying how to keep them), and kept when asked for."""
    p = shared_mesh("spot/spot.obj")
    with pytest.warns(UserWarning, match="spot.obj carries uv,") as record:
        r = qemjax.simplify(p, ratio=0.5, attributes=None)
    assert len(record) == 1 and r.stats["dropped"] == ["uv"]
    with pytest.warns(UserWarning, match="uv not kept by default .*attributes='uv'") as record:
        r = qemjax.simplify(p, ratio=0.5)
    assert len(record) == 1 and r.stats["dropped"] == ["uv"] and r.uv is None
    with pytest.warns(UserWarning, match="keeping uv turns off the default method's memoryless") as record:
        r = qemjax.simplify(p, ratio=0.5, attributes="uv")  # nothing dropped: the only warning is that one
    assert len(record) == 1 and r.stats["dropped"] == [] and r.uv is not None and r.material is None
