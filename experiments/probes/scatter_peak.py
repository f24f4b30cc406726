"""Time and peak resident memory of `qemjax._partition.scatter` on a large mesh file, each run in a fresh
child process (its peak read from the kernel's account of children, so nothing of this process counts).
A missing ``.ply`` is first written by `big_mesh.py` with the faces asked for.

    python experiments/probes/scatter_peak.py --faces 10000000 --mesh /tmp/big10.ply --part-faces 500000
    python experiments/probes/scatter_peak.py --mesh /tmp/big.obj --part-faces 1000000 --scratch /tmp/parts
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments"))

CHILD = """
import json, sys, time
from qemjax._partition.scatter import scatter
t = time.perf_counter()
m = scatter(sys.argv[1], sys.argv[2], int(sys.argv[3]), chunk_faces=int(sys.argv[4]))
print(json.dumps({"seconds": time.perf_counter() - t, "faces": m["n_faces"], "vertices": m["n_vertices"],
                  "parts": len(m["parts"]), "border": sum(p["border"] for p in m["parts"]),
                  "largest": max(p["faces"] for p in m["parts"])}))
"""


def run(mesh: str, scratch: str, part_faces: int, chunk_faces: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", CHILD, mesh, scratch, str(part_faces), str(chunk_faces)],
                         env=env, check=True, capture_output=True, text=True).stdout
    result = json.loads(out.strip().splitlines()[-1])
    result["peak_GiB"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20  # KiB on Linux
    return result


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", required=True)
    p.add_argument("--faces", type=int, default=10_000_000, help="faces of the mesh written when it is missing")
    p.add_argument("--part-faces", type=int, default=1_000_000)
    p.add_argument("--chunk-faces", type=int, default=1 << 21)
    p.add_argument("--scratch", default=None, help="parts folder (default: a temporary one)")
    args = p.parse_args(argv)
    if not os.path.exists(args.mesh):
        from figures import big_mesh
        t = time.perf_counter()
        nv, nf = big_mesh.write(args.mesh, args.faces)
        print(f"wrote {nf} faces in {time.perf_counter() - t:.1f} s -> {args.mesh}")
    with tempfile.TemporaryDirectory() as tmp:
        r = run(args.mesh, args.scratch or tmp, args.part_faces, args.chunk_faces)
    size = os.path.getsize(args.mesh) / 2**20
    print(f"{Path(args.mesh).name} ({size:.0f} MiB): {r['faces']} faces, {r['vertices']} vertices -> {r['parts']} "
          f"parts (largest {r['largest']}, border vertices {r['border']}); {r['seconds']:.1f} s, "
          f"{size / r['seconds']:.0f} MiB/s, peak RSS {r['peak_GiB']:.2f} GiB")


if __name__ == "__main__":
    main()
