"""Fast numpy idioms for the host-side scheduler's large arrays.

numpy's general calls are several times slower than these specialised ones on large arrays (on rows
``A[idx]``, ``A[idx] = rows``, ``mask[E].any(1)``, ``np.sort(F, axis=1)`` on (m,3) rows, ``V.min(0)`` on
(n,3) rows; docs/benchmarks.md, "Measured choices inside a run"). Likewise ``np.compress(mask, a)`` is
faster than ``a[mask]`` when the mask is dense and irregular, and one ``np.flatnonzero`` serves several
``np.take`` where one mask compacts several arrays.

On the small arrays of a small mesh's rounds the cost is the call itself: the methods ``a.take(idx)`` and
``a.compress(mask)`` skip the Python wrappers of ``np.take`` / ``np.compress`` (most of a small call's
cost; the scheduler makes thousands a run), with the same results.

Here too is the one bounding-box diagonal every relative distance divides by (`box_diagonal`), in a fixed
order of operations.
"""
from __future__ import annotations

import math

import numpy as np


def take_rows(A: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """A[idx] for rows."""
    return A.take(idx, axis=0)


def put_rows(A: np.ndarray, idx: np.ndarray, rows: np.ndarray) -> None:
    """A[idx] = rows for a C-contiguous 2-D A: each row is written as one opaque item (a void view), which
    skips numpy's general multi-dimensional assignment."""
    item = np.dtype((np.void, A.dtype.itemsize * A.shape[1]))
    np.put(A.view(item).reshape(-1), idx, np.ascontiguousarray(rows, A.dtype).view(item).reshape(-1))


def keep_rows(A: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A[mask] for rows."""
    return A.compress(mask, axis=0)


def any_at(mask: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """mask[idx].any(1) for (k,2) or (k,3) index rows into the (n,) bool ``mask``."""
    t = mask.take(idx)
    if idx.shape[1] == 2:
        return t.view(np.uint16).reshape(-1) != 0
    out = t[:, 0] | t[:, 1]
    for j in range(2, idx.shape[1]):
        out |= t[:, j]
    return out


def whole_numbers(a: np.ndarray) -> bool:
    """Whether ``a`` holds whole numbers only (integers, or finite floats without a fraction): indices given
    as floats are taken as such, and a cast would cut 2.7 to 2."""
    return bool(np.issubdtype(a.dtype, np.integer) or (
        np.issubdtype(a.dtype, np.floating) and np.isfinite(a).all() and (a == np.round(a)).all()))


def nonfinite(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the vertices of V (n,3) that are not finite, bool (n,); those of them a face of F uses, indices): the
    input rule that only a vertex a face uses must be finite (an unused one is junk a run drops)."""
    bad = ~np.isfinite(V).all(axis=1)
    if not bad.any():  # the usual case: no mask of the used ones
        return bad, np.zeros(0, np.int64)
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    return bad, np.flatnonzero(used & bad)


def row_index(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(len(B),) int64: for each row of B (k,3) float64, the index of the first row of A (n,3) float64 with
    the same bytes (exact positions), -1 where none has."""
    if len(A) == 0:
        return np.full(len(B), -1, np.int64)
    ka = np.ascontiguousarray(A, np.float64).view(np.dtype((np.void, 24))).ravel()
    kb = np.ascontiguousarray(B, np.float64).view(np.dtype((np.void, 24))).ravel()
    order = np.argsort(ka, kind="stable")
    at = np.minimum(np.searchsorted(ka[order], kb), len(ka) - 1)
    return np.where(ka[order][at] == kb, order[at], -1)


def sorted_triples(F: np.ndarray) -> np.ndarray:
    """np.sort(F, axis=1) for (k,3) integer rows: smallest, middle, largest by arithmetic."""
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    return np.stack([lo, a + b + c - lo - hi, hi], 1)


def column_bounds(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V.min(0), V.max(0)) for (n,c) rows, one column at a time."""
    return (np.array([V[:, j].min() for j in range(V.shape[1])], V.dtype),
            np.array([V[:, j].max() for j in range(V.shape[1])], V.dtype))


def face_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unnormalised normals (p1 − p0) × (p2 − p0) of faces F (m,3) over positions V (n,3), in V's dtype,
    with np.cross's arithmetic. float32 and float64 positions take one compiled pass (`face_passes.normals`:
    on 1.4 M faces the whole-array expressions gather (m,3) coordinates three times and make a dozen
    temporaries); other dtypes take those expressions, in blocks of faces."""
    if isinstance(V, np.ndarray) and V.dtype in (np.float32, np.float64) and np.asarray(F).dtype.kind in "iu":
        from .face_passes import normals  # numba: imported when first used

        return normals(V, np.asarray(F))
    if len(F) > _NORMAL_ROWS:
        out = np.empty((len(F), 3), V.dtype)
        for s in range(0, len(F), _NORMAL_ROWS):
            out[s:s + _NORMAL_ROWS] = face_normals(V, F[s:s + _NORMAL_ROWS])
        return out
    c = [np.take(V[:, i], F) for i in range(3)]  # (m,3) per coordinate
    u = [ci[:, 1] - ci[:, 0] for ci in c]
    w = [ci[:, 2] - ci[:, 0] for ci in c]
    return np.stack([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]], 1)


_NORMAL_ROWS = 1 << 19  # faces per block of `face_normals`


def face_stats(V: np.ndarray, F: np.ndarray):
    """Which faces F (m,3) over V (n,3) have a non-zero area (m,) bool, and the mean area and mean squared
    edge length of those faces (float64; numpy's sums do not depend on the number of threads). The per-face
    values come from one compiled pass (`face_passes.face_rows`), in V's dtype (float32 or float64; others as
    float64)."""
    from .face_passes import face_rows  # numba: imported when first used

    V = np.ascontiguousarray(V)
    if V.dtype not in (np.float32, np.float64):
        V = V.astype(np.float64)
    nz, area, e2 = face_rows(V, np.ascontiguousarray(F, np.int64), V.dtype.type(0.5))
    k = max(int(np.count_nonzero(nz)), 1)
    return nz, float(np.sum(area, dtype=np.float64) / k), float(np.sum(np.compress(nz, e2), dtype=np.float64) / (3 * k))


_libc = None


def release_free_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``; elsewhere nothing).

    Between the stages of a large run: a round's arrays under glibc's mapping threshold (which rises to
    32 MB once a larger array is freed) come from the heap, and their pages stay resident after they
    are freed, so the next stage's peak sat on the last one's garbage (a 5.5 M-face run: about 0.1 GiB)."""
    global _libc
    if _libc is None:
        try:
            import ctypes

            _libc = ctypes.CDLL("libc.so.6")
            _libc.malloc_trim  # noqa: B018 (glibc only)
        except (OSError, AttributeError):
            _libc = False
    if _libc:
        _libc.malloc_trim(0)


def box_diagonal(lo, hi) -> float:
    """The length of a bounding box's diagonal, ``hi - lo`` (3,): the squares summed left to right, the same
    bits on every CPU. Not ``np.linalg.norm``: on a 1-D array it is BLAS's dot product, whose kernel (and so
    its last bit) changes with the CPU, and every distance relative to the diagonal would change with it."""
    d = (np.asarray(hi, np.float64) - np.asarray(lo, np.float64)).tolist()
    return math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
