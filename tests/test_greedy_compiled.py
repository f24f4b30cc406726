"""The greedy queue in verified batches with its host side compiled (`_schedulers.greedy.batches`, kernels
in `greedy.speculate` and `rules`) gives exactly what the one-at-a-time loop of `_schedulers.greedy`
gives: the same contractions in the same order, the same outputs and stats bit for bit, in manifold and
non-manifold mode (coincident faces dropped), on simple meshes and on meshes with repeated corners or
faces; and each kernel answers as the code it stands for (flip test, link rule, coincident faces, heap
order, order check)."""
from __future__ import annotations

import dataclasses
import heapq
import warnings
from pathlib import Path

import numpy as np
import pytest

import qemjax
from qemjax import shapes

pytest.importorskip("numba")  # a core dependency; without it the one-at-a-time loop runs
from qemjax._costs import build  # noqa: E402
from qemjax._costs.base import MeshInput  # noqa: E402
from qemjax._costs.qem import QEM  # noqa: E402
from qemjax._kernels import flips as flips_mod  # noqa: E402
from qemjax._mesh import topology as topo  # noqa: E402
from qemjax._mesh.incidence import FaceLists  # noqa: E402
from qemjax._options import Options  # noqa: E402
from qemjax._schedulers import greedy, rules  # noqa: E402
from qemjax._schedulers.greedy import batches as greedy_compiled  # noqa: E402
from qemjax._schedulers.greedy import speculate as jit  # noqa: E402

import reference_rules  # noqa: E402
from qemjax._schedulers.greedy.queue import tie  # noqa: E402
from test_attributes import atlas_sphere  # noqa: E402

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


def _jittered_sphere(seed=0):
    """An icosphere with its vertices moved at random: uneven costs, some flips refused."""
    V, F = shapes.icosphere(3)
    rng = np.random.default_rng(seed)
    return V + rng.normal(0, 0.02, V.shape), F


def _bipyramid(k=150):
    """Two apexes of degree ``k``: vertex lists longer than the kernels' first buffers."""
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    V = np.concatenate([np.stack([np.cos(t), np.sin(t), 0.05 * np.sin(7 * t)], 1), [[0, 0, 1], [0, 0, -1]]])
    i = np.arange(k)
    F = np.concatenate([np.stack([i, (i + 1) % k, np.full(k, k)], 1), np.stack([(i + 1) % k, i, np.full(k, k + 1)], 1)])
    return V, F


def _two_spheres():
    """Two separate parts, one small: the part rule (keep_parts) refuses its last contraction."""
    V1, F1 = shapes.icosphere(2)
    V2, F2 = shapes.icosphere(0)
    return np.concatenate([V1, 0.2 * V2 + 3.0]), np.concatenate([F1, F2 + len(V1)])


def _nested_cubes():
    """A cube inside a slightly larger one, joined by close pairs (``pair_threshold``): in non-manifold
    mode the parts are pulled together and the faces that come to coincide are dropped."""
    V, F = shapes.cube(2)
    return np.concatenate([V, V * 0.9 + 0.05]), np.concatenate([F, F + len(V)])


COMPILED = dict(CASES)
COMPILED.update({
    "jittered-sphere": (_jittered_sphere, {"ratio": 0.05}),
    "bipyramid": (_bipyramid, {"ratio": 0.1}),
    "two-parts": (_two_spheres, {"ratio": 0.01}),
    # non-manifold mode where contractions drop coincident faces (DROPS: the run's count is checked > 0)
    "torus-non-manifold": (lambda: shapes.torus(n_major=24, n_minor=12), {"ratio": 0.01, "preserve_topology": False}),
    "nested-cubes-non-manifold": (_nested_cubes, {"ratio": 0.05, "preserve_topology": False, "pair_threshold": 0.2}),
    "non-manifold-max-error": (lambda: shapes.bumpy_sphere(3), {"max_error": 3e-4, "preserve_topology": False}),
})
DROPS = ("torus-non-manifold", "nested-cubes-non-manifold")


def _random_picks(n, k, seed):
    return np.random.default_rng(seed).choice(n, k, replace=False)


