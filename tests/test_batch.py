"""simplify_batch: configurations of one mesh in shared rounds give exactly what `simplify` gives alone."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import qemjax
from qemjax._kernels import compilation as _compilation
from qemjax import shapes
from qemjax import simplify_batch, simplify_cells
from qemjax._schedulers import batched, segments, select

MESHES = {
    "sheet": lambda: shapes.grid(10, hole=True),  # boundaries: boundary_weight matters
    "bumpy": lambda: shapes.bumpy_sphere(2),
}

CONFIGS = [
    dict(ratio=0.2),
    dict(ratio=0.2, boundary_weight=0.5),
    dict(ratio=0.2, area_weighted=False),
    dict(ratio=0.2, placement="endpoints"),
    dict(ratio=0.5),
    dict(target_faces=37),
    dict(ratio=0.05, max_error=1e-5),
    dict(ratio=0.2, regularize=0.05),
    dict(ratio=0.2, regularize=0.3, boundary_weight=2.0),
    dict(ratio=0.2, area_weight=0.5),
    dict(ratio=0.2, area_weight=2.0),
    dict(ratio=0.2, placement="rank"),
    dict(ratio=0.2, placement="rank", area_power=0.5),
    dict(ratio=0.2, flip_angle=None),  # another flip angle: another batch
    dict(ratio=0.2, preserve_topology=False),  # faces rebuilt each round, coincident faces dropped
    dict(ratio=0.3, preserve_topology=False, boundary_weight=1.0),
    dict(ratio=0.2, scheduler="greedy"),  # not batchable: runs alone
    dict(ratio=0.2, method="esqem"),  # refreshes state and splits: runs alone
]


def same(a, b) -> list[str]:
    """The fields where two results differ (empty: equal bit for bit)."""
    diff = []
    for name in ("vertices", "faces", "vertex_error", "source_vertices", "source_faces"):
        if not np.array_equal(getattr(a, name), getattr(b, name)):
            diff.append(name)
    for name in ("pairs", "positions", "costs", "rounds"):
        if not np.array_equal(getattr(a.history, name), getattr(b.history, name)):
            diff.append("history." + name)
    if a.history.parts.keys() != b.history.parts.keys() or any(
            not np.array_equal(a.history.parts[k], b.history.parts[k]) for k in a.history.parts):
        diff.append("history.parts")
    for name in ("removed_at", "coincident"):
        if not np.array_equal(getattr(a.record, name), getattr(b.record, name)):
            diff.append("record." + name)
    if a.stop_reason != b.stop_reason or a.max_error != b.max_error:
        diff.append("stop/max_error")
    for k in ("rounds", "contractions", "rejected", "rejected_by", "blocked_by", "branches", "faces_per_round",
              "faces_out", "target_faces"):
        if a.stats.get(k) != b.stats.get(k):
            diff.append("stats." + k)
    return diff


@pytest.fixture(scope="module", params=[pytest.param(name, marks=pytest.mark.slow) if name == "sheet" else name
                                        for name in sorted(MESHES)])  # one mesh in the fast tier
def case(request):
    mesh = MESHES[request.param]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        together = simplify_batch(mesh, CONFIGS)
        alone = [qemjax.simplify(mesh, **c) for c in CONFIGS]
    return mesh, together, alone


def test_every_configuration_equals_simplify_alone(case):
    _, together, alone = case
    for cfg, a, b in zip(CONFIGS, together, alone):
        assert same(a, b) == [], cfg


def test_configurations_really_shared_rounds(case):
    _, together, alone = case
    sizes = [r.stats.get("batch", {}).get("size", 1) for r in together]
    # plain QEM (any placement but rank: one kernel), regularize, area_weight, rank, no flip test,
    # non-manifold mode; greedy and esqem run alone
    assert sizes == [7] * 7 + [2] * 6 + [1] + [2] * 2 + [1, 1]
    # and the configurations differ: the batch did not compute one answer for all
    assert len({r.vertices.tobytes() for r in together[:13]}) >= 10


def test_copies_stop_in_different_rounds(case):
    """The batch of 7 stops its copies at several rounds: the rounds after the first stop run without the
    stopped copies' pairs (`_Batch._without_stopped`), and the equality test above covers them."""
    _, together, _ = case
    assert len({r.stats["rounds"] for r in together[:7]}) >= 3


