"""Appearance attributes: wedges loaded, carried through both schedulers, seams held, written out."""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import qemjax
from qemjax._mesh import wedges as _wedges
from qemjax import metrics, shapes

from conftest import shared_mesh


def atlas_sphere(subdivisions: int = 3):
    """A bumpy sphere cube-mapped into a 3×2 UV atlas: each face's chart is the dominant axis of its
    normal (6 charts, seams between them); vertices split per chart, as trimesh loads an OBJ."""
    V, F = shapes.bumpy_sphere(subdivisions, amplitude=0.05)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ax = np.argmax(np.abs(n), axis=1)
    chart = 2 * ax + (n[np.arange(len(F)), ax] < 0)
    key = F * 6 + chart[:, None]  # one split vertex per (vertex, chart)
    uniq, inv = np.unique(key.reshape(-1), return_inverse=True)
    v, c = uniq // 6, uniq % 6
    keep = [[1, 2], [1, 2], [0, 2], [0, 2], [0, 1], [0, 1]]
    proj = np.array([V[vi, keep[ci]] for vi, ci in zip(v, c)])  # (u, 2) in [-1.1, 1.1]
    tile = np.stack([c % 3, c // 3], 1).astype(float)
    uv = (tile + 0.5 + 0.4 * proj / 1.1) / np.array([3.0, 2.0])
    mesh = trimesh.Trimesh(V[v], inv.reshape(-1, 3), process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv), validate=False)
    return mesh, chart


def _linear_uv_grid(n=24):
    V, F = shapes.grid(n)
    V = V.copy()
    V[:, 2] = 0.05 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1])
    uv = np.c_[0.3 + 0.5 * V[:, 0] - 0.2 * V[:, 1], 0.1 + 0.7 * V[:, 1] + 0.1 * V[:, 0]]
    return trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=uv))


def _uv_tile(uv):
    return np.floor(uv * np.array([3.0, 2.0])).astype(int) @ np.array([1, 3])


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_seams_hold(scheduler):
    """No output face spans two charts, every chart survives, each wedge's UV stays in its chart's tile,
    and a vertex with two or more wedges sits where an input seam vertex was."""
    mesh, _ = atlas_sphere(3)
    r = qemjax.simplify(mesh, ratio=0.1, scheduler=scheduler, attributes="uv")  # seams: kept when asked
    assert r.uv is not None and r.stats["seam_vertices_in"] > 50
    rep = metrics.seam_report(r)
    assert rep["mixed_charts"] == 0 and rep["charts_out"] == rep["charts_in"] == 6
    assert r.stats["rejected_by"]["seam"] > 0  # the rule did refuse contractions
    tile = _uv_tile(r.uv)  # each output face's corners in one tile, the tile of its input face's chart
    assert np.all(tile[r.wedge_faces] == tile[r.wedge_faces][:, :1])
    assert np.all(r.faces == r.wedge_vertex[r.wedge_faces])
    multi = np.bincount(r.wedge_vertex, minlength=len(r.vertices)) > 1
    Vin = r.input_vertices
    win = np.zeros(len(Vin), int)
    np.add.at(win, np.unique(np.c_[r.input_faces.reshape(-1), r.input_wedge_faces.reshape(-1)], axis=0)[:, 0], 1)
    # (at the run's float32 resolution: seam vertices keep their run position, which replay reproduces)
    seam_in = Vin[win > 1]
    gap = np.min(np.linalg.norm(r.vertices[multi][:, None] - seam_in[None], axis=2), axis=1)
    assert multi.sum() > 10 and gap.max() < 1e-6


def test_seam_test_can_fail(monkeypatch):
    """With the seam rule switched off the same run welds charts together: `seam_report` sees it. (The
    numpy rounds, whose rule is these methods; the compiled rounds give the same results with it on:
    tests/test_round_loops.py.)"""
    from qemjax._schedulers.parallel import selection

    monkeypatch.setattr(selection, "fits", lambda *a: False)
    monkeypatch.setattr(_wedges.Tracker, "constrain", lambda self, faces, VQ, P, x, c: np.zeros(len(P), bool))
    monkeypatch.setattr(_wedges.Tracker, "allowed", lambda self, *a: True)
    monkeypatch.setattr(_wedges.Tracker, "refused", lambda self, faces, VQ, P, X, check: np.zeros(len(P), bool))

    def merge_anyway(self, faces, VQ, a, b, x):  # every b corner takes a's first wedge
        fa, _, _, wa = self._corners(faces, a)
        fb, _, kb, _ = self._corners(faces, b)
        self.C[fb, kb] = wa[0]
    monkeypatch.setattr(_wedges.Tracker, "contract", merge_anyway)
    monkeypatch.setattr(_wedges.Tracker, "contract_many", lambda self, faces, VQ, P, X: [
        merge_anyway(self, faces, VQ, a, b, x) for (a, b), x in zip(np.asarray(P).tolist(), X)])
    mesh, _ = atlas_sphere(3)
    r = qemjax.simplify(mesh, ratio=0.1, attributes="uv")
    assert metrics.seam_report(r)["mixed_charts"] > 0


