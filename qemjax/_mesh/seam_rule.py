"""The seam rule and the wedge updates of `wedges.Tracker`, compiled (numba): one call per round's stage
(`constrain`, `refused`, `contract_many`) instead of numpy calls per pair.

The faces come as `incidence.FaceLists`' arrays (F, alive, cnt, off, pool: each vertex's faces, live or not,
in its run of the pool), the wedges as the tracker's corner array C (m,3), values val (w,k) and the
seam-candidate flags multi (n,). Rows VQ are [position, model state], float32.

Float64 arithmetic repeats the Python rule's operations in its order, so the results are the same bits
(tests/test_seam_rule.py compares them with the Python reference on random inputs): the quadric error
(`wedges._quadric`), the attribute model's host solve (`_costs.attributes.solve_host`: cost and optimal
values of the translated, summed states) and its batched twin (`optimal_attributes`), the interpolation
parameter of a contraction (`fixed_order.dot`'s left-to-right sum from 0.0 per pair, numpy's elementwise
sum for the batched pairs) and numpy's ``np.clip``/``np.sum`` conventions. numba contracts no multiply-add,
so the bits do not depend on the CPU. ``m``: the attribute model's channel count, or -1 (positions only:
the quadric error; no optimal values).

Each entry point allocates its scratch once (`scratch`: integer rows for the faces, corners and wedges at
the two endpoints and the two maps; float rows for the host solve), so the per-pair work allocates
nothing."""
from __future__ import annotations

import numpy as np

from .compiled import njit

# the count `one_to_one` gives for a map that is not one to one (keeping that endpoint is refused)
_ONE_TO_ONE_FAILS = -1


@njit(cache=True, inline="always")
def _corner_of(F, f, v):
    """The first corner of face f holding v (0 if none, as ``argmax`` gives)."""
    if F[f, 0] == v:
        return 0
    if F[f, 1] == v:
        return 1
    if F[f, 2] == v:
        return 2
    return 0


@njit(cache=True, inline="always")
def _holds(F, f, v):
    return F[f, 0] == v or F[f, 1] == v or F[f, 2] == v


# rows of the integer scratch: faces, corners and wedges at a and at b, the wedges of the faces holding
# both (a's side, b's side), the maps b -> a and a -> b (keys, values)
FA, KA, WA, FB, KB, WB, SA, SB, KBA, VBA, KAB, VAB = range(12)


@njit(cache=True)
def scratch(P, cnt, width):
    """(integer scratch (12, the longest face list at P's endpoints), float scratch (4, width))."""
    cap = 1
    for i in range(len(P)):
        for e in range(2):
            if cnt[P[i, e]] > cap:
                cap = cnt[P[i, e]]
    return np.empty((12, cap), np.int64), np.empty((4, max(width, 1)))


@njit(cache=True)
def corners(F, alive, cnt, off, pool, C, v, f, k, w):
    """The live faces at v, in list order (`FaceLists.around`), into f; v's corner in each into k, its
    wedge into w. Returns their number."""
    j = 0
    for i in range(off[v], off[v] + cnt[v]):
        fi = pool[i]
        if alive[fi]:
            c = _corner_of(F, fi, v)
            f[j] = fi
            k[j] = c
            w[j] = C[fi, c]
            j += 1
    return j


@njit(cache=True)
def distinct(w, n):
    """(how many distinct values w[:n] holds, the smallest; -1 when none)."""
    count, low = 0, -1
    for i in range(n):
        new = True
        for j in range(i):
            if w[j] == w[i]:
                new = False
                break
        if new:
            count += 1
            if low < 0 or w[i] < low:
                low = w[i]
    return count, low


