"""The measured distance a result carries (`qemjax._pipeline.measure`): checked against a brute-force float64
reference, on by default with a re-fit, offered to every method, the same in a batch as alone."""
from __future__ import annotations

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._pipeline import measure
from qemjax._pipeline.refit import samples
from qemjax._pipeline import refit as _refit

KEYS = measure.KEYS


def _point_triangle(p, a, b, c):
    """Exact distance from p to triangle abc by brute force: the interior's plane foot if inside, else the
    nearest of the three edges (clamped projections)."""
    n = np.cross(b - a, c - a)
    nn = n @ n
    best = np.inf
    if nn > 0:
        q = p - ((p - a) @ n) / nn * n
        w0 = np.cross(b - q, c - q) @ n
        w1 = np.cross(c - q, a - q) @ n
        w2 = np.cross(a - q, b - q) @ n
        if w0 >= 0 and w1 >= 0 and w2 >= 0:
            best = np.linalg.norm(p - q)
    for u, v in ((a, b), (b, c), (c, a)):
        d = v - u
        t = 0.0 if d @ d == 0 else min(max((p - u) @ d / (d @ d), 0.0), 1.0)
        best = min(best, np.linalg.norm(p - (u + t * d)))
    return best


def test_distance_matches_brute_force_on_random_meshes():
    rng = np.random.default_rng(7)
    for _ in range(3):
        V = rng.normal(size=(40, 3))
        F = np.array([rng.choice(40, 3, replace=False) for _ in range(60)])
        X = V[:25] + 0.05 * rng.normal(size=(25, 3))
        G = np.array([rng.choice(25, 3, replace=False) for _ in range(30)])
        got = measure.distance(V, F, X, G)
        P, w, _ = samples(V, F, np.zeros(len(V), np.int64))
        d = np.array([min(_point_triangle(p, *X[g]) for g in G) for p in P])
        assert got["distance_max"] == pytest.approx(d.max(), rel=1e-9, abs=1e-12)
        assert got["distance_rms"] == pytest.approx(np.sqrt(np.sum(w * d * d) / w.sum()), rel=1e-9)
        diag = np.linalg.norm(V.max(0) - V.min(0))
        assert got["distance_max_rel"] == pytest.approx(d.max() / diag, rel=1e-9)
        assert got["distance_samples"] == len(P)


def test_scale_does_not_change_the_relative_distance():
    m = shapes.bumpy_sphere(3)
    base = qemjax.simplify(m, ratio=0.2)
    for s in (1e-80, 1e80):
        r = qemjax.simplify((m.vertices * s, m.faces), ratio=0.2)
        assert r.stats["distance_max"] == pytest.approx(base.stats["distance_max"] * s, rel=1e-6)
        assert r.stats["distance_max_rel"] == pytest.approx(base.stats["distance_max_rel"], rel=1e-6)


def test_default_measures_classic_offers_it(monkeypatch):
    m = shapes.bumpy_sphere(3)
    d = qemjax.simplify(m, ratio=0.1)
    assert d.stats["distance_max"] > d.stats["distance_rms"] > 0
    assert f"max {d.stats['distance_max']:.3g}" in d.summary()
    c = qemjax.simplify(m, ratio=0.1, method="classic")
    assert all(c.stats[k] is None for k in KEYS) and "not measured" in c.summary()
    cm = qemjax.simplify(m, ratio=0.1, method="classic", measure=True)
    assert np.array_equal(cm.vertices, c.vertices)  # measuring changes nothing of the result
    want = measure.distance(c.input_vertices, c.input_faces, c.vertices, c.faces)
    assert cm.stats["distance_max"] == want["distance_max"] and cm.stats["distance_rms"] == want["distance_rms"]
    # the default's measured distance takes the re-fit's samples (made once): the same stats as made anew
    again = measure.distance(d.input_vertices, d.input_faces, d.vertices, d.faces)
    assert all(d.stats[k] == again[k] for k in KEYS if k != "distance_s")
    made = []
    real = _refit.samples
    monkeypatch.setattr(_refit, "samples", lambda *a: made.append(1) or real(*a))
    assert qemjax.simplify(m, ratio=0.1).stats["distance_max"] == d.stats["distance_max"] and len(made) == 1
    off = qemjax.simplify(m, ratio=0.1, measure=False)
    assert np.array_equal(off.vertices, d.vertices) and off.stats["distance_max"] is None
    # the re-fit lowers the distance it measures (it minimises it at these samples)
    assert d.stats["distance_rms"] < cm.stats["distance_rms"]


def test_batch_measures_as_alone():
    m = shapes.bumpy_sphere(3)
    cfgs = [dict(ratio=0.1), dict(ratio=0.2, method="classic", measure=True), dict(ratio=0.3, method="classic")]
    batch = qemjax.simplify_batch(m, cfgs)
    for cfg, r in zip(cfgs, batch):
        alone = qemjax.simplify(m, **cfg)
        assert all(r.stats[k] == alone.stats[k] for k in KEYS if k != "distance_s")


@pytest.mark.parametrize("more", [0, 100])
@pytest.mark.parametrize("kw", [{}, {"measure": True, "refit": 0}, {"method": "esqem", "measure": True}])
def test_a_mesh_returned_unchanged_is_at_distance_zero_exactly(kw, more):
    import warnings

    V, F = shapes.bumpy_sphere(3)
    V = np.concatenate([V, [[9.0, 9.0, 9.0]]])  # an unused vertex: cleaned away, the surface the same
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a target above the faces says it returns the mesh unchanged
        res = qemjax.simplify((V, F), target_faces=len(F) + more, **kw)
    assert res.stop_reason == "unchanged" and len(res.faces) == len(F)
    assert (res.stats["distance_max"], res.stats["distance_rms"]) == (0.0, 0.0)
    assert (res.stats["distance_max_rel"], res.stats["distance_rms_rel"]) == (0.0, 0.0)
    assert res.stats["distance_samples"] > 0
    moved = res.vertices.copy()
    moved[0] += 1e-3  # any other output is measured as before
    d = measure.distance(res.input_vertices, res.input_faces, moved, res.faces)
    assert 0 < d["distance_max"] <= 1e-3


def test_measure_must_be_a_bool():
    with pytest.raises(ValueError, match="measure must be True or False"):
        qemjax.simplify(shapes.icosphere(2), ratio=0.5, measure="yes")


def test_quadric_cost_is_named_for_what_it_is():
    r = qemjax.simplify(shapes.bumpy_sphere(3), ratio=0.1)
    assert r.stats["error_unit"].startswith("quadric error")
    assert "squared distance, mesh units²)" not in r.summary()
