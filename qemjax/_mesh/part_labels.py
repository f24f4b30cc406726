"""Connected parts of a vertex graph, compiled (numba): a union-find over the pairs, then labels numbered
in the order of each part's lowest vertex, the numbering scipy's ``connected_components`` gives (a
search from each unlabelled vertex in turn), without building a sparse matrix (`topology.parts`). tests/test_topology.py compares the labels with
scipy's."""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, inline="always")
def _root(up, v):
    """v's part's representative, halving the path on the way."""
    while up[v] != v:
        up[v] = up[up[v]]
        v = up[v]
    return v


@njit(cache=True)
def labels(a, b, n):
    """(count, (n,) int64 labels) of the parts of the graph on n vertices with edges (a[i], b[i])."""
    up = np.arange(n)
    for i in range(len(a)):
        ra, rb = _root(up, a[i]), _root(up, b[i])
        if ra != rb:  # the lower vertex represents the union: any rule gives the same parts
            if ra < rb:
                up[rb] = ra
            else:
                up[ra] = rb
    label = np.full(n, -1, np.int64)
    count = 0
    for v in range(n):
        r = _root(up, v)
        if label[r] < 0:
            label[r] = count
            count += 1
        label[v] = label[r]
    return count, label
