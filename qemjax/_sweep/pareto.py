"""The Pareto front of a sweep table: the cells no other cell beats on both of two costs."""
from __future__ import annotations

import numpy as np


def pareto_front(table, x: str = "faces_out", y: str = "rms_rel"):
    """The rows of ``table`` (a DataFrame, e.g. from `qemjax.sweep`) that no other row dominates, both
    columns being costs to minimise: row a dominates row b when ``a[x] <= b[x]`` and ``a[y] <= b[y]``
    with one of them strictly less. Sorted by ``x`` (so ``y`` falls along the front); of rows with equal
    (x, y) the first is kept. Rows where either value is NaN or None (e.g. failed cells) are left out; a
    value that is not a number (a string such as "n/a") is refused, with its column and row.

    Sort by x, then y; walk in that order and keep a row when its y is below every y kept so far: any
    row before it has x ≤ its x, so it is dominated exactly when one of them has a smaller or equal y.
    """
    for col in (x, y):
        if col not in table:
            raise ValueError(f"pareto_front: no column {col!r} in the table (columns: {list(table.columns)})")
    values = table[[x, y]].apply(_costs)
    ok = values.notna().all(axis=1).to_numpy()
    xs, ys = values[x].to_numpy()[ok], values[y].to_numpy()[ok]
    order = np.lexsort((ys, xs))  # by x, then y
    keep, best = [], None  # the smallest y kept so far (None: no row yet, so that a y of inf is kept first)
    for i in order:
        if best is None or ys[i] < best:
            keep.append(i)
            best = ys[i]
    return table[ok].iloc[keep]


def _costs(column):
    """``column`` as float64; ValueError naming the column, the row and the value where one is neither a
    number nor missing (None, NaN: those rows are left out), not pandas' words for the first it met."""
    try:
        return column.astype(np.float64)
    except (TypeError, ValueError):
        pass
    import pandas as pd

    out = np.full(len(column), np.nan)
    for i, (label, v) in enumerate(column.items()):
        if v is None or (np.ndim(v) == 0 and pd.isna(v)):
            continue
        try:
            out[i] = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"pareto_front: column {column.name!r} holds {v!r} in row {label!r}, not a number "
                             "(a missing value is NaN or None: such rows are left out)") from None
    return pd.Series(out, index=column.index, name=column.name)
