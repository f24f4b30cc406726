"""`fixed_order.solve` compiled (numba): the same Gaussian elimination with partial pivoting, one system at
a time, with the same operations in the same order, so the same bits (tests/test_seam_rule.py compares
them); numba contracts no multiply-add. Used where a stack of small systems is solved on every run that keeps
attributes (`_costs.attributes.face_fields`), where numpy's per-step calls over the stack dominated."""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, error_model="numpy")  # a singular system gives inf/nan, as numpy's division does
def solve(M, rhs):
    """(X, det) as `fixed_order.solve`: X (s, n, m) solving M X = rhs for M (s, n, n), rhs (s, n, m), and
    det (s,) the determinants of M."""
    A = M.astype(np.float64)
    X = rhs.astype(np.float64)
    s, n, m = A.shape[0], A.shape[1], X.shape[2]
    det = np.ones(s)
    for q in range(s):
        d = 1.0
        for k in range(n):
            p = k  # the largest pivot, the first among equals; a NaN wins (np.argmax)
            best = abs(A[q, k, k])
            if best == best:
                for r in range(k + 1, n):
                    v = abs(A[q, r, k])
                    if v != v:
                        p = r
                        break
                    if v > best:
                        p, best = r, v
            if p != k:
                d = -d
                for j in range(n):
                    A[q, k, j], A[q, p, j] = A[q, p, j], A[q, k, j]
                for j in range(m):
                    X[q, k, j], X[q, p, j] = X[q, p, j], X[q, k, j]
            d = d * A[q, k, k]
            for i in range(k + 1, n):
                f = A[q, i, k] / A[q, k, k]
                for j in range(k, n):
                    A[q, i, j] = A[q, i, j] - f * A[q, k, j]
                for j in range(m):
                    X[q, i, j] = X[q, i, j] - f * X[q, k, j]
        det[q] = d
        for k in range(n - 1, -1, -1):
            for c in range(m):
                acc = X[q, k, c]
                for j in range(k + 1, n):
                    acc = acc - A[q, k, j] * X[q, j, c]
                X[q, k, c] = acc / A[q, k, k]
    return X, det
