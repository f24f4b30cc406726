"""Memoryless quadrics (Lindstrom & Turk 1998's key idea) for the QEM model (``simplify(memoryless=True)``).

Garland–Heckbert's quadric of a vertex is the sum of the quadrics of the vertices merged into it: it
remembers every plane of the input that the vertex stands for. A memoryless quadric forgets them: after
each contraction, the quadric of every vertex whose neighbourhood changed is rebuilt from the faces around
it *now* (plus a plane through each current boundary edge at it), exactly as the initial quadrics are built
from the input. The cost of contracting (v1, v2) to x is then the weighted sum of squared distances of x
to the planes of the current faces around v1 and v2: it measures how far the contraction moves the
surface from the current mesh, not from the input.

Weights are those of the initial quadrics (`quadrics.vertex_quadrics`): each face plane by
(area / mean area)^p (p = ``area_power``; p = 0 without ``area_weighted``), each boundary plane by
``boundary_weight``·(|e|² / mean |e|²)^p, with the means of the *input* (at unit extent) so that weights
rebuilt late in a run compare with those built early. The two means ride along in two extra state
columns (constant per run).

Memory (``memory_weight`` μ ≥ 0): each vertex also keeps the Garland–Heckbert quadric (the history, summed
by `merge` as QEM does), and a pair is priced with Q_current + μ·Q_history. μ = 0 is the memoryless cost
alone; μ > 0 adds back a share of the distance to the input's planes, which bounds how far thin parts can
drift (a purely memoryless run measures each step against the current surface only).

Volume (``volume_weight`` λ ≥ 0, Lindstrom & Turk's volume preservation as a penalty): each vertex also
carries g(v) = Σ ½(c1 − v)×(c2 − v) over the live faces [v, c1, c2] around it (their area-weighted
normals), so moving v to x changes the enclosed volume by g(v)·(x − v)/3. Contracting (v1, v2) to x
changes it by about (g(v1)·(x − v1) + g(v2)·(x − v2))/3 (the two faces holding both count twice), and
the price adds λ·s(x)², s(x) = (g(v1)·(x − v1) + g(v2)·(x − v2)) / (mean face area of the input), to the
merged quadric before placing: a squared length, like the quadric's costs. λ = 0 adds nothing.

The rebuild runs on the host in float64, compiled (`current_quadrics`), for the vertices the schedulers name
after each round (parallel) or contraction (greedy): one batched pass over the live faces around them.
A memoryless row is [position (3), history quadric (10), current quadric (10), g (3), input mean face
area, input mean squared edge length] (`CCOLS`, `GCOLS`, `MCOLS`): 25 floats of state instead of QEM's 10.
The history quadric sits where QEM keeps its quadric, so `vertex_error` is still the summed quadric's
error at the vertex (a squared distance to the input's planes); ``max_error`` bounds the cost that
ranks (Q_current + μ·Q_history + the volume term).
"""
from __future__ import annotations

from .._kernels.lazy import jnp  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._kernels.batching import DTYPE
from .._mesh.incidence import FaceLists
from .._kernels import kernel, placement
from .._kernels import quadrics as qd
from . import at_kept

WIDTH = 25  # state floats of a memoryless row (after the position)
CCOLS = 13  # first column of the current quadric in a vertex row [position, history, current, g, means]
GCOLS = (23, 24, 25)  # columns of g(v)
MCOLS = (26, 27)  # columns of the input's mean face area and mean squared edge length


def current_quadrics(P: np.ndarray, faces: FaceLists, verts: np.ndarray, *, area_power,
                     boundary_weight, mean_area, mean_e2) -> np.ndarray:
    """(k,13) float64: the quadrics (10) of ``verts`` (k,), each in its vertex's frame (so b = c = 0), from
    the live faces around it (positions P (n,3)): the plane of each face weighted by
    (area / mean_area)^area_power, and for each boundary edge at the vertex (an edge in one live face only)
    the plane through it perpendicular to that face, weighted by boundary_weight·(|e|² / mean_e2)^area_power
    (none when boundary_weight is 0); then g(v) (3): the sum of ½(c1 − v)×(c2 − v) over those faces. The
    four weights are numbers, or (k,) arrays: each vertex's own.
    Compiled (`current_sums.rebuild`; its numpy twin: tests/reference_memoryless.py)."""
    from .current_sums import rebuild  # numba, imported on first use: `qemjax --help` lists this model's fields

    verts = np.ascontiguousarray(verts, np.int64)

    def each(x):  # one writable signature for numbers and arrays alike
        x = np.asarray(x, np.float64)
        return np.require(x, requirements=("C", "W")) if x.ndim else np.full(verts.shape, x)
    return rebuild(np.ascontiguousarray(P, np.float64), faces.F, faces.alive, faces.cnt, faces.off, faces.pool,
                   verts, each(area_power), each(boundary_weight), each(mean_area), each(mean_e2))


def weights(model) -> tuple[float, float]:
    """(area power, boundary weight) of a memoryless model's face and boundary planes."""
    return float(model.area_power) if model.area_weighted else 0.0, float(model.boundary_weight)