@njit(cache=True)
def one_to_one(src, dst, ns, need, nn, keys, vals):
    """`wedges._one_to_one`: the map src[:ns] -> dst[:ns] into keys, vals when it is a function, one to
    one and covers every value of need[:nn]; returns its size, or -1 otherwise."""
    n = 0
    for i in range(ns):
        v = lookup(keys, vals, n, src[i])
        if v < 0:  # wedges are numbered from 0: not in the map yet
            keys[n] = src[i]
            vals[n] = dst[i]
            n += 1
        elif v != dst[i]:
            return _ONE_TO_ONE_FAILS
    for i in range(n):
        for j in range(i):
            if vals[i] == vals[j]:
                return _ONE_TO_ONE_FAILS
    for i in range(nn):
        if lookup(keys, vals, n, need[i]) < 0:
            return _ONE_TO_ONE_FAILS
    return n


@njit(cache=True)
def lookup(keys, vals, n, key):
    """The value of ``key`` in the map keys[:n] -> vals[:n], -1 when it has none."""
    for j in range(n):
        if keys[j] == key:
            return vals[j]
    return -1


@njit(cache=True)
def modes(F, alive, cnt, off, pool, C, multi, a, b, T):
    """`wedges.Tracker.modes`: (free, size of the map b -> a, of a -> b, faces at a, faces at b), the maps
    in T's rows KBA/VBA and KAB/VAB (size -1: keeping that endpoint is not allowed), the corners in
    FA..WB. Sets multi[a], multi[b] to whether each has two or more wedges now."""
    la = corners(F, alive, cnt, off, pool, C, a, T[FA], T[KA], T[WA])
    lb = corners(F, alive, cnt, off, pool, C, b, T[FB], T[KB], T[WB])
    na, ua = distinct(T[WA], la)
    nb, ub = distinct(T[WB], lb)
    multi[a], multi[b] = na > 1, nb > 1
    if na == 1 and nb == 1:
        T[KBA, 0], T[VBA, 0], T[KAB, 0], T[VAB, 0] = ub, ua, ua, ub
        return True, 1, 1, la, lb
    s = 0
    for i in range(la):
        f = T[FA, i]
        if _holds(F, f, b):
            T[SA, s] = T[WA, i]
            T[SB, s] = C[f, _corner_of(F, f, b)]
            s += 1
    nba = one_to_one(T[SB], T[SA], s, T[WB], lb, T[KBA], T[VBA])
    nab = one_to_one(T[SA], T[SB], s, T[WA], la, T[KAB], T[VAB])
    return False, nba, nab, la, lb


@njit(cache=True, inline="always")
def _max0(c):
    """Python's ``max(c, 0.0)`` (c unless 0.0 > c: NaN stays)."""
    return 0.0 if 0.0 > c else c


@njit(cache=True)
def quadric(VQ, r, x0, x1, x2):
    """`wedges._quadric`: Q(x) of row r's quadric (float64, the same order of operations)."""
    a0, a1, a2 = np.float64(VQ[r, 3]), np.float64(VQ[r, 4]), np.float64(VQ[r, 5])
    a3, a4, a5 = np.float64(VQ[r, 6]), np.float64(VQ[r, 7]), np.float64(VQ[r, 8])
    b0, b1, b2, c = np.float64(VQ[r, 9]), np.float64(VQ[r, 10]), np.float64(VQ[r, 11]), np.float64(VQ[r, 12])
    u0 = x0 - np.float64(VQ[r, 0])
    u1 = x1 - np.float64(VQ[r, 1])
    u2 = x2 - np.float64(VQ[r, 2])
    au0 = a0 * u0 + a1 * u1 + a2 * u2
    au1 = a1 * u0 + a3 * u1 + a4 * u2
    au2 = a2 * u0 + a4 * u1 + a5 * u2
    return (u0 * au0 + u1 * au1 + u2 * au2) + 2.0 * (b0 * u0 + b1 * u1 + b2 * u2) + c


