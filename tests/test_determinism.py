"""The same input gives the same output whatever number of cores the process may use.

Runs `simplify` here and in a subprocess pinned to one core (``taskset -c 0``) and compares sha256 hashes.
XLA:CPU splits large loop fusions by thread count, and its newer fusion emitter compiles the split code with
other FMA contractions (experiments/results/determinism.md); the kernels are therefore compiled with the
older emitter (`qemjax._kernels.kernel`). Should that option stop working, this test fails.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import qemjax
from qemjax import shapes

ROOT = Path(__file__).resolve().parents[1]
CODE = """
import hashlib, json, sys
import numpy as np
import qemjax
from qemjax import shapes
r = qemjax.simplify(shapes.bumpy_sphere(4), ratio=0.1, **json.loads(sys.argv[1]))
print(hashlib.sha256(r.vertices.tobytes() + r.faces.tobytes()).hexdigest())
"""


def _digest(r) -> str:
    return hashlib.sha256(np.ascontiguousarray(r.vertices).tobytes() + np.ascontiguousarray(r.faces).tobytes()
                          ).hexdigest()


@pytest.mark.slow  # fresh processes under taskset
@pytest.mark.parametrize("kwargs", [dict(scheduler="greedy"), dict(scheduler="parallel"), dict(preset="accurate")],
                         ids=["greedy", "parallel", "accurate"])
def test_same_output_on_one_core(kwargs):
    """The accurate preset covers the memoryless rebuild, the rank placement and the re-fit's solve."""
    if shutil.which("taskset") is None:
        pytest.skip("taskset is not installed")
    if not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2:
        pytest.skip("this process already runs on one core: nothing to compare")
    here = _digest(qemjax.simplify(shapes.bumpy_sphere(4), ratio=0.1, **kwargs))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run(["taskset", "-c", "0", sys.executable, "-c", CODE, json.dumps(kwargs)], env=env,
                          capture_output=True, text=True, timeout=300)
    if done.returncode:
        pytest.fail(f"the pinned subprocess failed:\n{done.stderr}")
    assert done.stdout.strip().splitlines()[-1] == here


def test_small_host_work_runs_on_the_calling_thread():
    """`select.submit`: work under INLINE_ROWS runs here (a done future, errors raised by result()),
    larger work on the worker thread; either way the caller sees the same future."""
    import threading

    from qemjax._schedulers import select
    here = threading.get_ident()
    small = select.submit(threading.get_ident, size=select.INLINE_ROWS - 1)
    assert small.done() and small.result() == here
    assert select.submit(threading.get_ident, size=select.INLINE_ROWS).result() != here
    assert select.submit(threading.get_ident).result() != here  # no size: always the worker
    bad = select.submit(int, "not a number", size=0)
    with pytest.raises(ValueError):
        bad.result()
