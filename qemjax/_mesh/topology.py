"""Mesh connectivity on the host (numpy): edges, boundaries, and the manifold (link) tests.

Sorting is done with numpy's vectorised sort on packed int64 keys: on the CPU it is an order of magnitude
faster than sorting inside XLA, and much faster than ``np.unique``.
"""
from __future__ import annotations

import numpy as np

from .arrays import box_diagonal, sorted_triples


def half_edges(F: np.ndarray) -> np.ndarray:
    """(3m,2) directed edges of faces (m,3), in face order: (f0,f1), (f1,f2), (f2,f0) for each face."""
    return np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)


def edge_keys(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """Undirected int64 key min·n + max of vertex pairs."""
    a = a.astype(np.int64)
    b = b.astype(np.int64)
    return np.minimum(a, b) * n + np.maximum(a, b)


def key_pairs(keys: np.ndarray, n: int, dtype) -> np.ndarray:
    """(k,2) vertex pairs (min, max) of `edge_keys` values, as ``dtype``."""
    return np.stack([keys // n, keys % n], 1).astype(dtype)


def _runs(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start index and length of each run of equal values in the sorted array s."""
    start = np.flatnonzero(np.concatenate([[s.size > 0], s[1:] != s[:-1]]))
    return start, np.diff(np.append(start, s.size))


def unique_counts(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique values of an int64 array and their multiplicities."""
    s = np.sort(keys)
    start, counts = _runs(s)
    return s[start], counts


def edges(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges (E,2) with u < v (F's integer dtype), sorted, and how many faces contain
    each (E,) int64."""
    he = half_edges(F)
    keys, counts = unique_counts(edge_keys(he[:, 0], he[:, 1], n))
    return key_pairs(keys, n, F.dtype), counts


MAX_PAIRS_PER_VERTEX = 50  # pair_threshold may add at most this many close pairs per vertex


def contraction_roots(pairs: np.ndarray, n: int) -> np.ndarray:
    """(n,) int64: each vertex's representative after contracting pairs (k,2) (kept, removed) in order
    (itself when it survives). Each vertex is removed at most once, into a vertex alive then: the removed ->
    kept links form a forest, resolved by pointer jumping (log of the longest chain passes)."""
    root = np.arange(n, dtype=np.int64)
    root[pairs[:, 1]] = pairs[:, 0]
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


def close_pairs(V: np.ndarray, F: np.ndarray, t: float) -> np.ndarray:
    """Non-edge vertex pairs (k,2) int64 at distance <= t (mesh units), found with scipy's KD-tree.

    Raises ValueError when there would be more than MAX_PAIRS_PER_VERTEX per vertex on average (the
    pair count grows with t³; such a t almost always means a unit mix-up).
    """
    if t <= 0:
        return np.zeros((0, 2), np.int64)
    from scipy.spatial import cKDTree

    tree = cKDTree(V)
    limit = MAX_PAIRS_PER_VERTEX * len(V)
    # count first (cheap), so an absurd t fails fast instead of exhausting memory
    n_close = (tree.count_neighbors(tree, t) - len(V)) // 2
    if n_close > limit:
        raise ValueError(f"pair_threshold={t} would make {n_close} vertex pairs (over {limit}, "
                         f"{MAX_PAIRS_PER_VERTEX} per vertex); the mesh's bounding-box diagonal is "
                         f"{box_diagonal(V.min(0), V.max(0)):.4g}: choose a smaller threshold")
    P = np.sort(tree.query_pairs(t, output_type="ndarray").astype(np.int64), axis=1)
    n = len(V)
    E, _ = edges(F, n)
    P = P[~np.isin(edge_keys(P[:, 0], P[:, 1], n), edge_keys(E[:, 0], E[:, 1], n))]
    return P[np.lexsort((P[:, 1], P[:, 0]))]


def parts(F: np.ndarray, n: int, extra: np.ndarray | None = None) -> tuple[int, np.ndarray]:
    """Connected parts of the graph of the faces' edges (and the ``extra`` pairs (k,2), which join parts
    that may merge): (count, (n,) int64 label of each vertex; a vertex in no face is a part of its own)."""
    from .part_labels import labels  # numba: imported when first used

    a = [F[:, :2].reshape(-1)] + ([] if extra is None or not len(extra) else [extra[:, 0]])
    b = [F[:, 1:].reshape(-1)] + ([] if extra is None or not len(extra) else [extra[:, 1]])
    count, label = labels(np.concatenate(a).astype(np.int64), np.concatenate(b).astype(np.int64), int(n))
    return int(count), label


def edge_table(F: np.ndarray, n: int):
    """`edges` and `boundary_edges` from one sort: (E (k,2) u < v sorted, face counts (k,), boundary
    edges (B,2) as directed in their face, their face indices (B,))."""
    bits = int(3 * len(F)).bit_length()
    if n > 0 and (n * n) < (1 << (63 - bits)):  # the half-edge index packed under the key: one array of keys
        from . import edge_lists  # numba: imported when first used

        F = np.ascontiguousarray(F)
        return edge_lists.tables(edge_lists.sorted_keys(F, n, bits), F, n, bits)
    return _edge_table_unpacked(F, n)


def _edge_table_unpacked(F: np.ndarray, n: int):
    """`edge_table` where the keys leave no room to pack the half-edge index (n² ≥ 2^(63 - bits)): a stable
    argsort."""
    he = half_edges(F)
    keys = edge_keys(he[:, 0], he[:, 1], n)
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    start, counts = _runs(ks)
    single = order[start[counts == 1]]
    return key_pairs(ks[start], n, F.dtype), counts, he[single], single // 3


def boundary_edges(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Edges used by exactly one face: (B,2) int64 as directed in that face, and the face index (B,)."""
    return edge_table(F, n)[2:]


def feature_edges_with_faces(F: np.ndarray, n: int, feat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For feature edges feat (k,2), every (edge, face) incidence: edges (j,2) directed as in the face,
    face indices (j,). Feature edges not in the mesh raise ValueError."""
    he = half_edges(F)
    keys = edge_keys(he[:, 0], he[:, 1], n)
    fk = edge_keys(feat[:, 0], feat[:, 1], n)
    # np.isin both ways, by one binary search of the half-edges among the (few) distinct feature keys
    fs = np.unique(fk)
    hit = np.zeros(len(keys), bool)
    found = np.zeros(len(fs), bool)
    if len(fs):
        at = np.minimum(np.searchsorted(fs, keys), len(fs) - 1)
        hit = fs[at] == keys
        found[at[hit]] = True
    missing = ~found[np.searchsorted(fs, fk)] if len(fk) else np.zeros(0, bool)
    if missing.any():
        raise ValueError(f"feature_edges contains {int(missing.sum())} pairs that are not mesh edges, "
                         f"first: {feat[np.flatnonzero(missing)[0]].tolist()}")
    idx = np.flatnonzero(hit)
    return he[idx], idx // 3


def vertex_degree(E: np.ndarray, n: int) -> np.ndarray:
    """Number of edges at each vertex (n,) int64 (one compiled pass: `edge_lists.degrees`)."""
    from .edge_lists import degrees  # numba: imported when first used

    return degrees(np.asarray(E), n)


def link_ok(pairs: np.ndarray, nfaces: np.ndarray, E: np.ndarray, n: int,
            boundary_vertex: np.ndarray, degree: np.ndarray, apexes: bool = False, edges_at: bool = False):
    """Manifold-preserving test for edge contractions; vectorised over pairs.

    ``pairs`` (S,2) must be vertex-disjoint edges with ``nfaces`` (S,) faces each; E (k,2) must include
    every edge at their endpoints (it may hold others). A pair passes when it is a manifold edge (1 or 2
    faces), its endpoints' common neighbours are exactly the apexes of its faces (the link condition),
    the contraction does not pinch two boundaries together through an interior edge, and no apex of an
    interior edge has degree 3 (which would leave two coincident faces, as in a tetrahedron).
    Returns (S,) bool; with ``apexes`` also (S,2) int64: the first two common neighbours of each pair
    (-1 where there are fewer), which for a passing pair are exactly the apexes of its faces; with
    ``edges_at`` also the rows of E at an endpoint (k,) and the pair of each (k,) (what an edge update reads).
    """
    S = len(pairs)
    if S == 0:
        out = (np.zeros(0, bool),) + ((np.zeros((0, 2), np.int64),) if apexes else ()) + \
            ((np.zeros(0, np.int64), np.zeros(0, np.int64)) if edges_at else ())
        return out if len(out) > 1 else out[0]
    a, b = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    lab = np.full(n, -1, np.int32)  # 2·pair + side (0 at a, 1 at b)
    lab[a] = 2 * np.arange(S, dtype=np.int32)
    lab[b] = lab[a] + 1
    # (pair, neighbour, side) for every edge leaving a labelled vertex; the pair's own edge (a, b) is
    # seen from one side only, which cannot make a common neighbour
    rows, L, c_, _ = _labelled_rows(lab, E)
    L = L.astype(np.int64)
    key = np.sort(((L >> 1) * n + c_) * 2 + (L & 1))
    base = key >> 1  # key // 2 (keys are non-negative)
    both = base[1:] == base[:-1]  # a neighbour seen from side 0 and side 1
    common_pair, common_v = np.divmod(base[1:].compress(both), n)
    ncommon = np.bincount(common_pair, minlength=S)

    ok = (nfaces >= 1) & (nfaces <= 2) & (ncommon == nfaces)
    ok &= ~(boundary_vertex[a] & boundary_vertex[b] & (nfaces == 2))
    interior = nfaces[common_pair] == 2
    bad_apex = interior & (degree[common_v] <= 3)
    ok &= np.bincount(common_pair[bad_apex], minlength=S) == 0
    out = (ok,)
    if apexes:
        apex = np.full((S, 2), -1, np.int64)
        rank = np.arange(len(common_pair)) - np.repeat(np.cumsum(ncommon) - ncommon, ncommon)  # by pair
        two = rank < 2
        apex[common_pair[two], rank[two]] = common_v[two]
        out += (apex,)
    if edges_at:
        out += (rows, L >> 1)
    return out if len(out) > 1 else out[0]


def coincident_removals(G: np.ndarray) -> np.ndarray:
    """Which faces of G (k,3) to drop so no two remaining faces share the same three vertices.

    Within a group of coincident faces, oppositely oriented faces cancel in pairs (together they bound
    nothing; this is how a part contracted to a sliver vanishes), lower face index first; of what is
    left, all of one orientation, the first face is kept. Returns (k,) bool, True = remove.
    """
    k = len(G)
    if k < 2:
        return np.zeros(k, bool)
    S = sorted_triples(G)
    # orientation: +1 when G is an even permutation of its sorted order
    inv = (G[:, 0] > G[:, 1]).astype(np.int8) + (G[:, 0] > G[:, 2]) + (G[:, 1] > G[:, 2])
    pos = inv % 2 == 0
    order = np.lexsort((np.arange(k), S[:, 2], S[:, 1], S[:, 0]))
    Ss = S[order]
    start = np.concatenate([[True], np.any(Ss[1:] != Ss[:-1], axis=1)])
    gid = np.cumsum(start) - 1
    if gid[-1] == k - 1:  # no coincident faces at all
        return np.zeros(k, bool)
    ps = pos[order]
    npos = np.bincount(gid, weights=ps, minlength=gid[-1] + 1).astype(np.int64)
    nneg = np.bincount(gid, minlength=gid[-1] + 1) - npos
    # rank of each face among the faces of its group with the same orientation (order is by index)
    sub = gid * 2 + ps
    first = np.concatenate([[True], sub[1:] != sub[:-1]])
    o2 = np.argsort(sub, kind="stable")
    sub_sorted = sub[o2]
    first2 = np.concatenate([[True], sub_sorted[1:] != sub_sorted[:-1]])
    starts = np.flatnonzero(first2)
    rank_sorted = np.arange(k) - starts[np.cumsum(first2) - 1]
    rank = np.empty(k, np.int64)
    rank[o2] = rank_sorted
    del first
    c = np.minimum(npos, nneg)[gid]
    mine = np.where(ps, npos[gid], nneg[gid])
    remove = (rank < c) | ((mine > c) & (rank > c))
    out = np.zeros(k, bool)
    out[order] = remove
    return out


def coincidence_count(G: np.ndarray, owner: np.ndarray, S: int) -> np.ndarray:
    """(S,) int: faces that the contractions would make coincide and drop (`coincident_removals`).

    G, owner: the touched faces after contraction and their pairs, from `FaceLists.touched` (every face
    that could coincide touches the pair, because pairs are two edges apart).
    """
    return np.bincount(owner[coincident_rows(G)], minlength=S)


def coincident_rows(G: np.ndarray) -> np.ndarray:
    """The rows of G (faces after a round's contractions, `coincidence_count`) that would be dropped as
    coincident (`coincident_removals`), ascending; empty in the common case."""
    # a symmetric hash, the same for any order of the corners: each corner mixed, the three summed modulo
    # 2**64 (so any order of summing gives the same bits); all corners in each array pass, in place
    g = G.astype(np.uint64)
    g *= np.uint64(0x9E3779B97F4A7C15)
    g ^= g >> np.uint64(29)
    g *= np.uint64(0xBF58476D1CE4E5B9)
    h = g[:, 0] + g[:, 1]
    h += g[:, 2]
    from .face_passes import repeated  # numba: imported when first used

    idx = repeated(h)  # the faces whose hash another face has too
    if idx.size == 0:  # the common case: no candidates at all
        return idx.astype(np.int64)
    return idx[coincident_removals(G.take(idx, axis=0))]


def _labelled_rows(label: np.ndarray, E: np.ndarray, rows: np.ndarray | None = None):
    """Edges with a labelled endpoint (int32 label >= 0, -1 elsewhere): their rows, the label of the first
    labelled endpoint, the other endpoint (int64), and which rows have both endpoints labelled. ``rows``:
    those rows when the caller knows them already (in any order), which saves the scan of E."""
    if rows is None:
        L = label.astype(np.int32, copy=False).take(E)  # one 2-D gather: faster than two column gathers
        rows = np.flatnonzero(L.view(np.int64).reshape(-1) != -1)  # an unlabelled edge is two -1s: all ones
        Lr, Er = L.take(rows, axis=0), E.take(rows, axis=0)
    else:
        Er = E.take(rows, axis=0)
        Lr = label.astype(np.int32, copy=False).take(Er)
    first = Lr[:, 0] >= 0
    lab = np.where(first, Lr[:, 0], Lr[:, 1])
    other = np.where(first, Er[:, 1], Er[:, 0]).astype(np.int64)
    return rows, lab, other, first & (Lr[:, 1] >= 0)
