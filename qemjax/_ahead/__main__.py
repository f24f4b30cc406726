"""``python -m qemjax._ahead``: ``--record`` runs the workloads and rewrites ``signatures.txt``; ``--build``
compiles every listed signature into numba's cache with only numpy, numba and scipy importable (the package
build's step, `setup.py`); with neither, compiles them in this environment (as ``qemjax compile``)."""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

from . import compile_all, read_manifest, used_signatures, write_manifest


def _parallel(jobs: int, build: bool) -> None:
    """Compile the manifest's functions in ``jobs`` processes, each its share. Two processes that compile
    one shared helper can each save its cache index, one losing the other's entry: the caller's final
    pass compiles whatever is missing then."""
    cmd = [sys.executable, "-m", "qemjax._ahead"] + (["--build"] if build else [])
    procs = [subprocess.Popen(cmd + ["--slice", f"{i}/{jobs}"]) for i in range(jobs)]
    for p in procs:
        p.wait()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m qemjax._ahead")
    ap.add_argument("--record", action="store_true", help="run the workloads and rewrite signatures.txt")
    ap.add_argument("--build", action="store_true", help="compile without importing the packages' __init__")
    ap.add_argument("--no-demo", action="store_true", help="--record: leave out the 327,680-face demo")
    ap.add_argument("--jobs", type=int, default=0, help="processes to compile in (default: one per core)")
    ap.add_argument("--slice", help=argparse.SUPPRESS)  # "i/n": this process's share (see `_parallel`)
    args = ap.parse_args(argv)
    if args.record:
        from .workloads import run_all

        run_all(demo=not args.no_demo)
        sigs = used_signatures()
        write_manifest(sigs)
        print(f"{sum(len(v) for v in sigs.values())} signatures of {len(sigs)} functions")
        return 0
    if args.slice:
        i, n = map(int, args.slice.split("/"))
        items = sorted(read_manifest().items())
        compile_all(dict(items[i::n]), bare=args.build)
        return 0
    jobs = args.jobs or os.cpu_count() or 1
    t0 = time.perf_counter()
    if jobs > 1:
        _parallel(jobs, args.build)
    r = compile_all(bare=args.build)  # what the shares left out or lost to a race, and the count
    r["seconds"] = time.perf_counter() - t0
    print(f"qemjax: compiled {r['compiled']}, already cached {r['loaded']} of {r['signatures']} signatures "
          f"in {r['seconds']:.1f} s" + (f"; {len(r['failed'])} failed" if r["failed"] else ""))
    for line in r["failed"]:
        print("  " + line, file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
