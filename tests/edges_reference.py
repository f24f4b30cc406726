"""The pairs' update through a round's contractions in numpy, as it was written before it was compiled
(`qemjax._schedulers.contraction.contract_edges`), kept as the reference the compiled update is tested against
(tests/test_topology.py, tests/test_round_loops.py)."""
from __future__ import annotations

import numpy as np

from qemjax._mesh import topology as topo


def contract_edges(E: np.ndarray, ecount: np.ndarray, a: np.ndarray, b: np.ndarray, apex: np.ndarray,
                   n: int, degree: np.ndarray, rows: np.ndarray | None = None):
    """Edges after contracting vertex-disjoint manifold pairs (b into a), updated instead of rebuilt.

    E (k,2) edges (u < v) with ``ecount`` (>= 1) faces each, in any order; the pairs must be two edges
    apart and pass `topo.link_ok`, so the only edges that merge are (b,c) into (a,c) for the apexes c of each
    pair.
    ``apex`` (S,2): the apexes of each pair's faces, -1 where it has one face (from `topo.link_ok`).
    ``degree`` (n,): edges at each vertex before. ``rows``: the rows of E at any endpoint, when known
    (`topo.link_ok` finds them), which saves a scan of E.
    Returns (E', ecount', keep, degree', at_a): the edges `topo.edges` would build from the contracted faces
    (u < v, same counts) in a deterministic order that is not sorted, the mask of old edges they continue
    (E' row i continues the i-th kept row: the same edge, or (b,c) for (a,c)), the degrees after, and
    which rows of E' are at an a (len(E'),) bool: only those have a stale cost.
    """
    S = len(a)
    apex = np.asarray(apex, np.int64)
    label = np.full(n, -1, np.int32)  # s at a_s, S + s at b_s
    label[a] = np.arange(S, dtype=np.int32)
    label[b] = label[a] + S
    # the edges at any endpoint; the contracted edge (a, b) itself has both labelled
    rows, lab, other, own = topo._labelled_rows(label, E, rows)
    # edges at b: (b, apex) merge into (a, apex), the rest move to a
    ib = np.flatnonzero((lab >= S) & ~own)
    s, c = lab.take(ib) - S, other.take(ib)
    ap = apex.take(s, axis=0)
    which = np.where(c == ap[:, 0], 0, np.where(c == ap[:, 1], 1, -1))
    merge = which >= 0
    rb = rows.take(ib)
    # (a, apex) loses the vanished face and gains the other faces of (b, apex)
    delta = np.zeros((S, 2), np.int64)
    rm = rb.compress(merge)
    delta[s.compress(merge), which.compress(merge)] = ecount.take(rm) - 2
    ia = np.flatnonzero((lab < S) & ~own)
    ta, oa = lab.take(ia), other.take(ia)
    ap = apex.take(ta, axis=0)
    hit = np.where(oa == ap[:, 0], 0, np.where(oa == ap[:, 1], 1, -1))
    h = hit >= 0
    rh = rows.take(ia).compress(h)
    count_h = ecount.take(rh) + delta[ta.compress(h), hit.compress(h)]
    mv = rb.compress(~merge)
    to, c = a.take(s.compress(~merge)).astype(np.int64), c.compress(~merge)
    keep = np.ones(len(E), bool)  # every edge has faces; only (a, apex) counts change, and may reach 0
    keep[rh] = count_h > 0
    keep[rows.compress(own)] = False
    keep[rm] = False
    deg = degree.copy()  # a gains b's edges but (a, b) and one of each (a, apex), (b, apex) pair
    deg[a] += degree[b] - 2 - (apex >= 0).sum(1)
    deg[b] = 0
    np.subtract.at(deg, apex[apex >= 0], 1)
    # the rows that stay, then the few that change patched in place: no full copies of E and the counts
    # (a 5.5 M-face run's peak memory)
    idx = np.flatnonzero(keep)  # one index array serves the gathers
    E2, count = E.take(idx, axis=0), ecount.take(idx)
    at = np.searchsorted(idx, mv)  # moved rows stay
    E2[at, 0] = np.minimum(to, c)
    E2[at, 1] = np.maximum(to, c)
    kh = count_h > 0
    count[np.searchsorted(idx, rh.compress(kh))] = count_h.compress(kh)
    at_a = np.zeros(len(idx), bool)  # every edge at an a or a b; those at a b that survive move to its a
    at_a[np.searchsorted(idx, rows.compress(keep.take(rows)))] = True
    return E2, count, keep, deg, at_a
