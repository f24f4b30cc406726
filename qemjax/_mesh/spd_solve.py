"""Solve a sparse symmetric positive-definite system N X = B (a few right-hand sides) with the same bits on
every CPU.

Why not a library solver: scipy's sparse direct solvers (SuperLU, UMFPACK) and every dense one call BLAS,
whose kernels (picked at run time by CPU: Haswell, SkylakeX, Zen, Sandybridge, ...) sum in different
orders and may fuse multiply-adds, so their last bits differ from one machine to the next. The re-fit's
positions then differed, and with them every later contraction. Here every sum runs in a fixed order in
compiled loops (numba, which fuses no multiply-add unless asked: ``fastmath`` is off), so the result is a
function of the inputs alone.

The method is conjugate gradients with a Jacobi (diagonal) preconditioner, one independent iteration per
right-hand side, sharing each pass over the matrix. It starts from ``X0`` (the re-fit passes the current
positions, close to the answer) and stops a column once its residual is at most ``rtol`` times its
right-hand side's norm (or after ``max_iter`` iterations: `solve_spd` reports whether every column got
there).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .compiled import njit


@njit(cache=True, nogil=True)
def _matvec(indptr, indices, data, x, out):
    """out = N @ x for x (n, c), row by row in index order."""
    n, c = x.shape
    for i in range(n):
        for j in range(c):
            out[i, j] = 0.0
        for t in range(indptr[i], indptr[i + 1]):
            a, col = data[t], indices[t]
            for j in range(c):
                out[i, j] += a * x[col, j]


@njit(cache=True, nogil=True)
def _dot(a, b, j):
    """Σ_i a[i, j]·b[i, j], in index order."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i, j] * b[i, j]
    return s


@njit(cache=True, nogil=True)
def _pcg(indptr, indices, data, diag, B, X, rtol, max_iter):
    """Jacobi-preconditioned conjugate gradients on the columns of B, from X (updated in place). Returns the
    iterations each column took (-1: it did not reach rtol within max_iter)."""
    n, c = B.shape
    R = np.empty_like(B)
    _matvec(indptr, indices, data, X, R)
    for i in range(n):
        for j in range(c):
            R[i, j] = B[i, j] - R[i, j]
    Z = np.empty_like(B)
    for i in range(n):
        for j in range(c):
            Z[i, j] = R[i, j] / diag[i]
    P = Z.copy()
    Q = np.empty_like(B)
    rz = np.empty(c)
    goal = np.empty(c)
    done = np.full(c, -1, np.int64)
    for j in range(c):
        rz[j] = _dot(R, Z, j)
        goal[j] = (rtol * np.sqrt(_dot(B, B, j))) ** 2
        if _dot(R, R, j) <= goal[j]:
            done[j] = 0
    for it in range(1, max_iter + 1):
        if np.all(done >= 0):
            break
        _matvec(indptr, indices, data, P, Q)
        for j in range(c):
            if done[j] >= 0:
                continue
            pq = _dot(P, Q, j)
            if not pq > 0.0:  # a breakdown (the matrix is not definite, or the residual is exactly 0)
                done[j] = it
                continue
            alpha = rz[j] / pq
            for i in range(n):
                X[i, j] += alpha * P[i, j]
                R[i, j] -= alpha * Q[i, j]
            if _dot(R, R, j) <= goal[j]:
                done[j] = it
                continue
            for i in range(n):
                Z[i, j] = R[i, j] / diag[i]
            rz_new = _dot(R, Z, j)
            beta = rz_new / rz[j]
            rz[j] = rz_new
            for i in range(n):
                P[i, j] = Z[i, j] + beta * P[i, j]
    return done


def solve_spd(N, B: np.ndarray, X0: np.ndarray, rtol: float = 1e-12, max_iter: int | None = None):
    """(X, converged): X (n, c) solving the sparse symmetric positive-definite N (n, n) X = B (n, c), from the
    guess X0, to a relative residual of ``rtol`` per column (module docstring); ``converged`` is False when
    some column needed more than ``max_iter`` iterations (default: 10·n + 100), X is then the last iterate."""
    N = sp.csr_matrix(N, dtype=np.float64)
    N.sum_duplicates()  # canonical: duplicates summed (as scipy's diagonal sums them), columns sorted (the
    # summation order is the index order)
    return solve_csr(N.indptr.astype(np.int64), N.indices.astype(np.int64), N.data, B, X0, rtol, max_iter)


def solve_csr(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, B: np.ndarray, X0: np.ndarray,
              rtol: float = 1e-12, max_iter: int | None = None):
    """`solve_spd` of N given as its CSR arrays (int64 indices, float64 data), each row's columns ascending
    and distinct, as the re-fit assembles them: without scipy's checks and copies (a third of a small
    re-fit's solve). The same bits as `solve_spd` of that matrix."""
    n = len(indptr) - 1
    B = np.ascontiguousarray(B, np.float64).reshape(n, -1)
    X = np.array(X0, np.float64, order="C").reshape(B.shape)
    if n == 0:
        return X, True
    diag = _diagonal(indptr, indices, data)
    if not np.all(diag > 0):
        raise ValueError("solve_spd: the matrix has a diagonal entry that is not positive (not definite)")
    iters = _pcg(indptr, indices, data, diag, B, X, float(rtol), int(10 * n + 100 if max_iter is None else max_iter))
    return X, bool(np.all(iters >= 0))


@njit(cache=True, nogil=True)
def _diagonal(indptr, indices, data):
    """N's diagonal (0 where a row has no diagonal entry), as scipy's ``N.diagonal()`` gives it."""
    n = len(indptr) - 1
    out = np.zeros(n)
    for i in range(n):
        for t in range(indptr[i], indptr[i + 1]):
            if indices[t] == i:
                out[i] = data[t]
    return out
