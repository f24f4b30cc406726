"""Partitioned simplification (`qemjax._partition`): the plan, the stitch, and whole runs of a 327,680-face
mesh made in code cut into parts of 20,000 faces, in this process, on two local worker processes and on a
two-process Dask `LocalCluster`: the exact target, a valid closed mesh with no crack where parts met, the
same bits everywhere, a resumed run and a run whose worker is killed."""
from __future__ import annotations

import dataclasses
import hashlib
import pathlib
import threading
import time
import warnings

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import Partition, shapes
from qemjax._partition import execute, pieces, plan
from conftest import sigint_default

RATIO, PART = 0.02, 20_000


def digest(res) -> str:
    return hashlib.sha256(res.vertices.tobytes() + res.faces.tobytes()).hexdigest()


@pytest.fixture(scope="module")
def mesh():
    m = shapes.bumpy_sphere(7)
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.fixture(scope="module")
def in_process(mesh):
    return qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, workers=1))


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("parts")


@pytest.fixture(scope="module")
def two_workers(mesh, scratch):
    return qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, workers=2, scratch=scratch))


# --- the plan -------------------------------------------------------------------------------------------------
def test_shares_sum_to_the_total_in_proportion():
    rng = np.random.default_rng(0)
    for _ in range(50):
        faces = rng.integers(1, 10_000, rng.integers(1, 40))
        total = int(rng.integers(1, faces.sum() + 1))
        s = plan.shares(faces, total)
        assert s.sum() == total and np.all(s <= faces) and np.all(s >= 0)
        assert np.all(np.abs(s - faces * total / faces.sum()) < 1 + 1e-9)


def test_levels_reduce_until_one_group_meets_the_target():
    p = Partition(part_faces=100_000)
    faces, first, levels = np.full(55, 100_000), True, []
    while True:
        groups, last = plan.level(faces, 55_000, p, first)
        assert all(g.faces <= p.part_faces or len(g.members) == 1 for g in groups) or last
        assert sorted(i for g in groups for i in g.members) == list(range(len(faces)))
        levels.append(groups)
        faces, first = np.array([g.target for g in groups]), False
        if last:
            break
    assert len(levels[-1]) == 1 and levels[-1][0].target == 55_000
    assert [sum(g.target for g in lv) for lv in levels][:2] == [1_375_000, 343_750]


