"""Methods and settings as data: method objects, registration from outside, and one source of truth for
the settings' names and types (the command line, config files and sweeps are generated from the fields)."""
from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
import pytest

import qemjax
from qemjax import _cli, _costs, shapes
from qemjax._pipeline import flat as _flat
from qemjax._sweep import run as _sweep, config as _sweep_config


# -- a method from outside the package: QEM with a point quadric at each vertex ------------------------

@dataclasses.dataclass(frozen=True)
class Damped(qemjax.QEM):
    """QEM whose vertex quadrics also hold ``damp`` × the squared distance to the vertex (a field of its
    own; the rest is QEM's)."""

    name: ClassVar[str] = "damped"
    damp: float = 0.1

    def init_state(self, mesh):
        q = super().init_state(mesh).copy()
        q[:, [0, 3, 5]] += np.float32(self.damp)  # A += damp·I in the vertex's own frame
        return q


@pytest.fixture
def damped():
    qemjax.register_method("damped", Damped)
    yield Damped
    del _costs.REGISTRY["damped"]


@pytest.fixture(scope="module")
def ball():
    return shapes.bumpy_sphere(2)


def same(a, b) -> bool:
    return np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_a_method_registered_from_outside_runs_everywhere(damped, ball, tmp_path):
    plain = qemjax.simplify(ball, ratio=0.2, method="qem")
    alone = {d: qemjax.simplify(ball, ratio=0.2, method=Damped(damp=d)) for d in (0.0, 0.1, 2.0)}
    assert same(alone[0.0], plain)  # adding nothing changes nothing
    assert not same(alone[2.0], plain)
    assert alone[2.0].stats["model"]["damp"] == 2.0 and alone[2.0].stats["method"] == "damped"
    # by name, and its field by name
    assert same(qemjax.simplify(ball, ratio=0.2, method="damped"), alone[0.1])
    assert same(qemjax.simplify(ball, ratio=0.2, method="damped", damp=2.0), alone[2.0])
    # simplify_batch
    batch = qemjax.simplify_batch(ball, [dict(ratio=0.2, method=Damped(damp=d)) for d in (0.0, 0.1, 2.0)])
    assert all(same(r, alone[d]) for r, d in zip(batch, (0.0, 0.1, 2.0)))
    # a sweep over objects, over its field by name and by dotted name
    by_object = qemjax.sweep({"ball": ball}, {"method": [qemjax.QEM(), Damped(damp=2.0)]}, [0.2],
                             metrics=False, progress=False)
    assert list(by_object["method"]) == ["qem", "damped(damp=2.0)"]
    assert list(by_object["result_sha256"]) == [_sweep.result_hash(plain), _sweep.result_hash(alone[2.0])]
    for key in ("damp", "method.damp"):
        df = qemjax.sweep({"ball": ball}, {"method": ["damped"], key: [0.1, 2.0]}, [0.2], metrics=False,
                          progress=False)
        assert list(df[key]) == [0.1, 2.0]
        assert list(df["result_sha256"]) == [_sweep.result_hash(alone[0.1]), _sweep.result_hash(alone[2.0])]
    # a config file, and the command line
    cfg = tmp_path / "s.toml"
    cfg.write_text('meshes = ["shapes.bumpy_sphere(subdivisions=2)"]\ntargets = [0.2]\nmetrics = false\n'
                   '[grid]\nmethod = ["damped"]\n"method.damp" = [2.0]\n')
    config = _sweep_config.load(cfg)
    df = qemjax.sweep(config.meshes, config.grid, config.targets, metrics=False, progress=False)
    assert list(df["result_sha256"]) == [_sweep.result_hash(alone[2.0])]
    args = _cli._parser().parse_args(["simplify", "in.ply", "out.ply", "--ratio", "0.2", "--method", "damped",
                                      "--damp", "2.0"])
    kw = _cli._simplify_kwargs(args)
    assert kw["damp"] == 2.0 and same(qemjax.simplify(ball, **{**kw, "progress": False}), alone[2.0])


