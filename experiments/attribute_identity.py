"""Bit-identity guard for the attribute path (wedges, seam rule, attribute quadrics), which the golden cases
(all ``attributes=None``) do not cover: hashes of textured / normal-carrying runs, this checkout against the
package at a git revision (loaded as ``qemjax_old``, `ab_compare.load_old`), in one process.

    python experiments/attribute_identity.py --rev 4e3085d          # OK / DIFF per case; exit 1 on any DIFF
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]
MESHES = HERE.parent.parent / "shared" / "meshes"


def cases(tmp: Path, qemjax) -> list:
    """(id, mesh path, keywords) of the attribute runs compared."""
    ex = {p.name: str(p) for p in qemjax.shapes.write_examples(tmp, subdivisions=3)}
    tex = ex["textured.obj"]
    lk = np.arange(0, len(qemjax.load(tex).vertices), 23)
    out = [
        ("textured/parallel/0.2", tex, dict(ratio=0.2, attributes="uv")),
        ("textured/greedy/0.2", tex, dict(ratio=0.2, attributes="uv", scheduler="greedy")),
        ("textured/weight0/0.1", tex, dict(ratio=0.1, attributes="uv", attribute_weights=0)),
        ("textured/weight3/0.05", tex, dict(ratio=0.05, attributes="uv", attribute_weights=3.0)),
        ("textured/locks/parallel/0.3", tex, dict(ratio=0.3, attributes="uv", locked=lk)),
        ("textured/locks/greedy/0.3", tex, dict(ratio=0.3, attributes="uv", locked=lk, scheduler="greedy")),
        ("textured/manifold-off/0.1", tex, dict(ratio=0.1, attributes="uv",
                                                topology=qemjax.Topology(preserve_topology=False))),
        ("textured/classic/0.1", tex, dict(ratio=0.1, attributes="uv", method="classic")),
    ]
    spot = MESHES / "spot" / "spot.obj"
    if spot.exists():
        out += [("spot/uv/0.1", str(spot), dict(ratio=0.1, attributes="uv")),
                ("spot/uv/0.01", str(spot), dict(ratio=0.01, attributes="uv")),
                ("spot/uv-weight0/0.1", str(spot), dict(ratio=0.1, attributes="uv", attribute_weights=0)),
                ("spot/uv/greedy/0.5", str(spot), dict(ratio=0.5, attributes="uv", scheduler="greedy"))]
    for name in ("beetle", "suzanne"):  # stored normals, with hard edges (seams)
        path = MESHES / f"{name}.obj"
        if path.exists():
            out += [(f"{name}/normal/0.1", str(path), dict(ratio=0.1, attributes="normal")),
                    (f"{name}/normal-w0.1/0.1", str(path), dict(ratio=0.1, attributes="normal",
                                                                attribute_weights={"normal": 0.1}))]
    return out


def digest(res) -> str:
    h = hashlib.sha256()
    for name in ("vertices", "faces", "uv", "colors", "normals", "wedge_faces"):
        a = getattr(res, name, None)
        if a is not None:
            a = np.ascontiguousarray(a)
            h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode() + a.tobytes())
    for a in (res.history.pairs, res.history.positions, res.history.costs):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", required=True, help="the old code's git revision")
    p.add_argument("--match", default="", help="only the cases whose id contains this")
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax
    from ab_compare import load_old

    old = load_old(args.rev)
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for cid, path, kw in cases(Path(tmp), qemjax):
            if args.match not in cid:
                continue
            kw_old = dict(kw)
            if "topology" in kw:
                kw_old["topology"] = old.Topology(preserve_topology=False)
            h_new, h_old = digest(qemjax.simplify(path, **kw)), digest(old.simplify(path, **kw_old))
            bad += h_new != h_old
            print(f"{'OK  ' if h_new == h_old else 'DIFF'} {cid:32s} {h_new} {h_old}", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
