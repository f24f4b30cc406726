"""Quantiles of distances: observed values, optionally weighted, for the measured distance and the metrics."""
from __future__ import annotations

import numpy as np


def quantiles(d: np.ndarray, qs, weights: np.ndarray | None = None) -> list[float]:
    """The q-quantiles (0 <= q <= 1) of the values d: the smallest value with at least a fraction q of them
    (of their total weight, with ``weights``) at or below it, an observed value, never interpolated (so
    the 1.0 quantile is the maximum and a bound on it is a bound on the samples)."""
    order = np.argsort(d, kind="stable")
    ds = np.asarray(d, np.float64)[order]
    cw = np.cumsum(np.ones(len(ds)) if weights is None else np.asarray(weights, np.float64)[order])
    idx = np.searchsorted(cw, np.asarray(qs, np.float64) * cw[-1], side="left")
    return [float(ds[min(i, len(ds) - 1)]) for i in idx]
