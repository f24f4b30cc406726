"""Re-fit the simplified mesh's vertex positions to the input surface (``simplify(refit=N)``).

A contraction places its vertex once, from the quadrics it has then (summed, rebuilt or blended); later
contractions around it change the surface it belongs to but never move it again. At very coarse outputs
(a few dozen faces) those early placements are far from the best positions for the final connectivity,
whatever the quadric. This post-pass is the continuous step of Hoppe et al. 1993 ("Mesh optimization",
E_dist with the connectivity fixed):

1. the input is sampled at every vertex (weight: a third of the area of its faces) and every face's
   centroid (weight: its area), the weights scaled to mean 1;
2. each sample is attached to its nearest point on the output (`qemjax._mesh.grid_nearest`), as barycentric
   coordinates b of an output face, among the faces of its own part (the input's connected parts, joined
   as aggregation joins them; an output face belongs to the part of the input face it continues): a
   sample of one part must not pull another part that happens to lie nearer (the truck's 50 parts did);
3. the positions X minimise Σ_i w_i·|b_i·X − p_i|² + λ·Σ_v |x_v − x_v⁰|² (a sparse linear least-squares
   problem, the same for the three coordinates, its normal equations summed in compiled loops
   (`refit_system`), solved by conjugate gradients in a fixed order of sums so
   that every CPU gives the same bits: `qemjax._mesh.spd_solve`): the samples' squared distances to the output surface,
   with a small damping λ = DAMPING · Σw / (vertices) towards the current positions x⁰, which holds a
   vertex that no sample sees and keeps the system definite;
4. a face whose normal the new positions turn by the flip angle or more (``cos_max``, as the contractions'
   rule), or turn against the input face it continues (``source_faces``; the output's validity rule), has the
   moves of its vertices halved, up to HALVINGS times, then undone (back to the position
   before this round), repeated until no face turns.

Steps 2-4 run ``rounds`` times (the attachment changes as the surface moves). Faces, connectivity and
everything but the positions stay as they are; kept UVs follow the moves (`carry_uv`), seam vertices being
held by the caller.
"""
from __future__ import annotations

import threading
import warnings
from typing import NamedTuple

import numpy as np

from .._mesh.arrays import face_normals
from .._mesh import fixed_order as _fixed
from .._mesh.box_bounds import row_bounds
from .._mesh.compiled import njit
from .._mesh.grid_nearest import FEW_QUERIES_CUBES_PER_FACE, grid, nearest, slivers
from .._mesh.spd_solve import solve_csr
from .fit_rules import _barycentric_at, _quality, _turned
from .refit_system import accumulate, finish, layout

DAMPING = 1e-3  # λ per vertex, relative to the mean sample weight (module docstring, step 3)
_ROWS = 32_768  # samples per block of the normal equations' assembly
RTOL = 1e-12  # the normal equations' relative residual (conjugate gradients, `_mesh.spd_solve`)
HALVINGS = 4  # a move that turns a face is halved this many times before it is undone (step 4)