def test_registration_refuses_taken_names_and_non_methods():
    with pytest.raises(ValueError, match="new, non-empty name"):
        qemjax.register_method("qem", Damped)
    with pytest.raises(ValueError, match="frozen dataclass"):
        qemjax.register_method("thing", dict)

    @dataclasses.dataclass(frozen=True)
    class Shadow(qemjax.QEM):  # a field named like a Topology setting: refused at registration (it was
        name = "shadow"        # taken, and every later call that named a setting failed)
        prune: bool = False

    with pytest.raises(ValueError, match="method 'shadow' has a field 'prune', which is a topology setting"):
        qemjax.register_method(Shadow)
    assert "shadow" not in qemjax.methods()
    assert len(qemjax.simplify(qemjax.shapes.icosphere(2), ratio=0.5, boundary_weight=3.0).faces) == 160


def test_registering_a_name_without_its_class_says_how():
    """``@qemjax.register_method("x")`` over a class (a decorator with a name, which register is not) said "a
    method must be a frozen dataclass subclass of qemjax.QEM ..., got None", about a class that is one."""
    with pytest.raises(ValueError, match=r"^register_method\('damped2'\) needs the class: "
                                         r"register_method\('damped2', cls\), or @register_method over a class"):
        @qemjax.register_method("damped2")
        @dataclasses.dataclass(frozen=True)
        class Damped2(qemjax.QEM):
            damp: float = 0.1
    assert "damped2" not in qemjax.methods()


def test_a_method_that_computes_no_cost_is_refused_by_name():
    """`qemjax.Method` itself, or a subclass of it that adds fields but no cost, ran until the cleaned mesh
    asked for its state and failed on a bare NotImplementedError (no message at all)."""
    @dataclasses.dataclass(frozen=True)
    class Bare(qemjax.Method):
        name: ClassVar[str] = "bare"
        weight: float = 1.0

    for method in (qemjax.Method(), qemjax.Method, Bare(weight=2.0)):
        with pytest.raises(ValueError, match=r"^method (Method|Bare) computes no cost: it does not implement "
                                             r"init_state, price, merge \(subclass qemjax.QEM"):
            qemjax.simplify(shapes.icosphere(1), ratio=0.5, method=method)


@pytest.mark.parametrize("field", ["ratio", "target_faces", "measure", "method"])
def test_registration_refuses_a_field_named_like_a_simplify_keyword(field):
    """A method with a field named like one of simplify's own keywords was registered: the field could never be
    given flat (``simplify(ratio=...)`` is the target), and the command line's parser then failed on every
    call in that process (argparse: "conflicting option string: --ratio")."""
    cls = dataclasses.make_dataclass("Clash", [(field, float, 1.0)], bases=(qemjax.QEM,), frozen=True,
                                     namespace={"name": "clash"})
    with pytest.raises(ValueError, match=f"^method 'clash' has a field '{field}', which is one of simplify's own"):
        qemjax.register_method(cls)
    assert "clash" not in qemjax.methods()
    assert _cli.main(["simplify", "--help"]) == 0  # the command line still parses


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_a_count_setting_that_is_no_whole_number_is_named(value):
    """refit, polish and sliver_moves given inf or NaN: Python's OverflowError ("cannot convert float infinity
    to integer", not even a ValueError) or its NaN message, without the setting's name."""
    for name in ("refit", "polish", "sliver_moves"):
        with pytest.raises(ValueError, match=f"^{name} must be a whole number, got"):
            qemjax.QEM(**{name: value})
    with pytest.raises(ValueError, match="^refit must be a whole number"):
        qemjax.simplify(qemjax.shapes.icosphere(1), ratio=0.5, refit=value)


def test_a_setting_of_another_method_is_refused_by_name(ball):
    with pytest.raises(ValueError, match="curvature_weight is not a setting of method 'default'.*esqem"):
        qemjax.simplify(ball, ratio=0.2, curvature_weight=0.5)
    with pytest.raises(TypeError, match="unknown setting 'no_such'"):
        qemjax.simplify(ball, ratio=0.2, no_such=1)
    with pytest.raises(TypeError, match="unknown topology setting"):
        qemjax.simplify(ball, ratio=0.2, **{"topology.no_such": 1})


