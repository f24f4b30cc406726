"""Cost models, one module each, and the registry `simplify(method=...)` dispatches through.

A new method is one module (a `CostModel` subclass) plus one line in REGISTRY. TERMS are wrappers that
add a term to whichever model runs, switched on by their keyword of `simplify` (a non-zero value).
"""
from __future__ import annotations

import dataclasses

from .base import CostModel as CostModel
from .base import MeshInput as MeshInput
from .base import MeshView as MeshView
from .area import Area
from .attributes import AttributeQEM
from .area_term import AreaTerm
from .esqem import ESQEM
from .line import LineQEM
from .probabilistic import ProbabilisticQEM
from .qem import QEM
from .regularize import Regularized

REGISTRY: dict[str, type[CostModel]] = {
    "qem": QEM,
    "esqem": ESQEM,
    "area": Area,
    "line": LineQEM,
    "probabilistic": ProbabilisticQEM,
}
TERMS = {
    "regularize": Regularized,
    "area_weight": AreaTerm,
}


def methods() -> tuple[str, ...]:
    """The names `simplify(method=...)` accepts."""
    return tuple(REGISTRY)


def register(cls: type[CostModel]) -> type[CostModel]:
    """Add a model class under its ``name`` (usable as a class decorator). Refuses to replace one."""
    if not cls.name or cls.name in REGISTRY:
        raise ValueError(f"a cost model needs a new, non-empty name; got {cls.name!r}")
    REGISTRY[cls.name] = cls
    return cls


# a method's model over appearance attributes, built when `simplify` keeps attributes with a weight > 0
WITH_ATTRIBUTES: dict[str, type[CostModel]] = {"qem": AttributeQEM}


def build(method: str, settings: dict, terms: dict, weights=None) -> CostModel:
    """The model for ``method`` with the settings it has fields for (others are not its business), wrapped
    by each term of TERMS whose value in ``terms`` is non-zero. ``weights``: per attribute channel (m,),
    for the method's model over appearance attributes (`WITH_ATTRIBUTES`); None: positions only."""
    if method not in REGISTRY:
        raise ValueError(f"unknown method {method!r}; choose from {methods()}")
    cls = REGISTRY[method]
    if weights is not None:
        if method not in WITH_ATTRIBUTES:
            raise ValueError(f"method {method!r} has no cost model over attributes; "
                             f"choose from {tuple(WITH_ATTRIBUTES)}")
        cls = WITH_ATTRIBUTES[method]
        settings = dict(settings, channels=len(weights), weights=tuple(float(w) for w in weights))
    fields = {f.name for f in dataclasses.fields(cls)}
    model = cls(**{k: v for k, v in settings.items() if k in fields})
    for key, value in terms.items():
        if key not in TERMS:
            raise ValueError(f"unknown term {key!r}; choose from {tuple(TERMS)}")
        if value:
            model = TERMS[key](model, value)
    return model
