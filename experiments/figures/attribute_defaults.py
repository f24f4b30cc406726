"""Which appearance attributes `simplify` keeps by default, and with what weight (issue 30).

The rule the defaults keep: keeping an attribute kind by default costs at most 10 % geometric rms and 1.5×
warm time against ``attributes=None``, on every case below. For each kind (UV, colour, normal) and each
weight on a grid, every case that carries the kind is simplified at each ratio with that kind alone at that
weight, and against positions only; rms is two-way (`qemjax.metrics.surface_distance`, relative to the
diagonal), time the median of warm runs, both ratios to ``attributes=None`` in the same process. A kind's
default weight is the largest weight on the grid that keeps the rule on every case; a kind with none is not
kept by default.

Cases: generated in code (a bumpy sphere with smooth unit normals, with the same normals scaled by random
lengths 0.05-13, with MeshLab-style area-sum normals; a bumpy cube with normals split into wedges at hard
creases; a bumpy sphere with smooth vertex colours; a bumpy sphere with a longitude/latitude UV map and
one seam), and the shared meshes that carry attributes when ../shared/meshes is there (beetle and suzanne
store normals, spot UVs; stanford-bunny written with unit normals scaled by random lengths).

    python experiments/figures/attribute_defaults.py                 # results/attribute_defaults.csv and .md
    python experiments/figures/attribute_defaults.py --quick         # fewer weights and repeats
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import qemjax  # noqa: E402
from qemjax._io import attribute_files as af  # noqa: E402
from qemjax import metrics, shapes  # noqa: E402

SHARED = ROOT.parent / "shared" / "meshes"
OUT = ROOT / "experiments" / "results"
RATIOS = (0.1, 0.02)
WEIGHTS = (0.0, 0.0003, 0.001, 0.003, 0.01, 0.03)
RMS_LIMIT, TIME_LIMIT = 1.10, 1.5


def bumpy_cube(subdivisions: int = 5):
    """A cube with small smooth bumps on its faces: sharp creases along its edges, detail to simplify."""
    V, F = shapes.cube(subdivisions)
    V = V - 0.5
    bump = 0.02 * np.sin(9 * V[:, 0]) * np.sin(7 * V[:, 1]) * np.sin(8 * V[:, 2])
    n = np.where(np.abs(V) >= 0.5 - 1e-9, np.sign(V), 0.0)  # push along the face normal(s) the vertex is on
    inner = np.abs(V).max(1) >= 0.5 - 1e-9
    on_one = (np.count_nonzero(n, axis=1) == 1) & inner
    V = V + np.where(on_one[:, None], n * bump[:, None], 0.0)
    return qemjax.Mesh(V, F)


def cases(folder: Path, shared: bool):
    """[(name, path, kind)]: files written in ``folder``."""
    out = []
    sphere = shapes.bumpy_sphere(5)
    p = folder / "normals-unit.ply"
    af.write_ply(p, sphere, normals=af.vertex_normals(sphere))
    out.append(("sphere, unit normals", p, "normal"))
    p = folder / "normals-scaled.ply"
    af.write_ply(p, sphere, normals=af.scaled_normals(sphere))
    out.append(("sphere, normals x random lengths", p, "normal"))
    p = folder / "normals-areasum.ply"
    af.write_ply(p, sphere, normals=af.area_sum_normals(sphere))
    out.append(("sphere, area-sum normals (VCG)", p, "normal"))
    cube = bumpy_cube()
    p = folder / "normals-creased.obj"
    af.write_obj(p, cube, corner_normals=af.crease_normals(cube))
    out.append(("bumpy cube, creased normals (wedges)", p, "normal"))
    p = folder / "colors.ply"
    af.write_ply(p, sphere, colors=af.smooth_colors(sphere))
    out.append(("sphere, smooth colours", p, "color"))
    p = folder / "uv.obj"
    uv, cuv = af.spherical_uv(sphere)
    af.write_obj(p, sphere, uv=uv, corner_uv=cuv)
    out.append(("sphere, UV map with one seam", p, "uv"))
    if shared:
        out += [("beetle (stored normals)", SHARED / "beetle.obj", "normal"),
                ("suzanne (stored normals)", SHARED / "suzanne.obj", "normal"),
                ("spot (UVs, 13 charts)", SHARED / "spot" / "spot.obj", "uv")]
        bunny = qemjax.load(SHARED / "stanford-bunny.obj")
        p = folder / "bunny-normals-scaled.ply"
        af.write_ply(p, bunny, normals=af.scaled_normals(bunny))
        out.append(("stanford-bunny, normals x random lengths", p, "normal"))
    return out


def timed(path, ratio, repeats, **kw):
    """(result, median warm seconds)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = qemjax.simplify(path, ratio=ratio, **kw)  # warm: compile
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            res = qemjax.simplify(path, ratio=ratio, **kw)
            ts.append(time.perf_counter() - t)
    return res, statistics.median(ts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="weights 0, 0.001, 0.003, 0.01; one timed run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--samples", type=int, default=30000)
    ap.add_argument("--no-shared", action="store_true")
    ap.add_argument("--default-only", action="store_true", help="only the default against attributes=None")
    args = ap.parse_args(argv)
    weights = () if args.default_only else (0.0, 0.001, 0.003, 0.01) if args.quick else WEIGHTS
    repeats = 1 if args.quick else args.repeats
    import pandas as pd

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, kind in cases(Path(tmp), SHARED.is_dir() and not args.no_shared):
            orig = qemjax.load(path)
            for ratio in RATIOS:
                base, t0 = timed(path, ratio, repeats, attributes=None)
                r0 = metrics.surface_distance(orig, base, n_samples=args.samples)["rms_rel"]
                for w in ("default",) + tuple(weights):
                    kw = dict(attributes="auto") if w == "default" else dict(attributes=kind,
                                                                              attribute_weights={kind: w})
                    res, t = timed(path, ratio, repeats, **kw)
                    r = metrics.surface_distance(orig, res, n_samples=args.samples)["rms_rel"]
                    rows.append(dict(case=name, kind=kind, ratio=ratio, weight=w, faces=len(res.faces),
                                     faces_none=len(base.faces), rms_rel=r, rms_none=r0, rms_ratio=r / r0,
                                     time_s=t, time_none_s=t0, time_ratio=t / t0,
                                     seam_vertices=res.stats.get("seam_vertices_in", 0),
                                     kept=",".join(res.stats.get("attributes", [])) or "-",
                                     stop=res.stop_reason))
                    print(f"{name:42s} {ratio:5} w={w:<6} rms x{r / r0:6.3f} time x{t / t0:5.2f} "
                          f"({t:.3f} s / {t0:.3f} s) faces {len(res.faces)}/{len(base.faces)} {res.stop_reason}",
                          flush=True)
    df = pd.DataFrame(rows)
    OUT.mkdir(parents=True, exist_ok=True)
    stem = "attribute_defaults" + ("_default" if args.default_only else "")
    df.to_csv(OUT / f"{stem}.csv", index=False)
    ok = df.assign(ok=(df.rms_ratio <= RMS_LIMIT) & (df.time_ratio <= TIME_LIMIT)
                   & (df.faces <= df.faces_none))
    seams = ok.groupby("case").seam_vertices.max()
    ok["seams"] = ok.case.map(seams) > 0
    lines = ["# Attribute defaults (`python experiments/figures/attribute_defaults.py`)", "",
             f"Rule: rms <= {RMS_LIMIT}x and warm time <= {TIME_LIMIT}x attributes=None, every case, ratios "
             f"{RATIOS}, and the face target met as without attributes. rms: two-way, relative to the "
             "diagonal; time: median of warm runs, file reading included (the same file for both).", "",
             "## The default (attributes='auto', default weights) against attributes=None", "",
             "| case | kind | seam vertices | kept by default | ratio | rms ratio | time ratio | keeps the rule |",
             "|---|---|---|---|---|---|---|---|"]
    for _, r in ok[ok.weight == "default"].iterrows():
        lines.append(f"| {r.case} | {r.kind} | {int(seams[r.case])} | {r.kept} | {r.ratio} | {r.rms_ratio:.3f} "
                     f"| {r.time_ratio:.2f} | {'yes' if r.ok else 'no'} |")
    w = ok[ok.weight != "default"]
    lines += ["", "## Each kind at each weight (asked for explicitly), worst case", "",
              "| kind | seams | weight | cases | worst rms ratio | worst time ratio | keeps the rule |",
              "|---|---|---|---|---|---|---|"]
    for (kind, seamed, wt), g in w.groupby(["kind", "seams", "weight"]):
        lines.append(f"| {kind} | {'yes' if seamed else 'no'} | {wt} | {g.case.nunique()} | {g.rms_ratio.max():.3f} "
                     f"| {g.time_ratio.max():.2f} | {'yes' if g.ok.all() else 'no'} |")
    lines += ["", "## Per case (worst over ratios)", "",
              "| case | kind | weight | rms ratio | time ratio | seam vertices |", "|---|---|---|---|---|---|"]
    for (case, kind, wt), g in ok.groupby(["case", "kind", "weight"], sort=False):
        lines.append(f"| {case} | {kind} | {wt} | {g.rms_ratio.max():.3f} | {g.time_ratio.max():.2f} "
                     f"| {int(g.seam_vertices.max())} |")
    chosen = {}  # the largest weight that keeps the rule with every smaller weight (noise cannot pick it)
    for kind, g in w[~w.seams].groupby("kind"):
        chosen[kind] = None
        for wt, gw in sorted(g.groupby("weight"), key=lambda x: x[0]):
            if not gw.ok.all():
                break
            chosen[kind] = wt
    seamed_ok = {kind: [wt for wt, gw in g.groupby("weight") if gw.ok.all()] for kind, g in w[w.seams].groupby("kind")}
    lines += ["", "Largest weight keeping the rule on every seamless case, with every smaller weight: "
              + ", ".join(f"{k}: {'none' if v is None else v}" for k, v in chosen.items()),
              "Weights keeping the rule on every case with seams: "
              + ", ".join(f"{k}: {v or 'none'}" for k, v in seamed_ok.items())]
    (OUT / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
