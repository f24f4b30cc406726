"""How a run uses the Python process: the cyclic garbage collector paused around a run that allocates by
the million, and wall time summed per named stage."""
from __future__ import annotations

import contextlib
import gc


@contextlib.contextmanager
def gc_paused():
    """Python's cyclic garbage collector off for the block (as it was after). The greedy queue allocates
    small tuples and sets by the million and keeps many alive, so the collector ran thousands of times
    and traversed them, for a large share of a greedy run's CPU time (experiments/probes/greedy_gc.py). The
    queue makes no reference cycles; whatever else the block leaves behind is collected once the
    collector is back."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


class Timer:
    """Accumulates wall time per named stage (seconds, keys like ``kernels_s``)."""

    def __init__(self):
        self.t = {}

    def add(self, name, dt):
        self.t[name] = self.t.get(name, 0.0) + dt
