"""The cost-model interface: what a method declares so that both schedulers can run it.

A cost model is a small frozen object (its fields are the method's settings) with a tiny interface:

- **state**: each vertex carries ``width`` floats after its position; `init_state` computes them from
  the cleaned mesh (QEM: the 10 numbers of a quadric). The schedulers keep one (n, 3 + width) float32
  row per vertex, on the host and on the device.
- **price** (jit-compiled, batched): index pairs into those rows -> one stacked (5 + len(parts), K) array:
  the new position (rows 0-2), the cost (row 3, what selection ranks), the branch taken (row 4, an index
  into ``branches``) and the cost parts (rows 5…) where a method combines terms. Ring models also get
  the faces around each pair (`ring.Rings`).
- **merge** (jit-compiled, batched): the kept vertex's new state after contracting a pair to x.
- **refresh** (optional): derived state recomputed, after a round, for vertices whose neighbourhood
  changed (curvature, area around a vertex); None when the state is only accumulated.
- **support**: ``"pair"``: a contraction changes only the costs of pairs at the kept vertex;
  ``"ring"``: also those of every pair in its 1-ring (the cost reads the faces around the pair).
- **per_pair_params**: its kernels accept every param as a (K,) array (one value per pair) as well as a
  0-d one, with the same results; `simplify_batch` then runs configurations of one mesh in shared rounds.
- **vertex_error**: a squared distance per vertex, in the normalised units of the run.
- **rank_weights** (optional): for a model whose selection adds weighted parts to the cost, the weights
  (p,) float64 from the parts (P,p) of the candidate pairs; the schedulers then rank pairs by
  cost + parts @ weights (the cost alone is still what ``max_error`` and the history mean), and ask for
  new weights whenever the face count has fallen by ``reweight_step`` since the last time. None: rank by
  the cost. ``part_units`` gives each part's power of length, so the history reports it in mesh units.

Numeric settings reach the kernels through `kernel_params` as 0-d arrays (a pytree): a new value never
recompiles, and a sweep can give every configuration its own.
"""
from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, NamedTuple

import numpy as np


class MeshInput(NamedTuple):
    """What `init_state` and `refresh` see: positions V (n,3) float32 at unit extent, faces F (m,3) int64,
    boundary edges (B,2) directed as in their face and those faces (B,), feature edges (k,2) or None, and
    (mean face area, mean squared edge length) at unit extent, summed on the host (or None), and the
    attribute values at each face corner (m,3,k) for a model over appearance attributes (else None)."""

    V: np.ndarray
    F: np.ndarray
    boundary: tuple
    feature_edges: Any
    means: Any = None
    attributes: Any = None


@dataclasses.dataclass(frozen=True)
class CostModel:
    """Base of every cost model; subclasses are frozen dataclasses whose fields are their settings."""

    name: ClassVar[str] = ""
    width: ClassVar[int] = 0
    support: ClassVar[str] = "pair"
    uses_ring: ClassVar[bool] = False
    ring_dead: ClassVar[bool] = False  # the ring also holds the faces the contraction removes (`ring`)
    parts: ClassVar[tuple[str, ...]] = ()
    branches: ClassVar[tuple[str, ...]] = ("solve", "segment", "endpoint", "truncated")
    per_pair_params: ClassVar[bool] = False  # its kernels also take each param as a (K,) array, one per pair

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        """(n, width) float32 state rows."""
        raise NotImplementedError

    def kernel_params(self) -> dict:
        """The numeric settings as 0-d arrays, by name (passed to `price` and `merge`)."""
        return {}

    def state_key(self):
        """Models with equal keys compute equal `init_state` on one mesh (a batch computes it once)."""
        return self

    def price(self, VS, pairs, params, rings=None):
        """Device rows VS (N, 3 + width), pairs (K,2) int32 -> (5 + len(parts), K) array (see module).
        A model whose price needs no ring also offers it as ``model.price_kernel(VS, pairs, params)``, a static
        function of its arrays (settings come in ``params``), so wrappers can call it inside their own
        jit without recompiling for new settings."""
        raise NotImplementedError

    def merge(self, VS, pairs, x, params):
        """(K, width) state of the kept vertices after contracting pairs (K,2) to x (K,3)."""
        raise NotImplementedError

    refresh = None  # or a function (VS host rows, MeshView, verts) -> (len(verts), width) rows
    rank_weights = None  # or a function (parts (P, p) of the candidates) -> (p,) float64 weights
    reweight_step: ClassVar[float] = 0.05
    part_units: ClassVar[tuple[int, ...]] = ()  # each part's power of length (empty: not reported)
    # what a contraction's cost (row 3: ``max_error``, ``history.costs``) measures, for summaries; every
    # model's cost is in mesh units² (`_units.Frame.errors_to_mesh`)
    error_measure: ClassVar[str] = "squared distance"

    @property
    def error_unit(self) -> str:
        """The cost's measure and unit, as the summary prints it: ``"squared distance, mesh units²"``."""
        return f"{self.error_measure}, mesh units²"

    def vertex_error(self, state: np.ndarray) -> np.ndarray:
        """(k,) float64 squared distances (normalised units) from state rows (k, width)."""
        return np.zeros(len(state))

    def describe(self) -> dict:
        """The settings, for stats: {field: value}."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


class MeshView(NamedTuple):
    """What `CostModel.refresh` reads after a round: the live faces around vertices (`FaceLists`) and
    the current vertex rows (n, 3 + width) float32 on the host."""

    faces: Any
    rows: np.ndarray


@dataclasses.dataclass(frozen=True)
class Term(CostModel):
    """A term added to another model's cost (`TERMS`: ``regularize``, ``area_weight``): it prices with its
    own kernel and takes the vertex state, the merge, the branches and the error from ``base``."""

    base: CostModel

    name = property(lambda self: self.base.name)
    per_pair_params = property(lambda self: self.base.per_pair_params and type(self).own_per_pair)
    own_per_pair: ClassVar[bool] = True  # the term's own kernel takes per-pair params
    width = property(lambda self: self.base.width)
    branches = property(lambda self: self.base.branches)
    added: ClassVar[str] = ""  # what the term adds to the base's cost, for `error_measure`
    error_measure = property(lambda self: f"{self.base.error_measure} plus {self.added}")

    def init_state(self, mesh):
        return self.base.init_state(mesh)

    def state_key(self):
        return self.base.state_key()

    def merge(self, VS, pairs, x, params):
        return self.base.merge(VS, pairs, x, params)

    def vertex_error(self, state):
        return self.base.vertex_error(state)

