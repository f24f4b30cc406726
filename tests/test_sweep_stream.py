"""Sweeps a researcher can watch, stop and resume (issue 41): rows reach `out` as cells finish, Ctrl-C
keeps every finished row and says how many, SIGKILL loses at most the cells in flight, a rerun skips the
rows already there and leaves them byte for byte; timing columns; settings that do not apply ("n/a")."""
from __future__ import annotations

import concurrent.futures
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import qemjax
import qemjax._sweep.run as sw
from qemjax import shapes
from conftest import sigint_default

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ball():
    return shapes.icosphere(2)


def _saves(monkeypatch):
    """The number of this grid's rows in each table the sweep wrote."""
    seen = []
    real_text, real_table = sw.write_text, sw.write_table
    monkeypatch.setattr(sw, "write_text", lambda header, records, out: seen.append(len(records)) or
                        real_text(header, records, out))
    monkeypatch.setattr(sw, "write_table", lambda df, out: seen.append(len(df)) or real_table(df, out))
    return seen


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_rows_reach_the_file_batch_by_batch(ball, tmp_path, monkeypatch, ext):
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    seen = _saves(monkeypatch)
    monkeypatch.setattr(sw, "BATCH_CELLS", 2)  # 6 distinct cells: 3 pieces
    monkeypatch.setattr(sw, "SAVE_EVERY_S", 1e9)  # no writes within a piece
    out = tmp_path / f"s{ext}"
    df = qemjax.sweep({"ball": ball}, {"placement": ["optimal", "endpoints", "rank"]}, [0.5, 40], metrics=False,
                      out=out, progress=False, workers=1)
    assert seen == [2, 4, 6]  # written after each batch, not once at the end
    assert list(sw.read_table(out)["cell"]) == list(df["cell"])


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_ctrl_c_during_a_write_still_keeps_every_finished_row(ball, tmp_path, monkeypatch, ext):
    """A Ctrl-C that lands while the table is being written (the write is lost: it goes to a temporary
    file first) leaves those rows waiting, and the interrupted sweep's last write keeps them all."""
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    real_text, real_table = sw.write_text, sw.write_table
    calls = []

    def interrupted_once(real):
        def write(*a):
            calls.append(1)
            if len(calls) == 2:
                raise KeyboardInterrupt  # the second write is where the signal lands
            return real(*a)
        return write
    monkeypatch.setattr(sw, "write_text", interrupted_once(real_text))
    monkeypatch.setattr(sw, "write_table", interrupted_once(real_table))
    monkeypatch.setattr(sw, "BATCH_CELLS", 2)  # 6 distinct cells: a write after each piece of 2 ...
    monkeypatch.setattr(sw, "SAVE_EVERY_S", 1e9)  # ... and none within a piece
    out = tmp_path / f"s{ext}"
    with pytest.raises(sw.SweepInterrupted, match="4 of 6 cells finished this run"):
        qemjax.sweep({"ball": ball}, {"placement": ["optimal", "endpoints", "rank"]}, [0.5, 40], metrics=False,
                     out=out, progress=False, workers=1)
    assert len(sw.read_table(out)) == 4  # every finished row, though the write that held the last two failed


def test_rows_reach_the_file_task_by_task_on_an_executor(ball, tmp_path, monkeypatch):
    seen = _saves(monkeypatch)
    monkeypatch.setattr(sw, "SAVE_EVERY_S", 0.0)  # tiny cells: written at each wake-up, not once a second
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        qemjax.sweep({"ball": ball}, {"boundary_weight": [1.0, 2.0, 3.0]}, [0.5], metrics=False, out=tmp_path / "s.csv",
                     executor=pool, progress=False)
    # one cell per task; the table after each wake-up (tasks done together are written together)
    assert seen[0] < 3 and seen[-1] == 3 and seen == sorted(set(seen))


def test_rows_stream_within_a_batch_with_metrics(ball, tmp_path, monkeypatch):
    """In a batch, each row is final after its metrics: the bar counts it then, and the table is written
    while the batch yields rows when `SAVE_EVERY_S` has passed (0 here: after every row)."""
    seen = _saves(monkeypatch)
    monkeypatch.setattr(sw, "SAVE_EVERY_S", 0.0)
    qemjax.sweep({"ball": ball}, {"boundary_weight": [1.0, 2.0]}, [0.5, 40], metrics={"n_samples": 500},
                 out=tmp_path / "s.csv", progress=False)
    assert seen[:4] == [1, 2, 3, 4]