@njit(cache=True)
def translated(VQ, r, x0, x1, x2, m, D):
    """Row r's attribute state moved to x (`attributes._np_translate`): returns its constant term (state
    entry 9) and fills D[:m] with the channels' constants (entries 14 + 4j)."""
    d0 = x0 - np.float64(VQ[r, 0])
    d1 = x1 - np.float64(VQ[r, 1])
    d2 = x2 - np.float64(VQ[r, 2])
    a0, a1, a2 = np.float64(VQ[r, 3]), np.float64(VQ[r, 4]), np.float64(VQ[r, 5])
    a3, a4, a5 = np.float64(VQ[r, 6]), np.float64(VQ[r, 7]), np.float64(VQ[r, 8])
    b0, b1, b2 = np.float64(VQ[r, 9]), np.float64(VQ[r, 10]), np.float64(VQ[r, 11])
    ad0 = a0 * d0 + a1 * d1 + a2 * d2
    ad1 = a1 * d0 + a3 * d1 + a4 * d2
    ad2 = a2 * d0 + a4 * d1 + a5 * d2
    for j in range(m):
        g = 14 + 4 * j
        D[j] = np.float64(VQ[r, g + 3]) + (np.float64(VQ[r, g]) * d0 + np.float64(VQ[r, g + 1]) * d1
                                           + np.float64(VQ[r, g + 2]) * d2)
    return np.float64(VQ[r, 12]) + (d0 * (ad0 + 2.0 * b0) + d1 * (ad1 + 2.0 * b1) + d2 * (ad2 + 2.0 * b2))


@njit(cache=True)
def numpy_sum(v, n):
    """``np.sum(v[:n])`` of a short float64 vector as numpy adds it (pairwise: left to right under 8
    entries, else eight running sums, up to 128)."""
    if n < 8:
        s = 0.0
        for i in range(n):
            s += v[i]
        return s
    r0, r1, r2, r3, r4, r5, r6, r7 = v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7]
    i = 8
    while i < n - n % 8:
        r0 += v[i]
        r1 += v[i + 1]
        r2 += v[i + 2]
        r3 += v[i + 3]
        r4 += v[i + 4]
        r5 += v[i + 5]
        r6 += v[i + 6]
        r7 += v[i + 7]
        i += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        s += v[i]
        i += 1
    return s


@njit(cache=True)
def solve_host(VQ, ra, rb, x0, x1, x2, m, s, W):
    """`attributes.solve_host` of rows ra, rb at x: returns the reduced cost (≥ 0; NaN stays) and fills
    s[:m] with the optimal (weighted) attribute values. W: float scratch (2, ≥ m)."""
    Da, Db = W[0], W[1]
    ca = translated(VQ, ra, x0, x1, x2, m, Da)
    cb = translated(VQ, rb, x0, x1, x2, m, Db)
    alpha = np.float64(VQ[ra, 13]) + np.float64(VQ[rb, 13])
    for j in range(m):
        Da[j] = Da[j] + Db[j]  # the summed state's constants G3
        Db[j] = Da[j] * Da[j]
    if alpha > 0:
        for j in range(m):
            s[j] = Da[j] / alpha
        cost = (ca + cb) - numpy_sum(Db, m) / alpha
    else:
        for j in range(m):
            s[j] = 0.0
        cost = (ca + cb) - 0.0
    return _max0(cost)


@njit(cache=True)
def optimal_attributes(VQ, ra, rb, x0, x1, x2, m, s):
    """`attributes.optimal_attributes` for one pair: s[:m] = Σ (D_j + G_j·(x − p)) / Σ α (0 where α ≤ 0)."""
    for j in range(m):
        s[j] = 0.0
    alpha = 0.0
    for r in (ra, rb):
        d0 = x0 - np.float64(VQ[r, 0])
        d1 = x1 - np.float64(VQ[r, 1])
        d2 = x2 - np.float64(VQ[r, 2])
        for j in range(m):
            g = 14 + 4 * j
            s[j] += np.float64(VQ[r, g + 3]) + (np.float64(VQ[r, g]) * d0 + np.float64(VQ[r, g + 1]) * d1
                                                + np.float64(VQ[r, g + 2]) * d2)
        alpha += np.float64(VQ[r, 13])
    for j in range(m):
        s[j] = s[j] / alpha if alpha > 0 else 0.0


