"""Benchmark qemjax against peer simplifiers: time and error, every method in the same run.

For each mesh x ratio x method: ``target = max(4, round(ratio * faces_in))``; simplify; time it; measure the
result with ``qemjax.metrics.evaluate(original, simplified, target_faces=target)``; write one CSV row. Then
each row gets time ratios against every peer on the same mesh and ratio: ``time_vs_<peer> = time_s / peer
time_s`` (and ``run_vs_<peer>``, which uses qemjax's own ``run_s``, i.e. without compilation).

Timing:
- peers: only the simplification call (array conversion left out), after one warm-up on a small icosphere
  per process (library loading, first-call setup);
- qemjax: wall time of ``qemjax.simplify`` (it includes any compilation, and the host<->device copies), plus
  ``compile_s`` / ``run_s`` from its stats. The first (mesh, ratio) each qemjax method meets is run twice:
  ``cold_s`` is the first call, ``time_s`` the second. ``--warm`` does this for every case.

Examples::

    python experiments/figures/bench_peers.py --meshes stanford-bunny cow --ratios 0.1 0.01
    python experiments/figures/bench_peers.py --methods meshoptimizer pyfqmr --meshes all --big
    python experiments/figures/bench_peers.py --meshes armadillo-x16 --ratios 0.01 --append

A method that fails records ``status=error`` and its message; the run goes on.

Where it writes, without ``--out``: the default run and ``--append`` runs (which replace only the rows they
make) write ``experiments/results/peers.csv``, the table docs/benchmarks.md cites, and ``machine.md`` beside
it; any other run (fewer meshes, ratios or methods, ...) writes ``peers_custom.csv`` and
``peers_custom_machine.md``, so that a quick run leaves the cited files alone.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
import traceback
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
import peers as bench_peers  # noqa: E402

RESULTS = EXPERIMENTS / "results"
DEFAULT_RATIOS = [0.5, 0.1, 0.01, 0.001]
QEMJAX_METHODS = {"qemjax-parallel": "parallel", "qemjax-greedy": "greedy"}
DEFAULT_METHODS = list(QEMJAX_METHODS) + list(bench_peers.PEERS)
SUMMARY_COLUMNS = ["mesh", "faces_in", "ratio", "method", "faces_out", "time_s", "rms_rel", "hausdorff_rel"]


# ----------------------------------------------------------------------------------------------- running


def run_qemjax(scheduler: str, V, F, target: int, repeats: int, **options) -> dict:
    """Run qemjax.simplify ``repeats`` times (extra keywords go to it); the last call is the one reported."""
    import qemjax

    walls = []
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, **options)
        V2 = np.asarray(result.vertices, dtype=np.float64)
        F2 = np.asarray(result.faces, dtype=np.int64)
        walls.append(time.perf_counter() - t0)
    stats = dict(getattr(result, "stats", {}) or {})
    row = {"V2": V2, "F2": F2, "time_s": walls[-1], "cold_s": walls[0] if repeats > 1 else math.nan,
           "flips_continued": continued_flips(result)}
    for key in ("compile_s", "run_s", "total_s", "rounds", "contractions"):
        value = stats.get(key, math.nan)
        row[key] = float(value) if _is_number(value) else math.nan
    return row


def continued_flips(result) -> int:
    """Output faces whose normal points against (dot <= 0) the input face they continue
    (``result.source_faces``): the flip test qemjax enforces. Only qemjax records that lineage; the
    ``flipped_faces`` metric, which every method gets, compares with the nearest input face instead."""
    def normals(V, F):
        V = np.asarray(V, np.float64)
        n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    n_in = normals(result.input_vertices, result.input_faces)[np.asarray(result.source_faces)]
    return int((np.sum(normals(result.vertices, result.faces) * n_in, axis=1) <= 0).sum())


def run_method(method: str, V, F, target: int, repeats: int) -> dict:
    if method in QEMJAX_METHODS:
        return run_qemjax(QEMJAX_METHODS[method], V, F, target, repeats)
    V2, F2, call_s = bench_peers.run_peer(method, V, F, target)
    return {"V2": V2, "F2": F2, "time_s": call_s}


def evaluate(V, F, V2, F2, target: int) -> dict:
    """Scalar metrics from qemjax.metrics.evaluate; keys that clash with the harness's own are prefixed."""
    from qemjax.metrics import evaluate as qevaluate

    metrics = qevaluate((V, F), (V2, F2), target_faces=target, seed=0)
    out = {}
    for key, value in dict(metrics).items():
        if isinstance(value, np.ndarray) and value.size == 1:
            value = value.item()
        elif hasattr(value, "item") and getattr(value, "shape", None) == ():
            value = value.item()
        if not (_is_number(value) or isinstance(value, (str, bool))):
            continue
        name = f"metric_{key}" if key in RESERVED else key
        out[name] = value
    return out


