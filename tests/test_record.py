"""The multiresolution record: replay to any face count, the vertex map, LOD chains, the .npz form."""
from __future__ import annotations

import dataclasses
import typing
import warnings

import numpy as np
import pytest
import scipy.sparse
import trimesh
from conftest import one_pair_per_round, shared_mesh

import qemjax
from qemjax import shapes
from qemjax._schedulers.parallel import driver
from qemjax._mesh.pointtri import point_triangle_distance


def same_mesh(level, res):
    """Byte-identical vertices, faces and correspondences."""
    assert level.vertices.tobytes() == res.vertices.tobytes()
    assert np.array_equal(level.faces, res.faces)
    assert np.array_equal(level.source_vertices, res.source_vertices)
    assert np.array_equal(level.source_faces, res.source_faces)
    assert level.max_error == res.max_error


def reachable(record, ratio):
    """A face count near ratio × the input's that some prefix of the record has exactly."""
    counts = record.face_counts()
    return int(counts[np.argmin(np.abs(counts - ratio * counts[0]))])


@pytest.mark.shared
@pytest.mark.parametrize("name", ["suzanne.obj", "rocker-arm-small.off"])
def test_greedy_replay_equals_simplify(name):
    """Each level of a greedy run is the run to that face count (summed quadrics throughout: the default's
    memoryless last stretch starts at 2× each run's own target, so there the levels are the long run's)."""
    path = shared_mesh(name)
    res = qemjax.simplify(path, ratio=0.05, scheduler="greedy", attributes=None, refit=0, late_memoryless=0)
    same_mesh(res.replay(contractions=len(res.history)), res)
    for ratio in (0.5, 0.2):
        k = reachable(res.record, ratio)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # reached exactly: no warning (attributes: named already)
            warnings.filterwarnings("ignore", ".*suzanne.obj carries")
            direct = qemjax.simplify(path, target_faces=k, scheduler="greedy", attributes=None, refit=0,
                                     late_memoryless=0)
        assert len(direct.faces) == k
        same_mesh(res.replay(k), direct)


def test_one_pair_per_round_replay_equals_simplify():
    """With one pair per round the parallel scheduler's choices do not depend on the target: every prefix
    is a run of its own (summed quadrics throughout, as above)."""
    V, F = shapes.bumpy_sphere(2)
    kw = dict(schedule=one_pair_per_round(), refit=0, late_memoryless=0)
    res = qemjax.simplify((V, F), ratio=0.1, **kw)
    for ratio in (0.6, 0.3):
        k = reachable(res.record, ratio)
        same_mesh(res.replay(k), qemjax.simplify((V, F), target_faces=k, **kw))


@pytest.mark.shared
def test_parallel_replay_is_the_run_at_round_boundaries(monkeypatch):
    """The mesh after each round, captured inside the run, is what the record replays there (one run: the
    default's memoryless last stretch is a second run on renumbered faces; its record replays the result,
    tests/test_late_memoryless.py)."""
    snaps = []

    choose = driver.choose

    def spying(run, glue=True):
        rnd = choose(run, glue)
        contract = rnd.contract

        def spy(*a):
            contract(*a)
            alive = run.faces.alive.copy()
            snaps.append((alive, run.faces.F[alive].copy(), run.VQ[: run.n, :3].copy()))
        rnd.contract = spy
        return rnd

    monkeypatch.setattr(driver, "choose", spying)
    res = qemjax.simplify(shared_mesh("cow.obj"), ratio=0.05, refit=0, late_memoryless=0)
    monkeypatch.undo()
    rec = res.record
    ends = np.flatnonzero(np.diff(np.append(rec.history.rounds, np.inf)) != 0) + 1  # prefix length per round
    assert len(ends) == len(snaps) > 3
    assert np.array_equal(rec.face_counts()[ends], res.stats["faces_per_round"])
    for j, (alive, F, X) in zip(ends, snaps):
        level = rec.replay(contractions=int(j))
        assert np.array_equal(level.source_faces, np.flatnonzero(alive))
        assert np.array_equal(level.source_vertices[level.faces], F)
        ids = level.source_vertices
        want = rec.frame.positions_to_mesh(X[ids], ids)  # unmoved vertices: float32-rounded here
        assert np.abs(level.vertices - want).max() <= 1e-6 * rec.frame.scale
    same_mesh(rec.replay(contractions=len(rec.history)), res)


