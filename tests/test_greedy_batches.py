"""The greedy queue run in verified batches (`_schedulers.greedy_batches`) gives exactly what the
one-at-a-time loop of `_schedulers.greedy` gives: the same contractions in the same order, the same
outputs bit for bit, the same stats."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers import greedy, greedy_batches

CASES = {
    "bumpy-sphere": (lambda: shapes.bumpy_sphere(3), {"ratio": 0.1}),
    # flat: costs tie at 0, so stale pairs often rank first and batches are undone (the rollback path)
    "grid-with-hole": (lambda: shapes.grid(24, hole=True), {"ratio": 0.1}),
    "grid-max-error": (lambda: shapes.grid(16, hole=True), {"ratio": 0.1, "max_error": 1e-6}),
    "bumpy-max-error": (lambda: shapes.bumpy_sphere(3), {"max_error": 1e-4}),
    "torus-flip-45": (lambda: shapes.torus(n_major=24, n_minor=12), {"ratio": 0.05, "flip_angle": 45}),
    "cube-non-manifold": (lambda: shapes.cube(3), {"ratio": 0.05, "preserve_topology": False}),
    "icosphere-rank": (lambda: shapes.icosphere(3), {"ratio": 0.05, "placement": "rank", "prune": True}),
}


def _same(x, y, where="res"):
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), where
    elif isinstance(x, dict):
        assert x.keys() == y.keys(), where
        for k in x:
            _same(x[k], y[k], f"{where}[{k!r}]")
    elif isinstance(x, (list, tuple)):
        assert len(x) == len(y), where
        for i, (a, b) in enumerate(zip(x, y)):
            _same(a, b, f"{where}[{i}]")
    else:
        assert x == y, where


@pytest.mark.parametrize("case", list(CASES))
def test_batched_queue_gives_the_one_at_a_time_result(case, monkeypatch):
    make, kw = CASES[case]
    mesh = make()
    failed = []
    loop = greedy_batches._Batches.loop

    def counting_loop(self):
        loop(self)
        failed.append(self.failed)

    monkeypatch.setattr(greedy_batches._Batches, "loop", counting_loop)
    monkeypatch.setattr(greedy, "_compiled", lambda: None)  # this Python loop (its compiled twin:
    # tests/test_greedy_compiled.py)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        new = qemjax.simplify(mesh, scheduler="greedy", **kw)
        monkeypatch.setattr(greedy_batches, "eligible", lambda model, wedges: False)
        old = qemjax.simplify(mesh, scheduler="greedy", **kw)
    assert len(failed) == 1  # the batched path ran (once), the other did not
    if case == "grid-with-hole":
        assert failed[0] > 0  # some batches were undone and run again
    for name in ("vertices", "faces", "vertex_error", "max_error", "stop_reason"):
        _same(getattr(new, name), getattr(old, name), name)
    for name in ("pairs", "positions", "costs", "rounds"):
        _same(getattr(new.history, name), getattr(old.history, name), f"history.{name}")
    drop = {k for k in new.stats if k.endswith("_s") or k == "compilations"}
    _same({k: v for k, v in new.stats.items() if k not in drop},
          {k: v for k, v in old.stats.items() if k not in drop}, "stats")
    k = max(1, len(old.faces) * 2)  # the record replays the same prefixes
    _same(new.replay(k).faces, old.replay(k).faces, "replay")


def test_eligible_models():
    from qemjax._costs.qem import QEM

    assert greedy_batches.eligible(QEM(), None)
    assert not greedy_batches.eligible(QEM(memoryless=True), None)  # ring support, refreshed state
    assert not greedy_batches.eligible(QEM(), object())  # wedges (attributes)


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6)],
                         ids=["grid-with-hole", "torus"])
def test_host_link_rule_matches_the_facelists_one(make):
    V, F = make()
    # the input, and coarser versions with irregular valence (and degree-3 vertices)
    meshes = [(V, F)] + [(r.vertices, r.faces) for r in (qemjax.simplify((V, F), ratio=t) for t in (0.4, 0.1))]
    seen = set()
    for Vm, Fm in meshes:
        Fm = np.asarray(Fm, np.int64)
        E = np.unique(np.sort(np.concatenate([Fm[:, [0, 1]], Fm[:, [1, 2]], Fm[:, [2, 0]]]), 1), axis=0)
        faces, mesh = FaceLists(Fm, len(Vm)), greedy_batches._Mesh(Fm, len(Vm), E)
        for a, b in E.tolist():
            nshared = len(mesh.at[a] & mesh.at[b])
            got = mesh.link_ok(a, b, nshared)
            assert got == greedy._link_ok(faces, a, b, nshared), (a, b)
            seen.add(got)
    assert seen == {True, False}


def test_queue_entries_order_as_the_tuples():
    """The int entries (`greedy_batches._entries` plus a stamp) sort, and come off a heap, in the order of
    the one-at-a-time queue's tuples (cost, squared length, tie, a, b, stamp): ties in cost and length,
    zeros of both signs, negative and infinite costs, equal entries but for the stamp."""
    import heapq

    from qemjax._schedulers.queue import tie

    rng = np.random.default_rng(0)
    k = 4000
    P = np.sort(rng.integers(0, 300, (k, 2)), axis=1)
    cost = rng.choice(np.array([0.0, -0.0, 1e-30, 2.5e-7, 3.0, -1e-8, np.inf], np.float32), k)
    cost[: k // 2] = rng.random(k // 2).astype(np.float32) * np.float32(1e-6)
    l2 = rng.choice(np.array([0.0, 1e-4, 2e-4, 0.5], np.float32), k)
    P[k - 50:] = P[:50]  # repeated pairs: same pair, other stamp (and sometimes the same price)
    cost[k - 25:], l2[k - 25:] = cost[:25], l2[:25]
    stamps = rng.permutation(k) + 1
    ints = [e | int(s) for e, s in zip(greedy_batches._entries(P, cost, l2), stamps)]
    tuples = [(float(c), float(d), tie(a, b), a, b, int(s)) for (a, b), c, d, s in zip(P.tolist(), cost, l2, stamps)]
    by_int = sorted(range(k), key=ints.__getitem__)
    by_tuple = sorted(range(k), key=tuples.__getitem__)
    assert by_int == by_tuple
    hi, ht = list(ints), list(tuples)
    heapq.heapify(hi)
    heapq.heapify(ht)
    out_i = [greedy_batches.entry_pair(heapq.heappop(hi)) for _ in range(k)]
    out_t = [heapq.heappop(ht)[3:5] for _ in range(k)]
    assert out_i == out_t


def _edges(F):
    F = np.asarray(F, np.int64)
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)


# a tent on edge (0, 1): faces (0, 2, 3) and (1, 3, 2) coincide once 1 goes into 0; vertex 4 gives 2 and 3
# a fourth neighbour, so the link rule holds there and the coincident-face rule decides
TENT = np.array([[0, 1, 2], [1, 0, 3], [0, 2, 3], [1, 3, 2], [2, 4, 3]])


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6),
                                  lambda: (np.zeros((5, 3)), TENT)], ids=["grid-with-hole", "torus", "tent"])
def test_simple_mesh_shortcuts_match_the_general_rules(make):
    """On a `simple` mesh (no repeated corners or faces) the link rule's degree test and the coincident
    faces test take shortcuts: the same answers as the general rules, for every edge."""
    V, F = make()
    meshes = [(V, F)]
    if len(F) > 10:  # coarser versions too, with irregular valence and degree-3 vertices
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meshes += [(r.vertices, r.faces) for r in (qemjax.simplify((V, F), ratio=t) for t in (0.4, 0.1))]
    seen = set()
    for Vm, Fm in meshes:
        E = _edges(Fm)
        mesh = greedy_batches._Mesh(np.asarray(Fm, np.int64), len(Vm), E)
        assert mesh.simple
        for a, b in E.tolist():
            dead = mesh.at[a] & mesh.at[b]
            common = mesh.link_common(a, b, len(dead))
            mesh.simple = False
            assert (mesh.link_common(a, b, len(dead)) is None) == (common is None), (a, b)
            mesh.simple = True
            if common is not None:
                ka, kb = mesh.at[a] - dead, mesh.at[b] - dead
                got = mesh.coincide(a, b, ka, kb, common)
                assert got == bool(mesh.coincident_drop(a, b, ka, kb)), (a, b)
                seen.add(got)
    assert seen == ({True, False} if len(F) == len(TENT) else {False})  # the tent has a coinciding contraction


def test_simple_means_no_repeated_corners_or_faces():
    E = _edges(TENT)
    assert greedy_batches._Mesh(TENT, 5, E).simple
    assert not greedy_batches._Mesh(np.concatenate([TENT, TENT[[2]][:, [1, 2, 0]]]), 5, E).simple  # a face twice
    assert not greedy_batches._Mesh(np.concatenate([TENT, [[2, 2, 4]]]), 5, E).simple  # a repeated corner
