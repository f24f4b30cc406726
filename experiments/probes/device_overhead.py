"""Where a small mesh's warm run spends its device calls: each JAX kernel's calls per run, their time and
what one call costs however few pairs it holds.

Every ``jax.jit`` the package makes is wrapped (before qemjax is imported) so that each call is timed to its
result (``block_until_ready``): the totals are what the calls would cost waited for one by one, an upper
bound on what they take from a run in which the host works while they run. Then, for each kernel, one call
of the shape it had in the run is timed alone, with the number of fusions in its compiled program; and each
kernel that takes pairs is called alone with its pairs cut or tiled to 16 … 4096 rows: what a call costs
however few pairs it holds, against a call of one fusion.

    python experiments/probes/device_overhead.py --mesh cow --ratio 0.1 --runs 16
"""
from __future__ import annotations

import argparse
import collections
import statistics
import sys
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import jax  # noqa: E402
import numpy as np  # noqa: E402

CALLS = collections.defaultdict(lambda: [0, 0.0])  # kernel name -> [calls, seconds to the result]
FIRST = {}  # kernel name -> (jitted function, whether it donates, the arguments of one call as numpy arrays)
_jit = jax.jit
SIZES = (16, 256, 1024, 4096)  # pairs a call holds, for the table of one call alone


def _name(fn) -> str:
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__name__', '?')}".replace("qemjax.", "")


class _Timed:
    """A jitted function whose calls are timed to their results while ``on``."""

    on = False

    def __init__(self, fn, *args, **kwargs):
        self.jitted, self.name = _jit(fn, *args, **kwargs), _name(fn)
        self.donates = kwargs.get("donate_argnums") not in (None, ())

    def __getattr__(self, attr):
        return getattr(self.jitted, attr)

    def __call__(self, *args, **kwargs):
        if not _Timed.on:
            return self.jitted(*args, **kwargs)
        if self.name not in FIRST:  # (before the call: it may donate its arguments)
            FIRST[self.name] = (self.jitted, self.donates, jax.tree_util.tree_map(
                lambda a: np.array(a) if isinstance(a, jax.Array) else a, (args, kwargs)))
        t = time.perf_counter()
        out = jax.block_until_ready(self.jitted(*args, **kwargs))
        c = CALLS[self.name]
        c[0] += 1
        c[1] += time.perf_counter() - t
        return out


jax.jit = _Timed  # before qemjax makes any of its kernels


def _alone(jitted, args, kwargs, donated: bool, repeats: int) -> float:
    """Median seconds of one call with these arguments (fresh device copies where the call donates)."""
    def dev():
        return jax.tree_util.tree_map(lambda a: jax.numpy.asarray(a) if isinstance(a, np.ndarray) else a, (args, kwargs))
    a, k = dev()
    ts = []
    for _ in range(repeats):
        if donated:
            a, k = dev()
        t = time.perf_counter()
        jax.block_until_ready(jitted(*a, **k))
        ts.append(time.perf_counter() - t)
    return statistics.median(ts[repeats // 5:])


def _fusions(jitted, args, kwargs) -> int:
    try:
        return jitted.lower(*args, **kwargs).compile().as_text().count("fusion(")
    except Exception:  # a kernel whose static arguments this probe did not keep
        return -1


def _resized(args, kwargs, n: int):
    """The arguments of a call on pairs (its second argument, (K,2) int) with every array of K rows cut or
    tiled to n rows; None for a call that takes no pairs there."""
    if len(args) < 2 or not isinstance(args[1], np.ndarray) or args[1].ndim != 2 or args[1].shape[1] != 2:
        return None
    K = args[1].shape[0]

    def fit(a):
        return np.resize(a, (n,) + a.shape[1:]) if isinstance(a, np.ndarray) and a.ndim and a.shape[0] == K else a
    return jax.tree_util.tree_map(fit, (args, kwargs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="cow")
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--runs", type=int, default=16)
    args = ap.parse_args()
    import meshes as bench_meshes
    from machine import cpu_model

    import qemjax

    bm = bench_meshes.load(args.mesh)
    mesh = (bm.V, bm.F)
    for _ in range(2):
        qemjax.simplify(mesh, ratio=args.ratio)  # compiles, fills the caches

    def runs():
        times = []
        for _ in range(args.runs):
            t = time.perf_counter()
            qemjax.simplify(mesh, ratio=args.ratio)
            times.append(time.perf_counter() - t)
        return times
    plain = runs()
    _Timed.on = True
    timed = runs()
    _Timed.on = False
    run_s = statistics.median(plain)
    print(f"# python experiments/probes/device_overhead.py --mesh {args.mesh} --ratio {args.ratio} --runs {args.runs} "
          f"({cpu_model()})")
    print(f"a warm run: {1e3 * run_s:.1f} ms (median of {args.runs}); with every device call waited for: "
          f"{1e3 * statistics.median(timed):.1f} ms")
    print("| kernel | calls a run | ms a run | share of the run | µs a call | µs a call alone | fusions |")
    print("|---|---|---|---|---|---|---|")
    total = 0.0
    for name, (n, s) in sorted(CALLS.items(), key=lambda kv: -kv[1][1]):
        jitted, donates, (a, k) = FIRST[name]
        alone = _alone(jitted, a, k, donates, 200)
        per_run = s / args.runs
        total += per_run
        print(f"| {name} | {n / args.runs:.1f} | {1e3 * per_run:.2f} | {per_run / run_s:.1%} | {1e6 * s / n:.0f} | "
              f"{1e6 * alone:.0f} | {_fusions(jitted, a, k)} |")
    print(f"| all | | {1e3 * total:.2f} | {total / run_s:.1%} | | | |")
    floor = _alone(_jit(lambda x: x + 1), (jax.numpy.ones(256),), {}, False, 500)
    print(f"\na call of one fusion (x + 1 on 256 values): {1e6 * floor:.1f} µs")
    print("\none call alone, its pairs cut or tiled to n rows (µs):\n| kernel | " +
          " | ".join(f"n = {n}" for n in SIZES) + " |\n|---|" + "---|" * len(SIZES))
    for name in sorted(FIRST):
        jitted, donates, (a, k) = FIRST[name]
        if _resized(a, k, 16) is None:
            continue
        cells = [f"{1e6 * _alone(jitted, *_resized(a, k, n), donates, 200):.0f}" for n in SIZES]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
