"""Quadrics carried from level to level of a partitioned run (`qemjax._partition.carry`): a run's exported
quadrics are the ones its scheduler summed, a run seeded with its own quadrics starts where it would have,
welded and shared vertices add their quadrics, the cuts between parts carry no boundary planes while the
input's own boundary along a cut keeps its planes, and a partitioned run keeps a sharp spike that only the
input's planes hold (as the in-core run does)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_mesh

import qemjax
from qemjax import Partition, shapes
from qemjax._partition import pieces
from qemjax._partition.carry import Carry, to_mesh, to_run, translate
from qemjax._pipeline.stages import SEED


def bumpy(subdivisions=4):
    m = shapes.bumpy_sphere(subdivisions)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def mean_area(V, F):
    return float(np.mean(0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)))


def test_unit_changes_invert_and_translation_is_exact_in_float64():
    rng = np.random.default_rng(0)
    Q = rng.normal(size=(50, 10))
    assert np.allclose(to_run(to_mesh(Q, 3.5, 0.02), 3.5, 0.02), Q, rtol=1e-14, atol=0)
    # a quadric's value at x, centred at p: the same after re-centring at p + d and evaluating at x - d
    d, u = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    assert np.allclose(value(translate(Q, d), u - d), value(Q, u), rtol=1e-12, atol=1e-12)


def value(q, x):
    """Quadrics q (n,10) at offsets x (n,3) from their centres."""
    A = np.stack([q[:, [0, 1, 2]], q[:, [1, 3, 4]], q[:, [2, 4, 5]]], 1)
    return np.einsum("ni,nij,nj->n", x, A, x) + 2 * np.einsum("ni,ni->n", q[:, 6:9], x) + q[:, 9]


@pytest.mark.parametrize("locked", [False, True])
def test_exported_quadrics_are_the_input_planes_merged_into_each_vertex(locked):
    """The default (face planes weighted by area^0.6, the re-fit moving the vertices after the run), on a
    mesh far from the origin and not of unit size, carried in a unit of its own: each output vertex's carried
    quadric, at points around it, is the float64 sum of w·(n·(x − p))² over the input faces of every input
    vertex merged into it (w = (area in the unit²)^0.6), as an in-core run sums them."""
    from qemjax._mesh.topology import contraction_roots

    V, F = bumpy(4)
    V = V * 7.3 + [40.0, -3.0, 12.0]
    unit = 9.0
    kw = {"locked": np.abs(V[:, 2] - 12.0) < 0.3} if locked else {}
    carry = Carry(V, None, unit)
    res = qemjax.simplify((V, F), ratio=0.1, measure=False, **kw, **{SEED: carry})
    Q = carry.export(res)
    assert np.any(res.vertices[np.isin(res.source_vertices, res.history.pairs[:, 0])]
                  != V[res.source_vertices[np.isin(res.source_vertices, res.history.pairs[:, 0])]])
    # the reference, in the carried unit
    P = V / unit
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    cr = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    n = cr / (2 * area)[:, None]
    w = area ** 0.6
    root = contraction_roots(res.history.pairs, len(V))
    slot = np.full(len(V), -1)
    slot[res.source_vertices] = np.arange(len(res.source_vertices))
    rng = np.random.default_rng(2)
    X = res.vertices / unit + rng.normal(scale=0.02, size=(len(res.vertices), 3))  # a point around each
    want = np.zeros(len(X))
    for c in range(3):  # each face's plane at each of its corners' output vertices
        j = slot[root[F[:, c]]]
        ok = j >= 0
        want += np.bincount(j[ok], weights=w[ok] * np.einsum("ij,ij->i", n[ok], X[j[ok]] - P[F[ok, 0]]) ** 2,
                            minlength=len(X))
    got = value(Q, X - res.vertices / unit)
    assert np.allclose(got, want, rtol=1e-3, atol=1e-6 * want.max())


@pytest.mark.parametrize("locked", [False, True])
def test_exported_quadrics_are_the_ones_the_run_summed(locked):
    """Classic QEM (summed quadrics, no re-fit): each output vertex's carried quadric, evaluated at the
    vertex, is the run's own vertex error (its summed quadric there), in the carried units (× the mean face
    area, area_power 1)."""
    V, F = bumpy(4)
    kw = {}
    if locked:  # the locked vertices of a band: the run is renumbered, the export is not
        kw["locked"] = np.abs(V[:, 2]) < 0.05
    carry = Carry(V, None)
    res = qemjax.simplify((V, F), ratio=0.1, method="classic", measure=False, **kw, **{SEED: carry})
    Q = carry.export(res)
    assert Q.shape == (len(res.vertices), 10)
    k = mean_area(V, F)
    got, want = Q[:, 9] / k, res.vertex_error
    scale = float(np.max(want))
    assert scale > 0 and np.allclose(got, want, rtol=2e-3, atol=2e-4 * scale)
    assert np.all(np.linalg.eigvalsh(np.stack([Q[:, [0, 1, 2]], Q[:, [1, 3, 4]], Q[:, [2, 4, 5]]], 1)) > -1e-9)


@pytest.mark.parametrize("locked", [False, True])
def test_a_run_seeded_with_its_own_quadrics_starts_where_it_would(locked):
    """The default's starting quadrics, carried out (in a unit of their own) and seeded into a run of the same
    mesh: the state the scheduler starts from is the model's own, to float32 rounding, in the run's
    numbering (locked vertices first)."""
    V, F = bumpy(4)
    kw = {"locked": V[:, 0] > 0.9} if locked else {}
    first = Carry(V, None, 3.0)
    qemjax.simplify((V, F), ratio=0.5, measure=False, **kw, **{SEED: first})
    seen = {}

    def seed(job, start):
        seen["own"], seen["seeded"] = job.model.init_state(start), Carry(V, first.start, 3.0)(job, start)
        return seen["seeded"]

    res = qemjax.simplify((V, F), ratio=0.1, measure=False, **kw, **{SEED: seed})
    own = np.asarray(seen["own"], np.float64)
    assert seen["seeded"].dtype == seen["own"].dtype and len(res.faces) == int(round(0.1 * len(F)))
    assert np.allclose(seen["seeded"], own, rtol=1e-6, atol=1e-6 * np.abs(own).max())


def test_welded_vertices_add_their_quadrics():
    V, F = bumpy(3)
    V2 = np.concatenate([V, V[:1]])  # vertex 0 given twice: the copy is welded into it
    F2 = F.copy()
    f = np.flatnonzero(np.any(F == 0, 1))[0]
    F2[f][F2[f] == 0] = len(V)  # one face of vertex 0 uses the copy
    rng = np.random.default_rng(1)
    Q = rng.normal(size=(len(V2), 10))
    carry = Carry(V2, Q)
    qemjax.simplify((V2, F2), ratio=0.9, method="classic", measure=False, **{SEED: carry})
    assert len(carry.start) == len(V)
    assert np.allclose(carry.start[0], Q[0] + Q[-1]) and np.allclose(carry.start[1:], Q[1:-1])


def test_the_cuts_between_parts_carry_no_boundary_planes():
    """A grid with a hole-free open border: with the border's vertices locked (as the cuts of level 1 are),
    the starting quadrics of the border vertices have no boundary planes; inside, they are the run's own."""
    g = shapes.grid(12)
    V, F = np.asarray(g.vertices, np.float64), np.asarray(g.faces, np.int64)
    edge = np.isclose(V[:, 0], V[:, 0].min()) | np.isclose(V[:, 0], V[:, 0].max())
    own, cut = Carry(V, None), Carry(V, None)
    qemjax.simplify((V, F), ratio=0.9, method="classic", measure=False, **{SEED: own})
    qemjax.simplify((V, F), ratio=0.9, method="classic", measure=False, locked=edge, **{SEED: cut})
    trace = lambda Q: Q[:, 0] + Q[:, 3] + Q[:, 5]  # noqa: E731
    ends = np.isclose(V[:, 1], V[:, 1].min()) | np.isclose(V[:, 1], V[:, 1].max())
    # along the cut only the face planes are left (the corners keep their planes of the other border)
    assert np.all(trace(cut.start)[edge & ~ends] < trace(own.start)[edge & ~ends] * 0.05)
    assert np.all(trace(cut.start)[edge & ends] < trace(own.start)[edge & ends] * 0.6)
    # inside, and along the other border (not locked), the run's own quadrics
    assert np.allclose(cut.start[~edge], own.start[~edge], rtol=1e-6)


