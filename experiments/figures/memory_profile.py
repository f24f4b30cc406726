"""Where a run's memory peak happens: RSS sampled every 10 ms, tagged with the stage running at the time.

    python experiments/figures/memory_profile.py [--mesh armadillo-x64] [--ratio 0.01] [--no-measure] [--out FILE]

The stages are tagged from outside the library (wrapped functions: loading, geometry, job, the scheduler's
set-up and round stages, the run's record arrays, compact output, re-fit, measure, the rest of ``finish``).
Prints per stage: its seconds, the highest RSS seen while it ran (GiB) and the RSS when it ended; then the
process's peak (``ru_maxrss``) and the sha256 of the output arrays (the same for the same output, so a memory
change that keeps the bits keeps the hash). A stage nested in another counts in both (the inner one's row
shows where in the outer the peak was).
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import resource
import sys
import threading
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))


def rss_gib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 2**20
    return float("nan")


class Profile:
    """A sampler thread and the stack of stages now running; per stage: seconds, max RSS, RSS at its end."""

    def __init__(self, every=0.01):
        self.stack, self.rows, self.order = ["start"], {}, []
        self.every, self.done = every, threading.Event()
        self.peak = (0.0, "")  # (GiB, the stack at that moment)
        self.thread = threading.Thread(target=self._sample, daemon=True)

    def _note(self, gib):
        for name in set(self.stack):
            row = self.rows.setdefault(name, [0.0, 0.0, 0.0, 0])
            row[1] = max(row[1], gib)
        if gib > self.peak[0]:
            self.peak = (gib, " > ".join(self.stack))

    def _sample(self):
        while not self.done.wait(self.every):
            self._note(rss_gib())

    def stage(self, name, fn):
        @functools.wraps(fn)
        def wrapped(*a, **k):
            if name not in self.rows:
                self.order.append(name)
                self.rows[name] = [0.0, 0.0, 0.0, 0]
            self.stack.append(name)
            self._note(rss_gib())
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                row = self.rows[name]
                row[0] += time.perf_counter() - t
                g = rss_gib()
                self._note(g)
                row[2], row[3] = g, row[3] + 1
                self.stack.pop()
        return wrapped

    def wrap(self, owner, attr, name=None):
        setattr(owner, attr, self.stage(name or attr, getattr(owner, attr)))


def output_hash(r) -> str:
    """sha256 over the result's arrays (positions, faces, sources, vertex errors, the history)."""
    h = hashlib.sha256()
    for a in (r.vertices, r.faces, r.source_vertices, r.source_faces, r.vertex_error, r.history.pairs,
              r.history.positions, r.history.costs, r.record.removed_at):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--mesh", default="armadillo-x64")
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--scheduler", default="parallel")
    ap.add_argument("--no-measure", action="store_true")
    ap.add_argument("--out", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    prof = Profile()
    prof.thread.start()
    import meshes

    bm = prof.stage("load", meshes.load)(args.mesh)  # before jax starts, as experiments/figures/memory_peak.py
    V, F = bm.V, bm.F
    del bm
    import qemjax
    from qemjax._pipeline import measure, refit, stages
    from qemjax._schedulers import outcome, parallel
    from qemjax._schedulers.parallel import driver

    for attr in ("geometry", "job", "run", "finish"):
        prof.wrap(stages, attr)
    prof.wrap(refit, "refit", "refit")
    prof.wrap(measure, "distance", "measure")
    for attr in ("samples", "_attach", "_system", "solve_csr"):  # measure imports samples at call time
        prof.wrap(refit, attr, "refit." + attr.strip("_"))
    from qemjax._mesh import grid_nearest
    prof.wrap(grid_nearest, "nearest", "nearest (measure)")  # refit's own name is wrapped by "refit.attach"
    prof.wrap(outcome, "compact_output")
    prof.wrap(parallel.Run, "__init__", "run.setup")
    for cls in (parallel.Round, parallel.StagedRound, parallel.LoopRound, parallel.GlueRound):
        for attr in ("update", "cost", "candidates", "rank", "select", "contract"):
            if attr in vars(cls):  # each implementation's own stages, under one name per stage
                prof.wrap(cls, attr, "round." + attr)
    for attr in ("history_columns", "removal_steps"):  # as the driver calls them
        prof.wrap(driver, attr, "run." + attr)
    simplify = prof.stage("simplify", qemjax.simplify)
    t0 = time.perf_counter()
    r = simplify((V, F), ratio=args.ratio, scheduler=args.scheduler, measure=False if args.no_measure else None)
    dt = time.perf_counter() - t0
    prof.done.set()
    prof.thread.join()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    lines = [f"# python experiments/figures/memory_profile.py --mesh {args.mesh} --ratio {args.ratio} --scheduler "
             f"{args.scheduler}{' --no-measure' if args.no_measure else ''}",
             f"faces {len(F)} -> {len(r.faces)}, simplify {dt:.1f} s, peak RSS (ru_maxrss) {peak:.2f} GiB, "
             f"highest sample {prof.peak[0]:.2f} GiB in: {prof.peak[1]}",
             f"output sha256 {output_hash(r)}",
             f"{'stage':28s} {'calls':>6s} {'seconds':>8s} {'max RSS':>8s} {'RSS at end':>10s}"]
    for name in prof.order:
        s, hi, end, calls = prof.rows[name]
        lines.append(f"{name:28s} {calls:6d} {s:8.2f} {hi:8.2f} {end:10.2f}")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
