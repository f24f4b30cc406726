"""The command line, called in-process through `main` (one test runs it as a fresh process)."""
from __future__ import annotations

import functools
import inspect
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import _cli, shapes

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def no_cache(monkeypatch):
    """In-process runs must not point this test process's JAX at the user's cache folder."""
    monkeypatch.setenv("QEMJAX_NO_CACHE", "1")


@pytest.fixture
def src(tmp_path):
    V, F = shapes.bumpy_sphere(3)  # 1280 faces
    path = tmp_path / "in.ply"
    trimesh.Trimesh(V, F, process=False).export(path)
    return path


def _no_simplify(monkeypatch):
    """Make any call of simplify fail loudly: checks that must come first are seen to."""
    @functools.wraps(qemjax.simplify)  # the parser reads simplify's signature and docstring
    def boom(*args, **kwargs):
        raise AssertionError("simplify was called")
    monkeypatch.setattr(_cli._api, "simplify", boom)


def test_simplify_command(src, tmp_path, capsys):
    dst = tmp_path / "out.obj"
    assert _cli.main(["simplify", str(src), str(dst), "--faces", "200", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "1280 -> 200 faces (target 200 faces)" in out and "(squared distance, mesh units²)" in out
    assert len(trimesh.load(dst, process=False, force="mesh").faces) == 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out.obj"]  # no temporary files left


def test_simplify_command_bad_input(tmp_path, capsys):
    assert _cli.main(["simplify", str(tmp_path / "missing.obj"), str(tmp_path / "o.obj"),
                      "--ratio", "0.5", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("qemjax: error: mesh file not found") and err.count("\n") == 1


@pytest.mark.parametrize("name,match", [("out.xyz", "cannot write .xyz files"), ("out", "needs an extension"),
                                        ("out.nosuchformat", "cannot write .nosuchformat")])
def test_output_format_is_checked_before_simplifying(src, tmp_path, capsys, monkeypatch, name, match):
    _no_simplify(monkeypatch)
    assert _cli.main(["simplify", str(src), str(tmp_path / name), "--faces", "200", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / name).exists()


def test_output_folder_is_checked_before_simplifying(src, tmp_path, capsys, monkeypatch):
    _no_simplify(monkeypatch)
    assert _cli.main(["simplify", str(src), str(tmp_path / "nope" / "out.obj"), "--faces", "9", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "folder" in err and "does not exist" in err
    assert _cli.main(["simplify", str(src), str(tmp_path), "--faces", "9", "--quiet"]) == 2
    assert "is a folder" in capsys.readouterr().err
    if Path("/proc/self").is_dir():  # a folder no one can create files in, root included
        assert _cli.main(["simplify", str(src), "/proc/out.obj", "--faces", "9", "--quiet"]) == 2
        assert "cannot write to /proc" in capsys.readouterr().err


def test_failed_write_leaves_no_partial_file(src, tmp_path, capsys, monkeypatch):
    """A write that fails half-way leaves neither a partial output nor a temporary file, and an existing
    output is untouched."""
    dst = tmp_path / "out.obj"
    dst.write_text("keep me")

    export = trimesh.Trimesh.export

    def half_written(self, file_obj=None, file_type=None, **kw):
        if file_obj is None:  # the format check before simplifying writes to memory
            return export(self, file_obj, file_type, **kw)
        Path(file_obj).write_text("partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(trimesh.Trimesh, "export", half_written)
    assert _cli.main(["simplify", str(src), str(dst), "--faces", "200", "--quiet"]) == 2
    assert "cannot write" in capsys.readouterr().err
    assert dst.read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out.obj"]


@pytest.mark.parametrize("ratio", ["2", "0", "-1", "nan"])
def test_ratio_outside_zero_one_is_refused(src, tmp_path, capsys, monkeypatch, ratio):
    _no_simplify(monkeypatch)
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", ratio, "--quiet"]) == 2
    assert "ratio must be in (0, 1]" in capsys.readouterr().err


def test_library_refuses_ratio_above_one():
    with pytest.raises(ValueError, match=r"ratio must be in \(0, 1\]"):
        qemjax.simplify(shapes.icosphere(1), ratio=2)


def test_no_target_is_refused(src, tmp_path, capsys):
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--quiet"]) == 2
    assert "give a target" in capsys.readouterr().err


def test_max_error_alone_names_it_as_the_target(src, tmp_path, capsys):
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--max-error", "1e-4", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "(target max error 0.0001)" in out and "target 0" not in out


def test_warnings_are_one_line(src, tmp_path, capsys):
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--faces", "5000", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err == "qemjax: warning: target of 5000 faces is not below the mesh's 1280 faces: returning it unchanged\n"


def test_summary_and_cli_report_the_same_max_error(src, tmp_path, capsys):
    """One convention: the squared distance in mesh units, printed as such by both."""
    r = qemjax.simplify(src, target_faces=200)
    assert f"max error {r.max_error:.3g} (squared distance, mesh units²)" in r.summary()
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--faces", "200", "--quiet"]) == 0
    assert f"max error {r.max_error:.3g} (squared distance, mesh units²)" in capsys.readouterr().out


def test_demo_writes_only_when_asked(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert _cli.main(["demo", "--subdivisions", "3", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "1280 faces" in out and "not written" in out
    assert list(tmp_path.iterdir()) == []
    for flag in ["--out", "--output"]:
        dst = tmp_path / f"demo{flag}.obj"
        assert _cli.main(["demo", flag, str(dst), "--subdivisions", "3", "--quiet"]) == 0
        assert dst.exists() and f"-> {dst}" in capsys.readouterr().out


def test_version(capsys):
    assert _cli.main(["--version"]) == 0
    assert capsys.readouterr().out.startswith(f"qemjax {qemjax.__version__} (jax ")


def _simplify_actions():
    parser = _cli._parser()
    sub = next(a for a in parser._actions if a.dest == "cmd")
    return {a.dest: a for a in sub.choices["simplify"]._actions}


def test_every_simplify_keyword_is_reachable_or_listed():
    """Each keyword of qemjax.simplify is an option of `qemjax simplify`, or named in NOT_EXPOSED."""
    keywords = set(inspect.signature(qemjax.simplify).parameters)
    deliberate = set(_cli.OPTIONS) | set(_cli.TARGETS) | set(_cli.NOT_EXPOSED)
    assert keywords == deliberate, f"not in the CLI tables: {keywords - deliberate}; stale: {deliberate - keywords}"
    actions = _simplify_actions()
    for name in set(_cli.OPTIONS) | set(_cli.TARGETS):
        assert name in actions, f"--{name.replace('_', '-')} missing"
        assert actions[name].help, f"--{name.replace('_', '-')} has no help"


def test_options_reach_simplify(src, tmp_path, monkeypatch):
    """A command line with every option passes each one on, converted; options not given are not passed."""
    seen = []

    @functools.wraps(qemjax.simplify)
    def record(mesh, **kwargs):
        seen.append(kwargs)
        raise ValueError("recorded")

    monkeypatch.setattr(_cli._api, "simplify", record)
    feat = tmp_path / "feat.txt"
    feat.write_text("# a comment\n0 1\n1 2\n")
    out = str(tmp_path / "o.obj")
    argv = ["simplify", str(src), out, "--faces", "100", "--max-error", "0.5", "--method", "qem",
            "--scheduler", "greedy", "--placement", "endpoints", "--boundary-weight", "3", "--no-area-weighted",
            "--feature-edges", str(feat), "--pair-threshold", "0.25", "--no-preserve-topology",
            "--flip-angle", "none", "--no-weld", "--quiet", "--curvature-weight", "0.1", "--split-factor", "none"]
    assert _cli.main(argv) == 2
    kw = seen.pop()
    fe = kw.pop("feature_edges")
    assert fe.tolist() == [[0, 1], [1, 2]]
    assert kw == dict(target_faces=100, max_error=0.5, method="qem", scheduler="greedy", placement="endpoints",
                      boundary_weight=3.0, area_weighted=False, pair_threshold=0.25, preserve_topology=False,
                      flip_angle=None, weld=False, progress=False, curvature_weight=0.1, split_factor=None)
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--flip-angle", "45"]) == 2
    assert seen.pop() == dict(ratio=0.5, flip_angle=45.0, progress=True)
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--method", "esqem", "--split-factor", "1.5"]) == 2
    assert seen.pop() == dict(ratio=0.5, method="esqem", split_factor=1.5, progress=True)
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--memoryless", "--volume-weight", "0.5"]) == 2
    assert seen.pop() == dict(ratio=0.5, memoryless=True, volume_weight=0.5, progress=True)
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--split-factor", "big"]) == 2
    np.save(tmp_path / "feat.npy", np.array([[3, 4]]))
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--feature-edges",
                      str(tmp_path / "feat.npy")]) == 2
    assert seen.pop()["feature_edges"].tolist() == [[3, 4]]


def test_bad_feature_edge_file(src, tmp_path, capsys):
    bad = tmp_path / "feat.txt"
    bad.write_text("0 1 2\n3\n")
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5",
                      "--feature-edges", str(bad)]) == 2
    assert "could not read feature edges" in capsys.readouterr().err


def test_library_sets_no_global_jax_options(src):
    import jax

    before = jax.config.jax_compilation_cache_dir
    qemjax.simplify(src, target_faces=100)
    assert jax.config.jax_compilation_cache_dir == before


def test_fresh_process_fills_the_compilation_cache(src, tmp_path):
    """The real command, in its own process: it enables the persistent cache in QEMJAX_CACHE_DIR, and
    --no-cache leaves it alone."""
    env = {k: v for k, v in os.environ.items() if k != "QEMJAX_NO_CACHE"}
    env.update(QEMJAX_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "qemjax._cli", "simplify", str(src), str(tmp_path / "o.obj"), "--faces", "200",
           "--quiet"]
    done = subprocess.run(cmd + ["--no-cache"], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "cache").exists()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert len(list((tmp_path / "cache").iterdir())) >= 3  # one entry per compiled kernel shape


# ---- qemjax sweep CONFIG ------------------------------------------------------------------------------

SWEEP_TOML = """
meshes = ["sheet.ply", "ball.ply"]
targets = [0.5, 60]
out = "table.parquet"
[grid]
boundary_weight = [0, 1.0]
split_factor = ["none"]
[metrics]
n_samples = 500
"""
SWEEP_YAML = """
meshes: [sheet.ply, ball.ply]
targets: [0.5, 60]
out: table.parquet
grid: {boundary_weight: [0, 1.0], split_factor: [null]}
metrics: {n_samples: 500}
"""
TIMES = ["compile_s", "run_s", "total_s", "cell_s", "time_s"]  # wall times differ between two runs


@pytest.fixture
def sweep_dir(tmp_path):
    for name, mesh in [("sheet", shapes.grid(6, hole=True)), ("ball", shapes.icosphere(2))]:
        trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(tmp_path / f"{name}.ply")
    return tmp_path


@pytest.mark.parametrize("name,text", [("sweep.toml", SWEEP_TOML), ("sweep.yaml", SWEEP_YAML)])
def test_sweep_command_writes_the_sweep_table(sweep_dir, name, text, capsys):
    import pandas as pd

    if name.endswith(".yaml"):
        pytest.importorskip("yaml")
    (sweep_dir / name).write_text(text)
    assert _cli.main(["sweep", str(sweep_dir / name), "--quiet"]) == 0
    assert f"8 cells (0 failed) -> {sweep_dir / 'table.parquet'}" in capsys.readouterr().out
    got = pd.read_parquet(sweep_dir / "table.parquet")
    paths = [str(sweep_dir / "sheet.ply"), str(sweep_dir / "ball.ply")]
    want = qemjax.sweep(paths, {"boundary_weight": [0.0, 1.0], "split_factor": [None]}, [0.5, 60],
                        metrics={"n_samples": 500}, progress=False)
    assert len(got) == 8 and got["result_sha256"].nunique() > 4
    pd.testing.assert_frame_equal(got.drop(columns=TIMES), want.drop(columns=TIMES), check_dtype=False)


def _boom(*args, **kwargs):
    raise AssertionError("the sweep ran")


@pytest.mark.parametrize("text,match", [
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nmesh = 1', "unknown key 'mesh'"),
    ("targets = [0.5]", "'meshes' is missing"),
    ('meshes = ["sheet.ply"]', "'targets' is missing"),
    ('meshes = ["nope.ply"]\ntargets = [0.5]', "mesh file not found: "),
    ("meshes = 3\ntargets = [0.5]", "meshes must be a path"),
    ('meshes = ["sheet.ply"]\ntargets = [1.5]', "bad target 1.5"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\ngrid = 2', "grid must be a table"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nboundary_weight = ["high"]',
     "grid.boundary_weight: expected a number, got 'high'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nweld = [1]', "grid.weld: expected true/false, got 1"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nmethod = ["qme"]', "grid.method: unknown value 'qme'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nratio = [0.1]', "targets go in 'targets'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nregularize = []', "grid.regularize is empty"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nout = "t.xlsx"', "out must end in one of"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nout = "no/such/t.csv"', "does not exist"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nmetrics = "yes"', "metrics must be true, false or a table"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[metrics]\nsamples = 5', "unknown metrics key 'samples'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 0', "executor.workers must be an integer"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = "2"', "executor.workers must be an integer"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 2\nscheduler = "slurm"',
     "executor.scheduler must be one of process, dask"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 2\naddress = "tcp://h:8786"',
     "takes no workers"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nthreads = 2', "unknown executor key 'threads'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5\n', "not valid TOML"),
])
def test_sweep_command_bad_config(sweep_dir, monkeypatch, capsys, text, match):
    monkeypatch.setattr(qemjax._sweep, "sweep", _boom)
    (sweep_dir / "bad.toml").write_text(text)
    assert _cli.main(["sweep", str(sweep_dir / "bad.toml"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("qemjax: error: bad.toml: ") and err.count("\n") == 1, err
    assert match in err, err


def test_sweep_command_bad_files(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(qemjax._sweep, "sweep", _boom)
    assert _cli.main(["sweep", str(tmp_path / "missing.toml")]) == 2
    assert "config file not found" in capsys.readouterr().err
    (tmp_path / "c.json").write_text("{}")
    assert _cli.main(["sweep", str(tmp_path / "c.json")]) == 2
    assert "a config must be .toml, .yaml or .yml" in capsys.readouterr().err
    (tmp_path / "c.yaml").write_text("meshes: [a.ply]\n")
    monkeypatch.setitem(sys.modules, "yaml", None)  # as if pyyaml were not installed
    assert _cli.main(["sweep", str(tmp_path / "c.yaml")]) == 2
    assert "needs pyyaml (pip install pyyaml)" in capsys.readouterr().err


def test_sweep_config_executors(sweep_dir):
    """workers = N is a spawn process pool of N (not started here: nothing is submitted)."""
    from qemjax import _sweep_config

    (sweep_dir / "c.toml").write_text('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 3')
    config = _sweep_config.load(sweep_dir / "c.toml", out=str(sweep_dir / "x.csv"))
    assert config.out == str(sweep_dir / "x.csv") and config.executor == {"workers": 3}
    with _sweep_config.executor(config.executor) as pool:
        assert pool._max_workers == 3 and pool._mp_context.get_start_method() == "spawn"
    with _sweep_config.executor({}) as none:
        assert none is None


def test_sweep_example_config_is_valid():
    """The README's example file passes the checks anywhere: its meshes are made in code (the README test
    runs it)."""
    from qemjax import _sweep_config, shapes

    config = _sweep_config.load(ROOT / "experiments" / "sweep_example.toml")
    assert set(config.meshes) == {"bumpy_sphere", "torus"}
    assert all(shapes.is_spec(m) for m in config.meshes.values())
    assert config.grid["split_factor"] == [None, 1.3333333] and config.executor == {"workers": 2}
    assert config.targets == [0.1, 0.25, 200] and isinstance(config.targets[2], int)
    assert config.out.endswith("sweep_example.csv")