@njit(cache=True)
def cost_at(VQ, a, b, v, m, W):
    """The Tracker's price of contracting pair (a, b) onto vertex v's position: the attribute model's
    reduced cost (m ≥ 0), else the sum of the two quadric errors. W: float scratch (3, ≥ m)."""
    x0, x1, x2 = np.float64(VQ[v, 0]), np.float64(VQ[v, 1]), np.float64(VQ[v, 2])
    if m >= 0:
        return solve_host(VQ, a, b, x0, x1, x2, m, W[2], W)
    return quadric(VQ, a, x0, x1, x2) + quadric(VQ, b, x0, x1, x2)


@njit(cache=True)
def constrain(F, alive, cnt, off, pool, C, multi, VQ, P, x, cost, m):
    """`wedges.Tracker.constrain`: pairs P (K,2) touching a seam vertex (flags read before the loop) get
    x (K,3) and cost (K,) at the allowed endpoint of smaller price (a first among equals). Returns (K,)
    bool: pairs with no allowed placement."""
    bad = np.zeros(len(P), np.bool_)
    constrain_rows(F, alive, cnt, off, pool, C, multi, VQ, P, np.arange(len(P)), x, cost, bad, True, m)
    return bad


@njit(cache=True)
def constrain_rows(F, alive, cnt, off, pool, C, multi, VQ, E, d, x, cost, bad, code, m):
    """`constrain` of the pairs E[d] written in place: rows d of x (P,3) and cost (P,) placed at the allowed
    endpoint, and bad[row] = ``code`` where there is none. Only the pairs at a seam vertex are touched (the
    flags read before the loop, as `constrain` reads them)."""
    K = len(d)
    seam = np.empty(K, np.bool_)
    n_seam = 0
    for i in range(K):
        seam[i] = multi[E[d[i], 0]] or multi[E[d[i], 1]]
        n_seam += seam[i]
    if n_seam == 0:
        return
    P = np.empty((n_seam, 2), E.dtype)
    j = 0
    for i in range(K):
        if seam[i]:
            P[j, 0], P[j, 1] = E[d[i], 0], E[d[i], 1]
            j += 1
    T, W = scratch(P, cnt, m)
    j = -1
    for i in range(K):
        if not seam[i]:
            continue
        j += 1
        r = d[i]
        a, b = P[j, 0], P[j, 1]
        free, nba, nab, _, _ = modes(F, alive, cnt, off, pool, C, multi, a, b, T)
        if free:
            continue
        best_v, c = endpoint(VQ, a, b, nba >= 0, nab >= 0, m, W)
        if best_v < 0:
            bad[r] = code
            continue
        for k in range(3):
            x[r, k] = VQ[best_v, k]
        cost[r] = c


@njit(cache=True)
def endpoint(VQ, a, b, keep_a, keep_b, m, W):
    """Of the pair (a, b) (rows of VQ), the endpoint to contract onto where keeping a (``keep_a``) or b
    (``keep_b``) is allowed: the one of smaller price (`cost_at`; a first among equals), as (its row, its
    price, not below 0); (-1, 0.0) where neither is allowed."""
    best, best_v = 0.0, -1
    if keep_a:
        best, best_v = cost_at(VQ, a, b, a, m, W), a
    if keep_b:
        c = cost_at(VQ, a, b, b, m, W)
        if best_v < 0 or c < best:
            best, best_v = c, b
    return best_v, _max0(best)


@njit(cache=True)
def _at(VQ, v, x):
    """Whether x (3,) equals vertex v's position exactly."""
    return x[0] == VQ[v, 0] and x[1] == VQ[v, 1] and x[2] == VQ[v, 2]


