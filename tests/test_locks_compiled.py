"""Runs with locked vertices and importance weights (`qemjax._schedulers.locks`) take the parallel round's compiled
path (`parallel.selection`, and with a model that fuses its device call `parallel.glue`) where a run without them would,
and give exactly the result of the numpy stages for the same run: vertices, faces, history, stop reason and
stats, bit for bit. The numpy stages are forced as tests/test_round_loops.py forces them (`selection.fits`
answering no)."""
from __future__ import annotations

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._mesh import topology as topo
from qemjax._schedulers import device, parallel
from qemjax._schedulers.parallel import driver
from qemjax._schedulers import locks as _locks
from test_attributes import atlas_sphere
from test_round_loops import _assert_same, _run


def _cap(subdivisions=4, keep=0.4):
    """An open mesh: the faces of a bumpy sphere in the top ``keep`` share of its height (one boundary loop)."""
    V, F = (np.asarray(x) for x in shapes.bumpy_sphere(subdivisions))
    z = V[F].mean(1)[:, 2]
    F = F[z >= np.quantile(z, 1.0 - keep)]
    used = np.unique(F)
    new = np.full(len(V), -1, np.int64)
    new[used] = np.arange(len(used))
    return V[used], new[F]


def _patches():
    """A grid with its corners locked (ears: contracting the pair across a corner's one face strands it),
    beside small open pieces, each with a locked vertex (their last contraction would take it out of every
    face), and fans of triangles that share one locked vertex only (the pairs of one pass strand it
    together, though none would alone)."""
    V, F = (np.asarray(x, float) for x in shapes.grid(24))
    Vs, Fs, locked = [V], [F], []
    corners = np.argsort(V[:, 0] + V[:, 1])[[0, -1]].tolist() + np.argsort(V[:, 0] - V[:, 1])[[0, -1]].tolist()
    n = len(V)
    for k in range(6):  # single triangles and two-triangle quads
        o = np.array([2.0 + 0.3 * k, 0.0, 0.0])
        Vs.append(np.array([o, o + [0.1, 0, 0], o + [0, 0.1, 0.01 * k], o + [0.1, 0.1, 0.02]]))
        Fs.append(np.array([[n, n + 1, n + 2]] + ([[n + 1, n + 3, n + 2]] if k % 2 else [])))
        locked.append(n)
        n += 4
    for j in range(5):  # fans: three triangles around one vertex, no edge shared
        c = np.array([3.0 + j, 1.0, 0.0])
        pts, tris = [c], []
        for i in range(3):
            ang = 2 * np.pi * i / 3
            pts += [c + 0.2 * np.array([np.cos(ang), np.sin(ang), 0.05 * i]),
                    c + 0.2 * np.array([np.cos(ang + 0.6), np.sin(ang + 0.6), 0.03 * j])]
            tris.append([n, n + 1 + 2 * i, n + 2 + 2 * i])
        Vs.append(np.array(pts))
        Fs.append(np.array(tris))
        locked.append(n)
        n += len(pts)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    mask = np.zeros(len(V), bool)
    mask[corners + locked] = True
    return (V, F), mask


MESHES = {
    "closed": lambda: shapes.bumpy_sphere(3),
    "open": _cap,
    "genus-1": lambda: shapes.torus(n_major=30, n_minor=14),
}


def _boundary(V, F):
    E, count = topo.edges(np.asarray(F), len(V))
    mask = np.zeros(len(V), bool)
    mask[E[count == 1].reshape(-1)] = True
    return mask


def _pattern(name, V, F):
    """(n,) bool: 2 % of the vertices at random, a band across the mesh (where a part's border would be), or
    the boundary vertices."""
    if name == "random":
        return np.random.default_rng(0).random(len(V)) < 0.02
    if name == "band":
        x = V[:, 0]
        return np.abs(x - np.median(x)) < 0.04 * np.ptp(x)
    return _boundary(V, F)


def _weights(n, seed=1):
    return np.random.default_rng(seed).uniform(0.2, 3.0, n)


