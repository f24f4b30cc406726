"""Host-side schedulers that decide which pairs to contract, in which order.

``parallel``: rounds of many non-interacting contractions chosen by an independent-set rule (`parallel`);
``greedy``: Garland & Heckbert's priority queue, one contraction at a time (`greedy`, the quality
reference). `batched` runs many parallel runs as one disjoint union.

**The contract.** A scheduler is a function ::

    run(V, S, F, extra_pairs, target_faces, model, options, progress=None, *, wedges=None, edges=None,
        part_scale=None, locks=None) -> outcome.Outcome

given the cleaned mesh in normalised units (V (n,3) float32 positions at unit extent, S (n, width) the
cost model's vertex state, F (m,3) int64 faces), extra non-edge pairs that may contract (k,2), the face
target, the cost model (`qemjax._costs`: it prices and merges), the rules every scheduler applies
(`qemjax._options.Options`: flip angle, topology mode, the cost limit ``max_cost``, the parallel `Schedule`), a
progress callback (faces left), the seam tracker of kept attributes (or None) and, when the caller has
them, the edge table and the per-part scale; ``locks`` (`locks.RunLocks`) only with a call's ``locked=`` or
``vertex_weights=`` (a scheduler without that keyword, or ``**kwargs``, is refused such a call). It returns an `outcome.Outcome` (positions, states, faces,
alive mask, history, stop reason, blocked_by and counts; built by the scheduler, read by `stages.finish`
through its fields and its `output`, `stop_above` and `counts`). A scheduler may also take ``replan``, a
function that is given the outcome at the target and returns a lower one to go on to (`greedy.run`): ESQEM's
split plan (`_pipeline.split.plan`) passes it where the scheduler takes it, else runs the scheduler twice.
A new scheduler is one module with such a ``run`` and one `register` call; `simplify(scheduler=NAME)`
then runs it.
"""
from __future__ import annotations

import importlib

# module names relative to this package, so that a copy imported under another name (the A/B scripts'
# `load_old`) runs its own schedulers, not the installed package's
_REGISTRY: dict = {"parallel": f"{__name__}.parallel", "greedy": f"{__name__}.greedy"}
BUILT_IN = tuple(_REGISTRY)  # the schedulers every process has (`register` adds to this process's only)


def names() -> tuple[str, ...]:
    """The names `simplify(scheduler=...)` accepts."""
    return tuple(_REGISTRY)


def get(name: str):
    """The ``run`` function of the scheduler ``name`` (its module imported on first use)."""
    entry = _REGISTRY[name]
    return importlib.import_module(entry, __name__).run if isinstance(entry, str) else entry


def register(name: str, run) -> None:
    """Add a scheduler: ``run`` keeps the contract above. Refuses a name already taken."""
    if not isinstance(name, str) or not name or name in _REGISTRY:
        raise ValueError(f"a scheduler needs a new, non-empty name; got {name!r} (taken: {names()})")
    if not callable(run):
        raise ValueError(f"a scheduler is a function run(V, S, F, ...) -> Outcome, got {run!r}")
    _REGISTRY[name] = run