_N3 = len(shapes.bumpy_sphere(3)[0])
_NG = len(shapes.grid(16, hole=True)[0])
_N2 = len(_two_spheres()[0])
# locks and weights (`_locks`): locked kept vertices priced where they stand, weights scaling the costs and
# carried through contractions, pairs of two locked vertices never taken, the LOCKED rule
COMPILED.update({
    "locked": (lambda: shapes.bumpy_sphere(3), {"ratio": 0.1, "locked": _random_picks(_N3, _N3 // 10, 0)}),
    "weights": (lambda: shapes.bumpy_sphere(3),
                {"ratio": 0.1, "vertex_weights": np.random.default_rng(1).choice([0.0, 1.0, 10.0], _N3)}),
    "locks-weights-non-manifold": (lambda: shapes.bumpy_sphere(3), {
        "ratio": 0.05, "preserve_topology": False, "locked": _random_picks(_N3, 30, 2),
        "vertex_weights": np.random.default_rng(3).random(_N3) * 5}),
    # 40 % locked: the run stops held back by its locks
    "locks-stop": (lambda: shapes.grid(16, hole=True),
                   {"ratio": 0.02, "locked": np.random.default_rng(4).random(_NG) < 0.4}),
    "locks-max-error": (lambda: shapes.grid(16, hole=True), {
        "max_error": 1e-3, "locked": [0, 5, 17], "vertex_weights": np.random.default_rng(5).random(_NG) * 3}),
    # the small sphere's last contractions would leave its locked vertex in no face: refused (LOCKED)
    "locks-vanishing-non-manifold": (_two_spheres, {"ratio": 0.001, "preserve_topology": False, "locked": [_N2 - 1]}),
})


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


def _run(mesh, kw, monkeypatch, compiled: bool):
    """A greedy run through `qemjax.simplify`, compiled or (``compiled=False``) the reference: the
    one-at-a-time loop, which also runs where numba is missing (`greedy._compiled` gives None). Returns
    the result and the compiled loop's failed-batch count per run."""
    ran = []
    loop = greedy_compiled._Compiled.loop

    def counting_loop(self):
        loop(self)
        ran.append(self.failed)

    with monkeypatch.context() as m:
        m.setattr(greedy_compiled._Compiled, "loop", counting_loop)
        if not compiled:
            m.setattr(greedy, "_compiled", lambda: None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return qemjax.simplify(mesh, scheduler="greedy", **kw), ran


def _assert_same(new, old):
    for name in ("vertices", "faces", "vertex_error", "max_error", "stop_reason"):
        _same(getattr(new, name), getattr(old, name), name)
    for name in ("pairs", "positions", "costs", "rounds"):
        _same(getattr(new.history, name), getattr(old.history, name), f"history.{name}")
    drop = {k for k in new.stats if k.endswith("_s") or k == "compilations"}
    _same({k: v for k, v in new.stats.items() if k not in drop},
          {k: v for k, v in old.stats.items() if k not in drop}, "stats")
    _same(new.record.removed_at, old.record.removed_at, "record.removed_at")
    _same(new.record.coincident, old.record.coincident, "record.coincident")


@pytest.mark.parametrize("case", list(COMPILED))
def test_compiled_queue_gives_the_one_at_a_time_result(case, monkeypatch):
    make, kw = COMPILED[case]
    mesh = make()
    new, ran = _run(mesh, kw, monkeypatch, True)
    old, ran_old = _run(mesh, kw, monkeypatch, False)
    assert len(ran) == 1 and ran_old == []  # the compiled loop ran (once), then not
    if case == "grid-with-hole":
        assert ran[0] > 0  # some batches were undone and run again
    if case in DROPS:
        assert new.record.coincident.sum() > 0  # contractions did drop coincident faces
    if "ratio" not in kw:
        assert new.stop_reason == "max_error"
    if case == "locks-stop":
        assert new.stop_reason == "locked"
    if case == "locks-vanishing-non-manifold":
        assert new.stats["rejected_by"]["locked"] > 0
    _assert_same(new, old)
    k = max(1, len(old.faces) * 2)  # the record replays the same prefixes
    _same(new.replay(k).faces, old.replay(k).faces, "replay")


# a tent on edge (0, 1): faces (0, 2, 3) and (1, 3, 2) coincide once 1 goes into 0; vertex 4 gives 2 and 3
# a fourth neighbour, so the link rule holds there and the coincident-face rule decides
TENT = np.array([[0, 1, 2], [1, 0, 3], [0, 2, 3], [1, 3, 2], [2, 4, 3]])


def _edges(F):
    F = np.asarray(F, np.int64)
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)


def _scheduler_run(V, F, ratio, preserve_topology, compiled: bool, monkeypatch, max_cost=np.inf):
    """`greedy.run` called as the pipeline calls it, on faces the pipeline's clean-up would have changed
    (repeated corners, faces twice): the QEM model's state from the faces as given."""
    V = np.asarray(V, np.float32)
    V = (V - V.min(0)) / np.float32(np.ptp(V, axis=0).max())
    F = np.asarray(F, np.int64)
    model = QEM()
    S = model.init_state(MeshInput(V, F, topo.boundary_edges(F, len(V)), None, (0.01, 0.01)))
    options = Options(cos_max=0.0, preserve_topology=preserve_topology, max_cost=max_cost)
    calls = []
    with monkeypatch.context() as m:
        real = greedy_compiled.run
        m.setattr(greedy_compiled, "run", lambda *a: calls.append(1) or real(*a))
        if not compiled:
            m.setattr(greedy, "_compiled", lambda: None)
        out = greedy.run(V, S, F, np.zeros((0, 2), np.int64), max(1, int(ratio * len(F))), model, options)
    assert len(calls) == int(compiled)
    return out


def _assert_same_outcome(new, old):
    for f in dataclasses.fields(old):
        x, y = getattr(new, f.name), getattr(old, f.name)
        if f.name == "history":
            for name in ("pairs", "positions", "costs"):
                _same(getattr(x, name), getattr(y, name), f"history.{name}")
        elif f.name != "stage_times":
            _same(x, y, f.name)


def _non_simple(kind):
    """A jittered sphere with faces twice (one of them reversed) or faces with a repeated corner added."""
    V, F = _jittered_sphere(1)
    rng = np.random.default_rng(5)
    if kind == "faces-twice":
        pick = rng.choice(len(F), 12, replace=False)
        more = F[pick]
        more[::2] = more[::2, ::-1]  # opposite orientation: the two cancel when dropped
        return V, np.concatenate([F, more])
    pick = rng.choice(len(F), 8, replace=False)
    return V, np.concatenate([F, F[pick][:, [0, 0, 1]]])


@pytest.mark.parametrize("kind", ["faces-twice", "repeated-corner"])
@pytest.mark.parametrize("manifold", [True, False], ids=["manifold", "non-manifold"])
def test_compiled_queue_on_a_non_simple_mesh(kind, manifold, monkeypatch):
    """Meshes the rules' shortcuts do not hold on (`greedy_compiled.simple` false): the general link and
    coincident-face rules, the same run as the one-at-a-time loop, every field of the outcome."""
    V, F = _non_simple(kind)
    added = np.arange(len(_jittered_sphere(1)[1]), len(F))
    assert not greedy_compiled.simple(F)
    new = _scheduler_run(V, F, 0.05, manifold, True, monkeypatch)
    old = _scheduler_run(V, F, 0.05, manifold, False, monkeypatch)
    _assert_same_outcome(new, old)
    assert len(new.history.pairs) > 100
    if kind == "faces-twice" and not manifold:
        assert new.coincident.sum() > 0  # the faces given twice were dropped by contractions
    if kind == "repeated-corner" and not manifold:
        assert np.any(new.removed_at[added] >= 0)  # (a contraction of their two distinct corners)
    if manifold:
        assert new.rejected_by.get("topology", 0) + new.rejected_by.get("coincident", 0) > 0


def test_compiled_queue_grows_its_arrays(monkeypatch):
    """Started with almost no room (journal, intervals, removed faces, pools, queue), the arrays grow
    between batches (batches that stop for room end early): the same result, in both modes, with kept
    attributes (their journal rows)."""
    grown = []
    room = greedy_compiled._Compiled.room

    def counting_room(self, stamps=0, full=False):
        grown.append(full)
        return room(self, stamps, full)

    for case in ("grid-with-hole", "nested-cubes-non-manifold", "atlas-non-manifold"):
        make, kw = COMPILED[case] if case in COMPILED else (UV[case][0], dict(UV[case][1], attributes="uv"))
        mesh = make()
        old, _ = _run(mesh, kw, monkeypatch, False)
        with monkeypatch.context() as m:
            m.setattr(greedy_compiled, "ROOM", 1)
            m.setattr(greedy_compiled, "SLACK", 4)
            m.setattr(greedy_compiled, "JOURNAL_ROWS", 8)
            m.setattr(greedy_compiled, "INTERVAL_ROWS", 2)
            m.setattr(greedy_compiled, "REMOVED_ROWS", 1)
            m.setattr(greedy_compiled._Compiled, "room", counting_room)
            grown.clear()
            new, ran = _run(mesh, kw, monkeypatch, True)
        assert len(ran) == 1 and any(grown), case
        _assert_same(new, old)


def test_eligible_models():
    assert greedy_compiled.eligible(QEM())
    assert not greedy_compiled.eligible(QEM(memoryless=True))  # ring support, refreshed state
    # the model of a run that keeps attributes (its wedges and locks run in the compiled batches too)
    assert greedy_compiled.eligible(build(QEM(), weights=np.ones(2)))


def test_simple_means_no_repeated_corners_or_faces():
    assert greedy_compiled.simple(TENT)
    assert not greedy_compiled.simple(np.concatenate([TENT, TENT[[2]][:, [1, 2, 0]]]))  # a face twice
    assert not greedy_compiled.simple(np.concatenate([TENT, [[2, 2, 4]]]))  # a repeated corner


def test_flip_kernel_matches_numpy():
    """`rules.flips` per face = `reference_rules.flips_host_faces`, bit for bit in its float32 decisions: random
    faces and moves, near-degenerate ones (collinear, zero area, tiny), three thresholds, and the quality
    guard with and without the flip test."""
    rng = np.random.default_rng(1)
    V = rng.normal(size=(60, 3)).astype(np.float32)
    V[50:] = V[:10] + rng.normal(0, 1e-4, (10, 3)).astype(np.float32)  # near duplicates
    V[40:45] = np.linspace(0, 1, 5)[:, None] * np.float32([1, 2, 3])  # collinear
    F = np.array([rng.choice(60, 3, replace=False) for _ in range(3000)], np.int64)
    N0 = reference_rules._cross3(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]).astype(np.float32)
    N0[::7] = rng.normal(size=N0[::7].shape).astype(np.float32)  # references far from the faces' own
    k = rng.integers(0, 3, len(F))
    X = np.where(rng.random((len(F), 1)) < 0.3, V[F[np.arange(len(F)), (k + 1) % 3]] * np.float32(1.0001),
                 rng.normal(size=(len(F), 3))).astype(np.float32)
    for cos_max, q in ((0.0, 0.0), (float(np.cos(np.radians(45))), 0.0), (-2.0, 0.0), (0.0, 0.2), (-2.0, 0.4)):
        want = reference_rules.flips_host_faces(V, N0, F, np.arange(len(F)), k, X, cos_max, q)
        shape = (np.float32(flips_mod.SLIVER), np.float32(q))
        got = [rules.flips(V, N0, F, f, k[f], X[f], np.float32(cos_max), shape) for f in range(len(F))]
        assert np.array_equal(np.array(got), want)
        assert 0 < want.sum() < len(F)


def _coarser(V, F):
    """The mesh and coarser versions of it (irregular valence, degree-3 vertices)."""
    meshes = [(V, F)]
    if len(F) > 10:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meshes += [(r.vertices, r.faces) for r in (qemjax.simplify((V, F), ratio=t) for t in (0.4, 0.1))]
    return meshes


def _kernel_lists(F, n):
    return greedy_compiled._lists(n, F.reshape(-1), np.repeat(np.arange(len(F)), 3))


def _at(F, n):
    at = [set() for _ in range(n)]
    for f, t in enumerate(F.tolist()):
        for v in t:
            at[v].add(f)
    return at


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6),
                                  lambda: (np.zeros((5, 3)), TENT), lambda: _non_simple("faces-twice")],
                         ids=["grid-with-hole", "torus", "tent", "faces-twice"])