def _both(mesh, kw, monkeypatch, fast=True):
    """The run on its own path and on the numpy stages: the same bits, and each took the path it should (a
    fast run with its prices at locked kept vertices in the round's device call, when it has such pairs)."""
    seen, fused = [], []
    choose, step_with = driver.choose, device._step_with

    def recording(run, glue=True):
        rnd = choose(run, glue)
        seen.append((isinstance(rnd, parallel.LoopRound), isinstance(rnd, parallel.GlueRound)))
        return rnd

    def recording_step(*a):
        fused.append(len(a[-1]))
        return step_with(*a)
    monkeypatch.setattr(driver, "choose", recording)
    monkeypatch.setattr(device, "_step_with", recording_step)
    new, _ = _run(mesh, kw, monkeypatch, True)
    old, _ = _run(mesh, kw, monkeypatch, False)
    # the default turns memoryless for its last stretch (`_schedulers.late`; not with UVs kept): a second run
    # of the scheduler, on the compiled loops with the numpy price stages as any memoryless run
    want = [(True, fast)] + ([(True, False)] if kw.get("method") == "default" and "attributes" not in kw else [])
    assert seen == want + [(False, False)] * len(want), seen
    _assert_same(new, old)
    if not fast or new.stats["rounds"] < 2 or "attributes" in kw:  # (UVs: priced on the host)
        assert not fused
    else:
        assert fused and min(fused) > 0
    return new


CASES = [(m, p, w) for m in MESHES for p in ("random", "band", "boundary") for w in (False, True)
         if not (m != "open" and p == "boundary")]  # (closed meshes have no boundary)


@pytest.mark.parametrize("mesh_name, pattern, weights", CASES)
def test_locked_runs_take_the_compiled_round_with_the_numpy_stages_bits(mesh_name, pattern, weights, monkeypatch):
    V, F = (np.asarray(x) for x in MESHES[mesh_name]())
    kw = {"ratio": 0.05, "method": "default", "locked": _pattern(pattern, V, F)}
    if weights:
        kw["vertex_weights"] = _weights(len(V))
    res = _both((V, F), kw, monkeypatch)
    assert res.stats["locked"] == int(kw["locked"].sum()) > 0 and res.stats["rounds"] > 2


@pytest.mark.parametrize("method", ["classic", "line", "probabilistic", "area", "memoryless"])
@pytest.mark.parametrize("weights", [False, True])
def test_every_path_of_the_compiled_round_keeps_the_bits(method, weights, monkeypatch):
    """Models that fuse their device call (`glue`: the locks applied to its raw price) and models
    that do not (`area`, memoryless: the compiled loops with the numpy price stages)."""
    V, F = (np.asarray(x) for x in _cap())
    kw = {"ratio": 0.05, "method": qemjax.QEM(memoryless=True) if method == "memoryless" else method,
          "locked": _pattern("band", V, F) | _pattern("boundary", V, F)}
    if weights:
        kw["vertex_weights"] = _weights(len(V))
    _both((V, F), kw, monkeypatch, fast=method not in ("area", "memoryless"))


@pytest.mark.parametrize("prune", [True, False])
@pytest.mark.parametrize("method", ["classic", "default", "area"])
def test_the_locked_rule_inside_the_loops(method, prune, monkeypatch):
    """Contractions that would leave a locked vertex in no face are refused inside the compiled loops as the
    numpy stages refuse them (`locks.vanishing`, `locks.strands`, counted over a pass's pairs together)."""
    mesh, locked = _patches()
    calls = {"vanishing": 0, "strands": 0}
    for name in calls:
        fn = getattr(_locks, name)

        def counting(*a, fn=fn, name=name):
            out = fn(*a)
            calls[name] += int(out.sum())
            return out
        monkeypatch.setattr(_locks, name, counting)
    res = _both(mesh, {"ratio": 0.01, "method": method, "locked": locked, "prune": prune}, monkeypatch,
                fast=method != "area")
    assert calls["vanishing"] > 0 and calls["strands"] > 0  # (on the numpy stages) both rules did refuse
    assert res.stats["rejected_by"]["locked" if prune else "vanishing_part"] > 0


