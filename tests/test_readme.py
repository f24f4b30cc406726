"""Every code block of README.md that a user would run, run as written in a fresh folder
(`tests/doc_blocks.py` says how). Nothing here reads the development meshes."""
from __future__ import annotations

import csv

import pytest

from doc_blocks import ROOT, child_env, command_lines, dev_log_references, python_blocks, run_commands, run_python

README = ROOT / "README.md"


@pytest.fixture(scope="module")
def env():
    return child_env()


def test_readme_is_short_and_starts_with_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    first = text.split("```bash\n", 1)[1].split("```", 1)[0].splitlines()
    assert first[2].endswith("pip install . && qemjax demo")
    assert first[4].endswith("pip install '.[test]' && python -m pytest -q")
    assert "(docs/img/" in text and (ROOT / "docs" / "img" / "bumpy.png").is_file()


def test_readme_has_the_blocks_it_promises():
    py, sh = python_blocks(README), command_lines(README)
    assert py and sh
    use = py[0][1]
    assert use.splitlines()[2].startswith("qemjax.shapes.write_examples()")  # the Use block's first line
    assert any(line.startswith("qemjax sweep sweep_example.toml") for _, line in sh)  # `qemjax examples` wrote it
    assert "max_error" not in use and 'res.stats["distance_max"]' in use  # a measured distance, not a cost


def test_readme_names_no_development_history():
    assert not dev_log_references(README), "\n".join(dev_log_references(README))


def test_readme_links_resolve():
    import re

    for target in re.findall(r"\]\(([^)#]+)\)", README.read_text()):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), target


@pytest.mark.slow
def test_python_blocks_run(tmp_path, monkeypatch, env):
    monkeypatch.chdir(tmp_path)
    namespace = run_python(README, tmp_path, env)
    for name in ("bumpy.obj", "bumpy.ply", "textured.obj", "textured.png", "bumpy-1000.obj"):
        assert (tmp_path / name).is_file(), name
    df = namespace["df"]
    assert len(df) == 6 and (df["error"] == "").all()
    assert (df["faces_out"] <= df["faces_in"]).all()


@pytest.mark.slow
def test_bash_lines_run(tmp_path, env):
    run_commands(README, tmp_path, env)
    assert (tmp_path / "out.ply").is_file()
    with open(tmp_path / "sweep_example.csv", newline="") as f:  # the pip-only example: written by qemjax examples
        rows = list(csv.DictReader(f))
    assert [r["target"] for r in rows[:3]] == ["0.1", "0.25", "200"]  # the config's order; a face count an int
    assert all(r["error"] == "" for r in rows)
