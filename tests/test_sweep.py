"""qemjax.sweep: every cell equals `simplify` alone, resume from `out=`, executors, validation."""
from __future__ import annotations

import concurrent.futures
import csv
import hashlib
import importlib.util
import multiprocessing
import os
import re
from pathlib import Path

import numpy as np
import pytest

import qemjax
import qemjax._sweep.run as sw
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
    real, real_batch = sw.simplify, sw.iter_cells

    def counting(mesh, **kw):
        calls.append(kw)
        return real(mesh, **kw)

    def counting_batch(cells, **kw):
        calls.extend(cells)
        return real_batch(cells, **kw)

    monkeypatch.setattr(sw, "simplify", counting)
    monkeypatch.setattr(sw, "iter_cells", counting_batch)
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
    real = sw.iter_rows
    monkeypatch.setattr(sw, "iter_rows", lambda items, metrics: ran.extend(c.key for _, c in items) or
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


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_a_mesh_changed_under_its_name_is_not_resumed(tmp_path, ext):
    """A resumed sweep whose mesh is another under the same name (a file edited, a shape made finer) refuses,
    naming the mesh and the file: its old rows would stand for the new mesh (all cells skipped), or sit
    beside the new mesh's rows. The same mesh again resumes."""
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"s{ext}"
    qemjax.sweep({"ball": shapes.icosphere(1)}, {}, [0.5], metrics=False, out=out, progress=False, workers=1)
    before = out.read_bytes()
    for targets in ([0.5], [0.5, 0.25]):  # every cell in the file, or some of them
        with pytest.raises(ValueError, match=r"holds rows of mesh 'ball' computed from another mesh"):
            qemjax.sweep({"ball": shapes.icosphere(2)}, {}, targets, metrics=False, out=out, progress=False,
                         workers=1)
        assert out.read_bytes() == before  # left as it was
    again = qemjax.sweep({"ball": shapes.icosphere(1)}, {}, [0.5, 0.25], metrics=False, out=out, progress=False,
                         workers=1)
    assert again.attrs["sweep"]["skipped"] == 1 and again["mesh_sha256"].nunique() == 1
    assert again["mesh_sha256"].iloc[0] == sw.mesh_hash(sw.load_mesh(shapes.icosphere(1)))


def test_metrics_columns(meshes):
    m = meshes["sphere"]
    df = qemjax.sweep({"sphere": m}, {"method": ["qem"]}, [0.5], metrics={"n_samples": 1000}, progress=False)
    res = qemjax.simplify(m, ratio=0.5, method="qem")
    row = qemjax.metrics.evaluate(m, res, target_faces=res.stats["target_faces"], n_samples=1000)
    for k, v in row.items():
        k = "metrics_s" if k == "time_s" else k  # the evaluation's own time, named so in a sweep
        assert k in df.columns
        if k != "metrics_s":
            assert df[k].item() == v, k
    for k in ("compile_s", "run_s", "total_s", "batch_wall_s", "share_s", "cell_s", "faces_in", "faces_out",
              "stop_reason"):
        assert k in df.columns


def test_progress_bar_counts_cells(meshes, capsys):
    qemjax.sweep({"sphere": meshes["sphere"]}, {"regularize": [0.0, 0.1]}, [0.5], metrics=False)
    assert "2/2" in capsys.readouterr().err


@pytest.mark.parametrize("kind", ["thread", pytest.param("process", marks=pytest.mark.slow)])
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
    # a tuple of two meshes is two meshes, not one (vertices, faces) pair: it was read as one, and every cell
    # failed on vertices "of rows of lengths [162, 320]"
    t = shapes.torus(n_major=8, n_minor=4)
    for pair in ((m, t), ((m.vertices, m.faces), (t.vertices, t.faces)), ("x/cow.obj", "y/bunny.ply")):
        named = sw.name_meshes(pair)
        assert len(named) == 2 and list(named.values()) == list(pair)
    assert list(sw.name_meshes((m.vertices.tolist(), m.faces.tolist()))) == ["mesh0"]
    assert list(sw.name_meshes((m.vertices.astype(object), m.faces))) == ["mesh0"]  # pandas' .values of a table


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
    ({"boundary_weight": [1.0, 1.0]}, [0.5], {}, "grid\\['boundary_weight'\\] repeats the value 1.0"),
    ({}, [0.5], {"out": "no/such/folder/x.csv"}, "out's folder does not exist"),
    ({}, [0.5], {"metrics": {"samples": 100}}, "metrics: unknown keyword 'samples'"),
    ({}, [0.5], {"metrics": {"seed": -1}}, "metrics: seed must be a non-negative integer, got -1"),
    ({}, [0.5], {"metrics": {"n_samples": 2.5}}, "metrics: n_samples must be a non-negative integer, got 2.5"),
])
def test_validation(grid, targets, kw, message, monkeypatch):
    """Each mistake is named before any cell runs (a bad metrics value was found by the first cell's
    evaluation, after its run, and named without 'metrics')."""
    def boom(*args, **kwargs):
        raise AssertionError("a cell ran")
    monkeypatch.setattr(sw, "iter_rows", boom)
    monkeypatch.setattr(sw, "run_cells", boom)
    with pytest.raises(ValueError, match=message):
        qemjax.sweep(shapes.icosphere(1), grid, targets, progress=False,
                     **(kw if "executor" in kw else {"workers": 1, **kw}))


def test_out_that_is_a_folder(tmp_path):
    (tmp_path / "t.csv").mkdir()
    with pytest.raises(ValueError, match="out is a folder"):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], progress=False, out=tmp_path / "t.csv")


