"""The scripts of experiments/ as tools: each answers ``--help`` without running, and a quick run leaves the
results files the docs cite alone."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
# scripts whose options another script parses (late_shape hands its arguments to figures/rank_peers.py)
DELEGATE = {"late_shape.py"}


def _programs():
    return sorted(p for p in EXPERIMENTS.rglob("*.py") if 'if __name__ == "__main__":' in p.read_text())


def test_every_script_parses_its_options():
    """A script run as a program parses its command line with argparse, so that ``--help`` prints its
    docstring and exits instead of running the whole experiment."""
    programs = _programs()
    assert len(programs) > 80
    silent = [str(p.relative_to(ROOT)) for p in programs
              if p.name not in DELEGATE and "ArgumentParser" not in p.read_text()]
    assert not silent


@pytest.mark.parametrize("script", ["meshes.py", "figures/appearance.py", "figures/docs_figures.py",
                                    "figures/refit_uv.py", "probes/shape_gate.py"])
def test_help_prints_the_docstring_and_exits(script):
    run = subprocess.run([sys.executable, str(EXPERIMENTS / script), "--help"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage:")
    first = (EXPERIMENTS / script).read_text().split('"""')[1].split()[:3]
    assert " ".join(first) in " ".join(run.stdout.split())


def test_a_quick_run_leaves_the_cited_results_alone(monkeypatch):
    """The default run (and the docs' command) writes the results file the docs cite; a run with other
    options writes another unless ``--out`` names one."""
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    from figures import bench_peers, line_quadrics, probabilistic_quadrics, regularize_sweep

    results = EXPERIMENTS / "results"
    assert bench_peers.parse_args([]).out == results / "peers.csv"
    assert bench_peers.parse_args(["--meshes", "cow", "--append"]).out == results / "peers.csv"
    assert bench_peers.parse_args(["--meshes", "cow"]).out == results / "peers_custom.csv"
    assert bench_peers.machine_path(results / "peers_custom.csv") == results / "peers_custom_machine.md"
    assert bench_peers.parse_args(["--meshes", "cow", "--out", "x.csv"]).out == Path("x.csv")

    cited = ["--repeats", "1", "--weights", "0.0001", "0.001", "0.01", "0.05"]  # docs/papers.md's command
    for argv in ([], cited):
        assert line_quadrics.parse_args(argv).out == results / "line_quadrics.md"
    assert line_quadrics.parse_args(["--meshes", "cow"]).out == results / "line_quadrics_custom.md"
    assert line_quadrics.parse_args(["--ratios", "0.1", "--out", "t.md"]).out == Path("t.md")

    cited = ["--repeats", "3", "--sigmas", "0.01:0", "0.03:0", "0.1:0", "0.3:0", "0.03:1", "0.1:1"]
    for argv in ([], cited):
        assert probabilistic_quadrics.parse_args(argv).out == results / "probabilistic_quadrics.md"
    assert (probabilistic_quadrics.parse_args(["--meshes", "cow", "--repeats", "1"]).out
            == results / "probabilistic_quadrics_custom.md")

    for argv in ([], ["--method", "classic"]):  # docs/methods.md's command
        assert regularize_sweep.parse_args(argv).out == results / "regularize_sweep.csv"
    assert regularize_sweep.parse_args(["--meshes", "cow"]).out == results / "regularize_sweep_custom.csv"
    assert regularize_sweep.parse_args(["--meshes", "cow", "--out", "r.csv"]).out == "r.csv"


def test_results_name_the_scripts_that_are_there():
    """The commands that the results files' headers (and command columns) name are scripts that exist: the
    scripts moved to figures/ and probes/, and a stale path leaves a command that does not run."""
    import re

    named = {(f.name, m) for f in (EXPERIMENTS / "results").iterdir() if f.suffix in (".txt", ".md", ".csv")
             for m in re.findall(r"(?<![/\w])experiments/[a-z0-9_/]+\.py\b", f.read_text())}
    assert len(named) > 50
    assert not sorted(f"{f}: {m}" for f, m in named if not (ROOT / m).is_file())


def test_nearest_order_loads_an_old_module_that_imports_its_siblings(monkeypatch, tmp_path):
    """probes/nearest_order.py --rev loads an old grid_nearest.py outside its package: its relative imports
    (``from . import threads`` since threads.py exists) are made absolute, whatever they name."""
    import importlib.util

    monkeypatch.syspath_prepend(str(EXPERIMENTS / "probes"))
    import nearest_order

    source = (ROOT / "qemjax" / "_mesh" / "grid_nearest.py").read_text()
    assert "from . import" in source or "from .pointtri import" in source
    fixed = nearest_order.absolute_imports(source, "qemjax._mesh")
    assert "from qemjax._mesh import threads" in fixed
    assert "from qemjax._mesh.pointtri import" in fixed
    assert nearest_order.absolute_imports("from .. import io\n    from ..x.y import z\n", "qemjax._mesh") == (
        "from qemjax import io\n    from qemjax.x.y import z\n")
    file = tmp_path / "grid_nearest_copy.py"
    file.write_text(fixed)
    spec = importlib.util.spec_from_file_location("grid_nearest_copy", file)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert callable(module.nearest)