def test_link_kernel_matches_the_loops_rule(make):
    """`rules.link_common` holds where the set-based twin (`reference_rules.link_ok_sets`) does, for
    every edge of the mesh and of coarser versions, and gives the common neighbours of the pair; with
    the simple-mesh shortcut where the mesh is simple, and without it (the same answers) anyway; and so
    on the one-at-a-time loop's face lists (`greedy.loop._link_ok`)."""
    V, F = make()
    seen = set()
    for Vm, Fm in _coarser(V, F):
        Fm = np.asarray(Fm, np.int64)
        n, E = len(Vm), _edges(Fm)
        faces, at = FaceLists(Fm, n), _at(Fm, n)
        fs, fl, fpool = _kernel_lists(Fm, n)
        cnt, out, alive = np.zeros((n, 3), np.int64), np.zeros(2, np.int64), np.ones(len(Fm), bool)
        shortcuts = (True, False) if greedy_compiled.simple(Fm) else (False,)
        for a, b in E.tolist():
            nshared = len(at[a] & at[b])
            want = reference_rules.link_ok_sets(faces, a, b, nshared)
            assert greedy.loop._link_ok(faces, a, b, nshared) == want, (a, b)
            common = ({v for f in at[a] for v in Fm[f]} & {v for f in at[b] for v in Fm[f]}) - {a, b}
            for simple in shortcuts:
                got = rules.link_common(Fm, alive, fs, fl, fpool, cnt, a, b, nshared, out, simple)
                assert (got >= 0) == want, (a, b, simple)
                if want:
                    assert got == len(common) and set(out[:got].tolist()) == common, (a, b)
                assert not cnt.any()
            seen.add(want)
    assert seen == {True, False}


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6)],
                         ids=["grid-with-hole", "torus"])
