"""JAX's persistent compilation cache for the ``qemjax`` command (the library never sets global options).

Each process otherwise compiles its kernels afresh (2-4 s on a CPU). The cache keeps the compiled
kernels on disk, keyed by their shapes, so a later process with meshes of a similar size loads them.
"""
from __future__ import annotations

import os


def default_dir() -> str:
    """$QEMJAX_CACHE_DIR, else $XDG_CACHE_HOME/qemjax/jax, else ~/.cache/qemjax/jax."""
    if os.environ.get("QEMJAX_CACHE_DIR"):
        return os.environ["QEMJAX_CACHE_DIR"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "qemjax", "jax")


def enable(path: str | None = None) -> str | None:
    """Point JAX's persistent compilation cache at ``path`` (default `default_dir`) and cache every
    kernel, however fast it compiled. Returns the folder, or None when it cannot be created (then
    nothing changes: the run just compiles). Takes effect only before the process's first compilation."""
    import jax

    path = path or default_dir()
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # default 1 s: ours take less
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)  # no size limit, no overrides
    return path
