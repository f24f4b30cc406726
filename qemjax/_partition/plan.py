"""Which pieces each level groups and how many faces each group keeps: pure functions of the pieces' face
counts, so that a resumed run plans the same levels."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._options import Partition

NEAR = 1.25  # × budget × target: the band of a level before the last (`level`)


class Group(NamedTuple):
    """One task of a level: the pieces it reads (indices into the previous level's outputs, consecutive in
    Hilbert order, so spatially close), their faces and the faces it keeps."""

    members: tuple
    faces: int
    target: int


def shares(faces: np.ndarray, total: int) -> np.ndarray:
    """``total`` split over groups in proportion to their faces, as integers summing to ``total`` (largest
    remainders first, ties to the lower index: deterministic)."""
    faces = np.asarray(faces, np.int64)
    exact = faces * (total / max(int(faces.sum()), 1))
    out = np.floor(exact).astype(np.int64)
    rest = int(total - out.sum())
    if rest > 0:
        order = np.lexsort((np.arange(len(exact)), -(exact - out)))
        out[order[:rest]] += 1
    return np.minimum(out, faces)


def consecutive(faces: np.ndarray, limit: int) -> list[tuple]:
    """Consecutive runs of pieces whose faces sum to at most ``limit`` (each run at least one piece)."""
    groups, cur, acc = [], [], 0
    for i, f in enumerate(np.asarray(faces, np.int64).tolist()):
        if cur and acc + f > limit:
            groups.append(tuple(cur))
            cur, acc = [], 0
        cur.append(i)
        acc += f
    if cur:
        groups.append(tuple(cur))
    return groups


def level(faces: np.ndarray, target: int, p: Partition, first: bool, stalled: bool = False,
          aimed: int | None = None) -> tuple[list[Group], bool]:
    """The next level's groups for pieces of ``faces`` faces (Hilbert order), and whether it is the last: one
    group, nothing locked, run to ``target``; or, when that group would read more than ``final_faces``, the
    groups of at most ``part_faces`` run to their shares of ``target`` with their borders locked. The first
    level runs each part alone. Any other level keeps ``max(faces / reduction, budget * target)`` faces in
    all, shared in proportion to the groups' faces.

    The next level is the last once the pieces hold at most NEAR × budget × target faces, or the level before
    aimed at no more (``aimed``: the faces it was to keep): another locked level would remove little and lock
    the same borders again. Which it is goes by the aim, not by what the level kept, which its groups' locked
    borders may hold a few faces over (one more locked level for those cost the quality of a locked level:
    `test_partition`). ``stalled``: the level before removed almost nothing (its groups' locked borders held
    their faces): the next is the last."""
    faces = np.asarray(faces, np.int64)
    total = int(faces.sum())
    band = NEAR * p.budget * target
    near = total <= p.part_faces or total <= band or (aimed is not None and aimed <= band) or len(faces) == 1 \
        or stalled
    if total <= p.final_faces and near:
        return [Group(tuple(range(len(faces))), total, min(target, total))], True
    members = [(i,) for i in range(len(faces))] if first else consecutive(faces, p.part_faces)
    keep = max(int(np.ceil(total / p.reduction)), int(np.ceil(p.budget * target)), target)
    last = stalled or keep >= total  # too large for one process, and no level can reduce it further
    if last:
        keep = target
    sums = np.array([faces[list(m)].sum() for m in members], np.int64)
    return [Group(m, int(s), int(t)) for m, s, t in zip(members, sums, shares(sums, min(keep, total)))], last


def pilots(n: int, k: int = 8) -> list[int]:
    """Up to ``k`` of ``n`` groups spread evenly along the Hilbert order: those that set a level's common
    cost (``Partition(share="cost")``)."""
    return sorted(set(np.linspace(0, n - 1, min(k, n)).round().astype(int).tolist()))


def common_cost(costs) -> float:
    """The cost every group of a level stops at: the median of the pilots' largest contraction costs."""
    return float(np.median(np.asarray(costs, np.float64)))