class _Parsed(Exception):
    """Raised in place of running a script once its command line is parsed."""


def _parse(module, argv, monkeypatch):
    """The namespace that ``module.main(argv)`` parses from ``argv`` (argparse exits on a bad command)."""
    import argparse

    parse = argparse.ArgumentParser.parse_args

    def stop(self, args=None, namespace=None):
        raise _Parsed(parse(self, args, namespace))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop)
    with pytest.raises(_Parsed) as parsed:
        module.main(argv)
    return parsed.value.args[0]


def _documented(script: str) -> list[list[str]]:
    """The arguments of every command that the script's docstring and the pages show for ``script``."""
    import re
    import shlex

    texts = [(EXPERIMENTS / script).read_text().split('"""')[1].replace("\\\n", " ")]
    texts += [p.read_text().replace("\n", " ") for p in [*(ROOT / "docs").glob("*.md"), EXPERIMENTS / "README.md"]]
    name = re.escape(f"experiments/{script}")
    found = [m for t in texts for m in re.findall(rf"python {name}((?: +--?[\w-]+(?: +[^\s`-][^\s`]*)*)*)", t)]
    return [shlex.split(m) for m in found]


@pytest.mark.parametrize("script", ["figures/greedy_sensitivity.py", "probes/refit_probe.py",
                                    "figures/gap_stages.py"])
def test_documented_commands_parse(script, monkeypatch):
    """The commands that a script's docstring and the docs show for it have every option it requires, and
    only options it has."""
    import importlib

    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    module = importlib.import_module(script[:-3].replace("/", "."))
    commands = _documented(script)
    assert commands
    for argv in commands:
        _parse(module, argv, monkeypatch)
    if script == "figures/gap_stages.py":  # its docstring tells of --goals
        assert _parse(module, ["--goals", "cow:10"], monkeypatch).goals == ["cow:10"]