def test_lock_rule_kernel_matches_the_loops(make):
    """`rules.stranded_by_step` (with `rules.locked_endpoint_bare`) = the loop's LOCKED rule (`_locks.vanishing` or `_locks.strands`) for
    every edge of the mesh and of coarser versions, with a third, then two thirds of the vertices locked."""
    from qemjax._schedulers import locks as _locks

    V, F = make()
    seen = set()
    rng = np.random.default_rng(6)
    for Vm, Fm in _coarser(V, F):
        Fm = np.asarray(Fm, np.int64)
        n, E = len(Vm), _edges(Fm)
        faces, at = FaceLists(Fm, n), _at(Fm, n)
        fs, fl, fpool = _kernel_lists(Fm, n)
        for share in (1 / 3, 2 / 3):
            locked = rng.random(n) < share
            lk = _locks.RunLocks(locked)
            for a, b in E.tolist():
                P = np.array([[a, b]])
                (fids, *_), _, (dead, _) = faces.touched_with_dead(P)
                want = bool(_locks.vanishing(lk, P, np.array([len(fids)]))[0]
                            or _locks.strands(lk, faces, P, (dead, np.zeros(len(dead), np.int64)))[0])
                D = np.array(sorted(at[a] & at[b]), np.int64)
                got = rules.locked_endpoint_bare(len(fids), locked, a, b) or \
                    rules.stranded_by_step(a, b, len(D), locked, Fm, fl, D)
                assert got == want, (a, b)
                seen.add(want)
    assert seen == ({True, False} if len(F) != 120 else {False})  # (the closed torus strands no vertex)


