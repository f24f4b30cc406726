"""numba's cache under processes that compile at once (`qemjax._mesh.compiled`): two processes that save two
signatures of one function at the same moment keep both, each entry loads the code of its own signature, and
an entry whose data was made for another signature is compiled again instead of run."""
from __future__ import annotations

import ast
import glob
import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

MODULE = """
from qemjax._mesh.compiled import njit

@njit(cache=True)
def plus_one(x):
    return x + 1
"""

# compiles plus_one for one type; with QEMJAX_TEST_MEET, the save waits (at most a few seconds) after reading
# the index until the other process has read it too: the moment two unlocked saves take one number
COMPILE = """
import os, sys, time
from pathlib import Path
import numba.core.caching as caching

meet = os.environ.get("QEMJAX_TEST_MEET")
if meet:
    me, other = Path(meet, sys.argv[1]), Path(meet, sys.argv[2])
    write_index = caching.IndexDataCacheFile._save_index

    def waiting(self, overloads):
        me.touch()
        t0 = time.time()
        while not other.exists() and time.time() - t0 < 4:
            time.sleep(0.01)
        write_index(self, overloads)

    caching.IndexDataCacheFile._save_index = waiting

if os.environ.get("QEMJAX_TEST_DIE_AT_SECOND_WRITE"):  # killed between the entry's two files
    writes = []

    def dying(write):
        def wrapped(self, *args):
            writes.append(write.__name__)
            if len(writes) == 2:
                os._exit(3)
            return write(self, *args)
        return wrapped

    caching.IndexDataCacheFile._save_index = dying(caching.IndexDataCacheFile._save_index)
    caching.IndexDataCacheFile._save_data = dying(caching.IndexDataCacheFile._save_data)

if os.environ.get("QEMJAX_TEST_NO_LOCKS"):  # a file system that refuses locks
    import errno, fcntl

    def refused(fd, op):
        raise OSError(errno.ENOLCK, "no locks available")

    fcntl.flock = refused

import probe
value = {"int": 1, "float": 1.5}[sys.argv[1]]
print(probe.plus_one(value), probe.plus_one.stats.cache_hits and 1 or 0)
"""


def _env(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT)]))
    env.pop("NUMBA_DISABLE_JIT", None)
    return env


def _run(tmp_path, kind, env):
    return subprocess.run([sys.executable, str(tmp_path / "compile.py"), kind, "float" if kind == "int" else "int"],
                          env=env, capture_output=True, text=True, timeout=120)


def _entries(tmp_path):
    """[(the signature an index entry is for, the signature its data was compiled for)]"""
    out = []
    for index in glob.glob(str(tmp_path / "cache" / "**" / "*.nbi"), recursive=True):
        with open(index, "rb") as f:
            pickle.load(f)
            _, overloads = pickle.loads(f.read())
        for key, name in overloads.items():
            with open(os.path.join(os.path.dirname(index), name), "rb") as f:
                out.append((tuple(map(str, key[0])), tuple(map(str, pickle.loads(f.read())[3].args))))
    return sorted(out)


@pytest.fixture
def probe(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))  # (reading the cache's data imports the module)
    monkeypatch.delitem(sys.modules, "probe", raising=False)
    (tmp_path / "probe.py").write_text(textwrap.dedent(MODULE))
    (tmp_path / "compile.py").write_text(textwrap.dedent(COMPILE))
    (tmp_path / "meet").mkdir()
    return tmp_path


