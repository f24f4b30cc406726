"""Partitioned simplification (`qemjax simplify --partition`) measured as a user meets it: file to file, each
command its own process, timed from start to exit, with the peak memory of every process.

    python experiments/figures/partition_bench.py speed   [--mesh armadillo-x64] [--ratio 0.01] [--workers 2]
    python experiments/figures/partition_bench.py quality [--meshes stanford-bunny armadillo-x16 armadillo-x64]
    python experiments/figures/partition_bench.py scale   [--faces 5500000 22000000 88000000] [--workers 2]
    python experiments/figures/partition_bench.py workers [--faces 2000000] [--counts 1 2 4]

speed: a shared mesh written as a binary PLY (float32, as scans are), then `qemjax simplify IN OUT --ratio R
--partition --workers N`, the same in core (no --partition) and meshoptimizer single-threaded file to file
(trimesh reads the PLY, `meshopt_simplify` to the same face count, trimesh writes it), alternating, each
``--repeats`` times; the medians and the ratios against meshoptimizer. quality: partitioned (2 workers) and in
core to the same target (``--refit``, ``--share``: each `Partition.refit` and `Partition.share` value), two-way rms and Hausdorff
(`qemjax.metrics.surface_distance`, 200,000 samples each way, relative to the diagonal) and their ratios
(``--late every``: also with the memoryless last stretch in every level, not only the last; ``--slivers last``:
also with the sliver moves in the last level only; ``--reduction``:
each `Partition.reduction` value), with
the seconds of each run (in this process; the workers warm after the first mesh). scale: meshes made in code (`big_mesh.py`: a bumpy torus,
binary PLY written in bands) of each size to 1 %, partitioned: seconds, microseconds per input face, peak
memory of the client and of the largest worker. workers: one input, the output file's sha256 with each
worker count. Appends to results/partition_bench.csv; prints a markdown table.
"""
from __future__ import annotations

import argparse
import contextlib
import itertools
import csv
import hashlib
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

from machine import cpu_model  # noqa: E402

RESULTS = EXPERIMENTS / "results"
QEMJAX = [sys.executable, "-m", "qemjax"]
PEER = r"""
import sys, numpy as np, trimesh
from qemjax.peers import simplify_meshoptimizer
m = trimesh.load(sys.argv[1], process=False)
V, F = simplify_meshoptimizer(np.asarray(m.vertices, np.float64), np.asarray(m.faces), int(sys.argv[3]))
trimesh.Trimesh(V, F, process=False).export(sys.argv[2])
"""


