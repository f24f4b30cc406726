"""Real meshes from ../shared/meshes (skipped where that folder is absent)."""
from __future__ import annotations

import pytest
from conftest import assert_valid, one_pair_per_round, shared_mesh

import qemjax

pytestmark = pytest.mark.slow  # every real mesh, both schedulers: the slow tier


def test_cow_to_1000_faces_exactly():
    p = shared_mesh("cow.obj")
    m = qemjax.load(p)
    r = qemjax.simplify(p, target_faces=1000)
    assert_valid(r, 1000, m.vertices, m.faces)


@pytest.mark.parametrize("name", ["stanford-bunny.obj", "face.obj", "teapot.obj", "beetle.obj",
                                  "spot/spot.obj", "fandisk.obj"])
def test_real_meshes_valid_at_ten_percent(name):
    p = shared_mesh(name)
    r = qemjax.simplify(p, ratio=0.1)
    closed_odd = name in ("fandisk.obj", "stanford-bunny.obj") and r.stats["target_faces"] % 2
    # a closed mesh loses faces in pairs: an odd target is unreachable, the next count above is right
    want = r.stats["target_faces"] + (1 if closed_odd and name == "fandisk.obj" else 0)
    assert_valid(r, want, r.input_vertices, r.input_faces)


def test_parallel_with_one_pair_per_round_is_greedy_on_rocker_arm():
    """The same equivalence on a real CAD-like mesh (720 contractions); the default's shape term is the
    parallel rounds' alone, so it is off here."""
    import numpy as np

    path = shared_mesh("rocker-arm-small.off")
    g = qemjax.simplify(path, ratio=0.1, scheduler="greedy")
    p = qemjax.simplify(path, ratio=0.1, schedule=one_pair_per_round(), quality_threshold=0.0)
    assert len(p.history.pairs) == len(g.history.pairs) > 500
    assert np.array_equal(np.sort(p.history.pairs, 1), np.sort(g.history.pairs, 1))
