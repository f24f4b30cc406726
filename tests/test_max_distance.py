"""``simplify(max_distance=D)`` / ``max_distance_rel=R`` (`qemjax._pipeline.bound`): the result lies within
the bound of the input both ways at the samples (input vertices and face centroids to the output, output
vertices and face centroids to the input), recomputed here by brute force in float64 mesh units with a
point-triangle distance of this file's own; combined with face targets; errors; the command line, batches
and sweeps."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from conftest import assert_valid
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_properties import meshes

import qemjax
from qemjax import _cli, shapes

SETTINGS = settings(max_examples=12, deadline=None, derandomize=True, database=None, print_blob=True,
                    suppress_health_check=[HealthCheck.too_slow])
# the test's own float64 arithmetic in mesh units, times the input's largest extent: the check inside qemjax
# keeps its figure below the bound by more than this (`bound.SLACK`)
ROUNDING = 1e-13


def _segment(P, a, b):
    """(q, t) distances from points P (q,3) to segments a-b (t,3)."""
    e = b - a
    w = P[:, None, :] - a[None]
    e2 = np.sum(e * e, axis=1)
    t = np.clip(np.einsum("qtk,tk->qt", w, e) / np.where(e2 > 0, e2, 1.0), 0.0, 1.0)
    return np.linalg.norm(w - t[..., None] * e[None], axis=2)


def brute_distance(P, V, F):
    """(q,) distance from each point to the nearest point of the triangles (V, F), all pairs: the plane's
    distance where the projection falls inside the triangle, else the nearest of its three edges."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    nn = np.sum(n * n, axis=1)
    w = P[:, None, :] - a[None]
    s = np.einsum("qtk,tk->qt", w, n) / np.where(nn > 0, nn, 1.0)
    proj = w - s[..., None] * n[None]  # the projection onto the plane, from a
    # barycentric coordinates of the projection by areas against the normal
    u = np.einsum("qtk,tk->qt", np.cross(proj, (c - a)[None]), n) / np.where(nn > 0, nn, 1.0)
    v = np.einsum("qtk,tk->qt", np.cross((b - a)[None], proj), n) / np.where(nn > 0, nn, 1.0)
    inside = (u >= 0) & (v >= 0) & (u + v <= 1) & (nn > 0)[None]
    plane = np.abs(s) * np.sqrt(nn)[None]
    edges = np.minimum(np.minimum(_segment(P, a, b), _segment(P, b, c)), _segment(P, a, c))
    return np.where(inside, np.minimum(plane, edges), edges).min(axis=1)


def two_way(res) -> float:
    """The largest distance of either way's samples, float64 mesh units."""
    V, F, X, G = res.input_vertices, res.input_faces, res.vertices, res.faces
    into = np.concatenate([V[np.unique(F)], V[F].mean(axis=1)])
    back = np.concatenate([X[np.unique(G)], X[G].mean(axis=1)])
    return max(brute_distance(into, X, G).max(), brute_distance(back, V, F).max())


