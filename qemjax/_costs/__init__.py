"""Cost models, one module each, and the registry `simplify(method=...)` dispatches through.

A method is a frozen dataclass (`base.Method`) whose fields are all its settings; `simplify(method=...)`
takes the object or its registered name. A new method is one module (a `Method` subclass) plus one call
of `register` (``qemjax.register_method``). TERMS are wrappers that add a term to whichever method runs,
switched on by the method's field of that name (a non-zero value).
"""
from __future__ import annotations

import dataclasses

from .._options import KEYWORDS, run_setting_group

from .base import CostModel as CostModel
from .base import MeshInput as MeshInput
from .base import MeshView as MeshView
from .base import Method as Method
from .area import AreaDifference
from .attributes import AttributeQEM
from .area_term import AreaTerm
from .esqem import ESQEM
from .line import LineQEM
from .probabilistic import ProbabilisticQEM
from .qem import QEM
from .regularize import Regularized

REGISTRY: dict[str, type[Method]] = {
    "qem": QEM,
    "esqem": ESQEM,
    "area": AreaDifference,
    "line": LineQEM,
    "probabilistic": ProbabilisticQEM,
}
BUILT_IN = tuple(REGISTRY)  # the methods every process has; `register` adds to REGISTRY in its own process only
# named configurations of a method: ``method="accurate"`` is ``QEM.accurate()``
PRESETS = {
    "default": QEM.default,
    "classic": QEM.classic,
    "accurate": QEM.accurate,
}
DEFAULT = "default"  # what `simplify` runs without a method (`QEM.default`)
TERMS = {
    "regularize": Regularized,
    "area_weight": AreaTerm,
}


def methods() -> tuple[str, ...]:
    """The names `simplify(method=...)` accepts: the registered methods, then the presets."""
    return tuple(REGISTRY) + tuple(PRESETS)


def register(name, cls: type[Method] | None = None):
    """Register a method class under ``name`` (``register(cls)`` or ``@register`` use ``cls.name``), so
    ``simplify(method=name)`` means ``cls()``; its fields become sweep keys, config keys and command-line
    options. Refuses a name already taken, a class that is not a frozen dataclass `Method`, and one with a field
    named like a `Topology` or `Attributes` setting or like one of `simplify`'s own keywords (``ratio``,
    ``measure``, ...)."""
    if cls is None and isinstance(name, type):
        name, cls = name.name, name
    if cls is None and isinstance(name, str):  # ``@register("x")`` over a class: it said "got None"
        raise ValueError(f"register_method({name!r}) needs the class: register_method({name!r}, cls), or "
                         "@register_method over a class whose name (a ClassVar) is the method's name")
    if not isinstance(cls, type) or not issubclass(cls, Method) or not dataclasses.is_dataclass(cls) \
            or not cls.__dataclass_params__.frozen:
        raise ValueError(f"a method must be a frozen dataclass subclass of qemjax.QEM (or another method), "
                         f"got {cls!r}")
    if not isinstance(name, str) or not name or name in REGISTRY or name in PRESETS:
        raise ValueError(f"a method needs a new, non-empty name; got {name!r} (taken: {methods()})")
    for f in dataclasses.fields(cls):  # a field named like a run setting could not be given flat
        group = run_setting_group(f.name) if f.init else None
        if group:
            raise ValueError(f"method {name!r} has a field {f.name!r}, which is a {group} setting")
        if f.init and f.name in KEYWORDS:  # `simplify(ratio=...)` is the target, and the CLI's --ratio clashed
            raise ValueError(f"method {name!r} has a field {f.name!r}, which is one of simplify's own keywords")
    REGISTRY[name] = cls
    return cls


def resolve(method) -> Method:
    """The method object for ``method``: a name of `methods` (its defaults) or a method object (as is).
    ValueError for a method that computes no cost (`Method` itself, or a subclass of it that does not
    implement ``init_state``, ``price`` and ``merge``): the run failed on a bare NotImplementedError."""
    if isinstance(method, str) and method in REGISTRY:
        method = REGISTRY[method]()
    elif isinstance(method, str) and method in PRESETS:
        method = PRESETS[method]()
    elif isinstance(method, type) and issubclass(method, Method):
        method = method()
    if not isinstance(method, Method):
        raise ValueError(f"unknown method {method!r}; choose from {methods()} or pass a method object "
                         "such as qemjax.QEM(...)")
    missing = [f for f in ("init_state", "price", "merge") if getattr(type(method), f) is getattr(CostModel, f)]
    if missing:
        raise ValueError(f"method {type(method).__name__} computes no cost: it does not implement "
                         f"{', '.join(missing)} (subclass qemjax.QEM, or another method, to add settings to its "
                         "cost)")
    return method


def name_of(method: Method) -> str:
    """The name a method object runs under: its class's registered name (a subclass made in a script and
    not registered runs under its parent's)."""
    for name, cls in REGISTRY.items():
        if type(method) is cls:
            return name
    return method.name


def shown_name(method: Method, given=None) -> str:
    """The name a result (``stats["method"]``), an error and a sweep's table give ``method``: ``given``
    when it is a name of `methods` (what the call named: ``"default"`` when it named none, also with
    settings replaced by name); else the preset's (``"default"``, ``"accurate"``) for an object equal to
    a preset that is not its class's defaults; else its registered name (`name_of`)."""
    if isinstance(given, str) and given in methods():
        return given
    name = name_of(method)
    cls = REGISTRY.get(name)
    if cls is not None and method == cls():
        return name
    for preset, make in PRESETS.items():
        if method == make():
            return preset
    return name


def label(method: Method) -> str:
    """`shown_name` and, unless the object equals that preset, the fields that differ from its class's
    defaults: ``"default"``, ``"toy(extra=3.0)"``, ``"esqem(curvature_weight=0.1)"``."""
    name = shown_name(method)
    if name in PRESETS:
        return name
    changed = method.changed()
    return name + ("(" + ", ".join(f"{k}={v!r}" for k, v in changed.items()) + ")" if changed else "")


# a method's model over appearance attributes, built when `simplify` keeps attributes with a weight > 0
WITH_ATTRIBUTES: dict[type, type[CostModel]] = {QEM: AttributeQEM}


def build(method: Method, weights=None) -> CostModel:
    """The cost model a run prices with: ``method`` itself, over appearance attributes when ``weights``
    (per attribute channel (m,)) is given (`WITH_ATTRIBUTES`), wrapped by each term of TERMS whose field
    is non-zero."""
    model = method
    if weights is not None:
        if type(method) not in WITH_ATTRIBUTES:
            raise ValueError(f"method {method.name!r} has no cost model over attributes; use qemjax.QEM")
        fields = {f.name: getattr(method, f.name) for f in dataclasses.fields(method)}
        model = WITH_ATTRIBUTES[type(method)](**fields, channels=len(weights),
                                               weights=tuple(float(w) for w in weights))
    for key, term in TERMS.items():
        value = getattr(method, key)
        if value:
            model = term(model, value)
    return model
