"""Property-based tests (hypothesis): random small meshes, targets and options.

Every output must be valid (conftest.assert_valid: indices in range, no degenerate, zero-area or duplicate
faces, finite coordinates, no face turned against the input face it continues), and either meet the face
target or stop above it. Derandomized, so a run is deterministic; about 25 examples per property.
"""
from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_valid
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import qemjax
from qemjax import shapes

SETTINGS = settings(max_examples=25, deadline=None, derandomize=True, database=None, print_blob=True,
                    suppress_health_check=[HealthCheck.too_slow])


@st.composite
def meshes(draw):
    """A perturbed grid (open, maybe with a hole), icosphere, torus or cube: (V, F), at most ~640 faces."""
    kind = draw(st.sampled_from(["grid", "icosphere", "torus", "cube"]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    if kind == "grid":
        V, F = shapes.grid(draw(st.integers(3, 12)), hole=draw(st.booleans()))
    elif kind == "icosphere":
        V, F = shapes.icosphere(draw(st.integers(0, 2)))
    elif kind == "torus":
        V, F = shapes.torus(n_major=draw(st.integers(3, 16)), n_minor=draw(st.integers(3, 10)))
    else:
        V, F = shapes.cube(draw(st.integers(0, 2)))
    jitter = draw(st.sampled_from([0.0, 1e-6, 1e-3, 0.05]))
    scale = draw(st.sampled_from([1.0, 1e-3, 1e4]))
    V = (V + jitter * rng.standard_normal(V.shape)) * scale
    return V, F


OPTIONS = st.fixed_dictionaries({}, optional={
    "scheduler": st.sampled_from(["parallel", "greedy"]),
    "placement": st.sampled_from(["optimal", "rank", "endpoints"]),
    "area_weighted": st.booleans(),
    "boundary_weight": st.sampled_from([0.0, 1.0, 1000.0]),
    "flip_angle": st.sampled_from([30.0, 90.0, 150.0]),
    "preserve_topology": st.booleans(),
})


def _check(r, target):
    """Valid; and the target met, or the result valid above it (the scheduler found nothing more)."""
    assert_valid(r, None, r.input_vertices, r.input_faces)
    assert np.all(np.isfinite(r.vertex_error)) and np.isfinite(r.max_error)
    assert len(r.faces) == r.stats["faces_out"] >= 1
    if len(r.faces) != target:
        assert len(r.faces) > target, (len(r.faces), target)
    # each contraction removes one vertex; without preserve_topology, dropped coincident faces can
    # leave more unused
    assert len(r.history) == r.stats["contractions"] <= len(r.input_vertices) - len(r.vertices)


@pytest.mark.slow
@SETTINGS
@given(mesh=meshes(), ratio=st.floats(0.01, 1.0), options=OPTIONS)
def test_random_meshes_ratio(mesh, ratio, options):
    r = qemjax.simplify(mesh, ratio=ratio, **options)
    _check(r, r.stats["target_faces"])


@SETTINGS
@given(mesh=meshes(), target=st.integers(1, 200), options=OPTIONS)
def test_random_meshes_face_target(mesh, target, options):
    r = qemjax.simplify(mesh, target_faces=min(target, len(mesh[1])), **options)
    _check(r, min(target, len(mesh[1])))


@SETTINGS
@given(mesh=meshes(), fraction=st.sampled_from([0.0, 1e-4, 1e-2, 1.0]))
def test_random_meshes_max_error(mesh, fraction):
    """The error bound is a squared distance in mesh units: no contraction costs more than asked."""
    V = np.asarray(mesh[0])
    limit = fraction * float(np.max(np.ptp(V, axis=0))) ** 2
    r = qemjax.simplify(mesh, max_error=limit)
    _check(r, 0)
    assert r.max_error <= limit * (1 + 1e-6) and np.all(r.history.costs <= limit * (1 + 1e-6))


@settings(max_examples=8, deadline=None, derandomize=True, database=None)
@given(mesh=meshes(), ratio=st.floats(0.05, 0.9))
def test_random_meshes_deterministic(mesh, ratio):
    a = qemjax.simplify(mesh, ratio=ratio)
    b = qemjax.simplify(mesh, ratio=ratio)
    assert np.array_equal(a.faces, b.faces) and np.array_equal(a.vertices, b.vertices)
