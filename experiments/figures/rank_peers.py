"""Rank qemjax against the best peer on every shared mesh: rms and Hausdorff over the best peer's, per case.

For each shared mesh (welded, `meshes.load`) and ratio (10 % and 1 % by default): ``target = max(4,
round(ratio * faces))``; every peer of `peers.PEERS` and every qemjax variant simplify to it; the two-way
distances come from ``qemjax.metrics.surface_distance`` (relative to the bounding-box diagonal, seed 0).
"Best peer" is taken per metric: the lowest rms among the peers, and separately the lowest Hausdorff.
A peer that fails is left out of that case.

A variant is ``LABEL`` or ``LABEL:key=value,...``: ``rev=REV`` runs qemjax as it was at that git revision
(unpacked by `ab_compare.load_old`, in this process); other keys set the QEM model's fields
(``placement``, ``cond_eps``, ``rank_eps``, ``max_shift``, ``area_weighted``, ``area_power``,
``boundary_weight``), other numeric keywords of ``simplify`` (``refit``) are passed to it, and
``preset=NAME`` passes ``simplify(preset=NAME)``; ``schedule.FIELD=VALUE`` (e.g. ``schedule.gate=2``) runs the
parallel scheduler with a `qemjax.Schedule` of those fields; ``method=NAME`` runs another registered method or
preset (its QEM fields set as above); without either, the revision's own default method runs.
``--warm`` times each qemjax run after an untimed one. So the table before and
after a change comes from one command::

    python experiments/figures/rank_peers.py --variant old:rev=02a1390 --variant rank:placement=rank
    python experiments/figures/rank_peers.py --variant new --variant loose:cond_eps=1e-9 --meshes cow face

Rows go to ``results/rank_peers.csv``; the printed table (one block per variant) also to
``results/rank_peers.txt``. ``--reuse-peers [CSV]`` takes the peers' rows from a CSV of an earlier run
instead of running them again (peers are deterministic; for studies of qemjax's own settings)::

    python experiments/figures/rank_peers.py --variant base --variant bw1000:boundary_weight=1000 \
        --meshes beetle face --reuse-peers experiments/results/rank_peers.csv --out experiments/results/boundary

Equal face counts: where a variant and the first one (the base) stop at different face counts (the
target cannot be reached, e.g. on meshes with many open parts), the one that went further runs again with
the other's face count as its target (row status ``matched to qemjax-OTHER``). The peer tables use the
runs as they stopped; the "variant / base" comparison prints both ratios, ``raw`` (as they stopped) and
``matched`` (at equal face counts), and counts the cases more than 3 % worse both ways.

``--summarize CSV`` prints the tables of an earlier run again (with the per-ratio counts and the
Hausdorff comparison, added after some runs were written) without running anything.
"""
from __future__ import annotations

import argparse
import importlib
import csv
import dataclasses
import inspect
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
import peers as bench_peers  # noqa: E402

RESULTS = EXPERIMENTS / "results"
COLUMNS = ["mesh", "faces_in", "ratio", "target", "method", "faces_out", "rms_rel", "hausdorff_rel", "slivers", "time_s",
           "branches", "status"]


