"""Host-side connectivity: the incremental edge and face updates against rebuilds from the faces."""
from __future__ import annotations

import numpy as np
import pytest

from qemjax._mesh import topology as topo
from qemjax import shapes
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers.parallel.pairs import accepted as _accepted
from edges_reference import contract_edges

rng = np.random.default_rng(7)


def _independent_pairs(E, ecount, n, F):
    """Random edges, two edges apart from each other, that pass the manifold (link) test."""
    adj_lock = np.zeros(n, bool)
    nbrs = [[] for _ in range(n)]
    for u, v in E:
        nbrs[u].append(v)
        nbrs[v].append(u)
    chosen = []
    for i in rng.permutation(len(E))[: len(E) // 4]:
        u, v = E[i]
        ring = [u, v] + nbrs[u] + nbrs[v]
        if adj_lock[ring].any():
            continue
        chosen.append(i)
        adj_lock[ring] = True
    P = E[chosen]
    deg = topo.vertex_degree(E, n)
    bvert = np.zeros(n, bool)
    bvert[E[ecount == 1].reshape(-1)] = True
    ok, apex, rows, pair = topo.link_ok(P, ecount[chosen], E, n, bvert, deg, apexes=True, edges_at=True)
    assert np.array_equal(ok, topo.link_ok(P, ecount[chosen], E, n, bvert, deg))
    # the edges at the endpoints, each once, with its pair
    assert np.array_equal(np.sort(rows), np.flatnonzero(np.isin(E, P).any(1)))
    assert (E[rows][:, :, None] == P[pair][:, None, :]).any((1, 2)).all()
    _, _, _, owner, G = FaceLists(F, n).touched(P)
    ok &= topo.coincidence_count(G, owner, len(P)) == 0
    return P[ok], apex[ok], np.compress(ok[pair], rows)


def _face_apexes(F, a, b):
    """Sorted apexes (S,2) of each pair's faces (-1 padded), found by brute force over the faces."""
    out = np.full((len(a), 2), -1)
    for s, (u, v) in enumerate(zip(a, b)):
        c = sorted(int(w) for f in F if u in f and v in f for w in f if w != u and w != v)
        out[s, 2 - len(c):] = c
    return out


@pytest.mark.parametrize("mesh", [shapes.bumpy_sphere(3), shapes.grid(12, hole=True), shapes.torus()],
                         ids=["sphere", "grid-with-hole", "torus"])
def test_incremental_edges_match_rebuild(mesh):
    F = np.asarray(mesh.faces, np.int64)
    n = len(mesh.vertices)
    E, ecount = topo.edges(F, n)
    degree = topo.vertex_degree(E, n)
    for _ in range(6):
        P, apex, rows = _independent_pairs(E, ecount, n, F)
        assert len(P) > 0
        a, b = P[:, 0], P[:, 1]
        # the link test's common neighbours are exactly the apexes of the pair's faces
        assert np.array_equal(np.sort(apex, 1), _face_apexes(F, a, b))
        rep = np.arange(n)
        rep[b] = a
        Fr = rep[F]
        deg = (Fr[:, 0] == Fr[:, 1]) | (Fr[:, 1] == Fr[:, 2]) | (Fr[:, 0] == Fr[:, 2])
        degree_before = degree
        E2, c2, keep, degree, at_a = contract_edges(E, ecount, a, b, apex, n, degree)
        # the same from the rows at the endpoints that the link test found (no scan of E)
        known = contract_edges(E, ecount, a, b, apex, n, degree_before, rows=rows[::-1])
        assert all(np.array_equal(x, y) for x, y in zip(known, (E2, c2, keep, degree, at_a)))
        assert np.array_equal(at_a, np.isin(E2, a).any(1))
        src = np.flatnonzero(keep)
        F = Fr[~deg]
        Eref, cref = topo.edges(F, n)
        order = np.lexsort((E2[:, 1], E2[:, 0]))  # same edges and counts, in another order
        assert np.array_equal(E2[order], Eref) and np.array_equal(c2[order], cref)
        assert np.array_equal(degree, topo.vertex_degree(Eref, n))
        assert (E2[:, 0] < E2[:, 1]).all()
        # each edge continues an old one: the same edge, or (b, c) for (a, c)
        old = E[src]
        same = (old == E2).all(1)
        moved = ~same
        assert np.isin(old[moved], b).any(1).all()
        E, ecount = E2, c2


def _brute_touched(F, P):
    """(face, corner, owner, face after) for faces holding exactly one endpoint of one pair."""
    out = set()
    for s, (u, v) in enumerate(P):
        for f, face in enumerate(F):
            if (u in face) != (v in face):
                k = list(face).index(u if u in face else v)
                after = list(face)
                after[k] = u
                out.add((f, k, s, tuple(after)))
    return out


@pytest.mark.parametrize("mesh", [shapes.bumpy_sphere(3), shapes.grid(12, hole=True)], ids=["sphere", "grid"])
@pytest.mark.parametrize("pool", ["roomy", "tight"])
@pytest.mark.parametrize("apply", ["contract", "reuse"])
def test_face_lists_follow_contractions(mesh, pool, apply):
    """FaceLists after rounds of contractions: the live faces equal the remapped, degenerate-free input,
    every vertex lists exactly its live faces, and `touched` matches a brute-force search. A tight pool
    compacts on every write. ``reuse``: the contractions are applied from `touched_with_dead` look-ups made
    in two passes, of which a subset is taken (as the parallel scheduler does), not looked up again."""
    F = np.asarray(mesh.faces, np.int64)
    n = len(mesh.vertices)
    lists = FaceLists(F, n)
    if pool == "tight":
        lists.pool = lists.pool[: lists.end].copy()
    E, ecount = topo.edges(F, n)
    for _ in range(5):
        P, _, _ = _independent_pairs(E, ecount, n, F)
        f, before, corner, owner, after = lists.touched(P.astype(np.int32))
        assert np.array_equal(before, lists.F[f])
        got = {(int(a), int(k), int(s), tuple(int(x) for x in g)) for a, k, s, g in zip(f, corner, owner, after)}
        live = np.flatnonzero(lists.alive)
        assert got == {(int(live[i]), k, s, g) for i, k, s, g in _brute_touched(F, P)}
        if apply == "reuse":  # two look-up passes over halves of P; every third pair is left out
            P = P.astype(np.int32)
            halves = np.array_split(np.arange(len(P)), 2)
            found = [(h, *lists.touched_with_dead(P[h])[1:], None) for h in halves]
            take = np.arange(len(P)) % 3 != 1
            pairs, kept, dead, _ = _accepted(P, found, take)
            assert np.array_equal(pairs, P[take])
            P = P[take]
        rep = np.arange(n)
        rep[P[:, 1]] = P[:, 0]
        Fr = rep[F]
        deg = (Fr[:, 0] == Fr[:, 1]) | (Fr[:, 1] == Fr[:, 2]) | (Fr[:, 0] == Fr[:, 2])
        if apply == "reuse":
            lists.contract_touched(pairs, kept, dead)
        else:
            dead = lists.contract(P[:, 0].astype(np.int32), P[:, 1].astype(np.int32))
        assert np.array_equal(np.sort(dead), live[deg])
        F = Fr[~deg]
        assert lists.count == len(F) and np.array_equal(lists.live(), F)
        w, fl = lists.around(np.arange(n))
        listed = {(int(v), int(x)) for v, x in zip(w, fl)}
        live = np.flatnonzero(lists.alive)
        assert listed == {(int(v), int(live[i])) for i, face in enumerate(F) for v in face}
        E, ecount = topo.edges(F, n)


@pytest.mark.parametrize("seed", range(4))
def test_parts_are_scipys_connected_components_label_for_label(seed):
    """The compiled union-find (`_mesh.part_labels`) against scipy's weak components of the same graph: the
    same count and the same labels (numbered by each part's lowest vertex), with isolated vertices and
    ``extra`` pairs joining parts."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(seed)
    n = 400
    F = rng.integers(0, n - 40, size=(150, 3))  # the last 40 vertices in no face: parts of their own
    extra = rng.integers(0, n, size=(5 * seed, 2))
    a = np.concatenate([F[:, :2].reshape(-1), extra[:, 0]])
    b = np.concatenate([F[:, 1:].reshape(-1), extra[:, 1]])
    want = connected_components(csr_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n)), directed=True,
                                connection="weak")
    count, label = topo.parts(F, n, extra)
    assert count == want[0] and count > 40
    np.testing.assert_array_equal(label, want[1])
    assert label.dtype == np.int64


def test_feature_edges_with_faces_is_isin_both_ways():
    """The half-edges on feature edges and the check that every feature edge is a mesh edge, against
    `np.isin` both ways, on random faces (repeated corners, duplicate and non-edge feature pairs)."""
    from qemjax._mesh.topology import edge_keys, feature_edges_with_faces, half_edges

    rng = np.random.default_rng(1)
    for t in range(300):
        n, m = int(rng.integers(3, 60)), int(rng.integers(1, 120))
        F = rng.integers(0, n, (m, 3))
        he = half_edges(F)
        feat = he[rng.choice(len(he), rng.integers(0, min(10, len(he)) + 1))]
        if t % 2:
            feat = np.concatenate([feat, feat[:1], rng.integers(0, n, (2, 2))])
        keys, fk = edge_keys(he[:, 0], he[:, 1], n), edge_keys(feat[:, 0], feat[:, 1], n)
        missing = ~np.isin(fk, keys)
        if missing.any():
            with pytest.raises(ValueError, match=f"contains {int(missing.sum())} pairs"):
                feature_edges_with_faces(F, n, feat)
            continue
        e, f = feature_edges_with_faces(F, n, feat)
        idx = np.flatnonzero(np.isin(keys, fk))
        assert np.array_equal(e, he[idx]) and np.array_equal(f, idx // 3)


def _edge_table_numpy(F, n):
    """`topology.edge_table` as numpy computed it (half-edges, packed keys, one sort)."""
    he = topo.half_edges(F)
    keys = topo.edge_keys(he[:, 0], he[:, 1], n)
    bits = int(len(keys)).bit_length()
    packed = np.sort((keys << bits) | np.arange(len(keys), dtype=np.int64))
    ks, order = packed >> bits, packed & ((1 << bits) - 1)
    start, counts = topo._runs(ks)
    single = order[start[counts == 1]]
    return topo.key_pairs(ks[start], n, F.dtype), counts, he[single], single // 3


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_edge_table_is_numpys(dtype):
    """The compiled `edge_table` against numpy's: edges, counts, boundary half-edges and their faces, values
    and dtypes, on closed and open meshes, edges with three faces, repeated faces, no faces, a fan whose
    apex has more edges than `edge_lists.sorted_keys` sorts by insertion (and its faces shuffled); and the
    unpacked path (keys too large to pack the index) gives the same tables."""
    rng = np.random.default_rng(7)
    fan = np.array([[0, i, i + 1] for i in range(1, 120)] + [[5, 1, 7]])
    meshes = [shapes.bumpy_sphere(2)[1], shapes.grid(9, hole=True)[1], np.zeros((0, 3), np.int64),
              rng.integers(0, 30, size=(200, 3)),  # random triangles: edges with many faces, repeats
              fan, rng.permutation(fan)[:, ::-1]]
    for F in meshes:
        F = F.astype(dtype)
        n = int(F.max()) + 1 if len(F) else 5  # (no faces, five vertices: the compiled path too)
        want = _edge_table_numpy(F, n)
        got = topo.edge_table(F, n)
        unpacked = topo._edge_table_unpacked(F, n)
        for w, g, u in zip(want, got, unpacked):
            assert np.array_equal(g, w) and g.dtype == w.dtype and g.shape == w.shape
            assert np.array_equal(u, w) and u.dtype == w.dtype


def test_seam_count_is_scipys_component_count():
    """`wedges.seam_count` (compiled union-find) against scipy's connected components of the seam graph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from qemjax._mesh.wedges import seam_count

    rng = np.random.default_rng(11)
    assert seam_count(np.zeros((0, 2), np.int64)) == 0
    for k in (1, 5, 40, 300):
        E = rng.integers(0, 10 ** 6, size=(k, 2)) // rng.integers(1, 5000)  # sparse ids, shared endpoints
        ids, inv = np.unique(E, return_inverse=True)
        inv = inv.reshape(-1, 2)
        g = coo_matrix((np.ones(k), (inv[:, 0], inv[:, 1])), shape=(len(ids), len(ids)))
        assert seam_count(E) == connected_components(g, directed=False)[0]


def _around_numpy(lists, verts):
    """`FaceLists.around` as numpy expressions (the reference of the compiled loop)."""
    lens = lists.cnt.take(verts)
    which = np.repeat(np.arange(len(verts)), lens)
    pos = np.arange(len(which), dtype=np.int64)
    pos += np.repeat(lists.off.take(verts) - (np.cumsum(lens) - lens), lens)
    f = lists.pool.take(pos)
    live = lists.alive.take(f)
    return which.compress(live), f.compress(live)


def _touched_numpy(lists, pairs):
    """`FaceLists.touched_with_dead` as numpy expressions (the reference of the compiled loop)."""
    ends = pairs.reshape(-1)
    w, f = _around_numpy(lists, ends)
    G = lists.F.take(f, axis=0)
    other = ends.take(w ^ 1)
    keep = (G[:, 0] != other) & (G[:, 1] != other) & (G[:, 2] != other)
    dies = ~keep & (w & 1).astype(bool)
    dead = (f.compress(dies), w.compress(dies) >> 1)
    w, f, G = w.compress(keep), f.compress(keep), G.compress(keep, axis=0)
    me = ends.take(w)
    corner = np.where(G[:, 0] == me, 0, np.where(G[:, 1] == me, 1, 2))
    owner = w >> 1
    after = G.copy()
    after[np.arange(len(G)), corner] = ends.take(2 * owner)
    return (f, G, corner, owner, after), (w, f, corner), dead


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_face_look_ups_are_numpys(seed, dtype):
    """`FaceLists.around` and `touched_with_dead` (compiled loops) give the numpy expressions' arrays, order
    and dtypes included, on a mesh whose lists went through contractions (dead faces still listed, runs
    moved to the pool's end), for vertex lists with repeats and for vertex-disjoint pairs."""
    rng = np.random.default_rng(seed)
    mesh = shapes.bumpy_sphere(3)
    F = np.asarray(mesh.faces, np.int64)
    n = len(mesh.vertices)
    lists = FaceLists(F, n)
    E, ecount = topo.edges(F, n)
    for _ in range(3):
        P, _, _ = _independent_pairs(E, ecount, n, F)
        P = P.astype(dtype)
        verts = rng.integers(0, n, 200).astype(dtype)
        for got, want in zip(lists.around(verts), _around_numpy(lists, verts)):
            assert got.dtype == want.dtype and np.array_equal(got, want)
        got, want = lists.touched_with_dead(P), _touched_numpy(lists, P)
        for g, w in zip([*got[0], *got[1], *got[2]], [*want[0], *want[1], *want[2]]):
            assert g.dtype == w.dtype and g.shape == w.shape and np.array_equal(g, w)
        assert len(got[2][0]) > 0 and len(got[0][0]) > 0
        dead = lists.contract(P[:, 0], P[:, 1])
        rep = np.arange(n)
        rep[P[:, 1]] = P[:, 0]
        Fr = rep[F]
        F = Fr[(Fr[:, 0] != Fr[:, 1]) & (Fr[:, 1] != Fr[:, 2]) & (Fr[:, 0] != Fr[:, 2])]
        assert len(dead) > 0 and np.array_equal(lists.live(), F)
        E, ecount = topo.edges(F, n)


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_compiled_degrees_endpoints_and_first_steps_are_numpys(dtype):
    """`edge_lists.degrees` / `endpoints` and `face_passes.first_step` against the numpy expressions they
    replaced (bincount, a scatter of the masked rows, the row-wise minimum of gathered steps)."""
    from qemjax._mesh.edge_lists import degrees, endpoints
    from qemjax._mesh.face_passes import first_step

    rng = np.random.default_rng(5)
    n = 300
    E = rng.integers(0, n, (2000, 2)).astype(dtype)
    E[:5] = [0, 0]  # a row repeating its vertex counts it twice, as bincount does
    got = degrees(E, n)
    assert got.dtype == np.int64 and np.array_equal(got, np.bincount(E.reshape(-1), minlength=n))
    assert np.array_equal(degrees(E[:0], n), np.zeros(n, np.int64))
    for p in (0.0, 0.3, 1.0):
        mask = rng.random(len(E)) < p
        want = np.zeros(n, bool)
        want[E[mask].reshape(-1)] = True
        assert np.array_equal(endpoints(E, mask, n), want)
    F = rng.integers(0, n, (500, 3)).astype(dtype)
    step_of = np.full(n, np.iinfo(np.int64).max)
    step_of[rng.choice(n, 100, replace=False)] = rng.permutation(100)
    faces = rng.choice(500, 200, replace=False).astype(dtype)
    want = np.full(500, -1, np.int64)
    want[faces] = step_of[F[faces]].min(1)
    got = np.full(500, -1, np.int64)
    first_step(F, step_of, faces, got)
    assert np.array_equal(got, want)


def test_repeated_rows_are_numpys_isin_of_the_sorted_repeats():
    """`face_passes.repeated` (a hash table) against the sort it replaced in `topology.coincidence_count`:
    values held twice and more, zero among them, none repeated, one row, no rows; and a table crowded with
    values that fall into one slot."""
    from qemjax._mesh.face_passes import repeated

    rng = np.random.default_rng(5)
    cases = [np.zeros(0, np.uint64), np.array([7], np.uint64), np.zeros(5, np.uint64),
             np.arange(1000, dtype=np.uint64) << np.uint64(40)]  # every value in the same slot at first
    for n, share in ((50, 0.0), (500, 0.1), (5000, 0.5)):
        h = rng.integers(0, 2**63, n, dtype=np.uint64)
        k = int(share * n)
        h[rng.integers(0, n, k)] = h[rng.integers(0, n, k)]
        h[:3] = 0
        cases.append(h)
    cases.append(np.concatenate([cases[-4], cases[-4]]))
    for h in cases:
        hs = np.sort(h)
        want = np.flatnonzero(np.isin(h, hs[1:][hs[1:] == hs[:-1]]))
        got = repeated(h)
        assert np.array_equal(got, want) and got.dtype == np.int64


def test_rows_by_key_are_a_stable_argsort():
    """`counting.counting_order` (the moves' samples by face, a partition's rows by file) against numpy's
    stable argsort and a search of its runs: keys with repeats, keys no row holds (at the start, inside, at
    the end), one key, no rows, keys out of range (a sample no face was found for: -1) placed as the argsort
    places them."""
    from qemjax._mesh.counting import counting_order

    rng = np.random.default_rng(3)
    for q, n, wild in ((1000, 40, False), (5000, 5000, False), (7, 1, False), (0, 3, False), (1000, 40, True)):
        keys = rng.integers(0, n, q) if n > 1 else np.zeros(q, np.int64)
        keys[(keys == 0) | (keys == n // 2) | (keys == n - 1)] = min(1, n - 1)  # keys with no rows
        if wild:
            keys[rng.random(q) < 0.1] = -1
            keys[rng.random(q) < 0.05] = n + 3
        order, start = counting_order(keys, n)
        want = np.argsort(keys, kind="stable")
        assert np.array_equal(order, want) and order.dtype == np.int64
        assert np.array_equal(start, np.searchsorted(keys[want], np.arange(n + 1))) and start.dtype == np.int64
