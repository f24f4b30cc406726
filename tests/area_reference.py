"""The wide-ring solve of ``method="area"`` as it was written in numpy before it was compiled
(`qemjax._costs.area_host`), kept as the reference the compiled loops are tested against
(tests/test_area.py): `solve_host` is the former `area.solve_host`, float64, batched over pairs, and
`price_host` the former `area._price_host`, which called it."""
from __future__ import annotations

import numpy as np


def _host_delta(s, u, w, mask, before):
    """ΔS at s (K, m) for float64 arrays u, w (K,R,3), mask (K,R), before (K,)."""
    v = u[:, None] + s[..., None, None] * w[:, None]
    return before[:, None] - 0.5 * np.sum(np.where(mask[:, None], np.linalg.norm(v, axis=-1), 0.0), -1)


def _host_bisect(f, lo, hi, steps=60):
    """Roots of non-decreasing f (K,) -> (K,) on [lo, hi] (K,), by plain bisection."""
    lo, hi = lo.copy(), hi.copy()
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        up = f(mid) >= 0
        hi, lo = np.where(up, mid, hi), np.where(up, lo, mid)
    return 0.5 * (lo + hi)


def solve_host(pa, pb, pos, moving, mask, lo, hi):
    """`solve_pair` for K pairs in float64 numpy (the same steps, batched on the host): arrays with a
    leading K axis. Returns (s, |ΔS|, ΔS, branch) (K,)."""
    p0 = np.where(moving[..., None], pa[:, None, None], pos)
    p1 = np.where(moving[..., None], pb[:, None, None], pos)
    cr = lambda p: np.cross(p[:, :, 1] - p[:, :, 0], p[:, :, 2] - p[:, :, 0])  # noqa: E731
    u = cr(p0)
    w = cr(p1) - u
    before = 0.5 * np.sum(np.where(mask, np.linalg.norm(cr(pos), axis=-1), 0.0), -1)

    def delta(s):
        return _host_delta(s[:, None], u, w, mask, before)[:, 0]

    def slope(s):
        v = u + s[:, None, None] * w
        n = np.linalg.norm(v, axis=-1)
        ok = mask & (n > 0)
        return 0.5 * np.sum(np.where(ok, np.sum(v * w, -1) / np.where(ok, n, 1.0), 0.0), -1)

    peak = np.clip(_host_bisect(slope, lo, hi), lo, hi)
    d_lo, d_hi, d_peak = delta(lo), delta(hi), delta(peak)
    left = np.clip(_host_bisect(delta, lo, peak), lo, peak)
    right = np.clip(_host_bisect(lambda s: -delta(s), peak, hi), peak, hi)
    s = np.stack([left, right, peak, lo, hi], 1)
    d = _host_delta(s, u, w, mask, before)
    ok = np.concatenate([np.stack([(d_lo <= 0) & (d_peak >= 0), (d_hi <= 0) & (d_peak >= 0)], 1),
                         np.ones((len(s), 3), bool)], 1)
    k = np.argmin(np.where(ok, np.abs(d), np.inf), 1)
    r = np.arange(len(s))
    branch = np.where(lo == hi, 3, np.array([0, 0, 1, 2, 2])[k])
    return s[r, k], np.abs(d[r, k]), d[r, k], branch


def price_host(VS, pairs, corners, mask):
    """The former `area._price_host`: the price rows (5, K) of pairs with rings wider than RING_CAP."""
    VS = np.asarray(VS, np.float64)
    pairs = np.asarray(pairs, np.int64)
    keep = np.asarray(mask).any(0)  # drop the columns no pair uses
    corners, mask = np.asarray(corners)[:, keep], np.asarray(mask)[:, keep]
    pos = VS[np.minimum(corners, len(VS) - 1), :3]
    moving = (corners == pairs[:, 0, None, None]) | (corners == pairs[:, 1, None, None])
    pa, pb = VS[pairs[:, 0], :3], VS[pairs[:, 1], :3]
    fa, fb = VS[pairs[:, 0], 3] > 0.5, VS[pairs[:, 1], 3] > 0.5
    lo, hi = np.where(fb & ~fa, 1.0, 0.0), np.where(fa & ~fb, 0.0, 1.0)
    s, cost, _, branch = solve_host(pa, pb, pos, moving, mask, lo, hi)
    x = pa + s[:, None] * (pb - pa)
    return np.concatenate([x.T, cost[None], branch[None]], 0).astype(np.float32)

