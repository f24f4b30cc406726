"""simplify(preset=...): a named set of options fills the keywords left at their defaults."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import _cli, _presets, shapes


@pytest.fixture(scope="module")
def sheet():
    return shapes.grid(12, hole=True)  # boundaries: the preset's boundary weight matters


def test_accurate_sets_its_options_and_model_fields(sheet):
    r = qemjax.simplify(sheet, ratio=0.3, preset="accurate")
    p = _presets.PRESETS["accurate"]
    for key, value in {**p.keywords, **p.model}.items():
        assert (r.stats["refit"] if key == "refit" else r.stats["model"][key]) == value, key
    assert r.stop_reason == "target" and len(r.faces) == r.stats["target_faces"]
    plain = qemjax.simplify(sheet, ratio=0.3)
    assert not np.array_equal(r.vertices, plain.vertices)


def test_a_keyword_with_another_value_wins(sheet):
    r = qemjax.simplify(sheet, ratio=0.3, preset="accurate", boundary_weight=5.0, memory_weight=1.0)
    assert r.stats["model"]["boundary_weight"] == 5.0 and r.stats["model"]["memory_weight"] == 1.0
    assert r.stats["model"]["placement"] == "rank"  # the rest still from the preset


def test_unknown_preset_is_refused(sheet):
    with pytest.raises(ValueError, match="unknown preset 'best'.*accurate"):
        qemjax.simplify(sheet, ratio=0.3, preset="best")


def test_preset_in_a_batch_and_a_sweep_equals_simplify(sheet):
    alone = qemjax.simplify(sheet, ratio=0.3, preset="accurate")
    both = qemjax.simplify_batch(sheet, [dict(ratio=0.3, preset="accurate"), dict(ratio=0.3)])
    assert np.array_equal(both[0].vertices, alone.vertices) and np.array_equal(both[0].faces, alone.faces)
    df = qemjax.sweep({"sheet": sheet}, {"preset": [None, "accurate"]}, [0.3], metrics=False, progress=False)
    assert list(df["faces_out"]) == [len(both[1].faces), len(alone.faces)]


def test_cli_preset(tmp_path, monkeypatch):
    monkeypatch.setenv("QEMJAX_NO_CACHE", "1")
    V, F = shapes.grid(12, hole=True)
    src, dst = tmp_path / "in.ply", tmp_path / "out.ply"
    trimesh.Trimesh(V, F, process=False).export(src)
    assert _cli.main(["simplify", str(src), str(dst), "--ratio", "0.3", "--preset", "accurate", "--quiet"]) == 0
    out = trimesh.load(dst, process=False)
    ref = qemjax.simplify((V, F), ratio=0.3, preset="accurate")
    assert len(out.faces) == len(ref.faces)
