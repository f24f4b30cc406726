"""Quality of the parallel scheduler against the greedy one (the quality reference), and its gate sweep.

For every shared mesh (``meshes.py``) x ratio: ``target = max(4, round(ratio * faces_in))`` as in
``bench_peers.py``; run ``qemjax.simplify`` with ``scheduler="greedy"`` and ``scheduler="parallel"`` and measure
both with ``qemjax.metrics.evaluate`` (through ``bench_peers.evaluate``: default samples, seed 0). One CSV row
per (mesh, ratio), and a markdown table with ``par vs greedy % = 100 * (rms_par / rms_greedy - 1)``; a summary
line gives the faces of the parallel outputs that point against the input face they continue (``flips_par``;
`bench_peers.continued_flips`), the worst percentage, how many cases are within +3 % and the parallel rounds
summed over all cases.

When one scheduler stops short of the target (no valid contraction left) and the other goes further, the two
meshes have different face counts and their errors are not comparable: the one that went further also runs
with the other's face count as its target, and ``matched %`` compares those two (it equals ``par vs greedy %``
when the counts agree; ``faces_matched`` is the count compared). The summary's "at equal face counts" figures
use it.

Greedy is slow and deterministic: its rows are cached in ``results/cache/greedy_rows.csv`` (git-ignored), keyed
by mesh, ratio, target and a hash of ``GREEDY_SOURCES``, so a re-run only recomputes the parallel rows.

``--set NAME=VALUE`` sets a field of the parallel scheduler's `qemjax.Schedule` (gate, gate_fraction, tail,
free_cost, max_passes, pass_yield), passed to every parallel call. The schedule's values go into every CSV
row.

Examples::

    python experiments/figures/parallel_vs_greedy.py
    python experiments/figures/parallel_vs_greedy.py --meshes cow stanford-bunny
    python experiments/figures/parallel_vs_greedy.py --set gate=1.2 --set gate_fraction=0.02 --out /tmp/g1.2_f0.02.csv
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

from figures import bench_peers  # noqa: E402
import meshes as bench_meshes  # noqa: E402

RESULTS = EXPERIMENTS / "results"
GREEDY_CACHE = bench_meshes.CACHE / "greedy_rows.csv"
# globs in the qemjax package that is imported: everything the greedy scheduler runs
GREEDY_SOURCES = ("_kernels/*.py", "_costs/*.py", "_schedulers/greedy/*.py", "_schedulers/rules.py",
                  "_schedulers/locks.py", "_schedulers/device.py", "_schedulers/runtime.py", "_schedulers/outcome.py", "_mesh/incidence.py",
                  "_kernels/batching.py", "_mesh/topology.py")
MEASURED = ("faces", "rounds", "time_s", "rms_rel", "hausdorff_rel")
WITHIN_PCT = 3.0


def source_hash(patterns=GREEDY_SOURCES) -> str:
    """Hash of the greedy scheduler's sources (paths and contents), in the qemjax that is imported."""
    import qemjax

    package = Path(qemjax.__file__).parent
    h = hashlib.sha256()
    for path in sorted(p for pattern in patterns for p in package.glob(pattern)):
        h.update(path.relative_to(package).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def apply_overrides(pairs: list[str]):
    """A `qemjax.Schedule` with the ``NAME=VALUE`` fields set (cast to the field's type), and its fields."""
    import dataclasses

    import qemjax

    fields = {f.name: f for f in dataclasses.fields(qemjax.Schedule)}
    values = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        if name not in fields or not value:
            raise SystemExit(f"--set expects NAME=VALUE with NAME a field of qemjax.Schedule {tuple(fields)}, "
                             f"got {pair!r}")
        values[name] = type(getattr(qemjax.Schedule(), name))(float(value))
    schedule = qemjax.Schedule(**values)
    return schedule, dataclasses.asdict(schedule)


SCHEDULE = None  # the parallel scheduler's `qemjax.Schedule` (--set)


def measure(scheduler: str, mesh, target: int) -> dict:
    extra = {"schedule": SCHEDULE} if scheduler == "parallel" and SCHEDULE is not None else {}
    out = bench_peers.run_qemjax(scheduler, mesh.V, mesh.F, target, repeats=1, **extra)
    metrics = bench_peers.evaluate(mesh.V, mesh.F, out["V2"], out["F2"], target)
    return {"faces": len(out["F2"]), "rounds": out["rounds"], "time_s": out["time_s"],
            "rms_rel": metrics["rms_rel"], "hausdorff_rel": metrics["hausdorff_rel"],
            "flips": out["flips_continued"]}


def greedy_row(cache, mesh, ratio: float, target: int, key: str) -> dict:
    """Greedy measurements from the cache, or computed and appended to it."""
    import pandas as pd

    if cache is not None:
        hit = cache[(cache["mesh"] == mesh.name) & (cache["ratio"] == ratio) & (cache["target"] == target)
                    & (cache["source_hash"] == key)]
        if len(hit):
            return hit.iloc[-1][list(MEASURED)].to_dict()
    row = {k: v for k, v in measure("greedy", mesh, target).items() if k in MEASURED}
    record = pd.DataFrame([{"mesh": mesh.name, "ratio": ratio, "target": target, "source_hash": key} | row])
    GREEDY_CACHE.parent.mkdir(parents=True, exist_ok=True)
    record.to_csv(GREEDY_CACHE, mode="a", header=not GREEDY_CACHE.exists(), index=False)
    return row


def markdown(df) -> str:
    lines = ["| mesh | ratio | target | faces par/greedy | rms parallel | rms greedy | par vs greedy % | matched % "
             "| rounds |", "|---|---|---|---|---|---|---|---|---|"]
    for r in df.itertuples():
        lines.append(f"| {r.mesh} | {r.ratio:g} | {r.target} | {r.faces_par}/{r.faces_greedy} | "
                     f"{r.rms_par:.3e} | {r.rms_greedy:.3e} | {r.par_vs_greedy_pct:+.1f} | {r.matched_pct:+.1f} | "
                     f"{r.rounds_par:.0f} |")
    return "\n".join(lines)


def summary(df, settings: dict) -> str:
    shown = " ".join(f"{k}={v:g}" for k, v in settings.items())
    parts = [f"parallel faces against the input face they continue: {int(df['flips_par'].sum())} in all"]
    for column, label in (("par_vs_greedy_pct", "at the target"), ("matched_pct", "at equal face counts")):
        pct = df[column]
        worst = df.loc[pct.idxmax()]
        parts.append(f"{label}: worst {pct.max():+.1f} % ({worst['mesh']} @ {worst['ratio']:g}), "
                     f"{int((pct <= WITHIN_PCT).sum())}/{len(df)} within +{WITHIN_PCT:g} %")
    return f"{shown}: " + "; ".join(parts) + f"; total parallel rounds {df['rounds_par'].sum():.0f}"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["all"], help="mesh names, or 'all' (every shared mesh)")
    p.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", dest="overrides",
                   help="set a field of qemjax.Schedule for the parallel runs, e.g. gate=1.2")
    p.add_argument("--out", type=Path, default=RESULTS / "parallel_vs_greedy.csv")
    return p.parse_args(argv)


