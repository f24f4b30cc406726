"""Start-up time of the command line: ``qemjax --version`` and ``qemjax simplify --help`` in fresh processes,
the working tree's package against an old git revision's (``--rev``, unpacked into a temporary folder), runs
alternating so both see the same machine state; medians of wall time, each command's old / new ratio, and
whether the process imported JAX, numba or trimesh.

    python experiments/figures/startup.py --rev db766be              # before issue 42's start-up item
    python experiments/figures/startup.py --rev db766be --repeats 15

Each run is ``python -c "from qemjax.__main__ import main; ..."``, the command's entry point (before it
existed: ``qemjax._cli``), with the package's folder first on sys.path; a run before the timed ones checks
that each side imports its own copy. Needs no peers and no meshes.
"""
from __future__ import annotations

import argparse
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
COMMANDS = {"--version": ["--version"], "simplify --help": ["simplify", "--help"]}
HEAVY = ("jax", "numba", "trimesh")
RUN = ("import sys; sys.path.insert(0, {root!r}); from qemjax.{entry} import main; code = main({argv!r}); "
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
    p = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True)
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
        heavy = {}
        for side, root in sides.items():  # untimed: each side imports its own copy (and warms the disk cache)
            for name, argv in COMMANDS.items():
                _, file, mods = run(root, argv)
                if not Path(file).resolve().is_relative_to(root.resolve()):
                    raise SystemExit(f"{side} imported {file}, not its own copy under {root}")
                heavy[side, name] = mods
        times = {key: [] for key in heavy}
        for i in range(args.repeats):
            order = list(sides.items()) if i % 2 == 0 else list(sides.items())[::-1]
            for side, root in order:
                for name, argv in COMMANDS.items():
                    times[side, name].append(run(root, argv)[0])
    print(f"{sys.executable} -c 'from qemjax.ENTRY import main; main(ARGV)' (ENTRY: "
          f"{', '.join(f'{side}: {entry(root)}' for side, root in sides.items())}), {args.repeats} alternating runs "
          f"each; wall seconds")
    print(f"{'command':<18} {'side':<22} {'median s':>9} {'min s':>7}  imports")
    for (side, name), ts in times.items():
        print(f"{name:<18} {side:<22} {statistics.median(ts):9.3f} {min(ts):7.3f}  "
              f"{', '.join(heavy[side, name]) or '-'}")
    old, new = list(sides)
    for name in COMMANDS:
        ratio = statistics.median(times[old, name]) / statistics.median(times[new, name])
        print(f"{name}: old / new = {ratio:.1f}x")


if __name__ == "__main__":
    main()
