"""Settings as frozen data: what a run was asked to do, resolved once by `simplify`.

`Schedule` holds the parallel scheduler's tunables (how much a round takes); `Options` holds the
model-independent rules every scheduler applies (validity, limits). A cost model is itself a frozen
object whose fields are its settings (`qemjax._costs`); its numbers reach the kernels as 0-d arrays (a
pytree, `CostModel.kernel_params`), so a new value never recompiles. Nothing here is a module global:
tests and sweeps pass these objects.
"""
from __future__ import annotations

import dataclasses
import numpy as np


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How much the parallel scheduler takes per round (results depend on these; the defaults are the
    measured trade-off between quality and rounds, see the README).

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
