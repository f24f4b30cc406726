"""Moves of the output's vertices after the re-fit, each made only when the distance allows it: the state the
minimax polish (`polish`) and the sliver moves (`slivers`) share.

Two sets of samples are kept with their distances to the other surface: the input's (the re-fit's: every
vertex and face centroid) to the output, and the output's (every vertex and BARY's seven points of every
face: its edges' midpoints, its centroid, and a point toward each corner, since a coarse face can bulge
between its corners) to the input. `Moves.attempt` makes a move (new positions of a few vertices) when
every sample it touches ends below a bound, the two-way rms (the mean of both sets' area-weighted mean
squares) stays within a limit, and no face breaks the re-fit's rules (turned by the flip angle, against the
input face it continues, or below the quality guard: `refit`) or a fixed vertex moves.

Each input sample holds its distance to one face of the output (`_mesh.grid_nearest`'s arithmetic): its
nearest when measured, so an upper bound of its distance once other faces move. The first pass is an
exact search. After a move, the samples whose face moved are measured to the faces around the move (their
own among them: still an upper bound); `Moves.worst` searches a sample whose bound is the largest exactly
again before it answers (the output's search structure is kept across moves, the faces moved since it was
built measured directly). So the largest distance is exact, and the rms a move is held to is never below
the true one: a bound on it holds. The output's samples are searched exactly against the input, which does
not move. The arithmetic is the re-fit's, in its unit frame, with sums in a fixed order: the same bits on
every CPU.
"""
from __future__ import annotations

import numpy as np

from .._mesh.arrays import face_normals
from .._mesh.box_bounds import face_boxes
from .._mesh.compiled import njit
from .._mesh.counting import counting_order
from .._mesh.grid_nearest import (FEW_QUERIES_CUBES_PER_FACE, _face_d2, _gap, _query, grid, query_here, search, slivers,
                                  stamps)
from .fit_rules import COS_SLIVER, _barycentric_at, _min_cos, _quality
from .refit_system import regions