def samples(V: np.ndarray, F: np.ndarray, part: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (q,3), weights (q,), mean 1, parts (q,)): the input's vertices (a third of their faces' area
    each) and face centroids (their area), with the part of each (``part``: a label per input vertex);
    samples of zero weight are left out."""
    P, w, lab = _sample_rows(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64),
                             np.ascontiguousarray(part))
    keep = w > 0
    if not keep.any():
        return P[:0], w[:0], lab[:0]
    if keep.all():  # the usual case: no copies
        return P, w / w.mean(), lab
    return P[keep], w[keep] / w[keep].mean(), lab[keep]


@njit(cache=True, nogil=True)  # the re-fits of a batch run on threads (`stages.refit_all`)
def _sample_rows(V, F, part):
    """`samples` before the zero weights go and the weights are scaled: every vertex, then every face's
    centroid, with their weights and parts, in one pass (no (m,3) temporaries: a 5.5 M-face input's peak).
    The arithmetic of numpy's ``0.5 * norm(face_normals(V, F), axis=1)``, ``V[F].sum(1) / 3`` and
    ``bincount(F.ravel(), repeat(area / 3, 3))``, in the same order: the same bits."""
    n, m = V.shape[0], F.shape[0]
    P = np.empty((n + m, 3))
    w = np.zeros(n + m)
    lab = np.empty(n + m, part.dtype)
    for i in range(n):
        P[i, 0], P[i, 1], P[i, 2] = V[i, 0], V[i, 1], V[i, 2]
        lab[i] = part[i]
    for f in range(m):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        ux, uy, uz = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        vx, vy, vz = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        area = 0.5 * np.sqrt((nx * nx + ny * ny) + nz * nz)
        w[n + f] = area
        third = area / 3
        w[a] += third
        w[b] += third
        w[c] += third
        for k in range(3):
            P[n + f, k] = ((V[a, k] + V[b, k]) + V[c, k]) / 3
        lab[n + f] = part[a]
    return P, w, lab


def _attach(X: np.ndarray, G: np.ndarray, gpart: np.ndarray, P: np.ndarray, spart: np.ndarray):
    """For each sample, a nearest output face among those of its part (-1: its part has none)."""
    f = np.full(len(P), -1, np.int32 if len(G) < 2**31 else np.int64)
    order = np.argsort(gpart, kind="stable")
    starts = np.searchsorted(gpart[order], np.unique(gpart))
    for faces in np.split(order, starts[1:]):
        at = spart == gpart[faces[0]]
        if at.all():  # one part (the usual case): the samples as they are, not a copy of them
            f[:] = faces[nearest(X, G[faces], P)[0]]
            continue
        mine = np.flatnonzero(at)
        if len(mine):
            f[mine] = faces[nearest(X, G[faces], P[mine])[0]]
    return f


def _system(Ps, sw, X, G, f, col, lay, lam):
    """The normal equations (N as its CSR arrays (indptr, indices, data), R (free, 3)) of the samples Ps with weights' square roots sw, attached
    to faces f of (X, G) (`refit_system`). The barycentric coordinates are found in blocks of rows."""
    indptr, indices, pos = lay
    data, rhs = np.zeros(len(indices)), np.zeros((len(indptr) - 1, 3))
    flat = slivers(X, G)
    for s in range(0, len(Ps), _ROWS):
        B = _barycentric_at(Ps[s : s + _ROWS], X, G, f[s : s + _ROWS], flat)
        B *= sw[s : s + _ROWS, None]
        accumulate(B, f[s : s + _ROWS], Ps[s : s + _ROWS], sw[s : s + _ROWS], G, col, X, pos, data, rhs)
    return finish(indptr, indices, data, lam), rhs


class _Prepared(NamedTuple):
    """What `InputSide` made: the input (V float64, F int64), its unit frame (centre, unit) and positions in it
    (Vn; None where the frame is of no use, `_in_frame`), its samples with their parts (`samples`; None: not
    made) and its search structure (`_mesh.grid_nearest.grid` of Vn; None: not made)."""
    V: np.ndarray
    F: np.ndarray
    centre: np.ndarray
    unit: float
    Vn: np.ndarray
    samples: tuple | None
    into: tuple | None


class InputSide:
    """The input's side of a re-fit: the surface fitted to and what `refit` computes of it alone (its unit
    frame, its samples, and for the moves after the fit its search structure), made once. ``make()``
    returns (V, F); ``part``: a part label per input vertex (None: one part), the labels the samples take.
    With ``thread``, they are made on a thread of their own from the start, while the caller runs the
    rounds (which keep one core busy, not two): the re-fit then finds them ready. Without, the first re-fit
    to ask makes them (re-fits on threads may share one side: `stages.refit_all`). The same values either
    way; `refit` waits for them (`get`), and an error making them is raised there."""

    def __init__(self, make, part=None, moves: bool = True, thread: bool = False):
        self._make, self._part, self._moves = make, part, moves
        self._done, self._error = None, None
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="qemjax-input-side", daemon=True) if thread else None
        if self._thread is not None:
            self._thread.start()

    def _run(self):
        try:
            V, F = self._make()
            V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
            centre, unit, Vn = _in_frame(V)
            made = into = None
            if Vn is not None:  # (else `refit` fits nothing)
                part = np.zeros(len(V), np.int32) if self._part is None else np.asarray(self._part, np.int32)
                made = samples(Vn, F, part)
                if self._moves and len(F):
                    into = grid(np.ascontiguousarray(Vn), np.ascontiguousarray(F), FEW_QUERIES_CUBES_PER_FACE)
            self._done = _Prepared(V, F, centre, unit, Vn, made, into)
        except BaseException as e:  # noqa: BLE001 - raised again where the re-fit asks for them
            self._error = e
        self._make = None

    def get(self) -> _Prepared:
        """What was made (made here, now, where no thread started it)."""
        if self._thread is not None:
            self._thread.join()
        else:
            with self._lock:
                if self._done is None and self._error is None:
                    self._run()
        if self._error is not None:
            raise self._error
        return self._done

    @property
    def one_part(self) -> bool:
        """Whether the samples were labelled as one part."""
        return self._part is None


def unit_frame(V: np.ndarray, bounds: tuple | None = None) -> tuple[np.ndarray, float]:
    """(centre (3,), unit): the centre of V's bounding box and its largest extent (no vertices: 0 and 1).
    Work in this frame keeps squared distances and areas finite at any scale (1e-100 or 1e100 mesh units).
    ``bounds``: V's (lo, hi) when the caller has them."""
    lo, hi = bounds if bounds is not None else (row_bounds(V) if len(V) else (np.zeros(3), np.ones(3)))
    return 0.5 * (lo + hi), float(np.max(hi - lo))