def _kept(F, at, a, b):
    dead = at[a] & at[b]
    return np.array(sorted(at[a] - dead), np.int64), np.array(sorted(at[b] - dead), np.int64)


def _drop_kernel(F, a, b, ka, kb):
    R = np.zeros(len(ka) + len(kb) + 1, np.int64)
    m = rules.coincident_drop(a, b, F, ka, len(ka), kb, len(kb), R)
    return R[:m].tolist()


def _drop_reference(F, a, b, ka, kb):
    """`topo.coincident_removals` of the faces after the contraction, in face order."""
    fids = np.array(sorted([*ka.tolist(), *kb.tolist()]), np.int64)
    after = F[fids].copy()
    moved = np.isin(fids, kb)
    after[moved] = np.where(after[moved] == b, a, after[moved])
    return fids[topo.coincident_removals(after)].tolist()


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6),
                                  lambda: (np.zeros((5, 3)), TENT)], ids=["grid-with-hole", "torus", "tent"])
def test_coincident_kernels_match_the_general_rule(make):
    """`rules.coincident_drop` = `topo.coincident_removals` for every edge; on a simple mesh
    where the link rule holds, the shortcut (`rules.coincide_at_apexes`) says whether that drops anything."""
    V, F = make()
    seen = set()
    for Vm, Fm in _coarser(V, F):
        Fm = np.asarray(Fm, np.int64)
        n, E = len(Vm), _edges(Fm)
        at = _at(Fm, n)
        fs, fl, fpool = _kernel_lists(Fm, n)
        cnt, common = np.zeros((n, 3), np.int64), np.zeros(2, np.int64)
        for a, b in E.tolist():
            ka, kb = _kept(Fm, at, a, b)
            want = _drop_reference(Fm, a, b, ka, kb)
            assert _drop_kernel(Fm, a, b, ka, kb) == want, (a, b)
            nc = rules.link_common(Fm, np.ones(len(Fm), bool), fs, fl, fpool, cnt, a, b, len(at[a] & at[b]), common,
                                   True)
            if nc >= 0:
                got = nc == 2 and rules.coincide_at_apexes(Fm, ka, len(ka), kb, len(kb), common[0], common[1])
                assert got == bool(want), (a, b)
                seen.add(got)
    assert seen == ({True, False} if len(F) == len(TENT) else {False})  # the tent has a coinciding contraction