RESERVED = {
    "mesh", "faces_in", "verts_in", "ratio", "target", "method", "faces_out", "verts_out", "time_s", "cold_s",
    "compile_s", "run_s", "total_s", "rounds", "contractions", "status", "error", "eval_status", "eval_error",
}


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


# ----------------------------------------------------------------------------------------------- tables


def add_time_ratios(df):
    """Add ``time_vs_<peer>`` (and ``run_vs_<peer>``) = this row's time / the peer's, same mesh and ratio."""
    import pandas as pd

    ok = df[df["status"] == "ok"]
    own_run = df["run_s"].where(df["run_s"].notna(), df["time_s"]) if "run_s" in df else df["time_s"]
    for peer in bench_peers.PEERS:
        ref = ok[ok["method"] == peer].set_index(["mesh", "ratio"])["time_s"]
        if ref.empty:
            continue
        ref = ref[~ref.index.duplicated(keep="last")]
        keys = pd.MultiIndex.from_frame(df[["mesh", "ratio"]])
        peer_time = ref.reindex(keys).to_numpy()
        df[f"time_vs_{peer}"] = df["time_s"].to_numpy() / peer_time
        df[f"run_vs_{peer}"] = own_run.to_numpy() / peer_time
    return df


def summary_table(df) -> str:
    cols = [c for c in SUMMARY_COLUMNS if c in df] + [c for c in ("compile_s", "status") if c in df]
    cols += [c for c in df.columns if c == "time_vs_meshoptimizer"]
    view = df[cols].copy()
    for col in ("faces_in", "faces_out"):
        if col in view:
            # integers, with "-" where a skipped / failed row has none (NaN would make the column float)
            view[col] = ["-" if isinstance(v, float) and math.isnan(v) else int(v) for v in view[col]]
    if "status" in view:
        view.loc[view["status"] == "ok", "status"] = ""
    return view.to_string(index=False, float_format=lambda x: f"{x:.3g}", na_rep="-")


# ----------------------------------------------------------------------------------------------- machine


def machine_report() -> str:
    from importlib import metadata

    lines = ["# Benchmark machine", ""]
    model = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = "unknown"
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 2**20:.1f} GiB"
                break
    except OSError:
        pass
    lines += [
        f"- date: {time.strftime('%Y-%m-%d %H:%M:%S %Z')}",
        f"- cores (os.cpu_count): {os.cpu_count()}",
        f"- CPU: {model}",
        f"- memory: {mem}",
        f"- platform: {platform.platform()}",
        f"- python: {platform.python_version()}",
    ]
    try:
        import jax

        devices = ", ".join(f"{d.platform}:{getattr(d, 'device_kind', '?')}" for d in jax.devices())
        lines.append(f"- jax devices: {devices}")
    except Exception as exc:  # jax missing or broken: say so, don't fail the benchmark
        lines.append(f"- jax devices: unavailable ({exc})")
    lines += ["", "| package | version |", "|---|---|"]
    packages = ["qemjax", "jax", "jaxlib", "numpy", "scipy", "trimesh", "pandas"]
    packages += list(bench_peers.PEER_PACKAGES.values())
    for pkg in packages:
        try:
            version = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            version = "not installed"
        lines.append(f"| {pkg} | {version} |")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------- main


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["all"], help="mesh names, or 'all' (every shared mesh)")
    p.add_argument("--ratios", nargs="+", type=float, default=DEFAULT_RATIOS)
    p.add_argument("--methods", nargs="+", default=DEFAULT_METHODS, choices=DEFAULT_METHODS)
    p.add_argument("--big", action="store_true", help="add armadillo-x16 (~1.38 M faces)")
    p.add_argument("--skip-greedy-above", type=int, default=200_000, metavar="N",
                   help="skip qemjax-greedy on meshes with more than N faces (default 200000)")
    p.add_argument("--warm", action="store_true", help="run qemjax twice on every case, report the second")
    p.add_argument("--no-metrics", action="store_true", help="skip qemjax.metrics.evaluate")
    p.add_argument("--no-plots", action="store_true", help="do not redraw the figures afterwards")
    p.add_argument("--append", action="store_true",
                   help="merge into an existing --out CSV (rows with the same mesh/ratio/method are replaced)")
    p.add_argument("--out", type=Path,
                   help="the CSV (default: results/peers.csv for the default run and --append runs, else "
                        "results/peers_custom.csv)")
    args = p.parse_args(argv)
    if args.out is None:
        default = {k: v for k, v in vars(p.parse_args([])).items() if k not in ("out", "no_plots")}
        options = {k: v for k, v in vars(args).items() if k not in ("out", "no_plots")}
        args.out = RESULTS / ("peers.csv" if args.append or options == default else "peers_custom.csv")
    return args


