"""JAX's persistent compilation cache, on by default for the library and the command.

Each process otherwise compiles its kernels afresh (seconds on a CPU for each new mesh size class). The cache
keeps the compiled kernels on disk, keyed by their shapes, so a later process, a sweep's worker or a new
mesh of a size seen before loads them. qemjax's first compilation (or a first ``qemjax.cache()``) turns it
on (`ensure_default`: importing qemjax itself does not start JAX) unless
``QEMJAX_NO_CACHE`` is set (to anything but "" or "0") or JAX's own cache folder is already set (by the
program or ``JAX_COMPILATION_CACHE_DIR``: then that one is used, untouched). ``qemjax.cache(False)`` turns
it off in a running process, ``qemjax.cache(folder)`` points it elsewhere; ``qemjax ... --no-cache`` too.
"""
from __future__ import annotations

import os

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
    _reset()
    _OWN[:] = [path]
    _DECIDED[:] = [True]
    return path


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
