"""The numpy idioms in qemjax/_arrays.py against plain fancy indexing."""
from __future__ import annotations

import numpy as np
import pytest

from qemjax._arrays import any_at, keep_rows, take_rows

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
