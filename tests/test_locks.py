"""Locked vertices and importance weights (`qemjax._pipeline.locks`): ``simplify(locked=..., vertex_weights=...)``."""
from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import shapes
from qemjax._io.text import obj_vertices as _obj_vertices
from qemjax._costs import at_kept
from qemjax._costs import area as area_model

from conftest import assert_valid

METHODS = {
    "qem": "qem",
    "esqem": "esqem",
    "area": "area",
    "line": "line",
    "probabilistic": "probabilistic",
    "memoryless": qemjax.QEM(memoryless=True),
    "accurate": "accurate",  # memoryless, rank placement, refit=1
    "regularize": qemjax.QEM(regularize=0.1),
    "area_weight": qemjax.QEM(area_weight=0.1),
}
SCHEDULERS = ("parallel", "greedy")


def _mesh(dtype=np.float64):
    m = shapes.bumpy_sphere(subdivisions=2)  # 162 vertices, 320 faces
    return np.asarray(m.vertices).astype(dtype), np.asarray(m.faces)


def _locked(n, k=16, seed=0):
    return np.sort(np.random.default_rng(seed).choice(n, k, replace=False))


def _row_of(res, i):
    """The output row of input vertex i (no welding here: cleaned ids are the given ones). ESQEM's split
    midpoints come after the contracted mesh's vertices and take an endpoint's id: the first row is i's."""
    rows = np.flatnonzero(res.source_vertices == i)
    assert rows.size >= 1, f"locked vertex {i} is not in the output"
    return rows[0]


