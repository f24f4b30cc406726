"""How much two processes get from this machine's two cores: the same CPU-bound work (a pure-Python loop,
no memory traffic to speak of) run alone, then as two processes at once. A shared virtual machine's cores
need not double the throughput; the sweep's and the partitioned run's speed-ups on 2 workers are bounded by
what this prints, whatever their own scheduling.

    python experiments/probes/core_throughput.py [--repeats 3] [--n 20000000]

Prints the median seconds of one process alone and of each of two at once, and the throughput of two
against one (2 × alone / together: 2.0 would be two full cores); appends the line to
results/core_throughput.txt.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

WORK = "import sys\ns = 0\nfor i in range(int(sys.argv[1])):\n    s += i * i\n"


def run(n: int, copies: int) -> float:
    """Seconds until all ``copies`` processes of the work have exited, started together."""
    t = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", WORK, str(n)]) for _ in range(copies)]
    for p in procs:
        p.wait()
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n", type=int, default=20_000_000)
    args = ap.parse_args()
    alone, together = [], []
    for _ in range(args.repeats):  # alternated: drift hits both alike
        alone.append(run(args.n, 1))
        together.append(run(args.n, 2))
    a, b = statistics.median(alone), statistics.median(together)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from machine import cpu_model

    line = (f"{cpu_model()}: one process alone {a:.2f} s, two at once {b:.2f} s each; "
            f"throughput of two = {2 * a / b:.2f} × one (--repeats {args.repeats} --n {args.n})")
    print(line)
    out = Path(__file__).resolve().parents[1] / "results" / "core_throughput.txt"
    with open(out, "a") as f:
        f.write(line + "\n")


if __name__ == "__main__":
    main()
