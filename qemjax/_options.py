"""Settings as frozen data: what a run was asked to do, resolved once by `simplify`.

`Schedule` holds the parallel scheduler's tunables (how much a round takes); `Options` holds the
model-independent rules every scheduler applies (validity, limits). A cost model is itself a frozen
object whose fields are its settings (`qemjax._costs`); its numbers reach the kernels as 0-d arrays (a
pytree, `CostModel.kernel_params`), so a new value never recompiles. Nothing here is a module global:
tests and sweeps pass these objects.
"""
from __future__ import annotations

import dataclasses
import math
import numpy as np


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How much the parallel scheduler takes per round (results depend on these; the defaults are the
    measured trade-off between quality and rounds, see docs/schedulers.md).

    gate: a round's candidates are the pairs costing at most gate × the cost of the k-th cheapest, where
        k = min(contractions still needed / (2·tail), gate_fraction × live pairs).
    tail: near the target a round takes at most about 1/(2·tail) of what is still needed.
    free_cost: costs below this (squared distance, with the extent of the pair's connected part as unit)
        always pass the gate (flat regions).
    max_passes: selection passes per round; pass_yield: stop a round's passes once one accepts under this
        fraction of what the round took.

    ``Schedule(gate=1.0, gate_fraction=1e-12, free_cost=0.0)`` takes one pair per round: the parallel
    scheduler then reproduces the greedy queue contraction for contraction.
    """

    gate: float = 1.2
    gate_fraction: float = 0.05
    tail: int = 10
    free_cost: float = 1e-10
    max_passes: int = 8
    pass_yield: float = 0.1

    def __post_init__(self):
        for name in ("gate", "gate_fraction", "free_cost", "pass_yield"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Schedule.{name} must be finite and >= 0, got {v}")
        if self.gate < 1:
            raise ValueError(f"Schedule.gate must be >= 1 (a multiple of the k-th cheapest cost), got {self.gate}")
        for name in ("tail", "max_passes"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValueError(f"Schedule.{name} must be a positive integer, got {v!r}")


def _number(owner: str, name: str, x) -> float:
    """x as a float; ValueError naming ``owner.name`` unless x is a real number (bools are refused)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ValueError(f"{owner}.{name} must be a number, got {x!r}")
    return float(x)


def _bool(owner: str, name: str, x) -> None:
    if not isinstance(x, (bool, np.bool_)):
        raise ValueError(f"{owner}.{name} must be True or False, got {x!r}")


@dataclasses.dataclass(frozen=True)
class Topology:
    """What a run may do to the mesh's topology, and how the input is cleaned (``simplify(topology=...)``).

    preserve_topology: forbid contractions that break the link condition or make faces coincide (keeps a
        manifold's genus and boundary loops). None (default): True when pair_threshold is 0, else False.
        With False, contractions may create non-manifold edges, and coincident faces are dropped
        (opposite ones cancel, so small parts can vanish), as in Garland & Heckbert's paper.
    prune: with preserve_topology, let small separate parts vanish (their last faces may contract away);
        False (default): every part keeps at least one face.
    pair_threshold: t in mesh units; besides edges, any two vertices within distance t may contract
        (Garland–Heckbert's aggregation: separate parts can join). 0 = edge contraction only.
    flip_angle: forbid a contraction that turns any surviving face's normal by this many degrees or more
        (90: any sign flip or collapse to zero area); None allows flips.
    weld: merge vertices with identical coordinates first (G&H need shared corners).
    """

    preserve_topology: bool | None = None
    prune: bool = False
    pair_threshold: float = 0.0
    flip_angle: float | None = 90.0
    weld: bool = True

    def __post_init__(self):
        _bool("Topology", "prune", self.prune)
        _bool("Topology", "weld", self.weld)
        if self.preserve_topology is not None:
            _bool("Topology", "preserve_topology", self.preserve_topology)
        t = _number("Topology", "pair_threshold", self.pair_threshold)
        if not (t >= 0 and np.isfinite(t)):
            raise ValueError(f"pair_threshold must be a finite distance >= 0, got {self.pair_threshold}")
        if self.preserve_topology and t > 0:
            raise ValueError("pair_threshold > 0 joins separate parts, which changes topology: "
                             "use preserve_topology=False (the default when pair_threshold > 0)")
        if self.flip_angle is not None:
            a = _number("Topology", "flip_angle", self.flip_angle)
            if not 0 < a <= 180:
                raise ValueError(f"flip_angle must be in (0, 180] degrees or None, got {self.flip_angle}")

    @property
    def manifold(self) -> bool:
        """preserve_topology as the run applies it (None resolved)."""
        return self.pair_threshold == 0 if self.preserve_topology is None else bool(self.preserve_topology)

    @property
    def cos_max(self) -> float:
        """The cosine of the flip angle (-2: flips allowed)."""
        return -2.0 if self.flip_angle is None else math.cos(math.radians(self.flip_angle))


@dataclasses.dataclass(frozen=True)
class Attributes:
    """Which appearance attributes a run carries through, and how they weigh (``simplify(attributes=...)``;
    docs/attributes.md).

    ``attributes``: ``'auto'`` (each kind the input carries without seams, and UVs with seams when the material names a
        texture image or ``texture`` is given; another seamed kind only when named),
        ``'uv'``, ``'color'``, ``'normal'``, a tuple of these, or None (positions only).
    ``attribute_weights``: w ≥ 0, one number for every kind or {kind: w}; None: the measured defaults
        (``qemjax._mesh.wedges.DEFAULT_WEIGHTS``).
    ``texture``: a path or PIL image: the texture of the UVs (for a file that names no material).
    """

    attributes: object = "auto"
    attribute_weights: object = None
    texture: object = None


@dataclasses.dataclass(frozen=True)
class Options:
    """Resolved options of one run, in internal units (coordinates normalised to unit extent).

    cos_max: cosine of the flip angle (-2: flips allowed).
    preserve_topology: link condition and no coincident faces (manifold mode).
    keep_parts: (manifold mode) forbid the contraction that would remove the last face of a part, so
        separate parts survive; False lets small parts vanish (``simplify(prune=True)``).
    max_cost: largest contraction cost allowed (squared distance at unit extent; inf = no limit).
    schedule: the parallel scheduler's `Schedule`.
    """

    cos_max: float
    preserve_topology: bool
    max_cost: float
    keep_parts: bool = True
    schedule: Schedule = Schedule()
