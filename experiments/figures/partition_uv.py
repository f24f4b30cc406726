"""UVs in partitioned runs against the in-core run: a bumpy sphere made in code (`qemjax.shapes.bumpy_sphere`)
with a longitude/latitude map (one seam along a meridian, `attribute_files.spherical_uv`), written as an OBJ
with ``vt``, simplified to ``--ratio`` with ``attributes="uv"`` in core and partitioned (``--workers`` local
processes), and the same without UVs for the cost of keeping them. For each run: seconds (in this process;
the workers warm from an untimed partitioned run first), two-way rms and Hausdorff distance from the input
(`qemjax.metrics.surface_distance`, 200,000 samples each way, relative to the diagonal), the UVs' deviation
from the map at each output wedge's vertex (median, 95th percentile, max), the vertices with several UVs
and how many of them are off the input's seam (a UV seam the cuts would have made), the faces whose
corners' u spans more than half the map (faces across the seam: at the poles only, in the input too).

    python experiments/figures/partition_uv.py --subdivisions 8 --ratio 0.01 --out experiments/results/partition_uv.txt
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from machine import cpu_model  # noqa: E402

import qemjax  # noqa: E402
from qemjax._io import attribute_files as af  # noqa: E402
from qemjax.metrics import surface_distance  # noqa: E402


def spherical(P: np.ndarray) -> np.ndarray:
    d = P / np.linalg.norm(P, axis=1, keepdims=True)
    return np.stack([(np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)) % 1.0, np.arccos(np.clip(d[:, 2], -1, 1)) / np.pi], 1)


def uv_row(res) -> str:
    if res.uv is None:
        return "| — | — | — | — | — | — |"
    e = np.abs(res.uv - spherical(res.vertices[res.wedge_vertex]))
    e[:, 0] = np.minimum(e[:, 0], np.abs(e[:, 0] - 1))
    e = np.hypot(e[:, 0], e[:, 1])
    several = np.flatnonzero(np.bincount(res.wedge_vertex, minlength=len(res.vertices)) > 1)
    off_seam = sum(np.ptp(res.uv[res.wedge_vertex == v, 0]) < 0.9 for v in several)
    across = int(np.sum(np.ptp(res.uv[res.wedge_faces][:, :, 0], axis=1) > 0.5))
    return (f"| {np.median(e):.2e} | {np.percentile(e, 95):.2e} | {e.max():.2e} | {len(several)} | {off_seam} "
            f"| {across} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subdivisions", type=int, default=8)
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--part-faces", type=int, default=100_000)
    ap.add_argument("--out", default=None, help="also write the table here")
    args = ap.parse_args()
    m = qemjax.shapes.bumpy_sphere(args.subdivisions)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    uv, corner = af.spherical_uv(m)
    lines = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "sphere.obj"
        af.write_obj(path, m, uv=uv, corner_uv=corner)
        part = qemjax.Partition(workers=args.workers, part_faces=args.part_faces)
        qemjax.simplify(str(path), ratio=args.ratio, attributes="uv", partition=part)  # untimed: warm workers
        runs = {}
        for name, kw in [("in core, UVs", dict(attributes="uv")), ("partitioned, UVs", dict(attributes="uv", partition=part)),
                         ("in core, positions", dict(attributes=None)),
                         ("partitioned, positions", dict(attributes=None, partition=part))]:
            t = time.perf_counter()
            res = qemjax.simplify(str(path), ratio=args.ratio, **kw)
            runs[name] = (res, time.perf_counter() - t)
    say(f"# python experiments/figures/partition_uv.py --subdivisions {args.subdivisions} --ratio {args.ratio} "
        f"--workers {args.workers} --part-faces {args.part_faces}")
    say(f"# bumpy sphere, {len(F)} faces, {len(uv)} UVs -> {args.ratio:g}; {cpu_model()}")
    say("")
    say("| run | faces | seconds | rms (rel) | Hausdorff (rel) | UV dev. median | p95 | max | vertices with several UVs "
        "| of them off the seam | faces across the seam |")
    say("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, (res, dt) in runs.items():
        d = surface_distance((V, F), (res.vertices, res.faces), n_samples=200_000)
        say(f"| {name} | {len(res.faces)} | {dt:.1f} | {d['rms_rel']:.3e} | {d['hausdorff_rel']:.3e} " + uv_row(res))
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
