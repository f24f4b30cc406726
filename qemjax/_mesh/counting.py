"""Rows grouped by small integer keys: a stable counting sort (`counting_order`), one pass to count and one
to place, where a comparison sort of millions of rows took a second (numba)."""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, nogil=True, inline="always")
def _bucket(k, n):
    """The bucket of key k among n keys: 0 below 0, 1 + k for a key, n + 1 at n and over."""
    return 0 if k < 0 else (k + 1 if k < n else n + 1)


@njit(cache=True, nogil=True)
def counting_order(keys, n):
    """(order, start): the rows of ``keys`` (values 0 … n−1) by key, rows with equal keys in their order,
    and where each key's rows begin in ``order`` (n + 1 entries), both int64: ``np.argsort(keys,
    kind="stable")`` and ``np.searchsorted`` of its runs. A key outside 0 … n−1 is placed as the argsort
    places it: before the first key's rows, or after the last's."""
    count = np.zeros(n + 3, np.int64)  # the buckets' starts, one place up
    for i in range(len(keys)):
        count[_bucket(keys[i], n) + 1] += 1
    for b in range(n + 2):
        count[b + 1] += count[b]
    order = np.empty(len(keys), np.int64)
    fill = count[:n + 2].copy()
    for i in range(len(keys)):
        b = _bucket(keys[i], n)
        order[fill[b]] = i
        fill[b] += 1
    return order, count[1:n + 2].copy()