def test_timing_columns_are_own_or_named_shares(ball):
    grid = {"placement": ["optimal", "endpoints"]}
    batched = qemjax.sweep({"ball": ball}, grid, [0.5], metrics={"n_samples": 500}, progress=False)
    alone = qemjax.sweep({"ball": ball}, grid, [0.5], metrics={"n_samples": 500}, progress=False, batch_size=1)
    assert list(batched["batch_size"]) == [2, 2] and list(alone["batch_size"]) == [1, 1]
    assert list(batched["result_sha256"]) == list(alone["result_sha256"])
    for r in batched.to_dict("records"):  # shared rounds: own time not measured; the share named so
        assert all(math.isnan(r[k]) for k in ("compile_s", "run_s", "total_s"))
        assert r["batch_wall_s"] > 0 and r["share_s"] >= r["batch_wall_s"] / 2
        assert r["cell_s"] == r["share_s"] + r["metrics_s"] and r["metrics_s"] > 0
    assert batched["batch_wall_s"].nunique() == 1  # the one shared run's wall time, in its own column
    for r in alone.to_dict("records"):  # alone: its own measured times
        assert r["total_s"] > 0 and r["share_s"] == r["batch_wall_s"] == r["total_s"]
        assert r["cell_s"] == r["total_s"] + r["metrics_s"]
    assert "time_s" not in batched.columns  # evaluate's time_s is metrics_s here


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_settings_that_do_not_apply_are_marked_and_counted(ball, tmp_path, ext):
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    grid = {"method": ["qem", "esqem"], "split_factor": [None, 1.5]}
    out = tmp_path / f"s{ext}"
    with pytest.warns(UserWarning, match=r"8 requested cells are 6 \(2 cells: split_factor does not apply to "
                                         r"method 'qem'"):
        df = qemjax.sweep({"ball": ball}, grid, [0.5, 40], metrics=False, out=out, progress=False)
    assert df.attrs["sweep"]["collapsed"] == {"split_factor does not apply to method 'qem'": 2}
    assert list(df.loc[df["method"] == "qem", "split_factor"]) == ["n/a", "n/a"]
    esqem = df.loc[df["method"] == "esqem", "split_factor"].tolist()
    assert esqem[2:] == [1.5, 1.5] and all(v is None or (isinstance(v, float) and math.isnan(v)) for v in esqem[:2])
    back = sw.read_table(out)  # the file keeps "n/a" apart from None (empty) and gives the numbers back
    assert back["split_factor"].tolist()[:2] == ["n/a", "n/a"] and back["split_factor"].tolist()[4:] == [1.5, 1.5]
    assert all(isinstance(v, float) and math.isnan(v) for v in back["split_factor"].tolist()[2:4])
    again = qemjax.sweep({"ball": ball}, grid, [0.5, 40], metrics=False, out=out, progress=False)
    assert again.attrs["sweep"]["skipped"] == 6 and again.attrs["sweep"]["ran"] == 0


def test_csv_columns_are_the_dataframes_and_the_documented_reader_keeps_not_applicable(ball, tmp_path):
    import csv
    import re

    import pandas as pd

    # qem rows come first and have no split_factor: the file's header must still put it after mesh
    grid = {"method": ["qem", "esqem"], "split_factor": [None, 1.5]}
    out = tmp_path / "sweep.csv"
    with pytest.warns(UserWarning, match="requested cells"):
        df = qemjax.sweep({"ball": ball}, grid, [0.5], metrics=False, out=out, progress=False)
    with open(out, newline="") as f:
        header = next(csv.reader(f))
    assert header == list(df.columns) and header[:5] == ["cell", "mesh", "method", "split_factor", "target"]
    # the recipe docs/sweeps.md gives, as written there
    doc = (ROOT / "docs" / "sweeps.md").read_text()
    (path, kwargs), = re.findall(r'pd\.read_csv\(("[^"]+"), (.*?)\)`', doc)
    assert path == '"sweep.csv"'
    back = eval(f"pd.read_csv(out, {kwargs})", {"pd": pd, "out": out})
    assert back["split_factor"].tolist()[0] == "n/a"  # qem: does not apply
    assert math.isnan(back["split_factor"].tolist()[1])  # esqem with split_factor None
    assert back["split_factor"].tolist()[2] == "1.5"
    assert pd.read_csv(out)["split_factor"].isna().tolist()[:2] == [True, True]  # what the recipe avoids


