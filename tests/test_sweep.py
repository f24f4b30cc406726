"""qemjax.sweep: every cell equals `simplify` alone, resume from `out=`, executors, validation."""
from __future__ import annotations

import concurrent.futures
import hashlib
import multiprocessing

import numpy as np
import pytest

import qemjax
import qemjax._sweep as sw
from qemjax import shapes

GRID = {"scheduler": ["parallel", "greedy"], "boundary_weight": [0.0, 1.0]}
TARGETS = [0.5, 60]


@pytest.fixture(scope="module")
def meshes():
    return {"sheet": shapes.grid(8, hole=True), "sphere": shapes.icosphere(2)}


@pytest.fixture(scope="module")
def reference(meshes):
    return qemjax.sweep(meshes, GRID, TARGETS, metrics=False, progress=False)


def own_hash(res) -> str:
    h = hashlib.sha256(np.ascontiguousarray(res.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(res.faces, np.int64).tobytes())
    return h.hexdigest()


def test_every_cell_equals_simplify_alone(meshes, reference):
    assert len(reference) == 2 * 4 * 2
    assert (reference["error"] == "").all()
    for row in reference.to_dict("records"):
        target = {"ratio": row["target"]} if row["target"] < 1 else {"target_faces": int(row["target"])}
        res = qemjax.simplify(meshes[row["mesh"]], scheduler=row["scheduler"],
                              boundary_weight=row["boundary_weight"], **target)
        assert row["result_sha256"] == own_hash(res), row["cell"]
        assert (row["faces_out"], row["stop_reason"]) == (len(res.faces), res.stop_reason)
    # the boundary weight changes the sheet's result: the grid really reached simplify
    sheet = reference[(reference["mesh"] == "sheet") & (reference["target"] == 60)]
    assert sheet["result_sha256"].nunique() == 4
    # on the closed sphere it changes nothing: the parallel cells of each target ran once, for both rows
    par = reference[reference["scheduler"] == "parallel"]
    assert list(par["same_run"]) == [1, 1, 1, 1, 2, 2, 2, 2]


def test_rows_in_cell_order_with_stable_keys(reference):
    assert list(reference.columns[:5]) == ["cell", "mesh", "scheduler", "boundary_weight", "target"]
    first = reference.iloc[0]
    assert (first["mesh"], first["scheduler"], first["boundary_weight"], first["target"]) == \
        ("sheet", "parallel", 0.0, 0.5)
    assert reference["cell"].is_unique
    # the key does not depend on the grid's key order
    assert sw.Cell("m", (("a", 1), ("b", 2)), 0.5).key == sw.Cell("m", (("b", 2), ("a", 1)), 0.5).key
    assert sw.Cell("m", (), 0.5).key != sw.Cell("m", (), 5).key


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_resume_runs_only_missing_cells(meshes, reference, tmp_path, monkeypatch, ext):
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"sweep{ext}"
    calls = []
    real, real_batch = sw.simplify, sw.simplify_cells

    def counting(mesh, **kw):
        calls.append(kw)
        return real(mesh, **kw)

    def counting_batch(cells, **kw):
        calls.extend(cells)
        return real_batch(cells, **kw)

    monkeypatch.setattr(sw, "simplify", counting)
    monkeypatch.setattr(sw, "simplify_cells", counting_batch)
    first = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, out=out, progress=False)
    assert len(calls) == len(reference)
    assert list(first["result_sha256"]) == list(reference["result_sha256"])

    table = sw.read_table(out)
    dropped = table["cell"].iloc[[3, 10]].tolist()
    sw.write_table(table[~table["cell"].isin(dropped)], out)
    calls.clear()
    again = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, out=out, progress=False)
    assert len(calls) == 2
    assert sorted(again.loc[again["cell"].isin(dropped), "cell"]) == sorted(dropped)
    assert list(again["result_sha256"]) == list(reference["result_sha256"])
    assert len(sw.read_table(out)) == len(reference)

    calls.clear()
    qemjax.sweep(meshes, GRID, TARGETS, metrics=False, out=out, progress=False)
    assert calls == []


def test_resume_reruns_exactly_the_dropped_cells(meshes, tmp_path, monkeypatch):
    out = tmp_path / "s.csv"
    grid = {"regularize": [0.0, 0.1, 0.3]}
    qemjax.sweep(meshes, grid, [0.5], metrics=False, out=out, progress=False)
    table = sw.read_table(out)
    keep = table[~((table["mesh"] == "sphere") & (table["regularize"] == 0.1))]
    sw.write_table(keep, out)
    ran = []
    real = sw.run_cells
    monkeypatch.setattr(sw, "run_cells", lambda items, metrics: ran.extend(c.key for _, c in items) or
                        real(items, metrics))
    qemjax.sweep(meshes, grid, [0.5], metrics=False, out=out, progress=False)
    assert ran == [sw.Cell("sphere", (("regularize", 0.1),), 0.5).key]


