"""Every code block of README.md that a user would run, run as written in a fresh folder.

The python blocks run in order in one namespace, in a temporary working folder (the Use block's first line
writes the example files there); a block that sets global JAX options (the compilation cache) runs in a
subprocess, so nothing leaks into other tests. Each command line of the bash blocks runs as its own process
in a folder laid out like a fresh clone (the repository files the lines name, copied) and must exit 0;
``qemjax`` is the installed command when it belongs to this interpreter's environment, else
``python -m qemjax._cli``. Not run: ``pip install`` lines (the install and test commands at the top),
comments, and lines marked as needing the development meshes or as long (`SKIP_MARKERS`). Nothing here
reads ../shared.
"""
from __future__ import annotations

import csv
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import qemjax

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SKIP_MARKERS = ("needs the development meshes", "(long)")  # a line's comment saying so: not run here
GLOBAL_JAX = "jax.config.update"  # a block that sets global JAX options runs in a subprocess


def blocks(lang: str) -> list[tuple[int, str]]:
    """(first line number, code) of each fenced block of ``lang`` in the README, in order."""
    text = README.read_text()
    out = []
    for m in re.finditer(rf"^```{lang}\n(.*?)^```", text, re.S | re.M):
        out.append((text.count("\n", 0, m.start(1)) + 1, m.group(1)))
    return out


def command_lines() -> list[tuple[int, str]]:
    """(line number, line) of every bash line the test runs."""
    lines = []
    for start, code in blocks("bash"):
        for i, line in enumerate(code.splitlines()):
            text = line.strip()
            if not text or text.startswith("#") or "pip install" in text:
                continue
            if any(marker in text for marker in SKIP_MARKERS):
                continue
            lines.append((start + i, text))
    return lines


def qemjax_command() -> list[str]:
    """The installed ``qemjax`` when it is this environment's (CI: pip-installed), else the module."""
    found = shutil.which("qemjax")
    if found and os.path.dirname(found) == os.path.dirname(sys.executable):
        return [found]
    return [sys.executable, "-m", "qemjax._cli"]


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """Child processes import this qemjax and share one compilation cache (later processes load the
    kernels the first compiled)."""
    e = dict(os.environ)
    package_root = str(Path(qemjax.__file__).resolve().parents[1])
    e["PYTHONPATH"] = os.pathsep.join([package_root] + ([e["PYTHONPATH"]] if e.get("PYTHONPATH") else []))
    e["QEMJAX_CACHE_DIR"] = str(tmp_path_factory.mktemp("jax-cache"))
    e.pop("JAX_COMPILATION_CACHE_DIR", None)
    return e


def test_readme_has_the_blocks_it_promises():
    py, sh = blocks("python"), command_lines()
    assert py and sh
    use = py[0][1]
    assert use.splitlines()[2].startswith("qemjax.shapes.write_examples()")  # the Use block's first line
    assert any(line.startswith("qemjax sweep sweep_example.toml") for _, line in sh)  # `qemjax examples` wrote it
    assert "shared" not in "".join(code for _, code in py) + "".join(line for _, line in sh)
    assert "m_in" not in use  # every name the block uses is defined in it


def test_toml_block_is_the_example_config():
    """The README shows the sweep_example.toml that `qemjax examples` writes, as it is."""
    (_, shown), = blocks("toml")
    assert shown.strip() == qemjax.shapes.EXAMPLE_SWEEP.strip()


def test_python_blocks_run(tmp_path, monkeypatch, env):
    monkeypatch.chdir(tmp_path)
    from qemjax import _costs

    namespace: dict = {"__name__": "__readme__"}
    registered = dict(_costs.REGISTRY)  # a block registers a method: undone after
    try:
        for start, code in blocks("python"):
            if GLOBAL_JAX in code:
                done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                                      text=True, timeout=300)
                assert done.returncode == 0, f"README.md line {start}:\n{done.stderr[-3000:]}"
                continue
            # dont_inherit: run as a user's script (without this file's __future__ imports)
            exec(compile("\n" * (start - 1) + code, str(README), "exec", dont_inherit=True), namespace)  # noqa: S102
    finally:
        _costs.REGISTRY.clear()
        _costs.REGISTRY.update(registered)
        for value in list(namespace.values()):  # a Dask client the blocks started: close it and its cluster
            if type(value).__module__.startswith("distributed") and hasattr(value, "close"):
                cluster = getattr(value, "cluster", None)
                value.close()
                if cluster is not None:
                    cluster.close()
    for name in ("bumpy.obj", "bumpy.ply", "creases.txt", "textured.obj", "textured.png", "bumpy-1000.obj",
                 "bumpy-lods.glb", "bumpy.npz", "textured-10.glb", "sweep.csv"):
        assert (tmp_path / name).is_file(), name
    df = namespace["df"]
    assert len(df) and (df["error"] == "").all()


def test_bash_lines_run(tmp_path, env):
    """Each command line exits 0, in a folder laid out like a fresh clone: the repository files the lines
    name and experiments/results, nothing else (the sweep's config is the one `qemjax examples` writes, as
    for a pip-only user)."""
    lines = command_lines()
    for _, line in lines:
        for arg in shlex.split(line, comments=True)[1:]:
            if not arg.startswith("-") and "/" in arg and (ROOT / arg).is_file():
                (tmp_path / arg).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(ROOT / arg, tmp_path / arg)
    assert (ROOT / "experiments" / "results").is_dir()  # committed: the example config's out folder
    (tmp_path / "experiments" / "results").mkdir(parents=True, exist_ok=True)
    for number, line in lines:
        argv = shlex.split(line, comments=True)
        if argv[0] == "qemjax":
            argv = qemjax_command() + argv[1:]
        elif argv[0] in ("python", "python3"):
            argv = [sys.executable] + argv[1:]
        done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"README.md line {number}: {line}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    for name in ("out.ply", "lods/bumpy-lod0.obj", "lods/bumpy-lods.glb", "lods/bumpy-record.npz",
                 "textured-10.obj", "textured-10.mtl", "textured-10.png"):
        assert (tmp_path / name).is_file(), name
    with open(tmp_path / "sweep_example.csv", newline="") as f:  # the pip-only example: written by qemjax examples
        rows = list(csv.DictReader(f))
    assert [r["target"] for r in rows[:3]] == ["0.1", "0.25", "200"]  # the config's order; a face count an int
    assert all(r["error"] == "" for r in rows)
