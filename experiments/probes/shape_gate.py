"""The shape term's gate (``quality_threshold``) set by the pairs that rank by their cost: does a round that
takes as many pairs as it would without the term keep what the term is for?

`qemjax._schedulers.shape.rerank` takes as many candidates as the round's gate on the costs admits. Once the
cheapest pairs are the ones the term lifts round after round, they set that gate, so rounds near the target
take a pair or two (the probe first prints the rounds of the armadillo to 10 % without the term, with it and
with it and this gate, ``quality_threshold=0.6``). The alternative here (`rerank_ranked`) sets the gate
again with the lifted pairs left aside (at most the gate × the k-th cheapest pair that ranks by its cost),
computes the term for the pairs that gate reaches beyond the pool, and gives as many places as pairs under it
rank by their cost, by smallest shaped key. It is put in place of the package's (the round's gate rank k
recorded as each round computes it) and the ranking run with both thresholds::

    python experiments/probes/shape_gate.py    # -> results/shape_gate.{csv,txt}

(`figures/rank_peers.py --warm --reuse-peers results/rank_late_memoryless.csv`, variants default,
``quality_threshold=0.5`` and ``0.6``; the package's own gate: results/rank_quality_threshold.txt.)
"""
from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from qemjax._kernels.batching import DTYPE  # noqa: E402
from qemjax._schedulers import select, shape  # noqa: E402
from qemjax._schedulers.parallel import compiled, stages  # noqa: E402

_K = [1]  # the gate rank of the round under way (single runs only: the ranking runs no batches)


def _kth(values, k: int):
    k = min(k, len(values))
    return np.partition(values, k - 1)[k - 1]


def _under(key, shaped, which, valid, k: int, gate: float, fl):
    """Under the gate set by the valid pairs but those the term lifted (in ``which``, shaped above cost)."""
    ranked = valid & ~(which & (shaped != key))
    if not ranked.any():
        return np.zeros(len(key), bool)
    return key <= np.maximum(gate * _kth(key.compress(ranked), k), fl)


def rerank_ranked(key, valid, cand, free, k: int, gate: float, E, X, VQ, faces, s: float):
    """(shaped keys, candidates) of one run's round with the gate described in the module docstring."""
    key = np.ascontiguousarray(key, DTYPE)
    floor = np.atleast_1d(np.asarray(free, DTYPE))
    fl = floor if len(floor) > 1 else floor[0]
    n, vk = int(np.count_nonzero(cand)), key.compress(valid)
    if not n or not len(vk):
        return key, cand
    which = valid & ((key <= _kth(vk, shape.SPAN * n)) | cand)

    def term(base, pairs):
        return shape.shaped_keys(base, pairs, floor, E, X, VQ, faces.F, faces.alive, faces.off, faces.cnt,
                                 faces.pool, np.float32(s))
    shaped = term(key, which)
    under = _under(key, shaped, which, valid, k, gate, fl)
    more = valid & ~which & under
    m = shape.SPAN * int(np.count_nonzero(which))
    if np.count_nonzero(more) > m:
        more &= key <= _kth(key.compress(more), m)
    if more.any():
        shaped = term(shaped, more)
        which |= more
        under = _under(key, shaped, which, valid, k, gate, fl)
    places = int(np.count_nonzero(valid & under & ((shaped == key) | ~which)))
    out = which & (shaped == key) & (key <= fl)
    rest, others = places - int(np.count_nonzero(out)), which & ~out
    if rest > 0 and others.any():
        out |= others & (shaped <= _kth(shaped.compress(others), rest))
    return shaped, out


@contextlib.contextmanager
def ranking(st, run, valid, cand, free, starts=None):
    """`shape.ranking` with `rerank_ranked`."""
    cost_key = st.key
    s = run.options.quality_threshold
    if s:
        if starts is not None:
            raise RuntimeError("this probe ranks single runs only")
        st.key, cand = rerank_ranked(st.key, valid, cand, free, _K[0], run.options.schedule.gate, st.E, st.x,
                                     run.VQ, run.faces, s)
    try:
        yield cand
    finally:
        st.key = cost_key


def _recording(gate_rank):
    def wrapped(*args):
        _K[0] = gate_rank(*args)
        return _K[0]
    return wrapped


def _rounds(mesh, **kw) -> int:
    import warnings

    import qemjax

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return int(qemjax.simplify(mesh, ratio=0.1, measure=False, **kw).stats["rounds"])


def main(argv=None) -> int:
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    import meshes as bench_meshes
    from figures import rank_peers

    arm = bench_meshes.load("armadillo")
    arm = (arm.V, arm.F)
    rounds = (f"armadillo -> 10 %: rounds without the term {_rounds(arm)}, with quality_threshold=0.6 "
              f"{_rounds(arm, quality_threshold=0.6)}")
    for mod in (stages, compiled):
        mod.ranking = ranking
        mod.gate_rank = _recording(select.gate_rank)
    rounds += f", with it and this probe's gate {_rounds(arm, quality_threshold=0.6)}"
    print(rounds)

    results = EXPERIMENTS / "results"
    argv = ["--warm", "--reuse-peers", "experiments/results/rank_late_memoryless.csv", "--out",
            "experiments/results/shape_gate", "--variant", "default:method=default",
            "--variant", "q05:quality_threshold=0.5", "--variant", "q06:quality_threshold=0.6"]
    code = rank_peers.main([str(EXPERIMENTS.parent / a) if a.startswith("experiments/") else a for a in argv])
    txt = results / "shape_gate.txt"  # its first line names the command: this probe's, which swapped the gate
    lines = txt.read_text().splitlines(keepends=True)
    txt.write_text("# python experiments/probes/shape_gate.py (figures/rank_peers.py " + " ".join(argv)
                   + ", with this probe's gate)\n# " + rounds + "\n" + "".join(lines[1:]))
    return code


if __name__ == "__main__":
    sys.exit(main())