def test_per_copy_face_targets_and_sums_match_the_one_copy_rules():
    rng = np.random.default_rng(5)
    C = 6
    for _ in range(50):
        ca = rng.integers(0, C, 40)
        removes = rng.integers(1, 4, 40)
        need = rng.integers(0, 30, C)
        take = batched._fits_targets(ca, removes, need, C)
        for c in range(C):
            mine = np.flatnonzero(ca == c)
            assert np.array_equal(take[mine], select.fits_target(removes[mine], int(need[c])))
        mask = rng.random(40) < 0.5
        starts = np.array([0, 0, 7, 7, 20, 33, 40])
        assert np.array_equal(segments.sums(mask, starts),
                              [mask[a:b].sum() for a, b in zip(starts[:-1], starts[1:])])


def test_results_of_a_batch_are_independent_of_its_company():
    mesh = shapes.icosphere(3)
    lone = simplify_batch(mesh, [dict(ratio=0.3, boundary_weight=3.0)] * 2)
    mixed = simplify_batch(mesh, [dict(ratio=0.1), dict(ratio=0.3, boundary_weight=3.0), dict(target_faces=500)])
    assert same(lone[0], mixed[1]) == [] and same(lone[1], mixed[1]) == []


def test_new_settings_in_a_batch_compile_nothing():
    mesh = shapes.icosphere(3)
    with pytest.warns(UserWarning, match="setting regularize turns off the default method's memoryless"):
        simplify_batch(mesh, [dict(ratio=0.2, regularize=0.1, boundary_weight=1.0), dict(ratio=0.3, regularize=0.2)])
    c0, _ = _compilation.snapshot()
    with pytest.warns(UserWarning, match="setting regularize turns off the default method's memoryless"):
        out = simplify_batch(mesh, [dict(ratio=0.2, regularize=0.7, boundary_weight=9.0),
                                    dict(ratio=0.3, regularize=0.05)])
    assert _compilation.snapshot()[0] == c0
    assert out[0].stats["batch"]["size"] == 2


def test_bad_configurations_raise_or_are_returned():
    mesh = shapes.icosphere(2)
    with pytest.raises(ValueError, match="boundary_weight"):
        simplify_batch(mesh, [dict(ratio=0.5), dict(ratio=0.5, boundary_weight=-1.0)])
    with pytest.raises(ValueError, match="progress"):
        simplify_batch(mesh, [dict(ratio=0.5, progress=True)])
    with pytest.raises(ValueError, match="unknown"):
        simplify_batch(mesh, [dict(ratio=0.5, colour="red")])
    out = simplify_batch(mesh, [dict(ratio=0.5), dict(ratio=2.0), dict(ratio=0.4)], errors=True)
    assert isinstance(out[1], ValueError) and "ratio" in str(out[1])
    assert same(out[0], qemjax.simplify(mesh, ratio=0.5)) == []
    assert out[0].stats["batch"]["size"] == 2


def test_batchable_models():
    from qemjax._costs import ESQEM, QEM, AreaDifference, AreaTerm, Regularized

    assert batched.batchable(QEM()) and batched.batchable(Regularized(QEM(), 0.1))
    assert batched.batchable(AreaTerm(QEM(), 0.5))
    assert not batched.batchable(ESQEM()) and not batched.batchable(AreaDifference())
    # a refreshing model only as a late run's second phases, each copy with its own model, and only
    # memoryless QEM rows (the batch rebuilds them for every copy in one pass)
    assert not batched.batchable(QEM(memoryless=True))
    assert batched.batchable(QEM(memoryless=True), own_refresh=True)
    assert not batched.batchable(ESQEM(), own_refresh=True)


def two_spheres():
    """One mesh of two parts of different sizes (per-part frames and free costs)."""
    a, b = shapes.icosphere(2), shapes.icosphere(3, radius=0.01)
    V = np.concatenate([a.vertices, b.vertices + [3.0, 0, 0]])
    return V, np.concatenate([a.faces, b.faces + len(a.vertices)])


