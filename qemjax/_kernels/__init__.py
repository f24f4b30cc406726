"""Jit-compiled, batched JAX kernels. Pure functions of arrays; no host logic here.

Dtype policy: kernels are dtype-polymorphic, qemjax drives them in float32 on coordinates normalised to
unit extent, with every vertex quadric stored in a frame centred on that vertex (so the constant and
linear terms stay small and float32 keeps its precision where costs are tiny). Tests run them in float64
under ``jax.enable_x64`` against numpy references.
"""
