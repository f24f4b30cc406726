"""The triangle-quality guard (`Topology.min_angle`): what it promises on every path that offers it (the
parallel round's compiled loops and numpy stages, the greedy queue, the re-fit), and that it changes nothing
when off (the golden outputs: tests/test_golden.py)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from test_round_loops import _assert_same, _run


def _quality(V, F) -> np.ndarray:
    """2·area / longest edge² per face, in float64 (never above the sine of the smallest angle)."""
    c = np.asarray(V, np.float64)[np.asarray(F)]
    n = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    longest = np.max([((c[:, (i + 1) % 3] - c[:, i]) ** 2).sum(1) for i in range(3)], axis=0)
    return n / longest


def _simplify(mesh, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return qemjax.simplify(mesh, **kw)


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("refit", [0, 1])
def test_faces_made_from_well_shaped_ones_keep_the_bound(scheduler, refit):
    """On an input whose faces all pass the bound, every output face passes it too (the guard refuses a
    face that ends below it and below what it was): with and without the re-fit, on both schedulers; the
    same run without the guard leaves faces below it (the check can fail), and both reach the target."""
    mesh = shapes.bumpy_sphere(3)
    angle = 20.0
    bound = math.sin(math.radians(angle))
    assert _quality(*mesh).min() > bound
    target = len(mesh[1]) // 10
    off = _simplify(mesh, target_faces=target, scheduler=scheduler, refit=refit)
    on = _simplify(mesh, target_faces=target, scheduler=scheduler, refit=refit, min_angle=angle)
    assert len(on.faces) == len(off.faces) == target
    assert _quality(off.vertices, off.faces).min() < bound
    # float32 arithmetic inside the rounds: a face may sit a rounding step under the bound
    assert _quality(on.vertices, on.faces).min() >= bound * (1 - 1e-4)


def test_the_numpy_stages_decide_as_the_compiled_loops(monkeypatch):
    """The guard on the device kernel (numpy stages) and in the host rule (compiled loops): the same run,
    bit for bit."""
    mesh = shapes.bumpy_sphere(3)
    kw = dict(ratio=0.05, min_angle=15.0)
    new, seen = _run(mesh, kw, monkeypatch, True)
    old, seen_old = _run(mesh, kw, monkeypatch, False)
    assert seen == [True] and seen_old == [False]
    _assert_same(new, old)
    assert not np.array_equal(new.faces, _run(mesh, {"ratio": 0.05}, monkeypatch, True)[0].faces)


def test_a_batch_keeps_each_configs_guard():
    """`simplify_batch` with and without the guard gives what each `simplify` gives alone."""
    mesh = shapes.bumpy_sphere(3)
    configs = [dict(ratio=0.1, min_angle=12.0), dict(ratio=0.1)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = qemjax.simplify_batch(mesh, configs)
    for res, cfg in zip(got, configs):
        want = _simplify(mesh, **cfg)
        np.testing.assert_array_equal(res.vertices, want.vertices)
        np.testing.assert_array_equal(res.faces, want.faces)
    assert not np.array_equal(got[0].faces, got[1].faces)


@pytest.mark.parametrize("value", [0, 60, -5, float("nan"), "ten"])
def test_a_bad_angle_is_named(value):
    with pytest.raises((ValueError, TypeError), match="min_angle"):
        qemjax.Topology(min_angle=value)


def test_command_line_and_sweep_take_the_guard(tmp_path, capsys):
    """``--min-angle`` on the command line and ``min_angle`` as a sweep key give `simplify`'s result."""
    from qemjax import _cli

    mesh = shapes.bumpy_sphere(3)
    src, dst = tmp_path / "in.obj", tmp_path / "out.obj"
    import trimesh

    trimesh.Trimesh(*mesh, process=False).export(src)
    assert _cli.main(["simplify", str(src), str(dst), "--ratio", "0.1", "--min-angle", "20", "--quiet"]) == 0
    got = qemjax.load(dst)
    want = _simplify(qemjax.load(src), ratio=0.1, min_angle=20.0)
    np.testing.assert_allclose(got.vertices, want.vertices, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(got.faces, want.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        table = qemjax.sweep({"s": mesh}, {"min_angle": [None, 20.0]}, [0.1], progress=False, workers=1)
    smallest = table["min_angle_min"].tolist()  # degrees
    assert smallest[0] < smallest[1] and smallest[1] >= 20.0 - 1e-3
