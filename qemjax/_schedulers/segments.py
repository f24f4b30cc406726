"""Order statistics of each copy's own pairs in a batch (pairs grouped by copy: copy c holds rows
starts[c] … starts[c+1] − 1; a single run is one copy), in one compiled pass over the rows instead of a
numpy call or three per copy and round: a sweep's batch has tens of copies and a round a few hundred
thousand pairs at most, so the calls, not the arithmetic, were the cost. The batch's gates (`batched`), a
single run's gate (`parallel.LoopRound.select`) and the shape term's two cuts (`shape`) take them."""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit


def sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(C,) int64: the sum of each copy's ``values`` (P,) (integers, or bools: the rows set)."""
    csum = np.concatenate([[0], np.cumsum(values, dtype=np.int64)])
    return np.diff(np.take(csum, starts))


# copies of this many rows or more take the k-th by radix passes over the keys' bits (`_radix_kth`): their
# values outgrow the core's cache, where a partition's swaps wait on memory and the passes stream through it
RADIX_FROM = 1 << 15


@njit(cache=True, nogil=True)
def kth(values, mask, starts, ks):
    """(C,) the ks[c]-th smallest (1-based) of copy c's ``values`` (P,) float32 where ``mask`` is set, the
    value ``np.partition`` gives (NaNs last; a zero may come back with the other sign, which no comparison
    sees); NaN where ks[c] < 1. ks[c] must not exceed the copy's masked rows. A copy of `RADIX_FROM` rows or
    more takes it by radix passes (`_radix_kth`): the same value."""
    C = len(starts) - 1
    out = np.full(C, np.nan, values.dtype)
    buf = np.empty(len(values), values.dtype)
    rows = np.empty(0, np.int64)
    for c in range(C):
        k = ks[c]
        if k < 1:
            continue
        if starts[c + 1] - starts[c] >= RADIX_FROM:
            if len(rows) == 0:
                rows = np.empty(len(values), np.int64)
            out[c] = _radix_kth(values, mask, starts[c], starts[c + 1], k, rows)
            continue
        m = 0
        for i in range(starts[c], starts[c + 1]):
            if mask[i]:
                buf[m] = values[i]
                m += 1
        out[c] = np.partition(buf[:m], k - 1)[k - 1]
    return out


@njit(cache=True, nogil=True, inline="always")
def _ordered(b):
    """A float32's bits b (uint32) as a uint32 whose order is the values' (-inf first; NaNs, either sign,
    last): a negative value's bits reversed, a positive one's above them."""
    if (b & np.uint32(0x7FFFFFFF)) > np.uint32(0x7F800000):
        return np.uint32(0xFFFFFFFF)
    if b & np.uint32(0x80000000):
        return ~b
    return b | np.uint32(0x80000000)


@njit(cache=True, nogil=True, inline="always")
def _digit_of(hist, k):
    """(the digit whose bin holds the k-th (1-based) count of ``hist``, k's rank within that bin)."""
    below = 0
    for j in range(len(hist)):
        if below + hist[j] >= k:
            return j, k - below
        below += hist[j]
    return len(hist) - 1, k - below


@njit(cache=True, nogil=True)
def _radix_kth(values, mask, lo, hi, k, rows):
    """The k-th smallest (1-based) of float32 ``values[lo:hi]`` where ``mask`` is set, as `kth` gives it: its
    ordered bits (`_ordered`) found eleven, eleven and ten bits at a time, each pass counting the rows whose
    higher bits are the k-th's (the second pass lists them in ``rows``, ≥ hi - lo, for the third); then a
    row with those bits, whose value is returned."""
    bits = np.ascontiguousarray(values).view(np.uint32)
    high = np.zeros(2048, np.int64)
    for i in range(lo, hi):
        high[_ordered(bits[i]) >> np.uint32(21)] += mask[i]
    d1, k = _digit_of(high, k)
    middle = np.zeros(2048, np.int64)
    n = 0
    for i in range(lo, hi):
        u = _ordered(bits[i])
        if (u >> np.uint32(21)) == d1 and mask[i]:
            rows[n] = i
            n += 1
            middle[(u >> np.uint32(10)) & np.uint32(0x7FF)] += 1
    d2, k = _digit_of(middle, k)
    low = np.zeros(1024, np.int64)
    m = 0
    for j in range(n):
        i = rows[j]
        u = _ordered(bits[i])
        if ((u >> np.uint32(10)) & np.uint32(0x7FF)) == d2:
            rows[m] = i
            m += 1
            low[u & np.uint32(0x3FF)] += 1
    d3, k = _digit_of(low, k)
    for j in range(m):
        if (_ordered(bits[rows[j]]) & np.uint32(0x3FF)) == d3:
            return values[rows[j]]
    return values[rows[0]]  # (not reached: the k-th's bits are some row's)


def per_row(per_copy: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(P,) each row's copy's value of ``per_copy`` (C,)."""
    return np.repeat(per_copy, np.diff(starts))
