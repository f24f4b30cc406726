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
import functools
import typing
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
        """(K, width) state of the kept vertices after contracting pairs (K,2) to x (K,3). A model may also
        offer it as ``model.merge_kernel(VS, pairs, x, params)``, a static function of its arrays (as
        ``price_kernel``): then a round's merge and the next round's price can share one jit-compiled call
        that does not recompile for new settings (`qemjax._schedulers.device.start_step`)."""
        raise NotImplementedError

    # a static function (VS, pairs, params) -> `price`'s rows with each pair placed at its kept vertex
    # (`at_kept`), for a model whose price needs no ring; None: the model offers no such price
    at_kept_kernel = None

    def price_at_kept(self, VS, pairs, params, rings=None):
        """`price`'s rows for pairs (K,2) contracted onto their kept vertex (``pairs[:, 0]``), where it stands:
        what a locked vertex allows (`at_kept`, `qemjax._schedulers.locks`)."""
        if self.at_kept_kernel is None:
            raise NotImplementedError(f"method {self.name!r} cannot price a contraction at a fixed position")
        return self.at_kept_kernel(VS, pairs, params)

    refresh = None  # or a function (VS host rows, MeshView, verts) -> (len(verts), width) rows
    rank_weights = None  # or a function (parts (P, p) of the candidates) -> (p,) float64 weights
    reweight_step: ClassVar[float] = 0.05
    part_units: ClassVar[tuple[int, ...]] = ()  # each part's power of length (empty: not reported)
    # what a contraction's cost (row 3: ``max_error``, ``history.costs``) measures, for summaries; every
    # model's cost is in mesh units² (`_units.Frame.errors_to_mesh`)
    error_measure: ClassVar[str] = "quadric error (a sum of squared distances to planes)"

    @property
    def error_unit(self) -> str:
        """The cost's measure and unit, as the summary prints it: ``"quadric error (a sum of squared distances to planes), mesh units²"``. Not a
        distance of the output from the input: `simplify`'s ``stats["distance_max"]`` measures that."""
        return f"{self.error_measure}, mesh units²"

    def vertex_error(self, state: np.ndarray) -> np.ndarray:
        """(k,) float64 squared distances (normalised units) from state rows (k, width)."""
        return np.zeros(len(state))

    def describe(self) -> dict:
        """The settings, for stats: {field: value}."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


QUALITY_MAX = 3 ** 0.5 / 2  # 2·area / longest edge² of an equilateral triangle, the largest of any


@dataclasses.dataclass(frozen=True)
class Method(CostModel):
    """A cost model as a user chooses it (``simplify(method=...)``; `qemjax.QEM`, `qemjax.ESQEM`, ...): its
    fields are every setting of the method, with their defaults. Besides the model's own settings, every
    method has these keyword-only fields that act around its cost:

    regularize: λ ≥ 0, weight of a triangle-shape term added to the cost (`regularize`; 0: none). Offered
        for the pair models whose cost has no parts of its own (`takes_terms`: qem, line, probabilistic).
    area_weight: λ ≥ 0, weight of the squared surface-area change added to the cost (`area_term`; 0: none);
        offered as ``regularize`` is, and not with it.
    refit: N ≥ 0 rounds of re-fitting the output's positions to the input after simplifying (`qemjax._pipeline.refit`).
    polish: N ≥ 0, with a re-fit, at most N moves after it that each lower the largest sampled distance
        between the input and the output, both ways, keeping the two-way rms within 1 % of the re-fit's
        (`qemjax._pipeline.polish`; 0: none).
    sliver_moves: N ≥ 0, with a re-fit, at most N moves after the polish that each take a sliver's corner
        (a face under 10°) along the surface until its smallest angle clears 10°, or part of the way for a
        later pass, keeping every sample's distance below the largest and the two-way rms within 3 % of the
        re-fit's (`qemjax._pipeline.slivers`; 0: none).
    quality_threshold: s in [0, √3/2), a triangle-shape term in the parallel scheduler's ranking (0: none): a
        contraction that would make a face worse than it was, with 2·area / longest edge² = q under s, ranks
        as if it cost s / q times more, so slivers form only where nothing cheaper is near (after MeshLab's
        quality threshold; faces that were under s / 10 already do not count; `qemjax._schedulers.shape`). The cost (``max_error``, the stats) stays the model's, and nothing is
        refused: the face target is reached as without it. Other schedulers than the parallel one (the greedy
        queue) rank by cost alone, and say so.

    A new method is a frozen dataclass subclass of a method (or of this class) with fields of its own,
    registered with `qemjax.register_method`; nothing else needs editing.
    """

    regularize: float = dataclasses.field(default=0.0, kw_only=True)
    area_weight: float = dataclasses.field(default=0.0, kw_only=True)
    refit: int = dataclasses.field(default=0, kw_only=True)
    polish: int = dataclasses.field(default=0, kw_only=True)
    sliver_moves: int = dataclasses.field(default=0, kw_only=True)
    quality_threshold: float = dataclasses.field(default=0.0, kw_only=True)

    def __post_init__(self):
        _check_types(self)
        require_nonnegative(self, "regularize", "area_weight")
        for term in ("regularize", "area_weight"):
            if getattr(self, term) and not takes_terms(type(self)):
                why = (f"its cost has parts of its own ({', '.join(self.parts)})" if self.parts else
                       "its price is computed over each pair's ring")
                raise ValueError(f"{term} is not offered for method {self.name!r}: {why}; it is for the pair "
                                 "models without parts: 'qem', 'line', 'probabilistic'")
        if self.refit < 0:
            raise ValueError(f"refit must be an integer >= 0 (rounds), got {self.refit!r}")
        if self.polish < 0:
            raise ValueError(f"polish must be an integer >= 0 (moves), got {self.polish!r}")
        if self.sliver_moves < 0:
            raise ValueError(f"sliver_moves must be an integer >= 0 (moves), got {self.sliver_moves!r}")
        if not 0 <= self.quality_threshold < QUALITY_MAX:
            raise ValueError(f"quality_threshold must be in [0, {QUALITY_MAX:.3f}) (2·area / longest edge² of a "
                             f"triangle is at most √3/2, an equilateral one's), got {self.quality_threshold!r}")

    def changed(self) -> dict:
        """{field: value} of the fields that differ from the class's defaults (for tables and labels)."""
        out = {}
        for f in dataclasses.fields(self):
            default = f.default if f.default is not dataclasses.MISSING else None
            value = getattr(self, f.name)
            if not (type(value) is type(default) and value == default):
                out[f.name] = value
        return out

    def label(self) -> str:
        """The method's name and its changed fields: ``"esqem(curvature_weight=0.1)"``."""
        changed = self.changed()
        return self.name + ("(" + ", ".join(f"{k}={v!r}" for k, v in changed.items()) + ")" if changed else "")