@pytest.mark.parametrize("scheduler,placement,weight,tol", [
    ("parallel", "endpoints", 0, 1e-6), ("greedy", "endpoints", 0, 1e-6), ("parallel", "optimal", 0, 2e-4),
    ("parallel", "optimal", None, 1e-4), ("greedy", "optimal", 1.0, 1e-4)])
def test_uv_follow_an_affine_field(scheduler, placement, weight, tol):
    """One chart whose UV is an affine function of x, y: every output UV is that function of its vertex.
    attribute_weights=0: interpolation along each contraction keeps an affine field exact when the placement
    lies on the segment ('endpoints': ends or midpoint); optimal placements off the segment take the UV of
    their projection on it, close (the z bumps are small). With the attribute quadric (default weights, or
    1) every face's field is the same affine map, so the solved UVs are that map at the placement (up to
    the float32 state: ~4e-5)."""
    mesh = _linear_uv_grid()
    # classic (QEM()): the default's re-fit moves positions after the attributes were interpolated, and its
    # boundary weight 10 lets optimal placements leave the grid's border further than these tolerances
    r = qemjax.simplify(mesh, ratio=0.1, scheduler=scheduler, placement=placement, attribute_weights=weight,
                        method="classic")
    P = r.vertices[r.wedge_vertex]
    want = np.c_[0.3 + 0.5 * P[:, 0] - 0.2 * P[:, 1], 0.1 + 0.7 * P[:, 1] + 0.1 * P[:, 0]]
    assert np.abs(r.uv - want).max() < tol
    # a shifted copy deviates by exactly the shift; the simplification by ~0 (the z bumps are small)
    assert metrics.attribute_deviation(mesh, r)["uv_dev_p95"] < 2e-3
    shifted = mesh.copy()
    shifted.visual = trimesh.visual.TextureVisuals(uv=mesh.visual.uv + [0.06, -0.08])
    dev = metrics.attribute_deviation(mesh, shifted, n_samples=2000)
    assert dev["uv_dev_rms"] == pytest.approx(0.1, abs=1e-9) and dev["uv_dev_max"] == pytest.approx(0.1, abs=1e-9)


def test_closest_barycentric_matches_point_triangle_distance():
    """float64 reference: the point the barycentric coordinates give is at the exact distance."""
    rng = np.random.default_rng(1)
    a, b, c = rng.normal(size=(3, 500, 3))
    p = rng.normal(size=(500, 3)) * 2
    w = metrics._appearance.closest_barycentric(p, a, b, c)
    assert np.all(w >= -1e-12) and np.allclose(w.sum(1), 1)
    q = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    d = metrics.point_triangle_distance(p, a, b, c)
    assert np.allclose(np.linalg.norm(p - q, axis=1), d, rtol=1e-9, atol=1e-12)


def test_vertex_colours_and_normals_kept(tmp_path):
    """A PLY with vertex colours and an OBJ with normals: kept, written back, colours as ColorVisuals."""
    V, F = shapes.icosphere(3)
    col = np.c_[(V * 0.5 + 0.5) * 255, np.full(len(V), 255)].astype(np.uint8)
    ply = tmp_path / "c.ply"
    trimesh.Trimesh(V, F, vertex_colors=col, process=False).export(ply)
    with pytest.warns(UserWarning) as said:  # nothing dropped: the only warning is the default's last stretch
        r = qemjax.simplify(ply, ratio=0.2)
    assert len(said) == 1 and str(said[0].message).startswith("keeping color turns off the default method's")
    assert r.colors is not None and r.uv is None and r.stats["dropped"] == []
    P = r.vertices[r.wedge_vertex]  # colour linear in position, interpolated along the surface: close
    assert np.abs(r.colors[:, :3] - (P / np.linalg.norm(P, axis=1, keepdims=True) * 0.5 + 0.5)).max() < 0.1
    tm = r.to_trimesh()
    assert tm.visual.kind == "vertex" and len(tm.vertices) == len(r.vertices)  # one chart: no splits
    obj = tmp_path / "n.obj"
    trimesh.Trimesh(V, F, vertex_normals=V, process=False).export(obj, include_normals=True)
    r = qemjax.simplify(obj, ratio=0.2, attributes="normal")
    assert r.normals is not None and np.allclose(np.linalg.norm(r.normals, axis=1), 1)
    Pn = r.vertices[r.wedge_vertex]
    assert np.min(np.einsum("ij,ij->i", r.normals, Pn / np.linalg.norm(Pn, axis=1, keepdims=True))) > 0.95


