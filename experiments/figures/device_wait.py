"""How the host waits for a round's device call: polling first (`_kernels.host.SPIN_S`, the default) against
blocking at once (SPIN_S = 0), alternating run by run in one process; warm medians of the whole run and of
the wait (``stats["kernels_s"]``), and whether the outputs are the same bits.

    python experiments/figures/device_wait.py --cases cow:0.1 stanford-bunny:0.1 --repeats 15
"""
from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1", "stanford-bunny:0.1"], help="mesh:ratio")
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    import qemjax
    from qemjax._kernels import host

    poll = host.SPIN_S
    modes = {"poll": poll, "block": 0.0}
    print(f"# python experiments/figures/device_wait.py --cases {' '.join(args.cases)} --repeats {args.repeats}")
    print(f"| case | rounds | whole run, poll ({poll * 1e6:.0f} µs) ms | whole run, block ms | poll / block | "
          "device wait, poll ms | device wait, block ms | same output |")
    print("|---|---|---|---|---|---|---|---|")
    for case in args.cases:
        name, ratio = case.split(":")
        bm = bench_meshes.load(name)
        target = int(len(bm.F) * float(ratio))
        runs = {m: [] for m in modes}
        waits = {m: [] for m in modes}
        digests = {m: set() for m in modes}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for m, s in modes.items():  # warm both
                host.SPIN_S = s
                qemjax.simplify((bm.V, bm.F), target_faces=target)
            for _ in range(args.repeats):
                for m, s in modes.items():
                    host.SPIN_S = s
                    t = time.perf_counter()
                    r = qemjax.simplify((bm.V, bm.F), target_faces=target)
                    runs[m].append(time.perf_counter() - t)
                    waits[m].append(r.stats["kernels_s"])
                    digests[m].add(hashlib.sha256(r.vertices.tobytes() + r.faces.tobytes()).hexdigest())
        host.SPIN_S = poll
        med = {m: statistics.median(v) * 1e3 for m, v in runs.items()}
        wmed = {m: statistics.median(v) * 1e3 for m, v in waits.items()}
        same = len(digests["poll"] | digests["block"]) == 1
        print(f"| {name} → {ratio} | {r.stats['rounds']} | {med['poll']:.1f} | {med['block']:.1f} | "
              f"{med['poll'] / med['block']:.2f} | {wmed['poll']:.1f} | {wmed['block']:.1f} | {same} |")


if __name__ == "__main__":
    main()
