"""Row gathers compiled (numba): ``A.take(idx, axis=0)`` for the scheduler's per-pair arrays, and the
same done in place for ascending indices (`compact`).

Each round carries the pairs' placements, costs and flags over to the pairs that stay: a gather of about
two million rows on a large mesh, with ascending indices. Moving the rows down within the array they are
in writes no new array of that size (tests/test_arrays.py compares both with numpy's take).
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _take1(A, idx):
    out = np.empty(len(idx), A.dtype)
    for k in range(len(idx)):
        out[k] = A[idx[k]]
    return out


@njit(cache=True, nogil=True)
def _take2(A, idx):
    w = A.shape[1]
    out = np.empty((len(idx), w), A.dtype)
    for k in range(len(idx)):
        i = idx[k]
        for j in range(w):
            out[k, j] = A[i, j]
    return out


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
    An array that cannot be written (a device result) or is not C-contiguous is gathered (`take`)."""
    if not (A.flags.writeable and A.flags.c_contiguous):
        return take(A, idx)
    if A.ndim == 1:
        _compact1(A, idx)
    else:
        _compact2(A, idx)
    return A[: len(idx)]


def take(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """A.take(idx, axis=0) for a 1-D or 2-D array of numbers or bools, with valid indices (unchecked)."""
    return _take1(A, idx) if A.ndim == 1 else _take2(A, idx)
