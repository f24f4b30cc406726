"""The re-fit's minimax polish (a method's ``polish``): moves that lower the largest distance, both ways.

The re-fit (`refit`) minimises the squared distances of the input's samples: an L2 fit, which leaves alone
a few samples far off, such as a thin tip the contractions cut short (the Cow's horns), while the
Hausdorff distance is set by exactly those. After the re-fit, this pass repeats, at most ``moves`` times:

1. find the sample farthest from the other surface, over both sample sets: the input's (the re-fit's:
   every vertex and face centroid) to the output, and the output's (every vertex and BARY's seven points
   of every face: its edges' midpoints, its centroid, and a point toward each corner, since a coarse face
   can bulge between its corners) to the input;
2. propose moves that bring it onto the other surface: for an input sample s, its nearest output face's
   corner with the largest barycentric weight b by (s − c) / max(b, ½) (c: the face's point nearest to s),
   or the face's three corners by s − c; for an output sample q, its vertex or its face's corners by r − q
   (r: the input's point nearest to q); each at STEPS of that length, in turn;
3. take the first proposal after which the largest distance over both sets is lower than before and the
   two-way rms (the mean of both sets' area-weighted mean squares) stays within RMS_SLACK of what the
   re-fit left, and which turns no face by the flip angle, against the input face it continues, or below
   the quality guard (the re-fit's rules, `refit`), nor moves a fixed vertex; stop when none passes.

How the distances are kept, exact where it counts and upper bounds elsewhere, and the rules every
move keeps: `moves`.
"""
from __future__ import annotations

import numpy as np

from .fit_rules import _barycentric_at
from .moves import Moves

STEPS = (1.0, 0.5, 0.25, 0.125)  # fractions of a proposed move, tried in turn (step 2)
RMS_SLACK = 0.01  # the two-way rms may rise this much (a fraction) over the re-fit's (step 3)


def _proposals(m: Moves, side: str, i: int):
    """The moves that bring sample i of ``side`` ('in': the input's, 'out': the output's) onto the other
    surface (module docstring, step 2), in the order they are tried."""
    X, G, free = m.X, m.G, m.free
    if side == "in":
        b = _barycentric_at(m.P[i:i + 1], X, G, m.fa[i:i + 1].astype(np.int32), m.out.flat)[0]
        tri = G[m.fa[i]]
        delta = m.P[i] - ((b[0] * X[tri[0]] + b[1] * X[tri[1]]) + b[2] * X[tri[2]])  # left to right: any CPU
        c = max((t for t in range(3) if free[tri[t]]), key=lambda t: b[t], default=None)
        corners = [v for v in tri if free[v]]
        for s in STEPS:
            if c is not None:
                yield {tri[c]: s * delta / max(b[c], 0.5)}
            if corners:
                yield {v: s * delta for v in corners}
    else:
        V, F = m.V, m.F
        g = m.ga[i]
        bi = _barycentric_at(m.Q[i:i + 1], V, F, np.array([g], np.int32), m.into[1])[0]
        delta = ((bi[0] * V[F[g, 0]] + bi[1] * V[F[g, 1]]) + bi[2] * V[F[g, 2]]) - m.Q[i]
        v = int(m.row_vertex([i])[0])
        verts = [v] if v >= 0 else list(G[m.row_face([i])[0]])
        verts = [v for v in verts if free[v]]
        if verts:
            for s in STEPS:
                yield {v: s * delta for v in verts}


def polish(m: Moves, moves: int) -> int:
    """At most ``moves`` moves of the minimax polish on ``m`` (module docstring); the number made."""
    if moves <= 0 or not m.ok:
        return 0
    start, limit = m.made, m.limit(RMS_SLACK)
    while m.made - start < moves:
        side, i, H = m.worst()
        if H <= 0:
            break
        # the samples at the largest distance: a move must take every one of them below it
        top_in = m.top_d.at_least(H)
        top_out = m.top_e.at_least(H)
        rf, rv = m.row_face(top_out), m.row_vertex(top_out)
        top_faces = {int(m.fa[t]) for t in top_in} | {int(f) for f in rf[rf >= 0]}
        top_verts = {int(v) for v in rv[rv >= 0]}
        for move in _proposals(m, side, i):
            if not (top_faces.issubset(m.ring(list(move)).tolist()) and top_verts.issubset(move)):
                continue  # a sample at the largest distance would keep it
            if m.attempt(move, H, limit):
                break
        else:
            break
    return m.made - start
