"""How much two processes get from this machine's two cores: the same CPU-bound work (a pure-Python loop,
no memory traffic to speak of) run alone, then as two processes at once. A shared virtual machine's cores
need not double the throughput; the sweep's and the partitioned run's speed-ups on 2 workers are bounded by
what this prints, whatever their own scheduling.

    python experiments/probes/core_throughput.py [--repeats 3] [--n 20000000]
    python experiments/probes/core_throughput.py --sweep distinct --repeats 3

Prints the median seconds of one process alone and of each of two at once, and the throughput of two
against one (2 × alone / together: 2.0 would be two full cores); appends the line to
results/core_throughput.txt. ``--sweep GRID``: the work is instead a warm sweep of the cow over
`figures/sweep_bench.py`'s grid GRID in one process on one thread (``workers=1``, qemjax's threads, numba's
and XLA's at one), timed from when every process has warmed up (a barrier of files), so what two at once lose
is the machine's, not the sweep's scheduling.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

WORK = "import sys\ns = 0\nfor i in range(int(sys.argv[1])):\n    s += i * i\n"
SWEEP = """
import os, sys, time
sys.path[:0] = [sys.argv[2], sys.argv[2] + "/figures"]
import meshes, qemjax
from qemjax._mesh import threads
from sweep_bench import GRIDS
grid, cow = GRIDS[sys.argv[1]], {"cow": qemjax.load(meshes.shared_files()["cow"])}
with threads.limited(1):
    qemjax.sweep(cow, grid, [0.1], metrics=False, progress=False, workers=1)
    open(sys.argv[3], "w").close()
    while not all(os.path.exists(p) for p in sys.argv[4:]):
        time.sleep(0.01)
    t = time.perf_counter()
    qemjax.sweep(cow, grid, [0.1], metrics=False, progress=False, workers=1)
    print(time.perf_counter() - t)
"""


def run(n: int, copies: int) -> float:
    """Seconds until all ``copies`` processes of the work have exited, started together."""
    t = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", WORK, str(n)]) for _ in range(copies)]
    for p in procs:
        p.wait()
    return time.perf_counter() - t


def run_sweep(grid: str, copies: int) -> float:
    """The median of the timed sweeps' seconds when ``copies`` processes run them at once (`SWEEP`)."""
    import os
    import tempfile

    from qemjax._partition.execute import _worker_env  # one thread for numba, XLA and BLAS

    with tempfile.TemporaryDirectory() as tmp:
        flags = [os.path.join(tmp, f"warm{k}") for k in range(copies)]
        env = _worker_env()
        experiments = str(Path(__file__).resolve().parents[1])
        procs = [subprocess.Popen([sys.executable, "-c", SWEEP, grid, experiments, flags[k], *flags], env=env,
                                  stdout=subprocess.PIPE, text=True) for k in range(copies)]
        return statistics.median(float(p.communicate()[0].split()[-1]) for p in procs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n", type=int, default=20_000_000)
    ap.add_argument("--sweep", default=None, help="a sweep_bench grid: the work is that sweep of the cow")
    args = ap.parse_args()
    alone, together = [], []
    for _ in range(args.repeats):  # alternated: drift hits both alike
        alone.append(run_sweep(args.sweep, 1) if args.sweep else run(args.n, 1))
        together.append(run_sweep(args.sweep, 2) if args.sweep else run(args.n, 2))
    a, b = statistics.median(alone), statistics.median(together)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from machine import cpu_model

    line = (f"{cpu_model()}: one process alone {a:.2f} s, two at once {b:.2f} s each; "
            f"throughput of two = {2 * a / b:.2f} × one ("
            + (f"the cow's sweep over the {args.sweep!r} grid, one thread each, --repeats {args.repeats})"
               if args.sweep else f"--repeats {args.repeats} --n {args.n})"))
    print(line)
    out = Path(__file__).resolve().parents[1] / "results" / "core_throughput.txt"
    with open(out, "a") as f:
        f.write(line + "\n")


if __name__ == "__main__":
    main()