@pytest.mark.shared
def test_parallel_replay_within_a_round_takes_the_cheapest_first():
    V0, F0 = (lambda m: (m.vertices, m.faces))(qemjax.load(shared_mesh("cow.obj")))
    res = qemjax.simplify((V0, F0), ratio=0.05, quality_threshold=0.0)  # (the shape term ranks by shaped keys)
    rec = res.record
    rounds, costs = rec.history.rounds, rec.history.costs
    for r in np.unique(rounds):
        c = costs[rounds == r]
        assert np.all(np.diff(c) >= 0), "a round's contractions are recorded in cost order"
    counts = rec.face_counts()
    big = np.bincount(rounds).argmax()
    inside = np.flatnonzero(rounds == big)
    j = int(inside[len(inside) // 2])  # halfway through the largest round
    k = int(counts[j])
    assert counts[inside[0]] > k > counts[inside[-1] + 1]
    level = rec.replay(k)
    assert len(level.faces) == k and level.contractions == j and level.round == big
    # a valid closed manifold of the input's genus, nothing degenerate or flipped
    mesh = level.to_trimesh()
    assert mesh.is_watertight and mesh.euler_number == trimesh.Trimesh(V0, F0, process=False).euler_number
    assert np.all(trimesh.triangles.area(mesh.triangles) > 0)
    n_in = trimesh.Trimesh(V0, F0, process=False).face_normals[level.source_faces]
    assert np.all(np.einsum("ij,ij->i", mesh.face_normals, n_in) > 0)


def _fan_distance2(points, level):
    """(n,) squared distance from each point to the faces around its vertex in ``level``."""
    V, F = level.vertices, level.faces
    inc = scipy.sparse.csr_matrix((np.ones(F.size), (F.reshape(-1), np.repeat(np.arange(len(F)), 3))),
                                  shape=(len(V), len(F)))
    vm = level.vertex_map
    cnt = np.diff(inc.indptr)[vm]
    pv = np.repeat(np.arange(len(points)), cnt)
    fs = inc.indices[np.concatenate([np.arange(inc.indptr[o], inc.indptr[o + 1]) for o in vm])]
    d = point_triangle_distance(points[pv], V[F[fs, 0]], V[F[fs, 1]], V[F[fs, 2]], squared=True)
    out = np.full(len(points), np.inf)
    np.minimum.at(out, pv, d)
    return out


@pytest.mark.shared
@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_vertex_map(scheduler):
    res = qemjax.simplify(shared_mesh("suzanne.obj"), ratio=0.1, scheduler=scheduler)
    vm = res.vertex_map
    assert vm.shape == (len(res.input_vertices),) and vm.min() == 0
    assert np.array_equal(vm[res.source_vertices], np.arange(len(res.vertices)))
    # each input vertex lies near the faces of its output vertex, within the run's largest error
    assert np.all(_fan_distance2(res.input_vertices, res.replay(contractions=len(res.history)))
                  <= res.max_error)
    level = res.replay(ratio=0.4)  # and at an intermediate level, within that level's error
    assert np.all(_fan_distance2(res.input_vertices, level) <= level.max_error)


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
def test_non_manifold_record_replays_coincident_removals(scheduler):
    """Two boxes joined by aggregation: faces that coincide are dropped, and the record says which
    contraction dropped them; a part that vanishes maps to -1."""
    b = trimesh.creation.box(extents=(1, 1, 1))
    s = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    V = np.concatenate([b.vertices, s.vertices + [2, 0, 0], b.vertices + [0, 3, 0]])
    F = np.concatenate([b.faces, s.faces + 8, b.faces + 16]).astype(np.int64)
    res = qemjax.simplify((V, F), target_faces=12, scheduler=scheduler, pair_threshold=0.1, refit=0)
    rec = res.record
    assert rec.coincident.any()
    assert np.all(rec.removed_at[rec.coincident] >= 0)
    counts = rec.face_counts()
    assert counts[-1] == len(res.faces)
    same_mesh(res.replay(contractions=len(rec.history)), res)
    assert np.all(res.vertex_map[8:16] == -1)  # the small box vanished
    for j in range(len(rec.history) + 1):  # every prefix is a mesh of the counted size, no coincident faces
        level = rec.replay(contractions=j)
        assert len(level.faces) == counts[j]
        key = np.sort(level.faces, axis=1)
        assert len(np.unique(key, axis=0)) == len(key)


def test_replay_rules_and_errors():
    res = qemjax.simplify(shapes.icosphere(2), ratio=0.2)
    rec = res.record
    assert len(rec.replay(ratio=1.0).faces) == len(res.input_faces)
    assert rec.replay(rec.face_counts()[0] + 10).contractions == 0
    odd = int(rec.face_counts()[5]) - 1  # a closed mesh: the level stops one face above an odd target
    assert len(rec.replay(odd).faces) == odd + 1
    with pytest.raises(ValueError, match="reaches") as err:
        rec.replay(len(res.faces) - 2)
    k = len(res.faces) - 2  # the message says which levels replay reaches, and how to get a coarser one
    assert str(err.value) == (f"replay reaches the levels between the input ({len(res.input_faces)} faces) and "
                              f"this result ({len(res.faces)} faces), not {k}; for fewer faces, simplify further: "
                              f"qemjax.simplify(..., target_faces={k}), or qemjax.lod_chain(..., ratios=[...]) "
                              "for every level from one run")
    parity = qemjax.simplify(shapes.icosphere(2), target_faces=63)  # stops at 64, as asked: no error
    assert len(parity.replay(63).faces) == 64
    with pytest.raises(ValueError, match="exactly one"):
        rec.replay(10, ratio=0.5)
    with pytest.raises(ValueError, match="ratio"):
        rec.replay(ratio=1.5)


def test_npz_round_trip_is_exact(tmp_path):
    res = qemjax.simplify(shapes.bumpy_sphere(2), ratio=0.1, method="esqem", split_factor=None)
    res.record.save(tmp_path / "a.npz")
    res.record.save(tmp_path / "b.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    back = qemjax.load_record(tmp_path / "a.npz")
    assert set(back.history.parts) == {"quadric", "curvature", "rank"}
    for k in (len(res.input_faces), 1000, len(res.faces)):
        a, b = res.replay(k), back.replay(k)
        assert a.vertices.tobytes() == b.vertices.tobytes() and np.array_equal(a.faces, b.faces)
    same_mesh(back.replay(len(res.faces)), res)
    np.savez(tmp_path / "c.npz", x=np.zeros(2))
    with pytest.raises(ValueError, match="not a qemjax record"):
        qemjax.load_record(tmp_path / "c.npz")
    (tmp_path / "d.npz").write_text("a text file")  # numpy's words: "pickled (object) data"
    with pytest.raises(ValueError, match="not a qemjax record .*: not an .npz archive"):
        qemjax.load_record(tmp_path / "d.npz")
    with pytest.raises(FileNotFoundError, match="no such record file"):
        qemjax.load_record(tmp_path / "missing.npz")
    import zipfile

    with zipfile.ZipFile(tmp_path / "a.npz") as z, zipfile.ZipFile(tmp_path / "e.npz", "w") as out:
        for name in z.namelist():
            if name != "pairs.npy":
                out.writestr(name, z.read(name))
    with pytest.raises(ValueError, match="the record is incomplete \\(no 'pairs' in it\\)"):
        qemjax.load_record(tmp_path / "e.npz")


def test_esqem_split_replays_the_contraction_phase_only():
    mesh = shapes.bumpy_sphere(4)
    res = qemjax.simplify(mesh, target_faces=600, method="esqem")
    phase = res.stats["split"]["simplified_to"]
    assert res.record.faces_out == phase < len(res.faces)
    level = res.replay(phase)
    assert len(level.faces) == phase
    assert np.array_equal(res.vertex_map[level.source_vertices], np.arange(len(level.vertices)))
    assert len(res.replay(600).faces) == 600  # the contractions passed through 600 faces
    with pytest.raises(ValueError, match="reaches"):
        res.replay(phase - 2)
    with pytest.raises(ValueError, match="split_factor=None"):
        qemjax.lod_chain(mesh, method="esqem")
    with pytest.raises(ValueError, match="split_factor=None"):  # the method as an object too
        qemjax.lod_chain(mesh, method=qemjax.ESQEM())
    assert len(qemjax.lod_chain(mesh, ratios=[0.5, 0.1], method=qemjax.ESQEM(split_factor=None))) == 2
    # the method as simplify resolves it: a split factor given beside an object without one, and a registered
    # subclass of ESQEM by its name, split after the contractions too (the chain's last level was then not
    # its result, and nothing said so)
    with pytest.raises(ValueError, match="split_factor=None"):
        qemjax.lod_chain(mesh, method=qemjax.ESQEM(split_factor=None), split_factor=1.5)

    @dataclasses.dataclass(frozen=True)
    class Curved(qemjax.ESQEM):
        name: typing.ClassVar[str] = "curved_for_lod"

    qemjax.register_method(Curved)
    try:
        with pytest.raises(ValueError, match="split_factor=None"):
            qemjax.lod_chain(mesh, method="curved_for_lod")
    finally:
        del qemjax._costs.REGISTRY["curved_for_lod"]
    with pytest.raises(ValueError, match="cannot run partitioned"):  # before the run, not after it
        qemjax.lod_chain(mesh, ratios=[0.5, 0.1], partition=True)


def test_lod_chain_levels_and_glb(tmp_path):
    mesh = shapes.bumpy_sphere(3)
    m = len(mesh.faces)
    chain = qemjax.lod_chain(mesh, ratios=[0.5, 0.25, 0.1, 0.01])
    targets = [round(r * m) for r in (0.5, 0.25, 0.1, 0.01)]
    assert [len(level.faces) for level in chain] == [t + t % 2 for t in targets]  # closed: even counts
    same_mesh(chain[-1], chain.result)
    for level, r in zip(chain, chain.ratios):
        assert np.array_equal(level.faces, chain.result.replay(ratio=r).faces)
    path = tmp_path / "chain.glb"
    chain.export(path)
    scene = trimesh.load(path)
    assert sorted(scene.graph.nodes_geometry) == ["lod0", "lod1", "lod2", "lod3"]
    assert sorted(len(g.faces) for g in scene.geometry.values()) == sorted(len(lv.faces) for lv in chain)
    with pytest.raises(ValueError, match="ratios"):
        qemjax.lod_chain(mesh, ratios=[0.5, 0])
    with pytest.raises(ValueError, match="targets"):
        qemjax.lod_chain(mesh, ratio=0.5)


def test_record_of_an_unchanged_mesh():
    res = qemjax.simplify(shapes.icosphere(1), ratio=1.0)
    assert len(res.history) == 0 and res.record.faces_out == len(res.faces)
    same_mesh(res.replay(ratio=1.0), res)
    assert np.array_equal(res.vertex_map, np.arange(len(res.input_vertices)))


def test_replay_and_vertex_map_check_their_arguments():
    """contractions=2.5 was taken as 2 and True as 1, vertex_map(-1) failed in numpy's words."""
    rec = qemjax.simplify(shapes.icosphere(2), ratio=0.5, method="classic").record
    n = len(rec.history)
    for bad in (2.5, -1, n + 1):
        with pytest.raises(ValueError, match=rf"contractions must be a whole number in \[0, {n}\], got"):
            rec.replay(contractions=bad)
        with pytest.raises(ValueError, match=rf"contractions must be a whole number in \[0, {n}\]"):
            rec.vertex_map(bad)
    for kw in (dict(contractions=True), dict(ratio="0.5")):
        with pytest.raises(ValueError, match=f"{next(iter(kw))} must be a number"):
            rec.replay(**kw)
    assert np.array_equal(rec.vertex_map(3), rec.replay(contractions=3).vertex_map)


@pytest.mark.parametrize("bad", [float("inf"), float("nan"), -float("inf")])
def test_replay_refuses_infinities_and_nans_in_its_words(bad):
    """replay(target_faces=inf) and replay(contractions=inf) raised OverflowError ("cannot convert float
    infinity to integer") and a NaN Python's ValueError ("cannot convert float NaN to integer"), where every
    other bad count is refused in the argument's name."""
    rec = qemjax.simplify(shapes.icosphere(2), ratio=0.5, method="classic").record
    n = len(rec.history)
    with pytest.raises(ValueError, match=rf"^contractions must be a whole number in \[0, {n}\], got -?(inf|nan)$"):
        rec.replay(contractions=bad)
    with pytest.raises(ValueError, match=rf"^contractions must be a whole number in \[0, {n}\], got -?(inf|nan)$"):
        rec.vertex_map(bad)
    with pytest.raises(ValueError, match=r"^target_faces must be an integer >= 1, got -?(inf|nan)$"):
        rec.replay(target_faces=bad)
    assert rec.replay(target_faces=np.int64(10**6)).contractions == 0  # an integer type is whole as it is


def test_lod_chain_takes_dotted_settings_as_simplify_does():
    """A setting named dotted ("method.refit") is the flat one: lod_chain's own default of refit=0 overrode
    it, and ESQEM's "method.split_factor": None was refused as missing; ratios=0.5 failed in Python's words."""
    V, F = shapes.icosphere(3)
    assert qemjax.lod_chain((V, F), ratios=[0.5, 0.2], **{"method.refit": 1}).result.stats["refit"] == 1
    assert qemjax.lod_chain((V, F), ratios=[0.5, 0.2]).result.stats["refit"] == 0
    chain = qemjax.lod_chain((V, F), ratios=[0.5, 0.2], method="esqem", **{"method.split_factor": None})
    assert [len(level.faces) for level in chain] == [640, 256]
    with pytest.raises(ValueError, match=r"ratios takes a list of ratios, one per level, got 0.5 \(ratios=\[0.5\]\)"):
        qemjax.lod_chain((V, F), ratios=0.5)
    for bad in (None, ["a"], [0.5, {}]):  # Python's words before ('NoneType' object is not iterable)
        with pytest.raises(ValueError, match=r"^ratios takes a list of ratios in \(0, 1\], one per level, got "):
            qemjax.lod_chain((V, F), ratios=bad)


def test_lod_chains_did_you_mean_names_only_what_it_takes():
    """lod_chain(ratioss=...) suggested 'ratio', which lod_chain refuses; an unknown keyword is refused before
    the run, its hint among lod_chain's own keywords."""
    mesh = shapes.icosphere(1)
    with pytest.raises(TypeError) as err:
        qemjax.lod_chain(mesh, ratioss=[0.5])
    assert str(err.value) == "unknown setting 'ratioss'; did you mean 'ratios'?"
    with pytest.raises(TypeError, match=r"^unknown setting 'rati'; did you mean 'ratios'\?$"):
        qemjax.lod_chain(mesh, rati=0.5)
    for key in ("target_face", "max_eror", "textur"):  # close to refused ones only: no suggestion of them
        with pytest.raises(TypeError, match=rf"^unknown setting '{key}' \(help\(qemjax.lod_chain\) lists"):
            qemjax.lod_chain(mesh, **{key: 1})
    with pytest.raises(TypeError, match=r"^unknown setting 'boundry_weight'; did you mean 'boundary_weight'\?$"):
        qemjax.lod_chain(mesh, boundry_weight=1.0)
    with pytest.raises(TypeError, match=r"^unknown method setting 'method.boundry_weight'; did you mean "
                                        r"'method.boundary_weight'\?$"):
        qemjax.lod_chain(mesh, **{"method.boundry_weight": 1.0})
    # what simplify takes, lod_chain passes on (schedule= was refused as unknown by this check)
    chain = qemjax.lod_chain(mesh, ratios=[0.5], schedule=qemjax.Schedule(), measure=False)
    assert len(chain.levels[0].faces) == 40


def test_cli_lod_writes_levels_glb_and_record(tmp_path, capsys):
    from qemjax._cli import main

    src = tmp_path / "sphere.obj"
    trimesh.Trimesh(*shapes.bumpy_sphere(3), process=False).export(src)
    out = tmp_path / "levels"
    assert main(["lod", str(src), str(out), "--ratios", "0.5", "0.1", "--glb", "--record", "--quiet",
                 "--no-cache"]) == 0
    rec = qemjax.load_record(out / "sphere-record.npz")
    for i, r in enumerate((0.5, 0.1)):
        written = trimesh.load(out / f"sphere-lod{i}.obj", process=False)
        assert len(written.faces) == len(rec.replay(ratio=r).faces)
    assert len(trimesh.load(out / "sphere-lods.glb").geometry) == 2
    assert main(["lod", str(src), str(src), "--quiet", "--no-cache"]) == 2  # a file, not a folder
    assert "is a file" in capsys.readouterr().err


def test_a_chain_flat_in_x_is_still_side_by_side():
    """A mesh in the plane x = 0 has no x-extent: its levels were stacked at the origin."""
    V, F = shapes.grid(8)
    V = np.asarray(V)[:, [2, 0, 1]]  # the grid in the y-z plane
    chain = qemjax.lod_chain((V, np.asarray(F)), ratios=[0.5, 0.2])
    scene = chain.to_scene()
    moves = [scene.graph[f"lod{i}"][0][0, 3] for i in range(2)]
    assert moves[0] == 0 and moves[1] == pytest.approx(1.2 * np.ptp(V, axis=0).max())


def test_the_warnings_of_lod_chain_and_a_partitioned_run_point_at_the_callers_line(tmp_path):
    """As simplify's own: a warning names the user's file and line, not qemjax's (lod_chain calls simplify; the
    partitioned run's closing warnings are issued two calls deeper than its first ones)."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # a tetrahedron: 4 faces is as far as it goes
    path = tmp_path / "tetra.ply"
    trimesh.Trimesh(V, F, process=False).export(path)
    for call in (lambda: qemjax.lod_chain((V, F), ratios=[0.5, 0.25]),
                 lambda: qemjax.simplify(str(path), target_faces=1, partition=qemjax.Partition(workers=1)),
                 lambda: qemjax.simplify((V, F), target_faces=1)):
        with warnings.catch_warnings(record=True) as got:
            warnings.simplefilter("always")
            call()
        assert got and {w.filename for w in got} == {__file__}, [(w.filename, str(w.message)[:60]) for w in got]
        # the partitioned run's warning gives the last level's reason once, not its "stopped at ..." again
        assert all(str(w.message).count("stopped at") == 1 for w in got)


def test_replay_of_a_run_that_kept_attributes_says_they_are_not_replayed():
    """res.replay of a run that kept UVs or colours gave a level of positions and faces without a word: it
    warns once per call, naming them; a run without attributes replays silently, and lod_chain given
    attributes to keep warns once for its levels, not once per level."""
    V, F = shapes.grid(12)
    V = V.copy()
    V[:, 2] = 0.05 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1])
    textured = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=V[:, :2] * 0.5))
    colored = trimesh.Trimesh(V, F, process=False, vertex_colors=np.c_[V[:, :2] * 100 + 50, np.full((len(V), 2), 255)])
    for mesh, kind, name in ((textured, "uv", "uv"), (colored, "color", "colors")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = qemjax.simplify(mesh, ratio=0.3, attributes=kind)
        assert getattr(res, name) is not None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            level = res.replay(ratio=0.6)
        assert [str(w.message) for w in caught] == [
            f"replay gives positions and faces only: the run's {name} is not replayed (the record holds the "
            "contractions, not the attributes' wedges)"] and caught[0].filename == __file__
        assert not hasattr(level, name)
    plain = qemjax.simplify(shapes.bumpy_sphere(2), ratio=0.3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plain.replay(ratio=0.6)
        chain = qemjax.lod_chain(shapes.bumpy_sphere(2), [0.6, 0.3])
    assert not caught and len(chain.levels) == 2
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        qemjax.lod_chain(textured, [0.6, 0.3], attributes="uv")
    # its levels lack the UVs asked for: said once for the chain (it said nothing), not once per level
    said = [w for w in caught if "not replayed" in str(w.message)]
    assert [str(w.message) for w in said] == [
        "lod_chain's levels have positions and faces only: the run's uv is not replayed (the record holds the "
        "contractions, not the attributes' wedges); chain.result keeps them"] and said[0].filename == __file__


def test_a_scheduler_that_gives_no_rounds_replays(monkeypatch, tmp_path):
    """The scheduler contract lets an Outcome leave history_rounds None (a scheduler registered from
    outside need not count rounds): the record then holds no rounds, and every level but the input's read
    the round of its last contraction from them, an IndexError out of replay, vertex_map, lod_chain and
    max_distance alike. Such a level's round is -1, as for the input."""
    from qemjax import _schedulers

    def plain(*args, **kwargs):
        return dataclasses.replace(_schedulers.get("parallel")(*args, **kwargs), history_rounds=None)

    monkeypatch.setitem(_schedulers._REGISTRY, "no_rounds", plain)
    m = shapes.icosphere(2)
    res = qemjax.simplify(m, ratio=0.2, method="classic", scheduler="no_rounds")
    want = qemjax.simplify(m, ratio=0.2, method="classic")
    assert len(res.history.rounds) == 0 and np.array_equal(res.faces, want.faces)
    level = res.replay(contractions=5)
    assert level.round == -1 and np.array_equal(level.faces, want.replay(contractions=5).faces)
    assert np.array_equal(res.vertex_map, want.vertex_map)
    res.record.save(tmp_path / "r.npz")
    assert np.array_equal(qemjax.load_record(tmp_path / "r.npz").replay(contractions=7).faces,
                          want.replay(contractions=7).faces)
    chain = qemjax.lod_chain(m, ratios=[0.5, 0.2], method="classic", scheduler="no_rounds")
    assert [len(lv.faces) for lv in chain] == [160, 64]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bounded = qemjax.simplify(m, max_distance_rel=0.01, method="classic", scheduler="no_rounds")
    assert bounded.stats["distance_two_way_max"] <= bounded.stats["max_distance"]


@pytest.mark.parametrize("shape, kw", [(shapes.icosphere(2), dict(ratio=0.2)),
                                       (shapes.cube(2), dict(target_faces=4, preserve_topology=False,
                                                             flip_angle=None))])  # coincident faces go
def test_a_scheduler_that_does_not_say_which_faces_went_replays(monkeypatch, shape, kw):
    """The scheduler contract lets an Outcome leave removed_at and coincident None, and the record then
    took every face for a survivor: each level re-linked all the input's faces, collapsed ones included
    (the last level 256 degenerate faces where the result has 64), and max_distance returned such a level
    as its result. They are found from the contractions, as the built-in schedulers record them."""
    from qemjax import _schedulers

    def silent(*args, **kwargs):
        out = _schedulers.get("parallel")(*args, **kwargs)
        return dataclasses.replace(out, removed_at=None, coincident=None)

    monkeypatch.setitem(_schedulers._REGISTRY, "silent", silent)
    res = qemjax.simplify(shape, method="classic", scheduler="silent", **kw)
    own = qemjax.simplify(shape, method="classic", **kw)
    assert np.array_equal(res.faces, own.faces)
    assert np.array_equal(res.record.removed_at, own.record.removed_at)
    assert np.array_equal(res.record.coincident, own.record.coincident)
    for j in range(len(res.history) + 1):
        same_mesh(res.replay(contractions=j), own.replay(contractions=j))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bounded = qemjax.simplify(shape, method="classic", scheduler="silent", max_distance_rel=0.05)
        alone = qemjax.simplify(shape, method="classic", max_distance_rel=0.05)
    assert np.array_equal(bounded.faces, alone.faces) and np.array_equal(bounded.vertices, alone.vertices)
