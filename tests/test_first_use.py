"""What a new user meets first (issue 40 §4, issue 42's start-up): the method's name in results, errors and
sweeps; short reprs; a misspelt setting; the command's start-up without JAX and Ctrl-C while importing."""
from __future__ import annotations

import dataclasses
import inspect
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import qemjax
from qemjax import _costs, shapes
from qemjax._pipeline import api as _api, flat as _flat

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ball():
    return shapes.bumpy_sphere(2)  # 320 faces


# -- the method's name -----------------------------------------------------------------------------------

def test_the_default_is_named_default(ball):
    assert qemjax.simplify(ball, ratio=0.5).stats["method"] == "default"
    assert qemjax.simplify(ball, ratio=0.5, method=qemjax.QEM.default()).stats["method"] == "default"
    assert qemjax.simplify(ball, ratio=0.5, refit=0).stats["method"] == "default"  # named none, one field set
    assert qemjax.simplify(ball, ratio=0.5, method="qem").stats["method"] == "qem"
    assert qemjax.simplify(ball, ratio=0.5, method=qemjax.QEM()).stats["method"] == "qem"
    assert qemjax.simplify(ball, ratio=0.5, preset="accurate").stats["method"] == "accurate"
    assert qemjax.simplify(ball, ratio=0.5, method="esqem", split_factor=None).stats["method"] == "esqem"
    with pytest.raises(ValueError, match=r"^curvature_weight is not a setting of method 'default' "):
        qemjax.simplify(ball, ratio=0.5, curvature_weight=0.5)
    with pytest.raises(ValueError, match=r"^curvature_weight is not a setting of method 'qem' "):
        qemjax.simplify(ball, ratio=0.5, method="qem", curvature_weight=0.5)
    assert _costs.label(qemjax.QEM.default()) == "default"
    assert _costs.label(qemjax.QEM.accurate()) == "accurate"
    assert _costs.label(dataclasses.replace(qemjax.QEM.default(), refit=0)).startswith("qem(")


@dataclasses.dataclass(frozen=True)
class Toy(qemjax.QEM):
    """QEM with a field of its own and no name of its own (it inherits QEM's)."""

    extra: float = 1.0


@pytest.fixture
def toy():
    qemjax.register_method("toy", Toy)
    yield Toy
    del _costs.REGISTRY["toy"]


def test_a_registered_class_goes_by_its_registered_name(toy, ball):
    assert Toy.name == "qem"  # inherited: the registry, not the class attribute, names it
    assert qemjax.simplify(ball, ratio=0.5, method=Toy(extra=3.0)).stats["method"] == "toy"
    with pytest.raises(ValueError, match="curvature_weight is not a setting of method 'toy'"):
        qemjax.simplify(ball, ratio=0.5, method=Toy(), curvature_weight=0.5)
    df = qemjax.sweep({"ball": ball}, {"method": [Toy(extra=3.0), Toy(), qemjax.QEM.default()]}, [0.5],
                      metrics=False, progress=False)
    assert list(df["method"]) == ["toy(extra=3.0)", "toy", "default"]


# -- reprs --------------------------------------------------------------------------------------------------

def test_reprs_are_a_few_lines_of_counts(ball):
    res = qemjax.simplify(ball, ratio=0.25)
    text = repr(res)
    lines = text.splitlines()
    assert 3 <= len(lines) <= 5 and "array" not in text
    assert lines[0] == (f"SimplifyResult: 320 -> {len(res.faces)} faces, {len(res.input_vertices)} -> "
                        f"{len(res.vertices)} vertices, stop_reason 'target' (target 80 faces)")
    assert "method 'default'" in lines[1] and f"{res.stats['rounds']} rounds" in lines[1]
    assert f"max_error {res.max_error:.3g}" in lines[2]
    chain = qemjax.lod_chain(ball, ratios=(0.5, 0.25, 0.1))
    lines = repr(chain).splitlines()
    assert len(lines) == 4 and "array" not in repr(chain)
    assert lines[0].startswith("LodChain: 3 levels of 320 faces from one run")
    for line, ratio, level in zip(lines[1:], chain.ratios, chain.levels):
        assert line.startswith(f"  [") and f"ratio {ratio:g}: {len(level.faces)} faces" in line
    for obj in (chain[0], res.record, res.history):  # what the fields show, one line each
        assert "\n" not in repr(obj) and "array" not in repr(obj) and len(repr(obj)) < 120
    assert repr(res.history).startswith(f"Contractions({len(res.history)} contractions")


