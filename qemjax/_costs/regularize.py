"""Triangle-shape regularisation: a ring term added to any model's cost (``regularize=λ``).

Quadric costs are blind to triangle shape, so simplified meshes collect slivers. This term charges a
contraction for the worst triangle it creates:

    cost = base cost + λ · ℓ² · max_f (1 − q_f)²,    q_f = 4√3·area_f / (sum of squared edge lengths of f)

over the faces f the contraction leaves around the new vertex x (its ring, `ring.Rings`); q is 1 for an
equilateral triangle and 0 for a degenerate one, and ℓ² is the mean squared edge length of those faces,
so the term is a squared length like the quadric error and λ is dimensionless. The position is the base
model's; the term changes only which contractions go first. It reads the faces around the pair, so its
support is "ring": a contraction changes the cost of every pair in the new vertex's 1-ring.

Peers have the same knob: meshoptimizer's ``Regularize`` flag, pymeshlab's quality threshold.
"""
from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

from .._kernels.lazy import jax, jnp  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._kernels.batching import DTYPE
from .._kernels import kernel
from .._kernels.fixed import cross3, dot3, norm3, tree_sum
from .base import Term, require_nonnegative

_SQRT3_2 = 2.0 * math.sqrt(3.0)


def shape_term(x, corners_pos, mask):
    """One pair: x (3,) the new position, corners_pos (R,3,3) positions of ``[v, c1, c2]`` per ring face,
    mask (R,) bool. Returns ℓ² · max (1 − q)² over the faces (x, c1, c2); 0 for an empty ring."""
    c1, c2 = corners_pos[:, 1], corners_pos[:, 2]
    e0, e1, e2 = c1 - x, c2 - c1, x - c2
    l2 = dot3(e0, e0) + dot3(e1, e1) + dot3(e2, e2)  # fixed order: `_kernels.fixed`
    twice_area = norm3(cross3(e0, c2 - x))
    tiny = jnp.finfo(l2.dtype).tiny
    q = jnp.where(l2 > tiny, _SQRT3_2 * twice_area / jnp.maximum(l2, tiny), 0.0)
    bad = jnp.where(mask, (1.0 - jnp.clip(q, 0.0, 1.0)) ** 2, 0.0)
    nf = jnp.sum(mask)
    ell2 = tree_sum(jnp.where(mask, l2, 0.0)) / jnp.maximum(3.0 * nf, 1.0)
    return ell2 * jnp.max(bad)


@kernel(static_argnums=0)
def _price(base_price, VS, pairs, params, corners, mask):
    out = base_price(VS, pairs, params)  # (5 + parts, K)
    out = jax.lax.optimization_barrier(out)  # no fusion across: the same bits with per-pair params
    pos = jnp.take(VS[:, :3], corners.reshape(-1), axis=0, mode="clip").reshape(corners.shape + (3,))
    shape = jax.vmap(shape_term)(out[:3].T, pos, mask)
    cost = out[3] + params["regularize"] * shape
    return jnp.concatenate([out[:3], cost[None], out[4:5], out[3:4], shape[None]], 0)


@dataclasses.dataclass(frozen=True)
class Regularized(Term):
    """``base`` with the shape term above, weighted by ``regularize`` (λ ≥ 0). Cost parts: the base
    model's cost (``"base"``) and the unweighted shape term (``"shape"``)."""

    support: ClassVar[str] = "ring"
    uses_ring: ClassVar[bool] = True
    parts: ClassVar[tuple[str, ...]] = ("base", "shape")
    added: ClassVar[str] = "λ·shape term"

    regularize: float = 0.0

    def __post_init__(self):
        require_nonnegative(self, "regularize")
        if self.base.parts:
            raise ValueError(f"regularize cannot wrap {self.base.name!r}, which has cost parts already")
        if not hasattr(type(self.base), "price_kernel"):
            raise ValueError(f"regularize cannot wrap {self.base.name!r}, whose price needs its ring")

    def kernel_params(self) -> dict:
        return {**self.base.kernel_params(), "regularize": np.asarray(self.regularize, DTYPE)}

    def price(self, VS, pairs, params, rings=None):
        return _price(self.base.price_kernel, VS, pairs, params, rings.corners, rings.mask)

    def price_at_kept(self, VS, pairs, params, rings=None):
        """The term at the kept vertex, added to the base's price there (`at_kept`)."""
        return _price(self.base.at_kept_kernel, VS, pairs, params, rings.corners, rings.mask)

    def describe(self) -> dict:
        return {**self.base.describe(), "regularize": self.regularize}
