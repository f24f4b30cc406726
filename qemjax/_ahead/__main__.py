"""``python -m qemjax._ahead``: ``--record`` runs the workloads and rewrites ``signatures.txt``; ``--build``
compiles every listed signature into numba's cache with only numpy, numba and scipy importable (the package
build's step, `setup.py`); with neither, compiles them in this environment (as ``qemjax compile``)."""
from __future__ import annotations

import argparse
import os
import sys

from . import compile_ahead, compile_all, read_manifest, used_signatures, write_manifest


def _check(demo: bool) -> int:
    import json

    from .._kernels import compilation
    from .workloads import run_all

    run_all(demo=demo)
    listed = read_manifest()
    missing = [f"{m}.{n}{s}" for (m, n), sigs in used_signatures().items() for s in sigs
               if s not in listed.get((m, n), ())]
    print(json.dumps({"compiled": compilation.numba_compiles(), "missing": missing,
                      "package": os.path.dirname(os.path.dirname(os.path.abspath(__file__)))}))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m qemjax._ahead")
    ap.add_argument("--record", action="store_true", help="run the workloads and rewrite signatures.txt")
    ap.add_argument("--check", action="store_true", help="run the workloads; print (JSON) the numba "
                    "compilations they needed and the signatures they used that signatures.txt lacks")
    ap.add_argument("--build", action="store_true", help="compile without importing the packages' __init__")
    ap.add_argument("--no-demo", action="store_true", help="--record: leave out the 327,680-face demo")
    ap.add_argument("--jobs", type=int, default=0, help="processes to compile in (default: one per core)")
    ap.add_argument("--slice", help=argparse.SUPPRESS)  # "i/n": this process's share (see `compile_ahead`)
    args = ap.parse_args(argv)
    if args.check:
        return _check(demo=not args.no_demo)
    if args.record and not os.environ.get("QEMJAX_AHEAD_RECORDING"):
        # in a fresh process with an empty numba cache, so that every function compiles, the ones only
        # compiled loops call included: the list then does not depend on what this machine had cached
        import subprocess
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, NUMBA_CACHE_DIR=tmp, QEMJAX_AHEAD_RECORDING="1")
            return subprocess.run([sys.executable, "-m", "qemjax._ahead"] + list(argv or sys.argv[1:]),
                                  env=env).returncode
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
    r = compile_ahead(args.jobs, build=args.build)
    print(f"qemjax: compiled {r['compiled']}, already cached {r['loaded']} of {r['signatures']} signatures "
          f"in {r['seconds']:.1f} s" + (f"; {len(r['failed'])} failed" if r["failed"] else ""))
    for line in r["failed"]:
        print("  " + line, file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