def test_results_compare_by_identity(ball):
    """`==` between two results (or their records, levels, histories, chains) raised numpy's "truth value of
    an array is ambiguous": they compare and hash by identity."""
    res, again = qemjax.simplify(ball, ratio=0.5), qemjax.simplify(ball, ratio=0.5)
    chain = qemjax.lod_chain(ball, ratios=(0.5, 0.25))
    pairs = [(res, again), (res.history, again.history), (res.record, again.record),
             (res.replay(200), again.replay(200)), (chain, qemjax.lod_chain(ball, ratios=(0.5, 0.25))),
             (chain[0], chain[1])]
    for a, b in pairs:
        assert a == a and not a != a and a != b and not a == b, type(a).__name__
        assert len({a, a, b}) == 2 and hash(a) == hash(a), type(a).__name__
    assert res in [again, res] and res not in [again]


# -- a misspelt setting ---------------------------------------------------------------------------------

def test_a_misspelt_setting_suggests_the_close_name(ball):
    with pytest.raises(TypeError) as err:
        qemjax.simplify(ball, ratoi=0.1)
    assert str(err.value) == "unknown setting 'ratoi'; did you mean 'ratio'?"
    with pytest.raises(TypeError, match=r"^unknown setting 'boundry_weight'; did you mean 'boundary_weight'"):
        qemjax.simplify(ball, ratio=0.5, boundry_weight=1.0)
    with pytest.raises(TypeError) as err:
        qemjax.simplify(ball, ratio=0.5, xyzzy=1)
    assert str(err.value).startswith("unknown setting 'xyzzy' (") and len(str(err.value)) < 160
    with pytest.raises(ValueError, match=r"^simplify_batch: unknown setting 'ratoi'; did you mean 'ratio'\?$"):
        qemjax.simplify_batch(ball, [dict(ratoi=0.1)])


def test_a_misspelt_dotted_setting_is_a_type_error_as_a_flat_one_is(ball):
    """A dotted typo ("method.boundry_weight") was a ValueError without a hint where the flat typo is a TypeError
    with one; "topology.flip_angel" named no close name either."""
    for key, message in [("method.boundry_weight", "unknown method setting 'method.boundry_weight'; did you mean "
                                                   "'method.boundary_weight'?"),
                         ("topology.flip_angel", "unknown topology setting 'topology.flip_angel'; did you mean "
                                                 "'topology.flip_angle'?"),
                         ("attributes.textur", "unknown attributes setting 'attributes.textur'; did you mean "
                                               "'attributes.texture'?"),
                         ("method.flip_angle", "unknown method setting 'method.flip_angle'; did you mean "
                                               "'topology.flip_angle'?"),
                         ("topolgy.flip_angle", "unknown setting 'topolgy.flip_angle'; did you mean "
                                                "'topology.flip_angle'?")]:
        with pytest.raises(TypeError) as err:
            qemjax.simplify(ball, ratio=0.5, **{key: 1.0})
        assert str(err.value) == message
    with pytest.raises(TypeError, match=r"^unknown method setting 'method.xyzzy' \(method 'default' has no such"):
        qemjax.simplify(ball, ratio=0.5, **{"method.xyzzy": 1})
    with pytest.raises(TypeError, match=r"^unknown topology setting 'topology.xyzzy'; qemjax.Topology has \["):
        qemjax.simplify(ball, ratio=0.5, **{"topology.xyzzy": 1})
    # another method's setting stays a ValueError that names the method, flat or dotted
    for key in ("curvature_weight", "method.curvature_weight"):
        with pytest.raises(ValueError, match=r"^curvature_weight is not a setting of method 'default' "):
            qemjax.simplify(ball, ratio=0.5, **{key: 0.5})


def test_a_misspelt_grid_key_suggests_the_close_name(ball):
    with pytest.raises(ValueError, match=r"^unknown grid keys \['boundry_weight'\]; did you mean 'boundary_weight'\?;"):
        qemjax.sweep({"ball": ball}, {"boundry_weight": [1.0]}, [0.5], metrics=False, progress=False)


def test_the_suggested_keywords_are_simplifys():
    own = {n for n, p in inspect.signature(_api.simplify).parameters.items() if p.kind is p.KEYWORD_ONLY}
    assert set(_flat.KEYWORDS) == own | {"preset", "locked", "vertex_weights"}