def test_a_files_attributes_reach_its_cells(tmp_path):
    """A sweep reads a file as `simplify` does: the vertex colours of a PLY and the UVs of an OBJ that
    names its texture are kept in its cells (its rows equal lone runs), and in a helper process too."""
    from qemjax._io import mesh as _io

    V, F = shapes.bumpy_sphere(3)
    colours = (np.abs(V) * 255 / np.abs(V).max()).astype(np.uint8)
    import trimesh

    trimesh.Trimesh(V, F, vertex_colors=colours, process=False).export(tmp_path / "c.ply")
    qemjax.shapes.write_examples(tmp_path)
    from qemjax._cli import write

    # an OBJ whose material names its texture image: "auto" keeps its UVs
    write(qemjax.simplify(str(tmp_path / "textured.obj"), ratio=0.5, texture=str(tmp_path / "textured.png")),
          str(tmp_path / "t.obj"), "obj")
    files = {"c": str(tmp_path / "c.ply"), "t": str(tmp_path / "t.obj")}
    alone = {k: qemjax.simplify(f, ratio=0.3) for k, f in files.items()}
    assert alone["c"].stats["attributes"] == ["color"] and alone["t"].stats["attributes"] == ["uv"]
    grid = {"attribute_weights": [None, 3.0]}
    df = qemjax.sweep(files, grid, [0.3], metrics=False, progress=False, workers=1)
    for k in files:
        rows = df[df["mesh"] == k]
        assert rows["result_sha256"].iloc[0] == sw.result_hash(alone[k])
        assert rows["result_sha256"].nunique() == 2  # the weight of the kept attribute changes the run
        heavy = qemjax.simplify(files[k], ratio=0.3, attribute_weights=3.0)
        assert rows["result_sha256"].iloc[1] == sw.result_hash(heavy)
    # what a helper process gets pickles, and reads as the file does
    import pickle

    for k, f in files.items():
        got = pickle.loads(pickle.dumps(sw.load_mesh(f)))
        assert sw.result_hash(qemjax.simplify(got, ratio=0.3)) == sw.result_hash(alone[k])
    assert isinstance(sw.load_mesh(str(tmp_path / "bumpy.obj")), _io.Mesh)  # positions only: its arrays


def test_a_value_of_the_wrong_type_is_that_cells_error():
    df = qemjax.sweep({"t": shapes.torus(n_major=16, n_minor=8)}, {"attributes": [None, 3]}, [0.5],
                      metrics=False, progress=False, workers=1)
    assert df["error"].iloc[0] == "" and df["error"].iloc[1].startswith("ValueError: attributes must be")


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_columns_of_mixed_values_are_written_and_read_back(tmp_path, ext):
    """A grid column that mixes kinds of value (None, a tuple, a text) is written (Parquet stores it as
    text, as a CSV does), a resumed run finds every row, and a CSV's rows read back have no error ("")."""
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"m{ext}"
    grid = {"attributes": [None, ("normal",), "auto"], "attribute_weights": [None, 1.5]}
    first = qemjax.sweep(shapes.icosphere(1), grid, [0.5], metrics=False, progress=False, out=out, workers=1)
    again = qemjax.sweep(shapes.icosphere(1), grid, [0.5], metrics=False, progress=False, out=out, workers=1)
    assert len(first) == 6 and again.attrs["sweep"]["skipped"] == 4  # the failed cells run again
    assert list(again["result_sha256"].fillna("")) == list(first["result_sha256"].fillna(""))
    assert list(again["error"] == "") == list(first["error"] == "") and (first["error"] == "").sum() == 4


def test_out_that_is_not_a_sweep_table(tmp_path):
    out = tmp_path / "other.csv"
    out.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a sweep table"):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], out=out, progress=False)
    assert out.read_text() == "a,b\n1,2\n"  # left as it was


def test_duplicate_names():
    with pytest.raises(ValueError, match="same name"):
        qemjax.sweep(["a/cow.obj", "b/cow.obj"], {}, [0.5], progress=False)


# ---- row order and target types (the config's order; face counts stay ints) ---------------------------

def test_rows_keep_the_order_and_types_of_the_targets(meshes, tmp_path):
    """Rows by mesh, then grid cell, then target in the order given (not sorted); an int face count stays
    an int beside ratios, in the DataFrame, in a CSV's text, and read back from CSV and Parquet."""
    targets = [0.5, 60, 0.25]
    grid = {"boundary_weight": [1.0, 0.0]}
    df = qemjax.sweep(meshes, grid, targets, metrics=False, out=tmp_path / "s.csv", progress=False)
    want = [(m, bw, t) for m in meshes for bw in grid["boundary_weight"] for t in targets]
    assert list(zip(df["mesh"], df["boundary_weight"], df["target"])) == want
    assert [type(t) for t in df["target"][:3]] == [float, int, float]
    assert "60.0" not in df.to_string() and "60.00" not in df.to_string()
    with open(tmp_path / "s.csv", newline="") as f:
        assert [r["target"] for r in csv.DictReader(f)][:3] == ["0.5", "60", "0.25"]  # the file's text
    back = sw.read_table(tmp_path / "s.csv")
    assert list(back["cell"]) == list(df["cell"]) and list(back["target"]) == list(df["target"])
    assert [type(t) for t in back["target"][:3]] == [float, int, float]
    if importlib.util.find_spec("pyarrow"):
        pq = qemjax.sweep(meshes, grid, targets, metrics=False, out=tmp_path / "s.parquet", progress=False)
        back = sw.read_table(tmp_path / "s.parquet")
        assert list(back["cell"]) == list(pq["cell"]) == list(df["cell"])
        assert [type(t) for t in back["target"][:3]] == [float, int, float]
    # all face counts: an int column; all ratios: a float column
    assert str(qemjax.sweep(meshes["sphere"], {}, [60, 40], metrics=False, progress=False)["target"].dtype) == "int64"
    assert str(qemjax.sweep(meshes["sphere"], {}, [0.5], metrics=False, progress=False)["target"].dtype) == "float64"


def test_written_table_is_in_row_order_with_an_executor_and_on_resume(meshes, tmp_path):
    """Cells that finish out of order (an executor) or rows already in the file (resume) are written in
    row order; rows of another grid already in the file stay, before them."""
    out = tmp_path / "s.csv"
    other = qemjax.sweep(meshes["sphere"], {"regularize": [0.1]}, [0.5], metrics=False, out=out, progress=False)
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        df = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, executor=pool, out=out, progress=False)
    table = sw.read_table(out)
    assert list(table["cell"]) == list(other["cell"]) + list(df["cell"])
    drop = table["cell"].iloc[[2, 5]].tolist()
    sw.write_table(table[~table["cell"].isin(drop)], out)
    again = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, out=out, progress=False)
    assert list(sw.read_table(out)["cell"]) == list(other["cell"]) + list(again["cell"])
    assert list(again["cell"]) == list(df["cell"])


def test_parquet_without_pyarrow_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(__import__("sys").modules, "pyarrow", None)  # import pyarrow now fails
    with pytest.raises(ValueError, match=r"needs pyarrow \(pip install 'qemjax\[sweep\]'\)"):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], out=tmp_path / "s.parquet", progress=False)
    assert not (tmp_path / "s.parquet").exists()


# ---- meshes named as shapes made in code ---------------------------------------------------------------

