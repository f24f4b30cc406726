"""Host arithmetic with the same bits on every CPU (numpy's counterpart of `qemjax._kernels.fixed`).

Two kinds of numpy call give different last bits on different x86-64 CPUs, and a last bit is enough to
change which pair contracts first and so the whole output:

* products through BLAS (``a @ b``, ``np.dot``, ``np.linalg.solve``/``det``): OpenBLAS picks its kernel by
  CPU (Haswell, SkylakeX, Zen, Sandybridge, ...), and the kernels sum in different orders and differ in
  fusing multiply-adds;
* transcendental functions (``np.exp``, ``np.log``, ``np.power``, ``np.arccos``, ``np.arctan2``, ...):
  numpy runs its own AVX-512 versions where the CPU has AVX-512 and the C library's elsewhere.

Here sums run left to right over a short axis with plain multiplies and adds, and transcendental
functions go through Python's ``math`` (the C library: one implementation on every FMA-capable x86-64).
Use these on every path that leads to a result; ``tests/test_cpu_independence.py`` runs the golden
cases under several BLAS kernels and without AVX-512 and checks one hash.
"""
from __future__ import annotations

import math

import numpy as np


def weighted_sum(parts: np.ndarray, weights) -> np.ndarray:
    """(n,) Σ_j parts[:, j]·weights[j], added left to right (float64)."""
    parts = np.asarray(parts, np.float64)
    out = np.zeros(parts.shape[0])
    for j, w in enumerate(np.asarray(weights, np.float64).tolist()):
        out = out + parts[:, j] * w
    return out


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(…,) a·b over the last axis, added left to right (float64; two vectors: a Python float)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.ndim == 1 and b.ndim == 1:  # one pair of vectors: Python floats (numpy's per-call cost dominates)
        s = 0.0
        for x, y in zip(a.tolist(), b.tolist()):
            s += x * y
        return s
    out = np.zeros(np.broadcast_shapes(a.shape, b.shape)[:-1])
    for j in range(a.shape[-1]):
        out = out + a[..., j] * b[..., j]
    return out


def solve(M: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(X, det): X (s, n, m) solving M X = rhs for a stack of small square systems M (s, n, n), rhs (s, n, m),
    and det (s,) the determinants of M, by Gaussian elimination with partial pivoting in a fixed order of
    operations. A singular system gives inf/nan in its X (as a division by zero does): test det first."""
    A = np.array(M, np.float64)
    X = np.array(rhs, np.float64)
    s, n = A.shape[0], A.shape[-1]
    idx = np.arange(s)
    det = np.ones(s)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(n):
            p = k + np.argmax(np.abs(A[:, k:, k]), axis=1)  # the largest pivot (the first among equals)
            det = np.where(p != k, -det, det)
            for arr in (A, X):
                rk, rp = arr[idx, k].copy(), arr[idx, p].copy()
                arr[idx, k], arr[idx, p] = rp, rk
            det = det * A[:, k, k]
            for i in range(k + 1, n):
                f = A[:, i, k] / A[:, k, k]
                A[:, i, k:] = A[:, i, k:] - f[:, None] * A[:, k, k:]
                X[:, i] = X[:, i] - f[:, None] * X[:, k]
        for k in range(n - 1, -1, -1):
            acc = X[:, k].copy()
            for j in range(k + 1, n):
                acc = acc - A[:, k, j][:, None] * X[:, j]
            X[:, k] = acc / A[:, k, k][:, None]
    return X, det


def _elementwise(fn):
    def apply(*args):
        arrays = np.broadcast_arrays(*[np.asarray(a, np.float64) for a in args])
        flat = [a.ravel().tolist() for a in arrays]
        return np.array([fn(*v) for v in zip(*flat)], np.float64).reshape(arrays[0].shape)
    apply.__doc__ = f"``math.{fn.__name__}`` element by element (the C library's: the same on every CPU)."
    apply.__name__ = fn.__name__
    return apply


exp = _elementwise(math.exp)
arccos = _elementwise(math.acos)
arctan2 = _elementwise(math.atan2)
sin = _elementwise(math.sin)
cos = _elementwise(math.cos)
power = _elementwise(math.pow)
