"""The exact nearest-triangle query (`qemjax._mesh.grid_nearest.nearest`) of the re-fit and the measured
distance, at a git revision against the working tree, in one process, alternating: the points are the
input's samples (every vertex and face centroid, `refit.samples`), the triangles the output of
``method="classic"``. Checks that both give the same faces and distances bit for bit and prints the
medians of ``--repeats`` calls each.

    python experiments/probes/nearest_order.py --rev 2656a42 --cases stanford-bunny:0.1 armadillo-x16:0.01 --repeats 9
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))
import meshes as bench_meshes  # noqa: E402
from ab_compare import package_at  # noqa: E402


def absolute_imports(source: str, package: str) -> str:
    """``source`` with its relative imports (``from . import threads``, ``from .pointtri import ...``) made
    absolute from ``package`` (the module's own, e.g. ``qemjax._mesh``), so that a module loaded outside its
    package imports the working tree's siblings."""
    def absolute(m):
        parts = package.split(".")
        base = ".".join(parts[:len(parts) - (len(m.group(2)) - 1)])
        return f"{m.group(1)}from {base}{'.' + m.group(3) if m.group(3) else ''} import"

    return re.sub(r"^(\s*)from (\.+)([\w.]*) import", absolute, source, flags=re.M)


def module_at(rev: str, path: str, name: str):
    """The module at ``path`` in git revision ``rev``, loaded as ``name`` (its imports: the working tree's)."""
    file = package_at(rev) / path
    file.write_text(absolute_imports(file.read_text(), ".".join(Path(path).parent.parts)))
    spec = importlib.util.spec_from_file_location(name, file)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", required=True)
    ap.add_argument("--cases", nargs="+", default=["stanford-bunny:0.1", "armadillo-x16:0.01"])
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    import qemjax
    from qemjax._mesh import grid_nearest as new
    from qemjax._pipeline.refit import samples, unit_frame

    old = module_at(args.rev, "qemjax/_mesh/grid_nearest.py", "grid_nearest_old")
    warnings.simplefilter("ignore")
    print(f"| case | points | triangles | {args.rev} ms | working tree ms | new / old | same bits |")
    print("|---|---|---|---|---|---|---|")
    for case in args.cases:
        name, ratio = case.split(":")
        mesh = bench_meshes.load(name)
        V, F = np.asarray(mesh.V, np.float64), np.asarray(mesh.F, np.int64)
        res = qemjax.simplify((V, F), ratio=float(ratio), method="classic")
        c, u = unit_frame(V)
        P, _, _ = samples((V - c) / u, F, np.zeros(len(V), np.int64))
        X, G = (np.asarray(res.vertices) - c) / u, np.asarray(res.faces, np.int64)
        a, b = old.nearest(X, G, P), new.nearest(X, G, P)  # (and compiles)
        same = np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        t_old, t_new = [], []
        for r in range(args.repeats):
            for which, mod, ts in ((("old", old, t_old), ("new", new, t_new)) if r % 2 == 0
                                   else (("new", new, t_new), ("old", old, t_old))):
                t = time.perf_counter()
                mod.nearest(X, G, P)
                ts.append(time.perf_counter() - t)
        mo, mn = statistics.median(t_old) * 1e3, statistics.median(t_new) * 1e3
        print(f"| {name} -> {ratio} | {len(P)} | {len(G)} | {mo:.1f} | {mn:.1f} | {mn / mo:.2f} | {same} |")


if __name__ == "__main__":
    main()
