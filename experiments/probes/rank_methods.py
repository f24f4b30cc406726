"""Rank qemjax configurations against the peers, all run by `qemjax.sweep` (peers as methods).

For each shared mesh (welded, `meshes.load`) and ratio (10 % and 1 % by default), ``target = max(4,
round(ratio * faces))`` (as `rank_peers.py`); every candidate configuration and every peer simplify to it
through `qemjax.sweep` (one cell each, alone, warm: qemjax's ``run_s`` leaves compilation out, a peer runs
once on a small icosphere first), measured by the sweep's own metrics (`qemjax.metrics.evaluate`, seed 0:
``rms_rel``, ``hausdorff_rel``). "Best peer" is per metric: the lowest rms among the peers, and separately
the lowest Hausdorff; a peer whose row has an error is left out of that case.

A candidate is ``LABEL`` or ``LABEL:key=value,...`` with ``simplify`` keywords (values read as Python
literals where they parse, else text): ``accurate:preset=accurate``, ``line:method=line``,
``r:regularize=0.1``. The first candidate is the base (default: ``default``, plain ``simplify``).

Per candidate: cases with rms <= best peer's, with Hausdorff <= best peer's, and the median over cases of its
warm ``run_s`` over the base's (same run; the machine may be shared: only this ratio is meaningful), with
the rows of stanford-bunny and armadillo spelled out. Equal face counts (`rank_peers.py`'s idea): where a
candidate and the base stop at different face counts, the one that went further runs again with the
other's count as its target, and the time ratio uses those matched runs (row ``status`` ``matched to
LABEL``); the peer comparison uses the runs as they stopped. ::

    python experiments/probes/rank_methods.py --candidate accurate:preset=accurate --candidate line:method=line
    python experiments/probes/rank_methods.py --candidate accurate:preset=accurate --meshes cow fandisk face \
        --out experiments/results/rank_methods_subset

Writes ``OUT.csv`` (one row per run) and ``OUT.md`` (the command, the date and the tables).
"""
from __future__ import annotations

import argparse
import ast
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402

RESULTS = EXPERIMENTS / "results"
COLUMNS = ["mesh", "faces_in", "ratio", "target", "label", "method", "faces_out", "rms_rel", "hausdorff_rel",
           "run_s", "status"]
SPELLED_OUT = ("stanford-bunny", "armadillo")


