"""Every page of docs/: its python blocks run as written, in order, in a fresh folder holding the example
files (`qemjax.shapes.write_examples`), and its command lines run as separate processes
(`tests/doc_blocks.py` says how). Pages name no development history. `mkdocs build --strict` itself runs in
CI (.ci/run)."""
from __future__ import annotations

import tomllib

import pytest

import qemjax
from doc_blocks import (ROOT, blocks, child_env, code_log_references, command_lines, dev_log_references, python_blocks,
                        run_commands, run_python)

DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
WITH_PYTHON = [p for p in PAGES if python_blocks(p)]


@pytest.fixture(scope="module")
def env():
    return child_env()


def test_every_page_is_in_the_site():
    nav = (ROOT / "mkdocs.yml").read_text()
    assert {p.name for p in PAGES} == {p.name for p in PAGES if f": {p.name}" in nav}
    assert {"getting-started.md", "methods.md", "papers.md", "benchmarks.md", "api.md"} <= {p.name for p in PAGES}


@pytest.mark.parametrize("page", PAGES + [ROOT / "CHANGELOG.md", ROOT / "experiments" / "README.md"],
                         ids=lambda p: p.name)
def test_page_names_no_development_history(page):
    assert not dev_log_references(page), "\n".join(dev_log_references(page))




def test_code_names_no_development_history():
    """The package's comments and docstrings say why without measured figures, dates, results files or issue
    numbers: those live in docs/ (benchmarks.md, design.md)."""
    files = sorted((ROOT / "qemjax").rglob("*.py"))
    assert len(files) > 50
    found = [line for p in files for line in code_log_references(p)]
    assert not found, "\n".join(found)


def test_every_experiment_is_listed():
    """experiments/README.md names every script of experiments/ (the figures', the probes', the shared modules)."""
    readme = (ROOT / "experiments" / "README.md").read_text()
    scripts = sorted((ROOT / "experiments").rglob("*.py"))
    assert {p.parent.name for p in scripts} == {"experiments", "figures", "probes"}
    assert not [p.name for p in scripts if p.name not in readme]


def test_named_experiments_and_results_exist():
    """Every script and results file that the pages, the README, the changelog, the tests and the package's
    comments name under experiments/ is there (a moved or deleted one leaves no stale command behind)."""
    import re

    texts = [*PAGES, ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "experiments" / "README.md",
             *(ROOT / "tests").glob("*.py"),
             *(ROOT / "qemjax").rglob("*.py")]
    named = {(t.name, m) for t in texts for m in re.findall(r"experiments/[a-z0-9_/.-]*[a-z0-9]\.(?:py|txt|csv|md|png)\b",
                                                           t.read_text())}
    assert len(named) > 50
    assert not sorted(f"{t}: {m}" for t, m in named if not (ROOT / m).is_file())
    # the pages and READMEs cite results by what they hold, not by the day they were made (_1128g)
    undated = {p.name for p in [*PAGES, ROOT / "README.md", ROOT / "experiments" / "README.md"]}
    assert not sorted(f"{t}: {m}" for t, m in named if t in undated and re.search(r"_\d{4}[a-z]?\.", m))


def test_the_config_shown_is_the_example_config():
    (_, shown), = blocks(DOCS / "cli.md", "toml")
    assert tomllib.loads(shown) == tomllib.loads(qemjax.shapes.EXAMPLE_SWEEP)  # what `qemjax examples` writes


def test_images_are_committed_and_small():
    for img in (DOCS / "img").glob("*.png"):
        assert img.stat().st_size < 150_000, img


