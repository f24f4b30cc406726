"""A piece of a partitioned run on disk: a level-0 part (`scatter`) or a group's output. Each is an ``.npz``
of ``V`` (k,3) float64, ``F`` (m,3) int32 into ``V`` and ``gid`` (k,) int64, the global id of each vertex
another piece may share (-1 for a vertex no other piece can hold: a new or interior one). Level-0 parts also
carry ``border`` (k,) bool (shared with another part); a group's output carries ``borders``, its sorted
global ids, the only ones the next level must know, and (a level before the last, when its method carries
them) ``Q`` (k,10) float64, each vertex's carried quadric (`carry`). A run that keeps UVs gives every piece
``UV`` (m,3,2) float64, the UVs of its triangles' corners (a vertex on a UV seam has several)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .write import replace_atomically, write_npz


def save(path, **arrays) -> None:
    """Write ``arrays`` to ``path`` whole or not at all, with bytes that depend only on the arrays (a task
    killed while writing leaves no piece a resumed run would trust; a retry writes the same file)."""
    write_npz(Path(path), **arrays)


def save_json(path, data: dict) -> None:
    replace_atomically(Path(path), lambda tmp: Path(tmp).write_text(json.dumps(data, sort_keys=True)))


def load(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """(V, F, gid, border or None) of a piece."""
    with np.load(path) as z:
        border = z["border"] if "border" in z.files else None
        return z["V"], z["F"].astype(np.int64), z["gid"], border


def borders(path) -> np.ndarray:
    """The sorted global ids a piece holds (read without its vertices and faces)."""
    with np.load(path) as z:
        if "borders" in z.files:
            return z["borders"]
        gid = z["gid"]
        return np.unique(gid[gid >= 0])


def sum_rows(Q: np.ndarray, to: np.ndarray, n: int) -> np.ndarray:
    """(n, Q's columns): the rows of Q summed by ``to`` (in row order: the same bits on any machine)."""
    return np.stack([np.bincount(to, weights=Q[:, j], minlength=n) for j in range(Q.shape[1])], 1)


def quadrics(path) -> np.ndarray | None:
    """A piece's carried quadrics ``Q``, or None when it has none."""
    with np.load(path) as z:
        return z["Q"] if "Q" in z.files else None


def corner_uv(path) -> np.ndarray | None:
    """A piece's corners' UVs ``UV`` (m,3,2), or None when it has none."""
    with np.load(path) as z:
        return z["UV"] if "UV" in z.files else None


def stitch_uv(paths: list) -> np.ndarray | None:
    """The corners' UVs of the pieces at ``paths`` in `stitch`'s face order, or None when any has none."""
    UVs = [corner_uv(p) for p in paths]
    return None if any(u is None for u in UVs) else np.concatenate(UVs)


def _first_holders(gid: np.ndarray) -> np.ndarray:
    """Each vertex's first holder of its global id: by a table of the ids (`holders.first_holders`) where they
    are as dense as a run's are (ids of the input's vertices), else by sorting them."""
    from .holders import first_holders  # numba: only where pieces are stitched

    held = np.flatnonzero(gid >= 0)
    size = int(gid.max()) + 1 if len(held) else 0
    if size <= 4 * len(gid) + 1024:
        return first_holders(gid, size)
    _, first, inverse = np.unique(gid[held], return_index=True, return_inverse=True)
    to = np.arange(len(gid))
    to[held] = held[first][inverse]
    return to


def stitch(paths: list, carried: bool = False) -> tuple:
    """The pieces at ``paths`` as one mesh: a global id held by several pieces becomes one vertex (its first
    holder's: locked, every holder has the same bits). Returns (V, F, gid, border) with border False where
    the pieces carry none; with ``carried``, also Q (k,10): the pieces' carried quadrics, summed over the
    holders of a shared vertex (each holds the planes of its own side), or None when a piece has none."""
    Vs, Fs, gids, bs, Qs, base = [], [], [], [], [], 0
    for p in paths:
        V, F, gid, border = load(p)
        Vs.append(V)
        Fs.append(F + base)
        gids.append(gid)
        bs.append(np.zeros(len(V), bool) if border is None else border)
        Qs.append(quadrics(p) if carried else None)
        base += len(V)
    V, F, gid, border = np.concatenate(Vs), np.concatenate(Fs), np.concatenate(gids), np.concatenate(bs)
    Q = np.concatenate(Qs) if carried and all(q is not None for q in Qs) else None
    if len(paths) == 1:
        return (V, F, gid, border) + ((Q,) if carried else ())
    from .holders import renumbered, same_positions  # numba: only where pieces are stitched

    ids = np.ascontiguousarray(gid, np.int64)  # (the pieces' ids are; ``gid`` is returned as it is)
    to = _first_holders(ids)  # every holder of a global id -> its first holder
    keep = to == np.arange(len(V))
    if not same_positions(V, to, ids):
        raise RuntimeError("partition: a shared vertex moved in one of its pieces (a lock was not kept)")
    new = np.cumsum(keep) - 1
    out = (V[keep], renumbered(F, to, new), gid[keep], border[keep])
    if not carried:
        return out
    if Q is not None:  # in piece order: the same sum for any number of workers
        Q = sum_rows(Q, new[to], int(keep.sum()))
    return out + (Q,)