def parse_variant(spec: str) -> tuple[str, str | None, dict]:
    """'LABEL[:k=v,...]' -> (label, rev or None, QEM field settings)."""
    label, _, rest = spec.partition(":")
    rev, settings = None, {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        if key == "rev":
            rev = value
        else:
            settings[key] = {"true": True, "false": False}.get(value.lower(), value)
    return label, rev, settings


def variant_runner(label: str, rev: str | None, settings: dict):
    """A function (V, F, target) -> result of ``simplify`` for one variant."""
    if rev is not None:
        import ab_compare

        package = ab_compare.load_old(rev, as_name=f"qemjax_{label.replace('-', '_')}")
    else:
        import qemjax as package
    costs = package._costs
    preset = settings.pop("preset", None)  # a simplify(preset=...) name
    # schedule.FIELD=VALUE: the parallel scheduler's `Schedule` with those fields (issue 33: fewer rounds)
    schedule = {k.split(".", 1)[1]: float(settings.pop(k)) for k in list(settings) if k.startswith("schedule.")}
    if schedule:
        ints = {"tail", "max_passes"}
        schedule = package.Schedule(**{k: int(v) if k in ints else v for k, v in schedule.items()})
    base_method = settings.pop("method", None)  # a registered method (its fields: the QEM ones it shares)
    # every setting of a method, Topology or Attributes by its name: `_pipeline.flat` (`_flat` before the
    # layout regroup, 61c71ce)
    try:
        flat = importlib.import_module(f"{package.__name__}._pipeline.flat")
    except ImportError:
        flat = getattr(package, "_flat", None)
    if flat is not None:
        table = flat.options()
        unknown = set(settings) - set(table)
        if unknown:
            raise SystemExit(f"unknown setting(s) {sorted(unknown)}; choose from {sorted(table)} or preset")
        keywords = {k: v if isinstance(v, bool) or v is None
                    else (None if str(v).lower() == "none" else float(v)) if table[k].default is None
                    else type(table[k].default)(v) for k, v in settings.items()}
        if preset or base_method:  # else the package's own default method
            keywords["method"] = preset or base_method
        if schedule:
            keywords["scheduler"] = schedule

        def run_flat(V, F, target):
            return package.simplify((V, F), target_faces=target, **keywords)
        return run_flat
    base_method = base_method or "qem"  # the default method of revisions before settings-as-objects
    # an older revision: its flat keywords, and QEM fields without a keyword as a registered subclass
    fields = {f.name: f for f in dataclasses.fields(costs.QEM)}
    params = inspect.signature(package.simplify).parameters
    # simplify keywords that are not QEM fields (e.g. refit), typed by their defaults
    extra = {k: type(params[k].default)(settings.pop(k)) for k in list(settings)
             if k not in fields and k in params and isinstance(params[k].default, (bool, int, float))}
    unknown = set(settings) - set(fields)
    if unknown:
        raise SystemExit(f"unknown QEM setting(s) {sorted(unknown)}; choose from {sorted(fields)} or preset")
    typed = {k: type(fields[k].default)(v) for k, v in settings.items()}
    # settings that simplify takes as keywords go there (it passes them to the model); the rest are
    # defaults of a QEM subclass
    keywords = {k: typed.pop(k) for k in list(typed) if k in inspect.signature(package.simplify).parameters}
    keywords.update(extra)
    if preset is not None:
        keywords["preset"] = preset
    if typed:  # a QEM subclass with these defaults, registered under its own name
        name = f"qem-{label}"
        cls = dataclasses.make_dataclass(name, [(k, type(v), dataclasses.field(default=v))
                                                for k, v in typed.items()],
                                         bases=(costs.REGISTRY[base_method],), frozen=True,
                                         namespace={"name": name})
        if name not in costs.REGISTRY:
            costs.register(cls)
        method = name
    else:
        method = base_method

    if schedule:
        keywords["scheduler"] = schedule

    def run(V, F, target):
        return package.simplify((V, F), target_faces=target, method=method, **keywords)
    return run


def distances(V, F, V2, F2) -> dict:
    from qemjax.metrics import surface_distance, triangle_quality

    d = surface_distance((V, F), (V2, F2), seed=0)
    return {"rms_rel": d["rms_rel"], "hausdorff_rel": d["hausdorff_rel"],
            "slivers": triangle_quality((V2, F2))["sliver_fraction"]}


def run_peers(mesh, ratio, target) -> list[dict]:
    rows = []
    for peer in bench_peers.PEERS:
        row = dict(mesh=mesh.name, faces_in=mesh.n_faces, ratio=ratio, target=target, method=peer)
        try:
            V2, F2, secs = bench_peers.run_peer(peer, mesh.V, mesh.F, target)
            row.update(faces_out=len(F2), time_s=secs, status="ok", **distances(mesh.V, mesh.F, V2, F2))
        except Exception as exc:  # a peer that fails on a mesh is left out of the case
            row.update(status=f"error: {type(exc).__name__}: {exc}"[:120])
        rows.append(row)
    return rows


def summary(rows: list[dict], cases, labels: list[str]) -> str:
    """One line per variant: cases at or below the best peer (rms, Hausdorff), cases whose fraction of
    slivers (smallest angle under 10°) is at or below pymeshlab's (rows without it: "-"), cases that stopped
    above the target, and its time over the first variant's (same run: median over the cases, and on the
    bunny and the armadillo at each ratio)."""
    def row_of(mesh, ratio, label):
        return next((r for r in rows if r["mesh"] == mesh and float(r["ratio"]) == ratio and r["status"] == "ok"
                     and r["method"] == f"qemjax-{label}"), None)

    named = [(m, q) for m, q in cases if m in ("stanford-bunny", "armadillo")]
    head = ("| variant | rms <= best peer | Hausdorff <= best peer | slivers <= pymeshlab | above target | time / "
            + labels[0] + " (median) |" + "".join(f" time / {labels[0]}, {m} @ {q:g} |" for m, q in named))
    lines = ["## Summary", "", head, "|" + "---|" * (6 + len(named))]
    for label in labels:
        n = n_r = n_h = n_s = n_sc = above = 0
        times = []
        for mesh, ratio in cases:
            here = [r for r in rows if r["mesh"] == mesh and float(r["ratio"]) == ratio and r["status"] == "ok"]
            peers = [r for r in here if r["method"] in bench_peers.PEERS]
            o, b = row_of(mesh, ratio, label), row_of(mesh, ratio, labels[0])
            if o is None or not peers:
                continue
            n += 1
            n_r += float(o["rms_rel"]) <= min(float(r["rms_rel"]) for r in peers)
            n_h += float(o["hausdorff_rel"]) <= min(float(r["hausdorff_rel"]) for r in peers)
            above += int(o["faces_out"]) > int(o["target"])
            pml = next((r for r in peers if r["method"] == "pymeshlab" and r.get("slivers") not in (None, "")), None)
            if pml is not None and o.get("slivers") not in (None, ""):
                n_sc += 1
                n_s += float(o["slivers"]) <= float(pml["slivers"])
            if b is not None:
                times.append(float(o["time_s"]) / float(b["time_s"]))
        at = []
        for m, q in named:
            o, b = row_of(m, q, label), row_of(m, q, labels[0])
            at.append(f"{float(o['time_s']) / float(b['time_s']):.2f}" if o and b else "-")
        sl = f"{n_s}/{n_sc}" if n_sc else "-"
        lines.append(f"| {label} | {n_r}/{n} | {n_h}/{n} | {sl} | {above}/{n} | "
                     f"{np.median(times) if times else float('nan'):.2f} |"
                     + "".join(f" {x} |" for x in at))
    return "\n".join(lines) + "\n"


def ranks(rows: list[dict], labels: list[str]) -> str:
    """Per variant: per case rms and Hausdorff over the best peer's, and the counts."""
    out = []
    cases = sorted({(r["mesh"], float(r["ratio"])) for r in rows}, key=lambda c: (-c[1], c[0]))
    for label in labels:
        lines = [f"## {label}", "",
                 "| mesh | ratio | rms | best peer rms | rms ratio | Hausdorff | best peer Hausdorff | H ratio |",
                 "|---|---|---|---|---|---|---|---|"]
        n = n_rms = n_h = 0
        rr, hr = [], []
        by_ratio = {}  # ratio -> [cases, rms <= best, H <= best]
        for mesh, ratio in cases:
            here = [r for r in rows if r["mesh"] == mesh and float(r["ratio"]) == ratio and r["status"] == "ok"]
            own = [r for r in here if r["method"] == f"qemjax-{label}"]
            peers = [r for r in here if r["method"] in bench_peers.PEERS]
            if not own or not peers:
                continue
            o = own[0]
            best_r = min(peers, key=lambda r: float(r["rms_rel"]))
            best_h = min(peers, key=lambda r: float(r["hausdorff_rel"]))
            a = float(o["rms_rel"]) / float(best_r["rms_rel"])
            b = float(o["hausdorff_rel"]) / float(best_h["hausdorff_rel"])
            n, n_rms, n_h = n + 1, n_rms + (a <= 1), n_h + (b <= 1)
            c = by_ratio.setdefault(ratio, [0, 0, 0])
            c[0], c[1], c[2] = c[0] + 1, c[1] + (a <= 1), c[2] + (b <= 1)
            rr.append(a)
            hr.append(b)
            lines.append(f"| {mesh} | {ratio:g} | {float(o['rms_rel']):.3e} | {float(best_r['rms_rel']):.3e} "
                         f"({best_r['method']}) | {a:.3f} | {float(o['hausdorff_rel']):.3e} | "
                         f"{float(best_h['hausdorff_rel']):.3e} ({best_h['method']}) | {b:.3f} |")
        if n:
            lines += ["", f"{label}: rms <= best peer in {n_rms}/{n} cases; Hausdorff <= best peer in {n_h}/{n}; "
                      f"rms ratio median {np.median(rr):.3f}, max {max(rr):.3f}; "
                      f"Hausdorff ratio median {np.median(hr):.3f}, max {max(hr):.3f}", ""]
            lines += [f"{label} per ratio: " + "; ".join(f"{ratio:g}: rms {c[1]}/{c[0]}, Hausdorff {c[2]}/{c[0]}"
                                                        for ratio, c in sorted(by_ratio.items(), reverse=True)),
                      ""]
        out.append("\n".join(lines))
    if len(labels) > 1 and cases:
        out.append(summary(rows, cases, labels))
    if len(labels) > 1 and cases:  # each variant against the first, per case
        for label in labels[1:]:
            out.append(against_base(rows, cases, labels[0], label))
    return "\n".join(out)


def against_base(rows: list[dict], cases, base: str, label: str) -> str:
    """``label`` against ``base`` per case: rms and Hausdorff ratios, raw (each run as it stopped) and
    matched (where the two stopped at different face counts, the one that went further is replaced by its
    `matched_runs` row at the other's face count; a CSV without such rows gives matched == raw)."""
    ch = []  # (raw rms ratio, mesh, ratio, raw H ratio, matched rms ratio, matched H ratio, faces note)
    for mesh, ratio in cases:
        here = [r for r in rows if r["mesh"] == mesh and float(r["ratio"]) == ratio]
        ok = {r["method"]: r for r in here if r["status"] == "ok"}
        v, b = ok.get(f"qemjax-{label}"), ok.get(f"qemjax-{base}")
        if v is None or b is None:
            continue
        mv = next((r for r in here if r["method"] == f"qemjax-{label}"
                   and r["status"] == f"matched to qemjax-{base}"), v)
        mb = next((r for r in here if r["method"] == f"qemjax-{base}"
                   and r["status"] == f"matched to qemjax-{label}"), b)
        note = "" if mv is v and mb is b else (f"{label} {v['faces_out']} -> {mv['faces_out']} faces, "
                                                f"{base} {b['faces_out']} -> {mb['faces_out']}")
        ch.append((_ratio(v, b, "rms_rel"), mesh, ratio, _ratio(v, b, "hausdorff_rel"),
                   _ratio(mv, mb, "rms_rel"), _ratio(mv, mb, "hausdorff_rel"), note))
    if not ch:
        return ""
    worst = max(ch)
    lines = [f"{label} rms / {base} rms: median {np.median([c[0] for c in ch]):.3f}, "
             f"worst {worst[0]:.3f} ({worst[1]} @ {worst[2]:g}); "
             f"{sum(c[0] > 1.03 for c in ch)} of {len(ch)} cases more than 3 % worse\n"]
    h_worse = [c for c in ch if c[3] > 1.03]
    lines.append(f"{label} Hausdorff / {base} Hausdorff: median {np.median([c[3] for c in ch]):.3f}; "
                 f"{len(h_worse)} of {len(ch)} cases more than 3 % worse"
                 + "".join(f"; at {ratio:g}: {sum(c[2] == ratio for c in h_worse)}"
                           for ratio in sorted({c[2] for c in ch}, reverse=True))
                 + "; rms more than 3 % worse: "
                 + (", ".join(f"{c[1]} @ {c[2]:g}" for c in ch if c[0] > 1.03) or "none") + "\n")
    matched = [c for c in ch if c[6]]
    lines.append(f"{label} / {base} at equal face counts (matched; {len(matched)} cases re-run where the two "
                 f"stopped at different face counts):")
    lines += [f"- {c[1]} @ {c[2]:g}: {c[6]}; rms ratio raw {c[0]:.3f}, matched {c[4]:.3f}; "
              f"Hausdorff ratio raw {c[3]:.3f}, matched {c[5]:.3f}" for c in matched]
    lines.append(f"{label} rms / {base} rms, more than 3 % worse: raw {sum(c[0] > 1.03 for c in ch)} of "
                 f"{len(ch)} (" + (", ".join(f"{c[1]} @ {c[2]:g}" for c in ch if c[0] > 1.03) or "none")
                 + f"); matched {sum(c[4] > 1.03 for c in ch)} of {len(ch)} ("
                 + (", ".join(f"{c[1]} @ {c[2]:g} {c[4]:.3f}" for c in ch if c[4] > 1.03) or "none") + ")"
                 + f"; matched rms ratio median {np.median([c[4] for c in ch]):.3f}, worst "
                 + "{0[4]:.3f} ({0[1]} @ {0[2]:g})".format(max(ch, key=lambda c: c[4])))
    lines.append(f"{label} Hausdorff / {base} Hausdorff, more than 3 % worse: raw {len(h_worse)} of {len(ch)}; "
                 f"matched {sum(c[5] > 1.03 for c in ch)} of {len(ch)}\n")
    return "\n".join(lines)


def _ratio(a: dict, b: dict, key: str) -> float:
    return float(a[key]) / float(b[key])


WARM = False  # --warm: time a second call (the first compiles what the case needs)


def run_variant(run, label: str, mesh, ratio: float, target: int, status: str = "ok") -> dict:
    """One qemjax variant on one case: its CSV row (faces, distances, time; warm with ``--warm``)."""
    if WARM:
        run(mesh.V, mesh.F, target)
    t0 = time.perf_counter()
    res = run(mesh.V, mesh.F, target)
    secs = time.perf_counter() - t0
    V2, F2 = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
    return dict(mesh=mesh.name, faces_in=mesh.n_faces, ratio=ratio, target=target, method=f"qemjax-{label}",
                faces_out=len(F2), time_s=secs, status=status,
                branches=" ".join(f"{k}={v}" for k, v in res.stats["branches"].items()),
                **distances(mesh.V, mesh.F, V2, F2))


def matched_runs(runners: dict, own: dict, mesh, ratio: float) -> list[dict]:
    """Where a variant and the first (base) one stop at different face counts (the target could not be
    reached), the one that went further (fewer faces, so a larger error for the same model) runs again
    with the other's face count as its target. Comparing the two at unequal face counts would charge the
    further one for faces the other kept. The new row's status is ``matched to qemjax-OTHER``; the
    tables (`ranks`) use only ``ok`` rows, except the "variant / base" comparison, which reports both."""
    labels = list(runners)
    out = []
    for label in labels[1:]:
        pair = (labels[0], label)
        a, b = (own[x] for x in pair)
        if a["faces_out"] == b["faces_out"]:
            continue
        further, other = pair if a["faces_out"] < b["faces_out"] else pair[::-1]
        out.append(run_variant(runners[further], further, mesh, ratio, own[other]["faces_out"],
                               status=f"matched to qemjax-{other}"))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", default=None,
                    help="LABEL or LABEL:rev=REV or LABEL:key=value,... (repeatable; default: 'qemjax')")
    ap.add_argument("--meshes", nargs="+", default=None, help="shared mesh names (default: all)")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--reuse-peers", nargs="?", const="", default=None, metavar="CSV",
                    help="peers' rows from this CSV (default: the --out one) instead of running them")
    ap.add_argument("--out", default=str(RESULTS / "rank_peers"), help="path without extension")
    ap.add_argument("--summarize", default=None, metavar="CSV",
                    help="only print the tables of an earlier run's CSV (its qemjax variants, in order; the "
                         "first is the one the others are compared with); runs and writes nothing")
    ap.add_argument("--warm", action="store_true",
                    help="time each qemjax run warm (one untimed call first; peers have nothing to compile)")
    args = ap.parse_args(argv)
    global WARM
    WARM = args.warm
    if args.summarize:
        with open(args.summarize) as fh:
            old = list(csv.DictReader(fh))
        labels = list(dict.fromkeys(r["method"][len("qemjax-"):] for r in old if r["method"].startswith("qemjax-")))
        print(ranks(old, labels))
        return 0
    import warnings

    warnings.simplefilter("ignore")
    variants = [parse_variant(s) for s in (args.variant or ["qemjax"])]
    runners = {label: variant_runner(label, rev, settings) for label, rev, settings in variants}
    names = args.meshes or list(bench_meshes.shared_files())
    if not names:
        raise SystemExit("no shared meshes (../shared/meshes is absent)")
    old_peers = {}
    if args.reuse_peers is not None:
        with open(args.reuse_peers or args.out + ".csv") as fh:
            for r in csv.DictReader(fh):
                if r["method"] in bench_peers.PEERS:
                    old_peers[(r["mesh"], float(r["ratio"]), r["method"])] = r
    rows = []
    for name in names:
        mesh = bench_meshes.load(name)
        for ratio in args.ratios:
            target = max(4, int(round(ratio * mesh.n_faces)))
            cached = [old_peers.get((name, ratio, p)) for p in bench_peers.PEERS]
            rows += cached if all(cached) else run_peers(mesh, ratio, target)
            own = {label: run_variant(run, label, mesh, ratio, target) for label, run in runners.items()}
            rows += own.values()
            rows += matched_runs(runners, own, mesh, ratio)
            print(f"{name} @ {ratio:g}: " + ", ".join(
                f"{r['method']} {float(r['rms_rel']):.3e}/{float(r['hausdorff_rel']):.3e}"
                for r in rows if r["mesh"] == name and float(r["ratio"]) == ratio and r["status"] == "ok")
                + "".join(f"; {r['method']} {r['status']} at {r['faces_out']} faces "
                          f"{float(r['rms_rel']):.3e}/{float(r['hausdorff_rel']):.3e}"
                          for r in rows if r["mesh"] == name and float(r["ratio"]) == ratio
                          and r["status"].startswith("matched")), flush=True)
    table = ranks(rows, [v[0] for v in variants])
    print(table)
    save_run(args.out, rows, COLUMNS, table, "figures/rank_peers.py", argv)
    return 0


def save_run(out: str, rows: list[dict], fields, text: str, script: str, argv) -> None:
    """``out``.csv (the rows, in ``fields``) and ``out``.txt (the printed ``text`` under the command line
    of ``experiments/script`` and the date)."""
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with open(out + ".csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fields, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    cmd = f"python experiments/{script} " + " ".join(sys.argv[1:] if argv is None else argv)
    Path(out + ".txt").write_text(f"# {cmd}\n# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}\n\n"
                                  + text + "\n")


if __name__ == "__main__":
    sys.exit(main())