def test_the_input_s_own_boundary_along_a_cut_keeps_its_planes():
    """The grid's border at the smallest x locked, as a cut is, but named as the input's own boundary
    (``boundary``, as `scatter` finds it): its vertices keep their boundary planes, the other cut's lose them."""
    g = shapes.grid(12)
    V, F = np.asarray(g.vertices, np.float64), np.asarray(g.faces, np.int64)
    low, high = np.isclose(V[:, 0], V[:, 0].min()), np.isclose(V[:, 0], V[:, 0].max())
    column = np.flatnonzero(low)[np.argsort(V[low, 1])]
    own, cut = Carry(V, None), Carry(V, None, boundary=np.stack([column[:-1], column[1:]], 1))
    qemjax.simplify((V, F), ratio=0.9, method="classic", measure=False, **{SEED: own})
    qemjax.simplify((V, F), ratio=0.9, method="classic", measure=False, locked=low | high, **{SEED: cut})
    trace = lambda Q: Q[:, 0] + Q[:, 3] + Q[:, 5]  # noqa: E731
    ends = np.isclose(V[:, 1], V[:, 1].min()) | np.isclose(V[:, 1], V[:, 1].max())
    assert np.allclose(cut.start[low], own.start[low], rtol=1e-6)
    assert np.all(trace(cut.start)[high & ~ends] < trace(own.start)[high & ~ends] * 0.05)