def test_a_level_aimed_within_the_band_is_followed_by_the_last():
    """Whether the next level is the last goes by what the level before aimed at, not by what it kept: a
    level aimed at the edge of the band ends a few faces over it (its groups' locked borders hold them), and
    one more locked level for those wore the surface (a teapot cut into parts of 1,000-1,500 faces, at 5 %:
    about twice the in-core Hausdorff distance; `experiments/probes/small_parts.py`)."""
    p = Partition(part_faces=1_000)
    for target in (316, 4903):  # the band's edge at 1,580 faces; and one a few faces off a round aim
        edge = plan.NEAR * p.budget * target
        total = int(edge * p.reduction)  # faces / reduction: the band's edge
        n = -(-total // 1000)
        parts = np.full(n, total // n)
        parts[: total - parts.sum()] += 1
        groups, last = plan.level(parts, target, p, first=True)
        aimed = sum(g.target for g in groups)
        assert not last and aimed <= edge
        for over in (0, 1, 6, 100):  # what the locked borders held over the aim, up to a level's worth
            kept = np.array([g.target for g in groups])
            kept[0] += over
            nxt, last = plan.level(kept, target, p, first=False, aimed=aimed)
            assert last and len(nxt) == 1 and nxt[0].target == target
            # without the aim (a resumed plan of old, or a first level), the kept faces decide
            assert plan.level(kept, target, p, first=False)[1] == (kept.sum() <= edge)
    # a level aimed above the band: another locked level first, whatever it kept
    groups, last = plan.level(np.full(8, 1000), 316, p, first=False, aimed=2000)
    assert not last


def test_a_level_too_large_for_one_process_ends_with_locked_groups():
    p = Partition(part_faces=10_000, final_faces=50_000)
    groups, last = plan.level(np.full(20, 10_000), 60_000, p, first=False)
    assert last and len(groups) > 1 and sum(g.target for g in groups) == 60_000


def test_stitch_merges_shared_ids_and_refuses_a_moved_one(tmp_path):
    V = np.random.default_rng(1).random((5, 3))
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    pieces.save(a, V=V[[0, 1, 2]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([10, 11, -1]))
    pieces.save(b, V=V[[1, 0, 3]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([11, 10, -1]))
    W, F, gid, _ = pieces.stitch([a, b])
    assert len(W) == 4 and np.array_equal(W[F[1]], V[[1, 0, 3]]) and list(gid) == [10, 11, -1, -1]
    pieces.save(b, V=V[[4, 0, 3]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([11, 10, -1]))
    with pytest.raises(RuntimeError, match="moved"):
        pieces.stitch([a, b])
    # ids saved narrower come back as they were saved (the stitch reads them as int64 for itself only)
    a, b = tmp_path / "a32.npz", tmp_path / "b32.npz"
    pieces.save(a, V=V[[0, 1, 2]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([10, 11, -1], np.int32))
    pieces.save(b, V=V[[1, 0, 3]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([11, 10, -1], np.int32))
    gid = pieces.stitch([a, b])[2]
    assert gid.dtype == np.int32 and list(gid) == [10, 11, -1, -1]


def test_stitch_loops_are_the_numpy_expressions_they_replace():
    """`holders` (a table of the ids, one pass over the faces) gives the arrays of the sort `stitch` made
    before: the first holder of each id, the faces renumbered, the positions check (a NaN on a shared
    vertex is refused, as np.array_equal refused it); ids too sparse for a table are sorted as before."""
    from qemjax._partition import holders

    rng = np.random.default_rng(4)
    for n, top in ((0, 1), (1, 1), (500, 300), (500, 10**12)):
        gid = np.where(rng.random(n) < 0.3, -1, rng.integers(0, top, n))
        held = np.flatnonzero(gid >= 0)
        _, first, inverse = np.unique(gid[held], return_index=True, return_inverse=True)
        ref = np.arange(n)
        ref[held] = held[first][inverse]
        to = pieces._first_holders(gid)
        assert to.dtype == ref.dtype and np.array_equal(to, ref)
        keep = to == np.arange(n)
        new = np.cumsum(keep) - 1
        F = rng.integers(0, max(n, 1), (40, 3)) if n else np.zeros((0, 3), np.int64)
        got = holders.renumbered(F, to, new)
        assert got.dtype == np.int64 and np.array_equal(got, new[to][F])
        V = rng.random((n, 3))
        V[held] = V[ref[held]]
        assert holders.same_positions(V, to, gid) == np.array_equal(V[to[held]], V[held]) is True
        if len(held):
            V[held[0], 1] = np.nan  # a first holder: not equal to itself
            assert holders.same_positions(V, to, gid) is np.array_equal(V[to[held]], V[held]) is False

def test_partition_settings_are_checked():
    with pytest.raises(ValueError, match="part_faces"):
        Partition(part_faces=10)
    with pytest.raises(ValueError, match="workers"):
        Partition(workers=0)
    with pytest.raises(ValueError, match="refit_input_faces"):
        Partition(refit_input_faces=-1)
    # numpy numbers are numbers (refused as "not an integer"), stored as Python's; NaN, inf and a measure
    # that is not a bool are refused (they were taken, and failed or did nothing in the run)
    p = Partition(part_faces=np.int64(5000), workers=np.int64(2), budget=np.float32(2.0))
    assert (p.part_faces, p.workers, p.budget) == (5000, 2, 2.0) and type(p.part_faces) is int
    for kw in (dict(budget=float("nan")), dict(reduction=float("inf")), dict(measure="no")):
        with pytest.raises(ValueError, match=f"Partition: {next(iter(kw))} must be"):
            Partition(**kw)


def test_partition_refuses_a_client_that_is_no_dask_client():
    """Partition(client=float('nan')) (or any object) was taken, to fail once the run had cut the input: it
    is refused at once, in one line, without importing dask (a client-like object is taken)."""
    import sys

    for bad in (float("nan"), "tcp://host:8786", object()):
        with pytest.raises(ValueError, match=r"^Partition: client must be a dask.distributed Client, or None "
                                             rf"for local processes; got {type(bad).__name__}$"):
            Partition(client=bad)

    class LikeAClient:
        def submit(self, *a, **k): ...
        def scheduler_info(self): ...
        def cancel(self, *a, **k): ...

    loaded = "distributed" in sys.modules
    assert Partition(client=LikeAClient()).client is not None and Partition(client=None).client is None
    assert ("distributed" in sys.modules) == loaded


def test_partition_settings_hash_and_refuse_a_scratch_that_is_no_path():
    """A list given as scratch was taken, and made the frozen settings unhashable."""
    assert hash(Partition(scratch="parts")) == hash(Partition(scratch="parts")) and len({Partition(), Partition()}) == 1
    with pytest.raises(ValueError, match=r"^Partition: scratch must be a folder's path or None, got list$"):
        Partition(scratch=["parts"])


def test_partition_settings_of_one_folder_given_as_str_or_path_are_equal():
    """Frozen settings compare by value: the same folder as a str and as a Path made unequal settings (with
    unequal hashes); the folder is kept as its str."""
    a, b = Partition(scratch="parts"), Partition(scratch=pathlib.Path("parts"))
    assert a == b and hash(a) == hash(b) and b.scratch == "parts" and type(b.scratch) is str
    assert Partition(scratch=None).scratch is None


# --- whole runs -----------------------------------------------------------------------------------------------
def closed_and_consistent(F: np.ndarray) -> bool:
    """Every directed edge once and its reverse once: closed (no crack), manifold, consistently oriented."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = e[:, 0] * (F.max() + 1) + e[:, 1]
    rev = e[:, 1] * (F.max() + 1) + e[:, 0]
    return len(np.unique(key)) == len(key) and np.array_equal(np.sort(key), np.sort(rev))


def test_target_exact_valid_closed_and_measured(mesh, in_process):
    V, F = mesh
    r = in_process
    target = round(RATIO * len(F))
    assert len(r.faces) == target and r.stop_reason == "target"
    G = r.faces
    assert G.min() >= 0 and G.max() < len(r.vertices) and len(np.unique(G)) == len(r.vertices)
    assert np.all((G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2]))
    assert len(np.unique(np.sort(G, 1), axis=0)) == len(G)
    assert closed_and_consistent(G)  # a border vertex is one vertex: no crack where parts met
    # a single vertex per position (parts never duplicate one) and the orientation of the input (volume > 0)
    assert len(np.unique(r.vertices, axis=0)) == len(r.vertices)
    T = r.vertices[G]
    assert np.einsum("ij,ij->i", T[:, 0], np.cross(T[:, 1], T[:, 2])).sum() > 0
    part = r.stats["partition"]
    assert part["parts"] >= 16 and part["levels"] >= 2 and part["locked_share"] == 0.0
    assert part["faces_per_level"][-1] == target and part["locked_per_level"][0] > 0
    # the distance the run measured part by part is the one the in-core measure gives for the whole input
    from qemjax._pipeline.measure import distance
    d = distance(V, F, r.vertices, r.faces)
    assert r.stats["distance_max"] == pytest.approx(d["distance_max"], rel=1e-6)
    assert r.stats["distance_rms"] == pytest.approx(d["distance_rms"], rel=1e-6)
    for q in (50, 95, 99):  # exact: the last level measured with the re-fit's samples (the test below)
        assert r.stats[f"distance_p{q}"] == pytest.approx(d[f"distance_p{q}"], rel=1e-9)
    assert r.stats["distance_samples"] == d["distance_samples"]
    assert r.stats["distance_max_rel"] == pytest.approx(d["distance_max_rel"], rel=1e-12)


def test_a_last_level_fitted_to_the_input_measures_there(mesh, monkeypatch):
    """The last level that fits its output to the input's parts measures the distance with the samples and
    nearest faces of its re-fit: the client reads the parts no second time (`task.measure_parts`, which reads
    them all, runs only where the last level did not fit to them: the percentiles then come from histograms)."""
    from qemjax._partition import task
    from qemjax._pipeline.measure import distance

    def refused(spec):
        raise AssertionError("the parts were read again to measure")

    monkeypatch.setattr(task, "measure_parts", refused)
    m = shapes.bumpy_sphere(5)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    r = qemjax.simplify((V, F), ratio=0.05, partition=Partition(part_faces=2000, workers=1))
    part = r.stats["partition"]
    assert part["levels"] >= 2 and part["refit_to"] == "input"
    d = distance(V, F, r.vertices, r.faces)
    for key in ("distance_max", "distance_rms", "distance_p50", "distance_p95", "distance_p99"):
        assert r.stats[key] == pytest.approx(d[key], rel=1e-9), key
    assert r.stats["distance_samples"] == d["distance_samples"]
    assert part["measure_s"] == r.stats["distance_s"] > 0
    monkeypatch.undo()
    own = qemjax.simplify((V, F), ratio=0.05, partition=Partition(part_faces=2000, workers=1, refit_input_faces=0))
    assert own.stats["partition"]["refit_to"] == "level input"  # measured part by part, as before
    assert own.stats["distance_max"] == pytest.approx(distance(V, F, own.vertices, own.faces)["distance_max"], rel=1e-9)
    off = qemjax.simplify((V, F), ratio=0.05, partition=Partition(part_faces=2000, workers=1, measure=False))
    assert off.stats["distance_max"] is None and np.array_equal(off.faces, r.faces)
    assert np.array_equal(off.vertices, r.vertices)  # measuring moves nothing


def test_levels_before_the_last_leave_out_what_a_run_s_end_is_for(in_process):
    """The memoryless last stretch (with its volume term) and the shape term: the default's, not classic's."""
    from qemjax._partition.run import _level_kwargs

    p, late = Partition(refit="all"), {"late_memoryless": 0, "volume_weight": 0}  # its volume term goes with it
    shape = {"quality_threshold": 0.0}
    off = late | shape
    assert _level_kwargs({}, p, last=False) == (off, off)  # the default switches late and shapes its rounds
    assert _level_kwargs({"volume_weight": 0.1}, p, last=True) == ({"volume_weight": 0.1}, {})
    assert _level_kwargs({"method": "classic"}, p, last=False) == ({"method": "classic"}, {})  # it does neither
    assert _level_kwargs({"preset": "classic"}, p, last=False)[1] == {}
    assert _level_kwargs({"preset": "classic", "quality_threshold": 0.5}, p, last=False)[1] == shape
    assert _level_kwargs({"method": "qem", "preset": "default"}, p, last=False)[1] == off
    assert _level_kwargs({"memoryless": True, "late_memoryless": 2}, p, last=False)[1] == shape  # memoryless all along
    assert _level_kwargs({"quality_threshold": 0.0}, p, last=False)[1] == late
    assert _level_kwargs({"schedule": None}, p, last=False)[1] == off
    kw, changed = _level_kwargs({"method.late_memoryless": 3, "method.refit": 1}, Partition(refit="last"), last=False)
    assert kw == changed == off | {"refit": 0}  # the dotted names would have won over the flat ones
    settings = in_process.stats["partition"]["settings_per_level"]  # the default: only the last level re-fits
    assert settings[:-1] == [off | {"refit": 0}] * (len(settings) - 1) and settings[-1] == {}


def test_esqem_splits_edges_in_the_last_level_only():
    """ESQEM's edge splits are a run's end: a level before the last runs without them, the last level splits,
    locked or not. The run: the exact target, no crack."""
    from qemjax._partition.run import _level_kwargs

    p, off = Partition(), {"split_factor": None}
    assert _level_kwargs({"method": "esqem"}, p, last=False)[1] == off | {"refit": 0}
    assert _level_kwargs({"method": "esqem"}, p, last=True) == ({"method": "esqem"}, {})
    assert _level_kwargs({"method": "esqem", "split_factor": None}, p, last=False)[1] == {"refit": 0}
    assert "split_factor" not in _level_kwargs({"method": "classic"}, p, last=False)[1]  # it does not split
    m = shapes.bumpy_sphere(5)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    r = qemjax.simplify((V, F), ratio=0.05, method="esqem", partition=Partition(part_faces=2000, workers=1))
    assert len(r.faces) == round(0.05 * len(F)) and r.stop_reason == "target"
    assert closed_and_consistent(r.faces) and len(np.unique(r.vertices, axis=0)) == len(r.vertices)
    settings = r.stats["partition"]["settings_per_level"]
    assert len(settings) >= 2 and settings[-1] == {} and all(s["split_factor"] is None for s in settings[:-1])
    # the last level split its long edges: its longest edge nearer the mean than without the splits
    plain = qemjax.simplify((V, F), ratio=0.05, method="esqem", split_factor=None,
                            partition=Partition(part_faces=2000, workers=1))

    def spread(res):
        e = np.linalg.norm(res.vertices[res.faces] - np.roll(res.vertices[res.faces], 1, axis=1), axis=2)
        return float(e.max() / e.mean())
    assert spread(r) < spread(plain)


def test_esqem_splits_in_a_last_level_of_several_locked_groups():
    """A last level of several groups (the output above ``final_faces``) keeps its borders locked and still
    splits long edges: a split's new vertex takes its first endpoint's source vertex, locked or not, and must
    not take that vertex's global id (the stitch would find one id at two positions: a crack, or the run
    stopping with "a shared vertex moved")."""
    m = shapes.bumpy_sphere(5)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    with pytest.warns(UserWarning, match="too large for one process"):
        r = qemjax.simplify((V, F), ratio=0.05, method="esqem",
                            partition=Partition(part_faces=2000, workers=1, final_faces=1500))
    p = r.stats["partition"]
    assert p["locked_share"] > 0 and p["settings_per_level"][-1] == {}
    assert len(r.faces) == round(0.05 * len(F)) and r.stop_reason == "target"
    assert closed_and_consistent(r.faces) and len(np.unique(r.vertices, axis=0)) == len(r.vertices)


def test_a_volume_term_runs_partitioned():
    """The default's volume term needs its memoryless stretch: the levels without the stretch drop it too
    (as an in-core run that stays summed does) instead of refusing it."""
    m = shapes.bumpy_sphere(4)
    r = qemjax.simplify((np.asarray(m.vertices), np.asarray(m.faces)), ratio=0.05, volume_weight=0.1,
                        partition=Partition(part_faces=1000, workers=1))
    assert len(r.faces) == round(0.05 * len(m.faces)) and r.stats["partition"]["levels"] >= 2
    assert r.stats["partition"]["settings_per_level"][0] == {"late_memoryless": 0, "volume_weight": 0,
                                                             "quality_threshold": 0.0, "refit": 0}


def test_the_last_level_fits_to_the_input_itself(mesh, in_process):
    """The last level's re-fit, polish and sliver moves fit the output to the level-0 parts, not to what the
    levels before left: the same faces, positions nearer the input (its samples are what the re-fit fits and
    the run measures). With ``refit_input_faces`` below the input's faces, or a run of one part, they fit to
    the level's own input, as before."""
    own = qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, workers=1, refit_input_faces=0))
    assert in_process.stats["partition"]["refit_to"] == "input"
    assert own.stats["partition"]["refit_to"] == "level input"
    assert np.array_equal(own.faces, in_process.faces) and not np.array_equal(own.vertices, in_process.vertices)
    assert in_process.stats["distance_rms"] < own.stats["distance_rms"]
    assert in_process.stats["distance_max"] < own.stats["distance_max"]
    small = shapes.bumpy_sphere(3)
    one = qemjax.simplify((np.asarray(small.vertices), np.asarray(small.faces)), ratio=0.1,
                          partition=Partition(workers=1))
    assert one.stats["partition"]["levels"] == 1 and one.stats["partition"]["refit_to"] == "level input"
    m = shapes.bumpy_sphere(4)  # a method that does not re-fit reads no parts for it
    classic = qemjax.simplify((np.asarray(m.vertices), np.asarray(m.faces)), ratio=0.05, method="classic",
                              partition=Partition(part_faces=1000, workers=1))
    assert classic.stats["partition"]["levels"] >= 2 and classic.stats["partition"]["refit_to"] == "level input"


def test_quality_near_the_in_core_run(mesh, in_process):
    whole = qemjax.simplify(mesh, ratio=RATIO)
    # the goals for the partitioned run (its last level fits to the input: the test above)
    assert in_process.stats["distance_rms"] <= 1.05 * whole.stats["distance_rms"]
    assert in_process.stats["distance_max"] <= 1.10 * whole.stats["distance_max"]


@pytest.mark.slow  # starts worker processes
def test_same_bits_on_two_local_workers(in_process, two_workers):
    assert digest(two_workers) == digest(in_process)
    # the measured distance too: its sums went over tasks of 4 × the workers' parts, in another order
    assert in_process.stats["partition"]["parts"] > 8
    for key in ("distance_max", "distance_rms", "distance_p50", "distance_p95", "distance_p99", "distance_samples"):
        assert two_workers.stats[key] == in_process.stats[key], key
    assert two_workers.stats["partition"]["where"] == "2 local processes"


@pytest.mark.slow
def test_resumed_run_reuses_the_parts_written(mesh, scratch, two_workers):
    for path in (scratch / "level2").glob("group_0000[0-1].*"):
        path.unlink()
    again = qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, workers=2, scratch=scratch))
    assert digest(again) == digest(two_workers)
    first = two_workers.stats["partition"]
    assert again.stats["partition"]["reused"] == sum(first["groups_per_level"]) - 2


def test_repeated_and_degenerate_faces_are_cleaned_as_in_core(tmp_path):
    """A ratio counts the faces left after the clean-up, partitioned or not: repeated faces (one of them
    flipped) and faces with a repeated vertex went into the partitioned run's count (twice the faces here)."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    extra = np.concatenate([F, F, F[:100, ::-1], F[:50, [0, 0, 1]]])
    core = qemjax.simplify((V, extra), ratio=0.1)
    for part_faces in (100_000, 1500):
        r = qemjax.simplify((V, extra), ratio=0.1, partition=Partition(workers=1, part_faces=part_faces))
        assert len(r.faces) == len(core.faces) == round(0.1 * len(F)) and r.stats["faces_in"] == len(F)
        assert r.stats["duplicate_removed"] == core.stats["duplicate_removed"] == len(F) + 100
        assert r.stats["degenerate_removed"] == core.stats["degenerate_removed"] == 50
        assert closed_and_consistent(r.faces)
        assert r.stats["distance_s"] > 0  # the measured distance's time, as in core (it was None)
        # the same samples as in core: a vertex on a border between parts counts once (it counted per part)
        assert r.stats["distance_samples"] == core.stats["distance_samples"]
        assert repr(r).startswith(f"SimplifyResult: {len(F)} -> {len(r.faces)} faces")  # it said 0 ->
    same = qemjax.simplify((V, F), ratio=1.0, partition=Partition(workers=1, part_faces=1500))
    assert len(same.faces) == len(F)
    # the samples at distance 0 exactly (most of an unchanged surface): a median of 0, not the maximum
    assert same.stats["distance_p50"] == 0.0 <= same.stats["distance_max"] < 1e-12


def test_weld_false_and_scratch_paths_in_the_users_terms(tmp_path):
    """weld=False is refused partitioned for what it is (a run welds to find where parts meet: it was refused
    "for UVs" under attributes='auto', and ignored with attributes=None); a scratch folder named by a file
    is refused in one line (it raised FileExistsError), and a missing input leaves no scratch folder behind."""
    m = shapes.bumpy_sphere(4)
    path = tmp_path / "b.ply"
    trimesh.Trimesh(m.vertices, m.faces, process=False).export(path)
    for attributes in ("auto", None, "uv"):
        with pytest.raises(ValueError, match="partition: weld=False is not offered: a partitioned run welds"):
            qemjax.simplify(str(path), ratio=0.1, weld=False, attributes=attributes, partition=Partition(workers=1))
    with pytest.raises(ValueError, match=r"^partition: the scratch folder .*b\.ply is a file$"):
        qemjax.simplify(str(path), ratio=0.1, partition=Partition(workers=1, scratch=path))
    with pytest.raises(FileNotFoundError, match="no such file"):
        qemjax.simplify(str(tmp_path / "nope.ply"), ratio=0.1,
                        partition=Partition(workers=1, scratch=tmp_path / "new" / "scratch"))
    assert not (tmp_path / "new").exists()


def test_a_resumed_run_reruns_a_task_its_plan_changed(tmp_path, monkeypatch):
    """A task's output is reused only for the task that wrote it: a scratch folder from a run planned otherwise
    (another version's rule for the last level) held a level's file of the same name written by a locked
    group, and the resumed run took it as its one group's output (a piece of the mesh, with open edges)."""
    mesh = shapes.bumpy_sphere(5)
    settings = Partition(part_faces=1000, workers=1, measure=False, scratch=tmp_path / "scratch")
    monkeypatch.setattr(plan, "NEAR", 1.3)  # another plan: level 2 the last, one group (the run's has three)
    old = qemjax.simplify(mesh, target_faces=1010, partition=settings)
    monkeypatch.undo()
    again = qemjax.simplify(mesh, target_faces=1010, partition=settings)
    fresh = qemjax.simplify(mesh, target_faces=1010, partition=dataclasses.replace(settings, scratch=None))
    assert len(old.stats["partition"]["faces_per_level"]) != len(fresh.stats["partition"]["faces_per_level"])
    assert again.stats["partition"]["faces_per_level"] == fresh.stats["partition"]["faces_per_level"]
    assert np.array_equal(again.faces, fresh.faces) and np.array_equal(again.vertices, fresh.vertices)
    assert again.stats["partition"]["reused"] > 0  # level 1 is the same tasks: reused


def test_a_resumed_run_that_now_measures_reuses_the_last_level(tmp_path):
    """Whether the last level's task measures moves nothing, so it is no part of the task's key: a run
    resumed with measure=True from a folder cut with measure=False (or by a version whose last level did not
    measure) ran its last level again; it reuses it now, and the parts measure it."""
    from qemjax._pipeline.measure import distance

    m = shapes.bumpy_sphere(5)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    settings = Partition(part_faces=2000, workers=1, measure=False, scratch=tmp_path / "scratch")
    off = qemjax.simplify((V, F), ratio=0.05, partition=settings)
    assert off.stats["distance_max"] is None and off.stats["partition"]["refit_to"] == "input"
    on = qemjax.simplify((V, F), ratio=0.05, partition=dataclasses.replace(settings, measure=True))
    assert on.stats["partition"]["reused"] == sum(off.stats["partition"]["groups_per_level"])
    assert np.array_equal(on.faces, off.faces) and np.array_equal(on.vertices, off.vertices)
    d = distance(V, F, on.vertices, on.faces)
    assert on.stats["distance_max"] == pytest.approx(d["distance_max"], rel=1e-9)
    again = qemjax.simplify((V, F), ratio=0.05, partition=settings)  # and back: nothing measured
    assert again.stats["partition"]["reused"] == on.stats["partition"]["reused"]
    assert again.stats["distance_max"] is None


def test_a_resumed_run_sees_a_replaced_file(tmp_path):
    """The resume key was the file's path, size and time: another scan of the same size copied over it with
    its time kept (cp -p) was given the old scan's result."""
    import os

    m = shapes.bumpy_sphere(4)
    path, other = tmp_path / "scan.ply", tmp_path / "other.ply"
    trimesh.Trimesh(m.vertices, m.faces, process=False).export(path)
    settings = Partition(workers=1, part_faces=2000, scratch=tmp_path / "scratch")
    first = qemjax.simplify(str(path), ratio=0.1, partition=settings)
    st = path.stat()
    trimesh.Trimesh(m.vertices * 3.0, m.faces, process=False).export(other)
    os.replace(other, path)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_size == st.st_size
    again = qemjax.simplify(str(path), ratio=0.1, partition=settings)
    assert again.stats["partition"]["reused"] == 0
    np.testing.assert_allclose(np.ptp(again.vertices, 0), 3 * np.ptp(first.vertices, 0), rtol=0.05)
    assert np.array_equal(again.vertices, qemjax.simplify(str(path), ratio=0.1, partition=Partition(
        workers=1, part_faces=2000)).vertices)
    assert qemjax.simplify(str(path), ratio=0.1, partition=settings).stats["partition"]["reused"] > 0


def test_ctrl_c_while_the_workers_leave_still_removes_the_temporary_folder(tmp_path, monkeypatch):
    """An interrupt inside the runner's close (the workers leaving) skipped the removal of the run's
    temporary folder: a large scan's parts stayed in /tmp."""
    import tempfile

    from qemjax._partition import execute

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    real = execute.LocalRunner.close

    def close(self, cancel=False):
        real(self, cancel)
        if not cancel:
            raise KeyboardInterrupt

    monkeypatch.setattr(execute.LocalRunner, "close", close)
    with pytest.raises(KeyboardInterrupt):
        qemjax.simplify(shapes.bumpy_sphere(4), ratio=0.1, partition=Partition(workers=2, part_faces=2000))
    assert not list(tmp_path.glob("qemjax-parts-*"))


def test_a_scratch_folder_with_a_users_files_is_refused_and_left_as_it_was(tmp_path):
    """A scratch folder is the run's: one that holds other files (a folder named like a level, a file named
    like the run's own input) is refused before anything in it is touched; the run's own folder is reused
    and, for other settings, cleared; an input in it under a name the run writes is refused."""
    m = shapes.bumpy_sphere(3)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    mine = tmp_path / "mine"
    (mine / "levels_of_detail").mkdir(parents=True)
    (mine / "levels_of_detail" / "a.txt").write_text("x")
    (mine / "input.ply").write_text("mine")
    with pytest.raises(ValueError, match="holds files a partitioned run did not write \\(levels_of_detail\\)"):
        qemjax.simplify((V, F), ratio=0.5, partition=Partition(workers=1, scratch=mine))
    assert (mine / "levels_of_detail" / "a.txt").read_text() == "x" and (mine / "input.ply").read_text() == "mine"
    ours = tmp_path / "ours"
    first = qemjax.simplify((V, F), ratio=0.5, partition=Partition(workers=1, scratch=ours))
    again = qemjax.simplify((V, F), ratio=0.5, partition=Partition(workers=1, scratch=ours))
    other = qemjax.simplify((V, F), ratio=0.4, partition=Partition(workers=1, scratch=ours))
    assert digest(again) == digest(first) and again.stats["partition"]["reused"] > 0
    assert len(other.faces) == round(0.4 * len(F)) and other.stats["partition"]["reused"] == 0
    assert (ours / "input.ply").exists()  # the arrays, as the run wrote them: a later run may rewrite it
    with pytest.raises(ValueError, match="is in the scratch folder under a name the run writes"):
        qemjax.simplify(str(ours / "input.ply"), ratio=0.5, partition=Partition(workers=1, scratch=ours))


def test_a_worker_s_share_of_the_cores_caps_its_threads(monkeypatch):
    from qemjax._mesh import threads

    monkeypatch.setattr(threads, "_cores", lambda: 4)
    assert threads.count() == 4
    with threads.limited(1):
        assert threads.count() == 1
        with threads.limited(None):  # no share given: the one around it holds
            assert threads.count() == 1
    with threads.limited(2):
        assert threads.count() == 2
        with threads.limited(8):  # never more than the cores
            assert threads.count() == 4
    assert threads.count() == 4
    # the local runner's share: one core each while every worker runs, all of them for a level's one task
    assert [execute.share(2, n) for n in (56, 2, 1)] == [2, 2, 4]
    assert [execute.share(4, n) for n in (14, 3, 1)] == [1, 1, 4]
    assert execute.share(8, 8) == 1
    running, most, lock = [0], [0], threading.Lock()

    def item(i):
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(0.01)
        with lock:
            running[0] -= 1
        return i * i

    for n in (1, 2):  # within a share, no more items at once than it; the answers in order
        most[0] = 0
        with threads.limited(n):
            assert threads.blocks(item, range(9)) == [i * i for i in range(9)]
        assert most[0] <= n


def test_other_inputs_or_settings_start_afresh(tmp_path):
    from qemjax._partition.run import _fresh

    (tmp_path / "level1").mkdir()
    (tmp_path / "level1" / "group_00000.npz").write_bytes(b"x")
    _fresh(tmp_path, {"input": "a", "target": 1})
    assert not (tmp_path / "level1").exists()  # no key yet: whatever is there is not trusted
    (tmp_path / "level1").mkdir()
    _fresh(tmp_path, {"input": "a", "target": 1})
    assert (tmp_path / "level1").exists()  # the same key: resumed
    _fresh(tmp_path, {"input": "a", "target": 2})
    assert not (tmp_path / "level1").exists()


@pytest.mark.slow
def test_a_killed_worker_does_not_lose_the_run(mesh, in_process, monkeypatch, tmp_path):
    runners, killed = [], []
    original = execute.open_runner
    monkeypatch.setattr(execute, "open_runner", lambda p: runners.append(original(p)) or runners[-1])

    def kill_one():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the first worker, once it has written a part
            if runners and runners[0].procs[0] is not None and list((tmp_path / "level1").glob("*.npz")):
                killed.append(runners[0].procs[0])
                killed[0].kill()
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_one)
    killer.start()
    r = qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, workers=2, scratch=tmp_path))
    killer.join()
    assert killed and killed[0].wait(timeout=10) != 0  # it was killed (and a new one started in its place)
    assert digest(r) == digest(in_process)


