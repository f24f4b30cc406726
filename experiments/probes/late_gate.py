"""The first phase of a late run sized against the final target: fewer rounds, at what cost in quality?

The default runs in two phases (`qemjax._schedulers.late`): summed quadrics to ``late_memoryless`` × the
target, then memoryless ones to the target. Each phase is a run of the parallel scheduler, whose rounds shrink
as it nears its own target (`select.gate_rank`: about 1/(2·tail) of what is still needed, one pair at
the end), so the first phase ends with a tail of small rounds although the second phase goes on from
there. The variant here sizes the first phase's rounds by the faces still to remove to the final target
(the need `gate_rank` sees is raised by the switch's faces over the target) while the first phase still
stops exactly at the switch (`select.fits_target` keeps its own need); the second phase is unchanged.

For each shared mesh at 10 % and 1 %, both versions run in this process, alternating, ``--repeats`` warm
times each: the rounds, the median wall time, and the measured two-way distance (the stats' Hausdorff and
rms, relative to the diagonal) and the sliver fraction (`metrics.triangle_quality`) of both.

    python experiments/probes/late_gate.py --repeats 3   # -> results/late_gate.txt

Single runs only (a sweep's batches size their rounds in `_schedulers.batched`, left as they are).
"""
from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402

import qemjax  # noqa: E402
from qemjax import metrics  # noqa: E402
from qemjax._schedulers import late, select  # noqa: E402
from qemjax._schedulers.parallel import compiled, stages  # noqa: E402

_EXTRA = [0]  # faces from the phase's own target to the final one, added to the need the gate sees
_GATE, _RUN = select.gate_rank, late.run


def _gate_rank(need, n_valid, n_pairs, schedule):
    return _GATE(need + _EXTRA[0], n_valid, n_pairs, schedule)


def _late_run(scheduler, V, S, F, extra_pairs, target_faces, model, *args, **kwargs):
    """`late.run` with the first phase (the scheduler's first call) sized against ``target_faces``."""
    extra, calls = late.first_target(model, target_faces) - target_faces, []

    def sized(*a, **kw):
        _EXTRA[0] = 0 if calls else extra
        calls.append(1)
        try:
            return scheduler(*a, **kw)
        finally:
            _EXTRA[0] = 0
    return _RUN(sized, V, S, F, extra_pairs, target_faces, model, *args, **kwargs)


@contextlib.contextmanager
def variant():
    """The first phase sized against the final target (module docstring), within."""
    saved = late.run, stages.gate_rank, compiled.gate_rank
    late.run, stages.gate_rank, compiled.gate_rank = _late_run, _gate_rank, _gate_rank
    try:
        yield
    finally:
        late.run, stages.gate_rank, compiled.gate_rank = saved


def _once(V, F, ratio: float, new: bool):
    """(seconds, result) of one run, the variant's with ``new``."""
    with variant() if new else contextlib.nullcontext():
        t = time.perf_counter()
        r = qemjax.simplify((V, F), ratio=ratio)
        return time.perf_counter() - t, r


def _case(V, F, ratio: float, repeats: int) -> tuple[dict, dict]:
    """(old, new): rounds, median seconds, measured distance and slivers; warm, alternating."""
    times = {False: [], True: []}
    res = {new: _once(V, F, ratio, new)[1] for new in (False, True)}  # warm
    for k in range(repeats):
        for new in ((False, True) if k % 2 == 0 else (True, False)):
            times[new].append(_once(V, F, ratio, new)[0])
    return tuple({"t": statistics.median(times[new]), "rounds": res[new].stats["rounds"],
                  "H": res[new].stats["distance_max_rel"], "rms": res[new].stats["distance_rms_rel"],
                  "slivers": metrics.triangle_quality((res[new].vertices, res[new].faces))["sliver_fraction"]}
                 for new in (False, True))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="*", default=None, help="shared mesh names (default: all)")
    ap.add_argument("--ratios", nargs="*", type=float, default=[0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(EXPERIMENTS / "results" / "late_gate.txt"))
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    names = args.meshes or sorted(bench_meshes.shared_files())
    given = sys.argv[1:] if argv is None else list(argv)
    lines = [" ".join(["# python experiments/probes/late_gate.py", *given]), "",
             "| case | rounds | new rounds | ms | new ms | Hausdorff new/old | rms new/old | slivers | new slivers |",
             "|---|---|---|---|---|---|---|---|---|"]
    rows = []
    for name in names:
        m = bench_meshes.load(name)
        for ratio in args.ratios:
            old, new = _case(m.V, m.F, ratio, args.repeats)
            rows.append((old, new))
            lines.append(f"| {name} @ {ratio} | {old['rounds']} | {new['rounds']} | {old['t'] * 1e3:.1f} | "
                         f"{new['t'] * 1e3:.1f} | {new['H'] / old['H']:.3f} | {new['rms'] / old['rms']:.3f} | "
                         f"{old['slivers']:.4f} | {new['slivers']:.4f} |")
            print(lines[-1], flush=True)
    h = np.array([n["H"] / o["H"] for o, n in rows])
    rms = np.array([n["rms"] / o["rms"] for o, n in rows])
    t = np.array([n["t"] / o["t"] for o, n in rows])
    lines += ["", f"rounds: {sum(o['rounds'] for o, _ in rows)} -> {sum(n['rounds'] for _, n in rows)}; "
              f"time new/old: median {np.median(t):.3f}, of the sums "
              f"{sum(n['t'] for _, n in rows) / sum(o['t'] for o, _ in rows):.3f}",
              f"Hausdorff new/old: median {np.median(h):.3f}, more than 3 % worse in {(h > 1.03).sum()} of {len(h)}, "
              f"more than 3 % better in {(h < 0.97).sum()}",
              f"rms new/old: median {np.median(rms):.3f}, more than 3 % worse in {(rms > 1.03).sum()} of {len(rms)}, "
              f"more than 3 % better in {(rms < 0.97).sum()}; worst {rms.max():.3f}"]
    print("\n".join(lines[-3:]))
    Path(args.out).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