def test_a_shape_too_large_to_run_is_refused_before_it_is_made(monkeypatch, tmp_path):
    """A shape named with counts whose run would not fit (shapes.torus(n_major=100000000)) was made all the
    same when the sweep loaded its meshes, and the system killed the process, without a word: it is refused
    when named, in the words of a file too large (`_pipeline.fits`)."""
    from qemjax._pipeline import fits
    from qemjax._sweep import config as _sweep_config

    monkeypatch.setattr(fits, "available", lambda: 1 << 30)  # 1 GiB: 2,097,152 faces at most
    assert shapes.parse_spec("shapes.torus(n_major=2048, n_minor=512)").name == "torus"  # 2,097,152 faces
    message = "shapes.torus(n_major=2049, n_minor=512): 2,098,176 faces need about 1.0 GiB in one process, and " \
              "this machine has 1.0 GiB available: ask for a smaller shape"
    with pytest.raises(ValueError, match=re.escape(message)):
        shapes.parse_spec("shapes.torus(n_major=2049, n_minor=512)")
    with pytest.raises(ValueError, match="shapes.icosphere.subdivisions=9.: 5,242,880 faces"):
        qemjax.sweep(["shapes.icosphere(subdivisions=9)"], {}, [0.5], progress=False)
    cfg = tmp_path / "s.toml"
    cfg.write_text('targets = [0.5]\n[meshes]\nbig = {shape = "grid", n = 1100}\n')
    with pytest.raises(ValueError, match=re.escape("s.toml: meshes: shapes.grid: 2,420,000 faces need")):
        _sweep_config.load(cfg)


@pytest.mark.parametrize("make,text", [
    (lambda: shapes.torus(n_major=300_000, n_minor=300_000), "shapes.torus(n_major=300000, n_minor=300000)"),
    (lambda: shapes.grid(300_000), "shapes.grid(n=300000)"),
    (lambda: shapes.icosphere(18), "shapes.icosphere(subdivisions=18)"),
    (lambda: shapes.bumpy_sphere(18), "shapes.bumpy_sphere(subdivisions=18)"),
    (lambda: shapes.cube(19), "shapes.cube(subdivisions=19)"),
    (lambda: shapes.double_cone(10**11), "shapes.double_cone(n=100000000000)"),
])
def test_a_shape_too_large_to_make_is_refused_when_called_directly(make, text, monkeypatch):
    """A generator called directly with counts whose mesh would need terabytes (here 10 TiB or more) went on
    to make it, and the system killed the process: only a shape named in a sweep was checked. It is refused
    before anything is made, in the sweep's words; a small shape does not read the memory available."""
    from qemjax._pipeline import fits

    monkeypatch.setattr(fits, "available", lambda: 1 << 30)
    with pytest.raises(ValueError, match=re.escape(text) + r": [\d,]+ faces need about \d+\.\d GiB in one "
                                         r"process, and this machine has 1\.0 GiB available: ask for a smaller shape$"):
        make()
    monkeypatch.setattr(fits, "available", lambda: 1 << 60)  # where they would fit: not refused
    assert shapes._room("torus", dict(n_major=300_000, n_minor=300_000)) is None
    monkeypatch.setattr(fits, "available", lambda: pytest.fail("a small shape read the memory available"))
    for small in (shapes.torus(), shapes.grid(), shapes.icosphere(4), shapes.bumpy_sphere(4), shapes.cube(5),
                  shapes.double_cone()):
        assert len(small.faces)


def test_shapes_named_as_text():
    spec = shapes.parse_spec("shapes.bumpy_sphere(subdivisions=2, amplitude=0.05)")
    assert spec == shapes.ShapeSpec("bumpy_sphere", (("subdivisions", 2), ("amplitude", 0.05)))
    assert shapes.parse_spec(str(spec)) == spec
    assert shapes.parse_spec("shapes.torus") == shapes.ShapeSpec("torus")
    assert shapes.parse_spec("shapes.grid(n=4, hole=true)").kwargs == (("n", 4), ("hole", True))
    assert shapes.parse_spec({"shape": "torus", "n_major": 12}) == shapes.parse_spec("shapes.torus(n_major=12)")
    V, F = spec.build()
    assert np.array_equal(F, shapes.bumpy_sphere(2, amplitude=0.05).faces)
    for bad, message in [("shapes.sphere", "unknown shape 'shapes.sphere'; qemjax.shapes makes shapes.bumpy"),
                         ("shapes.torus(3)", "give keyword arguments"),
                         ("shapes.torus(radius=2)", "unknown keyword 'radius'"),
                         ("shapes.torus(n_major=2.5)", "n_major must be int"),
                         ("shapes.torus(n_major=__import__('os'))", "must be numbers, strings or true/false"),
                         ("shapes.torus(", "write shapes.NAME"),
                         ("os.system('x')", "write shapes.NAME")]:
        with pytest.raises(ValueError, match=re.escape(message)):
            shapes.parse_spec(bad)


@pytest.mark.parametrize("make, message", [
    (lambda: shapes.torus(n_major=0), "shapes.torus: n_major must be an integer >= 3, got 0"),
    (lambda: shapes.torus(n_minor=2), "shapes.torus: n_minor must be an integer >= 3, got 2"),
    (lambda: shapes.torus(n_major=12.0), "shapes.torus: n_major must be an integer >= 3, got 12.0"),
    (lambda: shapes.grid(0), "shapes.grid: n must be an integer >= 1, got 0"),
    (lambda: shapes.grid(-2), "shapes.grid: n must be an integer >= 1, got -2"),
    (lambda: shapes.grid(2, hole=True), "shapes.grid: n must be an integer >= 3 with hole=True, got 2"),
    (lambda: shapes.icosphere(-1), "shapes.icosphere: subdivisions must be an integer >= 0, got -1"),
    (lambda: shapes.bumpy_sphere(-1), "shapes.bumpy_sphere: subdivisions must be an integer >= 0, got -1"),
    (lambda: shapes.cube(-1), "shapes.cube: subdivisions must be an integer >= 0, got -1"),
    (lambda: shapes.double_cone(2), "shapes.double_cone: n must be an integer >= 3, got 2"),
    (lambda: shapes.parse_spec("shapes.torus(n_minor=1)"),
     "shapes.torus(n_minor=1): n_minor must be an integer >= 3, got 1"),
    (lambda: shapes.parse_spec({"shape": "grid", "n": 1, "hole": True}), "shapes.grid: n must be an integer >= 3"),
    # lengths: zero made every vertex one point, a negative one turned the faces inside out
    (lambda: shapes.icosphere(2, radius=0), "shapes.icosphere: radius must be a number > 0, got 0"),
    (lambda: shapes.grid(4, size=-1.0), "shapes.grid: size must be a number > 0, got -1.0"),
    (lambda: shapes.double_cone(8, height=float("nan")), "shapes.double_cone: height must be a number > 0, got nan"),
    (lambda: shapes.torus(minor=0.0), "shapes.torus: minor must be a number > 0, got 0.0"),
    (lambda: shapes.torus(major=1.0, minor=1.5), "shapes.torus: minor must be less than major"),
    (lambda: shapes.parse_spec("shapes.torus(major=0.2)"), "shapes.torus(major=0.2): minor must be less than major"),
    # a bumpy sphere's seed raised numpy's own errors, and a NaN or infinite amplitude made NaN vertices
    (lambda: shapes.bumpy_sphere(1, seed=-1), "shapes.bumpy_sphere: seed must be an integer >= 0, got -1"),
    (lambda: shapes.bumpy_sphere(1, seed=1.5), "shapes.bumpy_sphere: seed must be an integer >= 0, got 1.5"),
    (lambda: shapes.bumpy_sphere(1, amplitude=float("nan")),
     "shapes.bumpy_sphere: amplitude must be a finite number, got nan"),
    (lambda: shapes.parse_spec("shapes.bumpy_sphere(amplitude=1e999)"),
     "shapes.bumpy_sphere(amplitude=1e999): amplitude must be a finite number, got inf"),
])
def test_shapes_refuse_counts_that_make_empty_or_repeated_faces(make, message):
    """0 or negative segments made an empty torus or grid, a negative subdivision quietly the level-0 mesh, two
    segments a torus or double cone of faces on the same vertices, a grid of 2 with a hole no faces at all."""
    with pytest.raises(ValueError, match="^" + re.escape(message)) as err:
        make()
    assert "\n" not in str(err.value)


