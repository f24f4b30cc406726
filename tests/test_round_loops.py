"""The parallel round's compiled loops (`_schedulers.parallel.selection` and `.contraction`) make exactly the choices of the numpy
stages they replace: whole runs (alone and batched) give the same result bit for bit, and each loop
answers as the numpy code it stands for (the flip test, the faces' and the pairs' contraction)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._kernels import flips as flips_mod
from qemjax._mesh import topology as topo
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers import rules
from qemjax._schedulers import parallel
from qemjax._schedulers.parallel import contraction, selection
from qemjax._schedulers.parallel import driver
from edges_reference import contract_edges
from test_attributes import atlas_sphere
import reference_rules
from test_greedy_compiled import CASES, _bipyramid, _jittered_sphere, _same, _two_spheres

def _finned_sphere(k=20, size=0.02):
    """A bumpy sphere with a small closed tetrahedron (a, b, c0, c1) on k of its edges (c0, c1), which then
    have four faces: contracting (a, b) passes the link condition (c0 and c1 have more than three
    neighbours) but leaves (a, c0, c1) and (b, c0, c1) coincident, so the coincidence rule refuses it."""
    V, F = shapes.bumpy_sphere(3)
    V, F = [np.asarray(v, float) for v in V], [list(f) for f in np.asarray(F)]
    used = set()
    for f in np.asarray(F)[np.random.default_rng(0).permutation(len(F))]:
        c0, c1 = int(f[0]), int(f[1])
        if c0 in used or c1 in used:
            continue
        used |= {c0, c1}
        mid, step = (V[c0] + V[c1]) / 2, (V[c1] - V[c0]) * 0.05
        out = mid / np.linalg.norm(mid) * size
        a, b = len(V), len(V) + 1
        V += [mid + out + step, mid + out - step]
        F += [[a, b, c0], [b, a, c1], [a, c1, c0], [b, c0, c1]]
        if len(used) >= 2 * k:
            break
    return np.array(V), np.array(F)


RUNS = {k: v for k, v in CASES.items() if k not in ("cube-non-manifold",)}  # (manifold mode only)
RUNS.update({
    "jittered-sphere": (_jittered_sphere, {"ratio": 0.05}),
    "bipyramid": (_bipyramid, {"ratio": 0.1}),
    "two-parts": (_two_spheres, {"ratio": 0.01}),
    "default-method": (lambda: shapes.bumpy_sphere(4), {"ratio": 0.02, "method": "default"}),
    "regularized": (lambda: shapes.torus(n_major=24, n_minor=12), {"ratio": 0.1, "regularize": 0.1}),
    "double-cone": (lambda: shapes.double_cone(60), {"ratio": 0.2}),
    "finned-sphere": (_finned_sphere, {"ratio": 0.1}),  # coincident faces refused inside the loop
    # kept UVs: the seam rule refuses contractions inside the loop, and the wedges follow the contractions
    "uv-seams": (lambda: atlas_sphere(3)[0], {"ratio": 0.1, "attributes": "uv"}),
    "uv-seams-default": (lambda: atlas_sphere(3)[0], {"ratio": 0.05, "attributes": "uv", "method": "default"}),
})


def _run(mesh, kw, monkeypatch, compiled: bool, batch=None):
    seen = []
    choose = driver.choose

    def recording(run, glue=True):
        rnd = choose(run, glue)
        seen.append(isinstance(rnd, parallel.LoopRound))
        return rnd

    with monkeypatch.context() as m:
        m.setattr(driver, "choose", recording)
        if not compiled:
            m.setattr(selection, "fits", lambda *a: False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if batch is not None:
                return qemjax.simplify_batch(mesh, batch), seen
            return qemjax.simplify(mesh, **({"method": "classic"} | kw)), seen


def _assert_same(new, old):
    for name in ("vertices", "faces", "vertex_error", "max_error", "stop_reason"):
        _same(getattr(new, name), getattr(old, name), name)
    for name in ("pairs", "positions", "costs", "rounds"):
        _same(getattr(new.history, name), getattr(old.history, name), f"history.{name}")
    drop = {k for k in (*new.stats, *old.stats) if k.endswith("_s") or k in ("compilations", "batch")}
    _same({k: v for k, v in new.stats.items() if k not in drop},
          {k: v for k, v in old.stats.items() if k not in drop}, "stats")


@pytest.mark.parametrize("case", list(RUNS))
def test_compiled_round_gives_the_numpy_rounds_result(case, monkeypatch):
    make, kw = RUNS[case]
    mesh = make()
    new, seen = _run(mesh, kw, monkeypatch, True)
    old, seen_old = _run(mesh, kw, monkeypatch, False)
    # the default's memoryless last stretch: a second run (not with UVs kept: it stays summed)
    runs = 2 if kw.get("method") == "default" and "attributes" not in kw else 1
    assert seen == [True] * runs and seen_old == [False] * runs
    _assert_same(new, old)
    assert new.stats["rounds"] > 1
    if "uv" in case:
        _same(new.uv, old.uv, "uv")
        assert new.stats["rejected_by"]["seam"] > 0  # the rule did refuse contractions
    if case == "finned-sphere":
        assert new.stats["rejected_by"]["coincident"] > 0


def test_compiled_round_in_a_batch(monkeypatch):
    """Copies with their own targets, boundary weights and max_error leave the passes at their own times
    (each copy's pass rule): the same results as the numpy rounds, and as each copy alone."""
    mesh = shapes.bumpy_sphere(3)
    configs = [{"ratio": 0.1}, {"ratio": 0.3, "boundary_weight": 1.0}, {"ratio": 0.02},
               {"max_error": 1e-4}, {"ratio": 0.05, "area_weighted": False}]
    configs = [{"method": "classic"} | c for c in configs]
    new, seen = _run(mesh, None, monkeypatch, True, batch=configs)
    old, seen_old = _run(mesh, None, monkeypatch, False, batch=configs)
    assert seen and all(seen), seen  # every batch of the call ran the compiled loops ...
    assert seen_old and not any(seen_old), seen_old  # ... and none with them switched off
    for a, b in zip(new, old):
        _assert_same(a, b)
    alone, _ = _run(mesh, configs[2], monkeypatch, True)
    _same(new[2].faces, alone.faces, "batch vs alone")


def test_flip_test_matches_the_kernel():
    """`rules.flips` (the rounds' flip test) against `reference_rules.flips_host_faces` (the device
    kernel's host twin) on random faces, near-degenerate ones included, at the default threshold and 45°,
    with and without the quality guard (alone, with flips allowed)."""
    rng = np.random.default_rng(3)
    V = rng.normal(size=(60, 3)).astype(np.float32)
    V[50:] = V[:10] + rng.normal(0, 1e-4, (10, 3)).astype(np.float32)  # near-duplicates: slivers
    F = np.array([rng.choice(60, 3, replace=False) for _ in range(400)], np.int32)
    N0 = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]).astype(np.float32)
    N0[::7] = -N0[::7]  # some references disagree with the face
    corner = rng.integers(0, 3, 400)
    X = (V[F[np.arange(400), corner]] + rng.normal(0, 0.3, (400, 3))).astype(np.float32)
    VQ = np.concatenate([V, np.zeros((60, 4), np.float32)], 1)
    for cos_max, q in ((0.0, 0.0), (np.cos(np.radians(45)), 0.0), (0.0, 0.3), (-2.0, 0.5)):
        want = reference_rules.flips_host_faces(VQ, N0, F, np.arange(400), corner, X, cos_max, q)
        shape = (np.float32(flips_mod.SLIVER), np.float32(q))
        got = np.array([rules.flips(VQ, N0, F, f, corner[f], X[f], np.float32(cos_max), shape) for f in range(400)])
        assert want.any() and not want.all()
        np.testing.assert_array_equal(got, want)


