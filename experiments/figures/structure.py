"""How the package reads to a newcomer: the code one default run crosses, the longest functions, lines per
module, and where each validity rule is written.

- **Crossed by one run**: one warm ``qemjax.simplify(bumpy_sphere(4), ratio=0.1)`` traced with
  ``sys.setprofile``: the distinct Python functions of ``qemjax`` it calls, the files they live in, and how
  often consecutive calls change file (numba-compiled bodies are opaque to the profiler: their Python
  entry counts once).
- **Longest functions**: every function of ``qemjax/`` by lines (``ast``), with its parameter count; and the
  functions with the most parameters.
- **Lines per module** under ``--package`` (``_schedulers`` by default), with the total.
- **Rules**: definitions whose names say which validity rule they implement (link condition, flip test,
  coincident faces, edge update, locks), in ``qemjax/`` and in ``tests/``. A rule written inline inside a
  longer function is not found by name; `--show` lists what was found, so a reader can check.

Runs on whichever ``qemjax`` is imported (``PYTHONPATH=TREE`` for another checkout)::

    python experiments/figures/structure.py
    PYTHONPATH=/tmp/old python experiments/figures/structure.py --show
"""
from __future__ import annotations

import argparse
import ast
import collections
import re
import sys
from pathlib import Path

RULES = {
    "link condition": r"link",
    "flip test": r"flip",
    "coincident faces": r"coincid",
    "edge update": r"(contract_edges|edge_?update|EdgeUpdate|update_edges)",
    "lock rule": r"(both_locked|lock_rule|locked_pair|vanishing|strands)",
}


def functions(root: Path):
    """(file, qualified name, lines, parameters) of every function under ``root``."""
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        stack = [(tree, "")]
        while stack:
            node, prefix = stack.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    a = child.args
                    params = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
                    if a.args and a.args[0].arg in ("self", "cls"):
                        params -= 1
                    name = prefix + child.name
                    yield path, name, child.end_lineno - child.lineno + 1, params
                    stack.append((child, name + "."))
                elif isinstance(child, ast.ClassDef):
                    stack.append((child, prefix + child.name + "."))


def crossed(package: Path):
    """Distinct functions, files and file changes of one warm default run."""
    import qemjax
    from qemjax.shapes import bumpy_sphere

    mesh = bumpy_sphere(4)
    qemjax.simplify(mesh, ratio=0.1)  # warm: compile and cache before tracing
    root = str(package)
    calls, seen = [], set()

    def profile(frame, event, arg):
        if event == "call" and frame.f_code.co_filename.startswith(root):
            code = frame.f_code
            calls.append(code.co_filename)
            seen.add((code.co_filename, code.co_firstlineno, code.co_name))

    sys.setprofile(profile)
    try:
        qemjax.simplify(mesh, ratio=0.1)
    finally:
        sys.setprofile(None)
    changes = sum(1 for x, y in zip(calls, calls[1:]) if x != y)
    return len(seen), len({f for f, _, _ in seen}), changes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--package", default="_schedulers", help="the sub-package whose module lines are listed")
    ap.add_argument("--top", type=int, default=12)
    ap.add_argument("--show", action="store_true", help="list every rule definition found")
    args = ap.parse_args(argv)

    import qemjax

    package = Path(qemjax.__file__).resolve().parent
    tests = package.parent / "tests"
    print(f"qemjax at {package}")

    nfun, nfile, changes = crossed(package)
    print(f"\none warm default run (bumpy_sphere(4), ratio 0.1): {nfun} functions in {nfile} files, "
          f"{changes} changes of file")

    rows = list(functions(package))
    print(f"\nlongest functions of qemjax/ (lines, parameters):")
    for path, name, lines, params in sorted(rows, key=lambda r: (-r[2], r[1]))[:args.top]:
        print(f"  {lines:5d} {params:3d}  {path.relative_to(package.parent)}:{name}")
    print(f"\nmost parameters:")
    for path, name, lines, params in sorted(rows, key=lambda r: (-r[3], r[1]))[:args.top]:
        print(f"  {params:3d} {lines:5d}  {path.relative_to(package.parent)}:{name}")

    sub = package / args.package
    print(f"\nlines per module of {args.package}/:")
    total = 0
    for path in sorted(sub.rglob("*.py")):
        n = len(path.read_text().splitlines())
        total += n
        print(f"  {n:5d}  {path.relative_to(sub)}")
    print(f"  {total:5d}  total ({len(list(sub.rglob('*.py')))} files)")

    test_rows = list(functions(tests)) if tests.is_dir() else []
    print("\nrules, definitions by name (qemjax/ | tests/):")
    for rule, pattern in RULES.items():
        rx = re.compile(pattern, re.IGNORECASE)
        found = [r for r in rows if rx.search(r[1].rsplit(".", 1)[-1])]
        in_tests = [r for r in test_rows if rx.search(r[1].rsplit(".", 1)[-1]) and not
                    r[1].rsplit(".", 1)[-1].startswith("test_")]
        files = collections.Counter(str(p.relative_to(package.parent)) for p, *_ in found)
        print(f"  {rule:17s} {len(found):3d} in {len(files)} files | {len(in_tests)} in tests")
        if args.show:
            for p, name, lines, _ in found:
                print(f"      {p.relative_to(package.parent)}:{name} ({lines} lines)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
