"""A partitioned run with small parts against the in-core run of the same mesh: the measured two-way
Hausdorff distance and rms (the run's stats, relative to the diagonal) of each, their ratios, and the
faces each level kept. Small parts put many cuts through a small mesh, where a rule of the levels (which
borders keep their planes, when a level is the last) shows in the distance.

    python experiments/probes/small_parts.py [--mesh teapot] [--ratio 0.1 0.05] [--part-faces 1000 1500 2000 3000]

Runs in this process with one worker (`Partition(workers=1)`); compare two revisions with ``PYTHONPATH`` set
to a `git worktree` of the other.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules

import meshes as bench_meshes  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="teapot")
    ap.add_argument("--ratio", nargs="+", type=float, default=[0.1, 0.05])
    ap.add_argument("--part-faces", nargs="+", type=int, default=[1000, 1500, 2000, 3000])
    args = ap.parse_args()
    import qemjax

    warnings.simplefilter("ignore")
    path = bench_meshes.shared_files().get(args.mesh)
    if path is None:
        sys.exit(f"{args.mesh}: not among the shared meshes ({bench_meshes.SHARED_MESHES})")
    print(f"qemjax from {Path(qemjax.__file__).parent}")
    print("| ratio | part_faces | Hausdorff / in core | rms / in core | faces per level |")
    print("|---|---|---|---|---|")
    for ratio in args.ratio:
        core = qemjax.simplify(str(path), ratio=ratio, progress=False).stats
        for pf in args.part_faces:
            part = qemjax.Partition(part_faces=pf, workers=1)
            s = qemjax.simplify(str(path), ratio=ratio, progress=False, partition=part).stats
            h = s["distance_max_rel"] / core["distance_max_rel"]
            r = s["distance_rms_rel"] / core["distance_rms_rel"]
            print(f"| {ratio:g} | {pf} | {h:.2f} | {r:.2f} | {s['partition']['faces_per_level']} |", flush=True)


if __name__ == "__main__":
    main()