def test_the_smallest_counts_make_meshes_of_distinct_faces():
    for mesh in (shapes.torus(n_major=3, n_minor=3), shapes.grid(1), shapes.grid(3, hole=True),
                 shapes.icosphere(0), shapes.cube(0), shapes.double_cone(3), shapes.torus(n_major=np.int64(3))):
        F = np.sort(mesh.faces, axis=1)
        assert len(F) and len(np.unique(F, axis=0)) == len(F) and (F[:, :-1] < F[:, 1:]).all()


def test_sweep_takes_shapes_named_as_text():
    df = qemjax.sweep(["shapes.icosphere(subdivisions=2)", "shapes.torus(n_major=12, n_minor=6)"], {}, [0.5],
                      metrics=False, progress=False)
    assert list(df["mesh"]) == ["icosphere", "torus"]
    assert list(df["faces_in"]) == [320, 144]
    assert df["result_sha256"][0] == own_hash(qemjax.simplify(shapes.icosphere(2), ratio=0.5))
    named = qemjax.sweep({"ball": "shapes.icosphere(subdivisions=2)"}, {}, [0.5], metrics=False, progress=False)
    assert named["mesh"].item() == "ball" and named["result_sha256"].item() == df["result_sha256"][0]
    with pytest.raises(ValueError, match="unknown shape 'shapes.ball'"):
        qemjax.sweep(["shapes.ball"], {}, [0.5], progress=False)


def test_config_file_with_shapes(tmp_path):
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "s.toml"
    cfg.write_text('meshes = ["shapes.icosphere(subdivisions=2)", "shapes.torus"]\ntargets = [0.5, 40]\n'
                   'out = "t.csv"\n[grid]\nboundary_weight = [1.0]\n')
    config = _sweep_config.load(cfg)
    assert config.meshes == {"icosphere": "shapes.icosphere(subdivisions=2)", "torus": "shapes.torus"}
    cfg.write_text('targets = [0.5]\n[meshes]\nball = {shape = "icosphere", subdivisions = 1}\n')
    assert _sweep_config.load(cfg).meshes == {"ball": "shapes.icosphere(subdivisions=1)"}
    for meshes, message in [('["shapes.sphere"]', "s.toml: meshes: unknown shape 'shapes.sphere'"),
                            ('["shapes.torus(n_major=true)"]', "s.toml: meshes: shapes.torus(n_major=true): "
                             "n_major must be int"),
                            ('["cow.obj"]', "s.toml: mesh file not found")]:
        cfg.write_text(f"meshes = {meshes}\ntargets = [0.5]\n")
        with pytest.raises(ValueError, match=re.escape(message)):
            _sweep_config.load(cfg)



def test_config_texture_paths_are_relative_to_the_config(tmp_path, monkeypatch):
    """A grid's texture image is a path relative to the config's folder, as its meshes are, whatever the
    working folder; a missing one is named before anything runs."""
    from qemjax._sweep import config as _sweep_config

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "tex.png").write_bytes(b"not read here")
    cfg = tmp_path / "sub" / "s.toml"
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "t.csv"\n'
                   '[grid]\nattributes = ["uv"]\ntexture = ["tex.png", "none"]\n')
    monkeypatch.chdir(tmp_path)
    config = _sweep_config.load(cfg)
    assert config.grid["texture"] == [str(tmp_path / "sub" / "tex.png"), None]
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\n[grid]\n"attributes.texture" = ["nope.png"]\n')
    with pytest.raises(FileNotFoundError, match=re.escape("s.toml: grid.attributes.texture: texture image not "
                                                          f"found: {tmp_path / 'sub' / 'nope.png'}")):
        _sweep_config.load(cfg)


def test_config_metrics_take_what_evaluate_takes(tmp_path):
    """A config's metrics.n_samples had to be >= 1 while qemjax.sweep and metrics.evaluate take 0 (the
    distances at the vertices alone, no attribute deviation): a config takes 0 too, and refuses what they
    refuse."""
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "s.toml"
    cfg.write_text('meshes = ["shapes.icosphere(subdivisions=2)"]\ntargets = [0.5]\nout = "t.csv"\n'
                   '[metrics]\nn_samples = 0\nseed = 0\n')
    config = _sweep_config.load(cfg)
    assert config.metrics == {"n_samples": 0, "seed": 0}
    df = qemjax.sweep(config.meshes, {}, config.targets, metrics=config.metrics, progress=False)
    assert df["error"].fillna("").eq("").all() and df["hausdorff"].notna().all()
    for k in ("n_samples", "seed"):
        cfg.write_text('meshes = ["shapes.icosphere(subdivisions=2)"]\ntargets = [0.5]\n'
                       f'[metrics]\n{k} = -1\n')
        with pytest.raises(ValueError, match=rf"metrics.{k} must be an integer >= 0, got -1"):
            _sweep_config.load(cfg)