def test_objects_and_flat_settings_give_the_same_run(ball):
    flat = qemjax.simplify(ball, ratio=0.2, method="esqem", curvature_weight=0.5, flip_angle=60.0,
                           attributes=None)
    objects = qemjax.simplify(ball, ratio=0.2, method=qemjax.ESQEM(curvature_weight=0.5),
                              topology=qemjax.Topology(flip_angle=60.0), attributes=qemjax.Attributes(None))
    assert same(flat, objects)


def test_a_grid_crossing_methods_leaves_out_the_settings_a_method_lacks(ball):
    grid = {"method": ["qem", "esqem"], "split_factor": [None, 1.5]}
    cells = _sweep.expand_grid(grid)
    assert cells == [(("method", "qem"),), (("method", "esqem"), ("split_factor", None)),
                     (("method", "esqem"), ("split_factor", 1.5))]
    peers = _sweep.expand_grid({"method": ["qem", "meshoptimizer"], "boundary_weight": [1.0, 1000.0]})
    assert peers == [(("method", "qem"), ("boundary_weight", 1.0)), (("method", "qem"), ("boundary_weight", 1000.0)),
                     (("method", "meshoptimizer"),)]  # a peer: once, no qemjax setting applies


# -- one source of truth: every field of every method round-trips through the CLI and a config file --

def _value(opt: _flat.Option):
    """A valid value other than the default, of the field's type."""
    special = {"placement": "endpoints", "attributes": ("uv",), "attribute_weights": 0.5, "texture": "t.png",
               "preserve_topology": True, "late_memoryless": 2.0}
    if opt.name in special:
        return special[opt.name]
    if opt.default is None or isinstance(opt.default, bool):
        return not opt.default if isinstance(opt.default, bool) else 0.5
    if isinstance(opt.default, int):
        return opt.default + 1
    if isinstance(opt.default, float):
        return None if type(None) in getattr(opt.type, "__args__", ()) else (0.5 if opt.default != 0.5 else 0.25)
    raise AssertionError(f"no test value for {opt.name} ({opt.type})")


def _cli_text(name: str, v) -> list[str]:
    flag = "--" + name.replace("_", "-")
    if isinstance(v, bool):
        return [flag if v else "--no-" + name.replace("_", "-")]
    return [flag, "none" if v is None else ",".join(v) if isinstance(v, tuple) else str(v)]


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return '"none"'
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, tuple):
        return "[" + ", ".join(f'"{x}"' for x in v) + "]"
    return repr(v)


def _object(owner, name, v):
    extra = {"memoryless": True} if name in ("volume_weight", "memory_weight") else {}
    return _flat.apply(owner, None, "auto", {name: v, **extra})


@pytest.mark.parametrize("name", sorted(_flat.options()))
def test_every_field_round_trips_through_the_cli_and_a_config_file(name, tmp_path):
    opt = _flat.options()[name]
    v = _value(opt)
    owners, ran = opt.owners or ("qem",), 0
    for owner in owners:
        try:
            want = _object(owner, name, v)
        except ValueError:  # a field the subclass inherits but refuses (ESQEM: memoryless)
            continue
        ran += 1
        args = _cli._parser().parse_args(["simplify", "in.ply", "out.ply", "--ratio", "0.5", "--method", owner,
                                          *_cli_text(name, v)])
        kw = _cli._simplify_kwargs(args)
        method = kw.pop("method")
        got = _flat.apply(method, None, "auto", {k: kw[k] for k in kw if k in _flat.options()}
                          | ({"memoryless": True} if name in ("volume_weight", "memory_weight") else {}))
        assert got == want, (name, owner)
        group = {"method": 0, "topology": 1, "attributes": 2}[opt.group]
        assert getattr(got[group], name) == v and type(getattr(got[group], name)) is type(v)
        cfg = tmp_path / f"{owner}.toml"
        cfg.write_text(f'meshes = ["shapes.torus"]\ntargets = [0.5]\n[grid]\nmethod = ["{owner}"]\n'
                       f'{name} = [{_toml(v)}]\n')
        if name == "texture":  # a file, relative to the config's folder (as its meshes are), that must exist
            (tmp_path / v).write_bytes(b"")
            v = str(tmp_path / v)
        grid = _sweep_config.load(cfg).grid
        assert grid[name] == [v] and type(grid[name][0]) is type(v), (name, owner, grid[name])
    assert ran
