"""The notebooks (quickstart.ipynb, lod_viewer.ipynb, sweep_analysis.ipynb) are clean, well-formed notebooks whose code parses.

Executing it is left to ``pytest --nbmake notebooks/`` (the notebook is the test there); this file only
catches the cheap mistakes: broken JSON, stored outputs, syntax errors.
"""

import ast
import json
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOK = NOTEBOOKS / "quickstart.ipynb"


@pytest.fixture(scope="module", params=["quickstart.ipynb", "lod_viewer.ipynb", "sweep_analysis.ipynb"])
def notebook(request):
    path = NOTEBOOKS / request.param
    if not path.exists():
        pytest.skip(f"{path} is absent")
    return json.loads(path.read_text())


def _source(cell):
    src = cell["source"]
    return "".join(src) if isinstance(src, list) else src


def test_notebook_is_nbformat4(notebook):
    assert notebook["nbformat"] == 4
    assert notebook["metadata"]["kernelspec"]["name"] == "python3"
    assert any(cell["cell_type"] == "code" for cell in notebook["cells"])


def test_notebook_has_no_stored_outputs(notebook):
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            assert cell.get("outputs", []) == [], "clear the notebook's outputs before committing"
            assert cell.get("execution_count") is None


def test_notebook_code_parses(notebook):
    for i, cell in enumerate(notebook["cells"]):
        if cell["cell_type"] != "code":
            continue
        lines = [line for line in _source(cell).splitlines() if not line.lstrip().startswith(("%", "!"))]
        ast.parse("\n".join(lines), filename=f"notebook cell {i}")


def test_notebook_runs_without_shared_meshes_fallback():
    """The quickstart must not need ../shared: it falls back to a mesh made in code."""
    if not NOTEBOOK.exists():
        pytest.skip(f"{NOTEBOOK} is absent")
    nb = json.loads(NOTEBOOK.read_text())
    code = "\n".join(_source(c) for c in nb["cells"] if c["cell_type"] == "code")
    assert "icosphere" in code


def test_lod_viewer_calls_its_slider_callback():
    """Headless (CI), the viewer exercises the slider by calling its callback; it makes its mesh in code."""
    path = NOTEBOOKS / "lod_viewer.ipynb"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    code = "\n".join(_source(c) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code")
    assert "slider.observe(show" in code and "show({" in code
    assert "shared" not in code


def test_sweep_analysis_checks_its_own_results():
    """nbmake runs the sweep notebook; its asserts are the checks: every cell ran without an error, every
    panel drew, the front is exactly the non-dominated cells (against a brute-force check written out in
    the notebook), and each rendered mesh is the one the sweep measured (its hash). It needs no ../shared."""
    path = NOTEBOOKS / "sweep_analysis.ipynb"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    code = "\n".join(_source(c) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code")
    for check in ['assert (table["error"] == "").all()', "qemjax.pareto_front(table", "any(dominates(other, row)",
                  'result_hash(res) == row["result_sha256"]', "bumpy_sphere(", "len(ax.lines) > 0"]:
        assert check in code, check
