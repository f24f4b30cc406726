"""Start-up and exit time of the command line: ``qemjax --version``, ``qemjax simplify --help`` and two small
runs of ``qemjax simplify``, from start to exit (the 5,120-face ``bumpy.obj`` of
`qemjax.shapes.write_examples` → 10 %, in core and partitioned into parts of 1,000 faces on two local
workers) in fresh processes, the working tree's package against an old git revision's (``--rev``, unpacked into
a temporary folder), runs alternating so both see the same machine state; medians of wall time, each
command's old / new ratio, and whether the process imported JAX, numba or trimesh.

    python experiments/figures/startup.py --rev db766be              # before issue 42's start-up item
    python experiments/figures/startup.py --rev db766be --repeats 15

Each run is ``python -c "import sys; sys.argv[1:] = ARGV; from qemjax.__main__ import main; ..."``, the
command's entry point as the ``qemjax`` command calls it (before it existed: ``qemjax._cli``), with the
package's folder first on sys.path and on ``PYTHONPATH``; a run before the timed ones checks that each side imports its own copy
(and fills the old side's compiled loops' cache: its first ``simplify`` compiles them). Needs no peers and no
meshes.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
REPO = EXPERIMENTS.parent
COMMANDS = {"--version": ["--version"], "simplify --help": ["simplify", "--help"],
            "simplify": ["simplify", "{tmp}/bumpy.obj", "{tmp}/out.obj", "--ratio", "0.1", "--quiet"],
            "simplify --partition": ["simplify", "{tmp}/bumpy.obj", "{tmp}/parts.obj", "--ratio", "0.1", "--partition",
                                     "--part-faces", "1000", "--workers", "2", "--quiet"]}
HEAVY = ("jax", "numba", "trimesh")
RUN = ("import sys; sys.path.insert(0, {root!r}); sys.argv[1:] = {argv!r}; from qemjax.{entry} import main; "
       "code = main(); "
       "print('@@', __import__('qemjax').__file__, *[m for m in {heavy!r} if m in sys.modules], file=sys.stderr); "
       "sys.exit(code)")


def unpack(rev: str, into: Path) -> Path:
    """The package at git revision ``rev``, written under ``into``; returns the folder that holds it."""
    data = subprocess.run(["git", "archive", "--format=tar", rev, "qemjax"], cwd=REPO, check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    return into


def entry(root: Path) -> str:
    """The module of the command's entry point in the package under ``root``."""
    return "__main__" if (root / "qemjax" / "__main__.py").exists() else "_cli"


def run(root: Path, argv: list[str]) -> tuple[float, str, list[str]]:
    """(wall seconds, the qemjax file imported, the heavy modules imported) of one fresh process."""
    code = RUN.format(root=str(root), entry=entry(root), argv=argv, heavy=HEAVY)
    t = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(root))  # (a partitioned run's workers import the same copy)
    p = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"{argv} under {root} failed ({p.returncode}): {p.stderr[-500:]}")
    tail = next(line for line in p.stderr.splitlines() if line.startswith("@@")).split()[1:]
    return wall, tail[0], tail[1:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", required=True, help="the old revision (e.g. db766be, before the start-up work)")
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sides = {f"old ({args.rev})": unpack(args.rev, Path(tmp)), "new (working tree)": REPO}
        sys.path.insert(0, str(REPO))
        from qemjax import shapes

        shapes.write_examples(tmp)
        commands = {name: [a.format(tmp=tmp) for a in argv] for name, argv in COMMANDS.items()}
        entries = {side: entry(root) for side, root in sides.items()}  # (the old side's folder goes with tmp)
        heavy = {}
        for side, root in sides.items():  # untimed: each side imports its own copy (and warms the disk cache)
            for name, argv in commands.items():
                _, file, mods = run(root, argv)
                if not Path(file).resolve().is_relative_to(root.resolve()):
                    raise SystemExit(f"{side} imported {file}, not its own copy under {root}")
                heavy[side, name] = mods
        times = {key: [] for key in heavy}
        for i in range(args.repeats):
            order = list(sides.items()) if i % 2 == 0 else list(sides.items())[::-1]
            for side, root in order:
                for name, argv in commands.items():
                    times[side, name].append(run(root, argv)[0])
    print(f"{sys.executable} -c 'sys.argv[1:] = ARGV; from qemjax.ENTRY import main; main()' (ENTRY: "
          f"{', '.join(f'{side}: {e}' for side, e in entries.items())}), {args.repeats} alternating runs "
          f"each; wall seconds")
    print(f"{'command':<22} {'side':<22} {'median s':>9} {'min s':>7}  imports")
    for (side, name), ts in times.items():
        print(f"{name:<22} {side:<22} {statistics.median(ts):9.3f} {min(ts):7.3f}  "
              f"{', '.join(heavy[side, name]) or '-'}")
    old, new = list(sides)
    for name in COMMANDS:
        ratio = statistics.median(times[old, name]) / statistics.median(times[new, name])
        print(f"{name}: old / new = {ratio:.1f}x")


if __name__ == "__main__":
    main()
