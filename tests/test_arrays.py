"""The numpy idioms in qemjax/_mesh/arrays.py against plain fancy indexing."""
from __future__ import annotations

import numpy as np
import pytest

from qemjax._mesh.arrays import any_at, column_bounds, keep_rows, put_rows, sorted_triples, take_rows
from qemjax._mesh.arrays import face_normals

rng = np.random.default_rng(3)


@pytest.mark.parametrize("width", [2, 3])
@pytest.mark.parametrize("rows", [0, 1, 1000])
def test_any_at_matches_fancy_indexing(width, rows):
    mask = rng.random(50) < 0.2
    idx = rng.integers(0, 50, (rows, width)).astype(np.int32)
    got = any_at(mask, idx)
    assert got.dtype == bool and got.shape == (rows,)
    assert np.array_equal(got, mask[idx].any(1) if rows else np.zeros(0, bool))


def test_take_and_keep_rows():
    A = rng.integers(0, 100, (200, 2)).astype(np.int32)
    idx = rng.integers(0, 200, 50)
    keep = rng.random(200) < 0.5
    assert np.array_equal(take_rows(A, idx), A[idx])
    assert np.array_equal(keep_rows(A, keep), A[keep])


@pytest.mark.parametrize("dtype,width", [(np.float32, 3), (np.float32, 13), (np.int64, 2)])
def test_put_rows_matches_fancy_assignment(dtype, width):
    A = rng.random((300, width)).astype(dtype)
    idx = rng.choice(300, 80, replace=False)
    rows = rng.random((80, width))  # float64: converted to A's dtype, as A[idx] = rows does
    want = A.copy()
    want[idx] = rows
    put_rows(A, idx, rows)
    assert np.array_equal(A, want)


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_sorted_triples_matches_sort(dtype):
    F = rng.integers(0, 7, (500, 3)).astype(dtype)  # many repeated indices within rows
    got = sorted_triples(F)
    assert got.dtype == F.dtype and np.array_equal(got, np.sort(F, axis=1))


def test_column_bounds_match_min_max():
    V = rng.standard_normal((300, 3)) * [1.0, 100.0, 1e-3]
    lo, hi = column_bounds(V)
    assert np.array_equal(lo, V.min(0)) and np.array_equal(hi, V.max(0))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.float16])
@pytest.mark.parametrize("fdtype", [np.int32, np.int64])
def test_face_normals_match_cross(dtype, fdtype):
    """Compiled (float32, float64) and numpy (others) normals: np.cross's values bit for bit, on
    contiguous rows and on a view of wider rows (as the scheduler's VQ[:, :3])."""
    V = rng.standard_normal((100, 5)).astype(dtype)
    F = rng.integers(0, 100, (400, 3)).astype(fdtype)
    for W in (np.ascontiguousarray(V[:, :3]), V[:, 1:4]):
        p = W[F]
        want = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        got = face_normals(W, F)
        assert got.dtype == dtype and got.shape == (400, 3)
        assert np.array_equal(got.view(np.uint8), want.view(np.uint8))  # the same arithmetic, bit for bit


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", range(3))
def test_face_stats_are_numpys_whole_array_arithmetic_bit_for_bit(seed, dtype):
    """`arrays.face_stats` (per-face values compiled: `_mesh.face_passes`) against the whole-array numpy
    expressions it replaced, in float64 and in float32: the same non-zero mask and the same bits of both
    means, with zero-area faces (repeated corners, collinear corners) among them."""
    from qemjax._mesh.arrays import face_stats

    rng = np.random.default_rng(seed)
    V = (rng.normal(size=(400, 3)) * 10.0 ** rng.uniform(-20, 20)).astype(dtype)
    F = rng.integers(0, 400, size=(3000, 3))
    F[:50, 1] = F[:50, 0]
    V[:20] = V[20:40] * 0.5 + V[40:60] * 0.5  # ... and some exactly midway: collinear corners
    F[50:70] = np.stack([np.arange(20), np.arange(20, 40), np.arange(40, 60)], 1)
    c = [np.take(V[:, i], F) for i in range(3)]
    d = [[ci[:, (j + 1) % 3] - ci[:, j] for ci in c] for j in range(3)]
    u, w = d[0], [-x for x in d[2]]
    n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
    nz = (n[0] != 0) | (n[1] != 0) | (n[2] != 0)
    area = 0.5 * np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    e2 = sum(x * x for ej in d for x in ej)
    k = max(int(np.count_nonzero(nz)), 1)
    want = (nz, float(np.sum(area, dtype=np.float64) / k), float(np.sum(np.compress(nz, e2), dtype=np.float64) / (3 * k)))
    got = face_stats(V, F)
    np.testing.assert_array_equal(got[0], want[0])
    assert not got[0][:50].any()
    assert got[1:] == want[1:]


