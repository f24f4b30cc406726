"""The same bits on every FMA-capable x86-64 CPU: golden cases run in subprocesses that imitate other CPUs.

What varies from one CPU to the next, and how each is imitated on this one:

* OpenBLAS's kernel (``OPENBLAS_CORETYPE``: Prescott, Sandybridge, Haswell, Zen, and SkylakeX where the CPU
  has AVX-512). The re-fit once solved with SuperLU, whose BLAS calls gave other bits under other kernels;
* numpy's own SIMD functions (``NPY_DISABLE_CPU_FEATURES`` turns its AVX-512 versions off, as on a CPU without
  AVX-512): ``np.exp``, ``np.power``, ``np.arccos``, ... give other last bits there;
* XLA's instruction set (``XLA_FLAGS=--xla_cpu_max_isa=AVX2``).

Each subprocess runs the same cases (the golden ones on generated meshes that cover the default's re-fit on
both schedulers and the classic method, the cow when ../shared/meshes has it, the default with UVs kept,
and the measured distances of a run and of `metrics.surface_distance`) and prints their digests; every
variant must give the golden hash, and the two outside the golden file the same digest under every variant.
`qemjax._mesh.fixed_order` says which numpy calls are avoided.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import golden_cases as gc
import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE_IDS = ["default/parallel/bumpy-sphere-3/0.1", "default/greedy/bumpy-sphere-3/0.1",
            "default/parallel/torus-32x16/0.1", "default/greedy/torus-32x16/0.1",
            "parallel/bumpy-sphere-4/0.1", "greedy/torus-32x16/0.1", "default/cow/0.1", "area/greedy/cow/0.1",
            "esqem/greedy/cow/0.1"]
CODE = r"""
import hashlib, json, sys, tempfile, warnings
sys.path.insert(0, sys.argv[1])
import numpy as np
import golden_cases as gc
import qemjax
warnings.simplefilter("ignore")
out = {}
for case in gc.cases():
    if case.id in json.loads(sys.argv[2]) and (not case.shared or gc.SHARED.joinpath(case.mesh).exists()):
        out[case.id] = gc.run(case)["hash"]
with tempfile.TemporaryDirectory() as tmp:  # the default with UVs kept (attribute quadrics, wedges)
    qemjax.shapes.write_examples(tmp, subdivisions=3)
    res = qemjax.simplify(tmp + "/textured.obj", ratio=0.2, attributes="uv")
h = hashlib.sha256()
for a in (res.vertices, res.faces, res.uv, res.wedge_faces):
    h.update(np.ascontiguousarray(a).tobytes())
out["uv"] = h.hexdigest()[:16]
# the measured distances, the run's and the metrics' (relative ones divide by the box's diagonal: three unlike
# extents), to the last bit
sphere = qemjax.shapes.bumpy_sphere(3)
V, F = np.asarray(sphere.vertices) * np.array([3.7, 0.013, 11.1]), np.asarray(sphere.faces)
res = qemjax.simplify((V, F), ratio=0.3)
d = qemjax.metrics.surface_distance((V, F), res)
values = [res.stats[k] for k in sorted(res.stats) if k.startswith("distance") and k != "distance_s"]
out["distance"] = hashlib.sha256(json.dumps(values + [d[k] for k in sorted(d)]).encode()).hexdigest()[:16]
print("DIGESTS " + json.dumps(out))
"""


def _avx512_features() -> list[str]:
    """numpy's AVX-512 dispatch targets that this CPU has (what NPY_DISABLE_CPU_FEATURES may turn off)."""
    try:
        from numpy._core import _multiarray_umath as mu
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as mu
    return [f for f in getattr(mu, "__cpu_dispatch__", []) if (f.startswith("AVX512") or f == "X86_V4")
            and mu.__cpu_features__.get(f)]


def _variants() -> dict[str, dict]:
    """name -> the environment changes that imitate another CPU (only those this CPU can run)."""
    out = {"as-is": {}, "openblas-prescott": {"OPENBLAS_CORETYPE": "Prescott"},
           "openblas-sandybridge+xla-avx2": {"OPENBLAS_CORETYPE": "Sandybridge",
                                             "XLA_FLAGS": "--xla_cpu_max_isa=AVX2"}}
    avx512 = _avx512_features()
    if avx512:  # a CPU with AVX-512: imitate one without, and run OpenBLAS's AVX-512 kernel
        out["openblas-zen+numpy-no-avx512"] = {"OPENBLAS_CORETYPE": "Zen",
                                               "NPY_DISABLE_CPU_FEATURES": " ".join(avx512)}
        out["openblas-skylakex"] = {"OPENBLAS_CORETYPE": "SkylakeX"}
    else:
        out["openblas-haswell"] = {"OPENBLAS_CORETYPE": "Haswell"}
    return out


def _run(extra: dict) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT), **extra)
    done = subprocess.run([sys.executable, "-c", CODE, str(ROOT / "tests"), json.dumps(CASE_IDS)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    line = [x for x in done.stdout.splitlines() if x.startswith("DIGESTS ")]
    assert line, done.stdout[-2000:] + done.stderr[-2000:]
    return json.loads(line[-1][len("DIGESTS "):])


@pytest.mark.slow
def test_golden_cases_give_one_hash_under_every_imitated_cpu():
    if sys.platform != "linux" or os.uname().machine not in ("x86_64", "AMD64"):
        pytest.skip("the imitated CPUs are x86-64 ones")
    variants = _variants()
    with ThreadPoolExecutor(max_workers=2) as pool:
        got = dict(zip(variants, pool.map(_run, variants.values())))
    golden = gc.load_golden()["cases"]
    # uv and the measured distances: the same under all
    want = {i: golden[i]["hash"] for i in CASE_IDS} | {k: got["as-is"][k] for k in ("uv", "distance")}
    wrong = {name: {i: h for i, h in digests.items() if h != want[i]} for name, digests in got.items()}
    wrong = {name: w for name, w in wrong.items() if w}
    assert not wrong, f"outputs differ from the golden hashes under {wrong} (variants: {variants})"
    assert all(set(d) == set(got["as-is"]) for d in got.values())
    assert len(got["as-is"]) >= 6
