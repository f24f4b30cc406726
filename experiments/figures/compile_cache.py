"""What the command's persistent compilation cache saves: `qemjax simplify` run three times, each in a
fresh process, all sharing one new, empty cache folder:

1. ``first``: mesh A with the empty cache (compiles everything and fills the cache);
2. ``second``: mesh B, a different mesh of similar size (loads what it can from the cache);
3. ``no_cache``: mesh B again with ``--no-cache`` (what a fresh process pays without the cache).

``compile_s`` is the stat of the same name (JAX tracing + lowering + compilation or cache loading inside
`simplify`), read from the command's summary line; ``wall_s`` is the whole process, Python start-up and
imports included.

    python experiments/figures/compile_cache.py                 # generated: bumpy spheres (20,480 faces), seeds 0 and 3
    python experiments/figures/compile_cache.py --pair shared   # ../shared/meshes cow.obj (5,804 faces), spot (5,856)

Prints a table and appends to results/compile_cache.csv.

``--sweep N`` (issue 41): a `qemjax.sweep` over N generated tori of N different sizes (one cell each, ratio
0.1, metrics off, ``batch_size`` 1 by default so each mesh compiles as a sweep on an executor would, or
``--batch-size 0``: the in-process default), three times, each in a fresh Python process: ``no_cache``
(QEMJAX_NO_CACHE=1: what the library paid before it turned the cache on), ``cold`` (an empty cache folder)
and ``warm`` (the same folder again). ``compile_s`` is the process's JAX tracing + lowering + compilation
(or cache loading) time (`qemjax._kernels.compilation.snapshot`), ``sweep_s`` the sweep's wall time.

    python experiments/figures/compile_cache.py --sweep 20
"""
from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
ROOT = EXPERIMENTS.parent
SHARED = ROOT.parent / "shared" / "meshes"
CSV = EXPERIMENTS / "results" / "compile_cache.csv"


def _meshes(pair: str, folder: Path) -> list[tuple[str, Path]]:
    if pair == "shared":
        return [("cow", SHARED / "cow.obj"), ("spot", SHARED / "spot" / "spot.obj")]
    import trimesh

    sys.path.insert(0, str(ROOT))
    from qemjax import shapes

    out = []
    for seed in (0, 3):
        path = folder / f"bumpy5-seed{seed}.ply"
        trimesh.Trimesh(*shapes.bumpy_sphere(5, seed=seed), process=False).export(path)
        out.append((f"bumpy_sphere(5, seed={seed})", path))
    return out


def run_cli(mesh: Path, out: Path, cache: Path, ratio: float, extra=()) -> dict:
    """One `qemjax simplify` in a fresh process; its compile_s and total_s (from the summary), wall time."""
    env = dict(os.environ, QEMJAX_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    env.pop("QEMJAX_NO_CACHE", None)
    cmd = [sys.executable, "-m", "qemjax", "simplify", str(mesh), str(out), "--ratio", str(ratio),
           "--quiet", *extra]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t0
    m = re.search(r"in ([0-9.]+) s \(compile ([0-9.]+) s, run ([0-9.]+) s\)", done.stdout)
    return {"total_s": float(m.group(1)), "compile_s": float(m.group(2)), "run_s": float(m.group(3)),
            "wall_s": round(wall, 2), "command": " ".join(["qemjax", *cmd[3:]])}


SWEEP = """
import json, sys, time
t0 = time.perf_counter()
import qemjax
from qemjax import shapes
from qemjax._kernels import compilation
n, batch = int(sys.argv[1]), int(sys.argv[2]) or None
meshes = {f"torus{k}": shapes.torus(n_major=24 + 6 * k, n_minor=12 + 3 * k) for k in range(n)}
t1 = time.perf_counter()
df = qemjax.sweep(meshes, {}, [0.1], metrics=False, progress=False, batch_size=batch)
t2 = time.perf_counter()
c, s = compilation.snapshot()
print(json.dumps({"compile_s": round(s, 2), "compilations": c, "sweep_s": round(t2 - t1, 2),
                  "import_s": round(t1 - t0, 2), "errors": int((df["error"] != "").sum()),
                  "faces": [int(df["faces_in"].min()), int(df["faces_in"].max())], "cache": qemjax.cache()}))
"""


def sweep_runs(n: int, batch: int) -> None:
    rows = []
    with tempfile.TemporaryDirectory(prefix="qemjax-cache-exp-") as tmp:
        for label in ("no_cache", "cold", "warm"):
            env = dict(os.environ, QEMJAX_CACHE_DIR=str(Path(tmp) / "cache"), PYTHONPATH=str(ROOT))
            env.pop("QEMJAX_NO_CACHE", None)
            env.pop("JAX_COMPILATION_CACHE_DIR", None)
            if label == "no_cache":
                env["QEMJAX_NO_CACHE"] = "1"
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, "-c", SWEEP, str(n), str(batch)], env=env, capture_output=True,
                                  text=True, check=True)
            r = json.loads(done.stdout.strip().splitlines()[-1])
            rows.append({"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
                         "cores": len(os.sched_getaffinity(0)), "run": label, "meshes": n,
                         "faces": f"{r['faces'][0]}-{r['faces'][1]}", "batch_size": batch or "default",
                         "compile_s": r["compile_s"], "compilations": r["compilations"], "sweep_s": r["sweep_s"],
                         "wall_s": round(time.perf_counter() - t0, 2), "errors": r["errors"],
                         "load_avg": round(os.getloadavg()[0], 2),
                         "command": f"python experiments/figures/compile_cache.py --sweep {n} --batch-size {batch}"})
    keys = list(rows[0])
    print(" | ".join(keys[2:-1]))
    for row in rows:
        print(" | ".join(str(row[k]) for k in keys[2:-1]))
    out = EXPERIMENTS / "results" / "compile_cache_sweep.csv"
    new = not out.exists()
    with open(out, "a", newline="") as f:
        w = csv.DictWriter(f, keys)
        if new:
            w.writeheader()
        w.writerows(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pair", choices=["generated", "shared"], default="generated")
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--sweep", type=int, default=0, help="a sweep over this many differently sized meshes")
    ap.add_argument("--batch-size", type=int, default=1, help="with --sweep: cells per batch (0: the default)")
    args = ap.parse_args(argv)
    if args.sweep:
        return sweep_runs(args.sweep, args.batch_size)
    rows = []
    with tempfile.TemporaryDirectory(prefix="qemjax-cache-exp-") as tmp:
        tmp = Path(tmp)
        cache = tmp / "cache"
        (a_name, a), (b_name, b) = _meshes(args.pair, tmp)
        for label, name, mesh, extra in [("first", a_name, a, ()), ("second", b_name, b, ()),
                                         ("no_cache", b_name, b, ("--no-cache",))]:
            r = run_cli(mesh, tmp / "out.obj", cache, args.ratio, extra)
            entries = len(list(cache.iterdir())) if cache.exists() else 0
            rows.append({"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
                         "cores": len(os.sched_getaffinity(0)), "run": label, "mesh": name,
                         "ratio": args.ratio, **{k: r[k] for k in ("compile_s", "run_s", "total_s", "wall_s")},
                         "cache_entries": entries, "command": r["command"]})
    keys = list(rows[0])
    print(" | ".join(keys[2:-1]))
    for row in rows:
        print(" | ".join(str(row[k]) for k in keys[2:-1]))
    new = not CSV.exists()
    CSV.parent.mkdir(exist_ok=True)
    with open(CSV, "a", newline="") as f:
        w = csv.DictWriter(f, keys)
        if new:
            w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
