"""Garland & Heckbert's algorithm as published: one priority queue of all valid pairs, contract the
cheapest, re-cost the pairs whose cost changed. The quality reference for the parallel scheduler.

It runs on the same rules as the parallel scheduler (`.._schedulers.rules`), one contraction at a time,
and the cost model's batched price and merge on the device rows. A run takes one of two paths, with the
same contractions in the same order and the same outputs:

* models whose price reads only the pair's two rows (`batches.eligible`: QEM and its attribute form
  without memoryless, ring support, refresh or ranking weights): the queue in verified speculative
  batches (`batches`), its host side compiled (`speculate`: pops, the rules in the loop's order from
  `checks`, contractions, journal and undo; `wedges`: kept attributes' seam rule, wedge updates and seam
  pricing, journaled): one merge and one price call per few dozen contractions instead of per
  contraction, in both modes, on any mesh, with or without locks and weights;
* everything else (ring-support, refreshed or rank-weighted models): the one-at-a-time queue (`loop`, on
  `queue.Queue`), one contraction and one device round trip at a time. It is the reference the batches
  are tested against (tests/test_greedy_compiled.py).
"""
from __future__ import annotations

import numpy as np

from ..._mesh import topology as topo
from ..._options import Options
from ..runtime import gc_paused
from . import loop


def _compiled():
    """`batches`, or None (then the one-at-a-time loop runs every model: what the tests compare with)."""
    try:
        from . import batches
    except ImportError:  # pragma: no cover
        return None
    return batches


def run(V: np.ndarray, S: np.ndarray, F: np.ndarray, extra_pairs: np.ndarray, target_faces: int, model,
        options: Options, progress=None, wedges=None, edges=None, part_scale=None, locks=None, normals=None,
        replan=None):
    """Simplify, with Python's garbage collector paused (`common.gc_paused`). V (n,3) float32 normalised
    positions, S (n, model.width) the model's vertex state, F (m,3) int64, extra_pairs (k,2) non-edge pairs
    that may also contract (aggregation). Returns the `outcome.Outcome` (``wedges``: as in `parallel.run`;
    ``edges`` and ``part_scale``, which the parallel scheduler uses, are not needed by the queue;
    ``locks``: a `locks.RunLocks` or None, and ``normals``, the flip test's reference normals, as there).

    ``replan``: None, or a function that is given the outcome at ``target_faces`` and returns a lower face
    target: the run then goes on to it and returns the outcome there, the same as a run started with that
    target (ESQEM's split plan, `_pipeline.split.plan`). The one-at-a-time queue goes on from where it
    stopped when it can (`loop.run`), saving a second run's contractions down to the first target."""
    with gc_paused():
        E, _ = topo.edges(F, len(V))
        pairs = np.concatenate([E, np.sort(np.asarray(extra_pairs, np.int64).reshape(-1, 2), axis=1)])
        compiled = _compiled()
        if compiled is not None and compiled.eligible(model):  # the same run, in verified batches
            out = compiled.run(V, S, F, pairs, target_faces, model, options, progress, locks, wedges, normals)
            if replan is None:
                return out
            return compiled.run(V, S, F, pairs, replan(out), model, options, progress, locks, wedges, normals)
        return loop.run(V, S, F, pairs, target_faces, model, options, progress, wedges, locks, normals, replan)