@pytest.mark.slow  # worker processes
def test_closing_the_local_runner_ends_every_worker_cleanly():
    """Told the run is done (their input closed), the idle workers exit by themselves with code 0, side by
    side (`worker.main` ends without Python's shutdown), rather than being killed when `close` stops waiting.
    (Closed as soon as they start, they are still importing: on a loaded machine that can outlast `close`'s
    wait, which is not what this checks.)"""
    runner = execute.LocalRunner(2, retries=0)
    runner.CLOSE_WAIT_S = 300
    procs = list(runner.procs)
    runner.close()
    assert [p.poll() for p in procs] == [0, 0]


def test_a_worker_close_kills_is_reaped():
    """A worker that does not exit within `close`'s wait is killed, and reaped: it polled as running after
    `close` returned (a zombie until collected)."""
    runner = execute.LocalRunner(1, retries=0)
    runner.CLOSE_WAIT_S = 0.01  # still importing: killed
    procs = list(runner.procs)
    runner.close()
    assert procs[0].poll() is not None


@pytest.mark.slow
def test_same_bits_on_a_dask_local_cluster(mesh, in_process):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            distributed.Client(cl) as client:
        r = qemjax.simplify(mesh, ratio=RATIO, partition=Partition(part_faces=PART, client=client))
    assert digest(r) == digest(in_process) and r.stats["partition"]["where"] == "dask"


