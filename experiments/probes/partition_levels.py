"""Where a partitioned run's time goes, level by level: one `simplify` of a shared or subdivided mesh written
as a binary PLY (as `figures/partition_bench.py speed` reads it), from the file, with the run's
`stats["partition"]`: seconds per level, groups and faces per level, reading and cutting the input
(``scatter_s``), the measured distance (``measure_s``), the largest worker's memory; and each level's tasks
from the files they leave in the scratch folder: their summed seconds against the level's seconds times the
workers it could use (at most its tasks; the rest is a worker waiting), the median task, the longest, and
the seconds they spent compiling (a worker's first task of a kind loads and traces its kernels).

    python experiments/probes/partition_levels.py --mesh armadillo-x64 --workers 2
    python experiments/probes/partition_levels.py --mesh armadillo-x64 --workers 1 --option refit=all
    PYTHONPATH=/tmp/old python experiments/probes/partition_levels.py   # another version (a `git worktree`)

It ends with a hash of the output's vertices and faces, to compare versions or worker counts."""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and figures/
sys.path[:0] = [str(EXPERIMENTS), str(EXPERIMENTS / "figures")]

from partition_bench import shared_ply  # noqa: E402


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="armadillo-x64")
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--option", nargs="*", default=[], help="KEY=VALUE settings of Partition")
    args = ap.parse_args()
    import qemjax

    warnings.simplefilter("ignore")
    options = {k: _value(v) for k, v in (o.split("=", 1) for o in args.option)}
    with tempfile.TemporaryDirectory() as tmp:
        src, n = shared_ply(args.mesh, Path(tmp))
        t = time.perf_counter()
        scratch = Path(tmp) / "scratch"
        res = qemjax.simplify(str(src), ratio=args.ratio, progress=False,
                              partition=qemjax.Partition(workers=args.workers, scratch=str(scratch), **options))
        total = time.perf_counter() - t
        tasks = [[json.loads(f.read_text()) for f in sorted((scratch / f"level{k}").glob("group_*.json"))]
                 for k in range(1, len(res.stats["partition"]["seconds_per_level"]) + 1)]
    p = res.stats["partition"]
    print(f"{args.mesh} ({n} faces) -> {len(res.faces)} faces, {args.workers} workers, {options or 'defaults'}: "
          f"{total:.1f} s from the file")
    print("| level | groups | faces out | seconds | tasks' seconds, summed (÷ seconds × workers) | median task | "
          "longest | compiling, summed |\n|---|---|---|---|---|---|---|---|")
    for k, (g, f, s, ts) in enumerate(zip(p["groups_per_level"], p["faces_per_level"], p["seconds_per_level"],
                                          tasks), 1):
        secs = np.array([t["seconds"] for t in ts])
        busy = secs.sum() / (s * min(args.workers, len(ts)))
        print(f"| {k} | {g} | {f} | {s:.1f} | {secs.sum():.1f} ({busy:.2f}) | {np.median(secs):.2f} | "
              f"{secs.max():.2f} | {sum(t['compile_s'] for t in ts):.1f} |")
    print(f"reading and cutting the input {p['scatter_s']:.1f} s, measured distance {p['measure_s']:.1f} s, "
          f"largest worker {p['peak_rss_workers'] / 2**30:.2f} GiB")
    digest = hashlib.sha256(np.ascontiguousarray(res.vertices).tobytes() + np.ascontiguousarray(res.faces).tobytes())
    print(f"output sha256 {digest.hexdigest()[:16]} (vertices and faces: the same bits from two versions, "
          "or with other workers)")


if __name__ == "__main__":
    main()
