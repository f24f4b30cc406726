"""The cost-model seam: the registry, stop reasons, a ring model with refreshed state, regularisation, and the
manifold rules greedy shares with the parallel scheduler (against an independent set-based reference)."""
from __future__ import annotations

import dataclasses
import math
import warnings
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import assert_valid, one_pair_per_round

import qemjax
from qemjax import _costs, shapes
from qemjax._costs import regularize as reg
from qemjax._costs.qem import QEM
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers import greedy

SCHEDULERS = ["parallel", "greedy"]
rng = np.random.default_rng(11)


def _simplify(*args, **kw):
    """simplify, returning (result, the messages of the warnings it gave)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = qemjax.simplify(*args, **kw)
    return r, [str(w.message) for w in caught]


# -- registry and options ------------------------------------------------------------------------------

def test_methods_come_from_the_registry():
    assert qemjax.methods() == tuple(_costs.REGISTRY) + tuple(_costs.PRESETS) and "qem" in qemjax.methods()
    with pytest.raises(ValueError, match="unknown method 'nope'.*qem"):
        qemjax.simplify(shapes.icosphere(1), ratio=0.5, method="nope")


def test_schedule_is_frozen_and_validated():
    s = qemjax.Schedule()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.gate = 2.0
    for bad in (dict(gate=0.5), dict(tail=0), dict(max_passes=1.5), dict(free_cost=-1.0)):
        with pytest.raises(ValueError, match="Schedule"):
            qemjax.Schedule(**bad)
    with pytest.raises(ValueError, match="qemjax.Schedule"):
        qemjax.simplify(shapes.icosphere(1), ratio=0.5, schedule={"gate": 1.0})


# -- stop reasons --------------------------------------------------------------------------------------

@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_stop_reason_target(scheduler):
    r, warned = _simplify(shapes.bumpy_sphere(3), target_faces=300, scheduler=scheduler)
    assert r.stop_reason == "target" and len(r.faces) == 300 and not warned


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_stop_reason_target_on_an_odd_target_of_a_closed_mesh(scheduler):
    """A closed manifold loses faces in pairs: one face above an odd target is the documented stop."""
    r, warned = _simplify(shapes.bumpy_sphere(3), target_faces=301, scheduler=scheduler)
    assert r.stop_reason == "target" and len(r.faces) == 302 and not warned


def test_stop_reason_unchanged():
    V, F = shapes.icosphere(1)
    r, warned = _simplify((V, F), target_faces=len(F))
    assert r.stop_reason == "unchanged" and len(r.faces) == len(F) and r.stats["contractions"] == 0
    assert not warned


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_stop_reason_max_error(scheduler):
    mesh = shapes.bumpy_sphere(3)
    full = qemjax.simplify(mesh, target_faces=100, scheduler=scheduler)
    limit = full.max_error / 50
    r, warned = _simplify(mesh, max_error=limit, scheduler=scheduler)  # no face target: no warning
    assert r.stop_reason == "max_error" and not warned and np.all(r.history.costs <= limit)
    r, warned = _simplify(mesh, max_error=limit, target_faces=100, scheduler=scheduler)
    assert r.stop_reason == "max_error" and len(r.faces) > 100
    assert len(warned) == 1 and "cost more than max_error" in warned[0]
    assert r.stats["blocked_by"]["max_error"] > 0


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_stop_reason_blocked_names_the_rule(scheduler):
    """A closed sphere cannot go below a tetrahedron in manifold mode: the link condition holds it."""
    r, warned = _simplify(shapes.icosphere(1), target_faces=1, scheduler=scheduler)
    assert r.stop_reason == "blocked" and len(r.faces) == 4
    assert r.stats["blocked_by"]["topology"] > 0 and r.stats["rejected_by"]["topology"] > 0
    assert len(warned) == 1 and "stopped at 4 faces" in warned[0] and "topology" in warned[0]
    assert_valid(r, 4)


# -- a ring model with refreshed state, registered from outside ---------------------------------------

def _area_around(V, F, n):
    """(n,) sum of the areas of the faces at each vertex (float64)."""
    a = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    return np.bincount(F.reshape(-1), np.repeat(a, 3), minlength=n)


@dataclasses.dataclass(frozen=True)
class _AreaQEM(QEM):
    """QEM plus one derived number per vertex, the area around it, kept up to date only by `refresh`
    (merge leaves it 0), and reported as the vertex error so that the test can read it back."""

    name: ClassVar[str] = "test-area-qem"
    width: ClassVar[int] = 11
    support: ClassVar[str] = "ring"

    def init_state(self, mesh):
        q = super().init_state(mesh)
        return np.concatenate([q, _area_around(mesh.V.astype(np.float64), mesh.F, len(mesh.V))[:, None]],
                              1).astype(np.float32)

    def merge(self, VS, pairs, x, params):
        q = super().merge(VS, pairs, x, params)
        return jnp.concatenate([q, jnp.zeros((q.shape[0], 1), q.dtype)], 1)

    def refresh(self, view, verts):
        w, f = view.faces.around(verts)
        F = view.faces.F[f]
        P = view.rows[:, :3].astype(np.float64)
        a = 0.5 * np.linalg.norm(np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]), axis=1)
        area = np.bincount(w, a, minlength=len(verts))
        return np.concatenate([view.rows[verts, 3:13], area[:, None]], 1)

    def vertex_error(self, state):
        return state[:, 10].astype(np.float64)


@pytest.fixture
def area_model():
    _costs.register(_AreaQEM)
    try:
        yield _AreaQEM.name
    finally:
        del _costs.REGISTRY[_AreaQEM.name]


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_a_registered_model_runs_and_its_refresh_keeps_state_current(area_model, scheduler):
    assert area_model in qemjax.methods()
    V, F = shapes.bumpy_sphere(3)
    r = qemjax.simplify((V, F), target_faces=200, method=area_model, scheduler=scheduler)
    assert_valid(r, 200, V, F)
    # the same contractions as plain QEM (the extra state does not enter the cost)
    plain = qemjax.simplify((V, F), target_faces=200, scheduler=scheduler, method="qem")
    assert np.array_equal(r.faces, plain.faces)
    # every output vertex's state is the area around it in the output mesh: refreshed, not merged
    want = _area_around(r.vertices, r.faces, len(r.vertices))
    np.testing.assert_allclose(r.vertex_error, want, rtol=2e-4, atol=1e-7)


# -- regularisation --------------------------------------------------------------------------------------

def _quality(p):
    """4√3·area / (sum of squared edge lengths) of triangles p (k,3,3)."""
    e = [p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(e[0], -e[2]), axis=1)
    return 4 * math.sqrt(3) * area / sum(np.sum(x * x, 1) for x in e)


def test_shape_term_matches_float64_reference():
    with jax.enable_x64(True):
        for R in (16, 32):
            for _ in range(20):
                k = int(rng.integers(0, R + 1))
                pos = rng.normal(size=(R, 3, 3))
                mask = np.arange(R) < k
                x = rng.normal(size=3)
                got = float(reg.shape_term(jnp.asarray(x), jnp.asarray(pos), jnp.asarray(mask)))
                if k == 0:
                    assert got == 0.0
                    continue
                tri = np.stack([np.broadcast_to(x, (k, 3)), pos[:k, 1], pos[:k, 2]], 1)
                q = _quality(tri)
                l2 = np.mean([np.sum((tri[:, i] - tri[:, (i + 1) % 3]) ** 2, 1) for i in range(3)])
                np.testing.assert_allclose(got, l2 * np.max((1 - q) ** 2), rtol=1e-10)


def _sliver_fraction(r, degrees=10.0):
    V, F = r.vertices, r.faces
    p = V[F]
    angles = []
    for i in range(3):
        u, w = p[:, (i + 1) % 3] - p[:, i], p[:, (i + 2) % 3] - p[:, i]
        c = np.sum(u * w, 1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return float(np.mean(np.min(angles, 0) < degrees))


def test_regularize_reduces_slivers_and_does_not_recompile():
    mesh = shapes.bumpy_sphere(4)
    plain = dict(quality_threshold=0.0, sliver_moves=0)  # the default's other sliver remedies off
    base = qemjax.simplify(mesh, ratio=0.05, **plain)
    with pytest.warns(UserWarning, match="setting regularize turns off the default method's memoryless"):
        r1 = qemjax.simplify(mesh, ratio=0.05, regularize=0.1, **plain)
        r2 = qemjax.simplify(mesh, ratio=0.05, regularize=0.3, **plain)
    assert_valid(r1, len(base.faces), mesh.vertices, mesh.faces)
    assert r1.stats["model"]["regularize"] == 0.1
    assert _sliver_fraction(r2) < _sliver_fraction(base)
    assert r2.stats["compilations"] == 0  # a new λ is a new array, not a new kernel


@pytest.mark.parametrize("seed", [0, 4])
def test_ring_support_parallel_one_pair_per_round_is_greedy(seed):
    """With a ring term, both schedulers must re-cost the pairs in the 1-ring of each new vertex: gated to
    one pair per round, the parallel scheduler then makes greedy's contractions in greedy's order."""
    mesh = shapes.bumpy_sphere(2, seed=seed)
    with pytest.warns(UserWarning, match="setting regularize turns off the default method's memoryless"):
        g = qemjax.simplify(mesh, target_faces=60, scheduler="greedy", regularize=0.2)
        p = qemjax.simplify(mesh, target_faces=60, schedule=one_pair_per_round(), regularize=0.2,
                            quality_threshold=0.0)  # the shape term is the parallel rounds' alone
    assert len(p.history.pairs) == len(g.history.pairs)
    assert np.array_equal(np.sort(p.history.pairs, 1), np.sort(g.history.pairs, 1))
    np.testing.assert_allclose(p.history.costs, g.history.costs, rtol=1e-4, atol=1e-10)


# -- greedy's manifold rule against an independent set-based reference ---------------------------------

def _reference_link_ok(F, a, b):
    """Garland & Heckbert's greedy as first written here (Python sets): the pair is a manifold edge, its
    endpoints' common neighbours are exactly its faces' apexes, it does not join two boundaries through an
    interior edge, and no apex of an interior edge has degree 3."""
    vfaces = {}
    for f, tri in enumerate(F.tolist()):
        for v in tri:
            vfaces.setdefault(v, set()).add(f)
    ecount = {}
    for t in F.tolist():
        for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            k = (min(u, v), max(u, v))
            ecount[k] = ecount.get(k, 0) + 1

    def nbrs(v):
        return {w for f in vfaces.get(v, ()) for w in F[f] if w != v}

    def boundary(v):
        return any(ecount.get((min(v, w), max(v, w)), 0) == 1 for w in nbrs(v))

    shared = vfaces.get(a, set()) & vfaces.get(b, set())
    k = len(shared)
    if k == 0 or k > 2:
        return False
    common = (nbrs(a) & nbrs(b)) - {a, b}
    if len(common) != k:
        return False
    if k == 2:
        if boundary(a) and boundary(b):
            return False
        if any(len(nbrs(c)) <= 3 for c in common):
            return False
    return True


@pytest.mark.parametrize("make", [lambda: shapes.grid(7, hole=True), lambda: shapes.torus(1.0, 0.35, 10, 6),
                                  lambda: shapes.icosphere(1)], ids=["grid-with-hole", "torus", "icosphere"])
def test_greedy_link_rule_matches_the_set_reference(make):
    V, F = make()
    # the input, and coarser versions with irregular valence (and degree-3 vertices)
    meshes = [(V, F)] + [(r.vertices, r.faces) for r in
                         (_simplify((V, F), ratio=t)[0] for t in (0.4, 0.15, 0.05))]
    seen = set()
    for Vm, Fm in meshes:
        Fm = np.asarray(Fm, np.int64)
        faces = FaceLists(Fm, len(Vm))
        E = np.unique(np.sort(np.concatenate([Fm[:, [0, 1]], Fm[:, [1, 2]], Fm[:, [2, 0]]]), 1), axis=0)
        for a, b in E.tolist():
            nshared = int(np.sum([(a in t) and (b in t) for t in Fm.tolist()]))
            got = greedy.loop._link_ok(faces, a, b, nshared)
            assert got == _reference_link_ok(Fm, a, b), (a, b)
            seen.add(got)
    assert seen == {True, False}


def test_area_power_keyword_reaches_the_model_and_one_is_the_default():
    mesh = shapes.bumpy_sphere(2, seed=3)
    base = qemjax.simplify(mesh, ratio=0.2, method="qem")
    same = qemjax.simplify(mesh, ratio=0.2, area_power=1.0, method="qem")
    half = qemjax.simplify(mesh, ratio=0.2, area_power=0.5, method="qem")
    assert np.array_equal(base.vertices, same.vertices) and np.array_equal(base.faces, same.faces)
    assert half.stats["model"]["area_power"] == 0.5
    assert not np.array_equal(base.history.pairs, half.history.pairs)
    with pytest.raises(ValueError, match="area_power"):
        qemjax.simplify(mesh, ratio=0.2, area_power=3.0)
    with pytest.raises(ValueError, match="placement='rank'"):
        qemjax.simplify(mesh, ratio=0.2, method="esqem", placement="rank")