def test_config_grid_takes_integers_and_untyped_keywords(tmp_path):
    """`grid.refit = [0, 1]` (an int keyword) and `grid.attributes = ["auto", "none"]` (a keyword without
    an annotation) are read as the Python sweep takes them, and run (issue 31's two config failures)."""
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "s.toml"
    cfg.write_text('meshes = ["shapes.icosphere(subdivisions=2)"]\ntargets = [0.5]\nout = "t.csv"\n'
                   '[metrics]\nn_samples = 500\n'
                   '[grid]\nrefit = [0, 1]\nattributes = ["auto", "none", ["uv"]]\n')
    config = _sweep_config.load(cfg)
    assert config.grid["refit"] == [0, 1] and all(type(v) is int for v in config.grid["refit"])
    assert config.grid["attributes"] == ["auto", None, ("uv",)]
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\n[grid]\nrefit = [0.5]\n')
    with pytest.raises(ValueError, match=r"grid.refit: expected a whole number, got 0.5"):
        _sweep_config.load(cfg)
    cfg.write_text('meshes = ["shapes.icosphere(subdivisions=2)"]\ntargets = [0.5]\nout = "t.csv"\n'
                   'metrics = false\n[grid]\nrefit = [0, 1]\nattributes = ["auto", "none"]\n')
    config = _sweep_config.load(cfg)
    df = qemjax.sweep(config.meshes, config.grid, config.targets, metrics=False, progress=False)
    assert len(df) == 4 and sorted(df["refit"].tolist()) == [0, 0, 1, 1]


# ---- pieces and helper processes (workers=) -------------------------------------------------------------

TIMINGS = ["compile_s", "run_s", "total_s", "batch_wall_s", "share_s", "cell_s"]  # the only columns that vary


def _table_bytes(df) -> bytes:
    """The table as CSV text without its timing columns (everything else is deterministic)."""
    return df.drop(columns=[c for c in TIMINGS if c in df.columns]).to_csv(index=False).encode()


def test_pieces_keep_runs_together_and_stay_within_their_caps(meshes, monkeypatch):
    """Cells that would run alike (every boundary weight on the closed sphere) are in one piece, where they
    run once; cells that cannot share rounds (another flip angle, the ring term) are in other pieces; each
    piece is within its caps; the cut depends on the cells alone."""
    monkeypatch.setattr(sw, "PIECE_RUNS", 2)
    grid = {"boundary_weight": [0.5, 2.0], "regularize": [0.0, 0.05], "flip_angle": [60.0, 90.0],
            "placement": ["optimal", "endpoints", "rank"]}
    cells = [sw.Cell(m, p, 0.5) for m in meshes for p in sw.expand_grid(grid)]
    loaded = {m: sw.load_mesh(v) for m, v in meshes.items()}
    faces = {m: len(v[1]) for m, v in loaded.items()}
    work = sw.pieces(cells, loaded, faces)
    assert sorted(c.key for p in work for c in p.cells) == sorted(c.key for c in cells)  # each cell once
    assert [[c.key for c in p.cells] for p in work] == \
        [[c.key for c in p.cells] for p in sw.pieces(cells, loaded, faces)]
    where = {c.key: k for k, p in enumerate(work) for c in p.cells}
    for c in cells:  # the sphere's boundary weights: the same run, in the same piece
        if c.mesh == "sphere" and dict(c.params)["boundary_weight"] == 0.5:
            twin = sw.Cell("sphere", tuple((k, 2.0 if k == "boundary_weight" else v) for k, v in c.params), 0.5)
            assert where[c.key] == where[twin.key]
    for p in work:
        kinds = {(dict(c.params)["flip_angle"], dict(c.params)["regularize"] > 0) for c in p.cells}
        assert len(kinds) == 1  # one group per piece: it shares its rounds
        runs = {(c.mesh, tuple((k, v) for k, v in c.params if not (c.mesh == "sphere" and k == "boundary_weight")))
                for c in p.cells}
        assert len(runs) <= sw.PIECE_RUNS


@pytest.mark.slow  # starts helper processes
def test_workers_give_the_same_table_as_this_process(meshes, reference, tmp_path, monkeypatch):
    """workers=2 (this process and a helper, taking pieces as each is free) and every piece on helpers give
    the same table as workers=1, byte for byte but the timings, and rows in cell order; the file too."""
    from qemjax._sweep import pool

    grid = {**GRID, "regularize": [0.0, 0.05]}
    try:
        one = qemjax.sweep(meshes, grid, TARGETS, metrics=False, progress=False, workers=1, out=tmp_path / "1.csv")
        monkeypatch.setattr(sw, "HERE_TOO", False)  # every piece to the helpers
        away = qemjax.sweep(meshes, grid, TARGETS, metrics=False, progress=False, workers=3,
                            out=tmp_path / "3.csv")
        assert pool.HELPERS.ready() >= 2
        monkeypatch.setattr(sw, "HERE_TOO", True)
        two = qemjax.sweep(meshes, grid, TARGETS, metrics=False, progress=False, workers=2)
        monkeypatch.delenv("QEMJAX_WORKERS", raising=False)  # automatic: finds them started, uses them
        default = qemjax.sweep(meshes, grid, TARGETS, metrics=False, progress=False)
    finally:
        pool.HELPERS.shutdown()
    assert _table_bytes(away) == _table_bytes(one) == _table_bytes(two) == _table_bytes(default)
    assert _table_bytes(sw.read_table(tmp_path / "3.csv")) == _table_bytes(sw.read_table(tmp_path / "1.csv"))
    ref = one[one["regularize"] == 0.0]
    assert list(ref["result_sha256"]) == list(reference["result_sha256"])


@pytest.mark.slow  # starts helper processes
def test_a_helper_that_dies_loses_no_row(meshes, tmp_path, monkeypatch):
    """A helper killed while it runs a piece: the piece runs again (on a helper, or here), every row is there."""
    import threading
    import time

    from qemjax._sweep import pool

    monkeypatch.setattr(sw, "HERE_TOO", False)
    monkeypatch.setattr(sw, "PIECE_RUNS", 1)  # many pieces
    killed = []

    def killer():
        t0 = time.monotonic()
        while not killed and time.monotonic() - t0 < 120:
            with pool.HELPERS.lock:
                busy = [h for h in pool.HELPERS.helpers if h.piece is not None]
            if busy:
                busy[0].proc.kill()
                killed.append(busy[0].proc.pid)
            time.sleep(0.001)

    side = threading.Thread(target=killer)
    try:
        side.start()
        df = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, progress=False, workers=3)
        side.join()
    finally:
        pool.HELPERS.shutdown()
    assert killed
    want = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, progress=False, workers=1)
    assert _table_bytes(df) == _table_bytes(want)


