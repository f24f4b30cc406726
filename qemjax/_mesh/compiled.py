"""`njit`: numba's ``njit`` whose on-disk cache (``cache=True``) stays right when several processes compile at
once, as a process pool, Dask workers, the test runner's workers or the package build's compiling slices do.

numba's cache keeps, per function, an index (signature -> data file) beside numbered data files. To save a new
signature it reads the index, takes the first unused number, writes the index, then the data, with no lock.
Two processes that compile two signatures of one function at the same moment
read the same index and take the same number: one index entry is lost, and the other can point at the code
compiled for the other signature. Every later process that loads that entry runs code built for other
argument types, and crashes. Here each function's saves hold an exclusive lock on a file beside its index
(reading the index afresh under it, and writing the data before the index that names it), and loads a shared
one, so that no process reads a half-made entry; an entry whose data was compiled for another signature (a
cache made before this, or by a process that does not lock) is treated as missing: numba compiles it again
and the save writes it over.

Where files cannot be locked (no ``fcntl``, as on Windows, a read-only cache folder, a file system without
locks) the cache works as numba's own.
"""
from __future__ import annotations

import contextlib
import itertools
import os

import numba
from numba.core.caching import IndexDataCacheFile

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None


@contextlib.contextmanager
def _locked(index_path: str, exclusive: bool):
    fd = None
    if fcntl is not None:
        try:
            fd = os.open(index_path + ".lock", os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:  # a folder this process may read but not write: it cannot save there either
            fd = None
    try:
        if fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
            except OSError:  # a file system without locks (some network and FUSE ones): as numba's own
                pass
        yield
    finally:
        if fd is not None:
            os.close(fd)  # (closing releases the lock)


def _compiled_for(data, sig) -> bool:
    """Whether a loaded cache entry ``data`` (numba's reduced compile result, whose fourth item is its
    signature) was compiled for the argument types ``sig``; an entry of another layout is taken as it is."""
    made = data[3] if isinstance(data, tuple) and len(data) > 3 else None
    args = getattr(made, "args", None)
    return args is None or tuple(args) == tuple(sig)


class LockedCacheFile(IndexDataCacheFile):
    """numba's index and data files of one function, saved under an exclusive lock and loaded under a shared
    one; an entry compiled for other types than its key's loads as missing."""

    def save(self, key, data):
        # numba's own save, with the data written before the index that names it: a process killed between
        # the two leaves an entry nobody reads, never one that names a file of older code
        with _locked(self._index_path, exclusive=True):
            overloads = self._load_index()
            name = overloads.get(key)
            if name is None:
                taken = set(overloads.values())
                name = next(self._data_name(i) for i in itertools.count(1) if self._data_name(i) not in taken)
            self._save_data(name, data)
            if overloads.get(key) != name:
                overloads[key] = name
                self._save_index(overloads)

    def load(self, key):
        with _locked(self._index_path, exclusive=False):
            data = super().load(key)
        return data if data is None or _compiled_for(data, key[0]) else None


def _safe(dispatcher):
    cache = getattr(dispatcher, "_cache", None)
    files = getattr(cache, "_cache_file", None)
    if type(files) is IndexDataCacheFile:
        files.__class__ = LockedCacheFile  # the same state; only saving and loading change
    return dispatcher


def njit(*args, **options):
    """``numba.njit`` (the same options, bare, called, or given the function) with the cache of
    `LockedCacheFile`. No signatures: numba compiles them as it decorates, before the locked cache is in place,
    and would save them with its own."""
    if args and callable(args[0]):
        return _safe(numba.njit(*args, **options))
    if args or options.get("signature_or_function") is not None:
        raise TypeError("qemjax's njit compiles on first use: give it no signatures (numba would compile and "
                        "save them as it decorates, with its own unlocked cache)")
    decorate = numba.njit(**options)
    return lambda f: _safe(decorate(f))
