"""The surface-area change as a term added to another model's cost (``area_weight=λ``, with QEM):

    cost = Q(x) + λ · ΔS(x)² / ℓ²

x is the base model's placement (QEM's optimal point), ΔS(x) the area of the faces around the pair before
minus the area after contracting to x (`area.py`; the faces holding both endpoints vanish), and ℓ² the
mean squared edge length of the faces around the pair before. A contraction that moves the surface by d
changes the area by about ℓ·d, so ΔS²/ℓ² is a squared length like Q, and λ is dimensionless and the
same at any mesh resolution. The term changes only which contractions go first, not where they go.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

from .._kernels.lazy import jax, jnp  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._kernels.batching import DTYPE
from .._kernels import kernel
from .._kernels.fixed import cross3, dot3, norm3, tree_sum
from .area import ring_positions
from .base import Term, require_nonnegative


def area_change(x, pos, moving, mask):
    """One pair: ΔS (area before − after) when the endpoints (``moving`` corners of the ring faces pos
    (R,3,3)) go to x (3,), and the mean squared edge length ℓ² of the faces before."""
    def twice_areas(p):
        return norm3(cross3(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))  # fixed order: `_kernels.fixed`
    after = jnp.where(moving[..., None], x, pos)
    delta = 0.5 * tree_sum(jnp.where(mask, twice_areas(pos) - twice_areas(after), 0.0))
    d = [pos[:, i] - pos[:, (i + 1) % 3] for i in range(3)]
    e2 = dot3(d[0], d[0]) + dot3(d[1], d[1]) + dot3(d[2], d[2])
    ell2 = tree_sum(jnp.where(mask, e2, 0.0)) / jnp.maximum(3.0 * jnp.sum(mask), 1.0)
    return delta, ell2


@kernel(static_argnums=0)
def _price(base_price, VS, pairs, params, corners, mask):
    out = base_price(VS, pairs, params)  # (5, K)
    out = jax.lax.optimization_barrier(out)  # no fusion across: the same bits with per-pair params
    pos, moving = ring_positions(VS, pairs, corners)
    delta, ell2 = jax.vmap(area_change)(out[:3].T, pos, moving, mask)
    tiny = jnp.finfo(ell2.dtype).tiny
    term = jnp.where(ell2 > tiny, delta * delta / jnp.maximum(ell2, tiny), 0.0)
    cost = out[3] + params["area_weight"] * term
    return jnp.concatenate([out[:3], cost[None], out[4:5], out[3:4], delta[None]], 0)


@dataclasses.dataclass(frozen=True)
class AreaTerm(Term):
    """``base`` with λ·ΔS²/ℓ² added, λ = ``area_weight`` ≥ 0. Cost parts: the base model's cost
    (``"base"``) and the signed area change ΔS (``"area"``, normalised units²)."""

    support: ClassVar[str] = "ring"
    uses_ring: ClassVar[bool] = True
    ring_dead: ClassVar[bool] = True
    parts: ClassVar[tuple[str, ...]] = ("base", "area")
    added: ClassVar[str] = "λ·area term"

    area_weight: float = 0.0

    def __post_init__(self):
        require_nonnegative(self, "area_weight")
        if self.base.parts:  # a term added already (regularize)
            raise ValueError(f"area_weight cannot be combined with another added term ({self.base.name!r} has "
                             f"the cost parts {', '.join(self.base.parts)}): give area_weight or regularize, "
                             "not both")
        if self.base.uses_ring or not hasattr(type(self.base), "price_kernel"):
            raise ValueError(f"area_weight cannot wrap {self.base.name!r}: it adds to a pair model without "
                             "cost parts (method='qem')")

    def kernel_params(self) -> dict:
        return {**self.base.kernel_params(), "area_weight": np.asarray(self.area_weight, DTYPE)}

    def price(self, VS, pairs, params, rings=None):
        return _price(self.base.price_kernel, VS, pairs, params, rings.corners, rings.mask)

    def price_at_kept(self, VS, pairs, params, rings=None):
        """The term at the kept vertex, added to the base's price there (`at_kept`)."""
        return _price(self.base.at_kept_kernel, VS, pairs, params, rings.corners, rings.mask)

    def describe(self) -> dict:
        return {**self.base.describe(), "area_weight": self.area_weight}
