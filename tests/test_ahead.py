"""The host loops compiled ahead (qemjax._ahead): the signature list covers what the common runs use, an
installed copy runs them without compiling, and compile_s counts numba's compilations."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def test_every_listed_signature_reads_back():
    from qemjax import _ahead

    listed = _ahead.read_manifest()
    assert len(listed) > 50
    for (mod, name), sigs in listed.items():
        assert mod.startswith("qemjax.") and name.isidentifier()
        for text in sigs:
            types = _ahead._sig_types(text)
            assert isinstance(types, tuple) and _ahead._sig_text(types) == text


def _env(cache_dir):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["NUMBA_CACHE_DIR"] = str(cache_dir)
    env["PYTHONPATH"] = str(REPO)
    return env


def test_compile_all_fills_the_cache_that_a_later_process_loads(tmp_path):
    """A small manifest compiled in one process (in the build's mode: sub-packages bare) is loaded, not
    compiled, by the next one."""
    manifest = tmp_path / "m.txt"
    manifest.write_text("qemjax._mesh.box_bounds row_bounds (Array(float64, 2, 'C', False, aligned=True),)\n"
                        "qemjax._mesh.box_bounds nothing (int64,)\n")
    code = ("import json, sys; from pathlib import Path; from qemjax import _ahead; "
            "r = _ahead.compile_all(_ahead.read_manifest(Path(sys.argv[1])), bare=True); "
            "r.pop('seconds'); print(json.dumps(r))")
    runs = [json.loads(subprocess.run([sys.executable, "-c", code, str(manifest)], env=_env(tmp_path / "c"),
                                      capture_output=True, text=True, check=True).stdout) for _ in range(2)]
    assert runs[0]["signatures"] == 1 and runs[0]["compiled"] == 1 and runs[0]["loaded"] == 0
    assert runs[1]["signatures"] == 1 and runs[1]["compiled"] == 0 and runs[1]["loaded"] == 1
    assert len(runs[0]["failed"]) == 1 and "nothing" in runs[0]["failed"][0]  # named, not fatal


def test_compile_seconds_count_numba_compilations_once():
    """A loop that calls another is one compilation, timed from the outside: compile_s sees it."""
    from numba import njit

    from qemjax._kernels import compilation

    @njit
    def inner(x):
        return x * 2.0

    @njit
    def outer(x):
        s = 0.0
        for v in x:
            s += inner(v)
        return s

    n0, (_, s0) = compilation.numba_compiles(), compilation.snapshot()
    assert outer(np.arange(4.0)) == 12.0
    n1, (_, s1) = compilation.numba_compiles(), compilation.snapshot()
    assert n1 - n0 == 1
    assert s1 - s0 > 0.0
    outer(np.arange(5.0))  # the same signature: no compilation
    assert compilation.numba_compiles() == n1


@pytest.mark.slow
def test_the_installed_package_runs_the_workloads_without_compiling_or_missing_signatures():
    """The README's runs and every method and scheduler, in a fresh process of the installed qemjax (cwd
    outside the repository): every signature they use is in signatures.txt, and where the package was
    installed from a build (not editable: CI's `pip install .`) none of them compiles, since the build
    compiled them ahead."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_") and k != "PYTHONPATH"}
        done = subprocess.run([sys.executable, "-m", "qemjax._ahead", "--check"], cwd=tmp, env=env,
                              capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["missing"] == [], ("signatures the workloads use that qemjax/_ahead/signatures.txt lacks; "
                                     "rerun `python -m qemjax._ahead --record`:\n" + "\n".join(report["missing"]))
    if Path(report["package"]).resolve() != (REPO / "qemjax").resolve():  # an install built from the sources
        assert report["compiled"] == 0


@pytest.mark.parametrize("options", [{}, {"scheduler": "greedy"}, {"locked": np.arange(0, 400, 4)}],
                         ids=["default", "greedy", "locks"])
def test_a_warm_run_types_every_compiled_loops_arguments_without_python(monkeypatch, options):
    """A warm run finds each compiled loop's version from its arguments' type codes, in C: none goes through
    numba's typing in Python (`Dispatcher._compile_for_args`, about 0.4 ms a call, once a round in the
    selection when a named tuple argument missed its type code)."""
    from numba.core import dispatcher

    import qemjax
    from qemjax import shapes

    mesh = shapes.bumpy_sphere(4, seed=3)
    qemjax.simplify(mesh, ratio=0.1, **options)  # compiles or loads what it uses
    typed = []
    original = dispatcher.Dispatcher._compile_for_args

    def counted(self, *args, **kws):
        typed.append(f"{self.py_func.__module__}.{self.py_func.__name__}")
        return original(self, *args, **kws)
    monkeypatch.setattr(dispatcher.Dispatcher, "_compile_for_args", counted)
    qemjax.simplify(mesh, ratio=0.1, **options)
    assert typed == []