# the output's samples on each face, as barycentric weights (module docstring)
BARY = np.array([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5], [1 / 3, 1 / 3, 1 / 3],
                 [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
REFRESH = 64  # stale input distances measured at once, the largest (`Moves.worst`)
LISTED = 1024  # the largest distances of each sample set kept listed (`_Largest`): a few moves' worth
# the output's search structure is built again once more than the larger of REBUILD and a REBUILD_SHARE-th of
# its faces moved since: the moved faces are measured one by one at each exact search (`Moves.worst`, a few
# hundred a run), while a build costs as much as searching every face
REBUILD = 64
REBUILD_SHARE = 64


@njit(cache=True, nogil=True)
def _wsum2(w, d):
    """Σ w·d², left to right."""
    s = 0.0
    for i in range(len(d)):
        s += w[i] * (d[i] * d[i])
    return s


@njit(cache=True, nogil=True)
def _sorted_unique(out):
    """``out`` sorted, each value once (in place; the leading part of it)."""
    out.sort()
    m = 0
    for j in range(len(out)):
        if m == 0 or out[j] != out[m - 1]:
            out[m] = out[j]
            m += 1
    return out[:m]


@njit(cache=True, nogil=True)
def _on_faces(fa, hit, faces, start, order, head, link):
    """The samples whose face (``fa``) is among ``faces`` (marked in ``hit``), in order: those each face held
    when the index (``start``, ``order``: the samples by face) was made, and those its chain (``head``,
    ``link``: `_chain`) has listed since, each kept where its face is marked now."""
    n = 0
    for g in faces:
        n += start[g + 1] - start[g]
        j = head[g]
        while j >= 0:
            n += 1
            j = link[j, 1]
    out = np.empty(n, np.int64)
    k = 0
    for g in faces:
        for j in range(start[g], start[g + 1]):
            i = order[j]
            if hit[fa[i]]:
                out[k] = i
                k += 1
        j = head[g]
        while j >= 0:
            i = link[j, 0]
            if hit[fa[i]]:
                out[k] = i
                k += 1
            j = link[j, 1]
    return _sorted_unique(out[:k])


@njit(cache=True, nogil=True)
def _chain(fa, rows, listed, head, link, n):
    """List each sample of ``rows`` whose face (``fa``) is not the one it is listed under (``listed``) in
    its face's chain: a node (sample, next node) of ``link`` from row ``n`` on, at the chain's ``head``.
    Returns the nodes used, or -1 when ``link`` is full (nothing listed then)."""
    need = 0
    for i in rows:
        need += fa[i] != listed[i]
    if n + need > len(link):
        return -1
    for i in rows:
        g = fa[i]
        if g != listed[i]:
            listed[i] = g
            link[n, 0], link[n, 1] = i, head[g]
            head[g] = n
            n += 1
    return n


class _ByFace:
    """The input samples by the output face each is measured to (``fa``), so that a move finds the samples
    of the faces it moved without reading them all: an index made from ``fa``, and per face a chain of the
    samples whose face was set to it since (`set`), read beside it; made again when the chains hold as many
    nodes as there are samples."""

    def __init__(self, fa, faces: int):
        self.faces = faces
        self.link = np.empty((len(fa), 2), np.int64)
        self.build(fa)

    def build(self, fa):
        self.order, self.start = counting_order(fa, self.faces)
        self.listed = fa.copy()  # the face each sample is listed under: in the index, or its chain's last
        self.head = np.full(self.faces, -1, np.int64)
        self.n = 0

    def set(self, fa, rows):
        """After fa[rows] was set."""
        n = _chain(fa, rows, self.listed, self.head, self.link, self.n)
        if n < 0:
            self.build(fa)
        else:
            self.n = n

    def on(self, fa, hit, faces):
        """The samples whose face is among ``faces`` (sorted, each marked in ``hit``), in order."""
        return _on_faces(fa, hit, faces, self.start, self.order, self.head, self.link)


@njit(cache=True, nogil=True)
def _nearer(P, X, G, B, flat, faces, f, d2, stop):
    """Lower each point's (f, d2) to its nearest among ``faces`` (the lowest index among equals), in place;
    B: the faces' boxes (a face whose box lies farther than the best so far is passed over). Whether every
    point ends nearer than ``stop``: at the first that does not, it returns False, the points after it left
    as they were (a move that fails there needs none of them)."""
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
        if np.sqrt(d2[p]) >= stop:  # the distance as `Moves.attempt` compares it
            return False
    return True


@njit(cache=True, nogil=True)
def _own_d2(P, rows, X, G, flat, faces):
    """Squared distance of each sample P[rows[t]] to its face faces[t]."""
    out = np.empty(len(rows))
    for t in range(len(rows)):
        p = rows[t]
        out[t] = _face_d2(P[p, 0], P[p, 1], P[p, 2], X, G, flat, faces[t])
    return out


@njit(cache=True, nogil=True)
def _ring(start, face, verts):
    """The faces at any of ``verts`` (CSR ``start``, ``face``), sorted, each once."""
    n = 0
    for v in verts:
        n += start[v + 1] - start[v]
    out = np.empty(n, np.int64)
    r = 0
    for v in verts:
        for i in range(start[v], start[v + 1]):
            out[r] = face[i]
            r += 1
    return _sorted_unique(out)


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
        self.stale = np.zeros(len(G), bool)  # the faces moved since the build
        self.limit = max(REBUILD, len(G) // REBUILD_SHARE)
        self.build(X)

    def build(self, X):
        self.B, self.flat, *self.rest = grid(X, self.G)
        self.stale[:] = False
        self.n_stale = 0

    def mark(self, X, faces):
        """After ``faces`` moved for good: built again when more than ``limit`` have (the larger of REBUILD
        and a REBUILD_SHARE-th of the faces)."""
        new = faces[~self.stale[faces]]
        self.stale[new] = True
        self.n_stale += len(new)
        if self.n_stale > self.limit:
            self.build(X)

    def nearest(self, X, P, seed):
        """Exact nearest faces and distances of P on (X, G): the kept structure, then the moved faces."""
        if not self.n_stale:  # nothing moved since the build: on threads
            return search(X, self.G, (self.B, self.flat, *self.rest), P, seed)
        f, d2 = query_here(X, self.G, (self.B, self.flat, *self.rest), P, seed)
        _nearer(P, X, self.G, self.B, self.flat, np.flatnonzero(self.stale), f, d2, np.inf)
        return f, np.sqrt(d2)


@njit(cache=True, nogil=True, inline="always")
def _normal(X, G, g):
    """Face g's corners and unnormalised normal (p1 − p0) × (p2 − p0), with np.cross's products
    (`arrays.face_normals`), and its first edge p1 − p0."""
    i0, i1, i2 = G[g, 0], G[g, 1], G[g, 2]
    ux, uy, uz = X[i1, 0] - X[i0, 0], X[i1, 1] - X[i0, 1], X[i1, 2] - X[i0, 2]
    wx, wy, wz = X[i2, 0] - X[i0, 0], X[i2, 1] - X[i0, 1], X[i2, 2] - X[i0, 2]
    return i0, i1, i2, uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx, ux, uy, uz


@njit(cache=True, nogil=True)
def _refused(X, G, R, n0, cos_max, agreed, source_normals, q0, min_quality):
    """Whether the faces R at X break one of the re-fit's rules (`refit`): turned by the flip angle or more
    (or lost all area), come to point against the input face they continue (``agreed``, per face: whether
    it pointed with it; empty: not checked), or fell below the quality guard and below their shape before
    (``q0``; empty: not checked). The arithmetic of the re-fit's numpy expressions (`fit_rules._turned`,
    `fit_rules._quality`): np.cross's products, norms summed left to right, einsum's three-term row products
    as (x·x' + z·z') + y·y' (its order on every SIMD level numpy dispatches to), so the answers are the same."""
    for t in range(len(R)):
        g = R[t]
        i0, i1, i2, ax, ay, az, ux, uy, uz = _normal(X, G, g)
        bx, by, bz = n0[g, 0], n0[g, 1], n0[g, 2]
        l0 = np.sqrt((bx * bx + by * by) + bz * bz)
        l1 = np.sqrt((ax * ax + ay * ay) + az * az)
        ll = l0 * l1
        cos = ((bx * ax + bz * az) + by * ay) / (ll if ll > 0 else 1.0)
        if (l1 == 0 and l0 > 0) or (l0 > 0 and cos <= cos_max):
            return True
        if len(agreed) and agreed[g]:
            sx, sy, sz = source_normals[g, 0], source_normals[g, 1], source_normals[g, 2]
            if (ax * sx + az * sz) + ay * sy <= 0:
                return True
        if len(q0):
            longest = (ux * ux + uy * uy) + uz * uz
            ex, ey, ez = X[i2, 0] - X[i1, 0], X[i2, 1] - X[i1, 1], X[i2, 2] - X[i1, 2]
            longest = max(longest, (ex * ex + ey * ey) + ez * ez)
            ex, ey, ez = X[i0, 0] - X[i2, 0], X[i0, 1] - X[i2, 1], X[i0, 2] - X[i2, 2]
            longest = max(longest, (ex * ex + ey * ey) + ez * ez)
            q1 = l1 / (longest if longest > 0 else 1.0)
            if q1 < min_quality and q1 < q0[g]:
                return True
    return False


@njit(cache=True, nogil=True)
def _face_weights(X, G, faces, nb):
    """(len(faces)·nb,): a face point's weight, a nb-th of its face's area, each repeated nb times (numpy's
    arithmetic: np.cross's products, the squares summed left to right)."""
    out = np.empty(len(faces) * nb)
    for t in range(len(faces)):
        ax, ay, az = _normal(X, G, faces[t])[3:6]
        w = 0.5 * np.sqrt((ax * ax + ay * ay) + az * az) / nb
        for b in range(nb):
            out[t * nb + b] = w
    return out


@njit(cache=True, nogil=True)
def _boxes_at(X, G, R, B, flat):
    """Boxes and slivers of the faces R at X, into the output structure's B and flat (`_Output`)."""
    GR = np.empty((len(R), 3), np.int64)
    for t in range(len(R)):
        GR[t] = G[R[t]]
    BR, fR = face_boxes(X, GR), slivers(X, GR)
    for t in range(len(R)):
        B[R[t]] = BR[t]
        flat[R[t]] = fR[t]


@njit(cache=True, nogil=True, inline="always")
def _largest(a, least):
    """a.max(initial=least), as numpy takes it: a NaN wins."""
    top = least
    for x in a:
        if x > top or x != x:
            top = x
    return top


@njit(cache=True, nogil=True)
def shape_of(X, G, R):
    """(slivers, largest cosine of a smallest angle) of the faces R: what the sliver moves' test compares."""
    mc = _min_cos(X, G, R)
    count = 0
    for t in range(len(mc)):
        count += mc[t] > COS_SLIVER
    return count, _largest(mc, -np.inf)


@njit(cache=True, nogil=True)
def _shaped_better(X, G, R, count0, worst0, strict):
    """The sliver moves' test on the faces R at the moved positions (`Moves.attempt`)."""
    count, worst = shape_of(X, G, R)
    if strict:
        return count < count0 and worst <= worst0
    return count <= count0 and worst < worst0


@njit(cache=True, nogil=True)
def _touched(X, G, R, P, fa, hit, start, order, head, link, oB, oflat, ring_start, ring_face, H):
    """The input samples A whose nearest face is among the moved faces R, with their faces and distances
    after the move: to their own face, and for those at H or farther, to the nearest face around R (an upper
    bound: exact unless a face farther out is nearer, then refreshed when it is the largest, `Moves.worst`);
    and whether every one ended below H (the search stops at the first that does not)."""
    for g in R:
        hit[g] = True
    A = _on_faces(fa, hit, R, start, order, head, link)
    for g in R:
        hit[g] = False
    fA = np.empty(len(A), np.int64)
    for t in range(len(A)):
        fA[t] = fa[A[t]]
    d2A = _own_d2(P, A, X, G, oflat, fA)
    far = np.flatnonzero(d2A >= H * H)
    below = True
    if len(far):
        f1, e1 = fA[far], d2A[far]
        PA = np.empty((len(far), 3))
        for t in range(len(far)):
            PA[t] = P[A[far[t]]]
        corners = np.empty(3 * len(R), np.int64)
        for t in range(len(R)):
            for k in range(3):
                corners[3 * t + k] = G[R[t], k]
        below = _nearer(PA, X, G, oB, oflat, _ring(ring_start, ring_face, _sorted_unique(corners)), f1, e1, H)
        fA[far], d2A[far] = f1, e1
    dA = np.sqrt(d2A)
    return below and _largest(dA, 0.0) < H, A, fA, dA


@njit(cache=True, nogil=True)
def _output_samples(X, G, verts, R, vrow, nu, W, src, ring_start, ring_face):
    """The output's sample rows a move changes (the moved vertices' own, those used, then W's points of each
    face of R: `Moves.row_vertex`), their points, where each one's search of the input starts (``src``: the
    input face of each output face; empty: nowhere) and how many are vertices."""
    nb = W.shape[0]
    nv = 0
    for v in verts:
        nv += vrow[v] >= 0
    rows = np.empty(nv + nb * len(R), np.int64)
    QR = np.empty((len(rows), 3))
    seed = np.empty(len(rows) if len(src) else 0, np.int32)
    r = 0
    for v in verts:  # a vertex's search starts at the input face of one of its faces
        if vrow[v] >= 0:
            rows[r] = vrow[v]
            QR[r] = X[v]
            if len(src):
                seed[r] = src[ring_face[ring_start[v]]]
            r += 1
    QR[nv:] = _face_points(X, G, R, W)
    for t in range(len(R)):
        for b in range(nb):
            rows[r] = nu + nb * R[t] + b
            if len(src):
                seed[r] = src[R[t]]
            r += 1
    return rows, QR, seed, nv


@njit(cache=True, nogil=True)
def _failed():
    """`_trial`'s answer for a move that fails."""
    no_i, no_f, no_p = np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3))
    return (False, no_i, no_i, no_f, no_i, no_p, no_i, no_f, no_f, 0.0, 0.0, 0.0)


@njit(cache=True, nogil=True)
def _trial(verts, steps, R, count0, worst0, strict, H, lim, stamp0, state):
    """`Moves.attempt`'s test of a move (verts moved by steps; R: the faces at them; count0 < 0: without the
    sliver moves' test; ``state``: the rest it reads, `Moves.state`), compiled: whether it passes, with what
    the caller keeps when it does (the touched input samples A with their faces and distances, the output's
    sample rows with their points, faces, distances and weights, the new sums). X and the output's boxes and
    slivers (oB, oflat) are left moved when it passes, as they were when not. The arithmetic of the numpy
    expressions it stands for, operation for operation."""
    (X, G, n0, cos_max, agreed, source_normals, q0, min_quality, oB, oflat, P, fa, hit, start, order, head, link,
     ring_start, ring_face, vrow, nu, W, V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, src, w, d, e, qw,
     s_in, s_out, sq, sw) = state
    old = np.empty((len(verts), 3))
    for t in range(len(verts)):
        for k in range(3):
            old[t, k] = X[verts[t], k]
            X[verts[t], k] = X[verts[t], k] + steps[t, k]
    failed = _failed()
    if (count0 >= 0 and not _shaped_better(X, G, R, count0, worst0, strict)) or _refused(
            X, G, R, n0, cos_max, agreed, source_normals, q0, min_quality):
        for t in range(len(verts)):
            for k in range(3):
                X[verts[t], k] = old[t, k]
        return failed
    _boxes_at(X, G, R, oB, oflat)
    below, A, fA, dA = _touched(X, G, R, P, fa, hit, start, order, head, link, oB, oflat, ring_start, ring_face, H)
    if below:
        rows, QR, seed, nv = _output_samples(X, G, verts, R, vrow, nu, W, src, ring_start, ring_face)
        # the output's points searched one by one (each point's answer is its own): the first at H or
        # farther fails the move
        gR, eR = np.empty(len(rows), np.int64), np.empty(len(rows))
        near = True
        for r in range(len(rows)):
            f1, e1 = _query(QR[r:r + 1], V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, stamp0 + r,
                            seed[r:r + 1])
            gR[r], eR[r] = f1[0], np.sqrt(e1[0])
            if not eR[r] < H:  # (a NaN fails too, as in numpy's max)
                near = False
                break
        if near:
            wR = np.zeros(len(rows))
            wR[nv:] = _face_weights(X, G, R, W.shape[0])
            wA, dOld = np.empty(len(A)), np.empty(len(A))
            for t in range(len(A)):
                wA[t], dOld[t] = w[A[t]], d[A[t]]
            qwR, eOld = np.empty(len(rows)), np.empty(len(rows))
            for t in range(len(rows)):
                qwR[t], eOld[t] = qw[rows[t]], e[rows[t]]
            s_in1 = s_in + (_wsum2(wA, dA) - _wsum2(wA, dOld))
            s_out1 = s_out + (_wsum2(wR, eR) - _wsum2(qwR, eOld))
            sq1 = sq + (_wsum2(wR, np.ones(len(wR))) - _wsum2(qwR, np.ones(len(rows))))
            if sq1 > 0 and s_in1 / sw + s_out1 / sq1 <= lim:
                return (True, A, fA, dA, rows, QR, gR, eR, wR, s_in1, s_out1, sq1)
    for t in range(len(verts)):
        for k in range(3):
            X[verts[t], k] = old[t, k]
    _boxes_at(X, G, R, oB, oflat)
    return failed


@njit(cache=True, nogil=True)
def _onto(x, V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, stamp0):
    """(whether found, the point of the input nearest to x (3,), its face): the nearest face's closest point
    by Ericson's regions (`fit_rules._barycentric_at`), summed left to right; not found where that face is
    a sliver (measured by its edges: `Moves.onto_input`)."""
    P = x.reshape(1, 3)
    f, _ = _query(P, V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, stamp0, np.zeros(0, np.int32))
    out = np.zeros(3)
    if iflat[f[0]]:
        return False, out, f[0]
    b = np.empty((1, 3))
    regions(P, V, F, f, b)
    t0, t1, t2 = F[f[0], 0], F[f[0], 1], F[f[0], 2]
    for k in range(3):
        out[k] = (b[0, 0] * V[t0, k] + b[0, 1] * V[t1, k]) + b[0, 2] * V[t2, k]
    return True, out, f[0]


class _Largest:
    """The largest values of an array ``a`` that changes a few entries at a time (`note`), read without
    scanning it: every index whose value is at least ``floor`` is listed (``members``, with values that fell
    below since; ``listed`` marks them), so the largest value, the k-th largest and the indices at or above
    a bound are read from the list. Made again (the LISTED-th largest value the floor) when fewer than
    needed are at or above the floor, and pruned when it has grown to many times LISTED. Each answer is
    numpy's on the whole array (np.argmax, np.partition, np.flatnonzero); with a NaN among the listed
    values, the whole array is read."""

    def __init__(self, a):
        self.a = a
        self.build()

    def build(self):
        a, n = self.a, len(self.a)
        self.floor = np.partition(a, n - LISTED)[n - LISTED] if n > LISTED else -np.inf
        self.members = np.flatnonzero(~(a < self.floor))  # (a NaN is listed)
        self.listed = np.zeros(n, bool)
        self.listed[self.members] = True

    def note(self, rows):
        """After a[rows] changed."""
        rows = np.asarray(rows)
        new = rows[~(self.a[rows] < self.floor) & ~self.listed[rows]]
        if len(new):
            new = np.unique(new)
            self.listed[new] = True
            self.members = np.concatenate([self.members, new])
            if len(self.members) > 8 * LISTED:
                keep = ~(self.a[self.members] < self.floor)
                self.listed[self.members[~keep]] = False
                self.members = self.members[keep]

    def _above(self, need: int):
        """The listed indices at or above the floor and their values, at least ``need`` of them (built again
        if fewer); None when a value is NaN."""
        for _ in range(2):
            values = self.a[self.members]
            if np.isnan(values).any():
                return None
            keep = values >= self.floor
            if np.count_nonzero(keep) >= min(need, len(self.a)):
                return self.members[keep], values[keep]
            self.build()
        raise AssertionError("a fresh list holds LISTED values at or above its floor")

    def argmax(self) -> int:
        """np.argmax(a): the first index of the largest value."""
        got = self._above(1)
        if got is None:
            return int(np.argmax(self.a))
        rows, values = got
        return int(rows[values == values.max()].min())

    def kth(self, k: int) -> float:
        """The k-th largest value, as np.partition gives it (k ≤ LISTED, k < len(a))."""
        got = self._above(k)
        if got is None:
            return np.partition(self.a, len(self.a) - k)[len(self.a) - k]
        values = got[1]
        return np.partition(values, len(values) - k)[len(values) - k]

    def at_least(self, h: float):
        """np.flatnonzero(a >= h)."""
        got = self._above(1) if h >= self.floor else None
        if got is None:
            return np.flatnonzero(self.a >= h)
        rows, values = got
        return np.sort(rows[values >= h])


class Moves:
    """The output's positions X (k,3) (a copy, moved in place) with the distances of both sample sets
    (module docstring). V, F: the input; G (j,3): the output's faces; P (q,3), w (q,): the input's samples
    and weights (`refit.samples`); ``cos_max``, ``min_quality``: the re-fit's rules; ``fixed`` (k,) bool:
    vertices that stay; ``source_normals`` (j,3): the normal of the input face each output face continues
    (None: not checked); ``seeds`` (q,): an output face near each input sample (the re-fit's last
    attachment; -1: none) and ``source_faces`` (j,): that input face of each output face, where the
    searches start (the same answers, found sooner); ``into``: `grid` of V and F where the caller made it
    (`refit.InputSide`). ``ok``: whether there is anything to move (some free
    vertex, samples of weight on both sides)."""

    def __init__(self, V, F, X, G, P, w, cos_max, fixed=None, source_normals=None, min_quality=0.0,
                 seeds=None, source_faces=None, into=None):
        self.X = X = np.array(X, np.float64)
        self.V = V = np.ascontiguousarray(V, np.float64)
        self.F = F = np.ascontiguousarray(F, np.int64)
        self.G = G = np.ascontiguousarray(G, np.int64)
        self.P, self.w = P, w
        self.cos_max, self.min_quality = float(cos_max), float(min_quality)
        k, j = len(X), len(G)
        self.free = np.ones(k, bool) if fixed is None else ~np.asarray(fixed, bool)
        self.made = 0  # moves made
        self.ok = bool(self.free.any()) and j > 0 and len(P) > 0
        if not self.ok:
            return
        # the faces at each vertex (CSR)
        order, self.ring_start = counting_order(G.reshape(-1), k)
        self.ring_face = order // 3
        self.n0 = n0 = face_normals(X, G)
        # the rules' arrays as `_refused` takes them (empty: not checked)
        self.q0 = _quality(X, G, n0) if min_quality > 0 else np.zeros(0)
        if source_normals is None:
            self.agreed, self.source_normals = np.zeros(0, bool), np.zeros((0, 3))
        else:
            self.source_normals = np.ascontiguousarray(source_normals, np.float64)
            self.agreed = np.einsum("ij,ij->i", n0, self.source_normals) > 0
        self.no_seed = np.zeros(0, np.int32)
        # where each output sample's search of the input starts: its face's input face (a vertex: one of its faces')
        self.src = None if source_faces is None else np.asarray(source_faces, np.int32)
        self.used = used = np.unique(G)
        self.nb = len(BARY)
        # output samples: the used vertices, then nb points per face (row of face g: len(used) + nb·g + b)
        self.vrow = np.full(k, -1, np.int64)
        self.vrow[used] = np.arange(len(used))
        self.Q = np.concatenate([X[used], _face_points(X, G, np.arange(j), BARY)])
        # the input's structure: it never moves, and only the output's samples query it
        self.into = grid(V, F, FEW_QUERIES_CUBES_PER_FACE) if into is None else into
        self.ga, self.e = self.to_input(self.Q, np.arange(len(self.Q)))
        self.out = _Output(X, G)
        # input samples → output, exact (the re-fit's faces, where given, start each search)
        seed0 = self.no_seed if seeds is None else np.ascontiguousarray(seeds, np.int32)
        self.fa, self.d = self.out.nearest(X, P, seed0)
        self.by_face = _ByFace(self.fa, j)
        self.version = np.zeros(len(P), np.int64)  # the move count when each d was measured (exact then)
        self.top_d, self.top_e = _Largest(self.d), _Largest(self.e)
        self.qw = np.concatenate([np.zeros(len(used)), self.face_weights(np.arange(j))])
        self.sw, self.sq = _wsum2(w, np.ones(len(w))), _wsum2(self.qw, np.ones(len(self.qw)))  # left to right
        self.s_in, self.s_out = _wsum2(w, self.d), _wsum2(self.qw, self.e)
        self.ok = bool(self.sq > 0 and self.sw > 0)
        self.base = self.s_in / self.sw + self.s_out / self.sq if self.ok else 0.0  # the re-fit's mean square
        self.hit = np.zeros(j, bool)  # the faces a move touches

    def limit(self, slack: float) -> float:
        """The bound on the sum of the two mean squares (twice the two-way mean square) for an rms at most
        ``slack`` above the re-fit's."""
        return self.base * (1 + slack) ** 2

    def ring(self, verts):
        """The faces at any of ``verts``, sorted."""
        return _ring(self.ring_start, self.ring_face, np.asarray(verts, np.int64))

    def row_vertex(self, rows):
        """The output vertex each of the output's sample rows is (-1: a face's point). The rows are the used
        vertices in order, then BARY's points of face g at len(used) + nb·g + b."""
        nu = len(self.used)
        rows = np.asarray(rows, np.int64)
        return np.where(rows < nu, self.used[np.minimum(rows, nu - 1)], -1)

    def row_face(self, rows):
        """The output face whose point each of the output's sample rows is (-1: a vertex; `row_vertex`)."""
        nu = len(self.used)
        rows = np.asarray(rows, np.int64)
        return np.where(rows < nu, -1, (rows - nu) // self.nb)

    def to_input(self, Q, rows):
        """Nearest input faces and distances of the output's samples Q, rows ``rows`` of the kept ones."""
        if self.src is None:
            return search(self.V, self.F, self.into, Q, self.no_seed)
        v = self.row_vertex(rows)  # a vertex's search starts at the input face of one of its faces
        face = np.where(v >= 0, self.ring_face[self.ring_start[np.maximum(v, 0)]], self.row_face(rows))
        return search(self.V, self.F, self.into, Q, self.src[face])

    def onto_input(self, x):
        """The input's point nearest to x (3,)."""
        V, F = self.V, self.F
        x = np.ascontiguousarray(x, np.float64)
        found, y, g = _onto(x, V, F, *self.into, stamps(self.into, 1))
        if found:
            return y
        b = _barycentric_at(x[None], V, F, np.array([g], np.int32), self.into[1])[0]  # a sliver: by its edges
        t = F[g]
        return (b[0] * V[t[0]] + b[1] * V[t[1]]) + b[2] * V[t[2]]  # left to right: any CPU

    def face_weights(self, faces):
        """Each face point stands for a seventh of its face's area."""
        return _face_weights(self.X, self.G, np.asarray(faces, np.int64), self.nb)

    def worst(self):
        """The farthest sample: ('in', i, distance) or ('out', i, distance); stale input distances measured."""
        d, version, fa = self.d, self.version, self.fa
        while True:
            i = self.top_d.argmax()
            if version[i] == self.made:
                break
            # the stale ones among the REFRESH largest, measured at once (the REFRESH-th largest value is the
            # same whichever way a partition orders ties), and always the largest itself
            edge = self.top_d.kth(REFRESH) if len(d) > REFRESH else -np.inf
            top = self.top_d.at_least(edge)
            top = top[version[top] != self.made]
            f1, d1 = self.out.nearest(self.X, self.P[top], fa[top].astype(np.int32))
            self.s_in += _wsum2(self.w[top], d1) - _wsum2(self.w[top], d[top])
            fa[top], d[top], version[top] = f1, d1, self.made
            self.top_d.note(top)
            self.by_face.set(fa, top)
        o = self.top_e.argmax()
        return ("in", i, d[i]) if d[i] >= self.e[o] else ("out", o, self.e[o])

    def attempt(self, move: dict, H: float, lim: float, shape=None, ring=None) -> bool:
        """Make ``move`` ({vertex: step}) when every sample it touches ends below H, the sum of the two mean
        squares stays within ``lim`` (`limit`), no face breaks the re-fit's rules and, with ``shape``
        (count, worst, strict: the sliver moves' test, against the faces' slivers and largest cosine of a
        smallest angle before), the faces at the moved vertices pass it: with ``strict``, fewer slivers and
        a smallest angle no smaller; else no more slivers and a larger smallest angle. Else leave
        everything as it was. ``ring``: the faces at the moved vertices (`ring`), where the caller has them.
        The test is one compiled pass (`_trial`)."""
        verts = np.array(sorted(move), np.int64)
        steps = np.array([move[v] for v in verts.tolist()], np.float64).reshape(-1, 3)
        R = self.ring(verts) if ring is None else ring
        count0, worst0, strict = (-1, 0.0, False) if shape is None else shape
        first = stamps(self.into, len(verts) + self.nb * len(R))  # the input's searches: one per output row at most
        passed = _trial(verts, steps, R, int(count0), float(worst0), bool(strict), float(H),
                        float(lim), first, self.state())
        if passed[0]:
            self.commit(R, passed)
        return bool(passed[0])

    def state(self) -> tuple:
        """What a move's compiled test (`_trial`) reads besides the move, in its order: made again after
        each move made (the sums change; the search structures may be rebuilt)."""
        out, bf = self.out, self.by_face
        return (self.X, self.G, self.n0, self.cos_max, self.agreed, self.source_normals, self.q0, self.min_quality,
                out.B, out.flat, self.P, self.fa, self.hit, bf.start, bf.order, bf.head, bf.link, self.ring_start,
                self.ring_face, self.vrow, len(self.used), BARY, self.V, self.F, *self.into,
                self.no_seed if self.src is None else self.src, self.w, self.d, self.e, self.qw,
                float(self.s_in), float(self.s_out), float(self.sq), float(self.sw))

    def commit(self, R, passed) -> None:
        """Keep a move `_trial` passed (X already moved; R: the faces at the moved vertices)."""
        _, A, fA, dA, rows, QR, gR, eR, wR, s_in1, s_out1, sq1 = passed
        self.made += 1
        self.fa[A], self.d[A], self.version[A] = fA, dA, -1  # upper bounds (`_trial`)
        self.by_face.set(self.fa, A)
        self.top_d.note(A)
        self.Q[rows], self.ga[rows], self.e[rows], self.qw[rows] = QR, gR, eR, wR
        self.top_e.note(rows)
        self.s_in, self.s_out, self.sq = s_in1, s_out1, sq1
        self.out.mark(self.X, R)
