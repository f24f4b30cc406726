"""Quantiles of distances: observed values, optionally weighted, for the measured distance and the metrics."""
from __future__ import annotations

import numpy as np

from .compiled import njit

DIGIT = 8  # bits per pass of the radix sort: 256 buckets, whose write positions stay in cache


@njit(cache=True, nogil=True)
def stable_order(d):
    """``np.argsort(d, kind="stable")`` of float64 values, int64: a radix sort of their bits, read as
    integers in the values' order (-0.0 as 0.0; every NaN last, in its order), least significant digit
    first, each pass stable and moving the keys with their rows (so that every pass reads in order); a
    digit every value shares is passed over. (numpy's stable sort of floats is a merge sort: several times
    slower on the millions of samples a measured distance has.)"""
    n = len(d)
    top = np.uint64(0xFFFFFFFFFFFFFFFF)
    sign = np.uint64(1) << np.uint64(63)
    buckets = 1 << DIGIT
    mask = np.uint64(buckets - 1)
    passes = 64 // DIGIT
    # every pass's bucket sizes from one read of the keys: a pass moves the keys, not their digits' counts
    counts = np.zeros((passes, buckets + 1), np.int64)
    key = np.empty(n, np.uint64)
    for i in range(n):
        x = d[i] + 0.0
        if x != x:
            k = top
        else:
            b = np.float64(x).view(np.uint64)
            k = ~b if b & sign else b | sign
        key[i] = k
        for p in range(passes):
            counts[p, ((k >> np.uint64(p * DIGIT)) & mask) + 1] += 1
    order = np.arange(n)
    key2 = np.empty(n, np.uint64)
    order2 = np.empty(n, np.int64)
    for p in range(passes):
        s = np.uint64(p * DIGIT)
        count = counts[p]
        if n == 0 or count[((key[0] >> s) & mask) + 1] == n:
            continue
        for b in range(buckets):
            count[b + 1] += count[b]
        for i in range(n):
            k = key[i]
            c = (k >> s) & mask
            at = count[c]
            key2[at] = k
            order2[at] = order[i]
            count[c] = at + 1
        key, key2 = key2, key
        order, order2 = order2, order
    return order


def quantiles(d: np.ndarray, qs, weights: np.ndarray | None = None) -> list[float]:
    """The q-quantiles (0 <= q <= 1) of the values d: the smallest value with at least a fraction q of them
    (of their total weight, with ``weights``) at or below it, an observed value, never interpolated (so
    the 1.0 quantile is the maximum and a bound on it is a bound on the samples)."""
    ds = np.ascontiguousarray(d, np.float64)
    w = np.zeros(0) if weights is None else np.ascontiguousarray(weights, np.float64)
    if weights is not None and len(w) < len(ds):
        raise ValueError(f"quantiles: {len(ds)} values but {len(w)} weights")
    ds, cw = sorted_sums(ds, stable_order(ds), w)
    idx = np.searchsorted(cw, np.asarray(qs, np.float64) * cw[-1], side="left")
    return [float(ds[min(i, len(ds) - 1)]) for i in idx]


@njit(cache=True, nogil=True)
def sorted_sums(d, order, w):
    """(d[order], np.cumsum(w[order])) in one pass, without the gathered weights (``w`` empty: every weight
    1): the cumulative sum runs left to right, as numpy's does, so the same bits."""
    n = len(order)
    ds = np.empty(n)
    cw = np.empty(n)
    acc = 0.0
    for i in range(n):
        j = order[i]
        ds[i] = d[j]
        x = w[j] if len(w) else 1.0
        acc = x if i == 0 else acc + x
        cw[i] = acc
    return ds, cw