def test_what_a_partitioned_run_does_not_offer(mesh):
    with pytest.raises(ValueError, match="max_error"):
        qemjax.simplify(mesh, ratio=0.1, max_error=1.0, partition=True)
    with pytest.raises(ValueError, match="locked"):
        qemjax.simplify(mesh, ratio=0.1, locked=[0], partition=True)
    with pytest.raises(ValueError, match="from a mesh file"):
        qemjax.simplify(mesh, ratio=0.1, attributes="uv", partition=True)
    with pytest.raises(ValueError, match="UVs and nothing else"):
        qemjax.simplify(mesh, ratio=0.1, attributes="normal", partition=True)


@pytest.mark.slow
def test_ctrl_c_stops_the_command_and_its_workers(mesh, tmp_path):
    psutil = pytest.importorskip("psutil")
    import signal
    import subprocess
    import sys
    from qemjax._partition.write import write_binary_ply

    src = tmp_path / "in.ply"
    write_binary_ply(src, *mesh)
    scratch = tmp_path / "scratch"
    proc = subprocess.Popen([sys.executable, "-m", "qemjax", "simplify", str(src), str(tmp_path / "out.ply"),
                             "--ratio", str(RATIO), "--partition", "--workers", "2", "--part-faces", str(PART),
                             "--scratch", str(scratch), "--quiet"], stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_default)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list((scratch / "level1").glob("*.npz")):
        time.sleep(0.05)
    workers = psutil.Process(proc.pid).children()
    assert len(workers) == 2
    t = time.monotonic()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    assert proc.returncode == 130 and time.monotonic() - t < 10
    assert "interrupted" in proc.stderr.read()
    gone, alive = psutil.wait_procs(workers, timeout=5)
    assert not alive and not (tmp_path / "out.ply").exists()
    assert list((scratch / "level1").glob("*.npz"))  # a scratch folder given is kept: the next run resumes