# -- the public API, imported on first use --------------------------------------------------------------

def test_the_public_names_are_the_modules_objects():
    import importlib

    for name, (module, attr) in qemjax._PUBLIC.items():
        assert getattr(qemjax, name) is getattr(importlib.import_module(module, "qemjax"), attr), name
    assert set(qemjax._PUBLIC) <= set(dir(qemjax)) and set(qemjax._MODULES) <= set(dir(qemjax))
    assert qemjax.__all__ == [*qemjax._PUBLIC, *qemjax._MODULES]  # in their groups (qemjax/__init__.py)
    assert all(getattr(qemjax.costs, n) is getattr(qemjax, n) for n in qemjax.costs.__all__)
    namespace = {}
    exec("from qemjax import *", namespace)
    assert set(qemjax._PUBLIC) <= set(namespace)
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        qemjax.nothing


# -- the command: start-up without JAX, Ctrl-C while importing ----------------------------------------------

def _python(code: str, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=120, **kw)


@pytest.mark.parametrize("entry", ["_cli", "__main__"])
@pytest.mark.parametrize("argv,expect", [(["--version"], f"qemjax {qemjax.__version__} (jax "),
                                         (["simplify", "--help"], "usage: qemjax simplify"),
                                         (["lod", "--help"], "usage: qemjax lod"),
                                         (["--help"], "usage: qemjax")])
def test_version_and_help_do_not_import_jax(argv, expect, entry):
    p = _python(f"import sys; from qemjax.{entry} import main; code = main({argv!r}); "
                "print('heavy:', *sorted(m for m in ('jax', 'numba', 'trimesh') if m in sys.modules)); sys.exit(code)")
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(expect) and p.stdout.splitlines()[-1] == "heavy:"
    if entry == "__main__" and argv == ["--version"]:  # answered before the command's modules are imported
        p = _python("import sys; from qemjax.__main__ import main; main(['--version']); print('numpy' in sys.modules)")
        version, numpy_imported = p.stdout.splitlines()
        assert version.startswith(expect) and numpy_imported == "False"
    if argv == ["simplify", "--help"]:
        assert "--boundary-weight" in p.stdout and "--curvature-weight" in p.stdout  # every method's fields


CHILD = textwrap.dedent("""
    import importlib.abc, sys, time

    class Slow(importlib.abc.MetaPathFinder):  # the import of {module!r} takes a while (as a cold one does)
        def find_spec(self, name, path=None, target=None):
            if name == {module!r}:
                print("importing", name, flush=True)
                time.sleep(30)
            return None

    sys.meta_path.insert(0, Slow())
    from qemjax.__main__ import main
    sys.exit(main({argv!r}))
""")


