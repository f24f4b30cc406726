"""Percentiles of the distance: in simplify's stats (area-weighted, at the measured distance's samples) and in
metrics.evaluate (the two-way samples pooled), as observed values (numpy's inverted-CDF quantiles)."""
from __future__ import annotations

import numpy as np
import pytest

import qemjax
from qemjax._mesh.quantiles import quantiles


@pytest.mark.parametrize("seed", range(5))
def test_quantiles_are_numpys_inverted_cdf_weighted_or_not(seed):
    rng = np.random.default_rng(seed)
    d = rng.exponential(size=rng.integers(1, 400))
    d[rng.random(len(d)) < 0.2] = 0.5  # ties
    w = rng.random(len(d)) + 1e-3
    qs = [0.0, 0.01, 0.5, 0.95, 0.99, 1.0]
    assert quantiles(d, qs) == [float(np.quantile(d, q, method="inverted_cdf")) for q in qs]
    ref = [float(np.quantile(d, q, weights=w, method="inverted_cdf")) for q in qs]
    assert quantiles(d, qs, w) == ref
    assert quantiles(d, [1.0], w) == [d.max()]  # the top quantile is the maximum: a bound on it bounds all


def test_stable_order_is_numpys_stable_argsort():
    """`quantiles.stable_order` (a radix sort) against ``np.argsort(kind="stable")``: ties, zeros of both
    signs, infinities, NaNs of both signs, subnormals, negatives, one value, none."""
    from qemjax._mesh.quantiles import stable_order

    rng = np.random.default_rng(2)
    for n in (0, 1, 2, 1000, 70000):
        d = rng.exponential(size=n)
        for value, share in ((0.5, 0.2), (0.0, 0.05), (-0.0, 0.05), (np.nan, 0.02), (np.inf, 0.02),
                             (-np.inf, 0.02), (-np.nan, 0.01), (5e-324, 0.01), (-5e-324, 0.01)):
            d[rng.random(n) < share] = value
        d[rng.random(n) < 0.1] *= -1
        assert np.array_equal(stable_order(d), np.argsort(d, kind="stable"))


def test_sorted_sums_are_numpys_gather_and_cumsum_bit_for_bit():
    """`quantiles.sorted_sums` (one compiled pass, the measured distance's millions of samples gathered once)
    gives d[order] and np.cumsum(w[order]) with the same bits: weights over many magnitudes (where the order
    of the sums shows), none (every weight 1), one value, none; a weight missing is refused in those words."""
    from qemjax._mesh.quantiles import sorted_sums, stable_order

    rng = np.random.default_rng(3)
    for n in (0, 1, 7, 5000):
        d = rng.exponential(size=n)
        d[rng.random(n) < 0.2] = 0.25  # ties: the stable order's rows in their order
        w = rng.random(n) * 10.0 ** rng.integers(-12, 12, n)
        order = stable_order(d)
        ds, cw = sorted_sums(d, order, w)
        assert ds.tobytes() == d[order].tobytes() and cw.tobytes() == np.cumsum(w[order]).tobytes()
        ds, cw = sorted_sums(d, order, np.zeros(0))
        assert ds.tobytes() == d[order].tobytes() and cw.tobytes() == np.cumsum(np.ones(n)).tobytes()
    with pytest.raises(ValueError, match="3 values but 2 weights"):
        quantiles(np.ones(3), [0.5], np.ones(2))

def test_simplify_stats_have_weighted_percentiles_below_the_maximum():
    from qemjax._pipeline import refit

    m = qemjax.shapes.bumpy_sphere(3)
    res = qemjax.simplify(m, ratio=0.1)
    s = res.stats
    assert 0 < s["distance_p50"] <= s["distance_p95"] <= s["distance_p99"] <= s["distance_max"]
    for k in ("max", "rms", "p50", "p95", "p99"):
        assert s[f"distance_{k}_rel"] == pytest.approx(s[f"distance_{k}"] / np.linalg.norm(np.ptp(m.vertices, 0)))
    # recomputed from the same samples and weights, in mesh units
    from qemjax._mesh.grid_nearest import nearest

    V, F = res.input_vertices, res.input_faces
    lo, hi = V.min(0), V.max(0)
    centre, unit = refit.unit_frame(V, (lo, hi))
    P, w, _ = refit.samples((V - centre) / unit, F, np.zeros(len(V), np.int64))
    _, d = nearest((res.vertices - centre) / unit, res.faces, P, None)
    for p in (50, 95, 99):
        ref = float(np.quantile(d, p / 100, weights=w, method="inverted_cdf")) * unit
        assert s[f"distance_p{p}"] == pytest.approx(ref, rel=1e-12)


def test_unmeasured_runs_have_no_percentiles():
    res = qemjax.simplify(qemjax.shapes.bumpy_sphere(2), ratio=0.2, measure=False)
    assert all(res.stats[f"distance_p{p}"] is None for p in (50, 95, 99))


def test_evaluate_gives_pooled_percentiles():
    from qemjax.metrics._common import as_mesh
    from qemjax.metrics._distance import two_way

    m = qemjax.shapes.torus(n_major=32, n_minor=16)
    res = qemjax.simplify(m, ratio=0.2)
    row = qemjax.metrics.evaluate(m, res, n_samples=5000, seed=3)
    assert row["p50"] <= row["p95"] <= row["p99"] <= row["hausdorff"]
    fwd, bwd, _, _ = two_way(as_mesh(m, "o"), as_mesh(res, "s"), 5000, 3)
    both = np.concatenate([fwd, bwd])
    for p in (50, 95, 99):
        assert row[f"p{p}"] == float(np.quantile(both, p / 100, method="inverted_cdf"))
        assert row[f"p{p}_rel"] == pytest.approx(row[f"p{p}"] / row["bbox_diagonal"])
