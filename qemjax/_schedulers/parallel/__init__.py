"""Independent-set scheduler: many non-interacting contractions per round.

A round is five named stages over a `RoundState` (`driver.rounds`):

1. **update** the candidate pairs after the last round's contractions (manifold mode: through the
   contractions, `contraction.contract_edges`; otherwise rebuilt from the faces and matched by key);
2. **cost**: price the pairs whose cost is stale with the cost model's batched kernel (fixed-size
   chunks: one compilation per size); the rest keep their numbers. Which pairs go stale is the model's
   ``support``: the pairs at moved vertices, or (``"ring"``) every pair in their 1-rings;
3. **select**, in passes, pairs that are the cheapest among all candidate pairs touching their
   endpoints' closed 1-rings (ties broken by a scramble of the pair index in an int64 key), so no two
   selected pairs share a vertex, a face or a 1-ring neighbour;
4. **validate** them (flip test, coincident faces, link test, and the part, lock and seam rules): invalid
   ones leave the candidate set with the rule they broke, valid ones lock their 1-rings, and the next pass
   selects among what is still free;
5. **contract** the accepted set at once (the model's merge; the faces through the vertex->face lists of
   `FaceLists`: validation looks them up and the contraction reuses that look-up, so neither scans the
   whole mesh).

Because accepted contractions are two edges apart, the validity computed for each stays true when all
happen together. The last round takes only as many, in cost order, as the exact face target allows.

**Three implementations of a round**, each making the same choices (the same bits; tested), one picked per
run by `driver.choose`:

- `StagedRound` (`staged`): the stages as numpy steps. Every mode, and the reference for the others. The link
  test and the edge update run on a host worker thread beside the main thread's face work; work on fewer
  than `select.INLINE_ROWS` rows runs on the main thread (waking the worker costs more than it overlaps).
- `LoopRound` (`compiled`): stages 3 to 5 as compiled loops (`selection`, `contraction`) where they apply: manifold mode,
  pairs updated in place, a mesh of at most `selection.MAX_FACES` faces; a single run's gate and order as
  compiled passes too (`segments.kth`, `glue.under_gate`, `glue.order_fit`). A batch of runs (`batched`)
  takes it there, with its per-copy gates and budgets.
- `GlueRound` (`compiled`): `LoopRound` with the rest of the numpy glue between the loops compiled too
  (`glue`) and the round's device work as one call: a single run whose model `device.fuses`.
  Its rounds hand over once the device's prices are in: the first round takes stages 1 and 2 as the numpy
  stages do (`Round.fresh`); every other round after a contraction takes them in one compiled pass over the
  device's raw prices (`GlueRound.carry`).

A round after one that only rejected (nothing contracted) selects again from that round's pairs and prices
without the rejected ones (`Round.without_rejected`), on every implementation; a batch (`batched`) updates
and prices its pairs again (`Round.retry`), as its copies seldom all reject at once.

Stages the implementations share are `stages.Round`'s; the run's state across rounds is `state.Run`. A
round's device work (`stages.SeparateCalls` or `stages.OneCall`) is asynchronous: the pricing, the flip
test and the merges run on JAX's threads while the host works on the topology, and are waited for only
where their results are needed.
"""
from __future__ import annotations

from .compiled import GlueRound, LoopRound
from .driver import choose, rounds, run
from .staged import StagedRound
from .stages import OneCall, Round, SeparateCalls
from .state import MERGE_CHUNK, SMALL_CHUNK, SMALL_MESH, STEP_PRICE, RoundState, Run, merge_size

__all__ = ["GlueRound", "LoopRound", "MERGE_CHUNK", "OneCall", "Round", "RoundState", "Run", "SMALL_CHUNK",
           "SMALL_MESH", "STEP_PRICE", "SeparateCalls", "StagedRound", "choose", "merge_size", "rounds", "run"]
