"""Shared fixtures and checks. Meshes are generated in code; real meshes come from ../shared/meshes and
tests using them skip when it is absent (a user's machine)."""
from __future__ import annotations

import os
import signal
import tempfile
from pathlib import Path

import numpy as np
import pytest

# importing qemjax turns JAX's persistent compilation cache on (qemjax.cache): the tests use a folder of their
# own, shared by their runs, never the user's ~/.cache/qemjax (tests that check the cache set their own)
os.environ.setdefault("QEMJAX_CACHE_DIR", os.path.join(tempfile.gettempdir(), "qemjax-test-cache"))

# sweeps run in the test's process unless a test asks for helper processes (workers=): a default sweep would
# start them once the session's sweeps add up (`qemjax._sweep.run.SWEPT_WORK`), and tests that count what
# runs here would then see pieces go elsewhere
os.environ.setdefault("QEMJAX_WORKERS", "1")

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "meshes"

# `-n auto` (pyproject's addopts) runs the suite on pytest-xdist workers, one per core up to MAX_WORKERS: each
# worker imports JAX and holds its own compiled kernels (about 1-2 GiB at its peak), and many tests start
# processes of their own (sweep helpers, partition workers, a Dask LocalCluster), so more workers than that
# add memory, not speed. One core: no workers (the tests run in this process).
MAX_WORKERS = 4


def pytest_configure(config):
    """On a fresh clone beside an install of the same sources, the install's compiled loops first
    (`built_loops`): the test processes load them instead of each compiling them."""
    from built_loops import copy_into, installed

    dist = installed()
    if dist is not None:
        copy_into(dist, Path(__file__).resolve().parents[1])


def pytest_xdist_auto_num_workers(config):
    from qemjax._sweep.pool import cores  # (imports no JAX)

    n = cores()
    return 0 if n < 2 else min(n, MAX_WORKERS)


def sigint_default() -> None:
    """``preexec_fn`` of a child process a test sends SIGINT: SIGINT's default in the child whatever this test
    run was started with (a CI runner, or ``cmd &`` in a script, starts it with SIGINT ignored; a child
    inherits that, and qemjax keeps an ignored SIGINT ignored, `tests/test_first_use.py`)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def shared_mesh(name: str) -> Path:
    p = SHARED / name
    if not p.exists():
        pytest.skip(f"{p} not available (../shared/meshes is only on development and CI machines)")
    return p


def one_pair_per_round():
    """A schedule that gates the parallel scheduler down to the single cheapest valid pair per round (no
    free pairs)."""
    import qemjax

    return qemjax.Schedule(gate=1.0, gate_fraction=1e-12, free_cost=0.0)


def unit_extent(V):
    """V centred on its bounding box and divided by its largest side: float64 checks on it neither
    underflow nor overflow, whatever the mesh's scale (1e-100 or 1e100)."""
    lo, hi = V.min(0), V.max(0)
    return (V - (0.5 * lo + 0.5 * hi)) / max(float(np.max(hi - lo)), np.finfo(float).tiny)


def face_normals(V, F):
    V = unit_extent(V)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    with np.errstate(invalid="ignore"):  # a zero-area face gets a NaN normal: no dot with it passes
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def assert_valid(result, target=None, V0=None, F0=None, allow_flips=False):
    """Indices in range, no degenerate (index or zero-area) faces, no duplicate faces, exact count, and
    no face whose normal opposes the nearest input face's normal (when the input is given)."""
    V, F = result.vertices, result.faces
    assert F.dtype == np.int64 and V.dtype == np.float64
    assert F.min() >= 0 and F.max() < len(V)
    assert np.all(np.isfinite(V))
    assert not np.any((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])), "degenerate"
    key = np.sort(F, axis=1)
    assert len(np.unique(key, axis=0)) == len(F), "duplicate faces"
    U = unit_extent(V)
    area2 = np.linalg.norm(np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]]), axis=1)
    assert np.all(area2 > 0), "zero-area faces"
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    assert used.all(), "unreferenced vertices"
    if target is not None:
        assert len(F) == target
    if V0 is not None and not allow_flips:
        # every output face continues an input face: it must not point against that face
        dots = np.sum(face_normals(V, F) * face_normals(V0, F0)[result.source_faces], 1)
        assert np.all(dots > 0), f"{np.sum(dots <= 0)} faces point against the input face they continue"


def pytest_collection_modifyitems(config, items):
    """The notebooks (run through nbmake) belong to the slow tier: ``pytest -m "not slow"`` leaves them out."""
    for item in items:
        if str(item.path).endswith(".ipynb"):
            item.add_marker(pytest.mark.slow)