def machine_path(out: Path) -> Path:
    """The machine report beside ``out``: ``machine.md`` beside the cited peers.csv, else ``<out>_machine.md``."""
    return out.parent / ("machine.md" if out == RESULTS / "peers.csv" else out.stem + "_machine.md")


def main(argv=None) -> int:
    import pandas as pd

    args = parse_args(argv)
    names = bench_meshes.names() if args.meshes == ["all"] else list(args.meshes)
    if args.big and "armadillo-x16" not in names:
        names.append("armadillo-x16")
    if not names:
        print(f"no meshes found (looked in {bench_meshes.SHARED_MESHES})", file=sys.stderr)
        return 1

    args.out.parent.mkdir(parents=True, exist_ok=True)
    machine_path(args.out).write_text(machine_report())

    previous = None
    if args.append and args.out.exists():
        previous = pd.read_csv(args.out)

    rows: list[dict] = []
    qemjax_warmed: set[str] = set()

    def save():
        df = pd.DataFrame(rows)
        if previous is not None:
            keep = previous.merge(df[["mesh", "ratio", "method"]], how="left", indicator=True)
            keep = keep[keep["_merge"] == "left_only"].drop(columns="_merge")
            keep = keep[[c for c in keep.columns if not c.startswith(("time_vs_", "run_vs_"))]]
            df = pd.concat([keep, df], ignore_index=True)
        df = add_time_ratios(df)
        df.to_csv(args.out, index=False)
        return df

    for name in names:
        t0 = time.perf_counter()
        mesh = bench_meshes.load(name)
        print(f"== {name}: V {mesh.n_vertices}, F {mesh.n_faces} (loaded in {time.perf_counter() - t0:.1f} s)",
              flush=True)
        for ratio in args.ratios:
            target = max(4, round(ratio * mesh.n_faces))
            for method in args.methods:
                row = {"mesh": name, "faces_in": mesh.n_faces, "verts_in": mesh.n_vertices, "ratio": ratio,
                       "target": target, "method": method, "status": "ok", "error": ""}
                if method == "qemjax-greedy" and mesh.n_faces > args.skip_greedy_above:
                    row.update(status="skipped", error=f"faces_in > --skip-greedy-above {args.skip_greedy_above}")
                    rows.append(row)
                    continue
                repeats = 1
                if method in QEMJAX_METHODS and (args.warm or method not in qemjax_warmed):
                    repeats = 2
                try:
                    out = run_method(method, mesh.V, mesh.F, target, repeats)
                    qemjax_warmed.add(method)
                except Exception as exc:
                    row.update(status="error", error=f"{type(exc).__name__}: {exc}"[:500])
                    print(f"   {method:20s} ratio {ratio:g}: ERROR {row['error']}", flush=True)
                    if os.environ.get("BENCH_TRACEBACK"):
                        traceback.print_exc()
                    rows.append(row)
                    save()
                    continue
                V2, F2 = out.pop("V2"), out.pop("F2")
                row.update(out)
                row.update(faces_out=len(F2), verts_out=len(V2))
                if len(F2) == 0:  # e.g. libigl's qslim refuses non-manifold input and returns nothing
                    row.update(status="empty", error="returned no faces")
                elif not args.no_metrics:
                    try:
                        row.update(evaluate(mesh.V, mesh.F, V2, F2, target))
                        row["eval_status"] = "ok"
                    except Exception as exc:
                        row.update(eval_status="error", eval_error=f"{type(exc).__name__}: {exc}"[:500])
                rows.append(row)
                df = save()
                rms = row.get("rms_rel", math.nan)
                print(f"   {method:20s} ratio {ratio:g}: {len(F2):8d} faces  {row['time_s']:8.3f} s  "
                      f"rms_rel {rms:.3g}", flush=True)

    df = save()
    print()
    print(summary_table(df))
    print(f"\nwrote {args.out} and {machine_path(args.out)}")
    if not args.no_plots:  # one command regenerates the table and the figures
        from figures import plot_results

        plot_results.main(["--csv", str(args.out)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