def test_peer_rows_mark_the_other_keys_not_applicable(ball):
    pytest.importorskip("meshoptimizer")
    df = qemjax.sweep({"ball": ball}, {"method": ["qem", "meshoptimizer"], "boundary_weight": [1.0, 2.0]}, [0.5],
                      metrics=False, progress=False)
    assert df.loc[df["method"] == "meshoptimizer", "boundary_weight"].tolist() == ["n/a"]


# ---- Ctrl-C, SIGKILL and resume, as a researcher meets them: the command in a process of its own -------

CONFIG = """meshes = ["shapes.bumpy_sphere(subdivisions=4)", "shapes.torus(n_major=48, n_minor=24)"]
targets = [0.5, 0.3, 0.2, 0.1]
out = "table.csv"
[grid]
boundary_weight = [1.0, 2.0]
regularize = [0.0, 0.05]
[metrics]
n_samples = 2000
"""
N_CELLS = 2 * 4 * 2 * 2

# the command with pieces of one run (so the test needs only small meshes to have many pieces)
SCRIPT = ("import sys, qemjax._sweep.run as sw; sw.PIECE_RUNS = 1; from qemjax import _cli; "
          "sys.exit(_cli.main(sys.argv[1:]))")


def _start(folder: Path, *args) -> subprocess.Popen:
    # the tests' compilation cache (`conftest`): the command loads the kernels the tests compiled
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("QEMJAX_NO_CACHE", None)
    return subprocess.Popen([sys.executable, "-c", SCRIPT, "sweep", str(folder / "s.toml"), "--quiet", *args],
                            cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_default)


def _rows(path: Path) -> list[str]:
    return path.read_text().splitlines()[1:] if path.exists() else []


def _wait_for_rows(proc, path: Path, n: int, timeout: float = 240) -> None:
    t0 = time.monotonic()
    while len(_rows(path)) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "no rows appeared"
        time.sleep(0.05)


# where the cells run: in the command's process (workers = 1), in it and a helper process (workers = 2), on a
# local Dask cluster (config lines)
EXECUTORS = {"in-process": "[executor]\nworkers = 1\n", "process-pool": "[executor]\nworkers = 2\n",
             "dask": "[executor]\nworkers = 2\nscheduler = \"dask\"\n"}