def test_attribute_options_are_checked(tmp_path):
    mesh, _ = atlas_sphere(2)
    with pytest.raises(ValueError, match="attributes must be"):
        qemjax.simplify(mesh, ratio=0.5, attributes="texture")
    with pytest.raises(ValueError, match="carries no color"):
        qemjax.simplify(mesh, ratio=0.5, attributes="color")
    with pytest.raises(ValueError, match="texture= needs UVs"):
        qemjax.simplify(shapes.icosphere(2), ratio=0.5, texture=tmp_path / "x.png")
    with pytest.raises(ValueError, match="could not read texture"):
        qemjax.simplify(mesh, ratio=0.5, texture=tmp_path / "missing.png")
    with pytest.warns(UserWarning, match="does not keep appearance attributes"):
        r = qemjax.simplify(mesh, ratio=0.5, method="area", attributes="uv")
    assert r.uv is None and "uv" in r.stats["dropped"]
    with pytest.warns(UserWarning, match="carries uv, which this run does not keep"):
        r = qemjax.simplify(mesh, ratio=0.5, attributes=None)
    assert r.uv is None and r.stats["dropped"] == ["uv"]


def test_attribute_settings_are_frozen_data_checked_when_made():
    """`Attributes` is frozen data: it could not be hashed with weights given as a dict, and took a list, a
    bad kind, weights of the wrong type or a texture that is no image unchecked (they failed later, inside the
    run, or never)."""
    import pickle

    from PIL import Image

    a = qemjax.Attributes("uv", {"uv": 0.5})
    assert a == qemjax.Attributes("uv", {"uv": 0.5}) and hash(a) == hash(qemjax.Attributes("uv", {"uv": 0.5}))
    assert a != qemjax.Attributes("uv", {"uv": 0.6}) and a != qemjax.Attributes("color", {"uv": 0.5})
    assert len({a, qemjax.Attributes("uv", {"uv": 0.5}), qemjax.Attributes()}) == 2
    assert pickle.loads(pickle.dumps(a)) == a and dataclasses.replace(a, texture="t.png").texture == "t.png"
    weights = {"uv": 0.5}
    b = qemjax.Attributes("uv", weights)
    weights["uv"] = 2.0  # the caller's dict, changed after: not the settings
    assert b.attribute_weights == {"uv": 0.5} and b == a
    with pytest.raises(TypeError, match="cannot be changed"):
        b.attribute_weights["uv"] = 3.0
    assert qemjax.Attributes(["uv", "color"]).attributes == ("uv", "color")  # a list is a tuple, hashable
    assert qemjax.Attributes({"normal", "uv"}).attributes == ("uv", "normal")
    assert hash(qemjax.Attributes(["uv"], 0.2)) == hash(qemjax.Attributes(("uv",), 0.2))
    image = Image.new("RGB", (2, 2))
    c = qemjax.Attributes("uv", texture=image)
    assert c == c and c != qemjax.Attributes("uv", texture=Image.new("RGB", (2, 2))) and hash(c) == hash(c)
    for kw, message in [(dict(attributes="uvs"), "attributes must be 'auto', None, or kinds from"),
                        (dict(attributes=["uv", "colour"]), "attributes must be .* got 'colour'$"),
                        (dict(attributes=3), "attributes must be .* got 3$"),
                        (dict(attribute_weights=[0.5]), r"^attribute_weights takes one number w >= 0 for every "
                                                        r"kind or \{kind: w\}, got list \[0.5\]$"),
                        (dict(attribute_weights={"uvs": 1.0}), "attribute_weights: unknown kind 'uvs'"),
                        (dict(attribute_weights=-1.0), "attribute_weights must be finite numbers >= 0"),
                        (dict(texture=["t.png"]), "^texture= takes an image file's path or a PIL image, got list$")]:
        with pytest.raises(ValueError, match=message) as err:
            qemjax.Attributes(**kw)
        assert "\n" not in str(err.value)


def test_seams_hold_a_mesh_above_its_target():
    """Six charts cannot go below their seam skeleton: the run stops above a tiny target with a warning
    that names the seams and suggests attributes=None."""
    mesh, _ = atlas_sphere(2)
    with pytest.warns(UserWarning, match="seam"):
        r = qemjax.simplify(mesh, target_faces=8, attributes="uv")
    assert r.stop_reason == "blocked" and len(r.faces) > 8 and r.stats["blocked_by"]["seam"] > 0


