"""Bounding boxes, compiled: numpy's ``V.min(0)`` / ``V.max(0)`` without its cost on (n,3) rows.

numpy reduces an (n,3) array over its first axis three values at a time: these loops take about a tenth
of its time (docs/benchmarks.md, "Measured choices inside a run"). A run took three on its input (the re-fit's frame, the measured
distance's frame and diagonal) and more in each nearest search's grid. These loops give the same values, signed
zeros and NaNs included: numpy's reduction keeps the running value only where it is strictly smaller (for
the minimum; larger for the maximum) or NaN, and otherwise takes the new one. tests/test_fixed_order.py
compares them with numpy on random rows full of ties between 0.0 and -0.0.
"""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, nogil=True, inline="always")
def _lo(acc, x):
    """numpy's minimum as its reduction applies it: the running value where strictly smaller or NaN."""
    return acc if (acc < x or acc != acc) else x


@njit(cache=True, nogil=True, inline="always")
def _hi(acc, x):
    return acc if (acc > x or acc != acc) else x


@njit(cache=True, nogil=True)
def row_bounds(V):
    """(V.min(0), V.max(0)) of (n, c) rows, n >= 1, as numpy gives them for rows in C order (for another
    layout numpy reduces each column with other loops, and a signed zero or a NaN's sign may differ)."""
    n, c = V.shape
    lo, hi = V[0].copy(), V[0].copy()
    for i in range(1, n):
        for j in range(c):
            lo[j] = _lo(lo[j], V[i, j])
            hi[j] = _hi(hi[j], V[i, j])
    return lo, hi


@njit(cache=True, nogil=True)
def used_bounds(X, G):
    """(X[np.unique(G)].min(0), ... .max(0)): the box of the vertices the triangles G (j,3) use, j >= 1."""
    used = np.zeros(X.shape[0], np.bool_)
    for g in range(G.shape[0]):
        for c in range(3):
            used[G[g, c]] = True
    first = 0
    while not used[first]:
        first += 1
    lo, hi = X[first].copy(), X[first].copy()
    for i in range(first + 1, X.shape[0]):
        if used[i]:
            for j in range(X.shape[1]):
                lo[j] = _lo(lo[j], X[i, j])
                hi[j] = _hi(hi[j], X[i, j])
    return lo, hi


@njit(cache=True, nogil=True)
def face_boxes(X, G):
    """(j, 6): each triangle's box, ``np.concatenate([X[G].min(1), X[G].max(1)], 1)``."""
    j = G.shape[0]
    B = np.empty((j, 6), X.dtype)
    for g in range(j):
        for ax in range(3):
            lo = hi = X[G[g, 0], ax]
            for c in range(1, 3):
                x = X[G[g, c], ax]
                lo, hi = _lo(lo, x), _hi(hi, x)
            B[g, ax], B[g, 3 + ax] = lo, hi
    return B