def test_vertex_runs_are_the_incidence_matrix_rows():
    """`face_passes.vertex_runs` against scipy's COO -> CSR conversion of the vertex-face incidence (what
    `FaceLists` used): each vertex's faces in face order, counts and offsets, a face that repeats a vertex
    listed once there; an index out of range fails."""
    import scipy.sparse

    from qemjax._mesh.face_passes import vertex_runs

    rng = np.random.default_rng(3)
    for n, m in ((1, 0), (5, 3), (40, 70), (300, 900), (6, 50)):
        F = np.array([rng.choice(n, 3, replace=False) for _ in range(m)], np.int32).reshape(-1, 3) if n >= 3 \
            else np.zeros((0, 3), np.int32)
        if n == 6:  # faces that repeat a corner (non-manifold mode keeps them): listed once at it
            F[::3, 2] = F[::3, 0]
            F[1::5, 1] = F[1::5, 2]
            F[2::7] = F[2::7, :1]
        inc = scipy.sparse.csr_matrix(
            (np.ones(3 * m, np.int8), (F.reshape(-1), np.repeat(np.arange(m, dtype=np.int32), 3))),
            shape=(n, max(m, 1)))
        cnt, off, pool, end = vertex_runs(F, n)
        assert np.array_equal(cnt, np.diff(inc.indptr)) and cnt.dtype == np.int64
        assert np.array_equal(off, inc.indptr[:-1]) and off.dtype == np.int64
        assert end == len(inc.indices) and np.array_equal(pool[:end], inc.indices) and pool.dtype == np.int32
        assert len(pool) == 6 * m + 64
    with pytest.raises(ValueError, match="out of range"):
        vertex_runs(np.array([[0, 1, 5]], np.int32), 5)


@pytest.mark.parametrize("dtype,shape", [(np.float32, (500, 3)), (np.float32, (500,)), (np.int8, (500,)),
                                         (np.float32, (500, 4)), (np.float32, (500, 0)), (np.bool_, (500,))])
def test_compact_in_place_is_take(dtype, shape):
    """`row_compact.compact`: numpy's take for ascending indices, as a view of the array's own first rows; a
    read-only array is gathered into a new one and left as it was."""
    from qemjax._mesh import row_compact

    A = (rng.standard_normal(shape) * 100).astype(dtype)
    for idx in (np.flatnonzero(rng.random(500) < 0.7), np.arange(500), np.zeros(0, np.int64)):
        B = A.copy()
        want = B.take(idx, axis=0)
        got = row_compact.compact(B, idx)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert np.shares_memory(got, B) or not got.size
        assert np.array_equal(got.view(np.uint8), want.view(np.uint8))
    R = A.copy()
    R.flags.writeable = False
    idx = np.flatnonzero(rng.random(500) < 0.5)
    got = row_compact.compact(R, idx)
    assert not np.shares_memory(got, R) and np.array_equal(got, A.take(idx, axis=0)) and np.array_equal(R, A)
