"""The device calls of both schedulers: a cost model's price and merge of pairs, a round's merge, row update
and next price as one call, and the flip test, each started asynchronously and padded to fixed shapes so
that a run compiles a handful of kernels; the settings copied to the device once."""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._costs import ring
from .._kernels import flips, kernel
from .._kernels.batching import DTYPE, chunk_size, chunks, pad_rows, piece_sizes
from .._kernels.host import to_host

RING_BLOCK = 1 << 16  # ring models gather the faces of this many pairs at a time (bounded memory)


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


def on_device(params: dict) -> dict:
    """A kernel's settings with each numpy value (0-d arrays, `CostModel.kernel_params`) copied to the device
    once, so that a run's hundreds of kernel calls pass device arrays instead of copying them each time.
    Same dtypes and shapes: the same compiled kernels, the same results. A small value's copy is kept for
    the next run with the same value (device arrays are immutable): the copies cost a small run as much
    as a round."""
    return {k: _device_value(np.asarray(v)) if isinstance(v, (np.ndarray, np.generic)) else v
            for k, v in params.items()}


_DEVICE_VALUES: dict = {}  # (dtype, shape, bytes, default device, x64) -> the device copy of a small setting


def _device_value(v: np.ndarray):
    """``jnp.asarray(v)``; for at most 16 values, the copy made for the same value before."""
    if v.size > 16:
        return jnp.asarray(v)
    # (the device dtype follows x64 mode too: float64 settings are float32 on the device without it)
    key = (v.dtype.str, v.shape, v.tobytes(), str(jax.config.jax_default_device), bool(jax.config.jax_enable_x64))
    d = _DEVICE_VALUES.get(key)
    if d is None:
        if len(_DEVICE_VALUES) >= 4096:  # a sweep over many values: start again rather than grow
            _DEVICE_VALUES.clear()
        d = _DEVICE_VALUES[key] = jnp.asarray(v)
    return d


def _params(params, pairs: np.ndarray) -> dict:
    """The params for a kernel call on ``pairs``: as given, or a `PerCopy`'s per pair."""
    return params.at(pairs) if isinstance(params, PerCopy) else params


def _priced(K: int, rows: int, dtype=DTYPE) -> Priced:
    """A `Priced` of K pairs, zeros, to fill from the kernels' (rows, k) outputs (`_put`)."""
    return Priced(np.zeros((K, 3), dtype), np.zeros(K, dtype), np.zeros(K, np.int8), np.zeros((rows - 5, K), dtype))


def _put(pr: Priced, at, o: np.ndarray) -> None:
    """Write a kernel output o (rows, k): [x (3), cost, branch, parts...] per column, into pairs ``at`` (a
    slice or k indices) of ``pr``."""
    pr.x[at], pr.cost[at] = o[:3].T, o[3]
    pr.branch[at], pr.parts[:, at] = o[4].astype(np.int8), o[5:]


def start_price(model, VSd, P: np.ndarray, params: dict, faces=None, pad: int = 0, at_kept: bool = False,
                size: int | None = None):
    """Start pricing pairs P (K,2) with ``model`` over device rows VSd (kernel calls are asynchronous).
    Returns a function that waits for the kernels and gives a `Priced`. Ring models (``uses_ring``) also
    need the `FaceLists` ``faces`` and a ``pad`` vertex row (zeros) for ring padding. ``at_kept``: price
    each pair contracted onto its kept vertex (``model.price_at_kept``; locked vertices, `qemjax._schedulers.locks`).
    ``size``: one fixed piece shape (else `chunks`' shapes)."""
    rows = 5 + len(model.parts)
    price = model.price_at_kept if at_kept else model.price
    if not model.uses_ring:  # (no pairs: no call, whose one piece would price padding alone)
        return _joined([price(VSd, part, _params(params, part)) for _, part in chunks(P.astype(np.int32), size=size)]
                       if len(P) else [], len(P), rows)
    pieces = []  # (indices into P, device output)
    for b0 in range(0, len(P), RING_BLOCK):
        block = P[b0:b0 + RING_BLOCK]
        for idx, rg in ring.gather_groups(faces, block, pad, model.ring_dead):
            parts = zip(chunks(block[idx].astype(np.int32), size=size), chunks(rg.corners, fill=pad, size=size),
                        chunks(rg.mask, size=size))
            for (s, pp), (_, cc), (_, mm) in parts:
                sel = idx[s:s + len(pp)]
                pieces.append((b0 + sel, price(VSd, pp, _params(params, pp), ring.Rings(cc, mm))))

    def ring_result():
        pr = _priced(len(P), rows)
        for sel, o in pieces:
            _put(pr, sel, to_host(o)[:, : len(sel)])
        return pr
    return ring_result