def open_tubes(k=4, around=48, along=10, seed=0):
    """``k`` open tubes (no caps) in random places and directions, each with a long first strip of faces
    and a bulge: a mesh of many open pieces, as the teapot's spout, whose border runs along the cuts between
    parts of 1,000 faces."""
    rng = np.random.default_rng(seed)
    Vs, Fs = [], []
    t = np.linspace(0, 2 * np.pi, around, endpoint=False)
    i, j = np.meshgrid(np.arange(along), np.arange(around), indexing="ij")
    a0, a1 = i * around + j, i * around + (j + 1) % around
    faces = np.concatenate([np.stack([a0, a1, a1 + around], -1).reshape(-1, 3),
                            np.stack([a0, a1 + around, a0 + around], -1).reshape(-1, 3)])
    for _ in range(k):
        length, radius, centre, axis = rng.uniform(1, 2), rng.uniform(0.2, 0.5), rng.uniform(-2, 2, 3), rng.normal(size=3)
        z = np.concatenate([[0.0], np.linspace(0.3 * length, length, along)])
        axis /= np.linalg.norm(axis)
        u = np.cross(axis, [0.3, 0.5, 0.8])
        u /= np.linalg.norm(u)
        w = np.cross(axis, u)
        r = radius * (1 + 0.3 * np.sin(3 * z / length))
        ring = np.cos(t)[None, :, None] * u + np.sin(t)[None, :, None] * w
        Vs.append((centre + z[:, None, None] * axis + r[:, None, None] * ring).reshape(-1, 3))
        Fs.append(faces + sum(len(v) for v in Vs[:-1]))
    return np.concatenate(Vs), np.concatenate(Fs)


