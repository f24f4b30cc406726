"""Golden-output guard: hashes of `qemjax.simplify` outputs on a fixed list of cases, to prove that a refactor
keeps every output bit-identical.

The cases and the hash live in ``tests/golden_cases.py`` (shared with ``tests/test_golden.py``); the hashes in
``tests/golden_hashes.json``. Cases: every mesh in ``../shared/meshes`` at 10 % and 1 % (parallel scheduler),
greedy on the smallest ones, a few option variants at 5 %, and generated meshes (`qemjax.shapes`, no files).

    python experiments/golden.py --check                          # OK / DIFF per case; exit 1 on any DIFF
    python experiments/golden.py --check --match greedy/          # only the cases whose id contains this
    python experiments/golden.py --regenerate --why "placement now solves in float64"

``--regenerate`` rewrites the hashes (of the ``--match``ed cases, or all) and appends the reason, the date and
the versions to the file's ``regenerations``; it refuses to run without ``--why``, and, without ``--match``, when
``../shared/meshes`` is absent (it would drop the shared cases).
"""
from __future__ import annotations

import argparse
import datetime
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# this checkout's qemjax, not whichever one the interpreter has installed (an editable install elsewhere)
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import golden_cases as gc  # noqa: E402


def versions() -> dict:
    import jax
    import numpy as np
    import scipy

    import qemjax

    return {"python": platform.python_version(), "numpy": np.__version__, "jax": jax.__version__,
            "scipy": scipy.__version__, "qemjax": qemjax.__version__, "machine": platform.machine(),
            "cpus": gc.usable_cpus()}


def git_commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "qemjax"], cwd=ROOT, capture_output=True,
                               text=True).stdout.strip()
        return out.stdout.strip() + ("+dirty qemjax/" if dirty else "")
    except OSError:
        return "unknown"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = p.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="compare with tests/golden_hashes.json")
    mode.add_argument("--regenerate", action="store_true", help="rewrite tests/golden_hashes.json (needs --why)")
    p.add_argument("--why", help="the reason for --regenerate (recorded in the file)")
    p.add_argument("--match", help="only the cases whose id contains this string")
    p.add_argument("--file", type=Path, default=gc.HASHES)
    args = p.parse_args(argv)
    if args.regenerate and not (args.why and args.why.strip()):
        p.error('--regenerate rewrites the golden hashes: say why, e.g. --why "placement now solves in float64"')

    cases = [c for c in gc.cases() if args.match is None or args.match in c.id]
    if not cases:
        p.error(f"no case id contains {args.match!r}")
    have_shared = gc.SHARED.is_dir()
    if args.regenerate and args.match is None and not have_shared:
        p.error(f"{gc.SHARED} is absent: regenerating would drop every shared-mesh case")

    import qemjax

    package = Path(qemjax.__file__).resolve().parent
    if package != ROOT / "qemjax":
        p.error(f"imported {package}, not this checkout's {ROOT / 'qemjax'}")
    print(f"qemjax from {package}")
    golden = gc.load_golden(args.file)
    stored = golden.get("cases", {})
    now = versions()
    if args.check and golden.get("versions") and golden["versions"] != now:
        print(f"note: hashes were made with {golden['versions']}, this is {now}")

    results, bad = {}, 0
    t_all = time.perf_counter()
    for case in cases:
        if case.shared and not (gc.SHARED / case.mesh).exists():
            print(f"SKIP  {case.id}  ({gc.SHARED / case.mesh} absent)")
            continue
        t = time.perf_counter()
        out = gc.run(case)
        dt = time.perf_counter() - t
        results[case.id] = out
        if args.regenerate:
            print(f"{out['hash']}  {case.id}  faces_out={out['faces_out']}  {dt:.1f} s", flush=True)
            continue
        want = stored.get(case.id)
        if want is None:
            status, bad = "NEW ", bad + 1
            detail = "no golden hash"
        elif want["hash"] == out["hash"]:
            status, detail = "OK  ", ""
        else:
            status, bad = "DIFF", bad + 1
            detail = (f"{want['hash']} -> {out['hash']}, faces_out {want['faces_out']} -> {out['faces_out']}, "
                      f"contractions {want.get('contractions')} -> {out['contractions']}")
        print(f"{status}  {case.id}  {dt:.1f} s  {detail}".rstrip(), flush=True)
    total = time.perf_counter() - t_all

    if args.regenerate:
        ids = [c.id for c in gc.cases()]
        merged = {**stored, **results} if args.match else results
        golden = {
            "about": "qemjax.simplify output hashes (tests/golden_cases.py); checked by tests/test_golden.py. "
                     "Regenerate only for a deliberate output change: " + gc.REGENERATE,
            "hash": f"sha256[:{gc.DIGEST_CHARS}] over name|dtype|shape| + bytes of res.vertices, res.faces, "
                    "res.history.pairs, res.history.positions, res.history.costs",
            "versions": now,
            "regenerations": golden.get("regenerations", []) + [{
                "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                "why": args.why.strip(), "commit": git_commit(), "cases": args.match or "all",
                "versions": now}],
            "cases": {i: {k: merged[i][k] for k in ("hash", "faces_out", "contractions")} | {
                "mesh": c.mesh, "kwargs": c.kwargs} for c in gc.cases() if (i := c.id) in merged},
        }
        args.file.write_text(json.dumps(golden, indent=1) + "\n")
        print(f"wrote {len(golden['cases'])} hashes to {args.file} ({total:.1f} s)")
        missing = [i for i in ids if i not in merged]
        if missing:
            print(f"not in the file (skipped): {missing}")
        return 0

    stale = sorted(set(stored) - {c.id for c in gc.cases()})
    if stale and args.match is None:
        print(f"note: {len(stale)} hashes in {args.file.name} belong to no case: {stale}")
    print(f"{len(results) - bad}/{len(results)} OK, {bad} changed or new, {len(cases) - len(results)} skipped "
          f"({total:.1f} s)")
    if bad:
        print(f"outputs changed. If deliberate: {gc.REGENERATE}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