@pytest.mark.slow
@pytest.mark.parametrize("executor", list(EXECUTORS.values()), ids=list(EXECUTORS))
def test_ctrl_c_keeps_finished_rows_and_the_rerun_resumes(tmp_path, executor):
    if "dask" in executor:
        pytest.importorskip("distributed")
    (tmp_path / "s.toml").write_text(CONFIG + executor)
    table = tmp_path / "table.csv"
    proc = _start(tmp_path)
    _wait_for_rows(proc, table, 1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = _rows(table)
    assert 1 <= len(kept) < N_CELLS  # stopped before the end, every finished row on disk
    line = err.strip().splitlines()[-1]
    assert line.startswith("qemjax: interrupted: ") and "cells finished this run, kept in" in line, err
    assert f"{len(kept)} of {N_CELLS} done in all (a rerun resumes)" in line, line

    again = _start(tmp_path)
    out, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    assert f"{N_CELLS} cells (0 failed)" in out and f"{len(kept)} were already there (skipped)" in out, out
    rows = _rows(table)
    assert len(rows) == N_CELLS
    it = iter(rows)  # the rows from before, byte for byte, in order among the new ones
    assert all(any(r == old for r in it) for old in kept)


@pytest.mark.slow
def test_sigkill_loses_at_most_the_cells_in_flight(tmp_path):
    (tmp_path / "s.toml").write_text(CONFIG)
    table = tmp_path / "table.csv"
    proc = _start(tmp_path)
    _wait_for_rows(proc, table, 2)
    proc.kill()
    proc.communicate(timeout=60)
    kept = _rows(table)  # a whole table (written under a temporary name, then renamed): no partial row
    assert 2 <= len(kept) < N_CELLS
    again = _start(tmp_path)
    out, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    assert f"{len(kept)} were already there (skipped)" in out, out
    rows = _rows(table)
    assert len(rows) == N_CELLS and set(kept) <= set(rows)


# ---- Dask: a worker that dies does not lose the sweep ---------------------------------------------------

@pytest.mark.slow
def test_dask_worker_killed_mid_sweep_loses_nothing(tmp_path):
    distributed = pytest.importorskip("distributed")
    # meshes large enough that the sweep is still running when the worker dies (a few seconds of cells)
    meshes = {"ball": shapes.icosphere(5), "torus": shapes.torus(n_major=120, n_minor=60)}
    grid, targets = {"boundary_weight": [1.0, 2.0], "regularize": [0.0, 0.05]}, [0.5, 0.2, 0.1]
    want = qemjax.sweep(meshes, grid, targets, metrics=False, progress=False)
    out = tmp_path / "s.csv"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        killed = []

        def killer():
            t0 = time.monotonic()
            while len(_rows(out)) < 2 and time.monotonic() - t0 < 120:
                time.sleep(0.02)
            os.kill(pids[0], signal.SIGKILL)
            killed.append(len(_rows(out)))

        with concurrent.futures.ThreadPoolExecutor(1) as side:
            job = side.submit(killer)
            df = qemjax.sweep(meshes, grid, targets, metrics=False, executor=client, out=out, progress=False)
            job.result()
    assert killed and killed[0] < len(want)  # the worker died while cells were left
    assert (df["error"] == "").all()
    assert list(df["result_sha256"]) == list(want["result_sha256"])
    assert len(_rows(out)) == len(want)


def test_a_batch_yields_each_run_as_it_ends(ball, monkeypatch):
    """Cells of one batch that cannot share rounds (the greedy scheduler) run one after another: each row
    is final, and counted, when its own run ends, not when the whole batch does."""
    from qemjax._pipeline import stages

    order = []
    real = stages.run
    monkeypatch.setattr(stages, "run", lambda job: order.append("run") or real(job))
    items = [(ball, sw.Cell("ball", (("scheduler", "greedy"), ("boundary_weight", b)), 0.5)) for b in (1.0, 2.0)]
    for r in sw.iter_rows(items, False):
        order.append(r["boundary_weight"])
    assert order == ["run", 1.0, "run", 2.0]


class _Losing(concurrent.futures.ThreadPoolExecutor):
    """An executor whose first ``lose`` tasks are lost (their futures fail, as when a worker dies), and that
    takes no task at all after ``broken_after`` submissions (a broken pool)."""

    def __init__(self, lose: int, broken_after: int = 10**9):
        super().__init__(1)
        self.lose, self.broken_after, self.submitted = lose, broken_after, 0

    def submit(self, fn, *args, **kwargs):
        self.submitted += 1
        if self.submitted > self.broken_after:
            raise concurrent.futures.BrokenExecutor("a worker died")
        if self.lose:
            self.lose -= 1
            f = concurrent.futures.Future()
            f.set_exception(RuntimeError("worker lost"))
            return f
        return super().submit(fn, *args, **kwargs)


@pytest.mark.parametrize("lose, broken_after, submitted", [(2, 10**9, 3 + 2), (1, 3, 4)])
def test_lost_tasks_are_retried_then_run_here(ball, lose, broken_after, submitted):
    grid = {"boundary_weight": [1.0, 2.0, 3.0]}
    want = qemjax.sweep({"ball": ball}, grid, [0.5], metrics=False, progress=False)
    with _Losing(lose, broken_after) as pool:
        df = qemjax.sweep({"ball": ball}, grid, [0.5], metrics=False, executor=pool, progress=False)
        assert pool.submitted == submitted  # 3 tasks + one per lost one (the last one refused: run here)
    assert (df["error"] == "").all() and list(df["result_sha256"]) == list(want["result_sha256"])


def test_lost_tasks_give_up_after_the_retries(ball, monkeypatch):
    monkeypatch.setattr(sw, "RETRIES", 2)
    with _Losing(100) as pool:  # every submission lost: 1 + 2 tries, then the cell runs here
        df = qemjax.sweep({"ball": ball}, {}, [0.5], metrics=False, executor=pool, progress=False)
        assert pool.submitted == 3
    assert (df["error"] == "").all() and df["faces_out"].item() > 0


def test_simplify_cells_warnings_point_at_its_caller(ball):
    """simplify_cells runs through the generator iter_cells (rows as runs end): its warnings still name
    the caller's file."""
    with pytest.warns(UserWarning, match="is not below the mesh") as got:
        qemjax.simplify_cells([(ball, {"target_faces": 10**6}), (ball, {"target_faces": 10**6 + 1})])
    assert {Path(w.filename).name for w in got} == {Path(__file__).name}
