"""Pieces both schedulers share: settings, padded kernel calls, initial quadrics, the output."""
from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import _topology as topo
from .._kernels import placement, quadrics

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


@dataclasses.dataclass(frozen=True)
class Settings:
    """Numbers a scheduler needs (all internal: coordinates normalised to unit extent)."""

    endpoints_only: bool
    cond_eps: float
    max_shift: float
    cos_max: float
    preserve_topology: bool
    max_cost: float  # internal units (squared distance in normalised coordinates); inf = no limit

    def kernel_args(self):
        """Tunables as 0-d arrays: changing their values never recompiles."""
        return (np.asarray(self.endpoints_only), np.asarray(self.cond_eps, DTYPE),
                np.asarray(self.max_shift, DTYPE))


class Timer:
    """Accumulates wall time per named stage (seconds, keys like ``kernels_s``)."""

    def __init__(self):
        self.t = {}

    def add(self, name, dt):
        self.t[name] = self.t.get(name, 0.0) + dt


_place_local = jax.jit(placement.place)


@functools.partial(jax.jit, donate_argnums=0)
def _set_rows(A, idx, rows):
    return A.at[idx].set(rows, mode="drop")


def set_rows(A, idx: np.ndarray, rows: np.ndarray, size: int = 4096):
    """A[idx] = rows for a device array A, updated in place (donated), in fixed-size pieces: padding
    indices point past the end and are dropped. Returns the new A (the old handle is invalid)."""
    for (_, ii), (_, rr) in zip(chunks(idx.astype(np.int32), fill=len(A), size=size), chunks(rows, size=size)):
        A = _set_rows(A, ii, rr)
    return A


def place_gathered(q1, q2, p1, p2, settings: Settings):
    """Placement for K pairs given their quadrics / positions (numpy); pads K to a bucket so only a
    handful of shapes are ever compiled. Returns numpy x (K,3), cost (K,), branch (K,), qsum (K,10)."""
    K = len(q1)
    if K == 0:
        return (np.zeros((0, 3), DTYPE), np.zeros(0, DTYPE), np.zeros(0, np.int32),
                np.zeros((0, 10), DTYPE))
    args = settings.kernel_args()
    pieces = zip(*(chunks(a) for a in (q1, q2, p1, p2)))
    outs = [_place_local(*(part for _, part in piece), *args) for piece in pieces]
    x, cost, branch, qsum = (np.concatenate([np.asarray(o[k]) for o in outs])[:K] for k in range(4))
    return x, cost, branch, qsum


def face_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unnormalised normals (p1 − p0) × (p2 − p0) of faces F (m,3) over positions V (n,3), in V's dtype:
    np.cross's arithmetic on one coordinate array at a time (half the time of gathering (m,3,3) rows)."""
    c = [np.take(V[:, i], F) for i in range(3)]  # (m,3) per coordinate
    u = [ci[:, 1] - ci[:, 0] for ci in c]
    w = [ci[:, 2] - ci[:, 0] for ci in c]
    return np.stack([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]], 1)


def initial_quadrics(V: np.ndarray, F: np.ndarray, *, area_weighted: bool, boundary_weight: float,
                     feature_edges: np.ndarray | None, boundary=None) -> np.ndarray:
    """(n,10) float32 vertex quadrics (each in its vertex's frame) with boundary/feature planes.
    ``boundary``: `topo.boundary_edges` of F when the caller has it."""
    n = len(V)
    be, bf = topo.boundary_edges(F, n) if boundary is None else boundary
    cw = np.full(len(be), boundary_weight, DTYPE)
    if feature_edges is not None and len(feature_edges):
        fe, ff = topo.feature_edges_with_faces(F, n, np.asarray(feature_edges, np.int64))
        be, bf = np.concatenate([be, fe]), np.concatenate([bf, ff])
        cw = np.concatenate([cw, np.full(len(fe), boundary_weight, DTYPE)])
    keep = cw > 0
    be, bf, cw = be[keep], bf[keep], cw[keep]
    cn = face_normals(V, F[bf]).astype(DTYPE)
    nb, nf, nv = bucket(len(be)), bucket(len(F), steps=4), bucket(n + 1, steps=4)  # faces: arithmetic
    Vp = pad_rows(V.astype(DTYPE), nv)
    Fp = pad_rows(F.astype(np.int32), nf, fill=n)  # padding faces point at a spare vertex
    fmask = np.arange(nf) < len(F)
    Q = quadrics.vertex_quadrics(
        Vp, Fp, fmask, jnp.asarray(area_weighted),
        pad_rows(be.astype(np.int32), nb, fill=n), pad_rows(cn, nb), pad_rows(cw, nb),
        np.arange(nb) < len(be))
    return np.asarray(Q)[:n]


def compact_output(V: np.ndarray, F: np.ndarray, alive_faces: np.ndarray):
    """Keep live faces and the vertices they use. Returns (V', F', kept vertex ids, kept face ids)."""
    fids = np.flatnonzero(alive_faces)
    F = F[fids]
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    ids = np.flatnonzero(used)
    newidx = np.cumsum(used) - 1
    return V[ids], newidx[F], ids, fids