def _in_frame(V: np.ndarray) -> tuple[np.ndarray, float, np.ndarray | None]:
    """(centre, unit, V in the unit frame): `unit_frame` and the positions in it, None where the frame is of no
    use (no extent, or not finite: there is nothing to fit to)."""
    centre, unit = unit_frame(V)
    if not (np.isfinite(unit) and unit > 0 and np.all(np.isfinite(centre))):
        return centre, unit, None
    return centre, unit, (V - centre) / unit


def refit(V: np.ndarray, F: np.ndarray, X: np.ndarray, G: np.ndarray, rounds: int, cos_max: float,
          part: np.ndarray | None = None, source_faces: np.ndarray | None = None,
          fixed: np.ndarray | None = None, sampled: list | None = None, min_quality: float = 0.0,
          polish: int = 0, sliver_moves: int = 0, report: dict | None = None,
          side: InputSide | None = None) -> np.ndarray:
    """Positions X (k,3) of the output faces G (j,3) re-fitted to the input (V, F) in ``rounds`` rounds
    (module docstring); float64, the input's units. ``part``: a part label per input vertex and
    ``source_faces``: the input face each output face continues (None: one part). ``fixed`` (k,) bool:
    vertices that keep their position exactly (locked ones; the others are fitted around them). X is
    returned unchanged (a copy) when there is nothing to fit. ``sampled``: a list to which the input's
    samples are appended, (points in the input's unit frame, weights), once made, then the output face
    each was attached to in the last round (-1: none): the measured distance of the same run takes the
    samples (`measure.distance`) instead of making them again, and starts each search at that face.
    ``min_quality``: the quality guard (`Topology.min_angle`; 0: off): a face's move is shortened as a
    turned face's is when it would take the face's 2·area / longest² below it and below what it was.
    ``polish``: then at most that many moves of the minimax polish (`_pipeline.polish`), under the same
    rules; ``sliver_moves``: then at most that many moves of slivers' corners (`_pipeline.slivers`);
    ``report``: a dict that gets the numbers made as ``polish_moves`` and ``sliver_moves``. ``side``: an
    `InputSide` of the input, whose V and F then stand for ``V`` and ``F`` (made once, perhaps already)."""
    X0 = np.array(X, np.float64)
    G = np.asarray(G, np.int64)
    pre = None
    if side is not None:
        pre = side.get()
        V, F, centre, unit, Vn = pre.V, pre.F, pre.centre, pre.unit, pre.Vn
    else:
        V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
        centre, unit, Vn = _in_frame(V)
    if Vn is None:
        return X0
    X = (X0 - centre) / unit
    after = polish > 0 or sliver_moves > 0  # moves after the re-fit (`moves`), which take its samples
    kept = sampled if sampled is not None else ([] if after else None)
    Y = _fit(Vn, F, X, G, rounds, cos_max, part, source_faces, fixed, kept, min_quality,
             None if pre is None else (pre.samples, side.one_part))
    if after and rounds > 0 and kept:
        from .moves import Moves
        from .polish import polish as _polish
        from .slivers import lift_slivers

        ns = None if source_faces is None else face_normals(Vn, F[np.asarray(source_faces, np.int64)])
        m = Moves(Vn, F, Y, G, *kept[0], cos_max, fixed, ns, min_quality,
                  seeds=kept[1] if len(kept) > 1 else None, source_faces=source_faces,
                  into=None if pre is None else pre.into)
        made = (_polish(m, polish), lift_slivers(m, sliver_moves))
        Y = m.X
        if sampled is not None and len(sampled) > 1:  # seeds nearer the moved output's faces (same answers)
            sampled[1] = m.fa
        if report is not None:
            report["polish_moves"], report["sliver_moves"] = made
    out = Y * unit + centre
    moved = np.any(Y != X, axis=1) & np.all(np.isfinite(out), axis=1)  # the others keep X0 bit for bit
    return np.where(moved[:, None], out, X0)


