"""``A.take(idx, axis=0)`` done in place for ascending indices (`compact`, numba), for the scheduler's per-pair
arrays.

Each round carries the pairs' placements, costs and flags over to the pairs that stay: a gather of about
two million rows on a large mesh, with ascending indices. Moving the rows down within the array they are
in writes no new array of that size (tests/test_arrays.py compares it with numpy's take).
"""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, nogil=True)
def _compact1(A, idx):
    for k in range(len(idx)):
        A[k] = A[idx[k]]


@njit(cache=True, nogil=True)
def _compact2(A, idx):
    for k in range(len(idx)):
        i = idx[k]
        for j in range(A.shape[1]):
            A[k, j] = A[i, j]


def compact(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """A.take(idx, axis=0) for strictly ascending indices, written over A's first rows (idx[k] >= k, so no
    row is overwritten before it is read) and returned as a view of them; A's rows are then garbage.
    An array that cannot be written (a device result) or is not C-contiguous is gathered by numpy."""
    if not (A.flags.writeable and A.flags.c_contiguous):
        return A.take(idx, axis=0)
    if A.ndim == 1:
        _compact1(A, idx)
    else:
        _compact2(A, idx)
    return A[: len(idx)]

