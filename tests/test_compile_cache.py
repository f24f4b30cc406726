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


# a small kernel compiled with qemjax's cache at argv[1]; argv[2] "full": the disk fills once 256 bytes of a file
# are written (a process killed while writing an entry leaves the same); prints the cache hits
CUT = """
import resource, sys, warnings
warnings.simplefilter("always")
import jax, jax.numpy as jnp, qemjax
hits = []
jax.monitoring.register_event_listener(lambda name, **kw: hits.append(name) if name.endswith("cache_hits") else None)
qemjax.cache(sys.argv[1])
if sys.argv[2] == "full":
    resource.setrlimit(resource.RLIMIT_FSIZE, (256, resource.RLIM_INFINITY))
print(jax.jit(lambda x: x * 2 + 1)(jnp.arange(3.0)), len(hits))
"""


def test_an_entry_cut_short_is_never_read_and_is_written_again(tmp_path):
    """JAX wrote an entry in place and never over one that is there: an entry cut short (a full disk here; a
    process killed while writing it, or read while another was writing it) was read by every later process,
    which warned "Error reading persistent compilation cache entry" and compiled again, for good. An entry is
    now written whole or not at all, and one that is not whole (left by an older version) is written again."""
    cache = tmp_path / "cache"
    env = {k: v for k, v in os.environ.items() if k not in ("QEMJAX_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env["PYTHONPATH"] = str(ROOT)

    def run(mode):
        done = subprocess.run([sys.executable, "-c", CUT, str(cache), mode], env=env, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stderr
        return done.stdout.split("]")[-1].strip(), done.stderr

    def entries():
        return {p.name: p.stat().st_size for p in cache.iterdir()}

    run("full")  # (its writes failed: JAX warns so)
    assert all(size > 256 for size in entries().values())  # no entry, or a whole one: none cut short
    hits, err = run("ok")
    assert "Error reading" not in err and len(entries()) >= 1
    whole = entries()
    hits, err = run("ok")
    assert "Error" not in err and int(hits) >= 1 and entries() == whole  # read from the cache
    for name in whole:  # an entry an older version cut short
        with open(cache / name, "r+b") as f:
            f.truncate(256)
    hits, err = run("ok")
    assert "Error reading" not in err and entries() == whole  # compiled again, its entry written again whole
    hits, err = run("ok")
    assert "Error" not in err and int(hits) >= 1