@pytest.mark.parametrize("scheduler", SCHEDULERS)
@pytest.mark.parametrize("name", list(METHODS))
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_locked_vertices_survive_exactly(name, scheduler, dtype):
    V, F = _mesh(dtype)
    lk = _locked(len(V))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a method's own notes (ESQEM's splitting) are not under test
        res = qemjax.simplify((V, F), ratio=0.2, method=METHODS[name], scheduler=scheduler, locked=lk)
    assert res.stop_reason == "target"
    assert_valid(res, V0=V.astype(np.float64), F0=F, allow_flips=name == "accurate")
    for i in lk:
        row = res.vertices[_row_of(res, i)]
        assert np.array_equal(row, V[i].astype(np.float64)), (i, row, V[i])
    pairs = res.history.pairs
    mask = np.zeros(len(V), bool)
    mask[lk] = True
    assert not np.any(mask[pairs[:, 1]]), "a locked vertex was removed"
    assert not np.any(mask[pairs[:, 0]] & mask[pairs[:, 1]]), "two locked vertices contracted"
    # every level of the record keeps them where they are
    rec = res.record
    for j in sorted({0, len(rec.history) // 3, len(rec.history) // 2, len(rec.history)}):
        lev = rec.replay(contractions=j)
        for i in lk:
            r = np.flatnonzero(lev.source_vertices == i)
            assert r.size == 1 and np.array_equal(lev.vertices[r[0]], V[i].astype(np.float64))


def test_record_round_trip_keeps_locks(tmp_path):
    V, F = _mesh()
    lk = _locked(len(V))
    res = qemjax.simplify((V, F), ratio=0.2, locked=lk)
    path = tmp_path / "rec.npz"
    res.record.save(path)
    back = qemjax.load_record(path) if hasattr(qemjax, "load_record") else None
    if back is None:
        from qemjax._record.history import load_record
        back = load_record(path)
    assert np.array_equal(back.locked, res.record.locked)
    lev = back.replay(contractions=len(back.history))
    assert np.array_equal(lev.vertices, res.record.replay(contractions=len(back.history)).vertices)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_weights_keep_detail_where_heavy(scheduler):
    V, F = _mesh()
    top = V[:, 2] > 0
    base = qemjax.simplify((V, F), ratio=0.2, scheduler=scheduler)
    heavy = qemjax.simplify((V, F), ratio=0.2, scheduler=scheduler, vertex_weights=np.where(top, 100.0, 1.0))
    light = qemjax.simplify((V, F), ratio=0.2, scheduler=scheduler, vertex_weights=np.where(top, 0.01, 1.0))
    share = [np.mean(top[r.source_vertices]) for r in (light, base, heavy)]
    assert share[0] < share[1] < share[2], share
    assert share[2] > 0.6 and share[0] < 0.4, share


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_no_locks_and_unit_weights_change_nothing(scheduler):
    V, F = _mesh()
    ref = qemjax.simplify((V, F), ratio=0.2, scheduler=scheduler)
    for kw in ({"locked": np.zeros(len(V), bool)}, {"vertex_weights": np.ones(len(V))}, {"locked": []},
               {"locked": np.zeros(len(V), bool), "vertex_weights": np.ones(len(V))}):
        res = qemjax.simplify((V, F), ratio=0.2, scheduler=scheduler, **kw)
        assert np.array_equal(res.vertices, ref.vertices) and np.array_equal(res.faces, ref.faces), kw
        assert np.array_equal(res.history.pairs, ref.history.pairs)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_locks_blocking_the_target_stop_with_a_reason(scheduler):
    V, F = _mesh()
    with pytest.warns(UserWarning, match="locked"):
        res = qemjax.simplify((V, F), ratio=0.1, scheduler=scheduler, locked=np.ones(len(V), bool))
    assert res.stop_reason == "locked"
    assert res.stats["blocked_by"]["locked"] > 0 and len(res.faces) == len(F)
    assert np.array_equal(res.vertices, V)
    with pytest.warns(UserWarning, match="locked"):
        res = qemjax.simplify((V, F), ratio=0.1, scheduler=scheduler, locked=V[:, 2] > -0.5)
    assert res.stop_reason == "locked" and res.stats["blocked_by"]["locked"] > 0
    assert res.stats["locked"] == int(np.sum(V[:, 2] > -0.5))


def test_bad_input_is_a_one_line_value_error():
    V, F = _mesh()
    n = len(V)
    cases = [
        (dict(locked=np.zeros(n - 1, bool)), "one entry per input vertex"),
        (dict(locked=[0, n]), "out of range"),
        (dict(locked=[-1]), "out of range"),
        (dict(locked=[0.5, 2.0]), "integer"),
        (dict(locked=np.zeros((2, 2), np.int64)), "one-dimensional"),
        (dict(vertex_weights=np.ones(n - 2)), "one weight per input vertex"),
        (dict(vertex_weights=-np.ones(n)), "finite and >= 0; vertex 0 has -1.0 "),  # a number, not numpy's repr
        (dict(vertex_weights=np.full(n, np.nan)), "finite and >= 0"),
        (dict(vertex_weights=np.full(n, np.inf)), "finite and >= 0"),
        (dict(vertex_weights=["a"] * n), "numbers"),
    ]
    for kw, match in cases:
        with pytest.raises(ValueError, match=match) as info:
            qemjax.simplify((V, F), ratio=0.5, **kw)
        assert "\n" not in str(info.value)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_deterministic(scheduler):
    V, F = _mesh()
    kw = dict(ratio=0.2, scheduler=scheduler, locked=_locked(len(V)), vertex_weights=1.0 + (V[:, 0] > 0))
    a, b = (qemjax.simplify((V, F), **kw) for _ in range(2))
    assert a.vertices.tobytes() == b.vertices.tobytes() and a.faces.tobytes() == b.faces.tobytes()
    assert a.history.pairs.tobytes() == b.history.pairs.tobytes()


def test_indices_refer_to_the_vertices_as_given():
    """A triangle soup (every face its own three vertices) is welded at load: a lock on any copy of a
    vertex locks the welded vertex, and an unreferenced locked vertex is reported."""
    V, F = _mesh()
    soup_V = V[F.reshape(-1)]
    soup_F = np.arange(len(soup_V)).reshape(-1, 3)
    extra = np.vstack([soup_V, [[5.0, 5.0, 5.0]]])  # one vertex no face uses, at the end
    copy_of = {}
    for k, v in enumerate(F.reshape(-1).tolist()):
        copy_of.setdefault(v, k)
    lk = _locked(len(V))
    given = [copy_of[i] for i in lk] + [len(extra) - 1]
    with pytest.warns(UserWarning, match="no face"):
        res = qemjax.simplify((extra, soup_F), ratio=0.2, locked=given)
    assert res.stats["locked_unreferenced"] == 1 and res.stats["locked"] == len(lk)
    # only unreferenced ones: the run is the run without locks, and the stats the warning names are there
    with pytest.warns(UserWarning, match=r"stats\['locked_unreferenced'\]"):
        alone = qemjax.simplify((extra, soup_F), ratio=0.2, locked=[len(extra) - 1])
    assert (alone.stats["locked_in"], alone.stats["locked"], alone.stats["locked_unreferenced"]) == (1, 0, 1)
    assert np.array_equal(alone.faces, qemjax.simplify((extra, soup_F), ratio=0.2).faces)
    out = {tuple(r) for r in res.vertices.tolist()}
    assert all(tuple(V[i]) in out for i in lk)
    # weights: a welded vertex takes the largest of its copies' weights
    w = np.ones(len(extra))
    w[[copy_of[i] for i in lk]] = 0.0  # one copy light, the others 1: the vertex keeps weight 1
    res = qemjax.simplify((extra, soup_F), ratio=0.2, vertex_weights=w)
    ref = qemjax.simplify((extra, soup_F), ratio=0.2)
    assert res.stats["vertex_weights"] is False and np.array_equal(res.vertices, ref.vertices)
    w = np.ones(len(extra))
    w[:-1][np.isin(F.reshape(-1), lk)] = 0.0  # every copy light
    res = qemjax.simplify((extra, soup_F), ratio=0.2, vertex_weights=w)
    assert res.stats["vertex_weights"] and not np.array_equal(res.vertices, ref.vertices)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_a_small_part_holding_a_lock_is_not_pruned(scheduler):
    big = shapes.icosphere(3)
    small = shapes.grid(2, size=0.05)  # an open patch of 8 faces: it may vanish
    V = np.vstack([np.asarray(big.vertices), np.asarray(small.vertices) + 3.0])
    F = np.vstack([np.asarray(big.faces), np.asarray(small.faces) + len(big.vertices)])
    i = len(big.vertices)  # a vertex of the small part
    free = qemjax.simplify((V, F), target_faces=40, scheduler=scheduler, prune=True, quality_threshold=0.0)
    assert free.source_vertices.max() < len(big.vertices), "the small part should vanish without a lock"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = qemjax.simplify((V, F), target_faces=40, scheduler=scheduler, prune=True, locked=[i])
    assert np.array_equal(res.vertices[_row_of(res, i)], V[i])


@pytest.mark.parametrize("scheduler", SCHEDULERS)
@pytest.mark.parametrize("topology", [{"preserve_topology": False}, {"pair_threshold": 0.5}])
def test_a_small_closed_part_holding_a_lock_keeps_it_in_non_manifold_mode(scheduler, topology):
    """In non-manifold mode a contraction drops the faces it makes coincide: a small closed part folding
    away took its locked vertex with it (its last faces dropped, not counted as the pair's). Each vertex of
    the small part locked in turn, at three targets: it stays, where it was."""
    big, small = shapes.bumpy_sphere(3), shapes.icosphere(1, radius=0.05)
    V = np.vstack([np.asarray(big.vertices), np.asarray(small.vertices) + [1.5, 0.0, 0.0]])
    F = np.vstack([np.asarray(big.faces), np.asarray(small.faces) + len(big.vertices)])
    topo = qemjax.Topology(**topology)
    lost = 0
    for i in range(len(big.vertices), len(V), 3):
        for target in (20, 60):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, topology=topo,
                                      locked=[i])
            assert len(res.faces) == target
            lost += not (res.vertices == V[i]).all(1).any()
    assert lost == 0


def test_simplify_batch_takes_locks_as_simplify():
    V, F = _mesh()
    lk = _locked(len(V))
    cfgs = [dict(ratio=0.2, locked=lk), dict(ratio=0.2, boundary_weight=10.0, locked=lk),
            dict(ratio=0.2, vertex_weights=1.0 + (V[:, 2] > 0))]
    for cfg, res in zip(cfgs, qemjax.simplify_batch((V, F), cfgs)):
        one = qemjax.simplify((V, F), **cfg)
        assert np.array_equal(res.vertices, one.vertices) and np.array_equal(res.faces, one.faces)


# -- the kernels, against float64 numpy --------------------------------------------------------------------

def _quadric(rng):
    A = rng.normal(size=(3, 3))
    A = A @ A.T
    return np.concatenate([A[0, 0:3], A[1, 1:3], A[2, 2:3], rng.normal(size=3), [abs(rng.normal())]])


def _q_at(q, u):
    A = np.array([[q[0], q[1], q[2]], [q[1], q[3], q[4]], [q[2], q[4], q[5]]])
    return u @ A @ u + 2 * q[6:9] @ u + q[9]


def test_quadric_price_at_kept_matches_numpy_in_float64():
    rng = np.random.default_rng(3)
    K = 12
    rows = np.array([np.concatenate([rng.normal(size=3), _quadric(rng)]) for _ in range(2 * K)])
    pairs = np.arange(2 * K).reshape(K, 2)
    with jax.enable_x64(True):
        out = np.asarray(at_kept.qem(jnp.asarray(rows), jnp.asarray(pairs), None))
    for k, (a, b) in enumerate(pairs):
        want = max(_q_at(rows[a, 3:], np.zeros(3)) + _q_at(rows[b, 3:], rows[a, :3] - rows[b, :3]), 0.0)
        np.testing.assert_allclose(out[3, k], want, rtol=1e-10, atol=1e-12)
        assert np.array_equal(out[:3, k], rows[a, :3])


def test_area_price_at_kept_matches_numpy_in_float64():
    rng = np.random.default_rng(4)
    R = 6
    for _ in range(5):
        pa, pb = rng.normal(size=3), rng.normal(size=3)
        ring = rng.normal(size=(R, 3, 3))
        moving = np.zeros((R, 3), bool)
        moving[:, 0] = True
        moving[:2, 1] = True  # the pair's two faces (dead after the contraction)
        ring[moving[:, 0], 0] = pa
        ring[:2, 1] = pb
        mask = np.ones(R, bool)
        with jax.enable_x64(True):
            d = float(area_model.delta_at_kept(*(jnp.asarray(x) for x in (pa, pb, ring, moving, mask))))
        after = np.where(moving[..., None], pa, ring)

        def area(p):
            return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
        np.testing.assert_allclose(d, abs(area(ring) - area(after)), rtol=1e-10, atol=1e-12)


def test_attributes_kept_with_locks(tmp_path):
    """The attribute model prices a locked pair on the host (`cost_at`); indices are the file's vertices
    (its ``v`` lines)."""
    path = [p for p in shapes.write_examples(tmp_path, subdivisions=2) if p.name == "textured.obj"][0]
    V = _obj_vertices(path.read_bytes())
    lk = np.arange(0, len(V), 23)
    for scheduler in SCHEDULERS:
        res = qemjax.simplify(str(path), ratio=0.3, attributes="uv", locked=lk, scheduler=scheduler)
        assert res.uv is not None and res.stop_reason == "target"
        out = {tuple(r) for r in res.vertices.tolist()}
        assert all(tuple(V[i]) in out for i in lk)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_locked_vertices_keep_their_uvs(tmp_path, scheduler):
    """A locked vertex keeps its UVs as it keeps its position, bit for bit (its wedges' values are not
    re-solved when a neighbour contracts onto it), and the other vertices' UVs do move."""
    import trimesh as tm
    path = [p for p in shapes.write_examples(tmp_path, subdivisions=3) if p.name == "textured.obj"][0]
    m = tm.load(str(path), process=False)
    V, UV = np.asarray(m.vertices), np.asarray(m.visual.uv)
    P = _obj_vertices(path.read_bytes())  # the file's vertices, which the locks count
    lk = np.arange(0, len(P), 7)
    res = qemjax.simplify(str(path), ratio=0.3, attributes="uv", locked=lk, scheduler=scheduler)
    assert res.stop_reason == "target"
    uvs = {}  # the UVs at each position (a vertex on a seam is split in the file: one copy per UV)
    for p, u in zip(map(tuple, V), map(tuple, UV)):
        uvs.setdefault(p, set()).add(u)
    held = {tuple(P[i]): uvs[tuple(P[i])] for i in lk}
    out = {}
    for p, u in zip(map(tuple, res.vertices[res.wedge_vertex]), map(tuple, res.uv)):
        out.setdefault(p, set()).add(u)
    assert all(out[p] == held[p] for p in held)  # every locked vertex is there, with its UVs
    inputs = {(tuple(p), tuple(u)) for p, u in zip(V, UV)}
    moved = [(p, u) for p, us in out.items() if p not in held for u in us if (p, u) not in inputs]
    assert len(moved) > 20


def test_cli_reads_locks_and_weights(tmp_path, capsys):
    from qemjax import _cli

    V, F = _mesh()
    src = tmp_path / "m.obj"
    trimesh.Trimesh(V, F, process=False).export(src)
    n = len(qemjax.load(str(src)).vertices)
    np.savetxt(tmp_path / "locked.txt", np.arange(0, n, 10), fmt="%d")
    np.save(tmp_path / "w.npy", np.linspace(0.5, 2.0, n))
    args = ["simplify", str(src), str(tmp_path / "out.obj"), "--ratio", "0.2", "--quiet"]
    assert _cli.main(args + ["--locked", str(tmp_path / "locked.txt"), "--vertex-weights",
                             str(tmp_path / "w.npy")]) == 0
    out = {tuple(r) for r in np.asarray(qemjax.load(str(tmp_path / "out.obj")).vertices).tolist()}
    Vin = np.asarray(qemjax.load(str(src)).vertices)
    assert all(tuple(Vin[i]) in out for i in range(0, n, 10))
    np.savetxt(tmp_path / "bad.txt", [n + 3], fmt="%d")
    assert _cli.main(args + ["--locked", str(tmp_path / "bad.txt")]) == 2
    assert "out of range" in capsys.readouterr().err


def _two_spheres():
    a, b = shapes.icosphere(2), shapes.icosphere(2)
    V = np.vstack([a.vertices, np.asarray(b.vertices) + [2.05, 0, 0]])
    return V, np.vstack([a.faces, np.asarray(b.faces) + len(a.vertices)])


def test_greedy_ranked_model_ends_when_a_reweight_leaves_only_blocked_pairs():
    """ESQEM ranks by weighted parts and rebuilds its queue from the unblocked pairs; with locks (blocked
    pairs) the rebuilt queue can be empty: the run then stops instead of popping an empty heap."""
    V, F = _two_spheres()
    lk = np.arange(0, len(V), 13)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = qemjax.simplify((V, F), ratio=0.1, scheduler="greedy", method="esqem", locked=lk,
                              vertex_weights=np.linspace(0.1, 3, len(V)))
    out = {tuple(r) for r in res.vertices.tolist()}
    assert all(tuple(V[i]) in out for i in lk)


def test_feature_edges_with_locks_are_checked_as_given():
    V, F = _two_spheres()
    with pytest.raises(ValueError, match=r"not mesh edges, first: \[0, 11\]"):
        qemjax.simplify((V, F), ratio=0.1, locked=np.arange(0, len(V), 13), feature_edges=[[0, 11]])
    res = qemjax.simplify((V, F), ratio=0.1, locked=np.arange(0, len(V), 13), feature_edges=F[:3, :2])
    assert res.stop_reason == "target"


def test_the_run_numbering_puts_locked_vertices_first_and_maps_back():
    """`_pipeline.locks`: the run's geometry numbers the locked vertices first, and its outcome goes back to
    the cleaned input's numbering."""
    from qemjax._pipeline import locks as _locks
    from qemjax._pipeline import stages
    from qemjax._schedulers import outcome

    V, F = _mesh()
    setup = stages.setup("default", "parallel", None, None, False, {})
    geo = stages.geometry((V, F), setup, stacklevel=2)
    lk = _locks.resolve(_locked(len(V)), None, geo, stacklevel=2)
    run = lk.geometry()
    assert run.vertex_map is None and np.array_equal(run.V, geo.V[lk.perm])
    assert np.array_equal(run.V[run.F], geo.V[geo.F])  # the same faces, in order
    assert lk.run().locked[: lk.stats["locked"]].all() and not lk.run().locked[lk.stats["locked"]:].any()
    pairs = np.array([[0, len(V) - 1]])
    out = outcome.Outcome(run.Vn, np.zeros((len(V), 1)), run.F, np.ones(len(F), bool),
                          outcome.History(pairs, np.zeros((1, 3)), np.zeros(1)), "target", {}, {})
    back, g, locked = _locks.back(lk, out, run)
    assert g is geo and locked is lk.locked and np.array_equal(back.faces, geo.F)
    assert np.array_equal(back.positions, geo.Vn) and back.history.pairs.tolist() == [lk.perm[pairs[0]].tolist()]
    assert _locks.back(None, out, run) == (out, run, None)


def test_the_pipeline_reaches_the_locks_through_one_module():
    """Only `_pipeline.locks` hands the schedulers their locks (`RunLocks`); the stages call it."""
    import ast
    from pathlib import Path

    import qemjax._pipeline as pipeline

    users = set()
    for path in Path(pipeline.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.endswith("_schedulers.locks"):
                users.add(path.name)
            elif isinstance(node, ast.ImportFrom) and node.module and "_schedulers" in node.module:
                assert "locks" not in [a.name for a in node.names], path.name
    assert users == {"locks.py"}


def test_an_obj_files_vertices_are_numbered_as_its_v_lines(tmp_path):
    """Locks and weights given for an OBJ file count its ``v`` lines, as the command's help says: the reader
    renumbers them (an unused vertex dropped, the vertices of a UV seam split), and the indices fell on other
    vertices (a mask of the file's length was refused)."""
    qemjax.shapes.write_examples(tmp_path, subdivisions=3)
    text = (tmp_path / "textured.obj").read_text()
    shifted = "".join(_shift_face(line) for line in text.splitlines(keepends=True))
    (tmp_path / "shifted.obj").write_text("v 9 9 9\n" + shifted)  # an unused vertex first
    for name in ("textured.obj", "shifted.obj"):
        path = str(tmp_path / name)
        P = _obj_vertices((tmp_path / name).read_bytes())
        idx = np.arange(1 if name == "shifted.obj" else 0, len(P), 7)
        mask = np.zeros(len(P), bool)
        mask[idx] = True
        for locked in (idx, mask):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = qemjax.simplify(path, ratio=0.2, locked=locked)
            assert all((res.vertices == P[i]).all(1).any() for i in idx)
        w = np.ones(len(P))
        w[idx] = 1e6
        assert qemjax.simplify(path, ratio=0.2, vertex_weights=w).stats["vertex_weights"]


def test_an_obj_file_is_read_for_its_numbering_once_per_geometry(tmp_path, monkeypatch):
    """`given_map` reads an OBJ file's ``v`` lines once for a geometry, however many runs lock vertices on
    it (each config of a batch read the file again), and gives the same map as read afresh."""
    import qemjax._io.text as io_text
    from qemjax._pipeline import locks as _locks, stages

    qemjax.shapes.write_examples(tmp_path, subdivisions=2)
    text = (tmp_path / "textured.obj").read_text()
    path = tmp_path / "shifted.obj"  # an unused vertex first: the file's numbering is not the reader's
    path.write_text("v 9 9 9\n" + "".join(_shift_face(line) for line in text.splitlines(keepends=True)))
    reads = []

    def counted(data):
        reads.append(len(data))
        return _obj_vertices(data)

    monkeypatch.setattr(io_text, "obj_vertices", counted)
    setup = stages.setup("default", "parallel", None, "auto", False, {})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geo = stages.geometry(str(path), setup, stacklevel=1)
    first = _locks.given_map(geo)
    assert _locks.given_map(geo) is first and len(reads) == 1
    afresh = _locks.given_map(geo._replace(given=None))
    assert len(reads) == 2 and np.array_equal(first, afresh) and first[0] == -1
    P = _obj_vertices(path.read_bytes())
    assert np.array_equal(geo.V[first[1:]], P[1:])
    reads.clear()
    lk = np.arange(1, len(P), 9)
    cfgs = [dict(ratio=0.3, locked=lk), dict(ratio=0.2, locked=lk), dict(ratio=0.2, vertex_weights=np.ones(len(P)))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        batch = qemjax.simplify_batch(str(path), cfgs)
        assert len(reads) == 1
        for cfg, res in zip(cfgs, batch):
            one = qemjax.simplify(str(path), **cfg)
            assert np.array_equal(res.vertices, one.vertices) and np.array_equal(res.faces, one.faces)


def _shift_face(line: str) -> str:
    """An OBJ line with its vertex numbers one higher (a ``v`` line put first), UV numbers as they were."""
    if not line.startswith("f "):
        return line
    corners = [c.split("/") for c in line.split()[1:]]
    return "f " + " ".join("/".join([str(int(c[0]) + 1), *c[1:]]) for c in corners) + "\n"


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_rounds_that_contract_nothing_are_counted_apart(scheduler):
    """On a grid with most vertices locked, some parallel rounds contract nothing (their picks all refused,
    or, last, nothing left to contract), and stats['rounds'] counted them with the rest with nothing apart.
    It still counts the rounds run; stats['rounds_contracting'] counts those that contracted something: the
    history's rounds, one entry each in faces_per_round, and the same after max_distance cuts the run short.
    The greedy queue's rounds are its contractions, each contracting."""
    V, F = shapes.grid(12)
    locked = np.flatnonzero(np.random.default_rng(0).random(len(V)) < 0.95)
    res = qemjax.simplify((V, F), ratio=0.1, locked=locked, scheduler=scheduler)
    s = res.stats
    assert res.stop_reason == "locked" and s["rounds_contracting"] == len(np.unique(res.history.rounds)) > 0
    if scheduler == "parallel":
        assert s["rounds_contracting"] == len(s["faces_per_round"]) < s["rounds"]
    else:
        assert s["rounds_contracting"] == s["rounds"] == s["contractions"] == len(res.history)
    V, F = shapes.bumpy_sphere(3)
    cut = qemjax.simplify((V, F), ratio=0.05, max_distance_rel=2e-3, scheduler=scheduler)
    assert cut.stop_reason == "max_distance"
    assert cut.stats["rounds_contracting"] == len(np.unique(cut.history.rounds)) <= cut.stats["rounds"]


def test_weights_too_large_for_the_costs_are_refused():
    """A weight of 1e300 (or the largest float, for "never") overflowed the single-precision costs it
    multiplies: numpy's "overflow encountered in cast" warnings by the hundred, and every such pair tied at
    infinity. Weights above 1e30 are refused in one line; 1e30 itself runs without a warning."""
    V, F = shapes.bumpy_sphere(2)
    n = len(V)
    w = np.ones(n)
    w[:5] = 1e300
    with pytest.raises(ValueError, match=r"^vertex_weights must be at most 1e\+30 .*; vertex 0 has 1e\+300 \(5 such\)$"):
        qemjax.simplify((V, F), ratio=0.5, vertex_weights=w)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = qemjax.simplify((V, F), ratio=0.5, vertex_weights=np.full(n, 1e30), measure=False)
    assert len(res.faces) == len(F) // 2 and np.isfinite(res.max_error)
