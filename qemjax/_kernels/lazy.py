"""Modules imported on first use. ``jnp = Lazy("jax.numpy")`` reads like ``import jax.numpy as jnp``, but
imports JAX when an attribute is first read (a kernel traced, a function called), not when the module
that holds it is imported: so `import qemjax`, the cost models' classes and the command line's --help
and --version do not start JAX. Code run at import time must not read them (`jit` defers a decorator)."""
from __future__ import annotations

import functools
import importlib


class Lazy:
    """A module by name, imported on the first attribute read (then every read is the module's)."""

    __slots__ = ("_name", "_module")

    def __init__(self, name: str):
        self._name = name
        self._module = None

    def __getattr__(self, attr):
        module = self._module
        if module is None:
            module = self._module = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self):
        return f"<module {self._name!r}, imported on first use>"


jax = Lazy("jax")
jnp = Lazy("jax.numpy")
optx = Lazy("optimistix")


def jit(fn=None, **jit_kwargs):
    """``jax.jit(fn, **jit_kwargs)``, made at the first call (a decorator that does not import JAX)."""
    if fn is None:
        return functools.partial(jit, **jit_kwargs)
    compiled = []

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if not compiled:
            compiled.append(jax.jit(fn, **jit_kwargs))
        return compiled[0](*args, **kwargs)
    return call