def test_the_reference_distance_is_exact():
    """This file's brute force agrees with qemjax's point-triangle distance (a check of the checker)."""
    from qemjax._mesh.pointtri import point_triangle_distance

    rng = np.random.default_rng(3)
    V, F = rng.standard_normal((12, 3)), rng.integers(0, 12, (9, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    P = 2 * rng.standard_normal((200, 3))
    want = point_triangle_distance(P[:, None], V[F[:, 0]][None], V[F[:, 1]][None], V[F[:, 2]][None]).min(1)
    np.testing.assert_allclose(brute_distance(P, V, F), want, rtol=1e-12, atol=1e-12)


def diagonal(V) -> float:
    return float(np.sqrt(np.sum((V.max(0) - V.min(0)) ** 2)))


def _check(res, D):
    assert_valid(res, None, res.input_vertices, res.input_faces)
    s = res.stats
    extent = float(np.max(res.input_vertices.max(0) - res.input_vertices.min(0)))
    assert s["max_distance"] == D
    assert s["distance_two_way_max"] <= D
    assert two_way(res) <= D + ROUNDING * extent
    # the measured distance is the returned geometry's: its input->output samples are among the checked
    assert s["distance_max"] <= s["distance_two_way_max"] + ROUNDING * extent
    assert len(res.faces) == s["faces_out"] and len(res.history) == s["contractions"]
    assert res.record.faces_out == len(res.faces)
    assert np.array_equal(res.replay(contractions=len(res.history)).faces, res.faces)
    per_round = s.get("faces_per_round")  # the parallel scheduler's: the returned level's rounds, cut or not
    if isinstance(per_round, list):
        assert len(per_round) == s["rounds_contracting"] and per_round[-1:] in ([], [len(res.faces)])


@SETTINGS
@given(mesh=meshes(), rel=st.sampled_from([0.0, 1e-4, 2e-3, 0.01, 0.05, 0.3]),
       ratio=st.sampled_from([None, 0.05, 0.5]), scheduler=st.sampled_from(["parallel", "greedy"]))
def test_random_meshes_stay_within_the_bound(mesh, rel, ratio, scheduler):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stopping above the target warns; checked below
        res = qemjax.simplify(mesh, max_distance_rel=rel, ratio=ratio, scheduler=scheduler)
    D = rel * diagonal(res.input_vertices)
    _check(res, D)
    if ratio is not None and res.stop_reason != "max_distance":
        assert len(res.faces) >= res.stats["target_faces"]


@pytest.fixture(scope="module")
def bumpy():
    return shapes.bumpy_sphere(3)  # 1280 faces


def test_the_tighter_of_target_and_bound_stops(bumpy):
    loose = qemjax.simplify(bumpy, target_faces=300, max_distance_rel=0.5)
    assert loose.stop_reason == "target" and len(loose.faces) == 300
    _check(loose, loose.stats["max_distance"])
    with pytest.warns(UserWarning, match="above the target of 100: a further contraction would put the output "
                                         "more than max_distance"):
        tight = qemjax.simplify(bumpy, target_faces=100, max_distance_rel=0.002)
    assert tight.stop_reason == "max_distance" and len(tight.faces) > 100
    _check(tight, tight.stats["max_distance"])
    alone = qemjax.simplify(bumpy, max_distance_rel=0.002)  # no target: as far as the bound allows
    assert alone.stop_reason == "max_distance" and alone.stats["target_faces"] == 0
    _check(alone, alone.stats["max_distance"])


def test_relative_is_absolute_times_the_diagonal(bumpy):
    rel = qemjax.simplify(bumpy, max_distance_rel=0.004)
    D = 0.004 * diagonal(rel.input_vertices)
    ab = qemjax.simplify(bumpy, max_distance=D)
    assert rel.stats["max_distance"] == ab.stats["max_distance"] == D
    assert ab.stats["max_distance_rel"] == pytest.approx(0.004, rel=1e-12)
    assert np.array_equal(rel.faces, ab.faces) and np.array_equal(rel.vertices, ab.vertices)


def test_zero_returns_the_input(bumpy):
    with pytest.warns(UserWarning, match="above the target of 640"):
        res = qemjax.simplify(bumpy, max_distance=0.0, ratio=0.5)
    assert len(res.faces) == len(bumpy[1]) and res.stop_reason == "max_distance"
    assert res.stats["distance_two_way_max"] == 0.0 and res.stats["distance_max"] == 0.0
    assert len(res.history) == 0


@pytest.mark.parametrize("kw, match", [
    (dict(max_distance=-1.0), "max_distance must be a finite distance >= 0"),
    (dict(max_distance=float("nan")), "max_distance must be a finite distance >= 0"),
    (dict(max_distance_rel=float("inf")), "max_distance_rel must be a finite distance >= 0"),
    (dict(max_distance="1"), "max_distance must be a number"),
    (dict(max_distance_rel=True), "max_distance_rel must be a number"),
    (dict(max_distance=1.0, max_distance_rel=0.1), "give at most one of max_distance"),
    (dict(max_distance=1.0, method="esqem"), "split_factor=None"),
])
def test_bad_values_are_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        qemjax.simplify(shapes.icosphere(2), **kw)


def test_lod_chain_refuses_it():
    with pytest.raises(ValueError, match="not max_distance"):
        qemjax.lod_chain(shapes.icosphere(2), max_distance=0.1)


def test_batch_equals_alone(bumpy):
    configs = [dict(max_distance_rel=0.003, ratio=0.1), dict(max_distance_rel=0.05, ratio=0.1),
               dict(ratio=0.1)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        batch = qemjax.simplify_batch(bumpy, configs)
        alone = [qemjax.simplify(bumpy, **c) for c in configs]
    for b, a in zip(batch, alone):
        assert b.stop_reason == a.stop_reason
        assert np.array_equal(b.faces, a.faces) and np.array_equal(b.vertices, a.vertices)
    assert batch[0].stop_reason == "max_distance" and batch[1].stop_reason == "target"


def test_command_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("QEMJAX_NO_CACHE", "1")
    V, F = shapes.bumpy_sphere(3)
    src, dst = tmp_path / "in.ply", tmp_path / "out.ply"
    trimesh.Trimesh(V, F, process=False).export(src)
    assert _cli.main(["simplify", str(src), str(dst), "--max-distance-rel", "0.003", "--quiet"]) == 0
    out = trimesh.load(dst, process=False)
    want = qemjax.simplify((V, F), max_distance_rel=0.003)
    assert len(out.faces) == len(want.faces) < len(F)
    assert "max distance" in capsys.readouterr().out
    assert _cli.main(["simplify", str(src), str(dst), "--max-distance", "-1", "--quiet"]) == 2
    assert _cli.main(["simplify", str(src), str(dst), "--max-distance", "1", "--max-distance-rel", "0.1",
                      "--quiet"]) == 2


def test_sweep_key():
    meshes = {"sphere": shapes.bumpy_sphere(2)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = qemjax.sweep(meshes, {"max_distance_rel": [0.002, 0.5]}, [0.1], metrics=False, progress=False)
    assert (df["error"] == "").all()
    assert list(df["stop_reason"]) == ["max_distance", "target"]
    for (_, row), rel in zip(df.iterrows(), [0.002, 0.5]):
        V = meshes["sphere"][0]
        assert row["distance_two_way_max"] <= rel * diagonal(V)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            alone = qemjax.simplify(meshes["sphere"], ratio=0.1, max_distance_rel=rel)
        assert row["faces_out"] == len(alone.faces)


def test_a_cut_run_counts_its_rounds_faces_as_its_own():
    """Where the bound cut a parallel run short, faces_per_round was the run's list cut at stats['rounds'], the
    rounds run: a round that contracted nothing has no entry, so after one the list kept an entry of a round
    past the cut (one more than rounds_contracting), and a cut inside a round kept that round's whole count,
    below the faces returned. Each entry is now the count after a round of the level returned, its last the
    level's own."""
    V, F = shapes.grid(12)
    V = V.copy()
    V[:, 2] = 0.05 * np.sin(5 * V[:, 0]) * np.cos(4 * V[:, 1])
    locked = np.flatnonzero(np.random.default_rng(0).random(len(V)) < 0.3)  # rounds that contract nothing
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        full = qemjax.simplify((V, F), ratio=0.05, locked=locked, method="classic")
        cuts = [qemjax.simplify((V, F), ratio=0.05, locked=locked, method="classic", max_distance_rel=rel)
                for rel in (0.005, 0.02, 0.03, 0.05)]
    assert full.stats["rounds_contracting"] < full.stats["rounds"]
    idle = 0
    for res in cuts:
        s = res.stats
        assert res.stop_reason == "max_distance"
        assert len(s["faces_per_round"]) == s["rounds_contracting"] == len(np.unique(res.history.rounds))
        assert s["faces_per_round"][-1] == s["faces_out"] == len(res.faces)
        # the rounds the cut kept whole have the run's own counts
        assert s["faces_per_round"][:-1] == full.stats["faces_per_round"][:len(s["faces_per_round"]) - 1]
        idle += s["rounds"] > s["rounds_contracting"]
    assert idle  # a cut past a round that contracted nothing, the case that kept an entry too many
