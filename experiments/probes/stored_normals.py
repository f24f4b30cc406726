"""Stored normals, before and after (issue 30's table): the default's rms and warm time over
``attributes=None``'s on PLY files whose normals are MeshLab-style area sums, unit vectors times random
lengths 0.05-13, and unit vectors, → 10 %.

    python experiments/probes/stored_normals.py                 # this checkout
    python experiments/probes/stored_normals.py --rev 065dd34   # also an older revision, in a temporary worktree

The files are written by this checkout's `qemjax._io.attribute_files` (loaded by path, so an older revision
without it still runs); the simplification is the revision's. Results: results/stored_normals.md.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "meshes"
OUT = ROOT / "experiments" / "results"


def writers():
    """`qemjax._io.attribute_files` of this checkout, without importing this checkout's qemjax."""
    import importlib.util

    def by_path(name: str, rel: str):
        spec = importlib.util.spec_from_file_location(name, ROOT / "qemjax" / rel)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    fixed_order = by_path("fixed_order", "_mesh/fixed_order.py")  # numpy only: loaded by path too
    src = (ROOT / "qemjax" / "_io/attribute_files.py").read_text().replace("from .mesh import Mesh", "Mesh = tuple")
    src = src.replace("from .._mesh import fixed_order", "")
    ns: dict = {"__name__": "attribute_files", "fixed_order": fixed_order}
    exec(compile(src, "_io/attribute_files.py", "exec"), ns)
    return ns


def measure(repeats: int) -> list[str]:
    """Rows '| case | rms ratio | time ratio |' for the qemjax on sys.path."""
    import qemjax
    from qemjax import metrics, shapes

    af = writers()
    sphere = shapes.bumpy_sphere(5)
    cases = [("sphere, area-sum normals (VCG)", sphere, af["area_sum_normals"]),
             ("sphere, unit normals x random lengths", sphere, af["scaled_normals"]),
             ("sphere, unit normals", sphere, af["vertex_normals"])]
    if (SHARED / "stanford-bunny.obj").exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bunny = qemjax.load(SHARED / "stanford-bunny.obj")
        cases.append(("stanford-bunny, unit normals x random lengths", bunny, af["scaled_normals"]))
    rows = []
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, mesh, normals in cases:
            path = os.path.join(tmp, "m.ply")
            af["write_ply"](path, mesh, normals=normals(mesh))
            out = {}
            for label, kw in (("default", {}), ("none", {"attributes": None})):
                qemjax.simplify(path, ratio=0.1, **kw)  # warm
                ts = []
                for _ in range(repeats):
                    t = time.perf_counter()
                    res = qemjax.simplify(path, ratio=0.1, **kw)
                    ts.append(time.perf_counter() - t)
                out[label] = (metrics.surface_distance(mesh, res, n_samples=30000)["rms_rel"], statistics.median(ts))
            rows.append(f"| {name} | {out['default'][0] / out['none'][0]:.2f} | "
                        f"{out['default'][1] / out['none'][1]:.2f} |")
            print(rows[-1], flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", help="also measure this git revision (a temporary worktree)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:  # run by --rev with PYTHONPATH at the revision
        measure(args.repeats)
        return
    head = "| case | rms default / None | time default / None |\n|---|---|---|"
    blocks = []
    if args.rev:
        with tempfile.TemporaryDirectory() as tmp:
            wt = os.path.join(tmp, "rev")
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", wt, args.rev], check=True)
            try:
                env = dict(os.environ, PYTHONPATH=wt)
                print(f"# {args.rev}", flush=True)
                got = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(args.repeats)],
                                     env=env, check=True, capture_output=True, text=True, cwd=tmp).stdout
                print(got, end="")
                blocks.append(f"## {args.rev}\n\n{head}\n" + "".join(line + "\n" for line in got.splitlines()
                                                                     if line.startswith("|")))
            finally:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", wt], check=False)
    sys.path.insert(0, str(ROOT))
    print("# this checkout", flush=True)
    rows = measure(args.repeats)
    blocks.append(f"## this checkout\n\n{head}\n" + "\n".join(rows) + "\n")
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "stored_normals.md").write_text(
        "# Stored normals → 10 % (`python experiments/probes/stored_normals.py"
        + (f" --rev {args.rev}" if args.rev else "") + "`)\n\n" + "\n".join(blocks))


if __name__ == "__main__":
    main()