@pytest.mark.slow
def test_last_level_runs_a_run_of_one_level():
    """probes/last_level.py on a mesh small enough for one level: its last level's input is the parts."""
    if not (ROOT.parent / "shared" / "meshes" / "cow.obj").is_file():
        pytest.skip("the shared meshes are not beside the project")
    run = subprocess.run([sys.executable, str(EXPERIMENTS / "probes" / "last_level.py"), "--mesh", "cow",
                          "--ratio", "0.1", "--repeats", "1"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "| first |" in run.stdout


def _methods_page() -> str:
    return " ".join((ROOT / "docs" / "methods.md").read_text().split())


def _results(name: str) -> str:
    return (EXPERIMENTS / "results" / name).read_text()


def test_refit_rounds_sentence_is_the_files():
    """docs/methods.md's re-fit rounds and Hausdorff counts are the variants rank_refit_rounds.txt has."""
    import re

    counts = {int(n): int(k) for n, k in re.findall(r"^acc_refit(\d+): .*Hausdorff <= best peer in (\d+)/34",
                                                    _results("rank_refit_rounds.txt"), re.M)}
    said = re.search(r"with ([\d, and]+) rounds .*? fall ([\d, ]+) of 34 \(`experiments/results/rank_refit_rounds",
                     _methods_page())
    assert said, "the sentence on re-fit rounds is gone"
    rounds = [int(x) for x in re.findall(r"\d+", said.group(1))]
    assert rounds == sorted(counts)
    assert [int(x) for x in re.findall(r"\d+", said.group(2))] == [counts[n] for n in rounds]


def test_preset_times_say_what_they_divide_by():
    """The preset table's time column: the default's and classic's from rank_default_final.txt (over classic),
    accurate's from rank_default_choice.txt, whose times divide by that run's default, as its cell says."""
    page = (ROOT / "docs" / "methods.md").read_text()
    final, choice = _results("rank_default_final.txt"), _results("rank_default_choice.txt")
    assert "| time / classic (median) |" in final and "| time / default (median) |" in choice
    head = next(line for line in page.splitlines() if line.startswith("| preset |"))
    assert "over classic's" in head

    def cell(row):
        return next(line for line in page.splitlines() if line.startswith(row)).split("|")[5].strip()

    def summary(text, variant):  # the variant's median time in the file's summary table
        lines = text.splitlines()
        head = next(line.split("|") for line in lines if line.startswith("| variant |") and "(median)" in line)
        column = next(i for i, c in enumerate(head) if "(median)" in c)
        return next(line for line in lines if line.startswith(f"| {variant} |")).split("|")[column].strip()

    assert cell('| `"default"`') == summary(final, "default")
    accurate = cell('| `"accurate"`')
    assert accurate.startswith(summary(choice, "accurate") + " ") and "default" in accurate


def test_refit_uv_figures_are_the_files():
    """docs/methods.md's re-fit-with-UVs figures come from results/refit_uv.md: the rms the re-fit saves
    against refit=0 (lowest and highest of the five cases) and spot at 2 % with the seam vertices fitted too."""
    import re

    rows = {}
    for line in _results("refit_uv.md").splitlines():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        if len(cells) == 9 and cells[1][:1].isdigit():
            rows[(cells[0], cells[1], cells[2])] = float(cells[7])
    cases = {(m, q) for m, q, _ in rows}
    saved = [100 * (1 - rows[(m, q, "re-fit, UVs carried (default)")] / rows[(m, q, "no re-fit (refit=0)")])
             for m, q in cases]
    page = _methods_page()
    low, high = map(int, re.search(r"lowers the geometric rms by (\d+)–(\d+) % against `refit=0`", page).groups())
    assert (low, high) == (round(min(saved)), round(max(saved)))
    seams, default = (rows[("spot", "0.02", run)] for run in ("re-fit with the seam vertices too, UVs carried",
                                                                "re-fit, UVs carried (default)"))
    assert f"spot at 2 %: {seams:.2g} against {default:.3g} of the diagonal" in page


@pytest.mark.slow
def test_refit_uv_rows_come_back(monkeypatch, tmp_path):
    """results/refit_uv.md's rows of the textured example (made in code) are what refit_uv.py makes now."""
    import warnings

    import qemjax

    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    from figures import refit_uv

    qemjax.shapes.write_examples(tmp_path, subdivisions=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        made = refit_uv.rows("textured example", tmp_path / "textured.obj", 0.25)
    kept = _results("refit_uv.md").splitlines()
    assert made and [line for line in made if line not in kept] == []


@pytest.mark.slow
def test_locks_weights_cap_shares_come_back(monkeypatch):
    """results/locks_weights.md's cap rows of the bumpy sphere with the parallel scheduler are what
    locks_weights.py makes now, and docs/methods.md's cap shares are theirs."""
    import re

    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    from figures import locks_weights

    sphere = locks_weights.meshes()["bumpy-sphere-5"]
    made: list[str] = []
    locks_weights.weights("bumpy-sphere-5", sphere, 0.05, made, schedulers=("parallel",))
    assert [line for line in made if line not in _results("locks_weights.md").splitlines()] == []
    share = {w: float(line.split("|")[5].strip(" %")) for line in made for w in [line.split("|")[3].strip()]}
    said = re.search(r"give it (\d+) % / (\d+) % of the output's vertices \((\d+) % without", _methods_page())
    assert [int(x) for x in said.groups()] == [round(share[w]) for w in ("10", "100", "1")]


def test_regularize_table_is_the_files():
    """docs/methods.md's regularisation table is results/regularize_sweep.txt's summary, and both name the
    method the sweep ran (the script's --method)."""
    import re

    text = _results("regularize_sweep.txt")
    command = re.match(r"# (python experiments/figures/regularize_sweep\.py.*)", text)
    assert command and "--method " in command.group(1)
    method = command.group(1).split("--method ")[1].split()[0]
    page = (ROOT / "docs" / "methods.md").read_text()
    assert f"`{command.group(1)}`" in " ".join(page.split())
    assert f"with the {method} method" in " ".join(page.split())
    summary = {(r, m): (s, q) for r, m, s, q in re.findall(r"^\| ([\d.]+) \| ([^|]+?) \| ([\d.]+) \| ([\d.]+) \|",
                                                          text, re.M)}
    rows = re.findall(r"^\| (\d+) % \| ([^|]+?) \| ([\d.]+) \| ([\d.]+) \|$", page, re.M)
    assert len(rows) >= 5
    for ratio, label, slivers, rms in rows:
        name = {"pymeshlab (quality threshold 0.3)": "pymeshlab"}.get(label, label.replace("λ = ", "qemjax λ="))
        assert summary[(f"{int(ratio) / 100:g}", name)] == (slivers, rms), (ratio, label)


@pytest.mark.slow
def test_distance_check_row_comes_back(tmp_path):
    """results/distance_check.txt's cow row (the largest cost, the measured and the reference distances, not
    the times) is what distance_check.py measures now."""
    if not (ROOT.parent / "shared" / "meshes" / "cow.obj").is_file():
        pytest.skip("the shared meshes are not beside the project")
    out = tmp_path / "distance_check.txt"
    run = subprocess.run([sys.executable, str(EXPERIMENTS / "figures" / "distance_check.py"), "--meshes", "cow",
                          "--ratios", "0.1", "--repeats", "1", "--out", str(out)], capture_output=True, text=True,
                         timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]

    def distances(text):
        return next(line.split("|")[0].split() for line in text.splitlines() if line.startswith("cow 0.1"))

    assert distances(out.read_text()) == distances(_results("distance_check.txt"))
    assert out.read_text().startswith("# python experiments/figures/distance_check.py --meshes cow")