@pytest.mark.slow  # a real mesh
def test_spot_writes_textured_obj_and_glb(tmp_path):
    """spot -> 10 %: an OBJ (with MTL and texture) and a GLB that reload with UVs and the image."""
    from qemjax import _cli

    src = shared_mesh("spot/spot.obj")
    tex = src.parent / "spot_texture.png"
    for name in ("spot10.obj", "spot10.glb"):
        assert _cli.main(["simplify", str(src), str(tmp_path / name), "--ratio", "0.1", "--texture", str(tex),
                          "--quiet"]) == 0
        m = trimesh.load(tmp_path / name, process=False, force="mesh")
        assert len(m.faces) == 586 and m.visual.kind == "texture" and len(m.visual.uv) == len(m.vertices)
        mat = m.visual.material
        img = getattr(mat, "image", None) or getattr(mat, "baseColorTexture", None)
        assert img is not None and img.size == (1024, 1024)
    assert (tmp_path / "spot10.mtl").exists() and (tmp_path / "spot10.png").exists()
    assert "map_Kd spot10.png" in (tmp_path / "spot10.mtl").read_text()


# -- the attribute cost model (`_costs.attributes`) -------------------------------------------------------

def _random_patch(seed=3, m=3):
    rng = np.random.default_rng(seed)
    V, F = shapes.grid(4)
    V = V + rng.normal(scale=0.05, size=V.shape)
    S = rng.random((len(F), 3, m))
    w = rng.random(len(F)) + 0.5
    return V, F, S, w


def test_attribute_state_matches_face_sum_float64():
    """float64 reference: the stored state (11 + 4m floats per vertex) evaluates, at any (p, s), to the
    sum over the vertex's faces of w·[(n·(p − p0))² + Σ_j (g_j·p + d_j − s_j)²], the fields fitted through
    the corners; and the reduced quadric equals that minimised over s."""
    from qemjax._costs import attributes as at

    V, F, S, w = _random_patch()
    m = S.shape[2]
    st = at.attribute_state(V, F, S, w)
    P = V[F]
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    g, d = at.face_fields(P, S)
    assert np.allclose(np.einsum("fji,fki->fkj", g, P) + d[:, None, :], S)  # through the corner values
    assert np.allclose(np.einsum("fji,fi->fj", g, n), 0)  # in the face's plane
    rng = np.random.default_rng(0)
    for v in (0, 7, 12):
        faces = np.flatnonzero(np.any(F == v, axis=1))
        row = np.r_[V[v], st[v]]
        row[3:13] += 0  # the geometric plane part is added by the model (QEM's init); here: planes by hand
        A = sum(w[f] * np.outer(n[f], n[f]) for f in faces)
        row[3:9] += [A[0, 0], A[0, 1], A[0, 2], A[1, 1], A[1, 2], A[2, 2]]
        for _ in range(3):
            p, s = V[v] + rng.normal(scale=0.2, size=3), rng.random(m)
            want = sum(w[f] * ((n[f] @ (p - P[f, 0])) ** 2 + np.sum((g[f] @ p + d[f] - s) ** 2)) for f in faces)
            u = p - V[v]
            q = row[3:]
            Am = np.array([[q[0], q[1], q[2]], [q[1], q[3], q[4]], [q[2], q[4], q[5]]])
            G = q[11:].reshape(m, 4)
            got = u @ Am @ u + 2 * q[6:9] @ u + q[9] + q[10] * s @ s - 2 * s @ (G[:, :3] @ u + G[:, 3])
            assert got == pytest.approx(want, rel=1e-10, abs=1e-12)
            smin = (G[:, :3] @ u + G[:, 3]) / q[10]
            want_min = sum(w[f] * ((n[f] @ (p - P[f, 0])) ** 2 + np.sum((g[f] @ p + d[f] - smin) ** 2))
                           for f in faces)
            assert at.solve_host(np.r_[V[v], q], np.r_[V[v], 0 * q], p, m)[0] == pytest.approx(want_min, rel=1e-9)


def test_attribute_kernels_match_numpy_float64():
    """The jitted price and merge against the float64 numpy twin (`solve_host`, `_np_translate`): the
    price's cost is the reduced quadric at its x, a solve-branch x is its stationary point, and the
    merged state is the two states summed in x's frame."""
    from qemjax._costs import attributes as at

    V, F, S, w = _random_patch(5, 2)
    m = 2
    st = at.attribute_state(V, F, S, w)
    E = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    VS = np.c_[V, st]
    with jax.enable_x64(True):
        out = np.asarray(at.price_pairs(m, False, jnp.asarray(VS), jnp.asarray(E), jnp.asarray(False),
                                        jnp.asarray(1e-9), jnp.asarray(2.0)))
        x = out[:3].T
        merged = np.asarray(at.merge_pairs(m, jnp.asarray(VS), jnp.asarray(E), jnp.asarray(x)))
    for k, (a, b) in enumerate(E):
        cost, s = at.solve_host(VS[a], VS[b], x[k], m)
        assert out[3, k] == pytest.approx(cost, rel=1e-8, abs=1e-12)
        want = at._np_translate(VS[a, 3:], x[k] - V[a], m) + at._np_translate(VS[b, 3:], x[k] - V[b], m)
        assert np.allclose(merged[k], want, rtol=1e-9, atol=1e-12)
        if out[4, k] == 0:  # solved: the reduced quadric's gradient vanishes at x
            eps = 1e-6
            grad = [(at.solve_host(VS[a], VS[b], x[k] + e, m)[0] - at.solve_host(VS[a], VS[b], x[k] - e, m)[0])
                    / (2 * eps) for e in np.eye(3) * eps]
            assert np.abs(grad).max() < 1e-5


