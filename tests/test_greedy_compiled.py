"""The greedy queue's compiled host side (`_schedulers.greedy_compiled`, kernels in `greedy_jit`) gives
exactly what the one-at-a-time loop of `_schedulers.greedy` gives, bit for bit; and each kernel answers
as the Python code it replaces (flip test, link rule, heap order, order check)."""
from __future__ import annotations

import heapq
import warnings

import numpy as np
import pytest

import qemjax
from qemjax import shapes

pytest.importorskip("numba")  # a core dependency; without it the Python batches run (tests/test_greedy_batches.py)
from qemjax._kernels import flips as flips_mod
from qemjax._schedulers import greedy, greedy_batches, greedy_compiled
from qemjax._schedulers import greedy_jit as jit
from qemjax._schedulers import greedy_rules_jit as rules_jit
from test_greedy_batches import CASES, TENT, _edges, _same


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


COMPILED = dict(CASES)
COMPILED.update({
    "jittered-sphere": (_jittered_sphere, {"ratio": 0.05}),
    "bipyramid": (_bipyramid, {"ratio": 0.1}),
    "two-parts": (_two_spheres, {"ratio": 0.01}),
})


def _run(mesh, kw, monkeypatch, compiled: bool):
    ran = []
    loop = greedy_compiled._Compiled.loop

    def counting_loop(self):
        loop(self)
        ran.append(self.failed)

    with monkeypatch.context() as m:
        m.setattr(greedy_compiled._Compiled, "loop", counting_loop)
        if not compiled:  # the reference: the one-at-a-time loop
            m.setattr(greedy_batches, "eligible", lambda model, wedges: False)
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


@pytest.mark.parametrize("case", list(COMPILED))
def test_compiled_queue_gives_the_one_at_a_time_result(case, monkeypatch):
    make, kw = COMPILED[case]
    mesh = make()
    new, ran = _run(mesh, kw, monkeypatch, True)
    old, ran_old = _run(mesh, kw, monkeypatch, False)
    assert len(ran) == 1 and ran_old == []  # the compiled loop ran (once), then not
    if case == "grid-with-hole":
        assert ran[0] > 0  # some batches were undone and run again
    _assert_same(new, old)
    k = max(1, len(old.faces) * 2)  # the record replays the same prefixes
    _same(new.replay(k).faces, old.replay(k).faces, "replay")


def test_compiled_queue_grows_its_arrays(monkeypatch):
    """Started with almost no room (journal, intervals, pools, queue), the arrays grow between batches
    (batches that stop for room end early): the same result."""
    grown = []
    room = greedy_compiled._Compiled.room

    def counting_room(self, stamps=0, full=False):
        grown.append(full)
        return room(self, stamps, full)

    make, kw = COMPILED["grid-with-hole"]
    mesh = make()
    old, _ = _run(mesh, kw, monkeypatch, False)
    monkeypatch.setattr(greedy_compiled, "ROOM", 1)
    monkeypatch.setattr(greedy_compiled, "SLACK", 4)
    monkeypatch.setattr(greedy_compiled, "JOURNAL_ROWS", 8)
    monkeypatch.setattr(greedy_compiled, "INTERVAL_ROWS", 2)
    monkeypatch.setattr(greedy_compiled._Compiled, "room", counting_room)
    new, ran = _run(mesh, kw, monkeypatch, True)
    assert len(ran) == 1 and any(grown)
    _assert_same(new, old)


def test_flip_kernel_matches_numpy():
    """`greedy_rules_jit.flips` per face = `flips.flips_host_faces`, bit for bit in its float32 decisions: random
    faces and moves, near-degenerate ones (collinear, zero area, tiny), three thresholds."""
    rng = np.random.default_rng(1)
    V = rng.normal(size=(60, 3)).astype(np.float32)
    V[50:] = V[:10] + rng.normal(0, 1e-4, (10, 3)).astype(np.float32)  # near duplicates
    V[40:45] = np.linspace(0, 1, 5)[:, None] * np.float32([1, 2, 3])  # collinear
    F = np.array([rng.choice(60, 3, replace=False) for _ in range(3000)], np.int64)
    N0 = flips_mod._cross3(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]).astype(np.float32)
    N0[::7] = rng.normal(size=N0[::7].shape).astype(np.float32)  # references far from the faces' own
    k = rng.integers(0, 3, len(F))
    X = np.where(rng.random((len(F), 1)) < 0.3, V[F[np.arange(len(F)), (k + 1) % 3]] * np.float32(1.0001),
                 rng.normal(size=(len(F), 3))).astype(np.float32)
    for cos_max in (0.0, float(np.cos(np.radians(45))), -2.0):
        want = flips_mod.flips_host_faces(V, N0, F, np.arange(len(F)), k, X, cos_max)
        got = [rules_jit.flips(V, N0, F, f, k[f], X[f], np.float32(cos_max), np.float32(flips_mod.SLIVER))
               for f in range(len(F))]
        assert np.array_equal(np.array(got), want)
        assert 0 < want.sum() < len(F)


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6),
                                  lambda: (np.zeros((5, 3)), TENT)], ids=["grid-with-hole", "torus", "tent"])