@njit(cache=True)
def refused(F, alive, cnt, off, pool, C, multi, VQ, P, X, check):
    """`wedges.Tracker.allowed` for each pair of P (K,2) at X (K,3) (VQ's dtype) where ``check`` (K,) and
    a flag (read before the loop) marks a seam endpoint, in order. Returns (K,) bool: refused."""
    K = len(P)
    T, _ = scratch(P, cnt, 0)
    seam = np.empty(K, np.bool_)
    for i in range(K):
        seam[i] = multi[P[i, 0]] or multi[P[i, 1]]
    out = np.zeros(K, np.bool_)
    for i in range(K):
        if not (check[i] and seam[i]):
            continue
        a, b = P[i, 0], P[i, 1]
        if not (multi[a] or multi[b]):
            continue
        free, nba, nab, _, _ = modes(F, alive, cnt, off, pool, C, multi, a, b, T)
        if free:
            continue
        out[i] = not ((nba >= 0 and _at(VQ, a, X[i])) or (nab >= 0 and _at(VQ, b, X[i])))
    return out


@njit(cache=True, inline="always")
def _clip01(t):
    """``np.clip(t, 0, 1)`` (NaN and -0.0 stay)."""
    if t < 0.0:
        return 0.0
    if t > 1.0:
        return 1.0
    return t


@njit(cache=True)
def _interpolate(VQ, val, a, b, wa, wb, t, x0, x1, x2, m, solved, weights, batched, W):
    """The kept wedge wa's new value: (1 − t)·val[wa] + t·val[wb], and for the solved channels the
    attribute model's optimum at x over the channel weights (``batched``: `optimal_attributes`' form,
    else `solve_host`'s). W: float scratch (4, ≥ the channels)."""
    k = val.shape[1]
    out, s = W[3], W[2]
    for c in range(k):
        out[c] = (1.0 - t) * val[wa, c] + t * val[wb, c]
    if m >= 0:
        if batched:
            optimal_attributes(VQ, a, b, x0, x1, x2, m, s)
        else:
            solve_host(VQ, a, b, x0, x1, x2, m, s, W)
        for c in range(k):
            if solved[c]:
                out[c] = s[c] / weights[c]
    for c in range(k):
        val[wa, c] = out[c]


@njit(cache=True)
def _contract(F, alive, cnt, off, pool, C, val, multi, VQ, a, b, x64, x, m, solved, weights, frozen, T, W):
    """`wedges.Tracker.contract`: the corners (and values) for contracting b into a at x64 (float64; x:
    the same in VQ's dtype; a ``frozen`` kept vertex keeps its wedge's value). Returns False where the seam
    rule does not allow it (nothing changed)."""
    lb = corners(F, alive, cnt, off, pool, C, b, T[FB], T[KB], T[WB])
    first = -1
    for j in range(lb):
        if _holds(F, T[FB, j], a):
            first = j
            break
    wa = wbv = -1
    nba = nab = la = _ONE_TO_ONE_FAILS
    if not (multi[a] or multi[b]) and first >= 0:  # single wedges: a's from a shared face
        free = True
        wa, wbv = C[T[FB, first], _corner_of(F, T[FB, first], a)], T[WB, 0]
    else:
        free, nba, nab, la, lb = modes(F, alive, cnt, off, pool, C, multi, a, b, T)
        if free:
            wa, wbv = T[KAB, 0], T[VAB, 0]
    if free:
        pa0, pa1, pa2 = np.float64(VQ[a, 0]), np.float64(VQ[a, 1]), np.float64(VQ[a, 2])
        d0 = np.float64(VQ[b, 0]) - pa0
        d1 = np.float64(VQ[b, 1]) - pa1
        d2 = np.float64(VQ[b, 2]) - pa2
        u0, u1, u2 = x64[0] - pa0, x64[1] - pa1, x64[2] - pa2
        ud = 0.0  # `fixed_order.dot`: from 0.0, left to right
        ud += u0 * d0
        ud += u1 * d1
        ud += u2 * d2
        dd = 0.0
        dd += d0 * d0
        dd += d1 * d1
        dd += d2 * d2
        t = _clip01(ud / (1e-300 if 1e-300 > dd else dd))
        if not frozen[a]:
            _interpolate(VQ, val, a, b, wa, wbv, t, x64[0], x64[1], x64[2], m, solved, weights, False, W)
        for j in range(lb):
            C[T[FB, j], T[KB, j]] = wa
        return True
    if nba >= 0 and _at(VQ, a, x):
        for j in range(lb):
            C[T[FB, j], T[KB, j]] = lookup(T[KBA], T[VBA], nba, T[WB, j])
    elif nab >= 0 and _at(VQ, b, x):
        for j in range(la):
            C[T[FA, j], T[KA, j]] = lookup(T[KAB], T[VAB], nab, T[WA, j])
    else:
        return False
    multi[a] = True  # conservative: the exact test decides
    return True


