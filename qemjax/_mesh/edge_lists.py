"""`topology.edge_table` compiled: the edges and the boundary from one sort, without its large temporaries.

numpy's version made the (3m,2) half-edges, their keys, the packed keys and a sorted copy: on armadillo ×16
(4.15 M half-edges) arrays of 33-66 MB each, which glibc maps afresh and the machine faults in page by page
on every run. Here the packed keys are written straight from the faces, grouped by their smaller vertex
and each group sorted (`sorted_keys`), and one pass over them gives the tables. The outputs are
`topology.edge_table`'s, bit for bit (tests/test_topology.py).

Also the vertex degrees and a mask's endpoints (`degrees`, `endpoints`: numpy's bincount and scatter,
without their copies of the pairs).
"""
from __future__ import annotations

import numpy as np

from .compiled import njit


@njit(cache=True, nogil=True)
def sorted_keys(F, n, bits):
    """(3m,) int64, sorted: each half-edge (F[f,c], F[f,(c+1)%3]) as (min·n + max) << bits | its index 3f + c.
    Written grouped by the smaller vertex (a counting sort), then each group sorted in place: the groups hold
    a vertex's few edges, so this costs about two passes over the faces, where a sort of all the keys took
    several times longer (`np.sort` on 64-bit keys is a comparison sort). The keys are distinct, so the
    order is the one any sort gives."""
    m = F.shape[0]
    start = np.zeros(n + 1, np.int64)
    for f in range(m):
        for c in range(3):
            a, b = F[f, c], F[f, (c + 1) % 3]
            start[(a if a < b else b) + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:n].copy()
    out = np.empty(3 * m, np.int64)
    for f in range(m):
        for c in range(3):
            a, b = np.int64(F[f, c]), np.int64(F[f, (c + 1) % 3])
            lo, hi = (a, b) if a < b else (b, a)
            out[fill[lo]] = ((lo * n + hi) << bits) | (3 * f + c)
            fill[lo] += 1
    for v in range(n):
        s, e = start[v], start[v + 1]
        if e - s > 32:  # a vertex of many edges (a fan's apex): no insertion sort's square
            out[s:e] = np.sort(out[s:e])
            continue
        for i in range(s + 1, e):
            x = out[i]
            j = i - 1
            while j >= s and out[j] > x:
                out[j + 1] = out[j]
                j -= 1
            out[j + 1] = x
    return out


@njit(cache=True, nogil=True)
def tables(packed, F, n, bits):
    """From the sorted packed keys: (E (k,2) in F's dtype, u < v, sorted; face counts (k,) int64; the boundary
    half-edges (B,2) as directed in their face; their faces (B,) int64)."""
    h = len(packed)
    mask = (np.int64(1) << bits) - 1
    k = 0
    B = 0
    i = 0
    while i < h:  # count the edges and the single ones
        key = packed[i] >> bits
        j = i + 1
        while j < h and (packed[j] >> bits) == key:
            j += 1
        k += 1
        B += j - i == 1
        i = j
    E = np.empty((k, 2), F.dtype)
    counts = np.empty(k, np.int64)
    he = np.empty((B, 2), F.dtype)
    face = np.empty(B, np.int64)
    k = B = 0
    i = 0
    while i < h:
        key = packed[i] >> bits
        j = i + 1
        while j < h and (packed[j] >> bits) == key:
            j += 1
        E[k, 0], E[k, 1] = key // n, key % n
        counts[k] = j - i
        k += 1
        if j - i == 1:
            t = packed[i] & mask
            f, c = t // 3, t % 3
            he[B, 0], he[B, 1] = F[f, c], F[f, (c + 1) % 3]
            face[B] = f
            B += 1
        i = j
    return E, counts, he, face


@njit(cache=True, nogil=True)
def degrees(E, n):
    """(n,) int64: how many rows of E (k,2) hold each vertex (``np.bincount(E.reshape(-1), minlength=n)``,
    without numpy's intp copy of E). Rows must hold vertices 0..n-1."""
    deg = np.zeros(n, np.int64)
    for i in range(E.shape[0]):
        deg[E[i, 0]] += 1
        deg[E[i, 1]] += 1
    return deg


@njit(cache=True, nogil=True)
def endpoints(E, mask, n):
    """(n,) bool: the vertices of the rows of E (k,2) where ``mask`` (k,) holds, without a branch (the
    mask follows no pattern)."""
    v = np.zeros(n, np.bool_)
    for i in range(E.shape[0]):
        m = mask[i]
        v[E[i, 0]] |= m
        v[E[i, 1]] |= m
    return v