def test_attribute_weights_do_not_recompile_and_matter():
    """A new weight is a new value in the state, not a new kernel; the weight changes the result (UV
    deviation falls, at some geometric error) and 0 gives the positions-only cost."""
    mesh, _ = atlas_sphere(3)
    r1 = qemjax.simplify(mesh, ratio=0.2, attributes="uv", attribute_weights=1.0)
    r2 = qemjax.simplify(mesh, ratio=0.2, attributes="uv", attribute_weights={"uv": 3.0})
    assert r2.stats["compilations"] == 0
    r0 = qemjax.simplify(mesh, ratio=0.2, attributes="uv", attribute_weights=0)
    assert r0.stats["model"].get("channels") is None and r1.stats["model"]["channels"] == 2
    assert not np.array_equal(r1.vertices, r2.vertices)
    with pytest.raises(ValueError, match="attribute_weights"):
        qemjax.simplify(mesh, ratio=0.2, attribute_weights=-1)
    with pytest.raises(ValueError, match="unknown kind"):
        qemjax.simplify(mesh, ratio=0.2, attribute_weights={"texture": 1})


@pytest.mark.slow
def test_colour_term_lowers_colour_error():
    """A sphere coloured by a sharp pattern: with the colour term, the colour deviation is lower than
    with positions-only costs (interpolated colours)."""
    V, F = shapes.icosphere(4)
    col = np.c_[0.5 + 0.5 * np.sign(np.sin(6 * V[:, 0]) * np.sin(6 * V[:, 1])), 0.5 + 0.5 * V[:, 2], 0.2 * np.ones(len(V)), np.ones(len(V))]
    mesh = trimesh.Trimesh(V, F, vertex_colors=(col * 255).astype(np.uint8), process=False)
    dev = {}
    for w in (0.0, 1.0):
        r = qemjax.simplify(mesh, ratio=0.1, attribute_weights=w)
        dev[w] = metrics.attribute_deviation(mesh, r, kind="color")["color_dev_mean"]
    assert dev[1.0] < 0.9 * dev[0.0], dev


def test_a_texture_given_as_an_array_is_refused_in_one_line(tmp_path):
    """texture= takes a path or a PIL image; an array was printed whole into a 49-line error."""
    qemjax.shapes.write_examples(tmp_path, subdivisions=2)
    with pytest.raises(ValueError, match=r"^texture= takes an image file's path or a PIL image, got ndarray") as err:
        qemjax.simplify(str(tmp_path / "textured.obj"), ratio=0.3, texture=np.zeros((64, 64, 3), np.uint8))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("scheduler", ["greedy", "parallel"])
def test_kept_colours_stay_in_the_unit_cube(scheduler):
    """A colour placed by its quadric's optimum (the colour term) could fall just outside [0, 1] (a green of
    -0.002 here), where `SimplifyResult.colors` promises RGBA in [0, 1]."""
    V, F = shapes.bumpy_sphere(4)
    rgb = np.clip(0.5 + 0.5 * V / np.abs(V).max(), 0, 1)
    mesh = trimesh.Trimesh(V, F, vertex_colors=(np.c_[rgb, np.ones(len(V))] * 255).astype(np.uint8), process=False)
    r = qemjax.simplify(mesh, ratio=0.1, method="classic", scheduler=scheduler, attribute_weights=1.0)
    assert r.colors is not None and r.colors.min() >= 0.0 and r.colors.max() <= 1.0
    assert r.colors[:, :3].min() < 0.02 and r.colors[:, :3].max() > 0.98  # the range is kept, not squeezed


