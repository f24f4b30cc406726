"""qemjax.pareto_front against a brute-force dominance check."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import qemjax


def brute_front(df, x, y):
    """Indices of rows no other row dominates (first of equal points), by the definition."""
    pts = df[[x, y]].to_numpy(np.float64)
    keep = []
    for i, (a, b) in enumerate(pts):
        if np.isnan(a) or np.isnan(b):
            continue
        dominated = any((c <= a and d <= b and (c < a or d < b)) or (c == a and d == b and j < i)
                        for j, (c, d) in enumerate(pts) if j != i and not (np.isnan(c) or np.isnan(d)))
        if not dominated:
            keep.append(df.index[i])
    return keep


@pytest.mark.parametrize("seed", range(5))
def test_front_is_the_non_dominated_rows(seed):
    rng = np.random.default_rng(seed)
    n = 60
    df = pd.DataFrame({"faces_out": rng.integers(10, 30, n),  # many ties in x
                       "rms_rel": rng.integers(0, 12, n) / 10.0, "other": np.arange(n)})
    df.loc[rng.choice(n, 5, replace=False), "rms_rel"] = np.nan  # failed cells
    front = qemjax.pareto_front(df)
    assert sorted(front.index) == sorted(brute_front(df, "faces_out", "rms_rel"))
    assert np.all(np.diff(front["faces_out"]) > 0) and np.all(np.diff(front["rms_rel"]) < 0)
    assert list(front.columns) == list(df.columns)


def test_a_row_of_infinite_cost_is_on_the_front_when_nothing_beats_it():
    df = pd.DataFrame({"faces_out": [3.0, 4.0, 5.0, 6.0], "rms_rel": [np.inf, np.inf, 2.0, 2.0]})
    assert list(qemjax.pareto_front(df).index) == [0, 2] == brute_front(df, "faces_out", "rms_rel")


def test_front_other_columns_and_bad_column():
    df = pd.DataFrame({"a": [1, 2, 3, 1], "b": [3.0, 1.0, 0.5, 4.0]})
    assert list(qemjax.pareto_front(df, "a", "b").index) == [0, 1, 2]
    assert list(qemjax.pareto_front(df, "b", "a").index) == [2, 1, 0]
    with pytest.raises(ValueError, match="no column 'rms'"):
        qemjax.pareto_front(df, "a", "rms")


def test_a_cost_that_is_not_a_number_is_named():
    """A column holding "n/a" failed in pandas' words (could not convert string to float): the error names
    the column, the row and the value; missing values (None, NaN) still leave their rows out."""
    df = pd.DataFrame({"faces_out": [10, 20, 30, 40], "rms_rel": [0.1, "n/a", 0.05, 0.2]}, index=list("abcd"))
    with pytest.raises(ValueError, match=r"^pareto_front: column 'rms_rel' holds 'n/a' in row 'b', not a number"):
        qemjax.pareto_front(df)
    df.loc["b", "rms_rel"] = None
    assert list(qemjax.pareto_front(df).index) == ["a", "c"] == brute_front(df.astype(float), "faces_out", "rms_rel")