def _joined(outs: list, K: int, rows: int):
    """A function that waits for the price pieces ``outs`` (device (rows, k) arrays, in order) and gives the
    `Priced` of their first K columns. (Called once) each piece goes straight into its four arrays and
    its device buffer is let go as it is copied: no (rows, K) matrix held by the views of cost and parts
    (a 5.5 M-face mesh's first round: 166 MB less held, and no second copy of the pieces while they are
    joined)."""
    def result():
        pr = _priced(K, rows, to_host(outs[0]).dtype if outs else DTYPE)
        s = 0
        for i in range(len(outs)):
            o = to_host(outs[i])[:, : K - s]
            outs[i] = None
            _put(pr, slice(s, s + o.shape[1]), o)
            s += o.shape[1]
        return pr
    return result


def fuses(model) -> bool:
    """Whether a round's merge, row update and next price can go to the device as one call (`start_step`):
    a model whose price reads only the pair's two rows, with no refresh between the merge and the price,
    and whose merge and price are static functions of arrays (``merge_kernel``, ``price_kernel``: the call
    is compiled once for them, whatever the settings)."""
    return (model.support == "pair" and not model.uses_ring and model.refresh is None
            and getattr(model, "merge_kernel", None) is not None and getattr(model, "price_kernel", None) is not None)


@kernel(static_argnums=(0, 1), donate_argnums=2)
def _step(merge, price, VS, rows_at, P, x, merge_params, Pn, price_params):
    """`start_step`'s one call: the merged state of pairs P at x (``merge``, a model's ``merge_kernel``),
    written with x into rows ``rows_at`` of VS (indices past the end are padding: dropped), then the price
    of pairs Pn on the new rows (``price``, its ``price_kernel``)."""
    merged = merge(VS, P, x, merge_params)
    VS = VS.at[rows_at].set(jnp.concatenate([x.astype(VS.dtype), merged.astype(VS.dtype)], 1), mode="drop")
    return VS, merged, price(VS, Pn, price_params)


def start_step(model, VSd, P: np.ndarray, x: np.ndarray, Pn: np.ndarray, params, size: int, price_size: int,
               raw: bool = False, kept: np.ndarray | None = None):
    """A round's device work in one call (`fuses`): contract pairs P (K,2) at x (K,3), i.e. write
    [x, merged state] into their kept vertices' rows, and start pricing the next round's stale pairs Pn
    (J,2) on the new rows. The merges go in pieces of ``size`` rows, one call each, and the first
    ``price_size`` stale pairs ride with the last one (the calls before it price padding); the other stale
    pairs go in `chunks`' shapes as calls of their own. On a small mesh that is one call a round, and a run compiles
    one `_step` per size. A round's kept and removed vertices are all distinct, so the merges read the
    same rows whatever their order, and the values are those of `start_merge`, `set_rows` and
    `start_price`. Returns (the new device rows (VSd is donated), a function giving the (K, width) merged
    states, and one giving the `Priced` of Pn, or with ``raw`` its (5 + p, J) columns as the kernel gives
    them, as `step_one` does). ``kept`` (k,2): pairs also priced at their kept vertex in the last piece's
    call (`kept_fuses`; locked vertices), then a fourth function gives their `Priced`."""
    Pi, Pn = P.astype(np.int32), Pn.astype(np.int32)
    pieces = list(zip(chunks(Pi, size=size), chunks(x, size=size), chunks(Pi[:, 0], fill=len(VSd), size=size)))
    head, idle = pad_rows(Pn[:price_size], price_size), np.zeros((price_size, 2), np.int32)
    merged = []
    for i, ((_, pp), (_, xx), (_, ii)) in enumerate(pieces):
        last = i == len(pieces) - 1
        qq = head if last else idle
        if last and kept is not None:
            VSd, m, first, at = _step_with(model, VSd, ii, pp, xx, qq, params, kept)
        else:
            VSd, m, first = _step(model.merge_kernel, model.price_kernel, VSd, ii, pp, xx, _params(params, pp), qq,
                                  _params(params, qq))
        merged.append(m)
    outs = [first] + ([model.price(VSd, part, _params(params, part)) for _, part in chunks(Pn[price_size:])]
                      if len(Pn) > price_size else [])
    priced = ((lambda: np.concatenate([to_host(o) for o in outs], 1)[:, : len(Pn)]) if raw
              else _joined(outs, len(Pn), 5 + len(model.parts)))
    out = VSd, lambda: np.concatenate([to_host(o) for o in merged])[: len(P)], priced
    return out if kept is None else (*out, at)


