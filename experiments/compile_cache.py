"""What the command's persistent compilation cache saves: `qemjax simplify` run three times, each in a
fresh process, all sharing one new, empty cache folder:

1. ``first``: mesh A with the empty cache (compiles everything and fills the cache);
2. ``second``: mesh B, a different mesh of similar size (loads what it can from the cache);
3. ``no_cache``: mesh B again with ``--no-cache`` (what a fresh process pays without the cache).

``compile_s`` is the stat of the same name (JAX tracing + lowering + compilation or cache loading inside
`simplify`), read from the command's summary line; ``wall_s`` is the whole process, Python start-up and
imports included.

    python experiments/compile_cache.py                 # generated: bumpy spheres (20,480 faces), seeds 0 and 3
    python experiments/compile_cache.py --pair shared   # ../shared/meshes cow.obj (5,804 faces), spot (5,856)

Prints a table and appends to results/compile_cache.csv.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SHARED = ROOT.parent / "shared" / "meshes"
CSV = HERE / "results" / "compile_cache.csv"


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
    cmd = [sys.executable, "-m", "qemjax._cli", "simplify", str(mesh), str(out), "--ratio", str(ratio),
           "--quiet", *extra]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t0
    m = re.search(r"in ([0-9.]+) s \(compile ([0-9.]+) s, run ([0-9.]+) s\)", done.stdout)
    return {"total_s": float(m.group(1)), "compile_s": float(m.group(2)), "run_s": float(m.group(3)),
            "wall_s": round(wall, 2), "command": " ".join(["qemjax", *cmd[3:]])}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pair", choices=["generated", "shared"], default="generated")
    ap.add_argument("--ratio", type=float, default=0.1)
    args = ap.parse_args(argv)
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