def timed(cmd: list[str]) -> tuple[float, float, str]:
    """(seconds from start to exit, peak RSS in GiB of the command's largest process, its stdout)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    dt = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # the largest child waited for so far
    return dt, max(after, before) / 2**20, out.stdout


def write_ply(path: Path, V: np.ndarray, F: np.ndarray) -> None:
    from qemjax._partition.write import write_binary_ply
    write_binary_ply(path, np.asarray(V, np.float32), np.asarray(F, np.int32))


def shared_ply(name: str, folder: Path) -> tuple[Path, int]:
    import meshes
    bm = meshes.load(name)
    path = folder / f"{name}.ply"
    if not path.exists():
        write_ply(path, bm.V, bm.F)
    return path, len(bm.F)


def partitioned_cmd(src, dst, ratio, workers, part_faces=None) -> list[str]:
    cmd = QEMJAX + ["simplify", str(src), str(dst), "--ratio", str(ratio), "--partition", "--workers",
                    str(workers), "--quiet"]
    return cmd + (["--part-faces", str(part_faces)] if part_faces else [])


def summary_peaks(stdout: str) -> str:
    return stdout.strip().splitlines()[0] if stdout.strip() else ""


def append(rows: list[dict]) -> None:
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "partition_bench.csv"
    keys = ["case", "mesh", "faces", "ratio", "what", "seconds", "peak_gib", "value", "cpu", "note"]
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, keys)
        if new:
            w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in keys} | {"cpu": cpu_model()})


def speed(args, folder: Path) -> None:
    src, n = shared_ply(args.mesh, folder)
    target = round(args.ratio * n)
    runs = {"partitioned": partitioned_cmd(src, folder / "p.ply", args.ratio, args.workers),
            "in core": QEMJAX + ["simplify", str(src), str(folder / "c.ply"), "--ratio", str(args.ratio), "--quiet"],
            "meshoptimizer": [sys.executable, "-c", PEER, str(src), str(folder / "m.ply"), str(target)]}
    if args.no_in_core:
        runs.pop("in core")
    times = {k: [] for k in runs}
    peaks = {k: 0.0 for k in runs}
    for rep in range(args.repeats):
        for name, cmd in (runs.items() if rep % 2 == 0 else reversed(list(runs.items()))):
            dt, peak, out = timed(cmd)
            times[name].append(dt)
            peaks[name] = peak
            print(f"  {name}: {dt:.1f} s {summary_peaks(out)[:200]}", flush=True)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"\n{args.mesh} ({n} faces) -> {args.ratio:g}, file to file, median of {args.repeats}, {cpu_model()}")
    print("| run | seconds | × meshoptimizer |\n|---|---|---|")
    for k in runs:
        print(f"| {k} | {med[k]:.1f} | {med[k] / med['meshoptimizer']:.2f} |")
    append([dict(case="speed", mesh=args.mesh, faces=n, ratio=args.ratio, what=k, seconds=med[k],
                 value=med[k] / med["meshoptimizer"], note=f"workers={args.workers}") for k in runs])


@contextlib.contextmanager
def _levels(late: str, slivers: str = "every"):
    """``late="every"``: every level of a partitioned run keeps the method's memoryless last stretch (as
    before the package left it to the last level: `_partition.run._level_kwargs`); ``slivers="last"``: the
    levels before the last run without the method's sliver moves (as the shape term does; the package keeps
    them in every level); for the comparison."""
    from qemjax._partition import run

    keep = run._level_kwargs
    kept = {"late_memoryless", "volume_weight"} if late == "every" else set()

    def changed_levels(kwargs, p, last):
        kw, changed = keep(kwargs, p, last)
        back = kept & changed.keys()
        kw = {k: v for k, v in kw.items() if k not in back} | {k: kwargs[k] for k in back if k in kwargs}
        changed = {k: v for k, v in changed.items() if k not in back}
        if slivers == "last" and not last and getattr(run._method(kwargs), "sliver_moves", 0):
            kw, changed = kw | {"sliver_moves": 0}, changed | {"sliver_moves": 0}
        return kw, changed

    if kept or slivers == "last":
        run._level_kwargs = changed_levels
    try:
        yield
    finally:
        run._level_kwargs = keep


def quality(args, folder: Path) -> None:
    import meshes
    import qemjax
    from qemjax.metrics import surface_distance

    rows = []
    print("| mesh | faces | re-fit | share | memoryless | sliver moves | reduction | rms part./in core | Hausdorff part./in core | partitioned s | in core s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        if name.startswith("bumpy-sphere-"):  # made in code: qemjax.shapes.bumpy_sphere(N)
            from types import SimpleNamespace
            m = qemjax.shapes.bumpy_sphere(int(name.rsplit("-", 1)[1]))
            bm = SimpleNamespace(V=np.asarray(m.vertices), F=np.asarray(m.faces))
        else:
            bm = meshes.load(name)
        t = time.perf_counter()
        core = qemjax.simplify((bm.V, bm.F), ratio=args.ratio, measure=False)
        t_core = time.perf_counter() - t
        dc = surface_distance((bm.V, bm.F), (core.vertices, core.faces), n_samples=200_000)
        for refit, share, late, red, sl in itertools.product(args.refit, args.share, args.late, args.reduction,
                                                             args.slivers):
            t = time.perf_counter()
            with _levels(late, sl):
                part = qemjax.simplify((bm.V, bm.F), ratio=args.ratio, measure=False,
                                       partition=qemjax.Partition(workers=args.workers, refit=refit, share=share,
                                                                  **({"part_faces": args.part_faces} if args.part_faces else {}),
                                                                  **({"reduction": red} if red else {})))
            t_part = time.perf_counter() - t
            dp = surface_distance((bm.V, bm.F), (part.vertices, part.faces), n_samples=200_000)
            r_rms, r_h = dp["rms_rel"] / dc["rms_rel"], dp["hausdorff_rel"] / dc["hausdorff_rel"]
            print(f"| {name} | {len(bm.F)} → {len(part.faces)} | {refit} | {share} | {late} | {sl} | {red or 'default'} | "
                  f"{r_rms:.3f} | {r_h:.3f} | "
                  f"{t_part:.1f} | {t_core:.1f} |", flush=True)
            note = f"refit={refit} levels={part.stats['partition']['levels']}" + (f" share={share}" if share != "faces" else "") \
                + (f" late={late}" if late != "last" else "") + (f" reduction={red:g}" if red else "") \
                + (f" slivers={sl}" if sl != "every" else "")
            rows += [dict(case="quality", mesh=name, faces=len(bm.F), ratio=args.ratio, what="rms ratio", value=r_rms,
                          seconds=t_part, note=note),
                     dict(case="quality", mesh=name, faces=len(bm.F), ratio=args.ratio, what="hausdorff ratio",
                          value=r_h, seconds=t_core, note=note)]
    append(rows)


def big(faces: int, folder: Path) -> Path:
    path = folder / f"torus-{faces}.ply"
    if not path.exists():
        subprocess.run([sys.executable, str(EXPERIMENTS / "figures" / "big_mesh.py"), "--faces", str(faces), "--out", str(path)],
                       check=True)
    return path


def scale(args, folder: Path) -> None:
    rows = []
    print("| input faces | seconds | µs per input face | levels | client peak GiB | largest worker GiB |")
    print("|---|---|---|---|---|---|")
    for faces in args.faces:
        src = big(faces, folder)
        out = folder / "s.ply"
        scratch = folder / "scratch"
        cmd = partitioned_cmd(src, out, args.ratio, args.workers) + ["--scratch", str(scratch)]
        dt, peak, stdout = timed(cmd)
        stats = json.loads((scratch / "stats.json").read_text())
        p = stats["partition"]
        print(f"| {stats['faces_in']} | {dt:.1f} | {1e6 * dt / stats['faces_in']:.2f} | {p['levels']} | "
              f"{p['peak_rss_client'] / 2**30:.2f} | {p['peak_rss_workers'] / 2**30:.2f} |", flush=True)
        rows.append(dict(case="scale", mesh="torus", faces=stats["faces_in"], ratio=args.ratio, what="partitioned",
                         seconds=dt, peak_gib=max(p["peak_rss_client"], p["peak_rss_workers"]) / 2**30,
                         value=1e6 * dt / stats["faces_in"], note=f"workers={args.workers}"))
        import shutil
        shutil.rmtree(scratch, ignore_errors=True)
        if not args.keep:
            src.unlink()
    append(rows)


def workers(args, folder: Path) -> None:
    src = big(args.faces[0], folder)
    digests = {}
    for k in args.counts:
        out = folder / f"w{k}.ply"
        dt, _, _ = timed(partitioned_cmd(src, out, args.ratio, k, args.part_faces))
        digests[k] = hashlib.sha256(out.read_bytes()).hexdigest()
        print(f"  {k} workers: {dt:.1f} s, sha256 {digests[k][:16]}", flush=True)
    same = len(set(digests.values())) == 1
    print(f"identical output bytes with {', '.join(map(str, args.counts))} workers: {same}")
    append([dict(case="workers", mesh="torus", faces=args.faces[0], ratio=args.ratio, what=f"{k} workers",
                 value=d[:16], note=f"identical={same}") for k, d in digests.items()])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", choices=["speed", "quality", "scale", "workers"])
    ap.add_argument("--mesh", default="armadillo-x64")
    ap.add_argument("--meshes", nargs="+", default=["stanford-bunny", "armadillo-x16", "armadillo-x64"])
    ap.add_argument("--faces", type=int, nargs="+", default=[5_500_000, 22_000_000, 88_000_000])
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--part-faces", type=int, default=None)
    ap.add_argument("--refit", nargs="+", default=["last", "all"], help="quality: Partition(refit=...) values")
    ap.add_argument("--share", nargs="+", default=["faces"], choices=["faces", "cost"],
                    help="quality: Partition(share=...) values")
    ap.add_argument("--late", nargs="+", default=["last"], choices=["last", "every"],
                    help="quality: the memoryless last stretch in the last level only (the package's) or in every level")
    ap.add_argument("--slivers", nargs="+", default=["every"], choices=["every", "last"],
                    help="quality: the sliver moves in every level (the package's) or in the last level only")
    ap.add_argument("--reduction", type=float, nargs="+", default=[None],
                    help="quality: Partition(reduction=...) values (default: the package's)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-in-core", action="store_true")
    ap.add_argument("--keep", action="store_true", help="scale: keep the generated PLY files")
    ap.add_argument("--folder", default=None, help="where the inputs are written (default: a temporary folder)")
    args = ap.parse_args(argv)
    folder = Path(args.folder or tempfile.mkdtemp(prefix="qemjax-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    {"speed": speed, "quality": quality, "scale": scale, "workers": workers}[args.case](args, folder)


if __name__ == "__main__":
    main()
