"""The documentation's figures and its table against the peers, from committed results files only.

Reads ``experiments/results/rank_default_final.csv`` (every benchmark mesh at 10 % and 1 %, qemjax's default
and classic method and five peers; written by ``python experiments/figures/rank_peers.py --warm --reuse-peers
experiments/results/rank_final.csv --out experiments/results/rank_default_final --variant
classic:method=classic --variant default:method=default``) and
``experiments/results/speed_table.txt`` (warm medians, every method in one process; written by
``python experiments/figures/speed_ratio.py --mesh MESH --ratio R --methods default classic --peers meshoptimizer
fast-simplification``). Writes, small and deterministic:

- ``docs/img/peers_quality.png``: each method's rms and Hausdorff distance over qemjax's default, per case;
- ``docs/img/speed.png``: warm seconds per method on three meshes (same process per mesh);
- ``docs/img/bumpy.png``: the example bumpy sphere and qemjax's default at 10 % (made in code);

and prints the Markdown table the README and docs/benchmarks.md show.

    python experiments/figures/docs_figures.py
"""
from __future__ import annotations

import argparse
import csv
import re
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
RESULTS = EXPERIMENTS / "results"
IMG = EXPERIMENTS.parent / "docs" / "img"
PEERS = ["meshoptimizer", "fast-simplification", "pyfqmr", "pymeshlab", "libigl"]
BASE = "qemjax-default"


def quality_rows(path=RESULTS / "rank_default_final.csv"):
    """{(mesh, ratio): {method: row}} from the ranking's CSV."""
    cases: dict = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if row["status"] != "ok":
                continue
            # a variant re-run at another face count (matched rows) keeps its first row
            cases.setdefault((row["mesh"], float(row["ratio"])), {}).setdefault(row["method"], row)
    return cases


def ratios(cases, method, column):
    """method's column over qemjax default's, per case: {ratio: [values]}."""
    out: dict = {}
    for (mesh, ratio), rows in sorted(cases.items()):
        if method in rows and BASE in rows:
            out.setdefault(ratio, []).append(float(rows[method][column]) / float(rows[BASE][column]))
    return out


def table(cases) -> str:
    lines = ["| method | rms / qemjax default (median of 34) | Hausdorff / qemjax default (median) "
             "| cases where qemjax's rms is lower |",
             "|---|---|---|---|"]
    for method in PEERS + ["qemjax-classic"]:
        rms = sum(ratios(cases, method, "rms_rel").values(), [])
        hd = sum(ratios(cases, method, "hausdorff_rel").values(), [])
        lines.append(f"| {method} | {np.median(rms):.2f} | {np.median(hd):.2f} | "
                     f"{sum(r > 1 for r in rms)}/{len(rms)} |")
    return "\n".join(lines)


def speed_tables(path=RESULTS / "speed_table.txt"):
    """[(title, {method: median s})] from speed_ratio.py's tables."""
    out = []
    for block in re.split(r"\n(?=\S+ \(\d+ faces\) -> )", path.read_text()):
        head = re.match(r"(\S+) \((\d+) faces\) -> (\d+) faces", block)
        if not head:
            continue
        times = {m: float(s) for m, s in re.findall(r"^\| (\S+) \| ([\d.]+) \|", block, re.M)}
        out.append((f"{head.group(1)}\n{int(head.group(2)):,} → {int(head.group(3)):,}", times))
    return out


def plot_quality(cases, plt):
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), dpi=90, sharey=True)
    methods = PEERS + ["qemjax-classic"]
    for ax, column, title in zip(axes, ["rms_rel", "hausdorff_rel"], ["rms distance", "Hausdorff distance"]):
        for i, method in enumerate(methods):
            for ratio, marker, colour in [(0.1, "o", "tab:blue"), (0.01, "^", "tab:orange")]:
                ys = ratios(cases, method, column).get(ratio, [])
                xs = i + np.linspace(-0.18, 0.18, len(ys)) + (0.0 if ratio == 0.1 else 0.04)
                ax.scatter(xs, ys, s=10, marker=marker, color=colour, alpha=0.75,
                           label=f"to {ratio:.0%}" if i == 0 else None)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        ax.set_xticks(range(len(methods)), [m.replace("qemjax-", "qemjax ").replace("fast-simplification",
                                                                                   "fast-simpl.")
                                            for m in methods], rotation=30, ha="right", fontsize=8)
        ax.set_title(f"{title} / qemjax default", fontsize=9)
    axes[0].set_ylabel("ratio per case (> 1: qemjax closer)", fontsize=8)
    axes[0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(IMG / "peers_quality.png", metadata={"Software": None})
    plt.close(fig)


def plot_speed(plt):
    tables = speed_tables()
    methods = ["qemjax-default", "qemjax-classic", "meshoptimizer", "fast-simplification"]
    fig, ax = plt.subplots(figsize=(7, 3), dpi=90)
    width = 0.2
    for j, method in enumerate(methods):
        ax.bar([i + (j - 1.5) * width for i in range(len(tables))], [t[method] for _, t in tables], width,
               label=method)
    ax.set_yscale("log")
    ax.set_xticks(range(len(tables)), [title for title, _ in tables], fontsize=8)
    ax.set_ylabel("warm seconds (median)", fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(IMG / "speed.png", metadata={"Software": None})
    plt.close(fig)


def plot_bumpy(plt):
    import qemjax
    from qemjax import render, shapes

    V, F = shapes.bumpy_sphere(subdivisions=4)
    res = qemjax.simplify((V, F), ratio=0.1, progress=False)
    fig = render.render_pair((V, F), res, titles=[f"input: {len(F):,} faces", f"qemjax: {len(res.faces):,} faces"],
                             figsize=(6, 3), dpi=80)
    fig.savefig(IMG / "bumpy.png", metadata={"Software": None})
    plt.close(fig)


def main(argv=None):
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    IMG.mkdir(parents=True, exist_ok=True)
    cases = quality_rows()
    plot_quality(cases, plt)
    plot_speed(plt)
    plot_bumpy(plt)
    print(table(cases))
    for title, times in speed_tables():
        base = times["qemjax-default"]
        print(title.replace("\n", " "), {m: f"{s:.4g} s (qemjax default / it: {base / s:.1f})" for m, s in times.items()})


if __name__ == "__main__":
    main()