def test_scatter_finds_the_input_s_boundary_edges_along_the_cuts(tmp_path):
    """`scatter.borders_on_cuts`: the edges of one face of the whole input whose two ends several parts use,
    neither a cut (two faces, in two parts) nor an edge inside a part."""
    from qemjax._partition.scatter import scatter
    from qemjax._partition.write import write_binary_ply

    V, F = open_tubes()
    write_binary_ply(tmp_path / "tubes.ply", V, F)
    manifest = scatter(tmp_path / "tubes.ply", tmp_path / "parts", 1000)
    shared = np.zeros(len(V), bool)
    for part in manifest["parts"]:
        _, _, gid, border = pieces.load(tmp_path / "parts" / part["file"])
        shared[gid[border]] = True
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    edges, count = np.unique(E, axis=0, return_counts=True)
    want = edges[(count == 1) & shared[edges[:, 0]] & shared[edges[:, 1]]]
    got = np.load(tmp_path / "parts" / manifest["borders_on_cuts"])["E"]
    assert len(want) > 0 and np.array_equal(got, want)


def test_a_border_along_the_cuts_is_kept_as_in_core(tmp_path):
    """Open tubes cut into parts of 1,000 faces: their borders run along the cuts, where level 1 locks both
    ends of an edge. Level 1 keeps the planes of those edges that are the input's boundary (the cuts' own go),
    so the last level, which sees them only through the carried quadrics, keeps the borders where the
    in-core run does (without them, the partitioned run's Hausdorff distance was several times the
    in-core one's)."""
    V, F = open_tubes()
    core = qemjax.simplify((V, F), ratio=0.1, progress=False)
    part = qemjax.simplify((V, F), ratio=0.1, progress=False,
                           partition=Partition(part_faces=1000, workers=1, scratch=tmp_path / "parts"))
    assert part.stats["partition"]["levels"] >= 2 and part.stats["partition"]["carried"]
    h_core, h_part = core.stats["distance_max_rel"], part.stats["distance_max_rel"]
    assert h_part < 1.5 * h_core, (h_part, h_core)
    assert len(np.load(tmp_path / "parts" / "level0" / "borders_on_cuts.npz")["E"]) > 0


def test_stitch_adds_the_quadrics_of_a_shared_vertex(tmp_path):
    V = np.random.default_rng(1).random((5, 3))
    Qa, Qb = np.arange(30.0).reshape(3, 10), 100 + np.arange(30.0).reshape(3, 10)
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    pieces.save(a, V=V[[0, 1, 2]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([10, 11, -1]), Q=Qa)
    pieces.save(b, V=V[[1, 0, 3]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([11, 10, -1]), Q=Qb)
    W, F, gid, _, Q = pieces.stitch([a, b], carried=True)
    assert list(gid) == [10, 11, -1, -1]
    assert np.array_equal(Q, np.stack([Qa[0] + Qb[1], Qa[1] + Qb[0], Qa[2], Qb[2]]))
    pieces.save(b, V=V[[1, 0, 3]], F=np.array([[0, 1, 2]], np.int32), gid=np.array([11, 10, -1]))
    assert pieces.stitch([a, b], carried=True)[4] is None  # a piece without quadrics: none carried


@pytest.mark.slow
def test_a_partitioned_run_keeps_a_spike_the_input_holds():
    """The Stanford bunny Loop-subdivided twice (1.1 M faces) has a spike of three long faces. The in-core run
    keeps it; so does the partitioned run, whose last level sees it only through the quadrics carried to it
    (its own planes at the spike, those of the coarse mesh the levels before left, make it cheap to remove:
    without carrying, the spike was 1.4 % of the diagonal from the output)."""
    import trimesh

    from qemjax._mesh.grid_nearest import nearest

    bunny = qemjax.load(shared_mesh("stanford-bunny.obj"))
    V, F = trimesh.remesh.subdivide_loop(np.asarray(bunny.vertices), np.asarray(bunny.faces), iterations=2)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    tip = V[np.argmin(np.sum((V - [-0.066, 0.067, 0.024]) ** 2, axis=1))][None]
    core = qemjax.simplify((V, F), ratio=0.01, measure=False)
    part = qemjax.simplify((V, F), ratio=0.01, measure=False, partition=Partition(workers=1))
    d_core, d_part = (nearest(r.vertices, r.faces, tip)[1][0] / diag for r in (core, part))
    assert d_core < 0.003 and d_part < 0.003, (d_core, d_part)
    assert part.stats["partition"]["levels"] >= 2 and part.stats["partition"]["carried"]
