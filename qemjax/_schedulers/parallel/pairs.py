"""The pairs and faces around a round's contractions, on the host: the candidate pairs with non-edge ones, the
1-rings a round touched, coincident faces resolved, what validation found renumbered for the contraction,
and the edge update split between two threads."""
from __future__ import annotations

import numpy as np

from ..._mesh import topology as topo
from ..._mesh.arrays import keep_rows as _keep, take_rows as _take
from ..._mesh.incidence import FaceLists
from . import contraction
from ..select import submit


def with_extra_pairs(E, ecount, extra_pairs, n):
    """Candidate pairs = mesh edges ∪ extra (non-edge) pairs, sorted by key; non-edges count 0 faces."""
    if len(extra_pairs) == 0:
        return E, ecount
    xk = np.unique(topo.edge_keys(extra_pairs[:, 0], extra_pairs[:, 1], n))
    ek = topo.edge_keys(E[:, 0], E[:, 1], n)
    xk = xk[~np.isin(xk, ek)]
    keys = np.concatenate([ek, xk])
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    E = topo.key_pairs(keys, n, E.dtype)
    return E, np.concatenate([ecount, np.zeros(len(xk), np.int64)])[order]


def accepted(E, found, take):
    """The pairs marked in ``take`` (len(E),) bool with what validation found for them (``found``: pair
    indices, kept faces, dead faces and, in manifold mode, the apexes per pass; `FaceLists.touched_with_dead`,
    `topo.link_ok`), renumbered as one set in pass order: pairs (S,2), the arguments ``kept`` and ``dead``
    of `FaceLists.contract_touched`, and the apexes (S,2) (None outside manifold mode).

    A kept face's position w counts endpoints (2·pair + side, side 1 at b), as `FaceLists` numbers them."""
    pairs, ws, fs, cs, ds, xs = [], [], [], [], [], []
    off = 0
    for idx, (w, f, c), (df, downer), apex in found:
        t = take[idx]
        pos = np.cumsum(t) - 1 + off  # each taken pair's place in the combined set
        pair_of, side = w >> 1, w & 1
        keep = t.take(pair_of)
        ws.append(2 * pos.take(pair_of.compress(keep)) + side.compress(keep))
        fs.append(f.compress(keep))
        cs.append(c.compress(keep))
        ds.append(df.compress(t.take(downer)))
        pairs.append(_take(E, idx.compress(t)))
        if apex is not None:
            xs.append(_keep(apex, t))
        off += int(t.sum())
    cat = np.concatenate
    return cat(pairs), (cat(ws), cat(fs), cat(cs)), cat(ds), cat(xs) if xs else None


def ring_vertices(faces: FaceLists, verts, n):
    """(n,) bool: ``verts`` and every vertex sharing a live face with one."""
    t = np.zeros(n, bool)
    t[verts] = True
    t[_take(faces.F, faces.around(verts)[1]).reshape(-1)] = True
    return t


def touched(faces: FaceLists, n: int, locked, acc, n_sel, E):
    """(n,) bool: the vertices around a round's contractions (rows ``acc`` of its pairs E, ``n_sel`` of them
    selected): the 1-rings that selection locked, unless the target cut the set short (then the rings of
    what contracted)."""
    return locked if acc.size == n_sel else ring_vertices(faces, _take(E, acc).reshape(-1), n)


def drop_coincident(faces: FaceLists, kept):
    """Resolve faces that coincide after contractions into the vertices ``kept`` (all such faces touch
    one), lower face index first (`topo.coincident_removals`). Returns the faces removed."""
    f = np.unique(faces.around(kept)[1])
    drop = f[topo.coincident_removals(_take(faces.F, f))]
    faces.remove(drop)
    return drop


class EdgeUpdate:
    """`contraction.contract_edges` with its two passes over every pair (listing the rows at an endpoint,
    copying the rows that stay) each split between the worker thread and the calling one: the first half's
    listing starts on the worker when the update is made, the rest runs when its `result` is asked for.
    The threads write disjoint parts of the arrays; the steps and the result are `contract_edges`'
    (tests/test_round_loops.py compares them). Before, the calling thread waited for the whole update on the
    worker once its own face update was done."""

    def __init__(self, E, ecount, deg, a, b, apex, label):
        self.args = (E, ecount, deg, a, b, apex, label)
        P = len(E)
        self.h = h = P // 2
        contraction.label_pairs(a, b, label)
        self.lists = contraction.listing(E, ecount, P)
        self.first = submit(contraction.list_rows, E, ecount, label, 0, h, *(x[:h] for x in self.lists), size=h)

    def result(self):
        """(E', ecount', keep, degree', stale'), as `contraction.contract_edges` returns them."""
        E, ecount, deg, a, b, apex, label = self.args
        P, h = len(E), self.h
        n_hi = contraction.list_rows(E, ecount, label, h, P, *(x[h:] for x in self.lists))
        n_lo = self.first.result()
        listed = []
        for x in self.lists:  # the upper half's listed rows moved down after the lower half's
            x[n_lo:n_lo + n_hi] = x[h:h + n_hi]
            listed.append(x[: n_lo + n_hi])
        rows, lab, far, nu, nv, cnt = listed
        keep, d2, m = contraction.listed_rows(E, deg, a, b, apex, label, rows, lab, far, nu, nv, cnt)
        E3, c3 = np.empty((m, 2), E.dtype), np.empty(m, ecount.dtype)
        k0 = h - int(np.count_nonzero(~keep.take(rows[:n_lo])))  # the rows kept before h
        lower = submit(contraction.copy_rows, E, ecount, keep, 0, h, E3, c3, 0, size=h)
        contraction.copy_rows(E, ecount, keep, h, P, E3, c3, k0)
        lower.result()
        return E3, c3, keep, d2, contraction.rewrite_rows(rows, keep, nu, nv, cnt, E3, c3)
