"""Garland & Heckbert's quadric error metric as a cost model.

State: each vertex's quadric (10 floats, in a frame centred on the vertex: `_kernels.quadrics`).
Price: the optimal placement with its fall-backs (`_kernels.placement`, hand-fused for the CPU).
Merge: Q1 + Q2 re-expressed at the new position. Support: pair (a contraction changes only the
quadric of the kept vertex, so only the pairs at it need a new price).

With ``memoryless=True`` (`memoryless`): the quadrics of the vertices around each contraction are rebuilt
from the current faces (`refresh`), so a contraction changes the quadrics of the kept vertex's whole
1-ring: support ring, and 15 more state columns (`memoryless`); ``volume_weight`` adds Lindstrom &
Turk's volume preservation as a penalty, ``memory_weight`` a share of the summed (history) quadric.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._mesh import topology as topo
from .._mesh.arrays import face_normals, face_stats
from .._kernels.batching import DTYPE, bucket, pad_rows
from .._mesh.incidence import FaceLists
from .._kernels import placement, quadrics
from . import at_kept
from . import memoryless as ml
from .base import MeshInput, Method, require_nonnegative

PLACEMENTS = ("optimal", "rank", "endpoints")
POLISH_MOVES = 256  # the default's minimax polish: moves at most (`_pipeline.polish`)
SLIVER_MOVES = 4096  # the default's sliver moves after it: moves at most (`_pipeline.slivers`)
SHAPE_THRESHOLD = 0.4  # the default's shape term in the parallel rounds' ranking (``quality_threshold``)


def initial_quadrics(V: np.ndarray, F: np.ndarray, *, area_weighted: bool, boundary_weight: float,
                     feature_edges: np.ndarray | None, boundary=None, means=None,
                     area_power: float = 1.0) -> np.ndarray:
    """(n,10) float32 vertex quadrics (each in its vertex's frame) with boundary/feature planes; with
    ``area_weighted`` the planes are weighted by (area / mean area)^area_power.
    ``boundary``: `topo.boundary_edges` of F when the caller has it; ``means``: (mean face area, mean
    squared edge length) when the caller has them (else `face_stats` of V and F)."""
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
        Vp, Fp, fmask, np.asarray(area_power if area_weighted else 0.0, DTYPE),
        pad_rows(be.astype(np.int32), nb, fill=n), pad_rows(cn, nb), pad_rows(cw, nb),
        np.arange(nb) < len(be),
        *(np.asarray(m, np.float32) for m in (face_stats(V, F)[1:] if means is None else means)))
    return np.asarray(Q)[:n]


def _price(VS, pairs, params):
    return placement.place_pairs(VS, pairs, params["endpoints_only"], params["cond_eps"], params["max_shift"])


def _merge(VS, pairs, x, params):
    return placement.merged_quadrics(VS, pairs, x)


def _merge_memoryless(VS, pairs, x, params):
    return ml.merge(VS, pairs, x)


def _price_rank(VS, pairs, params):
    return placement.place_pairs_rank(VS, pairs, params["endpoints_only"], params["rank_eps"],
                                      params["max_shift"])


@dataclasses.dataclass(frozen=True)
class QEM(Method):
    """Quadric error metric (Garland & Heckbert 1997).

    placement: ``'optimal'`` (solve when well conditioned; else the best point on the segment; else the
        best of the endpoints and the midpoint), ``'rank'`` (the truncated solve: the well-determined
        directions of the quadric solved, the others kept at the midpoint; `_kernels.placement`) or
        ``'endpoints'`` (the paper's fixed placement).
    area_weighted: weight each face plane by area / mean face area (else 1, the paper's choice).
    area_power: with area_weighted, weight by (area / mean area)^area_power instead (0.5: small faces,
        such as those at thin tips, count for more than their area; see docs/benchmarks.md).
    boundary_weight: weight of the plane through each boundary (or feature) edge perpendicular to its face.
    cond_eps: ``'optimal'``: the 3×3 solve is used when det(A) > cond_eps·‖A‖_F³.
    rank_eps: ``'rank'``: eigenvalues of A at or below rank_eps·λmax are truncated.
    max_shift: either solve is used when its solution lies within max_shift·|v2 − v1| of the midpoint.
    memoryless: rebuild the quadrics around each contraction from the current faces instead of summing
        them (Lindstrom & Turk 1998; `memoryless`). Support becomes ring and the state 25 floats wide.
    volume_weight: λ ≥ 0, memoryless only: add λ·(volume change / mean face area)² to each pair's quadric
        before placing (`memoryless`); 0 adds nothing.
    memory_weight: μ ≥ 0, memoryless only: price with Q_current + μ·Q_summed (0: memoryless alone).
    late_memoryless: K ≥ 1, or 0 (off): summed quadrics until the faces fall to K × the face target, then
        memoryless ones for the rest of the run (`_schedulers.late`), priced with Q_current +
        late_memory_weight·Q_summed (and ``volume_weight``). No effect with ``memoryless=True`` (memoryless
        throughout). The run stays summed without a face target (``max_error`` alone), with kept attributes
        or feature edges, with ``regularize`` or ``area_weight``, and on a scheduler registered from outside
        (stats["late_memoryless_off"] says why; a default run that one of these turns it off for warns too).
    late_memory_weight: μ ≥ 0 of the late phase (1: the summed quadric at full weight).
    """

    name: ClassVar[str] = "qem"
    per_pair_params: ClassVar[bool] = True  # (memoryless rows too: a batch refreshes each copy with its own model)
    memoryless_refused: ClassVar[str] = ""  # a subclass that cannot run memoryless: why (the error says it)

    placement: str = "optimal"
    area_weighted: bool = True
    area_power: float = 1.0
    boundary_weight: float = 100.0
    cond_eps: float = 1e-5
    rank_eps: float = 1e-4
    max_shift: float = 2.0
    memoryless: bool = False
    volume_weight: float = 0.0
    memory_weight: float = 0.0
    late_memoryless: float = 0.0
    late_memory_weight: float = 1.0

    # the memoryless mode's differences, as properties (ESQEM overrides all three as class attributes)
    width = property(lambda self: ml.WIDTH if self.memoryless else quadrics.QSIZE)
    support = property(lambda self: "ring" if self.memoryless else "pair")

    @property
    def error_measure(self) -> str:
        """What a cost is: a quadric error (memoryless: of the current faces, plus the weighted terms; a late
        switch's costs are both kinds, each a sum of squared distances to planes)."""
        if not self.memoryless:
            return "quadric error (a sum of squared distances to planes)"
        return "quadric error of the current faces (a sum of squared distances to their planes)" + "".join(
            f" plus {t}" for t, w in (("μ·summed quadric", self.memory_weight),
                                      ("λ·volume term", self.volume_weight)) if w)

    @property
    def refresh(self):
        """memoryless: (MeshView, verts) -> the rebuilt state rows (`memoryless.refresh_rows`); else None."""
        if not self.memoryless:
            return None
        return lambda view, verts: ml.refresh_rows(self, view, verts)

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "volume_weight", "memory_weight", "boundary_weight", "cond_eps", "rank_eps",
                            "max_shift")
        if (self.memoryless or self.late_memoryless) and self.memoryless_refused:
            which = "memoryless=True" if self.memoryless else "late_memoryless"
            raise ValueError(f"{which} works with method='qem' only ({self.memoryless_refused})")
        require_nonnegative(self, "late_memoryless", "late_memory_weight")
        if self.late_memoryless and self.late_memoryless < 1:
            raise ValueError(f"late_memoryless must be 0 (off) or at least 1 (a multiple of the face target), "
                             f"got {self.late_memoryless}")
        if self.memory_weight and not self.memoryless:
            raise ValueError("memory_weight > 0 needs memoryless=True (it weights a term of the memoryless cost; "
                             "late_memory_weight is the late phase's)")
        if self.volume_weight and not (self.memoryless or self.late_memoryless):
            raise ValueError("volume_weight > 0 needs memoryless=True or late_memoryless (it weights a term of "
                             "the memoryless cost)")
        if self.memoryless and (self.regularize or self.area_weight):
            raise ValueError("memoryless=True works with method='qem' only, without regularize and "
                             "area_weight (their terms price the summed quadrics' placement)")
        if self.placement not in PLACEMENTS:
            raise ValueError(f"unknown placement {self.placement!r}; choose from {PLACEMENTS}")
        if not 0 <= self.area_power <= 2:
            raise ValueError(f"area_power must be in [0, 2], got {self.area_power}")

    @classmethod
    def classic(cls) -> "QEM":
        """Garland & Heckbert's summed quadrics as this package ran them by default until the default was
        chosen by ranking (`default`): area-weighted planes, boundary planes at weight 100, the optimal
        placement, no re-fit. The same as ``QEM()``; ``method="classic"``."""
        return cls()

    @classmethod
    def default(cls) -> "QEM":
        """What `simplify` runs when no method is given (``method="default"``): summed quadrics with face
        planes weighted by (area / mean area)^0.6, boundary planes at weight 10, memoryless quadrics for
        the contractions below twice the target, the parallel rounds ranking contractions that would
        leave a sliver behind others (``quality_threshold``), then one round of re-fitting the positions to the input
        (``refit=1``), its minimax polish (``polish``, at most POLISH_MOVES moves) and sliver moves
        (``sliver_moves``, at most SLIVER_MOVES). Chosen by ranking every candidate against the
        peers on the benchmark meshes at 10 % and 1 % (``experiments/figures/rank_peers.py``; docs/methods.md, "QEM and
        its presets", which gives its time against `classic`'s)."""
        return cls(area_power=0.6, boundary_weight=10.0, refit=1, late_memoryless=2.0, polish=POLISH_MOVES,
                   quality_threshold=SHAPE_THRESHOLD, sliver_moves=SLIVER_MOVES)

    @classmethod
    def accurate(cls) -> "QEM":
        """Lindstrom–Turk-style memoryless quadrics with 0.3 of the summed (Garland–Heckbert) ones, the
        rank-aware placement with loose limits (``rank_eps=1e-3``, ``max_shift=0.5``), face planes weighted
        by (area / mean area)^0.6, boundary planes at weight 10, then one round of re-fitting the positions
        to the input (``refit=1``). Chosen on the benchmark meshes against meshoptimizer, fast-simplification,
        pyfqmr, pymeshlab and libigl (``experiments/figures/rank_peers.py``; docs/methods.md, "QEM and its
        presets", with its time against the default's). ``method="accurate"`` names it, and
        ``dataclasses.replace(QEM.accurate(), refit=0)`` is it without the re-fit."""
        return cls(memoryless=True, memory_weight=0.3, placement="rank", area_power=0.6, boundary_weight=10.0,
                   rank_eps=1e-3, max_shift=0.5, refit=1)

    @property
    def switches_late(self) -> bool:
        """Whether a run turns memoryless late (``late_memoryless``, not ``memoryless=True``)."""
        return bool(self.late_memoryless) and not self.memoryless

    def late_model(self) -> "QEM | None":
        """The model of a run's last stretch (``late_memoryless``): this one memoryless with the late phase's
        memory weight, without re-fit (the pipeline re-fits once, after the run); None when it does not
        switch."""
        if not self.switches_late:
            return None
        return dataclasses.replace(self, memoryless=True, memory_weight=self.late_memory_weight,
                                   late_memoryless=0.0, refit=0)

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        if self.memoryless and mesh.feature_edges is not None and len(mesh.feature_edges):
            raise ValueError("memoryless=True does not track feature edges through contractions; "
                             "leave feature_edges unset or use memoryless=False")
        if self.memoryless:  # the same rebuild as after each contraction, for every vertex
            means = face_stats(mesh.V, mesh.F)[1:] if mesh.means is None else mesh.means
            n = len(mesh.V)
            return ml.state_rows(self, mesh.V, FaceLists(mesh.F, n), np.arange(n), means)
        return initial_quadrics(mesh.V, mesh.F, area_weighted=self.area_weighted,
                                boundary_weight=self.boundary_weight, feature_edges=mesh.feature_edges,
                                boundary=mesh.boundary, means=mesh.means, area_power=self.area_power)

    def state_key(self):
        if type(self) is not QEM or self.memoryless:  # a subclass, or the memoryless rows, hold more state
            return self
        return (QEM, self.area_weighted, self.area_power, self.boundary_weight)

    def kernel_params(self) -> dict:
        params = {"endpoints_only": np.asarray(self.placement == "endpoints"),
                  "cond_eps": np.asarray(self.cond_eps, DTYPE), "rank_eps": np.asarray(self.rank_eps, DTYPE),
                  "max_shift": np.asarray(self.max_shift, DTYPE)}
        if self.memoryless:
            params["volume_weight"] = np.asarray(self.volume_weight, DTYPE)
            params["memory_weight"] = np.asarray(self.memory_weight, DTYPE)
        return params

    @property
    def price_kernel(self):
        """The price as a static function of arrays (VS, pairs, params): one kernel per placement mode
        ('rank' is its own kernel, so the default's compiled code stays as it was; memoryless rows have
        their own pair with the volume term)."""
        if self.memoryless:
            return ml.price_rank if self.placement == "rank" else ml.price_optimal
        return _price_rank if self.placement == "rank" else _price

    def price(self, VS, pairs, params, rings=None):
        return self.price_kernel(VS, pairs, params)

    @property
    def at_kept_kernel(self):
        """The price at the kept vertex (`at_kept`): the summed quadric (memoryless: its own rows) there."""
        return ml.price_at_kept if self.memoryless else at_kept.qem

    @property
    def merge_kernel(self):
        """The merge as a static function of arrays (VS, pairs, x, params)."""
        return _merge_memoryless if self.memoryless else _merge

    def merge(self, VS, pairs, x, params):
        return self.merge_kernel(VS, pairs, x, params)

    def vertex_error(self, state: np.ndarray) -> np.ndarray:
        return np.maximum(state[:, 9].astype(np.float64), 0.0)