@functools.lru_cache(maxsize=None)
def _hints(cls) -> tuple:
    """(name, base type, None allowed) of each field of a method class with a plain type (bool, int,
    float, str; ``X | None``), from its real annotations."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        hint = hints.get(f.name)
        args = typing.get_args(hint)
        optional = type(None) in args
        base = [a for a in args if a is not type(None)] if args else [hint]
        if len(base) == 1 and base[0] in (bool, int, float, str):
            out.append((f.name, base[0], optional))
    return tuple(out)


def takes_terms(cls) -> bool:
    """Whether a method class takes the added terms (``regularize``, ``area_weight``: `Term`): a pair model
    whose cost has no parts of its own (`regularize.Regularized`, `area_term.AreaTerm` wrap its price)."""
    return not cls.parts and not cls.uses_ring and hasattr(cls, "price_kernel")


def require_nonnegative(model, *names: str) -> None:
    """ValueError naming the first of the fields ``names`` of ``model`` that is not finite and >= 0 (a
    method's field types are checked before, by `_check_types`)."""
    for name in names:
        x = getattr(model, name)
        if not (x >= 0 and np.isfinite(x)):
            raise ValueError(f"{name} must be finite and >= 0, got {x!r}")


def _check_types(method) -> None:
    """Each field of a plain type holds a value of it (ValueError naming the field); a whole number given
    for a float field is stored as a float, so equal settings are equal objects."""
    for name, kind, optional in _hints(type(method)):
        x = getattr(method, name)
        if x is None and optional:
            continue
        if kind is bool:
            if not isinstance(x, (bool, np.bool_)):
                raise ValueError(f"{name} must be True or False, got {x!r}")
        elif kind in (int, float):
            if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)):
                raise ValueError(f"{name} must be a number, got {x!r}")
            if kind is int and not (np.isfinite(x) and float(x) == int(x)):  # NaN, inf: no whole number
                raise ValueError(f"{name} must be a whole number, got {x!r}")
            object.__setattr__(method, name, kind(x))
        elif not isinstance(x, str):
            raise ValueError(f"{name} must be a string, got {x!r}")


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

