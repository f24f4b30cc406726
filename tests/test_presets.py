"""Named methods (presets): ``qemjax.QEM.accurate()``, ``method="accurate"``, and the old ``preset=``."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import _cli, shapes

ACCURATE = dict(memoryless=True, memory_weight=0.3, placement="rank", area_power=0.6, boundary_weight=10.0,
                rank_eps=1e-3, max_shift=0.5, refit=1)


@pytest.fixture(scope="module")
def sheet():
    return shapes.grid(12, hole=True)  # boundaries: the preset's boundary weight matters


def same(a, b) -> bool:
    return np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_accurate_is_a_method_object_with_its_settings(sheet):
    m = qemjax.QEM.accurate()
    assert isinstance(m, qemjax.QEM) and dataclasses.is_dataclass(m)
    for key, value in ACCURATE.items():
        assert getattr(m, key) == value, key
    r = qemjax.simplify(sheet, ratio=0.3, method=m)
    for key, value in ACCURATE.items():
        assert (r.stats["refit"] if key == "refit" else r.stats["model"][key]) == value, key
    assert r.stop_reason == "target" and len(r.faces) == r.stats["target_faces"]
    assert not same(r, qemjax.simplify(sheet, ratio=0.3))
    assert qemjax.QEM.classic() == qemjax.QEM()


def test_names_and_the_old_keyword_mean_the_object(sheet):
    obj = qemjax.simplify(sheet, ratio=0.3, method=qemjax.QEM.accurate())
    assert same(obj, qemjax.simplify(sheet, ratio=0.3, method="accurate"))
    assert same(obj, qemjax.simplify(sheet, ratio=0.3, preset="accurate"))


def test_a_setting_at_its_default_value_switches_the_presets_off(sheet):
    """The bug of the flat keywords: refit=0 (the keyword's default) could not switch the re-fit off."""
    off = qemjax.simplify(sheet, ratio=0.3, method=dataclasses.replace(qemjax.QEM.accurate(), refit=0))
    assert off.stats["refit"] == 0
    assert same(off, qemjax.simplify(sheet, ratio=0.3, method="accurate", refit=0))
    assert same(off, qemjax.simplify(sheet, ratio=0.3, preset="accurate", refit=0))
    assert not same(off, qemjax.simplify(sheet, ratio=0.3, method="accurate"))


def test_a_setting_by_name_replaces_that_field_only(sheet):
    r = qemjax.simplify(sheet, ratio=0.3, method="accurate", boundary_weight=5.0, memory_weight=1.0)
    assert r.stats["model"]["boundary_weight"] == 5.0 and r.stats["model"]["memory_weight"] == 1.0
    assert r.stats["model"]["placement"] == "rank"  # the rest still the preset's


def test_unknown_names_are_refused(sheet):
    with pytest.raises(ValueError, match="unknown preset 'best'.*accurate"):
        qemjax.simplify(sheet, ratio=0.3, preset="best")
    with pytest.raises(ValueError, match="unknown method 'best'"):
        qemjax.simplify(sheet, ratio=0.3, method="best")
    with pytest.raises(ValueError, match="preset='accurate' names a method"):
        qemjax.simplify(sheet, ratio=0.3, method="esqem", preset="accurate")


def test_preset_in_a_batch_and_a_sweep_equals_simplify(sheet):
    alone = qemjax.simplify(sheet, ratio=0.3, method="accurate")
    both = qemjax.simplify_batch(sheet, [dict(ratio=0.3, method=qemjax.QEM.accurate()), dict(ratio=0.3)])
    assert same(both[0], alone)
    df = qemjax.sweep({"sheet": sheet}, {"method": ["qem", qemjax.QEM.accurate()]}, [0.3], metrics=False,
                      progress=False)
    assert list(df["faces_out"]) == [len(both[1].faces), len(alone.faces)]
    assert list(df["method"]) == ["qem", "accurate"]  # the preset's object by the preset's name (issue 40 §4)
    assert both[0].stats["method"] == "accurate" and alone.stats["method"] == "accurate"


@pytest.mark.parametrize("flags", [["--preset", "accurate"], ["--method", "accurate"]])
def test_cli_preset(tmp_path, monkeypatch, flags):
    monkeypatch.setenv("QEMJAX_NO_CACHE", "1")
    V, F = shapes.grid(12, hole=True)
    src, dst = tmp_path / "in.ply", tmp_path / "out.ply"
    trimesh.Trimesh(V, F, process=False).export(src)
    assert _cli.main(["simplify", str(src), str(dst), "--ratio", "0.3", *flags, "--quiet"]) == 0
    out = trimesh.load(dst, process=False)
    ref = qemjax.simplify((V, F), ratio=0.3, method="accurate")
    assert len(out.faces) == len(ref.faces)