@pytest.mark.slow
@pytest.mark.parametrize("page", WITH_PYTHON, ids=lambda p: p.name)
def test_python_blocks_run(page, tmp_path, monkeypatch, env):
    from qemjax import _schedulers

    monkeypatch.chdir(tmp_path)
    qemjax.shapes.write_examples(tmp_path)
    monkeypatch.setattr(_schedulers, "_REGISTRY", dict(_schedulers._REGISTRY))  # a page registers one
    namespace = run_python(page, tmp_path, env)
    if page.name == "sweeps.md":
        assert (tmp_path / "sweep.csv").is_file() and (namespace["df"]["error"] == "").all()
    if page.name == "record.md":
        assert (tmp_path / "bumpy-lods.glb").is_file() and (tmp_path / "bumpy.npz").is_file()
    if page.name == "attributes.md":
        assert (tmp_path / "textured-10.glb").is_file()


@pytest.mark.slow
def test_command_lines_run(tmp_path, env):
    page = DOCS / "cli.md"
    assert len(command_lines(page)) >= 10
    # what the README's test runs already (the sweep, above all) is not run twice; the example files are
    already = [line for _, line in command_lines(ROOT / "README.md") if not line.startswith("qemjax examples")]
    run_commands(page, tmp_path, env, skip=already)
    for name in ("out.ply", "lods/bumpy-lod0.obj", "lods/bumpy-lods.glb", "lods/bumpy-record.npz",
                 "textured-10.obj", "textured-10.mtl", "textured-10.png"):
        assert (tmp_path / name).is_file(), name


@pytest.mark.slow  # collects the whole suite in a fresh process
def test_contributing_states_the_test_counts():
    """docs/contributing.md quotes what the two collection commands print; a test added or removed there
    must be counted there too."""
    import re
    import subprocess
    import sys

    text = " ".join((DOCS / "contributing.md").read_text().split())
    fast = re.search(r"`(\d+)/(\d+) tests collected \((\d+) deselected\)`", text)
    full = re.search(r"`(\d+) tests collected`", text)
    assert fast and full, "contributing.md quotes no counts"

    def collected(*marks) -> str:
        p = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                            *marks], cwd=ROOT, capture_output=True, text=True, timeout=600)
        return re.sub(r" in [\d.]+s.*$", "", p.stdout.strip().splitlines()[-1])

    # one collection: the fast tier's line counts every test too (a second, full one took as long again)
    assert collected("-m", "not slow") == fast.group(0).strip("`")
    n_fast, n_all, n_slow = map(int, fast.groups())
    assert n_fast + n_slow == n_all == int(full.group(1))
    assert f"{n_slow} of {n_all} tests" in text and f"fast tier runs {n_fast}" in text



# keys a run sets only in some cases the small runs below do not reach, and where they are set
CONDITIONAL_KEYS = {"refit_skipped": "_pipeline/bound.py", "partition": "_partition/run.py",
                    "not_kept_seams": "_partition/run.py"}