def _fit(V, F, X, G, rounds, cos_max, part, source_faces, fixed, sampled=None, min_quality=0.0,
         made=None) -> np.ndarray:
    """`refit` in the unit frame. ``made``: (the input's samples, whether they were labelled as one part)
    from an `InputSide`, taken where the fit labels them so (None: made here)."""
    src = None if source_faces is None else F[np.asarray(source_faces, np.int64)]  # each output face's input face
    ns = None if src is None else face_normals(V, src)  # its normal
    one = part is None or src is None
    if one:
        part, gpart = np.zeros(len(V), np.int32), np.zeros(len(G), np.int32)
    else:
        part = np.asarray(part, np.int32)  # labels of parts: fewer than the vertices
        gpart = part[src[:, 0]]
    if made is not None and made[0] is not None and made[1] == one:
        P, w, spart = made[0]
    else:
        P, w, spart = samples(V, F, part)
    if sampled is not None:
        sampled.append((P, w))
    k = len(X)
    if rounds <= 0 or len(G) == 0 or len(P) == 0:
        return X
    lam = DAMPING * w.sum() / k
    free = np.ones(k, bool) if fixed is None else ~np.asarray(fixed, bool)
    if not free.any():
        return X
    col = np.where(free, np.cumsum(free) - 1, -1)  # each output vertex's row in the system (-1: fixed)
    lay = layout(G, col, int(free.sum()))
    for r in range(rounds):
        f = _attach(X, G, gpart, P, spart)
        if sampled is not None and r == rounds - 1:  # the last round's faces: the measured distance's seeds
            sampled.append(f)
        seen = f >= 0
        if seen.all():  # the usual case: no copies of the samples
            Ps, sw = P, np.sqrt(w)
        else:
            Ps, sw, f = P[seen], np.sqrt(w[seen]), f[seen]
        N, rhs = _system(Ps, sw, X, G, f, col, lay, lam)
        del f, Ps, sw
        rhs = rhs + lam * X[free]
        Y = X.copy()
        Y[free], converged = solve_csr(*N, rhs, X[free], rtol=RTOL)  # fixed-order sums: the same bits on every CPU
        if not converged:  # the last iterate still lowers the fit's error; the checks below still hold
            warnings.warn(f"re-fit: the solver stopped short of its tolerance ({RTOL:g}) on {len(Y[free])} vertices; "
                          "the positions are fitted less closely than usual", stacklevel=4)
        if not np.all(np.isfinite(Y)):
            break
        n0 = face_normals(X, G)
        agreed = None if ns is None else np.einsum("ij,ij->i", n0, ns) > 0
        q0 = _quality(X, G, n0) if min_quality > 0 else None  # the faces' shape before the moves
        cut = np.zeros(k, np.int64)  # times each vertex's move was halved (HALVINGS + 1: undone)
        while True:  # each pass only shortens moves, and an undone one stays undone: it ends
            n1 = face_normals(Y, G)
            bad = _turned(n0, n1, cos_max)
            if q0 is not None:  # nor may a face end below the quality bound and below its shape before
                q1 = _quality(Y, G, n1)
                bad |= (q1 < min_quality) & (q1 < q0)
            if ns is not None:  # nor may a face come to point against the input face it continues
                bad |= agreed & (np.einsum("ij,ij->i", n1, ns) <= 0)
            new = np.unique(G[bad])
            new = new[cut[new] <= HALVINGS]
            if len(new) == 0:
                break
            cut[new] += 1
            Y[new] = np.where((cut[new] > HALVINGS)[:, None], X[new], 0.5 * (X[new] + Y[new]))
        X = Y
    return X


