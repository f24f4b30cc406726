"""Where a partitioned run's last level goes, in this process: a partitioned run of a shared or subdivided
mesh written as a binary PLY keeps its scratch folder, then its last level's task (`task.run_group`: the
one group, fitted to the input's parts) runs again here ``--repeats`` times: the first in a process that
has run nothing (its loops loaded and its kernels traced here, more than a worker that ran the levels
before meets), the others warm. For each:
the task's seconds, when the rounds asked for the input side (`refit.InputSide`, read and made on a thread
from the task's start) and when it was made, how long the re-fit waited for it, and the run's re-fit and
stage seconds.

    python experiments/probes/last_level.py --mesh armadillo-x64 --repeats 2

Only the default method and `Partition` settings (the level's settings as `run._level_kwargs` gives them
for the last level: the run's own).
"""
from __future__ import annotations

import argparse
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="armadillo-x64")
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--workers", type=int, default=2, help="for the partitioned run that leaves the levels")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    import qemjax
    from qemjax._partition import task
    from qemjax._pipeline import api, refit

    warnings.simplefilter("ignore")
    marks: dict = {}
    made, get = refit.InputSide._run, refit.InputSide.get

    def timed_run(self):
        made(self)
        marks["made"] = time.perf_counter()

    def timed_get(self):
        t = time.perf_counter()
        marks.setdefault("asked", t)
        out = get(self)
        marks.setdefault("waited", time.perf_counter() - t)
        return out

    refit.InputSide._run, refit.InputSide.get = timed_run, timed_get
    results = []
    simplify = api.simplify

    def kept(*a, **k):
        results.append(simplify(*a, **k))
        return results[-1]

    with tempfile.TemporaryDirectory() as tmp:
        src, n = shared_ply(args.mesh, Path(tmp))
        scratch = Path(tmp) / "scratch"
        res = qemjax.simplify(str(src), ratio=args.ratio, progress=False,
                              partition=qemjax.Partition(workers=args.workers, scratch=str(scratch)))
        p = res.stats["partition"]
        levels = p["levels"]
        print(f"{args.mesh} ({n} faces) -> {len(res.faces)} faces, partitioned on {args.workers} workers: levels "
              f"{', '.join(f'{s:.1f}' for s in p['seconds_per_level'])} s, refit to the {p['refit_to']}")
        manifest = json.loads((scratch / "manifest.json").read_text())
        unit = float(np.max(np.subtract(manifest["bbox"][1], manifest["bbox"][0])))
        if p["groups_per_level"][-1] != 1:
            sys.exit(f"last_level: the last level of {args.mesh} -> {args.ratio:g} has "
                     f"{p['groups_per_level'][-1]} groups; this probe runs a last level of one group")
        parts = [str(scratch / part["file"]) for part in manifest["parts"]]
        # the last level's input: what the level before it wrote, or the parts themselves on a run of one level
        inputs = parts if levels == 1 else sorted(str(f) for f in
                                                  (scratch / f"level{levels - 1}").glob("group_*.npz"))
        out = Path(tmp) / "last.npz"
        spec = dict(inputs=inputs, locks=None, target=len(res.faces), kwargs={}, out=str(out), carry_out=False,
                    unit=unit, uv=False, refit_to=parts if p["refit_to"] == "input" else None, refit_moves=True)
        api.simplify = kept
        print("| run | task s | rounds asked for the side at s | side made at s | re-fit waited s | re-fit s | "
              "select s | contract s | compile s |\n|---|---|---|---|---|---|---|---|---|")
        for k in range(args.repeats):
            for f in (out, out.with_suffix(".json")):
                f.unlink(missing_ok=True)
            marks.clear()
            t0 = time.perf_counter()
            stats = task.run_group(spec)
            total = time.perf_counter() - t0
            s = results[-1].stats
            print(f"| {'first' if k == 0 else 'warm'} | {total:.2f} | {marks.get('asked', np.nan) - t0:.2f} | "
                  f"{marks.get('made', np.nan) - t0:.2f} | {marks.get('waited', np.nan):.2f} | {s['refit_s']:.2f} | "
                  f"{s['select_s']:.2f} | {s['contract_s']:.2f} | {stats['compile_s']:.2f} |")
            assert stats["faces_out"] == len(res.faces)


if __name__ == "__main__":
    main()