def test_cells_of_several_meshes_share_rounds():
    meshes = [shapes.icosphere(3), shapes.grid(9, hole=True), two_spheres(), shapes.torus(n_major=24, n_minor=12)]
    cells = [(m, dict(ratio=r, boundary_weight=w)) for m in meshes for r, w in ((0.2, 100.0), (0.4, 1.0))]
    together = simplify_cells(cells)
    assert {r.stats["batch"]["size"] for r in together} == {len(cells)}
    for (m, cfg), a in zip(cells, together):
        assert same(a, qemjax.simplify(m, **cfg)) == [], cfg
    assert together[4].stats["parts_in"] == 2


def test_cells_that_would_run_alike_run_once():
    """On a closed mesh boundary_weight changes nothing, nor does area_power without area weighting: those
    cells run once and each gets its own copy, equal to `simplify` alone; the others still differ."""
    mesh = shapes.icosphere(3)
    configs = [dict(ratio=0.2, boundary_weight=w) for w in (0.5, 1.0, 8.0)] + [
        dict(ratio=0.2, area_weighted=False, area_power=p) for p in (1.0, 0.5)] + [dict(ratio=0.3)]
    out = simplify_batch(mesh, configs)
    assert [r.stats["batch"]["same_run"] for r in out] == [3, 3, 3, 2, 2, 1]
    assert {r.stats["batch"]["copies"] for r in out} == {3} and {r.stats["batch"]["size"] for r in out} == {6}
    for cfg, r in zip(configs, out):
        assert same(r, qemjax.simplify(mesh, **cfg)) == [], cfg
    assert out[0].vertices is not out[1].vertices and out[0].history.pairs is not out[1].history.pairs
    out[0].vertices[:] = 0  # a copy: changing one result leaves the others as they were
    assert same(out[1], qemjax.simplify(mesh, **configs[1])) == []
    assert not np.array_equal(out[3].vertices, out[5].vertices)
    # with boundaries, boundary_weight matters: no cells merge
    sheet = shapes.grid(10, hole=True)
    on_sheet = simplify_batch(sheet, configs[:3])
    assert [r.stats["batch"]["same_run"] for r in on_sheet] == [1, 1, 1]


def test_malformed_configs_and_cells_are_refused_in_words():
    """A dict for configs, a list of numbers, cells without configurations: Python's own errors before."""
    m = shapes.icosphere(2)
    for configs in (dict(ratio=0.5), [0.5]):
        with pytest.raises(ValueError, match="configs takes a list of dicts of simplify's keywords"):
            qemjax.simplify_batch(m, configs)
    with pytest.raises(ValueError, match=r"cells takes a list of \(mesh, dict of simplify's keywords\) pairs"):
        simplify_cells([m])


def test_a_mesh_without_attributes_is_cleaned_once_for_methods_that_keep_them_and_not(monkeypatch):
    """A batch cleans a mesh apart for the cells whose method keeps attributes and those whose method keeps
    none (the cleaning's warning says what the result has). A mesh that carries none was cleaned twice
    alike; it is cleaned once now. One with UVs is still cleaned for each, and each cell gets what a
    single call gives."""
    import trimesh

    from qemjax._pipeline import stages

    made = []
    geometry = stages.geometry
    monkeypatch.setattr(stages, "geometry", lambda *a, **k: made.append(1) or geometry(*a, **k))
    cells = [dict(ratio=0.5), dict(ratio=0.5, method="esqem"), dict(ratio=0.3, method="accurate")]
    V, F = shapes.icosphere(3)
    got = simplify_batch((V, F), cells)
    assert len(made) == 1
    for cfg, res in zip(cells, got):
        one = qemjax.simplify((V, F), **cfg)
        assert np.array_equal(res.faces, one.faces) and res.vertices.tobytes() == one.vertices.tobytes()
    made.clear()
    uv = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=V[:, :2] * 0.5 + 0.5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = simplify_batch(uv, cells[:2])
        assert len(made) == 2
        assert got[0].uv is not None and got[1].uv is None and got[1].stats["dropped"] == ["uv"]
