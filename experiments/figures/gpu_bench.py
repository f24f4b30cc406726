"""The same code on an accelerator: kernel throughput and whole runs on JAX's default backend (a GPU where
one is present), against the CPU backend in the same process.

Nothing here needs a GPU: on a machine without one both columns are the CPU's. Reports

* the devices JAX sees;
* the price kernel (`placement.place_pairs`, the default's QEM price) at the scheduler's chunk shapes over
  1 M vertex rows: µs per call and pairs per second, on each backend;
* whole runs (`qemjax.simplify`, default and classic methods, the parallel scheduler) on meshes generated in
  code (and the shared meshes when ``../shared/meshes`` is present): warm median wall time on each backend,
  rounds, the measured distance (rms, mesh units) and whether the outputs are the same bits (an
  accelerator's float32 arithmetic may round differently: then the rms says whether quality moved).

    python experiments/figures/gpu_bench.py [--repeats 3] [--meshes bumpy-6 bumpy-7 stanford-bunny] [--out results.md]
"""
from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import numpy as np  # noqa: E402


def _mesh(name: str):
    from qemjax import shapes
    if name.startswith("bumpy-"):  # bumpy-k: a bumpy icosphere subdivided k times (20·4^k faces)
        return shapes.bumpy_sphere(int(name.split("-")[1]))
    import meshes as bench_meshes
    bm = bench_meshes.load(name)
    return bm.V, bm.F


def _sha(res) -> str:
    h = hashlib.sha256(np.ascontiguousarray(res.vertices).tobytes())
    h.update(np.ascontiguousarray(res.faces).tobytes())
    return h.hexdigest()[:16]


def _kernel_rows(devices: dict, repeats: int) -> list[str]:
    import jax
    import jax.numpy as jnp
    from qemjax._kernels import placement
    from qemjax._kernels.batching import CHUNKS

    rng = np.random.default_rng(0)
    n = 1 << 20
    rows = rng.normal(size=(n, 13)).astype(np.float32)
    out = ["| kernel | pairs per call | " + " | ".join(f"{k} µs per call | {k} M pairs/s" for k in devices) + " |",
           "|---|---|" + "---|---|" * len(devices)]
    for K in CHUNKS:
        P = rng.integers(0, n, (K, 2)).astype(np.int32)
        cells = []
        for dev in devices.values():
            with jax.default_device(dev):
                VS = jnp.asarray(rows)
                args = (jnp.asarray(P), jnp.asarray(np.bool_(False)), jnp.asarray(np.float32(1e-5)),
                        jnp.asarray(np.float32(2.0)))
                jax.block_until_ready(placement.place_pairs(VS, *args))
                ts = []
                for _ in range(max(repeats, 5)):
                    t = time.perf_counter()
                    jax.block_until_ready(placement.place_pairs(VS, *args))
                    ts.append(time.perf_counter() - t)
            best = min(ts)
            cells.append(f"{best * 1e6:.0f} | {K / best / 1e6:.1f}")
        out.append(f"| place_pairs | {K} | " + " | ".join(cells) + " |")
    return out


def _run_rows(devices: dict, names: list[str], repeats: int) -> list[str]:
    import jax
    import qemjax

    out = ["| mesh | faces | method | " + " | ".join(f"{k} s" for k in devices) + " | rounds | " +
           " | ".join(f"{k} rms" for k in devices) + " | same bits |",
           "|---|---|---|" + "---|" * len(devices) + "---|" + "---|" * len(devices) + "---|"]
    for name in names:
        try:
            V, F = _mesh(name)
        except Exception as e:  # a shared mesh without ../shared
            out.append(f"| {name} | skipped: {e} |")
            continue
        for method in ("default", "classic"):
            secs, rms, shas, rounds = [], [], [], None
            for dev in devices.values():
                with jax.default_device(dev), warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = qemjax.simplify((V, F), ratio=0.1, method=method)  # warm (compiles)
                    ts = []
                    for _ in range(repeats):
                        t = time.perf_counter()
                        res = qemjax.simplify((V, F), ratio=0.1, method=method)
                        ts.append(time.perf_counter() - t)
                secs.append(f"{statistics.median(ts):.3f}")
                rms.append(f"{res.stats['distance_rms']:.4g}" if res.stats.get("distance_rms") is not None else "-")
                shas.append(_sha(res))
                rounds = res.stats["rounds"]
            out.append(f"| {name} | {len(F)} | {method} | " + " | ".join(secs) + f" | {rounds} | " +
                       " | ".join(rms) + f" | {'yes' if len(set(shas)) == 1 else 'no: ' + ' / '.join(shas)} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["bumpy-5", "bumpy-6", "bumpy-7", "stanford-bunny"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", help="also write the report to this file")
    args = ap.parse_args(argv)
    import jax

    default = jax.devices()[0]
    devices = {default.platform: default}
    if default.platform != "cpu":
        devices["cpu"] = jax.devices("cpu")[0]
    lines = [f"# python experiments/figures/gpu_bench.py {' '.join(argv if argv is not None else sys.argv[1:])}",
             f"JAX {jax.__version__}; default backend {jax.default_backend()}; devices: "
             + ", ".join(f"{d.platform}:{getattr(d, 'device_kind', '')}" for d in jax.devices()), ""]
    if len(devices) == 1:
        lines.append("(no accelerator: one column, the CPU's)")
    lines += _kernel_rows(devices, args.repeats) + [""] + _run_rows(devices, args.meshes, args.repeats)
    text = "\n".join(lines)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