@pytest.fixture(scope="module")
def stats_keys() -> set:
    """The stats keys of five small runs that between them set every key but `CONDITIONAL_KEYS`'."""
    import warnings

    import numpy as np

    m = qemjax.shapes.bumpy_sphere(2)
    keys = set()
    for kw in (dict(ratio=0.2), dict(max_error=1e-3, scheduler="greedy"), dict(ratio=0.2, method="esqem"),
               dict(max_distance_rel=0.05), dict(ratio=0.2, method="classic", locked=np.arange(4), min_angle=5)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # what these runs warn of is tested where it is made
            keys |= set(qemjax.simplify(m, **kw).stats)
    for key, where in CONDITIONAL_KEYS.items():
        code = (ROOT / "qemjax" / where).read_text()
        assert f'"{key}"' in code or f"{key}=" in code, key
    return keys | set(CONDITIONAL_KEYS)


def test_the_stats_keys_the_pages_name_exist(stats_keys):
    """Every ``stats["KEY"]`` the pages and the README name is a key some run sets (docs/schedulers.md named a
    ``stats["blocked"]`` that no run has: the pairs a rule refused are in ``rejected_by`` and ``blocked_by``)."""
    import re

    named = {}
    for page in PAGES + [ROOT / "README.md"]:
        for key in re.findall(r'stats\["([a-z_0-9]+)"\]', page.read_text()):
            named.setdefault(key, page.name)
    assert {k: p for k, p in named.items() if k not in stats_keys} == {}


def test_the_result_s_docstring_names_every_stats_key_and_stop_reason(stats_keys):
    """`SimplifyResult`'s docstring, the reference for ``res.stats`` and ``res.stop_reason``, names every key
    the runs set and every reason (it named neither ``late_memoryless_off`` nor ``memoryless_from_faces``,
    nor the stop reason ``"locked"``)."""
    import re

    from qemjax._schedulers.outcome import STOPS

    doc = qemjax.SimplifyResult.__doc__
    named = set(re.findall(r"``([a-z_0-9]+)``", doc)) | set(re.findall(r'stats\["([a-z_0-9]+)"\]', doc))
    named |= {f"distance{k}" for k in named if k.startswith("_p")}  # ``distance_p50`` / ``_p95`` / ``_p99``
    named |= {f"{k}_rel" for k in named}  # "each also as ``*_rel``"
    assert sorted(k for k in stats_keys - {"partition", "not_kept_seams"} if k not in named) == []
    assert [s for s in STOPS + ("max_distance",) if f'``"{s}"``' not in doc] == []


def test_why_a_run_stopped_names_every_reason_and_rule():
    """docs/methods.md, "Why a run stopped", names every stop reason (it left out ``"max_distance"``) and
    every rule ``stats["rejected_by"]`` and ``stats["blocked_by"]`` count (it named four of nine)."""
    import numpy as np

    from qemjax._schedulers import outcome

    page = (DOCS / "methods.md").read_text()
    paragraph = page.split("**Why a run stopped.**")[1].split("\n\n")[0]
    assert [s for s in outcome.STOPS + ("max_distance",) if f'`"{s}"`' not in paragraph] == []
    none = np.zeros(0, bool)
    rules = [*outcome.REJECT.values(), *outcome.classify(2, 0, np.zeros(0, np.int8), np.zeros(0), none, none)[1]]
    assert [r for r in dict.fromkeys(rules) if f"`{r}`" not in paragraph] == []


def test_the_late_switch_s_reasons_are_all_on_the_methods_page():
    """docs/methods.md says each case in which ``stats["late_memoryless_off"]`` is set (`stages._late_off`):
    it named four of the five, not a run without a face target."""
    page = (DOCS / "methods.md").read_text()
    paragraph = next(p for p in page.split("\n\n") if 'stats["late_memoryless_off"]' in p)
    cases = ("without a face target (`max_error` alone)", "registered from outside", "`regularize`",
             "`area_weight`", "attributes kept", "`feature_edges`")
    assert [c for c in cases if c not in paragraph] == []


def test_getting_started_names_every_example_file_and_shape(tmp_path):
    """docs/getting-started.md, "The example files", names every file `write_examples` writes and every mesh
    generator of `qemjax.shapes` (it left out sweep_example.toml and double_cone)."""
    import inspect

    section = (DOCS / "getting-started.md").read_text().split("## The example files")[1].split("\n## ")[0]
    written = [p.name for p in qemjax.shapes.write_examples(tmp_path)]
    assert [n for n in written if f"`{n}`" not in section] == []
    makers = [n for n, f in vars(qemjax.shapes).items() if inspect.isfunction(f) and not n.startswith("_")
              and f.__module__ == "qemjax.shapes" and inspect.signature(f).return_annotation in ("Mesh",)]
    assert len(makers) >= 6 and [n for n in makers if f"`{n}`" not in section] == []


def test_the_pages_and_simplify_name_every_field_every_method_has():
    """docs/methods.md ("Settings as objects") and `simplify`'s docstring name every field of
    `qemjax.Method`, which every method has (they left out ``sliver_moves`` and ``quality_threshold``, and
    the docstring ``polish`` too)."""
    import dataclasses

    fields = [f.name for f in dataclasses.fields(qemjax.Method)]
    page = (DOCS / "methods.md").read_text()
    sentence = page.split("every method also has")[1].split(")\n")[0]
    assert [f for f in fields if f"`{f}`" not in sentence] == []
    doc = qemjax.simplify.__doc__.split("every method also has")[1].split("(`_costs.base.Method`)")[0]
    assert [f for f in fields if f"``{f}``" not in doc] == []


def test_the_level_s_fields_are_all_named_where_replay_is_described():
    """docs/record.md and `SimplifyResult.replay`'s docstring list every field of the `Level` it returns (they
    left out ``contractions`` and ``round``)."""
    import dataclasses
    import re

    fields = [f.name for f in dataclasses.fields(qemjax.Level)]
    page = (DOCS / "record.md").read_text()
    docstring = qemjax.SimplifyResult.replay.__doc__
    for text in (page.split("returns a `Level` (")[1], docstring.split("`qemjax.Level` (")[1]):
        listed = set(re.findall(r"[a-z_]+", text.split("):")[0].split(").")[0]))
        assert [f for f in fields if f not in listed] == []


def test_the_api_reference_covers_every_public_name():
    """docs/api.md has an entry for every name of ``qemjax.__all__`` (it had none for ``qemjax.cache``), of
    ``qemjax.metrics.__all__`` and ``qemjax.render.__all__`` (not ``charts``, ``point_triangle_distance``,
    ``face_texture_colors``), every mesh of `qemjax.shapes` (not ``double_cone``) and ``peers.PeerResult``,
    which the page names."""
    import re

    page = (DOCS / "api.md").read_text()
    entries = set(re.findall(r"^::: \S*?\.?(\w+)$", page, re.M))
    for block in re.findall(r"members: \[([^\]]*)\]", page):
        entries |= {n.strip() for n in block.split(",")}
    entries.add("register_method")  # documented as `qemjax._costs.register`, the page says so
    public = [n for n in qemjax.__all__ if n not in ("metrics", "costs", "shapes", "peers", "render")]
    public += [*qemjax.metrics.__all__, *qemjax.render.__all__, "PeerResult", "write_examples"]
    public += ["icosphere", "torus", "grid", "cube", "bumpy_sphere", "double_cone"]
    assert "`qemjax.register_method` is:\n\n::: qemjax._costs.register" in page
    assert [n for n in public if n not in entries] == []


def test_the_cache_s_docstring_says_when_and_where_it_turns_on():
    """`qemjax.cache`'s docstring said importing qemjax turns the cache on, at ``$QEMJAX_CACHE_DIR`` or
    ``~/.cache``: the first compilation does (importing qemjax starts no JAX), and ``$XDG_CACHE_HOME`` comes
    before ``~/.cache`` (`qemjax._kernels.cache.default_dir`, docs/getting-started.md)."""
    import os

    from qemjax._kernels import cache as _cache

    doc = " ".join(qemjax.cache.__doc__.split())
    assert "importing qemjax" not in doc and "first compilation turns it on" in doc
    assert "``$QEMJAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/qemjax/jax``, else ``~/.cache/qemjax/jax``" in doc
    page = " ".join((DOCS / "getting-started.md").read_text().split())
    assert "`$QEMJAX_CACHE_DIR`, else `$XDG_CACHE_HOME/qemjax/jax`, else `~/.cache/qemjax/jax`" in page
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("QEMJAX_CACHE_DIR", raising=False)
        mp.setenv("XDG_CACHE_HOME", "/xdg")
        assert _cache.default_dir() == os.path.join("/xdg", "qemjax", "jax")


def test_the_metrics_page_names_every_value_evaluate_returns(tmp_path):
    """docs/metrics.md, "`evaluate`", names every key `metrics.evaluate` returns, UVs kept (it left out the
    sample counts, ``bbox_diagonal``, the areas and volumes before and after, ``flipped_fraction`` and the
    appearance deviations)."""
    import re
    import warnings

    page = (DOCS / "metrics.md").read_text()
    section = page.split("## `evaluate`")[1].split("\n## ")[0]
    distances = page.split("## Two-way sampled distances")[1].split("\n## ")[0]  # "the distances above"
    named = set(re.findall(r"`([a-z_0-9]+)`", section + distances))
    before = re.search(r"input's (.*?) as `\*_before`", section, re.S).group(1)
    named |= {f"{k}_before" for k in re.findall(r"`([a-z_]+)`", before)}
    named |= {f"color_dev_{k[len('uv_dev_'):]}" for k in named if k.startswith("uv_dev_")}
    qemjax.shapes.write_examples(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = qemjax.simplify(tmp_path / "textured.obj", ratio=0.3, method="classic", attributes="uv")
    row = qemjax.metrics.evaluate(tmp_path / "textured.obj", res, n_samples=200)
    assert any(k.startswith("uv_dev_") for k in row)
    assert [k for k in row if k not in named and not (k.endswith("_rel") and k[:-4] in named)
            and not k.endswith(("_fwd", "_bwd", "_fwd_rel", "_bwd_rel"))] == []
    assert "`*_fwd` from the input to the result, `*_bwd` back" in " ".join(distances.split())


def test_every_parameter_of_the_public_functions_is_documented():
    """The docstring of each public function names each of its parameters (`simplify_batch` named no
    ``errors``, `render.render` and `render.render_pair` no ``figsize`` or ``dpi``, `metrics.attribute_deviation`
    no ``n_samples`` or ``seed``, and `charts`, `seam_report`, `uv_chart_integrity`, `shapes.icosphere`,
    `bumpy_sphere` and `double_cone` one or two each)."""
    import inspect

    functions = [getattr(qemjax, n) for n in qemjax.__all__ if inspect.isfunction(getattr(qemjax, n))]
    for module in (qemjax.metrics, qemjax.render, qemjax.shapes):
        functions += [f for n, f in vars(module).items() if inspect.isfunction(f) and not n.startswith("_")
                      and f.__module__.startswith("qemjax") and (n in getattr(module, "__all__", [n]))]
    functions += [qemjax.peers.simplify, qemjax.peers.available]
    left_out = {}
    plain = ("path", "mesh", "original", "simplified", "value")  # what each of these is goes without saying
    for f in functions:
        doc = f.__doc__ or ""
        missing = [p for p, spec in inspect.signature(f).parameters.items()
                   if spec.kind not in (spec.VAR_POSITIONAL, spec.VAR_KEYWORD) and p not in doc + " ".join(plain)]
        if missing:
            left_out[f"{f.__module__}.{f.__qualname__}"] = missing
    assert left_out == {}


def test_the_design_s_layer_table_names_every_package():
    """docs/design.md's table of layers names every package and module of `tests/test_layout.py`'s layers
    (it had no row for ``_partition`` or ``_ahead``) and every run setting of ``_options.py`` (not
    ``Partition``)."""
    import dataclasses

    from qemjax import _options
    from test_layout import LAYERS

    page = (DOCS / "design.md").read_text()
    table = page.split("## The layers")[1].split("\n## ")[0]
    rows = [line.split("|")[1] for line in table.splitlines() if line.startswith("| `qemjax/")]
    paths = " ".join(rows)
    assert [layer for layer in LAYERS if f"qemjax/{layer}" not in paths and f"`{layer}.py`" not in paths
            and f"{layer}.py" not in paths] == []
    options = next(r for r in table.splitlines() if r.startswith("| `qemjax/_options.py`"))
    settings = [n for n, c in vars(_options).items() if dataclasses.is_dataclass(c) and n in dir(qemjax)]
    assert len(settings) == 4 and [n for n in settings if f"`{n}`" not in options] == []