def carry_uv(X0: np.ndarray, X1: np.ndarray, F: np.ndarray, wedge_faces: np.ndarray, wedge_vertex: np.ndarray,
             uv: np.ndarray) -> np.ndarray:
    """The UVs (w,2) of a mesh whose vertices the re-fit moved from X0 to X1 (k,3), each wedge moved with its
    vertex: by the displacement times its chart's UV gradient, the area-weighted mean over the faces the
    wedge belongs to of each face's affine map from its plane to UV space. To first order a point keeps the
    texture it showed: a move across the surface (most of what the re-fit does: onto the input) changes
    nothing, a move along it slides along the map; without this the sideways part of a move would drag the
    texture with it. A wedge whose vertex did not move keeps its UV bit for bit; one with only zero-area
    faces too.
    F (j,3) and wedge_faces (j,3): the faces' vertices and corner wedges; wedge_vertex (w,): each wedge's
    vertex."""
    X0, X1 = np.asarray(X0, np.float64), np.asarray(X1, np.float64)
    F, WF = np.asarray(F, np.int64), np.asarray(wedge_faces, np.int64)
    uv = np.asarray(uv, np.float64)
    P, U = X0[F], uv[WF]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    d1, d2 = U[:, 1] - U[:, 0], U[:, 2] - U[:, 0]
    g11, g12, g22 = _fixed.dot(e1, e1), _fixed.dot(e1, e2), _fixed.dot(e2, e2)
    det = g11 * g22 - g12 * g12  # (2·area)²
    ok = det > 1e-12 * g11 * g22  # a usable plane: the sine at corner 0 above 1e-6 (det cancels below)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    # the map's rows: J = [d1 d2] · (EᵀE)⁻¹Eᵀ with E = [e1 e2]; c1, c2 are the rows of (EᵀE)⁻¹Eᵀ
    c1 = (g22 * inv)[:, None] * e1 - (g12 * inv)[:, None] * e2
    c2 = (g11 * inv)[:, None] * e2 - (g12 * inv)[:, None] * e1
    J = d1[:, :, None] * c1[:, None, :] + d2[:, :, None] * c2[:, None, :]  # (j,2,3)
    area = np.where(ok, np.sqrt(np.maximum(det, 0.0)), 0.0)
    w = len(uv)
    sums = np.zeros((w, 6))
    weight = np.zeros(w)
    flat = (J * area[:, None, None]).reshape(-1, 6)
    for k in range(3):  # each corner's wedge gathers its face's map
        weight += np.bincount(WF[:, k], area, minlength=w)
        for c in range(6):
            sums[:, c] += np.bincount(WF[:, k], flat[:, c], minlength=w)
    wv = np.asarray(wedge_vertex, np.int64)
    move = X1[wv] - X0[wv]
    go = np.any(move != 0, axis=1) & (weight > 0)
    grad = sums[go].reshape(-1, 2, 3) / weight[go][:, None, None]
    out = uv.copy()
    out[go] = uv[go] + _fixed.dot(grad, move[go][:, None, :])
    return out

