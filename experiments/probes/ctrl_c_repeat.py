"""The Ctrl-C test's scenario (`tests/test_sweep_stream.py`, in-process), run many times: a 32-cell sweep
of two generated meshes, one cell per batch, in its own process with a fresh compilation-cache folder;
SIGINT as soon as the first row is on disk. Counts the runs whose interrupt was lost (the sweep ran to its
end: every row kept) and the seconds from the signal to the exit.

    python experiments/probes/ctrl_c_repeat.py --runs 40
    python experiments/probes/ctrl_c_repeat.py --runs 40 --rev a9188fd   # the package at a git revision
    python experiments/probes/ctrl_c_repeat.py --runs 40 --executor dask --load 1 --trace

``--load`` runs that many busy processes beside it (a loaded machine, as a CI runner may be).
"""
from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))
sys.path.insert(0, str(ROOT / "tests"))  # test_sweep_stream imports conftest as pytest would
from ab_compare import package_at  # noqa: E402
from tests.test_sweep_stream import CONFIG, EXECUTORS, N_CELLS, SCRIPT, _rows, _wait_for_rows  # noqa: E402


# the command, printing the stack each Ctrl-C meets the handler at (``--trace``)
TRACED = SCRIPT.replace("from qemjax import _cli; ", "from qemjax import _cli; import traceback; h = _cli._on_sigint; "
                        "_cli._on_sigint = lambda s, f: (sys.stderr.write('Ctrl-C at:\\n' + "
                        "''.join(traceback.format_stack(f))), h(s, f))[1]; ")


def _busy(_):
    while True:
        pass


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--rev", default=None, help="run the package at this git revision instead of the tree's")
    ap.add_argument("--load", type=int, default=0, help="busy processes beside the sweeps")
    ap.add_argument("--executor", choices=sorted(EXECUTORS), default="in-process", help="where the cells run")
    ap.add_argument("--trace", action="store_true",
                    help="print where the handler met the signal, in runs that lost it")
    args = ap.parse_args()
    path = package_at(args.rev) if args.rev else ROOT
    burners = [multiprocessing.Process(target=_busy, args=(i,), daemon=True) for i in range(args.load)]
    for b in burners:
        b.start()
    lost, waits = 0, []
    try:
        for i in range(args.runs):
            folder = Path(tempfile.mkdtemp(prefix="ctrl-c-"))
            (folder / "s.toml").write_text(CONFIG + EXECUTORS[args.executor])
            env = dict(os.environ, QEMJAX_CACHE_DIR=str(folder / "cache"), PYTHONPATH=str(path))
            env.pop("QEMJAX_NO_CACHE", None)
            script = TRACED if args.trace else SCRIPT
            proc = subprocess.Popen([sys.executable, "-c", script, "sweep", str(folder / "s.toml"), "--quiet"],
                                    cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            _wait_for_rows(proc, folder / "table.csv", 1)
            t = time.monotonic()
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=120)
            waits.append(time.monotonic() - t)
            kept = len(_rows(folder / "table.csv"))
            lost += kept >= N_CELLS
            print(f"run {i + 1}: exit {proc.returncode}, {kept} of {N_CELLS} rows kept, "
                  f"{waits[-1]:.2f} s to stop{'  (interrupt lost)' if kept >= N_CELLS else ''}", flush=True)
            if args.trace and kept >= N_CELLS:
                print(err, flush=True)
            shutil.rmtree(folder)
    finally:
        for b in burners:
            b.terminate()
    print(f"package {args.rev or 'working tree'}, {args.executor}, load {args.load}: "
          f"interrupt lost in {lost} of {args.runs} runs; seconds to stop: median {statistics.median(waits):.2f}, max {max(waits):.2f}")


if __name__ == "__main__":
    main()
