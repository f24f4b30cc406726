"""Jit-compiled, batched JAX kernels. Pure functions of arrays; no host logic here.

Dtype policy: kernels are dtype-polymorphic, qemjax drives them in float32 on coordinates normalised to
unit extent, with every vertex quadric stored in a frame centred on that vertex (so the constant and
linear terms stay small and float32 keeps its precision where costs are tiny). Tests run them in float64
under ``jax.enable_x64`` against numpy references.
"""
from __future__ import annotations

import functools

from . import cache as _cache
from .lazy import jax  # imported on first use: importing qemjax stays light

# On the CPU, XLA's newer fusion emitter compiles a loop fusion that it splits over several threads into
# different machine code than the unsplit loop (other multiply-adds become FMAs), and it splits by the
# number of cores the process may use: results then depend on the core count (`taskset -c 0` changed the
# parallel scheduler's output; docs/design.md, "Determinism"). The older emitter gives the same bits
# either way, and was faster for the placement kernel here (the flip kernel, much slower with it, keeps the
# default: `flips.face_flips_at`). Set per kernel, never process-wide.
CPU_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def kernel(fn=None, **jit_kwargs):
    """``jax.jit`` for qemjax's kernels: on the CPU backend with `CPU_COMPILER_OPTIONS`, so the output
    does not depend on how many cores the process has. The backend is looked up at the first call (importing
    qemjax stays light). Usable as ``@kernel`` or ``@kernel(static_argnums=0)``."""
    if fn is None:
        return functools.partial(kernel, **jit_kwargs)
    compiled = []

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if not compiled:  # (one append of both: a thread's first call beside another's sees both or neither)
            _cache.ensure_default()  # JAX's persistent compilation cache, before the first compilation
            opts = CPU_COMPILER_OPTIONS if jax.default_backend() == "cpu" else None
            compiled.append((jax.jit(fn, compiler_options=opts, **jit_kwargs), _tracing()))
        jitted, tracing = compiled[0]
        if tracing(args, kwargs):
            return fn(*args, **kwargs)  # inside another kernel's trace: inline (options are top-level only)
        return jitted(*args, **kwargs)
    return call


def _tracing():
    """A function of a call's (args, kwargs) telling whether it runs inside a JAX trace: JAX's own flag
    where this JAX has it (next to free), else whether an argument is a tracer (walking the arguments costs
    a noticeable part of a small mesh's device call, every call)."""
    clean = _trace_flag()
    if clean is None:  # another JAX: look at the arguments
        return lambda args, kwargs: any(isinstance(a, jax.core.Tracer)
                                        for a in jax.tree_util.tree_leaves((args, kwargs)))
    return lambda args, kwargs: not clean()


def _trace_flag():
    """JAX's "no trace under way" test (a private function: None where this JAX lacks it)."""
    try:
        from jax._src.core import trace_state_clean
    except ImportError:
        return None
    return trace_state_clean