def parse_candidate(spec: str) -> tuple[str, dict]:
    """'LABEL[:k=v,...]' -> (label, simplify keywords)."""
    label, _, rest = spec.partition(":")
    kwargs = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            kwargs[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            kwargs[key] = value
    return label, kwargs


def sweep_rows(name, mesh, grid: dict, targets: list[int], label) -> list[dict]:
    """Rows of one `qemjax.sweep` of ``grid`` on one mesh, one cell at a time."""
    import qemjax

    df = qemjax.sweep({name: mesh}, {k: [v] if k != "method" else v for k, v in grid.items()}, targets,
                      batch_size=1, progress=False)
    rows = []
    for r in df.to_dict("records"):
        err = r.get("error") or ""
        rows.append({"mesh": name, "faces_in": len(mesh[1]), "target": int(r["target"]),
                     "label": label(r), "method": r["method"], "faces_out": r.get("faces_out"),
                     "rms_rel": r.get("rms_rel"), "hausdorff_rel": r.get("hausdorff_rel"),
                     "run_s": r.get("run_s"), "status": err[:120] if err else "ok"})
    return rows


def run_mesh(name: str, candidates: list, peer_names: list[str], ratios: list[float]) -> list[dict]:
    m = bench_meshes.load(name)
    mesh = (m.V, m.F)
    by_target = {max(4, int(round(r * m.n_faces))): r for r in ratios}
    targets = list(by_target)
    rows = sweep_rows(name, mesh, {"method": peer_names}, targets, lambda r: r["method"]) if peer_names else []
    own = {}
    for label, kw in candidates:
        grid = {**kw, "method": [kw.get("method", "qem")]}
        got = sweep_rows(name, mesh, grid, targets, lambda r, label=label: label)
        own[label] = {g["target"]: g for g in got}
        rows += got
    base = candidates[0][0]
    for label, kw in candidates[1:]:  # equal face counts for the time ratio
        for t in targets:
            a, b = own[label][t], own[base][t]
            if a["status"] != "ok" or b["status"] != "ok" or a["faces_out"] == b["faces_out"]:
                continue
            further, other, fkw = ((label, base, kw) if a["faces_out"] < b["faces_out"]
                                   else (base, label, dict(candidates[0][1])))
            fewer = min(a["faces_out"], b["faces_out"])
            grid = {**fkw, "method": [fkw.get("method", "qem")]}
            again = sweep_rows(name, mesh, grid, [int(max(a["faces_out"], b["faces_out"]))],
                               lambda r, f=further: f)[0]
            again.update(target=t, status=f"matched to {other}", matched_from=fewer)
            rows.append(again)
    for r in rows:
        r["ratio"] = by_target[r["target"]]
    return rows


def summarize(rows: list[dict], labels: list[str], peer_names: list[str]) -> str:
    ok = [r for r in rows if r["status"] == "ok"]
    cases = sorted({(r["mesh"], r["ratio"]) for r in rows}, key=lambda c: (-c[1], c[0]))
    base = labels[0]
    out = ["| candidate | cases | rms <= best peer | Hausdorff <= best peer | median run_s / " + base + " |",
           "|---|---|---|---|---|"]
    detail = []
    for label in labels:
        n = n_r = n_h = 0
        times = []
        for mesh, ratio in cases:
            here = [r for r in ok if r["mesh"] == mesh and r["ratio"] == ratio]
            o = next((r for r in here if r["label"] == label), None)
            b = next((r for r in here if r["label"] == base), None)
            peers = [r for r in here if r["label"] in peer_names]
            if o is None or not peers:
                continue
            br = min(peers, key=lambda r: r["rms_rel"])
            bh = min(peers, key=lambda r: r["hausdorff_rel"])
            a, h = o["rms_rel"] / br["rms_rel"], o["hausdorff_rel"] / bh["hausdorff_rel"]
            n, n_r, n_h = n + 1, n_r + (a <= 1), n_h + (h <= 1)
            tr = float("nan")
            if b is not None:  # matched runs where the face counts differ
                matched = {r["label"]: r for r in rows if r["mesh"] == mesh and r["ratio"] == ratio
                           and r["status"].startswith("matched to")}
                o2, b2 = matched.get(label, o), matched.get(base, b)
                tr = o2["run_s"] / b2["run_s"]
                times.append(tr)
            if mesh in SPELLED_OUT:
                detail.append(f"| {label} | {mesh} | {ratio:g} | {o['faces_out']} | {o['rms_rel']:.3e} | "
                              f"{br['rms_rel']:.3e} ({br['label']}) | {a:.3f} | {o['hausdorff_rel']:.3e} | "
                              f"{bh['hausdorff_rel']:.3e} ({bh['label']}) | {h:.3f} | {tr:.2f} |")
        med = f"{np.median(times):.2f}" if times else "n/a"
        out.append(f"| {label} | {n} | {n_r}/{n} | {n_h}/{n} | {med} |")
    if detail:
        out += ["", "| candidate | mesh | ratio | faces | rms | best peer rms | rms ratio | Hausdorff | "
                "best peer Hausdorff | H ratio | run_s / base |", "|---|---|---|---|---|---|---|---|---|---|---|",
                *detail]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--candidate", action="append", default=[],
                    help="LABEL or LABEL:key=value,... (simplify keywords; repeatable; 'default' is always first)")
    ap.add_argument("--peers", nargs="+", default=None, help="peer names (default: qemjax.peers.available())")
    ap.add_argument("--meshes", nargs="+", default=None, help="shared mesh names (default: all)")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--out", default=str(RESULTS / "rank_methods"), help="path without extension")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from qemjax import peers

    candidates = [("default", {})] + [parse_candidate(s) for s in args.candidate if s != "default"]
    peer_names = args.peers if args.peers is not None else peers.available()
    names = args.meshes or bench_meshes.names()
    if not names:
        raise SystemExit("no shared meshes (../shared/meshes is absent)")
    rows = []
    for name in names:
        got = run_mesh(name, candidates, peer_names, args.ratios)
        rows += got
        print(f"{name}: " + ", ".join(f"{r['label']}@{r['ratio']:g} {r['rms_rel']:.3e}/{r['hausdorff_rel']:.3e}"
                                      for r in got if r["status"] == "ok"), flush=True)
    table = summarize(rows, [c[0] for c in candidates], peer_names)
    print(table)
    import pandas as pd

    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).reindex(columns=COLUMNS + ["matched_from"]).to_csv(args.out + ".csv", index=False)
    cmd = "python experiments/probes/rank_methods.py " + " ".join(sys.argv[1:] if argv is None else argv)
    Path(args.out + ".md").write_text(
        f"`{cmd}`\n\n{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; peers: {', '.join(peer_names)}; "
        "metrics: qemjax.sweep's (evaluate, seed 0); times: warm run_s, same run, shared machine\n\n"
        + table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