def test_what_a_file_holds_besides_positions_is_named_when_dropped(tmp_path):
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    ply = tmp_path / "coloured.ply"
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty float x\nproperty float y\n"
            f"property float z\nproperty float nx\nproperty uchar red\nelement face {len(F)}\n"
            "property list uchar int vertex_indices\nproperty uchar quality\nend_header\n")
    rows = [f"{x} {y} {z} 0.5 200" for x, y, z in V] + [f"3 {a} {b} {c} 7" for a, b, c in F]
    ply.write_text(head + "\n".join(rows) + "\n")
    obj = tmp_path / "textured.obj"
    lines = [f"v {x} {y} {z}" for x, y, z in V] + ["vt 0.5 0.5"] + [f"f {a+1}/1 {b+1}/1 {c+1}/1" for a, b, c in F]
    obj.write_text("\n".join(lines) + "\n")
    settings = Partition(part_faces=1000, workers=1)
    with pytest.warns(UserWarning, match="positions only.*vertex properties nx, red; face properties quality"):
        res = qemjax.simplify(ply, ratio=0.2, partition=settings)
    assert res.stats["dropped"] == ["record", "vertex properties nx, red", "face properties quality"]
    with pytest.warns(UserWarning, match=r"texture coordinates \(vt\)"):
        res = qemjax.simplify(obj, ratio=0.2, partition=settings, attributes=None)
    assert res.stats["dropped"] == ["record", "texture coordinates (vt)"]
    with pytest.warns(UserWarning) as said:  # one UV for every corner: no seam, kept by default (as in core)
        assert qemjax.simplify(obj, ratio=0.2, partition=settings).stats["dropped"] == ["record"]
    assert [str(w.message).split(" turns off")[0] for w in said] == ["keeping uv"]  # the stretch's alone
    plain = tmp_path / "plain.obj"
    plain.write_text("\n".join(l for l in lines if not l.startswith("vt")).replace("/1", "") + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert qemjax.simplify(plain, ratio=0.2, partition=settings).stats["dropped"] == ["record"]


@pytest.mark.parametrize("kind", ["little", "big", "ascii"])
def test_a_ply_whose_vertices_have_a_list_property_runs_partitioned(tmp_path, kind):
    """A PLY whose vertex element has a list property (read in core) runs partitioned: the same bits as the
    same mesh without it, the list named among what is dropped."""
    from test_partition_scatter import _ply_with_vertex_list

    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices, np.float32).astype(np.float64), np.asarray(m.faces)
    uv = (V[:, :2] * 0.5 + 0.5).astype(np.float32)
    settings = Partition(part_faces=1000, workers=1)
    out = []
    for with_list in (False, True):
        path = tmp_path / f"{with_list}.ply"
        _ply_with_vertex_list(path, V, F, uv, kind, with_list)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            res = qemjax.simplify(path, ratio=0.2, attributes="uv", partition=settings)
        seen = [w for w in seen if not str(w.message).startswith("keeping uv turns off")]  # (kept UVs: the stretch)
        assert [str(w.message).endswith("input: vertex properties ids") for w in seen] == [True] * with_list
        assert res.stats["dropped"] == ["record", *(["vertex properties ids"] if with_list else [])]
        out.append((digest(res), res.uv.tobytes()))
    assert out[0] == out[1]


