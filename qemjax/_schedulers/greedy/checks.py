"""The greedy queue's rules for one popped pair, compiled (numba), in the order of the one-at-a-time loop
(`loop._run`): the face budget, the link condition, the part rule, the lock rule, (the seam rule, which
`speculate` applies between the two parts here), the flip test, the coincident faces. The rules themselves
are `.._schedulers.rules`; this module only orders them and lists the faces the contraction would change.

On a `batches.simple` mesh in manifold mode (the usual case) the link condition's degree test and the
coincident-face test take shortcuts that the mesh allows; elsewhere (non-manifold mode, where a
contraction drops the faces it makes coincide, or a mesh with repeated corners or faces) the general rules
run. The same answers as the loop (tests/test_greedy_compiled.py compares whole runs)."""
from __future__ import annotations

from typing import Any, NamedTuple

from .. import rules as rule
from ..._mesh.compiled import njit
from ..outcome import BUDGET, COINCIDENT, FLIP, LOCKED, PART, TOPOLOGY


class Step(NamedTuple):
    """What the rules leave of one popped pair (`checks.rules_head`, `checks.rules_tail`): the counts
    ``info``, the faces kept at a (A) and at b (B), the dead faces D, the dropped ones R; ``buf``: room for
    the longest list `_contract` writes."""
    info: Any
    A: Any
    B: Any
    D: Any
    R: Any
    buf: Any


@njit(cache=True)
def rules_head(a, b, faces_left, settings, locked, faces, cnt, step, common):
    """The code of the first rule up to the lock rule that contracting b into a breaks, or -1, with
    ``faces_left`` faces in the mesh. Leaves in ``step`` (`Step`) what the contraction would change: info =
    (number of dead faces, of faces kept at a, at b, of faces dropped as coincident (set by `rules_tail`), of
    common neighbours), A and B the faces kept at a and at b (room for fl[a] and fl[b]), D the dead faces
    (room for fl[a]); the common neighbours in ``common``. ``settings``: `speculate.Settings`; ``faces``:
    `rules.Faces`; ``cnt`` (n,3) zeros: the link condition's scratch."""
    info, A, B, D = step.info, step.A, step.B, step.D
    T, alive, fs, fl, fpool = faces
    target, manifold, simple, keep_parts, has_locks = (settings.target, settings.manifold, settings.simple,
                                                       settings.keep_parts, settings.has_locks)
    nd = nka = nkb = 0
    for i in range(fs[a], fs[a] + fl[a]):
        f = fpool[i]
        if rule.has(fpool, fs[b], fl[b], f):
            D[nd] = f
            nd += 1
        else:
            A[nka] = f
            nka += 1
    for i in range(fs[b], fs[b] + fl[b]):
        f = fpool[i]
        if not rule.has(D, 0, nd, f):
            B[nkb] = f
            nkb += 1
    info[0], info[1], info[2], info[3] = nd, nka, nkb, 0
    if faces_left - nd < target:
        return BUDGET
    ncommon = 0
    if manifold:
        ncommon = rule.link_common(T, alive, fs, fl, fpool, cnt, a, b, nd, common, simple)
        if ncommon < 0:
            return TOPOLOGY
        if rule.part_vanishes(keep_parts, nka + nkb):
            return PART
    info[4] = ncommon
    if has_locks and (rule.locked_endpoint_bare(nka + nkb, locked, a, b) or
                      rule.stranded_by_step(a, b, nd, locked, T, fl, D)):
        return LOCKED
    return -1


@njit(cache=True)
def rules_tail(a, b, x, faces_left, settings, faces, VQ, N0, step, common):
    """After `rules_head` (and the seam rule): the flip test, then the coincident faces; the code of the
    first that contracting b into a at x breaks, or -1. ``step``.R: the faces dropped as coincident
    (non-manifold mode; room for fl[a] + fl[b]), their number in info[3]."""
    info, A, B, R = step.info, step.A, step.B, step.R
    T = faces.T
    target, manifold, simple, cos_max, shape = (settings.target, settings.manifold, settings.simple,
                                                settings.cos_max, settings.shape)
    nd, nka, nkb, ncommon = info[0], info[1], info[2], info[4]
    for i in range(nka + nkb):
        f = A[i] if i < nka else B[i - nka]
        v = a if i < nka else b
        corner = 0 if T[f, 0] == v else (1 if T[f, 1] == v else 2)
        if rule.flips(VQ, N0, T, f, corner, x, cos_max, shape):
            return FLIP
    if manifold and simple:
        if ncommon == 2 and rule.coincide_at_apexes(T, A, nka, B, nkb, common[0], common[1]):
            return COINCIDENT
        return -1
    ndrop = rule.coincident_drop(a, b, T, A, nka, B, nkb, R)
    if ndrop and (manifold or faces_left - nd - ndrop < target):  # forbidden in manifold mode, else dropped
        return COINCIDENT if manifold else BUDGET
    info[3] = ndrop
    return -1
