"""Memoryless quadrics for the last stretch of a run (``QEM(late_memoryless=K)``, `qemjax._schedulers.late`):
the first phase is the summed run, bit for bit; the second is in effect and reported; the joined outcome
replays, stays valid, keeps locks and their carried weights, is deterministic, and is refused where it cannot
run."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import assert_valid

import qemjax
from qemjax import shapes
from qemjax._mesh import topology as topo
from qemjax._schedulers import late
from qemjax._schedulers import locks as _locks

LATE = dict(late_memoryless=2)


def holed_grid():
    """An open, bumpy grid with a hole: boundaries on both sides of the switch."""
    V, F = shapes.grid(24, hole=True)
    V = V + np.random.default_rng(3).normal(scale=0.01, size=V.shape) * [0, 0, 1]
    return V, F


MESHES = {"sphere": lambda: shapes.bumpy_sphere(3), "grid": holed_grid}


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("mesh", sorted(MESHES))
def test_first_phase_is_the_summed_run_then_memoryless(scheduler, mesh):
    """The contractions down to K × the target are those of the same model's run to that count (bit for
    bit); the ones after it differ from the summed run's, and the stats say where it switched."""
    V, F = MESHES[mesh]()
    target = len(F) // 10
    res = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, refit=0, **LATE)
    assert_valid(res, target, V, F)
    switch = res.stats["memoryless_from_faces"]
    summed = qemjax.simplify((V, F), target_faces=2 * target, scheduler=scheduler, refit=0, late_memoryless=0)
    assert switch == len(summed.faces) in (2 * target, 2 * target + 1)
    k = len(summed.history.pairs)
    assert np.array_equal(res.history.pairs[:k], summed.history.pairs)
    assert res.history.positions[:k].tobytes() == summed.history.positions[:k].tobytes()
    plain = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, refit=0, late_memoryless=0)
    assert len(plain.faces) == len(res.faces) and plain.vertices.tobytes() != res.vertices.tobytes()
    assert res.stats["model"]["late_memoryless"] == 2


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_joined_record_replays_the_result(scheduler):
    """The two phases are one history: replaying all of it gives the result, byte for byte; a level above
    the switch is a level of the summed phase."""
    V, F = shapes.bumpy_sphere(3)
    res = qemjax.simplify((V, F), ratio=0.05, scheduler=scheduler, refit=0, **LATE)
    level = res.replay(contractions=len(res.history))
    assert level.vertices.tobytes() == res.vertices.tobytes()
    assert np.array_equal(level.faces, res.faces)
    assert np.array_equal(level.source_faces, res.source_faces)
    assert res.record.faces_out == len(res.faces)