@njit(cache=True)
def contract_many(F, alive, cnt, off, pool, C, val, multi, VQ, P, X64, X, m, solved, weights, frozen):
    """`wedges.Tracker.contract_many` for vertex-disjoint pairs P (K,2) at X64 (K,3) float64 (X: the same
    in VQ's dtype): first the pairs of single-wedge vertices with live faces at both ends, in order (a's
    first face's wedge takes the value at the placement's projection, every corner of b names it), then
    the others one by one (`Tracker.contract`'s rule). Returns the first pair the seam rule refuses, or
    -1."""
    K = len(P)
    T, W = scratch(P, cnt, max(m, val.shape[1]))
    free = np.empty(K, np.bool_)
    for i in range(K):
        free[i] = not (multi[P[i, 0]] or multi[P[i, 1]])
    for i in range(K):
        if not free[i]:
            continue
        a, b = P[i, 0], P[i, 1]
        la = corners(F, alive, cnt, off, pool, C, a, T[FA], T[KA], T[WA])
        lb = corners(F, alive, cnt, off, pool, C, b, T[FB], T[KB], T[WB])
        if la == 0 or lb == 0:
            free[i] = False  # left to `contract`
            continue
        pa0, pa1, pa2 = np.float64(VQ[a, 0]), np.float64(VQ[a, 1]), np.float64(VQ[a, 2])
        d0 = np.float64(VQ[b, 0]) - pa0
        d1 = np.float64(VQ[b, 1]) - pa1
        d2 = np.float64(VQ[b, 2]) - pa2
        u0, u1, u2 = X64[i, 0] - pa0, X64[i, 1] - pa1, X64[i, 2] - pa2
        dd = d0 * d0 + d1 * d1 + d2 * d2  # numpy's elementwise sums
        ud = u0 * d0 + u1 * d1 + u2 * d2
        t = _clip01(ud / (dd if dd >= 1e-300 or dd != dd else 1e-300))
        wa = T[WA, 0]
        if not frozen[a]:
            _interpolate(VQ, val, a, b, wa, T[WB, 0], t, X64[i, 0], X64[i, 1], X64[i, 2], m, solved, weights, True,
                         W)
        for j in range(lb):
            C[T[FB, j], T[KB, j]] = wa
    for i in range(K):
        if not free[i]:
            if not _contract(F, alive, cnt, off, pool, C, val, multi, VQ, P[i, 0], P[i, 1], X64[i], X[i], m,
                             solved, weights, frozen, T, W):
                return i
    return -1


@njit(cache=True)
def contract(F, alive, cnt, off, pool, C, val, multi, VQ, a, b, x64, x, m, solved, weights, frozen):
    """`wedges.Tracker.contract` for one pair (b into a at x64, float64; x: the same in VQ's dtype).
    Returns False where the seam rule does not allow it (nothing changed)."""
    P = np.empty((1, 2), np.int64)
    P[0, 0], P[0, 1] = a, b
    T, W = scratch(P, cnt, max(m, val.shape[1]))
    return _contract(F, alive, cnt, off, pool, C, val, multi, VQ, a, b, x64, x, m, solved, weights, frozen, T, W)