def test_attribute_model_with_rank_placement_and_terms():
    """placement='rank' and the terms (regularize, area_weight) wrap the attribute model; repeated calls
    compile nothing new (the terms take its price as a static argument: one object per shape)."""
    mesh, _ = atlas_sphere(2)
    for kw in (dict(placement="rank"), dict(regularize=0.1), dict(area_weight=10.0)):
        said = f"setting {next(iter(kw))}" if "placement" not in kw else "keeping uv"  # the stretch off: why
        with pytest.warns(UserWarning, match=f"^{said} turns off the default method's memoryless"):
            r = qemjax.simplify(mesh, ratio=0.3, attributes="uv", **kw)
            again = qemjax.simplify(mesh, ratio=0.3, attributes="uv", **kw)
        assert r.uv is not None and metrics.seam_report(r)["mixed_charts"] == 0
        assert again.stats["compilations"] == 0, kw


def test_seam_edges_are_the_chart_borders():
    """`_wedges.seam_edges` (constrained like boundaries) finds exactly the edges between two charts."""
    mesh, chart = atlas_sphere(2)
    from qemjax._io import mesh as _io

    (V, F), rep = _io.prepare(mesh, attributes="uv")
    E = _wedges.seam_edges(F, rep["attributes"].corners)
    he = np.c_[F[:, [0, 1, 2]].reshape(-1), F[:, [1, 2, 0]].reshape(-1)]
    key = np.sort(he, 1) @ np.array([len(V), 1])
    fc = np.repeat(chart, 3)
    border = set()
    for k in np.unique(key):
        if len(set(fc[key == k])) > 1:
            border.add(int(k))
    assert len(E) > 20 and set((E @ np.array([len(V), 1])).tolist()) == border


