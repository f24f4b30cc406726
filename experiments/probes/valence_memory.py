"""Peak memory and time of simplifying meshes with high-valence vertices (issue 40 §2), per scheduler.

Inputs: trimesh's cylinder with 256 and 512 sections (two fan caps of valence 256 / 512) and closed
double cones (`qemjax.shapes.double_cone`: a ring of n vertices and two apexes of valence n) with n = 500
and 5,000; each to ratio 0.1 with the "parallel" and the "greedy" scheduler. Each case runs in its own
process (its peak RSS is that process's high-water mark, jax's import included) under an address-space
limit (``--limit-gib``, RLIMIT_AS, set before importing jax) and a time limit (``--timeout``):

    python experiments/probes/valence_memory.py [--limit-gib 3.5] [--timeout 300] [--method classic] [--out FILE]
    python experiments/probes/valence_memory.py --memoryless --schedulers greedy   # the one-at-a-time queue's path

Prints a table: faces in/out, stop reason, seconds in `simplify` (compilation included: a fresh process
each), peak RSS (GiB), or the error (MemoryError, time-out) a case ended with.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

CASES = ("cylinder-256", "cylinder-512", "cone-500", "cone-5000")
SCHEDULERS = ("parallel", "greedy")


def build(case: str):
    """The input (vertices, faces) of a case name."""
    kind, n = case.rsplit("-", 1)
    if kind == "cylinder":
        import trimesh

        m = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=int(n))
        return m.vertices, m.faces
    from qemjax.shapes import double_cone

    return double_cone(int(n))


def one(case: str, scheduler: str, limit_gib: float, method: str | None, memoryless: bool) -> dict:
    """Run one case in this process (the child); returns its row."""
    lim = int(limit_gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    row = {"case": case, "scheduler": scheduler}
    try:
        import qemjax

        V, F = build(case)
        row["faces_in"] = len(F)
        kw = {} if method is None else {"method": method}
        if memoryless:
            kw["method"] = qemjax.QEM(memoryless=True)
        t0 = time.perf_counter()
        r = qemjax.simplify((V, F), ratio=0.1, scheduler=scheduler, **kw)
        row.update(time_s=round(time.perf_counter() - t0, 2), faces_out=len(r.faces), stop=r.stop_reason)
    except MemoryError as e:
        row["error"] = f"MemoryError ({str(e)[:60]})"
    row["peak_rss_gib"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3)
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--limit-gib", type=float, default=3.5, help="address-space limit of each case's process")
    ap.add_argument("--timeout", type=float, default=300, help="seconds a case may run")
    ap.add_argument("--method", default=None, help="simplify's method= (default: the default)")
    ap.add_argument("--memoryless", action="store_true", help="method=QEM(memoryless=True) (ring support)")
    ap.add_argument("--cases", nargs="*", default=list(CASES))
    ap.add_argument("--schedulers", nargs="*", default=list(SCHEDULERS))
    ap.add_argument("--out", default=None, help="also write the table to this file")
    ap.add_argument("--one", nargs=2, metavar=("CASE", "SCHEDULER"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(*args.one, args.limit_gib, args.method, args.memoryless)))
        return
    lines = [f"# python experiments/probes/valence_memory.py {' '.join(sys.argv[1:] if argv is None else argv)}",
             f"# ratio 0.1, method {'QEM(memoryless=True)' if args.memoryless else args.method or 'default'}, RLIMIT_AS {args.limit_gib} GiB, timeout {args.timeout} s",
             f"{'case':<13} {'scheduler':<9} {'faces':>6} {'out':>5} {'stop':<9} {'time_s':>7} {'peak_GiB':>8}  error"]
    print("\n".join(lines), flush=True)
    for case in args.cases:
        for sched in args.schedulers:
            cmd = [sys.executable, __file__, "--one", case, sched, "--limit-gib", str(args.limit_gib)]
            if args.method:
                cmd += ["--method", args.method]
            if args.memoryless:
                cmd += ["--memoryless"]
            try:
                p = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
                out = p.stdout.strip().splitlines()
                row = json.loads(out[-1]) if p.returncode == 0 and out else \
                    {"error": f"exit {p.returncode}: {(p.stderr.strip().splitlines() or [''])[-1][:70]}"}
            except subprocess.TimeoutExpired:
                row = {"error": f"time-out after {args.timeout:g} s"}
            line = (f"{case:<13} {sched:<9} {row.get('faces_in', ''):>6} {row.get('faces_out', ''):>5} "
                    f"{row.get('stop', ''):<9} {row.get('time_s', ''):>7} {row.get('peak_rss_gib', ''):>8}  "
                    f"{row.get('error', '')}")
            lines.append(line)
            print(line, flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