def state_rows(model, P: np.ndarray, faces: FaceLists, verts: np.ndarray, means, history=None) -> np.ndarray:
    """(k, WIDTH) float32 state rows of ``verts``: the history quadrics (k,10) (None: the current ones, as
    at the start), `current_quadrics` with the model's weights, then the two input means ((2,), or (k, 2):
    each vertex's)."""
    return _rows(*weights(model), P, faces, verts, means, history)


def refresh_rows(model, view, verts) -> np.ndarray:
    """`CostModel.refresh` of a memoryless QEM model: the state rows of ``verts`` with the current quadric
    and g rebuilt (the history quadric and the input means are kept)."""
    return refresh_rows_each(*weights(model), view, verts)


def refresh_rows_each(powers, boundary_weights, view, verts) -> np.ndarray:
    """`refresh_rows` with the weights given (`weights` of a model, or (k,) arrays: each vertex's, for the
    copies of a batch side by side, one compiled pass for all of them); each row keeps the input means it
    holds (one run's rows all hold the same)."""
    verts = np.asarray(verts, np.int64)
    if len(verts) == 0:
        return np.zeros((0, WIDTH), DTYPE)
    return _rows(powers, boundary_weights, view.rows[:, :3], view.faces, verts,
                 view.rows[verts, MCOLS[0]:MCOLS[1] + 1], view.rows[verts, 3:CCOLS])


def _rows(powers, boundary_weights, P, faces, verts, means, history) -> np.ndarray:
    verts = np.asarray(verts, np.int64)
    means = np.broadcast_to(np.asarray(means, np.float64), (len(verts), 2))
    q = current_quadrics(P, faces, verts, area_power=powers, boundary_weight=boundary_weights,
                         mean_area=means[:, 0], mean_e2=means[:, 1])
    hist = q[:, :10] if history is None else np.asarray(history, np.float64)
    return np.concatenate([hist, q, means], 1).astype(DTYPE)


# -- the kernels ---------------------------------------------------------------------------------------

def _with_volume(VS, pairs, volume_weight, memory_weight):
    """Component lists (q1, q2, p1, p2) as `placement._gather_rows`: each the current quadric plus μ times
    the history, and λ·s(x)² (module docstring) added to q1 (in v1's frame: s = G·u + g2·(p1 − p2),
    u = x − p1, G = g1 + g2)."""
    a = jnp.take(VS, pairs[:, 0], axis=0, mode="clip").T
    b = jnp.take(VS, pairs[:, 1], axis=0, mode="clip").T
    mu = memory_weight
    q1 = [a[CCOLS + k] + mu * a[3 + k] for k in range(10)]
    q2 = [b[CCOLS + k] + mu * b[3 + k] for k in range(10)]
    p1, p2 = [a[k] for k in range(3)], [b[k] for k in range(3)]
    g1, g2 = [a[c] for c in GCOLS], [b[c] for c in GCOLS]
    ma = jnp.maximum(a[MCOLS[0]], jnp.finfo(a.dtype).tiny)
    G = [(g1[i] + g2[i]) / ma for i in range(3)]
    s0 = qd.dot(g2, [p1[i] - p2[i] for i in range(3)]) / ma
    lam = volume_weight
    pen = [G[0] * G[0], G[0] * G[1], G[0] * G[2], G[1] * G[1], G[1] * G[2], G[2] * G[2],
           G[0] * s0, G[1] * s0, G[2] * s0, s0 * s0]
    return [q1[k] + lam * pen[k] for k in range(10)], q2, p1, p2


@kernel
def price_optimal(VS, pairs, params):
    """`placement.place_pairs` for memoryless rows with the volume term: (5,K)."""
    q1, q2, p1, p2 = _with_volume(VS, pairs, params["volume_weight"], params["memory_weight"])
    x, cost, branch, _, _ = placement._place(q1, q2, p1, p2, params["endpoints_only"], params["cond_eps"],
                                             params["max_shift"])
    return jnp.stack(x + [cost, branch.astype(cost.dtype)], 0)


@kernel
def price_rank(VS, pairs, params):
    """`placement.place_pairs_rank` for memoryless rows with the volume term: (5,K)."""
    q1, q2, p1, p2 = _with_volume(VS, pairs, params["volume_weight"], params["memory_weight"])
    x, cost, branch, _, _ = placement._place_rank(q1, q2, p1, p2, params["endpoints_only"],
                                                  params["rank_eps"], params["max_shift"])
    return jnp.stack(x + [cost, branch.astype(cost.dtype)], 0)


@kernel
def merge(VS, pairs, x):
    """The history quadrics summed at x (QEM's merge: they sit in QEM's columns), then the kept vertex's
    current quadric, g and input means (`refresh` rebuilds the first two at once)."""
    q = placement.merged_quadrics(VS, pairs, x)
    return jnp.concatenate([q, jnp.take(VS[:, CCOLS:MCOLS[1] + 1], pairs[:, 0], axis=0)], 1)


@kernel
def price_at_kept(VS, pairs, params):
    """Memoryless rows at the kept vertex (`at_kept`): current + μ·summed quadric with the volume term there."""
    q1, q2, p1, p2 = _with_volume(VS, pairs, params["volume_weight"], params["memory_weight"])
    return at_kept.stacked(p1, at_kept.quadric_cost(q1, q2, p1, p2), at_kept.ENDPOINT)