def test_a_common_cost_share_meets_the_target_and_spreads_the_pilots():
    assert plan.pilots(3) == [0, 1, 2]
    assert plan.pilots(100) == [0, 14, 28, 42, 57, 71, 85, 99]
    assert plan.common_cost([3.0, 1.0, 2.0, 10.0]) == 2.5
    m = shapes.bumpy_sphere(5)
    res = qemjax.simplify(m, ratio=0.05, partition=Partition(part_faces=2000, workers=1, share="cost"))
    assert len(res.faces) == res.stats["target_faces"] and closed_and_consistent(res.faces)
    costs = res.stats["partition"]["cost_per_level"]
    assert costs[0] > 0 and costs[-1] is None  # the levels before the last share one cost; the last none
    with pytest.raises(ValueError, match="share must be"):
        Partition(share="area")


def test_the_docs_name_every_key_of_a_partitioned_result_s_stats(in_process):
    """docs/large-meshes.md, "What a partitioned result holds", names every key of ``stats`` and of
    ``stats["partition"]`` (it named neither ``rounds_contracting`` nor ``scratch``, ``format`` or ``welded``)."""
    import re

    page = (pathlib.Path(__file__).parent.parent / "docs" / "large-meshes.md").read_text()
    section = page.split("## What a partitioned result holds")[1].split("\n## ")[0]
    names = set(re.findall(r"`([a-z_0-9]+)`", section)) | set(re.findall(r'`stats\["([a-z_0-9]+)"\]', section))
    names |= {f"distance_{p}" for p in re.findall(r"`distance_(p\d+(?:/p\d+)*)`", section)[0].split("/")}

    def named(key):
        return key in names or (key.endswith("_rel") and key[:-4] in names)

    assert [k for k in in_process.stats if not named(k)] == []
    assert [k for k in in_process.stats["partition"] if not named(k)] == []