def test_attribute_state_equals_a_corner_loop():
    """`attribute_state` (bincount per column) against the per-corner accumulation it replaced, in the
    same order: equal to the last bit, on random float64 input."""
    from qemjax._costs.attributes import attribute_state, face_fields

    V, F = shapes.bumpy_sphere(2)
    rng = np.random.default_rng(0)
    S, w = rng.normal(size=(len(F), 3, 4)), rng.random(len(F))
    n, m = len(V), S.shape[2]
    g, _ = face_fields(V[F], S)
    extra, qa = np.zeros((n, 1 + 4 * m)), np.zeros((n, 10))
    gg = np.einsum("fji,fjk->fik", g, g)[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    for k in range(3):
        v, s = F[:, k], S[:, k]
        np.add.at(extra[:, 0], v, w)
        for j in range(m):
            np.add.at(extra[:, 1 + 4 * j: 4 + 4 * j], v, w[:, None] * g[:, j])
            np.add.at(extra[:, 4 + 4 * j], v, w * s[:, j])
        np.add.at(qa[:, :6], v, w[:, None] * gg)
        np.add.at(qa[:, 6:9], v, w[:, None] * np.einsum("fj,fji->fi", s, g))
        np.add.at(qa[:, 9], v, w * np.sum(s * s, 1))
    assert np.array_equal(attribute_state(V, F, S, w), np.concatenate([qa, extra], 1))


@pytest.mark.parametrize("kw", [dict(attributes="uv"), dict(attributes="uv", attribute_weights=0.0)])
def test_vectorised_wedge_contractions_equal_the_per_pair_ones(monkeypatch, kw):
    """`Tracker.contract_many` does pairs of single-wedge vertices together in numpy; one `contract` per
    pair (the rule as written) gives the same wedges and values, seams and all."""
    mesh, _ = atlas_sphere(3)
    fast = qemjax.simplify(mesh, ratio=0.1, **kw)

    def one_by_one(self, faces, VQ, P, X):
        for (a, b), x in zip(np.asarray(P).tolist(), np.asarray(X)):
            self.contract(faces, VQ, a, b, x)
    monkeypatch.setattr(_wedges.Tracker, "contract_many", one_by_one)
    slow = qemjax.simplify(mesh, ratio=0.1, **kw)
    for name in ("vertices", "faces", "wedge_faces", "wedge_vertex"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    np.testing.assert_allclose(fast.uv, slow.uv, rtol=0, atol=1e-15)


def test_textured_runs_refit_with_their_uvs_carried():
    """The default re-fits with UVs kept too: seam vertices stay where the contractions put them, the other
    wedges' UVs follow their vertices' moves (`refit.carry_uv`), a wedge whose vertex did not move keeps its
    UV bit for bit, faces and wedges are the run's without the re-fit; the geometry comes closer to the input
    and the texture deviation is no larger than without the re-fit, and smaller than with the UVs left behind."""
    mesh, _ = atlas_sphere(4)
    kept = qemjax.simplify(mesh, ratio=0.1, attributes="uv")
    base = qemjax.simplify(mesh, ratio=0.1, attributes="uv", refit=0)
    assert kept.stats["refit"] == 1 and "refit_skipped" not in kept.stats
    assert "re-fit skipped" not in kept.summary()
    for name in ("faces", "wedge_faces", "wedge_vertex"):
        assert np.array_equal(getattr(kept, name), getattr(base, name)), name
    seam = np.bincount(kept.wedge_vertex, minlength=len(kept.vertices)) > 1
    assert seam.any() and np.array_equal(kept.vertices[seam], base.vertices[seam])
    moved = np.any(kept.vertices != base.vertices, axis=1)
    assert moved.sum() > len(moved) // 4
    still = ~moved[kept.wedge_vertex]
    assert np.array_equal(kept.uv[still], base.uv[still]) and not np.array_equal(kept.uv, base.uv)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert metrics.surface_distance((V, F), kept)["rms_rel"] < 0.95 * metrics.surface_distance((V, F), base)["rms_rel"]
    left = dataclasses.replace(kept, uv=base.uv)  # the re-fit's positions, the UVs as they were
    dev = {k: metrics.attribute_deviation(mesh, r, n_samples=50_000)
           for k, r in (("carried", kept), ("no re-fit", base), ("left", left))}
    for stat in ("uv_dev_mean", "uv_dev_p95"):
        assert dev["carried"][stat] <= dev["no re-fit"][stat], (stat, dev)
        assert dev["carried"][stat] < dev["left"][stat], (stat, dev)
    batch = qemjax.simplify_batch(mesh, [{"ratio": 0.1, "attributes": "uv"}, {"ratio": 0.2, "attributes": "uv"}])
    assert np.array_equal(batch[0].vertices, kept.vertices) and np.array_equal(batch[0].uv, kept.uv)  # `refit_all`


def test_carry_uv_against_an_affine_map():
    """`refit.carry_uv` on a random triangulated plane (rotated, float64) whose UVs are one affine map of the
    position: moves within the plane give the map at the new positions (to rounding), moves across it change
    nothing, unmoved vertices and the wedges of a zero-area face keep their UVs bit for bit; a second chart
    (split wedges) is moved by its own map."""
    from scipy.spatial import Delaunay

    from qemjax._pipeline.refit import carry_uv

    rng = np.random.default_rng(7)
    P2 = rng.random((60, 2))
    F = Delaunay(P2).simplices.astype(np.int64)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    X0 = np.c_[P2, np.zeros(len(P2))] @ R.T
    A = rng.normal(size=(2, 3))
    c = rng.normal(size=2)
    # two charts: faces left of x = 0.5 use the map A, the others 2A (wedges split where they meet)
    right = P2[F].mean(1)[:, 0] > 0.5
    key = F * 2 + right[:, None]
    uniq, WF = np.unique(key.reshape(-1), return_inverse=True)
    WF = WF.reshape(-1, 3)
    wv, chart = uniq // 2, uniq % 2
    scale = np.where(chart == 1, 2.0, 1.0)[:, None]
    uv = scale * (X0[wv] @ A.T) + c
    inplane = np.c_[rng.normal(scale=0.01, size=(len(P2), 2)), np.zeros(len(P2))] @ R.T
    still = rng.random(len(P2)) < 0.3
    inplane[still] = 0
    X1 = X0 + inplane
    out = carry_uv(X0, X1, F, WF, wv, uv)
    np.testing.assert_allclose(out, scale * (X1[wv] @ A.T) + c, rtol=0, atol=1e-12)
    assert np.array_equal(out[still[wv]], uv[still[wv]])
    across = X0 + rng.normal(scale=0.01, size=(len(P2), 1)) * R[:, 2]
    np.testing.assert_allclose(carry_uv(X0, across, F, WF, wv, uv), uv, rtol=0, atol=1e-12)
    # a wedge whose only face has no area keeps its UV
    X0z = np.r_[X0, X0[:1], X0[:1] + 1e-3 * R[:, 0], X0[:1] + 2e-3 * R[:, 0]]
    Fz = np.r_[F, [[len(X0), len(X0) + 1, len(X0) + 2]]]
    WFz = np.r_[WF, [[len(uv), len(uv) + 1, len(uv) + 2]]]
    wvz = np.r_[wv, len(X0), len(X0) + 1, len(X0) + 2]
    uvz = np.r_[uv, rng.random((3, 2))]
    X1z = X0z + 0.01
    assert np.array_equal(carry_uv(X0z, X1z, Fz, WFz, wvz, uvz)[-3:], uvz[-3:])


@pytest.mark.parametrize("m", [1, 2])
def test_attribute_state_compiled_is_the_numpy_sums_bit_for_bit(m, monkeypatch):
    """`attribute_sums.corner_sums` against `attribute_state`'s numpy code (the compiled path switched off),
    on random faces with shared corners, zero and negative-zero values, thin faces and zero weights: every
    bit, signed zeros included."""
    from qemjax._costs import attributes as A, attribute_sums

    rng = np.random.default_rng(m)
    n, f = 150, 400
    V = rng.normal(size=(n, 3))
    V[:10] = V[10:20]  # coincident corners: thin faces (gradients 0)
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(f)])
    S = rng.normal(size=(f, 3, m))
    S[rng.random(S.shape) < 0.2] = 0.0
    S[rng.random(S.shape) < 0.2] = -0.0
    w = rng.random(f)
    w[::9] = 0.0
    got = A.attribute_state(V, F, S, w)
    monkeypatch.setattr(attribute_sums, "MAX_CHANNELS", 0)  # the numpy code
    want = A.attribute_state(V, F, S, w)
    assert got.shape == want.shape == (n, 11 + 4 * m)
    assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))