def _selected_pairs(F, n, seed):
    """Vertex-disjoint interior edges two edges apart that pass the link test, their apexes and the
    pairs E with counts and degrees (as a round hands them to the contraction)."""
    E, ecount = topo.edges(F, n)
    deg = topo.vertex_degree(E, n)
    bvert = np.zeros(n, bool)
    bvert[E[ecount == 1].reshape(-1)] = True
    rng = np.random.default_rng(seed)
    locked = np.zeros(n, bool)
    pick = []
    nbr = [set() for _ in range(n)]
    for u, v in E:
        nbr[u].add(v)
        nbr[v].add(u)
    for i in rng.permutation(len(E)):
        a, b = E[i]
        ring = {a, b} | nbr[a] | nbr[b]
        if not any(locked[list(ring)]):
            pick.append(i)
            locked[list(ring)] = True
    P = E[pick]
    ok, apex = topo.link_ok(P, ecount[pick], E, n, bvert, deg, apexes=True)
    return E, ecount, deg, P[ok], apex[ok]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contraction_loops_match_the_numpy_code(seed):
    V, F = shapes.bumpy_sphere(2) if seed != 2 else shapes.grid(12, hole=True)
    n = len(V)
    E, ecount, deg, P, apex = _selected_pairs(F, n, seed)
    assert len(P) > 5
    a, b = P[:, 0].copy(), P[:, 1].copy()
    # pairs: the numpy update against the compiled one
    want = contract_edges(E, ecount, a, b, apex, n, deg)
    label = np.full(n, -1, np.int32)
    got = contraction.contract_edges(E, ecount, deg, a, b, apex.astype(np.int64), label)
    for w, g, name in zip(want, got, ("E", "ecount", "keep", "degree", "stale")):
        np.testing.assert_array_equal(g, w, err_msg=name)
    assert (label == -1).all()
    # faces: `FaceLists.contract` against the compiled loop (with a pool that must be compacted first)
    ref, new = FaceLists(F, n), FaceLists(F, n)
    dead_ref = ref.contract(a, b)
    k = int(new.cnt[a].sum() + new.cnt[b].sum())
    new._compact(k)
    new.end, dead = contraction.contract_faces(a, b, new.F, new.alive, new.cnt, new.off, new.pool, new.end)
    np.testing.assert_array_equal(np.sort(dead), np.sort(dead_ref))
    np.testing.assert_array_equal(new.F[new.alive], ref.F[ref.alive])
    np.testing.assert_array_equal(new.alive, ref.alive)
    for v in range(n):  # each vertex's live faces, as sets
        w1, f1 = ref.around(np.array([v]))
        w2, f2 = new.around(np.array([v]))
        assert sorted(f1) == sorted(f2), v
    # and the edges of the contracted faces are the updated pairs
    E2, c2 = topo.edges(new.F[new.alive], n)
    order = np.lexsort((got[0][:, 1], got[0][:, 0]))
    np.testing.assert_array_equal(got[0][order], E2)
    np.testing.assert_array_equal(got[1][order], c2)


