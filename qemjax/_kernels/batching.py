"""Fixed batch shapes for the kernels: padding, bucketing and chunking (one compilation per shape).

Every batched kernel call goes through these helpers so that a run compiles a handful of shapes once,
whatever its number of rounds: pair batches use the three sizes of CHUNKS, other arrays a power-of-two
(or finer) bucket of their length.
"""
from __future__ import annotations

from .lazy import jit  # jax.jit made at the first call (`_kernels.lazy`)
import numpy as np

DTYPE = np.float32
MIN_BUCKET = 16
CHUNKS = (256, 4096, 1 << 16)  # batch shapes; larger batches are cut into pieces (`piece_sizes`)


def bucket(n: int, lo: int = MIN_BUCKET, steps: int = 1) -> int:
    """Padded capacity for n items: the next power of two (at least ``lo``), or with ``steps`` > 1 the
    next of ``steps`` evenly spaced sizes per octave (steps=4: ×1.25, ×1.5, ×1.75, ×2 of a power of two),
    for arrays whose padding costs arithmetic."""
    p = max(lo, 1 << max(0, int(n - 1).bit_length()))
    if steps > 1 and p > lo:
        half = p // 2
        step = max(1, half // steps)
        return min(p, half + -(-(n - half) // step) * step)
    return p


def chunk_size(n: int) -> int:
    """Batch shape for n rows: the smallest of CHUNKS that holds them (else the largest), so at most
    three shapes per kernel ever compile. The small ones serve the greedy scheduler's few-pair updates
    and the later rounds without computing mostly padding."""
    for size in CHUNKS:
        if n <= size:
            return size
    return CHUNKS[-1]


def pad_rows(a: np.ndarray, size: int, fill=0) -> np.ndarray:
    out = np.full((size,) + a.shape[1:], fill, dtype=a.dtype)
    out[: len(a)] = a
    return out


MAX_PIECES = 8  # a remainder takes up to this many pieces of a smaller shape instead of one padded larger


def piece_sizes(n: int) -> list[int]:
    """Shapes of the pieces that hold n rows: full pieces of the largest of CHUNKS, then the remainder
    in up to MAX_PIECES pieces of the smallest shape that allows it (one piece at least). Only the last
    piece is padded, by less than one piece of its shape, unless the remainder needs the largest shape."""
    big = CHUNKS[-1]
    out = [big] * ((n - 1) // big) if n > big else []
    rest = n - len(out) * big
    for i in range(len(CHUNKS) - 1, -1, -1):
        if i == 0 or -(-rest // CHUNKS[i - 1]) > MAX_PIECES:
            return out + [CHUNKS[i]] * max(1, -(-rest // CHUNKS[i]))


def chunks(arr: np.ndarray, fill=0, size: int | None = None):
    """Split rows into padded pieces of the shapes CHUNKS (see `piece_sizes`; or all exactly ``size``):
    yields (start, piece). Only the last piece holds padding."""
    n = len(arr)
    sizes = piece_sizes(n) if size is None else [size] * max(1, -(-n // size))
    start = 0
    for s in sizes:
        yield start, pad_rows(arr[start:start + s], s, fill)
        start += s


@jit(donate_argnums=0)  # jax.jit, made at the first call
def _set_rows(A, idx, rows):
    return A.at[idx].set(rows, mode="drop")


def set_rows(A, idx: np.ndarray, rows: np.ndarray, size: int = 4096):
    """A[idx] = rows for a device array A, updated in place (donated), in fixed-size pieces: padding
    indices point past the end and are dropped. Returns the new A (the old handle is invalid)."""
    for (_, ii), (_, rr) in zip(chunks(idx.astype(np.int32), fill=len(A), size=size), chunks(rows, size=size)):
        A = _set_rows(A, ii, rr)
    return A
