"""Quadrics carried from level to level of a partitioned run.

An in-core run with summed quadrics prices each contraction with the planes of every input face merged into
its two vertices: a vertex that has absorbed a sharp feature remembers it. Each group of a partitioned run is
a run of its own, and a run builds its quadrics from the faces it reads; without carrying, every level after
the first would start from the planes of the coarser mesh the level before left (a spike that three long
faces hold, for one, is cheap to remove there and costly in the input). So a group's run starts from the
quadrics its pieces carry (`Carry.__call__`, the pipeline's seed), summed where pieces share a border vertex
(`pieces.stitch`), and writes with its output the quadric of each output vertex (`Carry.export`): the sum
of those of the vertices the run merged into it, taken from the run's contractions in float64, each moved
to the output vertex's position. That is the quadric the in-core run would hold there, to the rounding.

Units: a carried quadric is centred on its vertex, in units of the whole input's largest extent (``unit``,
the same for every group, so that the values stay near 1 at any scale the in-core path accepts), its face
planes weighted by area^p (in those units; p the model's area power, 0 when it does not weight by area)
instead of by (area / the run's mean face area)^p. A run divides by its own mean, as it does for the planes
it builds, so the ranking within a run and the balance of the late memoryless stretch against the summed
quadric are an in-core run's. The boundary planes are scaled by the mean squared edge length instead; they
travel with the same factor (both are squared lengths: a close approximation).

Level 1 starts from the parts' own quadrics without the planes along edges whose two ends are locked: those
edges are cuts between parts, not boundaries of the input. A part alone cannot tell them from an edge of
the input's own boundary whose two ends both lie on cuts (where a boundary runs along a cut, a stretch of
them: a strip of long faces at an open end that the cut zigzags through); `scatter` finds those edges over
the whole input (`scatter.borders_on_cuts`) and they keep their planes (``boundary``). Had they lost them,
the later levels, which start from the carried quadrics alone, would price that border as free to move and
the last level would pull it in.

Only the summed quadrics of `QEM` (the default, ``"classic"``) are carried, with kept UVs too: a run that
keeps them adds its own faces' attribute quadrics to the carried position quadrics
(`AttributeQEM.with_attributes`), so its geometry remembers the input and its UVs follow the faces it
reads. Any other model's state is more than one quadric and its runs start from their own, as before.
"""
from __future__ import annotations

import numpy as np

from .._costs.attributes import AttributeQEM
from .._costs.qem import QEM
from .._kernels.batching import DTYPE
from .._kernels import quadrics
from .._mesh import topology as topo
from .._pipeline import stages
from . import pieces


def carries(model) -> bool:
    """Whether a run of ``model`` starts from carried quadrics: QEM's summed ones (with attributes too)."""
    return type(model) in (QEM, AttributeQEM) and not model.memoryless


def _state(job, start, q: np.ndarray) -> np.ndarray:
    """The run's starting state from its position quadrics ``q`` (n,10), in its numbering."""
    if type(job.model) is QEM:
        return q
    return job.model.with_attributes(start, q)


def _scale(job, unit: float) -> tuple[float, float]:
    """(carried units per frame unit, the run's (mean face area in carried units)^p): a run's quadric times
    these is a carried one (`to_mesh`)."""
    geo, model = job.geo, job.model
    s = float(geo.frame.scale) / unit
    p = float(model.area_power) if model.area_weighted else 0.0
    area = float(stages.frame_means(geo)[0]) * s * s
    return s, area ** p


def to_mesh(Q: np.ndarray, s: float, k: float) -> np.ndarray:
    """(n,10) quadrics of a run (frame units, weights relative to its mean face area) -> carried ones (units
    of ``s`` per frame unit, weights area^p)."""
    Q = np.asarray(Q, np.float64) * k
    Q[:, 6:9] *= s
    Q[:, 9] *= s * s
    return Q


def to_run(Q: np.ndarray, s: float, k: float) -> np.ndarray:
    """`to_mesh`'s inverse."""
    Q = np.asarray(Q, np.float64) / k
    Q[:, 6:9] /= s
    Q[:, 9] /= s * s
    return Q