def _start(module: str, argv: list, sigint, sleep: float = 30) -> subprocess.Popen:
    """The command in a fresh process whose import of ``module`` takes ``sleep`` seconds, started with
    SIGINT's disposition ``sigint`` whatever this test run was started with (a CI runner or ``cmd &`` in a
    script starts it with SIGINT ignored, and a child inherits that)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = CHILD.format(module=module, argv=argv).replace("time.sleep(30)", f"time.sleep({sleep})")
    return subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, sigint))


@pytest.mark.slow  # fresh processes, SIGINT
@pytest.mark.parametrize("module", ["qemjax._cli", "jax"])
def test_ctrl_c_while_importing_is_one_line(module, tmp_path):
    """SIGINT while the command imports the package (``qemjax._cli``) or JAX (the run's first import of
    it): one line, exit code 130, no traceback and no output file."""
    out = tmp_path / "out.ply"
    argv = ["simplify", str(tmp_path / "in.ply"), str(out), "--ratio", "0.5", "--quiet"]
    _write_ply(tmp_path / "in.ply")
    p = _start(module, argv, signal.SIG_DFL)
    try:
        assert p.stdout.readline() == f"importing {module}\n"
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 130 and stderr == "qemjax: interrupted\n" and stdout == ""
    assert not out.exists()


@pytest.mark.slow  # a fresh process that runs to the end
def test_started_with_sigint_ignored_the_command_keeps_ignoring_it(tmp_path):
    """Started with SIGINT ignored (``nohup``, a background job of a script), the command does not turn it
    back on: a SIGINT while it imports JAX changes nothing, and the run writes its output."""
    out = tmp_path / "out.ply"
    argv = ["simplify", str(tmp_path / "in.ply"), str(out), "--ratio", "0.5", "--quiet"]
    _write_ply(tmp_path / "in.ply")
    p = _start("jax", argv, signal.SIG_IGN, sleep=2)
    try:
        assert p.stdout.readline() == "importing jax\n"
        p.send_signal(signal.SIGINT)  # while `main` runs: its handler would be installed by now
        stdout, stderr = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 0, stderr
    assert out.exists() and "interrupted" not in stderr


def test_sigint_ignored_at_start_stays_ignored_while_main_runs(monkeypatch):
    from qemjax import _cli

    seen = []
    monkeypatch.setattr(_cli, "_main", lambda argv: seen.append(signal.getsignal(signal.SIGINT)) or 0)
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        assert _cli.main(["examples"]) == 0
        assert seen == [signal.SIG_IGN] and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        signal.signal(signal.SIGINT, signal.default_int_handler)
        assert _cli.main(["examples"]) == 0  # started with Python's handler: ours while it runs, then back
        assert seen[1] is _cli._on_sigint and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)


def _write_ply(path: Path) -> None:
    V, F = shapes.bumpy_sphere(1)
    lines = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property float x", "property float y",
             "property float z", f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(repr, map(float, v))) for v in V] + [f"3 {a} {b} {c}" for a, b, c in F]
    path.write_text("\n".join(lines) + "\n")


def test_the_readmes_notebook_command_has_timeouts():
    """nbconvert waits without end by default: a stuck kernel (issue 40 §4) must become an error."""
    text = " ".join((ROOT / "README.md").read_text().split())
    command = text[text.index("jupyter nbconvert --to notebook --execute"):]
    command = command[:command.index("`")]
    assert "--ExecutePreprocessor.timeout=600" in command and "--ExecutePreprocessor.startup_timeout=" in command


def test_the_readmes_notebook_output_is_ignored_by_git():
    text = " ".join((ROOT / "README.md").read_text().split())
    command = text[text.index("jupyter nbconvert --to notebook --execute"):]
    folder = command[command.index("--output-dir ") + len("--output-dir "):].split()[0]
    ignored = (ROOT / ".gitignore").read_text().splitlines()
    assert f"{folder}/" in ignored or folder in ignored, folder


@pytest.mark.slow  # a fresh process
def test_the_command_freezes_the_collector_at_its_end_only_as_the_program(tmp_path):
    """Run as the program (its arguments from ``sys.argv``, as the ``qemjax`` command and ``python -m qemjax``
    call it, or as ``python -m qemjax._cli``), a command ends with the garbage collector's objects frozen, so
    that Python's shutdown does not walk them (`qemjax._cli.exit_soon`); called with arguments from a
    caller's code, it leaves the caller's collector as it was. All write the same output."""
    from qemjax import shapes

    shapes.write_examples(tmp_path)
    argv = ["simplify", str(tmp_path / "bumpy.obj"), str(tmp_path / "a.obj"), "--ratio", "0.5", "--quiet"]
    code = (f"import gc, sys; from qemjax.__main__ import main; assert main({argv!r}) == 0; print('@@', gc.get_freeze_count()); "
            f"sys.argv[1:] = {[a.replace('a.obj', 'b.obj') for a in argv]!r}; assert main() == 0; "
            "print('@@', gc.get_freeze_count())")
    p = _python(code)
    assert p.returncode == 0, p.stderr[-2000:]
    called, program = (int(line.split()[1]) for line in p.stdout.splitlines() if line.startswith("@@"))
    assert called == 0 and program > 0
    assert (tmp_path / "a.obj").read_bytes() == (tmp_path / "b.obj").read_bytes()
    # the second entry point, as `python -m qemjax._cli` runs it
    code = (f"import gc, runpy, sys; sys.argv[:] = ['qemjax'] + {[a.replace('a.obj', 'c.obj') for a in argv]!r}\n"
            "try:\n    runpy.run_module('qemjax._cli', run_name='__main__')\nexcept SystemExit as e:\n"
            "    print('@@', e.code, gc.get_freeze_count())")
    p = _python(code)
    line = next(line for line in p.stdout.splitlines() if line.startswith("@@")).split()
    assert line[1] == "0" and int(line[2]) > 0, p.stderr[-2000:]
    assert (tmp_path / "c.obj").read_bytes() == (tmp_path / "a.obj").read_bytes()