def test_the_default_stays_here_for_little_work_and_starts_helpers_for_the_next_sweeps(meshes, monkeypatch):
    """Automatic workers: no helper for a small sweep (it would start slower); once this process's sweeps
    add up to SWEPT_WORK, the next sweep starts them; $QEMJAX_WORKERS sets the default."""
    from qemjax._sweep import pool

    monkeypatch.delenv("QEMJAX_WORKERS", raising=False)
    assert sw.default_workers() is None
    monkeypatch.setattr(pool, "cores", lambda: 4)
    work = [sw.Piece([], 1000.0)] * 3
    assert pool.HELPERS.size() == 0 and sw._helpers(None, work, []) == 0  # little work, none started
    assert sw._helpers(None, [sw.Piece([], float(sw.START_WORK))] * 3, []) == 2  # at most one per piece but one
    assert sw._helpers(3, work, []) == 2 and sw._helpers(1, work, []) == 0
    monkeypatch.setattr(sw, "_SWEPT", [0.0])
    monkeypatch.setattr(sw, "SWEPT_WORK", 1)
    assert sw._helpers(None, work, []) == 0
    qemjax.sweep(meshes["sphere"], {}, [0.5], metrics=False, progress=False)
    assert pool.HELPERS.size() == 0 and sw._SWEPT[0] > 0  # not for a sweep that ended ...
    assert sw._helpers(None, work, []) == 2  # ... but for the next one
    monkeypatch.setenv("QEMJAX_WORKERS", "2")
    assert sw.default_workers() == 2
    monkeypatch.setenv("QEMJAX_WORKERS", "zero")
    with pytest.raises(ValueError, match="QEMJAX_WORKERS must be"):
        sw.default_workers()


@pytest.mark.parametrize("kw, message", [({"workers": 0}, "workers must be"), ({"workers": True}, "workers must be"),
                                         ({"workers": 2, "executor": concurrent.futures.ThreadPoolExecutor(1)},
                                          "not both")])
def test_workers_validation(kw, message):
    with pytest.raises(ValueError, match=message):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], progress=False, **kw)


@pytest.mark.slow  # starts helper processes
def test_what_a_helper_cannot_import_runs_here(meshes, monkeypatch):
    """A method class from the caller's script (``__main__``: a helper does not run the script): the default
    keeps such a sweep in this process, and workers=2 runs those pieces here; the rows are simplify's."""
    import dataclasses

    from qemjax._sweep import pool

    @dataclasses.dataclass(frozen=True)
    class ScriptQEM(qemjax.QEM):
        pass

    monkeypatch.setattr(ScriptQEM, "__module__", "__main__")
    grid = {"method": [ScriptQEM(boundary_weight=2.0), "qem"]}
    configs = sw.expand_grid(grid)
    assert pool.from_main(configs[0][0][1]) and not pool.from_main(configs[1][0][1])
    monkeypatch.setattr(pool, "cores", lambda: 4)
    assert sw._helpers(None, [sw.Piece([], float(sw.START_WORK))] * 3, configs) == 0
    monkeypatch.setattr(sw, "HERE_TOO", False)
    try:
        df = qemjax.sweep(meshes["sheet"], grid, [0.5], metrics=False, progress=False, workers=2)
    finally:
        pool.HELPERS.shutdown()
    assert (df["error"] == "").all()
    res = qemjax.simplify(meshes["sheet"], method=ScriptQEM(boundary_weight=2.0), ratio=0.5)
    assert df["result_sha256"].iloc[0] == own_hash(res)


@__import__("dataclasses").dataclass(frozen=True)
class ShippedQEM(qemjax.QEM):
    """A method registered by this process (`test_a_method_registered_here_runs_on_the_helpers`)."""

    boundary_weight: float = 3.0


@pytest.mark.slow  # starts helper processes
def test_a_method_registered_here_runs_on_the_helpers(meshes, monkeypatch):
    """The methods this process registered (from a module a helper can import) are registered in the helpers
    too: a grid may name them."""
    from qemjax import _costs
    from qemjax._sweep import pool

    monkeypatch.setitem(_costs.REGISTRY, "shipped", ShippedQEM)
    assert pool.registered()["methods"] == {"shipped": ShippedQEM} and pool.shippable()
    monkeypatch.setattr(sw, "HERE_TOO", False)
    try:
        df = qemjax.sweep(meshes["sheet"], {"method": ["shipped"]}, [0.5, 0.25], metrics=False, progress=False,
                          workers=2)
        assert pool.HELPERS.ready() == 1
    finally:
        pool.HELPERS.shutdown()
    assert (df["error"] == "").all()
    assert df["result_sha256"].iloc[1] == own_hash(qemjax.simplify(meshes["sheet"], method=ShippedQEM(), ratio=0.25))


def test_config_and_out_mistakes_are_named(tmp_path):
    """A YAML key that is not text, a shape that makes no mesh: one line naming it; an empty file as out:
    a table with no rows yet."""
    from qemjax._sweep import config as _sweep_config

    pytest.importorskip("yaml")
    cfg = tmp_path / "k.yaml"
    cfg.write_text('meshes: ["shapes.torus"]\ntargets: [0.5]\ngrid: {3: [1]}\n')
    with pytest.raises(ValueError, match="k.yaml: 3 is not a key a sweep config has"):
        _sweep_config.load(cfg)
    with pytest.raises(ValueError, match=re.escape("shapes.torus(n_major=-3): n_major must be an integer >= 3")):
        qemjax.sweep(["shapes.torus(n_major=-3)"], {}, [0.5], metrics=False, progress=False, workers=1)
    out = tmp_path / "empty.csv"
    out.write_text("")
    df = qemjax.sweep(shapes.icosphere(1), {}, [0.5], metrics=False, progress=False, workers=1, out=out)
    assert len(df) == 1 and len(sw.read_table(out)) == 1


def test_a_second_sweep_writing_the_same_table_is_refused(meshes, tmp_path, monkeypatch):
    """Two sweeps given one ``out`` at once (a script started twice, two threads) each wrote back only the rows
    it had read and run itself, through the same temporary file: the rows of the one that wrote first were
    lost. The second is refused in one line while the first runs; the first writes every row, and no file is
    left beside the table."""
    import threading

    out = tmp_path / "s.csv"
    inside, go, real = threading.Event(), threading.Event(), sw.load_mesh

    def held(value):  # the first sweep waits here, its table read, until the second has tried
        if not inside.is_set():
            inside.set()
            go.wait(60)
        return real(value)

    monkeypatch.setattr(sw, "load_mesh", held)
    done = {}
    first = threading.Thread(target=lambda: done.update(df=qemjax.sweep(
        {"sphere": meshes["sphere"]}, {"scheduler": ["parallel"]}, [0.5], metrics=False, out=out, progress=False,
        workers=1)))
    first.start()
    try:
        assert inside.wait(60)
        with pytest.raises(ValueError, match=r"^out .*s\.csv is being written by another sweep"):
            qemjax.sweep({"sheet": meshes["sheet"]}, {"scheduler": ["parallel"]}, [0.5], metrics=False, out=out,
                         progress=False, workers=1)
    finally:
        go.set()
        first.join()
    assert list(sw.read_table(out)["cell"]) == list(done["df"]["cell"])
    assert [p.name for p in tmp_path.iterdir()] == ["s.csv"]
    # once it has ended, the table is free again: the next sweep adds its rows to it
    qemjax.sweep({"sheet": meshes["sheet"]}, {"scheduler": ["parallel"]}, [0.5], metrics=False, out=out,
                 progress=False, workers=1)
    assert len(sw.read_table(out)) == 2 and [p.name for p in tmp_path.iterdir()] == ["s.csv"]


