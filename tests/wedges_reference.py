"""The seam rule and wedge updates as they were written in Python before they were compiled
(`qemjax._mesh.seam_rule`), kept as the reference the compiled kernels are tested against
(tests/test_seam_rule.py): `ReferenceTracker` is the former `wedges.Tracker`, per pair in numpy."""
from __future__ import annotations

import numpy as np

from qemjax._mesh import fixed_order


class ReferenceTracker:
    """The wedges during a run: C (m,3) wedge per corner of each face row, V (w,k) wedge values.

    `constrain` prices pairs touching seams at their allowed endpoint, `allowed` is the validity rule and
    `contract` updates the corners (and, between single-wedge vertices, the kept wedge's value)."""

    def __init__(self, corners: np.ndarray, values: np.ndarray, n: int, F: np.ndarray, model=None,
                 solved=None, frozen=None):
        self.C = np.array(corners, np.int64)
        self.val = np.array(values, np.float64)
        self.frozen = np.zeros(n, bool) if frozen is None else np.asarray(frozen, bool)  # locked: values kept
        # the model's cost at a point (attribute quadrics: `_costs.attributes`), and its optimal attributes
        # for the channels marked in ``solved`` (the rest are interpolated)
        self.cost_at = getattr(model, "cost_at", None)
        self.attributes_at = getattr(model, "attributes_at", None) if solved is not None else None
        self.attributes_at_many = getattr(model, "attributes_at_many", None) if solved is not None else None
        self.solved = solved
        # seam candidates: vertices with two or more wedges (a flag that may stay set after faces die,
        # which only sends a pair through the exact per-pair test)
        used = np.unique(self.C)  # each wedge belongs to one vertex: count the wedges in use per vertex
        vertex_of = np.zeros(len(self.val), np.int64)
        vertex_of[self.C.reshape(-1)] = np.asarray(F).reshape(-1)
        self.multi = np.bincount(vertex_of[used], minlength=n) > 1
        self.seam_in = int(np.count_nonzero(self.multi))  # vertices on a seam in the input

    # -- per pair -------------------------------------------------------------------------------------
    def _corners(self, faces, v):
        f = faces.around(np.array([v]))[1]
        G = np.take(faces.F, f, axis=0)
        k = np.argmax(G == v, axis=1)
        return f, G, k, self.C[f, k]

    def modes(self, faces, a: int, b: int):
        """(free, map b->a or None, map a->b or None): free when both have one wedge; a map when keeping
        that endpoint is allowed (every wedge of the other maps one to one through the shared faces)."""
        fa, Ga, ka, wa = self._corners(faces, a)
        fb, Gb, kb, wb = self._corners(faces, b)
        ua, ub = np.unique(wa), np.unique(wb)
        self.multi[a], self.multi[b] = len(ua) > 1, len(ub) > 1  # exact now (the flag only narrows)
        if len(ua) == 1 and len(ub) == 1:
            return True, {int(ub[0]): int(ua[0])}, {int(ua[0]): int(ub[0])}
        shared = np.any(Ga == b, axis=1)
        sa = wa[shared]
        sb = self.C[fa[shared], np.argmax(Ga[shared] == b, axis=1)]
        return False, _one_to_one(sb, sa, ub), _one_to_one(sa, sb, ua)

    def allowed(self, faces, VQ, a: int, b: int, x) -> bool:
        """The validity rule for contracting b into a at x (module docstring)."""
        if not (self.multi[a] or self.multi[b]):
            return True
        free, ba, ab = self.modes(faces, a, b)
        if free:
            return True
        x = np.asarray(x, VQ.dtype)
        return bool((ba is not None and np.array_equal(x, VQ[a, :3]))
                    or (ab is not None and np.array_equal(x, VQ[b, :3])))

    def constrain(self, faces, VQ, P: np.ndarray, x: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """For pairs P (K,2) touching a seam vertex: x and cost (updated in place) at the allowed endpoint
        with the smaller quadric error. Returns (K,) bool: pairs with no allowed placement."""
        bad = np.zeros(len(P), bool)
        for i in np.flatnonzero(self.multi[P[:, 0]] | self.multi[P[:, 1]]):
            a, b = int(P[i, 0]), int(P[i, 1])
            free, ba, ab = self.modes(faces, a, b)
            if free:
                continue
            best = None
            for ok, v in ((ba, a), (ab, b)):
                if ok is not None:
                    c = (self.cost_at(VQ[a], VQ[b], VQ[v, :3]) if self.cost_at is not None
                         else _quadric(VQ[a], VQ[v, :3]) + _quadric(VQ[b], VQ[v, :3]))
                    if best is None or c < best[0]:
                        best = (c, v)
            if best is None:
                bad[i] = True
                continue
            x[i] = VQ[best[1], :3]
            cost[i] = max(best[0], 0.0)
        return bad

    def contract(self, faces, VQ, a: int, b: int, x) -> None:
        """Update the corners for contracting b into a at x (before the faces are relinked)."""
        fb, Gb, kb, wb = self._corners(faces, b)
        shared = np.flatnonzero(np.any(Gb == a, axis=1))
        if not (self.multi[a] or self.multi[b]) and shared.size:  # single wedges: a's from a shared face
            free, wa, wbv = True, int(self.C[fb[shared[0]], np.argmax(Gb[shared[0]] == a)]), int(wb[0])
        else:
            free, ba, ab = self.modes(faces, a, b)
            if free:
                wa, wbv = next(iter(ab.items()))
        if free:
            pa, pb = VQ[a, :3].astype(np.float64), VQ[b, :3].astype(np.float64)
            d = pb - pa
            t = float(np.clip(fixed_order.dot(np.asarray(x, np.float64) - pa, d) / max(fixed_order.dot(d, d), 1e-300),
                              0, 1))
            val = (1 - t) * self.val[wa] + t * self.val[wbv]
            if self.attributes_at is not None:  # the attribute quadric's optimum at x
                val = np.where(self.solved, self.attributes_at(VQ[a], VQ[b], x), val)
            if not self.frozen[a]:
                self.val[wa] = val
            self.C[fb, kb] = wa
            return
        x = np.asarray(x, VQ.dtype)
        if ba is not None and np.array_equal(x, VQ[a, :3]):
            self.C[fb, kb] = [ba[int(w)] for w in wb]
        elif ab is not None and np.array_equal(x, VQ[b, :3]):
            fa, Ga, ka, wa = self._corners(faces, a)
            self.C[fa, ka] = [ab[int(w)] for w in wa]
        else:
            raise AssertionError(f"seam rule broken for pair ({a}, {b})")
        self.multi[a] = True  # conservative: the exact test decides

    def contract_many(self, faces, VQ, P, X) -> None:
        """`contract` for vertex-disjoint pairs P (K,2) at X (K,3) (a round's: 1-rings apart). Pairs of
        single-wedge vertices (most of them: every pair away from seams) are done together in numpy
        (`_contract_free`); the others one by one."""
        P, X = np.asarray(P), np.asarray(X)
        if len(P) == 0:
            return
        free = ~(self.multi[P[:, 0]] | self.multi[P[:, 1]])
        free[free] = self._contract_free(faces, VQ, P[free], X[free])
        for (a, b), x in zip(P[~free].tolist(), X[~free]):
            self.contract(faces, VQ, a, b, x)

    def _contract_free(self, faces, VQ, P, X) -> np.ndarray:
        """`contract` for pairs P (K,2) of single-wedge vertices, 1-rings apart, at X (K,3): a's wedge
        takes the value interpolated at the placement's projection on the segment (or the attribute
        quadric's optimum for solved channels) and every corner of b names it. Returns (K,) bool: the
        pairs done here (a pair with no live face at a or b is left to `contract`)."""
        a, b = P[:, 0].astype(np.int64), P[:, 1].astype(np.int64)
        which_a, fa = faces.around(a)
        which_b, fb = faces.around(b)
        has_a = np.bincount(which_a, minlength=len(P)) > 0
        has_b = np.bincount(which_b, minlength=len(P)) > 0
        done = has_a & has_b
        first_a = np.searchsorted(which_a, np.arange(len(P)))  # each pair's first face at a
        first_b = np.searchsorted(which_b, np.arange(len(P)))
        ka = np.argmax(np.take(faces.F, fa, axis=0) == a[which_a, None], axis=1)
        kb = np.argmax(np.take(faces.F, fb, axis=0) == b[which_b, None], axis=1)
        wa_all, wb_all = self.C[fa, ka], self.C[fb, kb]
        idx = np.flatnonzero(done)
        wa, wbv = wa_all[first_a[idx]], wb_all[first_b[idx]]
        pa, pb = VQ[a[idx], :3].astype(np.float64), VQ[b[idx], :3].astype(np.float64)
        x = X[idx].astype(np.float64)
        d, u = pb - pa, x - pa
        dd = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        ud = u[:, 0] * d[:, 0] + u[:, 1] * d[:, 1] + u[:, 2] * d[:, 2]
        t = np.clip(ud / np.maximum(dd, 1e-300), 0, 1)[:, None]
        val = (1 - t) * self.val[wa] + t * self.val[wbv]
        if self.attributes_at is not None and len(idx):  # the attribute quadric's optimum at x
            many = getattr(self, "attributes_at_many", None)
            opt = (many(VQ[a[idx]], VQ[b[idx]], x) if many is not None else
                   np.stack([self.attributes_at(VQ[i], VQ[j], y) for i, j, y in zip(a[idx], b[idx], x)]))
            val = np.where(self.solved, opt, val)
        thaw = ~self.frozen[a[idx]]
        self.val[wa[thaw]] = val[thaw]
        sel = done[which_b]  # b's corners of the pairs done here now name a's wedge
        self.C[fb[sel], kb[sel]] = np.repeat(wa, np.bincount(which_b[sel], minlength=len(P))[idx])
        return done


def _one_to_one(src: np.ndarray, dst: np.ndarray, need: np.ndarray):
    """{src wedge: dst wedge} from corresponding corner wedges when it is a function, one to one, and
    covers every wedge in ``need``; else None."""
    m = {}
    for s, d in zip(src.tolist(), dst.tolist()):
        if m.setdefault(s, d) != d:
            return None
    if len(set(m.values())) != len(m) or any(int(w) not in m for w in need):
        return None
    return m


def _quadric(row: np.ndarray, x: np.ndarray) -> float:
    """Q(x) of a vertex row [position, quadric (10) in the vertex's frame, …] in float64."""
    a0, a1, a2, a3, a4, a5, b0, b1, b2, c = row[3:13].astype(np.float64).tolist()
    u0, u1, u2 = (np.asarray(x, np.float64) - row[:3].astype(np.float64)).tolist()
    # uᵀAu + 2 b·u + c in Python floats, in a fixed order (not BLAS: its bits vary by CPU)
    au = (a0 * u0 + a1 * u1 + a2 * u2, a1 * u0 + a3 * u1 + a4 * u2, a2 * u0 + a4 * u1 + a5 * u2)
    return (u0 * au[0] + u1 * au[1] + u2 * au[2]) + 2 * (b0 * u0 + b1 * u1 + b2 * u2) + c
