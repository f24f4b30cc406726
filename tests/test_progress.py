"""The progress bar of `simplify(progress=True)`: its total is the faces the run removes, from its first
line, and it ends full when the run reaches its goal, for every scheduler, method and target kind. The
bars are real tqdm bars writing to a string, recorded as they are made."""
from __future__ import annotations

import io
import warnings

import pytest
import tqdm.auto
import tqdm.std

import qemjax
from qemjax import shapes


class Bar(tqdm.std.tqdm):
    """A tqdm bar that writes to a string and keeps each total it was given and each update."""

    made: list = []

    def __init__(self, *args, **kwargs):
        kwargs["file"] = io.StringIO()
        super().__init__(*args, **kwargs)
        self.totals, self.updates = [self.total], []
        Bar.made.append(self)

    def update(self, n=1):
        self.updates.append(n)
        return super().update(n)

    def reset(self, total=None):
        super().reset(total)
        self.totals.append(total)
        self.updates.append("reset")

    def last_line(self) -> str:
        return self.fp.getvalue().replace("\r", "\n").strip().splitlines()[-1]


@pytest.fixture
def bars(monkeypatch):
    Bar.made = []
    monkeypatch.setattr(tqdm.auto, "tqdm", Bar)  # what `simplify` imports when it shows a bar
    return Bar.made


def _run(bars, mesh, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a closed mesh one face above an odd target says so
        res = qemjax.simplify(mesh, progress=True, **kw)
    (bar,) = bars
    return res, bar


BUMPY = shapes.bumpy_sphere(4)  # 5,120 faces, what `qemjax examples` writes as bumpy.obj


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("method,kw", [
    ("qem", {"ratio": 0.1}),
    ("esqem", {"ratio": 0.1}),  # splits edges after: the run itself goes past the target
    ("area", {"ratio": 0.1}),
    ("qem", {"target_faces": 511}),  # closed: faces go in pairs, it stops at 512
    ("qem", {"ratio": 0.1, "pair_threshold": 0.01, "preserve_topology": False}),  # aggregation
], ids=["qem", "esqem-split", "area", "odd-target", "aggregation"])
def test_the_total_is_the_faces_removed(bars, scheduler, method, kw):
    res, bar = _run(bars, BUMPY, method=method, scheduler=scheduler, **kw)
    m = len(BUMPY.faces)
    split = res.stats.get("split")
    removed = m - (split["simplified_to"] if split else len(res.faces))  # splitting adds faces back after
    assert res.stop_reason == "target"
    assert bar.totals[-1] == removed and bar.n == removed and bar.total == removed, (bar.totals, bar.n)
    run = bar.updates[bar.updates.index("reset") + 1:] if split else bar.updates  # the run after the plan
    assert all(u >= 0 for u in run) and sum(run) == removed
    if split:  # the planning run counts to the target, then the bar starts again for the run itself
        assert bar.totals[0] == m - 512 and bar.updates.count("reset") == 1
    else:
        assert bar.totals == [removed]  # right from its first line: nothing corrected at the end
    assert f"{removed}/{removed}" in bar.last_line() and "100%" in bar.last_line()


def test_an_open_mesh_and_lod_levels(bars):
    sheet = shapes.grid(24, hole=True)  # boundary edges: faces go one at a time there
    res, bar = _run(bars, sheet, ratio=0.1, scheduler="greedy")
    assert bar.totals == [len(sheet.faces) - len(res.faces)] and bar.n == bar.total
    bars.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        chain = qemjax.lod_chain(BUMPY, ratios=(0.5, 0.1), progress=True)
    (bar,) = bars  # one run down to the coarsest level
    assert bar.totals == [len(BUMPY.faces) - len(chain.levels[-1].faces)] and bar.n == bar.total


def test_a_run_to_an_error_bound_ends_full_and_one_stopped_short_does_not(bars):
    res, bar = _run(bars, BUMPY, max_error=1e-4)  # no face target: how far it goes is not known ahead
    assert res.stop_reason == "max_error" and bar.n == bar.total == len(BUMPY.faces) - len(res.faces)
    assert "100%" in bar.last_line()
    bars.clear()
    res, bar = _run(bars, BUMPY, ratio=0.01, max_error=1e-4)  # stopped by the error before the face target
    assert res.stop_reason == "max_error" and bar.n == len(BUMPY.faces) - len(res.faces) < bar.total
