"""The Pareto front of a sweep table: the cells no other cell beats on both of two costs."""
from __future__ import annotations

import numpy as np


def pareto_front(table, x: str = "faces_out", y: str = "rms_rel"):
    """The rows of ``table`` (a DataFrame, e.g. from `qemjax.sweep`) that no other row dominates, both
    columns being costs to minimise: row a dominates row b when ``a[x] <= b[x]`` and ``a[y] <= b[y]``
    with one of them strictly less. Sorted by ``x`` (so ``y`` falls along the front); of rows with equal
    (x, y) the first is kept. Rows where either value is NaN (e.g. failed cells) are left out.

    Sort by x, then y; walk in that order and keep a row when its y is below every y kept so far: any
    row before it has x ≤ its x, so it is dominated exactly when one of them has a smaller or equal y.
    """
    for col in (x, y):
        if col not in table:
            raise ValueError(f"pareto_front: no column {col!r} in the table (columns: {list(table.columns)})")
    values = table[[x, y]].apply(lambda c: c.astype(np.float64))
    ok = values.notna().all(axis=1).to_numpy()
    xs, ys = values[x].to_numpy()[ok], values[y].to_numpy()[ok]
    order = np.lexsort((ys, xs))  # by x, then y
    keep, best = [], None  # the smallest y kept so far (None: no row yet, so that a y of inf is kept first)
    for i in order:
        if best is None or ys[i] < best:
            keep.append(i)
            best = ys[i]
    return table[ok].iloc[keep]
