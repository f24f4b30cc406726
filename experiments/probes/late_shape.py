"""Triangle shape in the last stretch only: does the default's memoryless second phase, run with the shape
term (``quality_threshold``) or the quality guard (``min_angle``), remove the slivers at less cost than
either over the whole run?

The default switches to memoryless quadrics at twice the target (`_schedulers.late`); that stretch removes
half of the faces left and touches most of the output's faces. This probe gives the second phase's `Options`
the shape settings of two extra variant keys of `figures/rank_peers.py` (``late_qt=S``: the shape term at S;
``late_angle=A``: the guard at A degrees) and leaves the first phase as it is::

    python experiments/probes/late_shape.py [rank_peers arguments]

Without arguments: the ranking with the peers' rows reused, variants default, ``late_qt=0.6``,
``late_angle=10`` and both (-> results/late_shape.{csv,txt}).
"""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from qemjax import Topology  # noqa: E402
from qemjax._schedulers import late  # noqa: E402

_LATE: dict = {}  # the second phase's option changes of the run under way
_run = late.Second.run


def _second_run(self, scheduler, options, progress=None):
    if _LATE:
        options = dataclasses.replace(options, **_LATE)
    return _run(self, scheduler, options, progress)


def _late_options(settings: dict) -> dict:
    out = {}
    if "late_qt" in settings:
        out["quality_threshold"] = float(np.float32(settings.pop("late_qt")))
    if "late_angle" in settings:
        out["min_quality"] = float(Topology(min_angle=float(settings.pop("late_angle"))).min_quality)
    return out


def main(argv=None) -> int:
    from figures import rank_peers

    late.Second.run = _second_run
    runner = rank_peers.variant_runner

    def variant_runner(label, rev, settings):
        change = _late_options(settings)
        run = runner(label, rev, settings)

        def wrapped(V, F, target):
            _LATE.clear()
            _LATE.update(change)
            try:
                return run(V, F, target)
            finally:
                _LATE.clear()
        return wrapped

    rank_peers.variant_runner = variant_runner
    argv = argv or ["--warm", "--reuse-peers", "experiments/results/rank_late_memoryless.csv", "--out",
                    "experiments/results/late_shape", "--variant", "default:method=default",
                    "--variant", "lq06:late_qt=0.6", "--variant", "la10:late_angle=10",
                    "--variant", "lq06a10:late_qt=0.6,late_angle=10"]
    code = rank_peers.main([str(EXPERIMENTS.parent / a) if a.startswith("experiments/") else a for a in argv])
    out = Path(argv[argv.index("--out") + 1]) if "--out" in argv else None
    txt = out and (EXPERIMENTS.parent / out).with_suffix(".txt")
    if txt and txt.exists():  # its first line names the command: this probe's, which changed the second phase
        lines = txt.read_text().splitlines(keepends=True)
        txt.write_text("# python experiments/probes/late_shape.py (figures/rank_peers.py " + " ".join(argv)
                       + ", the second phase's options changed by this probe)\n" + "".join(lines[1:]))
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
