"""Pricing a pair at a fixed position: its kept vertex's (``pairs[:, 0]``), for locked vertices (`qemjax._locks`).

A locked vertex never moves, so a pair with one locked endpoint may only contract onto it. The run numbers
the locked vertices first (`_locks.permutation`), so the locked endpoint of such a pair is always its kept
one, and the price a lock needs is "the cost of contracting onto the kept vertex where it stands". Each cost
model offers it as ``model.price_at_kept(VS, pairs, params, rings=None)`` with the output of its ``price``
((5 + len(parts), K): position, cost, branch, parts); the position rows are the kept vertex's row, copied,
so the contraction puts it exactly where it was. The branch reported is the model's endpoint branch.

- quadric models (QEM, line, probabilistic quadrics, ESQEM, memoryless): the summed quadric at the kept
  vertex, Q1(0) + Q2(p1 − p2) (each quadric in its own vertex's frame; memoryless: the current quadric
  plus μ times the summed one and the volume term, as its own price builds them);
- the area method: |ΔS| with both endpoints at the kept vertex (s = 0 of its one-parameter family), +inf
  where its boundary rule pins the pair to the removed vertex (a boundary vertex would leave its boundary);
- the terms (``regularize``, ``area_weight``): their term at that position, added to the base's price.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

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


@kernel
def memoryless(VS, pairs, params):
    """Memoryless rows (`memoryless`): current + μ·summed quadric with the volume term, at the kept vertex."""
    from . import memoryless as ml

    q1, q2, p1, p2 = ml._with_volume(VS, pairs, params["volume_weight"], params["memory_weight"])
    return stacked(p1, quadric_cost(q1, q2, p1, p2), ENDPOINT)


def area_delta(pa, pb, pos, moving, mask):
    """One pair: |ΔS| when both endpoints go to pa (the area method's s = 0)."""
    from .area import _delta, _norm, affine_areas

    u, w = affine_areas(pa, pb, pos, moving)
    twice = jnp.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]).T
    before = 0.5 * jnp.sum(jnp.where(mask, _norm(twice), 0.0))
    return jnp.abs(_delta(jnp.zeros((), pa.dtype), (u.T, w.T, mask, before)))


@kernel
def area(VS, pairs, params, corners, mask):
    """The area method at the kept vertex (module docstring); ``branches``' "end" (2)."""
    from .area import interval, ring_positions

    pos, moving = ring_positions(VS, pairs, corners)
    pa, pb = VS[pairs[:, 0], :3], VS[pairs[:, 1], :3]
    lo, _ = interval(VS[pairs[:, 0], 3], VS[pairs[:, 1], 3])
    d = jax.vmap(area_delta)(pa, pb, pos, moving, mask)
    cost = jnp.where(lo > 0, jnp.inf, d)
    return jnp.concatenate([pa.T, cost[None], jnp.full_like(cost, 2.0)[None]], 0)