def test_an_input_cut_short_by_ctrl_c_is_written_again_when_resumed(tmp_path, monkeypatch):
    """Arrays are written to the scratch folder as ``input.ply`` whole or not at all: a Ctrl-C while they were
    written left a file cut short (its header still counting no faces), which every resumed run took as its
    input ("input.ply: the mesh has no faces")."""
    from qemjax._partition import write

    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    settings = Partition(workers=1, part_faces=1000, measure=False, scratch=tmp_path / "scratch")
    real = write.write_binary_ply

    def interrupted(path, vertices, faces, **kw):
        def chunks():  # Ctrl-C once the vertices and a few faces are written
            yield faces[:100]
            raise KeyboardInterrupt
        return real(path, vertices, chunks(), **kw)

    monkeypatch.setattr(write, "write_binary_ply", interrupted)
    with pytest.raises(KeyboardInterrupt):
        qemjax.simplify((V, F), ratio=0.1, partition=settings)
    monkeypatch.undo()
    assert not [p.name for p in (tmp_path / "scratch").iterdir() if "input" in p.name]  # nor its temporary file
    again = qemjax.simplify((V, F), ratio=0.1, partition=settings)
    fresh = qemjax.simplify((V, F), ratio=0.1, partition=dataclasses.replace(settings, scratch=None))
    assert again.stats["faces_in"] == len(F) and digest(again) == digest(fresh)


