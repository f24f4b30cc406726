"""Appearance attributes (issue 21) on spot: qemjax with UVs (attribute quadrics; and weight 0: positions-only
cost, UVs interpolated), qemjax without attributes, pymeshlab's quadric collapse with texture and
meshoptimizer's simplifyWithAttributes, at 10 % and 2 %: geometric rms / Hausdorff (qemjax.metrics), UV
deviation (texture space, `metrics.attribute_deviation`), seam integrity (`metrics.uv_chart_integrity`:
faces whose UVs leave their input chart), time. Then spot's texture baked to vertex colours: the colour
error with and without the colour term. Pictures: textured renders (each face coloured by the texture at
its UV centroid).

    python experiments/figures/appearance.py            # results/appearance.csv, appearance.md, appearance_*.png
"""
from __future__ import annotations

import argparse
import ctypes
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import qemjax  # noqa: E402
from qemjax import metrics, render  # noqa: E402

SPOT = ROOT.parent / "shared" / "meshes" / "spot"
OUT = ROOT / "experiments" / "results"
RATIOS = (0.1, 0.02)


def textured(V, F, uv, image):
    return trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(
        uv=uv, material=trimesh.visual.material.SimpleMaterial(image=image)))


def run_qemjax(path, target, image, **kw):
    qemjax.simplify(path, target_faces=target, texture=image, **kw)  # warm: compile once
    t = time.perf_counter()
    r = qemjax.simplify(path, target_faces=target, texture=image, **kw)
    dt = time.perf_counter() - t
    return (r.to_trimesh() if r.uv is not None else trimesh.Trimesh(r.vertices, r.faces, process=False)), dt, r


def run_pymeshlab(path, target, image, **kw):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    t = time.perf_counter()
    ms.meshing_decimation_quadric_edge_collapse_with_texture(targetfacenum=target, **kw)
    dt = time.perf_counter() - t
    m = ms.current_mesh()
    V, F, W = m.vertex_matrix(), m.face_matrix(), m.wedge_tex_coord_matrix()
    # per-corner UVs: split every corner, then merge corners with equal position and UV
    P = V[F].reshape(-1, 3)
    key = np.c_[P, W]
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return textured(uniq[:, :3], inv.reshape(-1, 3), uniq[:, 3:], image), dt, None


def run_meshopt(orig, target, image, weight=1.0):
    from meshoptimizer.simplifier import lib

    V = np.ascontiguousarray(orig.vertices, np.float32)
    uv = np.ascontiguousarray(orig.visual.uv, np.float32)
    index = np.ascontiguousarray(orig.faces.reshape(-1), np.uint32)
    dest = np.zeros_like(index)
    w = np.array([weight, weight], np.float32)
    f = lib.meshopt_simplifyWithAttributes  # the binding's wrapper passes a Python float without argtypes
    f.restype = ctypes.c_size_t
    P = lambda a, t: a.ctypes.data_as(ctypes.POINTER(t))  # noqa: E731
    t = time.perf_counter()
    n = f(P(dest, ctypes.c_uint), P(index, ctypes.c_uint), ctypes.c_size_t(len(index)), P(V, ctypes.c_float),
          ctypes.c_size_t(len(V)), ctypes.c_size_t(12), P(uv, ctypes.c_float), ctypes.c_size_t(8),
          P(w, ctypes.c_float), ctypes.c_size_t(2), ctypes.POINTER(ctypes.c_ubyte)(), ctypes.c_size_t(3 * target),
          ctypes.c_float(1.0), ctypes.c_uint(0), ctypes.POINTER(ctypes.c_float)())
    dt = time.perf_counter() - t
    F = dest[:n].reshape(-1, 3).astype(np.int64)
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return textured(orig.vertices[used], remap[F], orig.visual.uv[used], image), dt, None


def row(name, ratio, orig, out, dt, res=None):
    d = metrics.surface_distance(orig, out)
    r = {"method": name, "ratio": ratio, "faces": len(out.faces), "rms_rel": d["rms_rel"],
         "hausdorff_rel": d["hausdorff_rel"], "time_s": dt}
    if getattr(out.visual, "kind", None) == "texture":
        r.update(metrics.attribute_deviation(orig, out))
        r.update(metrics.uv_chart_integrity(orig, out))
    if res is not None and res.uv is not None:
        r["qemjax_mixed_charts"] = metrics.seam_report(res)["mixed_charts"]
    return r