def test_coincident_drop_kernel_on_groups():
    """Random groups of coinciding faces, both orientations, some with repeated corners: oppositely
    oriented faces cancel lower index first, and the first of what is left stays, as
    `topo.coincident_removals` says."""
    rng = np.random.default_rng(7)
    a, b = 0, 1
    checked = 0
    for _ in range(400):
        k = int(rng.integers(2, 12))
        at_b = rng.random(k) < 0.5  # kept at b (it moves to a), else at a
        others = rng.integers(2, 6, (k, 2))
        others[(rng.random(k) < 0.1) & ~at_b, 1] = a  # (a, u, a): a repeated corner
        F = np.array([rng.permutation(t) for t in np.concatenate([np.where(at_b, b, a)[:, None], others], 1)])
        ka, kb = np.flatnonzero(~at_b), np.flatnonzero(at_b)
        want = _drop_reference(F, a, b, ka, kb)
        assert _drop_kernel(F, a, b, ka, kb) == want
        checked += bool(want)
    assert checked > 100


def _entry(P, cost, l2, stamps):
    return [(float(c), float(d), tie(a, b), a, b, int(s)) for (a, b), c, d, s in zip(P.tolist(), cost, l2, stamps)]


def test_heap_pops_in_key_then_stamp_order():
    """`speculate.heap_push`/`heap_pop` with `batches.queue_keys` pop in the order of the
    one-at-a-time queue's tuples (cost, squared length, tie, a, b, stamp) from `heapq`: ties in cost and
    length, zeros of both signs, negative and infinite costs, repeated pairs, interleaved pushes and pops."""
    rng = np.random.default_rng(2)
    k = 3000
    P = np.sort(rng.integers(0, 200, (k, 2)), axis=1)
    cost = rng.choice(np.array([0.0, -0.0, 1e-30, 2.5e-7, 3.0, -1e-8, np.inf], np.float32), k)
    cost[: k // 3] = rng.random(k // 3).astype(np.float32) * np.float32(1e-6)
    l2 = rng.choice(np.array([0.0, 1e-4, 2e-4, 0.5], np.float32), k)
    P[k - 40:] = P[:40]
    cost[k - 20:], l2[k - 20:] = cost[:20], l2[:20]
    keys = greedy_compiled.queue_keys(P, cost, l2)
    tuples = _entry(P, cost, l2, np.arange(1, k + 1))
    K = np.zeros((k + 1, 3), np.uint64)
    K[1:] = keys
    heap, ctr, ref, got, want = np.zeros(k, np.int64), np.zeros(jit.NCTR, np.int64), [], [], []
    for s in rng.permutation(k) + 1:
        jit.heap_push(heap, ctr, K, s)
        heapq.heappush(ref, tuples[s - 1])
        if rng.random() < 0.3:
            got.append(int(jit.heap_pop(heap, ctr, K)))
            want.append(heapq.heappop(ref)[5])
    while ref:
        got.append(int(jit.heap_pop(heap, ctr, K)))
        want.append(heapq.heappop(ref)[5])
    assert got == want and ctr[jit.C_HSIZE] == 0


def _first_wrong(orders, keys, start, end):
    """The first step that a stale interval open at it (begun before it, not ended before it) would have
    preceded (the order check, in Python)."""
    for k, o in enumerate(orders):
        if any(s < k and e >= k and key < o for key, s, e in zip(keys, start, end)):
            return k
    return len(orders)


def test_order_check_matches_python():
    """`speculate.first_wrong` = the order check in Python on random steps and intervals."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        n, niv = int(rng.integers(1, 30)), int(rng.integers(0, 40))
        skeys = np.sort(rng.integers(0, 50, n)).astype(np.uint64)
        skeys[rng.random(n) < 0.2] = np.uint64(rng.integers(0, 50))  # (stale entries may rank anywhere)
        start = np.sort(rng.integers(0, n + 1, niv))
        end = np.where(rng.random(niv) < 0.3, jit.OPEN, start + rng.integers(0, n, niv))
        ikeys = rng.integers(0, 60, niv).astype(np.uint64)
        K = np.zeros((n + 1, 3), np.uint64)
        K[1:, 0] = skeys
        steps = np.zeros((n, 10), np.int64)
        steps[:, jit.S_STAMP] = np.arange(1, n + 1)
        iv = np.zeros((niv, 5), np.int64)
        iv[:, jit.I_START], iv[:, jit.I_END] = start, end
        ik = np.zeros((niv, 3), np.uint64)
        ik[:, 0] = ikeys
        want = _first_wrong(skeys.tolist(), ikeys.tolist(), start.tolist(), end.tolist())
        assert jit.first_wrong(steps, K, iv, ik, n) == want


@pytest.mark.parametrize("case", ["torus-flip-45", "grid-max-error", "jittered-sphere", "torus-non-manifold",
                                  "locks-stop", "locks-weights-non-manifold", "atlas-locks-weights-non-manifold"])
def test_compiled_queue_ends_in_the_loops_state(case, monkeypatch):
    """After the run, the queue as the one-at-a-time loop leaves it: the same pairs in it at the same
    cost and position, the same ones blocked by the same rules (pairs unblocked around a contraction and
    never taken again show only here: the outputs above do not tell), the same faces."""
    seen = {}
    loop = greedy_compiled._Compiled.loop

    def kept_loop(self):
        loop(self)
        seen["compiled"] = self

    queue_cls = greedy.loop._Queue

    class KeptQueue(queue_cls):
        def __init__(self):
            super().__init__()
            seen["loop"] = self

    monkeypatch.setattr(greedy_compiled._Compiled, "loop", kept_loop)
    monkeypatch.setattr(greedy.loop, "_Queue", KeptQueue)
    make, kw = COMPILED[case] if case in COMPILED else (UV[case][0], dict(UV[case][1], attributes="uv"))
    if kw.get("method", "default") == "default":  # the summed queue's end: without the memoryless last stretch
        kw = {"late_memoryless": 0, **kw}
    new, _ = _run(make(), kw, monkeypatch, True)
    old, _ = _run(make(), kw, monkeypatch, False)
    c, q = seen["compiled"], seen["loop"]
    pairs, stamps = jit.export(c.cur)
    got = {(p >> 32, p & 0xFFFFFFFF): (float(c.cost[s]), c.X[s].tolist()) for p, s in zip(pairs.tolist(), stamps.tolist())}
    want = {p: (float(v[2]), np.asarray(v[0]).tolist()) for p, v in q.placed.items()}
    assert got == want
    bp, codes = jit.export(c.blocked)
    assert {(p >> 32, p & 0xFFFFFFFF): k for p, k in zip(bp.tolist(), codes.tolist())} == dict(q.blocked)
    counts = np.zeros(c.n, np.int64)
    for a, b in q.blocked:
        counts[a] += 1
        counts[b] += 1
    assert np.array_equal(c.bat, counts)


@pytest.mark.slow
def test_kernels_stay_in_bounds():
    """The compiled loop indexes its arrays unchecked: run the cases that push its room checks (arrays
    grown from near-empty sizes, rollbacks, high-degree vertices, dropped faces, non-simple meshes) with
    numba's bounds checks on, in a process of its own (a separately cached compilation), where an index
    past an array's end raises."""
    import hashlib
    import os
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    here = Path(__file__).resolve()
    # a cache of its own per state of the package's sources: numba checks a cached function against its own
    # file only, so a cache kept from other sources could hold callees that were renamed or changed since.
    # (Most bounds-checked loops are not cached at all: numba declines, "uses dynamic globals", since a
    # failed check's error refers to objects of this process; so each run of this test compiles them.)
    digest = hashlib.sha256()
    for path in sorted((here.parent.parent / "qemjax").rglob("*.py")):
        digest.update(path.read_bytes())
    cache = Path(tempfile.gettempdir()) / f"qemjax-numba-boundscheck-{digest.hexdigest()[:16]}"
    # LLVM's optimisation off: the checks are made as the loops are lowered, whatever the level, and the
    # compilation (most of this test's time) is shorter
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_OPT="0", NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", str(here), "-k",
                          "grows or bipyramid or grid-with-hole or two-parts or non_simple or nested or locks"],
                         cwd=here.parent.parent, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert " passed" in out.stdout


