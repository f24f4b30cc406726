"""Pieces both schedulers share: the options, timing, and the batched kernel calls (a cost model's price
and merge, the flip test), padded to fixed shapes so that a run compiles a handful of kernels."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._mesh.arrays import face_normals as face_normals
from .._kernels.batching import DTYPE as DTYPE
from .._kernels.batching import bucket as bucket
from .._kernels.batching import chunk_size as chunk_size
from .._kernels.batching import chunks as chunks
from .._kernels.batching import pad_rows as pad_rows
from .._kernels.batching import set_rows as set_rows
from .._costs import ring
from .._kernels import flips
from .._options import Options as Options

RING_BLOCK = 1 << 16  # ring models gather the faces of this many pairs at a time (bounded memory)


class Timer:
    """Accumulates wall time per named stage (seconds, keys like ``kernels_s``)."""

    def __init__(self):
        self.t = {}

    def add(self, name, dt):
        self.t[name] = self.t.get(name, 0.0) + dt


class Priced(NamedTuple):
    """A model's price of K pairs: x (K,3) float32, cost (K,), branch (K,) int8, parts (p,K)."""

    x: np.ndarray
    cost: np.ndarray
    branch: np.ndarray
    parts: np.ndarray


class PerCopy(NamedTuple):
    """Kernel params of a batched run (`batched`): ``values`` name -> (C,) array, one value per copy, and
    ``copy`` (n,) int32, each vertex's copy. A kernel gets them per pair, as (K,) arrays."""

    values: dict
    copy: np.ndarray

    def at(self, pairs: np.ndarray) -> dict:
        c = np.take(self.copy, pairs[:, 0], mode="clip")
        return {k: np.take(v, c) for k, v in self.values.items()}


def _params(params, pairs: np.ndarray) -> dict:
    """The params for a kernel call on ``pairs``: as given, or a `PerCopy`'s per pair."""
    return params.at(pairs) if isinstance(params, PerCopy) else params


def _unpack(out: np.ndarray) -> Priced:
    return Priced(np.ascontiguousarray(out[:3].T), out[3], out[4].astype(np.int8), out[5:])


def start_price(model, VSd, P: np.ndarray, params: dict, faces=None, pad: int = 0):
    """Start pricing pairs P (K,2) with ``model`` over device rows VSd (kernel calls are asynchronous).
    Returns a function that waits for the kernels and gives a `Priced`. Ring models (``uses_ring``) also
    need the `FaceLists` ``faces`` and a ``pad`` vertex row (zeros) for ring padding."""
    rows = 5 + len(model.parts)
    if not model.uses_ring:
        outs = [model.price(VSd, part, _params(params, part)) for _, part in chunks(P.astype(np.int32))]

        def result():
            out = np.concatenate([np.asarray(o) for o in outs], 1)[:, : len(P)] if outs else \
                np.zeros((rows, 0), DTYPE)
            return _unpack(out)
        return result
    pieces = []  # (indices into P, device output)
    for b0 in range(0, len(P), RING_BLOCK):
        block = P[b0:b0 + RING_BLOCK]
        for idx, rg in ring.gather_groups(faces, block, pad, model.ring_dead):
            parts = zip(chunks(block[idx].astype(np.int32)), chunks(rg.corners, fill=pad), chunks(rg.mask))
            for (s, pp), (_, cc), (_, mm) in parts:
                sel = idx[s:s + len(pp)]
                pieces.append((b0 + sel, model.price(VSd, pp, _params(params, pp), ring.Rings(cc, mm))))

    def ring_result():
        out = np.zeros((rows, len(P)), DTYPE)
        for sel, o in pieces:
            out[:, sel] = np.asarray(o)[:, : len(sel)]
        return _unpack(out)
    return ring_result


def start_merge(model, VSd, P: np.ndarray, x: np.ndarray, params: dict, size: int | None = None):
    """Start computing the (K, width) state of the kept vertices of pairs P (K,2) contracted to x (K,3);
    returns a function that waits for it. ``size``: one fixed piece shape (else `chunks`' shapes)."""
    outs = [model.merge(VSd, pp, xx, _params(params, pp)) for (_, pp), (_, xx)
            in zip(chunks(P.astype(np.int32), size=size), chunks(x, size=size))]
    return lambda: np.concatenate([np.asarray(o) for o in outs])[: len(P)]


def start_flips(VQd, N0d, F, fids, corner, owner, x, S, cos_max):
    """Start the flip test: does moving the given corner of faces F (k,3) to x[owner] flip any of them?
    fids (k,): the input faces they continue (reference normals N0d[fids]). Fixed-size chunks.
    Returns a function that waits for the kernel and gives (S,) bool per pair."""
    cos_max = np.asarray(cos_max, DTYPE)
    parts = zip(chunks(F), chunks(fids.astype(np.int32)), chunks(corner.astype(np.int32)),
                chunks(np.take(x, owner, axis=0)))
    outs = [flips.face_flips_at(VQd, N0d, ff, ii, kk, xx, cos_max)
            for (_, ff), (_, ii), (_, kk), (_, xx) in parts]

    def result():
        bad = np.concatenate([np.asarray(o) for o in outs])[: len(F)] if outs else np.zeros(0, bool)
        res = np.zeros(S, bool)
        res[owner[bad]] = True
        return res
    return result


def compact_output(V: np.ndarray, F: np.ndarray, alive_faces: np.ndarray):
    """Keep live faces and the vertices they use. Returns (V', F', kept vertex ids, kept face ids)."""
    fids = np.flatnonzero(alive_faces)
    F = F[fids]
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    ids = np.flatnonzero(used)
    newidx = np.cumsum(used) - 1
    return V[ids], newidx[F], ids, fids
