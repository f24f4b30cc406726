"""Order statistics of each copy's own pairs in a batch (pairs grouped by copy: copy c holds rows
starts[c] … starts[c+1] − 1; a single run is one copy), in one compiled pass over the rows instead of a
numpy call or three per copy and round: a sweep's batch has tens of copies and a round a few hundred
thousand pairs at most, so the calls, not the arithmetic, were the cost. The batch's gates (`batched`), a
single run's gate (`parallel.LoopRound.select`) and the shape term's two cuts (`shape`) take them."""
from __future__ import annotations

import numpy as np
from numba import njit


def sums(values: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(C,) int64: the sum of each copy's ``values`` (P,) (integers, or bools: the rows set)."""
    csum = np.concatenate([[0], np.cumsum(values, dtype=np.int64)])
    return np.diff(np.take(csum, starts))


@njit(cache=True, nogil=True)
def kth(values, mask, starts, ks):
    """(C,) the ks[c]-th smallest (1-based) of copy c's ``values`` (P,) where ``mask`` is set, the value
    ``np.partition`` gives (NaNs last; a zero may come back with the other sign, which no comparison sees);
    NaN where ks[c] < 1. ks[c] must not exceed the copy's masked rows."""
    C = len(starts) - 1
    out = np.full(C, np.nan, values.dtype)
    buf = np.empty(len(values), values.dtype)
    for c in range(C):
        k = ks[c]
        if k < 1:
            continue
        m = 0
        for i in range(starts[c], starts[c + 1]):
            if mask[i]:
                buf[m] = values[i]
                m += 1
        out[c] = np.partition(buf[:m], k - 1)[k - 1]
    return out


def per_row(per_copy: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(P,) each row's copy's value of ``per_copy`` (C,)."""
    return np.repeat(per_copy, np.diff(starts))
