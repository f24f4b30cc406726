"""First contact, as a new user meets it: a fresh virtual environment, `pip install` of a revision, empty
compilation caches (JAX's and numba's), then the README's first commands from a scratch folder, each run twice
(the first run, then the same command again). Prints the install time and a table of wall times (command start
to exit) with the summary's own compile/run split, and the CPU.

    python experiments/figures/first_run.py                  # HEAD
    python experiments/figures/first_run.py --rev 9aab674    # another revision (before / after)

Package downloads come from pip's own cache when it has them (as on a machine that installed anything
before); nothing of qemjax's is cached: the venv, the JAX cache folder and numba's cache are all new.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
from machine import cpu_model  # noqa: E402

REPO = Path(__file__).resolve().parents[2]

def readme_example(readme: Path) -> str:
    """The README's first Python block, as written."""
    text = readme.read_text()
    start = text.index("```python") + len("```python")
    return text[start:text.index("```", start)]

CASES = [  # (label, argv after the venv's bin/): in this order, as the first-contact table
    ("qemjax simplify bumpy.obj o.ply --faces 1000", ["qemjax", "simplify", "bumpy.obj", "o.ply", "--faces", "1000"]),
    ("qemjax simplify ... --scheduler greedy", ["qemjax", "simplify", "bumpy.obj", "g.ply", "--faces", "1000",
                                                "--scheduler", "greedy"]),
    ("qemjax demo (327,680 faces)", ["qemjax", "demo"]),
    ("a textured mesh: qemjax simplify textured.obj", ["qemjax", "simplify", "textured.obj", "t.obj", "--ratio", "0.1"]),
    ("the README's Python example", ["python", "readme_example.py"]),
]


def timed(cmd, **kw) -> tuple[float, str]:
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, **kw)
    wall = time.perf_counter() - t0
    if done.returncode:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    return wall, done.stdout + done.stderr


def split(out: str) -> str:
    m = re.search(r"compile ([\d.]+) s, run ([\d.]+) s", out)
    return f"compile {m.group(1)} s, run {m.group(2)} s" if m else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", default="HEAD", help="the revision to install (default HEAD)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = ap.parse_args()
    rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", args.rev], capture_output=True,
                         text=True, check=True).stdout.strip()
    top = Path(tempfile.mkdtemp(prefix="qemjax-first-run-"))
    src, venv, work, caches = top / "src", top / "venv", top / "work", top / "caches"
    for d in (src, work, caches):
        d.mkdir()
    subprocess.run(f"git -C {REPO} archive {rev} | tar -x -C {src}", shell=True, check=True)
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("NUMBA_", "QEMJAX_", "JAX_", "XLA_", "VIRTUAL_ENV", "PYTHONPATH"))}
    env.update(XDG_CACHE_HOME=str(caches), HOME=str(top), PATH=f"{venv / 'bin'}{os.pathsep}{env['PATH']}")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    timed([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--upgrade", "pip"], env=env)
    install, _ = timed([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(src)], env=env)
    timed(["qemjax", "examples"], env=env, cwd=work)
    (work / "readme_example.py").write_text(readme_example(src / "README.md"))
    rows = []
    for label, cmd in CASES:
        first, out1 = timed(cmd, env=env, cwd=work)
        again, out2 = timed(cmd, env=env, cwd=work)
        rows.append((label, first, split(out1), again, split(out2)))
        print(f"  {label}: {first:.1f} s, again {again:.1f} s", file=sys.stderr, flush=True)
    print(f"# first contact at {rev}: fresh venv, empty JAX and numba caches; {cpu_model()}, {os.cpu_count()} cores")
    print(f"# pip install . (dependencies from pip's cache): {install:.1f} s")
    print("| first contact | first run | the summary says | the same command again | the summary says |")
    print("|---|---|---|---|---|")
    for label, first, s1, again, s2 in rows:
        print(f"| `{label}` | {first:.1f} s | {s1} | {again:.1f} s | {s2} |")
    if not args.keep:
        subprocess.run(["rm", "-rf", str(top)])
    else:
        print(f"# kept {top}")


if __name__ == "__main__":
    main()
