"""Plots from the CSV written by bench_peers.py.

Saves under the CSV's folder (default ``experiments/results/``):

- ``error_vs_ratio.png``: relative RMS distance (``rms_rel``) against the kept-face ratio, log-log, one line
  per method, one panel per mesh (``--meshes`` picks which; default: up to 6 of the largest);
- ``hausdorff_vs_ratio.png``: the same for ``hausdorff_rel``;
- ``time_vs_faces.png``: time against input faces, log-log, one line per method, one panel per ratio.

    python experiments/figures/plot_results.py [--csv experiments/results/peers.csv] [--meshes bunny cow ...]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/

# fixed colours and markers, so that a method looks the same in every figure
STYLE = {
    "qemjax-parallel": ("tab:red", "o"),
    "qemjax-greedy": ("tab:orange", "s"),
    "meshoptimizer": ("tab:blue", "^"),
    "fast-simplification": ("tab:green", "v"),
    "pyfqmr": ("tab:olive", "<"),
    "pymeshlab": ("tab:purple", "D"),
    "libigl": ("tab:brown", "P"),
}


def _style(method):
    return STYLE.get(method, ("gray", "x"))


def _grid(n):
    cols = min(3, n)
    rows = math.ceil(n / cols)
    return rows, cols


def plot_metric_vs_ratio(df, metric: str, meshes: list[str], path: Path):
    import matplotlib.pyplot as plt

    rows, cols = _grid(len(meshes))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, mesh in zip(axes.ravel(), meshes):
        sub = df[(df["mesh"] == mesh) & df[metric].notna() & (df[metric] > 0)]
        for method, group in sub.groupby("method", sort=False):
            group = group.sort_values("ratio")
            color, marker = _style(method)
            ax.plot(group["ratio"], group[metric], color=color, marker=marker, label=method, lw=1.2, ms=4)
        faces = df.loc[df["mesh"] == mesh, "faces_in"]
        ax.set_title(f"{mesh} ({int(faces.iloc[0]):,} faces)" if len(faces) else mesh, fontsize=10)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("kept face ratio")
        ax.set_ylabel(metric)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(meshes):]:
        ax.set_visible(False)
    fig.tight_layout(rect=_legend(fig, axes))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_time_vs_faces(df, path: Path):
    import matplotlib.pyplot as plt

    ratios = sorted(df["ratio"].unique(), reverse=True)
    rows, cols = _grid(len(ratios))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, ratio in zip(axes.ravel(), ratios):
        sub = df[(df["ratio"] == ratio) & df["time_s"].notna() & (df["time_s"] > 0)]
        for method, group in sub.groupby("method", sort=False):
            group = group.sort_values("faces_in")
            color, marker = _style(method)
            ax.plot(group["faces_in"], group["time_s"], color=color, marker=marker, label=method, lw=1.2, ms=4)
        ax.set_title(f"ratio {ratio:g}", fontsize=10)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("input faces")
        ax.set_ylabel("time (s)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(ratios):]:
        ax.set_visible(False)
    fig.tight_layout(rect=_legend(fig, axes))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _legend(fig, axes):
    """One legend for all panels, above them; returns the tight_layout rect that leaves room for it."""
    handles, labels = {}, []
    for ax in axes.ravel():
        for h, label in zip(*ax.get_legend_handles_labels()):
            if label not in handles:
                handles[label] = h
                labels.append(label)
    if not labels:
        return (0, 0, 1, 1)
    width, height = fig.get_size_inches()
    ncol = max(1, min(len(labels), int(width // 1.9)))  # ~1.9 inches per entry
    fig.legend([handles[label] for label in labels], labels, loc="upper center", ncol=ncol, fontsize=9,
               frameon=False)
    legend_rows = math.ceil(len(labels) / ncol)
    return (0, 0, 1, 1 - (0.25 * legend_rows + 0.1) / height)


def main(argv=None):
    import matplotlib

    matplotlib.use("Agg")
    import pandas as pd

    p = argparse.ArgumentParser(description="plot bench_peers.py results")
    p.add_argument("--csv", type=Path, default=EXPERIMENTS / "results" / "peers.csv")
    p.add_argument("--meshes", nargs="+", help="meshes for the error panels (default: up to 6 largest)")
    p.add_argument("--outdir", type=Path, help="default: the CSV's folder")
    args = p.parse_args(argv)

    df = pd.read_csv(args.csv)
    df = df[df["status"] == "ok"]
    outdir = args.outdir or args.csv.parent
    outdir.mkdir(parents=True, exist_ok=True)
    meshes = args.meshes or (
        df.groupby("mesh")["faces_in"].first().sort_values(ascending=False).index[:6].tolist()
    )
    written = []
    for metric, name in (("rms_rel", "error_vs_ratio.png"), ("hausdorff_rel", "hausdorff_vs_ratio.png")):
        if metric in df and df[metric].notna().any():
            plot_metric_vs_ratio(df, metric, meshes, outdir / name)
            written.append(name)
        else:
            print(f"no {metric} column with values in {args.csv}: skipping {name}")
    plot_time_vs_faces(df, outdir / "time_vs_faces.png")
    written.append("time_vs_faces.png")
    print("wrote", ", ".join(str(outdir / w) for w in written))


if __name__ == "__main__":
    main()