@pytest.mark.parametrize("share", [1.0, 0.75])
def test_runs_the_locks_block_stop_alike(share, monkeypatch):
    """Locks that hold back the target: the same stop (``"locked"``) and blocked pairs on both paths."""
    V, F = (np.asarray(x) for x in shapes.bumpy_sphere(2))
    locked = V[:, 2] >= np.quantile(V[:, 2], 1.0 - share)
    res = _both((V, F), {"ratio": 0.1, "locked": locked}, monkeypatch)
    assert res.stop_reason == "locked" and res.stats["blocked_by"]["locked"] > 0


@pytest.mark.parametrize("weights", [False, True])
def test_locks_with_kept_uvs(weights, monkeypatch):
    """Kept attributes with locks: seam placements of the carried prices are pinned at a locked kept vertex,
    and pairs of two locked vertices stay refused, as the numpy stages do it."""
    mesh = atlas_sphere(3)[0]
    V = np.asarray(mesh[0] if isinstance(mesh, tuple) else mesh.vertices)
    locked = _pattern("band", V, None) | (np.random.default_rng(2).random(len(V)) < 0.02)
    kw = {"ratio": 0.05, "attributes": "uv", "method": "default", "locked": locked}
    if weights:
        kw["vertex_weights"] = _weights(len(V))
    res = _both(mesh, kw, monkeypatch)
    assert res.stats["rejected_by"]["seam"] > 0


@pytest.mark.parametrize("method", ["classic", "default", "line", "probabilistic"])
def test_prices_at_kept_vertices_in_the_round_call_are_start_prices(method):
    """The round's device call with pairs priced at their kept vertex (`device.start_step` and `step_one` with
    ``kept``) gives the rows, merges and prices it gives without them, and for those pairs `start_price`'s
    price at the kept vertex on the new rows, bit for bit."""
    import jax.numpy as jnp

    from qemjax._costs import build, resolve
    from qemjax._kernels.batching import pad_rows

    rng = np.random.default_rng(3)
    model = build(resolve(method))
    assert device.kept_fuses(model)
    n, K, J, k = 3000, 90, 700, 60
    rows = np.zeros((4096, 3 + model.width), np.float32)
    rows[:n] = rng.normal(size=(n, 3 + model.width)).astype(np.float32)
    verts = rng.permutation(n)
    P = np.stack([verts[:K], verts[K:2 * K]], 1).astype(np.int32)
    x = rng.normal(size=(K, 3)).astype(np.float32)
    Pn = np.sort(rng.integers(0, n, (J, 2)), axis=1).astype(np.int32)
    Pk = Pn[rng.choice(J, k, replace=False)]
    params = device.on_device(model.kernel_params())
    ref_VS, ref_merged, ref_priced = device.start_step(model, jnp.asarray(rows), P, x, Pn, params, 256, 1024)
    ref_VS = np.asarray(ref_VS)
    ref_at = device.start_price(model, jnp.asarray(ref_VS), Pk, params, at_kept=True)()
    ref_priced, ref_merged = ref_priced(), ref_merged()
    calls = {
        "start_step": lambda: device.start_step(model, jnp.asarray(rows), P, x, Pn, params, 256, 1024, kept=Pk),
        "step_one": lambda: device.step_one(model, jnp.asarray(rows), pad_rows(P[:, 0], 256, 4096), pad_rows(P, 256),
                                            pad_rows(x, 256), pad_rows(Pn, 1024), params, K, kept=Pk)}
    for name, call in calls.items():
        VS, merged, priced, at = call()
        assert np.array_equal(np.asarray(VS), ref_VS) and np.array_equal(merged(), ref_merged), name
        got = priced()
        if name == "step_one":  # (its raw columns, as the kernel gives them)
            got = device.Priced(got[:3, :J].T, got[3, :J], got[4, :J].astype(np.int8), got[5:, :J])
        for field, want in zip(device.Priced._fields, ref_priced):
            assert np.array_equal(getattr(got, field), want, equal_nan=True), (name, field)
        at = at()
        for field, want in zip(device.Priced._fields, ref_at):
            g = getattr(at, field)
            assert g.dtype == want.dtype and np.array_equal(g, want, equal_nan=True), (name, field)