def main(argv=None) -> int:
    import pandas as pd

    args = parse_args(argv)
    global SCHEDULE
    SCHEDULE, settings = apply_overrides(args.overrides)
    names = bench_meshes.names() if args.meshes == ["all"] else list(args.meshes)
    key = source_hash()
    cache = pd.read_csv(GREEDY_CACHE) if GREEDY_CACHE.exists() else None

    rows = []
    for name in names:
        mesh = bench_meshes.load(name)
        for ratio in args.ratios:
            target = max(4, round(ratio * mesh.n_faces))
            greedy = greedy_row(cache, mesh, ratio, target, key)
            par = measure("parallel", mesh, target)
            row = {"mesh": name, "faces_in": mesh.n_faces, "ratio": ratio, "target": target}
            row |= {f"{k.removesuffix('_rel')}_par": v for k, v in par.items()}
            row |= {f"{k.removesuffix('_rel')}_greedy": v for k, v in greedy.items()}
            row["par_vs_greedy_pct"] = 100 * (par["rms_rel"] / greedy["rms_rel"] - 1)
            par_m, greedy_m = par, greedy
            if greedy["faces"] > par["faces"]:  # greedy stopped short: compare at its face count
                par_m = measure("parallel", mesh, int(greedy["faces"]))
            elif par["faces"] > greedy["faces"]:  # parallel stopped short
                greedy_m = greedy_row(cache, mesh, ratio, int(par["faces"]), key)
            row["faces_matched"] = max(par["faces"], greedy["faces"])
            row["matched_pct"] = 100 * (par_m["rms_rel"] / greedy_m["rms_rel"] - 1)
            rows.append(row | settings)
            print(f"{name:18s} {ratio:<5g} rms par {par['rms_rel']:.3e} greedy {greedy['rms_rel']:.3e} "
                  f"({row['par_vs_greedy_pct']:+.1f} %, matched {row['matched_pct']:+.1f} %), {par['rounds']:.0f} rounds",
                  flush=True)

    df = pd.DataFrame(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    print()
    print(markdown(df))
    print()
    print(summary(df, settings))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
