"""Command line: ``qemjax simplify IN OUT (--ratio R | --faces N | --max-error E)`` and ``qemjax demo``."""
from __future__ import annotations

import argparse
import sys

from . import _api


def _add_options(p: argparse.ArgumentParser):
    p.add_argument("--scheduler", choices=_api.SCHEDULERS, default="parallel")
    p.add_argument("--placement", choices=_api.PLACEMENTS, default="optimal")
    p.add_argument("--boundary-weight", type=float, default=_api.BOUNDARY_WEIGHT)
    p.add_argument("--no-weld", action="store_true", help="do not merge coincident vertices first")
    p.add_argument("--no-preserve-topology", action="store_true", help="allow non-manifold contractions")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _summary(name: str, res) -> str:
    s = res.stats
    return (f"{name}: faces {s['faces_in']} -> {s['faces_out']} (target {s['target_faces']}), "
            f"{s['total_s']:.2f} s (compile {s['compile_s']:.2f} s, run {s['run_s']:.2f} s), "
            f"{s['rounds']} rounds, max error {res.max_error:.3g} (squared distance, mesh units)")


def _run(mesh, args, **target):
    return _api.simplify(
        mesh, scheduler=args.scheduler, placement=args.placement, boundary_weight=args.boundary_weight,
        weld=not args.no_weld, preserve_topology=not args.no_preserve_topology,
        progress=not args.quiet, **target)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="qemjax", description="Quadric-error mesh simplification with JAX.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("simplify", help="simplify a mesh file")
    s.add_argument("input")
    s.add_argument("output", help="any format trimesh writes (.obj, .ply, .stl, .off, .glb)")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--ratio", type=float, help="keep this fraction of the faces")
    g.add_argument("--faces", type=int, help="target face count")
    g.add_argument("--max-error", type=float, help="max quadric error (squared distance, mesh units)")
    _add_options(s)
    d = sub.add_parser("demo", help="simplify a mesh generated in code (no file needed)")
    d.add_argument("--output", default="qemjax-demo.obj")
    d.add_argument("--subdivisions", type=int, default=7, help="7: 327,680 faces; 6: 81,920")
    d.add_argument("--ratio", type=float, default=0.02)
    _add_options(d)
    args = ap.parse_args(argv)

    try:
        if args.cmd == "simplify":
            target = {"ratio": args.ratio, "target_faces": args.faces, "max_error": args.max_error}
            res = _run(args.input, args, **{k: v for k, v in target.items() if v is not None})
            out, name = args.output, args.input
        else:
            from .shapes import bumpy_sphere

            mesh = bumpy_sphere(args.subdivisions)
            res = _run(mesh, args, ratio=args.ratio)
            out, name = args.output, f"bumpy sphere ({len(mesh.faces)} faces)"
        res.to_trimesh().export(out)
    except ValueError as exc:
        print(f"qemjax: error: {exc}", file=sys.stderr)
        return 2
    print(_summary(name, res) + f" -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