# kept attributes (UV seams, `greedy.wedges`): the seam rule at the pop, the wedge updates journaled (a
# batch undone restores them), pairs at seam vertices priced at an allowed endpoint where the loop pushes them
SPOT = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "spot" / "spot.obj"
_NA = len(atlas_sphere(3)[0].vertices)
UV = {
    "atlas": (lambda: atlas_sphere(3)[0], {"ratio": 0.1}),
    "atlas-non-manifold": (lambda: atlas_sphere(3)[0], {"ratio": 0.02, "preserve_topology": False}),
    "atlas-max-error": (lambda: atlas_sphere(3)[0], {"max_error": 1e-3}),
    "atlas-locks": (lambda: atlas_sphere(3)[0], {"ratio": 0.1, "locked": np.arange(0, _NA, 17)}),
    "atlas-locks-weights-non-manifold": (lambda: atlas_sphere(3)[0], {
        "ratio": 0.05, "preserve_topology": False, "locked": _random_picks(_NA, 40, 6),
        "vertex_weights": np.random.default_rng(7).random(_NA) * 3}),
    "atlas-weight0": (lambda: atlas_sphere(3)[0], {"ratio": 0.1, "attribute_weights": 0}),  # plain QEM model
    "spot": (lambda: str(SPOT), {"ratio": 0.1}),
    "spot-non-manifold-locks": (lambda: str(SPOT), {"ratio": 0.05, "preserve_topology": False,
                                                    "locked": np.arange(0, 2930, 31)}),
}


