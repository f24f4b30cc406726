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

Each input sample holds its distance to one face of the output (`_mesh.grid_nearest`'s arithmetic): its
nearest when measured, so an upper bound of its distance once other faces move. The first pass is an
exact search. After a move, the samples whose face moved are measured to the faces around the move (their
own among them: still an upper bound); a sample whose bound is the largest is searched exactly again
before anything is decided (the output's search structure is kept across moves, the faces moved since it
was built measured directly). So the largest distance a move must beat is exact, and the rms a move is
held to is never below the true one: the bound on it holds. The output's samples are searched exactly
against the input, which does not move. The arithmetic is the re-fit's, in its unit frame, with sums in a
fixed order: the same bits on every CPU.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._mesh.arrays import face_normals
from .._mesh.box_bounds import face_boxes
from .._mesh.grid_nearest import _face_d2, _gap, _query, grid, search, slivers
from .fit_rules import _barycentric_at, _quality, _turned

# the output's samples on each face, as barycentric weights (module docstring, step 1)
BARY = np.array([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5], [1 / 3, 1 / 3, 1 / 3],
                 [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
STEPS = (1.0, 0.5, 0.25, 0.125)  # fractions of a proposed move, tried in turn (step 2)
RMS_SLACK = 0.01  # the two-way rms may rise this much (a fraction) over the re-fit's (step 3)
REFRESH = 64  # stale input distances measured at once, the largest (`worst`)
REBUILD = 64  # faces moved since the output's search structure was built before it is built again


@njit(cache=True, nogil=True)
def _wsum2(w, d):
    """Σ w·d², left to right."""
    s = 0.0
    for i in range(len(d)):
        s += w[i] * (d[i] * d[i])
    return s


@njit(cache=True, nogil=True)
def _on_faces(fa, hit):
    """The samples whose face (``fa``) is marked in ``hit``, in order."""
    out = np.empty(len(fa), np.int64)
    n = 0
    for i in range(len(fa)):
        if hit[fa[i]]:
            out[n] = i
            n += 1
    return out[:n]


@njit(cache=True, nogil=True)
def _nearer(P, X, G, B, flat, faces, f, d2):
    """Lower each point's (f, d2) to its nearest among ``faces`` (the lowest index among equals), in place;
    B: the faces' boxes (a face whose box lies farther than the best so far is passed over)."""
    for p in range(P.shape[0]):
        px, py, pz = P[p, 0], P[p, 1], P[p, 2]
        for t in range(len(faces)):
            g = faces[t]
            bx, by, bz = _gap(px, B[g, 0], B[g, 3]), _gap(py, B[g, 1], B[g, 4]), _gap(pz, B[g, 2], B[g, 5])
            if bx * bx + by * by + bz * bz > d2[p]:
                continue
            e = _face_d2(px, py, pz, X, G, flat, g)
            if e < d2[p] or (e == d2[p] and g < f[p]):
                f[p], d2[p] = g, e


@njit(cache=True, nogil=True)
def _own_d2(P, rows, X, G, flat, faces):
    """Squared distance of each sample P[rows[t]] to its face faces[t]."""
    out = np.empty(len(rows))
    for t in range(len(rows)):
        p = rows[t]
        out[t] = _face_d2(P[p, 0], P[p, 1], P[p, 2], X, G, flat, faces[t])
    return out


@njit(cache=True, nogil=True)
def _face_points(X, G, faces, W):
    """(len(faces)·len(W), 3): the points of W's barycentric weights on each face, face by face."""
    out = np.empty((len(faces) * W.shape[0], 3))
    r = 0
    for t in range(len(faces)):
        g = faces[t]
        for b in range(W.shape[0]):
            for k in range(3):
                out[r, k] = (W[b, 0] * X[G[g, 0], k] + W[b, 1] * X[G[g, 1], k]) + W[b, 2] * X[G[g, 2], k]
            r += 1
    return out


class _Output:
    """The output's search structure, kept across moves (module docstring)."""

    def __init__(self, X, G):
        self.G = G
        self.build(X)

    def build(self, X):
        self.B, self.flat, *self.rest = grid(X, self.G)
        self.stale_list = np.zeros(0, np.int64)  # the faces moved since the build, sorted

    def update(self, X, faces):
        """Boxes and slivers of ``faces`` at X (after a move)."""
        self.B[faces] = face_boxes(X, self.G[faces])
        self.flat[faces] = slivers(X, self.G[faces])

    def mark(self, faces):
        self.stale_list = np.union1d(self.stale_list, faces)

    def nearest(self, X, P, seed):
        """Exact nearest faces and distances of P on (X, G): the kept structure, then the moved faces."""
        if not len(self.stale_list):  # nothing moved since the build: on threads
            return search(X, self.G, (self.B, self.flat, *self.rest), P, seed)
        f, d2 = _query(P, X, self.G, self.B, self.flat, *self.rest, seed)
        _nearer(P, X, self.G, self.B, self.flat, self.stale_list, f, d2)
        return f, np.sqrt(d2)


def _refused(X, G, R, n0, cos_max, agreed, source_normals, q0, min_quality) -> bool:
    """Whether the faces R at X break one of the re-fit's rules (`refit`): turned by the flip angle or more
    (or lost all area), come to point against the input face they continue, or fell below the quality
    guard and below their shape before."""
    n1 = face_normals(X, G[R])
    bad = _turned(n0[R], n1, cos_max)
    if agreed is not None:
        bad |= agreed[R] & (np.einsum("ij,ij->i", n1, source_normals[R]) <= 0)
    if q0 is not None:
        q1 = _quality(X, G[R], n1)
        bad |= (q1 < min_quality) & (q1 < q0[R])
    return bool(bad.any())


def polish(V, F, X, G, P, w, moves: int, cos_max: float, fixed=None, source_normals=None,
           min_quality: float = 0.0, seeds=None, source_faces=None) -> tuple[np.ndarray, int]:
    """(positions, moves made): X (k,3) of the output G (j,3) polished against the input (V, F), both in
    the re-fit's unit frame, with the input's samples P (q,3) and weights w (q,) (`refit.samples`); at most
    ``moves`` moves (module docstring). ``fixed`` (k,) bool: vertices that stay; ``source_normals`` (j,3):
    the normal of the input face each output face continues (None: not checked); ``cos_max``,
    ``min_quality``: the re-fit's rules. ``seeds`` (q,): an output face near each input sample (the
    re-fit's last attachment; -1: none) and ``source_faces`` (j,): that input face of each output face,
    where the searches start (the same answers, found sooner)."""
    if moves <= 0 or len(G) == 0 or len(P) == 0:
        return X, 0
    X = np.array(X, np.float64)
    V, F = np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64)
    G = np.ascontiguousarray(G, np.int64)
    k, j = len(X), len(G)
    free = np.ones(k, bool) if fixed is None else ~np.asarray(fixed, bool)
    if not free.any():
        return X, 0
    # the faces at each vertex (CSR)
    order = np.argsort(G.reshape(-1), kind="stable")
    ring_start = np.searchsorted(G.reshape(-1)[order], np.arange(k + 1))
    ring_face = order // 3

    def ring(verts):
        return np.unique(np.concatenate([ring_face[ring_start[v]:ring_start[v + 1]] for v in verts]))

    n0 = face_normals(X, G)
    q0 = _quality(X, G, n0) if min_quality > 0 else None
    agreed = None if source_normals is None else np.einsum("ij,ij->i", n0, source_normals) > 0
    into = grid(V, F)  # the input's structure: it never moves
    no_seed = np.zeros(0, np.int32)

    # where each output sample's search of the input starts: its face's input face (a vertex: one of its faces')
    src = None if source_faces is None else np.asarray(source_faces, np.int32)

    def to_input(Q, rows):
        if src is None:
            return search(V, F, into, Q, no_seed)
        face = np.where(rows < len(used), ring_face[ring_start[used[np.minimum(rows, len(used) - 1)]]],
                        (rows - len(used)) // nb)
        return search(V, F, into, Q, src[face])

    out = _Output(X, G)
    # input samples → output, exact (the re-fit's faces, where given, start each search)
    seed0 = no_seed if seeds is None else np.ascontiguousarray(seeds, np.int32)
    fa, d = out.nearest(X, P, seed0)
    version = np.zeros(len(P), np.int64)  # the move count when each d was measured (exact then)
    used = np.unique(G)
    nb = len(BARY)
    # output samples: the used vertices, then nb points per face (row of face g: len(used) + nb·g + b)
    vrow = np.full(k, -1, np.int64)
    vrow[used] = np.arange(len(used))
    Q = np.concatenate([X[used], _face_points(X, G, np.arange(j), BARY)])
    ga, e = to_input(Q, np.arange(len(Q)))

    def face_weights(Y, faces):  # each face point stands for a seventh of its face's area
        n = face_normals(Y, G[faces])
        return np.repeat(0.5 * np.sqrt((n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1]) + n[:, 2] * n[:, 2]) / nb, nb)

    qw = np.concatenate([np.zeros(len(used)), face_weights(X, np.arange(j))])
    sw, sq = _wsum2(w, np.ones(len(w))), _wsum2(qw, np.ones(len(qw)))  # left-to-right sums
    s_in, s_out = _wsum2(w, d), _wsum2(qw, e)
    if not (sq > 0 and sw > 0):
        return X, 0
    limit = (s_in / sw + s_out / sq) * (1 + RMS_SLACK) ** 2  # on the mean of the two mean squares
    made = 0

    def worst():
        """The farthest sample: ('in', i) or ('out', i), with its distance; stale input distances measured."""
        nonlocal s_in
        while True:
            i = int(np.argmax(d))
            if version[i] == made:
                break
            # the stale ones among the REFRESH largest, measured at once (the REFRESH-th largest value is the
            # same whichever way a partition orders ties), and always the largest itself
            edge = np.partition(d, len(d) - REFRESH)[len(d) - REFRESH] if len(d) > REFRESH else -np.inf
            top = np.flatnonzero((d >= edge) & (version != made))
            f1, d1 = out.nearest(X, P[top], fa[top].astype(np.int32))
            s_in += _wsum2(w[top], d1) - _wsum2(w[top], d[top])
            fa[top], d[top], version[top] = f1, d1, made
        o = int(np.argmax(e))
        return ("in", i, d[i]) if d[i] >= e[o] else ("out", o, e[o])

    def proposals(side, i):
        if side == "in":
            b = _barycentric_at(P[i:i + 1], X, G, fa[i:i + 1].astype(np.int32), out.flat)[0]
            tri = G[fa[i]]
            delta = P[i] - ((b[0] * X[tri[0]] + b[1] * X[tri[1]]) + b[2] * X[tri[2]])  # left to right: any CPU
            c = max((t for t in range(3) if free[tri[t]]), key=lambda t: b[t], default=None)
            corners = [v for v in tri if free[v]]
            for s in STEPS:
                if c is not None:
                    yield {tri[c]: s * delta / max(b[c], 0.5)}
                if corners:
                    yield {v: s * delta for v in corners}
        else:
            g = ga[i]
            bi = _barycentric_at(Q[i:i + 1], V, F, np.array([g], np.int32), into[1])[0]
            delta = ((bi[0] * V[F[g, 0]] + bi[1] * V[F[g, 1]]) + bi[2] * V[F[g, 2]]) - Q[i]
            verts = [used[i]] if i < len(used) else list(G[(i - len(used)) // nb])
            verts = [v for v in verts if free[v]]
            if verts:
                for s in STEPS:
                    yield {v: s * delta for v in verts}

    hit = np.zeros(j, bool)  # the faces a proposal moves
    while made < moves:
        side, i, H = worst()
        if H <= 0:
            break
        # the samples at the largest distance: a move must take every one of them below it
        top_in = np.flatnonzero(d >= H)
        top_out = np.flatnonzero(e >= H)
        top_faces = {int(fa[t]) for t in top_in} | {int((t - len(used)) // nb) for t in top_out if t >= len(used)}
        top_verts = {int(used[t]) for t in top_out if t < len(used)}
        for move in proposals(side, i):
            verts = np.array(sorted(move), np.int64)
            R = ring(verts)
            hit[R] = True
            if not (all(hit[f] for f in top_faces) and top_verts.issubset(move)):
                hit[R] = False  # a sample at the largest distance would keep it
                continue
            old = X[verts].copy()
            for v, dv in move.items():
                X[v] = X[v] + dv
            if _refused(X, G, R, n0, cos_max, agreed, source_normals, q0, min_quality):
                X[verts] = old
                hit[R] = False
                continue
            out.update(X, R)
            A = _on_faces(fa, hit)  # input samples whose nearest face moved
            hit[R] = False
            # their distance to the nearest face of the moved faces' neighbourhood: an upper bound (their
            # old face is among these), exact unless a face farther out is nearer (then refreshed when
            # it is the largest: `worst`)
            fA = fa[A]
            d2A = _own_d2(P, A, X, G, out.flat, fA)
            far = np.flatnonzero(d2A >= H * H)
            if len(far):
                f1, e1 = fA[far], d2A[far]
                _nearer(P[A[far]], X, G, out.B, out.flat, ring(np.unique(G[R])), f1, e1)
                fA[far], d2A[far] = f1, e1
            dA = np.sqrt(d2A)
            if dA.max(initial=0.0) < H:
                rows = np.concatenate([vrow[verts][vrow[verts] >= 0],
                                       len(used) + (nb * R[:, None] + np.arange(nb)).reshape(-1)])
                nv = int(np.sum(rows < len(used)))
                QR = np.concatenate([X[used[rows[:nv]]], _face_points(X, G, R, BARY)])
                gR, eR = to_input(QR, rows)
                wR = np.concatenate([np.zeros(nv), face_weights(X, R)])
                s_in1 = s_in + (_wsum2(w[A], dA) - _wsum2(w[A], d[A]))
                s_out1 = s_out + (_wsum2(wR, eR) - _wsum2(qw[rows], e[rows]))
                sq1 = sq + (_wsum2(wR, np.ones(len(wR))) - _wsum2(qw[rows], np.ones(len(rows))))
                if eR.max(initial=0.0) < H and sq1 > 0 and s_in1 / sw + s_out1 / sq1 <= limit:
                    made += 1
                    fa[A], d[A], version[A] = fA, dA, -1  # upper bounds (above)
                    Q[rows], ga[rows], e[rows], qw[rows] = QR, gR, eR, wR
                    s_in, s_out, sq = s_in1, s_out1, sq1
                    out.mark(R)
                    if len(out.stale_list) > REBUILD:
                        out.build(X)
                    break
            X[verts] = old
            out.update(X, R)
        else:
            break
    return X, made
