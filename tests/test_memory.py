"""Memory of a large run (issue 42, "Memory"): the arrays a run shares instead of copying.

The input check keeps int64 faces as given (no 127 MiB copy on a 5.5 M-face mesh) and the parallel
scheduler's first round uses the geometry's int32 edge table as it is. Both are safe only while nothing
writes into those arrays: these tests check the sharing itself and that a run leaves the shared arrays as
they were (both schedulers, both topology modes, the compiled and the numpy rounds). The peak itself is
measured by ``python experiments/figures/memory_peak.py`` and located by ``python experiments/figures/memory_profile.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

import qemjax
from qemjax._io import mesh as _io
from qemjax._pipeline import stages
from qemjax._schedulers.parallel import selection
from qemjax.shapes import icosphere


def test_int64_faces_are_used_as_given():
    V, F = icosphere(3)
    F = np.ascontiguousarray(F, np.int64)
    (V1, F1), _ = _io.prepare((V, F))
    assert np.shares_memory(F1, F), "int64 faces were copied by the input check"
    (V2, F2), _ = _io.prepare((V, F.astype(np.int32)))  # other dtypes: an int64 copy, the same faces
    assert F2.dtype == np.int64 and not np.shares_memory(F2, F) and np.array_equal(F2, F)


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("preserve", [True, False])
def test_a_run_leaves_its_input_as_given(scheduler, preserve):
    V, F = icosphere(3)
    V, F = np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64)
    V0, F0 = V.copy(), F.copy()
    topology = qemjax.Topology(preserve_topology=preserve)
    r = qemjax.simplify((V, F), ratio=0.1, scheduler=scheduler, topology=topology)
    assert np.array_equal(V, V0) and np.array_equal(F, F0), "the run wrote into the caller's arrays"
    assert np.shares_memory(r.input_faces, F)
    r2 = qemjax.simplify((V0, F0.astype(np.int32)), ratio=0.1, scheduler=scheduler, topology=topology)
    assert np.array_equal(r.faces, r2.faces) and np.array_equal(r.vertices, r2.vertices)
    assert len(r.faces) <= 0.1 * len(F) + 1


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("preserve", [True, False])
def test_the_edge_table_is_read_only_to_a_run(compiled, preserve, monkeypatch):
    """The first round takes the geometry's int32 edge table without a copy; a batch's runs share it."""
    if not compiled:  # the numpy stages, as on a large mesh
        monkeypatch.setattr(selection, "MAX_FACES", 0)
    V, F = icosphere(3)
    setup = stages.setup("default", "parallel", qemjax.Topology(preserve_topology=preserve), None, False, {})
    geo = stages.geometry((V, F), setup, stacklevel=2)
    E, ecount = geo.edges[0], geo.edges[1]
    assert E.dtype == np.int32
    E0, c0 = E.copy(), ecount.copy()
    job = stages.job(setup, geo, None, None, 0.1, None, stacklevel=2)
    out, _, _ = stages.run(job)
    assert np.array_equal(E, E0) and np.array_equal(ecount, c0), "the run wrote into the geometry's edges"
    assert out.alive.sum() <= 0.1 * len(F) + 1
    again, _, _ = stages.run(job)  # the same geometry again (as a batch): the same run
    assert np.array_equal(again.faces[again.alive], out.faces[out.alive])
