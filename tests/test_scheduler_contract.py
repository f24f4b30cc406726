"""The schedulers' contract (`qemjax._schedulers`): every scheduler returns an `Outcome`, and a scheduler
registered from outside runs through `simplify` with nothing else edited."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import qemjax
from qemjax import _schedulers, shapes
from qemjax._schedulers import outcome


def _capture(monkeypatch, name):
    """Wrap scheduler ``name`` so the outcomes it returns are kept (in a list)."""
    seen, run = [], _schedulers.get(name)

    def wrapped(*args, **kwargs):
        out = run(*args, **kwargs)
        seen.append((out, args[6]))  # the outcome and the Options
        return out

    monkeypatch.setitem(_schedulers._REGISTRY, name, wrapped)
    return seen


def _consistent(out: outcome.Outcome, options, res):
    assert isinstance(out, outcome.Outcome) and out.stop_reason in outcome.STOPS
    assert out.contractions == len(out.history.pairs) == len(out.history.costs) == res.stats["contractions"]
    assert int(out.alive.sum()) == len(res.faces) and len(out.faces) == len(out.alive)
    assert out.worst_cost == (float(np.max(out.history.costs)) if out.contractions else 0.0)
    assert out.worst_cost <= options.max_cost
    assert sum(out.rejected_by.values()) == out.rejected
    assert int(np.sum(out.branches)) == out.contractions


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("method", ["qem", "esqem", "area"])
def test_every_scheduler_returns_a_consistent_outcome(monkeypatch, scheduler, method):
    seen = _capture(monkeypatch, scheduler)
    mesh = shapes.bumpy_sphere(2)
    res = qemjax.simplify(mesh, target_faces=200, method=method, scheduler=scheduler, split_factor=None) \
        if method == "esqem" else qemjax.simplify(mesh, target_faces=200, method=method, scheduler=scheduler)
    assert len(seen) == 1
    _consistent(*seen[0], res)
    assert res.stop_reason == seen[0][0].stop_reason == "target"


def test_a_limit_and_the_observed_worst_cost_differ(monkeypatch):
    mesh = shapes.bumpy_sphere(2)
    full = qemjax.simplify(mesh, target_faces=100)
    seen = _capture(monkeypatch, "parallel")
    res = qemjax.simplify(mesh, max_error=full.max_error / 50)
    out, options = seen[0]
    _consistent(out, options, res)
    assert res.stop_reason == out.stop_reason == "max_error" and out.worst_cost <= options.max_cost


def test_batched_copies_return_outcomes(monkeypatch):
    from qemjax._schedulers import batched

    seen, run = [], batched.run

    def wrapped(*args, **kwargs):
        outs = run(*args, **kwargs)
        seen.extend(outs)
        return outs

    monkeypatch.setattr(batched, "run", wrapped)
    mesh = shapes.bumpy_sphere(2)
    res = qemjax.simplify_batch(mesh, [dict(target_faces=300, late_memoryless=0),
                                       dict(target_faces=200, boundary_weight=1.0, late_memoryless=0)])
    assert len(seen) == 2 and all(isinstance(o, outcome.Outcome) for o in seen)
    for out, r in zip(seen, res):
        assert int(out.alive.sum()) == len(r.faces) and out.contractions == r.stats["contractions"]


def test_the_outcome_checks_itself():
    V, F = shapes.icosphere(1)
    ok = outcome.Outcome.unchanged(V.astype(np.float32), np.zeros((len(V), 10), np.float32), F, 4)
    assert ok.stop_reason == "unchanged" and ok.contractions == 0
    with pytest.raises(ValueError, match="not one of"):
        outcome.Outcome(ok.positions, ok.states, F, ok.alive, ok.history, "tired", {}, {})
    with pytest.raises(ValueError, match="differ in length"):
        outcome.Outcome(ok.positions, ok.states, F, ok.alive[:-1], ok.history, "target", {}, {})


def test_a_scheduler_registered_from_outside_runs_through_simplify():
    """One function keeping the contract and one call: here a scheduler that contracts nothing."""

    def idle(V, S, F, extra_pairs, target_faces, model, options, progress=None, **_):
        return outcome.Outcome(V, S, F, np.ones(len(F), bool), outcome.History.empty(), "blocked", {"idle": 1},
                               outcome.count_reasons(np.zeros(0, np.int8)), branches=np.zeros(len(model.branches)))

    _schedulers.register("idle", idle)
    try:
        V, F = shapes.icosphere(2)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = qemjax.simplify((V, F), ratio=0.5, scheduler="idle")
        assert res.stop_reason == "blocked" and len(res.faces) == len(F)
        assert res.stats["scheduler"] == "idle" and res.stats["blocked_by"] == {"idle": 1}
        assert "not a built-in" in res.stats["late_memoryless_off"]  # the default's last stretch: built-ins only
        assert any("stopped at" in str(w.message) for w in caught)
        with pytest.raises(ValueError, match="new, non-empty name"):
            _schedulers.register("idle", idle)
    finally:
        del _schedulers._REGISTRY["idle"]
    with pytest.raises(ValueError, match="unknown scheduler 'idle'"):
        qemjax.simplify(shapes.icosphere(1), ratio=0.5, scheduler="idle")


def test_a_scheduler_without_locks_is_refused_a_call_with_locks_in_words():
    """A scheduler written to the contract's other keywords, without ``locks``, is refused a call with
    ``locked=`` or ``vertex_weights=`` before it runs, in one line that names it and the way out (it raised
    Python's "got an unexpected keyword argument 'locks'" from inside the run); the same call without them
    runs, and one whose run takes ``locks=`` gets them."""
    got = []

    def plain(V, S, F, extra_pairs, target_faces, model, options, progress=None, *, wedges=None, edges=None,
              part_scale=None):
        got.append("plain")
        return _schedulers.get("parallel")(V, S, F, extra_pairs, target_faces, model, options, progress,
                                           wedges=wedges, edges=edges, part_scale=part_scale)

    def with_locks(*args, locks=None, **kwargs):
        got.append(locks is not None)
        return _schedulers.get("parallel")(*args, locks=locks, **kwargs)

    _schedulers.register("plain", plain)
    _schedulers.register("with_locks", with_locks)
    try:
        m = shapes.icosphere(2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the default's last stretch is off on an outside scheduler
            assert len(qemjax.simplify(m, ratio=0.5, method="classic", scheduler="plain").faces) == 160
            for kw in (dict(locked=[0, 1]), dict(vertex_weights=np.full(len(m.vertices), 2.0))):
                with pytest.raises(ValueError, match=r"^scheduler='plain' takes no locks .*locked= and "
                                                      r"vertex_weights= cannot run on it"):
                    qemjax.simplify(m, ratio=0.5, method="classic", scheduler="plain", **kw)
            res = qemjax.simplify(m, ratio=0.5, method="classic", scheduler="with_locks", locked=[0, 1])
        assert got == ["plain", True] and res.stats["locked"] == 2
    finally:
        del _schedulers._REGISTRY["plain"], _schedulers._REGISTRY["with_locks"]


def test_a_scheduler_that_takes_replan_and_does_not_call_it_is_run_again():
    """ESQEM's split plan hands ``replan`` to a scheduler that takes it (the contract: it may). One that takes
    it and runs to its target without calling it got Python's "not enough values to unpack" from the plan;
    it is now run a second time from the input, as a scheduler without the keyword is (the same mesh). One
    that calls it twice is refused in one line naming it."""
    parallel = _schedulers.get("parallel")

    def ignores(*args, replan=None, **kwargs):
        return parallel(*args, **kwargs)

    def twice(*args, replan=None, **kwargs):
        out = parallel(*args, **kwargs)
        replan(out)
        replan(out)
        return out

    _schedulers.register("ignores", ignores)
    _schedulers.register("twice", twice)
    try:
        m = shapes.icosphere(3)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = qemjax.simplify(m, ratio=0.3, method="esqem", scheduler="ignores")
            ref = qemjax.simplify(m, ratio=0.3, method="esqem", scheduler="parallel")
            assert np.array_equal(res.faces, ref.faces) and res.vertices.tobytes() == ref.vertices.tobytes()
            with pytest.raises(ValueError, match=r"^scheduler 'twice' called replan 2 times: a scheduler that "
                                                  r"takes replan calls it once"):
                qemjax.simplify(m, ratio=0.3, method="esqem", scheduler="twice")
    finally:
        del _schedulers._REGISTRY["ignores"], _schedulers._REGISTRY["twice"]


def test_the_outcome_gives_its_surviving_mesh():
    """`Outcome.output`: the live faces, numbered into the vertices they use, and both their run ids."""
    V = np.arange(18, dtype=np.float32).reshape(6, 3)
    F = np.array([[0, 1, 2], [2, 3, 4], [3, 4, 5]])
    out = outcome.Outcome(V, np.zeros((6, 1)), F, np.array([False, True, True]), outcome.History.empty(),
                          "target", {}, {})
    o = out.output()
    assert o.source_faces.tolist() == [1, 2] and o.source_vertices.tolist() == [2, 3, 4, 5]
    assert o.faces.tolist() == [[0, 1, 2], [1, 2, 3]]
    assert np.array_equal(o.positions, V[2:]) and np.array_equal(o.positions[o.faces], V[F[1:]])


@pytest.mark.parametrize("stop, blocked, closed, faces, want", [
    ("blocked", {}, True, 11, "target"),  # a closed mesh one face above: the documented parity case
    ("target", {}, True, 11, "target"),
    ("max_error", {}, True, 11, "max_error"),  # the cost limit, not the parity, stopped it
    ("target", {}, False, 11, "blocked"),  # met by the run, then faces added back (splitting)
    ("blocked", {"locked": 3, "flip": 3}, True, 12, "locked"),  # locks hold back at least half of the rest
    ("blocked", {"locked": 3, "flip": 4}, True, 12, "blocked"),
    ("max_error", {"locked": 9}, True, 12, "max_error"),
])
def test_the_stop_reason_above_the_target(stop, blocked, closed, faces, want):
    V, F = shapes.icosphere(0)
    out = outcome.Outcome(V, np.zeros((len(V), 1)), F, np.ones(len(F), bool), outcome.History.empty(), stop,
                          blocked, {})
    assert out.stop_above(faces, 10, closed) == want


def test_the_run_reports_its_counts_in_the_stats(monkeypatch):
    seen = _capture(monkeypatch, "parallel")
    res = qemjax.simplify(shapes.bumpy_sphere(2), ratio=0.1, late_memoryless=0)  # one run (`test_late_memoryless`)
    counts = seen[0][0].counts(("a", "b", "c", "d")[:len(seen[0][0].branches)])
    assert list(counts) == ["contractions", "rejected", "rounds", "rounds_contracting", "branches", "rejected_by",
                            "blocked_by"]
    for k in ("contractions", "rejected", "rounds", "rounds_contracting", "rejected_by", "blocked_by"):
        assert res.stats[k] == counts[k]
    assert list(res.stats["branches"].values()) == list(counts["branches"].values())


def test_the_pipeline_reads_the_outcome_only():
    """The stages read a scheduler's `Outcome` through its fields and methods: no scheduler internals."""
    import ast
    from pathlib import Path

    import qemjax._pipeline as pipeline

    reached = []
    for path in Path(pipeline.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and "_schedulers" in node.module:
                reached += [f"{path.name}: {a.name}" for a in node.names
                            if a.name not in ("outcome", "locks", "RunLocks", "batched", "late")]
            elif isinstance(node, ast.Attribute) and node.attr in ("compact_output", "parity_only", "hold_back"):
                reached.append(f"{path.name}: {node.attr}")
    assert not reached, reached


def test_a_parallel_run_picks_its_round_implementation_once(monkeypatch):
    """`parallel.choose` once per run: the compiled loops and glue where they apply, the compiled loops alone
    for a batch (its gates are per copy), the numpy stages where the loops do not apply."""
    from qemjax._schedulers import parallel
    from qemjax._schedulers.parallel import selection
    from qemjax._schedulers.parallel import driver

    picked, choose = [], driver.choose

    def recording(run, glue=True):
        rnd = choose(run, glue)
        picked.append(type(rnd).__name__)
        return rnd
    monkeypatch.setattr(driver, "choose", recording)
    mesh = shapes.bumpy_sphere(3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        qemjax.simplify(mesh, ratio=0.1, late_memoryless=0)  # (the default's last stretch: a second run)
        qemjax.simplify_batch(mesh, [{"ratio": 0.1, "late_memoryless": 0}, {"ratio": 0.2, "late_memoryless": 0}])
        monkeypatch.setattr(selection, "fits", lambda *a: False)
        qemjax.simplify(mesh, ratio=0.1, late_memoryless=0)
    assert picked == ["GlueRound", "LoopRound", "StagedRound"]
    assert issubclass(parallel.GlueRound, parallel.LoopRound)


@pytest.mark.parametrize("kw,match", [
    (dict(gate="2"), "Schedule.gate must be a number, got '2'"),
    (dict(gate=None), "Schedule.gate must be a number"),
    (dict(free_cost=[0.1]), "Schedule.free_cost must be a number"),
    (dict(tail=None), "Schedule.tail must be a positive integer"),
    (dict(max_passes="3"), "Schedule.max_passes must be a positive integer"),
    (dict(tail=float("nan")), "Schedule.tail must be a positive integer"),
])
def test_schedule_fields_of_the_wrong_kind_are_named(kw, match):
    """They failed in numpy's or int()'s words (ufunc 'isfinite' not supported, ...)."""
    with pytest.raises(ValueError, match=match):
        qemjax.Schedule(**kw)