def test_deterministic_and_valid_with_the_refit():
    V, F = holed_grid()
    a = qemjax.simplify((V, F), ratio=0.1, **LATE)
    b = qemjax.simplify((V, F), ratio=0.1, **LATE)
    assert a.vertices.tobytes() == b.vertices.tobytes() and np.array_equal(a.faces, b.faces)
    assert_valid(a, len(F) // 10, V, F)
    assert a.stats["refit"] == 1  # the default's re-fit, once, after both phases


def test_locks_hold_and_weights_carry_through_the_switch():
    """Locked vertices keep their input positions through both phases; the second phase gets the weights
    as the first carried them (the largest of each merged group, as `locks.carry` in contraction order)."""
    V, F = shapes.bumpy_sphere(3)
    locked = np.flatnonzero(V[:, 2] > 0.9)
    res = qemjax.simplify((V, F), ratio=0.1, locked=locked, refit=0, **LATE)
    assert_valid(res, None, V, F)
    assert res.stats["memoryless_from_faces"] is not None
    kept = res.source_vertices
    where = {int(s): i for i, s in enumerate(kept)}
    for v in locked:
        assert int(v) in where and res.vertices[where[int(v)]].tolist() == V[v].tolist()
    w = np.random.default_rng(0).random(len(V))
    res_w = qemjax.simplify((V, F), ratio=0.1, vertex_weights=w, refit=0, **LATE)
    assert_valid(res_w, len(F) // 10, V, F)


@pytest.mark.parametrize("seed", range(4))
def test_survivors_and_carried_weights_against_a_sequential_replay(seed):
    """`topology.contraction_roots` (which `late` uses) follows each removed vertex to the one it ended in; the
    carried weights then equal `locks.carry` applied contraction by contraction."""
    rng = np.random.default_rng(seed)
    n = 60
    alive, pairs = list(range(n)), []
    for _ in range(45):
        a, b = rng.choice(alive, 2, replace=False)
        pairs.append((a, b))
        alive.remove(b)
    pairs = np.array(pairs, np.int64)
    to = topo.contraction_roots(pairs, n)
    w = rng.random(n)
    seq = w.copy()
    ref = np.arange(n)
    for a, b in pairs:
        _locks.carry(seq, np.array([a]), np.array([b]))
        ref[ref == b] = a
    assert np.array_equal(to, ref)
    carried = w.copy()
    np.maximum.at(carried, to, w)
    assert np.array_equal(carried[alive], seq[alive])


def test_no_target_no_switch_and_stats_say_so():
    """A run bounded by max_error alone has no target to switch at: it stays summed and says so."""
    V, F = shapes.bumpy_sphere(3)
    with pytest.warns(UserWarning, match="late_memoryless is not applied: there is no face target"):
        res = qemjax.simplify((V, F), max_error=1e-4, **LATE)
    plain = qemjax.simplify((V, F), max_error=1e-4, late_memoryless=0)
    assert "memoryless_from_faces" not in res.stats and "no face target" in res.stats["late_memoryless_off"]
    assert np.array_equal(res.faces, plain.faces)


def test_target_above_the_switch_runs_summed_only():
    """K × the target at or above the input's faces: the whole run is memoryless; a run that never gets to
    K × the target (blocked first) is the summed run."""
    V, F = shapes.bumpy_sphere(3)
    res = qemjax.simplify((V, F), target_faces=len(F) // 2 + 2, late_memoryless=3, refit=0)
    assert res.stats["memoryless_from_faces"] == len(F)
    assert_valid(res, len(F) // 2 + 2, V, F)


@pytest.mark.parametrize("rel", [0.002, 0.02])
def test_max_distance_bound_holds(rel):
    """The bound searches the joined record as any other: the level it returns lies within it."""
    V, F = holed_grid()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stopped above the target by the bound: the point of the test
        res = qemjax.simplify((V, F), ratio=0.05, max_distance_rel=rel, **LATE)
    diagonal = float(np.linalg.norm(V.max(0) - V.min(0)))
    assert res.stats["distance_two_way_max"] <= rel * diagonal
    assert res.stats["memoryless_from_faces"] == 2 * (len(F) // 20)
    assert_valid(res, None, V, F)


def test_second_phases_share_rounds_with_each_copys_own_settings(monkeypatch):
    """The second phases of a batch run together (one `batched.run` of every late cell), each copy's state
    rebuilt with its own settings (area power, boundary weight, its mesh's means): every result is its own
    call's, byte for byte, on two meshes (one open) at once."""
    from qemjax._schedulers import batched

    sizes = []
    real = batched.run

    def counted(Vs, *args, **kw):
        sizes.append((len(Vs), kw.get("models") is not None))
        return real(Vs, *args, **kw)
    monkeypatch.setattr(batched, "run", counted)
    configs = [dict(ratio=0.1), dict(ratio=0.1, area_power=0.5), dict(ratio=0.1, boundary_weight=1.0),
               dict(ratio=0.05, late_memory_weight=0.3), dict(ratio=0.1, placement="rank")]
    cells = [(m, c) for m in (shapes.bumpy_sphere(3), holed_grid()) for c in configs]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = qemjax.simplify_cells(cells)
        alone = [qemjax.simplify(m, **c) for m, c in cells]
    # the second phases: one batch of every cell with optimal placement, one of the two with "rank" (its kernel)
    assert sorted(c for c, second in sizes if second) == [2, len(cells) - 2]
    for r, a in zip(out, alone):
        assert r.stats["memoryless_from_faces"] == a.stats["memoryless_from_faces"] is not None
        assert r.vertices.tobytes() == a.vertices.tobytes() and np.array_equal(r.faces, a.faces)
        assert r.stop_reason == a.stop_reason and r.stats["rounds"] == a.stats["rounds"]
        assert np.array_equal(r.history.pairs, a.history.pairs) and np.array_equal(r.history.costs, a.history.costs)
    # (it can fail:) every setting matters on the open mesh (on the closed one the boundary weight cannot)
    assert len({r.vertices.tobytes() for r in out[len(configs):]}) == len(configs)


def test_batches_share_the_first_phase_with_the_same_results():
    """A batch runs the first phases together (copies of one run where they agree up to the switch), then each
    cell's second phase: every result is its own call's, byte for byte, whatever it is batched with."""
    V, F = shapes.bumpy_sphere(3)
    configs = [dict(ratio=0.1, **LATE), dict(ratio=0.1, late_memoryless=2, late_memory_weight=0.3),
               dict(ratio=0.1, late_memoryless=3), dict(ratio=0.1, late_memoryless=0), dict(ratio=0.05, **LATE),
               dict(ratio=0.1, max_error=1e-4, **LATE)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the max_error one stops above its target
        out = qemjax.simplify_batch((V, F), configs)
        alone = [qemjax.simplify((V, F), **c) for c in configs]
    assert out[0].stats["batch"]["size"] == len(configs)
    # the first two agree until their switch; the plain 10 % run is the first phase of the late 5 % one
    assert out[0].stats["batch"]["copies"] == 4
    for c, r, alone in zip(configs, out, alone):
        assert r.vertices.tobytes() == alone.vertices.tobytes() and np.array_equal(r.faces, alone.faces)
        assert r.stats.get("memoryless_from_faces") == alone.stats.get("memoryless_from_faces")


def test_new_weights_do_not_recompile():
    V, F = shapes.bumpy_sphere(3)
    qemjax.simplify((V, F), target_faces=300, **LATE)
    r = qemjax.simplify((V, F), target_faces=300, late_memoryless=2, late_memory_weight=0.3, volume_weight=0.1)
    assert r.stats["compilations"] == 0, r.stats["compilations"]


@pytest.mark.parametrize("what", ["uv", "feature_edges", "regularize", "max_error"])
def test_attributes_feature_edges_or_terms_keep_the_run_summed(what):
    """The memoryless rows carry no attribute terms, do not track feature edges, and the regularisation and
    area terms price the summed quadrics' placement: with any, the run is the summed one throughout
    (attributes kept), the stats say why, and a call that asked for the switch is warned. So is a run
    without a face target (max_error alone), whose switch would come at a multiple of it."""
    import trimesh

    V, F = shapes.grid(16)
    V = V + np.random.default_rng(1).normal(scale=0.01, size=V.shape) * [0, 0, 1]
    mesh, kw = (V, F), {}
    if what == "uv":
        mesh = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=V[:, :2].copy()))
    elif what == "feature_edges":
        kw = dict(feature_edges=np.array([[0, 1], [1, 2]]))
    elif what == "regularize":
        kw = dict(regularize=0.1)
    stop = dict(max_error=1e-5) if what == "max_error" else dict(ratio=0.2)
    with pytest.warns(UserWarning, match="late_memoryless is not applied"):
        res = qemjax.simplify(mesh, **stop, **LATE, **kw)
    plain = qemjax.simplify(mesh, **stop, late_memoryless=0, **kw)
    assert len(res.faces) < len(F)
    assert res.vertices.tobytes() == plain.vertices.tobytes() and np.array_equal(res.faces, plain.faces)
    assert "memoryless_from_faces" not in res.stats and res.stats["late_memoryless_off"]
    assert res.stats["model"]["late_memoryless"] == 0
    if what == "uv":
        assert res.stats["attributes"] == ["uv"] and res.uv is not None


def test_the_default_says_when_kept_attributes_turn_its_last_stretch_off():
    """The default method's memoryless last stretch has no attribute terms: a default run that keeps UVs stays
    on the summed quadrics, and says so in the stats and a warning that names the kept kinds and the way back
    to the default's geometry (it was said in the stats alone). Without attributes it switches and says
    nothing; a call that turned the stretch off itself is not warned, nor is one without a face target."""
    import trimesh

    V, F = shapes.bumpy_sphere(3)
    uv = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=V[:, :2] * 0.5 + 0.5))
    with pytest.warns(UserWarning, match=r"^keeping uv turns off the default method's memoryless last "
                                         r"stretch .*attributes=None \(CLI: --attributes none\)$") as said:
        res = qemjax.simplify(uv, ratio=0.1, attributes="uv")
    assert len([w for w in said if "last stretch" in str(w.message)]) == 1
    assert res.uv is not None and res.stats["attributes"] == ["uv"]
    assert "attributes are kept" in res.stats["late_memoryless_off"] and "memoryless_from_faces" not in res.stats
    assert_valid(res, len(F) // 10, V, F)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plain = qemjax.simplify((V, F), ratio=0.1)
        summed = qemjax.simplify(uv, ratio=0.1, attributes="uv", late_memoryless=0)
        qemjax.simplify(uv, max_error=1e-4, attributes="uv")
    assert plain.stats["memoryless_from_faces"] and "late_memoryless_off" not in plain.stats
    assert "late_memoryless_off" not in summed.stats and summed.uv is not None


def test_the_default_says_when_feature_edges_turn_its_last_stretch_off():
    """Feature edges given by the user keep a default run on the summed quadrics (the memoryless ones do not
    track them): said in a warning, as kept attributes are (it was said in the stats alone); none given (an
    empty list), the run switches and says nothing."""
    V, F = shapes.bumpy_sphere(3)
    with pytest.warns(UserWarning, match=r"^giving feature edges turns off the default method's memoryless "
                                         r"last stretch") as said:
        res = qemjax.simplify((V, F), ratio=0.1, feature_edges=F[:20, :2])
    assert len([w for w in said if "last stretch" in str(w.message)]) == 1
    assert "feature edges" in res.stats["late_memoryless_off"] and "memoryless_from_faces" not in res.stats
    assert_valid(res, len(F) // 10, V, F)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        none = qemjax.simplify((V, F), ratio=0.1, feature_edges=np.zeros((0, 2), int))
        asked = qemjax.simplify((V, F), ratio=0.1, feature_edges=F[:20, :2], late_memoryless=0)
    assert none.stats["memoryless_from_faces"] and "late_memoryless_off" not in asked.stats


@pytest.mark.parametrize("what", ["regularize", "area_weight", "scheduler"])
def test_the_default_says_when_a_setting_turns_its_last_stretch_off(what, tmp_path):
    """regularize, area_weight and a scheduler registered from outside keep a default run on the summed
    quadrics: said in a warning that names the setting and the way back to the default's geometry, as kept
    attributes are (it was said in the stats alone), and in a partitioned run's stats as that reason. A call
    that set late_memoryless itself gets its own warning alone; a bounded run (max_distance) keeps to the stats."""
    from qemjax import _schedulers

    V, F = shapes.bumpy_sphere(3)
    kw = {"regularize": dict(regularize=0.1), "area_weight": dict(area_weight=0.1),
          "scheduler": dict(scheduler="outside")}[what]
    match = {"regularize": r"^setting regularize .* than with regularize=0 \(CLI: --regularize 0\)$",
             "area_weight": r"^setting area_weight .* than with area_weight=0 \(CLI: --area-weight 0\)$",
             "scheduler": r"^scheduler='outside' .*: the default's geometry needs scheduler='parallel' or 'greedy'$"}
    _schedulers.register("outside", _schedulers.get("parallel"))
    try:
        with pytest.warns(UserWarning, match=match[what].replace(".*", "turns off the default method's "
                                                                      "memoryless last stretch .*")) as said:
            res = qemjax.simplify((V, F), ratio=0.1, **kw)
        assert len([w for w in said if "last stretch" in str(w.message)]) == 1
        reason = res.stats["late_memoryless_off"]
        assert ("not a built-in" if what == "scheduler" else f"{what} is set") in reason
        assert "memoryless_from_faces" not in res.stats
        with pytest.warns(UserWarning) as asked:
            qemjax.simplify((V, F), ratio=0.1, late_memoryless=2, **kw)
        assert [str(w.message).split(":")[0] for w in asked] == ["late_memoryless is not applied"]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            summed = qemjax.simplify((V, F), ratio=0.1, late_memoryless=0, **kw)
            bounded = qemjax.simplify((V, F), max_distance=1e-3, **kw)
        assert np.array_equal(res.faces, summed.faces) and res.vertices.tobytes() == summed.vertices.tobytes()
        assert bounded.stats["late_memoryless_off"] == reason
        if what == "regularize":  # a partitioned run's last level: its runs' own reason, not "attributes are kept"
            import trimesh

            path = tmp_path / "bumpy.ply"
            trimesh.Trimesh(V, F, process=False).export(path)
            with pytest.warns(UserWarning, match=match[what].split(" .*")[0]):
                part = qemjax.simplify(str(path), ratio=0.1, partition=qemjax.Partition(workers=1, part_faces=2000),
                                       **kw)
            assert part.stats["late_memoryless_off"] == reason
    finally:
        del _schedulers._REGISTRY["outside"]


@pytest.mark.parametrize("kw,match", [
    (dict(late_memoryless=0.5), "late_memoryless must be 0"),
    (dict(late_memoryless=-1), "late_memoryless must be finite"),
    (dict(late_memoryless=2, late_memory_weight=-1), "late_memory_weight must be finite"),
    (dict(late_memoryless=2, memory_weight=0.5), "memory_weight > 0 needs memoryless=True"),
    (dict(late_memoryless=2, method="probabilistic"), "not a setting|method='qem' only"),
])
def test_bad_options_raise(kw, match):
    V, F = shapes.bumpy_sphere(2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=match):
            qemjax.simplify((V, F), ratio=0.2, **kw)


def test_memoryless_true_is_memoryless_throughout():
    """``memoryless=True`` wins over a late switch (a preset's): the run is memoryless from the start."""
    V, F = shapes.bumpy_sphere(3)
    a = qemjax.simplify((V, F), ratio=0.1, memoryless=True, late_memoryless=2)
    b = qemjax.simplify((V, F), ratio=0.1, memoryless=True, late_memoryless=0)
    assert a.vertices.tobytes() == b.vertices.tobytes() and np.array_equal(a.faces, b.faces)
    assert "memoryless_from_faces" not in a.stats


def test_partitioned_runs_pass_it_to_every_group():
    """A partitioned run's groups switch too (each at K × its own share): the target is met, the mesh closed
    and valid, and the result is not the summed partitioned run's."""
    from qemjax import Partition

    m = shapes.bumpy_sphere(5)
    p = Partition(part_faces=2000, workers=1)
    res = qemjax.simplify(m, ratio=0.05, partition=p, **LATE)
    plain = qemjax.simplify(m, ratio=0.05, partition=p, late_memoryless=0)
    assert len(res.faces) == res.stats["target_faces"] == len(plain.faces)
    assert_valid(res, len(plain.faces))
    e = np.concatenate([res.faces[:, [0, 1]], res.faces[:, [1, 2]], res.faces[:, [2, 0]]])
    assert len(np.unique(e, axis=0)) == len(e)  # each directed edge once ...
    assert np.array_equal(np.unique(e, axis=0), np.unique(e[:, ::-1], axis=0))  # ... and its reverse: closed
    assert res.vertices.tobytes() != plain.vertices.tobytes()


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_the_joined_outcome_keeps_the_contract(scheduler, monkeypatch):
    """`late.join`: one outcome whose counts, faces, removal steps and rounds agree with each other and with
    the result's stats, as a single run's do (tests/test_scheduler_contract.py)."""
    seen = []
    join = late.join

    def kept(*a):
        out = join(*a)
        seen.append(out)
        return out
    monkeypatch.setattr(late, "join", kept)
    V, F = holed_grid()
    res = qemjax.simplify((V, F), ratio=0.05, scheduler=scheduler, **LATE)
    (out,) = seen
    k = out.contractions
    assert k == len(out.history.costs) == len(out.history_rounds) == res.stats["contractions"]
    assert int(out.alive.sum()) == len(res.faces) and sum(out.rejected_by.values()) == out.rejected
    assert int(np.sum(out.branches)) == k and out.rounds == res.stats["rounds"]
    assert np.all(np.diff(out.history_rounds) >= 0) and out.history_rounds[-1] < out.rounds
    assert np.all(out.removed_at[out.alive] == -1)
    assert np.all((out.removed_at[~out.alive] >= 0) & (out.removed_at[~out.alive] < k))
    assert out.states.shape == (len(V), 10)  # the summed quadrics' columns, as the pipeline reads them
    assert out.switched_at == res.stats["memoryless_from_faces"]
    assert out.worst_cost == float(np.max(out.history.costs))


def test_the_default_turns_memoryless_at_twice_the_target():
    V, F = shapes.bumpy_sphere(3)
    assert qemjax.QEM.default().late_memoryless == 2 and qemjax.QEM.default().late_memory_weight == 1
    a = qemjax.simplify((V, F), ratio=0.1)
    b = qemjax.simplify((V, F), ratio=0.1, method="qem", area_power=0.6, boundary_weight=10.0, refit=1,
                        late_memoryless=2, polish=256, quality_threshold=0.4, sliver_moves=4096)
    assert a.vertices.tobytes() == b.vertices.tobytes() and np.array_equal(a.faces, b.faces)
    assert a.stats["memoryless_from_faces"] == 256