def test_link_kernel_matches_python(make):
    """`greedy_rules_jit.link_common` = `greedy_batches._Mesh.link_common` for every edge of simple meshes and
    coarser versions of them (irregular valence, degree-3 vertices)."""
    V, F = make()
    meshes = [(V, F)]
    if len(F) > 10:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            meshes += [(r.vertices, r.faces) for r in (qemjax.simplify((V, F), ratio=t) for t in (0.4, 0.1))]
    seen = set()
    for Vm, Fm in meshes:
        Fm = np.asarray(Fm, np.int64)
        n, E = len(Vm), _edges(Fm)
        mesh = greedy_batches._Mesh(Fm, n, E)
        fs, fl, fpool = greedy_compiled._lists(n, Fm.reshape(-1), np.repeat(np.arange(len(Fm)), 3))
        cnt, out = np.zeros((n, 3), np.int64), np.zeros(2, np.int64)
        for a, b in E.tolist():
            nshared = len(mesh.at[a] & mesh.at[b])
            want = mesh.link_common(a, b, nshared)
            got = rules_jit.link_common(Fm, fs, fl, fpool, cnt, a, b, nshared, out, True)
            assert (got < 0) == (want is None), (a, b)
            if want is not None:
                assert got == len(want) and set(out[:got].tolist()) == want, (a, b)
            assert not cnt.any()
            seen.add(got >= 0)
    assert seen == {True, False}


def test_heap_pops_in_key_then_stamp_order():
    """`greedy_jit.heap_push`/`heap_pop` pop by (key, stamp), as the int entries of `greedy_batches` do
    from `heapq`: ties in cost and length, repeated pairs, interleaved pushes and pops."""
    rng = np.random.default_rng(2)
    k = 3000
    P = np.sort(rng.integers(0, 200, (k, 2)), axis=1)
    cost = rng.choice(np.array([0.0, -0.0, 1e-30, 3.0, np.inf], np.float32), k)
    l2 = rng.choice(np.array([0.0, 1e-4, 0.5], np.float32), k)
    P[k - 40:] = P[:40]
    keys = greedy_compiled.queue_keys(P, cost, l2)
    ints = greedy_batches._entries(P, cost, l2)
    K = np.zeros((k + 1, 3), np.uint64)
    K[1:] = keys
    heap, ctr, ref, got, want = np.zeros(k, np.int64), np.zeros(10, np.int64), [], [], []
    for s in rng.permutation(k) + 1:
        jit.heap_push(heap, ctr, K, s)
        heapq.heappush(ref, ints[s - 1] | int(s))
        if rng.random() < 0.3:
            got.append(int(jit.heap_pop(heap, ctr, K)))
            want.append(heapq.heappop(ref) & ((1 << greedy_batches.STAMP_BITS) - 1))
    while ref:
        got.append(int(jit.heap_pop(heap, ctr, K)))
        want.append(heapq.heappop(ref) & ((1 << greedy_batches.STAMP_BITS) - 1))
    assert got == want and ctr[jit.C_HSIZE] == 0


def test_order_check_matches_python():
    """`greedy_jit.first_wrong` = `greedy_batches._Batches.first_wrong` on random steps and intervals."""
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
        py = greedy_batches._Batches.__new__(greedy_batches._Batches)
        py.iv = type("IV", (), {"start": start.tolist(), "end": end.tolist()})
        assert jit.first_wrong(steps, K, iv, ik, n) == py.first_wrong(skeys.tolist(), ikeys.tolist())


@pytest.mark.parametrize("case", ["torus-flip-45", "grid-max-error", "jittered-sphere"])
def test_compiled_queue_ends_in_the_python_batches_state(case, monkeypatch):
    """After the run, the queue as `greedy_batches._Batches` leaves it: the same pairs current, at the same
    keys, the same ones blocked by the same rules (pairs unblocked around a contraction and never taken
    again show only here: the outputs above do not tell), the same faces."""
    seen = {}

    def keep(cls, name):
        loop = cls.loop

        def kept_loop(self):
            loop(self)
            seen[name] = self
        monkeypatch.setattr(cls, "loop", kept_loop)

    keep(greedy_compiled._Compiled, "compiled")
    keep(greedy_batches._Batches, "python")
    make, kw = COMPILED[case]
    mesh = make()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        qemjax.simplify(mesh, scheduler="greedy", **kw)
        monkeypatch.setattr(greedy, "_compiled", lambda: None)
        qemjax.simplify(mesh, scheduler="greedy", **kw)
    c, py = seen["compiled"], seen["python"]
    pairs, stamps = jit.export(c.cur)
    K = c.K[stamps].astype(object)
    keys = dict(zip(pairs.tolist(), ((K[:, 0] << 96) | (K[:, 1] << 32) | K[:, 2]).tolist()))
    assert keys == {p: e >> greedy_batches.STAMP_BITS for p, e in py.cur.items()}
    bp, codes = jit.export(c.blocked)
    assert dict(zip(bp.tolist(), codes.tolist())) == dict(py.blocked)
    counts = np.zeros(c.n, np.int64)
    for v, k in py.blocked.at.items():
        counts[v] = k
    assert np.array_equal(c.bat, counts)
    assert np.array_equal(c.alive, py.mesh.alive) and np.array_equal(c.T, np.array(py.mesh.tri))


@pytest.mark.slow
def test_kernels_stay_in_bounds():
    """The compiled loop indexes its arrays unchecked: run the cases that push its room checks (arrays
    grown from near-empty sizes, rollbacks, high-degree vertices) with numba's bounds checks on, in a
    process of its own (a separately cached compilation), where an index past an array's end raises."""
    import os
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    env = dict(os.environ, NUMBA_BOUNDSCHECK="1",
               NUMBA_CACHE_DIR=str(Path(tempfile.gettempdir()) / "qemjax-numba-boundscheck"))
    here = Path(__file__).resolve()
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(here), "-k",
                          "grows or bipyramid or grid-with-hole or two-parts"],
                         cwd=here.parent.parent, env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert " passed" in out.stdout
