"""Every setting under one flat name, read from the dataclass fields that hold it.

A run's settings live in three frozen objects: the method (`qemjax.QEM`, `qemjax.ESQEM`, ... : every field of
a registered class, `_costs.REGISTRY`), `Topology` and `Attributes`. Each field also has a flat name, its
own (``boundary_weight``, ``flip_angle``, ``attribute_weights``), and a dotted one (``method.boundary_weight``,
``topology.flip_angle``). The command line's options, a sweep's grid and config keys, and the flat keywords
that `simplify` still accepts all come from here, typed by the fields' real types (`typing.get_type_hints`),
so a field added to a method is an option everywhere with no other edit.
"""
from __future__ import annotations

import dataclasses
import difflib
import functools
import typing
from typing import Any

from .. import _costs, _schedulers
from .._options import KEYWORDS as KEYWORDS  # `simplify`'s keywords besides the settings
from .._options import Attributes, Schedule, Topology

GROUPS = {"topology": Topology, "attributes": Attributes}  # and "method": the registered classes


@dataclasses.dataclass(frozen=True)
class Option:
    """One setting: its flat name, the object that holds it (``"method"``, ``"topology"``, ``"attributes"``),
    its type (the field's resolved annotation), its default (the first owner's) and, for a method's field,
    the names of the methods that have it."""

    name: str
    group: str
    type: Any
    default: Any
    owners: tuple[str, ...] = ()


def _fields(cls) -> list[tuple[dataclasses.Field, Any]]:
    hints = typing.get_type_hints(cls)
    return [(f, hints.get(f.name, Any)) for f in dataclasses.fields(cls) if f.init]


def options() -> dict[str, Option]:
    """flat name → `Option`, for every field of `Topology`, `Attributes` and every registered method
    (a method registered later is included: the table is cached per state of the registry)."""
    return dict(_options(tuple(_costs.REGISTRY.items())))


@functools.lru_cache(maxsize=16)
def _options(registry: tuple) -> dict[str, Option]:
    out: dict[str, Option] = {}
    for group, cls in GROUPS.items():
        for f, hint in _fields(cls):
            out[f.name] = Option(f.name, group, hint, f.default)
    for name, cls in registry:  # (`_costs.register` refuses a field that shadows a run setting)
        for f, hint in _fields(cls):
            old = out.get(f.name)
            if old is None:
                out[f.name] = Option(f.name, "method", hint, f.default, (name,))
            else:
                out[f.name] = dataclasses.replace(old, owners=old.owners + (name,))
    return out


def scheduler_of(scheduler, schedule=None) -> tuple[str, Schedule]:
    """(scheduler name, the parallel scheduler's `Schedule`) from ``scheduler`` ('parallel', 'greedy' or
    a `Schedule`: the parallel scheduler with those tunables) and the old ``schedule`` keyword."""
    if isinstance(scheduler, Schedule):
        if schedule is not None:
            raise ValueError("give the Schedule once: scheduler=qemjax.Schedule(...)")
        return "parallel", scheduler
    if scheduler not in _schedulers.names():
        raise ValueError(f"unknown scheduler {scheduler!r}; choose from {_schedulers.names()} or a "
                         "qemjax.Schedule")
    if schedule is None:
        schedule = Schedule()
    elif not isinstance(schedule, Schedule):
        raise ValueError(f"schedule must be a qemjax.Schedule, got {type(schedule).__name__}")
    return scheduler, schedule


def apply(method, topology, attributes, flat: dict) -> tuple:
    """(method object, `Topology`, `Attributes`) for a call's ``method``, ``topology``, ``attributes`` and
    its settings given by flat or dotted name (``flat``; ``preset=NAME`` picks the named method). A setting
    given by name replaces the object's field, so ``method="accurate", refit=0`` is the accurate preset
    without its re-fit. TypeError for an unknown name, flat or dotted (``topology.flip_angel``, or
    ``method.X`` where no method has a field X), as Python's for an unknown keyword; ValueError for a setting
    of another method."""
    given: dict[str, dict] = {"method": {}, "topology": {}, "attributes": {}}
    flat = dict(flat)
    preset = flat.pop("preset", None)
    table = options() if flat else {}
    for key, value in flat.items():
        group, dot, field = key.partition(".")
        if dot and group in given:
            given[group][field] = value
        elif not dot and key in table:
            given[table[key].group][key] = value
        else:
            raise TypeError(unknown_setting(key, table))
    if preset is not None:
        if not (isinstance(method, str) and method in ("qem", _costs.DEFAULT)):
            raise ValueError(f"preset={preset!r} names a method: give it as method={preset!r} alone")
        if preset not in _costs.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; choose from {tuple(_costs.PRESETS)}")
        method = preset
    m = _costs.resolve(method)
    for group in given:  # a dotted name no object has: unknown, as a flat one is (only dotted ones get here)
        fields = field_names(group, m)
        unknown = [k for k in given[group] if k not in fields and not (
            group == "method" and k in table and table[k].group == "method")]  # another method's: below
        if unknown:
            key = f"{group}.{unknown[0]}"
            # matched by the field alone (the group's prefix would make every name of the group look close);
            # the groups' fields are distinct, so each names one dotted name
            full = {n.partition(".")[2]: n for n in dotted_names(m)}
            hint = did_you_mean(unknown[0], full, show=lambda f: repr(full[f])) or (
                f"; qemjax.{GROUPS[group].__name__} has {list(fields)}" if group in GROUPS
                else f" (method {_costs.shown_name(m, method)!r} has no such field)")
            raise TypeError(f"unknown {group} setting {key!r}{hint}")
    if given["method"]:
        names = {f.name for f in dataclasses.fields(m)}
        foreign = sorted(set(given["method"]) - names)
        if foreign:
            owners = {k: table[k].owners if k in table else () for k in foreign}
            raise ValueError("; ".join(f"{k} is not a setting of method {_costs.shown_name(m, method)!r}"
                                       + (f" (it is one of {', '.join(owners[k])})" if owners[k] else "")
                                       for k in foreign))
        m = dataclasses.replace(m, **given["method"])
    if topology is None:
        topology = Topology()
    elif not isinstance(topology, Topology):
        raise ValueError(f"topology must be a qemjax.Topology, got {type(topology).__name__}")
    if given["topology"]:
        topology = dataclasses.replace(topology, **given["topology"])
    if not isinstance(attributes, Attributes):
        attributes = Attributes(attributes=attributes)
    if given["attributes"]:
        attributes = dataclasses.replace(attributes, **given["attributes"])
    return m, topology, attributes