def test_a_second_run_in_a_scratch_folder_in_use_is_refused(tmp_path, monkeypatch):
    """Two runs in one scratch folder at once (the same command started twice, two threads of a script) each
    cleared or overwrote the other's parts and levels as it went: the second is refused in one line while the
    first holds the folder, and the first ends as it would alone; once it has ended, the folder is free."""
    from qemjax._partition import scatter

    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    settings = Partition(workers=1, part_faces=1000, measure=False, scratch=tmp_path / "scratch")
    inside, go, real = threading.Event(), threading.Event(), scatter.scatter

    def held(*args, **kw):  # the first run waits here, in the folder, until the second has tried
        if not inside.is_set():
            inside.set()
            go.wait(60)
        return real(*args, **kw)

    monkeypatch.setattr(scatter, "scatter", held)
    out = {}
    first = threading.Thread(target=lambda: out.update(res=qemjax.simplify((V, F), ratio=0.1, partition=settings)))
    first.start()
    try:
        assert inside.wait(60)
        with pytest.raises(ValueError, match=r"^partition: the scratch folder .*scratch is in use by another run"):
            qemjax.simplify((V, F), ratio=0.2, partition=settings)
    finally:
        go.set()
        first.join()
    fresh = qemjax.simplify((V, F), ratio=0.1, partition=dataclasses.replace(settings, scratch=None))
    assert digest(out["res"]) == digest(fresh)
    again = qemjax.simplify((V, F), ratio=0.1, partition=settings)
    assert digest(again) == digest(fresh) and again.stats["partition"]["reused"] > 0
    assert not (tmp_path / "scratch" / "run.lock").exists()  # let go, and removed


def test_a_resumed_run_removes_the_temporary_files_of_killed_writers(tmp_path):
    """A process killed while it wrote a piece (a worker stopped at Ctrl-C, or by the system for its memory)
    leaves its temporary file (``.NAME.PID.tmp``) in a kept scratch folder: a resumed run kept them for good.
    It now removes them, and reuses what was written whole."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    settings = Partition(workers=1, part_faces=1000, measure=False, scratch=tmp_path / "scratch")
    first = qemjax.simplify((V, F), ratio=0.1, partition=settings)
    left = [tmp_path / "scratch" / "level1" / ".group_00000.npz.4242.tmp", tmp_path / "scratch" / ".input.ply.4242.tmp",
            tmp_path / "scratch" / "level0" / ".part_00001.npz.4242.tmp"]
    for path in left:
        path.write_bytes(b"cut short")
    again = qemjax.simplify((V, F), ratio=0.1, partition=settings)
    assert digest(again) == digest(first) and again.stats["partition"]["reused"] > 0
    assert not [p for p in left if p.exists()]


class _ClosingRunner(execute.Runner):
    """A one-process runner that notes, as it is closed, whether another run could claim the scratch folder
    (``None`` not closed yet) and then raises ``fail`` if given (a Ctrl-C while the workers leave)."""

    def __init__(self, folder, fail=None):
        self.folder, self.fail, self.free_while_closing = folder, fail, None

    def close(self, cancel: bool = False) -> None:
        from qemjax._partition import run

        try:
            run._let_go(self.folder, run._claim(self.folder))
            self.free_while_closing = True
        except ValueError:
            self.free_while_closing = False
        if self.fail is not None:
            raise self.fail


def test_a_failed_run_holds_its_scratch_folder_until_its_workers_are_stopped(tmp_path, monkeypatch):
    """A run that fails (an error, a Ctrl-C) stops its workers (`Runner.close(cancel=True)`), which may still
    be writing pieces in the scratch folder: the folder stays held until they are stopped, so that no other
    run takes it meanwhile; then it is let go."""
    from qemjax._partition import scatter

    m = shapes.bumpy_sphere(4)
    folder = tmp_path / "scratch"
    runner = _ClosingRunner(folder)
    monkeypatch.setattr(execute, "open_runner", lambda p: runner)

    def broken(*args, **kw):
        raise RuntimeError("a worker's failure")

    monkeypatch.setattr(scatter, "scatter", broken)
    with pytest.raises(RuntimeError, match="a worker's failure"):
        qemjax.simplify((np.asarray(m.vertices), np.asarray(m.faces)), ratio=0.5,
                        partition=Partition(workers=1, part_faces=1000, measure=False, scratch=folder))
    assert runner.free_while_closing is False
    assert not (folder / "run.lock").exists()


def test_a_ctrl_c_while_the_workers_leave_lets_the_scratch_folder_go(tmp_path, monkeypatch):
    """A Ctrl-C while a finished run's workers leave (`Runner.close`) raised out of the run before it let go of
    its scratch folder: the lock stayed held by this process (a notebook's kernel) for its life, and every
    later run in the folder was refused as if another run held it."""
    m = shapes.bumpy_sphere(4)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    folder = tmp_path / "scratch"
    settings = Partition(workers=1, part_faces=1000, measure=False, scratch=folder)
    monkeypatch.setattr(execute, "open_runner", lambda p: _ClosingRunner(folder, KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        qemjax.simplify((V, F), ratio=0.5, partition=settings)
    monkeypatch.undo()
    again = qemjax.simplify((V, F), ratio=0.5, partition=settings)
    assert again.stats["partition"]["reused"] > 0
    assert not (folder / "run.lock").exists()
