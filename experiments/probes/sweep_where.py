"""Where a warm sweep's CPU goes, by stage, from a sampling profiler over every thread (py-spy: `pip install
py-spy`), so that the per-call cost cProfile adds to small functions does not inflate them: the rounds, the
re-fits (the fit, the polish, the sliver moves, the measured distance), the nearest-face queries under them,
the planning of the pieces. The sweep is the cow's 64 `distinct` configurations of
`experiments/figures/sweep_bench.py`, ``workers=1`` (this process and its threads, whose samples count
alike), two sweeps to warm up and then ``--sweeps``; samples taken while JAX compiles, traces or lowers a
kernel or Python imports (the start, the sweeps that warm up) are left out, as are those of a thread waiting
for work (its innermost frame a pool's or a condition's wait). A sample counts for the first stage in
`STAGES` its stack holds (the queries first: the re-fit's stages run them on threads).

    python experiments/probes/sweep_where.py [--mesh cow] [--sweeps 5] [--rate 200]
"""
from __future__ import annotations

import argparse
import collections
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules

import meshes as bench_meshes  # noqa: E402

CHILD = """
import sys, time, warnings
import qemjax
warnings.simplefilter("ignore")
path, n = sys.argv[1], int(sys.argv[2])
grid = {"area_power": [round(2 * (i + 1) / 32, 4) for i in range(32)], "placement": ["optimal", "endpoints"]}
for _ in range(2):
    qemjax.sweep({"m": path}, grid, [0.1], metrics=False, workers=1, progress=False)
t, c = time.perf_counter(), time.process_time()
for _ in range(n):
    qemjax.sweep({"m": path}, grid, [0.1], metrics=False, workers=1, progress=False)
print(f"{n} sweeps: {time.perf_counter() - t:.2f} s, CPU {time.process_time() - c:.2f} s")
"""
# (stage, a function name a sample's stack holds); a sample counts for the first stage it matches
STAGES = [
    ("planning the pieces (api.plan_cells)", "plan_cells api.py"),
    ("nearest-face queries (grid_nearest's search, under the re-fit's stages)", "search.<locals>.query grid_nearest.py"),
    ("re-fit: the measured distance (measure.distance)", "distance measure.py"),
    ("re-fit: the polish (polish.polish)", "polish polish.py"),
    ("re-fit: the sliver moves (slivers.lift_slivers)", "lift_slivers slivers.py"),
    ("re-fit: the moves' set-up (moves.Moves)", "Moves.__init__ moves.py"),
    ("re-fit: the fit (refit._fit)", "_fit refit.py"),
    ("re-fit: the rest", "RefitTask.__call__ stages.py"),
    ("rounds: the shape term (shape.py)", " shape.py"),
    ("rounds: the selection (batched.select_batch)", "_Batch.select_batch batched.py"),
    ("rounds: the contraction (batched.contract_batch)", "_Batch.contract_batch batched.py"),
    ("rounds: the rest (prices, carry, the second phases)", "_Batch.rounds batched.py"),
]

# a thread's innermost frame while it waits for work (a pool thread between items, a result awaited)
IDLE = {"_worker thread.py", "Condition.wait threading.py"}

# functions of `moves` whose share of the polish is printed (inclusive: a sample may count in several)
POLISH_PARTS = ["Moves.attempt moves.py", "Moves.worst moves.py", "_Largest._above moves.py", "query_here grid_nearest.py"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="cow")
    ap.add_argument("--sweeps", type=int, default=5)
    ap.add_argument("--rate", type=int, default=200, help="samples per second")
    args = ap.parse_args()
    spy = shutil.which("py-spy")
    if spy is None:
        sys.exit("py-spy is not installed: pip install py-spy")
    path = bench_meshes.shared_files()[args.mesh]
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "sweep.raw"
        out = subprocess.run([spy, "record", "-r", str(args.rate), "--threads", "--nonblocking", "-f", "raw",
                              "-o", str(raw), "--", sys.executable, "-c", CHILD, str(path), str(args.sweeps)],
                             capture_output=True, text=True)
        print(out.stdout.strip() or out.stderr.strip()[-2000:])
        counts, callers, inside = collections.Counter(), collections.Counter(), collections.Counter()
        total = polished = 0
        for line in raw.read_text().splitlines():
            stack, _, n = line.rpartition(" ")
            if not n.isdigit():
                continue  # a frame name py-spy wrote across lines (a thread's name): no count of its own
            # each frame "function (path/file.py:line)" as "function file.py"
            stack = re.sub(r" \((?:[^;]*/)?([^/;:]+):\d+\)", r" \1", stack)
            if any(word in stack for word in ("compile", "_find_and_load", "lower_jaxpr", "trace_to_jaxpr")):
                continue  # compiling, tracing, lowering or importing (the start, the first sweeps)
            if stack.rsplit(";", 1)[-1] in IDLE:
                continue  # a thread waiting for work
            total += int(n)
            stage = next((name for name, key in STAGES if key in stack), "the rest of the sweep (rows, the table)")
            counts[stage] += int(n)
            if stage == STAGES[1][0]:  # a query: the re-fit stage that asked it (unknown on a pool thread)
                callers[next((name for name, key in STAGES[2:8] if key in stack), "(on a pool thread)")] += int(n)
            if STAGES[3][1] in stack:  # in the polish: the parts of `moves` it spends on
                polished += int(n)
                for part in POLISH_PARTS:
                    inside[part] += int(n) if part in stack else 0
    print(f"{args.mesh}, {args.sweeps} warm sweeps of 64 configurations, workers=1: {total} samples at {args.rate}/s "
          "over every thread")
    for name, _ in STAGES + [("the rest of the sweep (rows, the table)", None)]:
        print(f"  {counts[name] / max(total, 1) * 100:5.1f} %  {name}")
    print("the queries by the stage that asked them (% of all samples; a pool thread's caller is not seen):")
    for name, n in callers.most_common():
        print(f"  {n / max(total, 1) * 100:5.1f} %  {name}")
    print(f"inside the polish ({polished} samples, its queries included; % of the polish's samples):")
    for part in POLISH_PARTS:
        print(f"  {inside[part] / max(polished, 1) * 100:5.1f} %  {part}")


if __name__ == "__main__":
    main()