def did_you_mean(key: str, names, show=repr) -> str:
    """``"; did you mean 'ratio'?"``: the names close to a misspelt ``key`` (each as ``show`` writes it), or
    '' when none is close. The one hint for every unknown name: keywords, options, config keys."""
    names = list(names)
    close = difflib.get_close_matches(key, names, n=3, cutoff=0.6)
    if close:  # the nearly as close only: 'boundary_weight' for 'boundry_weight', not 'memory_weight' too
        best = difflib.SequenceMatcher(None, key, close[0]).ratio()
        close = [c for c in close if difflib.SequenceMatcher(None, key, c).ratio() >= best - 0.1]
    return f"; did you mean {' or '.join(map(show, close))}?" if close else ""


def unknown_setting(key: str, table: dict | None = None, keywords=KEYWORDS, refused=(), who="simplify") -> str:
    """One line for a keyword that names nothing: the close names first (``did you mean 'ratio'?``), among
    ``who``'s ``keywords`` and the settings' flat names (and, for a dotted ``key``, the dotted ones), leaving
    out the ``refused`` ones (`lod_chain` takes no ``ratio``, so it suggests none)."""
    table = options() if table is None else table
    names = list(keywords) + sorted(table) + (dotted_names() if "." in key else [])
    hint = did_you_mean(key, [n for n in names if n not in refused]) or \
        f" (help(qemjax.{who}) lists the keywords; a method's settings are its fields, qemjax.QEM(...))"
    return f"unknown setting {key!r}{hint}"


def dotted_names(method=None) -> list[str]:
    """``topology.X`` and ``attributes.X`` for each field, and ``method.X`` for the fields of ``method`` (None:
    of every registered method)."""
    fields = field_names("method", method) if method is not None else \
        [k for k, o in options().items() if o.group == "method"]
    return [f"method.{f}" for f in fields] + [f"{g}.{f}" for g in GROUPS for f in field_names(g)]


def field_names(group: str, obj=None) -> tuple[str, ...]:
    """The fields of a group's object (``obj``'s, for a method)."""
    if group == "method":
        return tuple(f.name for f in dataclasses.fields(obj))
    return tuple(f.name for f in dataclasses.fields(GROUPS[group]))


RUN_TYPES = {"method": str, "scheduler": str, "topology": Topology, "attributes": Any,
             "max_error": typing.Optional[float], "max_distance": typing.Optional[float],
             "max_distance_rel": typing.Optional[float], "preset": str, "schedule": Schedule,
             "measure": typing.Optional[bool]}  # measure: `_pipeline.measure` (None: with a re-fit)


def grid_keys() -> tuple[str, ...]:
    """The keys a sweep's grid (and a config file's) may vary by name: the run keywords of `simplify`
    (but the target, progress and feature edges), then every setting's flat name. Dotted names
    (``method.curvature_weight``) are valid too (`key_type`)."""
    return tuple(RUN_TYPES) + tuple(k for k in options() if k not in RUN_TYPES)


def key_type(key: str):
    """The real type of a grid key: a run keyword's, a setting's field type by flat name, or by dotted
    name (``method.X``: X's type in the methods that have it; ``topology.X``, ``attributes.X``). KeyError
    for a key that names nothing."""
    if key in RUN_TYPES:
        return RUN_TYPES[key]
    group, dot, field = key.partition(".")
    table = options()
    if not dot:
        return table[key].type
    if group == "method" and field in table and table[field].group == "method":
        return table[field].type
    if group in GROUPS:
        for f, hint in _fields(GROUPS[group]):
            if f.name == field:
                return hint
    raise KeyError(key)
