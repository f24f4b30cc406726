"""notebooks/quickstart.ipynb is a clean, well-formed notebook whose code parses.

Executing it is left to ``pytest --nbmake notebooks/`` (the notebook is the test there); this file only
catches the cheap mistakes: broken JSON, stored outputs, syntax errors.
"""

import ast
import json
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "quickstart.ipynb"


@pytest.fixture(scope="module")
def notebook():
    if not NOTEBOOK.exists():
        pytest.skip(f"{NOTEBOOK} is absent")
    return json.loads(NOTEBOOK.read_text())


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
        ast.parse("\n".join(lines), filename=f"quickstart.ipynb cell {i}")


def test_notebook_runs_without_shared_meshes_fallback(notebook):
    """The notebook must not need ../shared: it falls back to a mesh made in code."""
    code = "\n".join(_source(c) for c in notebook["cells"] if c["cell_type"] == "code")
    assert "icosphere" in code
