"""Device calls per round: how many jit-compiled kernel calls a warm run makes, per scheduler round.

Counts the calls of every function made by ``jax.jit`` (wrapped before the package is imported, so its kernel
wrappers and its direct ``jax.jit`` uses are all seen) over a warm run (one untimed call first), for this
checkout and optionally the package at a git revision beside it (loaded as ``qemjax_old``,
`ab_compare.load_old`).

    python experiments/figures/device_calls.py --rev 4e3085d --meshes cow stanford-bunny
"""
from __future__ import annotations

import argparse
import functools
import sys
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402


CALLS = [0]


def count_jit_calls() -> None:
    """Make ``jax.jit`` return functions that count their calls in CALLS (before anything jits)."""
    import jax

    plain = jax.jit

    def counting(fn=None, **kw):
        if fn is None:
            return lambda f: counting(f, **kw)
        jitted = plain(fn, **kw)

        @functools.wraps(fn)
        def call(*args, **kwargs):
            CALLS[0] += 1
            return jitted(*args, **kwargs)
        return call
    jax.jit = counting


def kernel_calls(pkg, mesh, ratio: float) -> tuple[int, int]:
    """(device calls, rounds) of one warm default run of ``pkg`` on ``mesh``."""
    pkg.simplify(mesh, ratio=ratio)
    CALLS[0] = 0
    res = pkg.simplify(mesh, ratio=ratio)
    return CALLS[0], int(res.stats["rounds"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny"])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--rev", help="also count for the package at this git revision")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    count_jit_calls()
    import qemjax

    packages = {"this checkout": qemjax}
    if args.rev:
        from ab_compare import load_old

        packages[args.rev] = load_old(args.rev)
    print("| mesh | package | device calls | rounds | calls per round |")
    print("|---|---|---|---|---|")
    for name in args.meshes:
        m = bench_meshes.load(name)
        for label, pkg in packages.items():
            calls, rounds = kernel_calls(pkg, (m.V, m.F), args.ratio)
            print(f"| {name} | {label} | {calls} | {rounds} | {calls / max(rounds, 1):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
