"""Running the code blocks of the README and the documentation pages as a user would (tests/test_readme.py,
tests/test_docs.py).

Python blocks of one file run in order in one namespace, in a temporary working folder; a block that sets
global JAX options (the compilation cache) runs in a subprocess, so nothing leaks into other tests. Each
command line of the bash blocks runs as its own process in a folder laid out like a fresh clone (the
repository files the lines name, copied) and must exit 0; ``qemjax`` is the installed command when it
belongs to this interpreter's environment, else ``python -m qemjax._cli``. Not run: ``pip install``,
``mkdocs`` and ``jupyter`` lines, comments, bash lines whose comment carries one of `SKIP_MARKERS`, and
python blocks whose first line is a comment carrying one (a benchmark mesh or a long run). Nothing here
reads the development meshes.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import qemjax

ROOT = Path(__file__).resolve().parents[1]
SKIP_MARKERS = ("needs a benchmark mesh", "(long)", "(not run)")
NOT_COMMANDS = ("pip install", "mkdocs ", "jupyter ", "python -m pytest")
GLOBAL_JAX = "jax.config.update"


def blocks(path: Path, lang: str) -> list[tuple[int, str]]:
    """(first line number, code) of each fenced block of ``lang`` in ``path``, in order."""
    text = path.read_text()
    out = []
    for m in re.finditer(rf"^```{lang}\n(.*?)^```", text, re.S | re.M):
        out.append((text.count("\n", 0, m.start(1)) + 1, m.group(1)))
    return out


def python_blocks(path: Path) -> list[tuple[int, str]]:
    """The python blocks that run (not those marked on their first line)."""
    return [(n, code) for n, code in blocks(path, "python")
            if not any(marker in code.splitlines()[0] for marker in SKIP_MARKERS)]


def command_lines(path: Path) -> list[tuple[int, str]]:
    """(line number, line) of every bash line that runs."""
    lines = []
    for start, code in blocks(path, "bash"):
        for i, line in enumerate(code.splitlines()):
            text = line.strip()
            if not text or text.startswith("#") or any(c in text for c in NOT_COMMANDS):
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


def child_env() -> dict:
    """Child processes import this qemjax and share the test session's compilation cache (`conftest`'s
    QEMJAX_CACHE_DIR: what the tests compiled, the children load instead of compiling again)."""
    e = dict(os.environ)
    package_root = str(Path(qemjax.__file__).resolve().parents[1])
    e["PYTHONPATH"] = os.pathsep.join([package_root] + ([e["PYTHONPATH"]] if e.get("PYTHONPATH") else []))
    e.pop("JAX_COMPILATION_CACHE_DIR", None)
    return e


def run_python(path: Path, folder: Path, env: dict) -> dict:
    """Run ``path``'s python blocks in ``folder`` (the caller's working folder); returns their namespace."""
    from qemjax import _costs

    namespace: dict = {"__name__": "__docs__"}
    registered = dict(_costs.REGISTRY)  # a block registers a method: undone after
    try:
        for start, code in python_blocks(path):
            if GLOBAL_JAX in code:
                done = subprocess.run([sys.executable, "-c", code], cwd=folder, env=env, capture_output=True,
                                      text=True, timeout=300)
                assert done.returncode == 0, f"{path.name} line {start}:\n{done.stderr[-3000:]}"
                continue
            # dont_inherit: run as a user's script (without this file's __future__ imports)
            exec(compile("\n" * (start - 1) + code, str(path), "exec", dont_inherit=True), namespace)  # noqa: S102
    finally:
        _costs.REGISTRY.clear()
        _costs.REGISTRY.update(registered)
        for value in list(namespace.values()):  # a Dask client the blocks started: close it and its cluster
            if type(value).__module__.startswith("distributed") and hasattr(value, "close"):
                cluster = getattr(value, "cluster", None)
                value.close()
                if cluster is not None:
                    cluster.close()
    return namespace


def bare(line: str) -> list[str]:
    """A command line's words, without its comment."""
    return shlex.split(line, comments=True)


def run_commands(path: Path, folder: Path, env: dict, skip=()) -> None:
    """Run ``path``'s command lines in ``folder``, laid out like a fresh clone: the repository files the
    lines name, and experiments/results (the example config's output folder). Lines whose words are in
    ``skip`` (run by another test already) are left out."""
    lines = [(n, line) for n, line in command_lines(path) if bare(line) not in [bare(s) for s in skip]]
    for _, line in lines:
        for arg in shlex.split(line, comments=True)[1:]:
            if not arg.startswith("-") and "/" in arg and (ROOT / arg).is_file():
                (folder / arg).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(ROOT / arg, folder / arg)
    (folder / "experiments" / "results").mkdir(parents=True, exist_ok=True)
    for number, line in lines:
        argv = shlex.split(line, comments=True)
        if argv[0] == "qemjax":
            argv = qemjax_command() + argv[1:]
        elif argv[0] in ("python", "python3"):
            argv = [sys.executable] + argv[1:]
        done = subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"{path.name} line {number}: {line}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"


DEV_LOG = [
    (r"\.\./shared|shared meshes", "a development folder"),
    (r"\bissues? \d+|#\d{2,}\b", "an issue number"),
    (r"--rev [0-9a-f]{6,}|\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,12}\b", "a git revision"),
]


# The code's comments and docstrings say why; the figures that back them live in docs/ (benchmarks.md): on
# top of DEV_LOG, no timings, speed ratios, results files, dates or the pipeline's old module names.
CODE_LOG = DEV_LOG + [
    (r"\d\s?(ms|µs|us|ns)\b|\d\s(s|sec|seconds|minutes|min)\b", "a timing"),
    (r"\d[x×](?![\d\w])|\d ?% (faster|slower)", "a speed ratio"),  # 1.4×, 0.69x (not 3×3, nor armadillo x16)
    (r"\bresults/\w|_\d{4}[a-z]?\b", "a results file"),  # experiments/results/..., a day tag (_1128g)
    (r"\b20\d\d-\d\d-\d\d\b|\b(January|February|March|April|May|June|July|August|September|October|November"
     r"|December) \d{1,2}\b", "a date"),
    (r"(?<![\w.])_(stages|setup)\b", "a stale module name"),
]


def _matches(name: str, lines, patterns) -> list[str]:
    return [f"{name}:{number}: {what}: {line.strip()[:100]}"
            for number, line in lines for pattern, what in patterns if re.search(pattern, line, re.I)]


def dev_log_references(path: Path) -> list[str]:
    """Lines of ``path`` that point into the project's development history rather than at the user."""
    return _matches(path.name, enumerate(path.read_text().splitlines(), 1), DEV_LOG)


def commentary(source: str) -> list[tuple[int, str]]:
    """(line number, text) of the comments and the docstrings (every string standing alone as a statement)
    of a Python source, in line order; code and the strings it uses are left out."""
    import ast
    import io
    import tokenize

    found = [(t.start[0], t.string) for t in tokenize.generate_tokens(io.StringIO(source).readline)
             if t.type == tokenize.COMMENT]
    lines = source.splitlines()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found += [(n, lines[n - 1]) for n in range(node.lineno, node.end_lineno + 1)]
    return sorted(found)


def code_log_references(path: Path) -> list[str]:
    """Comment and docstring lines of the Python file ``path`` that quote development history (`CODE_LOG`)."""
    return _matches(str(path.relative_to(ROOT)), commentary(path.read_text()), CODE_LOG)