def test_failed_cells_have_an_error_and_rerun(meshes, tmp_path):
    out = tmp_path / "s.csv"
    grid = {"method": ["qem", "esqem"], "regularize": [0.1]}  # regularize cannot wrap esqem
    df = qemjax.sweep({"sphere": meshes["sphere"]}, grid, [0.5], metrics=False, out=out, progress=False)
    assert df.loc[df["method"] == "qem", "error"].item() == ""
    assert "regularize" in df.loc[df["method"] == "esqem", "error"].item()
    again = qemjax.sweep({"sphere": meshes["sphere"]}, grid, [0.5], metrics=False, out=out, progress=False)
    assert len(sw.read_table(out)) == 2 and len(again) == 2


def test_metrics_columns(meshes):
    m = meshes["sphere"]
    df = qemjax.sweep({"sphere": m}, {"method": ["qem"]}, [0.5], metrics={"n_samples": 1000}, progress=False)
    res = qemjax.simplify(m, ratio=0.5)
    row = qemjax.metrics.evaluate(m, res, target_faces=res.stats["target_faces"], n_samples=1000)
    for k, v in row.items():
        assert k in df.columns
        if k != "time_s":
            assert df[k].item() == v, k
    for k in ("compile_s", "run_s", "total_s", "faces_in", "faces_out", "stop_reason"):
        assert k in df.columns


def test_progress_bar_counts_cells(meshes, capsys):
    qemjax.sweep({"sphere": meshes["sphere"]}, {"regularize": [0.0, 0.1]}, [0.5], metrics=False)
    assert "2/2" in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["thread", "process"])
def test_executor_matches_in_process(meshes, reference, kind):
    if kind == "thread":
        pool = concurrent.futures.ThreadPoolExecutor(2)
    else:  # spawn: JAX's threads do not survive fork
        pool = concurrent.futures.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"))
    with pool:
        df = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, executor=pool, progress=False)
    assert list(df["cell"]) == list(reference["cell"])
    assert list(df["result_sha256"]) == list(reference["result_sha256"])


@pytest.mark.slow
def test_dask_local_cluster_matches_in_process(meshes, reference):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        scattered, scatter = [], client.scatter
        client.scatter = lambda data, **kw: scattered.append(len(data[0].faces)) or scatter(data, **kw)
        df = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, executor=client, progress=False)
    assert list(df["result_sha256"]) == list(reference["result_sha256"])
    assert scattered == [len(m.faces) for m in meshes.values()]  # each mesh once, not once per cell


def test_mesh_names(tmp_path):
    m = shapes.icosphere(1)
    assert list(sw.name_meshes(m)) == ["mesh0"]
    assert list(sw.name_meshes((m.vertices, m.faces))) == ["mesh0"]
    assert list(sw.name_meshes([m, m])) == ["mesh0", "mesh1"]
    assert list(sw.name_meshes({"a": m})) == ["a"]
    assert list(sw.name_meshes("x/cow.obj")) == ["cow"]
    assert list(sw.name_meshes(["x/cow.obj", "y/bunny.ply"])) == ["cow", "bunny"]


@pytest.mark.parametrize("grid, targets, kw, message", [
    ({"methd": ["qem"]}, [0.5], {}, "unknown grid keys \\['methd'\\]"),
    ({"ratio": [0.5]}, [0.5], {}, "targets go in `targets`"),
    ({"method": []}, [0.5], {}, "grid\\['method'\\] is empty"),
    ({}, [1.5], {}, "a ratio must be a float in \\(0, 1\\)"),
    ({}, [0], {}, "face count must be an int >= 1"),
    ({}, [True], {}, "bad target True"),
    ({}, ["10"], {}, "bad target '10'"),
    ({}, [], {}, "targets is empty"),
    ({}, [0.5, 0.5], {}, "repeat"),
    ({}, [0.5], {"out": "x.xlsx"}, "out must end in"),
    ({}, [0.5], {"executor": object()}, "executor must be"),
])
def test_validation(grid, targets, kw, message):
    with pytest.raises(ValueError, match=message):
        qemjax.sweep(shapes.icosphere(1), grid, targets, progress=False, **kw)


def test_out_that_is_not_a_sweep_table(tmp_path):
    out = tmp_path / "other.csv"
    out.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a sweep table"):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], out=out, progress=False)
    assert out.read_text() == "a,b\n1,2\n"  # left as it was


def test_duplicate_names():
    with pytest.raises(ValueError, match="same name"):
        qemjax.sweep(["a/cow.obj", "b/cow.obj"], {}, [0.5], progress=False)