def step_one(model, VSd, rows_at: np.ndarray, P: np.ndarray, x: np.ndarray, Pn: np.ndarray, params, K: int,
             kept: np.ndarray | None = None):
    """`start_step` for a round that one piece holds, its inputs already padded to the piece's shapes
    (`glue.contract`): the merges of pairs P at x into rows ``rows_at`` (padding past the end),
    and the price of the stale pairs Pn. Returns (the new device rows (VSd is donated), a function giving
    the K pairs' (K, width) merged states, and one giving the raw price, (5 + p, len(Pn)) as the kernel
    gives it), and with ``kept`` as `start_step` has it, a fourth."""
    if kept is not None:
        VSd, merged, priced, at = _step_with(model, VSd, rows_at, P, x, Pn, params, kept)
        return VSd, (lambda: to_host(merged)[:K]), (lambda: to_host(priced)), at
    VSd, merged, priced = _step(model.merge_kernel, model.price_kernel, VSd, rows_at, P, x, _params(params, P), Pn,
                                _params(params, Pn))
    return VSd, (lambda: to_host(merged)[:K]), (lambda: to_host(priced))


def kept_fuses(model) -> bool:
    """Whether a round's one device call (`start_step`, `step_one`) can also price pairs at their kept vertex
    (``kept``: locked vertices, `qemjax._schedulers.locks`): a model that `fuses` whose ``price_at_kept`` is
    its static ``at_kept_kernel``, so the values are those of `start_price` with ``at_kept``, and that does not
    price them on the host (``cost_at``)."""
    from .._costs.base import CostModel

    return (fuses(model) and getattr(model, "at_kept_kernel", None) is not None
            and getattr(model, "cost_at", None) is None and type(model).price_at_kept is CostModel.price_at_kept)


@kernel(static_argnums=(0, 1, 2), donate_argnums=3)
def _step_kept(merge, price, at_kept, VS, rows_at, P, x, merge_params, Pn, price_params, Pk, kept_params):
    """`_step`, and the price of pairs Pk at their kept vertex (``at_kept``, a model's ``at_kept_kernel``) on
    the new rows."""
    VS, merged, priced = _step(merge, price, VS, rows_at, P, x, merge_params, Pn, price_params)
    return VS, merged, priced, at_kept(VS, Pk, kept_params)


def _step_with(model, VSd, rows_at, P, x, Pn, params, kept):
    """`_step` with the pairs ``kept`` (k,2) priced at their kept vertex, padded to `chunk_size` (a round's are
    few: mostly the smallest shape). Returns `_step`'s three and a function giving their `Priced`."""
    k = len(kept)
    Pk = pad_rows(np.asarray(kept, np.int32), chunk_size(k))
    VSd, merged, priced, at = _step_kept(model.merge_kernel, model.price_kernel, model.at_kept_kernel, VSd, rows_at,
                                         P, x, _params(params, P), Pn, _params(params, Pn), Pk, _params(params, Pk))
    return VSd, merged, priced, _joined([at], k, 5 + len(model.parts))


def start_merge(model, VSd, P: np.ndarray, x: np.ndarray, params: dict, size: int | None = None):
    """Start computing the (K, width) state of the kept vertices of pairs P (K,2) contracted to x (K,3);
    returns a function that waits for it. ``size``: one fixed piece shape (else `chunks`' shapes)."""
    outs = [model.merge(VSd, pp, xx, _params(params, pp)) for (_, pp), (_, xx)
            in zip(chunks(P.astype(np.int32), size=size), chunks(x, size=size))]
    return lambda: np.concatenate([to_host(o) for o in outs])[: len(P)]


def start_flips(VQd, N0d, F, fids, corner, owner, x, S, cos_max, min_quality=None):
    """Start the flip test: does moving the given corner of faces F (k,3) to x[owner] flip any of them?
    fids (k,): the input faces they continue (reference normals N0d[fids]). Fixed-size chunks; ``min_quality``:
    the quality guard's bound (None: off).
    Returns a function that waits for the kernel and gives (S,) bool per pair.

    The inputs are padded once to the pieces' total (`piece_sizes`; zeros, as `chunks` pads) and each
    piece is a view: a pass tests a few dozen faces on a small mesh, where padding each array per piece
    cost half as much as the kernel."""
    cos_max = cos_max if isinstance(cos_max, jax.Array) else np.asarray(cos_max, DTYPE)
    if min_quality is not None and not isinstance(min_quality, jax.Array):  # (None: the guard is off)
        min_quality = np.asarray(min_quality, DTYPE)
    k = len(F)
    sizes = piece_sizes(k)
    total = sum(sizes)
    ints = np.zeros((3, total), np.int32)  # faces' first corner is padded as the other columns: zeros
    Fp = np.zeros((total, 3), F.dtype)
    Fp[:k] = F
    ints[0, :k] = fids
    ints[1, :k] = corner
    xp = np.zeros((total, 3), x.dtype)
    np.take(x, owner, axis=0, out=xp[:k])
    outs, start = [], 0
    for size in sizes:
        end = start + size
        outs.append(flips.face_flips_at(VQd, N0d, Fp[start:end], ints[0, start:end], ints[1, start:end],
                                        xp[start:end], cos_max, min_quality))
        start = end

    def result():
        bad = np.concatenate([to_host(o) for o in outs])[:k] if len(outs) > 1 else to_host(outs[0])[:k]
        res = np.zeros(S, bool)
        res[owner[bad]] = True
        return res
    return result
