"""JAX's persistent compilation cache, on by default for the library and the command.

Each process otherwise compiles its kernels afresh (seconds on a CPU for each new mesh size class). The cache
keeps the compiled kernels on disk, keyed by their shapes, so a later process, a sweep's worker or a new
mesh of a size seen before loads them. qemjax's first compilation (or a first ``qemjax.cache()``) turns it
on (`ensure_default`: importing qemjax itself does not start JAX) unless
``QEMJAX_NO_CACHE`` is set (to anything but "" or "0") or JAX's own cache folder is already set (by the
program or ``JAX_COMPILATION_CACHE_DIR``: then that one is used, untouched). ``qemjax.cache(False)`` turns
it off in a running process, ``qemjax.cache(folder)`` points it elsewhere; ``qemjax ... --no-cache`` too.

JAX writes a cache entry in place (no temporary file, no lock unless the cache has a size limit), and never
over an entry that is there: an entry cut short (a process killed or a disk filled while writing it, or read
while another process was still writing it) was read by every later process, warned "Error reading persistent
compilation cache entry" and compiled again, for good. In a folder qemjax sets (`enable`), an entry is written
under a temporary name and renamed once whole (`_WholeEntries`), and one that is not whole reads as missing and
is written again.
"""
from __future__ import annotations

import os

from .._io.atomic import replace_atomically

_OWN: list = []  # the folder enable() set, when it did
_DECIDED: list = []  # non-empty once the cache was set up, turned off, or left to the program's setting


def default_dir() -> str:
    """$QEMJAX_CACHE_DIR, else $XDG_CACHE_HOME/qemjax/jax, else ~/.cache/qemjax/jax."""
    if os.environ.get("QEMJAX_CACHE_DIR"):
        return os.environ["QEMJAX_CACHE_DIR"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "qemjax", "jax")


def opted_out() -> bool:
    """Whether the environment asks for no cache: QEMJAX_NO_CACHE set to anything but "" or "0"."""
    return os.environ.get("QEMJAX_NO_CACHE", "").strip() not in ("", "0")


def enable(path: str | None = None) -> str | None:
    """Point JAX's persistent compilation cache at ``path`` (default `default_dir`) and cache every
    kernel, however fast it compiled. Returns the folder, or None when it cannot be created (then
    nothing changes: the run just compiles)."""
    import jax

    path = os.fspath(path) if path else default_dir()
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_enable_compilation_cache", True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # JAX's default skips quick compilations: ours are
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)  # no size limit, no overrides
    _whole_entries()
    _reset()
    _OWN[:] = [path]
    _DECIDED[:] = [True]
    return path


def _whole(value: bytes) -> bool:
    """Whether a cache entry's bytes are a whole compressed stream (one cut short does not decompress)."""
    from jax._src.compilation_cache import decompress_executable

    try:
        decompress_executable(value)
    except Exception:  # noqa: BLE001 - zlib's or zstd's error for a stream cut short
        return False
    return True


def _whole_entries() -> None:
    """JAX's file caches made from now on read and write whole entries (`_WholeEntries`); nothing where this
    JAX has no such class to take after (the cache is then JAX's own)."""
    try:
        from jax._src import compilation_cache, lru_cache
    except ImportError:  # pragma: no cover - another JAX
        return
    base = getattr(compilation_cache, "LRUCache", None)
    if base is None or getattr(base, "whole_entries", False) or not hasattr(lru_cache, "_CACHE_SUFFIX"):
        return

    class _WholeEntries(base):
        """JAX's cache of files, whose entries are written whole or not at all (a temporary file of this
        process and thread, renamed), where JAX wrote them in place; an entry that is not whole reads as
        missing and is removed, so that the fresh compilation's entry takes its place."""

        whole_entries = True

        def _entry(self, key):
            return self.path / f"{key}{lru_cache._CACHE_SUFFIX}"

        def get(self, key):
            value = super().get(key)
            if value is None or _whole(value):
                return value
            try:
                os.unlink(self._entry(key))
            except OSError:
                pass
            return None

        def put(self, key, value):
            path = self._entry(key)
            # a cache with a size limit writes under JAX's own lock; another file system, JAX's own way
            if self.eviction_enabled or not lru_cache._is_local_filesystem(str(self.path)) or path.exists():
                return super().put(key, value)
            replace_atomically(path, lambda tmp: tmp.write_bytes(value))

    compilation_cache.LRUCache = _WholeEntries


def disable() -> None:
    """No persistent cache in this process from now on (kernels compile in memory, as JAX does by default)."""
    import jax

    jax.config.update("jax_enable_compilation_cache", False)
    _reset()
    _DECIDED[:] = [True]


def _reset() -> None:
    """Let a change take effect after the process's first compilation (JAX decides once per process)."""
    try:
        from jax._src import compilation_cache

        compilation_cache.reset_cache()
    except Exception:  # noqa: BLE001 - an older/newer JAX: the change then applies to a fresh process
        pass


def enable_default() -> str | None:
    """The cache at `default_dir`, unless QEMJAX_NO_CACHE opts out or JAX's cache folder is set already
    (then that is left as it is and returned)."""
    _DECIDED[:] = [True]
    if opted_out():
        return None
    import jax

    if jax.config.jax_compilation_cache_dir and not _OWN:
        return jax.config.jax_compilation_cache_dir
    return enable()


def ensure_default() -> None:
    """`enable_default`, once per process, unless the cache was already set up or turned off: called before
    qemjax's first compilation (`qemjax._kernels.kernel`, `simplify`), so the default applies to the library,
    sweeps and their workers, while ``import qemjax`` stays light."""
    if not _DECIDED:
        enable_default()


def cache(folder=None):
    """JAX's persistent compilation cache for qemjax's kernels (on by default: qemjax's first compilation
    turns it on at ``$QEMJAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/qemjax/jax``, else ``~/.cache/qemjax/jax``;
    ``QEMJAX_NO_CACHE=1`` opts out, and a cache folder already set for JAX is used as it is).
    ``cache()``: the folder in use, or None when off. ``cache(folder)``: use that folder. ``cache(False)``:
    off. Compiled kernels load from it in later processes (a sweep's workers, the next script), so each
    size class of mesh compiles once per machine instead of once per process."""
    import jax

    if folder is False:
        disable()
        return None
    if folder is not None:  # a folder, by its path (the library's own callers use `enable`, which may fail quietly)
        if not isinstance(folder, (str, os.PathLike)) or not os.fspath(folder):
            raise ValueError(f"cache() takes a folder's path, False (off) or nothing; got {folder!r}")
        if enable(folder) is None:
            raise ValueError(f"cache({os.fspath(folder)!r}): the folder cannot be created; the cache stays "
                             f"{cache() or 'off'}")
        return os.fspath(folder)
    ensure_default()
    on = jax.config.jax_enable_compilation_cache and jax.config.jax_compilation_cache_dir
    return jax.config.jax_compilation_cache_dir if on else None
