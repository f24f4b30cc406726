"""JAX's persistent compilation cache serves the library, sweeps and their workers (issue 41), not only the
command: importing qemjax turns it on; QEMJAX_NO_CACHE=1, qemjax.cache(False) and a cache folder the program
set itself are respected. Each check runs in a fresh process (JAX decides once per process)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # fresh processes (the fast tier leaves them out)

ROOT = Path(__file__).resolve().parents[1]
RUN = ("import qemjax, jax\n"
       "from qemjax import shapes\n"
       "print('before', qemjax.cache())\n"
       "{extra}\n"
       "qemjax.simplify(shapes.icosphere(2), ratio=0.5)\n"
       "print('after', qemjax.cache())\n")


def _run(tmp_path, extra="", **env_over):
    env = {k: v for k, v in os.environ.items() if k not in ("QEMJAX_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env.update(QEMJAX_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT), **env_over)
    done = subprocess.run([sys.executable, "-c", RUN.format(extra=extra)], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.split("\n")


def _entries(folder: Path) -> int:
    return len(list(folder.iterdir())) if folder.exists() else 0


def test_the_library_uses_the_cache_by_default(tmp_path):
    before, after, _ = _run(tmp_path)
    assert before == f"before {tmp_path / 'cache'}" and after == f"after {tmp_path / 'cache'}"
    assert _entries(tmp_path / "cache") >= 3  # one entry per compiled kernel


def test_opting_out(tmp_path):
    assert _run(tmp_path, QEMJAX_NO_CACHE="1")[:2] == ["before None", "after None"]
    assert _entries(tmp_path / "cache") == 0
    assert _run(tmp_path, extra="qemjax.cache(False)")[:2] == [f"before {tmp_path / 'cache'}", "after None"]
    assert _entries(tmp_path / "cache") == 0  # off before the first compilation: nothing written


def test_a_cache_folder_set_by_the_program_is_kept(tmp_path):
    own = tmp_path / "own"
    lines = _run(tmp_path, JAX_COMPILATION_CACHE_DIR=str(own))
    assert lines[:2] == [f"before {own}", f"after {own}"]
    assert _entries(tmp_path / "cache") == 0
    moved = _run(tmp_path, extra=f"qemjax.cache({str(tmp_path / 'elsewhere')!r})")
    assert moved[1] == f"after {tmp_path / 'elsewhere'}" and _entries(tmp_path / "elsewhere") >= 3


def test_cache_refuses_what_is_not_a_folder_it_can_use(tmp_path):
    """cache(0) and cache('') turned the cache on at the default folder, cache(True) failed in os.fspath's
    words, and a folder that cannot be made returned None ("off") while the cache stayed on."""
    import qemjax

    before = qemjax.cache()
    for bad in (0, "", True, 1.5):
        with pytest.raises(ValueError, match="cache\\(\\) takes a folder's path, False"):
            qemjax.cache(bad)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(ValueError, match="the folder cannot be created; the cache stays"):
        qemjax.cache(blocker / "sub")
    assert qemjax.cache() == before


def test_a_sweeps_process_pool_workers_use_it(tmp_path):
    """A sweep's spawn workers import qemjax: their kernels land in the cache (the next sweep loads them)."""
    code = ("import concurrent.futures, multiprocessing, qemjax\n"
            "if __name__ == '__main__':\n"
            "    ctx = multiprocessing.get_context('spawn')\n"
            "    with concurrent.futures.ProcessPoolExecutor(1, mp_context=ctx) as pool:\n"
            "        df = qemjax.sweep('shapes.icosphere(subdivisions=2)', {}, [0.5], metrics=False, executor=pool,\n"
            "                          progress=False)\n"
            "    print(df['error'].item() == '')\n")
    (tmp_path / "s.py").write_text(code)
    env = {k: v for k, v in os.environ.items() if k not in ("QEMJAX_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env.update(QEMJAX_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    # the parent compiles nothing (no cell runs in it): the entries are the worker's
    done = subprocess.run([sys.executable, str(tmp_path / "s.py")], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "True", done.stderr
    assert _entries(tmp_path / "cache") >= 3