def test_a_lock_a_forked_worker_inherited_does_not_hold_the_table(tmp_path):
    """A worker forked while a sweep held its table (a fork-based executor) keeps the lock it inherited for
    its own life: the lock file is removed as the sweep lets go, so the next sweep takes a new one."""
    from qemjax._io import held

    path = tmp_path / ".s.csv.lock"
    fd = held.take(path, "busy")
    inherited = os.dup(fd)  # what a forked process holds: the same lock
    try:
        with pytest.raises(ValueError, match="^busy$"):
            held.take(path, "busy")
        held.release(path, fd)
        again = held.take(path, "busy")
        assert again is not None and path.exists()
        held.release(path, again)
        assert not path.exists()
    finally:
        os.close(inherited)


def test_repeated_targets_are_named_by_a_config_check(tmp_path):
    """A target given twice is refused when the config is checked, naming the file and the value (it was
    refused only once the sweep started, in words that named neither); sweep names the value too."""
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "twice.toml"
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5, 100, 0.5]\nout = "t.csv"\n')
    with pytest.raises(ValueError, match=re.escape("twice.toml: targets repeat the value 0.5")):
        _sweep_config.load(cfg)
    with pytest.raises(ValueError, match="targets repeat the value 100"):
        qemjax.sweep(shapes.icosphere(1), {}, [100, 0.5, 100], metrics=False, progress=False, workers=1)
    assert sw.check_targets([0.5, 100]) == [0.5, 100]


@pytest.mark.parametrize("name, data, why", [
    ("bytes.csv", bytes(range(128, 256)) * 4, "it is not text"),
    ("ragged.csv", b"cell,mesh\na,b\n1,2,3,4\n", "Expected 2 fields in line 3, saw 4"),
    ("text.parquet", b"not a table\n", "it is not a Parquet file"),
])
def test_an_out_that_cannot_be_read_back_is_named(tmp_path, name, data, why):
    """A file at out that is no table (binary in a .csv, ragged rows, text in a .parquet): one line naming
    it, before anything runs, not the reader's own words (a decoder's byte position, pandas' C tokenizer,
    Parquet's footer) naming nothing; the file is left as it was."""
    if name.endswith(".parquet"):
        pytest.importorskip("pyarrow")
    out = tmp_path / name
    out.write_bytes(data)
    with pytest.raises(ValueError, match=re.escape(f"{out} exists but is not a sweep table ({why})")):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], metrics=False, progress=False, workers=1, out=out)
    assert out.read_bytes() == data


@pytest.mark.parametrize("cut", ["footer", "length"])
def test_a_damaged_parquet_out_is_named_as_no_table(tmp_path, cut):
    """A Parquet file at out whose magic bytes are right but whose footer is damaged (zeroed) or whose length
    is not the footer's (cut short) is no table either: pyarrow raises an OSError for the first ("Couldn't
    deserialize thrift"), which passed through in its words, and for the second named the file twice in its
    own. Both are the one line of a file that is no table; the file is left as it was."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    out = tmp_path / "s.parquet"
    pd.DataFrame({"cell": ["a" * 20] * 200, "x": range(200)}).to_parquet(out)
    whole = out.read_bytes()
    data = whole[:4] + bytes(len(whole) - 12) + whole[-8:] if cut == "footer" else whole[:len(whole) // 2] + whole[-8:]
    out.write_bytes(data)
    with pytest.raises(ValueError, match=re.escape(f"{out} exists but is not a sweep table (it is not a whole "
                                                   "Parquet file: cut short or damaged)")):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], metrics=False, progress=False, workers=1, out=out)
    assert out.read_bytes() == data


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_a_sweep_resumed_with_other_metrics_refuses(tmp_path, ext):
    """The metrics are no part of a cell's key: a sweep resumed with other metrics (none before, or other
    samples) skipped the cells in the file and returned their rows beside rows measured otherwise (NaN
    metrics, or another sampling), silently. It refuses, naming the file and both settings; the same
    settings, however written (True and the defaults spelt out), resume."""
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"s{ext}"
    mesh = {"ball": shapes.icosphere(1)}
    qemjax.sweep(mesh, {}, [0.5], metrics=False, out=out, progress=False, workers=1)
    before = out.read_bytes()
    with pytest.raises(ValueError, match=re.escape(f"{out} holds rows measured with metrics none (metrics=False), "
                                                   "where this sweep asks for n_samples=50, seed=0")):
        qemjax.sweep(mesh, {}, [0.5, 0.25], metrics={"n_samples": 50}, out=out, progress=False, workers=1)
    assert out.read_bytes() == before
    out.unlink()
    qemjax.sweep(mesh, {}, [0.5], metrics={"n_samples": 50}, out=out, progress=False, workers=1)
    with pytest.raises(ValueError, match="measured with metrics n_samples=50, seed=0, where this sweep asks for "
                                         "n_samples=60, seed=0"):
        qemjax.sweep(mesh, {}, [0.5, 0.25], metrics={"n_samples": 60}, out=out, progress=False, workers=1)
    with pytest.raises(ValueError, match="where this sweep asks for none"):
        qemjax.sweep(mesh, {}, [0.5], metrics=False, out=out, progress=False, workers=1)
    again = qemjax.sweep(mesh, {}, [0.5, 0.25], metrics={"seed": 0, "n_samples": 50}, out=out, progress=False,
                         workers=1)
    assert again.attrs["sweep"]["skipped"] == 1 and again["metrics_settings"].nunique() == 1
    assert sw.metrics_settings({}) == sw.metrics_settings({"n_samples": 100_000, "seed": 0})


def test_a_schedule_in_a_config_is_refused_without_pointing_at_fields_it_has_not(tmp_path):
    """A config cannot give a Schedule, nor vary its fields by name (grid."schedule.gate" is no grid key): the
    refusal sent the user to vary "its fields by name" with two Topology fields as the examples; it points at
    qemjax.sweep from Python alone. Topology's refusal still names its fields."""
    from qemjax._sweep import config as _sweep_config

    assert not sw.is_grid_key("schedule.gate") and sw.is_grid_key("topology.weld")
    cfg = tmp_path / "s.toml"
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "s.csv"\n[grid]\nschedule = ["fast"]\n')
    with pytest.raises(ValueError) as err:
        _sweep_config.load(cfg)
    assert str(err.value) == ('s.toml: grid.schedule: a Schedule cannot be given in a config file; use '
                              'qemjax.sweep from Python (grid={"schedule": [qemjax.Schedule(...), ...]})')
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "s.csv"\n[grid]\ntopology = ["x"]\n')
    with pytest.raises(ValueError, match=re.escape('vary its fields by name (grid.flip_angle, grid."topology.weld")')):
        _sweep_config.load(cfg)