def test_large_runs_keep_the_numpy_stages(monkeypatch):
    """Above `selection.MAX_FACES` the rounds run the numpy stages (faster there), with the same result."""
    mesh = shapes.bumpy_sphere(3)
    small, seen_small = _run(mesh, {"ratio": 0.1}, monkeypatch, True)
    monkeypatch.setattr(selection, "MAX_FACES", len(mesh[1]) - 1)
    large, seen_large = _run(mesh, {"ratio": 0.1}, monkeypatch, True)
    assert seen_small == [True] and seen_large == [False]
    _assert_same(large, small)


@pytest.mark.parametrize("threads", ["inline", "worker"])
@pytest.mark.parametrize("seed", [0, 2])
def test_edge_update_on_two_threads_is_contract_edges(seed, threads, monkeypatch):
    """`parallel.pairs.EdgeUpdate` (the pairs' update with its passes split between the worker and the calling
    thread) returns `contraction.contract_edges`' arrays, dtypes included, and leaves the labels cleared;
    ``worker``: the halves really run on the worker (no size is too small to hand over)."""
    from qemjax._schedulers import select
    from qemjax._schedulers.parallel.pairs import EdgeUpdate

    if threads == "worker":
        monkeypatch.setattr(select, "INLINE_ROWS", 0)
    V, F = shapes.bumpy_sphere(2) if seed != 2 else shapes.grid(12, hole=True)
    n = len(V)
    E, ecount, deg, P, apex = _selected_pairs(F, n, seed)
    a, b = P[:, 0].copy(), P[:, 1].copy()
    label = np.full(n, -1, np.int32)
    want = contraction.contract_edges(E, ecount, deg, a, b, apex.astype(np.int64), label)
    got = EdgeUpdate(E, ecount, deg, a, b, apex.astype(np.int64), label).result()
    for w, g, name in zip(want, got, ("E", "ecount", "keep", "degree", "stale")):
        assert g.dtype == w.dtype, name
        np.testing.assert_array_equal(g, w, err_msg=name)
    assert (label == -1).all() and not want[2].all()


@pytest.mark.parametrize("kw", [{"method": "default"}, {"method": "classic"},
                                {"method": "classic", "preserve_topology": False}],
                         ids=["default", "compiled-loops", "numpy-stages-rebuilt"])
def test_a_round_that_only_rejected_selects_again_from_its_own_pairs(kw, monkeypatch):
    """After a round whose every selected pair broke a rule, the next round selects among the same pairs
    and prices without the rejected ones (`Round.without_rejected`) instead of updating and pricing them
    again: the same result, bit for bit, as the full stages 1 and 2, and the pairs are made only in the
    rounds after a contraction (a thin torus near its end: many such rounds)."""
    mesh = shapes.torus(1.0, 0.05, 64, 8)
    kw = {"ratio": 0.02} | kw
    made, again = [], []

    def counted(pairs):
        def run(self, prev, need):
            made.append(prev)
            return pairs(self, prev, need)
        return run

    without_rejected = parallel.stages.Round.without_rejected

    def shortcut(self, st, valid):
        again.append(st)
        return without_rejected(self, st, valid)

    def full_stages(self, st, valid):  # the stages before: the same pairs rebuilt and priced again
        again.append(st)
        self.retry(st)
        return None

    with monkeypatch.context() as m:
        for cls in (parallel.stages.Round, parallel.GlueRound):
            m.setattr(cls, "pairs", counted(cls.pairs))
        m.setattr(parallel.stages.Round, "without_rejected", shortcut)
        new, _ = _run(mesh, kw, monkeypatch, True)
        new_made, new_again, made[:], again[:] = len(made), len(again), [], []
        m.setattr(parallel.stages.Round, "without_rejected", full_stages)
        old, _ = _run(mesh, kw, monkeypatch, True)
        old_made, old_again = len(made), len(again)
    _assert_same(new, old)
    assert new_again == old_again >= 3  # rounds that only rejected: the case at hand
    assert old_made == new.stats["rounds"]  # every round made its pairs ...
    assert new_made == old_made - new_again  # ... now every round but those after one that only rejected