def test_two_processes_saving_at_once_keep_both_signatures(probe):
    env = dict(_env(probe), QEMJAX_TEST_MEET=str(probe / "meet"))
    procs = [subprocess.Popen([sys.executable, str(probe / "compile.py"), a, b], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for a, b in (("int", "float"), ("float", "int"))]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    assert [o[0].split()[0] for o in outs] == ["2", "2.5"]
    assert _entries(probe) == [(("float64",), ("float64",)), (("int64",), ("int64",))]
    # and a later process loads each from the cache, with its own result
    for kind, want in (("int", "2 1"), ("float", "2.5 1")):
        done = _run(probe, kind, _env(probe))
        assert done.returncode == 0 and done.stdout.split() == want.split(), done.stderr[-2000:]


def test_an_entry_compiled_for_other_types_is_compiled_again(probe):
    env = _env(probe)
    for kind in ("int", "float"):
        assert _run(probe, kind, env).returncode == 0
    # the state an unlocked race leaves: each entry's data is the other signature's
    files = sorted(glob.glob(str(probe / "cache" / "**" / "*.nbc"), recursive=True))
    assert len(files) == 2
    first, second = (Path(f).read_bytes() for f in files)
    Path(files[0]).write_bytes(second)
    Path(files[1]).write_bytes(first)
    for kind, want in (("int", "2 0"), ("float", "2.5 0")):  # right, and compiled (no cache hit)
        done = _run(probe, kind, env)
        assert done.returncode == 0 and done.stdout.split() == want.split(), (done.stdout, done.stderr[-2000:])
    assert _entries(probe) == [(("float64",), ("float64",)), (("int64",), ("int64",))]  # and saved over


def test_a_process_killed_while_saving_leaves_no_entry_of_older_code(probe):
    """numba wrote the index before the data it names: a process killed between the two, after the source
    changed, left the new entry naming the file of the old code, which the next process ran."""
    env = _env(probe)
    assert _run(probe, "int", env).stdout.split() == ["2", "0"]
    (probe / "probe.py").write_text(textwrap.dedent(MODULE).replace("x + 1", "x + 2"))
    assert _run(probe, "int", dict(env, QEMJAX_TEST_DIE_AT_SECOND_WRITE="1")).returncode == 3
    done = _run(probe, "int", env)
    assert done.returncode == 0 and done.stdout.split()[0] == "3", (done.stdout, done.stderr[-2000:])


def test_a_file_system_without_locks_caches_as_numba_does(probe):
    env = dict(_env(probe), QEMJAX_TEST_NO_LOCKS="1")
    for want in ("2 0", "2 1"):  # compiled and saved, then loaded
        done = _run(probe, "int", env)
        assert done.returncode == 0 and done.stdout.split() == want.split(), done.stderr[-2000:]


def test_every_compiled_loop_uses_the_locked_cache():
    """No module of the package takes numba's ``njit`` itself: its cache would be unlocked."""
    direct = []
    for path in sorted((ROOT / "qemjax").rglob("*.py")):
        if path.name == "compiled.py" and path.parent.name == "_mesh":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "numba":
                direct += [f"{path.relative_to(ROOT)}: {a.name}" for a in node.names if a.name in ("njit", "jit")]
            if isinstance(node, ast.Attribute) and node.attr in ("njit", "jit") and \
                    isinstance(node.value, ast.Name) and node.value.id == "numba":
                direct.append(f"{path.relative_to(ROOT)}: numba.{node.attr}")
    assert not direct, direct


def test_the_loops_of_a_run_have_the_locked_cache():
    from qemjax._ahead import _dispatchers, read_manifest
    from qemjax._mesh.compiled import LockedCacheFile
    import importlib

    for mod in {m for m, _ in read_manifest()}:
        importlib.import_module(mod)
    found = _dispatchers()
    assert len(found) > 50
    plain = [k for k, d in found.items() if type(d._cache._cache_file) is not LockedCacheFile]
    assert not plain, plain


GIVEN = """
from qemjax._mesh.compiled import njit

def given(x):
    return x + 2.0

given = njit(given, cache=True)
"""


def test_a_function_given_as_an_argument_has_the_locked_cache_and_signatures_are_refused(tmp_path, monkeypatch):
    """njit(f, cache=True) returned a decorator instead of the compiled function; it is the compiled function,
    with the locked cache. Signatures, which numba compiles and saves with its own unlocked cache as it
    decorates, are refused in one line."""
    import importlib

    import numba

    from qemjax._mesh.compiled import LockedCacheFile, njit

    (tmp_path / "given_probe.py").write_text(GIVEN)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("given_probe")
    try:
        assert isinstance(module.given, numba.core.dispatcher.Dispatcher)
        assert type(module.given._cache._cache_file) is LockedCacheFile
        assert module.given(1.0) == 3.0
    finally:
        sys.modules.pop("given_probe", None)
    for args, kw in ((("f8(f8)",), {"cache": True}), ((), {"signature_or_function": "f8(f8)"})):
        with pytest.raises(TypeError, match="give it no signatures"):
            njit(*args, **kw)