@pytest.mark.parametrize("case", list(UV))
def test_compiled_queue_keeps_attributes_as_the_loop(case, monkeypatch):
    """``attributes="uv"`` on seamed meshes: the compiled batches give the loop's run bit for bit (the
    contractions, positions, UVs and wedges, stats), with the seam rule refusing contractions."""
    make, kw = UV[case]
    if case.startswith("spot") and not SPOT.exists():
        pytest.skip("the shared textured mesh is absent")
    kw = dict(kw, attributes="uv")
    new, ran = _run(make(), kw, monkeypatch, True)
    old, ran_old = _run(make(), kw, monkeypatch, False)
    assert len(ran) == 1 and ran_old == []
    _assert_same(new, old)
    for name in ("uv", "wedge_faces", "wedge_vertex"):
        _same(getattr(new, name), getattr(old, name), name)
    assert new.stats["seam_vertices_in"] > 50
    if "ratio" in kw:
        assert new.stats["rejected_by"]["seam"] > 0  # the rule fired
    else:
        assert new.stop_reason == "max_error"
    if case in ("atlas", "atlas-non-manifold"):
        assert ran[0] > 0  # batches were undone (with their wedge changes) and run again
    if "locked" in kw:
        assert new.stats["locked"] > 0


def test_compiled_queue_keeps_the_loops_wedges(monkeypatch):
    """After a uv run, the tracker as the loop leaves it: every corner's wedge, every wedge value and the
    seam flags (which decide how pairs at vertices with no faces left are priced), and the queue's entries."""
    trackers = []
    real = greedy.run

    def keep(*a, **k):
        trackers.append(k["wedges"])
        return real(*a, **k)

    monkeypatch.setattr(greedy, "run", keep)
    mesh = atlas_sphere(3)[0]
    kw = {"ratio": 0.02, "preserve_topology": False, "attributes": "uv"}
    _run(mesh, kw, monkeypatch, True)
    _run(mesh, kw, monkeypatch, False)
    new, old = trackers
    assert new is not old
    for name in ("C", "val", "multi"):
        _same(getattr(new, name), getattr(old, name), name)


@pytest.mark.parametrize("case", ["atlas", "atlas-locks-weights-non-manifold"])
def test_an_undone_batch_restores_the_wedges(case, monkeypatch):
    """Every other batch undone whole (its order check told to fail at its first step): the tracker's
    corners' wedges, values and seam flags come back exactly as the batch found them, and the run is still
    the loop's."""
    snaps, restored, changed = [], [], []
    calls = iter(range(10**9))
    real_spec, real_first, real_undo = jit.speculate, jit.first_wrong, jit.undo

    def speculate(*a):
        snaps.append([np.array(x, copy=True) for x in (a[2].C, a[2].val, a[2].multi)])  # the seams' arrays
        return real_spec(*a)

    def first_wrong(*a):
        k = real_first(*a)
        return 0 if a[4] and next(calls) % 2 == 0 else k

    def undo(mark, *a):
        wedges = a[-4:-1]
        if mark == 0:
            changed.append(any(not np.array_equal(x, y) for x, y in zip(wedges, snaps[-1])))
        real_undo(mark, *a)
        if mark == 0:
            restored.append(all(np.array_equal(x, y) for x, y in zip(wedges, snaps[-1])))

    make, kw = UV[case]
    kw = dict(kw, attributes="uv")
    old, _ = _run(make(), kw, monkeypatch, False)
    with monkeypatch.context() as m:
        m.setattr(jit, "speculate", speculate)
        m.setattr(jit, "first_wrong", first_wrong)
        m.setattr(jit, "undo", undo)
        new, ran = _run(make(), kw, monkeypatch, True)
    assert len(restored) > 5 and all(restored)
    assert sum(changed) > 5  # the undone batches had changed wedges
    _assert_same(new, old)
    _same(new.uv, old.uv, "uv")