def test_seam_edges_are_the_four_key_sort_and_unique_rows():
    """`wedges.seam_edges` against a four-key lexsort and `np.unique(axis=0)` on random faces and wedges."""
    from qemjax._mesh.wedges import seam_edges

    rng = np.random.default_rng(2)
    for _ in range(300):
        n, m = int(rng.integers(3, 60)), int(rng.integers(0, 120))
        F, C = rng.integers(0, n, (m, 3)), rng.integers(0, int(rng.integers(1, 2 * n + 2)), (m, 3))
        u, v = F[:, [0, 1, 2]].reshape(-1), F[:, [1, 2, 0]].reshape(-1)
        wu, wv = C[:, [0, 1, 2]].reshape(-1), C[:, [1, 2, 0]].reshape(-1)
        lo, hi, wlo, whi = np.minimum(u, v), np.maximum(u, v), np.where(u > v, wv, wu), np.where(u > v, wu, wv)
        o = np.lexsort((whi, wlo, hi, lo))
        lo, hi, wlo, whi = lo[o], hi[o], wlo[o], whi[o]
        d = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1]) & ((wlo[1:] != wlo[:-1]) | (whi[1:] != whi[:-1]))
        E = np.stack([lo[1:][d], hi[1:][d]], 1)
        want = np.unique(E, axis=0) if len(E) else np.zeros((0, 2), np.int64)
        got = seam_edges(F, C)
        assert got.shape == want.shape and np.array_equal(got, want)


def test_wedge_rows_are_every_corners_unique_rows():
    """`wedges._wedge_rows` (distinct vertex/source pairs first) against `_unique_rows` of every corner's
    [vertex, values] row: the same rows and indices, bit for bit, with values that differ only in the sign
    of a zero (the first corner's stays), NaNs, and shared values across source vertices."""
    from qemjax._mesh.wedges import _unique_rows, _wedge_rows

    rng = np.random.default_rng(5)
    for trial in range(200):
        ns, n, k = int(rng.integers(1, 40)), int(rng.integers(1, 20)), int(rng.integers(0, 150))
        M = rng.choice([0.0, -0.0, 0.5, 1.0, np.nan] if trial % 2 else [0.0, -0.0, 0.25], size=(ns, 2))
        src = rng.integers(0, ns, k)
        rep = rng.integers(0, n, k).astype(np.int64)
        want_u, want_i = _unique_rows(np.concatenate([rep.reshape(-1, 1).astype(np.float64), M[src]], 1))
        got_u, got_i = _wedge_rows(rep, src, M)
        assert got_u.shape == want_u.shape and np.array_equal(got_i, want_i), trial
        assert np.array_equal(got_u.view(np.int64), want_u.view(np.int64)), trial  # bits, signed zeros too


def test_face_systems_are_numpys():
    """`attribute_sums.face_systems` against the numpy code it replaces (np.cross, np.linalg.norm, the
    normal divided where non-zero), bit for bit: random faces, degenerate ones (zero normal), signed zeros."""
    from qemjax._costs import attribute_sums

    rng = np.random.default_rng(9)
    for trial in range(20):
        f, m = int(rng.integers(1, 300)), int(rng.integers(1, 4))
        P = rng.normal(size=(f, 3, 3)) * 10.0 ** rng.integers(-3, 4)
        P[::7, 2] = P[::7, 1]  # two corners at one point: no normal
        P[::11] = rng.choice([0.0, -0.0, 1.0], size=P[::11].shape)
        S = rng.normal(size=(f, 3, m))
        n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
        nn = np.linalg.norm(n, axis=1, keepdims=True)
        n = n / np.where(nn > 0, nn, 1.0)
        M = np.zeros((f, 4, 4))
        M[:, :3, :3], M[:, :3, 3], M[:, 3, :3] = P, 1.0, n
        rhs = np.zeros((f, 4, m))
        rhs[:, :3] = S
        gM, grhs, gnn = attribute_sums.face_systems(P, S)
        for g, w in ((gM, M), (grhs, rhs), (gnn, nn[:, 0])):
            assert np.array_equal(g.view(np.int64), w.view(np.int64)), trial