def translate(Q: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """(n,10) quadrics re-centred ``delta`` (n,3) away, float64 (`_kernels.quadrics.translate`'s algebra)."""
    return np.stack(quadrics.translate_c(list(Q.T), list(delta.T)), 1)


class Carry:
    """One group's carried quadrics: ``V`` (n,3) in mesh units, ``Q`` (n,10) carried quadrics of the group's
    vertices (its pieces', stitched) or None (level 1: the run's own, without the cuts' planes), ``unit``
    the carried units' length in mesh units (the input's largest extent), ``boundary`` (k,2) or None: edges
    of the input's own boundary whose two ends are locked, in ``V``'s numbering (level 1: they keep their
    planes, the other edges between locked vertices are cuts). Called as the pipeline's seed
    (`stages.SEED`), it gives the run's starting state and keeps what `export` needs."""

    def __init__(self, V: np.ndarray, Q: np.ndarray | None, unit: float = 1.0, exports: bool = True,
                 boundary: np.ndarray | None = None):
        self.V, self.Q, self.unit, self.exports = V, Q, float(unit), exports
        self.boundary = boundary
        self.start = None  # carried quadrics of the cleaned input's vertices, once the run has started
        self.carried = False

    def __call__(self, job, start) -> np.ndarray:
        """The state ``job``'s run starts from (``start``: the `_costs.MeshInput` of the model's own)."""
        S = self._seed(job, start)
        self.Q = None  # held no longer than needed: a last level's group is the run's largest
        if not self.exports:
            self.start = None
        return S

    def _seed(self, job, start) -> np.ndarray:
        if not carries(job.model):
            return job.model.init_state(start)
        self.carried = True
        lk = job.locks
        clean = job.geo if lk is None else lk.geo  # the run's geometry is renumbered when it has locks
        s, k = _scale(job, self.unit)
        if self.Q is None:
            if lk is not None:  # the model's own quadrics without the planes along the cuts
                locked = lk.locked[lk.perm]
                be, bf = start.boundary
                keep = ~(locked[be[:, 0]] & locked[be[:, 1]]) | self._input_boundary(lk, clean, be)
                start = start._replace(boundary=(be[keep], bf[keep]))
            q = QEM.init_state(job.model, start)
            self.start = to_mesh(q if lk is None else q[lk.inv], s, k)
            return _state(job, start, q)
        vm = clean.vertex_map
        ok = np.flatnonzero(vm >= 0)  # a welded vertex's quadric joins the one it was welded into
        Qc = translate(self.Q[ok], (clean.V[vm[ok]] - self.V[ok]) / self.unit)
        self.start = pieces.sum_rows(Qc, vm[ok], len(clean.V))
        q = to_run(self.start, s, k).astype(DTYPE)
        return _state(job, start, q if lk is None else q[lk.perm])

    def _input_boundary(self, lk, clean, be: np.ndarray) -> np.ndarray:
        """Which of the run's boundary edges ``be`` (its numbering) are among ``boundary``: edges of the
        input's own boundary whose two ends lie on cuts."""
        if self.boundary is None or not len(self.boundary) or not len(be):
            return np.zeros(len(be), bool)
        vm = clean.vertex_map
        E = vm[self.boundary]
        E = lk.inv[E[(E >= 0).all(1)]]
        n = len(clean.V)
        return np.isin(topo.edge_keys(be[:, 0], be[:, 1], n), topo.edge_keys(E[:, 0], E[:, 1], n))

    def export(self, res) -> np.ndarray | None:
        """(k,10) carried quadrics of ``res``'s output vertices, or None when the run did not carry (or was
        made with ``exports=False``)."""
        if self.start is None:
            return None
        n = len(res.input_vertices)
        root = topo.contraction_roots(res.history.pairs, n)  # the vertex each one was merged into
        slot = np.full(n, -1)
        slot[res.source_vertices] = np.arange(len(res.source_vertices))
        j = slot[root]
        ok = np.flatnonzero(j >= 0)  # vertices of dropped faces (coincident, vanishing parts) carry nowhere
        Q = translate(self.start[ok], (res.vertices[j[ok]] - res.input_vertices[ok]) / self.unit)
        return pieces.sum_rows(Q, j[ok], len(res.source_vertices))