def uv_table(rows):
    cols = ["method", "ratio", "faces", "rms_rel", "hausdorff_rel", "uv_dev_rms", "uv_dev_mean", "uv_dev_p95",
            "faces_spanning", "charts_out", "time_s"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c, "")
            cells.append(f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def baked_colours(orig, image):
    """spot with its texture sampled at every UV, averaged per position: a vertex-coloured mesh (no seams)."""
    tex = np.asarray(image.convert("RGB"), np.float64) / 255.0
    h, w = tex.shape[:2]
    uv = orig.visual.uv
    x = np.clip((uv[:, 0] % 1) * w, 0, w - 1).astype(int)
    y = np.clip((1 - uv[:, 1] % 1) * h, 0, h - 1).astype(int)
    col = tex[y, x]
    Vw, inv = np.unique(orig.vertices, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    acc = np.zeros((len(Vw), 3))
    np.add.at(acc, inv, col)
    acc /= np.bincount(inv)[:, None]
    rgba = np.c_[np.round(acc * 255), np.full(len(Vw), 255)].astype(np.uint8)
    return trimesh.Trimesh(Vw, inv[orig.faces], vertex_colors=rgba, process=False)


def main(argv=None):
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    path = SPOT / "spot.obj"
    image = Image.open(SPOT / "spot_texture.png")
    image.load()
    orig = textured(*(lambda m: (m.vertices, m.faces, m.visual.uv))(trimesh.load(path, process=False, force="mesh")),
                    image)
    m = len(orig.faces)
    rows, shown = [], {}
    warnings.simplefilter("ignore")
    for ratio in RATIOS:
        target = int(round(ratio * m))
        runs = [("qemjax uv (default w=0.03)", lambda: run_qemjax(path, target, image)),
                ("qemjax uv (w=1)", lambda: run_qemjax(path, target, image, attribute_weights=1.0)),
                ("qemjax uv (w=0, interpolated)", lambda: run_qemjax(path, target, image, attribute_weights=0)),
                ("qemjax no attributes", lambda: run_qemjax(path, target, None, attributes=None)),
                ("pymeshlab with texture", lambda: run_pymeshlab(path, target, image)),
                ("pymeshlab with texture, preserveboundary",
                 lambda: run_pymeshlab(path, target, image, preserveboundary=True)),
                ("meshoptimizer with attributes", lambda: run_meshopt(orig, target, image))]
        for name, fn in runs:
            out, dt, res = fn()
            rows.append(row(name, ratio, orig, out, dt, res))
            print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
            shown[(name, ratio)] = out
    # the UV weight at 10 %: UV deviation against geometric error
    target = int(round(0.1 * m))
    for w in (0.1, 0.3, 3.0):
        out, dt, res = run_qemjax(path, target, image, attribute_weights=w)
        rows.append(row(f"qemjax uv (w={w:g})", 0.1, orig, out, dt, res))
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    import csv

    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    with open(OUT / "appearance.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, keys)
        wr.writeheader()
        wr.writerows(rows)

    # vertex colours: spot's texture baked; the colour term against positions-only costs
    cmesh = baked_colours(orig, image)
    crow = []
    for ratio in RATIOS:
        for w in (0.0, 0.03, 0.1, 0.3, 1.0):
            t = time.perf_counter()
            r = qemjax.simplify(cmesh, ratio=ratio, attribute_weights=w)
            dt = time.perf_counter() - t
            d = metrics.surface_distance(cmesh, r)
            dev = metrics.attribute_deviation(cmesh, r, kind="color")
            crow.append({"ratio": ratio, "colour_weight": w, "faces": len(r.faces), "rms_rel": d["rms_rel"],
                         "hausdorff_rel": d["hausdorff_rel"], **dev, "time_s": dt})
            print(crow[-1], flush=True)
            shown[("colour", ratio, w)] = r
    with open(OUT / "appearance_colors.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, list(crow[0]))
        wr.writeheader()
        wr.writerows(crow)
    ctab = ["| ratio | colour weight | faces | rms_rel | hausdorff_rel | color_dev_rms | color_dev_mean | color_dev_p95 |",
            "|---|---|---|---|---|---|---|---|"]
    for r in crow:
        ctab.append(f"| {r['ratio']} | {r['colour_weight']} | {r['faces']} | {r['rms_rel']:.4g} | "
                    f"{r['hausdorff_rel']:.4g} | {r['color_dev_rms']:.4g} | {r['color_dev_mean']:.4g} | "
                    f"{r['color_dev_p95']:.4g} |")
    (OUT / "appearance.md").write_text(
        "# Appearance attributes on spot (experiments/figures/appearance.py)\n\n"
        "UV deviation: texture units (the texture is the unit square; 0.001 ≈ 1 texel of 1024), seam-tolerant "
        "(`metrics.attribute_deviation`); faces_spanning: output faces whose corner/centroid UVs share no input "
        "chart (`metrics.uv_chart_integrity`); qemjax times are warm (second call).\n\n"
        + uv_table(rows) + "\n\n## Vertex colours (texture baked to colours)\n\n" + "\n".join(ctab) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("input", orig)] + [(f"{n}\n{r:g}", shown[(n, r)]) for r in RATIOS
                                  for n in ("qemjax uv (default w=0.03)", "pymeshlab with texture", "meshoptimizer with attributes")]
    fig = plt.figure(figsize=(4 * 4, 8), dpi=110)
    for i, (title, mesh) in enumerate(panels):
        ax = fig.add_subplot(2, 4, i + 1, projection="3d")
        render.render(mesh, ax, color=render.face_texture_colors(mesh, image), view=(15, 30),
                      title=f"{title} ({len(mesh.faces)} faces)")
    fig.tight_layout()
    fig.savefig(OUT / "appearance_spot.png", bbox_inches="tight")
    plt.close(fig)
    fig = plt.figure(figsize=(16, 4), dpi=110)
    for i, (title, mesh) in enumerate([("baked colours", cmesh), ("10 %, colour weight 0", shown[("colour", 0.1, 0.0)]),
                                       ("10 %, colour weight 0.03 (default)", shown[("colour", 0.1, 0.03)]),
                                       ("10 %, colour weight 0.3", shown[("colour", 0.1, 0.3)])]):
        ax = fig.add_subplot(1, 4, i + 1, projection="3d")
        if hasattr(mesh, "wedge_faces"):
            fc = mesh.colors[mesh.wedge_faces].mean(1)[:, :3]
        else:
            fc = (np.asarray(mesh.visual.vertex_colors, float)[mesh.faces].mean(1) / 255)[:, :3]
        render.render(mesh, ax, color=fc, view=(15, 30), title=f"{title} ({len(mesh.faces)} faces)")
    fig.tight_layout()
    fig.savefig(OUT / "appearance_colors.png", bbox_inches="tight")
    plt.close(fig)
    print((OUT / "appearance.md").read_text())


if __name__ == "__main__":
    main()
