"""Pricing a pair at a fixed position: its kept vertex's (``pairs[:, 0]``), for locked vertices (`qemjax._schedulers.locks`).

A locked vertex never moves, so a pair with one locked endpoint may only contract onto it. The run numbers
the locked vertices first (`qemjax._pipeline.locks.Locks.geometry`), so the locked endpoint of such a pair is always its kept
one, and the price a lock needs is "the cost of contracting onto the kept vertex where it stands". Each cost
model offers it as ``model.price_at_kept(VS, pairs, params, rings=None)`` with the output of its ``price``
((5 + len(parts), K): position, cost, branch, parts); the position rows are the kept vertex's row, copied,
so the contraction puts it exactly where it was. The branch reported is the model's endpoint branch.

- quadric models (QEM, line, probabilistic quadrics, ESQEM, memoryless): the summed quadric at the kept
  vertex, Q1(0) + Q2(p1 − p2) (each quadric in its own vertex's frame; memoryless: the current quadric
  plus μ times the summed one and the volume term, as its own price builds them: `memoryless.price_at_kept`);
- the area method (`area.price_at_kept_kernel`): |ΔS| with both endpoints at the kept vertex (s = 0 of its
  one-parameter family), +inf where its boundary rule pins the pair to the removed vertex (a boundary vertex
  would leave its boundary);
- the terms (``regularize``, ``area_weight``): their term at that position, added to the base's price.

This module holds what the models share (the quadric cost at a point, the rows' layout) and QEM's kernel;
a model with its own state keeps its kernel in its own module.
"""
from __future__ import annotations

from .._kernels.lazy import jnp  # imported on first use (`_kernels.lazy`)

from .._kernels import kernel
from .._kernels import placement
from .._kernels import quadrics as qd

ENDPOINT = placement.ENDPOINT  # the branch a contraction onto the kept vertex reports (QEM's numbering)


def quadric_cost(q1, q2, p1, p2):
    """(K,) Q1(0) + Q2(p1 − p2), clamped at 0 (component lists, quadrics in their vertices' frames)."""
    return jnp.maximum(q1[9] + qd.evaluate_c(q2, [p1[i] - p2[i] for i in range(3)]), 0.0)


def stacked(p1, cost, branch_value, *parts):
    """The (5 + len(parts), K) price rows: position p1 (component list), cost, branch, parts."""
    return jnp.stack(list(p1) + [cost, jnp.full_like(cost, branch_value)] + list(parts), 0)


@kernel
def qem(VS, pairs, params):
    """QEM rows [x y z q0…q9 …]: the summed quadric at the kept vertex."""
    q1, q2, p1, p2 = placement._gather_rows(VS, pairs)
    return stacked(p1, quadric_cost(q1, q2, p1, p2), ENDPOINT)
