"""The command line, called in-process through `main` (one test runs it as a fresh process)."""
from __future__ import annotations

import argparse
import functools
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import qemjax
from qemjax import _cli, shapes
import qemjax._sweep.run  # noqa: F401  (tests patch its sweep; imported whichever tests run)
from conftest import sigint_default

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def no_cache(monkeypatch):
    """In-process runs keep the cache the test process has (conftest: a test folder, not the user's)."""
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
    assert "1280 -> 200 faces (target 200 faces)" in out and "(quadric error (a sum of squared distances to planes), mesh units²)" in out
    assert len(trimesh.load(dst, process=False, force="mesh").faces) == 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out.obj"]  # no temporary files left


def test_simplify_command_bad_input(tmp_path, capsys):
    assert _cli.main(["simplify", str(tmp_path / "missing.obj"), str(tmp_path / "o.obj"),
                      "--ratio", "0.5", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("qemjax: error: mesh file not found") and err.count("\n") == 1


@pytest.mark.parametrize("name,match", [("out.xyz", "as .xyz: the format holds points only, no faces; use one of obj"),
                                        ("out", "needs an extension"),
                                        ("out.nosuchformat", "as .nosuchformat: not a mesh format; use one of obj")])
def test_output_format_is_checked_before_simplifying(src, tmp_path, capsys, monkeypatch, name, match):
    _no_simplify(monkeypatch)
    assert _cli.main(["simplify", str(src), str(tmp_path / name), "--faces", "200", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err and err.count("\n") == 1
    assert "PointCloud" not in err and "exporter" not in err  # the user's terms, not trimesh's
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

    def half_written(path, data):
        Path(path).write_text("partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(_cli, "_write_file", half_written)
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


def test_summary_and_cli_report_the_same_distance_and_cost(src, tmp_path, capsys):
    """One convention: the measured distance in mesh units, and the largest cost named a quadric error."""
    r = qemjax.simplify(src, target_faces=200)
    line = (f"distance from the input: max {r.stats['distance_max']:.3g} = "
            f"{100 * r.stats['distance_max_rel']:.3g} % of the diagonal, rms {r.stats['distance_rms']:.3g} mesh units; "
            f"largest contraction cost {r.max_error:.3g} (quadric error (a sum of squared distances to planes), mesh units²)")
    assert line in r.summary()
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--faces", "200", "--quiet"]) == 0
    assert line in capsys.readouterr().out


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


def test_demo_subdivisions_are_bounded(capsys):
    """12 subdivisions made 335 M faces in memory until the system stopped the process: refused in one line."""
    for n in ("12", "-1"):
        assert _cli.main(["demo", "--subdivisions", n, "--quiet"]) == 2
        assert f"expected 0 to 10 subdivisions (20 × 4^N faces), got {n}" in capsys.readouterr().err


def test_version(capsys):
    assert _cli.main(["--version"]) == 0
    assert capsys.readouterr().out.startswith(f"qemjax {qemjax.__version__} (jax ")


def _simplify_actions():
    parser = _cli._parser()
    sub = next(a for a in parser._actions if a.dest == "cmd")
    return {a.dest: a for a in sub.choices["simplify"]._actions}


def test_every_simplify_keyword_and_setting_is_reachable_or_listed():
    """Each run keyword of qemjax.simplify and each field of the methods, Topology and Attributes is an
    option of `qemjax simplify` (with help), or named in NOT_EXPOSED."""
    import inspect as _inspect

    from qemjax._pipeline import flat as _flat

    params = _inspect.signature(qemjax.simplify).parameters
    keywords = {k for k, p in params.items() if p.kind is not p.VAR_KEYWORD}
    actions = _simplify_actions()
    for name in (keywords | set(_flat.options())) - set(_cli.NOT_EXPOSED):
        assert name in actions, f"--{name.replace('_', '-')} missing"
        assert actions[name].help, f"--{name.replace('_', '-')} has no help"
    assert set(_cli.OPTIONS) <= set(actions), f"stale OPTIONS: {set(_cli.OPTIONS) - set(actions)}"


def test_help_gives_the_default_methods_settings():
    """The defaults `--help` shows are the fields' own; where the method the command runs without --method
    sets another, the help says so (it showed QEM()'s alone: --boundary-weight 100, --refit 0)."""
    actions = _simplify_actions()
    default = qemjax.QEM.default()
    for name in ("boundary_weight", "refit", "polish", "sliver_moves", "quality_threshold", "area_power",
                 "late_memoryless"):
        text = " ".join(actions[name].help.split())
        assert f"; {getattr(default, name)} with the default method)" in text, (name, text)
    assert "with the default method" not in actions["flip_angle"].help  # the same in both


def test_help_says_what_an_unset_default_does():
    """--measure's help ended `(default: None)` and --min-angle's `default off (default: None)`: Python's
    None, not what the command does without them (measure when the method re-fits; no angle floor)."""
    for name, parser in _cli._parser().subcommands.items():
        for action in parser._actions:
            assert "(default: None)" not in (action.help or ""), (name, action.dest, action.help)
    actions = _simplify_actions()
    assert "(default: on when the method re-fits" in " ".join(actions["measure"].help.split())
    assert " ".join(actions["min_angle"].help.split()).endswith("'none': off (default: none)")


def test_help_says_each_default_once_and_offers_only_what_the_command_has():
    """--prune's help said its default twice ("False (default): ... (default: False)": its docstring's and
    the one added to every option), and `qemjax lod --help`'s --scheduler told of --partition, which lod
    does not offer: every option's help names its default at most once, and lod's mention no --partition."""
    for name, parser in _cli._parser().subcommands.items():
        for action in parser._actions:
            text = " ".join((action.help or "").split())
            assert text.count("(default") <= 1, (name, action.dest, text)
            if name == "lod" and action.help != argparse.SUPPRESS:
                assert "--partition" not in text, (action.dest, text)
    assert "--partition" in " ".join(_simplify_actions()["scheduler"].help.split())


def test_help_is_the_first_sentence_of_each_setting():
    """Each option's help is its setting's first sentence: a half-open interval, s in [0, √3/2), ended the
    sentence count's brackets one short, and --quality-threshold's help ran on through the whole entry;
    --tol, whose docstring has no entry of its own, had none."""
    actions = _simplify_actions()
    text = " ".join(actions["quality_threshold"].help.split())
    assert text.startswith("s in [0, √3/2), a triangle-shape term") and "The cost" not in text, text
    assert "bisection" in actions["tol"].help


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


def test_vertex_files_that_cannot_be_read_are_refused_in_the_users_terms(src, tmp_path, capsys):
    """A binary file given as text was refused in the words of Python's decoder ("'utf-8' codec can't decode
    byte 0x89"), a ragged one with numpy's advice to "use `usecols`", an argument of numpy's the user never
    passes: the file's form is named instead, and the advice left out."""
    image = tmp_path / "t.png"
    image.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    ragged = tmp_path / "feat.txt"
    ragged.write_text("0 1\n2\n")
    for flag, path, said in (
            ("--feature-edges", image, "could not read feature edges from {}: it is not text: expected a .npy file "
                                       "or text with two integers per line"),
            ("--locked", image, "could not read --locked from {}: it is not text: expected a .npy file or text "
                                "with one integer per line"),
            ("--vertex-weights", image, "could not read --vertex-weights from {}: it is not text: expected a .npy "
                                        "file or text with one number per line"),
            ("--feature-edges", ragged, "could not read feature edges from {}: the number of columns changed from "
                                        "2 to 1 at row 2")):
        assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", flag, str(path)]) == 2
        err = capsys.readouterr().err
        assert err.splitlines()[0] == "qemjax: error: " + said.format(path), err


def test_simplify_sets_no_global_jax_options(src):
    """Only importing qemjax touches JAX's options (the compilation cache: tests/test_compile_cache.py)."""
    import jax

    before = jax.config.jax_compilation_cache_dir
    qemjax.simplify(src, target_faces=100)
    assert jax.config.jax_compilation_cache_dir == before


@pytest.mark.slow
def test_fresh_process_fills_the_compilation_cache(src, tmp_path):
    """The real command, in its own process: the persistent cache in QEMJAX_CACHE_DIR is on, and --no-cache
    leaves it alone."""
    env = {k: v for k, v in os.environ.items() if k != "QEMJAX_NO_CACHE"}
    env.update(QEMJAX_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "qemjax._cli", "simplify", str(src), str(tmp_path / "o.obj"), "--faces", "200",
           "--quiet"]
    done = subprocess.run(cmd + ["--no-cache"], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())  # made at import, unused
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
flip_angle = ["none"]
[metrics]
n_samples = 500
"""
SWEEP_YAML = """
meshes: [sheet.ply, ball.ply]
targets: [0.5, 60]
out: table.parquet
grid: {boundary_weight: [0, 1.0], flip_angle: [null]}
metrics: {n_samples: 500}
"""
TIMES = ["compile_s", "run_s", "total_s", "batch_wall_s", "share_s", "metrics_s", "cell_s"]  # wall times differ


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
    want = qemjax.sweep(paths, {"boundary_weight": [0.0, 1.0], "flip_angle": [None]}, [0.5, 60],
                        metrics={"n_samples": 500}, progress=False)
    assert len(got) == 8 and got["result_sha256"].nunique() > 4
    pd.testing.assert_frame_equal(got.drop(columns=TIMES), want.drop(columns=TIMES), check_dtype=False)


def _boom(*args, **kwargs):
    raise AssertionError("the sweep ran")


@pytest.mark.parametrize("text,match", [
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nmesh = 1', "unknown key 'mesh'; did you mean 'meshes'?"),
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
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nboundry_weight = [0.1]',
     "unknown grid key 'boundry_weight'; did you mean 'boundary_weight'?;"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[grid]\nregularize = []', "grid.regularize is empty"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nout = "t.xlsx"', "out must end in one of"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nout = "no/such/t.csv"', "does not exist"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\nmetrics = "yes"', "metrics must be true, false or a table"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[metrics]\nsamples = 5',
     "unknown metrics key 'samples'; did you mean 'n_samples'?"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 0', "executor.workers must be an integer"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = "2"', "executor.workers must be an integer"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 2\nscheduler = "slurm"',
     "executor.scheduler must be one of process, dask"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 2\naddress = "tcp://h:8786"',
     "takes no workers"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nthreads = 2', "unknown executor key 'threads'"),
    ('meshes = ["sheet.ply"]\ntargets = [0.5\n', "not valid TOML"),
    ('meshes = ["shapes.torus(n_major=8)", "shapes.torus"]\ntargets = [0.5]',  # not "pass a dict", Python's
     "meshes: two meshes have the same name 'torus': name each in a table, [meshes] torus_a = "),
])
def test_sweep_command_bad_config(sweep_dir, monkeypatch, capsys, text, match):
    monkeypatch.setattr(qemjax._sweep.run, "sweep", _boom)
    (sweep_dir / "bad.toml").write_text(text)
    assert _cli.main(["sweep", str(sweep_dir / "bad.toml"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("qemjax: error: bad.toml: ") and err.count("\n") == 1, err
    assert match in err and err.count("bad.toml") == 1, err  # the file named once


def test_a_missing_mesh_in_a_config_is_a_file_not_found_error_named_once(sweep_dir):
    from qemjax._sweep import config

    (sweep_dir / "b1.toml").write_text('meshes = ["nope.ply"]\ntargets = [0.5]')
    with pytest.raises(FileNotFoundError) as err:
        config.load(sweep_dir / "b1.toml")
    assert str(err.value) == f"b1.toml: mesh file not found: {sweep_dir / 'nope.ply'}"
    assert err.value.filename == str(sweep_dir / "nope.ply")
    with pytest.raises(FileNotFoundError, match=r"^config file not found: .*missing\.toml$"):
        config.load(sweep_dir / "missing.toml")


def test_a_misspelt_option_suggests_the_close_one(src, tmp_path, capsys, monkeypatch):
    _no_simplify(monkeypatch)
    for cmd, args in [("simplify", [str(src), str(tmp_path / "o.obj"), "--ratio", "0.5"]),
                      ("lod", [str(src), str(tmp_path / "lods")])]:
        assert _cli.main([cmd, *args, "--boundry-weight", "1"]) == 2
        err = capsys.readouterr().err
        assert err == ("qemjax: error: unrecognized arguments: --boundry-weight 1; did you mean "
                       f"--boundary-weight?\nsee 'qemjax {cmd} --help'\n")
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio=0.5", "--flip-angel=30"]) == 2
    assert "--flip-angel=30; did you mean --flip-angle?\n" in capsys.readouterr().err
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", "--xyzzy"]) == 2
    assert capsys.readouterr().err.startswith("qemjax: error: unrecognized arguments: --xyzzy\n")
    # lod hides the options it refuses: they are not suggested
    assert _cli.main(["lod", str(src), str(tmp_path / "lods"), "--atributes", "uv"]) == 2
    assert "--attributes" not in capsys.readouterr().err


def test_lod_refuses_simplify_targets_as_lod_chain_does(src, tmp_path, capsys, monkeypatch):
    """qemjax lod --max-distance 0.1 answered "did you mean --max-shift?", an option of another meaning, and
    --faces or --max-error nothing: lod_chain's own refusal says where the levels' targets come from."""
    _no_simplify(monkeypatch)
    for flag in ("--max-distance", "--max-distance-rel", "--faces", "--max-error"):
        assert _cli.main(["lod", str(src), str(tmp_path / "lods"), flag, "0.1"]) == 2
        assert capsys.readouterr().err == (f"qemjax: error: unrecognized arguments: {flag} 0.1; qemjax lod takes "
                                           f"its targets from --ratios, not {flag}\nsee 'qemjax lod --help'\n")
    assert not (tmp_path / "lods").exists()


def test_what_max_distance_cannot_keep_is_named_as_an_option(src, tmp_path, capsys):
    """--max-distance with ESQEM's splits or with attributes kept: the error names the options that turn them
    off (it named simplify's keywords alone, split_factor=None and attributes=None)."""
    out = str(tmp_path / "o.ply")
    assert _cli.main(["simplify", str(src), out, "--method", "esqem", "--max-distance-rel", "0.01", "--quiet"]) == 2
    assert "(CLI: --split-factor none)" in capsys.readouterr().err
    V, F = shapes.bumpy_sphere(2)
    colours = np.random.default_rng(0).integers(0, 255, (len(V), 4)).astype(np.uint8)
    trimesh.Trimesh(V, F, vertex_colors=colours, process=False).export(tmp_path / "c.ply")
    assert _cli.main(["simplify", str(tmp_path / "c.ply"), out, "--max-distance-rel", "0.01", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "(CLI: --attributes none; kept: color)" in err and err.count("\n") == 1, err


def test_a_file_with_nan_coordinates_is_named(tmp_path, capsys):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    assert _cli.main(["simplify", str(path), str(tmp_path / "o.obj"), "--ratio", "0.5", "--quiet"]) == 2
    assert capsys.readouterr().err == \
        f"qemjax: error: {path}: vertices contain NaN or inf coordinates (1 vertices, first: 2)\n"


def test_sweep_command_bad_files(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(qemjax._sweep.run, "sweep", _boom)
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
    """workers = N is the sweep's own pool: N processes (this one and N - 1 helpers), no executor."""
    from qemjax._sweep import config as _sweep_config

    (sweep_dir / "c.toml").write_text('meshes = ["sheet.ply"]\ntargets = [0.5]\n[executor]\nworkers = 3')
    config = _sweep_config.load(sweep_dir / "c.toml", out=str(sweep_dir / "x.csv"))
    assert config.out == str(sweep_dir / "x.csv") and config.executor == {"workers": 3}
    assert _sweep_config.local(config.executor) and not _sweep_config.local({})
    assert not _sweep_config.local({"workers": 2, "scheduler": "dask"})
    with _sweep_config.executor(config.executor) as pool:
        assert pool is None
    with _sweep_config.executor({}) as none:
        assert none is None


def test_sweep_example_config_is_valid(tmp_path):
    """The example config `qemjax examples` writes passes the checks where it is written (the README test
    runs it): bumpy.obj beside it, the torus made in code."""
    from qemjax._sweep import config as _sweep_config

    assert _cli.main(["examples", str(tmp_path)]) == 0
    config = _sweep_config.load(tmp_path / "sweep_example.toml")
    assert config.meshes == {"bumpy": str(tmp_path / "bumpy.obj"), "torus": "shapes.torus(n_major=32, n_minor=16)"}
    assert config.grid["split_factor"] == [None, 1.3333333] and config.executor == {"workers": 2}
    assert config.targets == [0.1, 0.25, 200] and isinstance(config.targets[2], int)
    assert config.out == str(tmp_path / "sweep_example.csv")



def test_examples_help_names_every_file_it_writes(tmp_path, capsys):
    """`qemjax examples --help` and `qemjax --help` name every file `qemjax examples` writes (they left out
    sweep_example.toml)."""
    assert _cli.main(["examples", str(tmp_path)]) == 0
    for argv in (["examples", "--help"], ["--help"]):
        assert _cli.main(argv) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert [p.name for p in sorted(tmp_path.iterdir()) if p.name not in text] == []



def test_demo_help_names_the_subdivisions_as_its_text_does(capsys):
    """`qemjax demo --help` shows ``--subdivisions N``, the N its text counts with (it showed SUBDIVISIONS)."""
    assert _cli.main(["demo", "--help"]) == 0
    text = capsys.readouterr().out
    assert "--subdivisions N " in text and "20 × 4^N faces" in " ".join(text.split())


# ---- rough edges: one-line errors, Ctrl-C, units, clean-up and attributes in the summary, lod -------

@pytest.mark.parametrize("argv,match", [
    (["simplify", "IN", "OUT", "--ratio", "0"], "argument --ratio: ratio must be in (0, 1]"),
    (["simplify", "IN", "OUT", "--faces", "-5"], "argument --faces: the face target must be at least 1"),
    (["simplify", "IN", "OUT", "--faces", "2.5"], "argument --faces: expected a whole number of faces"),
    (["simplify", "IN", "OUT", "--method", "foo"], "argument --method: invalid choice: 'foo'"),
    (["simplify", "IN", "OUT", "--ratio", "0.5", "--bogus"], "unrecognized arguments: --bogus"),
    (["simplify", "IN", "OUT", "--ratio", "0.5", "--faces", "3"], "not allowed with argument --ratio"),
    (["lod", "IN", "OUT", "--ratios", "x"], "argument --ratios: expected a ratio in (0, 1], got 'x'"),
    (["demo", "--subdivisions", "x"], "argument --subdivisions: expected a whole number of subdivisions, got 'x'"),
    (["sweep"], "the following arguments are required: config"),
    (["frob"], "invalid choice: 'frob'"),
    (["simplify", "IN", "OUT"], "give a target"),  # a validation error after parsing: one line
])
def test_usage_errors_are_one_line(src, tmp_path, capsys, monkeypatch, argv, match):
    """No usage block: 'qemjax: error: …' and at most one hint line, exit code 2."""
    _no_simplify(monkeypatch)
    argv = [str(src) if a == "IN" else str(tmp_path / "o.obj") if a == "OUT" else a for a in argv]
    assert _cli.main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert 1 <= len(lines) <= 2 and lines[0].startswith("qemjax: error: ") and match in lines[0], captured.err
    assert "usage:" not in captured.err and captured.out == ""
    if len(lines) == 2:
        cmd = argv[0] if argv[0] in ("simplify", "lod", "sweep", "demo") else None
        assert lines[1] == f"see 'qemjax {cmd} --help'" if cmd else lines[1] == "see 'qemjax --help'"


def _interrupt(cmd, env, folder, timeout=300):
    """Run ``cmd``, send SIGINT once the progress bar shows (the run has started); (rc, stderr), rc None
    when the run finished before the signal."""
    import signal
    import threading
    import time

    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=sigint_default)
    err = bytearray()
    reader = threading.Thread(target=lambda: [err.extend(b) for b in iter(lambda: p.stderr.read1(4096), b"")])
    reader.start()
    end = time.monotonic() + timeout
    while b"simplify" not in err and p.poll() is None and time.monotonic() < end:
        time.sleep(0.02)
    finished = p.poll() is not None
    if not finished:
        p.send_signal(signal.SIGINT)
    try:
        rc = p.wait(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
        reader.join()
    return (None if finished else rc), err.decode()


@pytest.mark.slow
def test_ctrl_c_is_one_line_and_leaves_no_file(tmp_path):
    """SIGINT during a run: 'qemjax: interrupted', exit code 130, no output and no temporary file."""
    V, F = shapes.bumpy_sphere(7)  # 327,680 faces: seconds of work after the bar appears
    src = tmp_path / "big.obj"
    trimesh.Trimesh(V, F, process=False).export(src)
    env = dict(os.environ, PYTHONPATH=str(ROOT), QEMJAX_NO_CACHE="1")
    for scheduler in ("parallel", "greedy"):  # greedy is far slower, should the parallel run win the race
        cmd = [sys.executable, "-m", "qemjax._cli", "simplify", str(src), str(tmp_path / "out.obj"),
               "--ratio", "0.01", "--scheduler", scheduler]
        rc, err = _interrupt(cmd, env, tmp_path)
        if rc is not None:
            break
        (tmp_path / "out.obj").unlink()
    else:
        pytest.skip("both runs finished before SIGINT could be sent")
    assert rc == 130, err
    assert err.endswith("qemjax: interrupted\n") and err.count("\n") <= 2 and "Traceback" not in err, err
    assert [p.name for p in tmp_path.iterdir()] == ["big.obj"]


def test_ctrl_c_inside_a_gc_callback_is_sent_again(monkeypatch):
    """Python swallows an exception raised while a garbage-collector callback runs (JAX registers one), so
    the handler does not raise there: it remembers the interrupt and sends it again a moment later."""
    import gc
    import signal
    import time

    sent = []
    monkeypatch.setattr(_cli, "_resend", lambda: sent.append(True))
    monkeypatch.setattr(_cli, "_INTERRUPTED", [])
    frames = []

    def callback(phase, info):
        frames.append(sys._getframe())

    gc.callbacks.append(callback)
    try:
        gc.collect()
        assert _cli._on_sigint(signal.SIGINT, frames[0]) is None  # inside the callback: deferred, not raised
    finally:
        gc.callbacks.remove(callback)
    deadline = time.monotonic() + 5
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sent and _cli._INTERRUPTED
    with pytest.raises(KeyboardInterrupt):  # anywhere else: raised at once
        _cli._on_sigint(signal.SIGINT, sys._getframe())


def _frame_in(context: str):
    """A frame (finished) where Python or a library drops an exception raised there: numba's own Python
    code, a destructor, or a weak reference's callback (there: the weakref module's frame that calls it)."""
    import os
    import weakref

    import numba

    frames = []
    if context == "numba":  # a function whose code lives in numba's folder, as numba.core.serialize's does
        space = {"sys": sys}
        exec(compile("def callback():\n    return sys._getframe()\n",
                     os.path.join(os.path.dirname(numba.__file__), "core", "serialize.py"), "exec"), space)
        return space["callback"]()

    class Held:
        def __del__(self):
            frames.append(sys._getframe())
    held = Held()
    if context == "destructor":
        del held
    else:
        weakref.finalize(held, lambda: frames.append(sys._getframe(1)))
        del held
    return frames[-1]


@pytest.mark.parametrize("context", ["numba", "destructor", "weakref"])
def test_ctrl_c_where_python_drops_exceptions_is_sent_again(monkeypatch, context):
    """A compiled loop calls back into numba's Python code (to build its constants) and drops an exception
    raised there; Python drops one raised in a destructor (dask's futures have one) or a weak reference's
    callback. A Ctrl-C that lands in such a frame is remembered and sent again, not raised (a sweep ran to
    its end this way, its interrupt lost: in process in numba's code, once on Dask)."""
    import signal
    import time

    sent = []
    monkeypatch.setattr(_cli, "_resend", lambda: sent.append(True))
    monkeypatch.setattr(_cli, "_INTERRUPTED", [])
    monkeypatch.setattr(_cli, "_RAISED", [])
    try:
        _cli._on_sigint(signal.SIGINT, _frame_in(context))
    except KeyboardInterrupt:
        pytest.fail(f"raised inside {context}, where the exception would be dropped")
    deadline = time.monotonic() + 5
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sent and _cli._INTERRUPTED and not _cli._RAISED
    with pytest.raises(KeyboardInterrupt):  # in the project's own code: raised at once
        _cli._on_sigint(signal.SIGINT, sys._getframe())


def test_summary_names_each_methods_unit(src, tmp_path, capsys):
    """max error is a quadric error for qem/esqem, an area change for --method area."""
    from qemjax import _costs

    assert _costs.build(_costs.QEM()).error_unit == "quadric error (a sum of squared distances to planes), mesh units²"
    assert _costs.build(_costs.ESQEM()).error_unit == "quadric error (a sum of squared distances to planes), mesh units²"
    assert _costs.build(_costs.AreaDifference()).error_unit == "surface-area change, mesh units²"
    assert _costs.build(_costs.QEM(), weights=[1.0, 1.0]).error_unit == \
        "quadric error (a sum of squared distances to planes) plus weighted attribute deviation, mesh units²"
    assert _costs.build(_costs.QEM(regularize=0.5)).error_unit == \
        "quadric error (a sum of squared distances to planes) plus λ·shape term, mesh units²"
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--faces", "600", "--method", "area",
                      "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "(surface-area change, mesh units²)" in out and "squared distance" not in out


def test_cleanup_is_named_in_the_summary(tmp_path, capsys):
    V, F = shapes.bumpy_sphere(3)  # 1280 faces, plus 300 reversed and 100 exact copies
    path = tmp_path / "dup.ply"
    trimesh.Trimesh(V, np.concatenate([F, F[:300, ::-1], F[:100]]), process=False).export(path)
    assert _cli.main(["simplify", str(path), str(tmp_path / "o.ply"), "--ratio", "0.5", "--quiet"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "1280 -> 640 faces (target 640 faces)" in lines[0]
    assert lines[1] == "  clean-up: 400 duplicate faces removed; the ratio applied to the 1280 faces left " \
                       "(of 1680 read)"
    trimesh.Trimesh(V, F, process=False).export(path)  # clean: nothing to say
    assert _cli.main(["simplify", str(path), str(tmp_path / "o.ply"), "--ratio", "0.5", "--quiet"]) == 0
    assert "clean-up" not in capsys.readouterr().out


def _uv_grid_obj(path, n=12, material=None):
    """An n×n grid OBJ with UVs and no material, written as text: two charts split by a seam down the
    middle column (its n+1 vertices have two UVs each: n seam edges, one seam)."""
    lines = [f"mtllib {material}", "usemtl m"] if material else []
    lines += [f"v {i / n} {j / n} {0.03 * ((i * 7 + j * 3) % 5)}" for j in range(n + 1) for i in range(n + 1)]
    lines += [f"vt {0.5 * i / n} {j / n}" for j in range(n + 1) for i in range(n + 1)]  # left chart
    lines += [f"vt {0.55 + 0.5 * i / n} {j / n}" for j in range(n + 1) for i in range(n + 1)]  # right chart
    h = n // 2
    for j in range(n):
        for i in range(n):
            v = [j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i]
            t = [x + (0 if i < h else (n + 1) ** 2) + 1 for x in v]
            v = [x + 1 for x in v]
            lines.append(" ".join(["f"] + [f"{v[k]}/{t[k]}" for k in (0, 1, 2)]))
            lines.append(" ".join(["f"] + [f"{v[k]}/{t[k]}" for k in (0, 2, 3)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_summary_names_the_attributes_kept(tmp_path, capsys):
    src = _uv_grid_obj(tmp_path / "grid.obj")
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", "--quiet"]) == 0
    out = capsys.readouterr().out  # the default leaves seamed UVs out, and says how to keep them
    assert "  not kept by default, for their seams: uv (--attributes uv keeps them)" in out, out
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", "--quiet",
                      "--attributes", "uv"]) == 0
    out = capsys.readouterr().out
    assert "  kept uv: 1 seam (12 seam edges, 13 seam vertices) constrained like boundaries" in out, out
    assert "(quadric error (a sum of squared distances to planes) plus weighted attribute deviation, mesh units²)" in out
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", "--quiet",
                      "--attributes", "none"]) == 0
    captured = capsys.readouterr()
    assert "  dropped uv" in captured.out and "kept" not in captured.out


def test_uvs_without_material_get_no_made_up_image(tmp_path, capsys):
    """UVs are written (vt lines, TEXCOORD_0), but no image, mtl or glTF texture the input did not have."""
    import json
    import struct

    src = _uv_grid_obj(tmp_path / "grid.obj")
    out = tmp_path / "out"
    out.mkdir()
    keep = ["--attributes", "uv"]  # seamed UVs: kept when asked for
    assert _cli.main(["simplify", str(src), str(out / "o.obj"), "--ratio", "0.5", "--quiet", *keep]) == 0
    assert _cli.main(["simplify", str(src), str(out / "o.glb"), "--ratio", "0.5", "--quiet", *keep]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["o.glb", "o.obj"]
    text = (out / "o.obj").read_text()
    assert "\nvt " in text and "mtllib" not in text and "usemtl" not in text
    again = trimesh.load(out / "o.obj", process=False, force="mesh")
    assert again.visual.uv is not None and len(again.visual.uv) == len(again.vertices)
    data = (out / "o.glb").read_bytes()
    gltf = json.loads(data[20:20 + struct.unpack("<I", data[12:16])[0]])
    assert "images" not in gltf and "TEXCOORD_0" in gltf["meshes"][0]["primitives"][0]["attributes"]


def test_ply_output_says_it_leaves_the_texture_image_out(tmp_path, capsys):
    """--texture IMAGE with a .ply output wrote the UVs (s, t) and no image, without a word (an OBJ gets it
    beside, a GLB packs it): a warning says so; UVs without an image have none to leave out."""
    from PIL import Image

    src = _uv_grid_obj(tmp_path / "grid.obj")
    Image.new("RGB", (8, 8), (200, 30, 30)).save(tmp_path / "t.png")
    keep = ["--ratio", "0.5", "--quiet", "--attributes", "uv"]
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.ply"), *keep, "--texture", str(tmp_path / "t.png")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "texture image" in line]
    assert said == ["qemjax: warning: PLY holds the UVs (as s, t) but not their texture image: the image is not "
                    "written (.obj writes it beside the file, .glb and .gltf pack it in)"], said
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.obj", "o.ply", "t.png"]
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.ply"), *keep]) == 0
    assert "texture image" not in capsys.readouterr().err


def test_a_jpeg_texture_is_written_as_it_was_read(tmp_path):
    """A JPEG texture (the input's map_Kd, or --texture) came back encoded again by trimesh at its default
    quality (pixels moved by tens of levels), beside an OBJ and packed in a GLB, though simplification
    never changes it: the file's own bytes are written now. A PNG is written as before."""
    import json
    import struct

    from PIL import Image

    pixels = np.random.default_rng(3).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(tmp_path / "t.jpg", quality=90)
    Image.fromarray(pixels).save(tmp_path / "t.png")
    jpeg = (tmp_path / "t.jpg").read_bytes()
    (tmp_path / "m.mtl").write_text("newmtl m\nmap_Kd t.jpg\n")
    src = _uv_grid_obj(tmp_path / "grid.obj", material="m.mtl")
    plain = _uv_grid_obj(tmp_path / "plain.obj")
    keep = ["--ratio", "0.5", "--quiet", "--attributes", "uv"]
    partition = ["--partition", "--workers", "1"]
    for n, (given, texture) in enumerate([(src, []), (plain, ["--texture", str(tmp_path / "t.jpg")]),
                                          (src, partition), (plain, [*partition, "--texture", str(tmp_path / "t.jpg")])]):
        out = tmp_path / f"out{n}"
        out.mkdir()
        assert _cli.main(["simplify", str(given), str(out / "o.obj"), *keep, *texture]) == 0
        assert _cli.main(["simplify", str(given), str(out / "o.glb"), *keep, *texture]) == 0
        assert "map_Kd o.jpeg" in (out / "o.mtl").read_text()
        assert (out / "o.jpeg").read_bytes() == jpeg
        data = (out / "o.glb").read_bytes()
        gltf = json.loads(data[20:20 + struct.unpack("<I", data[12:16])[0]])
        view = gltf["bufferViews"][gltf["images"][0]["bufferView"]]
        binary = data[28 + struct.unpack("<I", data[12:16])[0]:]
        assert gltf["images"][0]["mimeType"] == "image/jpeg"
        stored = binary[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]]
        assert stored.rstrip(b"\0") == jpeg  # trimesh pads each view to 4 bytes
    out = tmp_path / "out_png"
    out.mkdir()
    assert _cli.main(["simplify", str(plain), str(out / "o.obj"), *keep, "--texture", str(tmp_path / "t.png")]) == 0
    assert np.array_equal(np.asarray(Image.open(out / "o.png")), pixels)


def test_obj_output_says_it_leaves_the_colours_alpha_out(tmp_path, capsys):
    """Kept vertex colours with alpha below 1 written as OBJ lost the alpha (OBJ's `v x y z r g b`) without
    a word, while STL, OFF and a PLY's texture image are named: a warning says so; PLY keeps the alpha,
    and opaque colours have none to lose."""
    mesh = qemjax.shapes.bumpy_sphere(1)
    rgba = np.full((len(mesh.vertices), 4), 255, np.uint8)
    rgba[:, 0] = np.arange(len(rgba)) % 256
    for alpha, name in ((128, "see.ply"), (255, "solid.ply")):
        rgba[:, 3] = alpha
        trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=rgba, process=False).export(tmp_path / name)
    for src, out, warned in (("see.ply", "o.obj", True), ("see.ply", "o.ply", False), ("solid.ply", "o.obj", False)):
        assert _cli.main(["simplify", str(tmp_path / src), str(tmp_path / out), "--ratio", "0.5", "--quiet"]) == 0
        said = [line for line in capsys.readouterr().err.splitlines() if "alpha" in line]
        assert len(said) == warned and all(re.fullmatch(
            r"qemjax: warning: OBJ stores vertex colours as RGB: their alpha \(below 1 at \d+ vertices\) is not "
            r"written \(\.ply, \.glb and \.gltf hold it\)", line) for line in said), said
    back = qemjax.simplify(tmp_path / "o.ply", ratio=1.0)
    assert np.allclose(back.colors[:, 3], 128 / 255)


def test_lod_refuses_texture_with_the_real_reason(tmp_path, capsys, monkeypatch):
    src = _uv_grid_obj(tmp_path / "grid.obj")  # it does carry UVs: the reason is the levels'
    _no_simplify(monkeypatch)
    for flags in (["--texture", str(tmp_path / "t.png")], ["--attributes", "uv"]):
        assert _cli.main(["lod", str(src), str(tmp_path / "lods"), *flags, "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "qemjax lod keeps positions only: its levels are replayed from " \
            "contractions" in err and "use qemjax simplify --texture for a textured result" in err, err
    assert not (tmp_path / "lods").exists()
    # a run that fails (here: no such input) leaves no folder it made; one that was there stays
    assert _cli.main(["lod", str(tmp_path / "nope.obj"), str(tmp_path / "lods"), "--quiet"]) == 2
    assert "not found" in capsys.readouterr().err and not (tmp_path / "lods").exists()
    (tmp_path / "mine").mkdir()
    assert _cli.main(["lod", str(tmp_path / "nope.obj"), str(tmp_path / "mine"), "--quiet"]) == 2
    assert (tmp_path / "mine").is_dir()
    assert _cli.main(["lod", "--help"]) == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--texture" not in help_text and "--attribute" not in help_text
    assert "side by side along x" in help_text
    for texture in ({"texture": str(tmp_path / "t.png")}, {"attributes.texture": str(tmp_path / "t.png")},
                    {"attributes": qemjax.Attributes("uv", texture=str(tmp_path / "t.png"))}):  # every way to give one
        with pytest.raises(ValueError, match="lod_chain keeps positions only"):
            qemjax.lod_chain(shapes.icosphere(2), **texture)


def test_lod_glb_levels_side_by_side(src, tmp_path, capsys):
    """Node i translated by i × 1.2 × the x-extent; each geometry the level's own, unmoved."""
    assert _cli.main(["lod", str(src), str(tmp_path / "lods"), "--ratios", "0.5", "0.1", "--glb", "--quiet"]) == 0
    chain = qemjax.lod_chain(src, ratios=[0.5, 0.1])
    scene = trimesh.load(tmp_path / "lods" / "in-lods.glb", process=False)
    spacing = 1.2 * max(np.ptp(level.vertices[:, 0]) for level in chain)
    assert spacing > 0
    for i, level in enumerate(chain):
        move, geom = scene.graph[f"lod{i}"]
        assert np.allclose(move, np.eye(4) + np.pad([[i * spacing], [0], [0]], ((0, 1), (3, 0))), atol=1e-6)
        mesh = scene.geometry[geom]
        assert np.allclose(mesh.vertices, level.vertices, atol=1e-6) and np.array_equal(mesh.faces, level.faces)
    stacked = chain.to_scene(spacing=0)
    assert all(np.array_equal(stacked.graph[f"lod{i}"][0], np.eye(4)) for i in range(2))


@pytest.mark.parametrize("value, match", [("0", "the number of workers must be at least 1"),
                                          ("abc", "a whole number of worker processes")])
def test_workers_are_named_as_workers(src, tmp_path, capsys, value, match):
    assert _cli.main(["simplify", str(src), str(tmp_path / "o.obj"), "--ratio", "0.5", "--partition",
                      "--workers", value, "--quiet"]) == 2
    assert match in capsys.readouterr().err


def test_a_partitioned_run_tells_what_it_keeps_and_drops_as_it_is(tmp_path):
    """A partitioned run: a target at the input's faces is no early stop (no warning), one above them is
    named as in core; an OBJ's vertex colours, which it drops, are named; the UVs it keeps are said kept
    without a seam count it does not make (it said "no seams" of a mesh with seams)."""
    import warnings as _w

    qemjax.shapes.write_examples(tmp_path, subdivisions=3)
    bumpy = str(tmp_path / "bumpy.obj")
    one = qemjax.Partition(workers=1)
    with _w.catch_warnings(record=True) as caught:
        _w.simplefilter("always")
        r = qemjax.simplify(bumpy, ratio=1.0, partition=one)
    assert r.stop_reason == "unchanged" and not caught
    with pytest.warns(UserWarning, match="target of 5000 faces is not below the mesh's 1280 faces"):
        qemjax.simplify(bumpy, target_faces=5000, partition=one)
    V, F = qemjax.shapes.bumpy_sphere(3)
    (tmp_path / "vc.obj").write_text("".join(f"v {x} {y} {z} 0.5 0.25 0.125\n" for x, y, z in V)
                                     + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    with pytest.warns(UserWarning, match=r"not carried over from the input: vertex colours \(v x y z r g b\)"):
        qemjax.simplify(str(tmp_path / "vc.obj"), ratio=0.5, partition=one)
    r = qemjax.simplify(str(tmp_path / "textured.obj"), ratio=0.3, attributes="uv", partition=one)
    assert r.stats["attributes"] == ["uv"] and _cli.attributes_note(r.stats).startswith("kept uv") \
        and "seam" not in _cli.attributes_note(r.stats)
    alone = qemjax.simplify(str(tmp_path / "textured.obj"), ratio=0.3, attributes="uv")
    assert "1 seam (" in _cli.attributes_note(alone.stats)
    assert _cli.attributes_note(qemjax.simplify(qemjax.shapes.bumpy_sphere(2), ratio=0.5).stats) == ""


@pytest.mark.parametrize("offset, radius", [((5e5, 5e6, 100.0), 10.0), ((0.0, 0.0, 0.0), 1e-6), ((0.0, 0.0, 0.0), 1.0)])
def test_written_positions_are_as_precise_as_the_result(tmp_path, capsys, offset, radius):
    """A PLY was written as float32 and an OBJ with 8 decimals whatever the mesh: a scan far from the origin
    (georeferenced) or a mesh a micrometre wide came back moved by more than the simplification moved it.
    Now no written position is farther than 1e-6 of the diagonal from the result's; an ordinary mesh is
    written as before (float32 PLY)."""
    import trimesh

    m = trimesh.creation.icosphere(3, radius=radius)
    V = np.asarray(m.vertices) + np.asarray(offset)
    src = tmp_path / "in.ply"
    trimesh.Trimesh(V, m.faces, process=False).export(src)  # float32: the input as written
    V = np.asarray(qemjax.load(str(src)).vertices)
    res = qemjax.simplify((V, np.asarray(m.faces)), ratio=0.1)
    diagonal = float(np.linalg.norm(res.vertices.max(0) - res.vertices.min(0)))
    for ext in ("ply", "obj"):
        out = tmp_path / f"out.{ext}"
        _cli.write(res, str(out), ext)
        back = np.asarray(qemjax.load(str(out)).vertices)
        assert np.abs(back - res.vertices).max() <= 1e-6 * diagonal
    doubles = b"property double x" in (tmp_path / "out.ply").read_bytes()[:300]
    assert doubles == (radius == 10.0)  # float32 kept where it holds the positions
    # the formats that cannot widen say what writing them costs (they said nothing), an ordinary mesh's not
    for ext in ("stl", "glb", "gltf"):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            _cli.write(res, str(tmp_path / f"out.{ext}"), ext)
        back = np.asarray(qemjax.load(str(tmp_path / f"out.{ext}")).vertices)
        moved = np.linalg.norm(back[:, None] - res.vertices[None], axis=2).min(1).max()
        said = [str(w.message) for w in seen if "cannot hold the result's positions" in str(w.message)]
        assert len(said) == (moved > 1e-6 * diagonal), (ext, moved, said)


def test_formats_without_attributes_say_they_drop_the_kept_ones(tmp_path):
    """STL and OFF hold positions and faces only: writing a result with kept colours says so (it was
    silent while the summary said "kept color")."""
    import trimesh

    m = shapes.bumpy_sphere(3)
    rgba = np.tile([200, 30, 30, 255], (len(m.vertices), 1)).astype(np.uint8)
    res = qemjax.simplify(trimesh.Trimesh(m.vertices, m.faces, vertex_colors=rgba, process=False), ratio=0.2)
    assert res.colors is not None
    for ext in ("stl", "off"):
        with pytest.warns(UserWarning, match=f"{ext.upper()} stores positions and faces only: the kept colors"):
            _cli.write(res, str(tmp_path / f"out.{ext}"), ext)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _cli.write(res, str(tmp_path / "out.ply"), "ply")


def test_gltf_is_one_file_and_lod_refuses_what_moves_only_the_result(src, tmp_path, capsys):
    """A .gltf output holds its buffers (trimesh wrote them beside it under fixed names, so the levels of
    `qemjax lod` overwrote each other's and a user's file of that name); `--refit` and friends move one
    result, which no level file holds, so `qemjax lod` refuses them."""
    (tmp_path / "gltf_buffer_0.bin").write_text("MY DATA")
    assert _cli.main(["lod", str(src), str(tmp_path), "--format", "gltf", "--ratios", "0.5", "0.1", "--quiet"]) == 0
    chain = qemjax.lod_chain(src, ratios=[0.5, 0.1])
    for i, level in enumerate(chain):
        back = qemjax.load(str(tmp_path / f"in-lod{i}.gltf"))
        assert np.array_equal(back.faces, level.faces) and np.allclose(back.vertices, level.vertices, atol=1e-6)
    assert (tmp_path / "gltf_buffer_0.bin").read_text() == "MY DATA"
    for flag in ("--refit", "--polish", "--sliver-moves"):
        assert _cli.main(["lod", str(src), str(tmp_path / "x"), flag, "2", "--quiet"]) == 2
        assert f"{flag} would not change" in capsys.readouterr().err


def test_lod_takes_locked_vertices_as_simplify_does(tmp_path, capsys):
    """cli.md: every option of `qemjax.simplify` is one of `qemjax lod` (--locked was not): the locked
    vertices are in every level, where they were."""
    qemjax.shapes.write_examples(tmp_path, subdivisions=3)
    V = np.asarray(qemjax.load(str(tmp_path / "bumpy.obj")).vertices)
    idx = np.arange(0, len(V), 11)
    np.savetxt(tmp_path / "lk.txt", idx, fmt="%d")
    assert _cli.main(["lod", str(tmp_path / "bumpy.obj"), str(tmp_path / "lods"), "--ratios", "0.5", "0.2",
                      "--locked", str(tmp_path / "lk.txt"), "--quiet"]) == 0
    for i in (0, 1):
        level = np.asarray(qemjax.load(str(tmp_path / "lods" / f"bumpy-lod{i}.obj")).vertices)
        assert all((np.abs(level - V[j]).max(1) < 1e-7).any() for j in idx)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_locked_vertices_are_written_bit_for_bit(tmp_path, fmt):
    """--locked: the vertices "stay exactly where they are", in the file too. An OBJ was written with a fixed
    count of decimals and a PLY in float32 where that moved no vertex far, so positions with more digits
    than those came back rounded (the result held them exactly). With locks, OBJ and PLY hold them bit for
    bit, in simplify's and lod's files; without, the files are as before."""
    V, F = qemjax.shapes.bumpy_sphere(3)
    src = tmp_path / "in.obj"  # 12 decimals: more than OBJ's 8 or float32 hold
    src.write_text("".join(f"v {x:.12f} {y:.12f} {z:.12f}\n" for x, y, z in V * 1.234567891234 + 0.1)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    V = np.asarray(qemjax.load(str(src)).vertices)  # what the run reads
    assert not np.array_equal(V.astype(np.float32).astype(np.float64), V)
    idx = np.arange(0, len(V), 7)
    np.savetxt(tmp_path / "lk.txt", idx, fmt="%d")
    out = tmp_path / f"out.{fmt}"
    for locked in (False, True):
        extra = ["--locked", str(tmp_path / "lk.txt")] if locked else []
        assert _cli.main(["simplify", str(src), str(out), "--ratio", "0.3", "--quiet", *extra]) == 0
        got = {tuple(row) for row in np.asarray(qemjax.load(str(out)).vertices).tolist()}
        exact = all(tuple(V[j].tolist()) in got for j in idx)
        assert exact == locked, (fmt, locked)
        if locked:
            res = qemjax.simplify(str(src), ratio=0.3, locked=idx)
            assert got == {tuple(row) for row in res.vertices.tolist()}  # every position, as the result holds it
    assert _cli.main(["lod", str(src), str(tmp_path / "lods"), "--ratios", "0.5", "--format", fmt, "--locked",
                      str(tmp_path / "lk.txt"), "--quiet"]) == 0
    level = {tuple(row) for row in np.asarray(qemjax.load(str(tmp_path / "lods" / f"in-lod0.{fmt}")).vertices).tolist()}
    assert all(tuple(V[j].tolist()) in level for j in idx)


def test_vertex_file_errors_name_the_option_and_the_file(src, tmp_path, capsys):
    """--locked and --vertex-weights files that do not fit said `locked must be one-dimensional` (simplify's
    keyword, not the option or its file), and an empty text file gave numpy's warning: each is one line
    naming the option and the file; an empty --locked file locks nothing, without a warning."""
    np.savetxt(tmp_path / "pairs.txt", np.arange(78).reshape(39, 2), fmt="%d")
    (tmp_path / "empty.txt").write_text("")
    np.save(tmp_path / "half.npy", np.array([0.5, 1.0]))
    np.savetxt(tmp_path / "three.txt", [1.0, 2.0, 3.0])
    out = str(tmp_path / "o.obj")
    for flag, name, says in (("--locked", "pairs.txt", "expected a flat list of values"),
                             ("--vertex-weights", "pairs.txt", "expected a flat list of values"),
                             ("--vertex-weights", "empty.txt", "needs one weight per input vertex (642), got 0"),
                             ("--vertex-weights", "three.txt", "needs one weight per input vertex (642), got 3"),
                             ("--locked", "half.npy", "must be a boolean mask or integer vertex indices")):
        for cmd in (["simplify", str(src), out, "--ratio", "0.5"], ["lod", str(src), str(tmp_path / "lods")]):
            assert _cli.main([*cmd, flag, str(tmp_path / name), "--quiet"]) == 2
            err = capsys.readouterr().err
            assert err.startswith(f"qemjax: error: {flag} {tmp_path / name}: {says}") and err.count("\n") == 1, err
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--locked", str(tmp_path / "empty.txt"),
                      "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def test_feature_edge_file_errors_name_the_option_and_the_file(src, tmp_path, capsys):
    """As --locked's: a --feature-edges file that did not fit said `feature_edges must have shape (k, 2)`
    (the keyword, without the file), and an empty text file gave numpy's warning; an empty file is no edges."""
    np.savetxt(tmp_path / "triples.txt", np.arange(9).reshape(3, 3), fmt="%d")
    np.savetxt(tmp_path / "far.txt", [[0, 10 ** 6]], fmt="%d")
    (tmp_path / "empty.txt").write_text("")
    out = str(tmp_path / "o.obj")
    for name, says in (("triples.txt", "must have shape (k, 2) (pairs of vertex indices), got (3, 3)"),
                       ("far.txt", "indices out of range")):
        assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--feature-edges", str(tmp_path / name),
                          "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"qemjax: error: --feature-edges {tmp_path / name}: {says}") and err.count("\n") == 1, err
    assert _cli.main(["simplify", str(src), out, "--ratio", "0.5", "--feature-edges", str(tmp_path / "empty.txt"),
                      "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def test_the_count_options_help_counts_with_its_metavar(capsys):
    """``--polish N`` and ``--sliver-moves N`` say "N ≥ 0 ... at most N moves" (they said M)."""
    assert _cli.main(["simplify", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in ("--polish N", "--sliver-moves N"):
        assert f"{option} N ≥ 0, with a re-fit, at most N moves" in text, option


def test_demo_takes_the_partition_settings_it_offers_partition_with(capsys):
    """`qemjax demo` offered --partition but not --part-faces, --workers or --scratch: `demo --workers 1`
    answered "did you mean --rank-eps?". They are the settings simplify's --partition takes."""
    assert _cli.main(["demo", "--subdivisions", "4", "--ratio", "0.1", "--partition", "--part-faces", "1000",
                      "--workers", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"partitioned: ([2-9]|\d\d+) parts", out), out