def test_a_config_with_an_unknown_preset_is_refused_before_it_runs(tmp_path):
    """grid.preset names a method configuration (as grid.method may): an unknown one stops the config's check,
    naming the file, the key and the presets, as an unknown method does; it ran, each cell failing."""
    from qemjax._sweep import config as _sweep_config

    cfg = tmp_path / "p.toml"
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "p.csv"\n[grid]\npreset = ["classic", "fast"]\n')
    with pytest.raises(ValueError, match=re.escape("p.toml: grid.preset: unknown value 'fast'; one of default, "
                                                   "classic, accurate")):
        _sweep_config.load(cfg)
    cfg.write_text('meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "p.csv"\n[grid]\npreset = ["classic", "accurate"]\n')
    assert _sweep_config.load(cfg).grid == {"preset": ["classic", "accurate"]}


def test_a_grid_value_given_twice_as_int_and_float_is_refused():
    """1 and 1.0 set the same boundary weight: the grid ran them as two cells (their keys' JSON differs),
    two rows of one configuration. Refused as any repeated value is; distinct values and bools stay."""
    with pytest.raises(ValueError, match=re.escape("grid['boundary_weight'] repeats the value 1: two cells")):
        qemjax.sweep(shapes.icosphere(1), {"boundary_weight": [1, 2.0, 1.0]}, [0.5], metrics=False,
                     progress=False, workers=1)
    with pytest.raises(ValueError, match="repeats the value 0.5"):
        sw.expand_grid({"regularize": [0.5, np.float64(0.5)]})
    assert len(sw.expand_grid({"boundary_weight": [1, 2.0, np.float32(0.1), 0.1]})) == 4
    assert len(sw.expand_grid({"measure": [True, False]})) == 2


@pytest.mark.parametrize("metrics", [None, "n_samples=100", 1, ["n_samples"]])
def test_metrics_that_are_neither_a_bool_nor_keywords_are_refused(metrics):
    """metrics takes True, False or evaluate's keywords: anything else (None, a text, a number) was read as
    False, a sweep without metrics and without a word. Refused before anything runs; numpy's bools are bools."""
    with pytest.raises(ValueError, match=re.escape(f"metrics must be True, False or a dict of "
                                                   f"qemjax.metrics.evaluate's keywords ({{'n_samples': 10_000}}), "
                                                   f"got {metrics!r}")):
        qemjax.sweep(shapes.icosphere(1), {}, [0.5], metrics=metrics, progress=False, workers=1)


def test_numpys_bools_are_metrics_bools():
    ball = shapes.icosphere(1)
    assert "rms_rel" not in qemjax.sweep(ball, {}, [0.5], metrics=np.False_, progress=False, workers=1)
    df = qemjax.sweep(ball, {}, [0.5], metrics=np.True_, progress=False, workers=1)
    assert df["rms_rel"].notna().all() and df["metrics_settings"].item() == sw.metrics_settings({})


def _folders_that_take_no_file(tmp_path):
    """Folders that exist but take no new file: /proc/self (Linux, even for root) and a read-only folder
    (where permissions hold: not for root)."""
    out = []
    if Path("/proc/self").is_dir():
        out.append(Path("/proc/self"))
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    if not os.access(locked, os.W_OK):
        out.append(locked)
    if not out:
        pytest.skip("no folder here refuses new files")
    return out


def test_an_out_whose_folder_takes_no_file_is_refused_before_anything_runs(tmp_path, monkeypatch):
    """The out's folder existing was checked, not that it takes the table's temporary file: the cells ran,
    then the first write failed with pandas' traceback (qemjax sweep: exit code 1). Refused before any cell
    runs, one line naming out, in qemjax.sweep and in a config's check."""
    from qemjax._sweep import config as _sweep_config

    def no_cell_may_run(items, metrics):
        pytest.fail(f"a cell ran: {items[0][1].key}")

    monkeypatch.setattr(sw, "iter_rows", no_cell_may_run)
    for folder in _folders_that_take_no_file(tmp_path):
        out = folder / "s.csv"
        with pytest.raises(ValueError, match=re.escape(f"cannot write {out}: its folder takes no new file (")):
            qemjax.sweep(shapes.icosphere(1), {}, [0.5], metrics=False, progress=False, workers=1, out=out)
        cfg = tmp_path / "c.toml"
        cfg.write_text(f'meshes = ["shapes.torus"]\ntargets = [0.5]\nout = "{out}"\n')
        with pytest.raises(ValueError, match=re.escape(f"c.toml: cannot write {out}: its folder takes no new file")):
            _sweep_config.load(cfg)
    assert os.listdir(tmp_path / "locked") == []


def test_a_table_on_a_file_system_without_locks_leaves_no_lock_file(meshes, tmp_path, monkeypatch):
    """Where the file system refuses locks (flock's ENOLCK on some network and FUSE file systems) nothing is
    held, as documented; but the lock file `take` made was kept, so every sweep left a hidden ``.NAME.lock``
    beside its table for good. It is removed when it cannot be locked."""
    import errno

    from qemjax._io import held

    class NoLocks:
        LOCK_EX, LOCK_NB = 2, 4

        @staticmethod
        def flock(fd, how):
            raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(held, "fcntl", NoLocks)
    assert held.take(tmp_path / ".x.lock", "busy") is None and not (tmp_path / ".x.lock").exists()
    out = tmp_path / "s.csv"
    qemjax.sweep({"sphere": meshes["sphere"]}, {"scheduler": ["parallel"]}, [0.5], metrics=False, out=out,
                 progress=False, workers=1)
    assert [p.name for p in tmp_path.iterdir()] == ["s.csv"]
