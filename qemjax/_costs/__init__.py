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
from .area_term import AreaTerm
from .esqem import ESQEM
from .qem import QEM
from .regularize import Regularized

REGISTRY: dict[str, type[CostModel]] = {
    "qem": QEM,
    "esqem": ESQEM,
    "area": Area,
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


def build(method: str, settings: dict, terms: dict) -> CostModel:
    """The model for ``method`` with the settings it has fields for (others are not its business), wrapped
    by each term of TERMS whose value in ``terms`` is non-zero."""
    if method not in REGISTRY:
        raise ValueError(f"unknown method {method!r}; choose from {methods()}")
    cls = REGISTRY[method]
    fields = {f.name for f in dataclasses.fields(cls)}
    model = cls(**{k: v for k, v in settings.items() if k in fields})
    for key, value in terms.items():
        if key not in TERMS:
            raise ValueError(f"unknown term {key!r}; choose from {tuple(TERMS)}")
        if value:
            model = TERMS[key](model, value)
    return model
